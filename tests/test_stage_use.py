"""Stage use (docs/stage_use.md): the profile reference of harness/scenarios/__init__.py, its windows
(harness/loop/profiles.py), the closed-loop FMU at a variable communication step, the wired master
playing a profile, and a deterministic slice of the stage-use family of
harness/studies/stage_use_table.py with issue 35's targets.

References: a plain NumPy transcription of the profile's samples (below), the one-sample-step
runs of the closed-loop FMU and of the native runner (bit for bit), and issue 35's targets."""

import math
from pathlib import Path

import numpy as np
import pytest

from harness.loop import profiles
from harness.masters import native
from harness.masters.closed_loop_fmu import (communication_points, simulate_closed_loop_fmu,
                                             simulate_closed_loop_fmu_steps)
from harness.masters.wired import simulate_wired
from harness.scenarios import (ScenarioFileError, get_scenario, load_scenario_file, load_scenarios,
                               parameter_set, profile_signal, stage_use_scenarios)

H = 0.0005
REPO = Path(__file__).resolve().parents[1]

PROFILE = """
[[scenario]]
name = "tour"
kind = "tracking"
plant_set = "mismatch_plant"
reference = { type = "profile", start = 1.5, segments = [
    { hold = 0.01 }, { move = 10.0 }, { hold = 0.0055 },
    { move = -4.0, shape = "scurve", time = 0.004 },
    { to = 2.0, shape = "ramp", time = 0.0025 },
    { scan = "triangle", frequency = 125.0, amplitude = 3.0, time = 0.011 },
    { scan = "sine", frequency = 50.0, amplitude = -2.0, time = 0.007 },
    { hold = 0.003 },
] }
"""


def numpy_profile(start, segments, h, n):
    """The profile's samples written out sample by sample: a hold keeps its position, a step
    jumps at its segment's first sample, a move of m samples passes p + D c(j/m), j = 0..m-1
    (ramp c(s) = s, S-curve the cycloid c(s) = s - sin(2 pi s)/(2 pi)) and leaves p + D (or its
    target) to the next segment, a scan from its position p: p + A tri(f j h) (tri(x) = 1 -
    |1 - 2 frac(x)|) or p + A sin(2 pi f j h), leaving the value at j = m; after the end the
    last position holds."""
    out, p = [], start
    for seg in segments:
        if "hold" in seg:
            m = round(seg["hold"] / h)
            out += [p] * m
        elif "move" in seg or "to" in seg:
            target = seg["to"] if "to" in seg else p + seg["move"]
            shape = seg.get("shape", "step")
            m = round(seg.get("time", 0.0) / h)
            for j in range(m):
                s = j / m
                c = s if shape == "ramp" else s - math.sin(2 * math.pi * s) / (2 * math.pi)
                out.append(p + (target - p) * c)
            p = target
        else:
            f, a, m = seg["frequency"], seg["amplitude"], round(seg["time"] / h)

            def value(j):
                x = f * j * h
                if seg["scan"] == "sine":
                    return p + a * math.sin(2 * math.pi * x)
                return p + a * (1 - abs(1 - 2 * (x - math.floor(x))))
            out += [value(j) for j in range(m)]
            p = value(m)
    return np.array(out + [p] * (n - len(out)))


def _tour(tmp_path):
    f = tmp_path / "tour.toml"
    f.write_text(PROFILE)
    return load_scenarios([f])["tour"]


def test_profile_samples_equal_a_numpy_transcription(tmp_path):
    sc = _tour(tmp_path)
    segs = [{"hold": 0.01}, {"move": 10.0}, {"hold": 0.0055},
            {"move": -4.0, "shape": "scurve", "time": 0.004}, {"to": 2.0, "shape": "ramp", "time": 0.0025},
            {"scan": "triangle", "frequency": 125.0, "amplitude": 3.0, "time": 0.011},
            {"scan": "sine", "frequency": 50.0, "amplitude": -2.0, "time": 0.007}, {"hold": 0.003}]
    n = sc.n_samples + 6
    want = numpy_profile(1.5, segs, H, n)
    # the length is the profile's: 86 samples (0.043 s); duration and window follow it
    assert (sc.n_samples, sc.duration, sc.metric_window) == (86, 0.043, (0.0, 0.043))
    got = sc.signal.evaluate(np.arange(n) * H)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    # the landmarks: 1.5 held, the step to 11.5 at sample 20, S-curve to 7.5, ramp to 2, scan
    assert got[19] == 1.5 and got[20] == 11.5 and got[31] == 11.5 and got[39] == 7.5
    assert got[44] == 2.0 and got[52] == pytest.approx(5.0, abs=1e-12)     # triangle top at 4 ms
    assert [s.kind for s in sc.signal.segments] == ["hold", "move", "hold", "move", "move", "scan",
                                                     "scan", "hold"]
    assert [(s.first, s.samples) for s in sc.signal.segments] == [
        (0, 20), (20, 0), (20, 11), (31, 8), (39, 5), (44, 22), (66, 14), (80, 6)]


def test_profile_signal_is_the_file_s_profile(tmp_path):
    sc = _tour(tmp_path)
    again = profile_signal([{"hold": 0.01}, {"move": 10.0}], start=1.5, step=H)
    np.testing.assert_array_equal(again.evaluate(np.arange(30) * H), sc.signal.evaluate(np.arange(30) * H))


@pytest.mark.parametrize("reference, field, needle", [
    ('{ type = "profile", segments = [] }', "reference.segments", "non-empty list"),
    ('{ type = "profile", segments = [{ hold = 0.1, move = 1.0 }] }', "reference.segments[1]",
     "exactly one of 'hold', 'move', 'to', 'scan'"),
    ('{ type = "profile", segments = [{ hold = 0.1 }, { move = 1.0, time = 0.1 }] }',
     "reference.segments[2].time", "a step takes no time"),
    ('{ type = "profile", segments = [{ hold = 0.1 }, { move = 1.0, shape = "scurve" }] }',
     "reference.segments[2].time", "missing (required for shape = \"scurve\")"),
    ('{ type = "profile", segments = [{ hold = 0.1 }, { move = 1.0, shape = "jerk", time = 0.1 }] }',
     "reference.segments[2].shape", "must be one of 'step', 'ramp', 'scurve'"),
    ('{ type = "profile", segments = [{ hold = 0.10001 }] }', "reference.segments[1].hold",
     "not a whole number of samples of step_size 0.0005 s"),
    ('{ type = "profile", segments = [{ hold = 0.1 }, { scan = "triangle", frequency = 1000.0, '
     'amplitude = 1.0, time = 0.1 }] }', "reference.segments[2].frequency", "Nyquist frequency 1000 Hz"),
    ('{ type = "profile", segments = [{ scan = "triangle", frequency = 10.0, time = 0.1 }] }',
     "reference.segments[1].amplitude", "missing (required for a scan)"),
    ('{ type = "profile", segments = [{ scan = "square", frequency = 10.0, amplitude = 1.0, time = 0.1 }] }',
     "reference.segments[1].scan", "must be one of 'triangle', 'sine'"),
    ('{ type = "profile", segments = [{ hold = -0.1 }] }', "reference.segments[1].hold", "must be > 0"),
    ('{ type = "profile", segments = [{ hold = 0.1, speed = 3 }] }', "reference.segments[1]",
     "unknown key(s) 'speed'"),
    ('{ type = "profile", segments = [{ move = 1.0 }] }', "reference.segments", "lasts no time"),
    ('{ type = "profile", start = "zero", segments = [{ hold = 0.1 }] }', "reference.start",
     "must be a finite number"),
])
def test_a_bad_profile_is_refused_naming_file_scenario_and_field(tmp_path, reference, field, needle):
    f = tmp_path / "bad.toml"
    f.write_text(f'[[scenario]]\nname = "p"\nkind = "tracking"\nreference = {reference}\n')
    with pytest.raises(ScenarioFileError) as err:
        load_scenario_file(f)
    text = str(err.value)
    assert text.startswith(f"{f}: scenario 'p': field '{field}': "), text
    assert needle in text, text


def test_a_profile_is_a_tracking_reference_and_its_duration_may_not_cut_it(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('[[scenario]]\nname = "v"\nkind = "validation"\n'
                 'input = { type = "profile", segments = [{ hold = 0.1 }] }\n')
    with pytest.raises(ScenarioFileError, match=r"scenario 'v': field 'input.type': a profile is a "
                                                r"tracking reference"):
        load_scenario_file(f)
    f.write_text('[[scenario]]\nname = "p"\nkind = "tracking"\nduration = 0.05\n'
                 'reference = { type = "profile", segments = [{ hold = 0.1 }] }\n')
    with pytest.raises(ScenarioFileError, match=r"field 'duration': duration 0.05 s would cut the "
                                                r"profile, which lasts 0.1 s"):
        load_scenario_file(f)
    # longer than the profile: the last position holds
    f.write_text('[[scenario]]\nname = "p"\nkind = "tracking"\nduration = 0.2\n'
                 'reference = { type = "profile", segments = [{ hold = 0.1 }, { move = 2.0 }, { hold = 0.05 }] }\n')
    sc = load_scenario_file(f)["p"]
    assert sc.n_samples == 400 and sc.signal.evaluate([0.19])[0] == 2.0


def test_profile_windows_come_from_the_profile():
    # hold 1 s, a step of +10 at sample 2000, hold 2 s, an S-curve over samples 6000..6099, hold
    # 1 s, a 2 s scan from 8100, a 2 s dwell, a 2 s scan from 16100, hold 0.7 s: 21500 samples
    frame = {"scan": "triangle", "frequency": 10.0, "amplitude": 2.0, "time": 2.0}
    sig = profile_signal([{"hold": 1.0}, {"move": 10.0}, {"hold": 2.0},
                          {"move": 5.0, "shape": "scurve", "time": 0.05}, {"hold": 1.0},
                          frame, {"hold": 2.0}, frame, {"hold": 0.7}], step=H)
    n = sig.samples
    assert n == 21500
    # a move's window: its first sample to 0.5 s after its last
    assert profiles.move_windows(sig, n, H) == [(1, 2000, 3000), (3, 6000, 7100)]
    # a hold's: 0.5 s after the motion before it (the run's start) to the next motion (the end)
    assert profiles.hold_windows(sig, n, H) == [(1000, 2000, 0.0), (3000, 6000, 10.0),
                                                (7100, 8100, 15.0), (13100, 16100, 15.0),
                                                (21100, 21500, 15.0)]
    # the frame after the dwell, and the last second of the frame before it
    assert profiles.scan_pairs(sig, n, H) == [(7, (16100, 20100), (10100, 12100))]
    # errors read over whichever rows a run recorded (every other sample here)
    k = np.arange(0, n, 2)
    y_d = sig.evaluate(k * H)
    y = y_d.copy()
    y[k == 2500] += 0.3          # in the first move's window
    y[k == 4000] -= 0.02         # in the second hold
    y[k == 18000] += 0.05        # in the frame after the dwell
    y[k == 11000] += 0.01        # in the last second before the dwell
    y[k == 8500] += 0.5          # in the first frame's first second: no window reads it
    assert [m.worst for m in profiles.move_errors(sig, k * H, y_d, y, H)] == [pytest.approx(0.3), 0.0]
    assert [h.worst for h in profiles.hold_errors(sig, k * H, y_d, y, H)] == [
        0.0, pytest.approx(0.02), 0.0, 0.0, 0.0]
    (scan,) = profiles.scan_errors(sig, k * H, y_d, y, H)
    assert (scan.worst, scan.steady) == (pytest.approx(0.05), pytest.approx(0.01))


def test_communication_points_hold_only_where_the_input_holds():
    sig = profile_signal([{"hold": 1.0}, {"move": 1.0}, {"hold": 0.7},
                          {"move": 1.0, "shape": "ramp", "time": 0.01}, {"hold": 1.0}], step=H)
    n = sig.samples
    y_d = sig.evaluate(np.arange(n + 2) * H)
    y_ref = y_d[2:]
    pts = communication_points(y_d[:n], y_ref, H, 2, hold_step=0.01, settle=0.5)
    steps = np.diff(pts)
    assert pts[0] == 0 and pts[-1] == n - 1 and steps.max() == 20
    # one sample per step over the first 0.5 s, and from 3 samples before y_d moves (the step at
    # 2000; the ramp from 3400 passes 3401 .. 3420) to 0.5 s after its last change
    for a, b in ((0, 1000), (1997, 3000), (3398, 4420)):
        assert set(range(a, b)) <= set(pts.tolist())
    # a long step never spans two values of the input, even where the motion's margin does not
    # cover it (told a lead of 0 for an input 2 samples ahead, and no settle time)
    for lead, settle in ((2, 0.5), (0, 0.0)):
        pts_ = communication_points(y_d[:n], y_ref, H, lead, hold_step=0.01, settle=settle)
        for a, b in zip(pts_[:-1], pts_[1:]):
            assert np.all(y_ref[a:b] == y_ref[a]), (lead, settle, a, b)
    # 10 ms steps in the holds: 0.5 s to 1 s, 1.5 s to 1.7 s, 2.21 s to the end
    assert np.sum((pts >= 1000) & (pts < 1997)) <= 51 and np.sum(pts >= 4420) <= 51


def _short_profile(tmp_path):
    f = tmp_path / "short.toml"
    f.write_text("""
[[scenario]]
name = "short"
kind = "tracking"
plant_set = "mismatch_plant"
plant = { "sensor.noise_rms" = 0.005 }
reference = { type = "profile", segments = [
    { hold = 0.7 }, { move = 10.0 }, { hold = 1.2 },
    { move = -6.0, shape = "scurve", time = 0.02 }, { hold = 0.9 },
    { scan = "triangle", frequency = 20.0, amplitude = 4.0, time = 0.3 }, { hold = 0.8 },
] }
""")
    return load_scenarios([f]), "short"


@pytest.mark.parametrize("law", ["ours", "paper"])
def test_closed_loop_fmu_at_a_variable_step_equals_one_sample_steps_bit_for_bit(tmp_path, law):
    reg, name = _short_profile(tmp_path)
    ctrl = parameter_set("paper_law") if law == "paper" else None
    whole = simulate_closed_loop_fmu(name, registry=reg, controller_params=ctrl)
    log = []
    steps = simulate_closed_loop_fmu_steps(name, registry=reg, controller_params=ctrl, log=log)
    k = profiles.sample_index(steps["time"], H)
    assert steps.size < 0.7 * whole.size and np.diff(k).max() == 20     # long steps did run
    for f in whole.dtype.names:
        np.testing.assert_array_equal(steps[f], whole[f][k], err_msg=f)
    # the FMI 3.0 edition gives the same rows
    fmi3 = simulate_closed_loop_fmu_steps(name, registry=reg, controller_params=ctrl, fmi_version=3)
    for f in steps.dtype.names:
        np.testing.assert_array_equal(fmi3[f], steps[f], err_msg=f)
    # and the native runner's samples are the same loop
    nat = native.simulate_closed_loop_native(name, registry=reg, controller_params=ctrl)
    for f in whole.dtype.names:
        np.testing.assert_array_equal(nat[f], whole[f], err_msg=f)
    assert set(np.unique(steps["adapting"])) <= {0.0, 1.0}
    if law == "ours":
        # the robust law adapts only while the reference excites the loop (its change 2 samples
        # ahead, for rls.excitation_time = 50 ms after) and in the start-up, where it chooses the
        # loop delay (one update at 12.5 ms here); it measures the noise
        moving = k < 100
        for _, seg in profiles.motions(get_scenario(name, reg).signal):
            moving |= (k >= seg.first - 2) & (k < max(seg.stop, seg.first + 1) + 102)
        assert steps["adapting"][~moving].sum() == 0 and steps["adapting"][moving].sum() > 0
        assert 0.004 < steps["noise"][-1] < 0.008       # 5 nm rms of noise on the 2 nm grid


def test_wired_master_plays_a_profile_as_reference_signal_would(tmp_path):
    reg, name = _short_profile(tmp_path)
    exchange = simulate_wired(name, "exchange", registry=reg, duration=1.5)
    nat = native.simulate_closed_loop_native(name, registry=reg, duration=1.5)
    for f in ("y_d", "y", "y_meas", "v", "q", "pred_error", "saturated"):
        np.testing.assert_array_equal(exchange.samples[f], nat[f], err_msg=f)
    gs = simulate_wired(name, ("plant", "controller", "reference"), registry=reg, duration=1.5)
    assert gs.error == "" and gs.samples["loop_delay"][-1] == 1          # true Gauss-Seidel: d = 1
    move = slice(1400, 2400)
    assert np.abs(gs.samples["y_d"] - gs.samples["y"])[move].max() < 2.0


def test_report_stage_use_reproduces_issue_35_and_the_robust_law_holds_its_tuning():
    from harness.report.stage_use import run_stage_use
    names = ["stage_step10_hold0.2s", "stage_step10_hold20s", "stage_scan10hz_dwell10s"]
    assert set(names) <= set(stage_use_scenarios())
    runs = {(r.scenario, r.law): r for r in run_stage_use(names, keep_data=False)}
    fresh, held = runs[("stage_step10_hold0.2s", "ours")], runs[("stage_step10_hold20s", "ours")]
    # issue 35's table with the paper's law: 1.70 um after 0.2 s, 11.6 um after 20 s (measured
    # here 1.705 and 11.437: the issue read them from another run of the same loop)
    assert runs[("stage_step10_hold0.2s", "paper")].moves[0].worst == pytest.approx(1.70, abs=0.01)
    assert runs[("stage_step10_hold20s", "paper")].moves[0].worst > 6 * fresh.moves[0].worst
    # the robust law: the same move after 20 s as after 0.2 s (target a: within 1.1x)
    assert held.moves[0].worst <= 1.1 * fresh.moves[0].worst
    assert held.a1_before == pytest.approx(-1.3767, abs=1e-3)         # the estimates held
    scan_ours = runs[("stage_scan10hz_dwell10s", "ours")].scans[0]
    scan_paper = runs[("stage_scan10hz_dwell10s", "paper")].scans[0]
    assert scan_paper.worst > 0.1 and scan_paper.ratio > 20          # issue 35: 135 nm, 26x
    assert scan_ours.worst < 0.015                                   # 8.7 nm measured
    for r in runs.values():
        assert r.worst_hold <= 5 * (0.001 + 0.002)                   # target d, 1 nm sensor
        assert r.supervision_warnings == []


# ---------------------------------------------------------------------------
# a deterministic slice of the family (harness/studies/stage_use_table.py)
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def family_slice():
    from harness.studies import stage_use_table as sut
    plist = [p for p in sut.profiles_of(holds=(0.2, 4.0), scans=(10.0,), tones=(), staircase=False)
             if p.move in ("step +10 um from 0", "S-curve +30 um in 50 ms from 10 um", "")]
    tasks = sut.family_tasks(stages=2, sensors=(1, 20), profile_list=plist, jacobi_stages=1,
                             fmu_stages=1, gs_stages=1, gs_orders=(sut.GS_ORDERS[0],))
    results = sut.run_family(tasks)
    return sut, plist, results, sut.summarize(results, plist)


def test_family_slice_meets_targets_a_b_d_e(family_slice):
    sut, plist, results, summary = family_slice
    # exchange: 2 stages x 2 sensors x 2 laws; Jacobi, the closed-loop FMU, one GS order: stage 0
    assert len(results) == 2 * 2 * 2 * len(plist) + 3 * (2 * 2 * len(plist))
    ours = lambda key: [r for r in summary[key] if r.law == "ours"]      # noqa: E731
    # (a) the move after 4 s, as after 0.2 s: measured 0.918 .. 1.0013 on every master here
    a = ours("a")
    assert len(a) == 2 * 2 + 2 * 2 and max(r.value for r in a) <= 1.1
    assert min(r.value for r in a) >= 0.9
    # (d) holds within 5 (noise + grid) everywhere (0.55 at worst), and (e) no supervision
    # verdict, no Error
    assert max(r.value for r in ours("d")) <= 1.0
    assert summary["e"] == [] and summary["errors"] == []
    # the checking masters give the exchange's rows, bit for bit
    assert summary["equal"] and all(all(flags) for flags in summary["equal"].values())
    # (b) 20 nm: within 1.25x the 1 nm reference + 0.1 um everywhere (0.44 .. 0.78 measured; at
    # 8580b7d's core stage 0 missed it by 5 %); the paper's law up to 671 (stage 1's S-curve
    # after 4 s: 84.9 um)
    b = ours("b")
    assert len(b) == 2 * 2 * 2 + 2 * 2 * 2
    assert max(r.value for r in b if r.stage == 1) <= 0.8
    assert 0.7 <= max(r.value for r in b) <= 0.8
    assert max(r.value for r in summary["b_paper"]) > 600
    # the paper's law misses (a): the flaw of issue 35 (its step after 4 s 2.3 .. 4.8x)
    assert min(r.value for r in summary["a_paper"] if r.profile.startswith("step +10")) > 2.0
    v = sut.verdicts(summary)
    assert v["a"][2] and v["b"][2] and v["d"][2] and v["e"] == (0, 0, True, False)


def test_family_slice_scan_after_a_dwell_is_a_restart_of_the_adaptation(family_slice):
    # target (c) is missed: the 10 Hz frame after a 10 s dwell is 0.97 .. 2.14x the steady one
    # (docs/stage_use.md); the estimates fixed at the nominal model make it 1.0 at a larger
    # steady error: the miss is the restart of the adaptation, not of the loop
    sut, plist, results, summary = family_slice
    c = [r for r in summary["c"] if r.law == "ours" and r.master == sut.MASTER_EXCHANGE]
    assert len(c) == 4 and 2.0 < max(r.value for r in c) < 2.2
    worst = max(c, key=lambda r: r.value)
    task = next(t for t in sut.family_tasks(stages=2, sensors=(worst.sensor_nm,), laws=("ours",),
                                            profile_list=plist)
                if t.stage == worst.stage and t.profile.name == worst.profile)
    fixed = sut._fixed_ratio("c", task)
    ratio, worst_nm = float(fixed.split()[0]), float(fixed.split("(")[1].split()[0])
    assert abs(ratio - 1.0) < 0.05
    scan = results[(worst.stage, worst.sensor_nm, "ours", worst.profile, sut.MASTER_EXCHANGE)].scans[0]
    assert worst_nm > 3 * scan[1] * 1e3


@pytest.mark.parametrize("stage", [1, 7])
def test_a_noise_free_quantised_sensor_in_a_dwell_is_not_taken_for_no_response(stage):
    """Reference: the fault table's verdicts and the supervisor's quantisation floor. Stages 1
    and 7 of the family with the 0 nm sensor (the 2 nm grid only), the robust law, a 10 Hz raster
    frame, a 10 s dwell, a frame: during the dwell the loop's v moves by amounts whose expected
    response (0.11 to 0.17 um over the window) stays within one grid step, so y_meas does not
    change. Without the floor on the response test's unexplained energy both were stopped as
    "no response" (at 3.88 s and 4.09 s, measured); with it they run to the end without an
    Error or a supervision warning, and the frame after the dwell tracks within 15 nm."""
    from harness.studies import stage_use_table as sut
    prof = next(p for p in sut.profiles_of() if p.name == "triangle scan 10 Hz, 10 s dwell")
    task = next(t for t in sut.family_tasks(stages=stage + 1, sensors=(0,), laws=("ours",),
                                            profile_list=[prof], jacobi_stages=0, fmu_stages=0,
                                            gs_stages=0) if t.stage == stage)
    (run,) = sut.run_task(task)
    assert run.error == ""
    assert not [w for w in run.warnings if any(x in w for x in sut._SUPERVISION_WARNINGS)]
    assert len(run.scans) == 1 and run.scans[0][0] < 0.015


def test_a_step_after_a_long_tone_is_not_taken_for_an_outlier():
    """Reference: the move of the family's stage 42 with the 20 nm sensor after 60 s of a 1 Hz,
    10 um tone (docs/stage_use.md). The tone leaves the estimates fitted to one frequency, so the
    10 um step's first answer is micrometres off the model's prediction. Taken for an outlier (a
    glitch), that sample reached neither the law nor the adaptation, v clipped, the delay
    detection restarted and the step erred 61.4 um (measured before the jump rule); with no
    reading taken for an outlier within d + 1 samples of a jump of the law's reference beyond
    monitor.pred_error_max, the adaptation fitted itself back on it and the step erred 7.19 um, as
    before the outlier test existed (a474c92). Since the estimates' guarantees the step (159 times
    the largest change a sample the tone taught them) makes the law fall back to the nominal model
    at its first sample: it errs 0.397 um, one fallback said in a Warning, one delay detection in
    the run, and still no reading taken for an outlier."""
    from harness.studies import stage_use_table as sut
    prof = next(p for p in sut.profiles_of() if p.name == "1 Hz tone for 60 s, then a 10 um step")
    task = next(t for t in sut.family_tasks(stages=43, sensors=(20,), laws=("ours",), profile_list=[prof],
                                            jacobi_stages=0, fmu_stages=0, gs_stages=0) if t.stage == 42)
    (run,) = sut.run_task(task)
    assert run.error == "" and len(run.moves) == 1
    assert run.moves[0] == pytest.approx(0.3973, abs=0.001)
    assert not [w for w in run.warnings if "delay detection restarted" in w]
    assert not [w for w in run.warnings if "an outlier" in w]
    assert len([w for w in run.warnings if "the law fell back to the nominal model at t = 60.499 s" in w]) == 1


def test_a_noise_free_sensor_s_hold_is_corrected_though_its_reading_rarely_changes():
    """Reference: target (d)'s band, 5 (noise rms + 2 nm) = 10 nm for the noise-free sensor on the
    2 nm grid (docs/stage_use.md). The family's stage 23 (its worst), the staircase (2 s on each
    stair), the robust law: on a reading that does not change the stage rests where the integral
    action leaves it. Held at once on a reading unchanged for 4 samples (35371df), the integral
    acted in 18 % of a stair's samples and the worst hold window was 3.12 times the band (31 nm,
    measured on 2acded2's core). Acting while sup.gain_min times the move the supervision's model
    gives the stage since the reading last changed is below one of its steps, every hold window is
    within the band (0.35 to 0.922 of it, measured; 0.917 before the stale reading's bridge)."""
    from harness.studies import stage_use_table as sut
    prof = next(p for p in sut.profiles_of() if p.name == "staircase")
    task = next(t for t in sut.family_tasks(stages=24, sensors=(0,), laws=("ours",), profile_list=[prof],
                                            jacobi_stages=0, fmu_stages=0, gs_stages=0) if t.stage == 23)
    (run,) = sut.run_task(task)
    assert run.error == ""
    band = sut.hold_band(0.0)
    assert band == pytest.approx(0.010, abs=1e-12)
    ratios = [w / band for w in run.holds]
    print(f"\nhold windows / band: {[round(r, 3) for r in ratios]}")
    assert len(ratios) == 6 and max(ratios) <= 1.0
    assert max(ratios) == pytest.approx(0.922, abs=0.002)
