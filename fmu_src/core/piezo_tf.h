/*
 * piezo_tf.h - second-order discrete transfer function with optional extra
 * input delay (paper eqs 7-10, 21; docs/model.md, plant).
 *
 *     G(z) = (b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2) * z^-delay
 *     x(k) = -a1 x(k-1) - a2 x(k-2) + b1 u(k-1-delay) + b2 u(k-2-delay)
 *
 * One sample of delay (no direct feedthrough): piezo_tf_step takes u(k) and
 * returns x(k+1). Stability (both poles strictly inside the unit circle, Jury):
 *     |a2| < 1  and  |a1| < 1 + a2.
 */
#ifndef PIEZO_TF_H
#define PIEZO_TF_H

#include "piezo_status.h"

#define PIEZO_TF_MAX_DELAY 32
#define PIEZO_TF_INPUT_RING 34  /* PIEZO_TF_MAX_DELAY + 2 */

typedef struct {
    double a1, a2, b1, b2;
    int delay;                    /* extra input delay in samples, 0..32 */
} piezo_tf_params;

typedef struct {
    double a1, a2, b1, b2;
    int delay;
    double x1, x2;                /* x(k), x(k-1) */
    double u_ring[PIEZO_TF_INPUT_RING]; /* past inputs, u_ring[head] is the newest */
    int head;
} piezo_tf;

/* Validate (finite coefficients, stable A, 0 <= delay <= 32), zero the state. */
piezo_status piezo_tf_init(piezo_tf *tf, const piezo_tf_params *params, piezo_diag *diag);
void piezo_tf_reset(piezo_tf *tf);
/* Consume u(k), return x(k+1) through *x_next. Non-finite u refused. */
piezo_status piezo_tf_step(piezo_tf *tf, double u, double *x_next);
/* x(k+1) for u(k) without committing; piezo_tf_commit(tf, u, x_next) then
 * makes it the step (for callers that can still refuse the sample). */
piezo_status piezo_tf_eval(const piezo_tf *tf, double u, double *x_next);
void piezo_tf_commit(piezo_tf *tf, double u, double x_next);

/* Invariants of a restored filter (e.g. from a deserialized FMU state): NULL
 * when delay and ring index are in range and every value is finite, else a
 * static text naming the first bad field. */
const char *piezo_tf_check(const piezo_tf *tf);

#endif
