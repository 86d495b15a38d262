"""The text report of ``bench``: the figures of :func:`harness.bench.measure.measure`."""

from __future__ import annotations

from .bound import RUN_SECONDS, Bound
from .measure import BLOCK, EXACT_WINDOW, WINDOW

__all__ = ["format_figures"]

PROG = "python -m harness bench"
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
    if "native runner" in f["loops"]:
        runner = f["loops"]["native runner"][last]
        bounds = [(s, Bound({"run": runner}, {"run": round(s / h)}, f["cores"]).runs_per_second({"run": 1}))
                  for s in RUN_SECONDS]
        lines.append(f"a sweep's compute bound (the native runner's {runner:.0f} ns/sample at {_count(last)} x "
                     f"samples a run / {f['cores']} cores): "
                     + ", ".join(f"{rate:.0f} runs/s of {s:g} s" for s, rate in bounds)
                     + "; `sweep` measures its own on its scenarios")
    return "\n".join(lines) + "\n"
