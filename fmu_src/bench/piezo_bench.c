/*
 * piezo_bench.c - speed and memory figures of the core (printed, not asserted).
 *
 * Targets (docs/model.md, plant): the default SOE creep costs O(1) per step
 * with fixed-size state; the exact mode costs O(k) per step and O(k) memory.
 * Usage: piezo_bench [seconds_of_signal]   (default 60 s at 2 kHz)
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "piezo_core.h"

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double input_voltage(size_t k, double h)
{
    double t = (double)k * h;
    return 10.0 * sin(2.0 * 3.14159265358979323846 * t) + 10.0;
}

/* Runs the plant for n samples; returns ns per sample, or -1 on failure. */
static double bench_plant(int exact, size_t n, double *y_last)
{
    piezo_plant_params params;
    piezo_plant plant;
    piezo_diag diag;
    double *history = NULL, t0, t1;
    size_t k;
    piezo_plant_default_params(&params);
    params.creep_exact = exact;
    if (piezo_plant_init(&plant, &params, &diag) != PIEZO_OK) return -1.0;
    if (exact) {
        history = malloc(2 * (n + 1) * sizeof *history);
        if (!history) return -1.0;
    }
    t0 = now_seconds();
    for (k = 0; k < n; ++k)
        if (piezo_plant_step(&plant, input_voltage(k, params.h), history, exact ? 2 * (n + 1) : 0, NULL) != PIEZO_OK) {
            free(history);
            return -1.0;
        }
    t1 = now_seconds();
    *y_last = plant.out.y;
    free(history);
    return (t1 - t0) / (double)n * 1e9;
}

/* Closed loop (nominal model, preview): controller + plant per sample. */
static double bench_closed_loop(size_t n, double *e_last)
{
    piezo_plant_params pp;
    piezo_controller_params cp;
    piezo_plant plant;
    piezo_controller ctrl;
    piezo_controller_output out;
    piezo_diag diag;
    double t0, t1, h;
    size_t k;
    piezo_plant_default_params(&pp);
    piezo_controller_default_params(&cp);
    if (piezo_plant_init(&plant, &pp, &diag) != PIEZO_OK) return -1.0;
    if (piezo_controller_init(&ctrl, &cp, &diag) != PIEZO_OK) return -1.0;
    h = pp.h;
    t0 = now_seconds();
    for (k = 0; k < n; ++k) {
        double y_ref = 10.0 * sin(2.0 * 3.14159265358979323846 * (double)(k + 1) * h);
        if (piezo_controller_step(&ctrl, y_ref, plant.out.y_meas, NULL, 0, &out) != PIEZO_OK) return -1.0;
        if (piezo_plant_step(&plant, out.v, NULL, 0, NULL) != PIEZO_OK) return -1.0;
    }
    t1 = now_seconds();
    *e_last = 10.0 * sin(2.0 * 3.14159265358979323846 * (double)n * h) - plant.out.y;
    return (t1 - t0) / (double)n * 1e9;
}

int main(int argc, char **argv)
{
    double seconds = argc > 1 ? atof(argv[1]) : 60.0;
    size_t n = (size_t)(seconds / 0.0005);
    size_t n_short = n / 10;
    double y_soe = 0.0, y_exact = 0.0, e_loop = 0.0, ns;
    piezo_gl gl;

    piezo_gl_init(&gl, 0.0002, 1.0, 0, NULL);
    printf("piezo core benchmark, %.0f s of signal at 2 kHz (%zu samples)\n", seconds, n);
    printf("memory: sizeof piezo_plant %zu B, piezo_controller %zu B, piezo_gl %zu B (fixed, SOE terms %d)\n",
           sizeof(piezo_plant), sizeof(piezo_controller), sizeof(piezo_gl), gl.n_terms);
    printf("        exact mode history: 16 B per sample (x and w_j) = %.1f MB after %.0f s\n", 16.0 * (double)n / 1e6, seconds);

    ns = bench_plant(0, n, &y_soe);
    printf("plant, SOE creep (default):  %8.1f ns/sample over %zu samples\n", ns, n);
    ns = bench_plant(1, n_short, &y_exact);
    printf("plant, exact creep:          %8.1f ns/sample over %zu samples (mean; grows with k)\n", ns, n_short);
    ns = bench_plant(1, n, &y_exact);
    printf("plant, exact creep:          %8.1f ns/sample over %zu samples\n", ns, n);
    printf("|y_SOE - y_exact| at the end: %.3e um\n", fabs(y_soe - y_exact));
    ns = bench_closed_loop(n, &e_loop);
    printf("closed loop (controller + plant, SOE): %8.1f ns/sample; final error %.3e um\n", ns, e_loop);
    printf("real-time margin at h = 0.5 ms: %.0fx\n", 0.0005 / (ns * 1e-9));
    return 0;
}
