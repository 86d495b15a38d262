/*
 * glibc_baseline.h - forced into every Linux binary the build ships (-include, CMakeLists.txt),
 * never into the FMUs' sources/: the few C library functions whose default symbol version
 * is newer than the baseline (GLIBC_BASELINE of harness/platforms.py, 2.17) are bound to
 * their first version, which every glibc since has kept.
 *
 *   exp, log, pow    GLIBC_2.29 (the versions without SVID error handling); the first
 *                    ones (x86-64: GLIBC_2.2.5, aarch64: GLIBC_2.17) call the same
 *                    implementation on a newer glibc and differ only in how a domain or
 *                    range error is reported (the FMUs refuse non-finite values anyway)
 *   dlopen, dlsym,   GLIBC_2.34 (moved from libdl into libc); the runner also names
 *   dlclose, dlerror libdl.so.2, where glibc < 2.34 has them (CMakeLists.txt)
 *
 * A binary that needs any other newer version fails tests/test_fmu_platforms.py, which
 * reads the version references of every shipped ELF file.
 */
#ifndef PIEZO_GLIBC_BASELINE_H
#define PIEZO_GLIBC_BASELINE_H
/* forced in only where the C library is glibc (CMakeLists.txt); no header is included here,
 * so that a file's own feature macros (_POSIX_C_SOURCE) still apply */
#if !defined(__ASSEMBLER__)
#if defined(__x86_64__)
#define PIEZO_GLIBC_FIRST "GLIBC_2.2.5"
#elif defined(__aarch64__)
#define PIEZO_GLIBC_FIRST "GLIBC_2.17"
#endif
#ifdef PIEZO_GLIBC_FIRST
#define PIEZO_GLIBC_PIN(name) __asm__(".symver " #name "," #name "@" PIEZO_GLIBC_FIRST);
PIEZO_GLIBC_PIN(exp)
PIEZO_GLIBC_PIN(log)
PIEZO_GLIBC_PIN(pow)
PIEZO_GLIBC_PIN(dlopen)
PIEZO_GLIBC_PIN(dlsym)
PIEZO_GLIBC_PIN(dlclose)
PIEZO_GLIBC_PIN(dlerror)
#undef PIEZO_GLIBC_PIN
#endif
#endif
#endif
