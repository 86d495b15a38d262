/* piezo_hysteresis.c - PI model and its inverse. See piezo_hysteresis.h. */
#include <math.h>
#include <string.h>
#include "piezo_hysteresis.h"
#include "piezo_simd.h"

/* eq 3: z_r(k) = max(v(k) - r, min(v(k) + r, z_r(k-1))). Static, so the
 * model loops inline it (an exported function is called through the PLT). */
static double play(double v, double r, double z_prev)
{
    double upper = v + r;
    double lower = v - r;
    double z = z_prev < upper ? z_prev : upper;
    return z > lower ? z : lower;
}

double piezo_play(double v, double r, double z_prev)
{
    return play(v, r, z_prev);
}

/* Names of the weights as FMU variables, for diagnostics. */
static const char *const weight_names[PIEZO_PI_MAX_OPERATORS] = {
    "pi.w[1]", "pi.w[2]", "pi.w[3]", "pi.w[4]", "pi.w[5]", "pi.w[6]", "pi.w[7]", "pi.w[8]",
    "pi.w[9]", "pi.w[10]", "pi.w[11]", "pi.w[12]", "pi.w[13]", "pi.w[14]", "pi.w[15]", "pi.w[16]"};

piezo_status piezo_pi_init(piezo_pi *pi, const piezo_pi_params *params, piezo_diag *diag)
{
    int j;
    double slope;
    if (!pi || !params) return PIEZO_ERR_NULL;
    if (params->m < 1 || params->m > PIEZO_PI_MAX_OPERATORS)
        return piezo_refuse(diag, "pi.m", "1..16", (double)params->m);
    if (!(isfinite(params->v_max) && params->v_max > 0.0))
        return piezo_refuse(diag, "pi.v_max", "(0, inf) V", params->v_max);
    if (!(isfinite(params->w0) && params->w0 > 0.0))
        return piezo_refuse(diag, "pi.w0", "(0, inf)", params->w0);
    /* Weights beyond m are ignored, but must still be valid numbers of the
     * parameter set (a user reducing pi.m should not hide a typo). */
    for (j = 0; j < PIEZO_PI_MAX_OPERATORS; ++j)
        if (!(isfinite(params->w[j]) && params->w[j] >= 0.0))
            return piezo_refuse(diag, weight_names[j], "[0, inf)", params->w[j]);
    /* the steepest slope of the loading curve, w0 + sum w_j, must be a number:
     * u overflows for any |v| > 1 otherwise, and the inverse's states are Inf * 0 */
    slope = params->w0;
    for (j = 0; j < params->m; ++j) {
        slope += params->w[j];
        if (!isfinite(slope))
            return piezo_refuse(diag, weight_names[j], "[0, inf) with pi.w0 + sum of pi.w[1..m] finite", params->w[j]);
    }

    memset(pi, 0, sizeof *pi);
    pi->m = params->m;
    pi->w0 = params->w0;
    for (j = 0; j < params->m; ++j) {
        pi->w[j] = params->w[j];
        /* eq 5 with j counted from 1: r_j = (j-1)/m * v_max */
        pi->r[j] = (double)j / (double)params->m * params->v_max;
    }
    return PIEZO_OK;
}

void piezo_pi_reset(piezo_pi *pi)
{
    if (pi) memset(pi->z, 0, sizeof pi->z);
}

/* One play operator of a PI sum: its next state into z_next[j] (after z[j] is
 * read), w_j z_j(k) returned. */
static double pi_term(const double *w, const double *r, const double *z, double *z_next, int j, double v)
{
    double zj = play(v, r[j], z[j]);
    z_next[j] = zj;
    return w[j] * zj;
}

/*
 * The PI sum of eq 18 (and of eq 24 for the inverse), with the play states of
 * sample k into z_next[0..m-1] (each written after z[j] is read: z_next may be
 * z, in place). Four partial sums, lane l = 0..3, each in increasing j
 * (piezo_hysteresis.h, "Summation order"):
 *     a_l = sum_{j = l mod 4} w_j z_j(k),   u = w0 v + ((a_0 + a_1) + (a_2 + a_3)).
 * The operators are independent, so a block of four is two SSE2 vectors
 * (minpd/maxpd for eq 3) and the lanes are four short chains of additions.
 */
static double pi_sum(int m, double w0, const double *w, const double *r, const double *z,
                     double *z_next, double v)
{
    double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
    int j;
    for (j = 0; j + 4 <= m; j += 4) {
        double z0 = play(v, r[j], z[j]);
        double z1 = play(v, r[j + 1], z[j + 1]);
        double z2 = play(v, r[j + 2], z[j + 2]);
        double z3 = play(v, r[j + 3], z[j + 3]);
        a0 += w[j] * z0;
        a1 += w[j + 1] * z1;
        a2 += w[j + 2] * z2;
        a3 += w[j + 3] * z3;
        z_next[j] = z0;
        z_next[j + 1] = z1;
        z_next[j + 2] = z2;
        z_next[j + 3] = z3;
    }
    /* the last m mod 4 operators continue lanes 0, 1, 2 */
    if (j < m) a0 += pi_term(w, r, z, z_next, j, v);
    if (j + 1 < m) a1 += pi_term(w, r, z, z_next, j + 1, v);
    if (j + 2 < m) a2 += pi_term(w, r, z, z_next, j + 2, v);
    return w0 * v + ((a0 + a1) + (a2 + a3));
}

#if PIEZO_HAVE_AVX_PATH
/* pi_sum with the four lanes in one 256-bit register (piezo_simd.h): lane l is
 * a_l, and a block of four operators is one vaddpd/vsubpd/vminpd/vmaxpd/vmulpd
 * per operation (eq 3 as play() writes it: min(z, v + r), then max(., v - r));
 * the last m mod 4 operators and the combination as in pi_sum. Same bits. */
__attribute__((target("avx")))
static double pi_sum_avx(int m, double w0, const double *w, const double *r, const double *z,
                         double *z_next, double v)
{
    const __m256d v4 = _mm256_set1_pd(v);
    __m256d acc = _mm256_setzero_pd();
    double a0, a1, a2, a3;
    int j;
    for (j = 0; j + 4 <= m; j += 4) {
        __m256d r4 = _mm256_loadu_pd(r + j);
        __m256d z4 = _mm256_min_pd(_mm256_loadu_pd(z + j), _mm256_add_pd(v4, r4));
        z4 = _mm256_max_pd(z4, _mm256_sub_pd(v4, r4));
        acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_loadu_pd(w + j), z4));
        _mm256_storeu_pd(z_next + j, z4);
    }
    piezo_avx_lanes(acc, &a0, &a1, &a2, &a3);
    if (j < m) a0 += pi_term(w, r, z, z_next, j, v);
    if (j + 1 < m) a1 += pi_term(w, r, z, z_next, j + 1, v);
    if (j + 2 < m) a2 += pi_term(w, r, z, z_next, j + 2, v);
    return w0 * v + ((a0 + a1) + (a2 + a3));
}
#endif

/* pi_sum_avx where the CPU has AVX, else pi_sum: the same bits. Not inlined,
 * so that piezo_pi_eval stays small enough to be inlined into its callers. */
__attribute__((noinline))
static double pi_sum_any(int m, double w0, const double *w, const double *r, const double *z,
                         double *z_next, double v)
{
#if PIEZO_HAVE_AVX_PATH
    if (piezo_cpu_has_avx()) return pi_sum_avx(m, w0, w, r, z, z_next, v);
#endif
    return pi_sum(m, w0, w, r, z, z_next, v);
}

/* eq 18: u(k) = w0 v(k) + sum_j w_j z_{r_j}(k) (pi_sum). z_next may be pi->z (in place). */
piezo_status piezo_pi_eval(const piezo_pi *pi, double v, double *z_next, double *u)
{
    if (!pi || !z_next || !u) return PIEZO_ERR_NULL;
    if (!isfinite(v)) return PIEZO_ERR_NONFINITE;
    *u = pi_sum_any(pi->m, pi->w0, pi->w, pi->r, pi->z, z_next, v);
    return PIEZO_OK;
}

piezo_status piezo_pi_step(piezo_pi *pi, double v, double *u)
{
    if (!pi) return PIEZO_ERR_NULL;
    return piezo_pi_eval(pi, v, pi->z, u);
}

piezo_status piezo_pi_inverse_init(piezo_pi_inverse *inv, const piezo_pi *pi)
{
    int i, j;
    if (!inv || !pi) return PIEZO_ERR_NULL;
    if (pi->m < 1 || pi->m > PIEZO_PI_MAX_OPERATORS || !(pi->w0 > 0.0)) return PIEZO_ERR_PARAM;
    memset(inv, 0, sizeof *inv);
    inv->m = pi->m;
    /* eq 26: w'_0 = 1/w0 */
    inv->w0 = 1.0 / pi->w0;
    for (i = 0; i < pi->m; ++i) {
        /* slope of the loading curve after / before threshold r_i is crossed */
        double slope_after = pi->w0, slope_before = pi->w0, r_prime = pi->w0 * pi->r[i];
        double z_prime;
        for (j = 0; j <= i; ++j) {
            slope_after += pi->w[j];
            if (j < i) slope_before += pi->w[j];
            /* eq 25 (corrected): r'_i = w0 r_i + sum_{j<=i} w_j (r_i - r_j) */
            r_prime += pi->w[j] * (pi->r[i] - pi->r[j]);
        }
        inv->r[i] = r_prime;
        /* eq 27 (corrected sign): w'_i = -w_i / ((w0 + sum_{j<=i} w_j)(w0 + sum_{j<i} w_j)) */
        inv->w[i] = -pi->w[i] / (slope_after * slope_before);
        /* eq 28 (corrected): z'_i(0) = (w0 + sum_{j<=i} w_j) z_i(0) + sum_{j>i} w_j z_j(0) */
        z_prime = slope_after * pi->z[i];
        for (j = i + 1; j < pi->m; ++j) z_prime += pi->w[j] * pi->z[j];
        inv->z[i] = z_prime;
    }
    return PIEZO_OK;
}

/* eq 24: v(k) = w'_0 u(k) + sum_i w'_i z'_{r'_i}(k) (pi_sum); z_next may be inv->z. */
piezo_status piezo_pi_inverse_eval(const piezo_pi_inverse *inv, double u, double *z_next, double *v)
{
    if (!inv || !z_next || !v) return PIEZO_ERR_NULL;
    if (!isfinite(u)) return PIEZO_ERR_NONFINITE;
    *v = pi_sum_any(inv->m, inv->w0, inv->w, inv->r, inv->z, z_next, u);
    return PIEZO_OK;
}

piezo_status piezo_pi_inverse_step(piezo_pi_inverse *inv, double u, double *v)
{
    if (!inv) return PIEZO_ERR_NULL;
    return piezo_pi_inverse_eval(inv, u, inv->z, v);
}

static int all_finite(const double *x, int n)
{
    int i;
    for (i = 0; i < n; ++i)
        if (!isfinite(x[i])) return 0;
    return 1;
}

const char *piezo_pi_check(const piezo_pi *pi)
{
    if (!pi) return "PI model missing";
    if (pi->m < 1 || pi->m > PIEZO_PI_MAX_OPERATORS) return "pi.m outside 1..16";
    if (!(isfinite(pi->w0) && pi->w0 > 0.0)) return "pi.w0 not in (0, inf)";
    if (!all_finite(pi->w, PIEZO_PI_MAX_OPERATORS) || !all_finite(pi->r, PIEZO_PI_MAX_OPERATORS)
        || !all_finite(pi->z, PIEZO_PI_MAX_OPERATORS))
        return "PI weights, thresholds or play states not finite";
    return NULL;
}

const char *piezo_pi_inverse_check(const piezo_pi_inverse *inv)
{
    if (!inv) return "inverse PI model missing";
    if (inv->m < 1 || inv->m > PIEZO_PI_MAX_OPERATORS) return "inverse PI m outside 1..16";
    if (!isfinite(inv->w0) || !all_finite(inv->w, PIEZO_PI_MAX_OPERATORS)
        || !all_finite(inv->r, PIEZO_PI_MAX_OPERATORS) || !all_finite(inv->z, PIEZO_PI_MAX_OPERATORS))
        return "inverse PI weights, thresholds or play states not finite";
    return NULL;
}
