"""What a sweep writes: the summary table (printed, CSV, Markdown), every run sorted, and the
worst and the first failed run of each scenario as scenario files."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from .manifest import read_manifest, write_manifest
from .plot import plot_errors
from .store import JOURNAL, RUNS, STATUS_CODE, STATUSES

__all__ = ["PROG", "PERCENTILES", "summary_rows", "format_summary", "write_parameter_file",
           "write_outputs"]

PROG = "python -m harness sweep"
PERCENTILES = (5, 50, 95, 99)
#: the statuses (store.STATUSES) in the order the tables show them
COUNTED = ("ok", "stopped", "diverged", "saturated", "invalid")


def summary_rows(result):
    """One dict per scenario: counts, percentiles and worst of e_rms [nm] and e_r [%]."""
    rows = []
    for name in result.scenarios:
        c = result.counts(name)
        row = {"scenario": name, "runs": len(result.runs[name]), **c}
        for field, scale, unit in (("e_rms", 1e3, "nm"), ("e_r", 100.0, "%")):
            vals = result.errors(name, field) * scale
            for p in PERCENTILES:
                row[f"{field}_p{p}_{unit}"] = float(np.percentile(vals, p)) if vals.size else math.nan
            row[f"{field}_worst_{unit}"] = float(vals.max()) if vals.size else math.nan
        rows.append(row)
    return rows


def _mb(n):
    return "?" if n is None else f"{n / 1e6:.0f} MB"


def _throughput_lines(result):
    """What this call computed, how fast, against the compute bound, and its peak RSS."""
    done = result.computed
    resumed = sum(len(v) for v in result.runs.values()) - done
    rate = done / result.elapsed if result.elapsed > 0 else math.nan
    steady = done / result.compute_seconds if result.compute_seconds > 0 else math.nan
    lines = [f"this call: {done} runs computed" + (f" ({resumed} from the journal)" if resumed else "")
             + (f": {steady:.0f} runs/s while computing ({result.compute_seconds:.1f} s), "
                f"{rate:.0f} runs/s including the start ({result.elapsed:.1f} s)" if done else "")]
    b = result.bound
    if isinstance(b, str) and done:
        lines.append(f"compute bound: not measured ({b})")
    elif b is not None and done:
        counts = {name: len(result.runs[name]) for name in result.scenarios}
        bound = b.runs_per_second(counts)
        costs = "; ".join(f"{b.ns_per_sample[k]:.0f} ns/sample x {b.samples[k]} samples a run"
                          + (f" ({k})" if len(counts) > 1 else "") for k in counts)
        lines.append(f"compute bound: {bound:.0f} runs/s (the native runner's {costs}, / {b.cores} "
                     f"core{'s' if b.cores != 1 else ''}; measured in this call): {steady / bound:.0%} "
                     f"of it while computing, {rate / bound:.0%} including the start")
        cpu = result.cpu_seconds or {}
        used = cpu.get("tasks", math.nan) + cpu.get("client", math.nan)
        need = done * b.seconds_per_run(counts)
        if used > 0:
            wall = cpu.get("tasks_wall", math.nan)
            share = (f" ({cpu['tasks'] / wall:.0%} of their {wall:.1f} s on the clock; other processes "
                     f"had the rest)" if wall > 0 else "")
            lines.append(f"CPU while computing: {cpu['tasks']:.1f} s in the tasks{share}, {cpu['client']:.1f} s "
                         f"in this process; the runs need {need:.1f} s of it at the runner's cost: "
                         f"{need / used:.0%} (the rest is the sweep's own work)")
    peak = result.peak_rss or {}
    load = (f"; load average {', '.join(f'{x:.2f}' for x in result.load)} at the start"
            if result.load else "")
    lines.append(f"peak RSS {_mb(peak.get('client'))} in this process"
                 + (f", {_mb(peak.get('worker'))} in the largest worker" if peak.get("worker") is not None else "")
                 + load)
    return lines


def format_summary(result):
    """The printed table."""
    n = len(next(iter(result.runs.values())))
    head = (f"{PROG}: {n} runs per scenario on {result.workers}, backend {result.options['backend']}, "
            f"{sum(len(v) for v in result.runs.values())} runs in {result.elapsed:.1f} s")
    lines = [head, "spreads: " + ("; ".join(s.describe() for s in result.spreads) or "none")]
    cols = ["runs", "ok", "stop", "div", "sat", "inv"] + [f"p{p}" for p in PERCENTILES] + ["worst"]
    k = len(COUNTED) + 1
    width = max(12, *(len(s) for s in result.scenarios))
    lines.append(f"{'':<{width}}  {'':>{6 * k - 1}}  {'e_rms [nm]':^38}  {'e_r [%]':^38}")
    lines.append(f"{'scenario':<{width}}  " + " ".join(f"{c:>5}" for c in cols[:k]) + "  "
                 + " ".join(f"{c:>7}" for c in cols[k:]) + "  "
                 + " ".join(f"{c:>7}" for c in cols[k:]))
    for row in summary_rows(result):
        counts = [row["runs"]] + [row[s] for s in COUNTED]
        e = [row[f"e_rms_p{p}_nm"] for p in PERCENTILES] + [row["e_rms_worst_nm"]]
        r = [row[f"e_r_p{p}_%"] for p in PERCENTILES] + [row["e_r_worst_%"]]
        lines.append(f"{row['scenario']:<{width}}  " + " ".join(f"{c:>5}" for c in counts) + "  "
                     + " ".join(f"{x:>7.3g}" for x in e) + "  " + " ".join(f"{x:>7.3g}" for x in r))
    lines.append("stop: stopped by the controller's supervision (the reason names the signal at fault), "
                 "div: diverged (divergence monitor, overflow or error above the reference), "
                 "sat: clipped persistently, inv: parameters refused by the FMU; percentiles over the ok runs")
    lines += _throughput_lines(result)
    return "\n".join(lines) + "\n"


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    v = float(v)
    if math.isnan(v):
        return "nan"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    text = repr(v)
    return text if any(ch in text for ch in ".en") else text + ".0"


def write_parameter_file(path, scenario, params, title, options=None):
    """Write ``params`` as a scenario file: a parameter set ``<stem>`` keyed by FMU variable
    names and a scenario ``<stem>`` that extends ``scenario`` with it."""
    path = Path(path)
    name = path.stem
    lines = [f"# {title}", "# Rerun: python -m harness run " + name + " --scenario-file " + path.name, "",
             f"[parameter_sets.{name}]"]
    lines += [f'"{k}" = {_toml_value(v)}' for k, v in params.items()]
    lines += ["", "[[scenario]]", f'name = "{name}"', f'extends = "{scenario}"',
              f'plant_set = "{name}"', f'description = "{title}"']
    if options and options.get("adaptation") is False:
        lines.append('controller = { "rls.enabled" = false }')
    path.write_text("\n".join(lines) + "\n")
    return path


def write_outputs(result, out_dir, plots=True):
    """Write the CSV/Markdown tables, the runs, the worst parameter files and the plot."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    rows = summary_rows(result)
    with open(out / "sweep_summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written.append(out / "sweep_summary.csv")
    md = ["| scenario | runs | " + " | ".join(COUNTED) + " | "
          + " | ".join(f"e_rms p{p} [nm]" for p in PERCENTILES) + " | e_rms worst [nm] | "
          + " | ".join(f"e_r p{p} [%]" for p in PERCENTILES) + " | e_r worst [%] |",
          "|" + "---|" * (2 + len(COUNTED) + 2 * (len(PERCENTILES) + 1))]
    for r in rows:
        vals = [r["scenario"], r["runs"]] + [r[s] for s in COUNTED]
        vals += [f"{r[f'e_rms_p{p}_nm']:.3g}" for p in PERCENTILES] + [f"{r['e_rms_worst_nm']:.3g}"]
        vals += [f"{r[f'e_r_p{p}_%']:.3g}" for p in PERCENTILES] + [f"{r['e_r_worst_%']:.3g}"]
        md.append("| " + " | ".join(str(v) for v in vals) + " |")
    (out / "sweep_summary.md").write_text(
        format_summary(result).splitlines()[0] + "\n\n" + "\n".join(md) + "\n")
    written.append(out / "sweep_summary.md")

    written.append(result.store.write_sorted(out / RUNS))

    for name in result.scenarios:
        i = result.worst(name)
        if i is not None:
            e = float(result.store.e_rms[name][i])
            title = (f"worst run of the sweep of {name}: run {i}, e_rms = {e * 1e3:.6g} nm "
                     f"(master {result.options['master']}, preview {result.options['preview']})")
            written.append(write_parameter_file(out / f"worst_{name}.toml", name,
                                                result.parameters[name][i], title, result.options))
        codes = result.store.status[name]
        bad = np.flatnonzero(np.isin(codes, [STATUS_CODE[s] for s in ("stopped", "diverged", "saturated")]))
        if bad.size:
            j = int(bad[0])
            title = f"first {STATUSES[codes[j]]} run of the sweep of {name}: run {j}"
            written.append(write_parameter_file(out / f"failed_{name}.toml", name,
                                                result.parameters[name][j], title, result.options))
    if plots:
        written.append(plot_errors(result, out / "sweep_e_rms.png"))
    if out.resolve() == result.store.folder.resolve() and result.store.path.name == JOURNAL:
        # the sorted table is written: the sweep is complete, its journal is no longer needed
        manifest = read_manifest(out)
        if manifest is not None:
            write_manifest(out, manifest["identity"], complete=True)
        journal = result.store.path
        result.store.adopt(out / RUNS)
        journal.unlink(missing_ok=True)
    return written
