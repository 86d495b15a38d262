"""ReferenceSignal FMU: interface, values against NumPy, preview, Nyquist refusal, states.

Drives the built FMU through fmpy's FMU2Slave (fixtures in conftest.py).
"""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from harness.scenarios import get_scenario

H = 0.0005
THREE_TONES = {"offset": 0.7, "amplitude[1]": 10.0, "frequency[1]": 1.0, "phase[1]": 0.0,
               "amplitude[2]": 4.0, "frequency[2]": 37.5, "phase[2]": 0.3,
               "amplitude[3]": 2.0, "frequency[3]": 999.9, "phase[3]": -1.1}


def numpy_reference(t, params):
    """y_d(t) = offset + sum_i a_i sin(2 pi f_i t + phi_i), written here from the documented
    equation (NumPy), over the 8 tones of `params` (missing ones are 0)."""
    y = np.full(np.shape(t), float(params.get("offset", 0.0)))
    for i in range(1, 9):
        a = params.get(f"amplitude[{i}]", 0.0)
        f = params.get(f"frequency[{i}]", 0.0)
        p = params.get(f"phase[{i}]", 0.0)
        y = y + a * np.sin(2 * np.pi * f * np.asarray(t) + p)
    return y


def record(fmu, n):
    rows = []
    for _ in range(n):
        rows.append(fmu.get_reals(["y_d", "y_ref", "y_preview", "t_preview"]))
        fmu.step()
    return np.array(rows)


def test_validate_fmu_reports_nothing(fmu_paths):
    assert validate_fmu(str(fmu_paths["ReferenceSignal"])) == []


def test_interface(reference_signal):
    """The documented interface: outputs y_d, y_ref, y_preview [um] and t_preview [s] with no
    dependencies; parameters offset, amplitude/frequency/phase[1..8] (0, except the paper's
    1 Hz, 10 um tone: amplitude[1] = 10, frequency[1] = 1), lead (2, the loop delay of a
    master that exchanges at communication points), h, preview (4)."""
    v = reference_signal.variables
    md = reference_signal.md
    assert md.coSimulation.modelIdentifier == "ReferenceSignal"
    assert [n for n, x in v.items() if x.causality == "output"] == ["y_d", "y_ref", "y_preview", "t_preview"]
    assert [n for n, x in v.items() if x.causality == "input"] == []
    names = ["offset"] + [f"{k}[{i}]" for k in ("amplitude", "frequency", "phase") for i in range(1, 9)]
    tone = {"amplitude[1]": 10.0, "frequency[1]": 1.0}
    for name in names:
        assert v[name].causality == "parameter" and float(v[name].start) == tone.get(name, 0.0), name
    assert v["lead"].type == "Integer" and int(v["lead"].start) == 2
    assert v["preview"].type == "Integer" and int(v["preview"].start) == 4
    assert float(v["h"].start) == H
    assert v["y_d"].unit == v["y_ref"].unit == v["y_preview"].unit == "um" and v["frequency[1]"].unit == "Hz"
    assert v["t_preview"].unit == "s"
    assert {u.variable.name: list(u.dependencies) for u in md.outputs} == \
        {"y_d": [], "y_ref": [], "y_preview": [], "t_preview": []}


@pytest.mark.parametrize("lead", [0, 1, 2, 7])
@pytest.mark.parametrize("t0", [0.0, 0.25])
def test_values_and_preview_against_numpy(reference_signal, make_fmu, lead, t0):
    """Reference: numpy_reference (the equation in NumPy) at t_k = t0 + k h: y_d(k),
    y_ref(k) = y_d(t0 + (k + lead) h) and the stamped preview y_preview(k) =
    y_d(t_preview(k)), t_preview(k) = t0 + (k + preview) h (preview = lead + 3 here), 2000
    samples, three tones up to 999.9 Hz (just below Nyquist), tolerance 1e-12 um (the stamp
    1e-12 s); one many-sample step equals single steps bitwise."""
    params = {**THREE_TONES, "lead": lead, "preview": lead + 3}
    fmu = make_fmu(reference_signal)
    fmu.initialize(params, start_time=t0)
    got = record(fmu, 2000)
    k = np.arange(2000)
    np.testing.assert_allclose(got[:, 0], numpy_reference(t0 + k * H, params), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 1], numpy_reference(t0 + (k + lead) * H, params), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 3], t0 + (k + lead + 3) * H, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 2], numpy_reference(t0 + (k + lead + 3) * H, params), rtol=0, atol=1e-12)
    coarse = make_fmu(reference_signal)
    coarse.initialize(params, start_time=t0)
    coarse.step(2000)
    assert coarse.get_reals(["y_d", "y_ref", "y_preview", "t_preview"]) == \
        fmu.get_reals(["y_d", "y_ref", "y_preview", "t_preview"])


def test_paper_references_equal_the_harness_signal(reference_signal, make_fmu):
    """Reference: harness.scenarios' Signal.evaluate (the references the harness feeds) for
    the 1/10/20 Hz mix, and its preview two samples ahead; tolerance 1e-12 um."""
    sig = get_scenario("track_1_10_20hz").signal
    params = {"offset": sig.offset}
    for i, (a, f, p) in enumerate(zip(sig.amplitudes, sig.frequencies, sig.phases), start=1):
        params.update({f"amplitude[{i}]": a, f"frequency[{i}]": f, f"phase[{i}]": p})
    fmu = make_fmu(reference_signal)
    fmu.initialize(params)
    got = record(fmu, 6000)
    t = np.arange(6002) * H
    want = sig.evaluate(t)
    np.testing.assert_allclose(got[:, 0], want[:6000], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 1], want[2:], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name,value,h", [("frequency[1]", 1000.0, H), ("frequency[8]", 1500.0, H),
                                          ("frequency[4]", 250.0, 0.002), ("frequency[2]", -1.0, H)])
def test_frequency_at_or_above_nyquist_is_refused(reference_signal, make_fmu, name, value, h):
    """A tone at or above 1/(2h) (or negative) is refused at fmi2ExitInitializationMode with a
    message naming it and the valid range; fixing it lets the same call succeed."""
    fmu = make_fmu(reference_signal)
    fmu.setup(params={"h": h, name: value, "amplitude[1]": 1.0})
    fmu.clear_messages()
    with pytest.raises(FMICallException):
        fmu.slave.exitInitializationMode()
    msg = fmu.last_error()
    assert f"{name} = {value:g} is out of range" in msg and "Nyquist" in msg, msg
    fmu.set({name: 0.25 / h})
    fmu.slave.exitInitializationMode()


@pytest.mark.parametrize("name,value,fragment", [("lead", -1, "lead = -1 is out of range"),
                                                 ("h", 0.0, "h = 0 is out of range")])
def test_other_bad_parameters_are_refused(reference_signal, make_fmu, name, value, fragment):
    fmu = make_fmu(reference_signal)
    fmu.setup(params={name: value})
    with pytest.raises(FMICallException):
        fmu.slave.exitInitializationMode()
    assert fragment in fmu.last_error()


def test_state_restore_continues_bitwise(reference_signal, make_fmu):
    """Save at sample 700, run on, restore (also through a serialized blob in a fresh
    instance): the continuation equals the first one bitwise."""
    fmu = make_fmu(reference_signal)
    fmu.initialize(THREE_TONES)
    record(fmu, 700)
    state = fmu.slave.getFMUstate()
    blob = fmu.slave.serializeFMUstate(state)
    first = record(fmu, 300)
    fmu.slave.setFMUstate(state)
    fmu.slave.freeFMUstate(state)
    fmu.k = 700
    assert np.array_equal(record(fmu, 300), first)
    fresh = make_fmu(reference_signal)
    restored = fresh.slave.deSerializeFMUstate(blob)
    fresh.slave.setFMUstate(restored)
    fresh.slave.freeFMUstate(restored)
    fresh.h, fresh.k = H, 700
    assert np.array_equal(record(fresh, 300), first)
    assert math.isfinite(first[0, 0])


@pytest.mark.parametrize("edition", ["fmi2", "fmi3"])
def test_a_plain_fmpy_run_shows_the_papers_1hz_tone(fmu_paths, fmu3_paths, edition):
    """A user's first `fmpy.simulate_fmu("ReferenceSignal.fmu")`, no parameters given: the
    default experiment (3 s) shows the paper's 1 Hz, 10 um tone, not a flat line.
    Reference: 10 sin(2 pi t) in NumPy on fmpy's output grid, and y_ref = y_d two samples on."""
    import fmpy

    path = (fmu_paths if edition == "fmi2" else fmu3_paths)["ReferenceSignal"]
    result = fmpy.simulate_fmu(str(path), output=["y_d", "y_ref"])
    t = result["time"]
    assert t[0] == 0.0 and t[-1] == pytest.approx(3.0) and len(t) > 500   # fmpy's output grid
    np.testing.assert_allclose(result["y_d"], 10 * np.sin(2 * np.pi * t), rtol=0, atol=1e-9)
    np.testing.assert_allclose(result["y_ref"], 10 * np.sin(2 * np.pi * (t + 2 * H)), rtol=0,
                               atol=1e-9)
    assert result["y_d"].max() > 9.99 and result["y_d"].min() < -9.99
