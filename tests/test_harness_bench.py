"""``python -m harness bench`` (harness.bench) and its timing loops (fmu_src/bench/).

No timed test: the speed figures are printed, never asserted. Checked here: the command runs
and reports every loop at the checkpoints it reached; the memory figures are the structs'
sizes (cffi's sizeof) and the FMUs' allocations; exact mode's history is 16 bytes per sample;
and the timing loops run the very trajectory of the closed loop (the plant and the controller
timed alone reproduce it, checked against the core binding's own loop).
"""
import math
import os
import re
import subprocess
import sys

import numpy as np

from harness.binding import core
from harness.bench.measure import timing_library
from harness.loop import prepare_closed_loop
from harness.masters import native
from harness.masters.c_core import simulate_closed_loop_core
from conftest import REPO


def test_bench_command_reports_every_loop(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-m", "harness", "bench", "--samples", "20000", "--repeat", "1",
                           "--fmpy-repeat", "1"], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert out.splitlines()[1].startswith("machine: ") and "cores" in out.splitlines()[1]
    header = next(line for line in out.splitlines() if line.strip().startswith("2e3"))
    assert header.split()[:2] == ["2e3", "2e4"] and "1.2e5" not in header   # beyond --samples
    for name in ("plant core", "controller core", "core closed loop", "core loop, supervision off",
                 "fmi2 API loop", "native runner", "fmpy loop"):
        line = next(line for line in out.splitlines() if line.startswith(name))
        cells = line[len(name):].split()
        ns = [float(c) for c in cells[:2]]
        ratio, rtf = float(cells[2].rstrip("x")), float(cells[3].rstrip("x"))
        assert all(math.isfinite(v) and v > 0 for v in ns), line
        assert math.isclose(rtf, 0.0005 / (ns[1] * 1e-9), rel_tol=0.01), line   # h / cost
    assert float(next(line for line in out.splitlines() if line.startswith("core closed loop"))
                 .split()[5].rstrip("x")) == 1.0
    # the supervision's cost: the difference of the two core loops' last cells
    on, off = (float(next(line for line in out.splitlines() if line.startswith(name))[len(name):].split()[1])
               for name in ("core closed loop", "core loop, supervision off"))
    m = re.search(r"the supervision costs (-?[\d.]+) ns/sample at 2e4 \((-?\d+) % of the loop without it", out)
    assert m and math.isclose(float(m.group(1)), on - off, abs_tol=1.0), out
    m = re.search(r"core piezo_plant (\d+) B, piezo_controller (\d+) B", out)
    assert (int(m.group(1)), int(m.group(2))) == (core.ffi.sizeof("piezo_plant"),
                                                  core.ffi.sizeof("piezo_controller"))
    m = re.search(r"PiezoStage (\d+) B, AdaptiveCompoundController (\d+) B", out)
    for _ in range(12):                       # instance names have a fixed width: same bytes
        loop = native.NativeLoop()
        loop.close()
    loop = native.NativeLoop()
    assert (int(m.group(1)), int(m.group(2))) == (loop.instance_bytes(0), loop.instance_bytes(1))
    loop.close()
    hist = next(line for line in out.splitlines() if line.startswith("history [MB]")).split()[2:]
    assert [float(x) for x in hist] == [0.032, 0.32]                         # 16 B per sample
    exact = [float(x) for x in next(line for line in out.splitlines()
                                    if line.startswith("plant ns/sample")).split()[2:]]
    assert len(exact) == 2 and all(x > 0 for x in exact)
    assert re.search(r"one 3 s run end to end .*: native [\d.]+ ms, fmpy [\d.]+ ms", out)
    # a sweep's bound: cores / (the native runner's ns/sample at the last point x samples a run)
    runner = float(next(line for line in out.splitlines() if line.startswith("native runner")).split()[3])
    m = re.search(r"compute bound \(the native runner's (\d+) ns/sample at 2e4 x samples a run / (\d+) "
                  r"cores\): (\d+) runs/s of 0.5 s, (\d+) runs/s of 3 s, (\d+) runs/s of 30 s", out)
    assert m and float(m.group(1)) == runner and int(m.group(2)) == os.cpu_count(), out
    for rate, samples in zip(m.groups()[2:], (1000, 6000, 60000)):
        assert math.isclose(float(rate), os.cpu_count() / (runner * 1e-9 * samples), rel_tol=0.01)

    # the closed-loop FMU through fmpy.simulate_fmu beside the loops of several FMUs: each run's
    # time, its time per sample (over 6000 samples of 3 s) and how much faster than the fmpy master
    rows = [line for line in out.splitlines() if re.search(r" ms +[\d.]+ us +[\d.]+x +[\d.]+x$", line)]
    labels = [re.split(r"\s{2,}", line.strip())[0] for line in rows]
    assert labels[0].startswith("fmpy.simulate_fmu PiezoStageClosedLoop, 10 ms step") and len(rows) == 7, rows
    assert labels[-1] == "fmpy's SSP player, the three FMUs"
    for line in rows:
        ms, us, same_run = re.search(r"([\d.]+) ms +([\d.]+) us +([\d.]+)x", line).groups()
        assert float(ms) > 0 and math.isclose(float(us), float(ms) * 1e3 / 6000, rel_tol=0.01, abs_tol=0.002)
    fmpy_master = next(line for line in rows if line.startswith("fmpy master"))
    assert re.search(r" 1\.0x +[\d.]+x$", fmpy_master)        # itself


def test_bench_loops_run_the_closed_loop_trajectory():
    """Reference: harness.masters.c_core.simulate_closed_loop_core (the core binding's loop with
    the FMUs' timing). piezo_bench_closed_loop records y_meas(k) and the applied v(k): both
    equal the reference's bit for bit; the plant timed alone on that v and the controller
    timed alone on those inputs run every sample (status PIEZO_OK)."""
    ffi, lib = timing_library()
    n = 3000
    setup = prepare_closed_loop("mismatch_1_5_10hz", duration=n * 0.0005)
    want = simulate_closed_loop_core("mismatch_1_5_10hz", duration=n * 0.0005)
    pp = core.plant_params_struct(setup.plant_params)
    cp = core.controller_params_struct(setup.controller_params)
    y_ref = np.ascontiguousarray(setup.y_ref)
    y_meas, v, block_ns = np.zeros(n), np.zeros(n), np.zeros(n // 500)
    status = ffi.new("int *")
    buf = lambda a: ffi.from_buffer("double[]", a)   # noqa: E731
    assert lib.piezo_bench_closed_loop(pp, cp, buf(y_ref), n, buf(y_meas), buf(v), 500, buf(block_ns),
                                       status) == n and status[0] == 0
    assert np.array_equal(y_meas, want["y_meas"]) and np.array_equal(v, want["v"])
    assert np.all(block_ns > 0)
    assert lib.piezo_bench_plant(pp, buf(v), n, 500, ffi.NULL, status) == n and status[0] == 0
    assert lib.piezo_bench_controller(cp, buf(y_ref), buf(y_meas), n, 500, ffi.NULL, status) == n
    # exact creep from a filled-in history: runs, and refuses nothing
    assert lib.piezo_bench_exact_plant(pp, 5000, 1000, 500, buf(block_ns[:2]), status) == 1000
    assert status[0] == 0
