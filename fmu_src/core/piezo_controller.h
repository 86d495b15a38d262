/*
 * piezo_controller.h - adaptive compound controller (docs/model.md, controller):
 *
 *     y_meas(k) -> RLS update -> MV law -> q(k) -> inverse creep -> r(k)
 *               -> inverse PI -> v(k) [-> saturation]
 *
 * Loop model seen from q: y(k) = -a1 y(k-1) - a2 y(k-2) + b1 q(k-d) + b2 q(k-d-1),
 * d = 1 + mv_delay, i.e. A(z^-1) y = z^-d B(z^-1) q.
 * Diophantine: 1 = A E + z^-d Gd, deg E = d-1, deg Gd = 1, F = B E (deg d).
 * Predictor: y(k+d) = Gd y(k) + F q(k). MV (with control weighting lambda_u):
 *     q(k) = f0 (y_ref - Gd y(k) - sum_{i=1..d} f_i q(k-i)) / (f0^2 + lambda_u)
 * where y_ref = y_d(k+d) (reference preview).
 */
#ifndef PIEZO_CONTROLLER_H
#define PIEZO_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>
#include "piezo_status.h"
#include "piezo_hysteresis.h"
#include "piezo_tf.h"
#include "piezo_creep.h"

#define PIEZO_MV_MAX_EXTRA_DELAY 8
#define PIEZO_MV_MAX_D 9          /* 1 + PIEZO_MV_MAX_EXTRA_DELAY */
#define PIEZO_MV_Q_RING 10        /* PIEZO_MV_MAX_D + 1 */
#define PIEZO_SAT_DEFAULT_V 150   /* default voltage limits +-150 V */
#define PIEZO_MONITOR_DEFAULT_ERROR 1   /* default bound on |pred_error| [um] */
#define PIEZO_MONITOR_DEFAULT_SAMPLES 200   /* default divergence window [samples] */

typedef struct {
    piezo_pi_params pi;          /* nominal hysteresis model */
    double tf_a1, tf_a2, tf_b1, tf_b2;  /* nominal G (eq 21) */
    double creep_k_c;            /* > 0 */
    double creep_alpha;          /* [-1, 1] */
    int creep_exact;             /* 1: full-memory inverse creep */
    double h;                    /* [s], > 0 */
    int mv_delay;                /* loop delay beyond one sample, 0..8; d = 1 + mv_delay */
    int mv_feedthrough;          /* 1: v(k) from the inputs of sample k (direct feedthrough) */
    double mv_lambda_u;          /* control weighting, >= 0 */
    int rls_enabled;
    double rls_forgetting;       /* (0, 1] */
    double rls_p0;               /* initial covariance P = p0 I, > 0 */
    double rls_trace_max;        /* bound on trace(P), >= 4 p0 */
    int sat_enabled;
    double sat_v_min, sat_v_max; /* [V], v_min < v_max when enabled */
    double monitor_pred_error_max;   /* [um], > 0: bound on |pred_error| */
    int monitor_divergence_samples;  /* consecutive samples beyond the bound that mean the loop
                                        is unstable (PIEZO_ERR_UNSTABLE); 0 = never */
} piezo_controller_params;

typedef struct {
    double v;                    /* control voltage v(k) [V] */
    double q;                    /* virtual input q(k) [um] (after saturation back-calculation) */
    double theta[4];             /* estimates a1, a2, b1, b2 used for q(k) */
    double pred_error;           /* RLS one-step prediction error at k [um] */
    int saturated;               /* 1 if v(k) was clipped */
} piezo_controller_output;

typedef struct {
    piezo_pi fwd_pi;             /* nominal forward PI: tracks the plant's hysteresis state */
    piezo_pi_inverse inv_pi;
    piezo_gl inv_creep;          /* order -alpha, gain h^alpha / k_c */
    int d;
    double lambda_u;
    int rls_enabled;
    double forgetting, p0, trace_max;
    double inv_forgetting;       /* 1 / forgetting, set at init (the RLS multiplies by it) */
    int sat_enabled;
    double sat_v_min, sat_v_max;
    double theta_nominal[4];
    double theta[4];             /* a1, a2, b1, b2 */
    double P[16];                /* RLS covariance, row-major 4x4 */
    double y_prev[2];            /* y(k-1), y(k-2) */
    double q_ring[PIEZO_MV_Q_RING];  /* q(k-1)..q(k-10), q_ring[head] newest */
    int head;
    int sat_hold;                /* samples until a clipped q leaves the regressor (no RLS meanwhile) */
    double pred_error_max;
    uint64_t divergence_samples;
    /* monitor counts since reset (see piezo_controller_diverged) */
    uint64_t n_saturated;        /* samples whose v was clipped */
    uint64_t n_large_error;      /* samples with |pred_error| > pred_error_max */
    uint64_t run_saturated;      /* consecutive clipped samples up to the last one */
    uint64_t run_large_error;    /* consecutive samples beyond the bound up to the last one */
    uint64_t k_first_saturated;  /* first clipped sample (valid when n_saturated > 0) */
    uint64_t k_first_large_error;/* first sample beyond the bound (valid when n_large_error > 0) */
    double max_abs_pred_error;   /* largest |pred_error| so far [um] */
    uint64_t k;
    piezo_controller_output out; /* result of the last committed sample */
} piezo_controller;

/*
 * One evaluated sample, for a caller that computes a sample before it decides
 * to commit it - e.g. an FMU whose outputs depend directly on its inputs: the
 * outputs read at a communication point are the very sample its doStep then
 * commits, computed once. Filled by piezo_controller_evaluate, consumed by
 * piezo_controller_commit. k, y_ref, y_meas and out say which sample it is
 * and what it gives; the other fields are the evaluation's next states.
 */
typedef struct {
    uint64_t k;                  /* the sample evaluated (ctrl->k at the evaluation) */
    double y_ref, y_meas;        /* its inputs */
    int reaches_window;          /* committing it would complete the divergence window */
    piezo_controller_output out; /* its outputs */
    double theta[4], P[16];      /* RLS result (valid when rls_updated) */
    int rls_updated;
    double creep_next[PIEZO_GL_MAX_TERMS];   /* inverse creep SOE states of k+1 */
    double inv_z[PIEZO_PI_MAX_OPERATORS];    /* inverse PI play states of k+1 */
    double fwd_z[PIEZO_PI_MAX_OPERATORS];    /* forward PI play states of k+1 */
    int sat_hold;
    int large_error;             /* |pred_error| > monitor_pred_error_max */
    uint64_t run_large_error;
} piezo_controller_sample;

/* Defaults of docs/fmus.md (nominal plant model). */
void piezo_controller_default_params(piezo_controller_params *params);
piezo_status piezo_controller_init(piezo_controller *ctrl, const piezo_controller_params *params,
                                   piezo_diag *diag);
void piezo_controller_reset(piezo_controller *ctrl);
/*
 * Compute the control of sample k from y_ref = y_d(k+d) and y_meas(k) and
 * commit it (RLS update, operator states, monitor, k -> k+1). Returns
 * PIEZO_ERR_UNSTABLE, committing nothing, when this sample would make the
 * run of samples with |pred_error| > monitor_pred_error_max reach
 * monitor_divergence_samples. Exact mode writes
 * history[2k], history[2k+1] (capacity >= piezo_controller_history_needed). Non-finite inputs refused, state unchanged.
 */
piezo_status piezo_controller_step(piezo_controller *ctrl, double y_ref, double y_meas,
                                   double *history, size_t history_capacity,
                                   piezo_controller_output *out);
/* Same result as piezo_controller_step without committing anything
 * (exact mode may write the unused slots history[2k], history[2k+1]); the
 * divergence window is not applied (the step that commits the sample does). */
piezo_status piezo_controller_peek(const piezo_controller *ctrl, double y_ref, double y_meas,
                                   double *history, size_t history_capacity,
                                   piezo_controller_output *out);
/*
 * The two halves of piezo_controller_step: evaluate sample k into *sample
 * (nothing committed; the checks, refusals and history writes of a peek,
 * which it equals), then commit it: PIEZO_ERR_PARAM (nothing done) unless
 * sample->k == ctrl->k, PIEZO_ERR_UNSTABLE (nothing done) when it completes
 * the divergence window. Commit only the latest evaluation of the sample, with
 * the state it was evaluated on (exact mode: history[2k..2k+1] are its own).
 */
piezo_status piezo_controller_evaluate(const piezo_controller *ctrl, double y_ref, double y_meas,
                                       double *history, size_t history_capacity,
                                       piezo_controller_sample *sample);
piezo_status piezo_controller_commit(piezo_controller *ctrl, const piezo_controller_sample *sample,
                                     piezo_controller_output *out);
size_t piezo_controller_history_needed(const piezo_controller *ctrl);
/*
 * Invariants of a restored controller (e.g. from a deserialized FMU state):
 * NULL when every index, count and flag is in range, the sample counters agree,
 * the monitor counts fit the sample count and every value is finite, else a
 * static text naming the first bad field. The exact-mode history is checked by
 * piezo_gl_check_history(&ctrl->inv_creep, ...).
 */
const char *piezo_controller_check(const piezo_controller *ctrl);

/* Diophantine 1 = A E + z^-d Gd for A = 1 + a1 z^-1 + a2 z^-2, 1 <= d <= 9:
 * e[0..d-1] (e[0] = 1), g[0..1]. */
piezo_status piezo_diophantine(double a1, double a2, int d, double *e, double *g);

#endif
