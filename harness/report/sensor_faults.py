"""The report's sensor faults: a sensor that stops answering on the report's stage, how soon the
supervision names it and what the stage does meanwhile and after (docs/robustness.md, "A sensor
that stops answering"; the whole family: ``python -m harness.supervision_table stuck``).

The stage is the report's day's (:data:`harness.report.stage_day.REPORT_STAGE`), run on the C core
in an exchange (:func:`harness.supervision_table.run_stuck`) with ``sup.reaction`` = 1, so that the
run goes on in the safe state after the verdict (v ramps to 0 V). The cases
(:data:`REPORT_CASES`): every :data:`harness.supervision_table.STUCK_CASES` case with the paper's
sensor (1 nm rms) and with a 20 nm one. The figure (:func:`sensor_faults_figure`) shows two of them
around their onset.
"""

from __future__ import annotations

import numpy as np

from .. import supervision_table as st
from .stage_day import REPORT_STAGE

__all__ = ["REPORT_SENSORS_NM", "REPORT_CASES", "FIGURE_CASES", "run_sensor_faults", "sensor_fault_rows",
           "sensor_faults_figure", "SENSOR_FAULT_NOTES"]

#: the sensors [nm rms] of the report's cases
REPORT_SENSORS_NM = (1, 20)
#: the cases (every case but the legitimate runs)
REPORT_CASES = tuple(c for c in st.STUCK_CASES if c.reads != "none")
#: the cases the figure draws: (case name, sensor)
FIGURE_CASES = (("stuck mid-scan", 1), ("dead (reads 0) in a hold", 20))
SAFE = {"sup.reaction": 1}

SENSOR_FAULT_NOTES = (
    "Run on the C core in an exchange, the controller at its defaults with sup.reaction = 1 (safe): "
    "after the verdict v ramps to 0 V over 10 ms and the run goes on. Time: from the sensor's failure "
    "to the verdict; excursion: the largest |y_d − y| from the failure to the verdict.",
    "The targets of issue 44: named within 20 ms in motion and 0.2 s in a hold, the stage within "
    "2 µm beyond the reference in a scan and 0.1 µm of the set-point in a hold. A quiet sensor stuck "
    "where the stage holds is what nothing can see: it runs on, the stage drifting by its creep.",
)


def run_sensor_faults(plant_of=None):
    """Every report case with every report sensor: ``[(case, nm, result), ...]`` (the results of
    :func:`harness.supervision_table.run_stuck`, with their traces)."""
    plant_of = plant_of or (lambda nm: st._day_plant(REPORT_STAGE, nm))
    return [(case, nm, st.run_stuck(case, plant_of(nm), SAFE, keep=True))
            for case in REPORT_CASES for nm in REPORT_SENSORS_NM]


def sensor_fault_rows(runs):
    """The report's table: (head, rows)."""
    head = ["case", "sensor [nm rms]", "verdict", "time [ms]", "excursion [µm]"]
    rows = []
    for case, nm, r in runs:
        named = bool(r["fault"])
        rows.append([case.name, f"{nm:g}", r["fault"] or "none (runs on)",
                     f"{1e3 * r['time']:.1f}" if named else "-", f"{r['excursion']:.3g}"])
    return head, rows


def sensor_faults_figure(runs, out_dir):
    """y_d, y and the y_meas the controller received around the onset of :data:`FIGURE_CASES`, the
    verdict marked, and v below."""
    from .figures import _pyplot, _save
    plt = _pyplot()
    fig, axes = plt.subplots(2, len(FIGURE_CASES), figsize=(9.0, 5.0), sharex="col",
                             gridspec_kw={"height_ratios": (2, 1)})
    for col, (name, nm) in enumerate(FIGURE_CASES):
        case, _, r = next(x for x in runs if x[0].name == name and x[1] == nm)
        t, y_d, y, ym, v = r["trace"]
        onset = st.STUCK_HOLD_ONSET if case.where == "hold" else st.STUCK_SCAN_ONSET
        sel = (t >= onset - 0.02) & (t <= onset + 0.06)
        ms = (t[sel] - onset) * 1e3
        ax, axv = axes[0][col], axes[1][col]
        ax.plot(ms, y_d[sel], "k--", lw=1, label="y_d")
        ax.plot(ms, y[sel], "-", lw=1.2, label="y (the stage)")
        ax.plot(ms, ym[sel], ":", lw=1.2, label="y_meas received")
        axv.plot(ms, v[sel], "-", lw=1)
        if r["fault"]:
            for a in (ax, axv):
                a.axvline(1e3 * r["time"], color="r", lw=0.8)
            ax.annotate(f"{r['fault']} at {1e3 * r['time']:.1f} ms", (1e3 * r["time"], float(np.max(y_d[sel]))),
                        fontsize=7, color="r", xytext=(4, -10), textcoords="offset points")
        ax.set_title(f"{name}, {nm:g} nm sensor", fontsize=9)
        ax.set_ylabel("[µm]")
        axv.set_ylabel("v [V]")
        axv.set_xlabel("time from the failure [ms]")
        ax.grid(True, alpha=0.3)
        axv.grid(True, alpha=0.3)
        if col == 0:
            ax.legend(fontsize=7)
    caption = ("A sensor that stops answering on the report's stage: the verdict (red) comes within "
               "milliseconds; with sup.reaction = 1 v then ramps to 0 V and the stage relaxes.")
    return _save(plt, fig, out_dir, "sensor_faults", caption, title="A sensor that stops answering")
