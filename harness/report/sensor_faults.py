"""The report's sensor faults: a sensor that stops answering on the report's stage, how soon the
supervision names it and what the stage does meanwhile and after (docs/robustness.md, "A sensor
that stops answering"; the whole family: ``python -m harness supervision stuck``).

The stage is the report's day's (:data:`harness.report.stage_day.REPORT_STAGE`), run on the C core
in an exchange (:func:`harness.studies.supervision_table.run_stuck`) with ``sup.reaction`` = 1, so that the
run goes on in the safe state after the verdict (v ramps to 0 V). The cases
(:data:`REPORT_CASES`): every :data:`harness.studies.supervision_table.STUCK_CASES` case with the paper's
sensor (1 nm rms) and with a 20 nm one. The figure (:func:`sensor_faults_figure`) shows two of them
around their onset. Leaving the safe state (:func:`run_resets`): every
:data:`harness.studies.supervision_table.RESET_CASES` case on the same stage with a 20 nm sensor, a reset
raised while the cause persists and one after it is gone (docs/robustness.md, "Leaving the safe
state"; the family: ``python -m harness supervision reset``); the figure (:func:`reset_figure`)
shows the stuck sensor's.
"""

from __future__ import annotations

import numpy as np

from ..studies import supervision_table as st
from .stage_day import REPORT_STAGE

__all__ = ["REPORT_SENSORS_NM", "REPORT_CASES", "FIGURE_CASES", "run_sensor_faults", "sensor_fault_rows",
           "sensor_faults_figure", "SENSOR_FAULT_NOTES", "RESET_SENSOR_NM", "run_resets", "reset_rows",
           "reset_figure", "RESET_NOTES"]

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
    :func:`harness.studies.supervision_table.run_stuck`, with their traces)."""
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


#: the sensor [nm rms] of the reset cases (a 1 nm sensor stuck in a hold is not seen: no safe state)
RESET_SENSOR_NM = 20
RESET_NOTES = (
    "sup.reaction = 1; sup.reset is raised at 2.6 s while the cause persists and at 3 s after it is "
    "gone (2.8 s), as a system model's operator would, its rising edge acted on at that sample. "
    "Step: the 10 µm step at 3.5 s, its largest |y_d − y| over 0.25 s against the same run's without "
    "a fault.",
    "A fault of the response (an amplifier still inverted) cannot be seen at rest: the reset is "
    "accepted and the restarted supervision stops the loop again, as at a fresh start.",
)


#: the report's words for a refusal, by a phrase of its message (piezo_controller_explain_reset)
REFUSALS = (("y_meas still reads", "y_meas still reads the verdict's value"),
            ("is still beyond what the stage reached", "the reference still beyond the reading at the rail"),
            ("still ramping", "v still ramping to 0 V"), ("is not finite", "an input not finite"))


def run_resets(plant=None):
    """Every reset case on the report's stage with the :data:`RESET_SENSOR_NM` sensor:
    ``[(case, result, step of the same run without a fault), ...]`` (with their traces)."""
    plant = plant or st._day_plant(REPORT_STAGE, RESET_SENSOR_NM)
    base = st.run_reset(st.RESET_BASELINE, plant)["step"]
    return [(case, st.run_reset(case, plant, keep=True), base) for case in st.RESET_CASES]


def reset_rows(runs):
    """The report's reset table: (head, rows)."""
    def said(outcome):
        if outcome is None:
            return "-"
        accepted, text = outcome
        if accepted:
            return "accepted"
        why = next((w for key, w in REFUSALS if key in text), text)
        return "refused: " + why
    head = ["case", "verdict", "reset at 2.6 s (cause persists)", "reset at 3 s", "after the restart"]
    rows = []
    for case, r, base in runs:
        after = (f"stopped again ({r['again']}) after {1e3 * r['again_time']:.1f} ms" if r["again"]
                 else f"step {r['step'] / base:.3f} × the fault-free run's")
        rows.append([case.name, r["fault"] or "none", said(r["early"]), said(r["late"]), after])
    return head, rows


def reset_figure(runs, out_dir):
    """The stuck sensor's run: y_d, y and the y_meas received from before the fault to after the
    step, the verdict and both resets marked, and v below."""
    from .figures import _pyplot, _save
    plt = _pyplot()
    case, r, _ = runs[0]
    t, y_d, y, ym, v = r["trace"]
    sel = t >= st.RESET_TIMES["fault"] - 0.1
    fig, (ax, axv) = plt.subplots(2, 1, figsize=(9.0, 5.0), sharex=True, gridspec_kw={"height_ratios": (2, 1)})
    ax.plot(t[sel], y_d[sel], "k--", lw=1, label="y_d")
    ax.plot(t[sel], y[sel], "-", lw=1.2, label="y (the stage)")
    ax.plot(t[sel], ym[sel], ":", lw=1.2, label="y_meas received")
    axv.plot(t[sel], v[sel], "-", lw=1)
    marks = ((st.RESET_TIMES["fault"], f"sensor stuck ({r['fault']})", "r"),
             (st.RESET_TIMES["early"], "sup.reset: refused", "tab:orange"),
             (st.RESET_TIMES["cleared"], "sensor back", "0.4"),
             (st.RESET_TIMES["late"], "sup.reset: accepted", "g"))
    top = float(np.max(y_d[sel]))
    for at, label, color in marks:
        for a in (ax, axv):
            a.axvline(at, color=color, lw=0.8)
        ax.annotate(label, (at, top), fontsize=7, color=color, rotation=90, xytext=(3, -4),
                    textcoords="offset points", va="top")
    ax.set_title(f"{case.name}, {RESET_SENSOR_NM} nm sensor, sup.reaction = 1", fontsize=9)
    ax.set_ylabel("[µm]")
    axv.set_ylabel("v [V]")
    axv.set_xlabel("time [s]")
    for a in (ax, axv):
        a.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="center right")
    caption = ("Leaving the safe state: the stuck sensor's verdict ramps v to 0 V; a reset while the reading "
               "is still stuck is refused; once the sensor is back a reset restarts the loop from the stage's "
               "rest, v ramping from 0 V, and the step after it is the fault-free run's.")
    return _save(plt, fig, out_dir, "fault_reset", caption, title="Leaving the safe state (sup.reset)")
