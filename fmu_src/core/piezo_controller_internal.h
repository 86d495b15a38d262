/* piezo_controller_internal.h - what the controller's files share and no caller sees.
 *
 * The controller is one module in several files, split where the work differs (docs/model.md):
 *   piezo_controller.c          the sample: the law, the estimates' update, the outlier and
 *                               fallback tests, the safe state's samples, the commit;
 *   piezo_controller_detect.c   the loop delay's detection (its candidates, probes, choice);
 *   piezo_controller_setup.c    the defaults, init, reset, the restart from the safe state;
 *   piezo_controller_check.c    the check of a restored state and of a parameter change;
 *   piezo_controller_explain.c  the messages.
 * The sample's own helpers stay static in piezo_controller.c (so the compiler treats them as
 * before the split); the other files reach the few they need through the piezo_ctl_ functions
 * below, which are thin calls of them.
 */
#ifndef PIEZO_CONTROLLER_INTERNAL_H
#define PIEZO_CONTROLLER_INTERNAL_H

#include <string.h>

#include "piezo_controller.h"

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
/* samples the measured noise takes to forget the start: a loop's first samples (a tone from t = 0,
 * its transient) start the tracker far above the sensor's noise, and it steps down by NOISE_STEP */
#define NOISE_SETTLE 100

/* Where the robust update restarts its estimator (a fallback; the projection's last resort): the
 * nominal model and P = rls.p0_loop I */
static inline void piezo_ctl_restart_estimates(const piezo_controller *c, double *theta, double *P)
{
    int j;
    memcpy(theta, c->theta_nominal, 4 * sizeof(double));
    for (j = 0; j < 16; ++j) P[j] = j % 5 == 0 ? c->p0_loop : 0.0;
}

/* piezo_controller.c */
double piezo_ctl_rls_error(const piezo_controller *c, const double *theta, int d, double y);
void piezo_ctl_rls_gain(const piezo_controller *c, const double *theta_in, const double *P, int d, double e,
                        double lambda, double inv_lambda, double trace_max, double *theta, double *P_new);
void piezo_ctl_project(const piezo_controller *c, double *th);
void piezo_ctl_detect_carry(const piezo_controller *c, piezo_controller_sample *s);
int piezo_ctl_all_finite(const double *x, int n);
double piezo_ctl_admissible_excess(const double *row, double d, const double *th);
int piezo_ctl_admissible_violated(const piezo_controller *c, const double *th);
double piezo_ctl_safe_v(const piezo_controller *c, double v0, uint64_t j);
/* piezo_controller_detect.c */
void piezo_ctl_detection_start(piezo_controller *c);
double piezo_ctl_detect_update(const piezo_controller *c, double y, piezo_controller_sample *s);
/* piezo_controller_setup.c */
double piezo_ctl_monitor_forgetting(int window);
void piezo_ctl_admissible_rows(const double *n, double z, double p, double g_lo, double g_hi, double rows[][4],
                               double *d);

#endif
