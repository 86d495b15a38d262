"""The safe reaction (sup.reaction = 1) and the fault outputs in the FMUs that run the controller,
AdaptiveCompoundController and PiezoStageClosedLoop, both FMI editions, and in the harness's
masters (issue 36; docs/robustness.md, the fault codes and the safe reaction).

References: the same loop with sup.reaction = 0 (the sample its doStep refuses, its message),
the core's safe state (harness.binding.core, the ramp's closed form), the FMI 2.0 edition against the
FMI 3.0 one, a run restored from a saved or serialized FMU state against the run it was saved
from, and the start time against the times the FMU states.
"""
import warnings

import numpy as np
import pytest

from harness import masters
from harness.fmu import LoopFaultWarning
from harness.masters.wired import Fault, simulate_wired

H = 0.0005
SAFE = {"sup.reaction": 1}
PLANT_DELAY_4 = {"tf.delay": 4}       # a loop delay of 6: "loop delay beyond the controller's", code 4


def _closed_loop(backend, fmi_version=2, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        extra = {} if backend in ("core", "native") else {"fmi_version": fmi_version}
        res = masters.closed_loop(backend)("mismatch_5hz", plant_params=PLANT_DELAY_4, controller_params=SAFE,
                                           duration=0.5, **extra, **kwargs)
    return res, [str(w.message) for w in caught if issubclass(w.category, LoopFaultWarning)]


def test_every_master_runs_on_in_the_safe_state_and_says_why(fmu_paths):
    """A plant input delay of 4 samples (the fault table's row 16) with sup.reaction = 1 under the
    harness's masters: fmpy (FMI 2.0 and 3.0), native, core and the closed-loop FMU (FMI 2.0 and
    3.0). Reference: the same run with sup.reaction = 0, which stops at sample 29 (t = 14.5 ms).
    Each run reaches its end (0.5 s), v ramps to 0 V from the sample after that and stays there,
    each master issues one LoopFaultWarning with the controller's words ("sup.reaction = safe:
    from t = 0.0145 s ... (sup.fault = 4) ... Set mv.delay = 5"), and all give the same samples
    bit for bit."""
    with pytest.raises(Exception, match="sample 29"):
        masters.closed_loop("fmpy")("mismatch_5hz", plant_params=PLANT_DELAY_4, duration=0.5)
    runs = {}
    for backend, fmi in (("fmpy", 2), ("fmpy", 3), ("native", 2), ("core", 2), ("closed-loop-fmu", 2),
                         ("closed-loop-fmu", 3)):
        res, said = _closed_loop(backend, fmi)
        runs[(backend, fmi)] = res
        assert len(res) == 1000 and len(said) == 1, (backend, fmi, said)
        assert "sup.reaction = safe: from t = 0.0145 s the loop is held in its safe state (sup.fault = 4)" in said[0]
        assert "Set mv.delay = 5 (d = 6)" in said[0]
        assert np.all(res["v"][30 + 20:] == 0.0) and np.any(res["v"][30:50] != 0.0), backend
    first = runs[("fmpy", 2)]
    for key, res in runs.items():
        for field in ("y", "v", "q", "pred_error"):
            assert np.array_equal(res[field], first[field]), (key, field)


def test_the_fault_outputs_and_the_warning_in_both_editions(fmu_paths):
    """The three FMUs wired by hand (an exchanging master), y_meas inverted from t = 1 s, in each FMI
    edition. Reference: sup.reaction = 0, whose doStep fails at sample k_e with the inverted verdict.
    With sup.reaction = 1 the run reaches its end (2 s); the controller's outputs sup.fault = 2
    (inverted response) and sup.fault_time = k_e h; its Warning comes once and carries the Error's
    message word for word; v is 0 V from k_e + 20 on (sup.ramp_time = 10 ms); the editions agree."""
    fault = (Fault("y_meas", "scale", -1.0, start=1.0),)
    got = {}
    for fmi in (2, 3):
        err = simulate_wired("mismatch_5hz", "exchange", fault, duration=2.0, fmi_version=fmi)
        assert err.error.startswith("fmi") and "supervision stopped the loop (inverted response)" in err.error
        k_e = round(err.error_time / H)
        safe = simulate_wired("mismatch_5hz", "exchange", fault, duration=2.0, fmi_version=fmi,
                              controller_params=SAFE)
        assert safe.error == "" and len(safe.samples) == 4000
        assert (safe.fault, safe.fault_time) == (2, pytest.approx(k_e * H, abs=1e-12))
        said = [w for w in safe.warnings["controller"] if "sup.reaction = safe" in w]
        assert len(said) == 1 and said[0].endswith(err.error.split(": ", 1)[1])
        v = safe.samples["v"]
        assert np.all(v[k_e + 21:] == 0.0) and v[k_e + 1] != 0.0      # published one row later
        got[fmi] = safe.samples
    assert np.array_equal(got[2], got[3])


def test_times_in_messages_and_outputs_count_from_the_start_time(closed_loop, make_fmu):
    """PiezoStageClosedLoop started at t0 = 100 s, its stage's PI weights a tenth of the controller's
    model (the issue's example). Reference: the same FMU started at 0, which stops at sample 29.
    Every time it states is absolute: the Error's window "t = 100.0015 to 100.0145 s", the
    refused step "from t = 100.0145"; with sup.reaction = 1 the Warning "from t = 100.0145 s" and
    sup.fault_time = 100.0145 (100 + 29 h, as the FMU's own time), sup.fault = 1."""
    weights = {"pi.w0": 0.03344, "pi.w[1]": 0.00714, "pi.w[2]": 0.00322, "pi.w[3]": 0.00072}
    fmu = make_fmu(closed_loop)
    fmu.setup(100.0, weights)
    fmu.slave.exitInitializationMode()
    fmu.h, fmu.k = H, 0
    with pytest.raises(Exception):
        for _ in range(200):
            fmu.step()
    assert fmu.k == 29
    assert "(t = 100.0015 to 100.0145 s)" in fmu.errors()[0] and "from t = 100.0145" in fmu.errors()[-1]
    assert "controller.pi.w0" in fmu.errors()[0]
    safe = make_fmu(closed_loop)
    safe.setup(100.0, {**weights, **SAFE})
    safe.slave.exitInitializationMode()
    safe.h, safe.k = H, 0
    for _ in range(200):
        safe.step()
    assert safe.get("sup.fault") == 1 and safe.get("sup.fault_time") == 100.0 + 29 * H
    said = [text for status, _, text in safe.messages if status == 1 and "sup.reaction = safe" in text]
    assert len(said) == 1 and "from t = 100.0145 s" in said[0] and "(t = 100.0015 to 100.0145 s)" in said[0]


@pytest.mark.parametrize("save_at", [20, 40])
def test_the_safe_state_is_saved_restored_and_serialized(closed_loop, make_fmu, save_at):
    """PiezoStageClosedLoop with tf.delay = 4 and sup.reaction = 1 (the safe state from sample 37: the
    quantisation floor of the response test holds the delay verdict 8 samples longer than at 29
    before it, while the tone's response is still small).
    Reference: the run itself. A state saved at sample 20 (before the verdict) or 40 (in the ramp),
    restored into the same instance and deserialized into a fresh one, continues to the same
    outputs bit for bit (v, y, sup.fault, sup.fault_time) for 200 samples; the Warning is said
    once in each continuation after a state saved before the verdict, and not again after one
    saved in the safe state (what was said is part of the state)."""
    names = ("v", "y", "sup.fault_time")

    def outputs(fmu, n):
        rows = []
        for _ in range(n):
            rows.append([*fmu.get_reals(names), fmu.get("sup.fault")])
            fmu.step()
        return rows

    fmu = make_fmu(closed_loop)
    fmu.initialize({**PLANT_DELAY_4, **SAFE})
    outputs(fmu, save_at)
    state = fmu.slave.getFMUstate()
    blob = fmu.slave.serializeFMUstate(state)
    k0 = fmu.k
    fmu.clear_messages()
    want = outputs(fmu, 200)
    said_after = [t for s, _, t in fmu.messages if s == 1 and "sup.reaction = safe" in t]
    assert want[-1][0] == 0.0 and want[-1][3] == 4 and want[-1][2] == 37 * H
    assert len(said_after) == (1 if save_at < 37 else 0)
    fmu.slave.setFMUstate(state)
    fmu.slave.freeFMUstate(state)
    fmu.k = k0
    fmu.clear_messages()
    assert outputs(fmu, 200) == want
    assert len([t for s, _, t in fmu.messages if s == 1 and "sup.reaction = safe" in t]) == len(said_after)
    fresh = make_fmu(closed_loop)
    fresh.initialize({**PLANT_DELAY_4, **SAFE})
    restored = fresh.slave.deSerializeFMUstate(blob)
    fresh.slave.setFMUstate(restored)
    fresh.slave.freeFMUstate(restored)
    fresh.k = k0
    assert outputs(fresh, 200) == want
