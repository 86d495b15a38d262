"""Monte Carlo sweeps (harness.sweep, ``python -m harness sweep``).

References: NumPy's own generator and np.roots for the draws and the pole/zero moves;
harness.native runs (the native master, itself checked bit for bit against fmpy) for the
sweep's errors and for the worst parameter file; a real ``dask scheduler`` and ``dask
worker`` on 127.0.0.1 for ``--scheduler``.
"""
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from harness import native, sweep  # noqa: E402
from harness.scenarios import load_scenarios  # noqa: E402

BASE = sweep.plant_start_values()
REALS = [k for k, v in BASE.items() if isinstance(v, float)]


def spread(text):
    return sweep.parse_spread(text, REALS)


def test_parse_spread_forms_and_errors():
    assert spread("pi.weights=10%") == sweep.Spread("pi.weights", "uniform", 0.1, True)
    assert spread("creep.alpha=normal:0.005") == sweep.Spread("creep.alpha", "normal", 0.005, False)
    assert spread("tf.gain=uniform:2.5%") == sweep.Spread("tf.gain", "uniform", 0.025, True)
    assert spread("sensor.noise_rms=1e-3") == sweep.Spread("sensor.noise_rms", "uniform", 1e-3, False)
    assert spread("sensor.seed") == sweep.Spread("sensor.seed", "seed")
    for bad, fragment in (("pi.weight=10%", "unknown key 'pi.weight'"),
                          ("tf.poles", "expected tf.poles=[uniform:|normal:]WIDTH[%]"),
                          ("tf.zero=gauss:1%", "expected tf.zero="),
                          ("creep.k_c=-5%", "the width must be a finite number >= 0"),
                          ("sensor.seed=3", "takes no width"),
                          ("pi.m=10%", "unknown key 'pi.m'")):
        with pytest.raises(ValueError, match=fragment.replace("[", r"\[").replace("]", r"\]")
                           .replace("|", r"\|").replace(".", r"\.")):
            spread(bad)


def test_draws_follow_the_given_distributions():
    """Reference: the draws' definition. Relative uniform +-10 % on every PI weight: each
    w/w_nominal - 1 within [-0.1, 0.1] and spread over it (min < -0.09, max > 0.09);
    absolute normal sigma 0.005 on alpha: sample mean within 4 standard errors of the
    nominal and sample std within 10 % of 0.005; every run a different seed; same seed
    gives the same draws, another seed others."""
    base = {**BASE, "pi.w0": 0.36784, "pi.w[1]": 0.07854, "pi.w[2]": 0.03542, "pi.w[3]": 0.00792,
            "creep.alpha": -0.0085}
    spreads = [spread("pi.weights=10%"), spread("creep.alpha=normal:0.005"), spread("sensor.seed")]
    sets = sweep.draw_plant_parameters(base, spreads, 2000, seed=3)
    ratios = np.array([[p[k] / base[k] - 1 for k in ("pi.w0", "pi.w[1]", "pi.w[2]", "pi.w[3]")]
                       for p in sets])
    assert ratios.min() >= -0.1 and ratios.max() <= 0.1
    assert ratios.min() < -0.09 and ratios.max() > 0.09
    assert np.corrcoef(ratios[:, 0], ratios[:, 1])[0, 1] < 0.1          # independent per weight
    assert all(p["pi.w[4]"] == 0.0 for p in sets)
    alpha = np.array([p["creep.alpha"] for p in sets])
    assert abs(alpha.mean() - (-0.0085)) < 4 * 0.005 / math.sqrt(2000)
    assert abs(alpha.std() / 0.005 - 1) < 0.1
    assert len({p["sensor.seed"] for p in sets}) == 2000
    assert sweep.draw_plant_parameters(base, spreads, 5, seed=3) == sets[:5]
    assert sweep.draw_plant_parameters(base, spreads, 5, seed=4) != sets[:5]


def _poles_zero_gain(p):
    poles = np.sort(np.roots([1.0, p["tf.a1"], p["tf.a2"]]).real)
    zero = -p["tf.b2"] / p["tf.b1"]
    gain = (p["tf.b1"] + p["tf.b2"]) / (1 + p["tf.a1"] + p["tf.a2"])
    return poles, zero, gain


def test_pole_zero_and_gain_moves_against_np_roots():
    """Reference: np.roots of the drawn A and B. Relative pole spread: each pole moves to
    p^(1 + delta) with |delta| <= 20 % (so it stays inside the unit circle) while the zero
    and the DC gain stay (to 1e-12); zero spread: the poles and the gain stay; gain spread:
    the poles and the zero stay and the gain moves within +-10 %."""
    base = dict(BASE)
    p0, z0, k0 = _poles_zero_gain(base)
    for p in sweep.draw_plant_parameters(base, [spread("tf.poles=20%")], 200, seed=5):
        poles, zero, gain = _poles_zero_gain(p)
        d = np.log(poles) / np.log(p0) - 1
        assert np.all(np.abs(d) <= 0.2 + 1e-9) and np.all(np.abs(poles) < 1)
        assert abs(zero - z0) < 1e-12 and abs(gain / k0 - 1) < 1e-12
    for p in sweep.draw_plant_parameters(base, [spread("tf.zero=10%")], 50, seed=6):
        poles, zero, gain = _poles_zero_gain(p)
        assert np.allclose(poles, p0, rtol=0, atol=1e-12) and abs(gain / k0 - 1) < 1e-12
        assert abs(np.log(zero) / np.log(z0) - 1) <= 0.1 + 1e-9
    moved = []
    for p in sweep.draw_plant_parameters(base, [spread("tf.gain=10%")], 50, seed=7):
        poles, zero, gain = _poles_zero_gain(p)
        assert np.allclose(poles, p0, rtol=0, atol=1e-12) and abs(zero - z0) < 1e-12
        moved.append(gain / k0 - 1)
    assert max(np.abs(moved)) <= 0.1 + 1e-12 and max(np.abs(moved)) > 0.08


def test_in_process_sweep_counts_failures_and_worst_file_reproduces(tmp_path):
    """Reference: native runs of the drawn parameter sets. A sweep with spreads wide enough to
    make runs diverge, clip or be refused (workers = 0: no Dask) counts every run exactly
    once, reports the not-ok ones without stopping, its e_rms equal fresh native runs of the
    same parameters bit for bit, and the worst parameter file, loaded as a scenario file,
    reproduces the worst e_rms exactly."""
    from harness._common import prepare_closed_loop
    from harness.metrics import compute_metrics

    spreads = ["tf.poles=0.01", "pi.weights=60%", "tf.zero=0.01"]
    result = sweep.run_sweep(["mismatch_20hz"], spreads, 24, seed=11, workers=0)
    c = result.counts("mismatch_20hz")
    assert sum(c.values()) == 24
    assert c["ok"] >= 10 and c["ok"] < 24
    assert c["diverged"] + c["saturated"] >= 1 and c["invalid"] >= 1
    runs = result.runs["mismatch_20hz"]
    sc = load_scenarios()["mismatch_20hz"]
    for i in [i for i, r in enumerate(runs) if r[0] == "ok"][:3]:
        data = native.NativeLoop().run(prepare_closed_loop(sc, plant_params=result.parameters["mismatch_20hz"][i]))
        m = compute_metrics(data["time"], data["y_d"], data["y"], sc.metric_window, sc.step_size)
        assert m.e_rms == runs[i][1]
    for r in runs:
        if r[0] != "ok":
            assert r[3] and math.isnan(r[1])
    files = sweep.write_outputs(result, tmp_path, plots=True)
    names = {p.name for p in files}
    assert {"sweep_summary.csv", "sweep_summary.md", "sweep_runs.csv", "worst_mismatch_20hz.toml",
            "failed_mismatch_20hz.toml", "sweep_e_rms.png"} <= names
    assert (tmp_path / "sweep_e_rms.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    registry = load_scenarios([tmp_path / "worst_mismatch_20hz.toml"])
    worst = registry["worst_mismatch_20hz"]
    data = native.simulate_closed_loop_native(worst)
    m = compute_metrics(data["time"], data["y_d"], data["y"], worst.metric_window, worst.step_size)
    assert m.e_rms == max(r[1] for r in runs if r[0] == "ok")
    row = sweep.summary_rows(result)[0]
    ok = np.array([r[1] for r in runs if r[0] == "ok"]) * 1e3
    assert row["e_rms_worst_nm"] == ok.max() and row["e_rms_p50_nm"] == np.percentile(ok, 50)


def _free_port():
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=20)


def test_sweep_on_a_real_dask_scheduler(tmp_path):
    """Reference: the same sweep in this process (workers = 0). A `dask scheduler` and a
    `dask worker` are started on 127.0.0.1 as subprocesses; `python -m harness sweep
    --scheduler ADDRESS` runs a small sweep on them and prints the same table figures and
    writes the same runs (CSV) as the in-process sweep; progress goes to stderr."""
    dask = shutil.which("dask")
    assert dask, "the dask command line is needed (pip install 'dask[distributed]')"
    env = {**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1"}
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    sched_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                       "--no-dashboard", "--scheduler-file", str(sched_file)],
                                      env=env, cwd=tmp_path, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        deadline = time.time() + 60
        while not sched_file.exists() and time.time() < deadline:
            time.sleep(0.2)
        assert sched_file.exists(), "the dask scheduler did not start"
        assert json.loads(sched_file.read_text())["address"] == address
        procs.append(subprocess.Popen([dask, "worker", address, "--nworkers", "1", "--nthreads", "1",
                                       "--no-dashboard", "--host", "127.0.0.1"],
                                      env=env, cwd=tmp_path, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        args = ["mismatch_5hz", "-n", "12", "--vary", "pi.weights=10%", "--vary", "tf.poles=10%",
                "--vary", "sensor.seed", "--seed", "5", "--no-plots"]
        # the worker registers within seconds; the client waits for it through the scheduler
        proc = subprocess.run([sys.executable, "-m", "harness", "sweep", *args, "--scheduler", address,
                               "--out", str(tmp_path / "dask")], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=300)
    finally:
        for p in reversed(procs):
            _stop(p)
    assert proc.returncode == 0, proc.stderr
    assert f"on the Dask cluster at {address}" in proc.stdout
    assert "sweep: 12/12 runs (100%)" in proc.stderr
    local = subprocess.run([sys.executable, "-m", "harness", "sweep", *args, "--workers", "0",
                            "--out", str(tmp_path / "local")], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=300)
    assert local.returncode == 0, local.stderr

    def table(text):
        return [line for line in text.splitlines() if line.startswith("mismatch_5hz")]

    assert table(proc.stdout) == table(local.stdout) and len(table(proc.stdout)) == 1

    def runs(path):
        lines = (path / "sweep_runs.csv").read_text().splitlines()
        return [",".join(cell for i, cell in enumerate(line.split(",")) if i != 5)   # seconds differ
                for line in lines]

    assert runs(tmp_path / "dask") == runs(tmp_path / "local")


def test_cli_sweep_local_cluster_and_errors(tmp_path):
    """The default path: a local Dask cluster (one worker process here) runs the sweep from the
    command line; user errors exit 2 with one line."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-m", "harness", "sweep", "mismatch_1hz", "-n", "6",
                           "--vary", "creep.k_c=5%", "--workers", "1", "--no-plots",
                           "--out", str(tmp_path)], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "a local Dask cluster of 1 worker process" in proc.stdout
    assert (tmp_path / "worst_mismatch_1hz.toml").exists()
    for args, fragment in ((["track_1hz", "--vary", "tf.pole=1%"], "unknown key 'tf.pole'"),
                           (["validate_1hz"], "is a validation scenario"),
                           (["nosuch"], "nosuch"),
                           (["track_1hz", "-n", "0"], "--runs must be at least 1")):
        bad = subprocess.run([sys.executable, "-m", "harness", "sweep", *args, "--workers", "0",
                              "--out", str(tmp_path / "x")], env=env, cwd=tmp_path,
                             capture_output=True, text=True, timeout=120)
        assert bad.returncode == 2, (args, bad.stderr)
        assert bad.stderr.count("\n") == 1 and fragment in bad.stderr, bad.stderr
