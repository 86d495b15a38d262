"""A stage's day: issue 43's targets measured on the stage family, over what a stage does all day.

::

    python -m harness stage-day                              # the family, Markdown on stdout
    python -m harness stage-day --write docs/stage_day.md    # into the page, between its markers
    python -m harness stage-day --stages 2 --quick           # a slice, in minutes

**The family** (:func:`family_tasks`): the stages :func:`harness.identify.family.draw_stage` draws
(seed 2026), each with a sensor of 0, 1, 5, 20, 100 and 200 nm rms noise on the 2 nm grid
(``sensor.seed`` = stage index + 1), the controller on the nominal model (its defaults), each part
of the day run twice: with the controller's defaults and with the estimates fixed at the nominal
model (``rls.enabled = false``, the loop delay given: ``mv.delay = 1``), the reference of "never
worse than no adaptation". The parts
(:func:`day_parts`):

* **rasters**: 100 frames of a 10 um triangle (2 s each, from 0 and back) at 1, 10 and 50 Hz,
  with dwells of 0.1, 0.5 and 2 s at 0 between them;
* **tones then a step**: 60 s and 600 s of a 10 um sine at 1, 5 and 20 Hz, 0.5 s at rest, a 10 um
  step; and the fresh step (0.2 s at rest, the same step) they are compared with;
* **a seeded random hour** (:func:`random_hour`, seed = stage index): holds of 0.5 to 60 s, steps
  and S-curves, bursts of raster frames and tones, within 0 to 60 um.

Every part runs on the native runner's exchange (the FMUs' binaries, the ModelStructure
Gauss-Seidel order, d = 2), its rows handed over in chunks (an hour is 7.2 million samples); on the
first ``--fmu-stages`` stages with the 1 nm sensor the closed-loop FMU runs the same part at 10 ms
steps while the reference holds (:func:`harness.masters.closed_loop_fmu.simulate_closed_loop_fmu_steps`)
and its rows must equal the exchange's at its communication points, bit for bit.

**The targets** (:data:`TARGETS`, issue 43; each printed PASS or FAIL):

* **growth**: after the first frame, every frame's worst ``|y_d - y|`` within 1.5 times the worst
  of frames 2-11 of its run;
* **fixed**: after the first frame, every frame's worst error within 1.5 times the same frame's with
  the estimates fixed at the nominal model; and in the random hour, every move's and every scan
  frame's worst error within 1.5 times the same with the estimates fixed;
* **frame**: no 10 um frame's worst error above 1 um;
* **tone**: the step after any tone within 1.25 times the fresh step (same stage, same sensor);
* **set**: the estimates the law uses (``est.a1`` .. ``est.b2``) inside the admissible set at every
  sample (:func:`admissible_rows`, the core's rows, checked with the core's arithmetic);
* **supervision**: no run stopped by an Error.

The command exits 1 when a measurement is worse than the number documented for it in
docs/stage_day.md (:data:`DOCUMENTED`): a regression.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import math
from pathlib import Path
import re
import sys
import time as _time

import numpy as np

from ..fmu import FMUError
from ..loop import prepare_closed_loop
from . import stage_use_table
from .stage_use_table import GRID, family_grid, hold_band, profile_scenario, stage_plant
from ..text_tables import markdown_table

__all__ = ["SEED", "SENSORS_NM", "RASTER_FREQUENCIES", "DWELLS", "FRAMES", "TONE_FREQUENCIES",
           "TONE_TIMES", "HOUR", "TARGETS", "DOCUMENTED", "DayPart", "Task", "PartMetrics",
           "random_hour", "day_parts", "family_tasks", "admissible_rows", "outside_admissible",
           "run_task", "run_family", "summarize", "family_markdown", "main"]

H = 0.0005
SEED = 2026
SENSORS_NM = (0, 1, 5, 20, 100, 200)
RASTER_FREQUENCIES = (1.0, 10.0, 50.0)
DWELLS = (0.1, 0.5, 2.0)
FRAMES = 100
FRAME_TIME = 2.0
AMPLITUDE = 10.0
TONE_FREQUENCIES = (1.0, 5.0, 20.0)
TONE_TIMES = (60.0, 600.0)
STEP = 10.0
HOUR = 3600.0
#: the issue's bound of each target (ratios; frame: um; set and supervision: counts)
TARGETS = {"growth": 1.5, "fixed": 1.5, "frame": 1.0, "tone": 1.25, "set": 0, "supervision": 0}
#: the worst measured over the whole family by this command, as docs/stage_day.md documents it: a
#: larger value is a regression (exit 1). Measured at 71b2e34 (issue 43's one-sample fallback), and
#: again at aabfd4f (its noise bound), both: 13.3, 42.7, 2.24 um, 3.59, 0 samples, 35 runs stopped;
#: with the supervisor's gain of one-sample evidence the same, and 13 runs stopped; with the
#: integral's gate (bb11c52, the 0-20 nm runs again): 13.6, 39.9, 2.24, 3.59, 0, 14 runs stopped; with
#: the stale reading bridged (3c88723, the 0-20 nm runs again): 12.9, 36.7, 2.24, 3.59, 0, 13.
DOCUMENTED = {"growth": 13.0, "fixed": 36.8, "frame": 2.25, "tone": 3.6, "set": 0, "supervision": 13}
#: the laws each part runs with
LAWS = ("ours", "fixed")
MASTER_EXCHANGE = "native exchange"
MASTER_FMU = "closed-loop FMU, 10 ms in holds"


# ---------------------------------------------------------------------------
# the parts of the day
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class DayPart:
    """One part of a stage's day: its profile segments and what it is."""

    name: str
    kind: str                   # "raster", "tone", "fresh", "hour"
    segments: tuple
    frequency: float = math.nan
    dwell: float = math.nan
    tone_time: float = math.nan
    seed: int = -1              # the random hour's

    def scenario(self, plant, controller):
        return profile_scenario(self.name, self.segments, plant, controller)


def _frame(f, amplitude=AMPLITUDE, time=FRAME_TIME):
    return {"scan": "triangle", "frequency": float(f), "amplitude": float(amplitude), "time": float(time)}


def raster_part(f, dwell, frames=FRAMES):
    """``frames`` raster frames at ``f`` with ``dwell`` at rest between them, after 0.2 s at 0."""
    segs = [{"hold": 0.2}]
    for _ in range(frames):
        segs += [_frame(f), {"hold": float(dwell)}]
    return DayPart(f"raster {f:g} Hz, {dwell:g} s dwells", "raster", tuple(segs), frequency=f, dwell=dwell)


def tone_part(f, seconds):
    """``seconds`` of a 10 um tone at ``f``, 0.5 s at rest, a 10 um step, 0.5 s to settle."""
    segs = ({"scan": "sine", "frequency": float(f), "amplitude": AMPLITUDE, "time": float(seconds)},
            {"hold": 0.5}, {"move": STEP}, {"hold": 0.5})
    return DayPart(f"{f:g} Hz tone for {seconds:g} s, then a step", "tone", segs, frequency=f,
                   tone_time=seconds)


FRESH = DayPart("fresh step", "fresh", ({"hold": 0.2}, {"move": STEP}, {"hold": 0.5}))


def random_hour(seed, seconds=HOUR, low=0.0, high=40.0):
    """A seeded random hour of a stage's use, as profile segments: holds (0.5 to 60 s, log-uniform),
    steps (0.5 to 20 um), S-curves (5 to 40 um in 20 to 200 ms), bursts of 1 to 10 raster frames
    (a triangle of 2 to 20 um at 1, 10 or 50 Hz, 2 s each, 0.1 to 2 s dwells between) and tones (1
    to 10 um at 1, 5 or 20 Hz for 5 to 60 s, whole periods), each from where the one before left
    the stage, within [low, high] um (40 um: a stage of the family reaches 60 um only beyond 150 V). Every time is a whole
    number of samples."""
    rng = np.random.default_rng(seed)
    segs, pos, t = [{"hold": 0.2}], 0.0, 0.2

    def quantum(x):
        return round(x / H) * H

    while t < seconds:
        kind = rng.choice(["hold", "step", "scurve", "raster", "tone"], p=[0.35, 0.2, 0.2, 0.15, 0.1])
        if kind == "hold":
            dt = quantum(math.exp(rng.uniform(math.log(0.5), math.log(60.0))))
            segs.append({"hold": dt})
        elif kind in ("step", "scurve"):
            size = rng.uniform(0.5, 20.0) if kind == "step" else rng.uniform(5.0, 40.0)
            to = pos + size * rng.choice([-1.0, 1.0])
            if not low <= to <= high:
                to = pos - (to - pos)
            to = float(min(high, max(low, to)))
            if kind == "step":
                segs.append({"to": to})
                dt = 0.0
            else:
                dt = quantum(rng.uniform(0.02, 0.2))
                segs.append({"to": to, "shape": "scurve", "time": dt})
            pos = to
            settle = quantum(rng.uniform(0.05, 1.0))
            segs.append({"hold": settle})
            dt += settle
        elif kind == "raster":
            f = float(rng.choice(RASTER_FREQUENCIES))
            amp = float(min(rng.uniform(2.0, 20.0), high - pos))
            frames = int(rng.integers(1, 11))
            dwell = quantum(rng.uniform(0.1, 2.0))
            dt = 0.0
            for _ in range(frames):
                segs += [_frame(f, amp), {"hold": dwell}]
                dt += FRAME_TIME + dwell
        else:
            f = float(rng.choice(TONE_FREQUENCIES))
            amp = float(min(rng.uniform(1.0, 10.0), pos - low, high - pos))
            periods = max(1, int(rng.uniform(5.0, 60.0) * f))
            dt = periods / f
            if amp > 0.1:
                segs.append({"scan": "sine", "frequency": f, "amplitude": amp, "time": dt})
            else:
                segs.append({"hold": dt})
            segs.append({"hold": 0.5})
            dt += 0.5
        t += dt
    return tuple(segs)


def hour_part(seed):
    return DayPart(f"random hour (seed {seed})", "hour", random_hour(seed), seed=seed)


def day_parts(frequencies=RASTER_FREQUENCIES, dwells=DWELLS, frames=FRAMES, tones=TONE_FREQUENCIES,
              tone_times=TONE_TIMES, hour=True):
    """The parts of the day every stage and sensor runs (the random hour's seed is set per stage
    in :func:`family_tasks`)."""
    out = [raster_part(f, dw, frames) for f in frequencies for dw in dwells]
    out += [tone_part(f, T) for f in tones for T in tone_times]
    out.append(FRESH)
    if hour:
        out.append(DayPart("random hour", "hour", (), seed=-1))
    return out


# ---------------------------------------------------------------------------
# the admissible set, as the core draws it
# ---------------------------------------------------------------------------

def admissible_rows(controller_params=None, margin=1e-4, radius=0.999):
    """The admissible set of the controller's estimates (docs/model.md, "Estimates with
    guarantees") as ``(C, d)``, ``C theta <= d``, from the controller's parameters (its nominal
    model ``tf.*``, ``rls.zero_min`` or the nominal zero ``-tf.b2/tf.b1`` where that is lower,
    ``rls.pole_min`` and the supervision's ``sup.gain_min``, ``sup.gain_max``), each row computed
    with the core's operations in the core's order (``piezo_ctl_admissible_rows`` in piezo_controller_setup.c), so
    that :func:`outside_admissible` gives the core's verdict bit for bit."""
    from ..binding.core import default_controller_params
    p = {**default_controller_params(), **(controller_params or {})}
    a1, a2, b1, b2 = p["tf.a1"], p["tf.a2"], p["tf.b1"], p["tf.b2"]
    z, pm, g_lo, g_hi = p["rls.zero_min"], p["rls.pole_min"], p["sup.gain_min"], p["sup.gain_max"]
    z = min(z, -b2 / b1)
    gain = (b1 + b2) / (1.0 + a1 + a2)
    C = np.array([[-1.0, -1.0, 0.0, 0.0], [-pm, -1.0, 0.0, 0.0], [(1.0 + pm) / 2.0, 1.0, 0.0, 0.0],
                  [0.0, 0.0, -radius, -1.0], [0.0, 0.0, z, 1.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, -1.0, 0.0],
                  [-g_hi * gain, -g_hi * gain, 1.0, 1.0], [g_lo * gain, g_lo * gain, -1.0, -1.0]])
    d = np.array([1.0 - margin, pm * pm, -pm - margin, 0.0, 0.0, g_hi * b1, -g_lo * b1, g_hi * gain,
                  -g_lo * gain])
    return C, d


def outside_admissible(theta, C, d):
    """Per row of estimates ``theta`` (n, 4): 1 where any row of the set is violated, the sums
    ``(((c0 a1 + c1 a2) + c2 b1) + c3 b2) - d`` taken as the core takes them."""
    theta = np.asarray(theta, dtype=float)
    bad = np.zeros(len(theta), dtype=bool)
    for row, bound in zip(C, d):
        excess = (((row[0] * theta[:, 0] + row[1] * theta[:, 1]) + row[2] * theta[:, 2])
                  + row[3] * theta[:, 3]) - bound
        bad |= excess > 0.0
    return bad


# ---------------------------------------------------------------------------
# the runs
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Task:
    """One part of the day on one stage with one sensor and one law."""

    stage: int
    sensor_nm: float
    law: str                    # "ours" or "fixed"
    part: DayPart
    plant: dict
    controller: dict
    fmu: bool = False


@dataclass
class PartMetrics:
    """What one run of a part gave: the worst error [um] of every motion segment (raster frame,
    tone, move: ``kinds`` says which), of every hold window, the samples whose estimates left the
    admissible set, the controller's fallbacks, its warnings, the Error that stopped it (""), and
    for the closed-loop FMU whether its rows equal the exchange's at its communication points."""

    master: str
    worst: list = field(default_factory=list)
    kinds: list = field(default_factory=list)
    holds: list = field(default_factory=list)
    outside: int = 0
    fallbacks: int = 0
    warnings: list = field(default_factory=list)
    error: str = ""
    samples: int = 0
    equal: object = None
    seconds: float = 0.0


def _controller(law):
    """The controller of a law: the defaults, or the estimates fixed at the nominal model. The fixed
    reference is given its loop delay (d = 2, the exchange's): with its candidates' estimates held
    too, the delay detection cannot tell the delays apart on a stage at rest from the start (the
    random hour may begin with a minute's hold) and stops with "no loop delay found" at 0.5 s."""
    return {"rls.enabled": False, "mv.delay": 1} if law == "fixed" else {}


def family_tasks(stages=50, seed=SEED, sensors=SENSORS_NM, laws=LAWS, parts=None, fmu_stages=2,
                 fmu_sensors=(1,), declared=False):
    """Every :class:`Task` of the family (see the module docstring). ``declared``: each sensor's noise
    declared to the controller (``sup.sensor_noise`` = its rms, for a sensor with noise)."""
    parts = day_parts() if parts is None else parts
    tasks = []
    for i, stage, nm, law, part in family_grid(stages, seed, sensors, laws, parts):
        if part.kind == "hour":
            part = hour_part(i)
        controller = {**_controller(law), **({"sup.sensor_noise": nm * 1e-3} if declared and nm > 0 else {})}
        tasks.append(Task(i, nm, law, part, stage_plant(stage, i, nm), controller,
                          fmu=i < fmu_stages and nm in fmu_sensors and law == "ours"))
    return tasks


def _segments_of(signal, n=None):
    """``(first, stop, kind)`` of every motion segment (scan frames and tones as "scan", moves as
    "move"): the windows whose worst errors a part's metrics keep. A move's window runs on to
    ``profiles.SETTLE`` after its last sample (within the run's ``n`` samples), as
    :func:`harness.loop.profiles.move_windows` has it."""
    from ..loop import profiles
    tail = int(round(profiles.SETTLE / H))
    n = signal.samples if n is None else n
    out = []
    for s in signal.segments:
        if s.kind == "scan":
            out.append((s.first, s.stop, "scan"))
        elif s.kind == "move" and s.end != s.start:
            out.append((s.first, min(n, s.stop + tail), "move"))
    return out


class _Streamer:
    """The metrics of one run from its rows, chunk by chunk."""

    def __init__(self, signal, n, controller_params, robust):
        from ..loop import profiles
        self.windows = _segments_of(signal, n)
        self.worst = np.full(len(self.windows), np.nan)
        self.holds_w = profiles.hold_windows(signal, n, H)
        self.holds = np.full(len(self.holds_w), np.nan)
        self.starts = np.array([w[0] for w in self.windows], dtype=np.int64)
        self.stops = np.array([w[1] for w in self.windows], dtype=np.int64)
        self.hstarts = np.array([w[0] for w in self.holds_w], dtype=np.int64)
        self.hstops = np.array([w[1] for w in self.holds_w], dtype=np.int64)
        self.C, self.d = admissible_rows(controller_params)
        self.robust = robust
        self.outside = 0
        self.samples = 0
        self.keep = None            # (stride, list of (k, a1, a2, b1, b2, err)) for a figure

    def _fold(self, starts, stops, target, first, last, err):
        lo = np.searchsorted(stops, first, side="right")
        hi = np.searchsorted(starts, last, side="left")
        for j in range(lo, hi):
            a, b = max(starts[j], first), min(stops[j], last)
            if b > a:
                m = float(np.max(err[a - first:b - first]))
                target[j] = m if not target[j] >= m else target[j]

    def __call__(self, first, rows):
        last = first + len(rows)
        err = np.abs(rows["y_d"] - rows["y"])
        self._fold(self.starts, self.stops, self.worst, first, last, err)
        self._fold(self.hstarts, self.hstops, self.holds, first, last, err)
        if self.robust:
            theta = np.column_stack([rows["a1"], rows["a2"], rows["b1"], rows["b2"]])
            self.outside += int(np.count_nonzero(outside_admissible(theta, self.C, self.d)))
        if self.keep is not None:
            stride, kept = self.keep
            sel = np.arange((-first) % stride, len(rows), stride)
            kept.append(np.column_stack([first + sel, rows["a1"][sel], rows["a2"][sel],
                                         rows["b1"][sel], rows["b2"][sel], err[sel]]))
        self.samples = last


_FALLBACKS = re.compile(r"fell back to the nominal model (\d+) times")


def _fallbacks(lines):
    """The controller's fallbacks, from its terminate summary (0 when it said none)."""
    for line in lines:
        m = _FALLBACKS.search(line)
        if m:
            return int(m.group(1))
    return 1 if any("the law fell back to the nominal model" in line for line in lines) else 0


def _warnings(lines):
    return [line[len("[Warning] "):] for line in lines if line.startswith("[Warning]")]


def run_part(task, keep_stride=0):
    """Run one :class:`Task` on the native runner's exchange, streaming: ``(PartMetrics, kept)``,
    kept the estimates and the error every ``keep_stride`` samples (when > 0)."""
    from ..masters import NATIVE_CONTROLLER, native_loop
    sc = task.part.scenario(task.plant, task.controller)
    setup = prepare_closed_loop(sc, master="gauss-seidel")
    robust = task.law != "fixed" and bool(setup.controller_params.get("rls.robust", True)) \
        and bool(setup.controller_params.get("rls.enabled", True))
    stream = _Streamer(sc.signal, setup.n, setup.controller_params, robust)
    if keep_stride > 0:
        stream.keep = (keep_stride, [])
    loop = native_loop()
    t0 = _time.perf_counter()
    error = ""
    try:
        loop.run_chunks(setup, stream)
    except FMUError as exc:
        error = str(exc)
    lines = loop.log(NATIVE_CONTROLLER)
    m = PartMetrics(MASTER_EXCHANGE, [float(x) for x in stream.worst], [w[2] for w in stream.windows],
                    [float(x) for x in stream.holds], stream.outside, _fallbacks(lines), _warnings(lines),
                    error, stream.samples, None, _time.perf_counter() - t0)
    kept = np.concatenate(stream.keep[1]) if keep_stride > 0 and stream.keep[1] else None
    return m, kept


def _fmu_check(task, exchange):
    """The closed-loop FMU at 10 ms steps in holds against the exchange at its communication
    points: a PartMetrics whose ``equal`` says whether every row's bits agree."""
    from ..loop import profiles
    from ..masters import native_loop, simulate_closed_loop_fmu_steps
    sc = task.part.scenario(task.plant, task.controller)
    t0 = _time.perf_counter()
    log = []
    try:
        steps = simulate_closed_loop_fmu_steps(sc, log=log)
    except FMUError as exc:
        return PartMetrics(MASTER_FMU, warnings=_warnings(log), error=str(exc))
    k = profiles.sample_index(steps["time"], H)
    want = {}
    names = steps.dtype.names

    def sink(first, rows):
        sel = k[(k >= first) & (k < first + len(rows))]
        if sel.size:
            want[first] = (sel, rows[sel - first])
    setup = prepare_closed_loop(sc, master="gauss-seidel")
    native_loop().run_chunks(setup, sink)
    got = {name: steps[name] for name in names}
    equal = True
    pos = 0
    for first in sorted(want):
        sel, rows = want[first]
        n = len(sel)
        for name in names:
            if name in rows.dtype.names and not np.array_equal(rows[name], got[name][pos:pos + n]):
                equal = False
        pos += n
    return PartMetrics(MASTER_FMU, warnings=_warnings(log), equal=equal and pos == len(k),
                       samples=int(k[-1]) + 1, seconds=_time.perf_counter() - t0)


def run_task(task):
    """Run one task on its masters: a list of :class:`PartMetrics`."""
    m, _ = run_part(task)
    out = [m]
    if task.fmu and not m.error:
        out.append(_fmu_check(task, m))
    return out


def run_family(tasks, jobs=1, progress=None, every=50):
    """Run every task (on ``jobs`` processes, the longest first: the pool ends together):
    ``{(stage, sensor, law, part name, master): PartMetrics}``."""
    return stage_use_table.run_tasks(tasks, run_task, _part_name, jobs, progress, every,
                                     order=_longest_first)


def _part_name(task):
    return task.part.name


def _longest_first(task):
    return -_part_seconds(task.part)


def _part_seconds(part):
    if part.kind == "hour":
        return HOUR
    total = 0.0
    for s in part.segments:
        total += float(s.get("time", s.get("hold", 0.0)) or 0.0)
    return total


def save_results(results, path):
    """Write the runs' metrics as JSON (one object per run)."""
    stage_use_table.save_results(results, path, part="part")


def load_results(path):
    """The runs' metrics written by :func:`save_results`."""
    return stage_use_table.load_results(path, lambda row: PartMetrics(**row), part="part")


# ---------------------------------------------------------------------------
# the targets
# ---------------------------------------------------------------------------

@dataclass
class Ratio:
    """One value of a target and where it came from."""

    value: float
    stage: int
    sensor_nm: float
    part: str
    detail: str = ""


def summarize(results):
    """The values of every target from the runs: ``{target: [Ratio]}`` (growth, fixed, frame,
    tone, hour_fixed, hold, set, supervision, fallbacks, errors, equal)."""
    out = {k: [] for k in ("growth", "fixed", "frame", "tone", "hour_fixed", "hold", "set", "supervision",
                           "fallbacks", "errors", "equal")}
    ex = {k[:4]: m for k, m in results.items() if k[4] == MASTER_EXCHANGE}
    for (stage, nm, law, name), m in ex.items():
        if law != "ours":
            continue
        if m.error:
            out["errors"].append(Ratio(math.nan, stage, nm, name, m.error[:300]))
            out["supervision"].append(Ratio(1, stage, nm, name, m.error[:300]))
            continue
        out["set"].append(Ratio(m.outside, stage, nm, name))
        out["fallbacks"].append(Ratio(m.fallbacks, stage, nm, name))
        fixed = ex.get((stage, nm, "fixed", name))
        fixed_ok = fixed is not None and not fixed.error and len(fixed.worst) == len(m.worst)
        frames = [w for w, k in zip(m.worst, m.kinds) if k == "scan"]
        if name.startswith("raster"):
            frames = np.array(frames)
            ref = np.nanmax(frames[1:11])
            out["growth"].append(Ratio(float(np.nanmax(frames[1:]) / ref), stage, nm, name,
                                       f"worst frame {np.nanmax(frames[1:]) * 1e3:.3g} nm, frames 2-11 "
                                       f"{ref * 1e3:.3g} nm"))
            out["frame"].append(Ratio(float(np.nanmax(frames)), stage, nm, name))
            if fixed_ok:
                ff = np.array([w for w, k in zip(fixed.worst, fixed.kinds) if k == "scan"])
                r = frames[1:] / ff[1:]
                j = int(np.nanargmax(r))
                out["fixed"].append(Ratio(float(r[j]), stage, nm, name,
                                          f"frame {j + 2}: {frames[j + 1] * 1e3:.3g} nm against "
                                          f"{ff[j + 1] * 1e3:.3g} nm fixed"))
        elif name.startswith("random hour") and fixed_ok:
            ours, fx = np.array(m.worst), np.array(fixed.worst)
            r = ours / fx
            j = int(np.nanargmax(r))
            out["hour_fixed"].append(Ratio(float(r[j]), stage, nm, name,
                                           f"segment {j + 1} ({m.kinds[j]}): {ours[j] * 1e3:.3g} nm "
                                           f"against {fx[j] * 1e3:.3g} nm fixed"))
            for w in m.holds:
                out["hold"].append(Ratio(w / hold_band(nm), stage, nm, name, f"{w * 1e3:.3g} nm"))
        elif m.kinds and m.kinds[-1] == "move" and name != FRESH.name:
            fresh = ex.get((stage, nm, "ours", FRESH.name))
            if fresh is not None and not fresh.error and fresh.worst:
                out["tone"].append(Ratio(m.worst[-1] / fresh.worst[-1], stage, nm, name,
                                         f"{m.worst[-1]:.3g} um / {fresh.worst[-1]:.3g} um"))
    for k, m in results.items():
        if k[4] == MASTER_FMU:
            out["equal"].append(Ratio(1.0 if m.equal else 0.0, k[0], k[1], k[3], m.error[:200]))
    return out


def _stats(ratios):
    v = np.array([r.value for r in ratios], dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan, math.nan, 0
    return float(np.median(v)), float(np.percentile(v, 95)), float(np.max(v)), int(v.size)


def _cell(x, digits=3):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}g}"


_ROWS = (
    ("growth", "growth: after the first frame, a raster's worst frame / the worst of frames 2-11", "<= 1.5"),
    ("fixed", "never worse than no adaptation: a frame / the same frame with the estimates fixed", "<= 1.5"),
    ("hour_fixed", "the random hour: a move or scan frame / the same with the estimates fixed", "<= 1.5"),
    ("frame", "no 10 um frame above 1 um: a raster's worst frame [um]", "<= 1"),
    ("tone", "a step after a tone / the fresh step (same sensor)", "<= 1.25"),
    ("hold", "the random hour's holds: max \\|y - y_d\\| / 5 (noise rms + 2 nm)", "<= 1"),
    ("set", "samples whose estimates left the admissible set, per run", "0"),
    ("fallbacks", "the law's fallbacks to the nominal model, per run", "(report)"),
)


def verdicts(summary):
    """``{target: (worst, bound, passed, regression)}``."""
    out = {}
    for key in ("growth", "fixed", "frame", "tone"):
        _, _, worst, n = _stats(summary[key] + (summary["hour_fixed"] if key == "fixed" else []))
        bound, doc = TARGETS[key], DOCUMENTED[key]
        out[key] = (worst, bound, n == 0 or worst <= bound, doc is not None and n > 0 and worst > doc)
    outside = sum(r.value for r in summary["set"])
    out["set"] = (outside, 0, outside == 0, outside > 0)
    stopped = len(summary["supervision"])
    doc = DOCUMENTED["supervision"]
    out["supervision"] = (stopped, 0, stopped == 0, doc is not None and stopped > doc)
    return out


def family_markdown(summary, stages, sensors, seconds=None):
    """The family's table (Markdown), the verdicts and the worst runs."""
    rows = []
    for key, what, bound in _ROWS:
        med, p95, worst, n = _stats(summary[key])
        rows.append([what, bound, str(n), _cell(med), _cell(p95), _cell(worst)])
    text = [markdown_table(["target", "bound", "runs", "median", "95 %", "worst"], rows), ""]
    v = verdicts(summary)
    text.append("Verdicts: " + "; ".join(f"{k} {'PASS' if ok else 'FAIL'} (worst {_cell(float(w))})"
                                        for k, (w, _, ok, _) in v.items()) + ".")
    text.append("")
    text.append(f"{stages} stages, sensors {', '.join(f'{s:g}' for s in sensors)} nm rms on the 2 nm grid"
                + (f"; {seconds / 60:.0f} min of computing" if seconds else "") + ".")
    eq = summary["equal"]
    if eq:
        text.append(f"The closed-loop FMU at 10 ms steps in holds: {sum(int(r.value) for r in eq)} of {len(eq)} "
                    "parts equal to the native exchange's rows bit for bit at its communication points.")
    if summary["errors"]:
        text.append(f"Runs stopped by an Error: {len(summary['errors'])}: " + "; ".join(
            f"stage {r.stage}, {r.sensor_nm:g} nm, {r.part}: {r.detail[:160]}" for r in summary["errors"][:5]))
    text.append("")
    text.append("The worst of each target:")
    text.append("")
    for key, what, _ in _ROWS[:6]:
        pool = sorted((r for r in summary[key] if math.isfinite(r.value)), key=lambda r: -r.value)[:3]
        for r in pool:
            text.append(f"- {key}: stage {r.stage}, {r.sensor_nm:g} nm, {r.part}: {_cell(r.value)}"
                        + (f" ({r.detail})" if r.detail else ""))
    return "\n".join(text) + "\n"


def breakdown_markdown(summary):
    """Per part and sensor: the median and worst of the targets that part measures."""
    groups = {}
    for key in ("growth", "fixed", "frame", "tone", "hour_fixed"):
        for r in summary[key]:
            part = re.sub(r" \(seed \d+\)", "", r.part)
            groups.setdefault((part, r.sensor_nm, key), []).append(r.value)
    rows = []
    for (part, nm, key), values in sorted(groups.items()):
        v = np.array(values, dtype=float)
        rows.append([part, f"{nm:g} nm", key, _cell(float(np.median(v))), _cell(float(np.max(v)))])
    return markdown_table(["part", "sensor", "target", "median", "worst"], rows) + "\n"


def write_into(path, text, name="stage_day"):
    """Replace what stands between ``<!-- name: begin -->`` and ``<!-- name: end -->`` in path."""
    p = Path(path)
    doc = p.read_text(encoding="utf-8")
    begin, end = f"<!-- {name}: begin -->", f"<!-- {name}: end -->"
    if begin not in doc or end not in doc:
        raise ValueError(f"{path}: the markers {begin} and {end} are missing")
    head, rest = doc.split(begin, 1)
    _, tail = rest.split(end, 1)
    p.write_text(head + begin + "\n" + text + end + tail, encoding="utf-8")


def main(argv=None, prog=None):
    ap = argparse.ArgumentParser(prog=prog or "python -m harness stage-day",
                                 description="Issue 43's targets over a stage's day on the stage family "
                                             "(docs/stage_day.md).")
    ap.add_argument("--stages", type=int, default=50, help="stages of the family (default 50)")
    ap.add_argument("--sensors", type=float, nargs="+", default=list(SENSORS_NM),
                    help="sensor noise rms [nm] (default 0 1 5 20 100 200)")
    ap.add_argument("--frames", type=int, default=FRAMES, help="raster frames per part (default 100)")
    ap.add_argument("--quick", action="store_true",
                    help="a slice: 20 frames, 60 s tones, no random hour")
    ap.add_argument("--fmu-stages", type=int, default=2,
                    help="stages whose 1 nm parts also run on the closed-loop FMU (default 2)")
    ap.add_argument("--laws", nargs="+", default=list(LAWS), choices=list(LAWS),
                    help="the controller's defaults (ours) and the estimates fixed (fixed); default both")
    ap.add_argument("--declared", action="store_true",
                    help="declare each sensor's noise to the controller (sup.sensor_noise = its rms)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--save", help="write every run's metrics to this JSON file")
    ap.add_argument("--load", help="read the runs' metrics from this JSON file instead of running")
    ap.add_argument("--write", help="write the table into this Markdown file, between its markers")
    args = ap.parse_args(argv)
    t0 = _time.perf_counter()
    if args.load:
        results = load_results(args.load)
        seconds = None
    else:
        parts = day_parts(frames=20 if args.quick else args.frames, tone_times=(60.0,) if args.quick else TONE_TIMES,
                          hour=not args.quick)
        tasks = family_tasks(args.stages, sensors=tuple(args.sensors), laws=tuple(args.laws), parts=parts,
                             fmu_stages=args.fmu_stages, declared=args.declared)
        print(f"{len(tasks)} tasks on {args.jobs} processes", file=sys.stderr)
        results = run_family(tasks, args.jobs, progress=lambda s: print(s, file=sys.stderr))
        seconds = _time.perf_counter() - t0
        if args.save:
            save_results(results, args.save)
    summary = summarize(results)
    stages = len({k[0] for k in results})
    sensors = sorted({k[1] for k in results})
    text = family_markdown(summary, stages, sensors, seconds) + "\n" + breakdown_markdown(summary)
    if args.write:
        write_into(args.write, text)
    print(text)
    regressions = [k for k, (_, _, _, reg) in verdicts(summary).items() if reg]
    unequal = [r for r in summary["equal"] if not r.value]
    if regressions or unequal:
        why = (f"worse than documented: {', '.join(regressions)}" if regressions else "") + \
              (f"; {len(unequal)} closed-loop FMU parts differ from the exchange" if unequal else "")
        print(f"stage_day: {why.strip('; ')}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
