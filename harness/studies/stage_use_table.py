"""The stage-use family: issue 35's targets measured on the stages of the identification family.

::

    python -m harness stage-use                            # the family, Markdown on stdout
    python -m harness stage-use --write docs/stage_use.md  # into the page, between its markers
    python -m harness stage-use --stages 3 --quick         # a slice, in a minute

**The family** (:func:`family_tasks`): the stages :func:`harness.identify.family.draw_stage`
draws (seed 2026), each with a sensor of 0, 1, 5 and 20 nm rms noise on the 2 nm grid
(``sensor.seed`` = stage index + 1), under the controller on the nominal model (its
defaults: the robust adaptation) and under the paper's law (the parameter set ``paper_law``
of harness/scenarios/stage_use.toml), on these profiles (:data:`MOVES`, :func:`profiles`):

* a hold of 0.2, 4, 60 s (and 600 s for :data:`LONG_HOLD_MOVES`) then a move: steps and
  S-curves of 1 to 50 um, from 0 and from an offset the stage was moved to;
* a staircase (four 5 um steps up, two 10 um steps down, 2 s on each stair);
* triangle raster scans at 1, 10 and 50 Hz (10 um): a 2 s frame, a 10 s dwell, a 2 s frame;
* a long tone then a step: 60 s of a 1 Hz or a 20 Hz 10 um sine, 0.5 s at rest, a 10 um step.

**The masters**: every run on the native runner's exchange (ModelStructure Gauss-Seidel order,
d = 2); on the first ``--jacobi-stages`` stages the native Jacobi order too (the same samples
with this controller: checked bit for bit); on the first ``--fmu-stages`` the closed-loop FMU at
10 ms steps during holds (its rows are the exchange's at its communication points: checked bit
for bit, its metrics read there); and on the first ``--gs-stages`` stages, with the 1 and 20 nm
sensors, without the 600 s holds and the tones, two true Gauss-Seidel orders (d = 1) of the
wired master (:mod:`harness.masters.wired`, which plays the profile as ReferenceSignal would).

**The targets** (:data:`TARGETS`, issue 35; :mod:`harness.loop.profiles` for the windows):

(a) a move after a hold T (sensors 0, 1, 5 nm): its worst ``|y_d - y|`` (from its start to
    0.5 s after its end) over the same move after a 0.2 s hold with the 1 nm sensor, <= 1.1;
(b) with the 20 nm sensor: over (1.25 x that 1 nm reference + 5 x 0.02 um), <= 1;
(c) a scan frame after a dwell: its worst error over the worst error in the last second before
    the dwell, <= 1.1;
(d) during holds (from 0.5 s after a motion to the next): max ``|y - y_d|`` over
    5 x (noise rms + grid step), <= 1;
(e) no supervision Error and no supervision Warning (the controller's stamps warnings, as
    :mod:`harness.studies.supervision_table` collects them) on the whole family;
(f) the same ratios with the paper's law, to show what changed.

Each target prints PASS or FAIL (against the issue's bound); the command exits 1 when a
measurement of the robust law is worse than the number documented for it in docs/stage_use.md
(:data:`DOCUMENTED`): a regression. Where a target is missed, the worst cases are run again with
the estimates fixed at the nominal model (``rls.enabled = false``), which shows whether the
adaptation or the loop itself makes the miss.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from functools import partial
import itertools
import json
import math
from pathlib import Path
import sys
import time as _time
from types import MappingProxyType

import numpy as np

from ..fmu import FMUError
from ..identify.family import draw_stage
from ..loop import prepare_closed_loop, profiles
from ..masters import (NATIVE_CONTROLLER, missing_runner_message, native_available, native_loop,
                      simulate_closed_loop_fmu_steps, simulate_wired)
from ..scenarios import PAPER_LAW_SET, Scenario, parameter_set, profile_signal
from ..text_tables import markdown_table

__all__ = ["SEED", "SENSORS_NM", "HOLDS", "MOVES", "LONG_HOLD_MOVES", "SCAN_FREQUENCIES",
           "TONE_FREQUENCIES", "GS_ORDERS", "TARGETS", "DOCUMENTED", "Profile", "Task", "RunMetrics",
           "profiles_of", "profile_scenario", "draw_stages", "stage_plant", "family_grid", "hold_band", "family_tasks", "run_task", "run_tasks", "run_family",
           "save_results", "load_results",
           "summarize", "family_markdown", "verdicts", "write_into", "main"]

H = 0.0005
SEED = 2026
GRID = 0.002
SENSORS_NM = (0, 1, 5, 20)
HOLDS = (0.2, 4.0, 60.0, 600.0)
#: the moves after a hold: (the offset the stage is moved to first, or None: from 0; the move)
MOVES = {
    "step +1 um from 0": (None, {"move": 1.0}),
    "step +10 um from 0": (None, {"move": 10.0}),
    "S-curve +50 um in 0.1 s from 0": (None, {"move": 50.0, "shape": "scurve", "time": 0.1}),
    "S-curve +30 um in 50 ms from 10 um": (10.0, {"move": 30.0, "shape": "scurve", "time": 0.05}),
    "step -5 um from 20 um": (20.0, {"move": -5.0}),
}
#: the moves that also follow a 600 s hold (one from 0, one from an offset: the long holds
#: dominate the family's cost)
LONG_HOLD_MOVES = ("step +10 um from 0", "S-curve +30 um in 50 ms from 10 um")
#: how the stage reaches an offset before its hold: an S-curve of 50 ms after 0.2 s at 0
TO_OFFSET = {"shape": "scurve", "time": 0.05}
SCAN_FREQUENCIES = (1.0, 10.0, 50.0)
TONE_FREQUENCIES = (1.0, 20.0)
#: the reference of target (a): the same move after this hold with this sensor
REFERENCE_HOLD, REFERENCE_NM = 0.2, 1
#: the sequential orders of the true Gauss-Seidel master (plant first, controller first)
GS_ORDERS = (("plant", "controller", "reference"), ("reference", "controller", "plant"))
MASTER_EXCHANGE = "native exchange"
MASTER_JACOBI = "native Jacobi"
MASTER_FMU = "closed-loop FMU, 10 ms in holds"
#: the controller's supervision warnings, by their words (as harness.studies.supervision_table)
_SUPERVISION_WARNINGS = ("is not connected (", "cannot be aligned")
_WARNING_KINDS = (("|pred_error| exceeded", "pred_error beyond its bound"),
                  ("was clipped", "v clipped"),
                  ("delay detection restarted", "delay detection restarted"),
                  ("fell back to the nominal model", "the law fell back to the nominal model"))

#: the issue's bound of each target (a ratio; e: a count)
TARGETS = {"a": 1.1, "b": 1.0, "c": 1.1, "d": 1.0, "e": 0}
#: the robust law's worst over the 50-stage family (every master) as docs/stage_use.md documents it,
#: measured by this command on this release's core (2.205, 1.065, 6.412, 1.089, 7 runs; at 14744e4's:
#: 2.818, 1.038, 13.16, 1.089, 5; at 8580b7d's: 7.82, 8.02, 2615, 1.33, 11): a larger value is a
#: regression and exits 1. Where the issue's bound is met, the bound is the limit. Measured again at
#: c22773e (the supervisor's judgement of one-sample evidence) and at aabfd4f, the release before it:
#: 2.377, 1.06, 6.451, 3.119 both, and 0 and 6 runs stopped; (a), (c) and (d) moved between
#: e7fc8f1 and aabfd4f, unmeasured then ((d): the integral held on an unchanged reading). With the
#: integral's gate (bb11c52: held only once a live reading would have changed): 2.377, 1.058, 6.412,
#: 1.089, 0 runs stopped.
DOCUMENTED = {"a": 2.38, "b": 1.06, "c": 6.42, "d": 1.09, "e": 0}


# ---------------------------------------------------------------------------
# the profiles and the runs
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Profile:
    """One profile of the family."""

    name: str
    family: str                 # "move", "staircase", "scan", "tone"
    segments: tuple
    move: str = ""              # a key of MOVES (the move's family), or the tone's step
    hold: float = math.nan      # the hold before the move [s]
    frequency: float = math.nan  # a scan's or a tone's [Hz]
    gs: bool = True             # also run on the true Gauss-Seidel master

    def scenario(self, plant, controller):
        return profile_scenario(self.name, self.segments, plant, controller)


def profile_scenario(name, segments, plant, controller):
    """The tracking scenario of profile segments on the 0.5 ms grid, its error measured over its whole
    length."""
    signal = profile_signal(segments, step=H)
    duration = signal.samples * H
    return Scenario(name, "tracking", name, signal, duration=duration, step_size=H,
                    metric_window=(0.0, duration), plant=MappingProxyType(dict(plant)),
                    controller=MappingProxyType(dict(controller)))


def _move_profile(key, hold):
    offset, move = MOVES[key]
    settle = {"hold": profiles.SETTLE}
    if offset is None:
        segs = ({"hold": hold}, move, settle)
    else:
        segs = ({"hold": REFERENCE_HOLD}, {"to": offset, **TO_OFFSET}, {"hold": hold}, move, settle)
    return Profile(f"{key}, after {hold:g} s", "move", segs, key, hold, gs=hold < 100)


def profiles_of(holds=HOLDS, moves=tuple(MOVES), long_hold_moves=LONG_HOLD_MOVES,
                scans=SCAN_FREQUENCIES, tones=TONE_FREQUENCIES, staircase=True):
    """The family's profiles (:class:`Profile`): every move after every hold below 100 s, the
    ``long_hold_moves`` after the longer ones too, the staircase, the scans, the tones."""
    out = []
    for key in moves:
        for hold in holds:
            if hold < 100 or key in long_hold_moves:
                out.append(_move_profile(key, hold))
    if staircase:
        segs = [{"hold": 0.2}]
        for step in (5.0, 5.0, 5.0, 5.0, -10.0, -10.0):
            segs += [{"move": step}, {"hold": 2.0}]
        out.append(Profile("staircase", "staircase", tuple(segs)))
    for f in scans:
        frame = {"scan": "triangle", "frequency": f, "amplitude": 10.0, "time": 2.0}
        out.append(Profile(f"triangle scan {f:g} Hz, 10 s dwell", "scan",
                           (frame, {"hold": 10.0}, frame), frequency=f))
    for f in tones:
        segs = ({"scan": "sine", "frequency": f, "amplitude": 10.0, "time": 60.0}, {"hold": 0.5},
                {"move": 10.0}, {"hold": profiles.SETTLE})
        out.append(Profile(f"{f:g} Hz tone for 60 s, then a 10 um step", "tone", segs,
                           "step +10 um from 0", frequency=f, gs=False))
    return out


@dataclass(frozen=True)
class Task:
    """The runs of one profile on one stage with one sensor and one law, on its masters."""

    stage: int
    sensor_nm: float
    law: str                    # "ours", "paper", or "fixed" (rls.enabled = false)
    profile: Profile
    plant: dict
    controller: dict
    jacobi: bool = False
    fmu: bool = False
    gs: tuple = ()


@dataclass
class RunMetrics:
    """What one run of a task gave: the worst error of each move [um], of each hold window [um],
    each scan frame after a dwell (worst, steady) [um], the controller's warnings, the Error that
    stopped it (""), and for a checking master whether its rows equal the exchange's."""

    master: str
    moves: list = field(default_factory=list)
    holds: list = field(default_factory=list)
    scans: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    error: str = ""
    equal: object = None
    seconds: float = 0.0


def draw_stages(n, seed):
    """The family's first n stages drawn with this seed (:func:`harness.identify.family.draw_stage`)."""
    rng = np.random.default_rng(seed)
    return [draw_stage(rng) for _ in range(n)]


def stage_plant(stage, index, nm):
    """The plant parameters of a drawn stage with a sensor of nm rms noise on the 2 nm grid (its
    noise seeded by the stage's index)."""
    return {**stage, "sensor.resolution": GRID, "sensor.noise_rms": nm * 1e-3, "sensor.seed": index + 1}


def family_grid(stages, seed, sensors, laws, items):
    """The runs of a family, in order: ``(i, stage, nm, law, item)`` for each of the first
    ``stages`` stages drawn with ``seed`` (index ``i``), each sensor noise ``nm`` [nm rms], each
    law and each item (a profile here, a part of the day in :mod:`.stage_day_table`)."""
    for i, stage in enumerate(draw_stages(stages, seed)):
        for nm, law, item in itertools.product(sensors, laws, items):
            yield i, stage, nm, law, item


def _controller(law):
    if law == "paper":
        return parameter_set(PAPER_LAW_SET)
    return {"rls.enabled": False} if law == "fixed" else {}


def family_tasks(stages=50, seed=SEED, sensors=SENSORS_NM, laws=("ours", "paper"), profile_list=None,
                 jacobi_stages=2, fmu_stages=5, gs_stages=5, gs_sensors=(1, 20), gs_orders=GS_ORDERS):
    """Every :class:`Task` of the family (see the module docstring)."""
    profile_list = profiles_of() if profile_list is None else profile_list
    tasks = []
    for i, stage, nm, law, prof in family_grid(stages, seed, sensors, laws, profile_list):
        gs = gs_orders if (i < gs_stages and nm in gs_sensors and prof.gs) else ()
        tasks.append(Task(i, nm, law, prof, stage_plant(stage, i, nm), _controller(law),
                          i < jacobi_stages, i < fmu_stages, gs))
    return tasks


def _metrics(master, signal, time, y_d, y, warnings, seconds, error="", equal=None):
    args = (signal, time, y_d, y, H)
    return RunMetrics(master, [m.worst for m in profiles.move_errors(*args)],
                      [x.worst for x in profiles.hold_errors(*args)],
                      [(s.worst, s.steady) for s in profiles.scan_errors(*args)],
                      warnings, error, equal, seconds)


def _warnings(lines):
    return [line[len("[Warning] "):] for line in lines if line.startswith("[Warning]")]


def _native(sc, master):
    """(rows, warnings, error) of the native runner."""
    loop = native_loop()
    setup = prepare_closed_loop(sc, master=master)
    try:
        rows = loop.run(setup)
        return rows, _warnings(loop.log(NATIVE_CONTROLLER)), ""
    except FMUError as exc:
        return None, _warnings(loop.log(NATIVE_CONTROLLER)), str(exc)


def run_task(task):
    """Run one :class:`Task` on its masters: a list of :class:`RunMetrics`."""
    sc = task.profile.scenario(task.plant, task.controller)
    out = []
    t0 = _time.perf_counter()
    rows, warns, error = _native(sc, "gauss-seidel")
    if rows is None:
        out.append(RunMetrics(MASTER_EXCHANGE, warnings=warns, error=error))
        return out
    out.append(_metrics(MASTER_EXCHANGE, sc.signal, rows["time"], rows["y_d"], rows["y"], warns,
                        _time.perf_counter() - t0))
    if task.jacobi:
        t0 = _time.perf_counter()
        other, warns, error = _native(sc, "jacobi")
        equal = other is not None and all(np.array_equal(rows[f], other[f]) for f in rows.dtype.names)
        out.append(RunMetrics(MASTER_JACOBI, warnings=warns, error=error, equal=equal,
                              seconds=_time.perf_counter() - t0))
    if task.fmu:
        t0 = _time.perf_counter()
        log = []
        try:
            steps = simulate_closed_loop_fmu_steps(sc, log=log)
        except FMUError as exc:
            out.append(RunMetrics(MASTER_FMU, warnings=_warnings(log), error=str(exc)))
        else:
            k = profiles.sample_index(steps["time"], H)
            equal = all(np.array_equal(rows[f][k], steps[f]) for f in rows.dtype.names)
            out.append(_metrics(MASTER_FMU, sc.signal, steps["time"], steps["y_d"], steps["y"],
                                _warnings(log), _time.perf_counter() - t0, equal=equal))
    for order in task.gs:
        t0 = _time.perf_counter()
        run = simulate_wired(sc, order)
        name = "true Gauss-Seidel: " + ", ".join(order)
        s = run.samples
        if run.error:
            out.append(RunMetrics(name, warnings=run.warnings["controller"], error=run.error))
        else:
            out.append(_metrics(name, sc.signal, s["time"], s["y_d"], s["y"], run.warnings["controller"],
                                _time.perf_counter() - t0))
    return out


def _run_with(run, task):
    return task, run(task)


def run_tasks(tasks, run, part_name, jobs=1, progress=None, every=100, order=None):
    """Run every task with ``run(task)`` (a list of metrics, each with its ``master``) on ``jobs``
    processes, in the given order or by ``order`` (a sort key): ``{(stage, sensor, law,
    part_name(task), master): metrics}``; ``progress`` is told every ``every`` tasks."""
    results = {}
    start = _time.perf_counter()
    todo = sorted(tasks, key=order) if order is not None else list(tasks)

    def keep(i, task, metrics):
        for m in metrics:
            results[(task.stage, task.sensor_nm, task.law, part_name(task), m.master)] = m
        if progress is not None and (i + 1) % every == 0:
            progress(f"{i + 1} of {len(todo)} tasks, {_time.perf_counter() - start:.0f} s")

    if jobs <= 1:
        for i, task in enumerate(todo):
            keep(i, *_run_with(run, task))
    else:
        with ProcessPoolExecutor(jobs) as ex:
            for i, (task, metrics) in enumerate(ex.map(partial(_run_with, run), todo, chunksize=1)):
                keep(i, task, metrics)
    return results


def run_family(tasks, jobs=1, progress=None, every=100):
    """Run every task (in order, on ``jobs`` processes): ``{(stage, sensor, law, profile name,
    master): RunMetrics}``."""
    return run_tasks(tasks, run_task, _profile_name, jobs, progress, every)


def _profile_name(task):
    return task.profile.name


# ---------------------------------------------------------------------------
# the targets
# ---------------------------------------------------------------------------

def save_results(results, path, part="profile"):
    """Write the runs' metrics as JSON, one object per run: its key (stage, sensor_nm, law, and the
    profile or day part under the name ``part``; the master is one of the metrics) beside them."""
    rows = [{"stage": k[0], "sensor_nm": k[1], "law": k[2], part: k[3], **asdict(m)}
            for k, m in results.items()]
    Path(path).write_text(json.dumps(rows), encoding="utf-8")


def _run_metrics(row):
    return RunMetrics(**{**row, "scans": [tuple(x) for x in row["scans"]]})


def load_results(path, metrics=_run_metrics, part="profile"):
    """The runs' metrics written by :func:`save_results`, each made by ``metrics(row)``."""
    out = {}
    for row in json.loads(Path(path).read_text(encoding="utf-8")):
        key = (row.pop("stage"), row.pop("sensor_nm"), row.pop("law"), row.pop(part), row["master"])
        out[key] = metrics(row)
    return out


def hold_band(nm):
    """5 x (noise rms + grid step) [um]: the hold band of target (d)."""
    return 5.0 * (nm * 1e-3 + GRID)


def _last(values):
    return values[-1] if values else math.nan


@dataclass
class Ratio:
    """One ratio of a target: its value and where it came from."""

    value: float
    stage: int
    sensor_nm: float
    law: str
    profile: str
    master: str
    detail: str = ""


def summarize(results, profile_list):
    """The ratios of every target from the runs: ``{target: [Ratio]}`` with targets ``a``, ``b``
    (robust law; ``a_paper``, ``b_paper`` the paper's), ``own`` (a move after 4 to 600 s over the
    same after 0.2 s with the same sensor: what the hold itself does),
    ``c``, ``d``, ``tone``, and their paper's twins; ``e``: the runs with a supervision Error or
    Warning; ``errors``: every run an Error stopped; ``warnings``: counts of the controller's other
    warnings by kind; ``equal``: the checking masters' comparisons; ``absolute``: the reference
    moves' worst errors [um]."""
    by_name = {p.name: p for p in profile_list}
    out = {k: [] for k in ("a", "b", "own", "c", "d", "tone", "a_paper", "b_paper", "own_paper",
                           "c_paper", "d_paper", "tone_paper", "e", "errors", "absolute")}
    out["warnings"], out["equal"] = {}, {}
    masters_ = sorted({k[4] for k in results})
    for (stage, nm, law, name, master), m in results.items():
        if law == "fixed":
            continue
        prof = by_name.get(name)
        suffix = "" if law == "ours" else "_paper"
        if m.error:
            out["errors"].append(Ratio(math.nan, stage, nm, law, name, master, m.error[:300]))
            continue
        sup = [w for w in m.warnings if any(words in w for words in _SUPERVISION_WARNINGS)]
        if sup:
            out["e"].append(Ratio(len(sup), stage, nm, law, name, master, sup[0][:300]))
        for w in m.warnings:
            kind = next((label for words, label in _WARNING_KINDS if words in w), "other")
            key = (law, master, kind)
            out["warnings"][key] = out["warnings"].get(key, 0) + 1
        if m.equal is not None:
            out["equal"].setdefault((law, master), []).append(bool(m.equal))
        if m.master == MASTER_JACOBI:
            continue
        for worst in m.holds:
            out["d" + suffix].append(Ratio(worst / hold_band(nm), stage, nm, law, name, master,
                                           f"{worst * 1e3:.3g} nm"))
        if prof is None:
            continue
        if prof.family == "scan":
            for worst, steady in m.scans:
                out["c" + suffix].append(Ratio(worst / steady, stage, nm, law, name, master,
                                               f"{worst * 1e3:.3g} nm after / {steady * 1e3:.3g} nm before"))
        if prof.family in ("move", "tone"):
            ref_name = _move_profile(prof.move, REFERENCE_HOLD).name
            ref = results.get((stage, REFERENCE_NM, law, ref_name, master))
            own = results.get((stage, nm, law, ref_name, master))
            e = _last(m.moves)
            if ref is None or ref.error or not ref.moves:
                continue
            e_ref = _last(ref.moves)
            if prof.family == "tone":
                out["tone" + suffix].append(Ratio(e / e_ref, stage, nm, law, name, master,
                                                  f"{e:.3g} um / {e_ref:.3g} um"))
                continue
            if nm == REFERENCE_NM and prof.hold == REFERENCE_HOLD:
                out["absolute"].append(Ratio(e, stage, nm, law, name, master))
                continue
            own_text = ""
            if own is not None and not own.error and own.moves and prof.hold != REFERENCE_HOLD:
                e_own = _last(own.moves)
                own_text = f"; {e / e_own:.3g}x the same after 0.2 s with {nm:g} nm ({e_own:.3g} um)"
                out["own" + suffix].append(Ratio(e / e_own, stage, nm, law, name, master))
            if nm < 20:
                out["a" + suffix].append(Ratio(e / e_ref, stage, nm, law, name, master,
                                               f"{e:.3g} um / {e_ref:.3g} um{own_text}"))
            else:
                bound = 1.25 * e_ref + 5 * nm * 1e-3
                out["b" + suffix].append(Ratio(e / bound, stage, nm, law, name, master,
                                               f"{e:.3g} um / {bound:.3g} um{own_text}"))
    out["masters"] = masters_
    return out


def _stats(ratios, master=None):
    values = np.array([r.value for r in ratios if master is None or r.master == master], dtype=float)
    if values.size == 0:
        return math.nan, math.nan, 0
    return float(np.median(values)), float(np.max(values)), values.size


def _p95(ratios, master=None):
    values = [r.value for r in ratios if master is None or r.master == master]
    return float(np.percentile(values, 95)) if values else math.nan


def _worst(ratios, master=None):
    pool = [r for r in ratios if master is None or r.master == master]
    return max(pool, key=lambda r: r.value) if pool else None


def _cell(x, digits=3):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}g}"


#: how the tables name the laws
_LAW_NAME = {"ours": "robust law", "paper": "paper's law", "fixed": "estimates fixed"}

#: the targets' rows: (key, what, bound text)
_TARGET_ROWS = (
    ("a", "(a) 0, 1, 5 nm: move after a hold of 0.2 to 600 s / the same move after 0.2 s "
          "with 1 nm", "<= 1.1"),
    ("b", "(b) 20 nm: move after any hold / (1.25 x the 1 nm reference + 0.1 um)", "<= 1"),
    ("own", "any sensor: move after a hold of 4 to 600 s / the same move after 0.2 s with the same "
            "sensor (what the hold itself does)", "(report)"),
    ("c", "(c) scan frame after a 10 s dwell / the last second before it (1, 10, 50 Hz)", "<= 1.1"),
    ("d", "(d) during holds: max \\|y - y_d\\| / 5 (noise rms + 2 nm)", "<= 1"),
    ("tone", "move after 60 s of a 1 or 20 Hz tone / the fresh move (0.2 s, 1 nm)", "(report)"),
)


def verdicts(summary, master=None):
    """``{target: (worst of the robust law, bound, passed, regression)}`` for a to e over every
    master (or one); a regression is a worst beyond the documented one (:data:`DOCUMENTED`)."""
    out = {}
    for key in ("a", "b", "c", "d"):
        _, worst, n = _stats(summary[key], master)
        bound = TARGETS[key]
        doc = DOCUMENTED[key]
        limit = max(bound, doc) if doc is not None else bound
        ok = n == 0 or worst <= bound
        out[key] = (worst, bound, ok, n > 0 and worst > limit)
    count = (len([r for r in summary["e"] if r.law == "ours"])
             + len([r for r in summary["errors"] if r.law == "ours"]))
    out["e"] = (count, 0, count == 0, count > (DOCUMENTED["e"] or 0))
    return out


def family_markdown(summary, stages, seconds=None):
    """The docs table of the family (Markdown)."""
    lines = []
    masters_ = [m for m in summary["masters"] if m != MASTER_JACOBI]
    head = ["target", "bound", "master", "runs", "robust law: median", "95 %", "worst",
            "paper's law: median", "95 %", "worst"]
    rows = []
    for key, what, bound in _TARGET_ROWS:
        for master in masters_:
            mo, wo, no = _stats(summary[key], master)
            mp, wp, np_ = _stats(summary[key + "_paper"], master)
            if no == 0 and np_ == 0:
                continue
            rows.append([what if master == masters_[0] else "", bound if master == masters_[0] else "",
                         master, f"{no} / {np_}", _cell(mo), _cell(_p95(summary[key], master)), _cell(wo),
                         _cell(mp), _cell(_p95(summary[key + "_paper"], master)), _cell(wp)])
    lines.append(markdown_table(head, rows))
    ours_err = [r for r in summary["errors"] if r.law == "ours"]
    paper_err = [r for r in summary["errors"] if r.law == "paper"]
    ours_sup = [r for r in summary["e"] if r.law == "ours"]
    paper_sup = [r for r in summary["e"] if r.law == "paper"]
    lines.append("")
    lines.append(f"(e) supervision: robust law {len(ours_err)} runs stopped by an Error, "
                 f"{len(ours_sup)} with a supervision Warning; paper's law {len(paper_err)} and "
                 f"{len(paper_sup)}.")
    kinds = {}
    for (law, master, kind), count in summary["warnings"].items():
        kinds.setdefault((law, kind), 0)
        kinds[(law, kind)] += count
    if kinds:
        lines.append("The controller's other warnings, runs that logged each (all masters): "
                     + "; ".join(f"{_LAW_NAME[law]}: {kind} {count}"
                                 for (law, kind), count in sorted(kinds.items())) + ".")
    for (law, master), flags in sorted(summary["equal"].items()):
        lines.append(f"{master} ({_LAW_NAME[law]}): {sum(flags)} of "
                     f"{len(flags)} runs equal to the native exchange's rows bit for bit"
                     + (" (at its communication points)" if master == MASTER_FMU else "") + ".")
    absolute = summary["absolute"]
    if absolute:
        rows = []
        for move in MOVES:
            name = _move_profile(move, REFERENCE_HOLD).name
            o = [r for r in absolute if r.profile == name and r.law == "ours" and r.master == MASTER_EXCHANGE]
            p = [r for r in absolute if r.profile == name and r.law == "paper" and r.master == MASTER_EXCHANGE]
            mo, wo, _ = _stats(o)
            mp, wp, _ = _stats(p)
            rows.append([move, _cell(mo), _cell(wo), _cell(mp), _cell(wp)])
        lines += ["", "The reference moves themselves (after 0.2 s, 1 nm, native exchange), worst "
                      "|y_d - y| [um]:", "",
                  markdown_table(["move", "robust law: median", "worst", "paper's law: median", "worst"],
                                 rows)]
    lines += ["", _breakdown(summary)]
    if seconds is not None:
        lines += ["", f"{stages} stages, {seconds / 60:.1f} min on one core."]
    return "\n".join(lines)


def _breakdown(summary):
    """(a)/(b) per move and sensor over the holds, and (c) per frequency and sensor: the robust
    law's median / worst, then the paper's (native exchange)."""
    rows = []

    def add(key, name, nm, label, hold, target):
        """One row: the robust law's runs of ``summary[key]`` and the paper's, native exchange."""
        o, p = ([r for r in summary[k] if r.profile == name and r.sensor_nm == nm and r.master == MASTER_EXCHANGE]
                for k in (key, key + "_paper"))
        if o or p:
            mo, wo, _ = _stats(o)
            mp, wp, _ = _stats(p)
            rows.append([label, f"{nm:g} nm", hold, target, f"{_cell(mo)} / {_cell(wo)}",
                         f"{_cell(mp)} / {_cell(wp)}"])

    for move in MOVES:
        for nm in SENSORS_NM:
            key = "b" if nm >= 20 else "a"
            for hold in HOLDS:
                add(key, _move_profile(move, hold).name, nm, move, f"{hold:g} s", f"({key})")
    for f in TONE_FREQUENCIES:
        name = f"{f:g} Hz tone for 60 s, then a 10 um step"
        for nm in SENSORS_NM:
            add("tone", name, nm, name, "0.5 s", "(tone)")
    for f in SCAN_FREQUENCIES:
        name = f"triangle scan {f:g} Hz, 10 s dwell"
        for nm in SENSORS_NM:
            add("c", name, nm, name, "10 s dwell", "(c)")
    return ("Per move, sensor and hold (native exchange): the target's ratio, median / worst over "
            "the stages.\n\n" + markdown_table(["profile", "sensor", "hold", "target",
                                                 "robust law", "paper's law"], rows))


def _distinct_worst(ratios, bound, worst):
    """The ``worst`` largest ratios above ``bound`` on the native exchange, one per stage."""
    out, seen = [], set()
    for r in sorted((r for r in ratios if r.value > bound and r.master == MASTER_EXCHANGE),
                    key=lambda r: -r.value):
        if r.stage not in seen:
            seen.add(r.stage)
            out.append(r)
        if len(out) == worst:
            break
    return out


def _diagnose(summary, tasks_by_key, worst=4, progress=None):
    """The worst misses of a, b and c (one per stage) run again with the estimates fixed
    (rls.enabled = false), and the worst of d and of the tone: lines of text."""
    lines = []
    for key in ("a", "b", "c"):
        for r in _distinct_worst(summary[key], TARGETS[key], worst):
            fixed = _fixed_ratio(key, tasks_by_key[(r.stage, r.sensor_nm, "ours", r.profile)])
            lines.append(f"({key}) stage {r.stage}, {r.sensor_nm:g} nm, {r.profile}: {r.value:.3g} "
                         f"({r.detail}); with the estimates fixed at the nominal model: {fixed}")
            if progress is not None:
                progress(lines[-1])
    for key, bound in (("d", TARGETS["d"]), ("tone", 1.1)):
        for r in _distinct_worst(summary[key], bound, worst):
            lines.append(f"({key}) stage {r.stage}, {r.sensor_nm:g} nm, {r.profile}: {r.value:.3g} ({r.detail})")
    return lines


def _fixed_ratio(key, task):
    """The ratio of target ``key`` for this case with rls.enabled = false."""
    fixed = {"rls.enabled": False}
    sc = task.profile.scenario(task.plant, fixed)
    rows, _, error = _native(sc, "gauss-seidel")
    if rows is None:
        return f"stopped ({error[:120]})"
    m = _metrics("fixed", sc.signal, rows["time"], rows["y_d"], rows["y"], [], 0.0)
    if key == "c":
        worst, steady = m.scans[0]
        return f"{worst / steady:.3g} ({worst * 1e3:.3g} nm / {steady * 1e3:.3g} nm)"
    stage = {k: v for k, v in task.plant.items() if not k.startswith("sensor.")}
    ref_plant = stage_plant(stage, task.stage, REFERENCE_NM)
    ref_prof = _move_profile(task.profile.move, REFERENCE_HOLD)
    ref_sc = ref_prof.scenario(ref_plant, fixed)
    ref_rows, _, _ = _native(ref_sc, "gauss-seidel")
    if ref_rows is None:
        return "reference stopped"
    e = _last(m.moves)
    e_ref = _last(_metrics("fixed", ref_sc.signal, ref_rows["time"], ref_rows["y_d"], ref_rows["y"],
                           [], 0.0).moves)
    if key == "a":
        return f"{e / e_ref:.3g} ({e:.3g} um / {e_ref:.3g} um)"
    return f"{e / (1.25 * e_ref + 5 * task.sensor_nm * 1e-3):.3g} ({e:.3g} um; reference {e_ref:.3g} um)"


BEGIN, END = "<!-- stage_use_table: begin -->", "<!-- stage_use_table: end -->"


def write_into(path, text):
    """Replace the block between :data:`BEGIN` and :data:`END` of ``path`` with ``text``."""
    page = Path(path).read_text(encoding="utf-8")
    if BEGIN not in page or END not in page:
        raise ValueError(f"{path} has no {BEGIN} ... {END} block to write the table into")
    head, rest = page.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    Path(path).write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}", encoding="utf-8")


def main(argv=None, prog=None):
    """``python -m harness stage-use``: the family's table, PASS/FAIL per target; exit 1 on
    a regression beyond the documented numbers."""
    ap = argparse.ArgumentParser(prog=prog or "python -m harness stage-use",
                                 description="Issue 35's stage-use targets on the family of stages "
                                             "(docs/stage_use.md).")
    ap.add_argument("--stages", type=int, default=50)
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--sensors", type=float, nargs="+", default=list(SENSORS_NM), help="nm rms")
    ap.add_argument("--quick", action="store_true",
                    help="holds 0.2 and 4 s only, no tones: a slice in a minute")
    ap.add_argument("--jacobi-stages", type=int, default=2)
    ap.add_argument("--fmu-stages", type=int, default=5)
    ap.add_argument("--gs-stages", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--write", metavar="PAGE", help="write the table into PAGE between its markers")
    ap.add_argument("--save", metavar="JSON", help="also write every run's metrics to JSON")
    ap.add_argument("--load", metavar="JSON", help="read the runs' metrics from JSON (of --save with "
                                                  "the same options) instead of running them")
    args = ap.parse_args(argv)
    say = lambda text: print(text, file=sys.stderr, flush=True)   # noqa: E731
    if not native_available():
        print(f"{prog or 'python -m harness stage-use'}: {missing_runner_message()}", file=sys.stderr)
        return 2
    sensors = tuple(int(s) if float(s).is_integer() else s for s in args.sensors)
    if REFERENCE_NM not in sensors:
        sensors = (REFERENCE_NM,) + sensors      # every ratio needs the 1 nm reference
    plist = profiles_of(holds=(0.2, 4.0), tones=()) if args.quick else profiles_of()
    tasks = family_tasks(args.stages, args.seed, sensors, profile_list=plist,
                         jacobi_stages=args.jacobi_stages, fmu_stages=args.fmu_stages,
                         gs_stages=args.gs_stages)
    say(f"{len(tasks)} tasks ({args.stages} stages, sensors {', '.join(f'{s:g}' for s in sensors)} nm, "
        f"{len(plist)} profiles, two laws)")
    t0 = _time.perf_counter()
    results = load_results(args.load) if args.load else run_family(tasks, args.jobs, progress=say)
    if args.save:
        save_results(results, args.save)
    summary = summarize(results, plist)
    seconds = None if args.load else _time.perf_counter() - t0
    by_key = {(t.stage, t.sensor_nm, t.law, t.profile.name): t for t in tasks}
    diagnosis = _diagnose(summary, by_key, progress=say)
    text = family_markdown(summary, args.stages, seconds)
    if diagnosis:
        text += "\n\nThe worst misses, run again with the estimates fixed:\n\n" + "\n".join(
            f"- {line}" for line in diagnosis)
    if args.write:
        write_into(args.write, text)
        say(f"wrote the table into {args.write}")
    else:
        print(text)
    regression = False
    for key, (worst, bound, ok, regressed) in verdicts(summary).items():
        documented = DOCUMENTED[key]
        say(f"{'PASS' if ok else 'FAIL'} ({key}): robust law worst {_cell(worst)}, target "
            f"{'<=' if key != 'e' else '='} {bound:g}"
            + ("" if documented is None else f", documented {documented:g}")
            + ("; REGRESSION" if regressed else ""))
        regression |= regressed
    for r in [r for r in summary["errors"] if r.law == "ours"][:10]:
        say(f"ERROR: stage {r.stage}, {r.sensor_nm:g} nm, {r.profile}, {r.master}: {r.detail}")
    for r in [r for r in summary["e"] if r.law == "ours"][:10]:
        say(f"SUPERVISION WARNING: stage {r.stage}, {r.sensor_nm:g} nm, {r.profile}, {r.master}: {r.detail}")
    unequal = [(k, f) for k, f in summary["equal"].items() if not all(f)]
    for (law, master), flags in unequal:
        say(f"NOT EQUAL: {master} ({law}): {len(flags) - sum(flags)} runs differ from the native exchange")
    return 1 if regression or unequal else 0


if __name__ == "__main__":
    sys.exit(main())
