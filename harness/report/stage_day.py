"""The report's stage day: one stage's day of use under the controller's defaults, with its
estimates fixed at the nominal model, and under the paper's law, through PiezoStageClosedLoop at a
variable communication step (docs/stage_day.md; the whole family: ``python -m harness stage-day``).

The stage is the fourth the identification family draws (``harness.studies.stage_day_table``'s family, seed
2026), with the paper's sensor (1 nm rms on the 2 nm grid): the one on which issue 43 found the
robust update of issue 35 bursting after a few raster frames. Its day (:data:`REPORT_PARTS`):
60 frames of a 10 Hz, 10 um raster with 0.5 s dwells, 60 s of a 1 Hz tone then a 10 um step, and
the fresh step the step after the tone is compared with. The figures: the worst error of every
frame over the day (:func:`day_frames_figure`), and the estimates over the day with the admissible
set drawn (:func:`day_estimates_figure`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import csv
import math
import time as _time

import numpy as np

from ..studies import stage_day_table as sd
from ..studies.stage_use_table import draw_stages
from ..fmu import FMUError
from ..masters import simulate_closed_loop_fmu_steps
from ..scenarios import PAPER_LAW_SET, parameter_set
from ..text_tables import fmt

__all__ = ["REPORT_STAGE", "REPORT_SENSOR_NM", "REPORT_PARTS", "DAY_LAWS", "DayRun", "run_stage_day",
           "stage_day_table_rows", "write_stage_day_csv", "day_frames_figure", "day_estimates_figure",
           "STAGE_DAY_NOTES"]

#: the family's stage (index) and sensor of the report's day
REPORT_STAGE, REPORT_SENSOR_NM = 3, 1
#: the parts of the report's day
REPORT_PARTS = (sd.raster_part(10.0, 0.5, frames=60), sd.tone_part(1.0, 60.0), sd.FRESH)
#: the laws: the defaults, the estimates fixed at the nominal model, the paper's law
DAY_LAWS = ("ours", "fixed", "paper")

STAGE_DAY_NOTES = (
    "ours: the controller's defaults (the robust update with its admissible set and the fallback "
    "to the nominal model); fixed: the same with rls.enabled = false (the nominal model, no "
    "adaptation); paper: the paper's law (paper_law of harness/scenarios/stage_use.toml).",
    "frames: the worst |y_d − y| of each raster frame (2 s of a 10 Hz, 10 µm triangle, 0.5 s "
    "dwells between them); growth: the worst frame after the first over the worst of frames 2-11; "
    "step after tone: the 10 µm step's worst error after 60 s of a 1 Hz tone, over the fresh step's.",
    "outside the set: communication points whose estimates (est.a1 .. est.b2) are outside the "
    "admissible set (docs/model.md); fallbacks: est.fallbacks at the end.",
)


@dataclass
class DayRun:
    """One part of the report's day under one law."""

    part: str
    law: str
    worst: list = field(default_factory=list)     # per motion segment [um]
    kinds: list = field(default_factory=list)
    outside: int = 0
    fallbacks: int = 0
    error: str = ""
    seconds: float = 0.0
    data: object = None                          # the rows (kept for the figures)


def _controller(law):
    if law == "paper":
        return parameter_set(PAPER_LAW_SET)
    return {"rls.enabled": False} if law == "fixed" else {}


def run_stage_day(*, fmu_dir=None, fmi_version=2, keep_data=True, progress=None):
    """Run the report's day (:data:`REPORT_PARTS` under :data:`DAY_LAWS`): a list of :class:`DayRun`."""
    stage = draw_stages(REPORT_STAGE + 1, sd.SEED)[REPORT_STAGE]
    plant = sd.stage_plant(stage, REPORT_STAGE, REPORT_SENSOR_NM)
    C, d = sd.admissible_rows()
    out = []
    for part in REPORT_PARTS:
        for law in DAY_LAWS:
            sc = part.scenario(plant, _controller(law))
            t0 = _time.perf_counter()
            run = DayRun(part.name, law)
            log = []
            try:
                rows = simulate_closed_loop_fmu_steps(sc, fmu_dir=fmu_dir, fmi_version=fmi_version, log=log)
            except FMUError as exc:
                run.error = str(exc)
            else:
                run.fallbacks = sd._fallbacks(log)
                k = np.rint(rows["time"] / sd.H).astype(np.int64)
                err = np.abs(rows["y_d"] - rows["y"])
                for a, b, kind in sd._segments_of(sc.signal):
                    sel = (k >= a) & (k < b)
                    run.worst.append(float(np.max(err[sel])) if sel.any() else math.nan)
                    run.kinds.append(kind)
                if law == "ours":
                    theta = np.column_stack([rows["a1"], rows["a2"], rows["b1"], rows["b2"]])
                    run.outside = int(np.count_nonzero(sd.outside_admissible(theta, C, d)))
                run.data = rows if keep_data else None
            run.seconds = _time.perf_counter() - t0
            if progress is not None:
                progress.done(f"stage day / {part.name} / {law}", run.seconds)
            out.append(run)
    return out


def _find(runs, part, law):
    return next((r for r in runs if r.part == part and r.law == law), None)


def stage_day_table_rows(runs):
    """(head, rows) of the report's table: per law, the raster's frames and the step after the tone."""
    raster, tone, fresh = (p.name for p in REPORT_PARTS)
    head = ["law", "first frame [nm]", "frames 2-11, worst [nm]", "later frames, worst [nm]", "growth",
            "step after the tone / fresh", "outside the set", "fallbacks"]
    rows = []
    for law in DAY_LAWS:
        r, t, f = _find(runs, raster, law), _find(runs, tone, law), _find(runs, fresh, law)
        if r is None or r.error:
            rows.append([law, "stopped: " + (r.error[:80] if r else "-")] + ["-"] * 6)
            continue
        frames = np.array(r.worst) * 1e3
        ref = float(np.nanmax(frames[1:11]))
        later = float(np.nanmax(frames[11:])) if len(frames) > 11 else math.nan
        ratio = "-" if t is None or f is None or t.error or f.error else fmt(t.worst[-1] / f.worst[-1], ".3g")
        fallbacks = str(r.fallbacks + (t.fallbacks if t is not None else 0)) if law == "ours" else "-"
        rows.append([law, fmt(frames[0], ".3g"), fmt(ref, ".3g"), fmt(later, ".3g"), fmt(max(ref, later) / ref, ".3g"), ratio,
                     str(r.outside) if law == "ours" else "-", fallbacks])
    return head, rows


def write_stage_day_csv(runs, path):
    """Every part's segments under every law: the worst error [um] of each."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["part", "law", "segment", "kind", "worst_um", "error"])
        for r in runs:
            if r.error:
                w.writerow([r.part, r.law, "", "", "", r.error[:200]])
            for i, (x, kind) in enumerate(zip(r.worst, r.kinds), start=1):
                w.writerow([r.part, r.law, i, kind, f"{x:.6g}", ""])
    return path


def day_frames_figure(runs, out_dir):
    """The worst error of every raster frame over the report's day, each law (log scale)."""
    from .figures import FigureFile, _pyplot, _save
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 3.2))
    raster = REPORT_PARTS[0].name
    for law, style in zip(DAY_LAWS, ("-o", "--s", ":^")):
        r = _find(runs, raster, law)
        if r is None or r.error or not r.worst:
            continue
        frames = np.array(r.worst) * 1e3
        ax.semilogy(np.arange(1, len(frames) + 1), frames, style, ms=3, label=law)
    ax.set_xlabel("raster frame (2 s of a 10 Hz, 10 µm triangle; 0.5 s dwells)")
    ax.set_ylabel("worst |y_d − y| [nm]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    caption = ("The worst error of every frame of 60 raster frames on the family's fourth stage (1 nm "
               "sensor): the defaults (ours) against the estimates fixed at the nominal model and the "
               "paper's law.")
    return _save(plt, fig, out_dir, "stage_day_frames", caption, title="A stage's day: raster frames")


def _poles(a1, a2):
    disc = a1 * a1 - 4.0 * a2
    root = np.sqrt(np.abs(disc))
    real = disc >= 0
    slow = np.where(real, (-a1 + root) / 2.0, -a1 / 2.0)
    fast = np.where(real, (-a1 - root) / 2.0, -a1 / 2.0)
    return slow, fast


def day_estimates_figure(runs, out_dir, nominal):
    """The estimates over the report's day (the defaults), as the admissible set bounds them: the zero
    of B, the poles of A, b1 and the static gain over the nominal model's, with the set's bounds."""
    from .figures import _pyplot, _save
    from ..binding.core import default_controller_params
    p = {**default_controller_params(), **(nominal or {})}
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 7.0), sharex=True)
    t_off, ticks = 0.0, []
    kn = (p["tf.b1"] + p["tf.b2"]) / (1.0 + p["tf.a1"] + p["tf.a2"])
    for part in REPORT_PARTS:
        r = _find(runs, part.name, "ours")
        if r is None or r.error or r.data is None:
            continue
        rows = r.data
        t = rows["time"] + t_off
        a1, a2, b1, b2 = rows["a1"], rows["a2"], rows["b1"], rows["b2"]
        slow, fast = _poles(a1, a2)
        axes[0].plot(t, -b2 / b1, lw=0.8, color="C0")
        axes[1].plot(t, slow, lw=0.8, color="C1")
        axes[1].plot(t, fast, lw=0.8, color="C2")
        axes[2].plot(t, b1 / p["tf.b1"], lw=0.8, color="C3")
        axes[2].plot(t, ((b1 + b2) / (1.0 + a1 + a2)) / kn, lw=0.8, color="C4")
        ticks.append((t_off, part.name))
        t_off = float(t[-1]) + 1.0
    axes[0].axhline(min(p["rls.zero_min"], -p["tf.b2"] / p["tf.b1"]), ls="--", color="k", lw=0.8)
    axes[0].axhline(0.999, ls="--", color="k", lw=0.8)
    axes[0].set_ylabel("zero of B")
    axes[1].axhline(p["rls.pole_min"], ls="--", color="k", lw=0.8)
    axes[1].axhline(1.0, ls="--", color="k", lw=0.8)
    axes[1].set_ylabel("poles of A\n(slow, fast)")
    axes[2].axhline(p["sup.gain_min"], ls="--", color="k", lw=0.8)
    axes[2].axhline(p["sup.gain_max"], ls="--", color="k", lw=0.8)
    axes[2].set_yscale("log")
    axes[2].set_ylabel("b1, static gain\n/ nominal")
    axes[2].set_xlabel("time over the day's parts [s] (raster, tone then step, fresh step)")
    for ax, names, where in ((axes[1], ("slow pole", "fast pole"), "center right"),
                             (axes[2], ("b1", "static gain"), "lower right")):
        if ticks:               # the first part's two curves name the colours
            ax.legend(ax.get_lines()[:2], names, loc=where, frameon=True, framealpha=0.85)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        for x, _ in ticks[1:]:
            ax.axvline(x, color="grey", lw=0.5)
    caption = ("The estimates the law used over the report's day (the defaults), dashed: the admissible "
               "set's bounds (rls.zero_min, or the nominal zero where that is lower, and 0.999 on the zero, rls.pole_min and 1 on the poles, "
               "sup.gain_min and sup.gain_max on b1 and the static gain over the nominal model's). The "
               "set holds the hull of the poles too; a pair of complex poles shows as one line.")
    return _save(plt, fig, out_dir, "stage_day_estimates", caption, title="A stage's day: the estimates")
