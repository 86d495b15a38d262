/*
 * piezo_creep.h - Grunwald-Letnikov fractional operator (paper eqs 13-17, 29;
 * docs/model.md, "Cost of the creep sum").
 *
 *     y(k) = gain * sum_{j=0..k} w_j x(k-j),
 *     w_0 = 1,  w_j = (1 - (alpha+1)/j) w_{j-1}     (eq 14)
 *
 * The plant's creep is order alpha with gain k_c h^-alpha (eq 17); the
 * controller's inverse creep is order -alpha with gain h^alpha / k_c.
 * Memory starts at k = 0 (t0).
 *
 * Two modes:
 *  - exact: the full sum, O(k) per step. The caller owns the history buffer
 *    (two doubles per sample: history[2j] = x(j), history[2j+1] = w_j) and
 *    passes it to every step, so the struct itself stays flat and copyable.
 *  - sum of exponentials (SOE, default): the first PIEZO_GL_HEAD+1 weights
 *    w_0..w_L0 exactly; for j > L0
 *        w_j = -(sin(pi alpha)/pi) int_0^inf e^{-s j} e^{alpha s} (1-e^{-s})^alpha ds
 *    discretised by the trapezoid rule in u = ln s, so w_j ~ sum_i c_i e^{-s_i j}
 *    and each term is a first-order recursion on x(k-L0-1), kept scaled by c_i:
 *        T_i(k) = c_i sum_{j>L0} e^{-s_i j} x(k-j)
 *               = e^{-s_i} T_i(k-1) + c_i e^{-s_i (L0+1)} x(k-L0-1).
 *    O(1) per step. T_i(k) depends only on inputs before x(k-L0), so the
 *    commit of sample k-1 already computes it: soe_state holds the states of
 *    the next sample, the evaluation of a sample only sums them (it writes
 *    nothing, so a refused sample needs no copy of them), and the commit
 *    advances them in place. The arithmetic, and so every result, is the
 *    same as advancing them in the evaluation.
 *
 * Summation order (it fixes the rounding, so it is part of the definition; the
 * same on every machine, since it is written out in the source): four partial
 * sums, lane l = 0..3, each in increasing index,
 *     a_l = sum_{j = 1..L0, j-1 = l mod 4} w_j x(k-j)
 *         + sum_{i = 0..n-1, i = l mod 4} T_i(k),
 *     y(k) = gain * (x(k) + ((a_0 + a_1) + (a_2 + a_3))),
 * so that the CPU overlaps the additions and the compiler can keep the lanes
 * in vector registers (SSE2 on any x86-64).
 *
 * Two versions of that sum, one result (piezo_simd.h): the portable one
 * (two lanes per 128-bit SSE2 register on baseline x86-64) and, on x86-64
 * with gcc or clang, one with the four lanes in a 256-bit AVX register. Each
 * step takes the AVX one when the CPU and the OS support AVX
 * (__builtin_cpu_supports, evaluated by libgcc when the binary is loaded; no
 * field of piezo_gl, so a serialized state does not depend on it). Both do
 * the same multiplications and additions on the same lanes in the same order,
 * without fused multiply-adds, so they give the same bits (tests/c/
 * simd_paths.c compares them on every term count); the binaries stay baseline
 * x86-64.
 */
#ifndef PIEZO_CREEP_H
#define PIEZO_CREEP_H

#include <stddef.h>
#include <stdint.h>
#include "piezo_status.h"

#define PIEZO_GL_HEAD 16        /* L0: weights w_0..w_L0 kept exactly */
#define PIEZO_GL_HEAD_LEN 17    /* PIEZO_GL_HEAD + 1 */
#define PIEZO_GL_MAX_TERMS 64   /* SOE terms */

typedef struct {
    double alpha;               /* order, [-1, 1] */
    double gain;                /* output gain */
    int exact;                  /* 1: full memory, 0: SOE */
    uint64_t k;                 /* samples consumed so far */
    double w_head[PIEZO_GL_HEAD_LEN];   /* w_0..w_L0 */
    /* x(k-1)..x(k-1-L0), a ring with a mirror: x(k-j) at x_ring[head + j - 1]
     * for j = 1..L0+1, and x_ring[p + L0+1] == x_ring[p], so the window is
     * contiguous wherever head is (one loop the compiler can vectorise) */
    double x_ring[2 * PIEZO_GL_HEAD_LEN];
    int head;                            /* 0..L0: x(k-1) at x_ring[head] */
    int n_terms;                         /* SOE terms in use */
    double soe_c[PIEZO_GL_MAX_TERMS];      /* c_i */
    double soe_decay[PIEZO_GL_MAX_TERMS];  /* e^{-s_i} */
    double soe_inject[PIEZO_GL_MAX_TERMS]; /* c_i e^{-s_i (L0+1)} */
    /* T_i(k) = c_i sum_{j>L0} e^{-s_i j} x(k-j) for the next sample k (advanced
     * by the commit of sample k-1; all 0 after a reset). Finite, or +-Inf once
     * an advance overflowed: then every later sample's sum is Inf or NaN and
     * is refused, as the sample that would have advanced them was before. */
    double soe_state[PIEZO_GL_MAX_TERMS];
} piezo_gl;

/* Closed-form-free weights by the recursion of eq 14: w[0..n-1]. */
void piezo_gl_weights(double alpha, double *w, size_t n);

/* Validate alpha in [-1, 1] and finite gain, derive weights and SOE nodes, reset. */
piezo_status piezo_gl_init(piezo_gl *gl, double alpha, double gain, int exact, piezo_diag *diag);
void piezo_gl_reset(piezo_gl *gl);
/*
 * Consume x(k), return y(k). In exact mode history must hold at least
 * 2(k+1) doubles (history_capacity, see piezo_gl_history_needed); entries
 * 2k and 2k+1 are written. In SOE mode history may be NULL. Non-finite x or
 * a too-small history is refused, state unchanged.
 */
piezo_status piezo_gl_step(piezo_gl *gl, double x, double *history, size_t history_capacity, double *y);
/*
 * The same sample without committing it, for callers that can still refuse
 * the sample afterwards: y(k), the operator unchanged (exact mode writes
 * history[2k], history[2k+1] as the step does). piezo_gl_commit(gl, x) then
 * makes it the step: the input ring, in SOE mode the states of k+1 (in
 * place), the sample counter.
 */
piezo_status piezo_gl_eval(const piezo_gl *gl, double x, double *history, size_t history_capacity, double *y);
void piezo_gl_commit(piezo_gl *gl, double x);
/* Doubles of history the next exact-mode step needs, 2(k+1); 0 in SOE mode.
 * SIZE_MAX when 2(k+1) does not fit a size_t (no buffer can be that large). */
size_t piezo_gl_history_needed(const piezo_gl *gl);
/*
 * Invariants of a restored operator (e.g. from a deserialized FMU state): NULL
 * when the flag, the ring index and the term count are in range and every value
 * is finite, else a static text naming the first bad field.
 */
const char *piezo_gl_check(const piezo_gl *gl);
/*
 * The exact-mode history of a restored operator: the n doubles must hold the
 * 2k written entries x(j) (finite) and w_j (equal to eq 14's recursion, bit for
 * bit), plus the two slots of the next step. NULL when they do, else why not.
 */
const char *piezo_gl_check_history(const piezo_gl *gl, const double *history, size_t n);

#endif
