"""The joint fit by variable projection: the PI weights solved, the rest searched.

The coupled model of every record is

    y = C_alpha[ G[ Phi w ] ],   Phi = [v, z_2 .. z_m]  (play operators of the voltage),

with the normalisation of :mod:`harness.identify.fit` (``G(1) = 1``, ``k_c = 1``,
``w1 = 0``).  ``G`` and the creep operator ``C_alpha`` are linear, so for fixed
poles, zero and creep order the output is *linear* in the PI weights: ``y = M(theta) w``
with ``M(theta) = C_alpha[G[Phi]]`` (each column filtered), and the best ``w >= 0``
is a non-negative least-squares problem (:func:`scipy.optimize.nnls`).  What is left
to search nonlinearly is ``theta``, four numbers (three without creep):

==========  =======================================  ==========================
``q1``      ``ln(1 - p1)``, ``p1`` the slow pole      keeps ``p1 < 1`` (stable)
``p2``      the fast pole                             in ``(-1, 1)``
``rho``     ``ln((1 - zeta) / (1 - p1))``             the zero ``zeta`` next to ``p1``
``alpha``   the creep order                           in ``[-0.9, 0.9]``
==========  =======================================  ==========================

so that ``a1 = -(p1 + p2)``, ``a2 = p1 p2``, ``b1 = (1 - p2) exp(-rho)``,
``b2 = -b1 zeta`` (then ``G(1) = 1`` by construction).  The slow pole and its
nearly cancelling zero are searched in logarithms of their distances to 1, which
is what the data resolve (a pole at 0.992 moves the output through ``1 - p1``).

The search minimises the projected residual ``r(theta) = M(theta) w*(theta) - y``
by :func:`scipy.optimize.least_squares` with the Kaufman Jacobian
``-(I - P_A) dM/dtheta w`` (``P_A`` the projector on the columns of the active
weights), computed analytically: one filter pass for the poles and the zero, one
FFT convolution for ``alpha``.  It stops when an iteration lowers the sum of
squares by less than ``FTOL`` of itself: at convergence the sum of squares is the
records' noise floor, so the rule is relative to the noise the data carry, not a
count of evaluations (``max_evaluations`` only guards against a search that
never settles).

Starts: the search is local, and a slow pole that runs towards 1 can mimic creep
(a local minimum), and a start on one side of the creep order can share one
with its neighbours.  :func:`fit_multistart` runs at least three starts (the
middle of Table 1's orders and both sides of it) and keeps the lowest sum of
squares; once two have ended there, the rest are skipped.  Real poles only: the joint refinement in :mod:`harness.identify.fit`
then polishes the general ``G`` (complex poles allowed) from the result.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time as _time

import numpy as np
# scipy is imported inside the functions that use it: the build imports this package with
# its build requirements only (fmpy, cffi, numpy), and scipy costs 0.3-0.7 s at import.
from numpy.linalg import LinAlgError

from .model import gl_weights

__all__ = ["FTOL", "DEFAULT_STARTS", "MIN_STARTS", "AGREE", "Theta", "LocalFit", "MultiStartFit", "ReducedProblem",
           "fit_multistart", "theta_from_g"]

#: Relative decrease of the sum of squares below which an iteration ends the search.
FTOL = 1e-10
#: Starts (slow pole, creep order), in the order they run: the middle of Table 1's orders,
#: then both sides of it, then farther out.
DEFAULT_STARTS = ((0.99, 0.0), (0.985, 0.01), (0.995, -0.01), (0.985, -0.01), (0.995, 0.01),
                  (0.99, 0.02), (0.99, -0.02))
#: Fewest starts that run, and how many of them must end at the lowest minimum before the
#: rest are skipped.
MIN_STARTS = 3
AGREE = 2
#: Start of the fast pole and of the zero's offset from the slow pole.
START_FAST_POLE = 0.45
START_RHO = 0.0
# bounds of (q1, p2, rho, alpha)
_LO = (math.log(1e-6), -0.95, -4.0, -0.9)
_HI = (math.log(1.9), 0.95, 4.0, 0.9)
# central-difference step in alpha for the derivative of the creep kernel
_ALPHA_STEP = 1e-6


@dataclass(frozen=True)
class Theta:
    """The searched parameters, named (see the module docstring)."""

    q1: float
    p2: float
    rho: float
    alpha: float = 0.0

    @property
    def slow_pole(self):
        return 1.0 - math.exp(self.q1)

    @property
    def zero(self):
        return 1.0 - math.exp(self.q1 + self.rho)

    def g(self):
        """``(a1, a2, b1, b2)`` of ``G`` with ``G(1) = 1``."""
        p1, p2 = self.slow_pole, self.p2
        b1 = (1.0 - p2) * math.exp(-self.rho)
        return -(p1 + p2), p1 * p2, b1, -b1 * self.zero


def theta_from_g(a1, a2, b1, b2, alpha=0.0):
    """The :class:`Theta` of a ``G`` with real poles in (-1, 1) and ``G(1) > 0``, or None.

    ``G`` is normalised to ``G(1) = 1`` first; the slow pole is the larger one.
    """
    disc = a1 * a1 - 4.0 * a2
    if disc < 0 or b1 == 0:
        return None
    r = math.sqrt(disc)
    p1, p2 = (-a1 + r) / 2.0, (-a1 - r) / 2.0
    zeta = -b2 / b1
    if not (-1.0 < p2 <= p1 < 1.0) or not zeta < 1.0:
        return None
    th = Theta(math.log(1.0 - p1), p2, math.log((1.0 - zeta) / (1.0 - p1)), float(alpha))
    lo, hi = _LO, _HI
    if not all(lo[i] < v < hi[i] for i, v in enumerate((th.q1, th.p2, th.rho, th.alpha))):
        return None
    return th


@dataclass(frozen=True)
class LocalFit:
    """One local search: where it started and ended, how well, how long."""

    start: Theta
    theta: Theta
    weights: np.ndarray
    cost: float            # half the sum of squares on the fit windows [um^2]
    rms: float             # rms of the residual [um]
    evaluations: int
    converged: bool
    message: str
    elapsed_s: float


@dataclass(frozen=True)
class MultiStartFit:
    """The best of several local searches, and all of them."""

    best: LocalFit
    fits: tuple
    agreed: int            # starts that ended at the best minimum (within the tolerance)
    elapsed_s: float


class _Record:
    """One record's design matrix, delayed by ``tf.delay``, and its transforms."""

    def __init__(self, design, y, n_fit, delay):
        from scipy import fft

        phi = np.asarray(design, dtype=float)
        if delay:
            phi = np.concatenate([np.zeros((delay, phi.shape[1])), phi[:phi.shape[0] - delay]])
        self.phi = phi
        self.y_fit = np.asarray(y, dtype=float)[:n_fit]
        self.n = phi.shape[0]
        self.n_fit = int(n_fit)
        self.nfft = fft.next_fast_len(2 * self.n - 1, real=True)
        self._phi_f = None

    def phi_f(self):
        from scipy import fft

        if self._phi_f is None:
            self._phi_f = fft.rfft(self.phi, self.nfft, axis=0)
        return self._phi_f


class ReducedProblem:
    """The projected residual of the coupled model over the fit windows of all records.

    Parameters
    ----------
    designs : sequence of ndarray, shape (N_i, m)
        ``[v, z_2 .. z_m]`` of each record over its whole length (from rest).
    ys : sequence of ndarray
        The measured displacement of each record.
    n_fits : sequence of int
        Samples of each record in its fit window (the first ``n_fit``).
    h : float
        Sample period [s].
    delay : int
        Extra input delay of ``G`` [samples].
    creep : bool
        With the creep operator (the coupled model) or without (the Hammerstein model).
    """

    def __init__(self, designs, ys, n_fits, h, delay=0, creep=True):
        self.records = [_Record(d, y, n, int(delay)) for d, y, n in zip(designs, ys, n_fits)]
        self.h = float(h)
        self.creep = bool(creep)
        self.y = np.concatenate([r.y_fit for r in self.records])
        self.m = self.records[0].phi.shape[1]
        self.evaluations = 0
        self._creep_cache = {}
        self._last = None

    # -- the operators ------------------------------------------------------
    def _kernels(self, alpha, rec):
        from scipy import fft

        h, n = self.h, rec.n
        lo, hi = max(alpha - _ALPHA_STEP, -1.0), min(alpha + _ALPHA_STEP, 1.0)
        k = fft.rfft(h ** -alpha * gl_weights(alpha, n), rec.nfft)
        dk = fft.rfft((h ** -hi * gl_weights(hi, n) - h ** -lo * gl_weights(lo, n)) / (hi - lo),
                      rec.nfft)
        return k, dk

    def creep_design(self, alpha):
        """``C_alpha[Phi]`` of every record (whole length) and the kernels' transforms."""
        from scipy import fft

        if not self.creep:
            return [(r.phi, None) for r in self.records]
        key = float(alpha)
        hit = self._creep_cache.get(key)
        if hit is None:
            if len(self._creep_cache) >= 4:
                self._creep_cache.pop(next(iter(self._creep_cache)))
            hit = []
            for r in self.records:
                k, dk = self._kernels(key, r)
                cphi = fft.irfft(k[:, None] * r.phi_f(), r.nfft, axis=0)[:r.n]
                hit.append((cphi, dk))
            self._creep_cache[key] = hit
        return hit

    @staticmethod
    def _filter(a1, a2, b1, b2, x):
        from scipy.signal import lfilter

        return lfilter([0.0, b1, b2], [1.0, a1, a2], x, axis=0)

    # -- evaluation ---------------------------------------------------------
    def _vector(self, theta):
        theta = np.asarray(theta, dtype=float)
        return Theta(*theta) if self.creep else Theta(*theta[:3], 0.0)

    def evaluate(self, theta):
        """``(w, residual, columns)`` at ``theta``: the projected solution, cached."""
        from scipy.optimize import nnls

        key = tuple(float(t) for t in theta)
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        th = self._vector(theta)
        a1, a2, b1, b2 = th.g()
        cols = []
        for r, (cphi, _) in zip(self.records, self.creep_design(th.alpha)):
            cols.append(self._filter(a1, a2, b1, b2, cphi[:r.n_fit]))
        big = np.vstack(cols)
        self.evaluations += 1
        if not np.all(np.isfinite(big)):
            out = (np.zeros(self.m), np.full(self.y.size, 1e6), big)
        else:
            r_, qty = _triangular(big, self.y)
            w, _ = nnls(r_, qty, maxiter=50 * self.m)
            out = (w, big @ w - self.y, big)
        self._last = (key, out)
        return out

    def residual(self, theta):
        """``M(theta) w*(theta) - y`` on the fit windows [um]."""
        return self.evaluate(theta)[1]

    def _partials(self, theta):
        """``(w, M, D)``: the weights, ``M(theta)`` and ``D = d(M w)/d theta`` at fixed ``w``."""
        from scipy import fft

        th = self._vector(theta)
        w, _, big = self.evaluate(theta)
        a1, a2, b1, b2 = th.g()
        e1, e1r = math.exp(th.q1), math.exp(th.q1 + th.rho)
        p1, p2, zeta = th.slow_pole, th.p2, th.zero
        # d(a1, a2, b1, b2) / d(q1, p2, rho), from a1 = -(p1 + p2), a2 = p1 p2,
        # b1 = (1 - p2) exp(-rho), b2 = -b1 zeta, p1 = 1 - exp(q1), zeta = 1 - exp(q1 + rho)
        chain = np.array([[e1, -1.0, 0.0],
                          [-e1 * p2, p1, 0.0],
                          [0.0, -math.exp(-th.rho), -b1],
                          [b1 * e1r, zeta * math.exp(-th.rho), b1]])
        blocks = []
        for r, (cphi, dk) in zip(self.records, self.creep_design(th.alpha)):
            s = cphi[:r.n_fit] @ w                     # C_alpha[Phi w] on the fit window
            y = self._filter(a1, a2, b1, b2, s)
            cols = [_g_partials(s, y, a1, a2) @ chain]
            if self.creep:                             # G[dC/dalpha [Phi w]]
                dc = fft.irfft(dk * fft.rfft(r.phi @ w, r.nfft), r.nfft)[:r.n_fit]
                cols.append(self._filter(a1, a2, b1, b2, dc)[:, None])
            blocks.append(np.hstack(cols))
        return w, big, np.vstack(blocks)

    def jacobian(self, theta):
        """Kaufman's Jacobian of :meth:`residual`: ``(I - P_A) d(M w)/d theta``."""
        w, big, jac = self._partials(theta)
        active = w > 0
        if np.any(active):
            a = big[:, active]
            jac = jac - a @ _lstsq_normal(a, jac)
        return jac

    def full_jacobian(self, theta):
        """Jacobian of the residual in ``(w, theta)`` together: ``[M, d(M w)/d theta]``."""
        _, big, d = self._partials(theta)
        return np.hstack([big, d])

    def design_column(self, j):
        """Column ``j`` of the design matrix over the fit windows of all records."""
        return np.concatenate([r.phi[:r.n_fit, j] for r in self.records])

    def bounds(self):
        k = 4 if self.creep else 3
        return list(_LO[:k]), list(_HI[:k])

    # -- one local search ---------------------------------------------------
    def solve(self, start, *, max_evaluations=400):
        """Search from ``start`` (a :class:`Theta`); return a :class:`LocalFit`."""
        from scipy.optimize import least_squares

        t0 = _time.perf_counter()
        k = 4 if self.creep else 3
        x0 = np.array([start.q1, start.p2, start.rho, start.alpha][:k])
        lo, hi = self.bounds()
        x0 = np.clip(x0, np.nextafter(lo, 0), np.nextafter(hi, 0))
        n0 = self.evaluations
        res = least_squares(self.residual, x0, jac=self.jacobian, bounds=(lo, hi), method="trf",
                            x_scale="jac", ftol=FTOL, xtol=FTOL, gtol=FTOL,
                            max_nfev=int(max_evaluations))
        w, resid, _ = self.evaluate(res.x)
        theta = self._vector(res.x)
        cost = 0.5 * float(resid @ resid)
        return LocalFit(start=start, theta=theta, weights=w.copy(), cost=cost,
                        rms=math.sqrt(2.0 * cost / resid.size), evaluations=self.evaluations - n0,
                        converged=res.status > 0, message=res.message,
                        elapsed_s=_time.perf_counter() - t0)

    def output(self, theta, w, record):
        """The model's output over the whole of record ``record`` (an index)."""
        th = self._vector(theta)
        r = self.records[record]
        cphi, _ = self.creep_design(th.alpha)[record]
        return self._filter(*th.g(), cphi @ w)


def _gram_factor(a):
    """``R`` with ``R^T R = a^T a`` (Cholesky of the column-scaled Gram matrix).

    For the tall, narrow matrices here (tens of thousands of rows, at most 16
    columns, condition number about 1e2 once the columns are scaled) this is one
    matrix product instead of a Householder QR, and accurate to about
    ``eps cond^2 = 1e-11``.  A column that is zero (a play operator the records
    never move) gets a unit diagonal, so that its weight comes out 0.  Columns so
    nearly collinear that the Gram matrix is not positive definite (operators the
    records move only together) fall back to a Householder QR.
    """
    from scipy.linalg import cholesky

    try:
        return _gram_cholesky(a, cholesky)
    except LinAlgError:
        return np.linalg.qr(a, mode="r")


def _gram_cholesky(a, cholesky):
    g = a.T @ a
    d = np.sqrt(np.diag(g).copy())
    dead = d == 0
    d[dead] = 1.0
    g = g / d[:, None] / d[None, :]
    g[dead, dead] = 1.0
    g[np.diag_indices_from(g)] += 1e-14
    return cholesky(g, lower=False) * d[None, :]


def _triangular(a, y):
    """``(R, Q^T y)`` of the least-squares problem ``min ||a w - y||`` (``a = Q R``)."""
    from scipy.linalg import cholesky, solve_triangular

    try:
        r = _gram_cholesky(a, cholesky)
        return r, solve_triangular(r, a.T @ y, trans="T", lower=False)
    except LinAlgError:
        q, r = np.linalg.qr(a)
        return r, q.T @ y


def _lstsq_normal(a, b):
    """``argmin_X ||a X - b||`` column by column (minimum norm where ``a`` is rank deficient)."""
    from scipy.linalg import cho_solve, cholesky

    try:
        return cho_solve((_gram_cholesky(a, cholesky), False), a.T @ b)
    except LinAlgError:
        return np.linalg.lstsq(a, b, rcond=None)[0]


def _g_partials(u, y, a1, a2):
    """``d y / d (a1, a2, b1, b2)`` of ``y = (b1 z^-1 + b2 z^-2)/(1 + a1 z^-1 + a2 z^-2) u``."""
    from scipy.signal import lfilter

    def shift(s, n):
        out = np.zeros_like(s)
        out[n:] = s[:s.size - n]
        return out

    cols = np.column_stack([-shift(y, 1), -shift(y, 2), shift(u, 1), shift(u, 2)])
    return lfilter([1.0], [1.0, a1, a2], cols, axis=0)


#: Two searches ended at the same minimum when their rms residuals differ by less than this
#: fraction, or both are below RMS_ZERO (noise-free records: round-off).
SAME_RMS = 1e-4
RMS_ZERO = 1e-9     # um


def _same_minimum(a, b):
    """Two local fits at the same minimum (rms within ``SAME_RMS``, or both at round-off)."""
    if max(a.rms, b.rms) <= RMS_ZERO:
        return True
    return abs(a.rms - b.rms) <= SAME_RMS * max(a.rms, b.rms)


def fit_multistart(problem, starts, *, max_evaluations=400, agree=AGREE,
                   min_starts=MIN_STARTS, progress=None, label="search"):
    """Run local searches from ``starts`` until ``agree`` of them end at the best minimum.

    At least ``min_starts`` run (starts on both sides of the usual creep order: a single
    side can share a local minimum); then the search stops as soon as ``agree`` runs
    ended at the lowest sum of squares found.

    Parameters
    ----------
    problem : ReducedProblem
    starts : sequence of Theta
    max_evaluations : int
        Most evaluations of one local search.
    agree : int
        Stop early once this many starts ended at the same lowest sum of squares.
    min_starts : int
        Starts that always run (all of them if fewer are given).
    progress : callable, optional
        Called with one line of text after each start.
    label : str
        Name of the search in the progress lines.

    Returns
    -------
    MultiStartFit
    """
    t0 = _time.perf_counter()
    fits = []
    for i, start in enumerate(starts, start=1):
        fit = problem.solve(start, max_evaluations=max_evaluations)
        fits.append(fit)
        best = min(fits, key=lambda f: f.cost)
        same = sum(_same_minimum(f, best) for f in fits)
        if progress is not None:
            state = "converged" if fit.converged else f"stopped ({fit.evaluations} evaluations)"
            progress(f"{label}: start {i}/{len(starts)} (slow pole {start.slow_pole:.4g}, "
                     f"alpha {start.alpha:+.3g}) -> rms {fit.rms * 1e3:.4g} nm, {state}, "
                     f"{fit.evaluations} evaluations, {fit.elapsed_s:.1f} s")
        if i >= min_starts and same >= agree and best.converged:
            break
    best = min(fits, key=lambda f: f.cost)
    same = sum(_same_minimum(f, best) for f in fits)
    return MultiStartFit(best=best, fits=tuple(fits), agreed=same,
                         elapsed_s=_time.perf_counter() - t0)
