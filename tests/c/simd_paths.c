/*
 * simd_paths.c - the AVX and the SSE2 versions of the four-lane sums give the
 * same bits (fmu_src/core/piezo_simd.h).
 *
 * The core chooses one version per call by the CPU, so a machine runs only one
 * of them in the FMUs and the pytest suite. This test compiles both from the
 * core's own sources (the .c files are included, so their static functions are
 * reachable) and runs them on the same random operators: the creep's SOE sum
 * (gl_soe_sum, gl_soe_sum_avx) and the advance of its states (gl_soe_advance,
 * gl_soe_advance_avx) for every term count 0..PIEZO_GL_MAX_TERMS and ring
 * position, the PI sum (pi_sum, pi_sum_avx) for every m = 1..16, and the
 * controller's finiteness check (piezo_all_finite_sse2, _avx) against isfinite, with
 * values of every magnitude, both signed zeros, subnormals, sums that overflow,
 * infinities and NaNs; out of place and in place. The results, the written
 * states and the untouched slots beyond the terms in use must be identical bit
 * for bit (two NaNs count as equal: the core refuses non-finite results, and
 * which NaN an addition returns depends on its operand order, which the
 * compiler may swap in either version).
 *
 * Exit 0: equal; 1: a difference (printed); 77: the CPU has no AVX (skipped).
 */
#include <stdio.h>
#include <string.h>
#include <math.h>
#include <stdint.h>

#include "piezo_creep.c"
#define all_finite pi_all_finite     /* both files have a static all_finite */
#include "piezo_hysteresis.c"
#undef all_finite

static uint64_t rng_state = 0x9e3779b97f4a7c15ULL;

static uint64_t next_u64(void)
{
    /* xorshift64* */
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 0x2545f4914f6cdd1dULL;
}

/* A double of any kind: mostly ordinary values in [-1, 1] and of other
 * magnitudes, sometimes a signed zero, a subnormal, a huge value, an infinity
 * or a NaN (special > 0 allows the non-finite ones). */
static double any_double(int special)
{
    uint64_t u = next_u64();
    int kind = (int)(u % 64);
    double sign = (u >> 8) & 1 ? -1.0 : 1.0;
    double frac = (double)(next_u64() >> 11) * 0x1p-53;
    switch (kind) {
    case 0: return 0.0;
    case 1: return -0.0;
    case 2: return sign * frac * 0x1p-1060;                 /* subnormal */
    case 3: return sign * (1.0 + frac) * 0x1p1020;          /* sums overflow */
    case 4: return special ? sign * INFINITY : sign * frac;
    case 5: return special ? NAN : sign * frac;
    case 6: return sign * ldexp(1.0 + frac, (int)(next_u64() % 200) - 100);
    default: return sign * frac;
    }
}

static int same_bits(double a, double b)
{
    if (isnan(a) && isnan(b)) return 1;
    return memcmp(&a, &b, sizeof a) == 0;
}

static int same_array(const double *a, const double *b, int n)
{
    int i;
    for (i = 0; i < n; ++i)
        if (!same_bits(a[i], b[i])) return 0;
    return 1;
}

static int failures = 0;

static void report(const char *what, int n, long trial, double ys, double ya)
{
    if (failures++ < 10)
        fprintf(stderr, "simd_paths: %s differs (terms %d, trial %ld): SSE2 %a, AVX %a\n", what, n,
                trial, ys, ya);
}

static void check_creep(long trials)
{
    long t;
    for (t = 0; t < trials; ++t) {
        piezo_gl gl, gl_avx;
        double x, x_leaving, ys, ya;
        int i, special = (t % 4) == 0;
        memset(&gl, 0, sizeof gl);
        gl.n_terms = (int)(t % (PIEZO_GL_MAX_TERMS + 1));
        gl.head = (int)(next_u64() % PIEZO_GL_HEAD_LEN);
        for (i = 0; i < PIEZO_GL_HEAD_LEN; ++i) {
            gl.w_head[i] = any_double(special);
            gl.x_ring[i] = gl.x_ring[i + PIEZO_GL_HEAD_LEN] = any_double(special);
        }
        for (i = 0; i < PIEZO_GL_MAX_TERMS; ++i) {
            gl.soe_decay[i] = any_double(special);
            gl.soe_inject[i] = any_double(special);
            /* the slots beyond n_terms too: neither version may touch them */
            gl.soe_state[i] = any_double(special);
        }
        x = any_double(special);
        x_leaving = any_double(special);
        gl_avx = gl;
        /* the sum reads the states and writes nothing */
        ys = gl_soe_sum(&gl, x);
        ya = gl_soe_sum_avx(&gl_avx, x);
        if (!same_bits(ys, ya)) report("creep SOE sum", gl.n_terms, t, ys, ya);
        if (memcmp(&gl, &gl_avx, sizeof gl) != 0) report("creep SOE sum wrote to the operator", gl.n_terms, t, ys, ya);
        /* the advance of the states, in place */
        gl_soe_advance(&gl, 0, x_leaving);
        gl_soe_advance_avx(&gl_avx, x_leaving);
        if (!same_array(gl.soe_state, gl_avx.soe_state, PIEZO_GL_MAX_TERMS))
            report("creep SOE states advanced", gl.n_terms, t, ys, ya);
    }
}

static void check_pi(long trials)
{
    long t;
    for (t = 0; t < trials; ++t) {
        double w[PIEZO_PI_MAX_OPERATORS], r[PIEZO_PI_MAX_OPERATORS], z[PIEZO_PI_MAX_OPERATORS];
        double z_s[PIEZO_PI_MAX_OPERATORS], z_a[PIEZO_PI_MAX_OPERATORS];
        double w0, v, us, ua;
        int j, m = 1 + (int)(t % PIEZO_PI_MAX_OPERATORS), special = (t % 4) == 0;
        for (j = 0; j < PIEZO_PI_MAX_OPERATORS; ++j) {
            w[j] = any_double(special);
            r[j] = any_double(special);
            z[j] = any_double(special);
            z_s[j] = z_a[j] = (double)j;
        }
        w0 = any_double(special);
        v = any_double(special);
        us = pi_sum(m, w0, w, r, z, z_s, v);
        ua = pi_sum_avx(m, w0, w, r, z, z_a, v);
        if (!same_bits(us, ua)) report("PI sum", m, t, us, ua);
        if (!same_array(z_s, z_a, PIEZO_PI_MAX_OPERATORS)) report("PI play states", m, t, us, ua);
        /* in place */
        memcpy(z_a, z, sizeof z);
        ua = pi_sum_avx(m, w0, w, r, z_a, z_a, v);
        if (!same_bits(us, ua)) report("PI sum in place", m, t, us, ua);
        for (j = 0; j < m; ++j) z[j] = z_s[j];
        if (!same_array(z, z_a, PIEZO_PI_MAX_OPERATORS)) report("PI play states in place", m, t, us, ua);
    }
}

/* The finiteness check (piezo_all_finite_sse2, piezo_all_finite_avx): the same answer for every
 * n = 0..70, on finite values of every magnitude (sums that overflow included: x * 0 does not),
 * and 0 with one Inf or NaN at each position; the reference is a plain loop of isfinite. */
static void check_finite(long trials)
{
    double x[70];
    long t;
    int n, j, bad, fs, fa;
    for (t = 0; t < trials; ++t) {
        n = (int)(t % 71);
        for (j = 0; j < n; ++j) x[j] = any_double(0);
        if (n > 0 && t % 2) x[next_u64() % (uint64_t)n] = (t / 2) % 3 == 0 ? NAN : ((t / 2) % 3 == 1 ? INFINITY : -INFINITY);
        for (bad = 0, j = 0; j < n; ++j) bad |= !isfinite(x[j]);
        fs = piezo_all_finite_sse2(x, n);
        fa = piezo_all_finite_avx(x, n);
        if (fs != !bad || fa != !bad) report("finite check (1: all finite) against isfinite", n, t, fs, fa);
    }
}

int main(void)
{
#if PIEZO_HAVE_AVX_PATH
    const long trials = 400000;
    if (!piezo_cpu_has_avx()) {
        printf("simd_paths: this CPU has no AVX, nothing to compare (skipped)\n");
        return 77;
    }
    check_creep(trials);
    check_pi(trials);
    check_finite(trials);
    if (failures) {
        fprintf(stderr, "simd_paths: %d differences\n", failures);
        return 1;
    }
    printf("simd_paths: SSE2 and AVX sums identical over %ld creep and %ld PI cases, and the finiteness "
           "check as isfinite over %ld arrays\n", trials, trials, trials);
    return 0;
#else
    printf("simd_paths: no AVX path on this target (skipped)\n");
    return 77;
#endif
}
