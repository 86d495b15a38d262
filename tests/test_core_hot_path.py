"""The core's in-place step (piezo_plant_step, piezo_controller_step): bit-identical results
and the refusal guarantees, without copies of the whole state.

Reference for bit identity: a scalar Python transcription of the documented equations
(piezo_hysteresis.h, piezo_tf.h, piezo_creep.h, piezo_plant.h, piezo_controller.h), every
sum in the order the headers give it (the PI and creep sums in four lanes, the RLS with one
reciprocal). Python floats are IEEE doubles and Python's math module calls the same libm, so
the same operations in the same order give the same bits; the transcription reads only the
constants the core derives at init (thresholds, inverse weights, SOE nodes and gains), never
a state the step computes. What it pins is the documented arithmetic, not one compiler's
output: that order is what makes a run the same on every machine (baseline x86-64, no FMA
contraction, no -ffast-math reassociation), so a change to the step's arithmetic (a
reordered sum, a reciprocal instead of a division, a contracted multiply-add) fails here
until the headers and this transcription say the same.

Reference for the refusals: the struct's bytes before the refused call, and an untouched
twin that continues the run.
"""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from harness import core  # noqa: E402

H = 0.0005
MISMATCH = {"pi.w0": 0.36784, "pi.w[1]": 0.07854, "pi.w[2]": 0.03542, "pi.w[3]": 0.00792,
            "creep.k_c": 1.0497, "creep.alpha": -0.0085, "tf.a1": -1.442037,
            "tf.a2": 0.44641665, "tf.b1": 0.62517, "tf.b2": -0.620235,
            "sensor.resolution": 0.002, "sensor.noise_rms": 0.001, "sensor.seed": 7}


def raw_bytes(obj):
    return bytes(core.ffi.buffer(obj.raw))


# --------------------------------------------------------------------------- transcription
def play(v, r, z_prev):
    """eq 3, as piezo_hysteresis.c evaluates it: min with v + r first, then max with v - r."""
    upper, lower = v + r, v - r
    z = z_prev if z_prev < upper else upper
    return z if z > lower else lower


def lanes4(terms):
    """Four partial sums, term n into lane n mod 4 in increasing n, then
    (a0 + a1) + (a2 + a3): the order of the PI and creep sums (piezo_hysteresis.h,
    piezo_creep.h)."""
    a = [0.0, 0.0, 0.0, 0.0]
    for n, t in enumerate(terms):
        a[n % 4] += t
    return (a[0] + a[1]) + (a[2] + a[3])


class PIRef:
    """u = w0 v + sum_j w_j z_j, the sum in four lanes (eq 18 / eq 24 for the inverse)."""

    def __init__(self, raw):
        m = raw.m
        self.w0, self.w, self.r = raw.w0, list(raw.w)[:m], list(raw.r)[:m]
        self.z = list(raw.z)[:m]

    def step(self, v):
        terms = []
        for j in range(len(self.w)):
            self.z[j] = play(v, self.r[j], self.z[j])
            terms.append(self.w[j] * self.z[j])
        return self.w0 * v + lanes4(terms)


class TFRef:
    """x(k+1) = -a1 x(k) - a2 x(k-1) + b1 u(k-delay) + b2 u(k-1-delay), left to right."""

    def __init__(self, raw):
        self.a1, self.a2, self.b1, self.b2, self.delay = raw.a1, raw.a2, raw.b1, raw.b2, raw.delay
        self.x1 = self.x2 = 0.0
        self.u = [0.0] * (self.delay + 2)       # u(k), u(k-1), ...

    def step(self, u):
        self.u = [u] + self.u[:-1]
        x = -self.a1 * self.x1 - self.a2 * self.x2 + self.b1 * self.u[self.delay] \
            + self.b2 * self.u[self.delay + 1]
        self.x2, self.x1 = self.x1, x
        return x


class SOERef:
    """SOE G-L operator (piezo_creep.h): y = gain (x(k) + sum_{j=1..16} w_j x(k-j) + sum_i T_i),
    T_i = decay_i T_i + inject_i x(k-17) (inject_i = c_i e^{-17 s_i}); lane l sums the head
    terms j - 1 = l mod 4, then the tail terms i = l mod 4, and
    y = gain (x + ((a0 + a1) + (a2 + a3)))."""

    def __init__(self, raw):
        n = raw.n_terms
        self.gain, self.w = raw.gain, list(raw.w_head)
        self.decay, self.inject = list(raw.soe_decay)[:n], list(raw.soe_inject)[:n]
        self.s = [0.0] * n
        self.x = [0.0] * 17                     # x(k-1) .. x(k-17)

    def evaluate(self, x):
        """(y, next T, next past) without committing."""
        leaving = self.x[16]
        a = [0.0, 0.0, 0.0, 0.0]
        for j in range(1, 17):
            a[(j - 1) % 4] += self.w[j] * self.x[j - 1]
        s_next = []
        for i in range(len(self.decay)):
            s = self.decay[i] * self.s[i] + self.inject[i] * leaving
            s_next.append(s)
            a[i % 4] += s
        return self.gain * (x + ((a[0] + a[1]) + (a[2] + a[3]))), s_next, [x] + self.x[:16]

    def step(self, x):
        y, self.s, self.x = self.evaluate(x)
        return y


class PlantRef:
    """piezo_plant.h: u = P[v], x(k+1) = G, y(k+1) = creep(x), y_meas = quantize(y + noise)."""

    def __init__(self, plant, normal):
        raw = plant.raw
        self.pi, self.tf, self.creep = PIRef(raw.pi), TFRef(raw.tf), SOERef(raw.creep)
        self.res, self.noise = raw.sensor_resolution, raw.sensor_noise_rms
        self.normal = normal

    def step(self, v):
        u = self.pi.step(v)
        x = self.tf.step(u)
        y = self.creep.step(x)
        reading = y + self.noise * self.normal() if self.noise > 0 else y
        if self.res > 0:
            reading = self.res * math.floor(reading / self.res + 0.5)
        return u, x, y, reading


class ControllerRef:
    """piezo_controller.h/.c: RLS (sums over i = 0..3, one reciprocal of the denominator,
    1/lambda from init, the update (P phi)_i (P phi)_j / denom symmetric by itself),
    projection, Diophantine, MV law, inverse creep, inverse PI, saturation with
    back-calculation, monitor counts."""

    def __init__(self, ctrl):
        c = ctrl.raw
        self.d, self.lam_u = c.d, c.lambda_u
        self.rls, self.lam, self.trace_max = c.rls_enabled, c.forgetting, c.trace_max
        self.sat, self.v_min, self.v_max = c.sat_enabled, c.sat_v_min, c.sat_v_max
        self.theta, self.nominal = list(c.theta), list(c.theta_nominal)
        self.P = [[c.P[4 * i + j] for j in range(4)] for i in range(4)]
        self.y_prev = [0.0, 0.0]
        self.q_past = [0.0] * 11                # q(k-1), q(k-2), ...
        self.sat_hold = 0
        self.creep, self.inv, self.fwd = SOERef(c.inv_creep), PIRef(c.inv_pi), PIRef(c.fwd_pi)
        self.n_saturated = 0

    def project(self, th):
        m = 1e-4
        if th[1] > 1.0 - m:
            th[1] = 1.0 - m
        if th[1] < -1.0 + m:
            th[1] = -1.0 + m
        a1_max = 1.0 + th[1] - m
        if abs(th[0]) > a1_max:
            th[0] = math.copysign(a1_max, th[0])
        floor_b1 = 1e-3 * self.nominal[2]
        if th[2] < floor_b1:
            th[2] = floor_b1
        if abs(th[3]) > 0.999 * th[2]:
            th[3] = math.copysign(0.999 * th[2], th[3])

    def rls_update(self, y):
        phi = [-self.y_prev[0], -self.y_prev[1], self.q_past[self.d - 1], self.q_past[self.d]]
        e = y
        for i in range(4):
            e -= phi[i] * self.theta[i]
        if not self.rls or self.sat_hold > 0:
            return e
        P, denom, pphi = self.P, self.lam, []
        for i in range(4):
            acc = 0.0
            for j in range(4):
                acc += P[i][j] * phi[j]
            pphi.append(acc)
        for i in range(4):
            denom += phi[i] * pphi[i]
        inv_denom, inv_lam = 1.0 / denom, 1.0 / self.lam
        self.theta = [self.theta[i] + pphi[i] * inv_denom * e for i in range(4)]
        new = [[(P[i][j] - pphi[i] * pphi[j] * inv_denom) * inv_lam for j in range(4)]
               for i in range(4)]
        trace = ((new[0][0] + new[1][1]) + new[2][2]) + new[3][3]
        if trace > self.trace_max:
            scale = self.trace_max / trace
            new = [[v * scale for v in row] for row in new]
        self.P = new
        self.project(self.theta)
        return e

    def step(self, y_ref, y_meas):
        pred_error = self.rls_update(y_meas)
        a1, a2, b1, b2 = self.theta
        d = self.d
        e = []
        for n in range(d):
            e1 = e[n - 1] if n >= 1 else 0.0
            e2 = e[n - 2] if n >= 2 else 0.0
            e.append((1.0 if n == 0 else 0.0) - a1 * e1 - a2 * e2)
        e_dm2 = e[d - 2] if d >= 2 else 0.0
        g0, g1 = -(a1 * e[d - 1] + a2 * e_dm2), -a2 * e[d - 1]
        f = [b1 * (e[i] if i < d else 0.0) + b2 * (e[i - 1] if i >= 1 else 0.0) for i in range(d + 1)]
        num = y_ref - g0 * y_meas - g1 * self.y_prev[0]
        for i in range(1, d + 1):
            num -= f[i] * self.q_past[i - 1]
        q = f[0] * num / (f[0] * f[0] + self.lam_u)
        r, s_next, x_next = self.creep.evaluate(q)
        inv_z = list(self.inv.z)
        v = self.inv.step(r)
        saturated = self.sat and (v > self.v_max or v < self.v_min)
        if saturated:
            v = self.v_max if v > self.v_max else self.v_min
            r_eff = self.fwd.step(v)
            self.inv.z = inv_z
            self.inv.step(r_eff)
            memory = self.creep.evaluate(0.0)[0]
            q = (r_eff - memory) / self.creep.gain
            r, s_next, x_next = self.creep.evaluate(q)
            self.sat_hold = d + 1
            self.n_saturated += 1
        else:
            self.fwd.step(v)
            if self.sat_hold > 0:
                self.sat_hold -= 1
        self.creep.s, self.creep.x = s_next, x_next
        self.q_past = [q] + self.q_past[:-1]
        self.y_prev = [y_meas, self.y_prev[0]]
        return (v, q, *self.theta, pred_error, saturated)


def core_normals(seed):
    """The sensor's N(0, 1) sequence: the core's own generator (tested bitwise against a
    Python xoshiro256** in test_core_plant.py), so the transcription draws the same noise."""
    rng = core.ffi.new("piezo_rng *")
    core.lib().piezo_rng_seed(rng, seed & 0xFFFFFFFF)
    core.lib().piezo_rng_normal(rng)            # y_meas(0) consumed one draw at reset
    return lambda: core.lib().piezo_rng_normal(rng)


def bits(values):
    return np.asarray(values, dtype=np.float64).view(np.uint64)


# --------------------------------------------------------------------------- bit identity
@pytest.mark.parametrize("params", [MISMATCH, {**MISMATCH, "tf.delay": 2, "creep.alpha": 0.3},
                                    {"pi.m": 16, "creep.alpha": -0.7}],
                         ids=["mismatch", "delay-alpha0.3", "m16-alpha-0.7"])
def test_plant_step_equals_scalar_transcription_bitwise(params):
    """Reference: PlantRef (module docstring), 3000 samples of a 3-tone voltage with noise
    and quantization: u, x, y, y_meas equal bit for bit at every sample."""
    plant = core.Plant(params)
    ref = PlantRef(plant, core_normals(plant.raw.sensor_seed))
    k = np.arange(3000)
    v = 40 * np.sin(2 * np.pi * 3 * k * H) + 20 * np.sin(2 * np.pi * 37 * k * H) \
        + 5 * np.sin(2 * np.pi * 210 * k * H) + 30
    got, want = [], []
    for vk in v.tolist():
        got.append(tuple(plant.step(vk)))
        want.append(ref.step(vk))
    assert np.array_equal(bits(got), bits(want))


@pytest.mark.parametrize("cparams", [{}, {"sat.v_max": 25.0, "sat.v_min": -2.0},
                                     {"mv.delay": 2, "mv.lambda_u": 0.003, "rls.trace_max": 8.0}],
                         ids=["default", "saturating", "d3-lambda-tracebound"])
def test_closed_loop_equals_scalar_transcription_bitwise(cparams):
    """Reference: ControllerRef and PlantRef closed with the loop delay the controller
    assumes (d = 1 + mv.delay: the FMUs' default timing for d = 2), mismatched noisy plant,
    2000 samples of a 1+5+10 Hz reference: every controller output (v, q, estimates,
    pred_error, saturated) and every plant output equal bit for bit. The saturating case
    must clip (and adapt around it), the third must move the estimates and hit the trace
    bound."""
    plant, ctrl = core.Plant(MISMATCH), core.Controller(cparams)
    pref, cref = PlantRef(plant, core_normals(plant.raw.sensor_seed)), ControllerRef(ctrl)
    d = ctrl.raw.d
    k = np.arange(2000 + d)
    y_d = 4 * np.sin(2 * np.pi * k * H) + 2 * np.sin(2 * np.pi * 5 * k * H) \
        + 1.5 * np.sin(2 * np.pi * 10 * k * H) + 5
    # the loop delay d: the plant's own sample plus d - 1 samples before v is applied
    pending, pending_ref = [0.0] * (d - 1), [0.0] * (d - 1)
    y_meas = y_meas_ref = 0.0
    for j in range(2000):
        out = ctrl.step(y_d[j + d], y_meas)
        want = cref.step(y_d[j + d], y_meas_ref)
        assert np.array_equal(bits(tuple(out)[:7]), bits(want[:7])), j
        assert out.saturated == want[7], j
        p = plant.step(pending.pop(0))
        p_ref = pref.step(pending_ref.pop(0))
        assert np.array_equal(bits(tuple(p)), bits(p_ref)), j
        pending.append(out.v)
        pending_ref.append(want[0])
        y_meas, y_meas_ref = p.y_meas, p_ref[3]
    assert ctrl.raw.n_saturated == cref.n_saturated
    if "sat.v_max" in cparams:
        assert cref.n_saturated > 10
    if "rls.trace_max" in cparams:
        assert abs(ctrl.raw.theta[0] - ctrl.raw.theta_nominal[0]) > 1e-4


# --------------------------------------------------------------------------- refusals
def test_plant_overflow_refusal_leaves_struct_bitwise_unchanged():
    """Reference: the struct bytes before the call and an untouched twin. With pi.w0 = 4,
    v = +-1e308 overflows in u; with tf.b1 large and a huge but finite u the overflow shows
    in x only; with creep.k_c = 1e300 it shows in y only (u and x finite). Each is refused as
    divergence, at several samples and in both creep modes, with nothing changed."""
    cases = [({"pi.w0": 4.0}, 1e308), ({"pi.w0": 4.0}, -1e308),
             ({"tf.b1": 1e300, "tf.b2": 0.0}, 1e10), ({"creep.k_c": 1e300}, 1e10)]
    for params, huge in cases:
        for exact in (False, True):
            prm = {**params, "creep.exact": exact, "sensor.noise_rms": 0.01}
            plant, twin = core.Plant(prm), core.Plant(prm)
            for k in range(60):
                if k in (0, 1, 17, 18, 59):
                    before = raw_bytes(plant)
                    with pytest.raises(core.CoreDivergedError):
                        plant.step(huge)
                    assert raw_bytes(plant) == before, (params, exact, k)
                a, b = plant.step(1.0 + 0.1 * k), twin.step(1.0 + 0.1 * k)
                assert np.array_equal(bits(a), bits(b))
            assert raw_bytes(plant) == raw_bytes(twin)


def test_plant_capacity_refusal_leaves_struct_bitwise_unchanged():
    """Reference: the struct bytes. Exact creep with a history buffer one sample short:
    PIEZO_ERR_CAPACITY, nothing changed; with a NULL buffer: PIEZO_ERR_NULL."""
    L, ffi = core.lib(), core.ffi
    plant = core.Plant({"creep.exact": True})
    for k in range(5):
        plant.step(float(k))
    need = L.piezo_plant_history_needed(plant.raw)
    buf = np.zeros(need)
    before = raw_bytes(plant)
    assert L.piezo_plant_step(plant.raw, 1.0, ffi.from_buffer("double[]", buf), need - 1,
                              ffi.NULL) == core.PIEZO_ERR_CAPACITY
    assert L.piezo_plant_step(plant.raw, 1.0, ffi.NULL, 0, ffi.NULL) == core.PIEZO_ERR_NULL
    assert raw_bytes(plant) == before


def _driven(cparams, n, exact=False):
    """A controller after n closed-loop samples on the mismatched plant (creep mode as given)."""
    plant = core.Plant({**MISMATCH, "creep.exact": exact})
    ctrl = core.Controller({**cparams, "creep.exact": exact})
    applied = 0.0
    for k in range(n):
        out = ctrl.step(5 + 4 * math.sin(2 * math.pi * 5 * (k + 2) * H), plant.output.y_meas)
        plant.step(applied)
        applied = out.v
    return ctrl, plant


@pytest.mark.parametrize("exact", [False, True], ids=["soe", "exact"])
@pytest.mark.parametrize("cparams", [{}, {"sat.enabled": False}], ids=["limits", "no-limits"])
def test_controller_overflow_refusal_leaves_struct_bitwise_unchanged(cparams, exact):
    """Reference: the struct bytes before the call and a twin driven identically. Finite but
    huge inputs make a computed value overflow: each refused step or peek
    (CoreDivergedError) leaves the struct unchanged; an input that the controller absorbs
    instead (a clipped voltage) is undone by restoring the bytes, so every input starts
    from the same state. At least two inputs must be refused, and the next regular step
    equals the twin's bit for bit."""
    ctrl, _ = _driven(cparams, 300, exact)
    twin, _ = _driven(cparams, 300, exact)
    before = raw_bytes(ctrl)
    assert before == raw_bytes(twin)
    refused = set()
    extremes = ((1e308, 0.0), (0.0, -1e308), (0.0, 1e308), (1e200, 1e200), (-1e308, 1e308),
                (1e300, -1e300), (1e150, 0.0))
    for inputs in extremes:
        for call in (ctrl.step, ctrl.peek):
            try:
                call(*inputs)
            except core.CoreDivergedError as exc:
                assert not isinstance(exc, core.CoreUnstableError)
                refused.add(inputs)
                assert raw_bytes(ctrl) == before, inputs
            core.ffi.memmove(ctrl.raw, before, len(before))
    assert len(refused) >= 2, refused
    assert np.array_equal(bits(tuple(ctrl.step(5.0, 5.0))[:7]), bits(tuple(twin.step(5.0, 5.0))[:7]))
    assert raw_bytes(ctrl) == raw_bytes(twin)


def test_controller_capacity_refusal_leaves_struct_bitwise_unchanged():
    """Reference: the struct bytes. Exact mode with a buffer one sample short and with NULL:
    PIEZO_ERR_CAPACITY / PIEZO_ERR_NULL from step and peek, nothing changed."""
    L, ffi = core.lib(), core.ffi
    ctrl, _ = _driven({}, 50, exact=True)
    need = L.piezo_controller_history_needed(ctrl.raw)
    buf = np.zeros(need)
    out = ffi.new("piezo_controller_output *")
    before = raw_bytes(ctrl)
    for fn in (L.piezo_controller_step, L.piezo_controller_peek):
        assert fn(ctrl.raw, 1.0, 1.0, ffi.from_buffer("double[]", buf), need - 1, out) \
            == core.PIEZO_ERR_CAPACITY
        assert fn(ctrl.raw, 1.0, 1.0, ffi.NULL, 0, out) == core.PIEZO_ERR_NULL
    assert raw_bytes(ctrl) == before


@pytest.mark.parametrize("exact", [False, True], ids=["soe", "exact"])
def test_step_is_peek_then_commit_also_when_clipping(exact):
    """Reference: peek. Over a closed loop whose voltage limits clip often (so the
    back-calculation runs), each step returns exactly what a peek of the same inputs returned
    just before, the peek leaves the struct bytes alone, and a peek with other inputs
    differs unless the voltage is clipped (it really evaluates)."""
    plant = core.Plant({**MISMATCH, "creep.exact": exact})
    ctrl = core.Controller({"sat.v_max": 18.0, "sat.v_min": 2.0, "creep.exact": exact})
    applied, clipped = 0.0, 0
    for k in range(800):
        y_ref = 6 + 5 * math.sin(2 * math.pi * 9 * (k + 2) * H)
        ym = plant.output.y_meas
        before = raw_bytes(ctrl)
        p = ctrl.peek(y_ref, ym)
        other = ctrl.peek(y_ref + 0.25, ym)
        assert raw_bytes(ctrl) == before
        s = ctrl.step(y_ref, ym)
        assert np.array_equal(bits(tuple(p)[:7]), bits(tuple(s)[:7])) and p.saturated == s.saturated
        assert other != s or s.saturated    # a clipped v does not depend on y_ref
        clipped += s.saturated
        plant.step(applied)
        applied = s.v
    assert clipped > 20


@pytest.mark.parametrize("exact", [False, True], ids=["soe", "exact"])
def test_evaluate_then_commit_is_the_step(exact):
    """Reference: an identical twin stepped with piezo_controller_step. Each sample is
    evaluated twice (other inputs first, then the real ones: only the latest evaluation is
    committed), leaving the struct bytes alone; committing it gives the twin's output and
    the twin's struct bytes; a stale sample (evaluated at an earlier k) is refused with
    PIEZO_ERR_PARAM and changes nothing."""
    L, ffi = core.lib(), core.ffi
    plant = core.Plant({**MISMATCH, "creep.exact": exact})
    ctrl = core.Controller({"sat.v_max": 18.0, "sat.v_min": 2.0, "creep.exact": exact})
    twin = core.Controller({"sat.v_max": 18.0, "sat.v_min": 2.0, "creep.exact": exact})
    hist = np.zeros(4000)
    hp = ffi.from_buffer("double[]", hist)
    sample, stale = ffi.new("piezo_controller_sample *"), ffi.new("piezo_controller_sample *")
    out = ffi.new("piezo_controller_output *")
    applied = 0.0
    for k in range(600):
        y_ref = 6 + 5 * math.sin(2 * math.pi * 9 * (k + 2) * H)
        ym = plant.output.y_meas
        before = raw_bytes(ctrl)
        assert L.piezo_controller_evaluate(ctrl.raw, y_ref + 1.0, ym, hp, 4000, sample) == 0
        assert L.piezo_controller_evaluate(ctrl.raw, y_ref, ym, hp, 4000, sample) == 0
        assert raw_bytes(ctrl) == before
        assert (sample.k, sample.y_ref, sample.y_meas) == (k, y_ref, ym)
        if k == 100:
            ffi.memmove(stale, sample, ffi.sizeof(sample[0]))
        if k == 101:
            assert L.piezo_controller_commit(ctrl.raw, stale, out) == core.PIEZO_ERR_PARAM
            assert raw_bytes(ctrl) == before
        assert L.piezo_controller_commit(ctrl.raw, sample, out) == 0
        want = twin.step(y_ref, ym)
        assert np.array_equal(bits(tuple(core._ctrl_out(out[0]))[:7]), bits(tuple(want)[:7]))
        assert raw_bytes(ctrl) == raw_bytes(twin)
        plant.step(applied)
        applied = out.v
    assert ctrl.raw.n_saturated > 20


def test_commit_refuses_the_sample_that_completes_the_divergence_window():
    """Reference: the monitor's definition (window of 25 samples beyond 1 um, rls off, y_meas
    held at 5 um as in test_core_controller). The 25th evaluation succeeds with
    reaches_window set and the values a peek returns; its commit is refused with
    PIEZO_ERR_UNSTABLE, nothing changed; the 24 before commit normally."""
    L, ffi = core.lib(), core.ffi
    c = core.Controller({"mv.delay": 0, "sat.enabled": False, "rls.enabled": False,
                         "monitor.pred_error_max": 1.0, "monitor.divergence_samples": 25})
    sample = ffi.new("piezo_controller_sample *")
    for k in range(25):
        assert L.piezo_controller_evaluate(c.raw, 0.0, 5.0, ffi.NULL, 0, sample) == 0
        assert sample.reaches_window == (k == 24)
        before = raw_bytes(c)
        st = L.piezo_controller_commit(c.raw, sample, ffi.NULL)
        if k < 24:
            assert st == 0 and c.raw.run_large_error == k + 1
        else:
            assert st == core.PIEZO_ERR_UNSTABLE and raw_bytes(c) == before
            assert np.array_equal(bits(tuple(c.peek(0.0, 5.0))[:7]),
                                  bits(tuple(core._ctrl_out(sample.out))[:7]))
