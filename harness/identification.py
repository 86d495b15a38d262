"""Step-wise identification of the Hammerstein part (paper section 3, steps 1 and 2).

Step 1 (:func:`identify_pi`): the PI weights by linear least squares with
nonnegativity (:func:`scipy.optimize.nnls`) on the play-operator outputs of
the input voltage (eq 18 is linear in the weights once the thresholds are
fixed, ``r_j = (j-1)/m * v_max``).

Step 2 (:func:`identify_transfer_function`): ``a1, a2, b1, b2`` of
``x(k) = -a1 x(k-1) - a2 x(k-2) + b1 u(k-1) + b2 u(k-2)`` (eq 21) by ordinary
least squares on the ARX regression.

Identifiability note: ``r_1 = 0`` makes the first play operator the identity
(``z_{r_1}(k) = v(k)``), so only ``w0 + w1`` is determined by data; give
``w0`` to fit ``w1 .. w_m`` with ``w0`` fixed, or leave it ``None`` to get the
whole linear gain in ``w0`` (and ``w1 = 0``).  Both splits give the same model
output and the same inverse.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "pi_thresholds",
    "play_operator_outputs",
    "pi_output",
    "identify_pi",
    "identify_transfer_function",
]


def pi_thresholds(m, v_max):
    """Thresholds ``r_j = (j-1)/m * v_max``, ``j = 1..m`` (eq 5, DESIGN.md section 1).

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


def identify_pi(v, y, m=9, v_max=20.0, w0=None):
    """Identify the PI weights from an input and its PI output (paper step 1).

    Solves ``min ||Phi w - y||`` subject to ``w >= 0`` with
    :func:`scipy.optimize.nnls`, ``Phi = [v, z_{r_1}(v), ..., z_{r_m}(v)]``.

    Parameters
    ----------
    v : array_like, shape (N,)
        Input voltage [V], starting from rest (play states 0).
    y : array_like, shape (N,)
        Output to fit, ``u(k) = P[v](k)`` [um] (the quasi-static displacement
        in the paper's low-frequency experiment).
    m : int
        Number of play operators.
    v_max : float
        Threshold scale [V] (frozen, DESIGN.md section 1).
    w0 : float, optional
        Known linear weight.  ``r_1 = 0`` makes ``z_{r_1} = v``, so the data
        only determine ``w0 + w1``; with ``w0`` given, ``w1..wm`` are fitted,
        otherwise ``w1 = 0`` and ``w0`` carries the whole linear gain.

    Returns
    -------
    ndarray, shape (m+1,)
        ``[w0, w1, ..., wm]``.

    Examples
    --------
    >>> import numpy as np
    >>> v = 10 * np.sin(2 * np.pi * np.arange(4000) * 0.0005) + 10
    >>> u = pi_output(v, [0.3344, 0.0714, 0.0322, 0.0072] + [0.0] * 6, 20.0)
    >>> w = identify_pi(v, u, 9, 20.0, w0=0.3344)
    >>> bool(np.allclose(w[:4], [0.3344, 0.0714, 0.0322, 0.0072], atol=1e-9))
    True
    """
    from scipy.optimize import nnls

    v = np.asarray(v, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if v.shape != y.shape:
        raise ValueError(f"v and y must have the same length, got {v.size} and {y.size}")
    if v.size < m + 1:
        raise ValueError(f"need at least m+1 = {m + 1} samples, got {v.size}")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(y))):
        raise ValueError("v and y must be finite")
    z = play_operator_outputs(v, pi_thresholds(m, v_max))
    weights = np.zeros(m + 1)
    if w0 is None:
        # columns: v (carries w0 + w1), z_2..z_m
        phi = np.column_stack([v, z[:, 1:]])
        sol, _ = nnls(phi, y, maxiter=50 * phi.shape[1])
        weights[0] = sol[0]
        weights[2:] = sol[1:]
    else:
        # columns: z_1 (= v, carries w1), z_2..z_m; target minus the known linear part
        sol, _ = nnls(z, y - float(w0) * v, maxiter=50 * z.shape[1])
        weights[0] = float(w0)
        weights[1:] = sol
    return weights


def identify_transfer_function(u, x, delay=0):
    """Identify ``G(z) = (b1 z + b2)/(z^2 + a1 z + a2)`` from its input and output (step 2).

    Ordinary least squares on the ARX form
    ``x(k) = -a1 x(k-1) - a2 x(k-2) + b1 u(k-1-n) + b2 u(k-2-n)``.

    Parameters
    ----------
    u : array_like, shape (N,)
        Input ``u(k)`` (the PI output of ``v(k)``), row-aligned with ``x``.
    x : array_like, shape (N,)
        Output ``x(k)``.
    delay : int
        Extra input delay n in samples (``tf.delay``).

    Returns
    -------
    a1, a2, b1, b2 : float
    """
    u = np.asarray(u, dtype=float).ravel()
    x = np.asarray(x, dtype=float).ravel()
    if u.shape != x.shape:
        raise ValueError(f"u and x must have the same length, got {u.size} and {x.size}")
    n = int(delay)
    if n < 0:
        raise ValueError(f"delay must be >= 0, got {delay}")
    k0 = 2 + n
    if x.size < k0 + 4:
        raise ValueError(f"need at least {k0 + 4} samples, got {x.size}")
    k = np.arange(k0, x.size)
    phi = np.column_stack([-x[k - 1], -x[k - 2], u[k - 1 - n], u[k - 2 - n]])
    theta, *_ = np.linalg.lstsq(phi, x[k], rcond=None)
    a1, a2, b1, b2 = (float(t) for t in theta)
    return a1, a2, b1, b2
