/* piezo_controller_detect.c - the loop delay's detection. See piezo_controller_internal.h. */
#include <math.h>
#include <string.h>
#include "piezo_controller_internal.h"

/* A candidate is chosen when its sum of squared a-priori errors is at most
 * DETECT_RATIO times every other candidate's, for PIEZO_DETECT_CONFIRM
 * consecutive samples. */
#define DETECT_RATIO (1.0 / PIEZO_DETECT_RATIO_INV)
/* With the robust update the delay candidates keep the tuning the detection was designed and
 * measured with (docs/cosimulation.md): forgetting 0.995, trace bound 100 (the loop's own
 * rls.forgetting and rls.trace_max are the robust update's; with the paper's update the
 * candidates use them, as before). With the loop's 0.99 and 1000 the candidates learn a
 * measurement that alternates +-10 um whatever v does so well that the divergence monitor
 * no longer stops it (measured: not within 3000 samples; 86 with 0.995 and 100). */
#define DETECT_FORGETTING 0.995
#define DETECT_TRACE_MAX 100.0

/* (Re)start delay detection: every candidate from the nominal model and the
 * initial covariance, sums at 0, the start-up law. */
void piezo_ctl_detection_start(piezo_controller *c)
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
/* The a-priori error of (theta_in, P) under delay d and, with update set, the update with the
 * paper's projection (the delay candidates, the paper's update). */
static double rls_step(const piezo_controller *c, const double *theta_in, const double *P, int d, double y,
                       int update, double lambda, double inv_lambda, double trace_max, double *theta, double *P_new)
{
    double e = piezo_ctl_rls_error(c, theta_in, d, y);
    if (!update) return e;
    piezo_ctl_rls_gain(c, theta_in, P, d, e, lambda, inv_lambda, trace_max, theta, P_new);
    piezo_ctl_project(c, theta);
    return e;
}
/* The one-step error the monitor judges while the detection runs, given its best candidate's: that
 * one's, but while the probes are buried the start-up law's own, the nominal model's at
 * PIEZO_DETECT_START_D (the candidates adapt while the reference moves, and on noisy data wander:
 * with a 200 nm sensor theirs wandered up to 26 um from y_meas while the stage tracked within
 * 0.65 um, and the monitor stopped 51 of 1300 runs of the stage's day's quick slice) */
static double detect_error(const piezo_controller *c, const piezo_controller_sample *s, double y, double best)
{
    return s->clock ? best : piezo_ctl_rls_error(c, c->theta_nominal, PIEZO_DETECT_START_D, y);
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
double piezo_ctl_detect_update(const piezo_controller *c, double y, piezo_controller_sample *s)
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
        piezo_ctl_detect_carry(c, s);
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
            piezo_ctl_restart_estimates(c, s->theta, s->P);
        } else {
            memcpy(s->theta, &s->det_theta[4 * best], sizeof s->theta);
            memcpy(s->P, &s->det_P[16 * best], sizeof s->P);
        }
    }
    return detect_error(c, s, y, err[best]);
}
