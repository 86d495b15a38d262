/* piezo_controller_setup.c - the controller's defaults, init, reset and restart. See
 * piezo_controller_internal.h. */
#include <math.h>
#include <string.h>
#include "piezo_controller_internal.h"
#include "piezo_plant.h"
#include "piezo_controller_params.h"

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
    /* the plain parameters' defaults (mv.observer, rls.forgetting, rls.robust, mv.integral, ...),
     * with the measurements that chose them, are in the controller's declaration:
     * piezo_controller_params.h */
#define PLAIN_DEFAULT(field, name, dflt, lo, hi, lo_open, hi_open, range) p->field = (dflt);
    PIEZO_CONTROLLER_PLAIN_PARAMS(PLAIN_DEFAULT)
#undef PLAIN_DEFAULT
    p->mv_delay = PIEZO_MV_AUTO_DELAY;   /* detected: 2 in a master that exchanges at
                                            communication points, 1 in true Gauss-Seidel */
    /* RLS tuning of the robust update (docs/model.md, adaptation): a trace bound of 100 (a
     * bound of 1000 tracked the mismatch case's tones 2-3 times better but burst on 10 of 200
     * tone runs of drawn stages, up to 68 um; 300 on 5, 100 on none) */
    p->rls_enabled = 1;
    p->rls_trace_max = 100.0;
    p->rls_excitation_time = 0.05;
    p->rls_p0_loop = 0.01;
    p->sat_enabled = 1;
    p->sat_v_min = -PIEZO_SAT_DEFAULT_V;
    p->sat_v_max = PIEZO_SAT_DEFAULT_V;
    p->monitor_divergence_samples = PIEZO_MONITOR_DEFAULT_SAMPLES;
    piezo_supervisor_default_params(&p->sup);
    /* estimates with guarantees (docs/model.md): measured on the stage family's days and the
     * paper's scenarios. The zero of B at 0.5 or above (a drift to -0.3 rang +-44 um; the
     * paper's tones move it to 0.66-0.95); b1 and the static gain are kept within the
     * supervision's sup.gain_min .. sup.gain_max times the nominal model's (piezo_supervisor.h);
     * the fallback's window 0.5 s (rls.pole_min and rls.fallback_ratio: the declaration) */
    p->rls_zero_min = 0.75;
    p->rls_fallback_window = 0.5;
}

/* lambda of the monitor's window: 1 - 1/monitor.divergence_samples (0: off) */
double piezo_ctl_monitor_forgetting(int window)
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
void piezo_ctl_admissible_rows(const double *n, double z, double p, double g_lo, double g_hi, double rows[][4],
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
    /* the plain parameters, each within its declared range (piezo_controller_params.h) */
#define PLAIN_CHECK(field, name, dflt, lo, hi, lo_open, hi_open, range) \
    if (!piezo_in_range((double)p->field, lo, hi, lo_open, hi_open)) \
        return piezo_refuse(diag, name, range, (double)p->field);
    PIEZO_CONTROLLER_PLAIN_PARAMS(PLAIN_CHECK)
#undef PLAIN_CHECK
    if (!(isfinite(p->rls_trace_max) && p->rls_trace_max >= 4.0 * p->rls_p0))
        return piezo_refuse(diag, "rls.trace_max", "[4 rls.p0, inf) (trace of the initial covariance)", p->rls_trace_max);
    if (!(isfinite(p->rls_excitation_time) && p->rls_excitation_time >= 0.0
          && p->rls_excitation_time <= 3600.0 && p->rls_excitation_time / p->h <= 9007199254740992.0))
        return piezo_refuse(diag, "rls.excitation_time", "[0, 3600] s (and at most 2^53 samples of h)",
                            p->rls_excitation_time);
    if (!(isfinite(p->rls_p0_loop) && p->rls_p0_loop > 0.0 && 4.0 * p->rls_p0_loop <= p->rls_trace_max))
        return piezo_refuse(diag, "rls.p0_loop", "(0, rls.trace_max / 4]", p->rls_p0_loop);
    if (p->sat_enabled) {
        if (!isfinite(p->sat_v_min)) return piezo_refuse(diag, "sat.v_min", "finite, < sat.v_max", p->sat_v_min);
        if (!(isfinite(p->sat_v_max) && p->sat_v_max > p->sat_v_min))
            return piezo_refuse(diag, "sat.v_max", "finite, > sat.v_min", p->sat_v_max);
    }
    if (p->monitor_divergence_samples < 0)
        return piezo_refuse(diag, "monitor.divergence_samples", "0..2147483647 samples (0: never)",
                            (double)p->monitor_divergence_samples);
    /* the admissible set must hold the nominal model: the estimates start there, and the fallback
     * returns there (tf.b1 > 0 and |tf.b2| <= 0.999 tf.b1 are checked above). A nominal zero below
     * rls.zero_min lowers the bound to it (admissible_zero_min), so the default suits any
     * identified stage */
    if (!(isfinite(p->rls_zero_min) && p->rls_zero_min >= -ZERO_RADIUS_MAX && p->rls_zero_min <= ZERO_RADIUS_MAX))
        return piezo_refuse(diag, "rls.zero_min", "[-0.999, 0.999] (lowest zero of B the estimates may have; "
                            "the nominal zero -tf.b2/tf.b1 when that is lower)", p->rls_zero_min);
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
        /* the rows use sup.gain_min and sup.gain_max before piezo_supervisor_init checks them:
         * the supervisor's plain parameters, each within its declared range, first */
#define SUP_PLAIN_CHECK(field, name, dflt, lo, hi, lo_open, hi_open, range) \
        if (!piezo_in_range((double)p->sup.field, lo, hi, lo_open, hi_open)) \
            return piezo_refuse(diag, name, range, (double)p->sup.field);
        PIEZO_SUPERVISOR_PLAIN_PARAMS(SUP_PLAIN_CHECK)
#undef SUP_PLAIN_CHECK
        piezo_ctl_admissible_rows(nominal, admissible_zero_min(p), p->rls_pole_min, p->sup.gain_min, p->sup.gain_max, rows, bounds);
        for (i = 0; i < PIEZO_ADMISSIBLE_ROWS; ++i)
            if (piezo_ctl_admissible_excess(rows[i], bounds[i], nominal) > 0.0)
                return piezo_refuse(diag, who[i], i < 3 ? "a value below both nominal poles (tf.a1, tf.a2: real "
                                    "poles in [rls.pole_min, 1 - 1e-4], or complex ones inside their hull)"
                                    : "a set that holds the nominal model", i < 3 ? p->rls_pole_min
                                    : (i < 5 ? p->rls_zero_min : (i == 5 || i == 7 ? p->sup.gain_max
                                                                                    : p->sup.gain_min)));
    }
    if (!(isfinite(p->rls_fallback_window) && p->rls_fallback_window > 0.0 && p->rls_fallback_window <= 3600.0))
        return piezo_refuse(diag, "rls.fallback_window", "(0, 3600] s (window of the prediction test, at least "
                            "one sample)", p->rls_fallback_window);

    /* a declared noise takes every sample's y_meas for a fresh reading: inputs held over a step repeat it */
    if (p->sup.enabled && p->mv_hold_inputs && p->sup.sensor_noise > 0.0)
        return piezo_refuse(diag, "sup.sensor_noise", "0 while mv.hold_inputs = true (inputs held over a step "
                            "repeat a reading, which the declared noise would take for a frozen sensor)",
                            p->sup.sensor_noise);
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
#define PLAIN_COPY(field, copy, name, lo, hi, lo_open, hi_open) c->copy = p->field;
    PIEZO_CONTROLLER_PLAIN_COPIES(PLAIN_COPY)
#undef PLAIN_COPY
    c->rls_enabled = p->rls_enabled ? 1 : 0;
    c->inv_forgetting = 1.0 / p->rls_forgetting;
    c->trace_max = p->rls_trace_max;
    c->excitation_samples = rounded_samples(p->rls_excitation_time, p->h);
    c->p0_loop = p->rls_p0_loop;
    c->sat_enabled = p->sat_enabled ? 1 : 0;
    c->sat_v_min = p->sat_v_min;
    c->sat_v_max = p->sat_v_max;
    c->divergence_samples = (uint64_t)p->monitor_divergence_samples;
    c->mon_forgetting = piezo_ctl_monitor_forgetting(p->monitor_divergence_samples);
    c->theta_nominal[0] = p->tf_a1;
    c->theta_nominal[1] = p->tf_a2;
    c->theta_nominal[2] = p->tf_b1;
    c->theta_nominal[3] = p->tf_b2;
    c->zero_min = admissible_zero_min(p);
    c->gain_lo = p->sup.gain_min;
    c->gain_hi = p->sup.gain_max;
    piezo_ctl_admissible_rows(c->theta_nominal, c->zero_min, c->pole_min, c->gain_lo, c->gain_hi, c->adm_c, c->adm_d);
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
        piezo_ctl_detection_start(c);
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
    c->suspect = c->stale = 0;
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
