"""The coupled model's blocks, evaluated forward (paper eqs 3-5, 17, 18, 21).

``v --PI--> u --G(z)--> x --creep--> y``, every record from rest:

* :func:`play_operator_outputs`, :func:`pi_output`: the Prandtl-Ishlinskii
  hysteresis (play operators with thresholds ``r_j = (j-1)/m v_max``);
* :func:`transfer_function_output`, :func:`g_filter`: ``G(z) = (b1 z + b2)/(z^2 + a1 z + a2)``
  with one sample of delay (plus an optional input delay);
* :func:`creep_output`: eq 17 by the C core's G-L operator (the plant's own
  code, sum-of-exponentials tail or full memory);
  :func:`gl_convolve`: the same full-memory sum by FFT convolution, vectorised
  over columns, for the least-squares fits that evaluate it many times.

Row alignment is the PiezoStage FMU's open-loop record: row k holds the
voltage ``v(k)`` applied at ``t_k`` and the displacement ``y(k)`` reported at
``t_k`` (which depends on ``v`` up to ``k-1``).
"""

from __future__ import annotations

import math

import numpy as np
# scipy is imported inside the functions that use it: the build imports this package with
# its build requirements only (fmpy, cffi, numpy), and scipy costs 0.3-0.7 s at import.

from ..binding import core

__all__ = [
    "IdentificationInputError",
    "pi_thresholds",
    "play_operator_outputs",
    "pi_output",
    "transfer_function_output",
    "g_filter",
    "creep_output",
    "gl_weights",
    "gl_convolve",
]


class IdentificationInputError(ValueError):
    """Bad data given to an identification function.

    Raised for arrays of different lengths, non-finite values, too few
    samples or a signal that carries no information (e.g. ``x`` identically
    zero).  It is a :class:`ValueError`.
    """


def pi_thresholds(m, v_max):
    """Thresholds ``r_j = (j-1)/m * v_max``, ``j = 1..m`` (eq 5; the model's definition).

    Parameters
    ----------
    m : int
        Number of play operators (>= 1).
    v_max : float
        Threshold scale [V] (> 0).

    Returns
    -------
    ndarray, shape (m,)
    """
    m = int(m)
    if m < 1:
        raise ValueError(f"m must be >= 1, got {m}")
    if not v_max > 0:
        raise ValueError(f"v_max must be > 0, got {v_max!r}")
    return np.arange(m, dtype=float) / m * float(v_max)


def play_operator_outputs(v, thresholds, z0=None):
    """Outputs of play operators driven by ``v`` (eq 3), initial states ``z0`` (default 0).

    ``z_r(k) = max(v(k) - r, min(v(k) + r, z_r(k-1)))``

    Parameters
    ----------
    v : array_like, shape (N,)
    thresholds : array_like, shape (m,)
        Nonnegative thresholds.
    z0 : array_like, shape (m,), optional
        States before the first sample.

    Returns
    -------
    ndarray, shape (N, m)
    """
    v = np.asarray(v, dtype=float).ravel()
    r = np.asarray(thresholds, dtype=float).ravel()
    if np.any(r < 0):
        raise ValueError("thresholds must be >= 0")
    z = np.zeros(r.size) if z0 is None else np.array(z0, dtype=float).ravel()
    out = np.empty((v.size, r.size))
    for k in range(v.size):     # vectorised over operators; the recursion is sequential
        z = np.maximum(v[k] - r, np.minimum(v[k] + r, z))
        out[k] = z
    return out


def pi_output(v, weights, v_max):
    """Forward PI model (eq 18): ``u(k) = w0 v(k) + sum_j w_j z_{r_j}(k)``.

    Parameters
    ----------
    v : array_like, shape (N,)
    weights : array_like, shape (m+1,)
        ``[w0, w1, ..., wm]``.
    v_max : float

    Returns
    -------
    ndarray, shape (N,)
    """
    w = np.asarray(weights, dtype=float).ravel()
    z = play_operator_outputs(v, pi_thresholds(w.size - 1, v_max))
    return w[0] * np.asarray(v, dtype=float).ravel() + z @ w[1:]


def transfer_function_output(u, a1, a2, b1, b2, delay=0):
    """Output of ``G(z)`` (eq 21) driven by ``u`` from rest.

    ``x(k) = -a1 x(k-1) - a2 x(k-2) + b1 u(k-1-n) + b2 u(k-2-n)``, with
    ``x`` and ``u`` zero before the first sample (row-aligned as the plant's
    open-loop records: ``x(0) = 0``).

    Parameters
    ----------
    u : array_like, shape (N,)
        Input ``u(k)`` [um].
    a1, a2, b1, b2 : float
        Coefficients of ``G``.
    delay : int
        Extra input delay n in samples (``tf.delay``).

    Returns
    -------
    ndarray, shape (N,)
    """
    n = int(delay)
    if n < 0:
        raise ValueError(f"delay must be >= 0, got {delay}")
    a1, a2, b1, b2 = float(a1), float(a2), float(b1), float(b2)
    # the recursion on Python floats: cheaper than importing scipy.signal for lfilter
    ul = [0.0] * (2 + n) + np.asarray(u, dtype=float).ravel().tolist()   # u(k) at ul[k + 2 + n]
    x = [0.0] * (len(ul) - n)                                             # x(k) at x[k + 2]
    for k in range(2, len(x)):
        x[k] = -a1 * x[k - 1] - a2 * x[k - 2] + b1 * ul[k - 1] + b2 * ul[k - 2]
    return np.array(x[2:])


def creep_output(x, k_c, alpha, h, exact=False):
    """Fractional creep (eq 17) of ``x``, computed by the C core's G-L operator.

    ``y(k) = k_c h^-alpha sum_{j=0..k} w_j(alpha) x(k-j)``, memory from the
    first sample (:func:`harness.binding.core.gl_operator`).

    Parameters
    ----------
    x : array_like, shape (N,)
        Creep input (the Hammerstein output) [um].
    k_c : float
        Gain (> 0).
    alpha : float
        Order, in [-1, 1].
    h : float
        Sample period [s].
    exact : bool
        Full-memory sum (O(N^2) per record) instead of the core's default
        sum-of-exponentials tail (O(N)); they differ by <= 3e-6 nm for
        ``|alpha| <= 0.01`` (README, "Creep cost").

    Returns
    -------
    ndarray, shape (N,)

    Raises
    ------
    IdentificationInputError
        ``x`` is empty or holds a non-finite value.
    ValueError
        ``k_c``, ``alpha`` or ``h`` out of range.
    """
    x = checked_signal("x", x)
    h = checked_sample_period(h)
    k_c = float(k_c)
    if not (math.isfinite(k_c) and k_c > 0):
        raise ValueError(f"k_c must be a finite number > 0, got {k_c!r}")
    alpha = checked_order(alpha)
    return gl_run(x, alpha, k_c * h ** -alpha, exact)


def checked_signal(name, a):
    """``a`` as a 1-D float array; :class:`IdentificationInputError` naming ``name`` when it
    is empty, not 1-D or not finite."""
    a = np.asarray(a, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise IdentificationInputError(
            f"{name} must be a non-empty 1-D sequence, got shape {a.shape}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise IdentificationInputError(
            f"{name}[{bad[0]}] = {float(a[bad[0]])!r} is not finite")
    return a


def checked_sample_period(h):
    """``h`` as a float; :class:`ValueError` unless finite and > 0."""
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"h must be a finite number > 0, got {h!r}")
    return h


def checked_order(alpha):
    """The creep order ``alpha`` as a float; :class:`ValueError` outside [-1, 1]."""
    alpha = float(alpha)
    if not -1.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be in [-1, 1], got {alpha!r}")
    return alpha


def gl_run(x, alpha, gain, exact):
    """``gain * sum_j w_j(alpha) x(k-j)`` by the C core (the plant's own operator)."""
    return core.gl_operator(alpha, gain, exact).run(x)



def g_filter(u, a1, a2, b1, b2, delay=0):
    """``G(z)`` applied to ``u`` from rest, vectorised over columns (scipy ``lfilter``).

    The same recursion as :func:`transfer_function_output`,
    ``x(k) = -a1 x(k-1) - a2 x(k-2) + b1 u(k-1-n) + b2 u(k-2-n)``, for an
    array of shape (N,) or (N, p) (each column filtered on its own).

    Parameters
    ----------
    u : array_like, shape (N,) or (N, p)
    a1, a2, b1, b2 : float
    delay : int
        Extra input delay n in samples.

    Returns
    -------
    ndarray, same shape as ``u``
    """
    from scipy.signal import lfilter

    u = np.asarray(u, dtype=float)
    n = int(delay)
    if n < 0:
        raise ValueError(f"delay must be >= 0, got {delay}")
    if n:
        u = np.concatenate([np.zeros((n,) + u.shape[1:]), u[:u.shape[0] - n]], axis=0)
    return lfilter([0.0, float(b1), float(b2)], [1.0, float(a1), float(a2)], u, axis=0)


def gl_weights(alpha, n):
    """Grunwald-Letnikov weights ``w_0 .. w_{n-1}`` of order ``alpha`` (eq 14).

    ``w_0 = 1``, ``w_j = (1 - (alpha + 1)/j) w_{j-1}`` (a cumulative product).

    Parameters
    ----------
    alpha : float
    n : int

    Returns
    -------
    ndarray, shape (n,)
    """
    n = int(n)
    w = np.ones(max(n, 0))
    if n > 1:
        w[1:] = np.cumprod(1.0 - (float(alpha) + 1.0) / np.arange(1, n))
    return w


def gl_convolve(x, alpha, gain=1.0):
    """Full-memory G-L sum ``gain * sum_{j=0..k} w_j(alpha) x(k-j)`` by FFT convolution.

    The same operator as the core's exact mode (``creep.exact = true``),
    computed for every k at once in O(N log N); it differs from the core's
    default sum-of-exponentials tail by far less than a nanometre
    (README, "Creep cost").  Memory starts at the first row.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, p)
        Input, one series per column.
    alpha : float
        Order, in [-1, 1].
    gain : float
        Output gain, e.g. ``k_c h^-alpha`` for eq 17.

    Returns
    -------
    ndarray, same shape as ``x``
    """
    from scipy import fft

    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if n == 0:
        return x.copy()
    nfft = fft.next_fast_len(2 * n - 1, real=True)
    kernel = fft.rfft(gl_weights(alpha, n), nfft)
    if x.ndim > 1:
        kernel = kernel.reshape((-1,) + (1,) * (x.ndim - 1))
    y = fft.irfft(kernel * fft.rfft(x, nfft, axis=0), nfft, axis=0)[:n]
    return float(gain) * y
