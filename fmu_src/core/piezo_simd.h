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

#endif
