/*
 * fmu_glue_core.c - the FMI layer without the FMI version (see fmu_glue_core.h
 * for what lives here, fmi2_glue.c for the modes and calls and the time grid,
 * fmu_glue_state.c for FMU states and fmu_state_format.h for their serialized form).
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_glue_core.h"

/* ------------------------------------------------------------------------ */
/* Instance                                                                  */

#define INSTANCE_MAGIC 0x50494e53u   /* "PINS" */

/* Which FMU an instance belongs to: the address of this binary's copy of its
 * GUID. Every FMU binary has its own copy, so one FMU's functions refuse another
 * FMU's instance (same glue, same magic) even when both are loaded in one
 * process; the check costs one comparison, no hashing per call. */
static const char model_guid[] = MODEL_GUID;

/*
 * The work one doStep may do. A host must never wait long in one call, so a
 * step that would take more than about a second is refused before any work,
 * naming the bound (docs/fmus.md, "Behaviour any importer can rely on", has the
 * figures: build/tests/fmu_bound_bench times the longest step each FMU accepts).
 * A sample costs 80-400 ns (the three FMUs, the inputs held, on the shared
 * development machine); with creep.exact the sample at k also sums k + 1 terms
 * of the creep, 0.3-0.5 ns each. A step of one sample always passes.
 */
#define MAX_STEP_SAMPLES 2000000ull             /* 1000 s at h = 0.5 ms */
#define MAX_STEP_CREEP_TERMS 1000000000ull      /* from t0: 44720 samples, 22 s at h = 0.5 ms */

enum { CAT_EVENTS = 1, CAT_WARNING = 2, CAT_ERROR = 4, CAT_ALL = 7 };

/* ------------------------------------------------------------------------ */
/* Logging                                                                   */

static const char *const category_names[] = { "logEvents", "logStatusWarning", "logStatusError", "logAll" };
static const unsigned category_bits[] = { CAT_EVENTS, CAT_WARNING, CAT_ERROR, CAT_ALL };
#define N_CATEGORIES (sizeof category_bits / sizeof category_bits[0])

const char *glue_real_text(char buf[GLUE_REAL_TEXT_SIZE], double x)
{
    int digits;
    for (digits = 15; digits <= 17; digits++) {
        snprintf(buf, GLUE_REAL_TEXT_SIZE, "%.*g", digits, x);
        if (strtod(buf, NULL) == x || x != x)
            break;
    }
    return buf;
}

static void vlog_to(const glue_host *host, const char *name, glue_status status, const char *category,
                    const char *fmt, va_list ap) GLUE_PRINTF(5, 0);
static void vlog_to(const glue_host *host, const char *name, glue_status status, const char *category,
                    const char *fmt, va_list ap)
{
    char text[2048];
    if (host == NULL || host->logger == NULL || host->deliver == NULL)
        return;
    vsnprintf(text, sizeof text, fmt, ap);
    host->deliver(host, name != NULL ? name : "?", status, category, text);
}

void glue_host_log(const glue_host *host, const char *instance_name, glue_status status, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vlog_to(host, instance_name, status,
            status == GLUE_ERROR ? "logStatusError" : status == GLUE_WARNING ? "logStatusWarning" : "logEvents",
            fmt, ap);
    va_end(ap);
}

void glue_log_error(const glue_instance *inst, const char *fmt, ...)
{
    va_list ap;
    if (!(inst->log_mask & CAT_ERROR))
        return;
    va_start(ap, fmt);
    vlog_to(&inst->host, inst->name, GLUE_ERROR, "logStatusError", fmt, ap);
    va_end(ap);
}

void glue_log_warning(const glue_instance *inst, const char *fmt, ...)
{
    va_list ap;
    if (!(inst->log_mask & CAT_WARNING))
        return;
    va_start(ap, fmt);
    vlog_to(&inst->host, inst->name, GLUE_WARNING, "logStatusWarning", fmt, ap);
    va_end(ap);
}

void glue_log_event(const glue_instance *inst, const char *fmt, ...)
{
    va_list ap;
    if (!(inst->log_mask & CAT_EVENTS))
        return;
    va_start(ap, fmt);
    vlog_to(&inst->host, inst->name, GLUE_OK, "logEvents", fmt, ap);
    va_end(ap);
}

const char *glue_mode_name(const glue_instance *inst, int mode)
{
    switch (mode) {
    case GLUE_MODE_INSTANTIATED: return inst->version->mode_names[0];
    case GLUE_MODE_INIT: return inst->version->mode_names[1];
    case GLUE_MODE_STEP: return inst->version->mode_names[2];
    case GLUE_MODE_TERMINATED: return inst->version->mode_names[3];
    case GLUE_MODE_ERROR: return inst->version->mode_names[4];
    default: return "?";
    }
}

static void mask_names(const glue_instance *inst, int mask, char *buf, size_t size)
{
    static const int modes[] = { GLUE_MODE_INSTANTIATED, GLUE_MODE_INIT, GLUE_MODE_STEP,
                                 GLUE_MODE_TERMINATED, GLUE_MODE_ERROR };
    size_t i, used = 0;
    buf[0] = '\0';
    for (i = 0; i < sizeof modes / sizeof modes[0]; i++) {
        if (mask & modes[i]) {
            int w = snprintf(buf + used, size - used, "%s%s", used ? ", " : "", glue_mode_name(inst, modes[i]));
            if (w < 0 || (size_t)w >= size - used)
                return;
            used += (size_t)w;
        }
    }
    if (used == 0)
        snprintf(buf, size, "none");
}

static GLUE_NOINLINE void log_core_failure(const glue_instance *inst, const char *fname, piezo_status st,
                                           const piezo_diag *diag)
{
    char text[1984];    /* the log line holds 2048 with the function's name */
    if (st != PIEZO_ERR_PARAM && model_failure_text(&inst->data, st, text, sizeof text)) {
        glue_log_error(inst, "%s: %s", fname, text);
        return;
    }
    switch (st) {
    case PIEZO_ERR_PARAM:
        glue_log_error(inst, "%s: %s = %.16g is out of range: valid range %s", fname,
                       diag->parameter != NULL ? diag->parameter : "(unknown parameter)", diag->value,
                       diag->valid_range != NULL ? diag->valid_range : "(unknown)");
        break;
    case PIEZO_ERR_NONFINITE:
        glue_log_error(inst, "%s: the model refused a non-finite value", fname);
        break;
    case PIEZO_ERR_DIVERGED:
        glue_log_error(inst, "%s: the model diverged: a computed value is not finite although the inputs "
                       "are (e.g. a voltage far outside the model's range, or an unstable loop)", fname);
        break;
    case PIEZO_ERR_CAPACITY:
        glue_log_error(inst, "%s: internal error: exact-mode history buffer too small", fname);
        break;
    case PIEZO_ERR_NULL:
        glue_log_error(inst, "%s: internal error: NULL pointer passed to the model", fname);
        break;
    case PIEZO_ERR_UNSTABLE:
        glue_log_error(inst, "%s: the model's monitor found the loop unstable", fname);
        break;
    case PIEZO_ERR_FAULT:
        glue_log_error(inst, "%s: the model's supervision found a loop that cannot work", fname);
        break;
    default:
        glue_log_error(inst, "%s: the model failed with status %d", fname, (int)st);
        break;
    }
}

/* ------------------------------------------------------------------------ */
/* Helpers                                                                   */

/* The refusal of a call outside its modes, apart from glue_instance_of so
 * that the check itself stays small enough to be inlined into every call. */
static GLUE_NOINLINE void log_illegal_sequence(const glue_instance *inst, const char *fname, int mask)
{
    char allowed[128];
    mask_names(inst, mask, allowed, sizeof allowed);
    glue_log_error(inst, "%s: illegal call sequence: the FMU is in state %s (allowed in: %s)",
                   fname, glue_mode_name(inst, inst->mode), allowed);
}

glue_instance *glue_instance_of(void *c, const char *fname, int mask)
{
    glue_instance *inst = (glue_instance *)c;
    if (inst == NULL || inst->magic != INSTANCE_MAGIC || inst->model != model_guid)
        return NULL;
    if (!(inst->mode & mask)) {
        log_illegal_sequence(inst, fname, mask);
        return NULL;
    }
    return inst;
}

int glue_null_arg(const glue_instance *inst, const char *fname, const char *arg, const void *p)
{
    if (p == NULL) {
        glue_log_error(inst, "%s: argument %s is NULL", fname, arg);
        return 1;
    }
    return 0;
}

/* Make room for `needed` doubles of history (doubling), keeping the content. */
int glue_ensure_history(glue_instance *inst, size_t needed, const char *fname)
{
    size_t cap;
    double *p;
    if (needed <= inst->history_capacity)
        return 1;
    cap = inst->history_capacity > 0 ? inst->history_capacity : 4096;
    while (cap < needed) {
        if (cap > SIZE_MAX / 2 / sizeof(double)) {
            glue_log_error(inst, "%s: exact-mode history of %llu samples is too large", fname,
                           (unsigned long long)needed);
            return 0;
        }
        cap *= 2;
    }
    p = (double *)inst->host.alloc(cap, sizeof(double));
    if (p == NULL) {
        glue_log_error(inst, "%s: out of memory growing the exact-mode history to %llu samples", fname,
                       (unsigned long long)cap);
        return 0;
    }
    if (inst->history != NULL) {
        memcpy(p, inst->history, inst->history_capacity * sizeof(double));
        inst->host.release(inst->history);
    }
    inst->history = p;
    inst->history_capacity = cap;
    return 1;
}

static void *value_ptr(glue_instance *inst, uint32_t index)
{
    return (char *)&inst->data + model_variables[index].offset;
}

/* Every model declares its sample period as the parameter "h" (a Real): read where its entry
 * of the generated variable table says it lies. */
double model_sample_period(const ModelData *data)
{
    return *(const double *)((const char *)data + model_variables[vr_h].offset);
}

/* The name of the variable at value reference vr: an array's without "[1]". */
static const char *variable_name(const glue_instance *inst, uint32_t vr, char *buf, size_t size)
{
    const char *name = model_variables[vr].name, *bracket = strchr(name, '[');
    if (inst->n_values[vr] <= 1 || bracket == NULL || (size_t)(bracket - name) >= size)
        return name;
    memcpy(buf, name, (size_t)(bracket - name));
    buf[bracket - name] = '\0';
    return buf;
}

/* The independent variable time (FMI 3.0): read only, the FMU's t0 + k h. */
static int is_time(const glue_instance *inst, uint32_t vr)
{
    return vr == GLUE_VR_TIME && inst->version->time_variable;
}

/* The values behind a checked value reference (past the table: time). */
static size_t values_of(const glue_instance *inst, uint32_t vr)
{
    return vr < (uint32_t)MODEL_N_VARIABLES ? inst->n_values[vr] : 1u;
}

static int check_vr(const glue_instance *inst, const char *fname, uint32_t vr, model_type type)
{
    const char *const *names = inst->version->type_names;
    char buf[64];
    if (is_time(inst, vr)) {
        if (type != MODEL_REAL) {
            glue_log_error(inst, "%s: variable time (value reference %u) is of type %s, not %s", fname,
                           (unsigned)vr, names[MODEL_REAL], names[type]);
            return 0;
        }
        return 1;
    }
    if (vr >= (uint32_t)MODEL_N_VARIABLES || inst->n_values[vr] == 0) {
        glue_log_error(inst, "%s: unknown value reference %u", fname, (unsigned)vr);
        return 0;
    }
    if (model_variables[vr].type != type) {
        glue_log_error(inst, "%s: variable %s (value reference %u) is of type %s, not %s", fname,
                       variable_name(inst, vr, buf, sizeof buf), (unsigned)vr, names[model_variables[vr].type],
                       names[type]);
        return 0;
    }
    return 1;
}

/* Bring the output values up to date with the parameters, inputs and state. */
static int refresh_outputs(glue_instance *inst, const char *fname)
{
    piezo_diag diag = { NULL, NULL, 0.0 };
    piezo_status st;
    if (inst->outputs_valid || inst->mode == GLUE_MODE_ERROR)
        return 1;
    if (inst->mode == GLUE_MODE_INIT) {
        /* Outputs during initialization: sample 0 of the current parameters. */
        st = model_init(&inst->data, inst->t0, &diag);
        if (st != PIEZO_OK) {
            log_core_failure(inst, fname, st, &diag);
            return 0;
        }
    }
    if (!glue_ensure_history(inst, model_history_needed(&inst->data), fname))
        return 0;
    st = model_update_outputs(&inst->data, inst->history, inst->history_capacity);
    if (st != PIEZO_OK) {
        log_core_failure(inst, fname, st, &diag);
        return 0;
    }
    inst->outputs_valid = 1;
    return 1;
}

static model_type kind_type(glue_values kind)
{
    switch (kind) {
    case GLUE_VALUES_DOUBLE: return MODEL_REAL;
    case GLUE_VALUES_INT:
    case GLUE_VALUES_INT32: return MODEL_INTEGER;
    default: return MODEL_BOOLEAN;
    }
}

/* A get/set without value references: nothing to do, and no value either
 * (FMI 3.0: nValues is the number of values the references hold, here 0;
 * FMI 2.0 passes nvr, so it always agrees). 0 when refused. */
static int no_references_no_values(const glue_instance *inst, const char *fname, size_t n_values)
{
    if (n_values != 0) {
        glue_log_error(inst, "%s: nValues = %llu, but no value reference is given (nValueReferences = 0): "
                       "nValues must be the number of values the references hold, here 0", fname,
                       (unsigned long long)n_values);
        return 0;
    }
    return 1;
}

/*
 * The hot path of a master's exchange: 1 when every vr[i] is a scalar variable
 * of the model of the given type (not time, not an array), which
 * check_references then accepts with nValues = nvr; *any_output says whether
 * one is an output. Only a yes/no: anything else (and every error with its
 * message) takes the checks of check_references.
 */
static int scalars_of_type(const glue_instance *inst, const uint32_t vr[], size_t nvr, model_type type,
                           int *any_output)
{
    size_t i;
    unsigned seen = 0;
    for (i = 0; i < nvr; i++) {
        uint32_t r = vr[i];
        if (r >= (uint32_t)MODEL_N_VARIABLES || !(inst->scalar[r] & GLUE_SCALAR_OF(type)))
            return 0;
        seen |= inst->scalar[r];
    }
    *any_output = (seen & GLUE_SCALAR_OUTPUT) != 0;
    return 1;
}

/* The hot path of a master's set: 1 when every vr[i] is a scalar Real input
 * and every v[i] finite, which the checks of glue_set's full path accept. */
static int finite_real_inputs(const glue_instance *inst, const uint32_t vr[], size_t nvr, const double v[])
{
    const unsigned want = GLUE_SCALAR_OF(MODEL_REAL) | GLUE_SCALAR_INPUT;
    size_t i;
    for (i = 0; i < nvr; i++) {
        uint32_t r = vr[i];
        if (r >= (uint32_t)MODEL_N_VARIABLES || (inst->scalar[r] & want) != want || !isfinite(v[i]))
            return 0;
    }
    return 1;
}

/* Check the references of a get/set and count their values; 0 when refused. */
static int check_references(const glue_instance *inst, const char *fname, const uint32_t vr[], size_t nvr,
                            model_type type, size_t n_values, int *any_output)
{
    size_t i, total = 0;
    *any_output = 0;
    for (i = 0; i < nvr; i++) {
        if (!check_vr(inst, fname, vr[i], type))
            return 0;
        total += values_of(inst, vr[i]);
        if (!is_time(inst, vr[i]) && model_variables[vr[i]].causality == MODEL_OUTPUT)
            *any_output = 1;
    }
    if (total != n_values) {
        glue_log_error(inst, "%s: nValues = %llu, but the %llu value references given hold %llu values",
                       fname, (unsigned long long)n_values, (unsigned long long)nvr,
                       (unsigned long long)total);
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------------ */
/* Instantiation, logging control                                            */

/* Which value references a version has (see glue_instance.n_values). */
static void map_scalars(glue_instance *inst);

static void map_variables(glue_instance *inst)
{
    size_t i, j;
    memset(inst->n_values, 1, sizeof inst->n_values);
    if (!inst->version->arrays) {
        map_scalars(inst);
        return;
    }
    /* a run name[1], name[2], ..., name[n] of one type and causality is one array */
    for (i = 0; i < (size_t)MODEL_N_VARIABLES; i++) {
        const char *first = model_variables[i].name, *bracket = strchr(first, '[');
        size_t base;
        if (bracket == NULL || strcmp(bracket, "[1]") != 0)
            continue;
        base = (size_t)(bracket - first);
        for (j = i + 1; j < (size_t)MODEL_N_VARIABLES && j - i < 255; j++) {
            const char *name = model_variables[j].name;
            char *end;
            if (strncmp(name, first, base) != 0 || name[base] != '['
                || strtoul(name + base + 1, &end, 10) != j - i + 1 || strcmp(end, "]") != 0
                || model_variables[j].type != model_variables[i].type
                || model_variables[j].causality != model_variables[i].causality)
                break;
        }
        if (j - i >= 2) {
            inst->n_values[i] = (unsigned char)(j - i);
            memset(inst->n_values + i + 1, 0, j - i - 1);
            i = j - 1;
        }
    }
    map_scalars(inst);
}

/* glue_instance.scalar from n_values and the model's table. */
static void map_scalars(glue_instance *inst)
{
    size_t i;
    for (i = 0; i < (size_t)MODEL_N_VARIABLES; i++) {
        const model_variable *var = &model_variables[i];
        inst->scalar[i] = 0;
        if (inst->n_values[i] != 1)
            continue;
        inst->scalar[i] = (unsigned char)(GLUE_SCALAR_OF(var->type)
                                          | (var->causality == MODEL_INPUT ? GLUE_SCALAR_INPUT : 0u)
                                          | (var->causality == MODEL_OUTPUT ? GLUE_SCALAR_OUTPUT : 0u));
    }
}

glue_instance *glue_instantiate(const glue_host *host, const glue_version *version, const char *fname,
                                const char *name, const char *resource_location, int location_is_uri,
                                const char *location_arg, int logging_on)
{
    glue_instance *inst;
    size_t len;
    inst = (glue_instance *)host->alloc(1, sizeof(glue_instance));
    if (inst == NULL) {
        glue_host_log(host, name, GLUE_ERROR, "%s: out of memory", fname);
        return NULL;
    }
    memset(inst, 0, sizeof *inst);
    len = strlen(name);
    inst->name = (char *)host->alloc(len + 1, 1);
    if (inst->name == NULL) {
        host->release(inst);
        glue_host_log(host, name, GLUE_ERROR, "%s: out of memory", fname);
        return NULL;
    }
    memcpy(inst->name, name, len + 1);
    inst->magic = INSTANCE_MAGIC;
    inst->model = model_guid;
    inst->version = version;
    inst->host = *host;
    inst->log_mask = logging_on ? CAT_ALL : CAT_ERROR | CAT_WARNING;
    inst->mode = GLUE_MODE_INSTANTIATED;
    map_variables(inst);
    model_set_start_values(&inst->data);
    /* resources/start_values of a parameterised FMU (harness export), over the defaults */
    if (!fmu_start_values_init(&inst->start_values, resource_location, location_is_uri, fname,
                               location_arg, host, name, &inst->data)) {
        glue_free_instance(inst, fname);
        return NULL;
    }
    glue_log_event(inst, "%s: %s instantiated (%s %s)", fname, MODEL_IDENTIFIER_STRING,
                   version->token_name, MODEL_GUID);
    return inst;
}


void glue_free_instance(void *c, const char *fname)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    void (*release)(void *);
    if (inst == NULL)
        return;
    glue_log_event(inst, "%s", fname);
    /* FMU states the host did not free die with their instance */
    while (inst->states != NULL)
        glue_state_free(inst, inst->states);
    release = inst->host.release;
    if (inst->history != NULL)
        release(inst->history);
    release(inst->name);
    fmu_start_values_free(&inst->start_values, &inst->host);
    inst->magic = 0;
    inst->model = NULL;
    release(inst);
}

glue_status glue_set_debug_logging(void *c, const char *fname, int logging_on, size_t n_categories,
                                   const char *const categories[])
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    unsigned bits = 0;
    size_t i, j;
    if (inst == NULL)
        return GLUE_ERROR;
    if (n_categories == 0) {
        inst->log_mask = logging_on ? CAT_ALL : CAT_ERROR | CAT_WARNING;
        return GLUE_OK;
    }
    if (glue_null_arg(inst, fname, "categories", categories))
        return GLUE_ERROR;
    for (i = 0; i < n_categories; i++) {
        int found = 0;
        if (categories[i] != NULL) {
            for (j = 0; j < N_CATEGORIES; j++) {
                if (strcmp(categories[i], category_names[j]) == 0) {
                    bits |= category_bits[j];
                    found = 1;
                }
            }
        }
        if (!found) {
            glue_log_error(inst, "%s: unknown log category %s (known: logEvents, "
                           "logStatusWarning, logStatusError, logAll)", fname,
                           categories[i] != NULL ? categories[i] : "(NULL)");
            return GLUE_ERROR;
        }
    }
    if (logging_on)
        inst->log_mask |= bits;
    else
        inst->log_mask &= ~bits;
    return GLUE_OK;
}

/* ------------------------------------------------------------------------ */
/* Experiment, initialization, termination                                   */

glue_status glue_setup(void *c, const char *fname, double start_time, int stop_time_defined,
                       double stop_time, int enter_init)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_INSTANTIATED);
    if (inst == NULL)
        return GLUE_ERROR;
    if (!isfinite(start_time)) {
        glue_log_error(inst, "%s: startTime = %g refused: valid range: finite values", fname, start_time);
        return GLUE_ERROR;
    }
    if (stop_time_defined && !(stop_time >= start_time)) {
        glue_log_error(inst, "%s: stopTime = %.16g refused: valid range [startTime = %.16g, inf)",
                       fname, stop_time, start_time);
        return GLUE_ERROR;
    }
    inst->t0 = start_time;
    inst->stop_time_defined = stop_time_defined ? 1 : 0;
    inst->stop_time = stop_time_defined ? stop_time : 0.0;
    if (enter_init) {
        inst->mode = GLUE_MODE_INIT;
        inst->outputs_valid = 0;
    }
    glue_log_event(inst, "%s: t0 = %.16g%s", fname, start_time,
                   stop_time_defined ? " (stopTime enforced)" : "");
    return GLUE_OK;
}

glue_status glue_enter_init(void *c, const char *fname)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_INSTANTIATED);
    if (inst == NULL)
        return GLUE_ERROR;
    inst->mode = GLUE_MODE_INIT;
    inst->outputs_valid = 0;
    glue_log_event(inst, "%s", fname);
    return GLUE_OK;
}

glue_status glue_exit_init(void *c, const char *fname)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_INIT);
    piezo_diag diag = { NULL, NULL, 0.0 };
    piezo_status st;
    double h;
    if (inst == NULL)
        return GLUE_ERROR;
    st = model_init(&inst->data, inst->t0, &diag);
    if (st != PIEZO_OK) {
        log_core_failure(inst, fname, st, &diag);
        inst->outputs_valid = 0;
        return GLUE_ERROR;      /* stays in initialization mode */
    }
    h = model_sample_period(&inst->data);
    if (!(h > 0.0) || !isfinite(h)) {
        glue_log_error(inst, "%s: h = %.16g is out of range: valid range (0, inf)", fname, h);
        return GLUE_ERROR;
    }
    inst->h = h;
    inst->k = 0;
    inst->t_off = 0.0;
    inst->mode = GLUE_MODE_STEP;
    inst->outputs_valid = 0;
    glue_log_event(inst, "%s: initialized, t0 = %.16g, h = %.16g", fname, inst->t0, h);
    return GLUE_OK;
}

glue_status glue_terminate(void *c, const char *fname)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_STEP);
    char text[512];
    glue_status status = GLUE_OK;
    if (inst == NULL)
        return GLUE_ERROR;
    inst->mode = GLUE_MODE_TERMINATED;
    glue_log_event(inst, "%s at t = %.16g", fname, glue_time(inst));
    if (model_terminate_warning(&inst->data, text, sizeof text)) {
        glue_log_warning(inst, "%s: %s", fname, text);
        status = GLUE_WARNING;
    }
    return status;
}

glue_status glue_reset(void *c, const char *fname)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    if (inst == NULL)
        return GLUE_ERROR;
    memset(&inst->data, 0, sizeof inst->data);
    model_set_start_values(&inst->data);
    fmu_start_values_apply(inst->start_values, &inst->data);
    inst->mode = GLUE_MODE_INSTANTIATED;
    inst->t0 = 0.0;
    inst->k = 0;
    inst->h = 0.0;
    inst->t_off = 0.0;
    inst->stop_time_defined = 0;
    inst->stop_time = 0.0;
    inst->outputs_valid = 0;
    inst->outputs_read = 0;
    glue_log_event(inst, "%s: back to %s with the start values", fname, glue_mode_name(inst, GLUE_MODE_INSTANTIATED));
    return GLUE_OK;
}

/* ------------------------------------------------------------------------ */
/* Getting and setting variables                                             */

/* One value of a get, in the layout of kind, from the variable at p. */
static void get_value(glue_values kind, void *values, size_t j, const void *p)
{
    switch (kind) {
    case GLUE_VALUES_DOUBLE: ((double *)values)[j] = *(const double *)p; break;
    case GLUE_VALUES_INT: ((int *)values)[j] = *(const int *)p; break;
    case GLUE_VALUES_INT32: ((int32_t *)values)[j] = (int32_t)*(const int *)p; break;
    case GLUE_VALUES_BOOL_INT: ((int *)values)[j] = *(const int *)p; break;     /* 0 or 1 */
    case GLUE_VALUES_BOOL_BYTE: ((unsigned char *)values)[j] = *(const int *)p != 0; break;
    }
}

/* glue_get after the instance check, for everything but scalars of the
 * getter's type: the checks with their messages, arrays, time. */
static GLUE_NOINLINE glue_status get_checked(glue_instance *inst, const char *fname, const uint32_t vr[],
                                             size_t nvr, glue_values kind, void *values, size_t n_values)
{
    size_t i, j, e;
    int need_outputs;
    if (nvr == 0)
        return no_references_no_values(inst, fname, n_values) ? GLUE_OK : GLUE_ERROR;
    if (glue_null_arg(inst, fname, "vr", vr) || glue_null_arg(inst, fname, "value", values))
        return GLUE_ERROR;
    if (!check_references(inst, fname, vr, nvr, kind_type(kind), n_values, &need_outputs))
        return GLUE_ERROR;
    if (need_outputs && !refresh_outputs(inst, fname))
        return GLUE_ERROR;
    if (need_outputs)
        inst->outputs_read = 1;
    for (i = 0, j = 0; i < nvr; i++) {
        if (is_time(inst, vr[i])) {
            ((double *)values)[j++] = glue_time(inst);
            continue;
        }
        for (e = 0; e < inst->n_values[vr[i]]; e++, j++)
            get_value(kind, values, j, value_ptr(inst, vr[i] + (uint32_t)e));
    }
    return GLUE_OK;
}

/* The master's exchange: scalar variables of the getter's type (vr non-empty,
 * nValues = nvr), which check_references accepts without a message; the rest
 * of get_checked, without its bookkeeping. Anything else takes get_checked. */
glue_status glue_get(void *c, const char *fname, const uint32_t vr[], size_t nvr, glue_values kind,
                     void *values, size_t n_values)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MASK_GET);
    size_t i;
    int need_outputs;
    if (inst == NULL)
        return GLUE_ERROR;
    if (nvr == 0 || nvr != n_values || vr == NULL || values == NULL
        || !scalars_of_type(inst, vr, nvr, kind_type(kind), &need_outputs))
        return get_checked(inst, fname, vr, nvr, kind, values, n_values);
    if (need_outputs) {
        if (!refresh_outputs(inst, fname))
            return GLUE_ERROR;
        inst->outputs_read = 1;
    }
    if (kind == GLUE_VALUES_DOUBLE) {
        /* one double each: get_value's copy without its switch */
        for (i = 0; i < nvr; i++)
            ((double *)values)[i] = *(const double *)value_ptr(inst, vr[i]);
        return GLUE_OK;
    }
    for (i = 0; i < nvr; i++)
        get_value(kind, values, i, value_ptr(inst, vr[i]));
    return GLUE_OK;
}

/* glue_set after the instance check: every case with its checks and messages. */
static GLUE_NOINLINE glue_status set_checked(glue_instance *inst, const char *fname, const uint32_t vr[],
                                             size_t nvr, glue_values kind, const void *values, size_t n_values)
{
    size_t i, j, e;
    int any_output;
    if (nvr == 0)
        return no_references_no_values(inst, fname, n_values) ? GLUE_OK : GLUE_ERROR;
    if (glue_null_arg(inst, fname, "vr", vr) || glue_null_arg(inst, fname, "value", values))
        return GLUE_ERROR;
    /* Check everything first: a refused call changes nothing. */
    for (i = 0, j = 0; i < nvr; i++) {
        const model_variable *var;
        if (!check_vr(inst, fname, vr[i], kind_type(kind)))
            return GLUE_ERROR;
        if (is_time(inst, vr[i])) {
            glue_log_error(inst, "%s: time is the independent variable: it cannot be set", fname);
            return GLUE_ERROR;
        }
        var = &model_variables[vr[i]];
        if (var->causality == MODEL_OUTPUT) {
            glue_log_error(inst, "%s: %s is an output: it cannot be set", fname, var->name);
            return GLUE_ERROR;
        }
        if (var->causality == MODEL_PARAMETER && inst->mode == GLUE_MODE_STEP) {
            glue_log_error(inst, "%s: illegal call sequence: %s is a fixed parameter, settable only "
                           "before %s (the FMU is in state %s)",
                           fname, var->name, inst->version->exit_init, glue_mode_name(inst, inst->mode));
            return GLUE_ERROR;
        }
        for (e = 0; e < inst->n_values[vr[i]]; e++, j++) {
            if (j < n_values && kind == GLUE_VALUES_DOUBLE && !isfinite(((const double *)values)[j])) {
                const model_variable *elem = &model_variables[vr[i] + e];
                glue_log_error(inst, "%s: %s = %g refused: valid range: finite values (%s keeps %.16g)",
                               fname, elem->name, ((const double *)values)[j], elem->name,
                               *(const double *)value_ptr(inst, vr[i] + (uint32_t)e));
                return GLUE_ERROR;
            }
        }
    }
    if (!check_references(inst, fname, vr, nvr, kind_type(kind), n_values, &any_output))
        return GLUE_ERROR;
    if (inst->outputs_read && inst->mode == GLUE_MODE_STEP && !inst->warned_read_before_set
        && kind == GLUE_VALUES_DOUBLE && model_direct_feedthrough(&inst->data)) {
        for (i = 0, j = 0; i < nvr; i++) {
            for (e = 0; e < inst->n_values[vr[i]]; e++, j++) {
                const model_variable *var = &model_variables[vr[i] + e];
                if (var->causality == MODEL_INPUT
                    && *(const double *)value_ptr(inst, vr[i] + (uint32_t)e) != ((const double *)values)[j]) {
                    glue_log_warning(inst, "%s: %s changed after the outputs were read at this communication "
                                     "point: the outputs depend directly on the inputs (direct feedthrough), so "
                                     "the values read were computed from the previous inputs and are not what "
                                     "%s commits. Read outputs after setting the inputs (Gauss-Seidel "
                                     "ordered by ModelStructure); a Jacobi master needs the no-feedthrough "
                                     "configuration. This warning is given once.", fname, var->name,
                                     inst->version->do_step);
                    inst->warned_read_before_set = 1;
                    break;
                }
            }
            if (inst->warned_read_before_set)
                break;
        }
    }
    for (i = 0, j = 0; i < nvr; i++) {
        for (e = 0; e < inst->n_values[vr[i]]; e++, j++) {
            void *p = value_ptr(inst, vr[i] + (uint32_t)e);
            switch (kind) {
            case GLUE_VALUES_DOUBLE: *(double *)p = ((const double *)values)[j]; break;
            case GLUE_VALUES_INT: *(int *)p = ((const int *)values)[j]; break;
            case GLUE_VALUES_INT32: *(int *)p = (int)((const int32_t *)values)[j]; break;
            case GLUE_VALUES_BOOL_INT: *(int *)p = ((const int *)values)[j] != 0 ? 1 : 0; break;
            case GLUE_VALUES_BOOL_BYTE: *(int *)p = ((const unsigned char *)values)[j] != 0 ? 1 : 0; break;
            }
        }
    }
    inst->outputs_valid = 0;
    return GLUE_OK;
}

/* The master's exchange: finite values for scalar Real inputs (vr non-empty,
 * nValues = nvr), with no feedthrough warning due. Every check of set_checked
 * passes and the values are stored as there; anything else takes set_checked. */
glue_status glue_set(void *c, const char *fname, const uint32_t vr[], size_t nvr, glue_values kind,
                     const void *values, size_t n_values)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MASK_SET);
    size_t i;
    if (inst == NULL)
        return GLUE_ERROR;
    if (kind != GLUE_VALUES_DOUBLE || nvr == 0 || nvr != n_values || vr == NULL || values == NULL
        || (inst->outputs_read && inst->mode == GLUE_MODE_STEP && !inst->warned_read_before_set
            && model_direct_feedthrough(&inst->data))
        || !finite_real_inputs(inst, vr, nvr, (const double *)values))
        return set_checked(inst, fname, vr, nvr, kind, values, n_values);
    for (i = 0; i < nvr; i++)
        *(double *)value_ptr(inst, vr[i]) = ((const double *)values)[i];
    inst->outputs_valid = 0;
    return GLUE_OK;
}

glue_status glue_no_such_type(void *c, const char *fname, int mask, const uint32_t vr[], size_t nvr,
                              const void *values, size_t n_values, const char *type_name)
{
    glue_instance *inst = glue_instance_of(c, fname, mask);
    const char *const *names;
    char buf[64];
    if (inst == NULL)
        return GLUE_ERROR;
    if (nvr == 0)
        return no_references_no_values(inst, fname, n_values) ? GLUE_OK : GLUE_ERROR;
    if (glue_null_arg(inst, fname, "vr", vr) || glue_null_arg(inst, fname, "value", values))
        return GLUE_ERROR;
    names = inst->version->type_names;
    if (is_time(inst, vr[0]))
        glue_log_error(inst, "%s: variable time (value reference %u) is of type %s, not %s (the FMU has "
                       "no %s variable)", fname, (unsigned)vr[0], names[MODEL_REAL], type_name, type_name);
    else if (vr[0] >= (uint32_t)MODEL_N_VARIABLES || inst->n_values[vr[0]] == 0)
        glue_log_error(inst, "%s: unknown value reference %u", fname, (unsigned)vr[0]);
    else
        glue_log_error(inst, "%s: variable %s (value reference %u) is of type %s, not %s (the FMU has "
                       "no %s variable)", fname, variable_name(inst, vr[0], buf, sizeof buf),
                       (unsigned)vr[0], names[model_variables[vr[0]].type], type_name, type_name);
    return GLUE_ERROR;
}

/* ------------------------------------------------------------------------ */
/* Stepping                                                                  */

double glue_time(const glue_instance *inst)
{
#if MODEL_ANY_STEP
    return fmu_sample_time(inst->t0, inst->k, inst->h) + inst->t_off;
#else
    return fmu_sample_time(inst->t0, inst->k, inst->h);
#endif
}

/* fmax(a, b) inline (a libm call on baseline x86-64): the larger, or the other
 * argument when one is NaN */
static double max_of(double a, double b)
{
    return a > b || b != b ? a : b;
}

/* How far a time x may be from a time of the FMU's grid and still count as
 * it: min(1e-9 max(h, |x|), 1e-3 h) (a communication point against t, the end
 * of a step against stopTime). */
static double time_tolerance(double h, double x)
{
    double tol = 1e-9 * max_of(h, fabs(x));
    return tol > 1e-3 * h ? 1e-3 * h : tol;
}

/* Log what the model asks to say after a step; a warning if it warned (a notice is
 * logged as a Warning but leaves the status OK: fmu_model.h). */
static glue_status step_warnings(glue_instance *inst, const char *fname)
{
    char text[1984];    /* the safe state's warning holds a verdict's message */
    glue_status status = GLUE_OK;
    int i;
    for (i = 0; i < 4 && model_step_event(&inst->data, text, sizeof text); i++)
        glue_log_event(inst, "%s: %s", fname, text);
    for (i = 0; i < 4 && model_step_notice(&inst->data, text, sizeof text); i++)
        glue_log_warning(inst, "%s: %s", fname, text);      /* the step's status stays OK */
    for (i = 0; i < 4 && model_step_warning(&inst->data, inst->t0, text, sizeof text); i++) {
        glue_log_warning(inst, "%s: %s", fname, text);
        status = GLUE_WARNING;
    }
    return status;
}

/* Terms of the exact creep sum over n samples whose first sums a:
 * a + (a + 1) + ... + (a + n - 1) = n a + n (n - 1) / 2 (exact in doubles up
 * to 2^53, far above the bound, so comparisons with the bound are exact). */
static double creep_terms(double n, double a)
{
    return n * a + n * (n - 1.0) / 2.0;
}

/* The longest step (>= 1 sample: one always passes) whose creep sums stay
 * within MAX_STEP_CREEP_TERMS when its first sample sums a terms: the root of
 * n^2/2 + (a - 1/2) n = B, then corrected to the exact integer. */
static uint64_t longest_creep_step(double a)
{
    const double b = (double)MAX_STEP_CREEP_TERMS;
    double n = floor(sqrt((a - 0.5) * (a - 0.5) + 2.0 * b) - (a - 0.5));
    while (n > 1.0 && creep_terms(n, a) > b)
        n -= 1.0;
    while (creep_terms(n + 1.0, a) <= b)
        n += 1.0;
    return n < 1.0 ? 1u : (uint64_t)n;
}

#if MODEL_ANY_STEP
/* Where a step of H from the FMU's time t = t_k + t_off ends: *n samples on (the instants
 * t_(k+1) .. t_(k+n) it passes) and *off past the last of them. An end within the time
 * tolerance of an instant is on it (off = 0), so a master that steps by whole samples
 * stays on the grid; 0 when the step is too long to count (the caller refuses it). */
static int step_end(const glue_instance *inst, double t, double H, double *n, double *off)
{
    double h = inst->h, span = inst->t_off + H, ratio = span / h, m = floor(ratio + 0.5);
    if (!(m <= (double)MAX_STEP_SAMPLES))
        return 0;
    *n = m;
    *off = 0.0;
    if (fabs(span - m * h) <= time_tolerance(h, t + H))
        return 1;
    m = floor(ratio);
    *off = span - m * h;
    if (!(*off > 0.0 && *off < h)) {     /* round-off at the edge of the tolerance: on the grid */
        *off = 0.0;
        m = floor(ratio + 0.5);
    }
    *n = m;
    return 1;
}
#endif

static glue_status do_step(glue_instance *inst, const char *fname, double currentCommunicationPoint,
                           double communicationStepSize)
{
    double t, ratio, n_real, t_end, off_end = 0.0;
    char t1[GLUE_REAL_TEXT_SIZE], t2[GLUE_REAL_TEXT_SIZE], t3[GLUE_REAL_TEXT_SIZE], t4[GLUE_REAL_TEXT_SIZE];
    uint64_t n, i;
    size_t needed;

    t = glue_time(inst);
    /* |currentCommunicationPoint - t| <= time_tolerance; the usual step starts exactly at
     * t, a finite time (as every time of the FMU's), which needs no tolerance */
    if (currentCommunicationPoint != t) {
        if (!isfinite(currentCommunicationPoint)
            || fabs(currentCommunicationPoint - t) > time_tolerance(inst->h, t)) {
            glue_log_error(inst, "%s: currentCommunicationPoint = %s does not match the FMU time "
                           "%s = %s (k = %llu, h = %s): step refused, state and time unchanged",
                           fname, glue_real_text(t1, currentCommunicationPoint),
                           MODEL_ANY_STEP && inst->t_off != 0.0 ? "t0 + k h + (the part of a sample the last step "
                           "ended in)" : "t0 + k h", glue_real_text(t2, t),
                           (unsigned long long)inst->k, glue_real_text(t3, inst->h));
            return GLUE_ERROR;
        }
    }
    if (communicationStepSize == inst->h && (!MODEL_ANY_STEP || inst->t_off == 0.0)) {
        /* one sample, the usual step: H = 1 h (h > 0 and finite) passes the checks below exactly */
        n_real = 1.0;
    } else {
        if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
            glue_log_error(inst, "%s: communicationStepSize = %s refused: the step size must be > 0%s%s%s; "
                           "state and time unchanged", fname, glue_real_text(t1, communicationStepSize),
                           MODEL_ANY_STEP ? " and finite (of any size: the samples of h = "
                           : ", a whole multiple n >= 1 of h = ", glue_real_text(t2, inst->h),
                           MODEL_ANY_STEP ? " whose instants the step passes are computed)"
                           : " (a positive step below 1e-9 h rounds to no sample and is a no-op)");
            return GLUE_ERROR;
        }
        ratio = communicationStepSize / inst->h;
#if MODEL_ANY_STEP
        if (!step_end(inst, t, communicationStepSize, &n_real, &off_end))
            n_real = floor(ratio + 0.5);      /* refused just below, naming the bound */
#else
        n_real = ratio == 1.0 ? 1.0 : floor(ratio + 0.5);
#endif
        if (!(n_real <= (double)MAX_STEP_SAMPLES)) {
            glue_log_error(inst, "%s: communicationStepSize = %s is %s samples of h = %s: refused, one doStep "
                           "computes at most %llu samples (about a second of work: a host must not wait longer "
                           "in one call); step at most %s s at a time; state and time unchanged", fname,
                           glue_real_text(t1, communicationStepSize), glue_real_text(t2, ratio),
                           glue_real_text(t3, inst->h), (unsigned long long)MAX_STEP_SAMPLES,
                           glue_real_text(t4, (double)MAX_STEP_SAMPLES * inst->h));
            return GLUE_ERROR;
        }
        if (!MODEL_ANY_STEP
            && fabs(communicationStepSize - n_real * inst->h) > 1e-9 * max_of(1.0, n_real) * inst->h) {
            glue_log_error(inst, "%s: communicationStepSize = %s is not a whole multiple of h = %s "
                           "(H/h = %s; tolerance |H - n h| <= 1e-9 max(1, n) h): step refused, state and "
                           "time unchanged", fname, glue_real_text(t1, communicationStepSize),
                           glue_real_text(t2, inst->h), glue_real_text(t3, ratio));
            return GLUE_ERROR;
        }
    }
    n = (uint64_t)n_real;
    /* the end of the step must be a time: k + n <= 2^53 and t0 + (k + n) h finite
     * (k + n does not wrap: k <= 2^53, n <= MAX_STEP_SAMPLES) */
    t_end = fmu_sample_time(inst->t0, inst->k + n, inst->h) + off_end;
    if (n > MAX_SAMPLES - inst->k || !isfinite(t_end)) {
        glue_log_error(inst, "%s: the step from t = %s over %s samples of h = %s ends beyond the FMU's time "
                       "range (at most 2^53 samples, finite t0 + k h): step refused, state and time unchanged",
                       fname, glue_real_text(t1, t), glue_real_text(t2, n_real), glue_real_text(t3, inst->h));
        return GLUE_ERROR;
    }
    if (inst->stop_time_defined && t_end > inst->stop_time + time_tolerance(inst->h, inst->stop_time)) {
        glue_log_error(inst, "%s: the step from t = %s to t = %s passes stopTime = %s of "
                       "%s: step refused, state and time unchanged", fname,
                       glue_real_text(t1, t), glue_real_text(t2, t_end), glue_real_text(t3, inst->stop_time),
                       inst->version->stop_time_source);
        return GLUE_ERROR;
    }
    if (n > 0) {
        char why[512];
        if (model_check_step(&inst->data, n, why, sizeof why)) {
            glue_log_error(inst, "%s: communicationStepSize = %s is %llu samples of h = %s: refused: %s; "
                           "state and time unchanged", fname, glue_real_text(t1, communicationStepSize),
                           (unsigned long long)n, glue_real_text(t2, inst->h), why);
            return GLUE_ERROR;
        }
    }
    if (n == 0) {
        inst->outputs_read = 0;
#if MODEL_ANY_STEP
        /* the step ends before the next sample: the outputs are held; a step from t_k
         * passes the instant of sample k, whose inputs are those held now */
        if (inst->t_off == 0.0 && off_end > 0.0)
            model_latch_inputs(&inst->data);
        inst->t_off = off_end;
        glue_log_event(inst, "%s: the step from t = %s to t = %s ends before the next sample (h = %s): "
                       "the outputs are held", fname, glue_real_text(t1, t), glue_real_text(t2, t_end),
                       glue_real_text(t3, inst->h));
#else
        /* 0 < H < 1e-9 h: the step ends on the sample it starts from */
        glue_log_event(inst, "%s: communicationStepSize = %s holds no sample of h = %s: nothing to do",
                       fname, glue_real_text(t1, communicationStepSize), glue_real_text(t2, inst->h));
#endif
        return GLUE_OK;
    }
    /* exact creep: the sample at k sums its k + 1 past values (the history holds
     * two doubles a sample), so the work grows with the time since t0 */
    needed = n > 1 ? model_history_needed(&inst->data) : 0;
    if (needed > 0 && creep_terms((double)n, (double)(needed / 2)) > (double)MAX_STEP_CREEP_TERMS) {
        uint64_t longest = longest_creep_step((double)(needed / 2));
        glue_log_error(inst, "%s: the step from t = %s over %llu samples would sum %s terms of the exact creep "
                       "(creep.exact = true: the sample at k sums its k + 1 past values), but one doStep sums at "
                       "most %llu (about a second of work): refused; from t = %s a step of at most %llu samples "
                       "(%s s) passes; state and time unchanged", fname, glue_real_text(t1, t),
                       (unsigned long long)n, glue_real_text(t2, creep_terms((double)n, (double)(needed / 2))),
                       (unsigned long long)MAX_STEP_CREEP_TERMS, glue_real_text(t3, t),
                       (unsigned long long)longest, glue_real_text(t4, (double)longest * inst->h));
        return GLUE_ERROR;
    }
    inst->outputs_read = 0;

    /* A refused sample changes nothing (model_step), so only a step of several
     * samples needs a copy to roll back the samples before the refused one. */
    if (n > 1)
        memcpy(&inst->backup, &inst->data, sizeof inst->data);
    for (i = 0; i < n; i++) {
        piezo_diag diag = { NULL, NULL, 0.0 };
        piezo_status st;
        /* grow the exact-mode history (by doubling) before the core needs it */
        needed = model_history_needed(&inst->data);
        if (needed > inst->history_capacity && !glue_ensure_history(inst, needed, fname)) {
            if (i > 0)
                memcpy(&inst->data, &inst->backup, sizeof inst->data);
            return GLUE_ERROR;
        }
        /* the first sample may reuse what the outputs were computed from */
        st = model_step(&inst->data, inst->history, inst->history_capacity,
                        i == 0 && inst->outputs_valid);
        if (st != PIEZO_OK) {
            /* said before the roll back: the model explains from the refused sample's data */
            log_core_failure(inst, fname, st, &diag);
            if (i > 0)
                memcpy(&inst->data, &inst->backup, sizeof inst->data);
            glue_log_error(inst, "%s: the model refused sample %llu of the step from t = %s; the state "
                           "is restored to that time and the FMU enters state Error (use %s "
                           "or %s)", fname, (unsigned long long)(inst->k + i), glue_real_text(t1, t),
                           inst->version->set_fmu_state, inst->version->reset);
            inst->outputs_valid = 0;
            inst->mode = GLUE_MODE_ERROR;
            return GLUE_ERROR;
        }
    }
    inst->k += n;
#if MODEL_ANY_STEP
    /* ends between two samples: the instant of the next sample lies in this step */
    if (off_end > 0.0)
        model_latch_inputs(&inst->data);
    inst->t_off = off_end;
#endif
    inst->outputs_valid = 0;
    return step_warnings(inst, fname);
}

glue_status glue_do_step(void *c, const char *fname, double t, double H, double *t_end)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_STEP);
    glue_status status;
    if (inst == NULL)
        return GLUE_ERROR;
    status = do_step(inst, fname, t, H);
    if (t_end != NULL)
        *t_end = glue_time(inst);
    return status;
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

glue_status glue_unsupported(void *c, const char *fname, const char *why)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    if (inst != NULL)
        glue_log_error(inst, "%s: not supported: %s", fname, why);
    return GLUE_ERROR;
}

glue_status glue_refuse(void *c, const char *fname, int mask, const char *fmt, ...)
{
    glue_instance *inst = glue_instance_of(c, fname, mask);
    char text[512];
    va_list ap;
    if (inst == NULL)
        return GLUE_ERROR;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    glue_log_error(inst, "%s: %s", fname, text);
    return GLUE_ERROR;
}
