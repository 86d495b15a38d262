"""``python -m harness bench``: speed and memory of the core, the FMI layer and the masters.

Figures are printed, never asserted (the machine is shared and noisy). Every loop runs a
closed-loop scenario (default ``mismatch_1_5_10hz``: the mismatched plant with its sensor
noise, adaptation on) up to ``--samples`` samples (default 1e6, 500 s) and times blocks of
250 samples with the thread's CPU clock, so preemption by other processes does not count.
The cost "at N samples into a run" is the median over the blocks of the last 10000 samples
before N (the last N/2 for N < 20000) and over the repetitions.

Loops, all on the same trajectory (the core closed loop records y_meas and v, which drive
the plant and the controller timed alone):

* plant core, controller core, core closed loop: ``build/libpiezo_bench.so`` (C, no FMI);
* fmi2 API loop: the native runner with the minimal exchange (y_meas and v only,
  nothing recorded): what the fmi2 calls of both FMUs cost;
* native runner: the native master recording every output (``--backend native``);
* fmpy loop: the fmpy master (``--backend fmpy``).

Also: memory per instance (core structs; bytes each FMU allocates in fmi2Instantiate),
exact creep mode's O(k) cost and history, the end-to-end time of one 3 s run per
master, and the machine.
"""

from __future__ import annotations

import math
import os
import platform
import statistics
import subprocess
import sys
import time

import numpy as np

from . import _paths

__all__ = ["CHECKPOINTS", "add_bench_arguments", "run_bench", "measure"]

CHECKPOINTS = (2_000, 20_000, 120_000, 1_000_000)
BLOCK = 250
WINDOW = 10000
EXACT_WINDOW = 1000      # exact creep costs O(k): fewer samples at each point
PROG = "python -m harness bench"


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------
def add_bench_arguments(parser):
    """Add the options of ``bench`` to an argparse parser."""
    parser.add_argument("--scenario", default="mismatch_1_5_10hz",
                        help="tracking scenario whose parameters and reference are run "
                             "(default mismatch_1_5_10hz)")
    parser.add_argument("--samples", type=int, default=CHECKPOINTS[-1], metavar="N",
                        help="length of the timed runs; checkpoints beyond it are skipped "
                             "(default 1000000)")
    parser.add_argument("--repeat", type=int, default=5, metavar="R",
                        help="repetitions of the C loops (default 5)")
    parser.add_argument("--fmpy-repeat", type=int, default=3, metavar="R",
                        help="repetitions of the fmpy loop (default 3)")
    parser.add_argument("--no-fmpy", action="store_true", help="skip the fmpy loop")
    parser.add_argument("--fmu-dir", metavar="DIR",
                        help=f"folder of the FMUs (default: {_paths.describe_fmu_dir()})")
    parser.add_argument("--scenario-file", action="append", default=[], metavar="FILE",
                        help="TOML file of extra scenarios (repeatable)")
    return parser


def run_bench(args, stream=None):
    """Run ``bench`` with parsed arguments; print the figures; return the exit code."""
    stream = stream or sys.stdout
    if args.samples < 2 * BLOCK:
        raise ValueError(f"--samples must be at least {2 * BLOCK}, got {args.samples}")
    if args.repeat < 1 or args.fmpy_repeat < 1:
        raise ValueError("--repeat and --fmpy-repeat must be at least 1")
    from .scenarios import load_scenarios

    registry = load_scenarios(args.scenario_file)
    figures = measure(args.scenario, n_max=args.samples, repeat=args.repeat,
                      fmpy_repeat=0 if args.no_fmpy else args.fmpy_repeat,
                      fmu_dir=args.fmu_dir, registry=registry, progress=sys.stderr)
    stream.write(format_figures(figures))
    return 0


# ---------------------------------------------------------------------------
# measurements
# ---------------------------------------------------------------------------
_BENCH = None


def _bench_lib():
    """(ffi, lib) of build/libpiezo_bench.so, declared on the core's ffi (shared struct types)."""
    from . import core

    global _BENCH
    if _BENCH is not None:
        return _BENCH
    core.lib()      # first: the timing loops then bind to this core (same soname), not their RUNPATH's
    from ._paths import bench_include_dir, bench_library, where_to_get_it

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
    from . import core
    from ._common import prepare_closed_loop
    from .cosim import _simulate, simulate_closed_loop
    from .native import NativeLoop, simulate_closed_loop_native

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
    ffi, blib = _bench_lib()
    pp = core._plant_params_struct(setup.plant_params)
    cp = core._controller_params_struct(setup.controller_params)
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
    from .native import live_bytes

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
            _simulate(setup, fmu_dir, BLOCK, block_ns)
            col.add("fmpy loop", block_ns)

    say("end-to-end 3 s runs, exact creep")
    end_to_end = {}
    short = prepare_closed_loop(scenario, registry=registry, duration=3.0)
    for name, fn in (("native", simulate_closed_loop_native), ("fmpy", simulate_closed_loop)):
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
        "machine": machine_description(),
    }


# ---------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------
_ORDER = ("plant core", "controller core", "core closed loop", "fmi2 API loop", "native runner",
          "fmpy loop")


def _count(n):
    if n >= 1_000_000 and n % 1_000_000 == 0:
        return f"{n // 1_000_000}e6"
    mant, exp = f"{n:.1e}".split("e")
    mant = mant.rstrip("0").rstrip(".")
    return f"{mant}e{int(exp)}"


def format_figures(f):
    """The benchmark's text report of :func:`measure`'s figures."""
    cps = f["checkpoints"]
    h = f["h"]
    last = cps[-1]
    core_loop = f["loops"]["core closed loop"]
    lines = [
        f"{PROG}: scenario {f['scenario']}, h = {h * 1e3:g} ms; runs of {f['n']} samples; "
        f"medians of {f['repeat']} runs (fmpy: {f['fmpy_repeat']}) and of the blocks of "
        f"{BLOCK} samples in the last {WINDOW} (or N/2) before each point N; thread CPU time",
        f"machine: {f['machine']}",
        "",
        "ns/sample at N samples into a run" + " " * 12 + "ratio to core loop   real time",
        f"{'':<28}" + "".join(f"{_count(n):>9}" for n in cps) + f"   {'(at ' + _count(last) + ')':>13}"
        + f"   {'(at ' + _count(last) + ')':>11}",
    ]
    for name in _ORDER:
        if name not in f["loops"]:
            continue
        med = f["loops"][name]
        cells = "".join(f"{med[n]:>9.0f}" for n in cps)
        ratio = med[last] / core_loop[last]
        rtf = h / (med[last] * 1e-9)
        lines.append(f"{name:<28}{cells}   {ratio:>12.2f}x   {rtf:>10.0f}x")
    spread = [core_loop[n] for n in cps]
    lines.append(f"core closed loop: largest / smallest over the points {max(spread) / min(spread):.3f}")
    m = f["memory"]
    lines += [
        "",
        "memory per instance: "
        f"core piezo_plant {m['plant struct']} B, piezo_controller {m['controller struct']} B (fixed, "
        f"SOE creep); FMU instances (allocated in fmi2Instantiate): PiezoStage "
        f"{m['plant FMU instance']} B, AdaptiveCompoundController {m['controller FMU instance']} B; "
        f"what they hold changed by {m['FMU growth over the runs']} B over all the runs above",
        "exact creep (creep.exact = true), plant core: O(k) time and memory; history 16 B per sample "
        f"(history of k samples filled in, then {EXACT_WINDOW} samples timed)",
        f"{'':<28}" + "".join(f"{_count(n):>11}" for n in cps),
        f"{'plant ns/sample':<28}" + "".join(f"{f['exact'][n]:>11.0f}" for n in cps),
        f"{'history [MB]':<28}" + "".join(f"{16 * n / 1e6:>11.3g}" for n in cps),
        "",
        f"one {f['short_n'] * h:g} s run end to end (scenario preparation, instances, run, "
        f"result; wall clock): native {f['end_to_end']['native'] * 1e3:.1f} ms, "
        f"fmpy {f['end_to_end']['fmpy'] * 1e3:.1f} ms",
    ]
    return "\n".join(lines) + "\n"
