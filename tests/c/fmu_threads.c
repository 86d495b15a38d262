/*
 * fmu_threads.c - instances of the FMUs run concurrently in 8 threads give
 * bitwise the results of the same runs made one after the other. Built once per
 * FMI version: fmu_threads (FMI 2.0 editions), fmu3_threads (FMI 3.0).
 *
 * Each run (configuration i of an FMU, see host_apply_config) steps N samples
 * with its own inputs and, every 250 samples, saves its state, serializes it,
 * deserializes it and restores it, so allocation, the FMU-state list and the
 * (de)serializer run concurrently too. The reference: the same runs made
 * sequentially in the main thread. Phases: 8 instances of each FMU, then 8
 * threads over all FMUs given. FMI 2.0 also counts the blocks its memory
 * callbacks hand out: all are freed at the end.
 *
 * usage: fmu_threads MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]
 */
#include "host.h"

#include <pthread.h>

#define N_THREADS 8
#define N_SAMPLES 2000

typedef struct {
    const host_fmu *f;
    int config;
    double *outputs;            /* N_SAMPLES x HOST_MAX_OUTPUTS */
    int n_done;                 /* samples completed */
    int ok;
    pthread_barrier_t *start;
} run_t;

/* get, serialize, deserialize, set */
static int state_round_trip(const host_fmu *f, void *c)
{
    host_state s = NULL, back = NULL;
    size_t size = 0;
    unsigned char *blob = NULL;
    int ok = host_get_state(f, c, &s) == HOST_OK && host_state_size(f, c, s, &size) == HOST_OK
             && (blob = malloc(size)) != NULL && host_serialize(f, c, s, blob, size) == HOST_OK
             && host_deserialize(f, c, blob, size, &back) == HOST_OK && host_set_state(f, c, back) == HOST_OK;
    host_free_state(f, c, &s);
    host_free_state(f, c, &back);
    free(blob);
    return ok;
}

static void *run(void *arg)
{
    run_t *r = (run_t *)arg;
    const host_fmu *f = r->f;
    host_inst in;
    int k;
    if (r->start != NULL)
        pthread_barrier_wait(r->start);
    r->ok = 0;
    r->n_done = 0;
    if (host_instantiate(&in, f, "thread") == NULL || host_enter_init(f, in.c, 0.0, 0, 0.0) != HOST_OK
        || !host_apply_config(f, in.c, r->config) || f->api.ExitInitializationMode(in.c) != HOST_OK) {
        host_free_instance(&in);
        return NULL;
    }
    for (k = 0; k < N_SAMPLES; k++) {
        if (k % 250 == 125 && !state_round_trip(f, in.c))
            break;
        if (!host_set_inputs(f, in.c, r->config, k) || host_step(f, in.c, k * f->h, f->h) > HOST_WARNING
            || host_real_outputs(f, in.c, r->outputs + (size_t)k * HOST_MAX_OUTPUTS, HOST_MAX_OUTPUTS) < 0)
            break;
        r->n_done = k + 1;
    }
    r->ok = r->n_done == N_SAMPLES;
    host_free_instance(&in);
    return NULL;
}

/* Runs configs[t] of fmus[t] sequentially, then concurrently; compares. */
static void phase(const char *name, const host_fmu **fmus, const int *configs)
{
    run_t seq[N_THREADS], par[N_THREADS];
    pthread_t threads[N_THREADS];
    pthread_barrier_t start;
    int t, started = 1;
    for (t = 0; t < N_THREADS; t++) {
        size_t bytes = (size_t)N_SAMPLES * HOST_MAX_OUTPUTS * sizeof(double);
        seq[t].f = par[t].f = fmus[t];
        seq[t].config = par[t].config = configs[t];
        seq[t].outputs = calloc(1, bytes);
        par[t].outputs = calloc(1, bytes);
        seq[t].start = NULL;
        par[t].start = &start;
        run(&seq[t]);
    }
    pthread_barrier_init(&start, NULL, N_THREADS);
    for (t = 0; t < N_THREADS; t++)
        if (pthread_create(&threads[t], NULL, run, &par[t]) != 0)
            started = 0;
    check(started, "%s: %d threads started", name, N_THREADS);
    if (!started)
        exit(host_summary());
    for (t = 0; t < N_THREADS; t++)
        pthread_join(threads[t], NULL);
    pthread_barrier_destroy(&start);
    /* the runs differ, so a thread reading another's state could not go unnoticed */
    for (t = 1; t < N_THREADS; t++)
        if (fmus[t] == fmus[0])
            check(memcmp(seq[t].outputs, seq[0].outputs, (size_t)N_SAMPLES * HOST_MAX_OUTPUTS * sizeof(double)) != 0,
                  "%s: configurations %d and %d give different outputs", name, configs[0], configs[t]);
    for (t = 0; t < N_THREADS; t++) {
        check(seq[t].ok, "%s: thread %d (%s, configuration %d) ran %d samples alone", name, t, fmus[t]->id,
              configs[t], seq[t].n_done);
        check(par[t].ok && memcmp(seq[t].outputs, par[t].outputs, (size_t)N_SAMPLES * HOST_MAX_OUTPUTS * sizeof(double)) == 0,
              "%s: thread %d (%s, configuration %d) concurrently: %d samples, bitwise equal to the sequential run",
              name, t, fmus[t]->id, configs[t], par[t].n_done);
        free(seq[t].outputs);
        free(par[t].outputs);
    }
}

int main(int argc, char **argv)
{
    static host_fmu fmus[4];
    const host_fmu *which[N_THREADS];
    int configs[N_THREADS], n = 0, i, t;
    char name[96];
    if (argc < 3 || argc % 2 == 0 || (argc - 1) / 2 > 4) {
        fprintf(stderr, "usage: %s MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    for (i = 1; i + 1 < argc; i += 2)
        if (!host_load(&fmus[n++], argv[i], argv[i + 1]))
            return 2;
    for (i = 0; i < n; i++) {
        for (t = 0; t < N_THREADS; t++) {
            which[t] = &fmus[i];
            configs[t] = t;
        }
        snprintf(name, sizeof name, "8 x %.63s", fmus[i].id);
        phase(name, which, configs);
    }
    for (t = 0; t < N_THREADS; t++) {
        which[t] = &fmus[t % n];
        configs[t] = N_THREADS - 1 - t;
    }
    phase("mixed FMUs", which, configs);
#if FMI_VERSION == 2
    check(host_mem_in_use() == 0, "every block the FMUs allocated was freed (%ld left)", host_mem_in_use());
#endif
    for (i = 0; i < n; i++)
        host_unload(&fmus[i]);
    return host_summary();
}
