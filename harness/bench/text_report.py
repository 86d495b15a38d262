"""The text report of ``bench``: the figures of :func:`harness.bench.measure.measure`."""

from __future__ import annotations

from ..binding.closed_loop import CLOSED_LOOP_MODEL
from .bound import RUN_SECONDS, Bound
from .measure import BLOCK, EXACT_WINDOW, SUPERVISION_OFF, WINDOW

__all__ = ["format_figures"]

PROG = "python -m harness bench"
_ORDER = ("plant core", "controller core", "core closed loop", SUPERVISION_OFF, "fmi2 API loop",
          "native runner", "fmpy loop")


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
    if SUPERVISION_OFF in f["loops"]:
        off = f["loops"][SUPERVISION_OFF][last]
        lines.append(f"the supervision costs {core_loop[last] - off:.1f} ns/sample at {_count(last)} "
                     f"({100 * (core_loop[last] / off - 1):.0f} % of the loop without it; sup.enabled = false)")
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
    lines += _closed_loop_lines(f)
    return "\n".join(lines) + "\n"


def _closed_loop_lines(f):
    """PiezoStageClosedLoop through fmpy.simulate_fmu against the loops of several FMUs."""
    c = f.get("closed_loop_fmu")
    if not c:
        return ["", "the closed-loop FMU through fmpy.simulate_fmu: not measured (it needs a scenario "
                    "with a sines reference)"]
    samples = c["duration"] / c["h"]
    fmpy_loop = f["loops"].get("fmpy loop", {}).get(f["checkpoints"][-1])
    per_sample = lambda seconds: seconds / samples * 1e6        # noqa: E731  [us]

    def row(label, seconds):
        ratios = f"{c['fmpy master'] / seconds:6.1f}x"
        if fmpy_loop:
            ratios += f"   {fmpy_loop * 1e-3 / per_sample(seconds):6.1f}x"
        return f"{label:<58}{seconds * 1e3:9.2f} ms {per_sample(seconds):8.3f} us   {ratios}"

    lines = [
        "",
        f"{c['duration']:g} s of the scenario (wall clock, medians of {c['repeat']}; per sample: the time over "
        f"its {samples:.0f} samples of h = {c['h'] * 1e3:g} ms)",
        f"{'':<58}{'run':>12} {'per sample':>11}   {'faster than the fmpy master':>28}",
        f"{'':<58}{'':>12} {'':>11}   {'(same run)':>12}  {'(fmpy loop/sample)':>17}",
        row(f"fmpy.simulate_fmu {CLOSED_LOOP_MODEL}, {c['step'] * 1e3:g} ms step, .fmu file", c["fmu file"]),
        row(f"  the same from its folder, model description given", c["fmu folder"]),
        row(f"  the same at a step of one sample ({c['h'] * 1e3:g} ms)", c["fmu folder, one sample"]),
        row(f"  fmpy.simulate_fmu's own cost: ReferenceSignal alone, {c['step'] * 1e3:g} ms", c["fmpy floor"]),
        row("fmpy master: PiezoStage + AdaptiveCompoundController", c["fmpy master"]),
        row("the three FMUs wired (exchange), fmpy's raw calls", c["wired"]),
    ]
    if "ssp player" in c:
        # the player runs the scenario's own duration: scaled to this one's
        lines.append(row("fmpy's SSP player, the three FMUs",
                         c["ssp player"] * c["duration"] / c["ssp player duration"]))
    return lines
