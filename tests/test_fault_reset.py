"""sup.reset, the controller's fault reset (issue 44; docs/robustness.md, "Leaving the safe state"),
on the C core, in both FMUs that run the controller and in both FMI editions.

References: the run's own cause by construction (a sensor stuck until a known sample, a reference
beyond any stage's reach until a known sample, an amplifier inverted for good); the same run with
no fault (the step after the restart against the same step); a run with no reset raised (what a
reset with no safe state must leave bit for bit); the core binding against the FMUs, and the FMI
2.0 edition against the FMI 3.0 one (the same samples bit for bit); a run restored from an FMU
state saved before the reset against the run it was saved from.
"""
import numpy as np
import pytest
from fmpy.fmi3 import FMU3Slave

from harness.binding import core
from harness.studies import supervision_table as st

H = 0.0005
SAFE = {"sup.reaction": 1}


def case(kind):
    return next(c for c in st.RESET_CASES if c.kind == kind)


@pytest.mark.parametrize("kind", ["stuck", "dead"])
@pytest.mark.parametrize("nm", [5, 200])
def test_a_reset_is_refused_while_the_sensor_is_stuck_and_accepted_once_it_is_back(kind, nm):
    """The stage's day's first two stages in a 5 um hold: y_meas sticks (where it was, or at 0) at
    t = 2 s, the safe state comes (y_meas frozen); a reset at 2.6 s, the sensor still stuck, is
    refused naming the cause ("y_meas still reads ... to the bit"); the sensor is back at 2.8 s; a
    reset at 3 s is accepted. The restarted loop starts v from 0 V (below 1.5 V at its first
    sample, the family's worst 1.1 V), nothing stops it, the 10 um step at 3.5 s errs within 5 %
    (5 nm) or 10 % (200 nm, whose noise moves the step's peak error: 1.06 here) of the same step in
    the same run without a fault, and the hold after it stays within the sensor's noise band
    (0.05 um at 5 nm, 0.5 um at 200 nm)."""
    for i in range(2):
        plant = st._day_plant(i, nm)
        r = st.run_reset(case(kind), plant)
        assert r["fault"] == "y_meas frozen"
        accepted, text = r["early"]
        assert not accepted and text.startswith("sup.reset refused at t = 2.6 s: the cause persists. y_meas still reads")
        assert "sup.fault = 8, y_meas frozen" in text
        accepted, text = r["late"]
        assert accepted and text.startswith("sup.reset accepted at t = 3 s (reset 1)"), text
        assert r["again"] == ""
        assert r["v_first"] < 1.5
        base = st.run_reset(st.RESET_BASELINE, plant)
        assert r["step"] <= (1.05 if nm == 5 else 1.1) * base["step"], (i, r["step"], base["step"])
        assert r["settled"] < (0.05 if nm == 5 else 0.5)


def test_a_reset_is_refused_while_the_reference_is_out_of_reach():
    """y_d jumps to 400 um (beyond the stage's reach) at 2 s: v is held at +150 V for
    sup.clip_time and the safe state comes (v held at a limit). A reset at 2.6 s, y_d still at
    400 um, is refused: the message names the reference and the reading at the rail. y_d is back
    at 5 um at 2.8 s; the reset at 3 s is accepted and the step after it is within 5 % of the
    fault-free run's."""
    plant = st._day_plant(0, 20)
    r = st.run_reset(case("reach"), plant)
    assert r["fault"] == "v held at a limit"
    accepted, text = r["early"]
    assert not accepted and "The reference y_ref = 400 um is still beyond what the stage reached with v held " \
                               "at 150 V" in text
    assert r["late"][0] and r["again"] == ""
    assert r["step"] <= 1.05 * st.run_reset(st.RESET_BASELINE, plant)["step"]


def test_a_reset_with_the_amplifier_still_inverted_is_stopped_again_in_motion():
    """The stage gets -v from 2 s on and nothing clears it. In the hold the loop runs to a rail
    (v held at a limit); the reset at 3 s is accepted (at rest the inversion cannot be seen, and
    the reading at the rail lies against the way v went, so it is not taken for the reach); the
    restarted loop's own ramp of the reference moves the stage, and the supervision stops it again
    as an inverted response within 20 ms (the family: 16.5 ms median at 5-100 nm)."""
    r = st.run_reset(case("inverted"), st._day_plant(0, 20))
    assert r["fault"] == "v held at a limit" and r["late"][0]
    assert r["again"] == "inverted response" and r["again_time"] < 0.02


def _loop(plant, n, y_d, hook=None, controller=None):
    """The core plant and controller stepped as an exchanging master; hook(k, c, y_ref, y_meas)
    before each sample. (y, v) of every sample."""
    p = core.Plant(plant)
    c = core.Controller(dict(SAFE, **(controller or {})))
    v, ys, vs = 0.0, np.empty(n), np.empty(n)
    for k in range(n):
        ys[k] = p.output.y
        r, meas = y_d[min(n - 1, k + 2)], p.output.y_meas
        if hook:
            hook(k, c, r, meas)
        out = c.step(r, meas)
        p.step(v)
        v = vs[k] = out.v
    return ys, vs, c


def test_a_reset_without_a_safe_state_changes_nothing():
    """Raised while the loop runs, the reset is "nothing to reset" and the run is the run without
    it, bit for bit (a 10 Hz, 10 um raster frame on the day's first stage)."""
    plant = st._day_plant(0, 1)
    t = np.arange(2000) * H
    y_d = 10.0 * np.abs(((t * 10.0) % 1.0) * 2.0 - 1.0)
    said = []
    base = _loop(plant, 2000, y_d)
    got = _loop(plant, 2000, y_d, hook=lambda k, c, r, m: said.append(c.fault_reset(r, m)) if k == 700 else None)
    assert np.array_equal(got[0], base[0]) and np.array_equal(got[1], base[1])
    assert said == [(False, "sup.reset raised at t = 0.35 s while the loop runs (sup.fault = 0): there is no "
                             "safe state to leave, nothing was done")]


def test_a_reset_during_the_ramp_to_0_V_is_refused_and_the_restarted_state_checks():
    """A dead sensor (reads 0) at 2 s in a 5 um hold, 20 nm: the safe state from sample 4003 (4
    equal samples). A reset 10 samples later, v still ramping (sup.ramp_time 10 ms = 20 samples),
    is refused ("v is still ramping to 0 V ... until t = 2.0115 s"); the sensor back, a reset at
    2.1 s restarts the loop: piezo_controller_check accepts the restarted state, k_start is that
    sample, and the check refuses it with k_start moved past the sample count."""
    plant = st._day_plant(0, 20)
    n = 4400
    y_d = np.full(n, 5.0)
    said = {}

    def hook(k, c, r, meas):
        if k in (4013, 4200):
            said[k] = c.fault_reset(r, meas)

    p = core.Plant(plant)
    c = core.Controller(SAFE)
    v = 0.0
    for k in range(n):
        meas = 0.0 if 4000 <= k < 4100 else p.output.y_meas
        hook(k, c, y_d[k], meas)
        if k == 4013:
            assert c.raw.fault == 8 and c.raw.k_fault == 4003
        out = c.step(y_d[k], meas)
        p.step(v)
        v = out.v
    assert not said[4013][0] and "v is still ramping to 0 V (sup.ramp_time = 0.01 s, until t = 2.0115 s)" \
        in said[4013][1]
    assert said[4200][0] and c.raw.fault == 0 and c.raw.k_start == 4200 and c.raw.n_resets == 1
    check = lambda: core.ffi.string(core.lib().piezo_controller_check(c.raw) or core.ffi.new("char[]", b"")).decode()  # noqa: E731
    assert check() == ""
    c.raw.k_start = c.raw.k + 1
    assert "restart (sup.reset)" in check()


# -------------------------------------------------------------------------------------------------
# the FMUs

REACH = 400.0       # um: beyond any stage's reach


def _closed_loop_fmi2(make_fmu, closed_loop):
    fmu = make_fmu(closed_loop, logging_on=True)
    fmu.initialize({"use_internal_reference": False, "y_d_lead": 2, **SAFE})
    return fmu


def _drive(fmu, schedule, n, get, set_, step):
    """Run n samples of the closed-loop FMU: y_d and sup.reset from schedule(k); rows of
    (y, v, sup.fault)."""
    rows = []
    for k in range(n):
        y_d, reset = schedule(k)
        set_(y_d, reset)
        step()
        rows.append(get())
    return rows


def _schedule(k):
    """5 um, then out of reach from sample 2000 to 3600; sup.reset raised at 3200 (refused), lowered
    at 3300, raised at 3800 (accepted)."""
    y_d = REACH if 2000 <= k < 3600 else 5.0
    return y_d, 3200 <= k < 3300 or k >= 3800


N = 4400


def test_the_closed_loop_fmu_refuses_then_accepts_a_reset_and_its_state_survives(make_fmu, closed_loop):
    """PiezoStageClosedLoop (FMI 2.0), y_d from its input: y_d out of reach from 1 s, v held at the
    rail, the safe state after sup.clip_time (sup.fault = 5 at 1.5 s). sup.reset raised at 1.6 s,
    y_d still out of reach: refused with one Warning ("sup.reset refused at t = 1.6 s: the cause
    persists. The reference y_ref = 400 um ..."), sup.fault stays 5. Lowered, y_d back at 5 um at
    1.8 s, raised at 1.9 s: accepted (an event "sup.reset accepted at t = 1.9 s (reset 1)"),
    sup.fault = 0 from that step, and the stage holds 5 um again within 5 nm by 2.2 s. An FMU
    state saved at 1.85 s and restored gives the same outputs bit for bit, messages included, and
    so does its serialized copy deserialized into a fresh instance."""
    fmu = _closed_loop_fmi2(make_fmu, closed_loop)

    def set_(y_d, reset):
        fmu.set({"y_d": y_d, "sup.reset": reset})

    def get():
        return (*fmu.get_reals(["y", "v"]), fmu.get("sup.fault"))

    rows = _drive(fmu, _schedule, 3700, get, set_, fmu.step)
    assert rows[3100][2] == 5 and rows[3250][2] == 5
    refused = [t for s, _, t in fmu.messages if s == 1 and t.split(": ", 1)[-1].startswith("sup.reset refused")]
    assert len(refused) == 1 and "sup.reset refused at t = 1.6 s: the cause persists. The reference y_ref = 400 um" \
        in refused[0]
    state = fmu.slave.getFMUstate()
    blob = fmu.slave.serializeFMUstate(state)
    fmu.clear_messages()
    tail = _drive(fmu, lambda k: _schedule(k + 3700), N - 3700, get, set_, fmu.step)
    said = [t for s, _, t in fmu.messages if "sup.reset" in t]
    assert len(said) == 1 and "sup.reset accepted at t = 1.9 s (reset 1)" in said[0]
    assert tail[99][2] == 5 and tail[100][2] == 0 and tail[-1][2] == 0
    assert max(abs(y - 5.0) for y, _, _ in tail[-200:]) < 0.005
    fmu.slave.setFMUstate(state)
    fmu.slave.freeFMUstate(state)
    fmu.k = 3700
    fmu.clear_messages()
    again = _drive(fmu, lambda k: _schedule(k + 3700), N - 3700, get, set_, fmu.step)
    assert again == tail
    assert [t for s, _, t in fmu.messages if "sup.reset" in t] == said
    fresh = _closed_loop_fmi2(make_fmu, closed_loop)
    restored = fresh.slave.deSerializeFMUstate(blob)
    fresh.slave.setFMUstate(restored)
    fresh.slave.freeFMUstate(restored)
    fresh.k = 3700
    got = _drive(fresh, lambda k: _schedule(k + 3700), N - 3700,
                 lambda: (*fresh.get_reals(["y", "v"]), fresh.get("sup.fault")),
                 lambda y_d, reset: fresh.set({"y_d": y_d, "sup.reset": reset}), fresh.step)
    assert got == tail


def test_the_fmi3_closed_loop_gives_the_fmi2_samples(make_fmu, closed_loop, fmu3_paths):
    """The same schedule through the FMI 3.0 edition of PiezoStageClosedLoop: the same y, v and
    sup.fault at every sample, bit for bit, and the same reset messages."""
    import fmpy
    fmu = _closed_loop_fmi2(make_fmu, closed_loop)

    def set2(y_d, reset):
        fmu.set({"y_d": y_d, "sup.reset": reset})

    want = _drive(fmu, _schedule, N, lambda: (*fmu.get_reals(["y", "v"]), fmu.get("sup.fault")), set2, fmu.step)
    path = str(fmu3_paths["PiezoStageClosedLoop"])
    md = fmpy.read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = fmpy.extract(path)
    messages = []
    s = FMU3Slave(guid=md.instantiationToken, unzipDirectory=unzip, modelIdentifier="PiezoStageClosedLoop",
                  instanceName="reset")
    s.instantiate(loggingOn=True, logMessage=lambda env, status, category, message: messages.append(message.decode()))
    s.enterInitializationMode(startTime=0.0)
    s.setBoolean([vr["use_internal_reference"]], [False])
    s.setInt32([vr["y_d_lead"]], [2])
    s.setInt32([vr["sup.reaction"]], [1])
    s.exitInitializationMode()
    t = [0]

    def set3(y_d, reset):
        s.setFloat64([vr["y_d"]], [y_d])
        s.setBoolean([vr["sup.reset"]], [bool(reset)])

    def step3():
        s.doStep(t[0] * H, H)
        t[0] += 1

    got = _drive(None, _schedule, N, lambda: (*s.getFloat64([vr["y"], vr["v"]]), s.getInt32([vr["sup.fault"]])[0]),
                 set3, step3)
    s.terminate()
    s.freeInstance()
    assert got == want
    assert any("sup.reset accepted at t = 1.9 s (reset 1)" in m for m in messages)
    assert any("sup.reset refused at t = 1.6 s" in m for m in messages)


def test_the_controller_fmu_restarts_as_the_core_does(make_fmu, controller):
    """AdaptiveCompoundController (FMI 2.0) in a loop with the core plant (an exchanging master),
    y_meas dead (reads 0) from 1 s to 1.3 s in a 5 um hold with a 20 nm sensor, sup.reset raised
    at 1.2 s (refused: y_meas still reads 0) and at 1.5 s (accepted), a 10 um step at 1.75 s. The
    FMU's v and sup.fault equal the core binding's (Controller.fault_reset at the same samples)
    at every sample, bit for bit."""
    plant = st._day_plant(0, 20)
    n = 4000
    y_d = np.where(np.arange(n) >= 3500, 15.0, 5.0)
    raised = lambda k: 2400 <= k < 2500 or k >= 3000      # noqa: E731

    def run(with_fmu):
        p = core.Plant(plant)
        if with_fmu:
            fmu = make_fmu(controller, logging_on=True)
            fmu.initialize(SAFE)
        else:
            c = core.Controller(SAFE)
            prev = False
        v, rows = 0.0, []
        for k in range(n):
            meas = 0.0 if 2000 <= k < 2600 else p.output.y_meas
            r = y_d[min(n - 1, k + 2)]
            if with_fmu:
                fmu.set({"y_ref": r, "y_meas": meas, "sup.reset": raised(k)})
                fmu.step()
                out_v, fault = fmu.get("v"), fmu.get("sup.fault")
            else:
                if raised(k) and not prev:
                    c.fault_reset(r, meas)
                prev = raised(k)
                out_v, fault = c.step(r, meas).v, c.fault
            p.step(v)
            v = out_v
            rows.append((out_v, fault))
        return rows, (fmu.messages if with_fmu else None)

    want, _ = run(False)
    got, messages = run(True)
    assert got == want
    assert want[2450][1] == 8 and want[3000][1] == 0
    texts = [t for _, _, t in messages if "sup.reset" in t]
    assert len(texts) == 2 and "sup.reset refused at t = 1.2 s" in texts[0] and "sup.reset accepted at t = 1.5 s" \
        in texts[1]
