"""Fit the coupled model to measured records of voltage ``v`` and displacement ``y`` only.

A real stage gives the applied voltage and the measured displacement, never
the internal signals ``u = P[v]`` and ``x = G[u]``.  :func:`fit_coupled_model`
identifies the model from ``v`` and ``y`` in four stages:

1. **Stepwise** (paper section 3), every step fitted to the measured ``y``:
   step 1, the PI weights from the low-frequency record (linear least
   squares with ``w >= 0``); step 2, ``G`` from the mixed-frequency record
   with ``u = P[v]`` of step 1 (ARX least squares refined by output error);
   step 3, ``k_c`` and ``alpha`` of each creep record with ``x = G[P[v]]`` of
   steps 1-2 (nonlinear least squares).  Because each step fits ``y``, each
   block absorbs what the later ones would explain (the 1 Hz PI fit takes
   ``G``'s gain and the creep, ``G`` takes the creep, and may come out
   unstable).  The stepwise result is reported and used as one start of the
   search; it never ends the run.
2. **Search** by variable projection (:mod:`harness.identify.varpro`) over
   all records together: the PI weights enter linearly and are solved (least
   squares with ``w >= 0``) for every value of the four parameters that do
   not (the slow pole, the fast pole, the zero and ``alpha``), which are
   searched from several starts (:data:`harness.identify.varpro.DEFAULT_STARTS`
   and the stepwise result): at least three, until two have ended at the lowest
   sum of squares found.
3. **Joint refinement**: every parameter at once (``G`` in its general form,
   complex poles allowed), by nonlinear least squares
   (:func:`scipy.optimize.least_squares`, trust region reflective, analytic
   Jacobian), started from the search's result; kept when it lowers the sum
   of squares.  One PI, one ``G`` and one creep row for the stage.
4. **Checks**: each parameter's standard error with a noise of at least
   :data:`SIGMA_FLOOR` (:func:`undetermined_parameters`); a parameter the
   records do not determine is named in
   :attr:`IdentificationResult.undetermined`, with the record that would fix it.

Both nonlinear fits stop by a rule relative to the data, not by a count: when
an iteration lowers the sum of squares by less than ``1e-10`` of itself (at
convergence the sum of squares is the records' noise floor), or moves the
parameters by less than ``1e-10`` relative.  ``max_evaluations`` only bounds a
search that would never settle; a search that reaches it raises
:class:`IdentificationFitError` saying so.

**Normalisation.**  ``y = C[G[P[v]]]`` is unchanged when the PI weights are
multiplied by ``c`` and ``G`` or ``k_c`` divided by it, so only the product of
the three gains is identifiable; and ``r_1 = 0`` makes the first play operator
the identity, so only ``w0 + w1`` is.  Parameters are reported under

* ``G(1) = (b1 + b2) / (1 + a1 + a2) = 1``: ``G`` describes dynamics only;
* ``k_c = 1`` for the stage's creep row: the creep block is
  ``h^-alpha sum_j w_j(alpha) x(k-j)``;
* ``w1 = 0``: ``w0`` carries the whole linear weight ``w0 + w1``;

so the PI weights carry the static gain in um/V and ``w0`` *is* the static
gain ``(w0 + w1) G(1) k_c``.  Any identified or true model maps onto this
form with :meth:`CoupledModel.normalized` without changing its output.  The
per-record creep rows (paper Table 1) are then fitted with the joint PI and
``G`` fixed, so their ``k_c`` is the record's gain relative to the stage's.

**Hold-out.**  Each record is split in time: the first ``1 - holdout`` of
its samples are fitted, the rest is held out.  Models are always simulated
over the whole record from rest (the creep remembers from the first
sample), and held-out errors (eqs 36-37, against the measured ``y``) are
computed on the held-out samples only.

**Confidence.**  Each step reports its parameters with standard errors
``sqrt(diag(s^2 (J^T J)^-1))``, ``J`` the Jacobian of the fit residuals at
the solution and ``s^2`` the residual variance; they assume white residuals
and are approximate for weights at their bound 0.

The creep operator is evaluated with the full memory by FFT convolution
(:func:`harness.identify.model.gl_convolve`); the FMUs' default
sum-of-exponentials tail differs from it by far less than a nanometre.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
import time as _time

import numpy as np
# scipy is imported inside the functions that use it: the build imports this package with
# its build requirements only (fmpy, cffi, numpy), and scipy costs 0.3-0.7 s at import.

from ..loop.metrics import relative_error, rms_error
from .model import (
    IdentificationInputError,
    creep_output,
    g_filter,
    gl_convolve,
    gl_weights,
    pi_thresholds,
    play_operator_outputs,
)
from .steps import identify_transfer_function
from .varpro import (DEFAULT_STARTS, FTOL as _FTOL, START_FAST_POLE, START_RHO, ReducedProblem,
                     Theta, _triangular, fit_multistart, theta_from_g)

__all__ = [
    "DEFAULT_HOLDOUT",
    "DEFAULT_MAX_EVALUATIONS",
    "SIGMA_FLOOR",
    "IdentificationFitError",
    "UndeterminedModelError",
    "Undetermined",
    "CoupledModel",
    "ParameterEstimate",
    "StepFit",
    "HeldOutFit",
    "IdentificationResult",
    "fit_coupled_model",
]

#: Fraction of each record held out by default (its last quarter).
DEFAULT_HOLDOUT = 0.25
#: Most evaluations of one local search (a guard; the stopping rule is relative to the data).
DEFAULT_MAX_EVALUATIONS = 500
#: Noise [um rms] below which the identifiability check does not trust the records: a
#: parameter must be determined as if the records carried at least this much noise.
SIGMA_FLOOR = 1e-3
#: Fewest samples in a record's fit window.
MIN_FIT_SAMPLES = 100
# Central-difference step in alpha for d y / d alpha (see steps._ALPHA_STEP).
_ALPHA_STEP = 1e-6


class IdentificationFitError(RuntimeError):
    """The search stopped at its evaluation limit before converging (the message says so)."""


class UndeterminedModelError(IdentificationInputError):
    """The records do not determine a parameter (the message names it and the record to add)."""


@dataclass(frozen=True)
class Undetermined:
    """A parameter the records do not determine, and what would.

    Attributes
    ----------
    parameter : str
        FMU variable name (``pi.w[3]``, ``creep.alpha``) or a derived quantity
        (``slow pole``, ``fast pole``, ``zero``).
    std_error : float
        Its standard error with the noise of the records, or :data:`SIGMA_FLOOR` if
        that is larger.
    limit : float
        The standard error above which it counts as undetermined.
    remedy : str
        The record that would determine it.
    """

    parameter: str
    std_error: float
    limit: float
    remedy: str

    def text(self):
        return (f"{self.parameter} (standard error {self.std_error:.3g}, limit {self.limit:g}): "
                f"{self.remedy}")


# ---------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class CoupledModel:
    """The coupled model ``v --PI--> u --G--> x --creep--> y`` (or the Hammerstein model).

    Attributes
    ----------
    weights : tuple of float
        ``(w0, w1, ..., wm)`` [um/V].
    v_max : float
        Threshold scale [V], ``r_j = (j-1)/m v_max``.
    a1, a2, b1, b2 : float
        ``G(z) = (b1 z + b2)/(z^2 + a1 z + a2)``.
    k_c, alpha : float
        Creep gain and order (eq 17).
    h : float
        Sample period [s].
    delay : int
        Extra input delay of ``G`` [samples].
    creep : bool
        False: the Hammerstein model (``creep.enabled = false``, ``y = x``).
    """

    weights: tuple
    v_max: float
    a1: float
    a2: float
    b1: float
    b2: float
    k_c: float
    alpha: float
    h: float
    delay: int = 0
    creep: bool = True

    @property
    def m(self):
        """Number of play operators."""
        return len(self.weights) - 1

    @property
    def dc_gain(self):
        """``G(1) = (b1 + b2) / (1 + a1 + a2)``."""
        return (self.b1 + self.b2) / (1.0 + self.a1 + self.a2)

    @property
    def poles(self):
        """Roots of ``z^2 + a1 z + a2``, largest real part first."""
        p = np.roots([1.0, self.a1, self.a2])
        p = np.real_if_close(p, tol=1e3)
        return tuple(sorted(p.tolist(), key=lambda z: -np.real(z)))

    @property
    def zero(self):
        """Zero of ``b1 z + b2``."""
        return -self.b2 / self.b1

    @property
    def static_gain(self):
        """``(w0 + w1) G(1) k_c`` [um/V]: the gain product, the same under every normalisation."""
        k = self.k_c if self.creep else 1.0
        return (self.weights[0] + self.weights[1]) * self.dc_gain * k

    def normalized(self):
        """The same model under the normalisation ``G(1) = 1``, ``k_c = 1``, ``w1 = 0``.

        Returns
        -------
        CoupledModel
            Its output equals this model's for every input (up to round-off).

        Raises
        ------
        IdentificationInputError
            ``G(1)`` is not a finite positive number (nothing to normalise by).
        """
        g1 = self.dc_gain
        if not (math.isfinite(g1) and g1 > 0):
            raise IdentificationInputError(
                f"G(1) = {g1:.6g} is not a positive number: G cannot be normalised "
                f"(a1 = {self.a1:.6g}, a2 = {self.a2:.6g}, b1 = {self.b1:.6g}, b2 = {self.b2:.6g})")
        scale = g1 * (self.k_c if self.creep else 1.0)
        w = [(self.weights[0] + self.weights[1]) * scale, 0.0]
        w += [wj * scale for wj in self.weights[2:]]
        return replace(self, weights=tuple(w), b1=self.b1 / g1, b2=self.b2 / g1, k_c=1.0,
                       alpha=self.alpha if self.creep else 0.0)

    def plant_params(self):
        """Parameters by PiezoStage variable name (``pi.*``, ``tf.*``, ``creep.*``, ``h``).

        Returns
        -------
        dict
            Also valid for AdaptiveCompoundController, except ``tf.delay`` and
            ``creep.enabled`` (plant only).
        """
        p = {"pi.m": self.m, "pi.v_max": float(self.v_max), "pi.w0": float(self.weights[0])}
        p.update({f"pi.w[{j}]": float(self.weights[j]) for j in range(1, self.m + 1)})
        p.update({"tf.a1": float(self.a1), "tf.a2": float(self.a2), "tf.b1": float(self.b1),
                  "tf.b2": float(self.b2), "tf.delay": int(self.delay)})
        if self.creep:
            p.update({"creep.k_c": float(self.k_c), "creep.alpha": float(self.alpha)})
        else:
            p["creep.enabled"] = False
        p["h"] = float(self.h)
        return p

    def simulate(self, v, memory="full"):
        """Model output ``y(k)`` for the voltage ``v`` from rest.

        Parameters
        ----------
        v : array_like, shape (N,)
        memory : {"full", "soe"}
            Creep with the full memory (FFT convolution, what the fits use),
            or by the C core's sum-of-exponentials tail, as the FMUs compute
            it by default (``creep.exact = false``).

        Returns
        -------
        ndarray, shape (N,)
        """
        if memory not in ("full", "soe"):
            raise ValueError(f"memory must be 'full' or 'soe', got {memory!r}")
        v = np.asarray(v, dtype=float).ravel()
        z = play_operator_outputs(v, pi_thresholds(self.m, self.v_max))
        return self._output(self.weights[0] * v + z @ np.asarray(self.weights[1:]), memory)

    def _output(self, u, memory="full"):
        x = g_filter(u, self.a1, self.a2, self.b1, self.b2, self.delay)
        if not self.creep:
            return x
        if memory == "soe":
            return creep_output(x, self.k_c, self.alpha, self.h)
        return gl_convolve(x, self.alpha, self.k_c * self.h ** -self.alpha)


# ---------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class ParameterEstimate:
    """A fitted parameter with its standard error (NaN where none is defined)."""

    name: str
    value: float
    std_error: float = math.nan


@dataclass(frozen=True)
class StepFit:
    """One fit: what it fitted, on which records, how well.

    Attributes
    ----------
    step : str
        ``"1 PI"``, ``"2 G"``, ``"3 creep"``, ``"joint"``, ``"Hammerstein"``
        or ``"creep row"`` (paper Table 1, with the joint PI and ``G``).
    records : tuple of str
        Labels of the records fitted.
    parameters : tuple of ParameterEstimate
    e_rms : float
        rms of ``y - y_model`` on the fit windows [um] (eq 36).
    e_r : float
        Relative error on the fit windows (eq 37, divided by the measured ``y``).
    n_samples : int
        Residuals fitted.
    note : str
        Why a step gave no usable result (empty when it did), e.g. an unstable ``G``.
    """

    step: str
    records: tuple
    parameters: tuple
    e_rms: float
    e_r: float
    n_samples: int
    note: str = ""

    def value(self, name):
        """The value of parameter ``name`` (KeyError if the step has none of that name)."""
        for p in self.parameters:
            if p.name == name:
                return p.value
        raise KeyError(f"step {self.step!r} has no parameter {name!r}")


@dataclass(frozen=True)
class HeldOutFit:
    """Errors of the Hammerstein and the coupled model on one record's held-out samples.

    ``e_rms`` [um] and ``e_r`` (eqs 36-37) against the measured ``y``.
    """

    label: str
    hammerstein_e_rms: float
    hammerstein_e_r: float
    coupled_e_rms: float
    coupled_e_r: float
    n_samples: int


@dataclass(frozen=True)
class IdentificationResult:
    """What :func:`fit_coupled_model` found.

    Attributes
    ----------
    model : CoupledModel
        The jointly refined coupled model, normalised: the one to export.
    stepwise : CoupledModel or None
        The stepwise result, normalised (one start of the search); None when a
        step gave no usable model (e.g. an unstable ``G``, see the step's note).
    hammerstein : CoupledModel or None
        The Hammerstein model (no creep) refined on the same data, normalised
        (None when not asked for).
    steps : tuple of StepFit
        Step 1, step 2, step 3 (one per creep record), the joint refinement
        and the Hammerstein refinement, in that order.
    creep_rows : tuple of StepFit
        Paper Table 1: ``k_c`` and ``alpha`` of each creep record, with the
        joint PI and ``G`` fixed.
    held_out : tuple of HeldOutFit
        Paper Tables 2-3 on the held-out samples, one per record (empty when
        ``holdout`` is 0).
    holdout : float
    joint : tuple of ParameterEstimate
        The refined parameters and derived quantities (poles, zero, static
        gain) with standard errors.
    search : harness.identify.varpro.MultiStartFit
        The search of the coupled model: every start, where it ended, how long.
    undetermined : tuple of Undetermined
        Parameters the records do not determine (empty: all are).
    elapsed_s : float
    """

    model: CoupledModel
    stepwise: CoupledModel
    hammerstein: CoupledModel
    steps: tuple
    creep_rows: tuple
    held_out: tuple
    holdout: float
    joint: tuple
    search: object = field(default=None, compare=False)
    undetermined: tuple = ()
    elapsed_s: float = field(default=0.0, compare=False)

    def step(self, name):
        """The first :class:`StepFit` whose ``step`` is ``name``."""
        for s in self.steps:
            if s.step == name:
                return s
        raise KeyError(f"no step {name!r}; steps: {', '.join(s.step for s in self.steps)}")


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------

class _Prepared:
    """A record with its PI design matrix ``[v, z_2 .. z_m]`` and its fit window."""

    def __init__(self, record, m, v_max, holdout):
        self.label = str(record.label)
        self.v = _finite(f"{self.label}: v", record.v)
        self.y = _finite(f"{self.label}: y", record.y)
        if self.v.shape != self.y.shape:
            raise IdentificationInputError(
                f"{self.label}: v and y must have the same length, got {self.v.size} "
                f"and {self.y.size}")
        n = self.v.size
        self.n_fit = n if holdout == 0 else int(round(n * (1.0 - holdout)))
        if self.n_fit < MIN_FIT_SAMPLES or (holdout > 0 and self.n_fit >= n):
            raise IdentificationInputError(
                f"{self.label}: {n} samples leave {self.n_fit} to fit and {n - self.n_fit} "
                f"held out; need at least {MIN_FIT_SAMPLES} to fit and 1 held out")
        z = play_operator_outputs(self.v, pi_thresholds(m, v_max))
        # r_1 = 0 makes z_1 = v: one column carries w0 + w1 (normalisation w1 = 0)
        self.design = np.column_stack([self.v, z[:, 1:]])

    @property
    def y_fit(self):
        return self.y[:self.n_fit]


def _finite(name, a):
    a = np.asarray(a, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise IdentificationInputError(f"{name} must be a non-empty 1-D sequence, got shape {a.shape}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise IdentificationInputError(f"{name}[{bad[0]}] = {float(a[bad[0]])!r} is not finite")
    return a


def _stable(a1, a2):
    """Jury test of ``z^2 + a1 z + a2``: both roots strictly inside the unit circle."""
    return abs(a2) < 1.0 and abs(a1) < 1.0 + a2


def _shift(s, n):
    """``s(k - n)`` with zeros before the first sample (along axis 0)."""
    if n == 0:
        return s
    out = np.zeros_like(s)
    out[n:] = s[:s.shape[0] - n]
    return out


def _metrics(y, y_model):
    return rms_error(y, y_model), relative_error(y, y_model, normalizer=y)


def _std_errors(jac, residual, n_params):
    """Standard errors and covariance ``s^2 (J^T J)^+`` of a least-squares fit."""
    n = residual.size
    dof = max(n - n_params, 1)
    s2 = float(residual @ residual) / dof
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    return np.sqrt(np.maximum(np.diag(cov), 0.0)), cov


def _pi_estimates(m, w_free, se):
    names = ["pi.w0"] + [f"pi.w[{j}]" for j in range(2, m + 1)]
    return [ParameterEstimate(n, float(w), float(s)) for n, w, s in zip(names, w_free, se)]


# ---------------------------------------------------------------------------
# the three steps on measured y
# ---------------------------------------------------------------------------

def _step_pi(rec):
    """Step 1: ``min ||Phi w - y||, w >= 0`` on the fit window (``w1 = 0``)."""
    from scipy.optimize import nnls

    phi = rec.design[:rec.n_fit]
    r, qty = _triangular(phi, rec.y_fit)     # the same minimiser, on an m x m system
    w, _ = nnls(r, qty, maxiter=50 * phi.shape[1])
    resid = phi @ w - rec.y_fit
    se, _ = _std_errors(phi, resid, phi.shape[1])
    e_rms, e_r = _metrics(rec.y_fit, phi @ w)
    m = phi.shape[1]
    fit = StepFit("1 PI", (rec.label,), tuple(_pi_estimates(m, w, se)), e_rms, e_r, rec.n_fit)
    return w, fit


def _g_jacobian(u, x, a1, a2, delay):
    """d x / d (a1, a2, b1, b2) of ``x = G[u]``, columns (N, 4)."""
    from scipy.signal import lfilter

    ud = _shift(u, delay)
    cols = np.column_stack([-_shift(x, 1), -_shift(x, 2), _shift(ud, 1), _shift(ud, 2)])
    return lfilter([1.0], [1.0, a1, a2], cols, axis=0)


def _step_g(rec, w_free, delay):
    """Step 2: ``G`` from ``u = P[v]`` (step 1) to the measured ``y`` (ARX, then output error).

    Returns ``(a1, a2, b1, b2)`` or None when the fitted ``G`` is unstable or has no
    positive static gain (the step then carries a note), and the :class:`StepFit`.
    """
    u = rec.design @ w_free
    a1, a2, b1, b2 = identify_transfer_function(u[:rec.n_fit], rec.y_fit, delay=delay)
    params = tuple(ParameterEstimate(n, v) for n, v in
                   zip(("tf.a1", "tf.a2", "tf.b1", "tf.b2"), (a1, a2, b1, b2)))
    g1 = (b1 + b2) / (1.0 + a1 + a2) if 1.0 + a1 + a2 != 0 else math.nan
    if not _stable(a1, a2) or not g1 > 0:
        why = "unstable" if not _stable(a1, a2) else f"with static gain {g1:.3g}"
        note = (f"G {why} (a1 = {a1:.6g}, a2 = {a2:.6g}): fitted to y, G absorbs the creep; "
                f"not used as a start")
        return None, StepFit("2 G", (rec.label,), params, math.nan, math.nan, rec.n_fit, note)
    x = g_filter(u, a1, a2, b1, b2, delay)[:rec.n_fit]
    jac = _g_jacobian(u[:rec.n_fit], x, a1, a2, delay)
    se, _ = _std_errors(jac, x - rec.y_fit, 4)
    e_rms, e_r = _metrics(rec.y_fit, x)
    params = tuple(ParameterEstimate(n, v, float(s)) for n, v, s in
                   zip(("tf.a1", "tf.a2", "tf.b1", "tf.b2"), (a1, a2, b1, b2), se))
    return (a1, a2, b1, b2), StepFit("2 G", (rec.label,), params, e_rms, e_r, rec.n_fit)


class _Creep:
    """The creep operator of order ``alpha`` for k_c = 1 on records of ``n`` samples.

    ``apply(x) = h^-alpha sum_j w_j(alpha) x(k-j)`` and ``dalpha(x)``, its
    derivative in ``alpha`` (central difference of the kernel), both by FFT
    convolution with the kernel transforms computed once.
    """

    def __init__(self, alpha, h, n):
        from scipy import fft

        self.n = n
        self.nfft = fft.next_fast_len(2 * n - 1, real=True)
        lo, hi = max(alpha - _ALPHA_STEP, -1.0), min(alpha + _ALPHA_STEP, 1.0)
        d_kernel = (h ** -hi * gl_weights(hi, n) - h ** -lo * gl_weights(lo, n)) / (hi - lo)
        self._k = fft.rfft(h ** -alpha * gl_weights(alpha, n), self.nfft)
        self._dk = fft.rfft(d_kernel, self.nfft)

    def _conv(self, kernel, x):
        from scipy import fft

        if x.ndim > 1:
            kernel = kernel[:, None]
        return fft.irfft(kernel * fft.rfft(x, self.nfft, axis=0), self.nfft, axis=0)[:self.n]

    def apply(self, x):
        return self._conv(self._k, x)

    def dalpha(self, x):
        return self._conv(self._dk, x)


def _fit_creep(x, y, h, label, step):
    """``k_c``, ``alpha`` of ``y = k_c h^-alpha GL_alpha[x]`` by least squares (fit window only)."""
    from scipy.optimize import least_squares

    if not np.any(x):
        raise IdentificationInputError(f"{label}: the model output x is zero: k_c and alpha "
                                       f"are not identifiable")

    cache = {}

    def creep(alpha):
        op = cache.get(alpha)
        if op is None:
            if len(cache) > 4:
                cache.clear()
            op = cache[alpha] = _Creep(alpha, h, x.size)
        return op

    def residual(p):
        return p[0] * creep(float(p[1])).apply(x) - y

    def jacobian(p):
        op = creep(float(p[1]))
        return np.column_stack([op.apply(x), p[0] * op.dalpha(x)])

    s0 = creep(0.0).apply(x)
    k0 = float(s0 @ y) / float(s0 @ s0)
    res = least_squares(residual, [k0 if k0 > 0 else 1.0, 0.0], jac=jacobian,
                        bounds=([0.0, -1.0], [np.inf, 1.0]), method="trf", x_scale="jac",
                        ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=200)
    k_c, alpha = float(res.x[0]), float(res.x[1])
    se, _ = _std_errors(jacobian(res.x), res.fun, 2)
    e_rms, e_r = _metrics(y, y + res.fun)
    params = (ParameterEstimate("creep.k_c", k_c, float(se[0])),
              ParameterEstimate("creep.alpha", alpha, float(se[1])))
    return StepFit(step, (label,), params, e_rms, e_r, int(y.size))


# ---------------------------------------------------------------------------
# joint refinement
# ---------------------------------------------------------------------------

class _Joint:
    """Residuals and analytic Jacobian of all records for the normalised parameters.

    ``theta = [w0, w2 .. wm, a1, a2, b1(, alpha)]`` with ``w1 = 0``,
    ``b2 = 1 + a1 + a2 - b1`` (``G(1) = 1``) and ``k_c = 1``.
    """

    def __init__(self, records, m, h, delay, creep):
        self.records, self.m, self.h, self.delay, self.creep = records, m, h, delay, creep
        self.n = sum(r.n_fit for r in records)
        self.scale = max(float(np.max(np.abs(r.y_fit))) for r in records)
        self._creep = {}

    def creep_op(self, alpha, n):
        op = self._creep.get((alpha, n))
        if op is None:
            if len(self._creep) > 16:
                self._creep.clear()
            op = self._creep[(alpha, n)] = _Creep(alpha, self.h, n)
        return op

    def unpack(self, theta):
        m = self.m
        a1, a2, b1 = (float(t) for t in theta[m:m + 3])
        alpha = float(theta[m + 3]) if self.creep else 0.0
        return theta[:m], a1, a2, b1, 1.0 + a1 + a2 - b1, alpha

    def pack(self, model):
        w = [model.weights[0]] + list(model.weights[2:])
        theta = w + [model.a1, model.a2, model.b1] + ([model.alpha] if self.creep else [])
        return np.array(theta, dtype=float)

    def bounds(self):
        lo = [0.0] * self.m + [-np.inf] * 3 + ([-1.0] if self.creep else [])
        hi = [np.inf] * (self.m + 3) + ([1.0] if self.creep else [])
        return lo, hi

    def model(self, theta, v_max):
        w, a1, a2, b1, b2, alpha = self.unpack(theta)
        weights = (float(w[0]), 0.0) + tuple(float(x) for x in w[1:])
        return CoupledModel(weights, float(v_max), a1, a2, b1, b2, 1.0, alpha, self.h,
                            self.delay, self.creep)

    def _x(self, rec, w, a1, a2, b1, b2):
        u = rec.design[:rec.n_fit] @ w
        return u, g_filter(u, a1, a2, b1, b2, self.delay)

    def residual(self, theta):
        w, a1, a2, b1, b2, alpha = self.unpack(theta)
        if not _stable(a1, a2):     # outside, the simulation diverges: steer back
            return np.full(self.n, 1e3 * self.scale)
        out = []
        for rec in self.records:
            _, x = self._x(rec, w, a1, a2, b1, b2)
            y = self.creep_op(alpha, rec.n_fit).apply(x) if self.creep else x
            out.append(y - rec.y_fit)
        return np.concatenate(out)

    def jacobian(self, theta):
        w, a1, a2, b1, b2, alpha = self.unpack(theta)
        p = theta.size
        if not _stable(a1, a2):
            return np.zeros((self.n, p))
        blocks = []
        for rec in self.records:
            u, x = self._x(rec, w, a1, a2, b1, b2)
            d = _g_jacobian(u, x, a1, a2, self.delay)
            # b2 = 1 + a1 + a2 - b1: chain rule onto (a1, a2, b1)
            dg = np.column_stack([d[:, 0] + d[:, 3], d[:, 1] + d[:, 3], d[:, 2] - d[:, 3]])
            cols = np.column_stack([g_filter(rec.design[:rec.n_fit], a1, a2, b1, b2,
                                             self.delay), dg])
            if self.creep:
                op = self.creep_op(alpha, rec.n_fit)
                cols = np.column_stack([op.apply(cols), op.dalpha(x)])
            blocks.append(cols)
        return np.vstack(blocks)


def _refine(records, start, creep, m, h, delay, max_evaluations):
    """Joint least squares from the normalised ``start`` (the search's result).

    Returns ``(model, StepFit, theta, cov)``: the refined model when it lowers the
    sum of squares, else ``start`` itself (with its standard errors).
    """
    from scipy.optimize import least_squares

    problem = _Joint(records, m, h, delay, creep)
    theta0 = problem.pack(start)
    lo, hi = problem.bounds()
    theta0 = np.clip(theta0, lo, hi)
    r0 = problem.residual(theta0)
    res = least_squares(problem.residual, theta0, jac=problem.jacobian, bounds=(lo, hi),
                        method="trf", x_scale="jac", ftol=_FTOL, xtol=_FTOL, gtol=_FTOL,
                        max_nfev=int(max_evaluations))
    theta = res.x.copy() if 2.0 * res.cost <= float(r0 @ r0) else theta0.copy()
    # the reflective solver keeps weights strictly inside w >= 0 (1e-29 and the like):
    # a weight that small is at its bound
    w = theta[:m]
    w[w <= 1e-12 * max(float(np.max(w)), 1e-300)] = 0.0
    model = problem.model(theta, start.v_max)
    resid = problem.residual(theta)
    jac = problem.jacobian(theta)
    se, cov = _std_errors(jac, resid, theta.size)
    y = np.concatenate([r.y_fit for r in records])
    e_rms, e_r = _metrics(y, y + resid)
    names = (["pi.w0"] + [f"pi.w[{j}]" for j in range(2, m + 1)] + ["tf.a1", "tf.a2", "tf.b1"]
             + (["creep.alpha"] if creep else []))
    params = tuple(ParameterEstimate(n, float(v), float(s)) for n, v, s in zip(names, theta, se))
    fit = StepFit("joint" if creep else "Hammerstein", tuple(r.label for r in records), params,
                  e_rms, e_r, int(resid.size))
    return model, fit, theta, cov


def _derived(model, cov, m):
    """b2, poles, zero and static gain of the refined model, standard errors by the delta method."""
    ia1, ia2, ib1 = m, m + 1, m + 2

    def se(grad):
        g = np.zeros(cov.shape[0])
        for i, v in grad.items():
            g[i] = v
        return float(math.sqrt(max(g @ cov @ g, 0.0)))

    a1, b1 = model.a1, model.b1
    out = [ParameterEstimate("tf.b2", model.b2, se({ia1: 1.0, ia2: 1.0, ib1: -1.0}))]
    for i, p in enumerate(model.poles, start=1):
        if isinstance(p, complex) or abs(2 * p + a1) < 1e-12:
            out.append(ParameterEstimate(f"pole {i}", p))
        else:
            out.append(ParameterEstimate(f"pole {i}", float(p),
                                         se({ia1: -p / (2 * p + a1), ia2: -1.0 / (2 * p + a1)})))
    s = 1.0 + model.a1 + model.a2
    out.append(ParameterEstimate("zero", model.zero, se({ia1: -1 / b1, ia2: -1 / b1,
                                                         ib1: s / b1 ** 2})))
    out.append(ParameterEstimate("static gain", model.static_gain, se({0: 1.0})))
    return out


def _design_weights(model):
    """The weights of the design matrix ``[v, z_2 .. z_m]``: ``[w0 + w1, w2 .. wm]``."""
    return np.array([model.weights[0] + model.weights[1]] + list(model.weights[2:]))


def _label_set(pi_record, tf_record, creep_records):
    """Distinct records in order of first use; labels must name one record each."""
    seen, out = {}, []
    for r in [pi_record, tf_record, *creep_records]:
        prev = seen.get(r.label)
        if prev is None:
            seen[r.label] = r
            out.append(r)
        elif prev is not r:
            raise IdentificationInputError(f"two different records are labelled {r.label!r}; "
                                           f"labels must be unique")
    return out


# ---------------------------------------------------------------------------
# public entry
# ---------------------------------------------------------------------------

def fit_coupled_model(pi_record, tf_record, creep_records, *, h=0.0005, m=9, v_max=None,
                      delay=0, holdout=DEFAULT_HOLDOUT, max_evaluations=DEFAULT_MAX_EVALUATIONS,
                      progress=None, hammerstein=True):
    """Identify the coupled model from measured ``v`` and ``y``: stepwise, then jointly.

    Parameters
    ----------
    pi_record : record
        Low-frequency experiment for step 1 (e.g. ``v = 10 sin(2 pi t) + 10``).
        A record is anything with ``label``, ``v`` and ``y`` (e.g.
        :class:`harness.identify.data.MeasuredRecord`), sampled at ``h`` from rest.
    tf_record : record
        Mixed-frequency experiment for step 2 (e.g. 5/40/80 Hz).
    creep_records : sequence of record
        Experiments for step 3, one creep row each (the same record may serve
        several steps).  Every distinct record enters the joint refinement.
    h : float
        Sample period [s].
    m : int
        Number of play operators (1..16).
    v_max : float, optional
        Threshold scale [V]; default ``max |v|`` of ``pi_record``.
    delay : int
        Extra input delay of ``G`` [samples] (``tf.delay``), not fitted.
    holdout : float
        Fraction of each record held out at its end, in [0, 0.9].
    max_evaluations : int
        Most evaluations of one local search (of each start, and of the joint
        refinement); a guard, the search stops by a rule relative to the data.
    progress : callable, optional
        Called with one line of text per start and stage.
    hammerstein : bool
        Also fit the Hammerstein model (no creep) for paper Tables 2-3 (the
        result's ``hammerstein`` is None without it).

    Returns
    -------
    IdentificationResult
        With :attr:`~IdentificationResult.undetermined` naming any parameter the
        records do not determine (the result is then not fit for export).

    Raises
    ------
    IdentificationInputError
        A record is malformed or too short for the split, or labels collide.
    IdentificationFitError
        The best search stopped at ``max_evaluations`` before converging.
    ValueError
        An argument is out of range.
    """
    t_start = _time.perf_counter()
    creep_records = list(creep_records)
    if not creep_records:
        raise ValueError("need at least one creep record")
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"h must be a finite number > 0, got {h!r}")
    m = int(m)
    if not 1 <= m <= 16:
        raise ValueError(f"m must be in 1..16, got {m}")
    delay = int(delay)
    if not 0 <= delay <= 8:
        raise ValueError(f"delay must be in 0..8 samples, got {delay}")
    holdout = float(holdout)
    if not 0.0 <= holdout <= 0.9:
        raise ValueError(f"holdout must be in [0, 0.9], got {holdout!r}")
    max_evaluations = int(max_evaluations)
    if max_evaluations < 1:
        raise ValueError(f"max_evaluations must be >= 1, got {max_evaluations}")
    if v_max is None:
        v_max = float(np.max(np.abs(_finite(f"{pi_record.label}: v", pi_record.v))))
    v_max = float(v_max)
    if not (math.isfinite(v_max) and v_max > 0):
        raise ValueError(f"v_max must be a finite number > 0 V, got {v_max!r}")

    distinct = _label_set(pi_record, tf_record, creep_records)
    prepared = {r.label: _Prepared(r, m, v_max, holdout) for r in distinct}
    p_pi, p_tf = prepared[pi_record.label], prepared[tf_record.label]
    p_creep = [prepared[r.label] for r in creep_records]
    records = list(prepared.values())

    say = progress if progress is not None else (lambda line: None)

    # stepwise: every step fitted to the measured y (paper section 3); a report and a start
    w, step1 = _step_pi(p_pi)
    g2, step2 = _step_g(p_tf, w, delay)
    step3, stepwise = [], None
    for rec in p_creep:
        if g2 is None:
            step3.append(StepFit("3 creep", (rec.label,), (), math.nan, math.nan, rec.n_fit,
                                 "not fitted: step 2 gave no usable G"))
            continue
        x = g_filter(rec.design[:rec.n_fit] @ w, *g2, delay)
        step3.append(_fit_creep(x, rec.y_fit, h, rec.label, "3 creep"))
    if g2 is not None:
        k_c0 = float(np.median([s.value("creep.k_c") for s in step3]))
        alpha0 = float(np.median([s.value("creep.alpha") for s in step3]))
        weights = (float(w[0]), 0.0) + tuple(float(x) for x in w[1:])
        if k_c0 > 0:
            stepwise = CoupledModel(weights, v_max, *g2, k_c0, alpha0, h, delay).normalized()
    say(f"stepwise (paper section 3): "
        + ("done" if stepwise is not None else f"no usable model ({step2.note})"))

    # the search by variable projection, then the joint refinement of everything
    designs = [r.design for r in records]
    ys = [r.y for r in records]
    n_fits = [r.n_fit for r in records]
    coupled = ReducedProblem(designs, ys, n_fits, h, delay, creep=True)
    search = fit_multistart(coupled, _starts(stepwise, creep=True),
                            max_evaluations=max_evaluations, progress=say, label="coupled model")
    _check_converged(search, max_evaluations, "coupled model")
    model0 = _model_of(search.best, v_max, h, delay, creep=True)
    model, joint, _, cov = _refine(records, model0, True, m, h, delay, max_evaluations)
    say(f"joint refinement: rms {joint.e_rms * 1e3:.4g} nm on the fit windows")
    undetermined = undetermined_parameters(coupled, search.best, v_max)

    # the Hammerstein model (no creep) on the same data, for paper Tables 2-3
    hammer, hfits = None, ()
    if hammerstein:
        plain = ReducedProblem(designs, ys, n_fits, h, delay, creep=False)
        hsearch = fit_multistart(plain, _starts(stepwise, creep=False),
                                 max_evaluations=max_evaluations, progress=say,
                                 label="Hammerstein")
        _check_converged(hsearch, max_evaluations, "Hammerstein model")
        hammer0 = _model_of(hsearch.best, v_max, h, delay, creep=False)
        hammer, hfit, _, _ = _refine(records, hammer0, False, m, h, delay, max_evaluations)
        hfits = (hfit,)

    # paper Table 1: one creep row per creep record, with the joint PI and G
    rows = []
    w_joint = _design_weights(model)
    for rec in p_creep:
        x = g_filter(rec.design[:rec.n_fit] @ w_joint, model.a1, model.a2, model.b1, model.b2,
                     delay)
        rows.append(_fit_creep(x, rec.y_fit, h, rec.label, "creep row"))

    # paper Tables 2-3 on the held-out samples
    held = []
    if holdout > 0:
        for rec in records:
            k = rec.n_fit
            y = rec.y[k:]
            yc = model._output(rec.design @ w_joint)[k:]
            ec, rc = _metrics(y, yc)
            eh = rh = math.nan
            if hammer is not None:
                eh, rh = _metrics(y, hammer._output(rec.design @ _design_weights(hammer))[k:])
            held.append(HeldOutFit(rec.label, eh, rh, ec, rc, int(y.size)))

    estimates = tuple(_ordered(joint.parameters, _derived(model, cov, m)))
    return IdentificationResult(
        model=model, stepwise=stepwise, hammerstein=hammer,
        steps=(step1, step2, *step3, joint, *hfits), creep_rows=tuple(rows), held_out=tuple(held),
        holdout=holdout, joint=estimates, search=search, undetermined=tuple(undetermined),
        elapsed_s=_time.perf_counter() - t_start)


def _ordered(fitted, derived):
    """The table's order: PI weights, tf.a1 .. tf.b2, creep.alpha, then poles, zero, gain."""
    fitted, derived = list(fitted), list(derived)
    alpha = [p for p in fitted if p.name == "creep.alpha"]
    b2 = [p for p in derived if p.name == "tf.b2"]
    return ([p for p in fitted if p.name != "creep.alpha"] + b2 + alpha
            + [p for p in derived if p.name != "tf.b2"])


def _starts(stepwise, creep):
    """Starts of the search: the default grid, then the stepwise result if it has real poles."""
    grid = DEFAULT_STARTS if creep else tuple(dict.fromkeys((p, 0.0) for p, _ in DEFAULT_STARTS))
    starts = [Theta(math.log(1.0 - p1), START_FAST_POLE, START_RHO, a if creep else 0.0)
              for p1, a in grid]
    if stepwise is not None:
        th = theta_from_g(stepwise.a1, stepwise.a2, stepwise.b1, stepwise.b2,
                          stepwise.alpha if creep else 0.0)
        if th is not None:
            starts.append(th)
    return starts


def _check_converged(search, max_evaluations, what):
    best = search.best
    if not best.converged:
        raise IdentificationFitError(
            f"the search of the {what} stopped at its limit of {max_evaluations} evaluations per "
            f"start before converging (rms {best.rms * 1e3:.4g} nm after {best.evaluations} "
            f"evaluations); rerun with --max-evaluations {4 * max_evaluations}")


def _model_of(fit, v_max, h, delay, creep):
    """The normalised :class:`CoupledModel` of a search's result."""
    a1, a2, b1, b2 = fit.theta.g()
    w = fit.weights
    weights = (float(w[0]), 0.0) + tuple(float(x) for x in w[1:])
    return CoupledModel(weights, float(v_max), a1, a2, b1, b2, 1.0,
                        fit.theta.alpha if creep else 0.0, h, delay, creep)


#: Standard errors above which a parameter counts as undetermined (with a noise of at least
#: SIGMA_FLOOR): (name, index in theta, limit, the record that would determine it).
_THETA_LIMITS = (
    ("slow pole", 0, 0.25,
     "the records do not show the slow settling of G (relative standard error of 1 - p1); add a "
     "longer record with a step or a low-frequency input (e.g. 10 s of a 1 Hz sine)"),
    ("fast pole", 1, 0.05,
     "the records do not excite G's fast dynamics; add a record with content between 20 and "
     "100 Hz (e.g. the 5/40/80 Hz multi-sine as --tf-data)"),
    ("zero", 2, 0.05,
     "the records do not separate G's zero from its slow pole (relative standard error of "
     "1 - zero); add a longer record with a step or a low-frequency input"),
    ("creep.alpha", 3, 0.005,
     "the records are too short to show the creep; add a longer record (e.g. 10 s at 1 Hz as "
     "--creep-data)"),
)
#: A PI weight is undetermined when its standard error exceeds this fraction of the static gain.
_WEIGHT_LIMIT = 0.05


def _unit_std_errors(jac):
    """``sqrt(diag((J^T J)^-1))``, infinite along directions the Jacobian does not see.

    By the SVD of ``J`` with scaled columns: a singular value below 1e-10 of the
    largest is a direction the data do not determine, and every parameter with a
    share in it (a component above 1e-6) gets an infinite standard error (a
    pseudo-inverse would quietly report a finite one).
    """
    norms = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    scale = np.where(norms > 0, norms, 1.0)
    _, sv, vt = np.linalg.svd(jac / scale, full_matrices=False)
    blind = sv <= 1e-10 * sv[0]
    inv = np.where(blind, 0.0, 1.0 / np.where(blind, 1.0, sv))
    var = (vt.T ** 2) @ (inv ** 2)
    unseen = np.any(np.abs(vt[blind]) > 1e-6, axis=0) | (norms == 0)
    return np.where(unseen, np.inf, np.sqrt(var) / scale)


def undetermined_parameters(problem, fit, v_max):
    """The parameters the records do not determine, with what would (a list of Undetermined).

    Standard errors come from the Jacobian of the search's residual at its result,
    ``s^2 (J^T J)^-1`` with ``s`` the residual's rms or :data:`SIGMA_FLOOR`, whichever
    is larger (noise-free records must determine the model robustly, not only
    because they carry no noise).  The limits are far above what usable records
    give (README, "Identification"): they catch records that miss a block, not
    records that are merely short.

    Parameters
    ----------
    problem : harness.identify.varpro.ReducedProblem
    fit : harness.identify.varpro.LocalFit
    v_max : float
        Threshold scale [V] (for the message about the PI weights).

    Returns
    -------
    list of Undetermined
    """
    th = fit.theta
    x = [th.q1, th.p2, th.rho, th.alpha] if problem.creep else [th.q1, th.p2, th.rho]
    se = max(fit.rms, SIGMA_FLOOR) * _unit_std_errors(problem.full_jacobian(x))
    m = problem.m
    out = []
    gain = max(float(fit.weights[0]), 1e-300)
    thresholds = pi_thresholds(m, v_max)
    for j in range(1, m):
        if se[j] > _WEIGHT_LIMIT * gain:
            r = thresholds[j]
            out.append(Undetermined(
                f"pi.w[{j + 1}]", float(se[j]), _WEIGHT_LIMIT * gain,
                f"the records do not move play operator {j + 1} (threshold r_{j + 1} = {r:.3g} V "
                f"of v_max = {v_max:g} V) on its own; record voltage swings over the whole "
                f"range (e.g. 0 to {v_max:g} V at 1 Hz as --pi-data), or lower --operators"))
    for name, i, limit, remedy in _THETA_LIMITS:
        if i < len(x) and se[m + i] > limit:
            out.append(Undetermined(name, float(se[m + i]), limit, remedy))
    return out
