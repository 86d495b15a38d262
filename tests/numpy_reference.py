"""Independent NumPy reference of the plant model and the controller pieces, written from docs/model.md.

Nothing here calls or transcribes the C core: it is the textbook form of the
equations in docs/model.md, plant and controller, favouring obviousness over speed.

Timing convention (docs/model.md, plant, piezo_plant.h): at sample k the plant
shows u(k-1), x(k), y(k); applying v(k) gives u(k) = P[v](k) and
x(k+1) = -a1 x(k) - a2 x(k-1) + b1 u(k-n) + b2 u(k-1-n) (n = extra delay).
"""
from __future__ import annotations

import numpy as np

# docs/model.md, plant; docs/fmus.md defaults, typed from the document.
DOC_DEFAULTS = {
    "pi.m": 9, "pi.v_max": 20.0, "pi.w0": 0.3344,
    "pi.w": [0.0714, 0.0322, 0.0072, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    "tf.a1": -1.3767, "tf.a2": 0.3816, "tf.b1": 0.5954, "tf.b2": -0.5907,
    "tf.delay": 0, "creep.enabled": True, "creep.k_c": 1.0463, "creep.alpha": 0.0002,
    "h": 0.0005,
}

# The design's start values of the controller's own parameters: the robust update (docs/model.md,
# adaptation: excitation 3 x the measured noise, 0.05 s after it, variance bound 0.004, the loop's
# initial covariance 0.01) with forgetting 0.99, trace bound 100, the candidates' initial
# covariance scale 1, integral action 0.01, the observer pole 0.5, mv.lambda_u 0; the drop-in timing (v published at
# the end of the step that sampled the inputs: no direct feedthrough, the loop delay detected);
# voltage limits on at +-150 V (the paper's amplifier range; every paper scenario stays below
# 62 V); the divergence monitor at 1 um for 200 samples; the estimates' admissible set (the zero
# of B at 0.5 or above, A's poles in the hull of real poles in [0, 1), b1 and the static gain
# within the supervision's sup.gain_min .. sup.gain_max, 0.25 .. 4, times the nominal's) and the
# fallback at twice the nominal model's squared errors over 0.5 s.
CONTROLLER_DOC_DEFAULTS = {
    "mv.delay": -1, "mv.feedthrough": False, "mv.hold_inputs": False, "mv.lambda_u": 0.0,
    "mv.observer": 0.5, "mv.integral": 0.01, "rls.enabled": True,
    "rls.forgetting": 0.99, "rls.p0": 1.0, "rls.trace_max": 100.0, "rls.robust": True,
    "rls.excitation": 3.0, "rls.excitation_time": 0.05, "rls.variance_max": 0.004, "rls.p0_loop": 0.01,
    "sat.enabled": True, "sat.v_min": -150.0, "sat.v_max": 150.0, "monitor.pred_error_max": 1.0,
    "monitor.divergence_samples": 200,
    # the estimates' guarantees (docs/model.md): the admissible set and the fallback
    "rls.zero_min": 0.75, "rls.pole_min": 0.0, "rls.fallback_ratio": 2.0, "rls.fallback_window": 0.5,
}
# The paper's law: its update on every sample with the tuning measured for it, no integral
# action, the observer pole measured for it (docs/model.md, adaptation); the robust update's
# parameters are then unused.
PAPER_LAW = {"rls.robust": False, "rls.forgetting": 0.995, "rls.trace_max": 100.0, "mv.integral": 0.0,
             "mv.observer": 0.4}

# Table 1 rows (f: k_c, alpha)
TABLE1 = {1: (1.0463, 0.0002), 10: (1.0497, -0.0085), 20: (1.0386, -0.0077),
          50: (1.0481, -0.0098), 100: (1.0327, -0.0059), "5/40/80": (1.0172, -0.0023)}


# ---------------------------------------------------------------- PI model

def _past(x):
    """x[i] of a sample sequence, 0.0 before its first sample (the loop starts from rest)."""
    return lambda i: x[i] if i >= 0 else 0.0

def pi_thresholds(m: int, v_max: float) -> np.ndarray:
    """r_j = (j-1)/m * v_max, j = 1..m (eq 5)."""
    return np.arange(m, dtype=float) / m * v_max


def play(v, r: float, z0: float = 0.0) -> np.ndarray:
    """One play operator, eq 3, as a plain loop."""
    z = np.empty(len(v))
    prev = z0
    for k, vk in enumerate(v):
        prev = max(vk - r, min(vk + r, prev))
        z[k] = prev
    return z


def pi_forward(v, w0: float, w, r, z0=None):
    """u(k) = w0 v(k) + sum_j w_j z_{r_j}(k). Returns (u, final play states)."""
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    r = np.asarray(r, dtype=float)
    z0 = np.zeros(len(w)) if z0 is None else np.asarray(z0, dtype=float)
    Z = np.column_stack([play(v, r[j], z0[j]) for j in range(len(w))]) if len(w) else np.zeros((len(v), 0))
    u = w0 * v + Z @ w
    zf = Z[-1].copy() if len(v) else z0.copy()
    return u, zf


def pi_inverse_params(w0: float, w, r):
    """Corrected eqs 25-27 (docs/model.md, controller): returns (w0', w', r')."""
    w = np.asarray(w, dtype=float)
    r = np.asarray(r, dtype=float)
    n = len(w)
    s_incl = np.array([w0 + w[: i + 1].sum() for i in range(n)])   # w0 + sum_{j<=i} w_j
    s_excl = np.array([w0 + w[:i].sum() for i in range(n)])        # w0 + sum_{j<i} w_j
    w0_inv = 1.0 / w0
    w_inv = -w / (s_incl * s_excl)
    r_inv = np.array([w0 * r[i] + sum(w[j] * (r[i] - r[j]) for j in range(i + 1)) for i in range(n)])
    return w0_inv, w_inv, r_inv


def pi_inverse_initial_states(w0: float, w, z):
    """Corrected eq 28: z'_i(0) = (w0 + sum_{j<=i} w_j) z_i(0) + sum_{j>i} w_j z_j(0)."""
    w = np.asarray(w, dtype=float)
    z = np.asarray(z, dtype=float)
    n = len(w)
    return np.array([(w0 + w[: i + 1].sum()) * z[i] + (w[i + 1:] * z[i + 1:]).sum() for i in range(n)])


def pi_inverse(u, w0: float, w, r, z0=None):
    """v = P^-1[u] as the PI model with the inverse parameters; z0: forward play states."""
    w0i, wi, ri = pi_inverse_params(w0, w, r)
    zi0 = None if z0 is None else pi_inverse_initial_states(w0, w, z0)
    v, _ = pi_forward(u, w0i, wi, ri, zi0)
    return v


# ---------------------------------------------------------------- G(z)
def tf_filter(u, a1, a2, b1, b2, delay: int = 0) -> np.ndarray:
    """Return x(0..N) for inputs u(0..N-1):
    x(k+1) = -a1 x(k) - a2 x(k-1) + b1 u(k-delay) + b2 u(k-1-delay), rest before k = 0."""
    u = np.asarray(u, dtype=float)
    n = len(u)
    x = np.zeros(n + 1)
    def U(i):
        return u[i] if 0 <= i < n else 0.0
    for k in range(n):
        xk = x[k]
        xkm1 = x[k - 1] if k >= 1 else 0.0
        x[k + 1] = -a1 * xk - a2 * xkm1 + b1 * U(k - delay) + b2 * U(k - 1 - delay)
    return x


# ---------------------------------------------------------------- G-L creep
def gl_weights(alpha: float, n: int) -> np.ndarray:
    """w_0 = 1, w_j = (1 - (alpha+1)/j) w_{j-1} (eq 14)."""
    j = np.arange(1, n, dtype=float)
    return np.concatenate([[1.0], np.cumprod(1.0 - (alpha + 1.0) / j)])[:n]


def gl_exact(x, alpha: float, gain: float = 1.0) -> np.ndarray:
    """y(k) = gain sum_{j=0..k} w_j x(k-j), full memory from k = 0 (direct convolution)."""
    x = np.asarray(x, dtype=float)
    w = gl_weights(alpha, len(x))
    return gain * np.convolve(x, w)[: len(x)]


def gl_exact_fft(x, alpha: float, gain: float = 1.0) -> np.ndarray:
    """Same as gl_exact via an FFT convolution (for long runs; rounding ~1e-12 of max|x|)."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    w = gl_weights(alpha, n)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    y = np.fft.irfft(np.fft.rfft(x, size) * np.fft.rfft(w, size), size)[:n]
    return gain * y


# ---------------------------------------------------------------- plant
def plant_params(**over) -> dict:
    p = dict(DOC_DEFAULTS)
    p["pi.w"] = list(p["pi.w"])
    p.update(over)
    return p


def plant_simulate(v, params: dict | None = None) -> dict:
    """Reference plant from rest at k = 0.

    Returns a dict of arrays aligned like harness.binding.core.Plant.simulate: row k holds
    u(k-1) (u of the last applied voltage, 0 at k = 0), x(k) and y(k).
    """
    p = plant_params() if params is None else params
    v = np.asarray(v, dtype=float)
    m = p["pi.m"]
    w = np.asarray(p["pi.w"][:m], dtype=float)
    r = pi_thresholds(m, p["pi.v_max"])
    u, _ = pi_forward(v, p["pi.w0"], w, r)
    x = tf_filter(u, p["tf.a1"], p["tf.a2"], p["tf.b1"], p["tf.b2"], p["tf.delay"])[: len(v)]
    if p["creep.enabled"]:
        gain = p["creep.k_c"] * p["h"] ** (-p["creep.alpha"])
        y = gl_exact(x, p["creep.alpha"], gain)
    else:
        y = x.copy()
    u_row = np.concatenate([[0.0], u[:-1]])
    return {"u": u_row, "x": x, "y": y}


def validation_inputs(h: float = 0.0005, duration: float = 10.0) -> dict:
    """docs/model.md, scenarios model-validation voltages, t = k h."""
    t = np.arange(int(round(duration / h))) * h
    out = {f"{f} Hz": 10 * np.sin(2 * np.pi * f * t) + 10 for f in (1, 10, 20, 50, 100)}
    out["5/40/80 Hz"] = 6 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t)
                             + np.sin(2 * np.pi * 80 * t)) + 18
    return out


def tracking_references():
    """docs/model.md, scenarios tracking references y_d(t) [um] as functions of t."""
    def tone(f):
        return lambda t: 10 * np.sin(2 * np.pi * f * t)

    def mix(fs):
        return lambda t: 10 * sum(np.sin(2 * np.pi * f * t) for f in fs)

    return {"1 Hz": tone(1), "5 Hz": tone(5), "10 Hz": tone(10), "20 Hz": tone(20),
            "1/5/10 Hz": mix((1, 5, 10)), "1/10/20 Hz": mix((1, 10, 20))}


# ---------------------------------------------------------------- controller pieces
def diophantine(a, d: int, t: float = 0.0):
    """T = A(z^-1) E(z^-1) + z^-d Gd(z^-1), T = 1 - t z^-1, by long division of T by A (A
    monic, powers of z^-1). Returns (E[0..d-1], Gd[0..len(A)-2])."""
    a = np.asarray(a, dtype=float)
    rem = np.zeros(d + len(a))
    rem[0] = 1.0
    rem[1] = -t
    e = np.zeros(d)
    for i in range(d):
        e[i] = rem[i]
        rem[i:i + len(a)] -= e[i] * a
    g = rem[d:d + len(a) - 1]
    return e, g


def mv_controller(y_ref, y_meas, theta, d: int, lambda_u: float = 0.0, observer: float = 0.0,
                  integral: float = 0.0):
    """Minimum-variance law with fixed model theta = (a1, a2, b1, b2) (docs/model.md, controller):
    with the observer polynomial T = 1 - observer z^-1, predictor
    T y(k+d) = Gd y(k) + F q(k), F = B E; q(k) chosen so the prediction equals
    T y_ref(k) = y_ref(k) - observer y_ref(k-1). With the control weighting lambda_u of the
    generalised MV law, q(k) minimises J(q) = (T y(k+d|k) - T y_ref(k))^2 + lambda_u q^2,
    solved here as the least-squares problem [f0; sqrt(lambda_u)] q ~ [T y_ref - rest; 0]
    (rest: the prediction without the f0 q(k) term), not by a closed-form transcription.

    Integral action (docs/model.md, controller): the law tracks r(k) = y_ref(k) + z(k),
    z(k) = z(k-1) + integral (y_ref(k-d) - y_meas(k)) from k = d on (y_ref(k-d) is y_d(k),
    the displacement wanted at the measurement's sample), z = 0 before."""
    a1, a2, b1, b2 = theta
    e, g = diophantine([1.0, a1, a2], d, observer)
    f = np.convolve([b1, b2], e)                  # F = B E, deg d
    n = len(y_ref)
    q = np.zeros(n)
    z = 0.0
    r = np.zeros(n)
    design = np.array([[f[0]], [np.sqrt(lambda_u)]])
    for k in range(n):
        if integral > 0.0 and k >= d:
            z = z + integral * (y_ref[k - d] - y_meas[k])
        r[k] = y_ref[k] + z if integral > 0.0 else y_ref[k]
        rest = g[0] * y_meas[k] + (g[1] * y_meas[k - 1] if k >= 1 else 0.0)
        rest += sum(f[i] * q[k - i] for i in range(1, len(f)) if k - i >= 0)
        t_ref = r[k] - (observer * r[k - 1] if k >= 1 else 0.0)
        sol, *_ = np.linalg.lstsq(design, np.array([t_ref - rest, 0.0]), rcond=None)
        q[k] = sol[0]
    return q


def controller_feedforward(q, params: dict | None = None):
    """v = P^-1( G-L_{-alpha, h^alpha / k_c}(q) ): inverse creep then inverse PI, from rest."""
    p = plant_params() if params is None else params
    m = p["pi.m"]
    w = np.asarray(p["pi.w"][:m], dtype=float)
    r = pi_thresholds(m, p["pi.v_max"])
    alpha, k_c, h = p["creep.alpha"], p["creep.k_c"], p["h"]
    rr = gl_exact(q, -alpha, h ** alpha / k_c)
    return pi_inverse(rr, p["pi.w0"], w, r)


# ---------------------------------------------------------------- RLS (indirect self-tuning)
# docs/model.md, controller ("Adaptation"): RLS with forgetting estimates theta = [a1, a2, b1, b2] of
# y(k) = -a1 y(k-1) - a2 y(k-2) + b1 q(k-d) + b2 q(k-d-1), with a bound on trace(P) and a
# projection that keeps b1 positive and the zero -b2/b1 of B inside the radius 0.999. The
# documentation says only "b1 > 0"; the floor 1e-3 x nominal b1 is the documented constant of
# piezo_controller.c (B1_FLOOR_FRACTION), taken as part of the spec here.
RLS_B1_FLOOR_FRACTION = 1e-3
RLS_ZERO_RADIUS_MAX = 0.999
RLS_A_STABILITY_MARGIN = 1e-4   # stable estimated A, with margin (README, controller)


def rls_project(theta, b1_nominal: float) -> np.ndarray:
    """Projection: the estimated A inside the stability (Jury) triangle shrunk by
    m = 1e-4 (A(1) >= m, A(-1) >= m, |a2| <= 1 - m: a2 clipped first, then a1), then
    b1 >= 1e-3 b1_nominal (docs/model.md, controller) and |b2| <= 0.999 b1."""
    th = np.array(theta, dtype=float)
    m = RLS_A_STABILITY_MARGIN
    th[1] = float(np.clip(th[1], -1.0 + m, 1.0 - m))
    th[0] = float(np.clip(th[0], -(1.0 + th[1] - m), 1.0 + th[1] - m))
    th[2] = max(th[2], RLS_B1_FLOOR_FRACTION * b1_nominal)
    th[3] = float(np.clip(th[3], -RLS_ZERO_RADIUS_MAX * th[2], RLS_ZERO_RADIUS_MAX * th[2]))
    return th


def _recorded(q, y):
    """Recorded data (q(k), y(k)) as arrays, and their pasts Q(i), Y(i) (0.0 before k = 0)."""
    q = np.asarray(q, dtype=float)
    y = np.asarray(y, dtype=float)
    return q, y, _past(q), _past(y)


def rls_step(theta, P, phi, e, lam: float, trace_max: float):
    """One exponentially weighted RLS update with the trace bound, from the a-priori error e:

        K      = P phi / (lambda + phi^T P phi)
        theta  = theta + K e,   P = (P - K phi^T P) / lambda
        if trace(P) > trace_max: P = P trace_max / trace(P)

    Returns theta, P and whether the trace bound acted."""
    K = P @ phi / (lam + phi @ P @ phi)
    theta = theta + K * e
    P = (P - np.outer(K, phi @ P)) / lam
    tr = np.trace(P)
    if tr > trace_max:
        return theta, P * (trace_max / tr), True
    return theta, P, False


def rls_reference(q, y, d: int, forgetting: float, p0: float, trace_max: float, theta0,
                  skip=None) -> dict:
    """Textbook exponentially weighted RLS, run over recorded data (q(k), y(k)), k = 0..N-1,
    everything zero before k = 0:

        phi(k) = [-y(k-1), -y(k-2), q(k-d), q(k-d-1)]
        e(k)   = y(k) - phi^T theta(k-1)                      (a-priori prediction error)
        K      = P phi / (lambda + phi^T P phi)
        theta  = theta + K e,   P = (P - K phi^T P) / lambda
        if trace(P) > trace_max: P = P trace_max / trace(P)
        theta  = projection(theta)

    starting from theta(-1) = theta0 (the nominal model) and P = p0 I. skip[k] = True leaves
    theta and P untouched at sample k (e(k) is still reported). Returns a dict of arrays:
    theta (N, 4) after sample k, P (N, 4, 4) after sample k, e (N,), trace_scaled (N, bool:
    the trace bound acted at k)."""
    q, y, Q, Y = _recorded(q, y)
    n = len(y)
    lam = float(forgetting)

    theta = np.array(theta0, dtype=float)
    b1_nominal = theta[2]
    P = p0 * np.eye(4)
    out = {"theta": np.zeros((n, 4)), "P": np.zeros((n, 4, 4)), "e": np.zeros(n),
           "trace_scaled": np.zeros(n, dtype=bool)}
    for k in range(n):
        phi = np.array([-Y(k - 1), -Y(k - 2), Q(k - d), Q(k - d - 1)])
        e = y[k] - phi @ theta
        if skip is None or not skip[k]:
            theta, P, out["trace_scaled"][k] = rls_step(theta, P, phi, e, lam, trace_max)
            theta = rls_project(theta, b1_nominal)
        out["theta"][k] = theta
        out["P"][k] = P
        out["e"][k] = e
    return out


# ---------------------------------------------------------------- the robust update
# docs/model.md, controller ("Adaptation", the robust update): written from the text.
NOISE_STEP = 1.0 + 1.0 / 64.0     # the median tracker's factor per sample
NOISE_SCALE = 1.0 / (0.6744897501960817 * np.sqrt(2.0))   # median |delta| of white noise -> its rms
NOISE_FLOOR = 1e-9
OFFSET_GAIN = 0.01


def measured_noise(x) -> np.ndarray:
    """The measured noise of a signal x(0..N-1) (x(-1) = 0): m(k+1) from m(k) and
    |x(k) - x(k-1)| s (s the scale of white noise): 0 until the first difference above the
    floor, which it takes; then m (1 + 1/64) when that difference is above m, m / (1 + 1/64)
    when not, never below the floor 1e-9 um. Returns m(1..N) (the value after each sample)."""
    x = np.asarray(x, dtype=float)
    out = np.zeros(len(x))
    m, prev = 0.0, 0.0
    for k, v in enumerate(x):
        delta = abs(v - prev) * NOISE_SCALE
        prev = v
        if m == 0.0:
            m = delta if delta > NOISE_FLOOR else 0.0
        else:
            m = m * NOISE_STEP if delta > m else m / NOISE_STEP
            m = max(m, NOISE_FLOOR)
        out[k] = m
    return out


def admissible_rows(theta0, zero_min: float, pole_min: float, gain_min: float = 0.25, gain_max: float = 4.0,
                    margin: float = 1e-4):
    """The admissible set of docs/model.md ("Estimates with guarantees") around the nominal model
    theta0 as rows C theta <= d: A's poles in the hull of real poles in [pole_min, 1) (A(1) >= m,
    A at pole_min >= 0, the chord from the double pole at pole_min to the one at 1), the zero
    -b2/b1 in [zero_min, 0.999], b1 and B(1)/A(1) within [gain_min, gain_max] times the
    nominal's (the supervision's sup.gain_min, sup.gain_max)."""
    a1, a2, b1, b2 = theta0
    gain = (b1 + b2) / (1.0 + a1 + a2)
    p, z, m = pole_min, zero_min, margin
    C = np.array([[-1.0, -1.0, 0.0, 0.0], [-p, -1.0, 0.0, 0.0], [(1.0 + p) / 2.0, 1.0, 0.0, 0.0],
                  [0.0, 0.0, -0.999, -1.0], [0.0, 0.0, z, 1.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, -1.0, 0.0],
                  [-gain_max * gain, -gain_max * gain, 1.0, 1.0], [gain_min * gain, gain_min * gain, -1.0, -1.0]])
    d = np.array([1.0 - m, p * p, -p - m, 0.0, 0.0, gain_max * b1, -gain_min * b1, gain_max * gain,
                  -gain_min * gain])
    return C, d


def admissible_projection(theta, P, C, d, nominal, sweeps: int = 8, p0_loop: float = 0.01):
    """Into C theta <= d: sweeps of projections onto each violated half-space in the metric of
    P^-1 (theta - P c (c^T theta - d) / c^T P c), then the step towards the nominal model that
    ends inside (theta = n + s (theta - n), s the least slack / (slack + excess); rounding may
    leave that on the wrong side of the boundary: s shrunk by 1e-12, 1e-9, 1e-6, 1e-3 of itself in
    turn), then the nominal model itself if still outside. ``(theta, P)``: P is p0_loop I when the
    nominal model was taken (``p0_loop``), else the P given."""
    if np.all(C @ theta <= d):
        return theta, P
    th = np.array(theta, dtype=float)
    for _ in range(sweeps):
        moved = False
        for i in range(len(d)):
            excess = C[i] @ th - d[i]
            if excess > 0.0:
                pc = P @ C[i]
                cpc = C[i] @ pc
                if not (cpc > 0.0 and np.isfinite(cpc)):
                    pc, cpc = C[i], C[i] @ C[i]
                th = th - pc * (excess / cpc)
                moved = True
        if not moved:
            break
    outside = C @ th - d > 0.0
    if np.any(outside):
        slack = d - C @ nominal
        excess = C @ th - d
        s = min(1.0, float(np.min(slack[outside] / (slack[outside] + excess[outside]))))
        out = th
        th = nominal + s * (out - nominal)
        for shrink in (1e-12, 1e-9, 1e-6, 1e-3):
            if not np.any(C @ th - d > 0.0):
                break
            th = nominal + (s - s * shrink) * (out - nominal)
        if np.any(C @ th - d > 0.0):
            th = np.array(nominal, dtype=float)
            P = p0_loop * np.eye(4)
    return th, P


#: the fallback's constants (piezo_controller.h): a jump beyond 5 times the largest change learned,
#: which fades over 2000 adapted samples; the prediction test beyond 3 times the measured noise
FALLBACK_JUMP_RATIO, FALLBACK_JUMP_MEMORY, FALLBACK_NOISE = 5.0, 2000.0, 3.0
#: the one-sample (ringing) test: beyond 5 times the prediction error's measured noise too
FALLBACK_RINGING_NOISE = 5.0


def rls_robust_reference(q, y, r, d: int, forgetting: float, p0_loop: float, trace_max: float,
                         variance_max: float, excitation: float, excitation_samples: int,
                         theta0, e_before=0.0, admissible=(0.5, 0.0, 0.25, 4.0), fallback=(2.0, 1000, 1.0),
                         probe_max=1.0, hold_same=4) -> dict:
    """The robust update over recorded data (q(k), y(k)) with the law's references r(k)
    (r(-1) = 0), from theta0 and P = p0_loop I, offset c = 0:

        excitation at k: |r(k-1) - line| > excitation * m_y(k), m_y the measured noise of y
                         before sample k, line the straight line through the last excitation
                         (its r, advanced by its r(j) - r(j-1) each sample since; a reference
                         with r(k-1) = r(k-2) stops the line there); the estimator
                         adapts at k and for excitation_samples samples after
        e(k) = y(k) - c - phi^T theta      (phi as rls_reference)
        adapting: the exponentially weighted RLS of rls_reference with
                  trace(P) <= min(trace_max, variance_max / m_e(k)^2), m_e the measured noise
                  of e before sample k (no bound from it while it is 0), then the projection
                  into the admissible set (admissible_rows of theta0 and admissible = (zero_min,
                  pole_min, gain_min, gain_max), admissible_projection)
        holding:  theta, P kept; c = c + 0.01 e(k), but while y(k) has equalled the samples before
                  it hold_same times in a row (a reading that may be stuck: c holds too; the
                  controller counts them in its supervision: None when that is off)
        too noisy: from sample 100, while 20 m_2 > 2 probe_max b1 (m_2 the measured noise of y's
                  second differences over sqrt 3 at the samples that are not excited, before
                  sample k; b1 of theta0), an excited
                  sample does not adapt (and c holds)
        fallback: while theta differs from theta0, with fallback = (ratio, N, pred_error_max):
                  S_a = l S_a + e^2, S_n = l S_n + e_n^2 (l = 1 - 1/N, e_n the nominal model's
                  a-priori error with the same c); S_a > ratio S_n + N (3 m_y)^2 (m_y before k),
                  or |e(k)| beyond pred_error_max and 5 m_e (m_e the measured noise of e before
                  k, from its first differences), outside a jump's answer (2 (d + 2) samples
                  from one |r(k-1) - r(k-2)| > pred_error_max), or
                  |r(k) - r(k-1)| beyond pred_error_max and 5 times the largest change
                  learned R (R = max(|r(k) - r(k-1)|, R (1 - 1/2000) when adapting) at every
                  sample): theta = theta0, P = p0_loop I, S_a = S_n = 0, R = the jump

    e_before is the prediction error of the sample before the first (0 from rest). Returns
    theta (N, 4), P (N, 4, 4), e (N,), c (N,) after each sample, adapting (N, bool: updated,
    or reset by a fallback) and fallback (N, int: 0, 1 a jump, 2 a prediction, 3 one beyond the bound)."""
    q, y, Q, Y = _recorded(q, y)
    r = np.asarray(r, dtype=float)
    n = len(y)
    lam = float(forgetting)

    theta = np.array(theta0, dtype=float)
    nominal = np.array(theta0, dtype=float)
    C, d_rows = admissible_rows(nominal, *admissible)
    ratio, window, pe_max = fallback
    lam_f = 1.0 - 1.0 / window
    s_a = s_n = learned = 0.0
    P = p0_loop * np.eye(4)
    c = 0.0
    m_y = m_e = m_2 = 0.0
    same = 0
    anchor, velocity, left = 0.0, 0.0, 0
    jump_left = 0
    e_prev = e_before
    out = {"theta": np.zeros((n, 4)), "P": np.zeros((n, 4, 4)), "e": np.zeros(n), "c": np.zeros(n),
           "adapting": np.zeros(n, dtype=bool), "fallback": np.zeros(n, dtype=int)}

    def track(m, delta):
        delta = abs(delta) * NOISE_SCALE
        if m == 0.0:
            return delta if delta > NOISE_FLOOR else 0.0
        m = m * NOISE_STEP if delta > m else m / NOISE_STEP
        return max(m, NOISE_FLOOR)

    for k in range(n):
        r1 = r[k - 1] if k >= 1 else 0.0
        r2 = r[k - 2] if k >= 2 else 0.0
        line = anchor + velocity
        event = abs(r1 - line) > excitation * m_y
        adapting = event or left > 0
        if event or r1 == r2:           # a reference that stops stops the line
            anchor, velocity = r1, r1 - r2
        else:
            anchor = line
        left = excitation_samples if event else max(left - 1, 0)
        m_y_before = m_y
        m_y = track(m_y, Y(k) - Y(k - 1))
        noisy = k >= 100 and 20.0 * m_2 > 2.0 * probe_max * nominal[2]
        jump_left = 2 * (d + 2) if abs(r1 - r2) > pe_max else max(jump_left - 1, 0)
        if not adapting:                # the sensor's noise, measured while the reference does not excite
            m_2 = track(m_2, (Y(k) - 2.0 * Y(k - 1) + Y(k - 2)) * 0.57735026918962576)
        same = same + 1 if k > 0 and y[k] == y[k - 1] else 0
        phi = np.array([-Y(k - 1), -Y(k - 2), Q(k - d), Q(k - d - 1)])
        e = y[k] - c - phi @ theta
        e_n = y[k] - c - phi @ nominal
        excited, adapting = adapting, adapting and not noisy
        if adapting:
            bound = trace_max if m_e == 0.0 else min(trace_max, variance_max / m_e ** 2)
            theta, P, _ = rls_step(theta, P, phi, e, lam, bound)
            theta, P = admissible_projection(theta, P, C, d_rows, nominal, p0_loop=p0_loop)
        elif not excited and (hold_same is None or same < hold_same):
            c = c + OFFSET_GAIN * e
        rate = abs(r[k] - r1)
        adapted = not np.array_equal(theta, nominal)
        reason = 0
        s_a_next, s_n_next = lam_f * s_a + e * e, lam_f * s_n + e_n * e_n
        if ratio > 0.0 and adapted and s_a_next > ratio * s_n_next + window * (FALLBACK_NOISE * m_y_before) ** 2:
            reason = 2
        if ratio > 0.0 and adapted and jump_left == 0 and abs(e) > max(pe_max, FALLBACK_RINGING_NOISE * m_e):
            reason = 3
        if adapted and rate > pe_max and rate > FALLBACK_JUMP_RATIO * learned:
            reason = 1
        if reason:
            theta, P = nominal.copy(), p0_loop * np.eye(4)
            s_a = s_n = 0.0
            learned = rate
        else:
            s_a, s_n = s_a_next, s_n_next
            learned = max(rate, learned * (1.0 - 1.0 / FALLBACK_JUMP_MEMORY) if adapting else learned)
        out["fallback"][k] = reason
        adapting = adapting or reason > 0
        m_e = track(m_e, e - e_prev)
        e_prev = e
        out["theta"][k], out["P"][k], out["e"][k], out["c"][k] = theta, P, e, c
        out["adapting"][k] = adapting
    return out
