"""harness.identify.fit: options and refusals of fit_coupled_model (the acceptance figures
are in test_identify_demo.py).

Records come from the core plant (the same C code as the FMU), noise-free and short
(1.5 s), so the reference is exact: the plant's parameters, normalised.
"""
import numpy as np
import pytest

from harness.masters.c_core import simulate_open_loop_core
from harness.identify.fit import CoupledModel, IdentificationInputError, fit_coupled_model
from harness.identify.steps import IdentificationRecord

H = 0.0005
PLANT = {"pi.w0": 0.3, "pi.w[1]": 0.05, "pi.w[2]": 0.04, "pi.w[3]": 0.02, "pi.w[4]": 0.01,
         "tf.a1": -1.442037, "tf.a2": 0.44641665, "tf.b1": 0.62517, "tf.b2": -0.620235,
         "creep.k_c": 1.03, "creep.alpha": -0.02}


def _truth(delay=0):
    w = (0.3, 0.05, 0.04, 0.02, 0.01, 0.0, 0.0, 0.0, 0.0, 0.0)
    return CoupledModel(w, 20.0, -1.442037, 0.44641665, 0.62517, -0.620235, 1.03, -0.02, H,
                        delay).normalized()


def _records(n=3000, delay=0):
    t = np.arange(n) * H
    inputs = {"low": 10 * np.sin(2 * np.pi * 2 * t) + 10,
              "mixed": 6 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t)
                            + np.sin(2 * np.pi * 80 * t)) + 18}
    out = {}
    for label, v in inputs.items():
        run = simulate_open_loop_core({**PLANT, "tf.delay": delay}, v)
        out[label] = IdentificationRecord(label, v, run["y"].copy())
    return out


@pytest.fixture(scope="module")
def records():
    return _records()


def _close_to_truth(model, truth, tol):
    assert np.max(np.abs(np.subtract(model.weights, truth.weights))) < tol
    np.testing.assert_allclose(model.poles, truth.poles, rtol=0, atol=tol)
    assert abs(model.zero - truth.zero) < tol and abs(model.alpha - truth.alpha) < tol


def test_a_record_serving_several_steps_and_no_holdout(records):
    """The low-frequency record serves steps 1 and 3, the mixed one steps 2 and 3; each enters
    the joint refinement once. Holdout 0 fits every sample and reports no held-out errors.
    Noise-free: the truth within 1e-7 (measured ~1e-11)."""
    low, mixed = records["low"], records["mixed"]
    r = fit_coupled_model(low, mixed, [low, mixed, low], holdout=0.0, v_max=20.0)
    assert r.held_out == () and r.holdout == 0.0
    assert [s.step for s in r.steps] == ["1 PI", "2 G", "3 creep", "3 creep", "3 creep", "joint",
                                         "Hammerstein"]
    assert r.step("joint").records == ("low", "mixed")
    assert r.step("joint").n_samples == low.v.size + mixed.v.size
    assert [row.records for row in r.creep_rows] == [("low",), ("mixed",), ("low",)]
    _close_to_truth(r.model, _truth(), 1e-7)
    with pytest.raises(KeyError, match="no step 'x'"):
        r.step("x")
    # default threshold scale: max |v| of the PI record (here 20 V at the sine's peak)
    assert fit_coupled_model(low, mixed, [low]).model.v_max == float(np.max(np.abs(low.v)))


def test_delay_is_honoured(records):
    """A plant with tf.delay = 1, identified with delay = 1: the truth again (and the output
    carries the delay)."""
    rec = _records(delay=1)
    r = fit_coupled_model(rec["low"], rec["mixed"], list(rec.values()), delay=1, v_max=20.0)
    assert r.model.delay == 1 and r.model.plant_params()["tf.delay"] == 1
    _close_to_truth(r.model, _truth(delay=1), 1e-6)
    for h in r.held_out:
        assert h.coupled_e_rms < 1e-6


def test_refusals(records):
    low, mixed = records["low"], records["mixed"]
    other = IdentificationRecord("low", mixed.v, mixed.y)
    with pytest.raises(IdentificationInputError, match="two different records are labelled 'low'"):
        fit_coupled_model(low, mixed, [other])
    short = IdentificationRecord("short", low.v[:120], low.y[:120])
    with pytest.raises(IdentificationInputError,
                       match="short: 120 samples leave 90 to fit and 30 held out; need at least 100"):
        fit_coupled_model(low, mixed, [short])
    bad = IdentificationRecord("bad", low.v, np.r_[low.y[:-1], np.nan])
    with pytest.raises(IdentificationInputError, match=r"bad: y\[2999\] = nan is not finite"):
        fit_coupled_model(low, mixed, [bad])
    ragged = IdentificationRecord("ragged", low.v, low.y[:-1])
    with pytest.raises(IdentificationInputError, match="ragged: v and y must have the same length"):
        fit_coupled_model(low, mixed, [ragged])
    for kwargs, message in [({"holdout": 0.95}, r"holdout must be in \[0, 0.9\]"),
                            ({"m": 17}, "m must be in 1..16"),
                            ({"delay": 9}, "delay must be in 0..8"),
                            ({"h": 0.0}, "h must be a finite number > 0"),
                            ({"v_max": -1.0}, "v_max must be a finite number > 0")]:
        with pytest.raises(ValueError, match=message):
            fit_coupled_model(low, mixed, [low], **kwargs)
    with pytest.raises(ValueError, match="need at least one creep record"):
        fit_coupled_model(low, mixed, [])
