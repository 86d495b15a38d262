"""The report's stage use: the built-in stage-use scenarios (harness/scenarios/stage_use.toml),
each run with the controller's defaults and with the paper's law, side by side.

Each runs through PiezoStageClosedLoop at a variable communication step
(:func:`harness.masters.closed_loop_fmu.simulate_closed_loop_fmu_steps`: one sample per step
while y_d moves and for :data:`harness.loop.profiles.SETTLE` after, 10 ms steps while it holds,
the rows of one-sample steps at those points), so a minute's hold costs a fraction of a
second. The metrics are :mod:`harness.loop.profiles`': the worst error after each move, the worst
``|y - y_d|`` during holds (at the communication points), and a scan frame after a dwell
against the last second before it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import csv
import math
import time as _time

import numpy as np

from ..loop import profiles
from ..masters import simulate_closed_loop_fmu_steps
from ..scenarios import PAPER_LAW_SET, get_scenario, parameter_set, stage_use_scenarios
from ..text_tables import fmt, num, titled_table

__all__ = ["HOLD_STEP", "LAWS", "StageUseRun", "run_stage_use", "stage_use_table_rows",
           "format_stage_use_table", "write_stage_use_csv", "STAGE_USE_NOTES"]

#: [s] the communication step while y_d holds
HOLD_STEP = 0.01
#: the two laws each scenario runs with: the controller's defaults, and the paper's set
LAWS = ("ours", "paper")
#: the warnings of the controller that are its supervision's (harness.studies.supervision_table's words)
_SUPERVISION_WARNINGS = ("is not connected (", "cannot be aligned")

STAGE_USE_NOTES = (
    "ours: the controller's defaults (the robust adaptation: the estimates adapt while the "
    "reference excites the loop and hold while the stage holds still, integral action); paper: "
    "the same scenario with the parameter set paper_law of harness/scenarios/stage_use.toml "
    "(rls.robust = false, rls.forgetting 0.995, rls.trace_max 100, mv.integral 0: the paper's "
    "update every sample).",
    "moves: the worst |y_d − y| from a move's first sample to 0.5 s after its last, one number "
    "per move in order. holds: the worst |y − y_d| from 0.5 s after a motion to the next one, "
    "read at the communication points (every 10 ms in a hold). scan after dwell / before: the "
    "worst error of the frame after the dwell / of the last second before the dwell.",
    "a1 before: est.a1 at the last communication point before the last motion (the plant's "
    "own a1 is −1.442, the controller's model −1.377; RLS identifies the loop, whose "
    "effective a1 differs from both). warnings: the controller's, per run (pred_error beyond "
    "its bound, v clipped, delay detection restarted; supervision: its verdicts on the wiring).",
)


@dataclass
class StageUseRun:
    """One stage-use scenario under one law: its metrics and (when kept) its rows."""

    scenario: str
    law: str
    description: str
    moves: list
    holds: list
    scans: list
    a1_before: float
    warnings: list
    n_points: int
    n_samples: int
    elapsed_s: float
    data: object = field(default=None, repr=False)
    spec: object = field(default=None, repr=False)

    @property
    def worst_hold(self):
        """The worst ``|y - y_d|`` over every hold window [um] (nan: none)."""
        values = [h.worst for h in self.holds if math.isfinite(h.worst)]
        return max(values) if values else math.nan

    @property
    def supervision_warnings(self):
        return [w for w in self.warnings if any(words in w for words in _SUPERVISION_WARNINGS)]


def _a1_before(signal, data, h):
    """est.a1 at the last row before the profile's last motion (nan: no motion)."""
    motions = profiles.motions(signal)
    if not motions:
        return math.nan
    k = profiles.sample_index(data["time"], h)
    before = np.flatnonzero(k < motions[-1][1].first)
    return float(data["a1"][before[-1]]) if before.size else math.nan


def run_stage_use(names=None, *, registry=None, fmu_dir=None, fmi_version=2, keep_data=True,
                  progress=None):
    """Run stage-use scenarios under both laws.

    Parameters
    ----------
    names : list of str, optional
        Scenarios with a profile reference (default: the built-in stage-use scenarios).
    registry : dict, optional
    fmu_dir : str or Path, optional
    fmi_version : {2, 3}
    keep_data : bool
        Keep each run's rows (for the figures).
    progress : harness.progress.Progress, optional
        Told of every finished run.

    Returns
    -------
    list of StageUseRun
        Per scenario, ours then the paper's.
    """
    names = stage_use_scenarios(registry) if names is None else list(names)
    paper = parameter_set(PAPER_LAW_SET)
    out = []
    for name in names:
        sc = get_scenario(name, registry)
        h = sc.step_size
        for law in LAWS:
            t0 = _time.perf_counter()
            log = []
            data = simulate_closed_loop_fmu_steps(sc, hold_step=HOLD_STEP, settle=profiles.SETTLE,
                                                  controller_params=paper if law == "paper" else None,
                                                  fmu_dir=fmu_dir, fmi_version=fmi_version, log=log)
            args = (sc.signal, data["time"], data["y_d"], data["y"], h)
            run = StageUseRun(
                name, law, sc.description.removeprefix("stage use: "),
                profiles.move_errors(*args), profiles.hold_errors(*args), profiles.scan_errors(*args),
                _a1_before(sc.signal, data, h),
                [w.removeprefix("[Warning] ") for w in log if w.startswith("[Warning]")],
                data.size, sc.n_samples, _time.perf_counter() - t0,
                data if keep_data else None, sc)
            out.append(run)
            if progress is not None:
                moves = ", ".join(f"{m.worst:.3g}" for m in run.moves) or "-"
                progress.done(f"stage use / {name} ({law}): moves {moves} µm", run.elapsed_s)
    return out


def _pairs(runs):
    by = {}
    for r in runs:
        by.setdefault(r.scenario, {})[r.law] = r
    return by


def _moves_text(run):
    return ", ".join(fmt(m.worst, ".3g") for m in run.moves) or "-"


def _worst_move(run):
    values = [m.worst for m in run.moves if math.isfinite(m.worst)]
    return fmt(max(values), ".3g") if values else "-"


def _scan_text(run):
    return ", ".join(f"{s.worst * 1e3:.3g} / {s.steady * 1e3:.3g}" for s in run.scans) or "-"


def stage_use_table_rows(runs, compact=False):
    """Head and rows of the stage-use table: one row per scenario, ours next to the paper's.
    ``compact`` (the terminal's, within 100 characters): the worst move only, no a1 and no
    warning counts."""
    rows = []
    if compact:
        head = ["scenario", "move µm ours", "paper", "hold nm ours", "paper", "scan nm ours",
                "paper"]
        for name, pair in _pairs(runs).items():
            o, p = pair["ours"], pair["paper"]
            rows.append([name, _worst_move(o), _worst_move(p), fmt(o.worst_hold * 1e3, ".3g"),
                         fmt(p.worst_hold * 1e3, ".3g"), _scan_text(o), _scan_text(p)])
        return head, rows
    head = ["scenario", "moves [µm] ours", "paper", "holds [nm] ours", "paper",
            "scan after dwell / before [nm] ours", "paper", "a1 before ours", "paper",
            "warnings ours", "paper"]
    for name, pair in _pairs(runs).items():
        o, p = pair["ours"], pair["paper"]
        rows.append([name, _moves_text(o), _moves_text(p), fmt(o.worst_hold * 1e3, ".3g"),
                     fmt(p.worst_hold * 1e3, ".3g"), _scan_text(o), _scan_text(p),
                     fmt(o.a1_before, ".4g"), fmt(p.a1_before, ".4g"), str(len(o.warnings)),
                     str(len(p.warnings))])
    return head, rows


def format_stage_use_table(runs, title=None, markdown=False):
    """The stage-use table as aligned text within 100 characters (``compact`` rows), or the
    whole table in Markdown."""
    head, rows = stage_use_table_rows(runs, compact=not markdown)
    return titled_table(head, rows, title, markdown)


def write_stage_use_csv(runs, path):
    """One line per window of every run: scenario, law, what (move, hold, scan), its samples,
    the worst error [um] (and a scan's steady one), full precision."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["scenario", "law", "what", "first_sample", "stop_sample", "worst_um",
                    "steady_um", "a1_before", "warnings"])
        for r in runs:
            for what, items in (("move", r.moves), ("hold", r.holds), ("scan", r.scans)):
                for x in items:
                    w.writerow([r.scenario, r.law, what, x.first, x.stop, num(x.worst),
                                num(getattr(x, "steady", None)), num(r.a1_before), len(r.warnings)])
    return path
