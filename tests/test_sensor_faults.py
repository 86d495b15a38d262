"""Issue 44 on the C core: a sensor that stops answering (stuck, dead, stuck after a dropout) is
named within the targets and bridged, no legitimate run is stopped, a quiet sensor stuck at the
set-point costs only the stage's own drift, and noisy sensors at start make the delay detection
wait instead of failing. A small deterministic slice of the studies whose whole families
docs/robustness.md shows (``python -m harness supervision stuck`` and ``start``).

References: the faults by construction (harness.studies.supervision_table.STUCK_CASES), the issue's
targets (named within 20 ms in motion and 0.2 s in a hold; the stage within 2 um beyond the
reference in a scan and 0.1 um of the set-point in a hold), the loop's own delay (2) and the
whole families' figures of docs/robustness.md."""

import math

import pytest

from harness.binding import core
from harness.studies import supervision_table as st
from harness.studies.stage_day_table import H

STAGES = 3


def case(name):
    return next(c for c in st.STUCK_CASES if c.name == name)


def plant(i, nm):
    return st._day_plant(i, nm)


@pytest.mark.parametrize("nm", [0, 1, 20, 200])
@pytest.mark.parametrize("where", ["none, hold", "none, scan"])
def test_the_legitimate_runs_of_the_slice_raise_no_alarm(where, nm):
    """The same hold and scan without a fault, sensors of 0 to 200 nm: nothing stops them, and the
    stage stays within the band the sensor's noise gives (as measured on the family: 0.58 um at
    200 nm in a hold, 0.87 um in the scan)."""
    for i in range(STAGES):
        r = st.run_stuck(case(where), plant(i, nm))
        assert r["fault"] == "", (i, r["error"])
        assert r["excursion"] < 0.9


@pytest.mark.parametrize("nm", [1, 20, 100])
@pytest.mark.parametrize("name", ["stuck mid-scan", "dead (reads 0) mid-scan", "stuck after a dropout, mid-scan"])
def test_a_sensor_that_stops_answering_in_a_scan_is_named_within_20_ms(name, nm):
    """Mid-ramp of a 10 Hz, 10 um raster the reading sticks (where it was, at 0, or after a dropout):
    the loop is stopped naming y_meas ("y_meas frozen", or "no response" whose message says "y_meas
    is stuck, or v does not reach the stage") within 20 ms of the onset (the family: 6 ms at worst),
    the stage within 2 um of the reference (the family: 1 um at worst)."""
    for i in range(STAGES):
        r = st.run_stuck(case(name), plant(i, nm))
        assert r["fault"] in ("y_meas frozen", "no response"), (i, r["error"])
        assert "y_meas" in r["error"] and r["time"] <= 0.02, (i, r["time"])
        assert r["excursion"] < 2.0, (i, r["excursion"])
        if r["fault"] == "no response":
            assert "y_meas is stuck, or v does not reach the stage" in r["error"]


@pytest.mark.parametrize("nm", [1, 20, 200])
def test_a_dead_sensor_in_a_hold_is_bridged_and_named_at_once(nm):
    """A sensor that reads 0 from t = 2 s in a 5 um hold: the reading is taken for an outlier, the
    model's prediction stands in for it and for its repeats, and after 4 equal samples (1.5 ms; 2.5
    with the 200 nm sensor, whose noise test needs 5) the loop is stopped, the message saying the
    reading jumped to 0 um and held it to the bit; the stage stays where it was (within the band
    of the sensor's noise: 0.34 um at 200 nm on the family, 4 nm at 1 nm)."""
    for i in range(STAGES):
        r = st.run_stuck(case("dead (reads 0) in a hold"), plant(i, nm))
        assert r["fault"] == "y_meas frozen" and r["time"] <= 0.003, (i, r["time"], r["error"])
        if nm < 200:
            assert "it jumped to 0 um" in r["error"] and "has held that value to the bit" in r["error"]
            assert r["time"] == pytest.approx(0.0015)
        assert r["excursion"] < (0.01 if nm == 1 else 0.4), (i, r["excursion"])


@pytest.mark.parametrize("nm", [5, 20, 200])
def test_a_noisy_sensor_stuck_in_a_hold_is_named_within_10_ms(nm):
    """A sensor whose noise shows (5 nm and more on the 2 nm grid) stuck where it was in a hold is
    stopped as "y_meas frozen" within 10 ms (the family: 7 ms at worst; the target 0.2 s). The stage
    is within 0.15 um beyond the noise band it had before: the law acts on the stuck noisy reading
    for the 2 to 4 ms before the verdict (a miss of the issue's 0.1 um: the family's worst with the
    20 nm sensor is 0.125 um against 0.08 before the onset)."""
    for i in range(STAGES):
        r = st.run_stuck(case("stuck in a hold"), plant(i, nm))
        assert r["fault"] == "y_meas frozen" and r["time"] <= 0.01, (i, r["time"], r["error"])
        assert r["excursion"] <= r["before"] + 0.15, (i, r["excursion"], r["before"])


@pytest.mark.parametrize("name", ["stuck in a hold", "stuck 2 nm off in a hold"])
@pytest.mark.parametrize("nm", [0, 1])
def test_a_quiet_sensor_stuck_at_the_set_point_is_bridged(nm, name):
    """The case nothing can see: a sensor of 0 or 1 nm stuck where the stage holds (or 2 nm off).
    Once sup.gain_min times the supervision model's move since it last changed reaches its step the
    reading is stale: the integral holds and the loop model's prediction stands in, so the stage
    holds on the model and drifts only by its own mismatch: over the 0.5 s after the onset within
    0.05 um (the family's worst 0.042 um), unnamed. The stages are the stage's day's 0, 7, 30 and
    38, chosen so that every case fails without the bridge (measured with the stale flag forced
    to 0: 0.1-0.2 um on stage 0 at 1 nm and in both 2 nm off cases, 0.10 um on stages 30 and 38
    stuck at 0 nm; stage 7: the family's worst, 2 nm off at 1 nm, when the stale reading's test
    used the noise measured while it is held, which decays)."""
    for i in (0, 7, 30, 38):
        r = st.run_stuck(case(name), plant(i, nm))
        assert r["fault"] == "" and r["excursion"] < 0.05, (i, r["excursion"], r["fault"])


def declared_repeats(sigma_nm, step_nm=2.0, log_odds=28):
    """The run of repeats a declared sensor noise turns into 'y_meas frozen', from the closed form:
    a live reading quantize(y + n), n ~ N(0, sigma^2) on a grid of step q, repeats its value with a
    chance of at most p = erf(q / (2 sqrt(2) sigma)); the verdict comes at the first m with
    p^m <= e^-log_odds."""
    p = math.erf(step_nm / (2.0 * math.sqrt(2.0) * sigma_nm))
    return math.ceil(log_odds / -math.log(p))


@pytest.mark.parametrize("name", ["stuck in a hold", "stuck 2 nm off in a hold"])
@pytest.mark.parametrize("nm", [1, 0.7])
def test_a_quiet_sensor_stuck_in_a_hold_is_named_once_its_noise_is_declared(nm, name):
    """The case the reading alone cannot tell from a noise-free loop at rest, with the sensor's
    noise declared (sup.sensor_noise = its rms): 'y_meas frozen' exactly when the run of repeats
    reaches the closed form's m (74 samples, 37 ms, for 1 nm on the 2 nm grid; 169, 84.5 ms, for
    0.7 nm), within the issue's 0.2 s, the message naming the declaration; the stage still within
    0.02 um of the set-point. Without the declaration the same runs are only bridged
    (test_a_quiet_sensor_stuck_at_the_set_point_is_bridged)."""
    m = declared_repeats(nm)
    assert m == {1: 74, 0.7: 169}[nm]
    k0 = round(st.STUCK_HOLD_ONSET / H)
    for i in (0, 7, 30, 38):
        r = st.run_stuck(case(name), plant(i, nm), {"sup.sensor_noise": nm * 1e-3}, keep=True)
        assert r["fault"] == "y_meas frozen", (i, r["error"])
        # the held value may repeat the readings just before the onset: those repeats count too
        y_meas = r["trace"][3]
        before = next(j for j in range(k0) if y_meas[k0 - 1 - j] != y_meas[k0])
        assert r["time"] == pytest.approx((m - before) * H, abs=1e-12), (i, r["time"], before)
        assert f"sup.sensor_noise = {nm * 1e-3:g} um rms" in r["error"], r["error"]
        assert f"and {m} repeats in a row with a chance below e^-28" in r["error"], r["error"]
        assert r["excursion"] < 0.02, (i, r["excursion"])


@pytest.mark.parametrize("nm", [1, 5, 20, 200])
@pytest.mark.parametrize("where", ["none, hold", "none, scan"])
def test_a_declared_noise_stops_no_healthy_loop(where, nm):
    """The legitimate hold and scan with each sensor's true noise declared: nothing stops them (the
    family's 600 such runs: none; the chance the declaration allows, e^-28 a run of repeats)."""
    for i in range(STAGES):
        r = st.run_stuck(case(where), plant(i, nm), {"sup.sensor_noise": nm * 1e-3})
        assert r["fault"] == "", (i, r["error"])


def test_a_declaration_above_the_sensor_s_noise_is_said():
    """A 1 nm sensor declared as 10 nm: its healthy reading repeats 12 times in a row (a chance of
    about 0.6^12 per run at rest, where the 10 nm the declaration claims would allow 0.08^12) and
    the loop is stopped, the message saying the declaration may exceed the sensor's noise."""
    assert declared_repeats(10) == 12
    r = st.run_stuck(case("none, hold"), plant(0, 1), {"sup.sensor_noise": 0.01})
    assert r["fault"] == "y_meas frozen"
    assert "or sup.sensor_noise declares more noise than the sensor has" in r["error"], r["error"]
    assert "and 12 repeats in a row" in r["error"]


@pytest.mark.parametrize("nm", [100, 200])
@pytest.mark.parametrize("part", ["raster 10 Hz", "fresh step", "1 Hz tone"])
def test_noisy_sensors_at_start_wait_for_the_reference_without_a_false_error(part, nm):
    """0.2 s at rest (or a tone from t = 0) behind a 100 or 200 nm sensor: no Error, and the delay
    chosen, if any, is the loop's own (2); before issue 44, 70 of the family's 600 such start-ups
    were stopped with "no loop delay found" (docs/robustness.md, "Noisy sensors at start")."""
    for i in range(4):
        r = st.run_start(part, plant(i, nm))
        assert r["error"] == "", (i, r["error"])
        assert r["delay"] in (0, st.START_DELAY), (i, r)


@pytest.mark.parametrize("nm", [0, 1, 20])
def test_quiet_sensors_at_start_choose_the_delay_as_before(nm):
    """Sensors of 0 to 20 nm do not bury the probes: the delay is chosen within 63 ms (the family's
    worst, unchanged by issue 44), and it is the loop's."""
    for i in range(4):
        r = st.run_start("fresh step", plant(i, nm))
        assert r["error"] == "" and r["delay"] == st.START_DELAY and r["time"] <= 0.063, (i, r)


def test_a_dead_200_nm_sensor_is_bridged_where_the_monitor_bound_matters():
    """The stage's day's stages 26 and 38 with a 200 nm sensor, dead (reads 0) in a hold. While the
    delay probes are buried the monitor judges the start-up law's own (the nominal model's)
    prediction, whose errors carry the noise 1.75 times and pass 1 um in 0.4 % of the samples; each
    such sample restarts the outlier test's quiet run. Judged against the fixed 1 um these two
    stages' dead sensors went unbridged (3.8 and 2.4 um off before the verdict at 2.5 ms); with the
    bound at 8 times the measured noise (1.6 um here) the reading is taken for an outlier at once,
    the model's prediction stands in, and "y_meas frozen" comes at 1.5 ms, the stage within the
    noise band (0.4 um, as on the other stages)."""
    for i in (26, 38):
        r = st.run_stuck(case("dead (reads 0) in a hold"), plant(i, 200))
        assert r["fault"] == "y_meas frozen" and r["time"] == pytest.approx(0.0015), (i, r["time"])
        assert r["excursion"] < 0.4, (i, r["excursion"])


def exchange(signal, plant_params, seconds, controller=None, each=None):
    """Run the C core's plant and controller as the native exchange does (y_ref two samples ahead,
    v applied over the next sample) on ``signal`` for ``seconds``: (plant, controller, y_d), y_d
    up to the last reference taken. ``each(c)`` after every sample."""
    import numpy as np
    from harness.binding import core
    n = int(seconds / H)
    y_d = signal.evaluate(np.arange(n + 2) * H)
    p, c = core.Plant(dict(plant_params)), core.Controller(dict(controller or {}))
    v = 0.0
    for k in range(n):
        out = c.step(y_d[k + 2], p.output.y_meas)
        p.step(v)
        v = out.v
        if each is not None:
            each(c)
    return p, c, y_d


def hour(stage):
    """The stage's day's random hour of ``stage`` as a signal on the 0.5 ms grid."""
    from harness.studies import stage_day_table as sd
    from harness.scenarios import profile_signal
    return profile_signal(sd.hour_part(stage).segments, step=H)


@pytest.mark.parametrize("stage,seconds,stopped,held", [(4, 44.48, 44.473, 255), (47, 0.95, 0.888, 359)])
def test_a_quiet_reading_held_after_a_long_move_is_not_taken_for_stuck(stage, seconds, stopped, held):
    """The stage's day's random hours of stages 4 and 47 with the noise-free sensor (0 nm on the
    2 nm grid), their first seconds through the C core in an exchange. After a 30 um move the law
    holds the stage to the nanometre against its creep and hysteresis by pushing q on, 0.2-0.4 um
    of the supervisor's model in 0.1-0.2 s while the reading stays on one grid step; the stuck test
    took that for a stuck y_meas ("no response") at 44.473 s and 0.888 s, after 255 and 461 equal
    readings. It now allows the model
    PIEZO_SUP_STUCK_CREEP_PERMILLE per mille of how far its yhat is from where it has been over the
    last second, and the runs go past those times with no verdict and a run of equal readings as
    long at stage 4 (at stage 47 359: the integral action now acts on a reading a live sensor may
    still show, where it held at once before), the stage still within 2 nm of the hold (the grid's
    step)."""
    same = [0]
    p, c, y_d = exchange(hour(stage), plant(stage, 0), seconds,
                         each=lambda c: same.__setitem__(0, max(same[0], c.raw.sup.y_same)))
    assert seconds > stopped and same[0] + 1 >= held
    assert abs(p.output.y - y_d[-1]) < 0.002


def test_a_noise_free_reading_that_stops_chattering_is_not_taken_for_frozen():
    """The stage-use family's stage 23 (harness.studies.stage_use_table, seed of its family) with the
    noise-free sensor on a 1 Hz triangle scan with 10 s dwells, its first 8 s through the C core
    in an exchange. In the dwell the loop chatters on the 2 nm grid, the reading stepping up and
    down as the stage itself moves (which the model explains), then settles on one step. The noise
    test took that for a sensor whose noise stopped ("y_meas frozen" at 7.53 s, 39 equal readings).
    It now asks that the model's best fit leave of the reading's changes more than
    PIEZO_SUP_FROZEN_FLOOR times the grid's quantisation floor: the run goes on, hundreds of equal
    readings later, with no verdict (968, from 7.5155 s; 989 from 7.505 s before the stale reading's
    bridge, 972 from 7.5135 s while the integral action held at once on 4 equal readings)."""
    from harness.studies import stage_use_table as su
    task = next(t for t in su.family_tasks(sensors=[0], laws=("ours",))
                if t.stage == 23 and t.profile.name == "triangle scan 1 Hz, 10 s dwell")
    n = int(8.0 / H)
    _, c, _ = exchange(task.profile.scenario(task.plant, task.controller).signal, task.plant, 8.0,
                       task.controller)
    assert c.raw.sup.y_same == n - 1 - round(7.5155 / H)     # equal since 7.5155 s
    assert c.raw.fault == 0


def test_the_waiting_detection_stays_finite_on_a_noisy_hour():
    """The stage's day's random hour of stage 6 with a 200 nm sensor, its first 18 s through the C
    core in an exchange. Behind probes buried in the noise the delay candidates do not adapt: when
    they did, as the reference moved, the d = 3 candidate's estimates grew to 1e153 and its score
    overflowed at 17.29 s (sample 34580), and the loop was refused as diverged. Now the run goes
    past it, still waiting with the start-up law (d = 2), every candidate's estimates within 10 of
    the nominal model's."""
    _, c, _ = exchange(hour(6), plant(6, 200), 18.0)
    assert c.raw.detecting and c.raw.d == 2
    assert max(abs(c.raw.det_theta[j]) for j in range(12)) < 10.0


@pytest.mark.parametrize("noise,words", [
    (0.05, "monitor.pred_error_max = 1 um"),
    (0.2, "1.6 um (monitor.pred_error_max = 1 um raised to 8 times y_meas's noise, 0.2 um rms)"),
    (0.3, "2 um (monitor.pred_error_max = 1 um raised for y_meas's noise, 0.3 um rms, to its cap)"),
])
def test_the_monitor_bound_is_said_as_it_is_computed(noise, words):
    """piezo_controller_explain_bound, the one wording of the monitor's bound that the unstable
    loop's Error and the FMU's large-error Warning both use, for a controller at its defaults
    (monitor.pred_error_max = 1 um) once the noise has settled (sample 100): below 1/8 um of noise
    the bound is monitor.pred_error_max, at 0.2 um it is 8 times the noise (1.6 um,
    piezo_controller_monitor_bound), at 0.3 um its cap of 2 um. Before sample 100 the noise counts
    for nothing."""
    from harness.binding import core
    c = core.Controller({})
    c.raw.noise_y2 = noise
    text = core.ffi.new("char[256]")
    lib = core.lib()
    for k, want in ((99, "monitor.pred_error_max = 1 um"), (100, words)):
        c.raw.k = k
        n = lib.piezo_controller_explain_bound(c.raw, text, 256)
        assert core.ffi.string(text).decode() == want and n == len(want)
    assert lib.piezo_controller_monitor_bound(c.raw) == pytest.approx(min(max(8 * noise, 1.0), 2.0), rel=1e-15)


def test_the_controller_fmus_name_a_declared_sensor_stuck_in_a_hold_as_the_core_does(make_fmu, controller,
                                                                                       fmu3_paths):
    """AdaptiveCompoundController (FMI 2.0, and its FMI 3.0 edition) in a loop with the core plant
    (stage 0 of the stage's day, 1 nm sensor), sup.sensor_noise = 1 nm and sup.reaction = 1: the
    sensor sticks in the 5 um hold at 2 s. sup.fault turns 8 (y_meas frozen) at the sample the core
    binding's run_stuck names it (74 repeats: 37 ms after the onset), sup.fault_time says that
    sample's time, and v at every sample equals between the editions bit for bit; the Warning
    names sup.sensor_noise."""
    import fmpy
    from fmpy.fmi3 import FMU3Slave
    params = {"sup.sensor_noise": 0.001, "sup.reaction": 1}
    stuck = case("stuck in a hold")
    want = st.run_stuck(stuck, plant(0, 1), {"sup.sensor_noise": 0.001})
    assert want["fault"] == "y_meas frozen"
    k0 = round(st.STUCK_HOLD_ONSET / H)
    k_fault = k0 + round(want["time"] / H)
    y_d = st._stuck_profile("hold")
    n = k_fault + 40

    def drive(set_inputs, step, read):
        p = core.Plant(plant(0, 1))
        v, held, rows = 0.0, None, []
        for k in range(n):
            meas = p.output.y_meas
            if k >= k0:
                held = meas if held is None else held
                meas = held
            set_inputs(y_d[min(len(y_d) - 1, k + 2)], meas)
            step()
            out_v, fault, fault_time = read()
            p.step(v)
            v = out_v
            rows.append((out_v, fault, fault_time))
        return rows

    fmu = make_fmu(controller, logging_on=True)
    fmu.initialize(params)
    got2 = drive(lambda r, m: fmu.set({"y_ref": r, "y_meas": m}), fmu.step,
                 lambda: (fmu.get("v"), fmu.get("sup.fault"), fmu.get("sup.fault_time")))
    faults = [f for _, f, _ in got2]
    assert faults.index(8) == k_fault and faults[k_fault - 1] == 0
    assert got2[-1][2] == pytest.approx(k_fault * H, abs=1e-12)
    warned = [t for s_, _, t in fmu.messages if "sup.sensor_noise = 0.001 um rms" in t]
    assert warned and "74 repeats in a row" in warned[0], fmu.messages[-3:]

    path = str(fmu3_paths["AdaptiveCompoundController"])
    md = fmpy.read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU3Slave(guid=md.instantiationToken, unzipDirectory=fmpy.extract(path),
                  modelIdentifier="AdaptiveCompoundController", instanceName="declared")
    s.instantiate()
    s.enterInitializationMode(startTime=0.0)
    s.setFloat64([vr["sup.sensor_noise"]], [0.001])
    s.setInt32([vr["sup.reaction"]], [1])
    s.exitInitializationMode()
    t = [0]

    def step3():
        s.doStep(t[0] * H, H)
        t[0] += 1

    got3 = drive(lambda r, m: s.setFloat64([vr["y_ref"], vr["y_meas"]], [r, m]), step3,
                 lambda: (s.getFloat64([vr["v"]])[0], s.getInt32([vr["sup.fault"]])[0],
                          s.getFloat64([vr["sup.fault_time"]])[0]))
    s.terminate()
    s.freeInstance()
    assert got3 == got2
