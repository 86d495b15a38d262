"""The controller's supervision, measured: the fault table of docs/robustness.md and the
validation family (no false alarm, and how close the legitimate runs came to each threshold).

::

    python -m harness supervision faults                # the fault table, in Markdown
    python -m harness supervision fault-family          # every fault on 50 drawn stages
    python -m harness supervision family --stages 50    # the legitimate family and its margins
    python -m harness supervision family --stages 50 --duration 120 --scenarios 1hz 20hz
    python -m harness supervision false-alarms --specs module:function   # any family of RunSpecs
    python -m harness supervision stuck                 # a sensor that stops answering (issue 44)
    python -m harness supervision start                 # noisy sensors at start (issue 44)

**Faults** (:data:`FAULTS`): each is a wiring or rig fault a user can make, run on the three
FMUs wired by hand (:mod:`harness.masters.wired`) in both FMI editions, in a master that
exchanges values at communication points and in true Gauss-Seidel (plant, controller,
reference), and, where a parameter expresses it, on the harness's own masters (fmpy, native,
core). Each cell is the time of the Error from the controller's doStep ("-": none), or for a
degraded loop whether its Warning came.

**Family** (:func:`family_specs`): stages drawn at random (fixed seed) from the identification
family (:func:`harness.identify.family.draw_stage`) with the paper's sensor (2 nm resolution,
1 nm rms noise), the controller given the stage's own model (as ``export`` makes it) or the
paper's, the six tracking references, ``tf.delay`` 0 and 1, under every schedule of the wired
master (the exchange, fmpy's player, the six sequential orders: each the samples of the real
importer bit for bit, ``tests/test_supervision_family.py``) and, with ``--masters real``, under
the real importers (the harness's fmpy master, fmpy's SSP player, the container of
fmu-manipulation-toolbox in parallel and in each sequential order); and the saturation runs
(the mismatch scenarios with voltage limits at 90, 70 and 50 % of the peak they need). A
legitimate run must end without an Error and without a supervision warning; the wired runs
also give their margins (:func:`harness.loop.supervision_margins.margins`). Every run of a family is run
with each ``sup.reaction`` (0, error, and 1, safe: the safe runs in groups of their own), where
a safe state's Warning counts as a false alarm. :func:`false_alarms` is that check for any
family: a list of :class:`RunSpec` on the wired master (a sines scenario), a real importer
(:data:`REAL_MASTERS`) or a harness master (:data:`HARNESS_MASTERS`, any scenario, tables
included); ``false-alarms --specs module:function`` runs it on the RunSpecs a function returns.
The fault table also runs each fault with ``sup.reaction`` = 1 (:func:`run_fault_safe`), and
holds the blind spots issue 36 measured: a fault a working loop must ride through
(``tolerated``: dropouts) and one the supervision cannot tell (``blind``: an offset drift).

**Stuck** (:data:`STUCK_CASES`, :func:`stuck_family`) and **start** (:data:`START_PARTS`,
:func:`start_family`): issue 44's studies, on the C core through the binding (an exchange: y_ref two
samples ahead) on the stage's day's 50 stages with sensors of 0 to 200 nm rms: a sensor that sticks,
dies or sticks after a dropout in a hold and mid-scan (the time to the verdict, the stage's
excursion), and the delay detection of a stage at rest from t = 0 (Errors, wrong delays, how long it
waits). Each exits 1 on a false alarm or a wrong delay.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
import dataclasses
import importlib
from dataclasses import dataclass, field
import itertools
import re
import sys
import warnings as _warnings

import numpy as np

from .. import masters
from ..binding import core
from ..fmu import SAFE_STATE_WORDS, FMUError, LoopFaultWarning
from ..identify.family import SENSOR, draw_stage
from ..loop.supervision_margins import controller_samples, margins, thresholds
from ..masters import (CONTAINER_ORDER, SCHEDULES, ContainerTerminateWarning, Fault, schedule_name,
                      simulate_wired)
from ..scenarios import MISMATCH_SCENARIOS, get_scenario

__all__ = ["FaultCase", "FAULTS", "FAULT_SCHEDULES", "SAFE_SCHEDULES", "FaultResult", "run_fault",
           "run_fault_safe", "harness_fault", "REACTIONS", "HARNESS_MASTERS", "with_reactions", "false_alarms",
           "fault_results", "fault_markdown", "FaultSpec", "fault_family_specs", "run_fault_spec",
           "fault_family", "fault_family_markdown", "RunSpec", "RunResult", "family_specs", "run_spec",
           "summarize", "family_markdown", "StuckCase", "STUCK_CASES", "run_stuck", "stuck_family",
           "stuck_markdown", "START_PARTS", "run_start", "start_family", "start_markdown", "main"]

H = 0.0005
#: the schedules of the fault table: an exchanging master and true Gauss-Seidel
FAULT_SCHEDULES = ("exchange", ("plant", "controller", "reference"))
_SEQ = (("plant", "controller", "reference"),)
#: the supervision warnings (the stamps), by their words
_SUPERVISION_WARNINGS = ("is not connected (", "cannot be aligned", SAFE_STATE_WORDS)
#: the controller's Warning of a measurement it took for an outlier (fmu_src/fmi/fmu_controller.c)
_OUTLIER_WORDS = "an outlier (a reading dropped or glitched)"
#: sup.reaction by name (an Integer in the FMUs)
REACTIONS = {"error": 0, "safe": 1}


@dataclass(frozen=True)
class FaultCase:
    """One fault of the table.

    Attributes
    ----------
    name : str
    faults : tuple of Fault
        What the wiring does (:class:`harness.masters.wired.Fault`).
    plant, controller, reference : dict
        Parameter overrides that make the fault (a plant delay, a wrong ``mv.delay``, ...).
    scenario : str
    harness : bool
        The fault is a parameter: the harness's own masters run it too.
    degraded : bool
        A loop that works, degraded: a Warning is expected, not an Error.
    schedules : tuple
        The schedules it is a fault in (a set ``mv.delay`` is right in some).
    tolerated : bool
        A fault a working loop must ride through (isolated outliers): no Error is expected, and
        y must track y_d within :data:`SILENT_ERROR`.
    blind : bool
        A fault the supervision cannot tell from a working loop (docs/robustness.md, "What it
        cannot tell"): measured and shown, no Error expected.
    """

    name: str
    faults: tuple = ()
    plant: dict = field(default_factory=dict)
    controller: dict = field(default_factory=dict)
    reference: dict = field(default_factory=dict)
    scenario: str = "mismatch_5hz"
    harness: bool = False
    degraded: bool = False
    schedules: tuple = FAULT_SCHEDULES
    tolerated: bool = False
    blind: bool = False


#: the fault table's rows
FAULTS = (
    FaultCase("y_meas not connected (0)", (Fault("y_meas", "constant", 0.0),)),
    FaultCase("y_meas stuck at its first value", (Fault("y_meas", "stuck"),)),
    FaultCase("y_meas stuck from t = 1 s (a sensor that fails)", (Fault("y_meas", "stuck", start=1.0),)),
    FaultCase("y_meas inverted", (Fault("y_meas", "scale", -1.0),)),
    FaultCase("y_meas inverted from t = 1 s", (Fault("y_meas", "scale", -1.0, start=1.0),)),
    FaultCase("y_meas in mm (x 0.001)", (Fault("y_meas", "scale", 1e-3),)),
    FaultCase("y_meas in nm (x 1000)", (Fault("y_meas", "scale", 1e3),)),
    FaultCase("y_meas alternating +-10 um, whatever v does", (Fault("y_meas", "alternate", 10.0),)),
    FaultCase("v not reaching the plant (0)", (Fault("v", "constant", 0.0),)),
    FaultCase("v lost from t = 1 s", (Fault("v", "constant", 0.0, start=1.0),)),
    FaultCase("v inverted (amplifier or wiring)", (Fault("v", "scale", -1.0),)),
    FaultCase("amplifier gain 0.1", (Fault("v", "scale", 0.1),)),
    FaultCase("amplifier gain 10", (Fault("v", "scale", 10.0),)),
    FaultCase("y_ref and y_meas swapped", (Fault("y_meas", "source", "reference.y_ref"),
                                          Fault("y_ref", "source", "plant.y_meas"))),
    FaultCase("y_meas fed ReferenceSignal's y_ref", (Fault("y_meas", "source", "reference.y_ref"),)),
    FaultCase("plant input delay of 4 samples (tf.delay = 4)", plant={"tf.delay": 4}, harness=True),
    FaultCase("mv.delay = 0 set for a loop of d = 2", controller={"mv.delay": 0}, harness=True,
              schedules=("exchange",)),
    FaultCase("mv.delay = 2 set for a loop of d = 2", controller={"mv.delay": 2}, harness=True,
              schedules=("exchange",)),
    FaultCase("reference beyond reach (500 um at 0.25 Hz)",
              reference={"amplitude[1]": 500.0, "frequency[1]": 0.25}, scenario="mismatch_1hz"),
    FaultCase("t_meas not connected", (Fault("t_meas", "open"),), degraded=True, schedules=_SEQ),
    FaultCase("t_preview not connected", (Fault("t_preview", "open"),), degraded=True, schedules=_SEQ),
    # the blind spots of issue 36, measured
    FaultCase("sensor gain 1 -> 0.5 from t = 1 s", (Fault("y_meas", "scale", 0.5, start=1.0),)),
    FaultCase("y_meas frozen during a hold at 5 um, from t = 1 s (20 nm rms sensor)",
              (Fault("y_meas", "freeze", start=1.0),), plant={"sensor.noise_rms": 0.02},
              reference={"amplitude[1]": 0.0, "offset": 5.0}),
    FaultCase("y_meas = 0 once every 100 samples (dropouts)", (Fault("y_meas", "dropout", 0.0, every=100),),
              tolerated=True),
    FaultCase("sensor offset drifting by 1 um/s from t = 1 s", (Fault("y_meas", "drift", 1.0, start=1.0),),
              blind=True),
    FaultCase("mv.delay = 8 set for a loop of d = 2", controller={"mv.delay": 8}, harness=True,
              schedules=("exchange",)),
)
#: the safe reaction's columns: each fault (but the degraded loops) in these, with sup.reaction = 1
SAFE_SCHEDULES = (("exchange", 2), ("exchange", 3))
SAFE = {"sup.reaction": 1}


@dataclass
class FaultResult:
    """One fault under one master: the time of the controller's Error (None: none came) and its
    message, or for a degraded loop whether its Warning came (``time`` None) and the Warning.
    With ``sup.reaction`` = 1 (``safe``): ``time`` is ``sup.fault_time`` (None: no verdict),
    ``message`` the safe state's Warning, ``completed`` whether the run reached its end, and
    ``v_end`` the controller's v there. ``e_rms``: for a run nothing stopped, the rms of
    y_d - y over its second half [um]."""

    case: str
    master: str
    time: float | None
    message: str
    warned: bool = False
    safe: bool = False
    completed: bool = True
    v_end: float = float("nan")
    fault: int = 0
    e_rms: float = float("nan")


def _supervision_warnings(warnings):
    return [w for w in warnings if any(words in w for words in _SUPERVISION_WARNINGS)]


def _second_half_rms(res):
    """The rms of y_d - y over the second half of a wired run [um]."""
    half = res.samples[len(res.samples) // 2:]
    return float(np.sqrt(np.mean((half["y_d"] - half["y"]) ** 2))) if len(half) else float("nan")


def _wired_fault(case, schedule, plant, controller, fmi_version=2, duration=2.0, fmu_dir=None):
    """Run ``case`` on the wired master with these parameters: (the run, the controller's Error or
    its first supervision warning, whether that warning came)."""
    res = simulate_wired(case.scenario, schedule, case.faults, duration=duration, plant_params=plant,
                         controller_params=controller, reference_params=case.reference,
                         fmu_dir=fmu_dir, fmi_version=fmi_version)
    warned = _supervision_warnings(res.warnings["controller"])
    return res, res.error or (warned[0] if warned else ""), bool(warned)


def run_fault(case, schedule, fmi_version=2, duration=2.0, fmu_dir=None):
    """Run one fault on the wired master (:class:`FaultResult`)."""
    res, message, warned = _wired_fault(case, schedule, case.plant, case.controller, fmi_version, duration,
                                        fmu_dir)
    if not message and res.warnings["controller"]:
        message = res.warnings["controller"][0]         # a run nothing stopped: what it said first
    return FaultResult(case.name, f"FMI {fmi_version}.0, {schedule_name(schedule)}", res.error_time, message,
                       warned, e_rms=_second_half_rms(res) if res.error_time is None else float("nan"))


def run_fault_safe(case, schedule, fmi_version=2, duration=2.0, fmu_dir=None):
    """Run one fault on the wired master with ``sup.reaction`` = 1 (:class:`FaultResult`, ``safe``):
    when the verdict came (``sup.fault_time``), the safe state's Warning, whether the run went on to
    its end and where v ended."""
    res = simulate_wired(case.scenario, schedule, case.faults, duration=duration, plant_params=case.plant,
                         controller_params={**case.controller, **SAFE}, reference_params=case.reference,
                         fmu_dir=fmu_dir, fmi_version=fmi_version)
    said = [w for w in res.warnings["controller"] if SAFE_STATE_WORDS in w]
    return FaultResult(case.name, f"safe, FMI {fmi_version}.0, {schedule_name(schedule)}",
                       res.fault_time if res.fault else None, res.error or (said[0] if said else ""),
                       len(said) == 1, safe=True, completed=res.error_time is None,
                       v_end=float(res.samples["v"][-1]) if len(res.samples) else float("nan"), fault=res.fault,
                       e_rms=_second_half_rms(res) if not res.fault else float("nan"))


def harness_fault(case, backend, duration=2.0):
    """Run a parameter fault on one of the harness's masters (``fmpy``, ``native``, ``core``):
    the time of the stop and its message (:class:`FaultResult`)."""
    try:
        masters.closed_loop(backend)(case.scenario, plant_params=case.plant, controller_params=case.controller,
                                     duration=duration)
    except (FMUError, core.CoreDivergedError) as exc:
        text = str(exc)
        found = re.search(r"sample (\d+)", text)
        return FaultResult(case.name, backend, int(found.group(1)) * H if found else None, text)
    return FaultResult(case.name, backend, None, "")


def fault_results(fmi_versions=(2, 3), backends=("fmpy", "native", "core"), progress=None):
    """Every fault under every applicable master: a list of :class:`FaultResult`."""
    out = []
    for case in FAULTS:
        for fmi, schedule in itertools.product(fmi_versions, FAULT_SCHEDULES):
            if schedule in case.schedules:
                out.append(run_fault(case, schedule, fmi))
        if not case.degraded:
            for schedule, fmi in SAFE_SCHEDULES:
                if fmi in fmi_versions and schedule in case.schedules:
                    out.append(run_fault_safe(case, schedule, fmi))
        if case.harness:
            for backend in backends:
                out.append(harness_fault(case, backend))
        if progress is not None:
            progress(case.name)
    return out


def _message_gist(text):
    """The verdict's words: the message from its subject to its first full stop or colon."""
    for start in ("supervision stopped the loop", "the closed loop is unstable", "t_meas is", "t_preview is",
                  "y_meas = "):
        if start in text:
            text = text[text.index(start):]
            break
    return text.split("; fmi")[0]


def _onset(case):
    """When the fault begins [s] (a Fault's start; 0 for a parameter)."""
    return min((f.start for f in case.faults), default=0.0)


def fault_markdown(results):
    """The fault table (docs/robustness.md) from :func:`fault_results`: per fault and master,
    how long after the fault began the controller's doStep failed (or whether the Warning of a
    degraded loop came), then what the controller says, under the first master, per fault."""
    masters_ = []
    for r in results:
        if r.master not in masters_:
            masters_.append(r.master)
    lines = ["| # | fault | " + " | ".join(masters_) + " |",
             "|---|---|" + "---|" * len(masters_)]
    by = {(r.case, r.master): r for r in results}
    said = []
    for i, case in enumerate(FAULTS, start=1):
        cells = []
        for m in masters_:
            r = by.get((case.name, m))
            if r is None:
                cells.append("n/a")
            elif case.degraded:
                cells.append("Warning" if r.warned else "**none**")
            elif r.safe and r.time is not None and not (r.completed and r.warned and r.v_end == 0.0):
                cells.append(f"**{1e3 * (r.time - _onset(case)):.1f} ms, {'v ' + format(r.v_end, '.3g') + ' V' if r.completed else 'Error'}**")
            elif r.time is not None:
                cells.append(f"{1e3 * (r.time - _onset(case)):.1f} ms")
            elif case.tolerated or case.blind:
                cells.append("runs" if r.safe else f"runs, {1e3 * r.e_rms:.3g} nm")
            else:
                cells.append("**not stopped**")
        lines.append(f"| {i} | {case.name} | " + " | ".join(cells) + " |")
        first = next((by[(case.name, m)] for m in masters_ if (case.name, m) in by), None)
        if first is not None:
            gist = _message_gist(first.message) if first.message else \
                f"nothing: y tracked y_d to {1e3 * first.e_rms:.3g} nm rms over the second half"
            said.append(f"{i}. {case.name} ({first.master}): \"{gist}\"")
    return "\n".join(lines) + "\n\n" + "\n".join(said)


# ---------------------------------------------------------------------------
# the fault family: every fault on stages drawn from the identification family
# ---------------------------------------------------------------------------

#: a faulty run nothing stopped must still track y_d within this rms [um] over its second half
SILENT_ERROR = 0.1


@dataclass(frozen=True)
class FaultSpec:
    """One fault of :data:`FAULTS` on one drawn stage, under one schedule of the wired master."""

    case: int                   # index into FAULTS
    stage: int
    model: str                  # the controller's model: "own" (the stage's) or "paper"
    schedule: object
    plant: dict
    controller: dict


def fault_family_specs(stages=50, seed=2028, models=("own", "paper")):
    """Every fault of :data:`FAULTS` in each of its schedules, on ``stages`` stages drawn from the
    identification family (the validation family's draw: the same seed gives the same stages),
    with the paper's sensor, the controller given the stage's own model or the paper's: a list of
    :class:`FaultSpec`. The fault's own parameters (a plant delay, a wrong ``mv.delay``) are set
    over the stage's."""
    specs = []
    for i, model, plant, controller in _drawn_loops(stages, seed, models):
        for c, case in enumerate(FAULTS):
            for schedule in case.schedules:
                specs.append(FaultSpec(c, i, model, schedule, {**plant, **case.plant},
                                       {**controller, **case.controller}))
    return specs


def run_fault_spec(spec, duration=2.0, fmi_version=2):
    """Run one :class:`FaultSpec`: (spec, seconds from the fault's onset to the controller's Error
    or None, its message or the supervision warning, whether that warning came, and for a run
    nothing stopped the rms of y_d - y over its second half [um]: is the stage where it should
    be?)."""
    case = FAULTS[spec.case]
    try:
        res, message, warned = _wired_fault(case, spec.schedule, spec.plant, spec.controller, fmi_version,
                                            duration)
    except (FMUError, core.CoreDivergedError) as exc:        # refused before the loop ran
        return spec, None, f"refused: {exc}", False, float("nan")
    time = None if res.error_time is None else res.error_time - _onset(case)
    e_rms = float("nan")
    if time is None:
        half = res.samples[len(res.samples) // 2:]
        e_rms = float(np.sqrt(np.mean((half["y_d"] - half["y"]) ** 2)))
    return spec, time, message, warned, e_rms


def fault_family(specs, jobs=2, progress=None):
    """Run the fault family; per fault (index into :data:`FAULTS`): a dict with ``runs``,
    ``caught`` (an Error, or the Warning of a degraded loop; for a tolerated fault, a run that went
    on and tracked within :data:`SILENT_ERROR`), the times of the Errors [s], ``verdicts`` (how many
    runs each verdict's words ended), ``e_rms`` (the rms tracking errors of y over the second half
    of the runs nothing stopped [um]) and ``missed`` (the runs not caught: their spec, what was said
    and that error)."""
    out = {c: {"runs": 0, "caught": 0, "times": [], "verdicts": {}, "missed": [], "e_rms": []}
           for c in range(len(FAULTS))}
    for spec, time, text, warned, e_rms in _run_all(specs, jobs, progress, run=run_fault_spec, chunksize=4,
                                                    every=500):
        o = out[spec.case]
        o["runs"] += 1
        case = FAULTS[spec.case]
        if time is None:
            o["e_rms"].append(e_rms)
        if case.tolerated:
            caught = time is None and e_rms <= SILENT_ERROR
        else:
            caught = warned if case.degraded else time is not None
        if case.tolerated and caught:
            o["caught"] += 1
        elif caught:
            o["caught"] += 1
            if time is not None:
                o["times"].append(time)
            gist = _verdict(text)
            o["verdicts"][gist] = o["verdicts"].get(gist, 0) + 1
        else:
            o["missed"].append((spec, text, e_rms))
    return out


def _verdict(text):
    """The verdict's name: the supervision's (in parentheses), the monitor's or the warning's."""
    found = re.search(r"supervision stopped the loop \(([^)]*)\)", text)
    if found:
        return found.group(1)
    if "the closed loop is unstable" in text:
        return "monitor"
    for words in ("t_meas is not connected", "t_preview is not connected", "cannot be aligned"):
        if words in text:
            return words
    return "other"


def fault_family_markdown(family):
    """The fault family's table: per fault, the runs, how many were caught, the median and the
    worst time from the fault's onset to the Error, the verdicts that caught them, and how far
    the stage was from y_d in the runs nothing caught (their largest rms error of y). A tolerated
    fault (dropouts) counts the runs that rode through it and gives their median and worst rms
    tracking error instead of times; a blind spot's row is marked so."""
    lines = ["| # | fault | runs | caught | median | worst | verdicts | not caught: largest rms error of y |",
             "|---|---|---|---|---|---|---|---|"]
    for c, case in enumerate(FAULTS):
        o = family[c]
        if not o["runs"]:
            continue
        t = np.array(o["times"]) * 1e3
        median = f"{np.median(t):.1f} ms" if t.size else ("Warning" if case.degraded else "-")
        worst = f"{t.max():.1f} ms" if t.size else ("Warning" if case.degraded else "-")
        verdicts = ", ".join(f"{k} {v}" for k, v in sorted(o["verdicts"].items(), key=lambda kv: -kv[1]))
        caught = str(o["caught"]) if o["caught"] == o["runs"] else f"**{o['caught']}**"
        missed = [e for _, _, e in o["missed"]]
        left = f"{len(missed)} runs, {1e3 * np.nanmax(missed):.3g} nm" if missed else "-"
        if case.tolerated:
            e = np.array(o["e_rms"]) * 1e3
            median = f"{np.median(e):.3g} nm rms" if e.size else "-"
            worst = f"{e.max():.3g} nm rms" if e.size else "-"
            verdicts = f"rode through {o['caught']}" + (f", {verdicts}" if verdicts else "")
        elif case.blind:
            caught = f"{o['caught']} (blind spot)"
        lines.append(f"| {c + 1} | {case.name} | {o['runs']} | {caught} | {median} | {worst} | {verdicts} | {left} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------
# the validation family
# ---------------------------------------------------------------------------

#: the real importers of docs/cosimulation.md, section 4
REAL_MASTERS = ("harness Jacobi", "harness Gauss-Seidel, plant first", "harness Gauss-Seidel, controller first",
                "fmpy SSP player", "container, parallel") + tuple(
    "container, sequential: " + ", ".join(o) for o in itertools.permutations(("reference", "controller", "plant")))
_CONTAINER_FILE = {"reference": "ReferenceSignal.fmu", "controller": "AdaptiveCompoundController.fmu",
                   "plant": "PiezoStage.fmu"}


@dataclass(frozen=True)
class RunSpec:
    """One legitimate run of the family."""

    group: str
    master: str                 # "wired: <schedule>", a real importer (REAL_MASTERS) or HARNESS_MASTERS
    scenario: str
    plant: dict
    controller: dict
    reference: dict
    duration: float | None


@dataclass
class RunResult:
    """What one legitimate run did: the Error that stopped it (""), the supervision warnings (a
    safe state's among them), its margins (wired runs), what the importer said besides (a
    container refusing to terminate after a run whose FMUs end with a Warning) and whether the
    controller took a measurement for an outlier (wired runs: its Warning)."""

    spec: RunSpec
    error: str
    warnings: list
    margins: object = None
    notes: tuple = ()
    outlier: str = ""


def _drawn_loops(stages, seed, models):
    """The drawn loops both families run: for each of ``stages`` stages drawn from the
    identification family (``seed``) and each controller model, (stage index, model, the
    stage's parameters with the paper's sensor, the controller's: the stage's own model for
    ``"own"``, the default (the paper's) otherwise)."""
    rng = np.random.default_rng(seed)
    draws = [draw_stage(rng) for _ in range(stages)]
    for i, stage in enumerate(draws):
        for model in models:
            yield i, model, {**stage, **SENSOR, "sensor.seed": i + 1}, (dict(stage) if model == "own" else {})


def _tracking(names=None):
    names = names or [n.split("mismatch_", 1)[1] for n in MISMATCH_SCENARIOS]
    return [f"track_{n}" for n in names]


def family_specs(stages=50, seed=2028, scenarios=None, masters_=("wired",), duration=None,
                 models=("own", "paper"), tf_delays=(0, 1), saturation=True):
    """The legitimate runs of the validation family (:class:`RunSpec`).

    Parameters
    ----------
    stages : int
        Stages drawn from the identification family.
    seed : int
    scenarios : list of str, optional
        The references (``1hz``, ``5hz``, ..., ``1_10_20hz``; default all six).
    masters_ : tuple of str
        ``"wired"`` (every schedule of the wired master) and/or ``"real"`` (:data:`REAL_MASTERS`).
    duration : float, optional
        Override the scenarios' 3 s.
    models : tuple of str
        The controller's model: the stage's ``"own"`` (identified) and/or the ``"paper"``'s.
    tf_delays : tuple of int
    saturation : bool
        Add the saturation runs (mismatch plant, limits at 90, 70, 50 % of the needed peak).
    """
    names = _tracking(scenarios)
    schedules = []
    if "wired" in masters_:
        schedules += [f"wired: {schedule_name(s)}" for s in SCHEDULES]
    if "real" in masters_:
        schedules += list(REAL_MASTERS)
    specs = []
    for _, model, stage_plant, controller in _drawn_loops(stages, seed, models):
        for master, td, sc in itertools.product(schedules, tf_delays, names):
            plant = {**stage_plant, "tf.delay": td}
            specs.append(RunSpec(f"stages, {model} model", master, sc, plant, controller, {}, duration))
    if saturation:
        peak = {"1hz": 18.0, "5hz": 18.0, "10hz": 18.5, "20hz": 19.0}   # |v| the mismatch runs need [V]
        for frac, master, td, sc in itertools.product((0.9, 0.7, 0.5), schedules, tf_delays,
                                                     [n.split("track_", 1)[1] for n in names]):
            limit = peak.get(sc, 49.0) * frac
            specs.append(RunSpec(f"saturation, limits {int(100 * frac)} % of the peak", master,
                                 f"mismatch_{sc}", {"tf.delay": td}, {"sat.v_min": -limit, "sat.v_max": limit},
                                 {}, duration))
    return specs


def _schedule_of(master):
    text = master.split("wired: ", 1)[1]
    return text if text in ("exchange", "player") else tuple(text.split(", "))


def run_spec(spec):
    """Run one :class:`RunSpec`; a :class:`RunResult` (its margins on the wired master)."""
    sc = get_scenario(spec.scenario)
    error, warnings, mg, notes, outlier = "", [], None, (), ""
    try:
        if spec.master.startswith("wired: "):
            res = simulate_wired(sc.name, _schedule_of(spec.master), (), duration=spec.duration,
                                 plant_params=spec.plant, controller_params=spec.controller,
                                 reference_params=spec.reference)
            error = res.error
            warnings = _supervision_warnings(res.warnings["controller"])
            outlier = next((w for w in res.warnings["controller"] if _OUTLIER_WORDS in w), "")
            c = {**core.default_controller_params(), **spec.controller}
            mg = margins(controller_samples(res), tuple(c[k] for k in ("tf.a1", "tf.a2", "tf.b1", "tf.b2")),
                         spec.controller)
        else:
            with _warnings.catch_warnings(record=True) as caught:
                _warnings.simplefilter("always", ContainerTerminateWarning)
                _warnings.simplefilter("always", LoopFaultWarning)
                _run_real(spec)
            notes = tuple(str(w.message) for w in caught if issubclass(w.category, ContainerTerminateWarning))
            warnings = [str(w.message) for w in caught if issubclass(w.category, LoopFaultWarning)]
    except (FMUError, core.CoreDivergedError) as exc:
        error = str(exc)
    except Exception as exc:     # an importer's own failure is a finding too; keep the family going
        error = f"{type(exc).__name__}: {exc}"
    return RunResult(spec, error, warnings, mg, notes, outlier)


#: the harness's own masters a RunSpec may name (any scenario, tables included), by their backend
HARNESS_MASTERS = {"harness native": "native", "harness core": "core", "harness closed-loop FMU": "closed-loop-fmu"}


def _run_real(spec):
    m = spec.master
    kwargs = {"plant_params": spec.plant, "controller_params": spec.controller}
    if spec.duration is not None and m.startswith("harness"):
        kwargs["duration"] = spec.duration
    if m in HARNESS_MASTERS:
        masters.closed_loop(HARNESS_MASTERS[m])(spec.scenario, **kwargs)
    elif m.startswith("harness"):
        extra = {"master": "jacobi"} if "Jacobi" in m else \
            {"step_order": "controller-first" if "controller first" in m else "plant-first"}
        masters.closed_loop("fmpy")(spec.scenario, **kwargs, **extra)
    elif m == "fmpy SSP player":
        masters.closed_loop("ssp-player")(spec.scenario, **kwargs)
    else:
        sequential = "sequential" in m
        order = CONTAINER_ORDER
        if sequential:
            order = tuple(_CONTAINER_FILE[n] for n in m.split(": ")[1].split(", "))
        masters.closed_loop("container")(spec.scenario, sequential=sequential, order=order, **kwargs)


def _run_all(specs, jobs, progress=None, run=None, chunksize=8, every=200):
    """``run`` (default :func:`run_spec`) of each spec, in order, on ``jobs`` processes; the count
    said to ``progress`` every ``every`` runs."""
    run = run_spec if run is None else run
    if jobs <= 1:
        for spec in specs:
            yield run(spec)
        return
    with ProcessPoolExecutor(jobs) as ex:
        for i, r in enumerate(ex.map(run, specs, chunksize=chunksize)):
            if progress is not None and i % every == 0:
                progress(f"{i} of {len(specs)} runs")
            yield r


def summarize(results):
    """Per group: runs, Errors, supervision warnings, and the closest approach to each
    threshold over its wired runs (the worst margin)."""
    th = thresholds()
    groups = {}
    for r in results:
        g = groups.setdefault(r.spec.group, {"runs": 0, "errors": [], "warnings": [], "margins": [],
                                             "notes": [], "outliers": []})
        g["runs"] += 1
        g["notes"] += [(r.spec, n) for n in r.notes]
        if r.outlier:
            g["outliers"].append((r.spec, r.outlier))
        if r.error:
            g["errors"].append((r.spec, r.error))
        if r.warnings:
            g["warnings"].append((r.spec, r.warnings[0]))
        if r.margins is not None:
            g["margins"].append(r.margins)
    out = {}
    for name, g in groups.items():
        ms = g["margins"]
        lows = [m.gain_low for m in ms if m.gain_low is not None]
        highs = [m.gain_high for m in ms if m.gain_high is not None]
        delays = [m.delay_unexplained for m in ms if m.delay_unexplained is not None]
        drops = [m.gain_drop for m in ms if m.gain_drop is not None]
        rises = [m.gain_rise for m in ms if m.gain_rise is not None]
        out[name] = {
            "runs": g["runs"], "errors": g["errors"], "warnings": g["warnings"], "notes": g["notes"],
            "outliers": g["outliers"],
            "gain_drop": (max(drops) if drops else None, th.gain_drop),
            "gain_rise": (max(rises) if rises else None, th.gain_rise),
            "frozen_run": (max((m.frozen_ratio for m in ms), default=0.0), 1.0),
            "gain_low": (min(lows) if lows else None, th.gain_min),
            "gain_high": (max(highs) if highs else None, th.gain_max),
            "delay_unexplained": (max(delays) if delays else None, th.delay_fraction),
            "candidate_run": (max((m.candidate_run for m in ms), default=0), th.confirm),
            "monitor_share": (max((m.monitor_share for m in ms), default=0.0), th.monitor_share),
            "clip_run": (max((m.clip_run for m in ms), default=0), round(th.clip_time / H)),
            "detection_run": (max((m.detection_run for m in ms), default=0), round(th.detect_time / H)),
            "monitor_run": (max((m.monitor_run for m in ms), default=0),
                            core.default_controller_params()["monitor.divergence_samples"]),
        }
    return out


def family_markdown(summary):
    """The family's table: one row per group."""
    def fmt(value, digits=3):
        if value is None:
            return "-"
        return f"{value:.{digits}g}" if isinstance(value, float) else str(value)

    # the thresholds summarize paired with each margin (the same in every group)
    first = next(iter(summary.values()), {})
    th = {key: f"{value[1]:g}" for key, value in first.items() if isinstance(value, tuple)}
    rows = [f"| runs | Errors | supervision warnings | importer notes | outliers replaced | "
            f"weakest gain (>= {th['gain_low']}) | "
            f"strongest gain (<= {th['gain_high']}) | unexplained by the law's delays (< {th['delay_unexplained']}) | "
            f"gain fell (< {th['gain_drop']}) | gain rose (< {th['gain_rise']}) | "
            f"longest fault candidate (< {th['candidate_run']}) | share of large errors (< {th['monitor_share']}) | "
            f"longest clipping [samples] (< {th['clip_run']}) | longest detection [samples] "
            f"(< {th['detection_run']}) | longest large-error run (< {th['monitor_run']}) | "
            f"longest still y_meas after noise, over the run that stops it (< {th['frozen_run']}) | group |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in summary.items():
        rows.append(f"| {s['runs']} | {len(s['errors'])} | {len(s['warnings'])} | {len(s['notes'])} | "
                    f"{len(s['outliers'])} | {fmt(s['gain_low'][0])} | "
                    f"{fmt(s['gain_high'][0])} | {fmt(s['delay_unexplained'][0])} | {fmt(s['gain_drop'][0])} | "
                    f"{fmt(s['gain_rise'][0])} | {s['candidate_run'][0]} | "
                    f"{fmt(s['monitor_share'][0])} | {s['clip_run'][0]} | {s['detection_run'][0]} | "
                    f"{s['monitor_run'][0]} | {fmt(s['frozen_run'][0])} | {name} |")
    return "\n".join(rows)


def with_reactions(specs, reactions=("error", "safe")):
    """Each :class:`RunSpec` once per ``sup.reaction`` (:data:`REACTIONS` by name); the runs with
    ``safe`` in groups of their own (``<group>, sup.reaction = safe``)."""
    out = []
    for reaction in reactions:
        code = REACTIONS[reaction]
        for spec in specs:
            if code == 0:
                out.append(spec)
            else:
                out.append(dataclasses.replace(spec, group=f"{spec.group}, sup.reaction = {reaction}",
                                               controller={**spec.controller, "sup.reaction": code}))
    return out


def false_alarms(specs, reactions=("error", "safe"), jobs=2, progress=None):
    """The no-false-alarm check of a legitimate family: run every :class:`RunSpec` (any family's:
    the wired master's schedules for a sines scenario, a real importer of :data:`REAL_MASTERS`, or a
    harness master of :data:`HARNESS_MASTERS` for any scenario, tables included) with each
    ``sup.reaction`` and summarize them (:func:`summarize`).

    Returns
    -------
    (dict, list)
        The summary per group, and the alarms: ``(group, spec, what was said)`` for every run that
        ended with an Error or logged a supervision warning (a safe state's among them). A
        legitimate family must give none.
    """
    summary = summarize(_run_all(with_reactions(list(specs), reactions), jobs, progress=progress))
    alarms = [(g, spec, text) for g, s in summary.items() for spec, text in s["errors"] + s["warnings"]]
    return summary, alarms


# ---------------------------------------------------------------------------
# a sensor that stops answering (issue 44): stuck, dead, stuck after a dropout
# ---------------------------------------------------------------------------

#: the sensors of the stuck family: rms noise [nm] on the 2 nm grid (the stage's day's)
STUCK_SENSORS_NM = (0, 1, 5, 20, 100, 200)
#: when the sensor fails in a hold (the reference at 5 um since 0.3 s) and mid-ramp of a scan
STUCK_HOLD_ONSET = 2.0
STUCK_SCAN_ONSET = 1.2125
#: how long each run goes on after the onset [s]
STUCK_AFTER = 0.5
#: the targets: named within 20 ms in motion, 0.2 s in a hold; the stage within 2 um beyond the
#: reference in a scan, 0.1 um of the set-point in a hold (a reading that sticks where it was)
STUCK_TARGETS = {"scan": (0.02, 2.0), "hold": (0.2, 0.1)}


@dataclass(frozen=True)
class StuckCase:
    """One way a sensor stops answering: in a hold or a scan, what y_meas reads from the onset.

    Attributes
    ----------
    name : str
    where : {"hold", "scan"}
    reads : {"last", "zero", "dropout"}
        The last reading (plus ``offset``), 0 (a dead sensor), or one reading of 0 and then the
        last good one (a sensor that sticks after a dropout); "none": no fault (the legitimate run).
    offset : float
        Added to the stuck reading [um].
    """

    name: str
    where: str
    reads: str
    offset: float = 0.0


STUCK_CASES = (
    StuckCase("none, hold", "hold", "none"),
    StuckCase("none, scan", "scan", "none"),
    StuckCase("stuck in a hold", "hold", "last"),
    StuckCase("stuck 2 nm off in a hold", "hold", "last", 0.002),
    StuckCase("stuck mid-scan", "scan", "last"),
    StuckCase("dead (reads 0) in a hold", "hold", "zero"),
    StuckCase("dead (reads 0) mid-scan", "scan", "zero"),
    StuckCase("stuck after a dropout, mid-scan", "scan", "dropout"),
)


def _stuck_profile(where, after=STUCK_AFTER):
    from ..scenarios import profile_signal
    if where == "hold":
        segs = ({"hold": 0.2}, {"to": 5.0, "shape": "scurve", "time": 0.1}, {"hold": STUCK_HOLD_ONSET + after})
    else:
        segs = ({"hold": 0.2}, {"scan": "triangle", "frequency": 10.0, "amplitude": 10.0,
                                "time": STUCK_SCAN_ONSET + after})
    sig = profile_signal(segs, step=H)
    return sig.evaluate(np.arange(sig.samples) * H)


def run_stuck(case, plant, controller=None, after=STUCK_AFTER, keep=False):
    """Run one :class:`StuckCase` on the C core (the plant and the controller stepped as a master that
    exchanges at communication points: y_ref = y_d two samples ahead). Returns a dict: ``fault`` (the
    verdict's name, "" for none), ``error`` (its message), ``time`` (from the onset to the verdict [s],
    nan for none), ``excursion`` (the largest |y - y_d| from the onset to the verdict, or to the end
    [um]), ``before`` (the largest |y - y_d| over the 0.5 s before the onset [um]), ``stopped_before``
    (a verdict before the onset: a false alarm) and ``drift`` (for a run nothing stopped, how far y
    went from y_d at the end [um]). ``after``: how long the run goes on after the onset [s]. With
    ``sup.reaction`` = 1 in ``controller`` the run goes on in the safe state (the verdict from
    ``sup.fault``) and the excursion runs to the verdict. ``keep``: also ``trace``, the arrays
    ``time, y_d, y, y_meas`` (as the controller received it) and ``v`` up to the last sample run."""
    y_d = _stuck_profile(case.where, after)
    n = len(y_d)
    k0 = int(round((STUCK_HOLD_ONSET if case.where == "hold" else STUCK_SCAN_ONSET) / H))
    p = core.Plant(plant)
    c = core.Controller(controller or {})
    v, held, fault, text, stop, k_fault = 0.0, 0.0, "", "", n, n
    y, ym, vs = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        y[k] = p.output.y
        meas = p.output.y_meas
        if case.reads != "none" and k >= k0:
            if k == k0:
                held = (0.0 if case.reads == "zero" else meas) + case.offset
            meas = 0.0 if case.reads == "dropout" and k == k0 else held
        ym[k] = meas
        vs[k] = v
        try:
            out = c.step(y_d[min(n - 1, k + 2)], meas)
        except core.CoreDivergedError as exc:
            fault = getattr(exc, "fault", "monitor")
            text, stop, k_fault = str(exc), k, k
            break
        if c.raw.fault and not fault:
            fault = core.ffi.string(core.lib().piezo_supervisor_fault_name(c.raw.fault)).decode()
            k_fault = k
        p.step(v)
        v = out.v
    err = np.abs(y[:stop] - y_d[:stop])
    res = {"fault": fault, "error": text, "time": (k_fault - k0) * H if fault else float("nan"),
           "excursion": float(err[k0:k_fault].max()) if k_fault > k0 else 0.0,
           "before": float(err[max(0, k0 - 1000):k0].max()) if stop > k0 else float(err.max()),
           "stopped_before": fault != "" and k_fault < k0,
           "drift": float(abs(y[stop - 1] - y_d[stop - 1])) if not fault else float("nan")}
    if keep:
        res["trace"] = (np.arange(stop) * H, y_d[:stop], y[:stop], ym[:stop], vs[:stop])
    return res


def _day_plant(i, nm):
    """The stage's day's i-th stage (seed 2026) with a sensor of nm rms on the 2 nm grid."""
    from .stage_day_table import SEED
    from .stage_use_table import draw_stages, stage_plant
    return stage_plant(draw_stages(i + 1, SEED)[i], i, nm)


def _day_controller(nm, declared):
    """The controller at its defaults; ``declared``: with the sensor's noise declared to it
    (``sup.sensor_noise`` = nm rms, for a sensor with noise)."""
    return {"sup.sensor_noise": nm * 1e-3} if declared and nm > 0 else {}


def _run_stuck_spec(spec):
    i, nm, case_index, declared = spec
    return spec, run_stuck(STUCK_CASES[case_index], _day_plant(i, nm), _day_controller(nm, declared))


def _per_key_and_sensor(specs, run, jobs, progress):
    """Run (i, nm, key) specs: ``{(key, nm): [result, ...]}`` in stage order."""
    out = {}
    for spec, res in _run_all(specs, jobs, progress, run=run, chunksize=4, every=200):
        out.setdefault((spec[2], spec[1]), []).append(res)
    return out


def stuck_family(stages=50, sensors=STUCK_SENSORS_NM, cases=None, jobs=2, progress=None, declared=False):
    """Every :data:`STUCK_CASES` case on the stage's day's stages (seed 2026, the controller at its
    defaults: the nominal model) with each sensor: ``{(case, nm): [result, ...]}``. ``declared``: each
    sensor's noise declared to the controller (``sup.sensor_noise``)."""
    cases = range(len(STUCK_CASES)) if cases is None else cases
    specs = [(i, nm, c, declared) for c in cases for nm in sensors for i in range(stages)]
    return _per_key_and_sensor(specs, _run_stuck_spec, jobs, progress)


def stuck_markdown(family):
    """The stuck family as a Markdown table: per case and sensor the runs, those stopped (before the
    onset: false alarms), the time to the verdict (median, worst), the stage's excursion from y_d
    after the onset (median, worst) beside the largest error before it, and the verdicts."""
    from ..text_tables import markdown_table
    rows = []
    for (ci, nm), res in sorted(family.items()):
        case = STUCK_CASES[ci]
        t = np.array([r["time"] for r in res if not r["stopped_before"]])
        ex = np.array([r["excursion"] for r in res if not r["stopped_before"]])
        before = max(r["before"] for r in res)
        stopped = int(np.isfinite(t).sum())
        early = sum(r["stopped_before"] for r in res)
        kinds = {}
        for r in res:
            kinds[r["fault"] or "none"] = kinds.get(r["fault"] or "none", 0) + 1
        ms = lambda x: f"{1e3 * x:.1f} ms" if np.isfinite(x) else "-"      # noqa: E731
        rows.append([case.name, f"{nm:g}", str(len(res)), str(stopped), str(early),
                     ms(np.nanmedian(t)) if stopped else "-", ms(np.nanmax(t)) if stopped else "-",
                     f"{np.median(ex):.3g}" if ex.size else "-", f"{np.max(ex):.3g}" if ex.size else "-",
                     f"{before:.3g}", ", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))])
    return markdown_table(["case", "sensor [nm rms]", "runs", "stopped", "stopped before the onset",
                           "time median", "time worst", "excursion median [um]", "excursion worst [um]",
                           "largest error before [um]", "verdicts"], rows)


# ---------------------------------------------------------------------------
# noisy sensors at start (issue 44): the delay detection on a stage at rest from t = 0
# ---------------------------------------------------------------------------

#: the start-up parts: 0.2 s at rest, then two raster frames (1, 10, 50 Hz, 0.1 s dwells) or a
#: 10 um step; or a tone from t = 0 (1 and 20 Hz, 2 s), 0.5 s at rest and a step
START_PARTS = ("raster 1 Hz", "raster 10 Hz", "raster 50 Hz", "fresh step", "1 Hz tone", "20 Hz tone")
#: the loop delay of the exchange the start-up family runs in (y_ref two samples ahead)
START_DELAY = 2


def _start_profile(part):
    from ..scenarios import profile_signal
    from .stage_day_table import FRESH, raster_part, tone_part
    if part.startswith("raster"):
        segs = raster_part(float(part.split()[1]), 0.1, 2).segments
    elif part == "fresh step":
        segs = FRESH.segments
    else:
        segs = tone_part(float(part.split()[0]), 2.0).segments
    sig = profile_signal(segs, step=H)
    return sig.evaluate(np.arange(sig.samples) * H)


def run_start(part, plant, controller=None):
    """Run one start-up part on the C core in an exchange (y_ref = y_d two samples ahead, a loop of
    delay 2): ``{"delay": the first d chosen (0: none), "time": when [s], "error": the Error's
    message ("" for none)}``."""
    y_d = _start_profile(part)
    n = len(y_d)
    p = core.Plant(plant)
    c = core.Controller(controller or {})
    v, first, at, error = 0.0, 0, float("nan"), ""
    for k in range(n):
        try:
            out = c.step(y_d[min(n - 1, k + START_DELAY)], p.output.y_meas)
        except core.CoreDivergedError as exc:
            error = str(exc)
            break
        if first == 0 and out.delay > 0:
            first, at = out.delay, k * H
        p.step(v)
        v = out.v
    return {"delay": first, "time": at, "error": error}


def _run_start_spec(spec):
    i, nm, part, declared = spec
    return spec, run_start(part, _day_plant(i, nm), _day_controller(nm, declared))


def start_family(stages=50, sensors=STUCK_SENSORS_NM, parts=START_PARTS, jobs=2, progress=None, declared=False):
    """Every start-up part on the stage's day's stages with each sensor: ``{(part, nm): [result]}``.
    ``declared``: each sensor's noise declared to the controller (``sup.sensor_noise``)."""
    specs = [(i, nm, part, declared) for part in parts for nm in sensors for i in range(stages)]
    return _per_key_and_sensor(specs, _run_start_spec, jobs, progress)


def start_markdown(family):
    """Per part and sensor: runs, Errors, the delays first chosen (the loop's is 2), the runs still
    detecting at the end (waiting for the reference), and when the delay was chosen."""
    from ..text_tables import markdown_table
    rows = []
    for (part, nm), res in sorted(family.items(), key=lambda kv: (START_PARTS.index(kv[0][0]), kv[0][1])):
        t = np.array([r["time"] for r in res if r["delay"] > 0])
        wrong = sum(r["delay"] not in (0, START_DELAY) for r in res)
        rows.append([part, f"{nm:g}", str(len(res)), str(sum(bool(r["error"]) for r in res)), str(wrong),
                     str(sum(r["delay"] == 0 and not r["error"] for r in res)),
                     f"{1e3 * np.median(t):.1f} ms" if t.size else "-", f"{1e3 * np.max(t):.1f} ms" if t.size else "-"])
    return markdown_table(["part", "sensor [nm rms]", "runs", "Errors", "wrong delay chosen",
                           "still detecting at the end", "chosen, median", "chosen, worst"], rows)


# ---------------------------------------------------------------------------------------------
# sup.reset: leaving the safe state (docs/robustness.md, "Leaving the safe state")
# ---------------------------------------------------------------------------------------------
RESET_SENSORS_NM = (5, 20, 100, 200)
#: y_d: a 5 um hold, the fault at FAULT, a reset raised while the cause persists (EARLY: refused),
#: the cause gone at CLEARED, a reset (LATE: accepted), a 10 um step at STEP, the end at END [s]
RESET_TIMES = {"fault": 2.0, "early": 2.6, "cleared": 2.8, "late": 3.0, "step": 3.5, "end": 4.0}
RESET_HOLD, RESET_STEP, RESET_FAR = 5.0, 15.0, 400.0


@dataclass(frozen=True)
class ResetCase:
    """A fault the safe state catches, the reset while it persists and the one after it is gone.

    ``kind``: "stuck" (y_meas holds its reading from the onset until ``cleared``), "dead" (it reads
    0), "reach" (y_d jumps to 400 um, beyond any stage's reach, and returns to the hold at
    ``cleared``: v held at a limit), "inverted" (the stage gets -v from the onset on, never
    cleared: in the hold the loop runs to a rail, v held at a limit; the reset at ``late`` is
    accepted, as the rail's reading, against the way v went, says nothing of the reach, and the
    restarted supervision must stop the loop again). ``faults``: the first verdicts that name the
    cause (a dead 200 nm sensor may be "no response", a reference out of reach with a noisy sensor
    the monitor's "loop unstable" while v is at the rail), empty: any.
    ``refusal``: the reason the early reset is refused (``piezo_reset_refusal``), None when the
    cause cannot be seen at rest and the early reset is not raised."""
    name: str
    kind: str
    faults: tuple
    refusal: int | None


RESET_CASES = (
    ResetCase("sensor stuck, then back", "stuck", ("y_meas frozen", "no response"), 4),
    ResetCase("sensor dead (reads 0), then back", "dead", ("y_meas frozen", "no response"), 4),
    ResetCase("reference out of reach, then back", "reach", ("v held at a limit", "loop unstable"), 5),
    ResetCase("amplifier inverted, never cleared", "inverted", (), None),
)


def _reset_profile(kind):
    n = int(round(RESET_TIMES["end"] / H))
    y_d = np.full(n, RESET_HOLD)
    if kind == "reach":
        y_d[int(round(RESET_TIMES["fault"] / H)):int(round(RESET_TIMES["cleared"] / H))] = RESET_FAR
    y_d[int(round(RESET_TIMES["step"] / H)):] = RESET_STEP
    return y_d


def run_reset(case, plant, controller=None, keep=False):
    """Run one :class:`ResetCase` on the C core (stepped as a master that exchanges at communication
    points), ``sup.reaction`` = 1, raising ``sup.reset`` as the FMUs act on its rising edge
    (``Controller.fault_reset``). Returns a dict: ``fault`` (the first verdict's name), ``early``
    (the early reset's outcome: None, or (accepted, message)), ``late`` (the same for the late
    one), ``again`` (the name of a verdict after the late reset, "" for none), ``again_time``
    (from the restart to it [s]) and ``again_excursion`` (the largest |y - y_d| from the restart
    to it [um]; ``first_excursion`` the same from the onset to the first verdict), ``step`` (the largest |y - y_d| over the step's first 0.25 s [um]),
    ``settled`` (over the last 0.25 s [um]), ``v_first`` (|v| at the first restarted sample [V]),
    ``v_jump`` (the largest change of v from one sample to the next over the ramp after the
    restart [V]). ``keep``: also ``trace`` (time, y_d, y, y_meas, v)."""
    y_d = _reset_profile(case.kind)
    n = len(y_d)
    at = {k: int(round(v / H)) for k, v in RESET_TIMES.items()}
    p = core.Plant(plant)
    c = core.Controller(dict(SAFE, **(controller or {})))
    v, held = 0.0, None
    res = {"fault": "", "early": None, "late": None, "again": "", "again_time": float("nan"),
           "again_excursion": float("nan"), "first_excursion": float("nan")}
    y, ym, vs = np.empty(n), np.empty(n), np.empty(n)
    k_restart = None
    for k in range(n):
        y[k] = p.output.y
        meas = p.output.y_meas
        if case.kind in ("stuck", "dead") and at["fault"] <= k < at["cleared"]:
            if held is None:
                held = 0.0 if case.kind == "dead" else meas
            meas = held
        ym[k] = meas
        r = y_d[min(n - 1, k + 2)]
        if case.kind == "none":
            pass
        elif k == at["early"] and case.refusal is not None:
            res["early"] = c.fault_reset(r, meas)
        elif k == at["late"]:
            res["late"] = c.fault_reset(r, meas)
            if res["late"][0]:
                k_restart = k
        before = c.raw.fault
        out = c.step(r, meas)
        if c.raw.fault and not before:
            name = core.ffi.string(core.lib().piezo_supervisor_fault_name(c.raw.fault)).decode()
            if k_restart is None:
                if not res["fault"]:
                    res["fault"] = name
                    res["first_excursion"] = float(np.abs(y[at["fault"]:k + 1] - y_d[at["fault"]:k + 1]).max())
            elif not res["again"]:
                res["again"], res["again_time"] = name, (k - k_restart) * H
                res["again_excursion"] = float(np.abs(y[k_restart:k + 1] - y_d[k_restart:k + 1]).max())
        p.step(-v if case.kind == "inverted" and k >= at["fault"] else v)
        v = out.v
        vs[k] = v
    err = np.abs(y - y_d)
    q = int(round(0.25 / H))
    res["step"] = float(err[at["step"]:at["step"] + q].max())
    res["settled"] = float(err[-q:].max())
    ramp = c.raw.sup.ramp_samples
    res["v_first"] = float(abs(vs[k_restart])) if k_restart is not None else float("nan")
    res["v_jump"] = (float(np.abs(np.diff(vs[k_restart - 1:k_restart + ramp + 1])).max())
                     if k_restart is not None else float("nan"))
    if keep:
        res["trace"] = (np.arange(n) * H, y_d, y, ym, vs)
    return res


#: the same profile without a fault: the step the restarted loop's is compared with
RESET_BASELINE = ResetCase("no fault", "none", (), None)


def _run_reset_spec(spec):
    i, nm, case_index, declared = spec
    plant, controller = _day_plant(i, nm), _day_controller(nm, declared)
    res = run_reset(RESET_CASES[case_index], plant, controller)
    res["step_ratio"] = res["step"] / run_reset(RESET_BASELINE, plant, controller)["step"]
    return spec, res


def reset_family(stages=50, sensors=RESET_SENSORS_NM, cases=None, jobs=2, progress=None, declared=False):
    """Every :data:`RESET_CASES` case on the stage's day's stages with each sensor:
    ``{(case, nm): [result, ...]}``. ``declared``: each sensor's noise declared to the controller
    (``sup.sensor_noise``)."""
    cases = range(len(RESET_CASES)) if cases is None else cases
    specs = [(i, nm, c, declared) for c in cases for nm in sensors for i in range(stages)]
    return _per_key_and_sensor(specs, _run_reset_spec, jobs, progress)


def reset_verdict(case, r):
    """"" when a run did what :class:`ResetCase` says, else why not."""
    if not r["fault"] or (case.faults and r["fault"] not in case.faults):
        return f"first verdict {r['fault'] or 'none'!r}, not one of {case.faults}"
    if case.refusal is not None and (r["early"] is None or r["early"][0]):
        return "the reset raised while the cause persisted was accepted"
    if r["late"] is None or not r["late"][0]:
        return "the reset after the cause was gone was refused: " + (r["late"][1] if r["late"] else "")
    if case.kind == "inverted":
        return "" if r["again"] else "after the restart nothing stopped the inverted loop"
    return f"a verdict after the restart: {r['again']}" if r["again"] else ""


def reset_markdown(family):
    """Per case and sensor: runs, those that did not do what the case says, the restart's first |v|
    and largest change of v per sample over its ramp, the step's error after the restart (median,
    worst) and the error over the last 0.25 s, and for the case never cleared the time from the
    step to the second verdict."""
    from ..text_tables import markdown_table
    rows = []
    for (ci, nm), res in sorted(family.items()):
        case = RESET_CASES[ci]
        bad = [reset_verdict(case, r) for r in res]
        fine = [r for r, b in zip(res, bad) if not b]
        col = lambda key: np.array([r[key] for r in fine])        # noqa: E731
        inverted = case.kind == "inverted"
        if not fine:
            rows.append([case.name, f"{nm:g}", str(len(res)), str(len(res))] + ["-"] * 4)
            continue
        if inverted:
            again, exc, first = col("again_time"), col("again_excursion"), col("first_excursion")
            after = (f"stopped again after {1e3 * np.median(again):.1f} / {1e3 * again.max():.1f} ms, "
                     f"{np.median(exc):.3g} / {exc.max():.3g} um off (the fault itself: {np.median(first):.3g} / "
                     f"{first.max():.3g} um)")
        else:
            ratio = col("step_ratio")
            after = f"{np.median(ratio):.3f} / {ratio.max():.3f}"
        rows.append([case.name, f"{nm:g}", str(len(res)), str(sum(bool(b) for b in bad)),
                     f"{col('v_first').max():.3g} V", f"{col('v_jump').max():.3g} V",
                     "-" if inverted else f"{col('settled').max():.3g}", after])
    return markdown_table(["case", "sensor [nm rms]", "runs", "not as the case says",
                           "first \\|v\\| after the reset, worst", "largest change of v a sample over the ramp, worst",
                           "\\|y - y_d\\| over the last 0.25 s [um], worst",
                           "the step after the reset against the same step without a fault (median / worst); "
                           "inverted: the restarted loop stopped again (median / worst)"], rows)


def _exit_code(bad, what):
    """0 when no run went wrong; else 1, after one line on stderr: ``bad`` runs, ``what`` they did."""
    if bad:
        print(f"{bad} {what}", file=sys.stderr)
    return 1 if bad else 0


def _sensor_family(args, family_of, markdown_of, progress):
    """Run one of the sensor studies (stuck, reset, start) with its options, print its table and
    return its results."""
    family = family_of(args.stages, tuple(args.sensors), jobs=args.jobs, progress=progress,
                       declared=args.declared)
    print(markdown_of(family))
    return family


def main(argv=None, prog=None):
    """``python -m harness supervision``: the fault table or the family, in Markdown."""
    ap = argparse.ArgumentParser(prog=prog or "python -m harness supervision",
                                 description="The controller's supervision, measured (docs/robustness.md).")
    sub = ap.add_subparsers(dest="job", required=True)
    fa = sub.add_parser("faults", help="the fault table")
    fa.add_argument("--fmi", type=int, nargs="+", default=[2, 3], choices=[2, 3])
    ff = sub.add_parser("fault-family", help="every fault on stages drawn from the identification family")
    ff.add_argument("--stages", type=int, default=50)
    ff.add_argument("--seed", type=int, default=2028)
    ff.add_argument("--models", nargs="+", default=["own", "paper"], choices=["own", "paper"])
    ff.add_argument("--jobs", type=int, default=2)
    fm = sub.add_parser("family", help="the legitimate family: Errors, warnings, margins")
    fm.add_argument("--stages", type=int, default=50)
    fm.add_argument("--seed", type=int, default=2028)
    fm.add_argument("--scenarios", nargs="+", default=None, help="e.g. 1hz 20hz (default: the six)")
    fm.add_argument("--masters", nargs="+", default=["wired"], choices=["wired", "real"])
    fm.add_argument("--models", nargs="+", default=["own", "paper"], choices=["own", "paper"])
    fm.add_argument("--duration", type=float, default=None, help="seconds per run (default: the scenario's 3 s)")
    fm.add_argument("--no-saturation", action="store_true")
    fm.add_argument("--jobs", type=int, default=2)
    fm.add_argument("--reactions", nargs="+", default=["error", "safe"], choices=list(REACTIONS),
                    help="sup.reaction of the runs (default: both, each run twice)")
    for name, text, sensors in (
            ("stuck", "a sensor that sticks, dies or sticks after a dropout, in holds and scans, on the stage's "
                      "day's stages with sensors of 0 to 200 nm rms", STUCK_SENSORS_NM),
            ("start", "noisy sensors at start: the delay detection on the stage's day's stages at rest from t = 0, "
                      "sensors of 0 to 200 nm rms", STUCK_SENSORS_NM),
            ("reset", "sup.reset: leaving the safe state after a stuck or dead sensor, a reference out of reach and "
                      "an inverted amplifier, on the stage's day's stages with sensors of 5 to 200 nm rms (a "
                      "quieter sensor stuck in a hold is not seen, so it has no safe state to leave)",
             RESET_SENSORS_NM)):
        study = sub.add_parser(name, help=text)
        study.add_argument("--stages", type=int, default=50, help="stages of the stage's day's family (default 50)")
        study.add_argument("--sensors", type=float, nargs="+", default=list(sensors),
                           help="sensor noise [nm rms] on the 2 nm grid (default "
                                + " ".join(f"{s:g}" for s in sensors) + ")")
        study.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
        study.add_argument("--declared", action="store_true",
                           help="declare each sensor's noise to the controller (sup.sensor_noise = its rms; "
                                "default: not declared)")
    fa_ = sub.add_parser("false-alarms", help="the no-false-alarm check of any family: a function "
                         "returning RunSpecs, as module:function (e.g. harness.studies.supervision_table:family_specs)")
    fa_.add_argument("--specs", required=True, help="module:function; called without arguments")
    fa_.add_argument("--reactions", nargs="+", default=["error", "safe"], choices=list(REACTIONS))
    fa_.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    say = lambda text: print(text, file=sys.stderr, flush=True)   # noqa: E731
    if args.job == "faults":
        print(fault_markdown(fault_results(tuple(args.fmi), progress=say)))
        return 0
    if args.job == "fault-family":
        specs = fault_family_specs(args.stages, args.seed, tuple(args.models))
        say(f"{len(specs)} runs")
        family = fault_family(specs, args.jobs, progress=say)
        print(fault_family_markdown(family))
        missed = [(c, m) for c, o in family.items() for m in o["missed"]]
        for c, (spec, text, e_rms) in missed[:20]:
            print(f"MISSED ({FAULTS[c].name}): stage {spec.stage}, {spec.model} model, "
                  f"{schedule_name(spec.schedule)}: y tracked y_d to {1e3 * e_rms:.3g} nm rms; "
                  f"{text[:300] or 'nothing said'}", file=sys.stderr)
        # a fault the loop tracks through is a stage to the controller; one it does not, a silent failure
        # (but for a blind spot docs/robustness.md documents)
        silent = [m for c, m in missed if not m[2] <= SILENT_ERROR and not FAULTS[c].blind]
        return _exit_code(len(silent), f"runs neither stopped nor tracking within "
                                       f"{1e3 * SILENT_ERROR:g} nm: silently wrong")
    if args.job == "stuck":
        family = _sensor_family(args, stuck_family, stuck_markdown, say)
        early = sum(r["stopped_before"] or (STUCK_CASES[c].reads == "none" and r["fault"] != "")
                    for (c, _), res in family.items() for r in res)
        return _exit_code(early, "runs stopped where no fault was: false alarms")
    if args.job == "reset":
        family = _sensor_family(args, reset_family, reset_markdown, say)
        bad = [(RESET_CASES[ci].name, nm, reset_verdict(RESET_CASES[ci], r))
               for (ci, nm), res in family.items() for r in res if reset_verdict(RESET_CASES[ci], r)]
        for name, nm, why in bad[:10]:
            print(f"{name}, {nm:g} nm: {why[:300]}", file=sys.stderr)
        return _exit_code(len(bad), "runs did not do what their case says")
    if args.job == "start":
        family = _sensor_family(args, start_family, start_markdown, say)
        bad = sum(bool(r["error"]) or r["delay"] not in (0, START_DELAY) for res in family.values() for r in res)
        return _exit_code(bad, "runs stopped or chose a wrong loop delay")
    if args.job == "false-alarms":
        module, _, function = args.specs.partition(":")
        specs = list(getattr(importlib.import_module(module), function)())
    else:
        specs = family_specs(args.stages, args.seed, args.scenarios, tuple(args.masters), args.duration,
                             tuple(args.models), saturation=not args.no_saturation)
    say(f"{len(specs)} legitimate runs, each with sup.reaction = {' and '.join(args.reactions)}")
    summary, alarms = false_alarms(specs, tuple(args.reactions), args.jobs, progress=say)
    print(family_markdown(summary))
    bad = [(g, s) for g, s in summary.items() if s["errors"] or s["warnings"]]
    for g, spec, text in alarms[:20]:
        print(f"FALSE ALARM ({g}): {spec.master}, {spec.scenario}: {text[:300]}", file=sys.stderr)
    for g, s in summary.items():
        for spec, text in s["notes"][:5]:
            print(f"NOTE ({g}): {spec.master}, {spec.scenario}: {text[:400]}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
