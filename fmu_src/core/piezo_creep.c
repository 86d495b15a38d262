/* piezo_creep.c - Grunwald-Letnikov operator, exact and sum-of-exponentials.
 * See piezo_creep.h. */
#include <math.h>
#include <string.h>
#include "piezo_creep.h"
#include "piezo_simd.h"

#define PI_D 3.14159265358979323846

/*
 * SOE quadrature (docs/model.md, plant; Jiang, Zhang, Zhang & Greengard 2017).
 * Nodes u_i = ln s_i on a uniform grid of step SOE_DU, from ln(SOE_S_MAX)
 * down to ln(SOE_S_LOW). SOE_S_MAX = 40/(L0+1) makes e^{-s j} < e^{-40} for
 * every tail index j > L0. Below SOE_S_LOW the grid continues to -inf, but
 * there s j <= SOE_S_LOW * SOE_N_HORIZON = 1e-4 for every j of a run of up to
 * SOE_N_HORIZON samples, so e^{-s j} ~ 1 and those infinitely many nodes add up
 * to ONE accumulator term (decay 1) whose coefficient is a geometric series.
 * This keeps 58 terms (57 nodes, 1 accumulator) while heavy tails (alpha -> -1) stay accurate. The
 * step 0.5 (trapezoid error ~ e^{-pi^2/du}) makes inverse creep after creep
 * the identity within 2e-10 um over 10 s for the Table 1 rows.
 */
#define SOE_DU 0.5
#define SOE_N_HORIZON 67108864.0 /* 2^26 samples = 9.3 h at 2 kHz */
#define SOE_S_LOW (1e-4 / SOE_N_HORIZON)

/* eq 14: w_0 = 1, w_j = (1 - (alpha+1)/j) w_{j-1}. At j = 1 the ratio is
 * exactly -alpha; computing it as 1 - (1 + alpha) would cancel and cost 1e-12
 * relative for alpha ~ 1e-4, so that one ratio is taken directly. */
static double gl_weight_ratio(double alpha, size_t j)
{
    return j == 1 ? -alpha : 1.0 - (alpha + 1.0) / (double)j;
}

void piezo_gl_weights(double alpha, double *w, size_t n)
{
    size_t j;
    if (!w || n == 0) return;
    w[0] = 1.0;
    for (j = 1; j < n; ++j) w[j] = gl_weight_ratio(alpha, j) * w[j - 1];
}

/* Integrand of the tail weights in u = ln s, without the e^{-s j} factor:
 * s e^{alpha s} (1 - e^{-s})^alpha, written with expm1 for small s. */
static double soe_density(double alpha, double s)
{
    return s * exp(alpha * s) * pow(-expm1(-s), alpha);
}

static int soe_add(piezo_gl *gl, double c, double s)
{
    int i = gl->n_terms;
    if (i >= PIEZO_GL_MAX_TERMS) return 0;
    gl->soe_c[i] = c;
    gl->soe_decay[i] = exp(-s);
    gl->soe_inject[i] = c * exp(-s * (double)PIEZO_GL_HEAD_LEN);
    gl->n_terms = i + 1;
    return 1;
}

static void soe_build(piezo_gl *gl)
{
    const double alpha = gl->alpha;
    const double u_top = log(40.0 / (double)PIEZO_GL_HEAD_LEN);
    const double u_low = log(SOE_S_LOW);
    const int n_nodes = (int)floor((u_top - u_low) / SOE_DU) + 1;
    double prefactor, u_last = u_top;
    int i;

    gl->n_terms = 0;
    /* Integer orders have finite or constant tails: handle them exactly.
     * alpha = 0: w_j = 0 (j >= 1); alpha = 1: w_j = 0 (j >= 2); alpha = -1: w_j = 1. */
    if (alpha == 0.0 || alpha == 1.0) return;
    if (alpha == -1.0) {
        soe_add(gl, 1.0, 0.0);
        return;
    }
    /* w_j = -(sin(pi alpha)/pi) int e^{-s j} density(s) du, trapezoid in u */
    prefactor = -sin(PI_D * alpha) / PI_D * SOE_DU;
    for (i = 0; i < n_nodes; ++i) {
        double s;
        u_last = u_top - (double)i * SOE_DU;
        s = exp(u_last);
        soe_add(gl, prefactor * soe_density(alpha, s), s);
    }
    {
        /* Nodes u_last - i du, i >= 1: density ~ s^(1+alpha) (s -> 0), so their
         * coefficients form a geometric series of ratio e^{-(1+alpha) du}. */
        double s_last = exp(u_last);
        double ratio = exp(-(1.0 + alpha) * SOE_DU);
        double first = prefactor * soe_density(alpha, s_last) * ratio;
        soe_add(gl, first / (1.0 - ratio), 0.0);
    }
}

piezo_status piezo_gl_init(piezo_gl *gl, double alpha, double gain, int exact, piezo_diag *diag)
{
    if (!gl) return PIEZO_ERR_NULL;
    if (!(isfinite(alpha) && alpha >= -1.0 && alpha <= 1.0))
        return piezo_refuse(diag, "creep.alpha", "[-1, 1]", alpha);
    if (!isfinite(gain)) return piezo_refuse(diag, "creep.k_c", "finite, > 0", gain);
    memset(gl, 0, sizeof *gl);
    gl->alpha = alpha;
    gl->gain = gain;
    gl->exact = exact ? 1 : 0;
    piezo_gl_weights(alpha, gl->w_head, PIEZO_GL_HEAD_LEN);
    if (!gl->exact) soe_build(gl);
    return PIEZO_OK;
}

void piezo_gl_reset(piezo_gl *gl)
{
    if (!gl) return;
    gl->k = 0;
    gl->head = 0;
    memset(gl->x_ring, 0, sizeof gl->x_ring);
    memset(gl->soe_state, 0, sizeof gl->soe_state);
}

size_t piezo_gl_history_needed(const piezo_gl *gl)
{
    if (!gl || !gl->exact) return 0;
    /* 2(k+1) without wrapping: a wrapped size would pass a capacity check */
    if (gl->k >= (uint64_t)(SIZE_MAX / 2 - 1)) return SIZE_MAX;
    return 2 * ((size_t)gl->k + 1);
}

static int all_finite(const double *x, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i)
        if (!isfinite(x[i])) return 0;
    return 1;
}

const char *piezo_gl_check(const piezo_gl *gl)
{
    int i;
    if (!gl) return "creep operator missing";
    if (gl->exact != 0 && gl->exact != 1) return "creep.exact is not 0 or 1";
    if (!(isfinite(gl->alpha) && gl->alpha >= -1.0 && gl->alpha <= 1.0)) return "creep.alpha outside [-1, 1]";
    if (!isfinite(gl->gain)) return "creep gain not finite";
    if (gl->head < 0 || gl->head >= PIEZO_GL_HEAD_LEN) return "creep ring index out of range";
    if (gl->n_terms < 0 || gl->n_terms > PIEZO_GL_MAX_TERMS) return "creep SOE term count out of range";
    if (gl->exact && gl->n_terms != 0) return "creep SOE terms in exact mode";
    if (!all_finite(gl->w_head, PIEZO_GL_HEAD_LEN) || !all_finite(gl->x_ring, PIEZO_GL_HEAD_LEN))
        return "creep head weights or inputs not finite";
    if (memcmp(gl->x_ring, gl->x_ring + PIEZO_GL_HEAD_LEN, sizeof gl->x_ring / 2) != 0)
        return "creep input ring differs from its mirror";
    if (!all_finite(gl->soe_c, PIEZO_GL_MAX_TERMS) || !all_finite(gl->soe_decay, PIEZO_GL_MAX_TERMS)
        || !all_finite(gl->soe_inject, PIEZO_GL_MAX_TERMS))
        return "creep SOE values not finite";
    /* the states may have overflowed to +-Inf in an advance (piezo_creep.h), never NaN:
     * decay * (finite or +-Inf) + finite inject * finite input, with the decay e^{-s} in (0, 1]
     * (a restored decay outside it made a later advance NaN, a state this check then refused:
     * found by CI's fuzzer, tests/c/fuzz_crashes/fuzz_deserialize_PiezoStage) */
    for (i = 0; i < PIEZO_GL_MAX_TERMS; ++i) {
        if (isnan(gl->soe_state[i])) return "creep SOE state is NaN";
        if (i < gl->n_terms && !(gl->soe_decay[i] > 0.0 && gl->soe_decay[i] <= 1.0))
            return "creep SOE decay outside (0, 1]";
    }
    return NULL;
}

const char *piezo_gl_check_history(const piezo_gl *gl, const double *history, size_t n)
{
    size_t j, k;
    if (!gl) return "creep operator missing";
    if (n != piezo_gl_history_needed(gl)) return "creep history length is not 2(k+1)";
    if (n == 0) return NULL;
    if (!history) return "creep history missing";
    k = (size_t)gl->k;
    for (j = 0; j < k; ++j) {
        double w = j == 0 ? 1.0 : gl_weight_ratio(gl->alpha, j) * history[2 * j - 1];
        if (!isfinite(history[2 * j])) return "creep history input not finite";
        if (history[2 * j + 1] != w) return "creep history weight differs from eq 14";
    }
    return NULL;
}

/* Exact: y(k) = gain * sum_{j=0..k} w_j x(k-j). history[2j] = x(j) and
 * history[2j+1] = w_j (eq 14, stored once when sample j arrives), so the sum
 * is a plain dot product; four partial sums let the CPU overlap the adds. */
static double gl_exact_sum(const double *history, size_t k)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    size_t j = 0;
    for (; j + 3 <= k; j += 4) {
        s0 += history[2 * j + 1] * history[2 * (k - j)];
        s1 += history[2 * j + 3] * history[2 * (k - j - 1)];
        s2 += history[2 * j + 5] * history[2 * (k - j - 2)];
        s3 += history[2 * j + 7] * history[2 * (k - j - 3)];
    }
    for (; j <= k; ++j) s0 += history[2 * j + 1] * history[2 * (k - j)];
    return (s0 + s1) + (s2 + s3);
}

/* The head window is summed in blocks of four lanes (piezo_creep.h). */
typedef char gl_head_is_a_multiple_of_4[PIEZO_GL_HEAD % 4 == 0 ? 1 : -1];

/* SOE: y(k) = gain * (x(k) + sum_{j=1..L0} w_j x(k-j) + sum_i T_i(k)), where
 * soe_state holds T_i(k) already (advanced by the commit of sample k-1,
 * gl_soe_advance), in the four lanes of piezo_creep.h:
 *     a_l = sum_{j-1 = l mod 4} w_j x(k-j) + sum_{i = l mod 4} T_i(k),
 *     sum = x(k) + ((a_0 + a_1) + (a_2 + a_3)).
 * x(k-j) is x_ring[head + j - 1] (the mirror keeps the window contiguous).
 * Every term is independent of the others: the lanes are four chains of
 * additions instead of one, and the blocks of four are two SSE2 vectors each.
 * Nothing is written: the sample can still be refused. */
static double gl_soe_sum(const piezo_gl *gl, double x)
{
    const double *xw = gl->x_ring + gl->head;    /* xw[j-1] = x(k-j) */
    const double *w = gl->w_head + 1;            /* w[j-1] = w_j */
    const double *state = gl->soe_state;         /* T_i(k) */
    double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
    int i, n = gl->n_terms;
    for (i = 0; i < PIEZO_GL_HEAD; i += 4) {
        a0 += w[i] * xw[i];
        a1 += w[i + 1] * xw[i + 1];
        a2 += w[i + 2] * xw[i + 2];
        a3 += w[i + 3] * xw[i + 3];
    }
    for (i = 0; i + 4 <= n; i += 4) {
        a0 += state[i];
        a1 += state[i + 1];
        a2 += state[i + 2];
        a3 += state[i + 3];
    }
    /* the last n mod 4 terms continue lanes 0, 1, 2 */
    if (i < n) a0 += state[i];
    if (i + 1 < n) a1 += state[i + 1];
    if (i + 2 < n) a2 += state[i + 2];
    return x + ((a0 + a1) + (a2 + a3));
}

/* The SOE states of the next sample, in place, once sample k is committed:
 *     T_i(k+1) = e^{-s_i} T_i(k) + c_i e^{-s_i (L0+1)} x(k-L0)
 * (x(k-L0) = x_leaving: the input that leaves the head window at sample k+1),
 * for the terms i = from..n-1. Each term is its own recursion: no sum, so any
 * grouping of the terms (gl_soe_advance_avx's blocks of four) gives the same bits. */
static void gl_soe_advance(piezo_gl *gl, int from, double x_leaving)
{
    const double *decay = gl->soe_decay, *inject = gl->soe_inject;
    double *state = gl->soe_state;
    int i;
    for (i = from; i < gl->n_terms; ++i) state[i] = decay[i] * state[i] + inject[i] * x_leaving;
}

#if PIEZO_HAVE_AVX_PATH
/* gl_soe_sum with the four lanes in one 256-bit register (piezo_simd.h): lane l
 * is a_l, and a block of four terms is one vmulpd/vaddpd per operation; the
 * last n mod 4 terms and the combination as in gl_soe_sum. Same bits. */
__attribute__((target("avx")))
static double gl_soe_sum_avx(const piezo_gl *gl, double x)
{
    const double *xw = gl->x_ring + gl->head;    /* xw[j-1] = x(k-j) */
    const double *w = gl->w_head + 1;            /* w[j-1] = w_j */
    const double *state = gl->soe_state;         /* T_i(k) */
    __m256d acc = _mm256_setzero_pd();
    double a0, a1, a2, a3;
    int i, n = gl->n_terms;
    for (i = 0; i < PIEZO_GL_HEAD; i += 4)
        acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_loadu_pd(w + i), _mm256_loadu_pd(xw + i)));
    for (i = 0; i + 4 <= n; i += 4)
        acc = _mm256_add_pd(acc, _mm256_loadu_pd(state + i));
    piezo_avx_lanes(acc, &a0, &a1, &a2, &a3);
    if (i < n) a0 += state[i];
    if (i + 1 < n) a1 += state[i + 1];
    if (i + 2 < n) a2 += state[i + 2];
    return x + ((a0 + a1) + (a2 + a3));
}

/* gl_soe_advance, four terms per 256-bit operation; the last n mod 4 by gl_soe_advance. */
__attribute__((target("avx")))
static void gl_soe_advance_avx(piezo_gl *gl, double x_leaving)
{
    const __m256d x_leaving4 = _mm256_set1_pd(x_leaving);
    const double *decay = gl->soe_decay, *inject = gl->soe_inject;
    double *state = gl->soe_state;
    int i, n = gl->n_terms;
    for (i = 0; i + 4 <= n; i += 4)
        _mm256_storeu_pd(state + i, _mm256_add_pd(_mm256_mul_pd(_mm256_loadu_pd(decay + i),
                                                                _mm256_loadu_pd(state + i)),
                                                  _mm256_mul_pd(_mm256_loadu_pd(inject + i), x_leaving4)));
    gl_soe_advance(gl, i, x_leaving);
}
#endif

/* gl_soe_sum_avx where the CPU has AVX, else gl_soe_sum: the same bits. */
static double gl_soe_sum_any(const piezo_gl *gl, double x)
{
#if PIEZO_HAVE_AVX_PATH
    if (piezo_cpu_has_avx()) return gl_soe_sum_avx(gl, x);
#endif
    return gl_soe_sum(gl, x);
}

static void gl_soe_advance_any(piezo_gl *gl, double x_leaving)
{
#if PIEZO_HAVE_AVX_PATH
    if (piezo_cpu_has_avx()) {
        gl_soe_advance_avx(gl, x_leaving);
        return;
    }
#endif
    gl_soe_advance(gl, 0, x_leaving);
}

piezo_status piezo_gl_eval(const piezo_gl *gl, double x, double *history, size_t history_capacity, double *y)
{
    double sum;
    if (!gl || !y) return PIEZO_ERR_NULL;
    if (!isfinite(x)) return PIEZO_ERR_NONFINITE;
    if (gl->exact) {
        size_t k = (size_t)gl->k;
        if (!history) return PIEZO_ERR_NULL;
        if (history_capacity < piezo_gl_history_needed(gl)) return PIEZO_ERR_CAPACITY;
        history[2 * k] = x;
        /* w_k by eq 14 from w_{k-1} (w_0 = 1) */
        history[2 * k + 1] = k == 0 ? 1.0 : gl_weight_ratio(gl->alpha, k) * history[2 * k - 1];
        sum = gl_exact_sum(history, k);
    } else {
        sum = gl_soe_sum_any(gl, x);
    }
    *y = gl->gain * sum;
    return PIEZO_OK;
}

void piezo_gl_commit(piezo_gl *gl, double x)
{
    if (!gl->exact) {
        /* the slot of x(k-L0-1) becomes the newest, in the ring and its mirror;
         * x(k-L0), which leaves the window at sample k+1, is then at head + L0 */
        gl->head = gl->head == 0 ? PIEZO_GL_HEAD : gl->head - 1;
        gl->x_ring[gl->head] = x;
        gl->x_ring[gl->head + PIEZO_GL_HEAD_LEN] = x;
        gl_soe_advance_any(gl, gl->x_ring[gl->head + PIEZO_GL_HEAD]);
    }
    gl->k += 1;
}

piezo_status piezo_gl_step(piezo_gl *gl, double x, double *history, size_t history_capacity, double *y)
{
    piezo_status st;
    if (!gl) return PIEZO_ERR_NULL;
    st = piezo_gl_eval(gl, x, history, history_capacity, y);
    if (st == PIEZO_OK) piezo_gl_commit(gl, x);
    return st;
}
