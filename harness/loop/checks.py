"""A closed-loop run's own checks: a regression run must never pass on garbage.

:func:`check_tracking_run` looks at a finished run and raises when it

* diverged: a value is not finite, or the tracking error over the metric
  window is larger than the reference itself (``e_rms > rms(y_d)``), or
* saturated persistently: the controller clipped ``v`` in more than
  :data:`MAX_SATURATED_FRACTION` of the samples of the metric window.

A run the controller itself stopped (its supervision found a loop that cannot work:
:class:`harness.fmu.LoopFaultError`; its monitor found the loop unstable, or a computed
value overflowed) raises :class:`harness.fmu.LoopDivergedError`
during the run.  The command line turns both into exit code
:data:`EXIT_RUN_FAILED` and one line saying why.

The rules themselves (:func:`error_above_reference`, :func:`clipped_too_often`) also
decide on whole columns of runs: a sweep's native batches (:mod:`harness.sweep.worker`)
apply them to the sums the C runner takes, and run every run they fail again through
:func:`check_tracking_run` for its message.
"""

from __future__ import annotations

import numpy as np

from .metrics import window_mask

__all__ = [
    "EXIT_RUN_FAILED",
    "MAX_SATURATED_FRACTION",
    "RunCheckError",
    "RunDivergedError",
    "RunSaturatedError",
    "check_tracking_run",
    "clipped_too_often",
    "error_above_reference",
    "reference_rms",
]

#: Exit code of the command line when a run diverged or saturated persistently.
EXIT_RUN_FAILED = 3
#: Largest fraction of clipped samples in the metric window that still counts as a passing run.
MAX_SATURATED_FRACTION = 0.01


class RunCheckError(RuntimeError):
    """A run finished but failed its own checks (diverged or saturated persistently)."""


class RunDivergedError(RunCheckError):
    """The run diverged: a non-finite value, or an error larger than the reference."""


class RunSaturatedError(RunCheckError):
    """The controller clipped the voltage in too many samples of the metric window."""


def check_tracking_run(run, scenario, label=None):
    """Raise if a closed-loop run diverged or saturated persistently.

    Parameters
    ----------
    run : ndarray
        A structured result of :func:`harness.masters.fmpy.simulate_closed_loop` (fields
        ``time, y_d, y, v`` and, when present, ``saturated``).
    scenario : Scenario
        For the metric window and the sample period.
    label : str, optional
        How the run is named in the message (default: the scenario's name).

    Raises
    ------
    RunDivergedError, RunSaturatedError
    """
    label = label or scenario.name
    fields = [f for f in ("y", "y_meas", "v") if f in run.dtype.names]
    for f in fields:
        bad = ~np.isfinite(run[f])
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise RunDivergedError(f"{label}: the run diverged: {f} is {run[f][k]} at "
                                   f"t = {run['time'][k]:.6g} s")
    win = window_mask(run["time"], scenario.metric_window, scenario.step_size)
    if not win.any():
        return
    err = float(np.sqrt(np.mean((run["y_d"][win] - run["y"][win]) ** 2)))
    ref = reference_rms(run["y_d"][win])
    if error_above_reference(err, ref):
        raise RunDivergedError(f"{label}: the run diverged: e_rms = {err:.4g} um over the metric "
                               f"window is larger than the reference itself (rms {ref:.4g} um)")
    if "saturated" in run.dtype.names:
        frac = float(np.mean(run["saturated"][win] != 0))
        if clipped_too_often(frac):
            vmax = float(np.max(np.abs(run["v"][win])))
            raise RunSaturatedError(
                f"{label}: the controller clipped v in {frac:.1%} of the samples of the metric "
                f"window (more than {MAX_SATURATED_FRACTION:.0%}; |v| up to {vmax:.4g} V): "
                f"the reference needs more voltage than sat.v_min/sat.v_max allow")


def reference_rms(y_d):
    """The rms of the reference over the metric window (``y_d`` there), the bound of the
    error of a run that did not diverge."""
    return float(np.sqrt(np.mean(np.asarray(y_d, dtype=float) ** 2)))


def error_above_reference(e_rms, ref):
    """Whether a run diverged by its error (elementwise for arrays): its e_rms over the
    metric window exceeds the reference's rms there (a reference of rms 0 bounds nothing)."""
    return np.logical_and(np.greater(ref, 0), np.greater(e_rms, ref))


def clipped_too_often(fraction):
    """Whether a run clipped persistently (elementwise for arrays): the controller clipped v
    in more than :data:`MAX_SATURATED_FRACTION` of the samples of the metric window."""
    return np.greater(fraction, MAX_SATURATED_FRACTION)
