/* piezo_controller.c - adaptive compound controller. See piezo_controller.h. */
#include <math.h>
#include <string.h>
#include "piezo_controller_internal.h"
#include "piezo_plant.h"
#include "piezo_simd.h"

/* The start-up law while the delay is detected: the nominal model, d = 2 and
 * t = 0.9. Its closed loop is stable for a loop delay of 1, 2 or 3 samples,
 * also with the mismatch case's plant and gains from 0.6 to 1.5 times the
 * model's (roots in docs/cosimulation.md); t = 0 (plain MV) is unstable for
 * every wrong d. */
#define START_OBSERVER 0.9
/* Robust adaptation (rls.robust; docs/model.md, adaptation). The measured noise of a signal
 * x is the median of |x(k) - x(k-1)|, scaled to the rms of a white x: a multiplicative
 * quantile tracker that steps up by NOISE_STEP when |x(k) - x(k-1)| NOISE_SCALE is above it
 * and down by the same factor when below, so it settles where half the samples are above,
 * within about 450 samples of a change by a factor 1000 (median |delta| = 0.6745 sqrt(2) rms
 * for white Gaussian x). A difference removes a smooth signal (a 1 Hz, 10 um tone changes by
 * 31 nm a sample; the model's error at 20 Hz is scaled by 2 sin(pi 20 h) = 0.063) but not
 * white sensor noise, and a median ignores the few samples of a step. NOISE_FLOOR keeps it
 * a normal number (a noise-free loop at rest has x(k) - x(k-1) = 0). */
#define NOISE_STEP (1.0 + 1.0 / 64.0)
#define NOISE_SCALE (1.0 / (0.6744897501960817 * 1.4142135623730951))  /* 1 / (median |N(0,1)| sqrt 2) */
#define NOISE_FLOOR 1e-9          /* [um] */
#define INV_SQRT3 0.57735026918962576
/* While the estimates are held (no excitation), the estimator's offset c follows its
 * prediction error: c += OFFSET_GAIN e, a time constant of 1 / OFFSET_GAIN = 100 samples.
 * Creep and the integral action move the stage's operating point while it holds still; c
 * keeps the regression y - c = phi^T theta consistent with it, so the first samples of the
 * next move do not teach theta the offset the hold built up (measured: a 30 um S-curve after
 * 600 s at 10 um, 7x the error after 0.2 s without c, 1.2x with it). */
#define OFFSET_GAIN 0.01
/* The admissible set's projection (docs/model.md, "Estimates with guarantees"): sweeps of
 * P-metric half-space projections over the violated rows, then a radial step towards the
 * nominal model (inside the set) that ends inside it whatever the sweeps left. */
#define ADMISSIBLE_SWEEPS 8
/* The fallback's prediction test counts only beyond this many times the measured noise of
 * y_meas (per sample, over the window): two models that both predict within the noise are
 * not told apart. */
#define FALLBACK_NOISE 3.0

/* The sample's checked block holds PIEZO_SAMPLE_CHECKED = 12 doubles and nothing else (sample_state_finite) */
typedef char assert_sample_block[offsetof(piezo_controller_sample, learned_rate) + sizeof(double)
                                 - offsetof(piezo_controller_sample, noise_y) == PIEZO_SAMPLE_CHECKED * sizeof(double)
                                 && PIEZO_SAMPLE_CHECKED == 12 ? 1 : -1];

/* The loop delay's one home is PIEZO_MV_MAX_D (piezo_supervisor.h); the literals the
 * binding reads beside it follow from it. */
typedef char assert_max_delay[(PIEZO_MV_MAX_EXTRA_DELAY == PIEZO_MV_MAX_D - 1
                               && PIEZO_MV_Q_RING == PIEZO_MV_MAX_D + 1
                               && PIEZO_SUP_REF_RING >= PIEZO_MV_MAX_D) ? 1 : -1];

piezo_status piezo_diophantine(double a1, double a2, int d, double *e, double *g)
{
    return piezo_diophantine_observer(a1, a2, 0.0, d, e, g);
}

/* T = A E + z^-d Gd with T = 1 + t_1 z^-1, t_1 = -t (t_n = 0 for n >= 2):
 * e_0 = 1, e_n = t_n - a1 e_{n-1} - a2 e_{n-2} (n < d),
 * Gd = (t_d - a1 e_{d-1} - a2 e_{d-2}) + (t_{d+1} - a2 e_{d-1}) z^-1. */
piezo_status piezo_diophantine_observer(double a1, double a2, double t, int d, double *e, double *g)
{
    int n;
    double e_dm1, e_dm2;
    if (!e || !g) return PIEZO_ERR_NULL;
    if (d < 1 || d > PIEZO_MV_MAX_D) return PIEZO_ERR_PARAM;
    for (n = 0; n < d; ++n) {
        double e1 = n >= 1 ? e[n - 1] : 0.0;
        double e2 = n >= 2 ? e[n - 2] : 0.0;
        double t_n = n == 0 ? 1.0 : (n == 1 ? -t : 0.0);
        e[n] = t_n - a1 * e1 - a2 * e2;
    }
    e_dm1 = e[d - 1];
    e_dm2 = d >= 2 ? e[d - 2] : 0.0;
    g[0] = (d == 1 ? -t : 0.0) - (a1 * e_dm1 + a2 * e_dm2);
    g[1] = -a2 * e_dm1;
    return PIEZO_OK;
}

static double monitor_bound(const piezo_controller *c);

/* Whether the measured noise of y_meas has settled (from sample NOISE_SETTLE on): its measurement
 * starts at the first difference, which a reading that jumps from 0 (a stage held at 5 um from the
 * start, say) makes micrometres */
static int noise_settled(const piezo_controller *c)
{
    return c->k >= NOISE_SETTLE;
}

/* c^T theta - d of one row (> 0: theta violates it), in one fixed order */
static double admissible_excess(const double *row, double d, const double *th)
{
    return (((row[0] * th[0] + row[1] * th[1]) + row[2] * th[2]) + row[3] * th[3]) - d;
}

/* Whether theta violates a row of the admissible set (1) or is inside it (0). Once per update, so
 * each row is written out with its zero coefficients left out: the same products and sums in the
 * same order as admissible_excess, whose verdict (> 0) a dropped +-0 term cannot change. */
static int admissible_violated(const piezo_controller *c, const double *th)
{
    const double (*r)[4] = c->adm_c;
    const double *d = c->adm_d;
    const double a1 = th[0], a2 = th[1], b1 = th[2], b2 = th[3];
    return ((r[0][0] * a1 + r[0][1] * a2) - d[0] > 0.0) | ((r[1][0] * a1 + r[1][1] * a2) - d[1] > 0.0)
           | ((r[2][0] * a1 + r[2][1] * a2) - d[2] > 0.0) | ((r[3][2] * b1 + r[3][3] * b2) - d[3] > 0.0)
           | ((r[4][2] * b1 + r[4][3] * b2) - d[4] > 0.0) | (r[5][2] * b1 - d[5] > 0.0)
           | (r[6][2] * b1 - d[6] > 0.0)
           | ((((r[7][0] * a1 + r[7][1] * a2) + r[7][2] * b1) + r[7][3] * b2) - d[7] > 0.0)
           | ((((r[8][0] * a1 + r[8][1] * a2) + r[8][2] * b1) + r[8][3] * b2) - d[8] > 0.0);
}

/* q(k-i), i >= 1 */
static double q_past(const piezo_controller *c, int i)
{
    int at = c->head + i - 1;       /* head <= 9 and i <= d + 1 <= 10: below 2 rings */
    return c->q_ring[at < PIEZO_MV_Q_RING ? at : at - PIEZO_MV_Q_RING];
}

/* The projection of the paper's update and of the delay candidates: b1 positive, the zero of B
 * inside the radius, A inside the Jury triangle shrunk by m (coordinate clamps). The robust
 * update projects into its admissible set instead (admissible_project). */
static void project(const piezo_controller *c, double *th)
{
    const double m = A_STABILITY_MARGIN;
    double b1_floor = B1_FLOOR_FRACTION * c->theta_nominal[2];
    double a1_max;
    /* stable A (Jury triangle shrunk by m): clamp a2, then a1 given a2 */
    if (th[1] > 1.0 - m) th[1] = 1.0 - m;
    if (th[1] < -1.0 + m) th[1] = -1.0 + m;
    a1_max = 1.0 + th[1] - m;
    if (fabs(th[0]) > a1_max) th[0] = copysign(a1_max, th[0]);
    /* B: positive gain, zero inside the radius */
    if (th[2] < b1_floor) th[2] = b1_floor;
    if (fabs(th[3]) > ZERO_RADIUS_MAX * th[2]) th[3] = copysign(ZERO_RADIUS_MAX * th[2], th[3]);
}

/*
 * One sample is evaluated into a piezo_controller_sample (the caller's
 * storage) without changing the controller, then committed by copying the
 * few states it changed. A refusal after the input checks (overflow, or the
 * monitor's window) therefore needs no rollback, a peek is the evaluation
 * alone, and the saturation back-calculation re-evaluates from the untouched
 * state instead of keeping snapshots.
 */

/*
 * RLS with forgetting on y(k) = phi^T theta, phi = [-y(k-1), -y(k-2), q(k-d), q(k-d-1)]:
 *   e = y(k) - phi^T theta,  K = P phi / (lambda + phi^T P phi),
 *   theta += K e,  P = (P - (P phi)(P phi)^T / (lambda + phi^T P phi)) / lambda,
 *   trace(P) <= trace_max.
 * One division per sample: 1 / (lambda + phi^T P phi); 1/lambda is fixed
 * between samples (c->inv_forgetting, set at init). P stays bitwise symmetric
 * from the diagonal P0 on (a restored P that is not is refused,
 * piezo_controller_check): (P phi)_i (P phi)_j is the same product as
 * (P phi)_j (P phi)_i, so P_new[ij] = P_new[ji], and only the upper triangle
 * is computed (and scaled by the trace bound), then mirrored;
 * P phi = sum_j phi_j (row j of P), four-element rows the compiler vectorises.
 * The same update serves the chosen loop and each delay candidate: the
 * a-priori prediction error of (theta_in, P) under delay d; with update set,
 * the updated estimates and covariance go to theta, P_new (not P's storage).
 */
/* e = y - phi^T theta under delay d (the a-priori prediction error), in the order above */
static double rls_error(const piezo_controller *c, const double *theta, int d, double y)
{
    /* phi as four scalars, not an array: built from separate loads, an array
     * went through the stack and was read back as pairs, a store-to-load
     * forwarding stall on the loop's path from y(k) to the law */
    const double phi0 = -c->y_prev[0], phi1 = -c->y_prev[1];
    const double phi2 = q_past(c, d), phi3 = q_past(c, d + 1);
    double e = y;
    e -= phi0 * theta[0];
    e -= phi1 * theta[1];
    e -= phi2 * theta[2];
    e -= phi3 * theta[3];
    return e;
}

/* The update of (theta_in, P) by the a-priori error e under delay d, into theta, P_new (not P's
 * storage), the trace bounded; no projection (the caller's). */
static void rls_gain(const piezo_controller *c, const double *theta_in, const double *P, int d, double e,
                     double lambda, double inv_lambda, double trace_max, double *theta, double *P_new)
{
    const double phi0 = -c->y_prev[0], phi1 = -c->y_prev[1];
    const double phi2 = q_past(c, d), phi3 = q_past(c, d + 1);
    double Pphi[4], denom, inv_denom, trace, n00, n01, n02, n03, n11, n12, n13, n22, n23, n33;
    int i;
    /* (P phi)_i = sum_j P_ij phi_j in increasing j (from 0.0), P_ij read as P_ji (symmetric) */
    for (i = 0; i < 4; ++i)
        Pphi[i] = (((0.0 + P[i] * phi0) + P[4 + i] * phi1) + P[8 + i] * phi2) + P[12 + i] * phi3;
    denom = (((lambda + phi0 * Pphi[0]) + phi1 * Pphi[1]) + phi2 * Pphi[2]) + phi3 * Pphi[3];
    inv_denom = 1.0 / denom;
    for (i = 0; i < 4; ++i) theta[i] = theta_in[i] + Pphi[i] * inv_denom * e;
    /* the upper triangle j >= i (P_new is not P), the lower one its mirror image: P_ij = P_ji
     * and (P phi)_i (P phi)_j = (P phi)_j (P phi)_i, so its entries are these bits */
#define P_NEW(i, j) ((P[4 * (i) + (j)] - Pphi[i] * Pphi[j] * inv_denom) * inv_lambda)
    n00 = P_NEW(0, 0); n01 = P_NEW(0, 1); n02 = P_NEW(0, 2); n03 = P_NEW(0, 3);
    n11 = P_NEW(1, 1); n12 = P_NEW(1, 2); n13 = P_NEW(1, 3);
    n22 = P_NEW(2, 2); n23 = P_NEW(2, 3);
    n33 = P_NEW(3, 3);
#undef P_NEW
    trace = ((n00 + n11) + n22) + n33;
    if (trace > trace_max) {
        double scale = trace_max / trace;
        n00 *= scale; n01 *= scale; n02 *= scale; n03 *= scale;
        n11 *= scale; n12 *= scale; n13 *= scale;
        n22 *= scale; n23 *= scale;
        n33 *= scale;
    }
    P_new[0] = n00;  P_new[1] = n01;  P_new[2] = n02;  P_new[3] = n03;
    P_new[4] = n01;  P_new[5] = n11;  P_new[6] = n12;  P_new[7] = n13;
    P_new[8] = n02;  P_new[9] = n12;  P_new[10] = n22; P_new[11] = n23;
    P_new[12] = n03; P_new[13] = n13; P_new[14] = n23; P_new[15] = n33;
}

/*
 * The robust update's projection into the admissible set (admissible_rows), after its update:
 * sweeps over the rows, each violated one a projection onto its half-space in the metric of
 * P^-1 (Goodwin and Sin; Ioannou and Sun, parameter projection), which moves theta along the
 * directions the data determine least,
 *     theta -= P c (c^T theta - d) / (c^T P c),
 * then, if a sweep limit left a row violated, the step towards the nominal model (inside the
 * set) that ends on the set: theta = n + s (theta - n), s the least of
 * slack / (slack + excess) over the violated rows (slack = d - c^T n); where rounding leaves that
 * outside, s shrunk by RADIAL_SHRINK of itself in turn; only then the nominal model, with P as a
 * fallback's (docs/model.md, item 2: why, measured). 1 when theta changed.
 */
static const double RADIAL_SHRINK[5] = {0.0, 1e-12, 1e-9, 1e-6, 1e-3};
static int admissible_project(const piezo_controller *c, double *P, double *th)
{
    int sweep, i, j;
    if (!admissible_violated(c, th)) return 0;
    for (sweep = 0; sweep < ADMISSIBLE_SWEEPS; ++sweep) {
        int moved = 0;
        for (i = 0; i < PIEZO_ADMISSIBLE_ROWS; ++i) {
            const double *row = c->adm_c[i];
            double excess = admissible_excess(row, c->adm_d[i], th), Pc[4], cPc;
            if (!(excess > 0.0)) continue;
            for (j = 0; j < 4; ++j)
                Pc[j] = ((P[4 * j] * row[0] + P[4 * j + 1] * row[1]) + P[4 * j + 2] * row[2]) + P[4 * j + 3] * row[3];
            cPc = ((row[0] * Pc[0] + row[1] * Pc[1]) + row[2] * Pc[2]) + row[3] * Pc[3];
            if (!(cPc > 0.0 && isfinite(cPc))) {       /* P singular along c: the Euclidean metric */
                for (j = 0; j < 4; ++j) Pc[j] = row[j];
                cPc = ((row[0] * row[0] + row[1] * row[1]) + row[2] * row[2]) + row[3] * row[3];
            }
            for (j = 0; j < 4; ++j) th[j] -= Pc[j] * (excess / cPc);
            moved = 1;
        }
        if (!moved) break;
    }
    if (admissible_violated(c, th)) {
        const double *n = c->theta_nominal;
        double s = 1.0, out[4];
        for (i = 0; i < PIEZO_ADMISSIBLE_ROWS; ++i) {
            double excess = admissible_excess(c->adm_c[i], c->adm_d[i], th);
            if (excess > 0.0) {
                double slack = -admissible_excess(c->adm_c[i], c->adm_d[i], n);
                double ratio = slack / (slack + excess);
                if (ratio < s) s = ratio;
            }
        }
        memcpy(out, th, sizeof out);
        for (i = 0; i < 5 && (i == 0 || admissible_violated(c, th)); ++i)
            for (j = 0; j < 4; ++j) th[j] = n[j] + (s - s * RADIAL_SHRINK[i]) * (out[j] - n[j]);
        if (admissible_violated(c, th)) piezo_ctl_restart_estimates(c, th, P);
    }
    return 1;
}

/*
 * The chosen loop's RLS, given its a-priori prediction error e (of y - c for the robust
 * update); the updated theta and P go to *s when the update runs. The robust update (rls.robust) regresses
 * y - c on phi, updates only while the reference excites the loop
 * (s->excited, excitation_next), and bounds trace(P) by
 *     min(rls.trace_max, rls.variance_max / sigma_e^2),
 * sigma_e the measured noise of its prediction error: P sigma_e^2 is the covariance
 * of the estimates, and the bound keeps a noisy sensor from winding P up into
 * estimates that follow the noise (measured: a 1 Hz raster scan with a 20 nm
 * sensor burst to 59 um with rls.trace_max alone). While it holds its estimates,
 * c follows the prediction error (OFFSET_GAIN).
 */
static void rls_update(const piezo_controller *c, double e, piezo_controller_sample *s)
{
    double bound = c->trace_max;
    int may = c->rls_enabled && !(c->sat_hold > 0) && !s->outlier && !s->stale;
    s->offset = c->offset;
    s->projected = 0;
    if (!c->robust) {
        s->rls_updated = may;
        if (may) {
            rls_gain(c, c->theta, c->P, c->d, e, c->forgetting, c->inv_forgetting, c->trace_max, s->theta, s->P);
            project(c, s->theta);
        }
        return;
    }
    if (c->noise_e > 0.0) {
        double b = c->variance_max / (c->noise_e * c->noise_e);
        if (b < bound) bound = b;
    }
    /* no update while the sensor's noise is twice what buries the delay probes (above 60 nm rms with the
     * defaults): data that noisy do not identify the model, and the estimates fitted to them burst where the
     * nominal model tracks (on the stage's day with 200 nm sensors: a 10 um step after a 5 Hz tone erred
     * 18.5 um against 0.9 um fresh); a 20 nm sensor, whose measured noise passes 30 nm at times, adapts */
    s->rls_updated = may && s->excited
                     && !(noise_settled(c) && PROBE_SNR * c->noise_y2 > 2.0 * c->probe_max * c->theta_nominal[2]);
    if (s->rls_updated) {
        rls_gain(c, c->theta, c->P, c->d, e, c->forgetting, c->inv_forgetting, bound, s->theta, s->P);
        s->projected = admissible_project(c, s->P, s->theta);
    }
    if (may && !s->excited && !s->held) s->offset = c->offset + OFFSET_GAIN * e;
}

/* The measured noise after one more difference delta (NOISE_STEP): 0 until the first
 * nonzero difference, which starts it. */
static double noise_next(double m, double delta)
{
    double x = fabs(delta) * NOISE_SCALE;
    if (m == 0.0) return x > NOISE_FLOOR ? x : 0.0;
    m = x > m ? m * NOISE_STEP : m * (1.0 / NOISE_STEP);
    return m > NOISE_FLOOR ? m : NOISE_FLOOR;
}

/*
 * Whether the reference excites the loop at sample k (robust update): an excitation is a
 * reference r(k-1) that leaves the straight line through the last excitation (its value
 * there, advanced by its change per sample there) by more than rls.excitation times the
 * measured noise of y_meas (a move the sensor can see); the estimator updates at it and for
 * rls.excitation_time after it. A stage that holds still, or moves at a constant velocity,
 * teaches little but the noise: its estimates are held. A reference that stops (r(k-1) =
 * r(k-2)) stops the line there, so that the small velocity of a move's last excitation does
 * not carry the line away from a hold and call the hold an excitation later. (Measured: a 1 Hz, 10 um triangle
 * scan with a 20 nm sensor, a constant 20 um/s between its corners, drifted a1 from -1.38 to
 * -0.24 within 2 s when any change counted, and the next frame erred 6.2 um; with the line,
 * 52 nm.)
 */
static void excitation_next(const piezo_controller *c, double y_meas, piezo_controller_sample *s)
{
    const double r1 = c->r_last;            /* r(k-1), 0 before the first sample */
    const double line = c->r_anchor + c->r_velocity;
    const int still = r1 == c->r_last2;     /* the reference holds: the line does too */
    int event = fabs(r1 - line) > c->excitation * c->noise_y;
    s->noise_y = noise_next(c->noise_y, y_meas - c->y_prev[0]);
    s->r_anchor = event || still ? r1 : line;
    s->r_velocity = event || still ? r1 - c->r_last2 : c->r_velocity;
    s->excited = event || c->excite_left > 0;
    /* the sensor's noise, measured while the reference does not excite (at rest or on a straight
     * line: a move's start would set the tracker far above it, as a tone from t = 0 did at its first
     * acceleration, 200 samples later still burying the probes of a 1 nm sensor; and a master that
     * repeats y_ref makes "at rest" every other sample of a tone), from second differences: white
     * noise's has sqrt(3) times the rms of its first, a line's none */
    s->noise_y2 = !s->excited ? noise_next(c->noise_y2, (y_meas - 2.0 * c->y_prev[0] + c->y_prev[1]) * INV_SQRT3)
                              : c->noise_y2;
    s->excite_left = event ? c->excitation_samples : (c->excite_left > 0 ? c->excite_left - 1 : 0);
}

/*
 * Whether the delay probes are buried in the noise (robust update): the probe a trial needs to be
 * seen, PROBE_SNR times the measured noise of y_meas over the model's first response tf.b1, is
 * beyond mv.probe_max (with the defaults: a sensor noise above 30 nm rms), the noise measured from
 * the second differences of y_meas while the reference does not excite (noise_y2: at rest or on a
 * straight line, which a tone's start or a scan's corner does not inflate), from
 * sample NOISE_SETTLE on. Then a sample at rest teaches the detection nothing: its candidates score
 * only the reference's excitations (rls.excitation, for rls.excitation_time) and adapt only while
 * it moves, a leader must lead PIEZO_DETECT_CONFIRM_BURIED samples (in effect none is chosen: the
 * start-up law runs on), and the watchdog (sup.detect_time) does not count the wait
 * (docs/robustness.md, "Noisy sensors at start"). The measured noise, not the candidates' errors:
 * those hold the model's error too, and a stage far from the model would wait where its probes
 * decide within 62 ms.
 */
int piezo_controller_probes_buried(const piezo_controller *c)
{
    return c->robust && noise_settled(c) && PROBE_SNR * c->noise_y2 > c->probe_max * c->theta_nominal[2];
}

double piezo_controller_probe_snr(void) { return PROBE_SNR; }
double piezo_controller_monitor_bound(const piezo_controller *c) { return c ? monitor_bound(c) : 0.0; }

/* The detection state of k+1 when nothing is detected this sample (the
 * candidates' sums, estimates and covariances are not used then: neither
 * copied here nor committed). */
static void detect_carry(const piezo_controller *c, piezo_controller_sample *s)
{
    s->d = c->d;
    s->detecting = c->detecting;
    s->det_leader = c->det_leader;
    s->det_run = c->det_run;
    s->k_delay = c->k_delay;
    s->new_trial = 0;
    s->next_probe = 0.0;
    s->next_noise = c->det_noise;
}

/* The reference r(k) = y_d(k + d): the stamped preview for sample k + d when
 * this sample's input or the ring holds it, else y_ref. */
static double reference(const piezo_controller *c, const piezo_controller_input *in, int d, int *stamped)
{
    uint64_t want = c->k + (uint64_t)d;
    int slot = (int)(want % PIEZO_PREVIEW_RING);
    *stamped = 1;
    if (in->preview_lead == d)
        return in->y_preview;
    if (c->preview_tag[slot] == want + 1)
        return c->preview_value[slot];
    *stamped = 0;
    return in->y_ref;
}

int piezo_controller_preview(const piezo_controller *c, uint64_t sample, double *value)
{
    int slot;
    if (!c || !value) return 0;
    slot = (int)(sample % PIEZO_PREVIEW_RING);
    if (c->preview_tag[slot] != sample + 1) return 0;
    *value = c->preview_value[slot];
    return 1;
}

/* 1 when every x[i] is finite (piezo_simd.h: AVX where the CPU has it) */
static int all_finite(const double *x, int n)
{
    return piezo_all_finite(x, n);
}

/* The estimates, the covariance and the supervisor's next statistics and gain (an output:
 * szw / sww overflows where sww is tiny) of an evaluated sample are finite. The
 * operators' next states need no check of their own: each operator's output
 * is a finite-coefficient sum over its next states (SOE: sum c_i S_i; PI:
 * w0 u + sum w_i z_i), and an Inf or NaN state makes that sum Inf or NaN
 * (0 * Inf is NaN), so a finite output (checked where the operator runs) means
 * finite states. */
static int sample_state_finite(const piezo_controller *c, const piezo_controller_sample *s)
{
    /* the supervisor's next doubles, z .. clip_error_sum, are contiguous (set when it runs);
     * its gain szw / sww overflows where sww is tiny and szw huge (a restored state) */
    enum { SUP_DOUBLES = (offsetof(piezo_supervisor_next, clip_error_sum) - offsetof(piezo_supervisor_next, z))
                         / sizeof(double) + 1 };
    /* the block of the sample's doubles that a square or a difference of finite values overflows
     * (e^2 of a huge a-priori error, y(k) - y(k-1)), y_meas (for an outlier, the one it left) and the
     * estimates the law used: x * 0 is 0 for a finite x, NaN otherwise (all_finite's test, no call).
     * Not checked, since they cannot overflow: the weights err_weight and outlier_sum, the monitor's
     * sums (at most 1 / (1 - lambda)), the raw a-priori error (finite when err_sum is, or, for an
     * outlier, when the y_meas it left is) */
    double robust_zero = s->y_meas * 0.0 + (s->outlier ? s->y_meas + s->raw_error : 0.0) * 0.0;
    const double theta_zero = s->out.theta[0] * 0.0 + s->out.theta[1] * 0.0 + s->out.theta[2] * 0.0
                              + s->out.theta[3] * 0.0;
    int i;
#if defined(__GNUC__) && (__GNUC__ >= 8 || defined(__clang__))
#pragma GCC unroll 12   /* PIEZO_SAMPLE_CHECKED (asserted at the top: a pragma takes no macro) */
#endif
    for (i = 0; i < PIEZO_SAMPLE_CHECKED; ++i)
        robust_zero += (&s->noise_y)[i] * 0.0;
    return robust_zero + theta_zero == 0.0
           && (!c->sup.enabled || (all_finite(&s->sup.z, SUP_DOUBLES) && isfinite(s->sup.gain)))
           && (!s->rls_updated || all_finite(s->P, 16))
           && (!s->detecting || (all_finite(s->det_theta, PIEZO_DETECT_THETA)
                                 && all_finite(s->det_P, PIEZO_DETECT_P) && all_finite(s->det_score, PIEZO_DETECT_N)));
}

/* lambda of the outlier sums' window */
#define OUTLIER_FORGETTING (1.0 - 1.0 / PIEZO_OUTLIER_WINDOW)

/*
 * An outlier (a dropped or glitched reading): the a-priori error e of the law's model
 * (the loop's estimates, or the start-up law's nominal model while detecting) is beyond
 * PIEZO_OUTLIER_RATIO times the rms error of the accepted samples of the last
 * PIEZO_OUTLIER_WINDOW (E = sum lambda^(k-j) e(j)^2 over weight W = sum lambda^(k-j)),
 * |e| > R sqrt(E / W), and beyond PIEZO_OUTLIER_FLOOR_PERCENT % of monitor.pred_error_max,
 * while the PIEZO_OUTLIER_QUIET samples before were neither outliers nor beyond the monitor's bound and
 * outliers were fewer than PIEZO_OUTLIER_MAX_PERCENT % of that window. Only isolated
 * samples qualify: a fault goes on, and its second sample is judged as it comes. Not
 * while the delay is detected, but while it waits with its probes buried in the noise: the
 * start-up law's errors (a probe's answer) are the detection's evidence.
 */
static int is_outlier(const piezo_controller *c, double e, int buried)
{
    double a = fabs(e);
    return c->k - c->k_start >= PIEZO_OUTLIER_MIN_SAMPLES && (!c->detecting || buried)
           && c->quiet >= PIEZO_OUTLIER_QUIET
           && c->outlier_sum * 100.0 < PIEZO_OUTLIER_MAX_PERCENT * (double)PIEZO_OUTLIER_WINDOW
           && a * 100.0 > PIEZO_OUTLIER_FLOOR_PERCENT * c->pred_error_max
           && a * a * c->err_weight > (double)(PIEZO_OUTLIER_RATIO * PIEZO_OUTLIER_RATIO) * c->err_sum;
}

/* The outlier sums of k+1: an accepted sample adds its error, an outlier counts */
static void outlier_sums(const piezo_controller *c, piezo_controller_sample *s)
{
    const double lam = OUTLIER_FORGETTING;
    s->outlier_sum = lam * c->outlier_sum + (s->outlier ? 1.0 : 0.0);
    s->err_sum = s->outlier || s->stale ? c->err_sum : lam * c->err_sum + s->raw_error * s->raw_error;
    s->err_weight = s->outlier || s->stale ? c->err_weight : lam * c->err_weight + 1.0;
}

/*
 * The fallback to the nominal model (robust update, while the loop's estimator runs; docs/model.md, "Estimates
 * with guarantees", item 3), given the law's reference r = y_d(k + d) (without z), the measurement and the loop
 * model's a-priori error e_a of sample k. Three reasons, each judged only while the estimates differ from nominal:
 * - a jump: |r(k) - r(k-1)| beyond monitor.pred_error_max and beyond PIEZO_FALLBACK_JUMP_RATIO times the largest
 *   change per sample R the estimates learned on (R = max(|r(k) - r(k-1)|, R (1 - 1/PIEZO_FALLBACK_JUMP_MEMORY))
 *   over the samples they adapted at);
 * - a prediction over the window of rls.fallback_window (lambda = 1 - 1/N),
 *     S_a = lambda S_a + e_a^2,  S_n = lambda S_n + e_n^2,  e_n = y - c - phi^T theta_nominal,
 *   S_a > rls.fallback_ratio S_n + N (FALLBACK_NOISE noise_y)^2;
 * - one prediction: |e_a| beyond monitor.pred_error_max and PIEZO_FALLBACK_RINGING_NOISE noise_e (a 200 nm sensor's
 *   20 Hz tone: 203 errors past 1 um in 600 s, 5 past 5 noise_e, whose tracker a ringing outruns), outside a
 *   jump's answer (jump_left = 0): a loop that rings, before the window sees it. A fallback puts the nominal
 *   model and rls.p0_loop I in the estimator and the law of this very sample (*theta), empties the window, and
 *   counts the jump as learned.
 */
static void fallback_test(const piezo_controller *c, double r, double y_meas, double e_a, const double **theta,
                          piezo_controller_sample *s)
{
    double rate, faded;
    int reason = PIEZO_FALLBACK_NONE;
    s->fb_adapted = c->fb_adapted;
    s->fb_nominal = c->fb_nominal;
    s->learned_rate = c->learned_rate;
    s->fallback_value = s->fallback_other = 0.0;
    s->out.fallback = PIEZO_FALLBACK_NONE;
    if (!c->robust || c->detecting || s->detecting) return;
    rate = fabs(r - c->r_last);
    /* whether the law's estimates differ from the nominal model (asked only where it decides) */
#define ADAPTED (c->rls_enabled && memcmp(*theta, c->theta_nominal, sizeof c->theta) != 0)
    if (c->fallback_ratio > 0.0) {
        const double e_n = rls_error(c, c->theta_nominal, c->d, y_meas - c->offset);
        const double lambda = c->fallback_forgetting, floor_rms = FALLBACK_NOISE * c->noise_y, a = fabs(e_a);
        s->fb_adapted = lambda * c->fb_adapted + e_a * e_a;
        s->fb_nominal = lambda * c->fb_nominal + e_n * e_n;
        if (s->fb_adapted > c->fallback_ratio * s->fb_nominal
                            + (double)c->fallback_samples * (floor_rms * floor_rms) && ADAPTED) {
            reason = PIEZO_FALLBACK_PREDICTION;
            s->fallback_value = sqrt(s->fb_adapted / (double)c->fallback_samples);  /* the rms errors */
            s->fallback_other = sqrt(s->fb_nominal / (double)c->fallback_samples);
        }
        if (s->jump_left == 0 && a > c->pred_error_max && a > PIEZO_FALLBACK_RINGING_NOISE * c->noise_e && ADAPTED) {
            reason = PIEZO_FALLBACK_RINGING;
            s->fallback_value = a;
            s->fallback_other = fabs(e_n);
        }
    }
    if (rate > c->pred_error_max && rate > PIEZO_FALLBACK_JUMP_RATIO * c->learned_rate && ADAPTED) {
        reason = PIEZO_FALLBACK_JUMP;
        s->fallback_value = rate;
        s->fallback_other = c->learned_rate;
    }
#undef ADAPTED
    s->out.fallback = reason;
    if (reason != PIEZO_FALLBACK_NONE) {
        piezo_ctl_restart_estimates(c, s->theta, s->P);
        s->rls_updated = 1;
        s->projected = 0;
        *theta = c->theta_nominal;
        s->fb_adapted = s->fb_nominal = 0.0;
        s->learned_rate = rate;
    } else {
        /* every change the reference makes while these estimates run is learned: a jump's answer
         * follows it, and the excitation it is makes the estimator update on that answer; what
         * is learned fades as the estimator updates on other data */
        faded = s->rls_updated ? c->learned_rate * (1.0 - 1.0 / PIEZO_FALLBACK_JUMP_MEMORY) : c->learned_rate;
        s->learned_rate = rate > faded ? rate : faded;
    }
}

/* The monitor's bound on |pred_error|: monitor.pred_error_max, or PIEZO_MONITOR_NOISE times the
 * measured noise of y_meas (robust update; from its second differences at rest) when that is
 * larger, up to PIEZO_MONITOR_NOISE_CAP times monitor.pred_error_max, once the noise has settled
 * (noise_settled). The nominal model's one-step error carries a sensor's noise 1.75 times: a
 * 200 nm sensor's passed 1 um in 0.4 % of the samples. The cap: "noise" beyond 250 nm rms is a
 * fault's (y_meas alternating +-10 um measures as 23 um); docs/model.md, "A loop that diverges". */
static double monitor_bound(const piezo_controller *c)
{
    double b = PIEZO_MONITOR_NOISE * c->noise_y2, cap = PIEZO_MONITOR_NOISE_CAP * c->pred_error_max;
    if (!noise_settled(c)) return c->pred_error_max;
    if (b > cap) b = cap;
    return b > c->pred_error_max ? b : c->pred_error_max;
}

/* After a reset (sup.reset) the law's reference ramps from where the stage rested, y_start, to
 * y_d over sup.ramp_time's n samples: r(k) = y_start + (j + 1) / n (y_d(k + d) - y_start) for
 * j = k - k_start < n, so v ramps from 0 V as the law follows (a step of v would excite the
 * stage's resonance, as the safe state's own ramp to 0 V avoids) */
static double ramp_reference(const piezo_controller *c, double r)
{
    double f = (double)(c->k - c->k_start + 1) / (double)(c->k_ramp_end - c->k_start);
    return c->y_start + f * (r - c->y_start);
}

/* Evaluate sample k into *s without changing *c (the caller guarantees
 * finite inputs and enough history). Exact mode writes history[2k],
 * history[2k+1]. The inputs are finite, so a non-finite value computed on
 * the way means divergence. A run of large prediction errors that reaches
 * the divergence window is only marked (s->reaches_window): the commit
 * refuses it, a peek reports the values. */
static piezo_status loop_eval(const piezo_controller *c, const piezo_controller_input *in,
                              double *history, size_t capacity, piezo_controller_sample *s)
{
    double e[PIEZO_MV_MAX_D], g[2] = {0.0, 0.0}, f[PIEZO_MV_MAX_D + 1];
    double pred_error, numerator, q, r, v, t, bound, y_meas = in->y_meas;
    /* y_d(k), the reference the law took for sample k, and whether it was taken */
    const double yd_k = c->yd_value[c->k % PIEZO_MV_Q_RING];
    const int yd_taken = c->yd_tag[c->k % PIEZO_MV_Q_RING] == c->k + 1;
    const double *theta;
    piezo_status st;
    int i, d, stamped, saturated = 0, operators_finite, live;

    /* s->out: each member is set below (its padding is left as it is: the commit copies the
     * members, copy_output) */
    s->k = c->k;
    s->y_ref = in->y_ref;
    s->y_preview = in->y_preview;
    s->preview_lead = in->preview_lead;
    s->reaches_window = 0;
    s->restarted = 0;
    s->fault = 0;
    s->projected = 0;
    /* an outlier: the model's prediction stands in for the measurement in this sample */
    s->raw_error = rls_error(c, c->detecting ? c->theta_nominal : c->theta, c->d,
                             y_meas - (c->robust && !c->detecting ? c->offset : 0.0));
    /* a jump of the law's reference by more than the monitor's bound (a step y_d) is answered
     * within d + 1 samples: the large error it may bring then is the loop's, not a glitch (a
     * model drifted by a long tone fits itself back on it). Its answer is given 2 (d + 2)
     * samples: the large prediction errors of a 10 um step on 8 stages of the family with 20 and
     * 100 nm sensors, fresh and after a 5 Hz tone, came within 3 samples of the law's jump, and
     * are counted by the monitor but not said as a Warning (n_large_settled) */
    s->jump_left = fabs(c->r_last - c->r_last2) > c->pred_error_max ? 2 * ((uint64_t)c->d + 2)
                   : (c->jump_left > 0 ? c->jump_left - 1 : 0);
    /* a reading that repeats, to the bit, one taken for an outlier is one too (a sensor that died or
     * stuck on a glitch: the model's prediction keeps standing in, and the supervision names it once it
     * held PIEZO_SUP_STUCK_SAME samples) */
    /* the probes buried in the noise (judged once a sample, from the state the sample starts from) */
    s->clock = !piezo_controller_probes_buried(c);
    s->outlier = (s->jump_left == 0 && is_outlier(c, s->raw_error, !s->clock))
                 || (c->suspect && in->y_meas == c->suspect_y);
    /* a reading equal to the ones before for PIEZO_SUP_STUCK_SAME samples (the supervision's count, so
     * not while it is off) tells nothing new: the estimator's offset holds. Once a live sensor would
     * have changed it (piezo_supervisor_may_be_live) the integral action holds (below); and if it
     * reads the stage at its reference y_d(k), within the reading's floor, while the reference holds
     * (y_d(k + d) = y_d(k)), it is stale until either changes: the loop model's prediction stands in
     * for it, as for an outlier (robust update, d chosen). As it came, a reading stuck in a hold is
     * chased through the model's slow pole (A(1) small: y_ss - r = G(1) (r - y_s) / (A(1) E(1))): the
     * stage walked 0.22 um in 0.5 s behind a quiet sensor. A reading beyond the floor is chased (the
     * stage may have stopped short of the model: a noise-free one 0.9 um short after a 50 um move in
     * 0.1 s), and one while the reference moves (a live reading answers within d samples) */
    s->held = c->sup.enabled && c->sup.k > 0 && in->y_meas == c->sup.y1
              && c->sup.y_same + 1 >= PIEZO_SUP_STUCK_SAME;
    live = !s->held || piezo_supervisor_may_be_live(&c->sup, q_past(c, 1), q_past(c, 2), c->d);
    s->stale = !live && c->robust && !c->detecting && yd_taken && reference(c, in, c->d, &stamped) == yd_k
               && (c->stale || fabs(yd_k - in->y_meas) <= piezo_supervisor_reading_floor(&c->sup, c->noise_y2));
    if (s->outlier || s->stale)
        y_meas -= s->raw_error;
    s->y_meas = y_meas;
    if (c->robust) {
        excitation_next(c, y_meas, s);
    } else {
        s->noise_y = s->noise_y2 = 0.0;
        s->r_anchor = c->r_anchor;
        s->r_velocity = c->r_velocity;
        s->excite_left = 0;
        s->excited = 1;
    }
    /* the detection learns from this sample unless the stage rests (the reference does not
     * excite) while the noise asks for a probe beyond mv.probe_max, and its watchdog counts it
     * unless the noise asks for such a probe (the paper's update: every sample, both) */
    s->live = s->clock || s->excited;
    if (c->detecting) {
        s->offset = 0.0;
        pred_error = piezo_ctl_detect_update(c, y_meas, s);
    } else {
        /* the loop model's a-priori error is the outlier test's (computed once), unless the
         * model's prediction stood in for y_meas */
        pred_error = s->outlier || s->stale ? rls_error(c, c->theta, c->d, y_meas - (c->robust ? c->offset : 0.0))
                                            : s->raw_error;
        rls_update(c, pred_error, s);
        detect_carry(c, s);
    }
    s->noise_e = c->robust ? noise_next(c->noise_e, pred_error - c->out.pred_error) : 0.0;
    /* supervision of sample k: what the measurement did with the past outputs (an outlier as it
     * came: the first sample of a fault that goes on is evidence; a dropout only weakens it) */
    s->sup_in.y_meas = in->y_meas;
    s->sup_in.y_ref = in->y_ref;
    s->sup_in.q1 = q_past(c, 1);
    s->sup_in.q2 = q_past(c, 2);
    s->sup_in.v1 = c->out.v;
    s->sup_in.clipped1 = c->out.saturated;
    s->sup_in.clip_run = c->run_saturated;
    s->sup_in.clip_v = c->out.v;
    s->sup_in.error_bound = c->pred_error_max;
    s->sup_in.law_delay = s->d;
    s->sup_in.loop_delay = s->detecting ? 0 : s->d;
    s->sup_in.auto_delay = c->auto_delay;
    s->sup_in.noise = s->noise_y2;
    s->sup_in.bridged = s->outlier;
    s->sup_in.bridged_error = s->raw_error;
    /* the search for the loop delay lasts from its start until a chosen d holds: a loop whose
     * choices are undone within PIEZO_DETECT_HELD samples is still searching (a measurement
     * that alternates whatever v does restarted the detection 166 times in 10 s, each search
     * shorter than sup.detect_time, and was never stopped) */
    s->sup_in.detecting_for = s->detecting ? c->det_clock + (uint64_t)s->clock : 0;
    piezo_supervisor_evaluate(&c->sup, &s->sup_in, &s->sup);

    /* the law: the start-up law (nominal model, d = 2, t = 0.9) while detecting,
     * else the loop's estimates, d and observer */
    d = s->d;
    theta = s->detecting ? c->theta_nominal : (s->rls_updated ? s->theta : c->theta);
    t = s->detecting ? START_OBSERVER : c->observer;
    r = reference(c, in, d, &stamped);
    if (c->k < c->k_ramp_end) r = ramp_reference(c, r);
    fallback_test(c, r, y_meas, pred_error, &theta, s);
    /* integral action (mv.integral): z(k) = z(k-1) + gamma (y_d(k) - y_meas(k)), y_d(k) the
     * reference the law took for sample k (its r(j) is y_d(j + d), kept by sample, so a
     * change of d while detecting leaves no misaligned sample); held while detecting, while a
     * clipped sample pauses the adaptation (anti-windup), when no reference for sample k
     * was taken, and on a held reading a live sensor would have changed (live, above; the
     * paper's law too). Before that it acts: a noise-free reading that has not crossed its grid
     * carries the error (held at once on 4 equal samples, noise-free holds stayed 32 nm off) */
    s->r_plain = r;
    s->integral = c->integral;
    if (c->integral_gain > 0.0 && !s->detecting && c->sat_hold == 0 && yd_taken && live)
        s->integral = c->integral + c->integral_gain * (yd_k - y_meas);
    if (c->integral_gain > 0.0) r += s->integral;   /* (r + 0 would turn a -0 reference into +0) */

    /* Diophantine with the current estimate; F = B E: f_n = b1 e_n + b2 e_{n-1}
     * (e_{-1} = e_d = 0, multiplied as any other: b * 0 is -0 for a negative b) */
    piezo_diophantine_observer(theta[0], theta[1], t, d, e, g);
    f[0] = theta[2] * e[0] + theta[3] * 0.0;
    for (i = 1; i < d; ++i) f[i] = theta[2] * e[i] + theta[3] * e[i - 1];
    f[d] = theta[2] * 0.0 + theta[3] * e[d - 1];

    /* MV: T y(k+d) = Gd y(k) + F q(k) := T r(k), weighted by lambda_u */
    numerator = (r - t * c->r_prev) - g[0] * y_meas - g[1] * c->y_prev[0];
    for (i = 1; i <= d; ++i) numerator -= f[i] * q_past(c, i);
    q = f[0] * numerator / (f[0] * f[0] + c->lambda_u);
    /* the probe doublet on the first two samples of a detection trial */
    s->probe = 0.0;
    if (s->detecting && c->k - c->det_trial < 2)
        s->probe = c->k == c->det_trial ? c->det_probe : -c->det_probe;
    q += s->probe;
    s->r = r;
    s->out.delay = s->detecting ? 0 : d;
    s->out.preview = stamped;

    /* feedforward: inverse creep, then inverse PI */
    st = piezo_gl_eval(&c->inv_creep, q, history, capacity, &r);
    if (st != PIEZO_OK) return st == PIEZO_ERR_NONFINITE ? PIEZO_ERR_DIVERGED : st;
    st = piezo_pi_inverse_eval(&c->inv_pi, r, s->inv_z, &v);
    if (st != PIEZO_OK) return st == PIEZO_ERR_NONFINITE ? PIEZO_ERR_DIVERGED : st;

    if (c->sat_enabled && (v > c->sat_v_max || v < c->sat_v_min)) {
        /* Back-calculate what the plant model really receives at the clipped
         * voltage, so the operator memories and the MV past stay consistent:
         * r_eff = P[v_sat], q_eff from r_eff = gain (q_eff + memory). The
         * operators are re-evaluated from the committed (untouched) state. */
        double r_eff, memory, v_resync;
        saturated = 1;
        v = v > c->sat_v_max ? c->sat_v_max : c->sat_v_min;
        piezo_pi_eval(&c->fwd_pi, v, s->fwd_z, &r_eff);
        st = piezo_pi_inverse_eval(&c->inv_pi, r_eff, s->inv_z, &v_resync);  /* re-sync the inverse states */
        if (st != PIEZO_OK) return PIEZO_ERR_DIVERGED;
        piezo_gl_eval(&c->inv_creep, 0.0, history, capacity, &memory);
        q = (r_eff - memory) / c->inv_creep.gain;
        st = piezo_gl_eval(&c->inv_creep, q, history, capacity, &r);
        if (st != PIEZO_OK) return PIEZO_ERR_DIVERGED;
        operators_finite = isfinite(r_eff) && isfinite(v_resync) && isfinite(r);
        /* no adaptation until the clipped sample leaves the regressor (while
         * detecting, the longest candidate's) */
        s->sat_hold = (s->detecting ? PIEZO_DETECT_N : d) + 1;
    } else {
        piezo_pi_eval(&c->fwd_pi, v, s->fwd_z, &r);
        operators_finite = isfinite(r);   /* v is checked below; r of the inverse creep made it */
        s->sat_hold = c->sat_hold > 0 ? c->sat_hold - 1 : c->sat_hold;
    }

    /* While a clipped sample pauses adaptation the estimates are frozen, and an
     * estimate adapted to a measurement that is no stage's response (one that
     * alternates, say) can predict it well: the monitor then also judges the
     * nominal model's prediction error, A y(k) - B q(k-d), which a working loop
     * keeps small while clipped (at most 0.13 um on the saturation family). */
    bound = monitor_bound(c);
    s->large_error = fabs(s->stale ? s->raw_error : pred_error) > bound;   /* a stale reading's as it came */
    if (c->sat_hold > 0 && !s->large_error) {
        /* A y(k) on the controller's own past (the supervisor's z, same operands and order,
         * but computed here: a switched-off supervisor computes nothing) */
        double a_y = y_meas + c->theta_nominal[0] * c->y_prev[0] + c->theta_nominal[1] * c->y_prev[1];
        s->large_error = fabs(a_y - (c->theta_nominal[2] * q_past(c, d) + c->theta_nominal[3] * q_past(c, d + 1)))
                         > bound;
    }
    s->run_large_error = s->large_error ? c->run_large_error + 1 : 0;
    /* a chosen loop whose prediction error stays beyond the bound since the
     * choice goes back to detection (from the next sample) */
    s->restarted = c->auto_delay && !s->detecting && s->run_large_error >= PIEZO_DETECT_REDETECT
                   && c->k + 1 - s->k_delay >= PIEZO_DETECT_REDETECT;
    s->out.v = v;
    s->out.q = q;
    memcpy(s->out.theta, theta, sizeof s->out.theta);
    s->out.pred_error = s->outlier || s->stale ? s->raw_error : pred_error;   /* a bridged one's as it came */
    s->out.saturated = saturated;
    s->out.adapting = s->rls_updated && !s->detecting;
    s->out.noise = s->noise_y;
    outlier_sums(c, s);
    /* every output (the estimates too) and the state the sample leaves behind are finite,
     * or the sample is refused: the RLS covariance can overflow (phi P phi^T) while theta
     * stays finite, and the operators' next states are what the next sample starts from */
    if (!(isfinite(v) && isfinite(q) && isfinite(pred_error) && operators_finite) || !sample_state_finite(c, s))
        return PIEZO_ERR_DIVERGED;
    /* the monitor: a run of the window, or a quarter of the window's samples (a loop
     * that restarts its detection between runs, or oscillates between the limits).
     * The share is of the whole window, N = monitor.divergence_samples samples, the
     * weight sum_j lambda^j = 1 / (1 - lambda) = N of a full one:
     *     S(k) = lambda S(k-1) + [|e(k)| > bound],   refused when S(k) >= N / 4,
     * so that the start-up transient of a stage far from the model (its first 30
     * samples beyond the bound, say) is a share of N, not of the samples seen so
     * far: a run of errors trips it after ln(3/4) / ln(lambda) = 58 samples of N = 200,
     * errors in every other sample at sample 137. */
    s->mon_share = c->mon_forgetting * c->mon_share + (s->large_error ? 1.0 : 0.0);
    s->mon_weight = c->mon_forgetting * c->mon_weight + 1.0;
    s->reaches_window = c->divergence_samples > 0
                        && (s->run_large_error >= c->divergence_samples
                            || (c->k - c->k_start >= PIEZO_MONITOR_SHARE_MIN_SAMPLES
                                && s->mon_share * 100.0
                                   >= PIEZO_MONITOR_SHARE_PERCENT * (double)c->divergence_samples));
    return PIEZO_OK;
}

/* v of the safe state j samples after the verdict: the ramp from v0 to 0 V over the
 * sup.ramp_time samples n, v(k_f + j) = v0 (n - 1 - j) / n, then 0 V. */
static double safe_v(const piezo_controller *c, double v0, uint64_t j)
{
    uint64_t n = c->sup.ramp_samples;
    return j + 1 >= n ? 0.0 : v0 * ((double)(n - 1 - j) / (double)n);
}

/* A sample of the safe state: nothing of the loop is evaluated (its state stays that of the
 * verdict's sample: no law, no adaptation, no supervision); v ramps to 0 V and stays. */
static void safe_sample(const piezo_controller *c, const piezo_controller_input *in, int fault,
                        piezo_controller_sample *s)
{
    double v0 = c->fault ? c->v_fault : c->out.v;
    uint64_t j = c->fault ? c->k - c->k_fault : 0;
    /* the verdict's sample keeps the supervision's evidence for the commit (its message) */
    piezo_supervisor_input sup_in;
    piezo_supervisor_next sup;
    if (!c->fault) {
        sup_in = s->sup_in;
        sup = s->sup;
    }
    memset(s, 0, sizeof *s);
    if (!c->fault) {
        s->sup_in = sup_in;
        s->sup = sup;
    }
    s->k = c->k;
    s->y_ref = in->y_ref;
    s->y_meas = in->y_meas;
    s->y_preview = in->y_preview;
    s->preview_lead = in->preview_lead;
    s->reaches_window = 0;
    s->restarted = 0;
    s->fault = fault;
    s->out.v = safe_v(c, v0, j);
    memcpy(s->out.theta, c->theta, sizeof s->out.theta);
    s->out.delay = c->out.delay;
}

/* The code of the verdict an evaluated sample (status st) reaches, 0 for none: the monitor's,
 * the supervision's, or a value not finite. */
static int verdict_code(const piezo_controller_sample *s, piezo_status st)
{
    if (st == PIEZO_ERR_DIVERGED) return PIEZO_SUP_DIVERGED;
    if (st != PIEZO_OK) return 0;
    if (s->reaches_window) return PIEZO_SUP_UNSTABLE;
    return s->sup.fault;
}

/* Evaluate sample k: in the safe state, its ramp; else the loop, and with sup.reaction = safe
 * a verdict turns the sample into the safe state's first (the commit enters it). */
static piezo_status controller_eval(const piezo_controller *c, const piezo_controller_input *in,
                                    double *history, size_t capacity, piezo_controller_sample *s)
{
    piezo_status st;
    int code;
    if (c->fault) {
        safe_sample(c, in, c->fault, s);
        return PIEZO_OK;
    }
    st = loop_eval(c, in, history, capacity, s);
    if (c->sup.reaction == PIEZO_SUP_REACT_SAFE && (code = verdict_code(s, st)) != 0) {
        /* the supervision's evidence stays in s (sup_in, sup) for the commit's verdict */
        safe_sample(c, in, code, s);
        return PIEZO_OK;
    }
    return st;
}

/* The delay detection's and the preview ring's part of a commit (c->k is
 * still the sample's). */
static void commit_timing(piezo_controller *c, const piezo_controller_sample *s)
{
    if (s->preview_lead >= 1 && s->preview_lead < PIEZO_PREVIEW_RING) {
        uint64_t at = c->k + (uint64_t)s->preview_lead;
        int slot = (int)(at % PIEZO_PREVIEW_RING);
        c->preview_value[slot] = s->y_preview;
        c->preview_tag[slot] = at + 1;
    }
    c->d = s->d;
    c->detecting = s->detecting;
    c->det_leader = s->det_leader;
    c->det_run = s->det_run;
    c->k_delay = s->k_delay;
    if (c->detecting) {
        memcpy(c->det_score, s->det_score, sizeof c->det_score);
        memcpy(c->det_theta, s->det_theta, sizeof c->det_theta);
        memcpy(c->det_P, s->det_P, sizeof c->det_P);
    }
    if (s->new_trial) {
        int i;
        c->det_trial = c->k + 1;
        c->det_noise = s->next_noise;
        c->det_probe = s->next_probe;
        c->det_probes += s->next_probe > 0.0;
        c->det_leader = -1;
        c->det_run = 0;
        for (i = 0; i < PIEZO_DETECT_N; ++i) c->det_score[i] = 0.0;
    }
}

/* *to = *from member by member, every member of piezo_controller_output (a new one is set in
 * loop_eval and safe_sample and copied here): the padding of *to stays as it was (zero from
 * init: FMU states are hashed bytewise), whatever an evaluated sample's holds (loop_eval sets
 * the members only) */
static void copy_output(piezo_controller_output *to, const piezo_controller_output *from)
{
    to->v = from->v;
    to->q = from->q;
    memcpy(to->theta, from->theta, sizeof to->theta);
    to->pred_error = from->pred_error;
    to->saturated = from->saturated;
    to->delay = from->delay;
    to->preview = from->preview;
    to->adapting = from->adapting;
    to->noise = from->noise;
    to->fallback = from->fallback;
}

/* Make the evaluated sample k the controller's state (k -> k+1). */
static void controller_commit(piezo_controller *c, const piezo_controller_sample *s)
{
    double q = s->out.q, y_meas = s->y_meas;
    if (s->rls_updated) {
        memcpy(c->theta, s->theta, sizeof c->theta);
        memcpy(c->P, s->P, sizeof c->P);
    }
    piezo_gl_commit(&c->inv_creep, q);
    memcpy(c->inv_pi.z, s->inv_z, (size_t)c->inv_pi.m * sizeof *s->inv_z);
    memcpy(c->fwd_pi.z, s->fwd_z, (size_t)c->fwd_pi.m * sizeof *s->fwd_z);
    c->sat_hold = s->sat_hold;

    /* monitor: counts and current runs of clipped samples and large errors */
    if (s->out.saturated) {
        if (c->n_saturated == 0) c->k_first_saturated = c->k;
        c->n_saturated += 1;
        c->run_saturated += 1;
    } else {
        c->run_saturated = 0;
    }
    if (s->large_error) {
        if (c->n_large_error == 0) c->k_first_large_error = c->k;
        c->n_large_error += 1;
        if (s->jump_left == 0) {
            if (c->n_large_settled == 0) c->k_first_large_settled = c->k;
            c->n_large_settled += 1;
        }
    }
    c->run_large_error = s->run_large_error;
    c->mon_share = s->mon_share;
    c->mon_weight = s->mon_weight;
    if (fabs(s->out.pred_error) > c->max_abs_pred_error) c->max_abs_pred_error = fabs(s->out.pred_error);
    /* outliers: the sums; one is counted (and said) once the sample after it is within the bound
     * again (a reading that went back: not the first sample of a change that goes on) */
    c->err_sum = s->err_sum;
    c->err_weight = s->err_weight;
    c->outlier_sum = s->outlier_sum;
    c->quiet = s->outlier || s->large_error ? 0 : c->quiet + 1;
    if (c->suspect && !s->large_error) {
        if (c->n_outliers == 0) {
            c->k_first_outlier = c->k - 1;
            c->first_outlier = c->suspect_y;
            c->first_outlier_error = c->suspect_error;
        }
        c->n_outliers += 1;
    }
    c->suspect = s->outlier;
    c->stale = s->stale;
    c->suspect_y = s->outlier ? s->sup_in.y_meas : 0.0;
    c->suspect_error = s->outlier ? s->raw_error : 0.0;

    /* shift the pasts (an outlier's: the prediction that stood in for it) */
    c->head = c->head == 0 ? PIEZO_MV_Q_RING - 1 : c->head - 1;
    c->q_ring[c->head] = q;
    {
        uint64_t at = c->k + (uint64_t)s->d;        /* r(k) is y_d(k + d) */
        c->yd_value[at % PIEZO_MV_Q_RING] = s->r_plain;
        c->yd_tag[at % PIEZO_MV_Q_RING] = at + 1;
    }
    c->r_last2 = c->r_last;
    c->r_last = s->r_plain;
    c->r_velocity = s->r_velocity;
    c->integral = s->integral;
    c->offset = s->offset;
    c->noise_y = s->noise_y;
    c->noise_y2 = s->noise_y2;
    c->noise_e = s->noise_e;
    c->r_anchor = s->r_anchor;
    c->excite_left = s->excite_left;
    c->jump_left = s->jump_left;
    c->fb_adapted = s->fb_adapted;
    c->fb_nominal = s->fb_nominal;
    c->learned_rate = s->learned_rate;
    c->n_projections += (uint64_t)s->projected;
    if (s->out.fallback != PIEZO_FALLBACK_NONE) {
        if (c->n_fallbacks == 0) {
            c->k_first_fallback = c->k;
            c->first_fallback = s->out.fallback;
            c->first_fallback_value = s->fallback_value;
            c->first_fallback_other = s->fallback_other;
        }
        c->n_fallbacks += 1;
    }
    c->y_prev[1] = c->y_prev[0];
    c->y_prev[0] = y_meas;
    c->r_prev = s->r;
    commit_timing(c, s);
    c->det_clock += (uint64_t)s->clock;
    c->k += 1;
    copy_output(&c->out, &s->out);
    piezo_supervisor_commit(&c->sup, &s->sup_in, &s->sup, s->r);
    if (s->restarted) {
        if (c->k - c->k_delay >= PIEZO_DETECT_HELD) {
            c->k_search = c->k;
            c->det_clock = 0;
        }
        piezo_ctl_detection_start(c);
        c->k_delay = c->k;
    }
}

/* Refusals that must leave the state untouched, checked before any work. */
static piezo_status check_step_inputs(const piezo_controller *c, const piezo_controller_input *in,
                                      const double *history, size_t capacity)
{
    if (!(isfinite(in->y_ref) && isfinite(in->y_meas))) return PIEZO_ERR_NONFINITE;
    if (in->preview_lead != 0 && !isfinite(in->y_preview)) return PIEZO_ERR_NONFINITE;
    if (in->preview_lead < 0 || in->preview_lead >= PIEZO_PREVIEW_RING) return PIEZO_ERR_PARAM;
    if (c->inv_creep.exact) {
        if (!history) return PIEZO_ERR_NULL;
        if (capacity < piezo_controller_history_needed(c)) return PIEZO_ERR_CAPACITY;
    }
    return PIEZO_OK;
}

/* The inputs of a sample without a stamped preview. */
static piezo_controller_input plain_input(double y_ref, double y_meas)
{
    piezo_controller_input in;
    in.y_ref = y_ref;
    in.y_meas = y_meas;
    in.y_preview = 0.0;
    in.preview_lead = 0;
    return in;
}

piezo_status piezo_controller_evaluate(const piezo_controller *c, const piezo_controller_input *in,
                                       double *history, size_t capacity, piezo_controller_sample *sample)
{
    piezo_status st;
    if (!c || !in || !sample) return PIEZO_ERR_NULL;
    st = check_step_inputs(c, in, history, capacity);
    if (st != PIEZO_OK) return st;
    return controller_eval(c, in, history, capacity, sample);
}

/* The supervision's verdict on an evaluated sample into c->verdict, with what the delay
 * detection knows of the noise when no delay was found. */
static void record_verdict(piezo_controller *c, const piezo_controller_sample *s)
{
    piezo_sup_verdict *v = &c->verdict;
    piezo_supervisor_verdict(&c->sup, &s->sup_in, &s->sup, v);
    if (v->fault == PIEZO_SUP_UNDETECTED) {
        v->noise = c->det_noise;
        v->probe = c->det_probe;
        v->probe_gain = c->theta_nominal[2];
        v->probe_snr = PROBE_SNR;
        v->probe_wanted = PROBE_SNR * c->det_noise / c->theta_nominal[2];
        v->probe_max = c->probe_max;
        v->probes = c->det_probes;
        v->reversal_share = s->sup.weight > 0.0 ? s->sup.reversals / s->sup.weight : 0.0;
        v->step_rms = s->sup.weight > 0.0 ? sqrt(s->sup.steps2 / s->sup.weight) : 0.0;
    }
}

/* Enter the safe state with the evaluated verdict's sample (sup.reaction = safe), or take
 * one more of its samples: the loop's state stays that of the verdict's sample. */
static void safe_commit(piezo_controller *c, const piezo_controller_sample *s)
{
    if (!c->fault) {
        if (s->fault <= PIEZO_SUP_FROZEN)
            record_verdict(c, s);
        c->fault = s->fault;
        c->k_fault = c->k;
        c->v_fault = c->out.v;
        c->y_fault = isfinite(s->y_meas) ? s->y_meas : 0.0;
        c->y_moved = 0;
    } else if (s->y_meas != c->y_fault) {
        c->y_moved = 1;
    }
    c->k += 1;
    c->out = s->out;
}

/* Commit an evaluated sample, or refuse it: the divergence monitor's window reached
 * (PIEZO_ERR_UNSTABLE), or a supervision verdict (PIEZO_ERR_FAULT, recorded in c->verdict);
 * a refused sample commits nothing of the loop. A sample of the safe state commits. */
static piezo_status commit_or_refuse(piezo_controller *c, const piezo_controller_sample *s,
                                     piezo_controller_output *out)
{
    if (s->fault) {
        safe_commit(c, s);
        if (out) *out = c->out;
        return PIEZO_OK;
    }
    if (s->reaches_window) return PIEZO_ERR_UNSTABLE;
    if (s->sup.fault) {
        record_verdict(c, s);
        return PIEZO_ERR_FAULT;
    }
    controller_commit(c, s);
    if (out) *out = c->out;
    return PIEZO_OK;
}

piezo_status piezo_controller_commit(piezo_controller *c, const piezo_controller_sample *sample,
                                     piezo_controller_output *out)
{
    if (!c || !sample) return PIEZO_ERR_NULL;
    if (sample->k != c->k) return PIEZO_ERR_PARAM;
    return commit_or_refuse(c, sample, out);
}

/* evaluate + commit, without the exported entry points (no PLT in the hot path) */
piezo_status piezo_controller_step_input(piezo_controller *c, const piezo_controller_input *in,
                                         double *history, size_t capacity, piezo_controller_output *out)
{
    piezo_controller_sample s;
    piezo_status st;
    if (!c || !in) return PIEZO_ERR_NULL;
    st = check_step_inputs(c, in, history, capacity);
    if (st == PIEZO_OK) st = controller_eval(c, in, history, capacity, &s);
    if (st != PIEZO_OK) return st;
    return commit_or_refuse(c, &s, out);
}

piezo_status piezo_controller_step(piezo_controller *c, double y_ref, double y_meas,
                                   double *history, size_t capacity, piezo_controller_output *out)
{
    piezo_controller_input in = plain_input(y_ref, y_meas);
    return piezo_controller_step_input(c, &in, history, capacity, out);
}

piezo_status piezo_controller_peek(const piezo_controller *c, double y_ref, double y_meas,
                                   double *history, size_t capacity, piezo_controller_output *out)
{
    piezo_controller_sample s;
    piezo_controller_input in = plain_input(y_ref, y_meas);
    piezo_status st;
    if (!c || !out) return PIEZO_ERR_NULL;
    st = piezo_controller_evaluate(c, &in, history, capacity, &s);
    if (st == PIEZO_OK) *out = s.out;
    return st;
}

/* The sample's helpers for the controller's other files (piezo_controller_internal.h) */
double piezo_ctl_rls_error(const piezo_controller *c, const double *theta, int d, double y)
{
    return rls_error(c, theta, d, y);
}

void piezo_ctl_rls_gain(const piezo_controller *c, const double *theta_in, const double *P, int d, double e,
                        double lambda, double inv_lambda, double trace_max, double *theta, double *P_new)
{
    rls_gain(c, theta_in, P, d, e, lambda, inv_lambda, trace_max, theta, P_new);
}

void piezo_ctl_project(const piezo_controller *c, double *th) { project(c, th); }
void piezo_ctl_detect_carry(const piezo_controller *c, piezo_controller_sample *s) { detect_carry(c, s); }
int piezo_ctl_all_finite(const double *x, int n) { return all_finite(x, n); }
double piezo_ctl_admissible_excess(const double *row, double d, const double *th)
{
    return admissible_excess(row, d, th);
}
int piezo_ctl_admissible_violated(const piezo_controller *c, const double *th) { return admissible_violated(c, th); }
double piezo_ctl_safe_v(const piezo_controller *c, double v0, uint64_t j) { return safe_v(c, v0, j); }
