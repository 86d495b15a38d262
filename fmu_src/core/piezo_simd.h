/*
 * piezo_simd.h - the AVX paths of the four-lane sums (internal to the core's
 * .c files; not part of the API, not read by the cffi binding).
 *
 * The creep's SOE sum and head window (piezo_creep.c) and the PI sums
 * (piezo_hysteresis.c) are defined as four partial sums, term n in lane
 * n mod 4, combined as (a_0 + a_1) + (a_2 + a_3) (piezo_creep.h,
 * piezo_hysteresis.h). Baseline x86-64 (SSE2) holds the lanes in two 128-bit
 * registers; a CPU with AVX holds them in one 256-bit register, so a block of
 * four terms is one instruction per operation instead of two. Each sum has
 * both versions, and which one runs is chosen per call by
 * piezo_cpu_has_avx() (a flag the compiler's runtime, libgcc, sets once
 * when the binary is loaded; no state of ours, so nothing in a serialized FMU
 * state depends on it). The binaries stay baseline x86-64: only those functions are compiled
 * for "avx", and run only where the CPU and the OS have it.
 *
 * Same bits on every machine: the AVX versions do the same operations on the
 * same lanes in the same order. vaddpd, vsubpd, vmulpd, vminpd and vmaxpd
 * round (and order their operands) as addsd, subsd, mulsd, minsd and maxsd;
 * only "avx" is enabled, not "fma" or "avx2", so nothing can be contracted
 * into a fused multiply-add (and -ffp-contract=off holds everywhere); the last
 * n mod 4 terms and the combination of the lanes are the SSE2 versions' scalar
 * code. tests/c/simd_paths.c compares both versions bit for bit.
 *
 * The controller's finiteness check of a sample's new state (piezo_all_finite, some 55 values a
 * sample) is here too, both versions: its answer is a boolean, the same in either.
 */
#ifndef PIEZO_SIMD_H
#define PIEZO_SIMD_H

/* gcc and clang (also MinGW-w64) on x86-64 compile one function for AVX in a
 * baseline binary; elsewhere, or with -DPIEZO_NO_AVX_PATH, only the portable
 * versions exist. */
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(PIEZO_NO_AVX_PATH)
#define PIEZO_HAVE_AVX_PATH 1
#include <immintrin.h>

/* 1 when the CPU and the OS support AVX (libgcc checks CPUID and XGETBV). */
static inline int piezo_cpu_has_avx(void)
{
    return __builtin_cpu_supports("avx") != 0;
}

/* The lanes a_0..a_3 of acc as scalars, for the last n mod 4 terms and the
 * combination (a_0 + a_1) + (a_2 + a_3), both done as in the SSE2 versions.
 * (Those terms as a masked block, vmaskmovpd, with a haddpd combination were
 * slower on the AMD EPYC of docs/speed.md.) */
__attribute__((target("avx")))
static inline void piezo_avx_lanes(__m256d acc, double *a0, double *a1, double *a2, double *a3)
{
    __m128d lo = _mm256_castpd256_pd128(acc), hi = _mm256_extractf128_pd(acc, 1);
    *a0 = _mm_cvtsd_f64(lo);
    *a1 = _mm_cvtsd_f64(_mm_unpackhi_pd(lo, lo));
    *a2 = _mm_cvtsd_f64(hi);
    *a3 = _mm_cvtsd_f64(_mm_unpackhi_pd(hi, hi));
}
#else
#define PIEZO_HAVE_AVX_PATH 0
#endif

/* 1 when every x[i] is finite: x * 0 is +-0 for a finite x and NaN for Inf or NaN (IEEE 754; no
 * -ffinite-math-only here), so a sum of those products is 0 exactly when all are finite, in
 * whatever order it is added. No branch per element, and four short chains of additions, z[j] over
 * the x[i] with i mod 4 = j, instead of one: the compiler adds them as two pairs in two vector
 * registers; the last n mod 4 as a pair and one (not a loop: a 32-bit build's loop optimisation
 * warned of one). */
static inline int piezo_all_finite_sse2(const double *x, int n)
{
    double z[4] = { 0.0, 0.0, 0.0, 0.0 };
    int i, j;
    for (i = 0; i + 4 <= n; i += 4)
        for (j = 0; j < 4; ++j) z[j] += x[i + j] * 0.0;
    if (i + 2 <= n) {
        z[0] += x[i] * 0.0;
        z[1] += x[i + 1] * 0.0;
        i += 2;
    }
    if (i < n) z[2] += x[i] * 0.0;
    return (z[0] + z[1]) + (z[2] + z[3]) == 0.0;
}

#if PIEZO_HAVE_AVX_PATH
/* The same, a block of four in one register (the lanes as above, the last n mod 4 scalar); on the
 * stage's bench tones it took the check from 195 to 151 instructions a sample */
__attribute__((target("avx")))
static inline int piezo_all_finite_avx(const double *x, int n)
{
    __m256d acc = _mm256_setzero_pd();
    const __m256d zero = _mm256_setzero_pd();
    double a0, a1, a2, a3;
    int i;
    for (i = 0; i + 4 <= n; i += 4)
        acc = _mm256_add_pd(acc, _mm256_mul_pd(_mm256_loadu_pd(x + i), zero));
    piezo_avx_lanes(acc, &a0, &a1, &a2, &a3);
    for (; i < n; ++i) a0 += x[i] * 0.0;
    return (a0 + a1) + (a2 + a3) == 0.0;
}
#endif

/* piezo_all_finite_avx where the CPU has AVX, else piezo_all_finite_sse2 */
static inline int piezo_all_finite(const double *x, int n)
{
#if PIEZO_HAVE_AVX_PATH
    if (piezo_cpu_has_avx()) return piezo_all_finite_avx(x, n);
#endif
    return piezo_all_finite_sse2(x, n);
}

#endif
