"""The worker side of a sweep: a task runs some runs of one scenario, each on its own drawn
parameters, on this process's instances of the shipped FMUs, and returns their journal rows.

On the native master a task's runs are one C call (``piezo_runner_batch``): the
parameters are drawn for the whole task (:func:`harness.sweep.spreads.draw_columns`), the
runner runs them back to back and returns per run the sums the checks and metrics are made
of, and the checks' rules (:mod:`harness.loop.checks`) decide on all of them at once. A run that
fails a rule, or whose FMI calls failed, is run again on its own, the way every run is run
otherwise (:func:`harness.masters.prepared_loop`, :func:`harness.loop.checks.check_tracking_run`),
and reported with that run's status and message. Both ways give the same bits.
"""

from __future__ import annotations

import atexit
from dataclasses import fields
import math
from pathlib import Path
import shutil
import sys
import tempfile
import time
from types import MappingProxyType

import numpy as np

from .. import masters
from ..fmu import FMUError, FMUInitializationError, LoopDivergedError, LoopFaultError, UnknownParameterError
from ..loop import prepare_closed_loop
from ..loop.checks import (RunCheckError, RunSaturatedError, check_tracking_run, clipped_too_often,
                           error_above_reference, reference_rms)
from ..loop.metrics import compute_metrics, relative_from_sums, rms_from_sum, window_mask
from ..scenarios import Scenario
from .spreads import apply_spreads, draw_columns, run_deltas
from .store import task_rows

__all__ = ["run_chunk", "sweep_inputs", "prepare_worker", "scenario_fields", "scenario_from_fields",
           "first_line", "peak_rss", "remove_at_exit"]

_TEMP_DIRS = {}        # the folders this process made, removed at its exit


def _cleanup():
    for d in _TEMP_DIRS.values():
        shutil.rmtree(d, ignore_errors=True)


atexit.register(_cleanup)


def remove_at_exit(folder):
    """Remove ``folder`` when this process exits."""
    _TEMP_DIRS[str(folder)] = str(folder)


def _fmu_dir_for(package):
    """A folder holding the shipped FMU files on this worker (written once per content)."""
    digest, files = package
    d = _TEMP_DIRS.get(digest)
    if d is None:
        d = tempfile.mkdtemp(prefix="harness_sweep_")
        for name, data in files.items():
            Path(d, name).write_bytes(data)
        _TEMP_DIRS[digest] = d
    return d


def scenario_fields(sc):
    """A picklable description of a Scenario (its mappings are read-only proxies)."""
    out = {f.name: getattr(sc, f.name) for f in fields(sc)}
    for k in ("plant", "controller", "paper"):
        out[k] = dict(out[k])
    return out


def scenario_from_fields(fields_):
    """The Scenario of :func:`scenario_fields`."""
    f = dict(fields_)
    for k in ("plant", "controller", "paper"):
        f[k] = MappingProxyType(dict(f[k]))
    return Scenario(**f)


def _one_run(scenario, params, options, fmu_dir):
    """Run one closed loop; return (status, e_rms [um], e_r, reason)."""
    try:
        setup = prepare_closed_loop(scenario, plant_params=params, adaptation=options["adaptation"],
                                    preview=options["preview"], master=options["master"])
        data = masters.prepared_loop(options["backend"], fmu_dir)(setup)
        check_tracking_run(data, scenario)
    except LoopFaultError as exc:
        return "stopped", math.nan, math.nan, first_line(exc)
    except LoopDivergedError as exc:
        return "diverged", math.nan, math.nan, first_line(exc)
    except RunSaturatedError as exc:
        return "saturated", math.nan, math.nan, first_line(exc)
    except RunCheckError as exc:
        return "diverged", math.nan, math.nan, first_line(exc)
    except (FMUInitializationError, UnknownParameterError, TypeError, ValueError) as exc:
        return "invalid", math.nan, math.nan, first_line(exc)
    except FMUError as exc:
        return "diverged", math.nan, math.nan, first_line(exc)
    m = compute_metrics(data["time"], data["y_d"], data["y"], scenario.metric_window,
                        scenario.step_size)
    return "ok", m.e_rms, m.e_r, ""


def first_line(exc):
    """The message of an exception on one line, at most 400 characters."""
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    return " ".join(text.split())[:400]


def peak_rss():
    """This process's peak resident set size in bytes (None where the OS does not say).

    On Linux the high-water mark of this process's own memory (``VmHWM``): ``getrusage``'s
    ``ru_maxrss`` keeps, across the ``exec`` of a process started by fork and exec (a Dask
    worker), the RSS its parent had at the fork, so a worker started by a client holding a
    million runs' arrays would report those as its own.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import resource                                     # POSIX only
    except ImportError:                                     # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


def _run_alone(scenario, base, spreads, seed, index, options, fmu_dir):
    """Run i on its own: (status, e_rms, e_r, reason, seconds)."""
    params = apply_spreads(base, spreads, run_deltas(spreads, seed, index))
    t0 = time.perf_counter()
    status, e_rms, e_r, reason = _one_run(scenario, params, options, fmu_dir)
    return status, e_rms, e_r, reason, time.perf_counter() - t0


def _batch(scenario, base, columns, options, fmu_dir):
    """The runs as one batch of the master: (e_rms, e_r, seconds, clean) arrays, ``clean``
    False for a run a check's rule fails or whose FMI calls failed; None when the master has
    no batch or the batch does not apply (the setup or the parameters are refused: every run
    then says why on its own)."""
    run_batch = masters.prepared_batch(options["backend"], fmu_dir)
    if run_batch is None:
        return None
    try:
        setup = prepare_closed_loop(scenario, plant_params=base, adaptation=options["adaptation"],
                                    preview=options["preview"], master=options["master"])
    except (TypeError, ValueError):
        return None
    window = window_mask(setup.time, scenario.metric_window, scenario.step_size)
    where = np.flatnonzero(window)
    if where.size == 0 or where[-1] - where[0] + 1 != where.size:
        return None
    try:
        out = run_batch(setup, columns, (where[0], where[-1] + 1))
    except (TypeError, ValueError, UnknownParameterError):
        return None
    e_rms = rms_from_sum(out["sum_error2"], where.size)
    e_r = relative_from_sums(out["sum_error2"], out["sum_y2"])
    clean = ((out["status"] <= 1) & out["finite"]
             & ~error_above_reference(e_rms, reference_rms(setup.y_d[window]))
             & ~clipped_too_often(out["saturated"] / where.size))
    return e_rms, e_r, out["seconds"], clean


def prepare_worker(package, options):
    """Ready this process for the sweep's tasks (what a worker's first task would do first):
    the FMU files written and, with the native backend, extracted, their binaries loaded and
    a pair instantiated, so the thread that runs the tasks only instantiates its own pair."""
    masters.prepared_loop(options["backend"], _fmu_dir_for(package))


def sweep_inputs(package, scenarios, spreads, varied, options):
    """What every task of a sweep needs besides its runs, as one value (:func:`run_chunk`'s
    ``inputs``).

    On Dask this is a task of its own, which the tasks of runs depend on: its arguments are
    in its definition, which the scheduler keeps, so when the workers holding its result
    are lost the scheduler computes it again (scattered data cannot be: a task whose
    scattered input was on a lost worker is cancelled).

    Parameters
    ----------
    package : (str, dict)
        Content digest and ``{file name: bytes}`` of both FMUs.
    scenarios : dict
        Scenario name -> (its description from :func:`scenario_fields`, its complete plant
        parameter set before the spreads).
    spreads : list of Spread
    varied : list of str
        Parameter names whose drawn values are returned with each run.
    options : dict
        ``backend``, ``adaptation``, ``preview``, ``master``.
    """
    return {"package": package, "scenarios": scenarios, "spreads": spreads, "varied": varied,
            "options": options}


def run_chunk(inputs, name, seed, indices):
    """Worker task: some runs of one scenario, each drawing its own parameters.

    Parameters
    ----------
    inputs : dict
        What every task needs, from :func:`sweep_inputs`.
    name : str
        The scenario.
    seed : int
    indices : sequence of int
        The runs (run i draws from the generator seeded by (seed, i)).

    Returns
    -------
    (harness.sweep.store.TaskRows, int or None, (float, float))
        The runs' journal rows (scenario, run, status, e_rms [um], e_r, seconds, the values
        of ``varied``, reason), this worker's peak RSS in bytes, and the CPU seconds this
        process spent on the task (all its threads) with the wall-clock seconds it took.
    """
    cpu, wall = time.process_time(), time.perf_counter()
    description, base = inputs["scenarios"][name]
    spreads, varied, options = inputs["spreads"], inputs["varied"], inputs["options"]
    fmu_dir = _fmu_dir_for(inputs["package"])
    scenario = scenario_from_fields(description)
    indices = [int(i) for i in indices]
    m = len(indices)
    columns = draw_columns(base, spreads, seed, indices)
    statuses, reasons = ["ok"] * m, [""] * m
    batch = _batch(scenario, base, columns, options, fmu_dir) if m else None
    if batch is not None:
        e_rms, e_r, seconds, clean = batch
        e_rms, e_r, seconds = e_rms.tolist(), e_r.tolist(), seconds.tolist()
        again = np.flatnonzero(~clean).tolist()
    else:
        e_rms, e_r, seconds = [math.nan] * m, [math.nan] * m, [math.nan] * m
        again = range(m)
    for j in again:
        statuses[j], e_rms[j], e_r[j], reasons[j], seconds[j] = _run_alone(
            scenario, base, spreads, seed, indices[j], options, fmu_dir)
    values = [columns[k].tolist() if k in columns else [base[k]] * m for k in varied]
    rows = task_rows(scenario.name, indices, statuses, e_rms, e_r, seconds, values, reasons)
    return rows, peak_rss(), (time.process_time() - cpu, time.perf_counter() - wall)
