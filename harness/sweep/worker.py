"""The worker side of a sweep: a task runs some runs of one scenario, each on its own drawn
parameters, on this process's instances of the shipped FMUs."""

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

from .. import masters
from ..checks import RunCheckError, RunSaturatedError, check_tracking_run
from ..fmu import FMUError, FMUInitializationError, LoopDivergedError, UnknownParameterError
from ..loop import prepare_closed_loop
from ..metrics import compute_metrics
from ..scenarios import Scenario
from .spreads import apply_spreads, run_deltas

__all__ = ["run_chunk", "scenario_fields", "scenario_from_fields", "first_line", "peak_rss",
           "remove_at_exit"]

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
    """This process's peak resident set size in bytes (None where the OS does not say)."""
    try:
        import resource                                     # POSIX only
    except ImportError:                                     # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


def run_chunk(package, description, base, spreads, seed, indices, varied, options):
    """Worker task: some runs of one scenario, each drawing its own parameters.

    Parameters
    ----------
    package : (str, dict)
        Content digest and ``{file name: bytes}`` of both FMUs.
    description : dict
        The scenario, from :func:`scenario_fields`.
    base : dict
        The scenario's complete plant parameter set, before the spreads.
    spreads : list of Spread
    seed : int
    indices : list of int
        The runs (run i draws from the generator seeded by (seed, i)).
    varied : list of str
        Parameter names whose drawn values are returned with each run.
    options : dict
        ``backend``, ``adaptation``, ``preview``, ``master``.

    Returns
    -------
    (list of tuple, int or None)
        ``(index, status, e_rms_um, e_r, reason, seconds, [values of varied])`` per run,
        and this worker's peak RSS in bytes.
    """
    fmu_dir = _fmu_dir_for(package)
    scenario = scenario_from_fields(description)
    out = []
    for index in indices:
        params = apply_spreads(base, spreads, run_deltas(spreads, seed, index))
        t0 = time.perf_counter()
        status, e_rms, e_r, reason = _one_run(scenario, params, options, fmu_dir)
        out.append((int(index), status, e_rms, e_r, reason, time.perf_counter() - t0,
                    [params[k] for k in varied]))
    return out, peak_rss()

