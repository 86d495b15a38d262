"""Second-order transfer function G(z) with extra input delay (piezo_tf.h)."""

import numpy as np
import pytest
from scipy import signal

from conftest import assert_nonfinite_refusals_change_nothing
from harness.binding import core
import numpy_reference as ref

D = ref.DOC_DEFAULTS
NOMINAL = (D["tf.a1"], D["tf.a2"], D["tf.b1"], D["tf.b2"])
OTHER = (-1.1, 0.45, 0.3, 0.25)          # poles 0.55 +- 0.38j, different zero


def make_signal():
    rng = np.random.default_rng(3)
    t = np.arange(20000) * 0.0005
    return 10 * np.sin(2 * np.pi * 5 * t) + 10 + np.cumsum(rng.normal(0, 0.05, t.size))


def run_core(coeffs, delay, u):
    a1, a2, b1, b2 = coeffs
    tf = core.transfer_function({"tf.a1": a1, "tf.a2": a2, "tf.b1": b1, "tf.b2": b2, "tf.delay": delay})
    return np.array([tf.step(x) for x in u])


@pytest.mark.parametrize("coeffs", [NOMINAL, OTHER], ids=["nominal", "other"])
@pytest.mark.parametrize("delay", [0, 1, 3, 32])
def test_matches_lfilter(coeffs, delay):
    """Reference: scipy.signal.lfilter with b = [0]*(1+delay) + [b1, b2], a = [1, a1, a2].
    The core's step(u(k)) returns x(k+1), i.e. lfilter's sample k+1. 20000 samples of a
    0-20 um signal; tolerance 1e-10 um (summation order; the slow pole amplifies
    rounding by ~1/(1-0.992))."""
    a1, a2, b1, b2 = coeffs
    u = make_signal()
    x_ref = signal.lfilter([0.0] * (1 + delay) + [b1, b2], [1.0, a1, a2], np.append(u, 0.0))
    got = run_core(coeffs, delay, u)
    err = np.max(np.abs(got - x_ref[1:]))
    assert err <= 1e-10, err


def test_matches_numpy_loop_reference():
    """Reference: numpy_reference.tf_filter (the difference equation as a loop), delay 3;
    tolerance 1e-12 um."""
    u = make_signal()[:5000]
    got = run_core(NOMINAL, 3, u)
    want = ref.tf_filter(u, *NOMINAL, delay=3)[1:]
    assert np.max(np.abs(got - want)) <= 1e-12


def test_design_facts_poles_zero_dc_gain():
    """Reference: docs/model.md, plant facts (poles 0.992037 and 0.384663, zero 0.992106,
    DC gain 0.959) from numpy.roots on the core's default coefficients, and the core's
    step response after 10 s reaching the DC gain (b1+b2)/(1+a1+a2) within 1e-9."""
    p = core.default_plant_params()
    a1, a2, b1, b2 = p["tf.a1"], p["tf.a2"], p["tf.b1"], p["tf.b2"]
    poles = np.sort(np.roots([1, a1, a2]).real)
    assert poles == pytest.approx([0.384663, 0.992037], abs=1e-6)
    assert -b2 / b1 == pytest.approx(0.992106, abs=1e-6)
    dc = (b1 + b2) / (1 + a1 + a2)
    assert dc == pytest.approx(0.959, abs=5e-4)
    x = run_core((a1, a2, b1, b2), 0, np.ones(20000))
    assert abs(x[-1] - dc) <= 1e-9


@pytest.mark.parametrize("a1,a2", [
    (-1.5, 0.5),      # pole at z = 1
    (-2.1, 1.1),      # pole outside
    (0.0, 1.0),       # poles on the unit circle (+-j)
    (0.2, -1.0),      # |a2| = 1
    (2.0, 0.95),      # |a1| > 1 + a2 (a real pole below -1)
    (-2.0, 1.0),      # double pole at 1
    (float("nan"), 0.3),
])
def test_unstable_denominator_refused(a1, a2):
    """Reference: the Jury conditions |a2| < 1 and |a1| < 1 + a2 (numpy.roots confirms
    each case has a pole on or outside the unit circle). The core must refuse with a
    CoreParameterError naming tf.a1 or tf.a2 and a range."""
    if np.isfinite(a1):
        assert np.max(np.abs(np.roots([1, a1, a2]))) >= 1 - 1e-12
    with pytest.raises(core.CoreParameterError) as ei:
        core.transfer_function({"tf.a1": a1, "tf.a2": a2})
    assert ei.value.parameter in ("tf.a1", "tf.a2")
    assert ei.value.valid_range
    with pytest.raises(core.CoreParameterError):
        core.Plant({"tf.a1": a1, "tf.a2": a2})


def test_nearly_unit_pole_accepted():
    """Reference: numpy.roots. A = 1 - 1.9 z^-1 + 0.9005 z^-2 has poles 0.95 +- 0.0224j,
    |p| = 0.94895 < 1: must be accepted."""
    assert np.max(np.abs(np.roots([1, -1.9, 0.9005]))) < 1
    core.transfer_function({"tf.a1": -1.9, "tf.a2": 0.9005})


@pytest.mark.parametrize("delay", [-1, 33, 1000])
def test_delay_out_of_range_refused(delay):
    """Reference: piezo_tf.h (0 <= delay <= 32)."""
    with pytest.raises(core.CoreParameterError) as ei:
        core.transfer_function({"tf.delay": delay})
    assert ei.value.parameter == "tf.delay" and ei.value.value == delay


@pytest.mark.parametrize("name", ["tf.b1", "tf.b2"])
def test_nonfinite_numerator_refused(name):
    """Reference: piezo_tf.h (finite coefficients)."""
    for bad in (np.nan, np.inf):
        with pytest.raises(core.CoreParameterError) as ei:
            core.transfer_function({name: bad})
        assert ei.value.parameter == name


def test_nonfinite_input_refused_state_unchanged():
    """Reference: an uninterrupted run; the continuation after refused NaN/Inf inputs is
    bitwise identical."""
    assert_nonfinite_refusals_change_nothing(lambda: core.transfer_function({"tf.delay": 2}),
                                             make_signal()[:300], (0, 50, 299), core.CoreInputError)


def test_reset_restores_rest():
    """Reference: a fresh instance; reset() gives bitwise the same response."""
    u = make_signal()[:500]
    tf = core.transfer_function({"tf.delay": 3})
    first = [tf.step(x) for x in u]
    tf.reset()
    assert [tf.step(x) for x in u] == first
