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

import numpy as np
import pytest

from harness.binding import core
from harness.studies.supervision_table import _day_plant
from conftest import mismatch_plant

H = 0.0005
MISMATCH = {**mismatch_plant(), "sensor.seed": 7}      # docs/model.md's mismatch plant, another seed


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


NOISE_STEP = 1.0 + 1.0 / 64.0
NOISE_SCALE = 1.0 / (0.6744897501960817 * 1.4142135623730951)
NOISE_FLOOR = 1e-9


def track_noise(m, delta):
    """The measured noise after one more difference (piezo_controller.c, NOISE_STEP)."""
    x = abs(delta) * NOISE_SCALE
    if m == 0.0:
        return x if x > NOISE_FLOOR else 0.0
    m = m * NOISE_STEP if x > m else m * (1.0 / NOISE_STEP)
    return m if m > NOISE_FLOOR else NOISE_FLOOR


class ControllerRef:
    """piezo_controller.h/.c: RLS (sums over i = 0..3, one reciprocal of the denominator,
    1/lambda from init, the update (P phi)_i (P phi)_j / denom symmetric by itself),
    projection, delay detection (one RLS per candidate d = 1, 2, 3, sums of squared
    a-priori errors per trial, the clear-leader rule, probes, restarts; with the robust update,
    the wait of probes buried in the noise: scores and leads only on the samples that teach,
    adapting while the reference moves, a leader of 10 samples), the robust update
    (the excitation by the law's past reference against the measured noise of y_meas, the
    offset, the noise-scaled trace bound, the candidates' own forgetting and bound, the
    loop's fresh covariance at the choice), Diophantine with the observer polynomial T, MV
    law on T r with the integral action, inverse creep, inverse PI, saturation with
    back-calculation, monitor counts, and the guarantees of the robust update (its projection
    into the admissible set in the metric of P^-1 with the radial step, the fallback to the
    nominal model at a jump or a worse prediction), the offset held on a reading unchanged for
    PIEZO_SUP_STUCK_SAME samples, and once sup.gain_min times the supervision's model's move
    since the reading last changed, over the samples it answers (yhat(k - d + 1)), reaches its
    smallest step (that model, yhat = B q - (A - 1) yhat, transcribed with the supervision's
    nominal A, B) the integral action holds, and if the reading is within two of its steps and 4
    times its measured noise of y_d(k) while the reference holds (y_d(k + d) = y_d(k)) it is
    stale until either changes: the law's prediction stands in for it (robust update). Written from the header's and the docs'
    description, operation by operation in the C order; the admissible set's rows are constants
    the core derives at init."""

    START_D, START_T, N, CONFIRM, TRIAL, REDETECT, PROBES = 2, 0.9, 3, 3, 20, 10, 8
    DETECT_LAMBDA, DETECT_TRACE, OFFSET_GAIN = 0.995, 100.0, 0.01
    CONFIRM_BURIED, NOISE_SETTLE, STUCK_SAME, INV_SQRT3 = 40, 100, 4, 0.57735026918962576

    def __init__(self, ctrl):
        c = ctrl.raw
        self.auto = bool(c.auto_delay)
        self.d, self.lam_u, self.observer = c.d, c.lambda_u, c.observer
        self.rls, self.lam, self.trace_max, self.p0 = c.rls_enabled, c.forgetting, c.trace_max, c.p0
        self.robust, self.excitation, self.excitation_samples = bool(c.robust), c.excitation, c.excitation_samples
        self.variance_max, self.p0_loop, self.gamma = c.variance_max, c.p0_loop, c.integral_gain
        self.noise_y = self.noise_y2 = self.noise_e = self.anchor = self.offset = self.z = 0.0
        self.probe_max, self.sup_enabled, self.same = c.probe_max, bool(c.sup.enabled), 0
        self.y_raw1, self.n_stale, self.stale = 0.0, 0, False
        # the supervision's model of the stage (delay 1) and the reading's smallest step
        self.sup_model, self.gain_min = (c.sup.a1, c.sup.a2, c.sup.b1, c.sup.b2), c.sup.gain_min
        self.yhat1 = self.yhat2 = self.min_step = 0.0
        self.yhat_frozen = (0.0, 0.0, 0.0)
        self.left, self.prev_pred_error = 0, 0.0
        self.r_last = self.r_last2 = self.velocity = 0.0   # the law's reference without z at k-1, k-2
        self.yd = {}                            # y_d by sample: the law's r(j) is y_d(j + d)
        self.sat, self.v_min, self.v_max = c.sat_enabled, c.sat_v_min, c.sat_v_max
        self.pe_max, self.window = c.pred_error_max, c.divergence_samples
        self.theta, self.nominal = list(c.theta), list(c.theta_nominal)
        self.P = [[c.P[4 * i + j] for j in range(4)] for i in range(4)]
        self.y_prev = [0.0, 0.0]
        self.q_past = [0.0] * 11                # q(k-1), q(k-2), ...
        self.r_prev = 0.0
        self.sat_hold = 0
        self.creep, self.inv, self.fwd = SOERef(c.inv_creep), PIRef(c.inv_pi), PIRef(c.fwd_pi)
        self.n_saturated = 0
        self.k, self.k_delay, self.n_detections, self.run_large = 0, 0, 0, 0
        self.detecting = False
        if self.auto:
            self.start_detection()
        self.adm_c = [list(c.adm_c[i]) for i in range(9)]
        self.adm_d = list(c.adm_d)
        self.fb_ratio, self.fb_n_samples, self.fb_lam = c.fallback_ratio, c.fallback_samples, c.fallback_forgetting
        self.fb_a = self.fb_n = self.learned = 0.0
        self.jump_left = 0
        self.n_fallbacks = 0

    def start_detection(self):
        self.detecting, self.d = True, self.START_D
        self.leader, self.run = -1, 0
        self.trial, self.probe, self.probes = self.k, 0.0, 0
        self.n_detections += 1
        self.scores = [0.0] * self.N
        self.det_theta = [list(self.nominal) for _ in range(self.N)]
        self.det_P = [[[self.p0 if i == j else 0.0 for j in range(4)] for i in range(4)]
                      for _ in range(self.N)]

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

    def excess(self, i, th):
        """c_i^T theta - d_i of the admissible set's row i, in the C order."""
        row = self.adm_c[i]
        return (((row[0] * th[0] + row[1] * th[1]) + row[2] * th[2]) + row[3] * th[3]) - self.adm_d[i]

    def outside(self, th):
        return any(self.excess(i, th) > 0.0 for i in range(9))

    def admissible_project(self, P, th):
        """Sweeps of P-metric half-space projections over the violated rows (at most 8), then
        the radial step towards the nominal model (shrunk by 1e-12 .. 1e-3 of itself while
        rounding leaves it outside), then the nominal model itself with P = p0_loop I:
        ``(theta, P)``."""
        if not self.outside(th):
            return th, P
        th = list(th)
        for _ in range(8):
            moved = False
            for i in range(9):
                row, excess = self.adm_c[i], self.excess(i, th)
                if not excess > 0.0:
                    continue
                pc = [((P[j][0] * row[0] + P[j][1] * row[1]) + P[j][2] * row[2]) + P[j][3] * row[3]
                      for j in range(4)]
                cpc = ((row[0] * pc[0] + row[1] * pc[1]) + row[2] * pc[2]) + row[3] * pc[3]
                if not (cpc > 0.0 and math.isfinite(cpc)):
                    pc = list(row)
                    cpc = ((row[0] * row[0] + row[1] * row[1]) + row[2] * row[2]) + row[3] * row[3]
                th = [th[j] - pc[j] * (excess / cpc) for j in range(4)]
                moved = True
            if not moved:
                break
        if self.outside(th):
            n, s = self.nominal, 1.0
            for i in range(9):
                excess = self.excess(i, th)
                if excess > 0.0:
                    slack = -self.excess(i, n)
                    ratio = slack / (slack + excess)
                    if ratio < s:
                        s = ratio
            out = th
            th = [n[j] + s * (out[j] - n[j]) for j in range(4)]
            for shrink in (1e-12, 1e-9, 1e-6, 1e-3):
                if not self.outside(th):
                    break
                th = [n[j] + (s - s * shrink) * (out[j] - n[j]) for j in range(4)]
            if self.outside(th):
                th = list(n)
                P = [[self.p0_loop if i == j else 0.0 for j in range(4)] for i in range(4)]
        return th, P

    def error(self, theta, d, y):
        """The a-priori error y - phi^T theta, in the C order."""
        phi = [-self.y_prev[0], -self.y_prev[1], self.q_past[d - 1], self.q_past[d]]
        e = y
        for i in range(4):
            e -= phi[i] * theta[i]
        return e

    def rls_step(self, theta, P, d, y, update, lam=None, trace_max=None, paper_projection=True):
        """(a-priori error, theta, P) of one RLS under delay d; the paper's projection (the
        delay candidates, the paper's update) unless paper_projection is false (the robust
        update, whose caller projects into the admissible set)."""
        lam = self.lam if lam is None else lam
        trace_max = self.trace_max if trace_max is None else trace_max
        phi = [-self.y_prev[0], -self.y_prev[1], self.q_past[d - 1], self.q_past[d]]
        e = y
        for i in range(4):
            e -= phi[i] * theta[i]
        if not update:
            return e, theta, P
        denom, pphi = lam, []
        for i in range(4):
            acc = 0.0
            for j in range(4):
                acc += P[i][j] * phi[j]
            pphi.append(acc)
        for i in range(4):
            denom += phi[i] * pphi[i]
        inv_denom, inv_lam = 1.0 / denom, 1.0 / lam
        theta = [theta[i] + pphi[i] * inv_denom * e for i in range(4)]
        new = [[(P[i][j] - pphi[i] * pphi[j] * inv_denom) * inv_lam for j in range(4)]
               for i in range(4)]
        trace = ((new[0][0] + new[1][1]) + new[2][2]) + new[3][3]
        if trace > trace_max:
            scale = trace_max / trace
            new = [[v * scale for v in row] for row in new]
        if paper_projection:
            self.project(theta)
        return e, theta, new

    def buried(self):
        """piezo_controller_probes_buried: the robust update's probes buried in the noise."""
        return self.robust and self.k >= self.NOISE_SETTLE and 20.0 * self.noise_y2 > self.probe_max * self.nominal[2]

    def detect(self, y, live=True):
        """One sample of the detection; returns the leader's a-priori error."""
        update = self.rls and not self.sat_hold > 0 and not self.buried() and (live or self.r_last != self.r_last2)
        errs, scores = [], []
        for i in range(self.N):
            e, self.det_theta[i], self.det_P[i] = self.rls_step(
                self.det_theta[i], self.det_P[i], i + 1, y, update,
                self.DETECT_LAMBDA if self.robust else None, self.DETECT_TRACE if self.robust else None)
            errs.append(e)
            scores.append(self.scores[i] + e * e)
        if not live:
            return errs[self.START_D - 1]
        self.scores = scores
        order = [self.START_D - 1, 0, 2]
        best = order[0]
        for i in order[1:]:
            if self.scores[i] < self.scores[best]:
                best = i
        second = -1
        for i in range(self.N):
            if i != best and (second < 0 or self.scores[i] < self.scores[second]):
                second = i
        if self.scores[second] > 0.0 and self.scores[best] <= (1.0 / 10) * self.scores[second]:
            self.run = self.run + 1 if self.leader == best else 1
            self.leader = best
        else:
            self.run, self.leader = 0, -1
        self.detecting = self.run < (self.CONFIRM_BURIED if self.buried() else self.CONFIRM)
        self.new_trial = self.detecting and self.k + 1 - self.trial >= self.TRIAL
        if self.new_trial:
            p = 20.0 * math.sqrt(self.scores[best] / self.TRIAL) / self.nominal[2]
            if p < 2.0 * self.probe:
                p = 2.0 * self.probe
            lo = 1e-3 if 1e-3 < self.probe_max else self.probe_max
            self.next_probe = 0.0 if self.probes >= self.PROBES else (lo if p < lo else
                                                                      (self.probe_max if p > self.probe_max else p))
        if not self.detecting:
            self.d, self.k_delay = best + 1, self.k
            self.theta, self.P = list(self.nominal if self.robust else self.det_theta[best]), self.det_P[best]
            if self.robust:
                self.P = [[self.p0_loop if i == j else 0.0 for j in range(4)] for i in range(4)]
        return errs[best]

    def step(self, y_ref, y_meas):
        was_detecting = self.detecting
        self.new_trial = False
        excited, offset = True, self.offset
        offset_before, noise_y_before, noise_e_before, updated = self.offset, self.noise_y, self.noise_e, False
        # the monitor's bound (monitor_bound): monitor.pred_error_max, or 8 times the noise measured
        # before this sample when larger, at most twice monitor.pred_error_max
        monitor = min(8.0 * self.noise_y2, 2.0 * self.pe_max) if self.robust and self.k >= self.NOISE_SETTLE else 0.0
        monitor = monitor if monitor > self.pe_max else self.pe_max
        # a jump of the law's reference (beyond monitor.pred_error_max) is answered for 2 (d + 2) samples
        self.jump_left = (2 * (self.d + 2) if abs(self.r_last - self.r_last2) > self.pe_max
                          else (self.jump_left - 1 if self.jump_left > 0 else 0))
        # a reading unchanged for STUCK_SAME samples (the supervision's count, of the readings as they
        # came): the offset holds
        raw = y_meas
        same = self.same + 1 if self.k > 0 and y_meas == self.y_raw1 else 0
        held = self.sup_enabled and same >= self.STUCK_SAME
        # stale once a live reading would have changed (gain_min |yhat - yhat(f)| >= q): the integral
        # holds, and (robust update, delay chosen) the law's model's prediction stands in for y_meas
        sa1, sa2, sb1, sb2 = self.sup_model
        yhat = sb1 * self.q_past[0] + sb2 * self.q_past[1] - sa1 * self.yhat1 - sa2 * self.yhat2
        yhats = (yhat, self.yhat1, self.yhat2)      # yhat(k), yhat(k-1), yhat(k-2)
        yhat_frozen = yhats if same == 0 else self.yhat_frozen
        step = abs(y_meas - self.y_raw1) if self.k > 0 else 0.0
        # over the samples the readings answer: yhat(k - d + 1) (d of the loop; beyond 3 not judged)
        integral_held = (held and 1 <= self.d <= 3
                         and not self.gain_min * abs(yhats[self.d - 1] - yhat_frozen[self.d - 1]) < self.min_step)
        # ... if it reads y_d(k) within 2 steps and 4 times the measured noise while the reference
        # holds (y_d(k + d) = y_d(k)), until either changes
        stale = (integral_held and self.robust and not was_detecting and self.k in self.yd
                 and y_ref == self.yd[self.k]
                 and (self.stale or abs(self.yd[self.k] - y_meas) <= 2.0 * self.min_step + 4 * self.noise_y2))
        raw_error = self.error(self.theta, self.d, y_meas - self.offset) if stale else 0.0
        y_meas -= raw_error
        self.n_stale += stale
        if self.sup_enabled:
            self.yhat2, self.yhat1, self.yhat_frozen = self.yhat1, yhat, yhat_frozen
            if step > 0.0 and (self.min_step == 0.0 or step < self.min_step):
                self.min_step = step
        if self.robust:
            r1 = self.r_last
            line = self.anchor + self.velocity
            still = r1 == self.r_last2
            event = abs(r1 - line) > self.excitation * self.noise_y
            noise_y = track_noise(self.noise_y, y_meas - self.y_prev[0])
            noise_y2 = (track_noise(self.noise_y2, (y_meas - 2.0 * self.y_prev[0] + self.y_prev[1]) * self.INV_SQRT3)
                        if not (event or self.left > 0) else self.noise_y2)
            excited = event or self.left > 0
            anchor = r1 if event or still else line
            velocity = r1 - self.r_last2 if event or still else self.velocity
            left = self.excitation_samples if event else (self.left - 1 if self.left > 0 else 0)
        live = not self.buried() or (self.robust and excited)
        if was_detecting:
            offset = 0.0
            buried = self.buried()
            pred_error = self.detect(y_meas, live)
            if buried:      # the start-up law's own prediction: the nominal model's at d = START_D
                pred_error = self.error(self.nominal, self.START_D, y_meas)
        elif self.robust:
            may = self.rls and not self.sat_hold > 0 and not stale
            bound = self.trace_max
            if self.noise_e > 0.0:
                b = self.variance_max / (self.noise_e * self.noise_e)
                if b < bound:
                    bound = b
            updated = may and excited and not (self.k >= self.NOISE_SETTLE
                                                and 20.0 * self.noise_y2 > 2.0 * self.probe_max * self.nominal[2])
            pred_error, self.theta, self.P = self.rls_step(self.theta, self.P, self.d, y_meas - self.offset,
                                                           updated, self.lam, bound, paper_projection=False)
            if updated:
                self.theta, self.P = self.admissible_project(self.P, self.theta)
            if may and not excited and not held:
                offset = self.offset + self.OFFSET_GAIN * pred_error
        else:
            pred_error, self.theta, self.P = self.rls_step(self.theta, self.P, self.d, y_meas,
                                                           self.rls and not self.sat_hold > 0)
        if self.robust:
            self.noise_e = track_noise(self.noise_e, pred_error - self.prev_pred_error)
            self.noise_y, self.anchor, self.left, self.velocity = noise_y, anchor, left, velocity
            self.noise_y2 = noise_y2
        self.same, self.y_raw1, self.stale = same, raw, stale
        self.prev_pred_error = pred_error
        self.offset = offset
        d = self.d
        r_plain = y_ref
        if self.robust and not was_detecting and not self.detecting:
            # the fallback to the nominal model: a worse prediction over the window, or a jump
            rate = abs(r_plain - self.r_last)
            adapted = self.rls and bits(self.theta).tobytes() != bits(self.nominal).tobytes()
            reason, fb_a, fb_n = 0, self.fb_a, self.fb_n
            if self.fb_ratio > 0.0:
                e_n = self.error(self.nominal, d, y_meas - offset_before)
                fb_a = self.fb_lam * self.fb_a + pred_error * pred_error
                fb_n = self.fb_lam * self.fb_n + e_n * e_n
                floor = 3.0 * noise_y_before
                if adapted and fb_a > self.fb_ratio * fb_n + float(self.fb_n_samples) * (floor * floor):
                    reason = 2
                if (self.jump_left == 0 and abs(pred_error) > self.pe_max
                        and abs(pred_error) > 5.0 * noise_e_before and adapted):
                    reason = 3
            if adapted and rate > self.pe_max and rate > 5 * self.learned:
                reason = 1
            if reason:
                self.theta = list(self.nominal)
                self.P = [[self.p0_loop if i == j else 0.0 for j in range(4)] for i in range(4)]
                self.fb_a = self.fb_n = 0.0
                self.learned = rate
                self.n_fallbacks += 1
            else:
                self.fb_a, self.fb_n = fb_a, fb_n
                faded = self.learned * (1.0 - 1.0 / 2000) if updated else self.learned
                self.learned = rate if rate > faded else faded
        a1, a2, b1, b2 = self.nominal if self.detecting else self.theta
        t = self.START_T if self.detecting else self.observer
        z = self.z
        if self.gamma > 0.0 and not self.detecting and self.sat_hold == 0 and self.k in self.yd and not integral_held:
            z = self.z + self.gamma * (self.yd[self.k] - y_meas)
        r = r_plain + z if self.gamma > 0.0 else r_plain
        e = []
        for n in range(d):
            e1 = e[n - 1] if n >= 1 else 0.0
            e2 = e[n - 2] if n >= 2 else 0.0
            t_n = 1.0 if n == 0 else (-t if n == 1 else 0.0)
            e.append(t_n - a1 * e1 - a2 * e2)
        e_dm2 = e[d - 2] if d >= 2 else 0.0
        g0 = (-t if d == 1 else 0.0) - (a1 * e[d - 1] + a2 * e_dm2)
        g1 = -a2 * e[d - 1]
        f = [b1 * (e[i] if i < d else 0.0) + b2 * (e[i - 1] if i >= 1 else 0.0) for i in range(d + 1)]
        num = (r - t * self.r_prev) - g0 * y_meas - g1 * self.y_prev[0]
        for i in range(1, d + 1):
            num -= f[i] * self.q_past[i - 1]
        q = f[0] * num / (f[0] * f[0] + self.lam_u)
        if self.detecting and self.k - self.trial < 2:
            q += self.probe if self.k == self.trial else -self.probe
        r_c, s_next, x_next = self.creep.evaluate(q)
        inv_z = list(self.inv.z)
        v = self.inv.step(r_c)
        saturated = self.sat and (v > self.v_max or v < self.v_min)
        if saturated:
            v = self.v_max if v > self.v_max else self.v_min
            r_eff = self.fwd.step(v)
            self.inv.z = inv_z
            self.inv.step(r_eff)
            memory = self.creep.evaluate(0.0)[0]
            q = (r_eff - memory) / self.creep.gain
            r_c, s_next, x_next = self.creep.evaluate(q)
            self.sat_hold = (self.N if self.detecting else d) + 1
            self.n_saturated += 1
        else:
            self.fwd.step(v)
            if self.sat_hold > 0:
                self.sat_hold -= 1
        self.run_large = self.run_large + 1 if abs(raw_error if stale else pred_error) > monitor else 0
        restart = (self.auto and not self.detecting and self.run_large >= self.REDETECT
                   and self.k + 1 - self.k_delay >= self.REDETECT)
        self.creep.s, self.creep.x = s_next, x_next
        self.q_past = [q] + self.q_past[:-1]
        self.r_last2, self.r_last = self.r_last, r_plain
        self.yd[self.k + d] = r_plain
        self.z = z
        self.y_prev = [y_meas, self.y_prev[0]]
        self.r_prev = r
        theta_out = list(self.nominal if self.detecting else self.theta)
        delay = 0 if self.detecting else d
        if self.new_trial:
            self.trial, self.probe = self.k + 1, self.next_probe
            self.probes += self.next_probe > 0.0
            self.leader, self.run = -1, 0
            self.scores = [0.0] * self.N
        self.k += 1
        if restart:
            self.start_detection()
            self.k_delay = self.k
        return (v, q, *theta_out, raw_error if stale else pred_error, saturated, delay)


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


@pytest.mark.parametrize("cparams, d", [
    ({}, 2), ({"sat.v_max": 25.0, "sat.v_min": -2.0}, 2),
    ({"mv.delay": 2, "mv.lambda_u": 0.003, "rls.trace_max": 8.0, "mv.observer": 0.0}, 3),
    ({}, 1), ({}, 3), ({"mv.delay": 0, "mv.observer": 0.7}, 1)],
    ids=["default", "saturating", "d3-lambda-tracebound-plain", "detect-d1", "detect-d3",
         "set-d1-observer0.7"])
def test_closed_loop_equals_scalar_transcription_bitwise(cparams, d):
    """Reference: ControllerRef and PlantRef closed with a loop delay d (the plant's own
    sample plus d - 1 samples before v is applied), mismatched noisy plant, 2000 samples of
    a 1+5+10 Hz reference y_d(k + d): every controller output (v, q, estimates, pred_error,
    saturated, the delay of the law) and every plant output equal bit for bit. The default
    controller detects d (1, 2 and 3 here: the transcription must choose the same at the
    same sample); the saturating case must clip (and adapt around it); the third must move
    the estimates and hit the trace bound; the last sets d = 1 and another observer pole."""
    k = np.arange(2000 + d)
    y_d = 4 * np.sin(2 * np.pi * k * H) + 2 * np.sin(2 * np.pi * 5 * k * H) \
        + 1.5 * np.sin(2 * np.pi * 10 * k * H) + 5
    ctrl, cref, _ = _run_bitwise(cparams, d, y_d, 2000)
    if ctrl.raw.auto_delay:
        assert ctrl.raw.d == d and not ctrl.raw.detecting     # detected the loop's own d
    if "sat.v_max" in cparams:
        assert cref.n_saturated > 10
    if "rls.trace_max" in cparams:
        assert abs(ctrl.raw.theta[0] - ctrl.raw.theta_nominal[0]) > 1e-4


def _run_bitwise(cparams, d, y_d, n, plant_params=MISMATCH, each=None, sensor_gain=None, stuck_from=None):
    """The loop of test_closed_loop_equals_scalar_transcription_bitwise: n samples of the
    core and the transcription side by side, asserting bit identity at every sample
    (sensor_gain: y_meas of sample j times sensor_gain[j], before both read it; stuck_from: from
    that sample on both read the y_meas of that sample). Returns the controller, the transcription
    and the plant's y of each sample."""
    plant, ctrl = core.Plant(plant_params), core.Controller(cparams)
    pref, cref = PlantRef(plant, core_normals(plant.raw.sensor_seed)), ControllerRef(ctrl)
    # the loop delay d: the plant's own sample plus d - 1 samples before v is applied
    pending, pending_ref = [0.0] * (d - 1), [0.0] * (d - 1)
    y_meas = y_meas_ref = 0.0
    ctrl.held = 0
    ys, stuck = [], None
    for j in range(n):
        if each is not None:
            each(ctrl, cref)
        if sensor_gain is not None:
            y_meas, y_meas_ref = y_meas * sensor_gain[j], y_meas_ref * sensor_gain[j]
        if stuck_from is not None and j >= stuck_from:
            stuck = (y_meas, y_meas_ref) if stuck is None else stuck
            y_meas, y_meas_ref = stuck
        out = ctrl.step(y_d[j + d], y_meas)
        ctrl.held += not ctrl.raw.out.adapting
        want = cref.step(y_d[j + d], y_meas_ref)
        assert np.array_equal(bits(tuple(out)[:7]), bits(want[:7])), j
        assert (out.saturated, out.delay) == want[7:9], j
        pending.append(out.v)
        pending_ref.append(want[0])
        p = plant.step(pending.pop(0))
        p_ref = pref.step(pending_ref.pop(0))
        assert np.array_equal(bits(tuple(p)), bits(p_ref)), j
        y_meas, y_meas_ref = p.y_meas, p_ref[3]
        ys.append(p.y)
    assert ctrl.raw.n_saturated == cref.n_saturated
    return ctrl, cref, np.array(ys)


def test_a_detection_that_waits_for_the_reference_equals_scalar_transcription_bitwise():
    """Reference: ControllerRef and PlantRef as above, behind a 150 nm rms sensor with probes of at
    most 50 nm: 0.3 s at rest (the probes buried in the noise from sample 100: the detection waits,
    no candidate scores), then 10 um steps every 50 ms (the candidates score on the reference's
    excitations; they do not adapt while the probes are buried; a leader would have to lead 40
    samples, longer than a trial of 20, so none is chosen: the start-up law runs). Bit identity at
    every sample; the wait must happen, the run end still detecting with the start-up law's d = 2."""
    y_d = np.concatenate([np.zeros(600)] + [np.full(100, 10.0 * (j % 2 == 0)) for j in range(30)])
    n = len(y_d) - 2
    buried = []
    plant = {**MISMATCH, "sensor.noise_rms": 0.15}
    ctrl, cref, _ = _run_bitwise({"mv.probe_max": 0.05}, 2, y_d, n, plant_params=plant,
                              each=lambda c, r: buried.append((r.buried(), bool(c.raw.detecting))))
    waits = sum(b and det for b, det in buried)
    print(f"\nburied and detecting in {waits} of {n} samples")
    assert waits > 3000 and ctrl.raw.detecting and ctrl.raw.d == 2 and cref.detecting


PAPER_LAW = {"rls.robust": False, "rls.forgetting": 0.995, "rls.trace_max": 100.0, "mv.integral": 0.0,
             "mv.observer": 0.4}


def _stage_use():
    """y_d of a stage's use: a hold at 0, a 6 um step, a hold, a 30 ms cycloid move to 10 um, a hold,
    50 ms of a 20 Hz triangle, a hold (4210 samples)."""
    segs = [np.zeros(600), np.full(600, 6.0)]
    s = np.arange(1, 61) / 60
    segs += [6.0 + 4.0 * (s - np.sin(2 * np.pi * s) / (2 * np.pi)), np.full(900, 10.0)]
    tri = np.abs(((np.arange(100) * H * 20) % 1.0) * 2 - 1)
    segs += [10.0 - 2.0 * (1 - tri), np.full(1950, 10.0)]
    return np.concatenate(segs)


@pytest.mark.parametrize("cparams, d", [({}, 2), ({}, 1), ({"mv.integral": 0.05, "rls.excitation_time": 0.01}, 2),
                                        (PAPER_LAW, 2)],
                         ids=["default", "default-d1", "integral0.05-excitation10", "paper-law"])
def test_holds_and_moves_equal_scalar_transcription_bitwise(cparams, d):
    """Reference: ControllerRef and PlantRef as above, on a stage's use instead of tones: a
    hold at 0, a 6 um step, a hold, a 30 ms cycloid move to 10 um, a hold, 50 ms of a 20 Hz
    triangle, a hold (4200 samples, the mismatched noisy plant). Bit identity at every sample;
    with the robust update the estimates must hold for a third of the run or more (est.adapting
    false) and the offset and the integral action must both be used (nonzero at the end)."""
    y_d = _stage_use()
    n = len(y_d) - d
    ctrl, cref, _ = _run_bitwise(cparams, d, y_d, n)
    print(f"\n{cparams}: estimates held in {ctrl.held} of {n} samples")
    if ctrl.raw.robust:
        assert ctrl.held >= n / 3
        assert ctrl.raw.offset != 0.0 and ctrl.raw.integral != 0.0
        assert ctrl.raw.offset == cref.offset and ctrl.raw.integral == cref.z
        assert ctrl.raw.noise_y == cref.noise_y and ctrl.raw.noise_e == cref.noise_e
    else:
        assert ctrl.held <= 50       # the paper's update adapts on every sample (but while detecting)


@pytest.mark.parametrize("noise", [0.0, 1.0], ids=["noise-free", "1nm"])
def test_a_reading_stuck_in_a_hold_equals_scalar_transcription_bitwise(noise):
    """Reference: ControllerRef and PlantRef as above, on the stage's use of the test above, on the
    stage's day's stage 32 (of the stuck table's worst drift before) with its sensor (2 nm grid,
    noise-free or 1 nm rms) stuck from sample 2600 (in the last hold at 10 um) to the end, 1608
    samples. Bit identity at every sample; the reading must be taken for stale (the
    supervision's model moved beyond what a live reading allows) for more than 500 of them (605 and
    1327 measured), and the stage hold within 50 nm of 10 um: the law answered the stuck reading through its model's slow
    pole before, and walked 0.2 um in 0.5 s (docs/robustness.md, stuck table)."""
    y_d = _stage_use()
    n = len(y_d) - 2
    ctrl, cref, y = _run_bitwise({}, 2, y_d, n, plant_params=_day_plant(32, noise), stuck_from=2600)
    drift = np.abs(y[2600:] - 10.0).max()
    print(f"\nstale in {cref.n_stale} samples, stage within {drift * 1e3:.1f} nm of 10 um")
    assert cref.n_stale > 500 and ctrl.raw.fault == 0
    assert drift < 0.05


@pytest.mark.parametrize("case", ["tone-then-step", "raster-narrow-set", "steps-prediction", "ringing",
                                  "noisy-tone"])
def test_guarantees_equal_scalar_transcription_bitwise(case):
    """Reference: ControllerRef and PlantRef as above, on what the robust update's guarantees
    (docs/model.md, "Estimates with guarantees") act on, each case made to exercise its part:
    1.5 s of a 10 Hz tone then an 8 um step (projections into the admissible set, and the jump
    fallback: the step is 32 times the tone's largest change a sample); a 10 Hz triangle raster
    with a narrow set (sup.gain_min 0.85, sup.gain_max 1.2, rls.zero_min 0.9: the projection at most samples); a
    square wave of 3 um steps on a stage with 20 % more hysteresis gain, with the prediction test
    at rls.fallback_ratio 1 over 5 ms (prediction fallbacks); a loop that rings: the tone behind a
    sensor of gain 0.3 (the estimates learn b1 0.26, the nominal 0.595), 0.1 s at rest, the gain
    back to 1 halfway (the law now drives the stage 2.3 times too hard and rings around the rest:
    the one-sample fallback within 0.1 s, supervision off); a 20 Hz tone from t = 0 behind a 200 nm
    rms sensor (no sample at rest: the estimates adapt, and the noise's a-priori errors pass 1 um at
    times, within 5 times their measured noise: no one-sample fallback). Bit identity at every
    sample."""
    k = np.arange(6002)
    plant, gain = MISMATCH, None
    if case == "tone-then-step":
        cparams, y_d = {}, np.where(k < 3000, 4 * np.sin(2 * np.pi * 10 * k * H), 8.0)
    elif case == "raster-narrow-set":
        cparams = {"sup.gain_min": 0.85, "sup.gain_max": 1.2, "rls.zero_min": 0.9}
        y_d = 10 * np.abs(((k * H * 10) % 1.0) * 2 - 1)
    elif case == "noisy-tone":
        cparams, plant = {"sup.enabled": False}, {**MISMATCH, "sensor.noise_rms": 0.2}
        y_d = 4 * np.sin(2 * np.pi * 20 * k * H)
    elif case == "ringing":
        cparams = {"sup.enabled": False}
        y_d = np.where((k < 3000) | (k >= 3200), 4 * np.sin(2 * np.pi * 10 * k * H), 0.0)
        gain = np.where(k < 3100, 0.3, 1.0)
    else:
        cparams = {"rls.fallback_ratio": 1.0, "rls.fallback_window": 0.005}
        y_d = np.where((k // 1000) % 2 == 1, 3.0, 0.0)
        plant = {"pi.w0": 0.40}
    ctrl, cref, _ = _run_bitwise(cparams, 2, y_d, 6000, plant, sensor_gain=gain)
    raw = ctrl.raw
    assert raw.n_fallbacks == cref.n_fallbacks
    if case == "tone-then-step":
        assert raw.n_projections > 0 and raw.n_fallbacks == 1
        assert (raw.first_fallback, raw.k_first_fallback) == (core.lib().PIEZO_FALLBACK_JUMP, 2998)
    elif case == "raster-narrow-set":
        assert raw.n_projections > 1000 and raw.n_fallbacks == 0
    elif case == "ringing":
        print(f"\nfirst fallback {raw.first_fallback} at {raw.k_first_fallback}, {raw.n_fallbacks} in all, "
              f"{raw.n_outliers} outliers")
        assert raw.n_outliers == 0 and raw.n_fallbacks >= 1
        assert raw.first_fallback == core.lib().PIEZO_FALLBACK_RINGING and 3100 < raw.k_first_fallback < 3300
    elif case == "noisy-tone":
        # the noise's errors reached the one-sample test's first bound, not its second
        print(f"\nmax |pred_error| {raw.max_abs_pred_error:.4g} um, noise_e {raw.noise_e:.4g} um")
        assert raw.max_abs_pred_error > 1.0 and raw.n_fallbacks == 0
    else:
        assert raw.n_fallbacks > 10 and raw.first_fallback == core.lib().PIEZO_FALLBACK_PREDICTION


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


def _input(y_ref, y_meas, y_preview=0.0, preview_lead=0):
    """A piezo_controller_input (cffi)."""
    return core.ffi.new("piezo_controller_input *", {"y_ref": y_ref, "y_meas": y_meas,
                                                    "y_preview": y_preview, "preview_lead": preview_lead})


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
        assert L.piezo_controller_evaluate(ctrl.raw, _input(y_ref + 1.0, ym), hp, 4000, sample) == 0
        assert L.piezo_controller_evaluate(ctrl.raw, _input(y_ref, ym), hp, 4000, sample) == 0
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
        assert L.piezo_controller_evaluate(c.raw, _input(0.0, 5.0), ffi.NULL, 0, sample) == 0
        assert sample.reaches_window == (k == 24)
        before = raw_bytes(c)
        st = L.piezo_controller_commit(c.raw, sample, ffi.NULL)
        if k < 24:
            assert st == 0 and c.raw.run_large_error == k + 1
        else:
            assert st == core.PIEZO_ERR_UNSTABLE and raw_bytes(c) == before
            assert np.array_equal(bits(tuple(c.peek(0.0, 5.0))[:7]),
                                  bits(tuple(core._ctrl_out(sample.out))[:7]))
