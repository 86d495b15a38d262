/* piezo_supervisor.c - supervision of the closed loop. See piezo_supervisor.h. */
#include <math.h>
#include <string.h>
#include "piezo_supervisor.h"
#include "piezo_controller_params.h"

/* Defaults (docs/model.md, supervision; the margins measured on the legitimate family are in
 * docs/robustness.md; the plain parameters' defaults, sup.gain_min, sup.gain_max, sup.ramp_time
 * and sup.clip_error, with why, are in the controller's declaration: piezo_controller_params.h):
 * v stayed clipped at most 669 samples (0.33 s) with limits at half the peak needed; a delay was
 * chosen within 103 samples (51.5 ms). */
#define DEFAULT_CLIP_TIME 0.5
#define DEFAULT_DETECT_TIME 0.5
#define WINDOW_MIN 20
#define WINDOW_MAX 1000000

void piezo_supervisor_default_params(piezo_supervisor_params *p)
{
    if (!p) return;
#define PLAIN_DEFAULT(field, name, dflt, lo, hi, lo_open, hi_open, range) p->field = (dflt);
    PIEZO_SUPERVISOR_PLAIN_PARAMS(PLAIN_DEFAULT)
#undef PLAIN_DEFAULT
    p->window = PIEZO_SUP_DEFAULT_WINDOW;
    p->clip_time = DEFAULT_CLIP_TIME;
    p->detect_time = DEFAULT_DETECT_TIME;
    p->reaction = PIEZO_SUP_REACT_ERROR;
}

/* samples of a duration t at h, at least 1, saturated far below 2^63 */
static uint64_t samples_of(double t, double h)
{
    double n = ceil(t / h - 1e-9);
    if (!(n >= 1.0)) return 1;
    if (n > 9.0e15) return (uint64_t)9.0e15;
    return (uint64_t)n;
}

piezo_status piezo_supervisor_init(piezo_supervisor *s, const piezo_supervisor_params *p,
                                   double a1, double a2, double b1, double b2, double h, piezo_diag *diag)
{
    if (!s || !p) return PIEZO_ERR_NULL;
    /* the plain parameters, each within its declared range (piezo_controller_params.h) */
#define PLAIN_CHECK(field, name, dflt, lo, hi, lo_open, hi_open, range) \
    if (!piezo_in_range((double)p->field, lo, hi, lo_open, hi_open)) \
        return piezo_refuse(diag, name, range, (double)p->field);
    PIEZO_SUPERVISOR_PLAIN_PARAMS(PLAIN_CHECK)
#undef PLAIN_CHECK
    if (p->window < WINDOW_MIN || p->window > WINDOW_MAX)
        return piezo_refuse(diag, "sup.window", "20..1000000 samples", (double)p->window);
    if (!(isfinite(p->clip_time) && p->clip_time > 0.0))
        return piezo_refuse(diag, "sup.clip_time", "(0, inf) s", p->clip_time);
    if (!(isfinite(p->detect_time) && p->detect_time > 0.0))
        return piezo_refuse(diag, "sup.detect_time", "(0, inf) s", p->detect_time);
    if (p->reaction != PIEZO_SUP_REACT_ERROR && p->reaction != PIEZO_SUP_REACT_SAFE)
        return piezo_refuse(diag, "sup.reaction", "0 (error: a verdict fails the step) or 1 (safe: v ramps "
                            "to 0 V and the simulation goes on)", (double)p->reaction);
    memset(s, 0, sizeof *s);
#define PLAIN_COPY(field, copy, name, lo, hi, lo_open, hi_open) s->copy = p->field;
    PIEZO_SUPERVISOR_PLAIN_COPIES(PLAIN_COPY)
#undef PLAIN_COPY
    s->forgetting = 1.0 - 1.0 / (double)p->window;
    s->clip_samples = samples_of(p->clip_time, h);
    s->detect_samples = samples_of(p->detect_time, h);
    s->window = (uint64_t)p->window;
    s->reaction = p->reaction;
    s->ramp_samples = p->ramp_time > 0.0 ? samples_of(p->ramp_time, h) : 0;
    s->a1 = a1;
    s->a2 = a2;
    s->b1 = b1;
    s->b2 = b2;
    s->h = h;
    piezo_supervisor_reset(s);
    return PIEZO_OK;
}

void piezo_supervisor_reset(piezo_supervisor *s)
{
    if (!s) return;
    s->k = 0;
    s->y1 = s->y2 = s->r1 = s->r2 = 0.0;
    s->z1 = s->zr1 = s->w1 = 0.0;
    memset(s->dw, 0, sizeof s->dw);
    memset(s->sww, 0, sizeof s->sww);
    s->szz = s->srr = 0.0;
    memset(s->szw, 0, sizeof s->szw);
    memset(s->srw, 0, sizeof s->srw);
    s->yhat1 = s->yhat2 = 0.0;
    s->candidate = s->candidate_run = 0;
    s->status = 0;
    s->gain = 0.0;
    s->delay = 0;
    s->k_verified = 0;
    s->verified_gain = 0.0;
    s->clip_error_sum = 0.0;
    s->y_same = 0;
    memset(s->ref, 0, sizeof s->ref);
    s->ref_head = 0;
    s->weight = s->travel_model = s->travel_meas = 0.0;
    s->followed_gain = s->reversals = s->steps2 = s->dy1 = 0.0;
    s->followed_n = s->followed_peak_n = 0;
    s->followed_peak = s->dw_peak = 0.0;
    s->min_step = s->big_steps = s->repeats = 0.0;
    memset(s->yhat_frozen, 0, sizeof s->yhat_frozen);
    memset(s->yhat_turned, 0, sizeof s->yhat_turned);
    s->yhat_slow = 0.0;
    s->v2 = 0.0;
    s->v_dir = 0;
    s->bridged_run = 0;
}

/* A stage at rest at y: A(1) y = B(1) q in the model, so z = A(1) y for every past sample, and
 * the model's own prediction rests at w / A(1) */
void piezo_supervisor_restart(piezo_supervisor *s, double y, double w)
{
    double a;
    if (!s) return;
    a = 1.0 + s->a1 + s->a2;
    piezo_supervisor_reset(s);
    s->y1 = s->y2 = s->r1 = s->r2 = y;
    s->z1 = s->zr1 = a * y;
    s->w1 = w;
    s->yhat1 = s->yhat2 = s->yhat_slow = w / a;
}

/* Sww_d(k) = Sww_1(k - d + 1): the new one for d = 1, the kept ones for d >= 2 */
static double sww_of(const piezo_supervisor *s, const piezo_supervisor_next *n, int d)
{
    return d == 1 ? n->sww1 : s->sww[d - 2];
}

/* E_d = Szz - Szw_d^2 / Sww_d (Szz when Sww_d = 0: nothing expected) */
static double unexplained(const piezo_supervisor *s, const piezo_supervisor_next *n, int d)
{
    double sww = sww_of(s, n, d);
    return sww > 0.0 ? n->szz - n->szw[d - 1] * (n->szw[d - 1] / sww) : n->szz;
}

/* the delay with the least unexplained energy (most explained Szw^2 / Sww; ties:
 * the shorter), by cross-multiplication: no division per candidate */
static int best_delay(const piezo_supervisor *s, const piezo_supervisor_next *n)
{
    int d, best = 0;
    double num = 0.0, den = 1.0;
    for (d = 1; d <= PIEZO_MV_MAX_D; ++d) {
        double sww = d == 1 ? n->sww1 : s->sww[d - 2], szw2 = n->szw[d - 1] * n->szw[d - 1];
        if (sww > 0.0 && (best == 0 || szw2 * den > num * sww)) {
            best = d;
            num = szw2;
            den = sww;
        }
    }
    return best;
}

/* The quantisation floor of dz's energy over the window: a reading on a grid of step q (its
 * smallest step seen) hides up to q^2/12 of dz's energy a sample, times sum c_i^2 of
 * Delta A = (1, a1 - 1, a2 - a1, -a2) (0 before y_meas ever stepped) */
static double quantisation_floor(const piezo_supervisor *s, const piezo_supervisor_next *n)
{
    double c1 = s->a1 - 1.0, c2 = s->a2 - s->a1;
    return n->weight * s->min_step * s->min_step / 12.0 * (1.0 + c1 * c1 + c2 * c2 + s->a2 * s->a2);
}

/* A gain that changed from the one followed since the loop was verified (the mean of the verified
 * judgements' gains), by the factor PIEZO_SUP_DROP_PERCENT / 100 down or PIEZO_SUP_RISE_PERCENT / 100
 * up. Evidence that one sample carries (its change of B q beyond PIEZO_SUP_PEAK_PERCENT % of Sww_1: a
 * stop, a start, a reversal, where a stage answers through its own hysteresis' local slope, not the
 * model's) is judged against the lower of that mean and the mean of such judgements alone (the higher
 * for a rise), and by PIEZO_SUP_DROP_FIRST_PERCENT while none of them was followed yet. *followed:
 * the gain judged against. */
static int peak_evidence(const piezo_supervisor_next *n)
{
    return n->dw_peak * 100.0 > PIEZO_SUP_PEAK_PERCENT * n->sww1;
}

/* A followed mean moved toward a verified gain g by its n-th judgement: weight 1/n while that is
 * above JUDGE_EVERY / window, that from then on */
static double follow(const piezo_supervisor *s, double mean, uint64_t n, double g)
{
    double w = (double)PIEZO_SUP_JUDGE_EVERY / (double)s->window;
    if (1.0 / (double)n > w)
        w = 1.0 / (double)n;
    return mean + (g - mean) * w;
}

static int gain_changed(const piezo_supervisor *s, const piezo_supervisor_next *n, double g, double *followed)
{
    double lo = s->followed_gain, hi = s->followed_gain, drop = PIEZO_SUP_DROP_PERCENT;
    *followed = s->followed_gain;
    if (s->followed_n < PIEZO_SUP_CONFIRM) return 0;
    if (peak_evidence(n)) {
        if (s->followed_peak_n < PIEZO_SUP_CONFIRM) drop = PIEZO_SUP_DROP_FIRST_PERCENT;
        else if (s->followed_peak < lo) lo = s->followed_peak;
        else hi = s->followed_peak;
    }
    if (lo * 100.0 > drop * g) {
        *followed = lo;
        return 1;
    }
    *followed = hi;
    return g * 100.0 > PIEZO_SUP_RISE_PERCENT * hi;
}

/* The response verdict of the evaluated statistics: a fault kind, 0 for a
 * verified loop, -1 without strong evidence. *gain, *delay: the best fit. */
static int response_kind(const piezo_supervisor *s, const piezo_supervisor_input *in,
                         const piezo_supervisor_next *n, double *gain, int *delay)
{
    int b = best_delay(s, n), law_ok, d;
    double sww, g, e_best, explained;
    if (b == 0 || s->k < PIEZO_SUP_MIN_SAMPLES
        || n->travel_model * 100.0 < PIEZO_SUP_TRAVEL_PERCENT * in->error_bound)
        return -1;
    sww = sww_of(s, n, b);
    g = n->szw[b - 1] / sww;
    e_best = n->szz - n->szw[b - 1] * g;
    /* a response smaller than the grid is not evidence of none */
    {
        double floor_q = quantisation_floor(s, n);
        if (e_best < floor_q) e_best = floor_q;
    }
    /* the response the fit explains, or the one the model expects when that is larger */
    explained = sww * (g * g > 1.0 ? g * g : 1.0);
    if (!(explained >= PIEZO_SUP_EVIDENCE * e_best)) return -1;
    *gain = g;
    *delay = b;
    if (g <= -s->gain_min) return PIEZO_SUP_INVERTED;
    if (fabs(g) < s->gain_min) return PIEZO_SUP_NO_RESPONSE;
    if (g > s->gain_max) return PIEZO_SUP_GAIN_HIGH;
    /* the delays the law runs: 1..3 while it detects them, else its own */
    law_ok = in->auto_delay ? b <= PIEZO_SUP_DEFAULT_DETECTABLE : b == in->law_delay;
    if (!law_ok) {
        double e_law = INFINITY;
        if (in->auto_delay) {
            for (d = 1; d <= PIEZO_SUP_DEFAULT_DETECTABLE; ++d) {
                double e = unexplained(s, n, d);
                if (e < e_law) e_law = e;
            }
        } else if (in->law_delay >= 1 && in->law_delay <= PIEZO_MV_MAX_D) {
            e_law = unexplained(s, n, in->law_delay);
        } else {
            e_law = 0.0;        /* a delay beyond the tested ones: no verdict on it */
        }
        if (e_law * 100.0 >= PIEZO_SUP_DELAY_PERCENT * explained) return PIEZO_SUP_DELAY;
    }
    /* a gain that changed from the one followed since the loop was verified */
    {
        double followed;
        if (gain_changed(s, n, g, &followed)) return PIEZO_SUP_GAIN_CHANGED;
    }
    return 0;
}

/* y_meas frozen by its noise: constant for m samples (y_same of them equal to the one before),
 * although before it reversed its direction in PIEZO_SUP_FROZEN_PERCENT % of the samples and
 * stepped by more than PIEZO_SUP_BIG_STEP_PERCENT % of its smallest step in
 * PIEZO_SUP_FROZEN_BIG_PERMILLE per mille of them (a sensor whose noise showed), and m is
 * at least PIEZO_SUP_STUCK_SAME and sup.window or as many as a chance of e^-PIEZO_SUP_STUCK_LOG_ODDS (7e-13)
 * allows, p^m <= e^-L, for the share p of equal samples before (a 20 nm sensor on a 2 nm grid
 * repeats 2 % of its samples: 8 samples; a sensor updated every 20 samples 95 %: 540, so
 * sup.window). Over the constant stretch of m samples the window's weight grew by
 * S_m = sum_{j<m} lambda^j, its repeats by S_m and its reversals by none, so the shares before it
 * are (sum - S_m) / (weight - S_m) (the sums at the stretch's start, all scaled by lambda^m).
 * *share, *step_rms, *repeat_share: the evidence. */
static int frozen(const piezo_supervisor *s, const piezo_supervisor_next *n, double *share, double *step_rms,
                  double *repeat_share)
{
    double lam = s->forgetting, stretch, before, p, m;
    int b;
    if (n->y_same < PIEZO_SUP_STUCK_SAME)
        return 0;
    stretch = (1.0 - pow(lam, (double)n->y_same)) / (1.0 - lam);
    before = n->weight - stretch;
    if (!(before >= 1.0))
        return 0;
    *share = n->reversals / before;
    *step_rms = sqrt(n->steps2 / before);
    p = (n->repeats - stretch) / before;
    *repeat_share = p > 0.0 ? p : 0.0;
    if (!(*share * 100.0 >= PIEZO_SUP_FROZEN_PERCENT && n->big_steps * 1000.0 >= PIEZO_SUP_FROZEN_BIG_PERMILLE * before))
        return 0;
    /* m ln p <= -L, p at least 1e-3 (a stretch of PIEZO_SUP_STUCK_SAME does not rest on one share) */
    m = (double)n->y_same;
    if (n->y_same < s->window && m * log(p > 1e-3 ? p : 1e-3) > -(double)PIEZO_SUP_STUCK_LOG_ODDS)
        return 0;
    /* ... and the changes were noise: what the model's best fit leaves of dz beyond
     * PIEZO_SUP_FROZEN_FLOOR times the quantisation floor (a loop that chattered on a noise-free
     * reading, moving the stage itself, leaves no more than the grid's share: then it settles) */
    b = best_delay(s, n);
    return b > 0 && unexplained(s, n, b) > PIEZO_SUP_FROZEN_FLOOR * quantisation_floor(s, n);
}

/* y_meas frozen against its declared noise (sup.sensor_noise = sigma > 0). A live reading
 * quantize(y + n), n white N(0, sigma^2), lands in one cell of its grid (step q) with a chance of
 * at most
 *     p = erf(q / (2 sqrt(2) sigma)),
 * that of the cell centred on y, whatever y the stage is at; so m readings each equal to the one
 * before have a chance of p^m at most. Frozen when
 *     m ln p <= -PIEZO_SUP_STUCK_LOG_ODDS,   m = y_same >= PIEZO_SUP_STUCK_SAME,
 * q the smallest step y_meas ever made (a multiple of the grid's step: p only larger; none yet: no
 * verdict). 1 nm on a 2 nm grid: p = 0.683, m = 74; 20 nm: p = 0.040, m = 9. *p: the chance. */
static int frozen_declared(const piezo_supervisor *s, const piezo_supervisor_next *n, double *p)
{
    if (!(s->sensor_noise > 0.0) || !(n->min_step > 0.0) || n->y_same < PIEZO_SUP_STUCK_SAME)
        return 0;
    *p = erf(n->min_step / (2.8284271247461903 * s->sensor_noise));
    return *p < 1.0 && (double)n->y_same * log(*p) <= -(double)PIEZO_SUP_STUCK_LOG_ODDS;
}

/* y_meas held on an outlier: the reading jumped away from the model's prediction (an outlier, for
 * which the prediction stood in) and has held that value to the bit since, PIEZO_SUP_STUCK_SAME
 * samples in all: a sensor that died or stuck on a glitch (a stage bumped that far that reads the same
 * value to the bit, behind a noise-free sensor, would be taken for one: not measured) */
static int held_outlier(const piezo_supervisor_next *n)
{
    return n->bridged_run >= PIEZO_SUP_STUCK_SAME && n->y_same + 1 >= PIEZO_SUP_STUCK_SAME;
}

double piezo_supervisor_reading_floor(const piezo_supervisor *s, double noise)
{
    return 2.0 * s->min_step + PIEZO_SUP_STUCK_NOISE * noise;
}

/* y_meas stuck against the model: y_meas has not changed since sample f, and v has moved one way
 * since (y_same >= the loop's
 * delay d, 1..3, chosen) while the model says the stage moved, over the samples the constant
 * readings answer, |yhat(k - d + 1) - yhat(f - d + 1)| (yhat is the model's y_meas of a loop of
 * delay 1), so far that even sup.gain_min of that move is beyond two of the reading's steps and
 * PIEZO_SUP_STUCK_NOISE times its measured noise: a stage that moved that much shows it, whatever its
 * gain within the supervision's band. Both moves are taken less PIEZO_SUP_STUCK_CREEP_PERMILLE per
 * mille of |yhat - yhat_slow|, the distance from where the model's stage has been over the last
 * second: after a move the law goes on pushing q to hold the stage against its creep and
 * hysteresis, a move the model shows and the stage does not. 0 before y_meas ever changed (the "no
 * response" verdict's case). The move is returned in *move, 0 when not judged. */
static int stuck(const piezo_supervisor *s, const piezo_supervisor_input *in, const piezo_supervisor_next *n,
                 double *move, double *bound)
{
    int d = in->loop_delay > 0 ? in->loop_delay : in->law_delay;   /* detecting: the start-up law's 2 (a
                                        loop of 1 or 3 shifts the move by one sample, within the margin of
                                        PIEZO_SUP_STUCK_SPEED samples of the model's speed) */
    double now, near, far, creep, floor = piezo_supervisor_reading_floor(s, in->noise);
    *move = *bound = 0.0;
    if (d < 1 || d > 3 || n->y_same < (uint64_t)d || !(s->min_step > 0.0) || s->open_loop)
        return 0;
    now = d == 1 ? n->yhat : (d == 2 ? s->yhat1 : s->yhat2);
    /* less PIEZO_SUP_STUCK_SPEED samples of the model's mean speed over the window: its transient
     * after a fast move errs in proportion to the move */
    creep = PIEZO_SUP_STUCK_CREEP_PERMILLE * 1e-3 * fabs(now - n->yhat_slow);
    near = fabs(now - n->yhat_turned[d - 1]) - PIEZO_SUP_STUCK_SPEED * n->travel_model / n->weight - creep;
    far = fabs(now - n->yhat_frozen[d - 1]) - PIEZO_SUP_STUCK_SPEED * n->travel_model / n->weight - creep;
    *bound = floor > PIEZO_SUP_STUCK_MOVE_NM * 1e-3 ? floor : PIEZO_SUP_STUCK_MOVE_NM * 1e-3;
    if (near * s->gain_min > *bound) {
        *move = near;
        return 1;
    }
    *bound = floor > PIEZO_SUP_STUCK_FAR_NM * 1e-3 ? floor : PIEZO_SUP_STUCK_FAR_NM * 1e-3;
    *move = far;
    return far * s->gain_min > *bound;
}

/* the model's y_meas(k) from q (delay 1): yhat = -a1 yhat(k-1) - a2 yhat(k-2) + w, w = b1 q(k-1) + b2 q(k-2) */
static double model_next(const piezo_supervisor *s, double q1, double q2, double *w)
{
    *w = s->b1 * q1 + s->b2 * q2;
    return *w - s->a1 * s->yhat1 - s->a2 * s->yhat2;
}

int piezo_supervisor_may_be_live(const piezo_supervisor *s, double q1, double q2, int d)
{
    double w, now;
    if (d < 1 || d > 3)
        return 1;   /* not judged (as the stuck test) */
    now = d == 1 ? model_next(s, q1, q2, &w) : (d == 2 ? s->yhat1 : s->yhat2);
    return s->gain_min * fabs(now - s->yhat_frozen[d - 1]) < s->min_step;
}

void piezo_supervisor_evaluate(const piezo_supervisor *s, const piezo_supervisor_input *in,
                               piezo_supervisor_next *n)
{
    const double lam = s->forgetting;
    double dz, dzr, kind_gain = 0.0, e;
    int d, kind, kind_delay = 0;
    if (!s->enabled) {
        n->fault = PIEZO_SUP_NONE;  /* switched off: no statistics, no verdict */
        return;
    }
    n->stuck_move = 0.0;

    /* dz(k) = Delta[A y](k), dw(k) = Delta[B q](k-1) = w(k) - w(k-1) */
    n->z = in->y_meas + s->a1 * s->y1 + s->a2 * s->y2;
    n->zr = in->y_ref + s->a1 * s->r1 + s->a2 * s->r2;
    n->yhat = model_next(s, in->q1, in->q2, &n->w);
    dz = n->z - s->z1;
    dzr = n->zr - s->zr1;
    n->dw = n->w - s->w1;
    n->szz = lam * s->szz + dz * dz;
    n->srr = lam * s->srr + dzr * dzr;
    n->sww1 = lam * s->sww[0] + n->dw * n->dw;
    n->dw_peak = lam * s->dw_peak > n->dw * n->dw ? lam * s->dw_peak : n->dw * n->dw;
    /* Szw_d uses dw(k - d + 1): the new dw for d = 1, the kept ones (a shift register:
     * contiguous, so the loop vectorises) for d >= 2 */
    n->szw[0] = lam * s->szw[0] + dz * n->dw;
    for (d = 2; d <= PIEZO_MV_MAX_D; ++d)
        n->szw[d - 1] = lam * s->szw[d - 1] + dz * s->dw[d - 2];
    n->srw[0] = lam * s->srw[0] + dzr * n->dw;
    for (d = 2; d <= PIEZO_SUP_DEFAULT_DETECTABLE; ++d)
        n->srw[d - 1] = lam * s->srw[d - 1] + dzr * s->dw[d - 2];
    n->y_same = s->k > 0 && in->y_meas == s->y1 ? s->y_same + 1 : 0;
    /* the evidence: the distances travelled over the window */
    n->weight = lam * s->weight + 1.0;
    n->travel_model = lam * s->travel_model + fabs(n->yhat - s->yhat1);
    n->travel_meas = lam * s->travel_meas + fabs(in->y_meas - s->y1);
    n->yhat_slow = s->yhat_slow + (n->yhat - s->yhat_slow) * (1.0 / PIEZO_SUP_CREEP_SAMPLES);
    /* a live measurement's noise: its reversals of direction (the last change kept over equal
     * samples, so a quantised reading's up, equal, down counts) and its steps */
    {
        double dy = s->k > 0 ? in->y_meas - s->y1 : 0.0;
        double a = fabs(dy);
        n->reversals = lam * s->reversals + (dy * s->dy1 < 0.0 ? 1.0 : 0.0);
        n->steps2 = lam * s->steps2 + dy * dy;
        n->dy1 = dy != 0.0 ? dy : s->dy1;
        /* a big step that reverses the direction: noise's (a move's steps keep theirs) */
        n->big_steps = lam * s->big_steps + (s->min_step > 0.0 && dy * s->dy1 < 0.0
                                              && a * 100.0 > PIEZO_SUP_BIG_STEP_PERCENT * s->min_step ? 1.0 : 0.0);
        n->min_step = a > 0.0 && (s->min_step == 0.0 || a < s->min_step) ? a : s->min_step;
        n->repeats = lam * s->repeats + (n->y_same > 0 ? 1.0 : 0.0);
    }
    n->bridged_run = in->bridged ? s->bridged_run + 1 : 0;
    /* v's direction; a reversal restarts the stuck test's move as a change of y_meas does (right after
     * a reversal a stage answers by its hysteresis' initial slope, which may be far below the model's:
     * at the end of a 50 Hz scan the model moved 207 nm while the stage stood still) */
    {
        double dv = s->k > 0 ? in->v1 - s->v2 : 0.0;
        int dir = dv > 0.0 ? 1 : (dv < 0.0 ? -1 : s->v_dir);
        const double now[3] = { n->yhat, s->yhat1, s->yhat2 };
        n->v_dir = dir;
        memcpy(n->yhat_frozen, n->y_same == 0 ? now : s->yhat_frozen, sizeof n->yhat_frozen);
        memcpy(n->yhat_turned, n->y_same == 0 || (s->v_dir != 0 && dir != s->v_dir) ? now : s->yhat_turned,
               sizeof n->yhat_turned);
    }
    n->followed_gain = s->followed_gain;
    n->followed_n = s->followed_n;
    n->followed_peak = s->followed_peak;
    n->followed_peak_n = s->followed_peak_n;

    /* the response verdict, confirmed over PIEZO_SUP_CONFIRM samples */
    n->status = s->status;
    n->gain = s->gain;
    n->delay = s->delay;
    n->fault = PIEZO_SUP_NONE;
    /* judged every PIEZO_SUP_JUDGE_EVERY samples, and every sample while a fault candidate runs */
    kind = s->candidate != 0 || s->k % PIEZO_SUP_JUDGE_EVERY == 0
           ? response_kind(s, in, n, &kind_gain, &kind_delay) : -1;
    if (kind >= 0) {
        n->gain = kind_gain;
        n->delay = kind_delay;
    }
    if (kind > 0) {
        /* a gain that changed, then fell below sup.gain_min (or rose beyond sup.gain_max, or turned
         * over) is one fault going on: its run counts on */
        n->candidate = kind;
        n->candidate_run = kind == s->candidate || (s->candidate == PIEZO_SUP_GAIN_CHANGED && kind <= PIEZO_SUP_GAIN_HIGH)
                           ? s->candidate_run + 1 : 1;
    } else {
        n->candidate = 0;
        n->candidate_run = 0;
        if (kind == 0) {
            /* verified: the gain followed moves toward it, and so does the mean of the judgements
             * whose evidence one sample carried when this one's did */
            n->status = 1;
            n->followed_n = s->followed_n + 1;
            n->followed_gain = follow(s, s->followed_gain, n->followed_n, kind_gain);
            if (peak_evidence(n)) {
                n->followed_peak_n = s->followed_peak_n + 1;
                n->followed_peak = follow(s, s->followed_peak, n->followed_peak_n, kind_gain);
            }
        }
    }
    /* the clipping watchdog: mean |y_d - y_meas| over the clipped run */
    n->clip_error_sum = 0.0;
    if (in->clipped1) {
        int dl = in->law_delay >= 1 && in->law_delay <= PIEZO_SUP_REF_RING ? in->law_delay : 1;
        int at = s->ref_head + dl - 1;
        double target = s->k >= (uint64_t)dl ? s->ref[at < PIEZO_SUP_REF_RING ? at : at - PIEZO_SUP_REF_RING]
                                             : 0.0;
        e = fabs(target - in->y_meas);
        n->clip_error_sum = s->clip_error_sum + e;
    }
    if (s->open_loop) {
        /* no loop to judge the response or the delay of: no such verdict, and no candidate
         * carried into a connected sample (v held at a limit still stops it) */
        n->candidate = 0;
        n->candidate_run = 0;
    }
    if (n->candidate_run >= PIEZO_SUP_CONFIRM)
        n->fault = n->candidate;
    else if (in->clipped1 && in->clip_run >= s->clip_samples
             && n->clip_error_sum > s->clip_error * (double)in->clip_run)
        n->fault = PIEZO_SUP_CLIPPED;
    else if (in->detecting_for >= s->detect_samples && !s->open_loop)
        n->fault = PIEZO_SUP_UNDETECTED;
    else if (n->y_same > 0) {
        /* each of these needs y_meas unchanged since the sample before at least (held_outlier 3
         * samples, frozen PIEZO_SUP_STUCK_SAME, stuck the loop's delay): a reading that changed
         * skips their calls, n->stuck_move staying 0 */
        double share, step_rms, repeat_share, bound, chance;
        if (held_outlier(n) || frozen_declared(s, n, &chance) || frozen(s, n, &share, &step_rms, &repeat_share))
            n->fault = PIEZO_SUP_FROZEN;
        else if (stuck(s, in, n, &n->stuck_move, &bound))
            n->fault = PIEZO_SUP_NO_RESPONSE;   /* y_meas stuck, or v not reaching the stage: a quiet
                                                   reading does not tell them apart */
    }
}

void piezo_supervisor_commit(piezo_supervisor *s, const piezo_supervisor_input *in,
                             const piezo_supervisor_next *n, double r)
{
    int i;
    if (!s->enabled) {
        s->k += 1;
        return;
    }
    s->y2 = s->y1;
    s->y1 = in->y_meas;
    s->r2 = s->r1;
    s->r1 = in->y_ref;
    s->z1 = n->z;
    s->zr1 = n->zr;
    s->w1 = n->w;
    for (i = PIEZO_MV_MAX_D - 1; i > 0; --i) {     /* the shift registers: no call */
        s->dw[i] = s->dw[i - 1];
        s->sww[i] = s->sww[i - 1];
    }
    s->dw[0] = n->dw;
    s->sww[0] = n->sww1;
    s->szz = n->szz;
    s->srr = n->srr;
    memcpy(s->szw, n->szw, sizeof s->szw);
    memcpy(s->srw, n->srw, sizeof s->srw);
    s->yhat2 = s->yhat1;
    s->yhat1 = n->yhat;
    s->candidate = n->candidate;
    s->candidate_run = n->candidate_run;
    if (n->status && !s->status) {
        s->k_verified = s->k;
        s->verified_gain = n->gain;
    }
    s->status = n->status;
    s->gain = n->gain;
    s->delay = n->delay;
    s->clip_error_sum = n->clip_error_sum;
    s->y_same = n->y_same;
    s->ref_head = s->ref_head == 0 ? PIEZO_SUP_REF_RING - 1 : s->ref_head - 1;
    s->ref[s->ref_head] = r;
    s->weight = n->weight;
    s->travel_model = n->travel_model;
    s->travel_meas = n->travel_meas;
    s->followed_gain = n->followed_gain;
    s->followed_n = n->followed_n;
    s->followed_peak = n->followed_peak;
    s->followed_peak_n = n->followed_peak_n;
    s->dw_peak = n->dw_peak;
    s->reversals = n->reversals;
    s->steps2 = n->steps2;
    s->dy1 = n->dy1;
    s->min_step = n->min_step;
    s->big_steps = n->big_steps;
    s->repeats = n->repeats;
    memcpy(s->yhat_frozen, n->yhat_frozen, sizeof s->yhat_frozen);
    memcpy(s->yhat_turned, n->yhat_turned, sizeof s->yhat_turned);
    s->yhat_slow = n->yhat_slow;
    s->v2 = in->v1;
    s->v_dir = n->v_dir;
    s->bridged_run = n->bridged_run;
    s->k += 1;
}

void piezo_supervisor_verdict(const piezo_supervisor *s, const piezo_supervisor_input *in,
                              const piezo_supervisor_next *n, piezo_sup_verdict *v)
{
    int d, b;
    double window = 1.0 / (1.0 - s->forgetting);
    memset(v, 0, sizeof *v);
    v->fault = n->fault;
    v->k = s->k;
    v->loop_delay = in->loop_delay;
    v->auto_delay = in->auto_delay;
    b = best_delay(s, n);
    if (b > 0) {
        double sww = sww_of(s, n, b);
        double g = n->szw[b - 1] / sww;
        double e = n->szz - n->szw[b - 1] * g;
        v->gain = g;
        v->delay = b;
        v->fit = n->szz > 0.0 ? 1.0 - (e > 0.0 ? e : 0.0) / n->szz : 0.0;
    }
    /* y_ref as if it were the measurement, at the loop's delays */
    for (d = 1; d <= PIEZO_SUP_DEFAULT_DETECTABLE; ++d) {
        double sww = sww_of(s, n, d), g, e, fit;
        if (!(sww > 0.0) || !(n->srr > 0.0)) continue;
        g = n->srw[d - 1] / sww;
        e = n->srr - n->srw[d - 1] * g;
        fit = 1.0 - (e > 0.0 ? e : 0.0) / n->srr;
        if (fit > v->ref_fit) {
            v->ref_fit = fit;
            v->ref_gain = g;
        }
    }
    /* the evidence over the window (its weighted sums: about the last sup.window samples) */
    v->window = (uint64_t)(n->weight < window ? n->weight : window);
    v->travel_model = n->travel_model;
    v->travel_meas = n->travel_meas;
    v->y_meas = in->y_meas;
    v->v = in->v1;
    v->y_same = n->y_same;
    /* a real sensor repeats a value 16 times in a row only at rest (quantized, noise below its step) */
    v->y_constant = n->y_same + 1 >= (v->window < 16 ? v->window : 16);
    v->clip_v = in->clip_v;
    v->clip_samples = n->fault == PIEZO_SUP_UNDETECTED ? in->detecting_for : in->clip_run;
    v->error = in->clip_run > 0 ? n->clip_error_sum / (double)in->clip_run : 0.0;
    v->error_bound = s->clip_error;
    v->verified_gain = s->status ? s->verified_gain : 0.0;
    v->followed_gain = s->followed_gain;
    if (n->fault == PIEZO_SUP_GAIN_CHANGED)
        gain_changed(s, n, v->gain, &v->followed_gain);
    v->gain_min = s->gain_min;
    if (n->fault == PIEZO_SUP_FROZEN && held_outlier(n))
        v->bridged_error = in->bridged_error != 0.0 ? in->bridged_error : 1e-300;
    else if (n->fault == PIEZO_SUP_FROZEN && frozen_declared(s, n, &v->repeat_chance)) {
        v->declared_noise = s->sensor_noise;
        v->grid_step = n->min_step;
    } else if (n->fault == PIEZO_SUP_FROZEN)
        frozen(s, n, &v->reversal_share, &v->step_rms, &v->repeat_share);
    else if (n->fault == PIEZO_SUP_NO_RESPONSE && !stuck(s, in, n, &v->stuck_move, &v->stuck_bound))
        v->stuck_move = 0.0;
}

static int finite_all(const double *x, int n)
{
    int i;
    for (i = 0; i < n; ++i)
        if (!isfinite(x[i])) return 0;
    return 1;
}

const char *piezo_supervisor_check(const piezo_supervisor *s)
{
    int i;
    if (!s) return "supervisor missing";
    /* the plain parameters' copies, each within its declared range (piezo_controller_params.h) */
#define PLAIN_COPY_CHECK(field, copy, name, lo, hi, lo_open, hi_open) \
    if (!piezo_in_range((double)s->copy, lo, hi, lo_open, hi_open)) return name " out of range";
    PIEZO_SUPERVISOR_PLAIN_COPIES(PLAIN_COPY_CHECK)
#undef PLAIN_COPY_CHECK
    if (s->bridged_run > s->k)
        return "supervisor counters exceed the sample count";
    if ((s->status != 0 && s->status != 1)
        || (s->open_loop != 0 && s->open_loop != 1) || s->v_dir < -1 || s->v_dir > 1)
        return "supervisor flags are not 0 or 1";
    if (!(s->forgetting >= 1.0 - 1.0 / WINDOW_MIN && s->forgetting < 1.0)
        || s->clip_samples < 1 || s->detect_samples < 1 || !(isfinite(s->h) && s->h > 0.0)
        || s->window < WINDOW_MIN || s->window > WINDOW_MAX
        || (s->reaction != PIEZO_SUP_REACT_ERROR && s->reaction != PIEZO_SUP_REACT_SAFE)
        || s->ramp_samples != (s->ramp_time > 0.0 ? samples_of(s->ramp_time, s->h) : 0))
        return "supervisor parameters out of range";
    if (s->ref_head < 0 || s->ref_head >= PIEZO_SUP_REF_RING)
        return "supervisor ring index out of range";
    /* a candidate is a response kind: 1..4, or a changed gain */
    if (s->candidate < 0 || (s->candidate > PIEZO_SUP_DELAY && s->candidate != PIEZO_SUP_GAIN_CHANGED)
        || s->candidate_run < 0
        || s->candidate_run >= PIEZO_SUP_CONFIRM || (s->candidate == 0 && s->candidate_run != 0)
        || s->delay < 0 || s->delay > PIEZO_MV_MAX_D)
        return "supervisor verdict state out of range";
    if (s->y_same > s->k || (s->status ? s->k_verified >= s->k : s->k_verified != 0) || s->followed_n > s->k
        || (s->followed_n == 0) != (s->followed_gain == 0.0) || s->followed_peak_n > s->followed_n
        || (s->followed_peak_n == 0) != (s->followed_peak == 0.0))
        return "supervisor counters exceed the sample count";
    if (!finite_all(s->dw, PIEZO_MV_MAX_D) || !finite_all(s->sww, PIEZO_MV_MAX_D)
        || !finite_all(s->szw, PIEZO_MV_MAX_D) || !finite_all(s->srw, PIEZO_SUP_DEFAULT_DETECTABLE)
        || !finite_all(s->ref, PIEZO_SUP_REF_RING))
        return "supervisor values not finite";
    {
        double sc[] = { s->y1, s->y2, s->r1, s->r2, s->z1, s->zr1, s->w1, s->szz, s->srr, s->yhat1, s->yhat2,
                        s->gain, s->verified_gain, s->clip_error_sum, s->a1, s->a2, s->b1, s->b2,
                        s->weight, s->travel_model, s->travel_meas, s->followed_gain, s->reversals,
                        s->steps2, s->dy1, s->min_step, s->big_steps, s->repeats, s->yhat_frozen[0],
                        s->yhat_frozen[1], s->yhat_frozen[2], s->yhat_turned[0], s->yhat_turned[1],
                        s->yhat_turned[2], s->yhat_slow, s->v2, s->followed_peak, s->dw_peak };
        if (!finite_all(sc, (int)(sizeof sc / sizeof sc[0]))) return "supervisor values not finite";
    }
    if (s->szz < 0.0 || s->srr < 0.0 || s->clip_error_sum < 0.0 || s->travel_model < 0.0 || s->travel_meas < 0.0
        || s->weight > (double)s->k || s->followed_gain < 0.0 || s->reversals < 0.0 || s->reversals > s->weight
        || s->steps2 < 0.0 || s->min_step < 0.0 || s->big_steps < 0.0 || s->big_steps > s->weight
        || s->repeats < 0.0 || s->repeats > s->weight || s->followed_peak < 0.0 || s->dw_peak < 0.0
        || s->dw_peak > s->sww[0])
        return "supervisor sums negative or beyond their weight";
    for (i = 0; i < PIEZO_MV_MAX_D; ++i)
        if (s->sww[i] < 0.0) return "supervisor sums negative";
    return NULL;
}
