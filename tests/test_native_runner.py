"""The native closed-loop master (fmu_src/runner/, harness.masters.native).

Reference: the fmpy master (harness.masters.fmpy.simulate_closed_loop) on the same FMU files, whose
schedule the runner implements; results must be equal bit for bit, errors must carry the
same messages. The runner must never end the process on an FMU error.
"""
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness import fmu, masters
from conftest import NEAR_LIMITS, NEAR_LIMITS_NAME, REPO, error_lines
from harness.loop import prepare_closed_loop
from harness.masters import fmpy as fmpy_master, native

BITS = np.uint64


def bits(run):
    return run.view(np.float64).view(BITS)


CASES = [
    ("mismatch_1_5_10hz", {}),
    ("mismatch_20hz", {"master": "jacobi"}),
    ("mismatch_5hz", {"step_order": "controller-first"}),
    ("mismatch_1hz", {"controller_params": {"mv.feedthrough": True, "mv.delay": 0}}),
    ("mismatch_10hz", {"controller_params": {"sat.v_max": 15.0}}),
    ("track_1hz", {"plant_params": {"creep.exact": True}, "controller_params": {"creep.exact": True},
                   "duration": 1.0}),
    ("mismatch_1_10_20hz", {"adaptation": False, "preview": False, "master": "jacobi",
                            "step_order": "controller-first"}),
]


@pytest.mark.parametrize("scenario,kwargs", CASES,
                         ids=["gs", "jacobi", "controller-first", "feedthrough-d1", "clipping",
                              "exact-creep", "no-adaptation-no-preview"])
def test_native_equals_fmpy_bitwise(scenario, kwargs):
    """Reference: the fmpy master, same FMUs and options. Every field of every row equal
    bit for bit (Gauss-Seidel both step orders, Jacobi, direct feedthrough with d = 1,
    clipping with the controller's fmi2Warning, exact creep, adaptation and preview off)."""
    want = fmpy_master.simulate_closed_loop(scenario, **kwargs)
    got = native.simulate_closed_loop_native(scenario, **kwargs)
    assert got.dtype == want.dtype and got.shape == want.shape
    assert np.array_equal(bits(got), bits(want))
    if "sat.v_max" in kwargs.get("controller_params", {}):
        assert got["saturated"].sum() > 100            # the warning path ran


def test_clipping_warning_completes_the_step_and_is_logged():
    """Reference: the controller FMU's contract (first clipped voltage: fmi2DoStep returns
    fmi2Warning and logs why, the step is done). The native run goes on to the end, the
    log holds the warning and the terminate summary, the voltage stays within the limit."""
    loop = native.NativeLoop()
    setup = prepare_closed_loop("mismatch_10hz", controller_params={"sat.v_max": 15.0}, duration=1.0)
    run = loop.run(setup)
    assert run.shape == (2000,)
    assert run["v"].max() == 15.0
    log = loop.log(native.CONTROLLER)
    assert any(line.startswith("[Warning]") and "clipped" in line for line in log), log
    assert any(line.startswith("[Warning]") and "fmi2Terminate" in line for line in log), log
    loop.close()


@pytest.mark.parametrize("supervision", [True, False])
def test_divergence_is_loop_diverged_error_with_the_fmpy_message(supervision):
    """Reference: the fmpy master's exception. A controller that assumes d = 1 in the
    default d = 2 loop is stopped by its supervision (LoopFaultError: the loop delay is 2), or
    with the supervision off by its monitor (LoopDivergedError): the same class and message
    (sample, time and the FMU's explanation) as the fmpy master's."""
    kwargs = {"controller_params": {"mv.delay": 0, "sup.enabled": supervision}}
    error, fragment = (fmu.LoopFaultError, "Set mv.delay = 1") if supervision else \
        (fmu.LoopDivergedError, "unstable")
    with pytest.raises(fmu.LoopDivergedError) as want:
        fmpy_master.simulate_closed_loop("mismatch_5hz", **kwargs)
    with pytest.raises(fmu.LoopDivergedError) as got:
        native.simulate_closed_loop_native("mismatch_5hz", **kwargs)
    assert type(got.value) is type(want.value) is error
    assert str(got.value) == str(want.value)
    assert fragment in str(got.value) and "sample" in str(got.value)


def test_nonfinite_reference_is_an_fmu_error_and_the_loop_recovers():
    """Reference: the fmpy master. A NaN in y_ref is refused by fmi2SetReal: FMUError (not a
    divergence) naming the sample, as fmpy's; the same loop then runs a regular scenario
    (fmi2Reset out of the Error state) equal to a fresh fmpy run."""
    setup = prepare_closed_loop("track_5hz", duration=0.2)
    bad = setup.__class__(**{**setup.__dict__, "y_ref": setup.y_ref[:150] + [float("nan")]
                             + setup.y_ref[151:]})
    loop = native.NativeLoop()
    with pytest.raises(fmu.FMUError) as info:
        loop.run(bad)
    assert not isinstance(info.value, fmu.LoopDivergedError)
    assert "sample 150" in str(info.value) and "fmi2SetReal" in str(info.value)
    assert "y_ref" in str(info.value)
    after = loop.run(prepare_closed_loop("mismatch_5hz", duration=0.5))
    want = fmpy_master.simulate_closed_loop("mismatch_5hz", duration=0.5)
    assert np.array_equal(bits(after), bits(want))
    loop.close()


def test_refused_and_unknown_parameters():
    """Reference: the fmpy master's errors: an out-of-range value is refused at
    initialization with the FMU's message naming it (FMUInitializationError); an unknown
    name raises UnknownParameterError with the suggestion; the loop is usable afterwards."""
    loop = native.NativeLoop()
    with pytest.raises(fmu.FMUInitializationError, match=r"creep.alpha = 5 is out of range"):
        loop.run(prepare_closed_loop("track_1hz", plant_params={"creep.alpha": 5.0}, duration=0.01))
    with pytest.raises(fmu.UnknownParameterError, match="did you mean rls.forgetting"):
        loop.run(prepare_closed_loop("track_1hz", controller_params={"rls.forgeting": 0.9},
                                     duration=0.01))
    ok = loop.run(prepare_closed_loop("track_1hz", duration=0.05))
    assert ok.shape == (100,) and np.all(np.isfinite(ok["y"]))
    loop.close()


def test_instances_reused_through_reset_give_fresh_results():
    """Reference: fresh loops. One loop runs A, B, A (other parameters, other lengths in
    between): the second A equals the first and a fresh loop's A bit for bit, and the FMU
    memory held by the runners returns to its level when the loops are closed."""
    before = native.live_bytes()
    a = prepare_closed_loop("mismatch_1_5_10hz", duration=0.6)
    b = prepare_closed_loop("mismatch_20hz", plant_params={"sensor.seed": 9}, duration=0.3,
                            master="jacobi")
    loop = native.NativeLoop()
    assert loop.instance_bytes(native.PLANT) > 0 and loop.instance_bytes(native.CONTROLLER) > 0
    first = loop.run(a)
    loop.run(b)
    again = loop.run(a)
    fresh = native.NativeLoop()
    other = fresh.run(a)
    assert np.array_equal(bits(first), bits(again)) and np.array_equal(bits(first), bits(other))
    assert native.live_bytes() > before
    loop.close()
    fresh.close()
    assert native.live_bytes() == before


def test_runner_refuses_bad_binaries_without_crashing():
    """A library without the fmi2 API, a missing file and a wrong GUID: piezo_runner_new
    returns NULL with the reason (the FMU's own message for the GUID), the process lives."""
    ffi, lib = native._binding()
    info = fmu.load(fmu.fmu_path(fmu.PLANT_MODEL))
    real = str(Path(info.unzipdir, "binaries", "linux64", "PiezoStage.so"))

    def new(library, guid):
        keep = [ffi.new("char[]", s.encode()) for s in (library, guid, "x")]
        f = ffi.new("piezo_runner_fmu *")
        f.library, f.guid, f.instance_name = keep
        refs = ffi.new("piezo_runner_refs *")
        err = ffi.new("char[1024]")
        r = lib.piezo_runner_new(f, f, refs, err, 1024)
        text = ffi.string(err).decode()
        if r != ffi.NULL:
            lib.piezo_runner_free(r)
        return r == ffi.NULL, text

    core_lib = str(REPO / "build" / "libpiezo_core.so")
    assert new(core_lib, info.md.guid) == (True, "the FMU binary does not export fmi2Instantiate")
    refused, text = new("/nonexistent/PiezoStage.so", info.md.guid)
    assert refused and text.startswith("cannot load /nonexistent/PiezoStage.so")
    refused, text = new(real, "{00000000-0000-0000-0000-000000000000}")
    assert refused and "fmi2Instantiate" in text and "wrong GUID" in text


def test_missing_runner_library_says_how_to_build(tmp_path):
    """A fresh process with PIEZO_RUNNER_LIB pointing nowhere: FileNotFoundError with the
    build command, and the command line exits 2 with one line."""
    env = {**os.environ, "PIEZO_RUNNER_LIB": str(tmp_path / "nope.so"), "PYTHONPATH": str(REPO)}
    code = ("import harness.masters.native as n\n"
            "try:\n    n.simulate_closed_loop_native('track_1hz', duration=0.01)\n"
            "except FileNotFoundError as e:\n    print('FNF', e)\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         cwd=tmp_path, timeout=120)
    assert out.stdout.startswith("FNF native runner library not found"), out.stderr
    assert "cmake -S . -B build && cmake --build build" in out.stdout
    cli = subprocess.run([sys.executable, "-m", "harness", "run", "track_1hz", "--backend", "native",
                          "--no-plots", "--out", str(tmp_path / "o")], env=env, capture_output=True,
                         text=True, cwd=tmp_path, timeout=120)
    assert cli.returncode == 2
    lines = error_lines(cli.stderr)
    assert len(lines) == 1 and "native runner library not found" in lines[0], cli.stderr


def test_auto_backend_uses_native_for_long_runs(monkeypatch):
    """simulate_closed_loop_auto: runs of LONG_RUN_SAMPLES and more go to the native master,
    shorter ones to fmpy (spies on both); the results equal the fmpy master's either way."""
    calls = []
    real_native, real_fmpy = native.simulate_closed_loop_native, fmpy_master.simulate_closed_loop
    monkeypatch.setattr(native, "simulate_closed_loop_native",
                        lambda *a, **k: calls.append("native") or real_native(*a, **k))
    monkeypatch.setattr(fmpy_master, "simulate_closed_loop",
                        lambda *a, **k: calls.append("fmpy") or real_fmpy(*a, **k))
    long_s = masters.LONG_RUN_SAMPLES * 0.0005
    long_run = masters.simulate_closed_loop_auto("mismatch_5hz", duration=long_s)
    short_run = masters.simulate_closed_loop_auto("mismatch_5hz", duration=1.0)
    assert calls == ["native", "fmpy"]
    assert long_run.shape == (masters.LONG_RUN_SAMPLES,)
    assert np.array_equal(bits(long_run[:2000]), bits(short_run[:2000]))


def test_cli_native_backend_failing_run_exits_3(tmp_path):
    """The command line with --backend native: a run the controller stops exits 3 with one
    line saying why (the controller's supervision: the loop's delay), as with fmpy."""
    f = tmp_path / "bad.toml"
    f.write_text('[[scenario]]\nname = "bad"\nextends = "mismatch_5hz"\n'
                 'controller = { "mv.delay" = 0 }\n')
    proc = subprocess.run([sys.executable, "-m", "harness", "run", "bad", "--scenario-file", str(f),
                           "--backend", "native", "--no-plots", "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, cwd=REPO, timeout=300)
    assert proc.returncode == 3, proc.stderr
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and "supervision stopped the loop" in lines[0], proc.stderr
    assert "Set mv.delay = 1 (d = 2)" in lines[0], proc.stderr


def test_pairwise_sum_is_numpys():
    """Reference: np.sum, NumPy's pairwise summation. piezo_runner_pairwise_sum (the sums of a
    batch's checks and metrics) gives the same bits for every length up to 300 and across
    the recursion's splits (8192 and beyond, the 58000 of a 30 s window), on terms spread
    over 24 decades; summing in order gives other bits for some of them (the test tells the
    two apart)."""
    ffi, lib = native._binding()
    rng = np.random.default_rng(4)
    in_order_differs = 0
    for n in [*range(0, 300), 1000, 4000, 8191, 8192, 8193, 58000]:
        x = rng.standard_normal(n) ** 2 * 10.0 ** rng.uniform(-12, 12, n)
        got = lib.piezo_runner_pairwise_sum(ffi.from_buffer("double[]", x), n)
        assert np.float64(got).view(BITS) == np.sum(x).view(BITS), n
        in_order = 0.0
        for v in x.tolist():
            in_order += v
        in_order_differs += in_order != got
    assert in_order_differs > 10


def _batch_parameters(n):
    """n plant parameter sets of the near-limits scenario wide enough that runs clip, are
    stopped or are refused (the spreads of the sweep test), as per-run columns and one by one."""
    from harness.scenarios import load_scenarios
    from harness.sweep import parse_spread, plant_start_values
    from harness.sweep.spreads import apply_spreads, draw_columns, run_deltas
    base_all = plant_start_values()
    reals = [k for k, v in base_all.items() if isinstance(v, float)]
    spreads = [parse_spread(s, reals) for s in ("tf.poles=0.01", "pi.weights=60%", "tf.zero=0.01",
                                                "sensor.seed")]
    sc = load_scenarios([NEAR_LIMITS])[NEAR_LIMITS_NAME]
    base = {**base_all, **dict(sc.plant), "h": sc.step_size}
    columns = draw_columns(base, spreads, 11, range(n))
    return sc, base, columns, [apply_spreads(base, spreads, run_deltas(spreads, 11, i)) for i in range(n)]


def test_batch_equals_runs_one_by_one():
    """Reference: each parameter set run on its own by NativeLoop.run (itself equal to the
    fmpy master bit for bit) and NumPy on its rows. One piezo_runner_batch over 24 sets:
    every run that completes has the status of the run on its own and the sums np.sum takes
    of (y_d - y)^2 and y^2 over the metric window, bit for bit, with its clipped samples
    there and whether y, y_meas and v stayed finite; every run whose FMI calls fail on its
    own fails in the batch too, at the same sample. The batch is the same with fresh
    instances and with used ones, and a run after it equals a fresh loop's."""
    from harness.loop.metrics import window_mask
    sc, base, columns, sets = _batch_parameters(24)
    setup = prepare_closed_loop(sc, plant_params=base)
    win = window_mask(setup.time, sc.metric_window, sc.step_size)
    w = np.flatnonzero(win)
    loop, alone = native.NativeLoop(), native.NativeLoop()
    out = loop.run_batch(setup, columns, (w[0], w[-1] + 1))
    again = loop.run_batch(setup, columns, (w[0], w[-1] + 1))
    for key in out:
        assert np.array_equal(np.asarray(out[key]).view(np.uint8), np.asarray(again[key]).view(np.uint8)) \
            or key == "seconds", key
    kinds = set()
    for i, params in enumerate(sets):
        try:
            data = alone.run(prepare_closed_loop(sc, plant_params=params))
        except fmu.FMUInitializationError:
            kinds.add("refused")
            assert out["status"][i] > 1 and out["samples"][i] == 0, i
            continue
        except fmu.FMUError as exc:
            kinds.add("stopped")
            assert out["status"][i] > 1 and out["failed_call"][i] == 4, i       # fmi2DoStep
            stopped_at = int(re.search(r"\(sample (\d+)\) failed", str(exc)).group(1))
            assert out["samples"][i] == stopped_at < setup.n, (i, out["samples"][i], str(exc))
            continue
        assert out["status"][i] <= 1 and out["samples"][i] == setup.n, i
        err = data["y_d"][win] - data["y"][win]
        assert out["sum_error2"][i].view(BITS) == np.sum(err * err).view(BITS), i
        assert out["sum_y2"][i].view(BITS) == np.sum(data["y"][win] ** 2).view(BITS), i
        assert out["saturated"][i] == np.count_nonzero(data["saturated"][win]), i
        assert out["finite"][i] == all(np.isfinite(data[f]).all() for f in ("y", "y_meas", "v")), i
        kinds.add("clipped" if out["saturated"][i] else "completed")
    assert kinds == {"refused", "stopped", "clipped", "completed"}, kinds
    check = prepare_closed_loop("mismatch_5hz", duration=0.5)
    assert np.array_equal(bits(loop.run(check)), bits(native.NativeLoop().run(check)))
    loop.close()
    alone.close()
