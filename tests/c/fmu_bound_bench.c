/*
 * fmu_bound_bench.c - the time the longest step one doStep accepts takes, for
 * each FMU given: the bound of fmu_glue_core.c on the samples of one doStep,
 * and with creep.exact the bound on the terms of the exact creep sum (the
 * longest step from t0). The bounds are read from the FMU's own refusal of a
 * longer step, so this program holds no copy of them. A benchmark: it prints
 * figures (wall seconds of each run and their median), it asserts nothing.
 *
 * The inputs are held at 3 over the step (the controller with mv.hold_inputs =
 * true, without which it refuses a step of several samples); the controller's
 * monitor is off (monitor.divergence_samples = 0), the reference signal sums
 * its 8 tones.
 *
 * Built for the FMI 2.0 editions (-DFMI_VERSION=2 over host.h).
 *
 * usage: fmu_bound_bench [--runs N] MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]
 */
#include "host.h"

#include <time.h>

static double seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* A fresh instance in StepComplete at t0 = 0 (creep.exact as asked), inputs at 3;
 * NULL if not (in is to be freed either way). */
static void *start(host_inst *in, const host_fmu *f, int exact)
{
    char name[32];
    int i;
    /* the controller holds its inputs over a step of several samples only when asked */
    if (host_instantiate(in, f, "bench") == NULL || !host_hold_inputs(f, in->c)
        || host_enter_init(f, in->c, 0.0, 0, 0.0) != HOST_OK)
        return NULL;
    if (exact)
        host_set_named(f, in->c, "creep.exact", 1.0);
    if (host_named(f, "monitor.divergence_samples", NULL) != NULL)
        host_set_named(f, in->c, "monitor.divergence_samples", 0.0);
    for (i = 1; i <= 8; i++) {
        snprintf(name, sizeof name, "amplitude[%d]", i);
        if (host_named(f, name, NULL) != NULL) {
            host_set_named(f, in->c, name, 1.0);
            snprintf(name, sizeof name, "frequency[%d]", i);
            host_set_named(f, in->c, name, 1.5 * i);
        }
    }
    if (f->api.ExitInitializationMode(in->c) != HOST_OK)
        return NULL;
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].causality == VAR_INPUT)
            host_set(f, in->c, &f->vars[i], 3.0);
    return in->c;
}

/* The number after `key` in the refusal of a step of `huge` samples, or 0. */
static unsigned long long bound_from_refusal(const host_fmu *f, int exact, double huge, const char *key)
{
    host_inst in;
    unsigned long long n = 0;
    const char *p;
    if (start(&in, f, exact) != NULL) {
        host_log_clear(&in.log);
        if (host_step(f, in.c, 0.0, huge * f->h) == HOST_ERROR && (p = strstr(in.log.last_error, key)) != NULL)
            n = strtoull(p + strlen(key), NULL, 10);
    }
    host_free_instance(&in);
    return n;
}

static void time_step(const host_fmu *f, int exact, unsigned long long n, int runs, const char *what)
{
    double t[32], total;
    int r;
    for (r = 0; r < runs; r++) {
        host_inst in;
        double t0;
        host_status st;
        if (start(&in, f, exact) == NULL) {
            printf("%s: could not start an instance\n", f->id);
            host_free_instance(&in);
            return;
        }
        t0 = seconds();
        st = host_step(f, in.c, 0.0, (double)n * f->h);
        t[r] = seconds() - t0;
        if (st > HOST_WARNING) {
            printf("%s: the step of %llu samples was refused: %s\n", f->id, n, in.log.last_error);
            host_free_instance(&in);
            return;
        }
        host_free_instance(&in);
    }
    qsort(t, (size_t)runs, sizeof t[0], by_value);
    printf("%-27s %-34s %9llu samples (%8.1f s of model time): median %.3f s, %.1f ns/sample; runs",
           f->id, what, n, (double)n * f->h, t[runs / 2], 1e9 * t[runs / 2] / (double)n);
    for (r = 0, total = 0.0; r < runs; r++) {
        printf(" %.3f", t[r]);
        total += t[r];
    }
    printf("\n");
}

int main(int argc, char **argv)
{
    static host_fmu fmus[8];
    int i, n_fmus = 0, runs = 5, first = 1;
    if (argc > 2 && strcmp(argv[1], "--runs") == 0) {
        runs = atoi(argv[2]);
        first = 3;
    }
    if (runs < 1 || runs > 32 || argc - first < 2 || (argc - first) % 2 != 0 || (argc - first) / 2 > 8) {
        fprintf(stderr, "usage: %s [--runs N (1..32)] MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]\n", argv[0]);
        return 2;
    }
    for (i = first; i + 1 < argc; i += 2)
        if (!host_load(&fmus[n_fmus++], argv[i], argv[i + 1]))
            return 2;
    for (i = 0; i < n_fmus; i++) {
        const host_fmu *f = &fmus[i];
        unsigned long long samples = bound_from_refusal(f, 0, 1e12, "computes at most ");
        if (samples == 0) {
            printf("%s: no bound named in the refusal of a step of 1e12 samples\n", f->id);
            continue;
        }
        time_step(f, 0, samples, runs, "longest step");
        if (host_named(f, "creep.exact", NULL) != NULL) {
            unsigned long long longest = bound_from_refusal(f, 1, (double)samples, "a step of at most ");
            if (longest > 0)
                time_step(f, 1, longest, runs, "longest step from t0, creep.exact");
        }
    }
    for (i = 0; i < n_fmus; i++)
        host_unload(&fmus[i]);
    return 0;
}
