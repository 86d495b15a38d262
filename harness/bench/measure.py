"""The measurements of ``bench``: the C timing loops, the masters on the same trajectory,
memory per instance, exact creep's O(k) cost, end-to-end runs, and the machine they ran on."""

from __future__ import annotations

import math
import os
import platform
import statistics
import subprocess
import time

import numpy as np

from .. import core, masters
from ..loop import prepare_closed_loop
from ..masters.fmpy import simulate_setup
from ..masters.native import NativeLoop, live_bytes
from ..paths import bench_include_dir, bench_library, where_to_get_it

__all__ = ["CHECKPOINTS", "BLOCK", "WINDOW", "EXACT_WINDOW", "timing_library", "measure",
           "machine_description"]

CHECKPOINTS = (2_000, 20_000, 120_000, 1_000_000)
BLOCK = 250
WINDOW = 10000
EXACT_WINDOW = 1000      # exact creep costs O(k): fewer samples at each point


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
    y_ref = np.ascontiguousarray(setup.y_ref, dtype=float)
    y_meas, v = np.zeros(n), np.zeros(n)
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
        fn(scenario, registry=registry, duration=3.0, fmu_dir=fmu_dir)     # warm: extraction, loading
        times = []
        for _ in range(max(3, repeat)):
            t0 = time.perf_counter()
            fn(scenario, registry=registry, duration=3.0, fmu_dir=fmu_dir)
            times.append(time.perf_counter() - t0)
        end_to_end[name] = statistics.median(times)

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
        "machine": machine_description(), "cores": os.cpu_count() or 1,
    }
