"""A stage's day (harness/studies/stage_day_table.py, docs/stage_day.md): the parts of the day, the admissible
set's check against the core's own, the native runner in chunks, and the slice of the family the
suite runs (the family's fourth stage over 30 raster frames, and a 60 s tone then a step) with its
exact figures."""
import numpy as np
import pytest

from harness.binding import core
from harness.loop import profiles
from harness.studies import stage_day_table as sd
from harness.studies.stage_use_table import draw_stages
from harness.masters.c_core import simulate_closed_loop_core
from harness.scenarios import profile_signal

H = sd.H


def test_random_hour_is_seeded_on_the_grid_and_within_range():
    """Reference: its own definition (harness.studies.stage_day_table.random_hour): the same seed gives the same
    segments, another seed others; every segment's time is a whole number of samples; the profile
    lasts at least the hour and stays within [0, 40] um at every sample; it holds, moves and scans."""
    a, b, c = sd.random_hour(3), sd.random_hour(3), sd.random_hour(4)
    assert a == b and a != c
    sig = profile_signal(a, step=H)
    for seg in a:
        for key in ("hold", "time"):
            if key in seg:
                assert abs(seg[key] / H - round(seg[key] / H)) < 1e-9, seg
    assert sig.samples * H >= sd.HOUR
    y = sig.evaluate(np.arange(sig.samples) * H)
    assert y.min() >= -1e-9 and y.max() <= 40.0 + 1e-9
    kinds = {s.kind for s in sig.segments}
    assert kinds == {"hold", "move", "scan"}


def test_outside_admissible_is_the_cores_verdict():
    """Reference: the core's own check of a restored state (piezo_controller_check refuses estimates
    outside the admissible set). 2000 estimates drawn around the set's boundary (the nominal model
    moved along random directions by up to 1.5 times the distance to a row): the Python check with the
    core's rows gives the core's verdict on every one, both kinds occur."""
    ctrl = core.Controller({})
    C, d = sd.admissible_rows()
    raw = ctrl.raw
    nominal = np.array(list(raw.theta_nominal))
    assert np.array_equal(C, np.array([list(raw.adm_c[i]) for i in range(9)]))
    assert np.array_equal(d, np.array(list(raw.adm_d)))
    rng = np.random.default_rng(5)
    verdicts = []
    for _ in range(2000):
        u = rng.normal(size=4) * np.array([0.05, 0.05, 0.3, 0.3])
        theta = nominal + rng.uniform(0.0, 1.5) * u
        raw.theta = list(theta)
        fault = core.lib().piezo_controller_check(raw)
        text = core.ffi.string(fault).decode() if fault != core.ffi.NULL else ""
        core_outside = "outside the admissible set" in text
        assert core_outside or text == "", text
        mine = bool(sd.outside_admissible(theta[None, :], C, d)[0])
        assert mine == core_outside, theta
        verdicts.append(mine)
    assert 100 < sum(verdicts) < 1900


def test_admissible_rows_follow_a_lower_nominal_zero_as_the_core_does():
    """Reference: the core's rows (raw.adm_c, raw.adm_d). For a nominal model whose zero (0.6) is
    below rls.zero_min (0.75, the default), the set's zero bound is the nominal zero in the core
    and in harness.studies.stage_day_table.admissible_rows alike, bit for bit, and the nominal model is inside."""
    b1 = core.default_controller_params()["tf.b1"]
    params = {"tf.b2": -0.6 * b1}
    raw = core.Controller(params).raw
    C, d = sd.admissible_rows(params)
    assert np.array_equal(C, np.array([list(raw.adm_c[i]) for i in range(9)]))
    assert np.array_equal(d, np.array(list(raw.adm_d)))
    assert C[4, 2] == 0.6 * b1 / b1
    assert not sd.outside_admissible(np.array([list(raw.theta_nominal)]), C, d)[0]


def test_the_native_runner_in_chunks_gives_the_runs_bits():
    """Reference: NativeLoop.run, the whole run at once. The same run in chunks of 1000 samples
    (NativeLoop.run_chunks) hands over the same rows, bit for bit, in order."""
    from harness.loop import prepare_closed_loop
    from harness.masters import native
    part = sd.raster_part(50.0, 0.1, frames=2)
    sc = part.scenario(sd.stage_plant(draw_stages(1, sd.SEED)[0], 0, 1), {})
    setup = prepare_closed_loop(sc)
    loop = native.native_loop()
    whole = loop.run(setup)
    pieces = []
    loop.run_chunks(setup, lambda first, rows: pieces.append((first, rows.copy())), chunk=1000)
    assert [f for f, _ in pieces] == list(range(0, setup.n, 1000))
    joined = np.concatenate([r for _, r in pieces])
    for name in whole.dtype.names:
        assert np.array_equal(whole[name].view(np.uint64), joined[name].view(np.uint64)), name


def _core_run(part, law, stage=3, nm=1):
    st = draw_stages(stage + 1, sd.SEED)[stage]
    sc = part.scenario(sd.stage_plant(st, stage, nm), sd._controller(law))
    rows = simulate_closed_loop_core(sc)
    err = np.abs(rows["y_d"] - rows["y"])
    k = profiles.sample_index(rows["time"], H)
    worst = [float(np.max(err[(k >= a) & (k < b)])) for a, b, _ in sd._segments_of(sc.signal)]
    return rows, worst


def test_the_family_stage_of_issue_43_scans_30_frames_flat_inside_the_set():
    """Reference: the same frames with the estimates fixed at the nominal model, and the issue's
    measurement on main 14744e4 (the family's fourth stage, 1 nm sensor with seed 4, 30 frames of a
    10 Hz, 10 um raster with 0.5 s dwells: worst per frame 88 22 22 61 3409 4993 ... 61870 nm, 52-55
    nm with the estimates fixed). On the C core: every frame after the first within 1.5 times the
    worst of frames 2-11 and within 1.5 times the same frame with the estimates fixed, none above
    1 um, the estimates inside the admissible set at every sample; the figures as measured (the
    first frame 88.3 nm, the second 9.4 nm, the worst after the first 45.5 nm, rising slowly from
    24 nm in the third: from the first frames on the zero of B rests on its bound rls.zero_min =
    0.75; fixed 52.3 to 54.6 nm; issue 44's integral action and offset, held on readings unchanged
    for 4 samples, moved the first frame from 87.4 nm and the worst from 45.1 nm to 45.6; the
    integral acting on such a reading until a live one would have changed moved the second frame
    from 9.1 nm and the worst back to 45.2; the stale reading's bridge the worst to 45.5)."""
    part = sd.raster_part(10.0, 0.5, frames=30)
    rows, ours = _core_run(part, "ours")
    _, fixed = _core_run(part, "fixed")
    ours, fixed = np.array(ours), np.array(fixed)
    print("\nours [nm]:", " ".join(f"{x * 1e3:.0f}" for x in ours))
    print("fixed [nm]:", " ".join(f"{x * 1e3:.0f}" for x in fixed))
    assert np.max(ours[1:]) <= 1.5 * np.max(ours[1:11])
    assert np.all(ours[1:] <= 1.5 * fixed[1:])
    assert np.max(ours) < 1.0
    theta = np.column_stack([rows["a1"], rows["a2"], rows["b1"], rows["b2"]])
    C, d = sd.admissible_rows()
    assert not sd.outside_admissible(theta, C, d).any()
    assert ours[0] * 1e3 == pytest.approx(88.3, abs=0.1)
    assert ours[1] * 1e3 == pytest.approx(9.4, abs=0.1)
    assert np.max(ours[1:]) * 1e3 == pytest.approx(45.5, abs=0.1)
    assert fixed.min() * 1e3 == pytest.approx(52.3, abs=0.1) and fixed.max() * 1e3 == pytest.approx(54.6, abs=0.1)


def test_a_step_after_a_minute_of_a_tone_is_met_by_the_nominal_model():
    """Reference: the fresh step (0.2 s at rest, the same 10 um step) and the issue's measurement
    on main 14744e4 (after 60 s of a 1 Hz, 10 um tone a 10 um step erred 7.15 um on a stage unlike
    the model, against 0.96 um after a 0.2 s hold). On the C core, the family's fourth stage with
    the 1 nm sensor: the step after the tone (which falls back to the nominal model at its first
    sample: test_stage_use.py, test_core_hot_path.py) errs within 1.25 times the fresh step, the
    figures as measured (1.504 um against 1.518 um)."""
    tone, fresh = sd.tone_part(1.0, 60.0), sd.FRESH
    rows, after = _core_run(tone, "ours")
    _, fresh_worst = _core_run(fresh, "ours")
    ratio = after[-1] / fresh_worst[-1]
    print(f"\nstep after the tone {after[-1]:.4f} um, fresh {fresh_worst[-1]:.4f} um: {ratio:.3f}")
    assert ratio <= 1.25
    assert after[-1] == pytest.approx(1.5036, abs=5e-4)
    assert fresh_worst[-1] == pytest.approx(1.5181, abs=5e-4)


def test_a_tone_that_stops_dead_is_no_gain_change_and_a_halved_sensor_still_is():
    """Reference: the stage's day before this rule (the family's stage 10, noise-free sensor: its
    20 Hz tones for 60 and 600 s were stopped at the tone's stop, "response gain changed", the
    response 0.66 times the gain followed over the tone) and the thresholds of piezo_supervisor.h.
    A 20 Hz, 10 um tone for 5 s stops dead at full speed; the sample that stops it carries most of
    the window's evidence, and the stage answers it through its own hysteresis' local slope: 0.668
    times the gain followed (a drop by 1.5, beyond PIEZO_SUP_DROP_PERCENT's 1.3). Evidence one
    sample carries is judged against the gain of such evidence alone, and by
    PIEZO_SUP_DROP_FIRST_PERCENT (1.75) while none was followed: the run ends without an Error.
    The same run with the sensor halved from the tone's stop on (the tone stops at 0 um, and the
    stage rests there 0.5 s: a halved reading of 0 is 0) is stopped within 10 ms of the step that
    follows (its response 0.22 times the model's: "no response", below sup.gain_min = 0.25)."""
    from harness.loop import prepare_closed_loop
    from harness.masters.c_core import REFERENCE_PREVIEW
    part, stop, step = sd.tone_part(20.0, 5.0), int(round(5.0 / H)), int(round(0.5 / H))
    sc = part.scenario(sd.stage_plant(draw_stages(11, sd.SEED)[10], 10, 0), {})
    setup = prepare_closed_loop(sc)

    def run(scale):
        """The exchange's loop on the core (as stage_day's replays): the sample an Error stops, or None."""
        plant, ctrl = core.Plant(setup.plant_params), core.Controller(setup.controller_params)
        out, published = plant.output, ctrl.output
        for k in range(setup.n):
            applied = published[0]
            y = out.y_meas * (scale if k >= stop else 1.0)
            try:
                published = ctrl.step_input(setup.y_ref[k], y, setup.y_preview[k], REFERENCE_PREVIEW if k else 0)
            except core.CoreFaultError as exc:
                return k, exc
            out = plant.step(applied)
        return None, None

    k, exc = run(1.0)
    assert exc is None, (k, exc)
    k, exc = run(0.5)
    print(f"\nhalved from sample {stop}: stopped at {k}, {exc.fault if exc else None}")
    assert exc is not None and exc.fault in ("response gain changed", "no response"), exc
    assert stop + step <= k < stop + step + 20, k


def test_an_estimate_that_rounding_leaves_outside_the_set_stays_on_its_edge():
    """Reference: the same hour with the estimates fixed at the nominal model, and this run before
    the change (main 3e281d5). The stage's day's random hour of stage 49 with the noise-free sensor,
    on the native runner's exchange (the FMUs' binaries). At 3192.476 s the estimates sat on the
    corner of two rows of the admissible set (a2 >= 0 and B's zero at rls.zero_min = 0.75); after
    the sweeps the radial step towards the nominal model put them back on it, but rounding left them
    1e-17 outside (s rounded to 1), and the projection then took the nominal model itself, keeping
    the covariance that the boundary's data had wound up (trace 100, against rls.p0_loop I = 0.01 I
    after a fallback). Fitting the next corner of the scan with that covariance took b1 to 0.25 of
    the nominal in 25 ms, and the scan (segment 443) erred 12.68 um where the fixed estimates err
    6.1 nm. The radial step is now shrunk (by 1e-12 .. 1e-3 of itself) until it ends inside: the
    estimates stay on the edge, and that scan errs 148 nm (the figure as measured; 148 nm too while
    the integral action held at once on a reading unchanged for 4 samples, 146 nm with the integral's
    gate before the stale reading's bridge); no segment of
    the hour errs beyond 6.5 um (its largest move, which the fixed estimates err 6.5 um too), and the
    estimates stay inside the set at every sample."""
    task = [t for t in sd.family_tasks(stages=50, sensors=[0], laws=["ours"], parts=[sd.hour_part(49)],
                                       fmu_stages=0) if t.stage == 49][0]
    m, _ = sd.run_part(task)
    assert m.error == ""
    worst = np.array(m.worst)
    print(f"\nsegment 443: {worst[442] * 1e3:.1f} nm; the hour's worst {worst.max():.3f} um")
    assert m.kinds[442] == "scan"
    assert worst[442] < 0.2
    assert worst[442] == pytest.approx(0.1480, abs=1e-4)
    assert worst.max() < 6.5
    assert m.outside == 0


def test_saved_results_load_as_they_were(tmp_path):
    """Reference: the runs themselves (a round trip through JSON): the stage day's and the stage-use
    table's results, saved with --save and read with --load, are equal to what was saved, keys
    (stage, sensor, law, part or profile, master) and metrics alike (the scans' pairs as tuples)."""
    from harness.studies import stage_use_table as su
    day = {(3, 1.0, "ours", "tone 1 Hz, 60 s", sd.MASTER_EXCHANGE):
           sd.PartMetrics(sd.MASTER_EXCHANGE, worst=[0.5, 0.25], kinds=["tone", "step"], holds=[0.004],
                          outside=0, fallbacks=1, warnings=["fallback at t = 60.5 s"], samples=120000,
                          seconds=1.5)}
    use = {(0, 20.0, "ours", "raster", "native"):
           su.RunMetrics("native", moves=[0.125], holds=[0.01], scans=[(0.5, 0.25), (0.375, 0.125)],
                         error="monitor: stopped", equal=True, seconds=2.0)}
    sd.save_results(day, tmp_path / "day.json")
    su.save_results(use, tmp_path / "use.json")
    assert sd.load_results(tmp_path / "day.json") == day
    assert su.load_results(tmp_path / "use.json") == use
