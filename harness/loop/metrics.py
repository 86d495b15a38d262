"""Tracking and model-error metrics of the paper (eqs 36-37).

``e_rms = sqrt(mean((y_ref - y)^2))`` and
``e_r = sqrt(sum((y_ref - y)^2) / sum(y^2))``, evaluated over a time window.
For tracking, ``y_ref`` is the desired displacement ``y_d`` and ``y`` the
*true* displacement of the stage (docs/model.md, scenarios).  For model validation,
``y_ref`` is the output taken as the truth (the coupled model here) and ``y``
the model compared with it (the Hammerstein model).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = [
    "Metrics",
    "window_mask",
    "rms_error",
    "relative_error",
    "rms_from_sum",
    "relative_from_sums",
    "compute_metrics",
]


@dataclass(frozen=True)
class Metrics:
    """Error metrics over a window.

    Attributes
    ----------
    e_rms : float
        Root-mean-square error (eq 36), in the unit of the signals (um).
    e_r : float
        Relative error (eq 37), dimensionless (multiply by 100 for %).
    n_samples : int
        Number of samples in the window.
    """

    e_rms: float
    e_r: float
    n_samples: int


def window_mask(time, window=None, step=None):
    """Select the samples whose time lies in ``[t_start, t_stop)``.

    Parameters
    ----------
    time : array_like
        Sample times, on a uniform grid ``t_k = t_0 + k h``.
    window : tuple of float, optional
        ``(t_start, t_stop)``; ``None`` selects every sample.
    step : float, optional
        Sample period ``h``.  When given, the bounds are compared on the
        integer sample grid (robust against float round-off of ``k h``);
        otherwise a relative tolerance of 1e-9 of the time step is used.

    Returns
    -------
    mask : ndarray of bool
    """
    time = np.asarray(time, dtype=float)
    if window is None:
        return np.ones(time.shape, dtype=bool)
    t_start, t_stop = (float(window[0]), float(window[1]))
    if not t_start < t_stop:
        raise ValueError(f"metric window must satisfy start < stop, got {window!r}")
    if step is None:
        step = float(time[1] - time[0]) if time.size > 1 else 1.0
    tol = 1e-9 * step
    return (time >= t_start - tol) & (time < t_stop - tol)


def _paired(reference, output):
    """The two signals as float arrays of one shape, with at least one sample."""
    reference = np.asarray(reference, dtype=float)
    output = np.asarray(output, dtype=float)
    if reference.shape != output.shape:
        raise ValueError(f"shape mismatch: {reference.shape} vs {output.shape}")
    if reference.size == 0:
        raise ValueError("no samples to evaluate the error on")
    return reference, output


def rms_error(reference, output):
    """Root-mean-square error, eq 36: ``sqrt(mean((reference - output)^2))``.

    Parameters
    ----------
    reference, output : array_like
        Signals of equal length (at least one sample).

    Returns
    -------
    float
    """
    reference, output = _paired(reference, output)
    err = reference - output
    return float(rms_from_sum(np.sum(err * err), err.size))


def relative_error(reference, output, normalizer=None):
    """Relative error, eq 37: ``sqrt(sum((reference - output)^2) / sum(y^2))``.

    Parameters
    ----------
    reference, output : array_like
        Signals of equal length.
    normalizer : array_like, optional
        The signal ``y`` whose energy is the denominator.  Defaults to
        ``output`` (the paper's eq 37 divides by the measured displacement,
        which for tracking is the true stage output).

    Returns
    -------
    float
        Dimensionless ratio; ``nan`` if the normalizer is identically zero.
    """
    reference, output = _paired(reference, output)
    norm = output if normalizer is None else np.asarray(normalizer, dtype=float)
    err = reference - output
    return float(relative_from_sums(np.sum(err * err), np.sum(norm * norm)))


def rms_from_sum(sum_squared_error, n):
    """Eq 36 from the sum of the n squared errors: ``sqrt(sum / n)`` (elementwise).

    The sum is NumPy's (``np.sum``), so this is :func:`rms_error`'s value, which it
    computes; the native master's batches (``piezo_runner_batch``) take the same sums
    in C and give their runs' e_rms through here.

    Parameters
    ----------
    sum_squared_error : float or ndarray
    n : int or ndarray
        Samples summed (at least one).

    Returns
    -------
    float or ndarray
    """
    return np.sqrt(np.asarray(sum_squared_error, dtype=float) / n)


def relative_from_sums(sum_squared_error, sum_squared_normalizer):
    """Eq 37 from the sums of the squared errors and of the squared normalizer:
    ``sqrt(error sum / normalizer sum)``, ``nan`` where the normalizer sum is 0
    (elementwise; :func:`relative_error`'s value, which it computes).

    Parameters
    ----------
    sum_squared_error, sum_squared_normalizer : float or ndarray

    Returns
    -------
    float or ndarray
    """
    num = np.asarray(sum_squared_error, dtype=float)
    den = np.asarray(sum_squared_normalizer, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den == 0.0, math.nan, np.sqrt(num / np.where(den == 0.0, 1.0, den)))


def compute_metrics(time, reference, output, window=None, step=None, normalizer=None):
    """Compute ``e_rms`` and ``e_r`` over a time window.

    Parameters
    ----------
    time : array_like
        Sample times.
    reference : array_like
        Desired (or "true") signal, e.g. ``y_d``.
    output : array_like
        Signal compared with it, e.g. the true stage displacement ``y``.
    window : tuple of float, optional
        ``(t_start, t_stop)`` half-open window; ``None`` uses every sample.
    step : float, optional
        Sample period, see :func:`window_mask`.
    normalizer : array_like, optional
        Denominator signal of ``e_r``; defaults to ``output`` (eq 37).

    Returns
    -------
    Metrics

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(4) * 0.5
    >>> m = compute_metrics(t, [1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 3.0])
    >>> round(m.e_rms, 6)
    0.5
    """
    mask = window_mask(time, window, step)
    reference = np.asarray(reference, dtype=float)[mask]
    output = np.asarray(output, dtype=float)[mask]
    norm = None if normalizer is None else np.asarray(normalizer, dtype=float)[mask]
    if reference.size == 0:
        raise ValueError(f"the metric window {window!r} holds no samples")
    return Metrics(
        e_rms=rms_error(reference, output),
        e_r=relative_error(reference, output, norm),
        n_samples=int(reference.size),
    )
