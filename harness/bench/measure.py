"""The measurements of ``bench``: the C timing loops, the masters on the same trajectory,
memory per instance, exact creep's O(k) cost, end-to-end runs, and the machine they ran on."""

from __future__ import annotations

import math
import os
import platform
import statistics
import subprocess
import tempfile
import time

import fmpy
import numpy as np

from .. import masters
from ..binding import core
from ..binding.closed_loop import CLOSED_LOOP_MODEL
from ..fmu import REFERENCE_MODEL, fmu_path
from ..loop import prepare_closed_loop
from ..masters import (NativeLoop, closed_loop_fmu_parameters, live_bytes, simulate_setup,
                       simulate_ssp_scenario, simulate_wired)
from ..paths import bench_include_dir, bench_library, where_to_get_it

__all__ = ["CHECKPOINTS", "BLOCK", "SUPERVISION_OFF", "WINDOW", "EXACT_WINDOW", "CLOSED_LOOP_STEP",
           "CLOSED_LOOP_DURATION",
           "timing_library", "measure", "closed_loop_fmu_times", "machine_description"]

CHECKPOINTS = (2_000, 20_000, 120_000, 1_000_000)
BLOCK = 250
#: the row of the core closed loop with sup.enabled = false (the supervision's cost)
SUPERVISION_OFF = "core loop, supervision off"
WINDOW = 10000
EXACT_WINDOW = 1000      # exact creep costs O(k): fewer samples at each point
#: the closed-loop FMU through fmpy.simulate_fmu: communication step and length of the run [s]
CLOSED_LOOP_STEP = 0.01
CLOSED_LOOP_DURATION = 3.0


_BENCH = None


def timing_library():
    """(ffi, lib) of build/libpiezo_bench.so, declared on the core's ffi (shared struct types)."""
    global _BENCH
    if _BENCH is not None:
        return _BENCH
    core.lib()      # first: the timing loops then bind to this core (same soname), not their RUNPATH's
    path = bench_library()
    if not path.is_file():
        raise FileNotFoundError(f"benchmark library not found: {path}; {where_to_get_it()}")
    core.ffi.cdef(core.header_cdef(bench_include_dir(), ("piezo_bench.h",)))
    _BENCH = (core.ffi, core.ffi.dlopen(str(path)))
    return _BENCH


def _window_costs(block_ns, checkpoints):
    """ns/sample of the blocks in each checkpoint's window: {N: [values]}."""
    out = {}
    for n in checkpoints:
        width = min(WINDOW, n // 2)
        first, last = (n - width) // BLOCK, n // BLOCK          # blocks [first, last)
        vals = [block_ns[i] / BLOCK for i in range(first, last) if i < len(block_ns)]
        out[n] = vals
    return out


class _Collector:
    """Per loop and checkpoint, every block figure of every repetition."""

    def __init__(self, checkpoints):
        self.checkpoints = checkpoints
        self.values = {}

    def add(self, name, block_ns):
        table = self.values.setdefault(name, {n: [] for n in self.checkpoints})
        for n, vals in _window_costs(list(block_ns), self.checkpoints).items():
            table[n].extend(vals)

    def medians(self, name):
        return {n: (statistics.median(v) if v else math.nan) for n, v in self.values[name].items()}


def _status_error(what, status, done, n):
    raise RuntimeError(f"{what} stopped at sample {done} of {n} (piezo_status {status})")


def machine_description():
    """One line: CPU, cores, OS, Python, C compiler, load."""
    cpu = platform.processor() or platform.machine()
    family = model = None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                key, value = key.strip(), value.strip()
                if key == "model name" and cpu in ("", platform.machine(), "x86_64"):
                    cpu = value
                elif key == "cpu family" and family is None:
                    family = value
                elif key == "model" and model is None:
                    model = value
    except OSError:
        pass
    if family and model:
        cpu += f" (family {family}, model {model})"
    os_name = platform.system() + " " + platform.release()
    try:
        with open("/etc/os-release") as f:
            pretty = [ln.split("=", 1)[1].strip().strip('"') for ln in f if ln.startswith("PRETTY_NAME=")]
        if pretty:
            os_name = f"{pretty[0]}, {os_name}"
    except OSError:
        pass
    try:
        cc = subprocess.run(["cc", "--version"], capture_output=True, text=True, timeout=10).stdout
        cc = cc.splitlines()[0] if cc else "cc ?"
    except (OSError, subprocess.SubprocessError):
        cc = "cc ?"
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return (f"{cpu}, {os.cpu_count()} cores; {os_name}; Python {platform.python_version()}; "
            f"{cc} (-O2); load average {load}")


def _median_time(fn, repeat):
    """Median wall time [s] of `repeat` calls of fn after one to warm up."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def closed_loop_fmu_times(scenario="mismatch_1_5_10hz", *, fmu_dir=None, registry=None, repeat=5,
                          ssp_repeat=1, progress=None):
    """Wall times [s] of CLOSED_LOOP_DURATION of a sines scenario: PiezoStageClosedLoop through
    ``fmpy.simulate_fmu`` at a step of CLOSED_LOOP_STEP (from the .fmu file, which fmpy extracts at
    every call, and from a folder it was extracted to once, with the model description read once:
    fmpy's own arguments for a repeated run) and at one sample (h), fmpy's own cost for the same
    steps (ReferenceSignal alone, from its folder), and the loops of several FMUs over the same
    time: the fmpy master (PiezoStage and AdaptiveCompoundController, the reference given), the
    three FMUs wired by hand (exchange schedule) and fmpy's SSP player on the closed-loop SSP
    (`ssp_repeat` runs, 0: not run). Medians of `repeat` runs after a warm-up. None for a
    scenario whose reference is not a sum of sines."""
    def say(text):
        if progress is not None:
            progress(text)

    duration, step = CLOSED_LOOP_DURATION, CLOSED_LOOP_STEP
    setup = prepare_closed_loop(scenario, registry=registry, duration=duration)
    if not setup.scenario.signal.internal:
        return None         # the internal reference (and the wired loop, the SSP) need sines
    params = closed_loop_fmu_parameters(setup)
    path = fmu_path(CLOSED_LOOP_MODEL, fmu_dir)
    ref_path = fmu_path(REFERENCE_MODEL, fmu_dir)
    md, ref_md = fmpy.read_model_description(str(path)), fmpy.read_model_description(str(ref_path))
    out = {"duration": duration, "step": step, "h": setup.h, "repeat": repeat}
    with tempfile.TemporaryDirectory(prefix="bench_closed_loop_") as tmp:
        folder, ref_folder = os.path.join(tmp, "loop"), os.path.join(tmp, "reference")
        fmpy.extract(str(path), unzipdir=folder)
        fmpy.extract(str(ref_path), unzipdir=ref_folder)
        say(f"fmpy.simulate_fmu of {CLOSED_LOOP_MODEL}, {repeat} x {duration:g} s")
        out["fmu file"] = _median_time(lambda: fmpy.simulate_fmu(
            str(path), stop_time=duration, output_interval=step, start_values=params), repeat)
        out["fmu folder"] = _median_time(lambda: fmpy.simulate_fmu(
            folder, stop_time=duration, output_interval=step, start_values=params,
            model_description=md), repeat)
        out["fmu folder, one sample"] = _median_time(lambda: fmpy.simulate_fmu(
            folder, stop_time=duration, output_interval=setup.h, start_values=params,
            model_description=md), max(1, repeat // 2))
        out["fmpy floor"] = _median_time(lambda: fmpy.simulate_fmu(
            ref_folder, stop_time=duration, output_interval=step, model_description=ref_md), repeat)
    say(f"the loops of several FMUs, {duration:g} s")
    fmpy_master = masters.closed_loop("fmpy")
    out["fmpy master"] = _median_time(lambda: fmpy_master(scenario, registry=registry, duration=duration,
                                                          fmu_dir=fmu_dir), repeat)
    out["wired"] = _median_time(lambda: simulate_wired(scenario, "exchange", duration=duration,
                                                       fmu_dir=fmu_dir, registry=registry), repeat)
    if ssp_repeat:
        say("fmpy's SSP player")
        # the player runs the scenario's own duration (the SSP's stop time)
        out["ssp player duration"] = float(setup.scenario.duration)
        out["ssp player"] = _median_time(lambda: simulate_ssp_scenario(scenario, fmu_dir=fmu_dir,
                                                                       registry=registry), ssp_repeat)
    return out


def measure(scenario="mismatch_1_5_10hz", *, n_max=CHECKPOINTS[-1], repeat=5, fmpy_repeat=3,
            fmu_dir=None, registry=None, progress=None):
    """Measure every figure of the benchmark; return a dict (see :func:`format_figures`)."""
    def say(text):
        if progress is not None:
            progress.write(f"bench: {text}\n")
            progress.flush()

    checkpoints = tuple(n for n in CHECKPOINTS if n <= n_max)
    if not checkpoints:
        checkpoints = (n_max,)
    h_setup = prepare_closed_loop(scenario, registry=registry)
    h = h_setup.h
    setup = prepare_closed_loop(scenario, registry=registry, duration=n_max * h)
    n = setup.n
    ffi, blib = timing_library()
    pp = core.plant_params_struct(setup.plant_params)
    cp = core.controller_params_struct(setup.controller_params)
    # the same loop without the controller's supervision (docs/robustness.md): what it costs
    cp_off = core.controller_params_struct({**setup.controller_params, "sup.enabled": False})
    y_ref = np.ascontiguousarray(setup.y_ref, dtype=float)
    y_meas, v = np.zeros(n), np.zeros(n)
    y_meas_off, v_off = np.zeros(n), np.zeros(n)
    status = ffi.new("int *")
    nb = n // BLOCK
    col = _Collector(checkpoints)
    buf = lambda a: ffi.from_buffer("double[]", a)   # noqa: E731

    say(f"core loops, {repeat} x {n} samples")
    for r in range(repeat):
        block_ns = np.zeros(nb)
        done = blib.piezo_bench_closed_loop(pp, cp, buf(y_ref), n, buf(y_meas), buf(v), BLOCK,
                                            buf(block_ns), status)
        if done != n:
            _status_error("core closed loop", status[0], done, n)
        col.add("core closed loop", block_ns)
        block_ns = np.zeros(nb)
        done = blib.piezo_bench_plant(pp, buf(v), n, BLOCK, buf(block_ns), status)
        if done != n:
            _status_error("plant core", status[0], done, n)
        col.add("plant core", block_ns)
        block_ns = np.zeros(nb)
        done = blib.piezo_bench_controller(cp, buf(y_ref), buf(y_meas), n, BLOCK, buf(block_ns), status)
        if done != n:
            _status_error("controller core", status[0], done, n)
        col.add("controller core", block_ns)
        block_ns = np.zeros(nb)
        done = blib.piezo_bench_closed_loop(pp, cp_off, buf(y_ref), n, buf(y_meas_off), buf(v_off), BLOCK,
                                            buf(block_ns), status)
        if done != n:
            _status_error("core closed loop, supervision off", status[0], done, n)
        col.add(SUPERVISION_OFF, block_ns)

    say(f"fmi2 API loop and native runner, {repeat} x {n} samples")
    loop = NativeLoop(fmu_dir)
    memory = {"plant struct": core.ffi.sizeof("piezo_plant"),
              "controller struct": core.ffi.sizeof("piezo_controller"),
              "plant FMU instance": loop.instance_bytes(0),
              "controller FMU instance": loop.instance_bytes(1)}
    held_before = live_bytes()
    for r in range(repeat):
        col.add("fmi2 API loop", loop.run_minimal(setup, block=BLOCK))
        loop.run(setup, block=BLOCK)
        col.add("native runner", loop.last_block_ns)
    memory["FMU growth over the runs"] = live_bytes() - held_before
    loop.close()

    if fmpy_repeat:
        say(f"fmpy loop, {fmpy_repeat} x {n} samples")
        for r in range(fmpy_repeat):
            block_ns = []
            simulate_setup(setup, fmu_dir, BLOCK, block_ns)
            col.add("fmpy loop", block_ns)

    say("end-to-end 3 s runs, exact creep")
    end_to_end = {}
    short = prepare_closed_loop(scenario, registry=registry, duration=3.0)
    for name in ("native", "fmpy"):
        fn = masters.closed_loop(name)
        # the first call warms up: extraction, loading
        end_to_end[name] = _median_time(
            lambda: fn(scenario, registry=registry, duration=3.0, fmu_dir=fmu_dir), max(3, repeat))

    closed_loop = closed_loop_fmu_times(scenario, fmu_dir=fmu_dir, registry=registry,
                                        repeat=max(3, repeat), ssp_repeat=1 if fmpy_repeat else 0,
                                        progress=say)

    exact = {}
    for k in checkpoints:
        width = min(EXACT_WINDOW, k // 2) // BLOCK * BLOCK
        vals = []
        for _ in range(max(1, min(repeat, 3))):
            block_ns = np.zeros(width // BLOCK)
            done = blib.piezo_bench_exact_plant(pp, k - width, width, BLOCK, buf(block_ns), status)
            if done != width:
                _status_error("exact plant", status[0], done, width)
            vals.extend((block_ns / BLOCK).tolist())
        exact[k] = statistics.median(vals)

    return {
        "scenario": scenario, "h": h, "n": n, "repeat": repeat, "fmpy_repeat": fmpy_repeat,
        "checkpoints": checkpoints,
        "loops": {name: col.medians(name) for name in col.values},
        "memory": memory, "exact": exact, "end_to_end": end_to_end, "short_n": short.n,
        "closed_loop_fmu": closed_loop,
        "machine": machine_description(), "cores": os.cpu_count() or 1,
    }
