/*
 * piezo_hysteresis.h - classical Prandtl-Ishlinskii model and its inverse
 * (paper eqs 1-5, 18, 24-28; docs/model.md, plant and controller).
 *
 * Play operator, threshold r >= 0 (eq 3):
 *     z_r(k) = max(v(k) - r, min(v(k) + r, z_r(k-1)))
 * PI model (eq 18):
 *     u(k) = w0 v(k) + sum_{j=1..m} w_j z_{r_j}(k),  r_j = (j-1)/m * v_max  (eq 5)
 * Inverse (corrected eqs 25-28, Kuhnen & Janocha): a PI model with
 *     r'_i = w0 r_i + sum_{j<=i} w_j (r_i - r_j),   w'_0 = 1/w0,
 *     w'_i = -w_i / ((w0 + sum_{j<=i} w_j)(w0 + sum_{j<i} w_j)),
 *     z'_i(0) = (w0 + sum_{j<=i} w_j) z_i(0) + sum_{j>i} w_j z_j(0).
 *
 * Summation order of both sums (it fixes the rounding, so it is part of the
 * definition, the same on every machine): four partial sums over the operators
 * j = 1..m, lane l = 0..3 taking j - 1 = l mod 4 in increasing j,
 *     a_l = sum w_j z_{r_j}(k),   u(k) = w0 v(k) + ((a_0 + a_1) + (a_2 + a_3)).
 * Where the CPU has AVX, the four lanes are one 256-bit register (the same
 * operations in the same order, the same bits: piezo_simd.h, piezo_creep.h).
 */
#ifndef PIEZO_HYSTERESIS_H
#define PIEZO_HYSTERESIS_H

#include "piezo_status.h"

#define PIEZO_PI_MAX_OPERATORS 16

typedef struct {
    int m;                                /* number of play operators, 1..16 */
    double v_max;                         /* threshold scale [V], > 0 (eq 5) */
    double w0;                            /* linear weight, > 0 */
    double w[PIEZO_PI_MAX_OPERATORS];     /* play weights w_1..w_m, >= 0 */
} piezo_pi_params;

/* Forward PI model: flat, caller-owned. */
typedef struct {
    int m;
    double w0;
    double w[PIEZO_PI_MAX_OPERATORS];     /* w_1..w_m */
    double r[PIEZO_PI_MAX_OPERATORS];     /* thresholds r_1..r_m, r_1 = 0 */
    double z[PIEZO_PI_MAX_OPERATORS];     /* play states z_1..z_m */
} piezo_pi;

/* Inverse PI model: v = w'_0 u + sum_i w'_i z'_{r'_i}(u). */
typedef struct {
    int m;
    double w0;                            /* w'_0 = 1/w0 */
    double w[PIEZO_PI_MAX_OPERATORS];     /* w'_1..w'_m (negative) */
    double r[PIEZO_PI_MAX_OPERATORS];     /* r'_1..r'_m */
    double z[PIEZO_PI_MAX_OPERATORS];     /* inverse play states z'_1..z'_m */
} piezo_pi_inverse;

/* One play operator update (eq 3). */
double piezo_play(double v, double r, double z_prev);

/* Validate params, derive thresholds, zero the states. */
piezo_status piezo_pi_init(piezo_pi *pi, const piezo_pi_params *params, piezo_diag *diag);
/* Zero the play states. */
void piezo_pi_reset(piezo_pi *pi);
/* u = P[v](k); refuses non-finite v without touching the state. */
piezo_status piezo_pi_step(piezo_pi *pi, double v, double *u);
/* The same sample without committing it: u and the play states it leads to
 * (z_next[0..m-1]; may be pi->z itself, which is then the step). For callers
 * that can still refuse the sample afterwards; they commit by copying z_next. */
piezo_status piezo_pi_eval(const piezo_pi *pi, double v, double *z_next, double *u);

/* Derive the inverse of `pi`, with initial states consistent with pi->z (eq 28). */
piezo_status piezo_pi_inverse_init(piezo_pi_inverse *inv, const piezo_pi *pi);
/* v = P^-1[u](k); refuses non-finite u without touching the state. */
piezo_status piezo_pi_inverse_step(piezo_pi_inverse *inv, double u, double *v);
/* The same sample without committing it (z_next as in piezo_pi_eval). */
piezo_status piezo_pi_inverse_eval(const piezo_pi_inverse *inv, double u, double *z_next, double *v);

/* Invariants of a restored model (e.g. from a deserialized FMU state): NULL
 * when m is in 1..16 and every weight, threshold and state is finite (w0 > 0
 * for the forward model), else a static text naming the first bad field. */
const char *piezo_pi_check(const piezo_pi *pi);
const char *piezo_pi_inverse_check(const piezo_pi_inverse *inv);

#endif
