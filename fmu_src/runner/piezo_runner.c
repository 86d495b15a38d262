/* piezo_runner.c - native closed-loop co-simulation master. See piezo_runner.h. */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "piezo_runner.h"

#define LOG_KEEP 256
#define LOG_TEXT 1024

/* ------------------------------------------------------------------------ */
/* Allocator handed to the FMUs: counts the bytes they hold                  */

static size_t live_bytes;   /* updated atomically: FMUs may live in several threads */

/* 16-byte header with the size, so that free can subtract it */
#define HEADER 16u

static void *counting_calloc(size_t nobj, size_t size)
{
    unsigned char *p;
    size_t bytes;
    if (size != 0 && nobj > (SIZE_MAX - HEADER) / size) return NULL;
    bytes = nobj * size;
    p = calloc(1, bytes + HEADER);
    if (p == NULL) return NULL;
    memcpy(p, &bytes, sizeof bytes);
    __atomic_add_fetch(&live_bytes, bytes, __ATOMIC_RELAXED);
    return p + HEADER;
}

static void counting_free(void *obj)
{
    unsigned char *p;
    size_t bytes;
    if (obj == NULL) return;
    p = (unsigned char *)obj - HEADER;
    memcpy(&bytes, p, sizeof bytes);
    __atomic_sub_fetch(&live_bytes, bytes, __ATOMIC_RELAXED);
    free(p);
}

size_t piezo_runner_live_bytes(void)
{
    return __atomic_load_n(&live_bytes, __ATOMIC_RELAXED);
}

/* ------------------------------------------------------------------------ */
/* One FMU instance                                                          */

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_initialization;
    fmi2ExitInitializationModeTYPE *exit_initialization;
    fmi2TerminateTYPE *terminate;
    fmi2ResetTYPE *reset;
    fmi2GetRealTYPE *get_real;
    fmi2SetRealTYPE *set_real;
    fmi2GetBooleanTYPE *get_boolean;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2DoStepTYPE *do_step;
} fmi2_api;

struct piezo_runner;

typedef struct {
    struct piezo_runner *owner;
    int role;
    void *library;
    fmi2_api api;
    fmi2CallbackFunctions callbacks;
    fmi2Component component;
    size_t instance_bytes;      /* allocated by fmi2Instantiate */
} slave;

typedef struct {
    int role;
    int status;
    char *text;
} log_entry;

struct piezo_runner {
    slave fmu[2];               /* PIEZO_RUNNER_PLANT, PIEZO_RUNNER_CONTROLLER */
    fmi2ValueReference p_out[3];        /* y, y_meas, t_meas */
    fmi2ValueReference p_y_meas;
    fmi2ValueReference p_in;            /* v */
    fmi2ValueReference c_in[5];         /* y_ref, y_meas, y_preview, t_preview, t_meas */
    fmi2ValueReference c_out[PIEZO_RUNNER_CTRL_REALS];
    fmi2ValueReference c_sat;
    double start_time;
    size_t k;                   /* samples since initialization */
    log_entry log[LOG_KEEP];
    size_t n_log;
    size_t n_dropped;
};

static void runner_logger(fmi2ComponentEnvironment env, fmi2String instance_name, fmi2Status status,
                          fmi2String category, fmi2String message, ...)
{
    slave *s = (slave *)env;
    struct piezo_runner *r;
    char text[LOG_TEXT];
    va_list ap;
    (void)instance_name;
    (void)category;
    if (s == NULL || s->owner == NULL) return;
    r = s->owner;
    if (r->n_log >= LOG_KEEP) {
        r->n_dropped += 1;
        return;
    }
    va_start(ap, message);
    vsnprintf(text, sizeof text, message != NULL ? message : "", ap);
    va_end(ap);
    r->log[r->n_log].text = malloc(strlen(text) + 1);
    if (r->log[r->n_log].text == NULL) {
        r->n_dropped += 1;
        return;
    }
    strcpy(r->log[r->n_log].text, text);
    r->log[r->n_log].role = s->role;
    r->log[r->n_log].status = (int)status;
    r->n_log += 1;
}

/* An object pointer from dlsym as a function pointer, without the cast ISO C forbids. */
static int bind(void *library, const char *name, void *function_pointer, size_t size,
                char *error, size_t error_size)
{
    void *symbol = dlsym(library, name);
    if (symbol == NULL) {
        snprintf(error, error_size, "the FMU binary does not export %s", name);
        return 0;
    }
    memcpy(function_pointer, &symbol, size);
    return 1;
}

#define BIND(field, name) \
    bind(s->library, name, &s->api.field, sizeof s->api.field, error, error_size)

static int load(slave *s, const piezo_runner_fmu *fmu, char *error, size_t error_size)
{
    const char *why;
    s->library = dlopen(fmu->library, RTLD_NOW | RTLD_LOCAL);
    if (s->library == NULL) {
        why = dlerror();
        snprintf(error, error_size, "cannot load %s: %s", fmu->library, why != NULL ? why : "?");
        return 0;
    }
    return BIND(instantiate, "fmi2Instantiate") && BIND(free_instance, "fmi2FreeInstance")
        && BIND(setup_experiment, "fmi2SetupExperiment")
        && BIND(enter_initialization, "fmi2EnterInitializationMode")
        && BIND(exit_initialization, "fmi2ExitInitializationMode")
        && BIND(terminate, "fmi2Terminate") && BIND(reset, "fmi2Reset")
        && BIND(get_real, "fmi2GetReal") && BIND(set_real, "fmi2SetReal")
        && BIND(get_boolean, "fmi2GetBoolean") && BIND(set_integer, "fmi2SetInteger")
        && BIND(set_boolean, "fmi2SetBoolean") && BIND(do_step, "fmi2DoStep");
}

/* The last error messages of one FMU, for the reason a creation failed. */
static void append_errors(const struct piezo_runner *r, int role, char *error, size_t error_size)
{
    size_t i, used = strlen(error);
    for (i = 0; i < r->n_log && used + 3 < error_size; ++i) {
        if (r->log[i].role != role) continue;
        used += (size_t)snprintf(error + used, error_size - used, "; %s", r->log[i].text);
        if (used >= error_size) break;
    }
}

void piezo_runner_free(piezo_runner *r)
{
    int i;
    size_t j;
    if (r == NULL) return;
    for (i = 0; i < 2; ++i) {
        slave *s = &r->fmu[i];
        if (s->component != NULL) s->api.free_instance(s->component);
        if (s->library != NULL) dlclose(s->library);
    }
    for (j = 0; j < r->n_log; ++j) free(r->log[j].text);
    free(r);
}

piezo_runner *piezo_runner_new(const piezo_runner_fmu *plant, const piezo_runner_fmu *controller,
                               const piezo_runner_refs *refs, char *error, size_t error_size)
{
    const piezo_runner_fmu *fmus[2];
    piezo_runner *r;
    size_t before;
    int i;
    char scratch[8];
    if (error == NULL || error_size == 0) {
        error = scratch;
        error_size = sizeof scratch;
    }
    error[0] = '\0';
    if (plant == NULL || controller == NULL || refs == NULL) {
        snprintf(error, error_size, "piezo_runner_new: NULL argument");
        return NULL;
    }
    fmus[PIEZO_RUNNER_PLANT] = plant;
    fmus[PIEZO_RUNNER_CONTROLLER] = controller;
    r = calloc(1, sizeof *r);
    if (r == NULL) {
        snprintf(error, error_size, "out of memory");
        return NULL;
    }
    r->p_out[0] = (fmi2ValueReference)refs->plant_y;
    r->p_out[1] = (fmi2ValueReference)refs->plant_y_meas;
    r->p_out[2] = (fmi2ValueReference)refs->plant_t_meas;
    r->p_y_meas = (fmi2ValueReference)refs->plant_y_meas;
    r->p_in = (fmi2ValueReference)refs->plant_v;
    r->c_in[0] = (fmi2ValueReference)refs->ctrl_y_ref;
    r->c_in[1] = (fmi2ValueReference)refs->ctrl_y_meas;
    r->c_in[2] = (fmi2ValueReference)refs->ctrl_y_preview;
    r->c_in[3] = (fmi2ValueReference)refs->ctrl_t_preview;
    r->c_in[4] = (fmi2ValueReference)refs->ctrl_t_meas;
    for (i = 0; i < PIEZO_RUNNER_CTRL_REALS; ++i) r->c_out[i] = (fmi2ValueReference)refs->ctrl_reals[i];
    r->c_sat = (fmi2ValueReference)refs->ctrl_saturated;
    for (i = 0; i < 2; ++i) {
        slave *s = &r->fmu[i];
        const piezo_runner_fmu *f = fmus[i];
        s->owner = r;
        s->role = i;
        if (f->library == NULL || f->guid == NULL || f->instance_name == NULL) {
            snprintf(error, error_size, "piezo_runner_new: library, guid and instance_name are required");
            piezo_runner_free(r);
            return NULL;
        }
        if (!load(s, f, error, error_size)) {
            piezo_runner_free(r);
            return NULL;
        }
        s->callbacks.logger = runner_logger;
        s->callbacks.allocateMemory = counting_calloc;
        s->callbacks.freeMemory = counting_free;
        s->callbacks.stepFinished = NULL;
        s->callbacks.componentEnvironment = s;
        before = piezo_runner_live_bytes();
        s->component = s->api.instantiate(f->instance_name, fmi2CoSimulation, f->guid, f->resource_uri,
                                          &s->callbacks, fmi2False, fmi2False);
        s->instance_bytes = piezo_runner_live_bytes() - before;
        if (s->component == NULL) {
            snprintf(error, error_size, "fmi2Instantiate of %s failed", f->library);
            append_errors(r, i, error, error_size);
            piezo_runner_free(r);
            return NULL;
        }
    }
    return r;
}

static int bad_role(int role)
{
    return role != PIEZO_RUNNER_PLANT && role != PIEZO_RUNNER_CONTROLLER;
}

int piezo_runner_set_real(piezo_runner *r, int role, const int *refs, const double *values, size_t n)
{
    fmi2ValueReference vr[64];
    size_t i;
    if (r == NULL || bad_role(role) || n > 64 || (n > 0 && (refs == NULL || values == NULL))) return fmi2Error;
    for (i = 0; i < n; ++i) vr[i] = (fmi2ValueReference)refs[i];
    return r->fmu[role].api.set_real(r->fmu[role].component, vr, n, values);
}

int piezo_runner_set_integer(piezo_runner *r, int role, const int *refs, const int *values, size_t n)
{
    fmi2ValueReference vr[64];
    size_t i;
    if (r == NULL || bad_role(role) || n > 64 || (n > 0 && (refs == NULL || values == NULL))) return fmi2Error;
    for (i = 0; i < n; ++i) vr[i] = (fmi2ValueReference)refs[i];
    return r->fmu[role].api.set_integer(r->fmu[role].component, vr, n, values);
}

int piezo_runner_set_boolean(piezo_runner *r, int role, const int *refs, const int *values, size_t n)
{
    fmi2ValueReference vr[64];
    fmi2Boolean b[64];
    size_t i;
    if (r == NULL || bad_role(role) || n > 64 || (n > 0 && (refs == NULL || values == NULL))) return fmi2Error;
    for (i = 0; i < n; ++i) {
        vr[i] = (fmi2ValueReference)refs[i];
        b[i] = values[i] ? fmi2True : fmi2False;
    }
    return r->fmu[role].api.set_boolean(r->fmu[role].component, vr, n, b);
}

static void result_start(piezo_runner_result *res)
{
    res->status = fmi2OK;
    res->samples = 0;
    res->failed_role = -1;
    res->failed_call = PIEZO_RUNNER_CALL_NONE;
}

/* Record a status; 1 if the sequence must stop (above fmi2Warning). */
static int failed(piezo_runner_result *res, int status, int role, int call)
{
    if (status > res->status) res->status = status;
    if (status <= fmi2Warning) return 0;
    res->failed_role = role;
    res->failed_call = call;
    return 1;
}

int piezo_runner_initialize(piezo_runner *r, double start_time, double stop_time, piezo_runner_result *res)
{
    piezo_runner_result local;
    int i;
    if (res == NULL) res = &local;
    result_start(res);
    if (r == NULL) return res->status = fmi2Error;
    for (i = 0; i < 2; ++i) {
        slave *s = &r->fmu[i];
        if (failed(res, s->api.setup_experiment(s->component, fmi2False, 0.0, start_time, fmi2True, stop_time),
                   i, PIEZO_RUNNER_CALL_SETUP_EXPERIMENT)
            || failed(res, s->api.enter_initialization(s->component), i, PIEZO_RUNNER_CALL_ENTER_INITIALIZATION)
            || failed(res, s->api.exit_initialization(s->component), i, PIEZO_RUNNER_CALL_EXIT_INITIALIZATION))
            return res->status;
    }
    r->start_time = start_time;
    r->k = 0;
    return res->status;
}

static double thread_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
}

/* fmi2OK, the usual status, changes nothing in res: only another is recorded */
#define CALL(expr, role, call) \
    do { int st_ = (expr); if (st_ != fmi2OK && failed(res, st_, (role), (call))) goto stop; } while (0)

int piezo_runner_run(piezo_runner *r, size_t n, double h, int master, int step_order,
                     const double *y_ref, const double *y_preview, const double *t_preview,
                     double *rows, size_t row_stride,
                     size_t timing_block, double *block_ns, piezo_runner_result *res)
{
    piezo_runner_result local;
    fmi2Component pc, cc;
    const fmi2_api *pa, *ca;
    const int plant = PIEZO_RUNNER_PLANT, ctrl = PIEZO_RUNNER_CONTROLLER;
    double c_in[5], p_out[3], minimal[2], t_block = 0.0;
    fmi2Boolean sat;
    size_t k, k0, block_left = timing_block;    /* samples until the current timing block is complete */
    int jacobi = master == PIEZO_RUNNER_JACOBI, ctrl_first = step_order == PIEZO_RUNNER_CONTROLLER_FIRST;
    int timing = block_ns != NULL && timing_block > 0;
    if (res == NULL) res = &local;
    result_start(res);
    if (r == NULL || (n > 0 && y_ref == NULL) || (y_preview != NULL && t_preview == NULL)
        || (rows != NULL && row_stride < PIEZO_RUNNER_ROW)
        || (master != PIEZO_RUNNER_GAUSS_SEIDEL && !jacobi)
        || (step_order != PIEZO_RUNNER_PLANT_FIRST && !ctrl_first))
        return res->status = fmi2Error;
    pc = r->fmu[plant].component;
    cc = r->fmu[ctrl].component;
    pa = &r->fmu[plant].api;
    ca = &r->fmu[ctrl].api;
    k0 = r->k;
    if (timing) t_block = thread_ns();
    for (k = 0; k < n; ++k) {
        /* time on the integer grid, as the harness computes it: start + k h (k < 2^63, so
         * the signed conversion gives (double)k in one instruction, the unsigned one takes several) */
        double t = r->start_time + (double)(int64_t)(k0 + k) * h;
        if (rows != NULL) {
            double *row = rows + k * row_stride;
            CALL(pa->get_real(pc, r->p_out, 3, p_out), plant, PIEZO_RUNNER_CALL_GET_REAL);  /* y, y_meas, t_meas */
            row[0] = p_out[0];
            row[1] = p_out[1];
            c_in[0] = y_ref[k];
            c_in[1] = p_out[1];
            /* the stamped preview (0, 0 without one: a stamp that does not advance) */
            c_in[2] = y_preview != NULL ? y_preview[k] : 0.0;
            c_in[3] = y_preview != NULL ? t_preview[k] : 0.0;
            c_in[4] = p_out[2];
            if (jacobi) {
                CALL(ca->get_real(cc, r->c_out, PIEZO_RUNNER_CTRL_REALS, row + 2), ctrl, PIEZO_RUNNER_CALL_GET_REAL);
                CALL(ca->get_boolean(cc, &r->c_sat, 1, &sat), ctrl, PIEZO_RUNNER_CALL_GET_BOOLEAN);
                CALL(pa->set_real(pc, &r->p_in, 1, row + 2), plant, PIEZO_RUNNER_CALL_SET_REAL);
                CALL(ca->set_real(cc, r->c_in, 5, c_in), ctrl, PIEZO_RUNNER_CALL_SET_REAL);
            } else {
                CALL(ca->set_real(cc, r->c_in, 5, c_in), ctrl, PIEZO_RUNNER_CALL_SET_REAL);
                CALL(ca->get_real(cc, r->c_out, PIEZO_RUNNER_CTRL_REALS, row + 2), ctrl, PIEZO_RUNNER_CALL_GET_REAL);
                CALL(ca->get_boolean(cc, &r->c_sat, 1, &sat), ctrl, PIEZO_RUNNER_CALL_GET_BOOLEAN);
                CALL(pa->set_real(pc, &r->p_in, 1, row + 2), plant, PIEZO_RUNNER_CALL_SET_REAL);
            }
            row[PIEZO_RUNNER_ROW - 1] = sat != fmi2False ? 1.0 : 0.0;
        } else {
            /* the minimal exchange: y_meas to the controller, v to the plant */
            CALL(pa->get_real(pc, &r->p_y_meas, 1, &c_in[1]), plant, PIEZO_RUNNER_CALL_GET_REAL);
            c_in[0] = y_ref[k];
            if (jacobi) {
                CALL(ca->get_real(cc, r->c_out, 1, minimal), ctrl, PIEZO_RUNNER_CALL_GET_REAL);
                CALL(pa->set_real(pc, &r->p_in, 1, minimal), plant, PIEZO_RUNNER_CALL_SET_REAL);
                CALL(ca->set_real(cc, r->c_in, 2, c_in), ctrl, PIEZO_RUNNER_CALL_SET_REAL);
            } else {
                CALL(ca->set_real(cc, r->c_in, 2, c_in), ctrl, PIEZO_RUNNER_CALL_SET_REAL);
                CALL(ca->get_real(cc, r->c_out, 1, minimal), ctrl, PIEZO_RUNNER_CALL_GET_REAL);
                CALL(pa->set_real(pc, &r->p_in, 1, minimal), plant, PIEZO_RUNNER_CALL_SET_REAL);
            }
        }
        if (ctrl_first) {
            CALL(ca->do_step(cc, t, h, fmi2True), ctrl, PIEZO_RUNNER_CALL_DO_STEP);
            CALL(pa->do_step(pc, t, h, fmi2True), plant, PIEZO_RUNNER_CALL_DO_STEP);
        } else {
            CALL(pa->do_step(pc, t, h, fmi2True), plant, PIEZO_RUNNER_CALL_DO_STEP);
            CALL(ca->do_step(cc, t, h, fmi2True), ctrl, PIEZO_RUNNER_CALL_DO_STEP);
        }
        res->samples = k + 1;
        /* block (k + 1) / timing_block - 1 ends with sample k when timing_block divides k + 1
         * (counted down: no division per sample) */
        if (timing && --block_left == 0) {
            double now = thread_ns();
            block_ns[(k + 1) / timing_block - 1] = now - t_block;
            t_block = now;
            block_left = timing_block;
        }
    }
stop:
    r->k += res->samples;
    return res->status;
}

/* ------------------------------------------------------------------------ */
/* Batches                                                                   */

/* The terms the batch sums: x[i] (SUM_PLAIN), (x[i] - y[i s])^2 (SUM_ERROR2), y[i s]^2 (SUM_SQUARE) */
enum { SUM_PLAIN, SUM_ERROR2, SUM_SQUARE };

static double term(int kind, const double *x, const double *y, size_t stride, size_t i)
{
    double e;
    switch (kind) {
    case SUM_ERROR2:
        e = x[i] - y[i * stride];
        return e * e;
    case SUM_SQUARE:
        e = y[i * stride];
        return e * e;
    default:
        return x[i];
    }
}

/* NumPy's pairwise summation (see piezo_runner.h), without the leading 0.0 + */
static double pairwise(int kind, const double *x, const double *y, size_t stride, size_t n)
{
    size_t i, j, n2;
    double s[8], sum;
    if (n < 8) {
        sum = 0.0;
        for (i = 0; i < n; ++i) sum += term(kind, x, y, stride, i);
        return sum;
    }
    if (n <= 128) {
        for (j = 0; j < 8; ++j) s[j] = term(kind, x, y, stride, j);
        for (i = 8; i < n - n % 8; i += 8)
            for (j = 0; j < 8; ++j) s[j] += term(kind, x, y, stride, i + j);
        sum = ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]));
        for (; i < n; ++i) sum += term(kind, x, y, stride, i);
        return sum;
    }
    n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise(kind, x, y, stride, n2)
        + pairwise(kind, x == NULL ? NULL : x + n2, y == NULL ? NULL : y + n2 * stride, stride, n - n2);
}

double piezo_runner_pairwise_sum(const double *x, size_t n)
{
    if (x == NULL && n > 0) return 0.0;
    return 0.0 + pairwise(SUM_PLAIN, x, NULL, 0, n);
}

static double wall_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int bad_params(const piezo_runner_params *p)
{
    return p == NULL || p->n_real > 64 || p->n_int > 64 || p->n_bool > 64
        || (p->n_real > 0 && (p->real_refs == NULL || p->reals == NULL))
        || (p->n_int > 0 && (p->int_refs == NULL || p->ints == NULL))
        || (p->n_bool > 0 && (p->bool_refs == NULL || p->bools == NULL));
}

/* Set one FMU's parameters of run i; 1 if a call failed (recorded in res). */
static int set_params(piezo_runner *r, int role, const piezo_runner_params *p, size_t i, piezo_runner_result *res)
{
    size_t row = p->per_run ? i : 0;
    if (p->n_real > 0
        && failed(res, piezo_runner_set_real(r, role, p->real_refs, p->reals + row * p->n_real, p->n_real),
                  role, PIEZO_RUNNER_CALL_SET_REAL))
        return 1;
    if (p->n_int > 0
        && failed(res, piezo_runner_set_integer(r, role, p->int_refs, p->ints + row * p->n_int, p->n_int),
                  role, PIEZO_RUNNER_CALL_SET_INTEGER))
        return 1;
    if (p->n_bool > 0
        && failed(res, piezo_runner_set_boolean(r, role, p->bool_refs, p->bools + row * p->n_bool, p->n_bool),
                  role, PIEZO_RUNNER_CALL_SET_BOOLEAN))
        return 1;
    return 0;
}

/* One run of a batch (parameters set): its samples in blocks whose rows stay in the cache;
 * y kept for the sums, the finite and clipped samples counted as the blocks complete. */
static void batch_run(piezo_runner *r, const piezo_runner_experiment *x, double *block, double *y,
                      piezo_runner_result *res, size_t i, piezo_runner_outcomes *out)
{
    piezo_runner_result part;
    size_t k0, k, len, sat = 0;
    int finite = 1;
    for (k0 = 0; k0 < x->n; k0 += len) {
        len = x->n - k0 < PIEZO_RUNNER_BATCH_BLOCK ? x->n - k0 : PIEZO_RUNNER_BATCH_BLOCK;
        piezo_runner_run(r, len, x->h, x->master, x->step_order, x->y_ref + k0,
                         x->y_preview != NULL ? x->y_preview + k0 : NULL,
                         x->t_preview != NULL ? x->t_preview + k0 : NULL,
                         block, PIEZO_RUNNER_ROW, 0, NULL, &part);
        if (part.status > res->status) res->status = part.status;
        res->samples = k0 + part.samples;
        if (part.status > fmi2Warning) {
            res->failed_role = part.failed_role;
            res->failed_call = part.failed_call;
            return;
        }
        for (k = 0; k < len; ++k) {
            const double *row = block + k * PIEZO_RUNNER_ROW;
            finite &= isfinite(row[0]) && isfinite(row[1]) && isfinite(row[2]);    /* y, y_meas, v */
            y[k0 + k] = row[0];
            sat += k0 + k >= x->window_start && k0 + k < x->window_stop && row[PIEZO_RUNNER_ROW - 1] != 0.0;
        }
    }
    out->finite[i] = finite;
    out->saturated[i] = sat;
    out->sum_error2[i] = 0.0 + pairwise(SUM_ERROR2, x->y_d + x->window_start, y + x->window_start, 1,
                                        x->window_stop - x->window_start);
    out->sum_y2[i] = 0.0 + pairwise(SUM_SQUARE, NULL, y + x->window_start, 1, x->window_stop - x->window_start);
}

size_t piezo_runner_batch(piezo_runner *r, const piezo_runner_experiment *x,
                          const piezo_runner_params *plant, const piezo_runner_params *controller,
                          size_t runs, int fresh, piezo_runner_outcomes *out)
{
    size_t i;
    piezo_runner_result res;
    double t0, *block, *y;
    if (r == NULL || x == NULL || out == NULL || bad_params(plant) || bad_params(controller)
        || x->y_ref == NULL || x->y_d == NULL || (x->y_preview != NULL && x->t_preview == NULL)
        || x->window_start > x->window_stop || x->window_stop > x->n
        || out->status == NULL || out->failed_call == NULL || out->samples == NULL || out->finite == NULL
        || out->sum_error2 == NULL || out->sum_y2 == NULL || out->saturated == NULL || out->seconds == NULL)
        return 0;
    block = malloc((PIEZO_RUNNER_BATCH_BLOCK * PIEZO_RUNNER_ROW + x->n + 1) * sizeof *block);
    if (block == NULL) return 0;
    y = block + PIEZO_RUNNER_BATCH_BLOCK * PIEZO_RUNNER_ROW;
    for (i = 0; i < runs; ++i) {
        t0 = wall_seconds();
        if (i > 0 || !fresh) piezo_runner_reset(r);
        piezo_runner_clear_log(r);
        out->finite[i] = 0;
        out->sum_error2[i] = out->sum_y2[i] = 0.0;
        out->saturated[i] = 0;
        result_start(&res);
        if (!set_params(r, PIEZO_RUNNER_PLANT, plant, i, &res)
            && !set_params(r, PIEZO_RUNNER_CONTROLLER, controller, i, &res)
            && piezo_runner_initialize(r, 0.0, (double)x->n * x->h, &res) <= fmi2Warning) {
            batch_run(r, x, block, y, &res, i, out);
            if (res.status <= fmi2Warning) piezo_runner_terminate(r);
        }
        out->status[i] = res.status;
        out->failed_call[i] = res.failed_call;
        out->samples[i] = res.samples;
        out->seconds[i] = wall_seconds() - t0;
    }
    free(block);
    return runs;
}

int piezo_runner_terminate(piezo_runner *r)
{
    piezo_runner_result res;
    int i;
    result_start(&res);
    if (r == NULL) return fmi2Error;
    for (i = 0; i < 2; ++i) failed(&res, r->fmu[i].api.terminate(r->fmu[i].component), i, PIEZO_RUNNER_CALL_TERMINATE);
    return res.status;
}

int piezo_runner_reset(piezo_runner *r)
{
    piezo_runner_result res;
    int i;
    result_start(&res);
    if (r == NULL) return fmi2Error;
    for (i = 0; i < 2; ++i) failed(&res, r->fmu[i].api.reset(r->fmu[i].component), i, PIEZO_RUNNER_CALL_RESET);
    r->k = 0;
    return res.status;
}

size_t piezo_runner_instance_bytes(const piezo_runner *r, int role)
{
    return r != NULL && !bad_role(role) ? r->fmu[role].instance_bytes : 0;
}

size_t piezo_runner_log_count(const piezo_runner *r)
{
    return r != NULL ? r->n_log : 0;
}

size_t piezo_runner_log_dropped(const piezo_runner *r)
{
    return r != NULL ? r->n_dropped : 0;
}

const char *piezo_runner_log_text(const piezo_runner *r, size_t i)
{
    return r != NULL && i < r->n_log ? r->log[i].text : "";
}

int piezo_runner_log_status(const piezo_runner *r, size_t i)
{
    return r != NULL && i < r->n_log ? r->log[i].status : -1;
}

int piezo_runner_log_role(const piezo_runner *r, size_t i)
{
    return r != NULL && i < r->n_log ? r->log[i].role : -1;
}

void piezo_runner_clear_log(piezo_runner *r)
{
    size_t i;
    if (r == NULL) return;
    for (i = 0; i < r->n_log; ++i) free(r->log[i].text);
    r->n_log = 0;
    r->n_dropped = 0;
}
