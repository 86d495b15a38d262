/* piezo_bench.c - timing loops of the core. See piezo_bench.h. */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdlib.h>
#include <time.h>
#include "piezo_bench.h"

static double thread_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

/* Block timer: call tick(k + 1) after sample k. */
typedef struct {
    size_t block;
    double *block_ns;
    double t;
} block_timer;

static void timer_start(block_timer *tm, size_t block, double *block_ns)
{
    tm->block = block_ns != NULL ? block : 0;
    tm->block_ns = block_ns;
    tm->t = tm->block ? thread_ns() : 0.0;
}

static void timer_tick(block_timer *tm, size_t done)
{
    if (tm->block && done % tm->block == 0) {
        double now = thread_ns();
        tm->block_ns[done / tm->block - 1] = now - tm->t;
        tm->t = now;
    }
}

static int set_status(int *status, int st)
{
    if (status) *status = st;
    return st;
}

/* Nothing run: why in *status. */
static size_t refuse(int *status, int st)
{
    set_status(status, st);
    return 0;
}

size_t piezo_bench_closed_loop(const piezo_plant_params *pp, const piezo_controller_params *cp,
                               const double *y_ref, size_t n, double *y_meas, double *v,
                               size_t block, double *block_ns, int *status)
{
    piezo_plant plant;
    piezo_controller ctrl;
    piezo_controller_output out;
    block_timer tm;
    double published;
    size_t k;
    int st;
    if (!pp || !cp || !y_ref) return refuse(status, PIEZO_ERR_NULL);
    if (pp->creep_exact || cp->creep_exact) return refuse(status, PIEZO_ERR_PARAM);
    st = piezo_plant_init(&plant, pp, NULL);
    if (st == PIEZO_OK) st = piezo_controller_init(&ctrl, cp, NULL);
    if (set_status(status, st) != PIEZO_OK) return 0;
    published = ctrl.out.v;
    timer_start(&tm, block, block_ns);
    for (k = 0; k < n; ++k) {
        double applied;
        if (y_meas) y_meas[k] = plant.out.y_meas;
        st = piezo_controller_step(&ctrl, y_ref[k], plant.out.y_meas, NULL, 0, &out);
        if (st != PIEZO_OK) break;
        applied = cp->mv_feedthrough ? out.v : published;
        published = out.v;
        if (v) v[k] = applied;
        st = piezo_plant_step(&plant, applied, NULL, 0, NULL);
        if (st != PIEZO_OK) break;
        timer_tick(&tm, k + 1);
    }
    set_status(status, st);
    return k;
}

size_t piezo_bench_plant(const piezo_plant_params *params, const double *v, size_t n,
                         size_t block, double *block_ns, int *status)
{
    piezo_plant plant;
    block_timer tm;
    size_t k;
    int st;
    if (!params || !v) return refuse(status, PIEZO_ERR_NULL);
    if (params->creep_exact) return refuse(status, PIEZO_ERR_PARAM);
    st = piezo_plant_init(&plant, params, NULL);
    if (set_status(status, st) != PIEZO_OK) return 0;
    timer_start(&tm, block, block_ns);
    for (k = 0; k < n; ++k) {
        st = piezo_plant_step(&plant, v[k], NULL, 0, NULL);
        if (st != PIEZO_OK) break;
        timer_tick(&tm, k + 1);
    }
    set_status(status, st);
    return k;
}

size_t piezo_bench_controller(const piezo_controller_params *params, const double *y_ref,
                              const double *y_meas, size_t n, size_t block, double *block_ns,
                              int *status)
{
    piezo_controller ctrl;
    piezo_controller_output out;
    block_timer tm;
    size_t k;
    int st;
    if (!params || !y_ref || !y_meas) return refuse(status, PIEZO_ERR_NULL);
    if (params->creep_exact) return refuse(status, PIEZO_ERR_PARAM);
    st = piezo_controller_init(&ctrl, params, NULL);
    if (set_status(status, st) != PIEZO_OK) return 0;
    timer_start(&tm, block, block_ns);
    for (k = 0; k < n; ++k) {
        st = piezo_controller_step(&ctrl, y_ref[k], y_meas[k], NULL, 0, &out);
        if (st != PIEZO_OK) break;
        timer_tick(&tm, k + 1);
    }
    set_status(status, st);
    return k;
}

size_t piezo_bench_exact_plant(const piezo_plant_params *params, size_t k0, size_t n,
                               size_t block, double *block_ns, int *status)
{
    piezo_plant_params p;
    piezo_plant plant;
    block_timer tm;
    double *history, *w;
    size_t j, k, capacity;
    int st;
    if (!params) return refuse(status, PIEZO_ERR_NULL);
    p = *params;
    p.creep_exact = 1;
    p.creep_enabled = 1;
    st = piezo_plant_init(&plant, &p, NULL);
    if (set_status(status, st) != PIEZO_OK) return 0;
    capacity = 2 * (k0 + n + 1);
    history = malloc(capacity * sizeof *history);
    w = malloc((k0 + 1) * sizeof *w);
    if (!history || !w) {
        free(history);
        free(w);
        return refuse(status, PIEZO_ERR_CAPACITY);
    }
    /* history[2j] = x(j), history[2j+1] = w_j (piezo_creep.h) */
    piezo_gl_weights(p.creep_alpha, w, k0 + 1);
    for (j = 0; j < k0; ++j) {
        history[2 * j] = 5.0 + 4.0 * sin(2.0 * 3.14159265358979323846 * (double)j * p.h);
        history[2 * j + 1] = w[j];
    }
    plant.creep.k = k0;
    timer_start(&tm, block, block_ns);
    for (k = 0; k < n; ++k) {
        double vk = 10.0 + 8.0 * sin(2.0 * 3.14159265358979323846 * (double)(k0 + k) * p.h);
        st = piezo_plant_step(&plant, vk, history, capacity, NULL);
        if (st != PIEZO_OK) break;
        timer_tick(&tm, k + 1);
    }
    free(history);
    free(w);
    set_status(status, st);
    return k;
}
