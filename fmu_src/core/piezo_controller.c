/* piezo_controller.c - adaptive compound controller. See piezo_controller.h. */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "piezo_controller.h"
#include "piezo_plant.h"

/* Projection bounds (docs/model.md, controller): b1 stays positive, the zero of B
 * stays inside the unit circle so that MV, which inverts B, stays stable. */
#define B1_FLOOR_FRACTION 1e-3  /* b1 >= 1e-3 * nominal b1 */
#define ZERO_RADIUS_MAX 0.999   /* |b2 / b1| <= 0.999 */
/* The estimated A stays stable with a margin: A(1) = 1 + a1 + a2 >= m,
 * A(-1) = 1 - a1 + a2 >= m, |a2| <= 1 - m. Without it a single tone lets
 * (a1, a2) wander along the unexcited directions; with the documented -10 % PI
 * weights the loop then diverged (a1, a2 -> 1e12 within 0.6 s). m is 50x
 * below the nominal A(1) = 0.0049, so every plausible stage fits inside. */
#define A_STABILITY_MARGIN 1e-4
/* Observer pole t of T = 1 - t z^-1 (docs/model.md, controller): the
 * measurement noise reaches y through Gd / T, whose norm falls from 1.6 (t = 0)
 * to 0.96 (t = 0.4) for d = 2. With the paper's update, measured on the mismatch
 * case (six scenarios, d = 1, 2, 3, four sensor seeds), t = 0.4 had the lowest
 * median e_rms and t = 0.5 raised the worst case (2.83 nm against 2.65). With the
 * robust update (six scenarios, d = 2 and 3, four seeds: 48 runs) t = 0.4, 0.5,
 * 0.6 give medians 0.81, 0.69, 0.59 nm and worst cases 2.03, 1.98, 2.06 nm:
 * 0.5 has the lowest worst case. The paper's law keeps 0.4. */
#define DEFAULT_OBSERVER 0.5
/* The start-up law while the delay is detected: the nominal model, d = 2 and
 * t = 0.9. Its closed loop is stable for a loop delay of 1, 2 or 3 samples,
 * also with the mismatch case's plant and gains from 0.6 to 1.5 times the
 * model's (roots in docs/cosimulation.md); t = 0 (plain MV) is unstable for
 * every wrong d. */
#define START_OBSERVER 0.9
/* A candidate is chosen when its sum of squared a-priori errors is at most
 * DETECT_RATIO times every other candidate's, for PIEZO_DETECT_CONFIRM
 * consecutive samples. */
#define DETECT_RATIO (1.0 / PIEZO_DETECT_RATIO_INV)
/* A trial of PIEZO_DETECT_TRIAL samples that chooses nothing is followed by
 * one that starts with a probe: the doublet +p, -p added to q on its first two
 * samples. Its first response, b1 p, is PROBE_SNR times the rms a-priori
 * error of the best candidate in the trial before (noise and model error),
 * p within [PROBE_MIN, mv.probe_max] um (default 1 um; 0: no probe); each
 * further trial doubles it. After PIEZO_DETECT_PROBES probes a detection
 * probes no more (a measurement that never answers, e.g. a controller driven
 * open loop): its trials go on, and a kink of the reference can still decide. */
#define PROBE_SNR 20.0
#define PROBE_MIN 1e-3
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
/* samples the measured noise takes to forget the start: a loop's first samples (a tone from t = 0,
 * its transient) start the tracker far above the sensor's noise, and it steps down by NOISE_STEP */
#define NOISE_SETTLE 100
/* While the estimates are held (no excitation), the estimator's offset c follows its
 * prediction error: c += OFFSET_GAIN e, a time constant of 1 / OFFSET_GAIN = 100 samples.
 * Creep and the integral action move the stage's operating point while it holds still; c
 * keeps the regression y - c = phi^T theta consistent with it, so the first samples of the
 * next move do not teach theta the offset the hold built up (measured: a 30 um S-curve after
 * 600 s at 10 um, 7x the error after 0.2 s without c, 1.2x with it). */
#define OFFSET_GAIN 0.01
/* With the robust update the delay candidates keep the tuning the detection was designed and
 * measured with (docs/cosimulation.md): forgetting 0.995, trace bound 100 (the loop's own
 * rls.forgetting and rls.trace_max are the robust update's; with the paper's update the
 * candidates use them, as before). With the loop's 0.99 and 1000 the candidates learn a
 * measurement that alternates +-10 um whatever v does so well that the divergence monitor
 * no longer stops it (measured: not within 3000 samples; 86 with 0.995 and 100). */
#define DETECT_FORGETTING 0.995
#define DETECT_TRACE_MAX 100.0
/* The admissible set's projection (docs/model.md, "Estimates with guarantees"): sweeps of
 * P-metric half-space projections over the violated rows, then a radial step towards the
 * nominal model (inside the set) that ends inside it whatever the sweeps left. */
#define ADMISSIBLE_SWEEPS 8
/* The fallback's prediction test counts only beyond this many times the measured noise of
 * y_meas (per sample, over the window): two models that both predict within the noise are
 * not told apart. */
#define FALLBACK_NOISE 3.0

/* The loop delay's one home is PIEZO_MV_MAX_D (piezo_supervisor.h); the literals the
 * binding reads beside it follow from it. */
typedef char assert_max_delay[(PIEZO_MV_MAX_EXTRA_DELAY == PIEZO_MV_MAX_D - 1
                               && PIEZO_MV_Q_RING == PIEZO_MV_MAX_D + 1
                               && PIEZO_SUP_REF_RING >= PIEZO_MV_MAX_D) ? 1 : -1];

void piezo_controller_default_params(piezo_controller_params *p)
{
    piezo_plant_params plant;
    if (!p) return;
    memset(p, 0, sizeof *p);
    /* The nominal model is the plant's default parameter set: one source. */
    piezo_plant_default_params(&plant);
    p->pi = plant.pi;
    p->tf_a1 = plant.tf.a1;
    p->tf_a2 = plant.tf.a2;
    p->tf_b1 = plant.tf.b1;
    p->tf_b2 = plant.tf.b2;
    p->creep_k_c = plant.creep_k_c;
    p->creep_alpha = plant.creep_alpha;
    p->creep_exact = plant.creep_exact;
    p->h = plant.h;
    /* No direct feedthrough by default: the control computed from the inputs
     * of sample k is published at t_(k+1), so the loop delay is d = 2. */
    p->mv_delay = PIEZO_MV_AUTO_DELAY;   /* detected: 2 in a master that exchanges at
                                            communication points, 1 in true Gauss-Seidel */
    p->mv_feedthrough = 0;
    p->mv_lambda_u = 0.0;
    p->mv_observer = DEFAULT_OBSERVER;
    /* RLS tuning of the robust update (docs/model.md, adaptation): forgetting 0.99 and a
     * trace bound of 100 (a bound of 1000 tracked the mismatch case's tones 2-3 times better
     * but burst on 10 of 200 tone runs of drawn stages, up to 68 um; 300 on 5, 100 on none);
     * the noise-scaled bound rls.variance_max keeps a noisy sensor from driving the estimates. */
    p->rls_enabled = 1;
    p->rls_forgetting = 0.99;
    p->rls_p0 = 1.0;
    p->rls_trace_max = 100.0;
    /* robust adaptation and integral action, measured on the stage-use family and the
     * paper's scenarios (docs/model.md, adaptation); the paper's law is rls.robust = false,
     * rls.forgetting = 0.995, mv.integral = 0, mv.observer = 0.4 */
    p->rls_robust = 1;
    p->rls_excitation = 3.0;
    p->rls_excitation_time = 0.05;
    p->rls_variance_max = 0.004;
    p->rls_p0_loop = 0.01;
    p->mv_integral = 0.01;
    p->sat_enabled = 1;
    p->sat_v_min = -PIEZO_SAT_DEFAULT_V;
    p->sat_v_max = PIEZO_SAT_DEFAULT_V;
    p->monitor_pred_error_max = PIEZO_MONITOR_DEFAULT_ERROR;
    p->monitor_divergence_samples = PIEZO_MONITOR_DEFAULT_SAMPLES;
    piezo_supervisor_default_params(&p->sup);
    p->mv_probe_max = PIEZO_DETECT_PROBE_MAX;
    /* estimates with guarantees (docs/model.md): measured on the stage family's days and the
     * paper's scenarios. The zero of B at 0.5 or above (a drift to -0.3 rang +-44 um; the
     * paper's tones move it to 0.66-0.95), poles of A in the hull of real poles in [0, 1) (a
     * fast pole driven to -0.3 by a 1 Hz tone overshot a step by 8.5 um); b1 and the static
     * gain are kept within the supervision's sup.gain_min .. sup.gain_max times the nominal
     * model's (piezo_supervisor.h); the fallback at twice the nominal model's squared errors
     * over 0.5 s */
    p->rls_zero_min = 0.75;
    p->rls_pole_min = 0.0;
    p->rls_fallback_ratio = 2.0;
    p->rls_fallback_window = 0.5;
}

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

/* lambda of the monitor's window: 1 - 1/monitor.divergence_samples (0: off) */
static double monitor_forgetting(int window)
{
    return window > 0 ? 1.0 - 1.0 / (double)window : 0.0;
}

/* samples of a duration t at h, rounded to the nearest, saturated far below 2^63 (a tiny h with a
 * long duration must not overflow the conversion, as the fuzzer found) */
static uint64_t rounded_samples(double t, double h)
{
    double n = floor(t / h + 0.5);
    if (!(n >= 0.0)) return 0;
    if (n > 9.0e15) return (uint64_t)9.0e15;
    return (uint64_t)n;
}

/* The admissible set's lowest zero of B: rls.zero_min, or the nominal zero -tf.b2/tf.b1 when that
 * is lower (the set always holds the nominal model; a stage identified with a lower zero keeps
 * the default) */
static double admissible_zero_min(const piezo_controller_params *p)
{
    double nominal_zero = -p->tf_b2 / p->tf_b1;
    return p->rls_zero_min < nominal_zero ? p->rls_zero_min : nominal_zero;
}

/*
 * The admissible set of the robust update's estimates theta = [a1, a2, b1, b2] (docs/model.md,
 * "Estimates with guarantees"), as rows c^T theta <= d, from the nominal model n, the lowest
 * zero z (admissible_zero_min), the lowest pole p (rls.pole_min) and the supervision's range of a working
 * loop's response gain [g_lo, g_hi] (sup.gain_min, sup.gain_max: a gain the supervision takes for
 * a working loop the estimates can follow, and one beyond it the supervision stops);
 * A(x) = 1 + a1 x^-1 + a2 x^-2, so A(1) = 1 + a1 + a2, and m = A_STABILITY_MARGIN:
 *   A's poles in the convex hull of {real poles in [p, 1)}, the triangle of
 *     A(1) >= m                    (no pole at 1 or beyond):   -a1 - a2 <= 1 - m
 *     p^2 + a1 p + a2 >= 0         (both poles on one side of p): -p a1 - a2 <= p^2
 *     a2 + (1 + p)/2 a1 <= -p - m  (the chord from the double pole at p to the one at 1: complex
 *                                   poles only where they are damped as real ones between)
 *   B's zero -b2/b1 in [z, 0.999] (b1 > 0):  -0.999 b1 - b2 <= 0,  z b1 + b2 <= 0
 *   b1 within [g_lo n_b1, g_hi n_b1]:        b1 <= g_hi n_b1,  -b1 <= -g_lo n_b1
 *   B(1)/A(1) within [g_lo K, g_hi K], K the nominal's (A(1) > 0 by the first row):
 *     b1 + b2 - g_hi K (1 + a1 + a2) <= 0,   g_lo K (1 + a1 + a2) - b1 - b2 <= 0.
 * Every row is linear in theta: the set is a convex polytope (the hull, not the real-pole set
 * itself, which is not convex).
 */
static void admissible_rows(const double *n, double z, double p, double g_lo, double g_hi, double rows[][4],
                            double *d)
{
    const double m = A_STABILITY_MARGIN;
    const double gain = (n[2] + n[3]) / (1.0 + n[0] + n[1]);
    int r = 0;
#define ADMISSIBLE_ROW(x0, x1, x2, x3, bound) \
    do { rows[r][0] = (x0); rows[r][1] = (x1); rows[r][2] = (x2); rows[r][3] = (x3); d[r] = (bound); ++r; } while (0)
    ADMISSIBLE_ROW(-1.0, -1.0, 0.0, 0.0, 1.0 - m);
    ADMISSIBLE_ROW(-p, -1.0, 0.0, 0.0, p * p);
    ADMISSIBLE_ROW((1.0 + p) / 2.0, 1.0, 0.0, 0.0, -p - m);
    ADMISSIBLE_ROW(0.0, 0.0, -ZERO_RADIUS_MAX, -1.0, 0.0);
    ADMISSIBLE_ROW(0.0, 0.0, z, 1.0, 0.0);
    ADMISSIBLE_ROW(0.0, 0.0, 1.0, 0.0, g_hi * n[2]);
    ADMISSIBLE_ROW(0.0, 0.0, -1.0, 0.0, -g_lo * n[2]);
    ADMISSIBLE_ROW(-g_hi * gain, -g_hi * gain, 1.0, 1.0, g_hi * gain);
    ADMISSIBLE_ROW(g_lo * gain, g_lo * gain, -1.0, -1.0, -g_lo * gain);
#undef ADMISSIBLE_ROW
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

piezo_status piezo_controller_init(piezo_controller *c, const piezo_controller_params *p, piezo_diag *diag)
{
    piezo_pi_params pi_params;
    piezo_tf tf_check;
    piezo_tf_params tf_params;
    piezo_status st;
    if (!c || !p) return PIEZO_ERR_NULL;
    if (!(isfinite(p->h) && p->h > 0.0)) return piezo_refuse(diag, "h", "(0, inf) s", p->h);
    if (!(isfinite(p->creep_k_c) && p->creep_k_c > 0.0))
        return piezo_refuse(diag, "creep.k_c", "(0, inf)", p->creep_k_c);
    if (!(isfinite(p->creep_alpha) && p->creep_alpha >= -1.0 && p->creep_alpha <= 1.0))
        return piezo_refuse(diag, "creep.alpha", "[-1, 1]", p->creep_alpha);
    /* the nominal G must be a valid plant model (stable A) ... */
    tf_params.a1 = p->tf_a1;
    tf_params.a2 = p->tf_a2;
    tf_params.b1 = p->tf_b1;
    tf_params.b2 = p->tf_b2;
    tf_params.delay = 0;
    st = piezo_tf_init(&tf_check, &tf_params, diag);
    if (st != PIEZO_OK) return st;
    /* ... and invertible by MV: positive gain, zero inside the projection radius */
    if (!(p->tf_b1 > 0.0)) return piezo_refuse(diag, "tf.b1", "(0, inf) (MV divides by b1)", p->tf_b1);
    if (!(fabs(p->tf_b2) <= ZERO_RADIUS_MAX * p->tf_b1))
        return piezo_refuse(diag, "tf.b2", "|tf.b2| <= 0.999 tf.b1 (zero of B inside the unit circle)", p->tf_b2);
    if (p->mv_delay < PIEZO_MV_AUTO_DELAY || p->mv_delay > PIEZO_MV_MAX_EXTRA_DELAY)
        return piezo_refuse(diag, "mv.delay", "-1 (detect d in 1..3) or 0..8 samples (d = 1 + mv.delay)",
                            (double)p->mv_delay);
    if (p->mv_feedthrough != 0 && p->mv_feedthrough != 1)
        return piezo_refuse(diag, "mv.feedthrough", "false or true", (double)p->mv_feedthrough);
    if (p->mv_hold_inputs != 0 && p->mv_hold_inputs != 1)
        return piezo_refuse(diag, "mv.hold_inputs", "false or true", (double)p->mv_hold_inputs);
    if (!(isfinite(p->mv_lambda_u) && p->mv_lambda_u >= 0.0))
        return piezo_refuse(diag, "mv.lambda_u", "[0, inf)", p->mv_lambda_u);
    if (!(isfinite(p->mv_observer) && p->mv_observer >= 0.0 && p->mv_observer < 1.0))
        return piezo_refuse(diag, "mv.observer", "[0, 1) (pole of the observer polynomial T)", p->mv_observer);
    if (!(isfinite(p->rls_forgetting) && p->rls_forgetting > 0.0 && p->rls_forgetting <= 1.0))
        return piezo_refuse(diag, "rls.forgetting", "(0, 1]", p->rls_forgetting);
    if (!(isfinite(p->rls_p0) && p->rls_p0 > 0.0))
        return piezo_refuse(diag, "rls.p0", "(0, inf)", p->rls_p0);
    if (!(isfinite(p->rls_trace_max) && p->rls_trace_max >= 4.0 * p->rls_p0))
        return piezo_refuse(diag, "rls.trace_max", "[4 rls.p0, inf) (trace of the initial covariance)", p->rls_trace_max);
    if (p->rls_robust != 0 && p->rls_robust != 1)
        return piezo_refuse(diag, "rls.robust", "false or true", (double)p->rls_robust);
    if (!(isfinite(p->rls_excitation) && p->rls_excitation >= 0.0))
        return piezo_refuse(diag, "rls.excitation", "[0, inf) (times the measured noise of y_meas)", p->rls_excitation);
    if (!(isfinite(p->rls_excitation_time) && p->rls_excitation_time >= 0.0
          && p->rls_excitation_time <= 3600.0 && p->rls_excitation_time / p->h <= 9007199254740992.0))
        return piezo_refuse(diag, "rls.excitation_time", "[0, 3600] s (and at most 2^53 samples of h)",
                            p->rls_excitation_time);
    if (!(isfinite(p->rls_variance_max) && p->rls_variance_max > 0.0))
        return piezo_refuse(diag, "rls.variance_max", "(0, inf) (bound on trace(P) times the measured noise squared)",
                            p->rls_variance_max);
    if (!(isfinite(p->rls_p0_loop) && p->rls_p0_loop > 0.0 && 4.0 * p->rls_p0_loop <= p->rls_trace_max))
        return piezo_refuse(diag, "rls.p0_loop", "(0, rls.trace_max / 4]", p->rls_p0_loop);
    if (!(isfinite(p->mv_integral) && p->mv_integral >= 0.0 && p->mv_integral < 1.0))
        return piezo_refuse(diag, "mv.integral", "[0, 1) (gain of the integral action per sample)", p->mv_integral);
    if (p->sat_enabled) {
        if (!isfinite(p->sat_v_min)) return piezo_refuse(diag, "sat.v_min", "finite, < sat.v_max", p->sat_v_min);
        if (!(isfinite(p->sat_v_max) && p->sat_v_max > p->sat_v_min))
            return piezo_refuse(diag, "sat.v_max", "finite, > sat.v_min", p->sat_v_max);
    }
    if (!(isfinite(p->monitor_pred_error_max) && p->monitor_pred_error_max > 0.0))
        return piezo_refuse(diag, "monitor.pred_error_max", "(0, inf) um", p->monitor_pred_error_max);
    if (p->monitor_divergence_samples < 0)
        return piezo_refuse(diag, "monitor.divergence_samples", "0..2147483647 samples (0: never)",
                            (double)p->monitor_divergence_samples);
    if (!(isfinite(p->mv_probe_max) && p->mv_probe_max >= 0.0))
        return piezo_refuse(diag, "mv.probe_max", "[0, inf) um (0: no delay probe)", p->mv_probe_max);
    /* the admissible set must hold the nominal model: the estimates start there, and the fallback
     * returns there (tf.b1 > 0 and |tf.b2| <= 0.999 tf.b1 are checked above). A nominal zero below
     * rls.zero_min lowers the bound to it (admissible_zero_min), so the default suits any
     * identified stage */
    if (!(isfinite(p->rls_zero_min) && p->rls_zero_min >= -ZERO_RADIUS_MAX && p->rls_zero_min <= ZERO_RADIUS_MAX))
        return piezo_refuse(diag, "rls.zero_min", "[-0.999, 0.999] (lowest zero of B the estimates may have; "
                            "the nominal zero -tf.b2/tf.b1 when that is lower)", p->rls_zero_min);
    if (!(isfinite(p->rls_pole_min) && p->rls_pole_min >= -1.0 && p->rls_pole_min < 1.0))
        return piezo_refuse(diag, "rls.pole_min", "[-1, 1) (the poles of A in the hull of real poles in "
                            "[rls.pole_min, 1))", p->rls_pole_min);
    {
        /* the nominal model inside the set, row by row (the parameter that draws each row) */
        static const char *const who[PIEZO_ADMISSIBLE_ROWS] = {
            "rls.pole_min", "rls.pole_min", "rls.pole_min", "rls.zero_min", "rls.zero_min",
            "sup.gain_min", "sup.gain_min", "sup.gain_max", "sup.gain_min" };
        double rows[PIEZO_ADMISSIBLE_ROWS][4], bounds[PIEZO_ADMISSIBLE_ROWS], nominal[4];
        int i;
        nominal[0] = p->tf_a1;
        nominal[1] = p->tf_a2;
        nominal[2] = p->tf_b1;
        nominal[3] = p->tf_b2;
        if (!(isfinite(p->sup.gain_min) && p->sup.gain_min > 0.0 && p->sup.gain_min < 1.0))
            return piezo_refuse(diag, "sup.gain_min", "(0, 1) (times the model's response)", p->sup.gain_min);
        if (!(isfinite(p->sup.gain_max) && p->sup.gain_max > 1.0))
            return piezo_refuse(diag, "sup.gain_max", "(1, inf) (times the model's response)", p->sup.gain_max);
        admissible_rows(nominal, admissible_zero_min(p), p->rls_pole_min, p->sup.gain_min, p->sup.gain_max, rows, bounds);
        for (i = 0; i < PIEZO_ADMISSIBLE_ROWS; ++i)
            if (admissible_excess(rows[i], bounds[i], nominal) > 0.0)
                return piezo_refuse(diag, who[i], i < 3 ? "a value below both nominal poles (tf.a1, tf.a2: real "
                                    "poles in [rls.pole_min, 1 - 1e-4], or complex ones inside their hull)"
                                    : "a set that holds the nominal model", i < 3 ? p->rls_pole_min
                                    : (i < 5 ? p->rls_zero_min : (i == 5 || i == 7 ? p->sup.gain_max
                                                                                    : p->sup.gain_min)));
    }
    if (!(isfinite(p->rls_fallback_ratio) && p->rls_fallback_ratio >= 0.0))
        return piezo_refuse(diag, "rls.fallback_ratio", "[0, inf) (times the nominal model's squared prediction "
                            "errors; 0: no prediction test)", p->rls_fallback_ratio);
    if (!(isfinite(p->rls_fallback_window) && p->rls_fallback_window > 0.0 && p->rls_fallback_window <= 3600.0))
        return piezo_refuse(diag, "rls.fallback_window", "(0, 3600] s (window of the prediction test, at least "
                            "one sample)", p->rls_fallback_window);

    memset(c, 0, sizeof *c);
    pi_params = p->pi;
    st = piezo_pi_init(&c->fwd_pi, &pi_params, diag);
    if (st != PIEZO_OK) return st;
    /* eq 29: inverse creep = G-L of order -alpha, gain h^alpha / k_c */
    st = piezo_gl_init(&c->inv_creep, -p->creep_alpha, pow(p->h, p->creep_alpha) / p->creep_k_c,
                       p->creep_exact, diag);
    if (st != PIEZO_OK) return st;
    c->auto_delay = p->mv_delay == PIEZO_MV_AUTO_DELAY;
    c->d = c->auto_delay ? PIEZO_DETECT_START_D : 1 + p->mv_delay;
    c->lambda_u = p->mv_lambda_u;
    c->observer = p->mv_observer;
    c->rls_enabled = p->rls_enabled ? 1 : 0;
    c->forgetting = p->rls_forgetting;
    c->inv_forgetting = 1.0 / p->rls_forgetting;
    c->p0 = p->rls_p0;
    c->trace_max = p->rls_trace_max;
    c->robust = p->rls_robust;
    c->excitation = p->rls_excitation;
    c->excitation_samples = rounded_samples(p->rls_excitation_time, p->h);
    c->variance_max = p->rls_variance_max;
    c->p0_loop = p->rls_p0_loop;
    c->integral_gain = p->mv_integral;
    c->sat_enabled = p->sat_enabled ? 1 : 0;
    c->sat_v_min = p->sat_v_min;
    c->sat_v_max = p->sat_v_max;
    c->pred_error_max = p->monitor_pred_error_max;
    c->divergence_samples = (uint64_t)p->monitor_divergence_samples;
    c->mon_forgetting = monitor_forgetting(p->monitor_divergence_samples);
    c->theta_nominal[0] = p->tf_a1;
    c->theta_nominal[1] = p->tf_a2;
    c->theta_nominal[2] = p->tf_b1;
    c->theta_nominal[3] = p->tf_b2;
    c->probe_max = p->mv_probe_max;
    c->zero_min = admissible_zero_min(p);
    c->pole_min = p->rls_pole_min;
    c->gain_lo = p->sup.gain_min;
    c->gain_hi = p->sup.gain_max;
    admissible_rows(c->theta_nominal, c->zero_min, c->pole_min, c->gain_lo, c->gain_hi, c->adm_c, c->adm_d);
    c->fallback_ratio = p->rls_fallback_ratio;
    c->fallback_samples = rounded_samples(p->rls_fallback_window, p->h);
    if (c->fallback_samples < 1) c->fallback_samples = 1;
    c->fallback_forgetting = 1.0 - 1.0 / (double)c->fallback_samples;
    /* the supervisor judges the loop by the nominal model */
    st = piezo_supervisor_init(&c->sup, &p->sup, p->tf_a1, p->tf_a2, p->tf_b1, p->tf_b2, p->h, diag);
    if (st != PIEZO_OK) return st;
    piezo_controller_reset(c);
    /* The inverse PI must exist in doubles: its thresholds grow like
     * (w0 + sum w_j) v_max, its weights like 1/w0 (and 1/w0^2 inside eq 27). */
    {
        int i, thresholds_ok = 1, weights_ok = isfinite(c->inv_pi.w0);
        for (i = 0; i < PIEZO_PI_MAX_OPERATORS; ++i) {
            thresholds_ok = thresholds_ok && isfinite(c->inv_pi.r[i]);
            weights_ok = weights_ok && isfinite(c->inv_pi.w[i]);
        }
        if (!thresholds_ok)
            return piezo_refuse(diag, "pi.v_max",
                                "(0, inf) V with (pi.w0 + sum of pi.w[j]) pi.v_max finite (thresholds of the inverse PI)",
                                p->pi.v_max);
        if (!weights_ok)
            return piezo_refuse(diag, "pi.w0", "(0, inf) with 1/pi.w0^2 finite (weights of the inverse PI)", p->pi.w0);
        if (piezo_pi_inverse_check(&c->inv_pi) != NULL)
            return piezo_refuse(diag, "pi.w0", "(0, inf) with a finite inverse PI (pi.w0, pi.w[j], pi.v_max)", p->pi.w0);
    }
    return PIEZO_OK;
}

/* (Re)start delay detection: every candidate from the nominal model and the
 * initial covariance, sums at 0, the start-up law. */
static void detection_start(piezo_controller *c)
{
    int i, j;
    c->detecting = 1;
    c->d = PIEZO_DETECT_START_D;
    c->det_leader = -1;
    c->det_run = 0;
    c->det_trial = c->k;
    c->det_probe = 0.0;
    c->det_probes = 0;
    c->n_detections += 1;
    for (i = 0; i < PIEZO_DETECT_N; ++i) {
        c->det_score[i] = 0.0;
        memcpy(&c->det_theta[4 * i], c->theta_nominal, 4 * sizeof(double));
        for (j = 0; j < 16; ++j) c->det_P[16 * i + j] = j % 5 == 0 ? c->p0 : 0.0;
    }
}

/* The loop's states as a fresh controller's at sample c->k (c->k_start): the nominal model, its
 * covariance, the delay detection, the supervision, every sum of the loop; the hysteresis model and
 * the inverse creep are the caller's (reset: zero states; restart: the stage's after 0 V). The
 * counts of the run are not touched. */
static void loop_start(piezo_controller *c)
{
    int i;
    memcpy(c->theta, c->theta_nominal, sizeof c->theta);
    memset(c->P, 0, sizeof c->P);
    for (i = 0; i < 4; ++i) c->P[5 * i] = c->robust ? c->p0_loop : c->p0;
    c->y_prev[0] = c->y_prev[1] = 0.0;
    memset(c->q_ring, 0, sizeof c->q_ring);
    c->head = 0;
    c->r_prev = 0.0;
    c->noise_y = c->noise_y2 = c->noise_e = c->r_anchor = c->offset = c->integral = c->r_last = c->r_last2 = c->r_velocity = 0.0;
    c->excite_left = c->jump_left = 0;
    memset(c->yd_value, 0, sizeof c->yd_value);
    memset(c->yd_tag, 0, sizeof c->yd_tag);
    memset(c->preview_value, 0, sizeof c->preview_value);
    memset(c->preview_tag, 0, sizeof c->preview_tag);
    c->k_delay = c->k;
    c->k_search = c->k;
    c->det_clock = 0;
    c->detecting = 0;
    if (c->auto_delay)
        detection_start(c);
    c->sat_hold = 0;
    c->run_saturated = c->run_large_error = 0;
    c->mon_share = c->mon_weight = 0.0;
    memset(&c->out, 0, sizeof c->out);
    memcpy(c->out.theta, c->theta, sizeof c->theta);
    piezo_supervisor_reset(&c->sup);
    memset(&c->verdict, 0, sizeof c->verdict);
    c->det_noise = 0.0;
    c->err_sum = c->err_weight = c->outlier_sum = 0.0;
    c->quiet = 0;
    c->suspect = 0;
    c->suspect_y = c->suspect_error = 0.0;
    c->fault = 0;
    c->k_fault = 0;
    c->v_fault = 0.0;
    c->y_fault = 0.0;
    c->y_moved = 0;
    c->fb_adapted = c->fb_nominal = c->learned_rate = 0.0;
}

void piezo_controller_reset(piezo_controller *c)
{
    if (!c) return;
    piezo_pi_reset(&c->fwd_pi);
    piezo_pi_inverse_init(&c->inv_pi, &c->fwd_pi);   /* consistent with zero states */
    piezo_gl_reset(&c->inv_creep);
    c->k = 0;
    c->k_start = c->k_ramp_end = c->n_resets = 0;
    c->y_start = 0.0;
    c->n_detections = 0;
    loop_start(c);
    c->n_saturated = c->n_large_error = 0;
    c->k_first_saturated = c->k_first_large_error = 0;
    c->n_large_settled = c->k_first_large_settled = 0;
    c->max_abs_pred_error = 0.0;
    c->n_outliers = c->k_first_outlier = 0;
    c->first_outlier = c->first_outlier_error = 0.0;
    c->n_projections = 0;
    c->n_fallbacks = c->k_first_fallback = 0;
    c->first_fallback = PIEZO_FALLBACK_NONE;
    c->first_fallback_value = c->first_fallback_other = 0.0;
}

int piezo_controller_reset_refusal(const piezo_controller *c, const piezo_controller_input *in)
{
    double rail;
    if (!c || !c->fault) return PIEZO_RESET_NO_FAULT;
    if (c->k - c->k_fault < c->sup.ramp_samples) return PIEZO_RESET_RAMPING;
    if (!in || !isfinite(in->y_ref) || !isfinite(in->y_meas)) return PIEZO_RESET_INPUTS;
    /* a reading that never left the verdict's: the frozen or silent sensor is still there (a
     * sensor that came back reads the stage, which moved as v went to 0 V) */
    if ((c->fault == PIEZO_SUP_FROZEN || c->fault == PIEZO_SUP_NO_RESPONSE || c->fault == PIEZO_SUP_CLIPPED)
        && !c->y_moved && in->y_meas == c->y_fault)
        return PIEZO_RESET_STUCK;
    /* the rail the loop was held at (the clipping watchdog's verdict, or another one while v was at
     * a rail: the monitor's, say), and the reading it reached there: a reference still beyond
     * it by more than the watchdog's bound would clip again. Only where the stage answered the rail
     * the right way round, its reading falling back from there as v went to 0 V: an inverted
     * amplifier or sensor also holds v at a rail, and its reading there says nothing of the reach
     * (the restarted supervision judges that loop) */
    rail = c->v_fault >= 0.0 ? 1.0 : -1.0;
    if ((c->fault == PIEZO_SUP_CLIPPED || (c->sat_enabled && (c->v_fault == c->sat_v_max || c->v_fault == c->sat_v_min)))
        && (c->y_fault - in->y_meas) * rail > 0.0
        && (in->y_ref - c->y_fault) * rail > c->sup.clip_error)
        return PIEZO_RESET_OUT_OF_REACH;
    return PIEZO_RESET_ACCEPTED;
}

/*
 * The restart from rest at y = y_meas(k) after v went to 0 V: the forward PI's operators take
 * v = 0 (a play operator is rate independent, so the ramp's monotone path ends where a jump to 0
 * does) and the inverse is rebuilt consistent with them (eq 28); the inverse creep starts anew;
 * the law's past is that of a stage at rest there, q(k-i) = q0 = P[0] / gain of the inverse creep
 * (what 0 V gives the model) and y(k-i) = y, and its reference starts from y: the reference then
 * comes as a step.
 */
piezo_status piezo_controller_restart(piezo_controller *c, double y)
{
    double r0, q0, w, noise_y, noise_y2, noise_e;
    int i, d, keep_d;
    if (!c) return PIEZO_ERR_NULL;
    if (!c->fault || !isfinite(y)) return PIEZO_ERR_PARAM;
    piezo_pi_eval(&c->fwd_pi, 0.0, c->fwd_pi.z, &r0);     /* the operators after 0 V, committed */
    piezo_pi_inverse_init(&c->inv_pi, &c->fwd_pi);
    piezo_gl_reset(&c->inv_creep);
    c->k_start = c->k;
    c->k_ramp_end = c->k + c->sup.ramp_samples;
    c->n_resets += 1;
    /* what the loop learned of its wiring and its sensor, not of the stage's model, stays: the
     * loop delay chosen (unless the verdict was about the delay), the measured noise (a restart that
     * measured it anew would probe behind a 200 nm sensor, which it had found buries the probes) */
    keep_d = c->auto_delay && !c->detecting && c->fault != PIEZO_SUP_DELAY && c->fault != PIEZO_SUP_UNDETECTED;
    d = c->d;
    noise_y = c->noise_y;
    noise_y2 = c->noise_y2;
    noise_e = c->noise_e;
    loop_start(c);
    c->noise_y = noise_y;
    c->noise_y2 = noise_y2;
    c->noise_e = noise_e;
    if (keep_d) {
        c->detecting = 0;
        c->d = d;
        c->n_detections -= 1;
    }
    q0 = r0 / c->inv_creep.gain;
    if (!isfinite(q0)) q0 = 0.0;
    for (i = 0; i < PIEZO_MV_Q_RING; ++i) c->q_ring[i] = q0;
    c->y_prev[0] = c->y_prev[1] = y;
    c->r_prev = c->r_last = c->r_last2 = c->r_anchor = y;
    c->y_start = y;
    w = (c->theta_nominal[2] + c->theta_nominal[3]) * q0;
    piezo_supervisor_restart(&c->sup, y, w);
    return PIEZO_OK;
}

size_t piezo_controller_history_needed(const piezo_controller *c)
{
    return c ? piezo_gl_history_needed(&c->inv_creep) : 0;
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

/* The a-priori error of (theta_in, P) under delay d and, with update set, the update with the
 * paper's projection (the delay candidates, the paper's update). */
static double rls_step(const piezo_controller *c, const double *theta_in, const double *P, int d, double y,
                       int update, double lambda, double inv_lambda, double trace_max, double *theta, double *P_new)
{
    double e = rls_error(c, theta_in, d, y);
    if (!update) return e;
    rls_gain(c, theta_in, P, d, e, lambda, inv_lambda, trace_max, theta, P_new);
    project(c, theta);
    return e;
}

/*
 * The robust update's projection into the admissible set (admissible_rows), after its update:
 * sweeps over the rows, each violated one a projection onto its half-space in the metric of
 * P^-1 (Goodwin and Sin; Ioannou and Sun, parameter projection), which moves theta along the
 * directions the data determine least,
 *     theta -= P c (c^T theta - d) / (c^T P c),
 * then, if a sweep limit left a row violated, the step towards the nominal model (inside the
 * set) that ends on the set: theta = n + s (theta - n), s the least of
 * slack / (slack + excess) over the violated rows (slack = d - c^T n). 1 when theta changed.
 */
static int admissible_project(const piezo_controller *c, const double *P, double *th)
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
        double s = 1.0;
        for (i = 0; i < PIEZO_ADMISSIBLE_ROWS; ++i) {
            double excess = admissible_excess(c->adm_c[i], c->adm_d[i], th);
            if (excess > 0.0) {
                double slack = -admissible_excess(c->adm_c[i], c->adm_d[i], n);
                double ratio = slack / (slack + excess);
                if (ratio < s) s = ratio;
            }
        }
        for (j = 0; j < 4; ++j) th[j] = n[j] + s * (th[j] - n[j]);
        /* rounding may leave it an ulp outside: then the nominal model itself */
        if (admissible_violated(c, th)) memcpy(th, n, 4 * sizeof(double));
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
    int may = c->rls_enabled && !(c->sat_hold > 0) && !s->outlier;
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
    /* no update while the sensor's noise is twice what buries the delay probes (above 60 nm rms with
     * the defaults): data that noisy do not identify the model, and the estimates fitted to them
     * burst where the nominal model tracks (on the stage's day with 200 nm sensors: a 10 um step
     * after a 5 Hz tone erred 18.5 um against 0.9 um fresh); a 20 nm sensor, whose measured noise
     * passes 30 nm at times, adapts as before */
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
double piezo_controller_probe_snr(void)
{
    return PROBE_SNR;
}

double piezo_controller_monitor_bound(const piezo_controller *c)
{
    return c ? monitor_bound(c) : 0.0;
}

int piezo_controller_explain_bound(const piezo_controller *c, char *text, size_t size)
{
    double bound;
    if (c == NULL) return 0;
    bound = monitor_bound(c);
    if (bound >= PIEZO_MONITOR_NOISE_CAP * c->pred_error_max)
        return snprintf(text, size, "%.4g um (monitor.pred_error_max = %g um raised for y_meas's noise, %.4g um "
                        "rms, to its cap)", bound, c->pred_error_max, c->noise_y2);
    if (bound > c->pred_error_max)
        return snprintf(text, size, "%.4g um (monitor.pred_error_max = %g um raised to %d times y_meas's noise, "
                        "%.4g um rms)", bound, c->pred_error_max, PIEZO_MONITOR_NOISE, c->noise_y2);
    return snprintf(text, size, "monitor.pred_error_max = %g um", c->pred_error_max);
}

int piezo_controller_probes_buried(const piezo_controller *c)
{
    return c->robust && noise_settled(c) && PROBE_SNR * c->noise_y2 > c->probe_max * c->theta_nominal[2];
}

static void detect_carry(const piezo_controller *c, piezo_controller_sample *s);

/* The one-step error the monitor judges while the detection runs, given its best candidate's: that
 * one's, but while the probes are buried the start-up law's own, the nominal model's at
 * PIEZO_DETECT_START_D (the candidates adapt while the reference moves, and on noisy data wander:
 * with a 200 nm sensor theirs wandered up to 26 um from y_meas while the stage tracked within
 * 0.65 um, and the monitor stopped 51 of 1300 runs of the stage's day's quick slice) */
static double detect_error(const piezo_controller *c, const piezo_controller_sample *s, double y, double best)
{
    return s->clock ? best : rls_error(c, c->theta_nominal, PIEZO_DETECT_START_D, y);
}

/*
 * Delay detection, one sample (docs/cosimulation.md): each candidate
 * d = i + 1 predicts y(k) with its own RLS, adds its squared a-priori error to
 * its sum, and adapts. The candidate with the smallest sum leads clearly when
 * that sum is at most DETECT_RATIO times every other candidate's; it is chosen
 * after leading clearly for PIEZO_DETECT_CONFIRM consecutive samples, and its
 * estimates and covariance become the loop's (s->theta, s->P, s->rls_updated).
 * Returns the a-priori error of the leader by sum (ties: the start-up law's d).
 */
static double detect_update(const piezo_controller *c, double y, piezo_controller_sample *s)
{
    static const int order[PIEZO_DETECT_N] = { PIEZO_DETECT_START_D - 1, 0, 2 };
    double err[PIEZO_DETECT_N];
    /* the candidates adapt while the reference moves or the sample can teach them, and score only on
     * the samples that can; not at all while the probes are buried in the noise (nothing can be chosen
     * then, and the monitor judges the nominal model): adapting on 200 nm data as the reference moved,
     * the d = 3 candidate's estimates grew without bound (1e153 after 17 s of the stage's day's hour
     * on stage 6) until its score overflowed and the loop was refused as diverged, in 18 of the 1700
     * robust runs of the day with 100 and 200 nm sensors */
    int i, best = order[0], second = -1, update = c->rls_enabled && !(c->sat_hold > 0) && !s->outlier
                                                  && s->clock && (s->live || c->r_last != c->r_last2);
    for (i = 0; i < PIEZO_DETECT_N; ++i) {
        err[i] = rls_step(c, &c->det_theta[4 * i], &c->det_P[16 * i], i + 1, y, update,
                          c->robust ? DETECT_FORGETTING : c->forgetting,
                          c->robust ? 1.0 / DETECT_FORGETTING : c->inv_forgetting,
                          c->robust ? DETECT_TRACE_MAX : c->trace_max, &s->det_theta[4 * i], &s->det_P[16 * i]);
        if (!update) {
            memcpy(&s->det_theta[4 * i], &c->det_theta[4 * i], 4 * sizeof(double));
            memcpy(&s->det_P[16 * i], &c->det_P[16 * i], 16 * sizeof(double));
        }
        s->det_score[i] = c->det_score[i] + err[i] * err[i];
    }
    if (!s->live) {
        /* a sample the detection cannot learn from: none scores or leads (in closed loop at rest the
         * law's own answer to the noise favours one delay: the candidate of d = 3 led clearly within
         * 62 ms on a stage with a 200 nm sensor; candidates that adapt to the noise at rest wander
         * until the monitor stops the loop, and candidates that do not adapt along a slow ramp err
         * beyond its bound) */
        detect_carry(c, s);
        memcpy(s->det_score, c->det_score, sizeof s->det_score);
        s->rls_updated = 0;
        return detect_error(c, s, y, err[PIEZO_DETECT_START_D - 1]);
    }
    for (i = 1; i < PIEZO_DETECT_N; ++i)
        if (s->det_score[order[i]] < s->det_score[best]) best = order[i];
    for (i = 0; i < PIEZO_DETECT_N; ++i)
        if (i != best && (second < 0 || s->det_score[i] < s->det_score[second])) second = i;
    if (s->det_score[second] > 0.0 && s->det_score[best] <= DETECT_RATIO * s->det_score[second]) {
        s->det_run = c->det_leader == best ? c->det_run + 1 : 1;
        s->det_leader = best;
    } else {
        s->det_run = 0;
        s->det_leader = -1;
    }
    /* a leader of noise-buried probes must lead a run of PIEZO_DETECT_CONFIRM_BURIED, longer than a
     * trial (PIEZO_DETECT_TRIAL), whose start resets the run: in effect none is chosen while the noise
     * buries the probes, and the start-up law runs on (on the stage's day's quick slice with 100 and
     * 200 nm sensors, 1300 runs: leading 10 samples, two wrong choices of d = 3 after waits of 25 and
     * 49 s swung the stage 5.6 um before the restart; 20, 4.2 and 5.3 um; 40, none, the frames within
     * 2.2 um) */
    s->detecting = s->det_run < (!s->clock ? PIEZO_DETECT_CONFIRM_BURIED
                                                                               : PIEZO_DETECT_CONFIRM);
    /* a trial that chose nothing: the next starts with a probe */
    s->new_trial = s->detecting && c->k + 1 - c->det_trial >= PIEZO_DETECT_TRIAL;
    s->next_noise = c->det_noise;
    if (s->new_trial) {
        double p, lo = PROBE_MIN < c->probe_max ? PROBE_MIN : c->probe_max;
        s->next_noise = sqrt(s->det_score[best] / PIEZO_DETECT_TRIAL);
        p = PROBE_SNR * s->next_noise / c->theta_nominal[2];
        if (p < 2.0 * c->det_probe) p = 2.0 * c->det_probe;
        s->next_probe = c->det_probes >= PIEZO_DETECT_PROBES ? 0.0
                        : p < lo ? lo : (p > c->probe_max ? c->probe_max : p);
    }
    s->d = s->detecting ? PIEZO_DETECT_START_D : best + 1;
    s->k_delay = s->detecting ? c->k_delay : c->k;
    s->rls_updated = !s->detecting;
    if (!s->detecting) {
        memcpy(s->theta, c->robust ? c->theta_nominal : &s->det_theta[4 * best], sizeof s->theta);
        if (c->robust) {
            /* the robust update starts the loop from the nominal model and rls.p0_loop I (after a
             * restart too: estimates fitted under another delay are no start for this one); the
             * candidates' estimates and covariance are sized to
             * tell the delays apart within milliseconds. Their estimates, fitted to the
             * detection's few samples of sensor noise and probes, moved b1 from 0.595 to 0.526
             * on a stage with a 20 nm sensor (its 10 um step then erred 2.23 um, 0.076 with the
             * estimates fixed); and the first large move of a loop that keeps their covariance
             * fits its estimates to that one move (a 50 um S-curve: b1 driven to its floor,
             * errors of 2-12 um) */
            int j;
            for (j = 0; j < 16; ++j) s->P[j] = j % 5 == 0 ? c->p0_loop : 0.0;
        } else {
            memcpy(s->P, &s->det_P[16 * best], sizeof s->P);
        }
    }
    return detect_error(c, s, y, err[best]);
}

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

/* 1 when every x[i] is finite: x * 0 is +-0 for a finite x and NaN for Inf or
 * NaN (IEEE 754; no -ffinite-math-only here), so a sum of those products is 0
 * exactly when all are finite, in whatever order it is added. No branch per
 * element, and four short chains of additions, z[j] over the x[i] with
 * i mod 4 = j, instead of one (the check runs on every sample, some 50 values):
 * the compiler adds them as two pairs in two vector registers; the last n mod 4
 * as a pair and one (not a loop: a 32-bit build's loop optimisation warned of one). */
static int all_finite(const double *x, int n)
{
    double z[4] = { 0.0, 0.0, 0.0, 0.0 };
    int i, j;
    for (i = 0; i + 4 <= n; i += 4)
        for (j = 0; j < 4; ++j) z[j] += x[i + j] * 0.0;
    if (i + 2 <= n) {
        z[0] += x[i] * 0.0;
        z[1] += x[i + 1] * 0.0;
        i += 2;
    }
    if (i < n) z[2] += x[i] * 0.0;
    return (z[0] + z[1]) + (z[2] + z[3]) == 0.0;
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
    /* the robust update's and the outlier test's next doubles: a square or a difference of
     * finite values overflows (e^2 of a huge a-priori error, y(k) - y(k-1)). x * 0 is 0 for a
     * finite x and NaN otherwise (all_finite's test, here without building an array on the
     * sample's path). Not checked, since they cannot overflow: the weights err_weight and
     * outlier_sum, and the monitor's sums (at most 1 / (1 - lambda)); the raw a-priori error
     * (finite when err_sum is, or, for an outlier, when the y_meas it left is) */
    const double robust_zero = s->noise_y * 0.0 + s->noise_y2 * 0.0 + s->noise_e * 0.0 + s->r_anchor * 0.0 + s->offset * 0.0
                               + s->integral * 0.0 + s->r_velocity * 0.0 + s->r_plain * 0.0 + s->y_meas * 0.0
                               + s->err_sum * 0.0 + (s->outlier ? s->y_meas + s->raw_error : 0.0) * 0.0
                               + s->fb_adapted * 0.0 + s->fb_nominal * 0.0 + s->learned_rate * 0.0;
    /* the estimates the law used, the same way (four values: no call) */
    const double theta_zero = s->out.theta[0] * 0.0 + s->out.theta[1] * 0.0 + s->out.theta[2] * 0.0
                              + s->out.theta[3] * 0.0;
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
    s->err_sum = s->outlier ? c->err_sum : lam * c->err_sum + s->raw_error * s->raw_error;
    s->err_weight = s->outlier ? c->err_weight : lam * c->err_weight + 1.0;
}

/*
 * The fallback to the nominal model (robust update, while the loop's estimator runs; docs/model.md,
 * "Estimates with guarantees"), given the law's reference r = y_d(k + d) (without z), the
 * measurement and the loop model's a-priori error e_a of sample k. Two reasons, each judged
 * only while the law's estimates differ from the nominal model:
 * - a jump: |r(k) - r(k-1)| beyond monitor.pred_error_max and beyond PIEZO_FALLBACK_JUMP_RATIO
 *   times the largest change per sample R the estimates learned on (R = max(|r(k) - r(k-1)|,
 *   R (1 - 1/PIEZO_FALLBACK_JUMP_MEMORY)) over the samples they adapted at): a step after a long
 *   tone meets estimates fitted to one frequency (after 60 s of a 1 Hz tone, b1 1.7 times and
 *   the fast pole -0.09 against 0.385: the step erred 4.1 um, 11 times the fresh step); every
 *   change of the reference while the estimates run counts (its answer follows, and the
 *   estimator updates on it), and fades only over the samples it updates at;
 * - a prediction: over the window of rls.fallback_window (lambda = 1 - 1/N),
 *     S_a = lambda S_a + e_a^2,  S_n = lambda S_n + e_n^2,  e_n = y - c - phi^T theta_nominal,
 *   S_a > rls.fallback_ratio S_n + N (FALLBACK_NOISE noise_y)^2.
 * A fallback puts the nominal model and rls.p0_loop I in the estimator and the law of this very
 * sample (*theta), empties the window, and counts the jump as learned.
 */
static void fallback_test(const piezo_controller *c, double r, double y_meas, double e_a, const double **theta,
                          piezo_controller_sample *s)
{
    double rate, faded;
    int reason = PIEZO_FALLBACK_NONE, j;
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
        const double lambda = c->fallback_forgetting, floor_rms = FALLBACK_NOISE * c->noise_y;
        s->fb_adapted = lambda * c->fb_adapted + e_a * e_a;
        s->fb_nominal = lambda * c->fb_nominal + e_n * e_n;
        if (s->fb_adapted > c->fallback_ratio * s->fb_nominal
                            + (double)c->fallback_samples * (floor_rms * floor_rms) && ADAPTED) {
            reason = PIEZO_FALLBACK_PREDICTION;
            s->fallback_value = sqrt(s->fb_adapted / (double)c->fallback_samples);  /* the rms errors */
            s->fallback_other = sqrt(s->fb_nominal / (double)c->fallback_samples);
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
        memcpy(s->theta, c->theta_nominal, sizeof s->theta);
        for (j = 0; j < 16; ++j) s->P[j] = j % 5 == 0 ? c->p0_loop : 0.0;
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
 * larger, up to PIEZO_MONITOR_NOISE_CAP times monitor.pred_error_max. The nominal model's one-step
 * prediction error carries a sensor's noise 1.75 times (sqrt(1 + a1^2 + a2^2) for the paper's
 * model): a 200 nm sensor's passes 1 um in 0.4 % of the samples, each of which restarted the
 * outlier test's quiet run (a dead sensor then went unbridged on 2 of 50 stages, 3.8 um off). The
 * cap: "noise" beyond 250 nm rms is no sensor's but a fault's (y_meas alternating +-10 um measures
 * as 23 um of noise, and uncapped the bound would have let it run). Once the noise has settled
 * (noise_settled), as for the probes' burial. */
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
    const double *theta;
    piezo_status st;
    int i, d, stamped, saturated = 0, operators_finite;

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
     * not while it is off) tells nothing new: the integral action and the estimator's offset hold,
     * and never walk the stage on a reading that may be stuck */
    s->held = c->sup.enabled && c->sup.k > 0 && in->y_meas == c->sup.y1
              && c->sup.y_same + 1 >= PIEZO_SUP_STUCK_SAME;
    if (s->outlier)
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
        pred_error = detect_update(c, y_meas, s);
    } else {
        /* the loop model's a-priori error is the outlier test's (computed once), unless the
         * model's prediction stood in for y_meas */
        pred_error = s->outlier ? rls_error(c, c->theta, c->d, y_meas - (c->robust ? c->offset : 0.0))
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
     * clipped sample pauses the adaptation (anti-windup) and when no reference for sample k
     * was taken */
    s->r_plain = r;
    s->integral = c->integral;
    if (c->integral_gain > 0.0 && !s->detecting && c->sat_hold == 0
        && c->yd_tag[c->k % PIEZO_MV_Q_RING] == c->k + 1 && !s->held)
        s->integral = c->integral + c->integral_gain * (c->yd_value[c->k % PIEZO_MV_Q_RING] - y_meas);
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
    s->large_error = fabs(pred_error) > bound;
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
    s->out.pred_error = s->outlier ? s->raw_error : pred_error;   /* an outlier's as it came */
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
        detection_start(c);
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


const char *piezo_controller_check(const piezo_controller *c)
{
    const char *fault;
    const piezo_controller_output *o;
    int i, j, m;
    uint64_t k_loop;
    if (!c) return "controller missing";
    /* the safe state: its fault, the verdict's sample (the loop's state is of then), the ramp */
    if (c->fault < 0 || c->fault > PIEZO_SUP_FAULT_MAX) return "safe state's fault code out of range";
    if (c->fault ? (c->sup.reaction != PIEZO_SUP_REACT_SAFE || c->k_fault >= c->k || !isfinite(c->v_fault)
                    || (c->fault <= PIEZO_SUP_FROZEN && c->verdict.fault != c->fault)
                    || (c->sat_enabled && (c->v_fault > c->sat_v_max || c->v_fault < c->sat_v_min)))
                 : c->k_fault != 0 || c->v_fault != 0.0)
        return "safe state inconsistent (reaction, sample, start of the ramp or verdict)";
    if (!isfinite(c->y_fault) || (c->y_moved != 0 && c->y_moved != 1)
        || (!c->fault && (c->y_fault != 0.0 || c->y_moved)))
        return "safe state's reading at the verdict inconsistent";
    k_loop = c->fault ? c->k_fault : c->k;
    /* sup.reset: the loop restarted at k_start (>= 1, a safe state came before), v ramping until
     * k_ramp_end; the loop's counters run from k_start */
    if (c->k_start > k_loop || c->n_resets > c->k || !isfinite(c->y_start)
        || (c->n_resets == 0 ? c->k_start != 0 || c->k_ramp_end != 0
                             : c->k_start == 0 || c->k_ramp_end != c->k_start + c->sup.ramp_samples))
        return "restart (sup.reset) sample, ramp or count inconsistent";
    if ((fault = piezo_pi_check(&c->fwd_pi)) != NULL) return fault;
    if ((fault = piezo_pi_inverse_check(&c->inv_pi)) != NULL) return fault;
    if (c->inv_pi.m != c->fwd_pi.m) return "inverse PI and forward PI differ in m";
    if ((fault = piezo_gl_check(&c->inv_creep)) != NULL) return fault;
    if (c->inv_creep.k != k_loop - c->k_start) return "inverse creep sample counter differs from the controller's";
    if (c->d < 1 || c->d > PIEZO_MV_MAX_D) return "loop delay d outside 1..9";
    if (c->head < 0 || c->head >= PIEZO_MV_Q_RING) return "q ring index out of range";
    if (c->sat_hold < 0 || c->sat_hold > (c->d > PIEZO_DETECT_N ? c->d : PIEZO_DETECT_N) + 1)
        return "adaptation pause outside 0..max(d, 3)+1";
    if ((c->auto_delay != 0 && c->auto_delay != 1) || (c->detecting != 0 && c->detecting != 1)
        || (c->detecting && !c->auto_delay) || (c->auto_delay && c->d > PIEZO_DETECT_N)
        || (c->detecting && c->d != PIEZO_DETECT_START_D))
        return "delay detection flags or d inconsistent";
    /* a choice leaves its leader with a run of PIEZO_DETECT_CONFIRM (PIEZO_DETECT_CONFIRM_BURIED
     * while the probes are buried in the noise) */
    if (c->det_leader < -1 || c->det_leader >= PIEZO_DETECT_N || c->det_run < 0
        || c->det_run > (PIEZO_DETECT_CONFIRM > PIEZO_DETECT_CONFIRM_BURIED ? PIEZO_DETECT_CONFIRM
                                                                             : PIEZO_DETECT_CONFIRM_BURIED)
        || (c->detecting && c->det_run >= (piezo_controller_probes_buried(c) ? PIEZO_DETECT_CONFIRM_BURIED
                                                                              : PIEZO_DETECT_CONFIRM))
        || (c->det_leader < 0 && c->det_run != 0))
        return "delay detection leader out of range";
    if (!(isfinite(c->probe_max) && c->probe_max >= 0.0) || !(isfinite(c->det_noise) && c->det_noise >= 0.0))
        return "mv.probe_max or the detection's noise out of range";
    if (c->det_trial > c->k || !(isfinite(c->det_probe) && c->det_probe >= 0.0 && c->det_probe <= c->probe_max)
        || c->det_probes < 0 || c->det_probes > PIEZO_DETECT_PROBES)
        return "delay detection trial out of range";
    if (c->k_delay > c->k || c->k_search > c->k_delay || c->det_clock > c->k - c->k_search
        || (c->auto_delay && (c->n_detections < 1 || c->n_detections > c->k + 1))
        || (!c->auto_delay && c->n_detections != 0))
        return "delay detection counters out of range";
    if (!all_finite(c->det_theta, PIEZO_DETECT_THETA) || !all_finite(c->det_P, PIEZO_DETECT_P)
        || !all_finite(c->det_score, PIEZO_DETECT_N) || !isfinite(c->r_prev)
        || !all_finite(c->preview_value, PIEZO_PREVIEW_RING))
        return "delay detection or preview values not finite";
    if (!(isfinite(c->observer) && c->observer >= 0.0 && c->observer < 1.0)) return "mv.observer out of range";
    if ((c->rls_enabled != 0 && c->rls_enabled != 1) || (c->sat_enabled != 0 && c->sat_enabled != 1))
        return "rls.enabled or sat.enabled is not 0 or 1";
    if (!(isfinite(c->lambda_u) && c->lambda_u >= 0.0)) return "mv.lambda_u out of range";
    if (!(isfinite(c->forgetting) && c->forgetting > 0.0 && c->forgetting <= 1.0)) return "rls.forgetting out of range";
    if (c->inv_forgetting != 1.0 / c->forgetting) return "the reciprocal of rls.forgetting kept from init does not match rls.forgetting";
    if (!(isfinite(c->p0) && c->p0 > 0.0 && isfinite(c->trace_max) && c->trace_max >= 4.0 * c->p0))
        return "rls.p0 or rls.trace_max out of range";
    if (!(isfinite(c->sat_v_min) && isfinite(c->sat_v_max) && (!c->sat_enabled || c->sat_v_max > c->sat_v_min)))
        return "sat.v_min or sat.v_max out of range";
    if ((c->robust != 0 && c->robust != 1) || !(isfinite(c->excitation) && c->excitation >= 0.0)
        || c->excitation_samples > 9007199254740992ULL
        || !(isfinite(c->variance_max) && c->variance_max > 0.0)
        || !(isfinite(c->p0_loop) && c->p0_loop > 0.0 && 4.0 * c->p0_loop <= c->trace_max)
        || !(isfinite(c->integral_gain) && c->integral_gain >= 0.0 && c->integral_gain < 1.0))
        return "rls.robust, rls.excitation*, rls.variance_max, rls.p0_loop or mv.integral out of range";
    if (!(isfinite(c->noise_y) && c->noise_y >= 0.0 && isfinite(c->noise_y2) && c->noise_y2 >= 0.0
          && isfinite(c->noise_e) && c->noise_e >= 0.0
          && isfinite(c->r_anchor) && isfinite(c->offset) && isfinite(c->integral) && isfinite(c->r_last)
          && isfinite(c->r_last2) && isfinite(c->r_velocity)
          && all_finite(c->yd_value, PIEZO_MV_Q_RING)) || c->excite_left > c->excitation_samples || c->jump_left > 2 * (PIEZO_MV_MAX_D + 2)
        || (!c->robust && (c->noise_y != 0.0 || c->noise_y2 != 0.0 || c->noise_e != 0.0 || c->offset != 0.0 || c->excite_left != 0
                           || c->r_anchor != 0.0 || c->r_velocity != 0.0))
        || (c->integral_gain == 0.0 && c->integral != 0.0))
        return "robust adaptation or integral action state out of range";
    for (i = 0; i < PIEZO_MV_Q_RING; ++i)
        if (c->yd_tag[i] != 0 && (c->yd_tag[i] > c->k + PIEZO_MV_Q_RING || (c->yd_tag[i] - 1) % PIEZO_MV_Q_RING != (uint64_t)i))
            return "a kept reference's sample is not its slot's or too far ahead";
    if (!(isfinite(c->pred_error_max) && c->pred_error_max > 0.0)) return "monitor.pred_error_max out of range";
    if (c->divergence_samples > 2147483647u) return "monitor.divergence_samples out of range";
    if (c->mon_forgetting != monitor_forgetting((int)c->divergence_samples))
        return "the monitor's window kept from init does not match monitor.divergence_samples";
    if (!(isfinite(c->mon_share) && isfinite(c->mon_weight) && c->mon_share >= 0.0 && c->mon_share <= c->mon_weight
          && c->mon_weight <= (double)c->k))
        return "monitor share out of range";
    if (!(all_finite(c->theta_nominal, 4) && c->theta_nominal[2] > 0.0)) return "nominal model not finite or b1 <= 0";
    if (!all_finite(c->theta, 4) || !all_finite(c->P, 16) || !all_finite(c->y_prev, 2)
        || !all_finite(c->q_ring, PIEZO_MV_Q_RING))
        return "estimates, covariance or past values not finite";
    /* the loop's covariance and each candidate's stay bitwise symmetric (rls_step) */
    for (m = 0; m <= PIEZO_DETECT_N; ++m) {
        const double *P = m == 0 ? c->P : &c->det_P[16 * (m - 1)];
        for (i = 0; i < 4; ++i)
            for (j = 0; j < i; ++j)
                if (memcmp(&P[4 * i + j], &P[4 * j + i], sizeof P[0]) != 0)
                    return m == 0 ? "covariance not symmetric" : "a delay candidate's covariance not symmetric";
    }
    if (!(isfinite(c->max_abs_pred_error) && c->max_abs_pred_error >= 0.0)) return "largest |pred_error| not finite";
    if (c->n_saturated > c->k || c->n_large_error > c->k || c->run_saturated > c->n_saturated
        || c->run_large_error > c->n_large_error || c->n_large_settled > c->n_large_error
        || (c->n_large_settled > 0 ? c->k_first_large_settled >= c->k || c->k_first_large_settled
                                     < c->k_first_large_error : c->k_first_large_settled != 0))
        return "monitor counts exceed the sample count";
    if ((c->n_saturated > 0 && c->k_first_saturated >= c->k) || (c->n_large_error > 0 && c->k_first_large_error >= c->k))
        return "monitor first-sample index beyond the sample count";
    /* a run reaching the window, or a share reaching its quarter, would have been refused */
    if (c->divergence_samples > 0 && c->run_large_error >= c->divergence_samples)
        return "monitor run at or beyond the divergence window";
    if (c->divergence_samples > 0 && k_loop - c->k_start > PIEZO_MONITOR_SHARE_MIN_SAMPLES
        && c->mon_share * 100.0 >= PIEZO_MONITOR_SHARE_PERCENT * (double)c->divergence_samples)
        return "monitor share at or beyond its bound";
    if ((fault = piezo_supervisor_check(&c->sup)) != NULL) return fault;
    if (c->sup.k != k_loop - c->k_start) return "supervisor sample counter differs from the controller's";
    if (c->verdict.fault < PIEZO_SUP_NONE || c->verdict.fault > PIEZO_SUP_FROZEN)
        return "supervision verdict out of range";
    /* outliers: sums within their weights, counts within the samples */
    if (!(isfinite(c->err_sum) && isfinite(c->err_weight) && isfinite(c->outlier_sum) && c->err_sum >= 0.0
          && c->err_weight >= 0.0 && c->err_weight <= (double)c->k && c->outlier_sum >= 0.0
          && c->outlier_sum <= (double)c->k && isfinite(c->first_outlier) && isfinite(c->first_outlier_error))
        || c->quiet > c->k || c->n_outliers > c->k || (c->suspect != 0 && c->suspect != 1)
        || (c->suspect && c->k == 0) || !isfinite(c->suspect_y) || !isfinite(c->suspect_error)
        || (!c->suspect && (c->suspect_y != 0.0 || c->suspect_error != 0.0))
        || (c->n_outliers > 0 ? c->k_first_outlier >= c->k
                              : c->k_first_outlier != 0 || c->first_outlier != 0.0 || c->first_outlier_error != 0.0))
        return "outlier sums or counts out of range";
    /* estimates with guarantees: the set is the one its parameters draw around the nominal model,
     * and the loop's estimates are in it; the fallback's window and counts in range */
    {
        double rows[PIEZO_ADMISSIBLE_ROWS][4], bounds[PIEZO_ADMISSIBLE_ROWS];
        if (!(isfinite(c->zero_min) && isfinite(c->pole_min) && isfinite(c->gain_lo) && isfinite(c->gain_hi)
              && c->gain_lo > 0.0 && c->gain_lo < 1.0 && c->gain_hi > 1.0))
            return "rls.zero_min, rls.pole_min or the admissible gain range out of range";
        admissible_rows(c->theta_nominal, c->zero_min, c->pole_min, c->gain_lo, c->gain_hi, rows, bounds);
        if (memcmp(rows, c->adm_c, sizeof rows) != 0 || memcmp(bounds, c->adm_d, sizeof bounds) != 0)
            return "the admissible set differs from the one rls.zero_min, rls.pole_min and the gain range draw";
        if (admissible_violated(c, c->theta_nominal) || (c->robust && admissible_violated(c, c->theta)))
            return "the estimates (or the nominal model) outside the admissible set";
    }
    if (!(isfinite(c->fallback_ratio) && c->fallback_ratio >= 0.0)
        || c->fallback_samples < 1 || c->fallback_forgetting != 1.0 - 1.0 / (double)c->fallback_samples
        || !(isfinite(c->fb_adapted) && c->fb_adapted >= 0.0 && isfinite(c->fb_nominal) && c->fb_nominal >= 0.0
             && isfinite(c->learned_rate) && c->learned_rate >= 0.0)
        || c->n_projections > c->k || c->n_fallbacks > c->k
        || (c->n_fallbacks > 0 ? (c->k_first_fallback >= c->k || c->first_fallback < PIEZO_FALLBACK_JUMP
                                  || c->first_fallback > PIEZO_FALLBACK_PREDICTION)
                               : (c->k_first_fallback != 0 || c->first_fallback != PIEZO_FALLBACK_NONE
                                  || c->first_fallback_value != 0.0 || c->first_fallback_other != 0.0))
        || !(isfinite(c->first_fallback_value) && isfinite(c->first_fallback_other))
        || (!c->robust && (c->fb_adapted != 0.0 || c->fb_nominal != 0.0 || c->learned_rate != 0.0
                           || c->n_projections != 0 || c->n_fallbacks != 0)))
        return "the fallback's window, learned rate or counts out of range";
    o = &c->out;
    if (!(isfinite(o->v) && isfinite(o->q) && isfinite(o->pred_error) && all_finite(o->theta, 4)))
        return "controller outputs not finite";
    if (o->saturated != 0 && o->saturated != 1) return "saturated output is not 0 or 1";
    if (o->adapting != 0 && o->adapting != 1) return "adapting output is not 0 or 1";
    if (o->fallback < PIEZO_FALLBACK_NONE || o->fallback > PIEZO_FALLBACK_PREDICTION
        || (o->fallback != PIEZO_FALLBACK_NONE && !c->robust))
        return "fallback output out of range";
    if (!(isfinite(o->noise) && o->noise >= 0.0)) return "noise output not finite or negative";
    if (o->delay < 0 || o->delay > PIEZO_MV_MAX_D || (o->preview != 0 && o->preview != 1))
        return "delay or preview output out of range";
    if (c->fault && (o->v != safe_v(c, c->v_fault, c->k - 1 - c->k_fault) || o->q != 0.0 || o->pred_error != 0.0
                     || o->saturated || o->preview || o->adapting || memcmp(o->theta, c->theta, sizeof o->theta) != 0))
        return "safe state's outputs differ from its ramp";
    return NULL;
}

/* the running length of a text written piece by piece (what it wanted) */
static void said(int *used, int w)
{
    if (w > 0) *used += w;
}

piezo_status piezo_controller_fault_status(int fault)
{
    if (fault == PIEZO_SUP_UNSTABLE) return PIEZO_ERR_UNSTABLE;
    if (fault == PIEZO_SUP_DIVERGED) return PIEZO_ERR_DIVERGED;
    return fault > 0 && fault <= PIEZO_SUP_FAULT_MAX ? PIEZO_ERR_FAULT : PIEZO_OK;
}

int piezo_controller_explain(const piezo_controller *c, int st, char *text, size_t size)
{
    piezo_sup_context ctx;
    memset(&ctx, 0, sizeof ctx);
    ctx.h = c != NULL ? c->sup.h : 0.0;
    return piezo_controller_explain_in(c, st, &ctx, text, size);
}

int piezo_controller_explain_in(const piezo_controller *c, int st, const piezo_sup_context *ctx,
                                char *text, size_t size)
{
    int used = 0;
#define AT (used >= 0 && (size_t)used < size ? text + used : NULL)
#define LEFT (used >= 0 && (size_t)used < size ? size - (size_t)used : 0)
    if (text != NULL && size > 0) text[0] = '\0';
    if (c == NULL || ctx == NULL) return 0;
    if (st == PIEZO_ERR_FAULT) {
        /* the words harness/fmu.py LOOP_FAILURES knows this Error by */
        said(&used, snprintf(AT, LEFT, "supervision stopped the loop (%s): ",
                                         piezo_supervisor_fault_name(c->verdict.fault)));
        said(&used, piezo_supervisor_explain_in(&c->verdict, ctx, AT, LEFT));
        return used;
    }
    if (st == PIEZO_ERR_UNSTABLE) {
        /* the share the refused sample would have made, of the whole window */
        double share = 100.0 * (c->mon_forgetting * c->mon_share + 1.0) / (double)c->divergence_samples;
        char beyond[256];
        piezo_controller_explain_bound(c, beyond, sizeof beyond);
        said(&used, snprintf(AT, LEFT, "the closed loop is unstable: |pred_error| was beyond "
             "%s in %.0f %% of the monitor's window of %llu samples, %llu of them "
             "in a row now (the loop is stopped at monitor.divergence_samples = %llu in a row, or at %d %% of "
             "the window, older samples counting less; where v was clipped the nominal model's prediction "
             "error counts too; largest |pred_error| so far %.6g um). ",
             beyond, share, (unsigned long long)c->divergence_samples,
             (unsigned long long)(c->run_large_error + 1),
             (unsigned long long)c->divergence_samples, PIEZO_MONITOR_SHARE_PERCENT, c->max_abs_pred_error));
        /* the supervisor's evidence: how far y_meas went against the model's expectation */
        if (c->sup.enabled && c->sup.travel_model > 0.0 && c->sup.travel_meas > 2.0 * c->sup.travel_model)
            said(&used, snprintf(AT, LEFT, "y_meas travelled %.3g times as far as the model "
                 "expects (%.4g um against %.4g um over about the last %llu samples): the loop's gain is far "
                 "above the model's. %s", c->sup.travel_meas / c->sup.travel_model, c->sup.travel_meas,
                 c->sup.travel_model, (unsigned long long)c->sup.weight,
                 ctx->internal ? "Compare the stage's parameters (pi.w0, pi.w[j], tf.*, creep.*) with the "
                 "controller's model (controller.pi.w0, controller.pi.w[j], controller.tf.*, controller.creep.*)"
                 : "Check the amplifier's gain, the units of v (V) and y_meas (um), and that the controller's "
                 "model (pi.*, tf.*, creep.*) is this stage's"));
        else if (ctx->internal)
            said(&used, snprintf(AT, LEFT, "Usual causes: the controller's loop delay d = %d %s does not match "
                 "this loop's, tf.delay + %d = %d (the stage's input delay tf.delay = %d, mv.feedthrough = %s), or "
                 "the stage's parameters (pi.w0, pi.w[j], tf.*, creep.*) far from the controller's model "
                 "(controller.pi.w0, controller.pi.w[j], controller.tf.*, controller.creep.*)", c->d,
                 !c->auto_delay ? "(1 + mv.delay, set)"
                 : c->detecting ? "(the start-up law's, still detecting)" : "(detected)",
                 ctx->feedthrough ? 1 : 2, ctx->stage_delay + (ctx->feedthrough ? 1 : 2), ctx->stage_delay,
                 ctx->feedthrough ? "true" : "false"));
        else
            said(&used, snprintf(AT, LEFT, "Usual causes: the controller's loop delay d = %d %s "
                 "does not match the loop (a master that hands the plant the controller's post-step output "
                 "removes a sample, as does mv.feedthrough; an extra plant or actuation delay adds one), a gain of "
                 "the sensor or amplifier far from the model's, or a plant far from the nominal model", c->d,
                 !c->auto_delay ? "(1 + mv.delay, set)"
                 : c->detecting ? "(the start-up law's, still detecting)" : "(detected)"));
        return used;
    }
    if (st == PIEZO_ERR_DIVERGED) {
        said(&used, snprintf(AT, LEFT, "the closed loop diverged: a value computed by the controller "
             "is not finite although its inputs are (loop delay d = %d%s; check it against %s)", c->d,
             c->auto_delay ? ", mv.delay = -1: detected" : " = 1 + mv.delay",
             ctx->internal ? "the stage's tf.delay and its parameters" : "the master and the plant"));
        return used;
    }
#undef AT
#undef LEFT
    return 0;
}

int piezo_controller_explain_safe_state(const piezo_controller *c, const piezo_sup_context *ctx,
                                        char *text, size_t size)
{
    int used;
    if (text != NULL && size > 0) text[0] = '\0';
    if (c == NULL || ctx == NULL || !c->fault) return 0;
    /* the words harness/fmu.py SAFE_STATE_WORDS knows this Warning by */
    used = snprintf(text, size, "sup.reaction = safe: from t = %.9g s the loop is held in its safe state "
                    "(sup.fault = %d): v ramps to 0 V over sup.ramp_time = %g s and stays there, adaptation "
                    "is frozen, the simulation goes on. Why: ", ctx->t0 + (double)(int64_t)c->k_fault * ctx->h,
                    c->fault, c->sup.ramp_time);
    if (used < 0) return 0;
    return used + piezo_controller_explain_in(c, piezo_controller_fault_status(c->fault), ctx,
                                              (size_t)used < size ? text + used : NULL,
                                              (size_t)used < size ? size - (size_t)used : 0);
}

/* the time of sample k where the loop is */
static double context_time(const piezo_sup_context *ctx, uint64_t k)
{
    return ctx->t0 + (double)(int64_t)k * ctx->h;
}

int piezo_controller_explain_reset(const piezo_controller *c, int refusal, const piezo_controller_input *in,
                                   uint64_t k, const piezo_sup_context *ctx, char *text, size_t size)
{
    double now, y_ref = in ? in->y_ref : 0.0, y_meas = in ? in->y_meas : 0.0;
    if (text != NULL && size > 0) text[0] = '\0';
    if (c == NULL || ctx == NULL) return 0;
    now = context_time(ctx, k);
    switch (refusal) {
    case PIEZO_RESET_ACCEPTED:
        /* c has restarted: its fault is gone, its count says how many times */
        return snprintf(text, size, "sup.reset accepted at t = %.9g s (reset %llu): the loop leaves its safe state "
                        "and restarts from the nominal model, its parameters kept, from the stage at rest at "
                        "y_meas = %.6g um: the law's reference ramps from there to y_d over sup.ramp_time = %g s, so "
                        "v ramps from 0 V; the estimates and the supervision start anew (sup.status 0 until it "
                        "verifies the loop again), the loop delay chosen and the sensor's measured noise are kept. "
                        "A fault of the response (inverted, gain, delay, unstable) cannot be seen at rest: if it "
                        "persists, the supervision stops the loop again once the stage moves",
                        now, (unsigned long long)c->n_resets, y_meas, c->sup.ramp_time);
    case PIEZO_RESET_NO_FAULT:
        return snprintf(text, size, "sup.reset raised at t = %.9g s while the loop runs (sup.fault = 0): there is "
                        "no safe state to leave, nothing was done", now);
    case PIEZO_RESET_RAMPING:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: v is still ramping to 0 V (sup.ramp_time = "
                        "%g s, until t = %.9g s); the loop stays in its safe state (sup.fault = %d). Lower sup.reset "
                        "and raise it again once v is at 0 V", now, c->sup.ramp_time,
                        context_time(ctx, c->k_fault + c->sup.ramp_samples), c->fault);
    case PIEZO_RESET_INPUTS:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: y_ref = %g um or y_meas = %g um is not "
                        "finite; the loop stays in its safe state (sup.fault = %d)", now, y_ref, y_meas, c->fault);
    case PIEZO_RESET_STUCK:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: the cause persists. y_meas still reads "
                        "%.9g um, to the bit what it read at the verdict (t = %.9g s), although v went from %g V to "
                        "0 V since: the sensor is still frozen, or v still does not reach the stage (sup.fault = "
                        "%d, %s). Check the sensor, its cable and the amplifier, then lower sup.reset and raise "
                        "it again", now, y_meas, context_time(ctx, c->k_fault), c->v_fault, c->fault,
                        piezo_supervisor_fault_name(c->fault));
    case PIEZO_RESET_OUT_OF_REACH:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: the cause persists. The reference y_ref = "
                        "%.6g um is still beyond what the stage reached with v held at %g V (y_meas = %.6g um), by "
                        "more than sup.clip_error = %g um: restarted, the loop would be held at the rail again "
                        "(sup.fault = %d, %s). Bring the reference within reach, or widen sat.v_min..sat.v_max, "
                        "then lower sup.reset and raise it again", now, y_ref, c->v_fault, c->y_fault,
                        c->sup.clip_error, c->fault, piezo_supervisor_fault_name(c->fault));
    default:
        return 0;
    }
}

const char *piezo_controller_check_params(const piezo_controller *c, const piezo_controller_params *q)
{
    piezo_controller scratch;
    if (!c || !q) return "controller missing";
    if (piezo_controller_init(&scratch, q, NULL) != PIEZO_OK) return "parameters out of range";
    if ((q->mv_delay == PIEZO_MV_AUTO_DELAY) != c->auto_delay || (!c->auto_delay && c->d != 1 + q->mv_delay)
        || c->observer != q->mv_observer || c->fwd_pi.m != q->pi.m || c->inv_creep.exact != (q->creep_exact ? 1 : 0)
        || c->inv_creep.alpha != -q->creep_alpha || c->lambda_u != q->mv_lambda_u
        || c->rls_enabled != (q->rls_enabled ? 1 : 0) || c->sat_enabled != (q->sat_enabled ? 1 : 0)
        || c->forgetting != q->rls_forgetting || c->p0 != q->rls_p0 || c->trace_max != q->rls_trace_max
        || c->robust != q->rls_robust || c->excitation != q->rls_excitation
        || c->excitation_samples != scratch.excitation_samples || c->variance_max != q->rls_variance_max
        || c->p0_loop != q->rls_p0_loop || c->integral_gain != q->mv_integral
        || c->pred_error_max != q->monitor_pred_error_max
        || c->divergence_samples != (uint64_t)q->monitor_divergence_samples
        || (c->sat_enabled && (c->sat_v_min != q->sat_v_min || c->sat_v_max != q->sat_v_max))
        || c->sup.enabled != q->sup.enabled || c->sup.gain_min != q->sup.gain_min
        || c->sup.gain_max != q->sup.gain_max || c->sup.forgetting != scratch.sup.forgetting
        || c->sup.clip_samples != scratch.sup.clip_samples || c->sup.detect_samples != scratch.sup.detect_samples
        || c->sup.window != scratch.sup.window || c->sup.clip_error != q->sup.clip_error
        || c->sup.reaction != q->sup.reaction || c->sup.ramp_time != q->sup.ramp_time
        || c->sup.ramp_samples != scratch.sup.ramp_samples || c->probe_max != q->mv_probe_max
        || c->zero_min != scratch.zero_min || c->pole_min != q->rls_pole_min || c->gain_lo != q->sup.gain_min || c->gain_hi != q->sup.gain_max
        || c->fallback_ratio != q->rls_fallback_ratio || c->fallback_samples != scratch.fallback_samples)
        return "controller state does not match its parameters";
    return NULL;
}
