/*
 * fmi2_glue.c - the shared FMI 2.0 Co-Simulation layer, compiled into each
 * FMU together with that FMU's model.c (see fmu_model.h for the contract).
 *
 * State machine (modes are bits; a call outside its modes returns fmi2Error,
 * logs "illegal call" and changes nothing):
 *
 *   function                         Inst  Init  Step  Term  Err
 *   SetDebugLogging, Reset,            x     x     x     x    x
 *     FreeInstance, Get/SetFMUstate,
 *     FreeFMUstate, (De)Serialize*
 *   SetupExperiment,                   x     .     .     .    .
 *     EnterInitializationMode
 *   ExitInitializationMode             .     x     .     .    .
 *   Get{Real,Integer,Boolean,String}   .     x     x     x    x
 *   Set* of a parameter (fixed)        x     x     .     .    .
 *   Set* of an input                   x     x     x     .    .
 *   DoStep, Terminate                  .     .     x     .    .
 *   Get*Status                         .     .     x     x    .
 *   CancelStep, input/output derivatives, directional derivatives, all Model
 *   Exchange functions: never (fmi2Error, logged).
 *
 * Every refused call (illegal sequence, NULL pointer, unknown value reference,
 * wrong type or causality, non-finite Real, bad time or step size, parameter
 * out of range at fmi2ExitInitializationMode, bad FMU state or blob) returns
 * fmi2Error, logs why and leaves the instance exactly as it was (an
 * ExitInitializationMode refused for a bad parameter stays in
 * initialization mode: fix the parameter and call it again). The Error mode
 * is entered only when the core refuses a step the glue had validated (an
 * internal fault): the state is restored to the start of the step and only
 * getters, the FMU-state functions, Reset and FreeInstance remain.
 *
 * Identity: an instance is accepted only by the functions of the FMU binary
 * that made it (model_guid below), an FMU state only by the instance that made
 * it; states still allocated at fmi2FreeInstance are freed with it. A NULL
 * logger callback is refused at fmi2Instantiate (see there).
 *
 * Time is t0 + k h with an integer sample counter k. A communication step H
 * must be n h with n >= 0 (|H - n h| <= 1e-9 max(1, n) h); the n samples are
 * computed with the inputs held. A step that rounds to no sample (|H| below
 * 1e-9 h, as importers issue when they step to input time points that equal
 * the FMU's grid up to round-off) is a no-op returning fmi2OK. A step whose
 * end passes the stopTime of fmi2SetupExperiment is refused.
 * After a step the model may ask for a warning (logged once per kind, e.g.
 * the first clipped voltage, with a count at fmi2Terminate); fmi2DoStep then
 * returns fmi2Warning. Logging: messages go through the host's
 * logger as (..., "%s", text). Categories logEvents, logStatusWarning,
 * logStatusError, logAll. Errors and warnings are logged even with
 * loggingOn = false (only the logEvents trace is debug logging), unless
 * switched off explicitly with fmi2SetDebugLogging.
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"
#include "fmu_start_values.h"

/* ------------------------------------------------------------------------ */
/* Instance                                                                  */

#define INSTANCE_MAGIC 0x50494e53u   /* "PINS" */
#define STATE_MAGIC    0x50535441u   /* "PSTA" */

/* Which FMU an instance belongs to: the address of this binary's copy of its
 * GUID. Every FMU binary has its own copy, so one FMU's functions refuse another
 * FMU's instance (same glue, same magic) even when both are loaded in one
 * process; the check costs one comparison, no hashing per call. */
static const char model_guid[] = MODEL_GUID;

/* Most samples since t0: (double)k stays exact and t0 + k h keeps its meaning. */
#define MAX_SAMPLES 9007199254740992ull     /* 2^53 */

enum {
    MODE_INSTANTIATED = 1,
    MODE_INIT = 2,
    MODE_STEP_COMPLETE = 4,
    MODE_TERMINATED = 8,
    MODE_ERROR = 16
};
#define MODE_ALL (MODE_INSTANTIATED | MODE_INIT | MODE_STEP_COMPLETE | MODE_TERMINATED | MODE_ERROR)
#define MODE_CORE_READY (MODE_STEP_COMPLETE | MODE_TERMINATED | MODE_ERROR)

enum { CAT_EVENTS = 1, CAT_WARNING = 2, CAT_ERROR = 4, CAT_ALL = 7 };

typedef struct fmu_state fmu_state;

typedef struct {
    uint32_t magic;
    const char *model;          /* model_guid of the binary that made it */
    char *name;
    fmi2CallbackFunctions cb;
    unsigned log_mask;
    int mode;
    double t0;                  /* start time (fmi2SetupExperiment) */
    uint64_t k;                 /* samples since t0 */
    double h;                   /* sample period, fixed at ExitInitializationMode */
    int stop_time_defined;      /* fmi2SetupExperiment's stopTime applies */
    double stop_time;
    int outputs_valid;          /* the output values match data (no set/step since) */
    int outputs_read;           /* outputs were read since the last doStep */
    int warned_read_before_set; /* that warning is given once per instance */
    double *history;            /* exact-mode history, grown by doubling */
    size_t history_capacity;    /* in doubles */
    fmu_state *states;          /* FMU states not yet freed: fmi2FreeInstance frees them */
    ModelData data;
    ModelData backup;           /* data at the start of a doStep */
    fmu_start_values *start_values;  /* resources/start_values, applied at instantiation and reset */
} fmu_instance;

/* An FMU state: a copy of everything that defines the instance's future. It
 * belongs to the instance that made it (fmi2GetFMUstate, fmi2DeSerializeFMUstate)
 * and sits in that instance's list until freed. */
struct fmu_state {
    uint32_t magic;
    const fmu_instance *owner;
    fmu_state *prev, *next;     /* the owner's list */
    int mode;
    double t0;
    uint64_t k;
    double h;
    ModelData data;
    size_t n_history;
    size_t history_capacity;
    double *history;
};

/* ------------------------------------------------------------------------ */
/* Logging                                                                   */

static const char *const category_names[] = { "logEvents", "logStatusWarning", "logStatusError", "logAll" };
static const unsigned category_bits[] = { CAT_EVENTS, CAT_WARNING, CAT_ERROR, CAT_ALL };
#define N_CATEGORIES (sizeof category_bits / sizeof category_bits[0])

#if defined(__GNUC__)
#define PRINTF_LIKE(f, a) __attribute__((format(printf, f, a)))
#else
#define PRINTF_LIKE(f, a)
#endif

/* The shortest decimal text that reads back as x (h = 0.0005, not
 * 0.00050000000000000001): messages for people, still exact. */
#define REAL_TEXT_SIZE 32
static const char *real_text(char buf[REAL_TEXT_SIZE], double x)
{
    int digits;
    for (digits = 15; digits <= 17; digits++) {
        snprintf(buf, REAL_TEXT_SIZE, "%.*g", digits, x);
        if (strtod(buf, NULL) == x || x != x)
            break;
    }
    return buf;
}

static void vlog_to(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status,
                    const char *category, const char *fmt, va_list ap) PRINTF_LIKE(5, 0);
static void vlog_to(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status,
                    const char *category, const char *fmt, va_list ap)
{
    char text[1024];
    if (cb == NULL || cb->logger == NULL)
        return;
    vsnprintf(text, sizeof text, fmt, ap);
    cb->logger(cb->componentEnvironment, name != NULL ? name : "?", status, category, "%s", text);
}

static void log_to(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status,
                   const char *category, const char *fmt, ...) PRINTF_LIKE(5, 6);
static void log_to(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status,
                   const char *category, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vlog_to(cb, name, status, category, fmt, ap);
    va_end(ap);
}

static void log_error(const fmu_instance *inst, const char *fmt, ...) PRINTF_LIKE(2, 3);
static void log_error(const fmu_instance *inst, const char *fmt, ...)
{
    va_list ap;
    if (!(inst->log_mask & CAT_ERROR))
        return;
    va_start(ap, fmt);
    vlog_to(&inst->cb, inst->name, fmi2Error, "logStatusError", fmt, ap);
    va_end(ap);
}

static void log_warning(const fmu_instance *inst, const char *fmt, ...) PRINTF_LIKE(2, 3);
static void log_warning(const fmu_instance *inst, const char *fmt, ...)
{
    va_list ap;
    if (!(inst->log_mask & CAT_WARNING))
        return;
    va_start(ap, fmt);
    vlog_to(&inst->cb, inst->name, fmi2Warning, "logStatusWarning", fmt, ap);
    va_end(ap);
}

static void log_event(const fmu_instance *inst, const char *fmt, ...) PRINTF_LIKE(2, 3);
static void log_event(const fmu_instance *inst, const char *fmt, ...)
{
    va_list ap;
    if (!(inst->log_mask & CAT_EVENTS))
        return;
    va_start(ap, fmt);
    vlog_to(&inst->cb, inst->name, fmi2OK, "logEvents", fmt, ap);
    va_end(ap);
}

static const char *mode_name(int mode)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "Instantiated";
    case MODE_INIT: return "InitializationMode";
    case MODE_STEP_COMPLETE: return "StepComplete";
    case MODE_TERMINATED: return "Terminated";
    case MODE_ERROR: return "Error";
    default: return "?";
    }
}

static void mask_names(int mask, char *buf, size_t size)
{
    static const int modes[] = { MODE_INSTANTIATED, MODE_INIT, MODE_STEP_COMPLETE, MODE_TERMINATED, MODE_ERROR };
    size_t i, used = 0;
    buf[0] = '\0';
    for (i = 0; i < sizeof modes / sizeof modes[0]; i++) {
        if (mask & modes[i]) {
            int w = snprintf(buf + used, size - used, "%s%s", used ? ", " : "", mode_name(modes[i]));
            if (w < 0 || (size_t)w >= size - used)
                return;
            used += (size_t)w;
        }
    }
    if (used == 0)
        snprintf(buf, size, "none");
}

static void log_core_failure(const fmu_instance *inst, const char *fname, piezo_status st,
                             const piezo_diag *diag)
{
    char text[512];
    if (st != PIEZO_ERR_PARAM && model_failure_text(&inst->data, st, text, sizeof text)) {
        log_error(inst, "%s: %s", fname, text);
        return;
    }
    switch (st) {
    case PIEZO_ERR_PARAM:
        log_error(inst, "%s: %s = %.16g is out of range: valid range %s", fname,
                  diag->parameter != NULL ? diag->parameter : "(unknown parameter)", diag->value,
                  diag->valid_range != NULL ? diag->valid_range : "(unknown)");
        break;
    case PIEZO_ERR_NONFINITE:
        log_error(inst, "%s: the model refused a non-finite value", fname);
        break;
    case PIEZO_ERR_DIVERGED:
        log_error(inst, "%s: the model diverged: a computed value is not finite although the inputs "
                  "are (e.g. a voltage far outside the model's range, or an unstable loop)", fname);
        break;
    case PIEZO_ERR_CAPACITY:
        log_error(inst, "%s: internal error: exact-mode history buffer too small", fname);
        break;
    case PIEZO_ERR_NULL:
        log_error(inst, "%s: internal error: NULL pointer passed to the model", fname);
        break;
    case PIEZO_ERR_UNSTABLE:
        log_error(inst, "%s: the model's monitor found the loop unstable", fname);
        break;
    default:
        log_error(inst, "%s: the model failed with status %d", fname, (int)st);
        break;
    }
}

/* ------------------------------------------------------------------------ */
/* Helpers                                                                   */

/* The instance if c is one of ours and its mode is in mask, else NULL
 * (logged when possible). */
static fmu_instance *get_instance(fmi2Component c, const char *fname, int mask)
{
    fmu_instance *inst = (fmu_instance *)c;
    char allowed[128];
    if (inst == NULL || inst->magic != INSTANCE_MAGIC || inst->model != model_guid)
        return NULL;
    if (!(inst->mode & mask)) {
        mask_names(mask, allowed, sizeof allowed);
        log_error(inst, "%s: illegal call sequence: the FMU is in state %s (allowed in: %s)",
                  fname, mode_name(inst->mode), allowed);
        return NULL;
    }
    return inst;
}

static int null_arg(const fmu_instance *inst, const char *fname, const char *arg, const void *p)
{
    if (p == NULL) {
        log_error(inst, "%s: argument %s is NULL", fname, arg);
        return 1;
    }
    return 0;
}

static uint64_t fnv1a(const unsigned char *p, size_t n, uint64_t h)
{
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

#define FNV_OFFSET 0xcbf29ce484222325ull

/* Make room for `needed` doubles of history (doubling), keeping the content. */
static int ensure_history(fmu_instance *inst, size_t needed, const char *fname)
{
    size_t cap;
    double *p;
    if (needed <= inst->history_capacity)
        return 1;
    cap = inst->history_capacity > 0 ? inst->history_capacity : 4096;
    while (cap < needed) {
        if (cap > SIZE_MAX / 2 / sizeof(double)) {
            log_error(inst, "%s: exact-mode history of %llu samples is too large", fname,
                      (unsigned long long)needed);
            return 0;
        }
        cap *= 2;
    }
    p = (double *)inst->cb.allocateMemory(cap, sizeof(double));
    if (p == NULL) {
        log_error(inst, "%s: out of memory growing the exact-mode history to %llu samples", fname,
                  (unsigned long long)cap);
        return 0;
    }
    if (inst->history != NULL) {
        memcpy(p, inst->history, inst->history_capacity * sizeof(double));
        inst->cb.freeMemory(inst->history);
    }
    inst->history = p;
    inst->history_capacity = cap;
    return 1;
}

static void *value_ptr(fmu_instance *inst, fmi2ValueReference vr)
{
    return (char *)&inst->data + model_variables[vr].offset;
}

static const char *type_name(model_type t)
{
    switch (t) {
    case MODEL_REAL: return "Real";
    case MODEL_INTEGER: return "Integer";
    case MODEL_BOOLEAN: return "Boolean";
    default: return "?";
    }
}

static int check_vr(const fmu_instance *inst, const char *fname, fmi2ValueReference vr, model_type type)
{
    if (vr >= (fmi2ValueReference)MODEL_N_VARIABLES) {
        log_error(inst, "%s: unknown value reference %u", fname, (unsigned)vr);
        return 0;
    }
    if (model_variables[vr].type != type) {
        log_error(inst, "%s: variable %s (value reference %u) is of type %s, not %s", fname,
                  model_variables[vr].name, (unsigned)vr, type_name(model_variables[vr].type), type_name(type));
        return 0;
    }
    return 1;
}

/* Bring the output values up to date with the parameters, inputs and state. */
static int refresh_outputs(fmu_instance *inst, const char *fname)
{
    piezo_diag diag = { NULL, NULL, 0.0 };
    piezo_status st;
    if (inst->outputs_valid || inst->mode == MODE_ERROR)
        return 1;
    if (inst->mode == MODE_INIT) {
        /* Outputs during initialization: sample 0 of the current parameters. */
        st = model_init(&inst->data, inst->t0, &diag);
        if (st != PIEZO_OK) {
            log_core_failure(inst, fname, st, &diag);
            return 0;
        }
    }
    if (!ensure_history(inst, model_history_needed(&inst->data), fname))
        return 0;
    st = model_update_outputs(&inst->data, inst->history, inst->history_capacity);
    if (st != PIEZO_OK) {
        log_core_failure(inst, fname, st, &diag);
        return 0;
    }
    inst->outputs_valid = 1;
    return 1;
}

#define MASK_GET (MODE_INIT | MODE_STEP_COMPLETE | MODE_TERMINATED | MODE_ERROR)
#define MASK_SET (MODE_INSTANTIATED | MODE_INIT | MODE_STEP_COMPLETE)

static fmi2Status get_values(fmi2Component c, const char *fname, const fmi2ValueReference vr[],
                             size_t nvr, model_type type, void *values)
{
    fmu_instance *inst = get_instance(c, fname, MASK_GET);
    size_t i;
    int need_outputs = 0;
    if (inst == NULL)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    if (null_arg(inst, fname, "vr", vr) || null_arg(inst, fname, "value", values))
        return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (!check_vr(inst, fname, vr[i], type))
            return fmi2Error;
        if (model_variables[vr[i]].causality == MODEL_OUTPUT)
            need_outputs = 1;
    }
    if (need_outputs && !refresh_outputs(inst, fname))
        return fmi2Error;
    if (need_outputs)
        inst->outputs_read = 1;
    for (i = 0; i < nvr; i++) {
        const void *p = value_ptr(inst, vr[i]);
        if (type == MODEL_REAL)
            ((fmi2Real *)values)[i] = *(const double *)p;
        else
            ((fmi2Integer *)values)[i] = *(const int *)p;  /* fmi2Boolean is int too */
    }
    return fmi2OK;
}

static fmi2Status set_values(fmi2Component c, const char *fname, const fmi2ValueReference vr[],
                             size_t nvr, model_type type, const void *values)
{
    fmu_instance *inst = get_instance(c, fname, MASK_SET);
    size_t i;
    if (inst == NULL)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    if (null_arg(inst, fname, "vr", vr) || null_arg(inst, fname, "value", values))
        return fmi2Error;
    /* Check everything first: a refused call changes nothing. */
    for (i = 0; i < nvr; i++) {
        const model_variable *var;
        if (!check_vr(inst, fname, vr[i], type))
            return fmi2Error;
        var = &model_variables[vr[i]];
        if (var->causality == MODEL_OUTPUT) {
            log_error(inst, "%s: %s is an output: it cannot be set", fname, var->name);
            return fmi2Error;
        }
        if (var->causality == MODEL_PARAMETER && inst->mode == MODE_STEP_COMPLETE) {
            log_error(inst, "%s: illegal call sequence: %s is a fixed parameter, settable only "
                      "before fmi2ExitInitializationMode (the FMU is in state %s)",
                      fname, var->name, mode_name(inst->mode));
            return fmi2Error;
        }
        if (type == MODEL_REAL && !isfinite(((const fmi2Real *)values)[i])) {
            log_error(inst, "%s: %s = %g refused: valid range: finite values (%s keeps %.16g)",
                      fname, var->name, ((const fmi2Real *)values)[i], var->name,
                      *(const double *)value_ptr(inst, vr[i]));
            return fmi2Error;
        }
    }
    if (inst->outputs_read && inst->mode == MODE_STEP_COMPLETE && !inst->warned_read_before_set
        && model_direct_feedthrough(&inst->data)) {
        for (i = 0; i < nvr; i++) {
            const model_variable *var = &model_variables[vr[i]];
            if (var->causality == MODEL_INPUT && type == MODEL_REAL
                && *(const double *)value_ptr(inst, vr[i]) != ((const fmi2Real *)values)[i]) {
                log_warning(inst, "%s: %s changed after the outputs were read at this communication "
                            "point: the outputs depend directly on the inputs (direct feedthrough), so "
                            "the values read were computed from the previous inputs and are not what "
                            "fmi2DoStep commits. Read outputs after setting the inputs (Gauss-Seidel "
                            "ordered by ModelStructure); a Jacobi master needs the no-feedthrough "
                            "configuration. This warning is given once.", fname, var->name);
                inst->warned_read_before_set = 1;
                break;
            }
        }
    }
    for (i = 0; i < nvr; i++) {
        void *p = value_ptr(inst, vr[i]);
        if (type == MODEL_REAL)
            *(double *)p = ((const fmi2Real *)values)[i];
        else if (type == MODEL_INTEGER)
            *(int *)p = ((const fmi2Integer *)values)[i];
        else
            *(int *)p = ((const fmi2Boolean *)values)[i] != fmi2False ? 1 : 0;
    }
    inst->outputs_valid = 0;
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Inquiry, instantiation, logging control                                   */

const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    fmu_instance *inst;
    size_t len;
    (void)visible;
    /* No logger, no instance (as the Modelica Reference FMUs do): every refusal
     * is explained only through the logger, and a host that cannot hear why a
     * call failed should learn that at once, not at its first fmi2Error. */
    if (functions == NULL || functions->logger == NULL)
        return NULL;
    if (instanceName == NULL || instanceName[0] == '\0') {
        log_to(functions, instanceName, fmi2Error, "logStatusError",
               "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        log_to(functions, instanceName, fmi2Error, "logStatusError",
               "fmi2Instantiate: the callbacks allocateMemory and freeMemory are required");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        log_to(functions, instanceName, fmi2Error, "logStatusError",
               "fmi2Instantiate: %s supports Co-Simulation only (fmuType = %d)",
               MODEL_IDENTIFIER_STRING, (int)fmuType);
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MODEL_GUID) != 0) {
        log_to(functions, instanceName, fmi2Error, "logStatusError",
               "fmi2Instantiate: wrong GUID %s: this binary is %s %s",
               fmuGUID != NULL ? fmuGUID : "(NULL)", MODEL_IDENTIFIER_STRING, MODEL_GUID);
        return NULL;
    }
    inst = (fmu_instance *)functions->allocateMemory(1, sizeof(fmu_instance));
    if (inst == NULL) {
        log_to(functions, instanceName, fmi2Error, "logStatusError", "fmi2Instantiate: out of memory");
        return NULL;
    }
    memset(inst, 0, sizeof *inst);
    len = strlen(instanceName);
    inst->name = (char *)functions->allocateMemory(len + 1, 1);
    if (inst->name == NULL) {
        functions->freeMemory(inst);
        log_to(functions, instanceName, fmi2Error, "logStatusError", "fmi2Instantiate: out of memory");
        return NULL;
    }
    memcpy(inst->name, instanceName, len + 1);
    inst->magic = INSTANCE_MAGIC;
    inst->model = model_guid;
    inst->cb = *functions;
    inst->log_mask = loggingOn ? CAT_ALL : CAT_ERROR | CAT_WARNING;
    inst->mode = MODE_INSTANTIATED;
    model_set_start_values(&inst->data);
    /* resources/start_values of a parameterised FMU (harness export), over the defaults */
    if (!fmu_start_values_init(&inst->start_values, fmuResourceLocation, functions, instanceName,
                               &inst->data)) {
        fmi2FreeInstance(inst);
        return NULL;
    }
    log_event(inst, "fmi2Instantiate: %s instantiated (GUID %s)", MODEL_IDENTIFIER_STRING, MODEL_GUID);
    return inst;
}

static void state_free(fmu_instance *inst, fmu_state *st);

void fmi2FreeInstance(fmi2Component c)
{
    fmu_instance *inst = get_instance(c, "fmi2FreeInstance", MODE_ALL);
    fmi2CallbackFreeMemory free_memory;
    if (inst == NULL)
        return;
    log_event(inst, "fmi2FreeInstance");
    /* FMU states the host did not free die with their instance */
    while (inst->states != NULL)
        state_free(inst, inst->states);
    free_memory = inst->cb.freeMemory;
    if (inst->history != NULL)
        free_memory(inst->history);
    free_memory(inst->name);
    fmu_start_values_free(&inst->start_values, &inst->cb);
    inst->magic = 0;
    inst->model = NULL;
    free_memory(inst);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    fmu_instance *inst = get_instance(c, "fmi2SetDebugLogging", MODE_ALL);
    unsigned bits = 0;
    size_t i, j;
    if (inst == NULL)
        return fmi2Error;
    if (nCategories == 0) {
        inst->log_mask = loggingOn ? CAT_ALL : CAT_ERROR | CAT_WARNING;
        return fmi2OK;
    }
    if (null_arg(inst, "fmi2SetDebugLogging", "categories", categories))
        return fmi2Error;
    for (i = 0; i < nCategories; i++) {
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
            log_error(inst, "fmi2SetDebugLogging: unknown log category %s (known: logEvents, "
                      "logStatusWarning, logStatusError, logAll)",
                      categories[i] != NULL ? categories[i] : "(NULL)");
            return fmi2Error;
        }
    }
    if (loggingOn)
        inst->log_mask |= bits;
    else
        inst->log_mask &= ~bits;
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Experiment, initialization, termination                                   */

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    fmu_instance *inst = get_instance(c, "fmi2SetupExperiment", MODE_INSTANTIATED);
    (void)toleranceDefined;     /* a discrete-time model: no tolerance to honour */
    (void)tolerance;
    if (inst == NULL)
        return fmi2Error;
    if (!isfinite(startTime)) {
        log_error(inst, "fmi2SetupExperiment: startTime = %g refused: valid range: finite values", startTime);
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        log_error(inst, "fmi2SetupExperiment: stopTime = %.16g refused: valid range [startTime = %.16g, inf)",
                  stopTime, startTime);
        return fmi2Error;
    }
    inst->t0 = startTime;
    inst->stop_time_defined = stopTimeDefined ? 1 : 0;
    inst->stop_time = stopTimeDefined ? stopTime : 0.0;
    log_event(inst, "fmi2SetupExperiment: t0 = %.16g%s", startTime,
              stopTimeDefined ? " (stopTime enforced)" : "");
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    fmu_instance *inst = get_instance(c, "fmi2EnterInitializationMode", MODE_INSTANTIATED);
    if (inst == NULL)
        return fmi2Error;
    inst->mode = MODE_INIT;
    inst->outputs_valid = 0;
    log_event(inst, "fmi2EnterInitializationMode");
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    fmu_instance *inst = get_instance(c, "fmi2ExitInitializationMode", MODE_INIT);
    piezo_diag diag = { NULL, NULL, 0.0 };
    piezo_status st;
    double h;
    if (inst == NULL)
        return fmi2Error;
    st = model_init(&inst->data, inst->t0, &diag);
    if (st != PIEZO_OK) {
        log_core_failure(inst, "fmi2ExitInitializationMode", st, &diag);
        inst->outputs_valid = 0;
        return fmi2Error;       /* stays in initialization mode */
    }
    h = model_sample_period(&inst->data);
    if (!(h > 0.0) || !isfinite(h)) {
        log_error(inst, "fmi2ExitInitializationMode: h = %.16g is out of range: valid range (0, inf)", h);
        return fmi2Error;
    }
    inst->h = h;
    inst->k = 0;
    inst->mode = MODE_STEP_COMPLETE;
    inst->outputs_valid = 0;
    log_event(inst, "fmi2ExitInitializationMode: initialized, t0 = %.16g, h = %.16g", inst->t0, h);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    fmu_instance *inst = get_instance(c, "fmi2Terminate", MODE_STEP_COMPLETE);
    char text[512];
    fmi2Status status = fmi2OK;
    if (inst == NULL)
        return fmi2Error;
    inst->mode = MODE_TERMINATED;
    log_event(inst, "fmi2Terminate at t = %.16g", inst->t0 + (double)inst->k * inst->h);
    if (model_terminate_warning(&inst->data, text, sizeof text)) {
        log_warning(inst, "fmi2Terminate: %s", text);
        status = fmi2Warning;
    }
    return status;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    fmu_instance *inst = get_instance(c, "fmi2Reset", MODE_ALL);
    if (inst == NULL)
        return fmi2Error;
    memset(&inst->data, 0, sizeof inst->data);
    model_set_start_values(&inst->data);
    fmu_start_values_apply(inst->start_values, &inst->data);
    inst->mode = MODE_INSTANTIATED;
    inst->t0 = 0.0;
    inst->k = 0;
    inst->h = 0.0;
    inst->stop_time_defined = 0;
    inst->stop_time = 0.0;
    inst->outputs_valid = 0;
    inst->outputs_read = 0;
    log_event(inst, "fmi2Reset: back to Instantiated with the start values");
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Getting and setting variables                                             */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    return get_values(c, "fmi2GetReal", vr, nvr, MODEL_REAL, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    return get_values(c, "fmi2GetInteger", vr, nvr, MODEL_INTEGER, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    return get_values(c, "fmi2GetBoolean", vr, nvr, MODEL_BOOLEAN, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    fmu_instance *inst = get_instance(c, "fmi2GetString", MASK_GET);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    if (null_arg(inst, "fmi2GetString", "vr", vr))
        return fmi2Error;
    log_error(inst, "fmi2GetString: value reference %u is not a String variable (the FMU has none)", (unsigned)vr[0]);
    return fmi2Error;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    return set_values(c, "fmi2SetReal", vr, nvr, MODEL_REAL, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    return set_values(c, "fmi2SetInteger", vr, nvr, MODEL_INTEGER, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    return set_values(c, "fmi2SetBoolean", vr, nvr, MODEL_BOOLEAN, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    fmu_instance *inst = get_instance(c, "fmi2SetString", MASK_SET);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    if (null_arg(inst, "fmi2SetString", "vr", vr))
        return fmi2Error;
    log_error(inst, "fmi2SetString: value reference %u is not a String variable (the FMU has none)", (unsigned)vr[0]);
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* Stepping                                                                  */

/* Log what the model asks to say after a step; fmi2Warning if anything. */
static fmi2Status step_warnings(fmu_instance *inst, const char *fname)
{
    char text[512];
    fmi2Status status = fmi2OK;
    int i;
    for (i = 0; i < 4 && model_step_warning(&inst->data, inst->t0, text, sizeof text); i++) {
        log_warning(inst, "%s: %s", fname, text);
        status = fmi2Warning;
    }
    return status;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    static const char fname[] = "fmi2DoStep";
    fmu_instance *inst = get_instance(c, fname, MODE_STEP_COMPLETE);
    double t, tol, ratio, n_real;
    char t1[REAL_TEXT_SIZE], t2[REAL_TEXT_SIZE], t3[REAL_TEXT_SIZE];
    uint64_t n, i;
    size_t needed;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst == NULL)
        return fmi2Error;

    t = inst->t0 + (double)inst->k * inst->h;
    tol = 1e-9 * fmax(inst->h, fabs(t));
    if (tol > 1e-3 * inst->h)
        tol = 1e-3 * inst->h;
    if (!isfinite(currentCommunicationPoint) || fabs(currentCommunicationPoint - t) > tol) {
        log_error(inst, "%s: currentCommunicationPoint = %s does not match the FMU time "
                  "t0 + k h = %s (k = %llu, h = %s): step refused, state and time unchanged",
                  fname, real_text(t1, currentCommunicationPoint), real_text(t2, t),
                  (unsigned long long)inst->k, real_text(t3, inst->h));
        return fmi2Error;
    }
    if (!isfinite(communicationStepSize) || communicationStepSize < 0.0) {
        log_error(inst, "%s: communicationStepSize = %s refused: it must be a whole multiple "
                  "n >= 0 of h = %s; state and time unchanged", fname,
                  real_text(t1, communicationStepSize), real_text(t2, inst->h));
        return fmi2Error;
    }
    ratio = communicationStepSize / inst->h;
    n_real = floor(ratio + 0.5);
    if (ratio > 4.0e15) {
        log_error(inst, "%s: communicationStepSize = %s is too large: %s samples of h = %s", fname,
                  real_text(t1, communicationStepSize), real_text(t2, ratio), real_text(t3, inst->h));
        return fmi2Error;
    }
    if (fabs(communicationStepSize - n_real * inst->h) > 1e-9 * fmax(1.0, n_real) * inst->h) {
        log_error(inst, "%s: communicationStepSize = %s is not a whole multiple of h = %s "
                  "(H/h = %s; tolerance |H - n h| <= 1e-9 max(1, n) h): step refused, state and "
                  "time unchanged", fname, real_text(t1, communicationStepSize), real_text(t2, inst->h),
                  real_text(t3, ratio));
        return fmi2Error;
    }
    n = (uint64_t)n_real;
    /* the end of the step must be a time: k + n <= 2^53 and t0 + (k + n) h finite */
    if (n > MAX_SAMPLES - inst->k || !isfinite(inst->t0 + (double)(inst->k + n) * inst->h)) {
        log_error(inst, "%s: the step from t = %s over %s samples of h = %s ends beyond the FMU's time "
                  "range (at most 2^53 samples, finite t0 + k h): step refused, state and time unchanged",
                  fname, real_text(t1, t), real_text(t2, n_real), real_text(t3, inst->h));
        return fmi2Error;
    }
    if (inst->stop_time_defined) {
        double t_end = inst->t0 + (double)(inst->k + n) * inst->h;
        double tol_end = fmin(1e-9 * fmax(inst->h, fabs(inst->stop_time)), 1e-3 * inst->h);
        if (t_end > inst->stop_time + tol_end) {
            log_error(inst, "%s: the step from t = %s to t = %s passes stopTime = %s of "
                      "fmi2SetupExperiment: step refused, state and time unchanged", fname,
                      real_text(t1, t), real_text(t2, t_end), real_text(t3, inst->stop_time));
            return fmi2Error;
        }
    }
    inst->outputs_read = 0;
    if (n == 0) {
        /* |H| < 1e-9 h: the step ends on the sample it starts from */
        log_event(inst, "%s: communicationStepSize = %s holds no sample of h = %s: nothing to do",
                  fname, real_text(t1, communicationStepSize), real_text(t2, inst->h));
        return fmi2OK;
    }

    /* A refused sample changes nothing (model_step), so only a step of several
     * samples needs a copy to roll back the samples before the refused one. */
    if (n > 1)
        memcpy(&inst->backup, &inst->data, sizeof inst->data);
    for (i = 0; i < n; i++) {
        piezo_diag diag = { NULL, NULL, 0.0 };
        piezo_status st;
        /* grow the exact-mode history (by doubling) before the core needs it */
        needed = model_history_needed(&inst->data);
        if (needed > inst->history_capacity && !ensure_history(inst, needed, fname)) {
            if (i > 0)
                memcpy(&inst->data, &inst->backup, sizeof inst->data);
            return fmi2Error;
        }
        /* the first sample may reuse what the outputs were computed from */
        st = model_step(&inst->data, inst->history, inst->history_capacity,
                        i == 0 && inst->outputs_valid);
        if (st != PIEZO_OK) {
            if (i > 0)
                memcpy(&inst->data, &inst->backup, sizeof inst->data);
            log_core_failure(inst, fname, st, &diag);
            log_error(inst, "%s: the model refused sample %llu of the step from t = %s; the state "
                      "is restored to that time and the FMU enters state Error (use fmi2SetFMUstate "
                      "or fmi2Reset)", fname, (unsigned long long)(inst->k + i), real_text(t1, t));
            inst->outputs_valid = 0;
            inst->mode = MODE_ERROR;
            return fmi2Error;
        }
    }
    inst->k += n;
    inst->outputs_valid = 0;
    return step_warnings(inst, fname);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    fmu_instance *inst = get_instance(c, "fmi2CancelStep", MODE_ALL);
    if (inst == NULL)
        return fmi2Error;
    log_error(inst, "fmi2CancelStep: no step is in progress (fmi2DoStep is synchronous and never returns fmi2Pending)");
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    fmu_instance *inst = get_instance(c, "fmi2SetRealInputDerivatives", MODE_ALL);
    (void)vr; (void)nvr; (void)order; (void)value;
    if (inst == NULL)
        return fmi2Error;
    log_error(inst, "fmi2SetRealInputDerivatives: not supported (canInterpolateInputs = false: inputs are held over a step)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    fmu_instance *inst = get_instance(c, "fmi2GetRealOutputDerivatives", MODE_ALL);
    (void)vr; (void)nvr; (void)order; (void)value;
    if (inst == NULL)
        return fmi2Error;
    log_error(inst, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder = 0)");
    return fmi2Error;
}

#define MASK_STATUS (MODE_STEP_COMPLETE | MODE_TERMINATED)

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    fmu_instance *inst = get_instance(c, "fmi2GetStatus", MASK_STATUS);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    log_error(inst, "fmi2GetStatus: status kind %d not available (fmi2DoStep never returns fmi2Pending)", (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    fmu_instance *inst = get_instance(c, "fmi2GetRealStatus", MASK_STATUS);
    if (inst == NULL)
        return fmi2Error;
    if (null_arg(inst, "fmi2GetRealStatus", "value", value))
        return fmi2Error;
    if (s != fmi2LastSuccessfulTime) {
        log_error(inst, "fmi2GetRealStatus: status kind %d not available (only fmi2LastSuccessfulTime)", (int)s);
        return fmi2Error;
    }
    *value = inst->t0 + (double)inst->k * inst->h;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    fmu_instance *inst = get_instance(c, "fmi2GetIntegerStatus", MASK_STATUS);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    log_error(inst, "fmi2GetIntegerStatus: status kind %d not available", (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    fmu_instance *inst = get_instance(c, "fmi2GetBooleanStatus", MASK_STATUS);
    if (inst == NULL)
        return fmi2Error;
    if (null_arg(inst, "fmi2GetBooleanStatus", "value", value))
        return fmi2Error;
    if (s != fmi2Terminated) {
        log_error(inst, "fmi2GetBooleanStatus: status kind %d not available (only fmi2Terminated)", (int)s);
        return fmi2Error;
    }
    *value = fmi2False;     /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    fmu_instance *inst = get_instance(c, "fmi2GetStringStatus", MASK_STATUS);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    log_error(inst, "fmi2GetStringStatus: status kind %d not available", (int)s);
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

static fmu_state *checked_state(const fmu_instance *inst, const char *fname, fmi2FMUstate s)
{
    fmu_state *st = (fmu_state *)s;
    if (st == NULL) {
        log_error(inst, "%s: the FMU state is NULL", fname);
        return NULL;
    }
    if (st->magic != STATE_MAGIC || st->owner != inst) {
        log_error(inst, "%s: not an FMU state of this %s instance (a state belongs to the instance "
                  "that made it with fmi2GetFMUstate or fmi2DeSerializeFMUstate)", fname, MODEL_IDENTIFIER_STRING);
        return NULL;
    }
    return st;
}

/* A state to fill: *slot if it is one of ours, else a new one in the list. */
static fmu_state *state_slot(fmu_instance *inst, const char *fname, fmi2FMUstate *slot)
{
    fmu_state *st = (fmu_state *)*slot;
    if (st != NULL)
        return checked_state(inst, fname, st);
    st = (fmu_state *)inst->cb.allocateMemory(1, sizeof(fmu_state));
    if (st == NULL) {
        log_error(inst, "%s: out of memory", fname);
        return NULL;
    }
    memset(st, 0, sizeof *st);
    st->magic = STATE_MAGIC;
    st->owner = inst;
    st->next = inst->states;
    if (inst->states != NULL)
        inst->states->prev = st;
    inst->states = st;
    return st;
}

/* Unlink st from its owner's list and free it. */
static void state_free(fmu_instance *inst, fmu_state *st)
{
    if (st->prev != NULL)
        st->prev->next = st->next;
    else
        inst->states = st->next;
    if (st->next != NULL)
        st->next->prev = st->prev;
    if (st->history != NULL)
        inst->cb.freeMemory(st->history);
    st->magic = 0;
    st->owner = NULL;
    inst->cb.freeMemory(st);
}

static int state_reserve_history(fmu_instance *inst, const char *fname, fmu_state *st, size_t n)
{
    double *p;
    if (n <= st->history_capacity)
        return 1;
    p = (double *)inst->cb.allocateMemory(n, sizeof(double));
    if (p == NULL) {
        log_error(inst, "%s: out of memory for %llu history samples", fname, (unsigned long long)n);
        return 0;
    }
    if (st->history != NULL)
        inst->cb.freeMemory(st->history);
    st->history = p;
    st->history_capacity = n;
    return 1;
}

/* After a failure: a state made by this call goes, a reused one stays. */
static void state_release(fmu_instance *inst, fmu_state *st, int was_new)
{
    if (was_new)
        state_free(inst, st);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    static const char fname[] = "fmi2GetFMUstate";
    /* allowed in Error too (FMI 2.0): a host may keep the failed state for debugging */
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    fmu_state *st;
    size_t n_hist = 0;
    int was_new;
    if (inst == NULL || null_arg(inst, fname, "FMUstate", FMUstate))
        return fmi2Error;
    was_new = *FMUstate == NULL;
    st = state_slot(inst, fname, FMUstate);
    if (st == NULL)
        return fmi2Error;
    if (inst->mode & MODE_CORE_READY) {
        /* the whole buffer the next step needs (slots not yet written are
         * rewritten before they are read) */
        n_hist = model_history_needed(&inst->data);
        if (!ensure_history(inst, n_hist, fname)) {
            state_release(inst, st, was_new);
            return fmi2Error;
        }
    }
    if (!state_reserve_history(inst, fname, st, n_hist)) {
        state_release(inst, st, was_new);
        return fmi2Error;
    }
    st->mode = inst->mode;
    st->t0 = inst->t0;
    st->k = inst->k;
    st->h = inst->h;
    memcpy(&st->data, &inst->data, sizeof st->data);
    if (n_hist > 0)
        memcpy(st->history, inst->history, n_hist * sizeof(double));
    st->n_history = n_hist;
    *FMUstate = st;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    static const char fname[] = "fmi2SetFMUstate";
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    fmu_state *st;
    if (inst == NULL)
        return fmi2Error;
    st = checked_state(inst, fname, FMUstate);
    if (st == NULL)
        return fmi2Error;
    if (!ensure_history(inst, st->n_history, fname))
        return fmi2Error;
    if (st->n_history > 0)
        memcpy(inst->history, st->history, st->n_history * sizeof(double));
    memcpy(&inst->data, &st->data, sizeof inst->data);
    inst->mode = st->mode;
    inst->t0 = st->t0;
    inst->k = st->k;
    inst->h = st->h;
    inst->outputs_valid = 0;
    log_event(inst, "%s: restored a state in %s at t = %.16g", fname, mode_name(inst->mode),
              inst->t0 + (double)inst->k * inst->h);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    static const char fname[] = "fmi2FreeFMUstate";
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    fmu_state *st;
    if (inst == NULL || null_arg(inst, fname, "FMUstate", FMUstate))
        return fmi2Error;
    if (*FMUstate == NULL)
        return fmi2OK;
    st = checked_state(inst, fname, *FMUstate);
    if (st == NULL)
        return fmi2Error;
    state_free(inst, st);
    *FMUstate = NULL;
    return fmi2OK;
}

/*
 * Serialized FMU state (format version 1). Header integers and doubles are
 * little-endian whatever the host; the ModelData image is the host's native
 * layout, guarded by its size and a byte-order marker.
 *
 *   offset  size  field
 *        0     8  magic "PZFMUST1"
 *        8     4  format version (1)
 *       12     4  header size (128)
 *       16     8  total size of the blob, checksum included
 *       24    48  model GUID, NUL padded
 *       72     8  sizeof(ModelData)
 *       80     4  byte-order marker 0x01020304 written natively
 *       84     4  FMU mode (1 Instantiated, 2 InitializationMode, 4 StepComplete, 8 Terminated,
 *                 16 Error)
 *       88     8  t0 (IEEE double)
 *       96     8  k, samples since t0
 *      104     8  h (IEEE double)
 *      112     8  n_history, doubles of exact-mode history
 *      120     8  reserved (0)
 *      128     .  ModelData image (sizeof(ModelData) bytes)
 *        .     .  n_history doubles (IEEE, little-endian)
 *    end-8     8  FNV-1a 64 checksum of every preceding byte
 *
 * A blob is untrusted input: fmi2DeSerializeFMUstate reads nothing it has not
 * bounded (sizes compared without arithmetic that can wrap) and accepts only what
 * a live instance could have saved: the exact GUID field, a known mode, the
 * time fields of that mode (before initialization k = 0 and h = 0; after it
 * h = the model's h, k <= 2^53, t0 + k h finite), reserved = 0, finite Reals
 * and 0/1 Booleans in every variable, and the model's own invariants
 * (model_check_data: indices, counts, flags, sample counters against k and the
 * history). Anything else is refused and nothing is changed.
 */
#define BLOB_MAGIC "PZFMUST1"
#define BLOB_VERSION 1u
#define BLOB_HEADER 128u
#define BLOB_GUID_LEN 48u
#define BLOB_BOM 0x01020304u

static void put_u32(unsigned char *p, uint32_t v)
{
    int i;
    for (i = 0; i < 4; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static void put_u64(unsigned char *p, uint64_t v)
{
    int i;
    for (i = 0; i < 8; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static uint32_t get_u32(const unsigned char *p)
{
    uint32_t v = 0;
    int i;
    for (i = 3; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static uint64_t get_u64(const unsigned char *p)
{
    uint64_t v = 0;
    int i;
    for (i = 7; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static void put_f64(unsigned char *p, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    put_u64(p, v);
}

static double get_f64(const unsigned char *p)
{
    uint64_t v = get_u64(p);
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

#define BLOB_MIN_SIZE (BLOB_HEADER + sizeof(ModelData) + 8u)   /* no history */

static size_t blob_size(size_t n_history)
{
    return BLOB_MIN_SIZE + n_history * sizeof(double);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    static const char fname[] = "fmi2SerializedFMUstateSize";
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    fmu_state *st;
    if (inst == NULL || null_arg(inst, fname, "size", size))
        return fmi2Error;
    st = checked_state(inst, fname, FMUstate);
    if (st == NULL)
        return fmi2Error;
    *size = blob_size(st->n_history);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    static const char fname[] = "fmi2SerializeFMUstate";
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    fmu_state *st;
    unsigned char *b = (unsigned char *)serializedState;
    uint32_t bom = BLOB_BOM;
    size_t total, i, off;
    if (inst == NULL || null_arg(inst, fname, "serializedState", serializedState))
        return fmi2Error;
    st = checked_state(inst, fname, FMUstate);
    if (st == NULL)
        return fmi2Error;
    total = blob_size(st->n_history);
    if (size < total) {
        log_error(inst, "%s: buffer of %llu bytes is too small: the state needs %llu (fmi2SerializedFMUstateSize)",
                  fname, (unsigned long long)size, (unsigned long long)total);
        return fmi2Error;
    }
    memset(b, 0, total);
    memcpy(b, BLOB_MAGIC, 8);
    put_u32(b + 8, BLOB_VERSION);
    put_u32(b + 12, BLOB_HEADER);
    put_u64(b + 16, (uint64_t)total);
    memcpy(b + 24, MODEL_GUID, strlen(MODEL_GUID) < BLOB_GUID_LEN ? strlen(MODEL_GUID) : BLOB_GUID_LEN - 1);
    put_u64(b + 72, (uint64_t)sizeof(ModelData));
    memcpy(b + 80, &bom, 4);
    put_u32(b + 84, (uint32_t)st->mode);
    put_f64(b + 88, st->t0);
    put_u64(b + 96, st->k);
    put_f64(b + 104, st->h);
    put_u64(b + 112, (uint64_t)st->n_history);
    memcpy(b + BLOB_HEADER, &st->data, sizeof(ModelData));
    off = BLOB_HEADER + sizeof(ModelData);
    for (i = 0; i < st->n_history; i++, off += 8)
        put_f64(b + off, st->history[i]);
    put_u64(b + off, fnv1a(b, off, FNV_OFFSET));
    return fmi2OK;
}

/* The first variable whose value a live instance could not hold (a non-finite
 * Real, a Boolean other than 0 or 1), or -1. Outputs count only once the core
 * is initialized (before that they are recomputed when read). */
static int invalid_variable(const ModelData *data, int core_ready)
{
    int vr;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++) {
        const model_variable *var = &model_variables[vr];
        const char *p = (const char *)data + var->offset;
        if (var->causality == MODEL_OUTPUT && !core_ready)
            continue;
        if (var->type == MODEL_REAL && !isfinite(*(const double *)p))
            return vr;
        if (var->type == MODEL_BOOLEAN && *(const int *)p != 0 && *(const int *)p != 1)
            return vr;
    }
    return -1;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    static const char fname[] = "fmi2DeSerializeFMUstate";
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    const unsigned char *b = (const unsigned char *)serializedState;
    char guid[BLOB_GUID_LEN], expected_guid[BLOB_GUID_LEN];
    char t1[REAL_TEXT_SIZE], t2[REAL_TEXT_SIZE];
    uint32_t bom = BLOB_BOM;
    uint64_t total, n_hist64, k;
    size_t n_hist, i, off;
    int mode, core_ready, bad_vr;
    double t0, h, *history = NULL;
    const char *fault;
    fmu_state *st;
    ModelData *data;

    if (inst == NULL || null_arg(inst, fname, "serializedState", serializedState)
        || null_arg(inst, fname, "FMUstate", FMUstate))
        return fmi2Error;
    if (size < BLOB_HEADER + 8u || memcmp(b, BLOB_MAGIC, 8) != 0) {
        log_error(inst, "%s: refused: not a serialized %s state (bad magic or %llu bytes only)",
                  fname, MODEL_IDENTIFIER_STRING, (unsigned long long)size);
        return fmi2Error;
    }
    if (get_u32(b + 8) != BLOB_VERSION || get_u32(b + 12) != BLOB_HEADER) {
        log_error(inst, "%s: refused: format version %u (header %u bytes) is not the supported version %u",
                  fname, (unsigned)get_u32(b + 8), (unsigned)get_u32(b + 12), (unsigned)BLOB_VERSION);
        return fmi2Error;
    }
    total = get_u64(b + 16);
    if (total != (uint64_t)size) {
        log_error(inst, "%s: refused: the blob says %llu bytes but %llu were given (truncated or padded)",
                  fname, (unsigned long long)total, (unsigned long long)size);
        return fmi2Error;
    }
    /* the whole field, padding included: serialization writes exactly this */
    memset(expected_guid, 0, sizeof expected_guid);
    memcpy(expected_guid, MODEL_GUID, strlen(MODEL_GUID) < BLOB_GUID_LEN ? strlen(MODEL_GUID) : BLOB_GUID_LEN - 1);
    if (memcmp(b + 24, expected_guid, BLOB_GUID_LEN) != 0) {
        memcpy(guid, b + 24, BLOB_GUID_LEN);
        guid[BLOB_GUID_LEN - 1] = '\0';
        for (i = 0; guid[i] != '\0'; i++)
            if ((unsigned char)guid[i] < 0x20 || (unsigned char)guid[i] > 0x7e)
                guid[i] = '?';
        log_error(inst, "%s: refused: the state belongs to GUID %s, not %s %s",
                  fname, guid, MODEL_IDENTIFIER_STRING, MODEL_GUID);
        return fmi2Error;
    }
    if (get_u64(b + 72) != (uint64_t)sizeof(ModelData) || memcmp(b + 80, &bom, 4) != 0) {
        log_error(inst, "%s: refused: model data layout differs (size %llu vs %llu, or byte order): "
                  "the state comes from another build or platform",
                  fname, (unsigned long long)get_u64(b + 72), (unsigned long long)sizeof(ModelData));
        return fmi2Error;
    }
    /* total = BLOB_MIN_SIZE + 8 n_history, compared without arithmetic that can wrap */
    n_hist64 = get_u64(b + 112);
    if (total < (uint64_t)BLOB_MIN_SIZE || (total - BLOB_MIN_SIZE) % 8u != 0
        || (total - BLOB_MIN_SIZE) / 8u != n_hist64) {
        log_error(inst, "%s: refused: history length %llu does not match the blob size %llu",
                  fname, (unsigned long long)n_hist64, (unsigned long long)total);
        return fmi2Error;
    }
    n_hist = (size_t)n_hist64;  /* < size, so it fits */
    off = (size_t)total - 8u;
    if (fnv1a(b, off, FNV_OFFSET) != get_u64(b + off)) {
        log_error(inst, "%s: refused: checksum mismatch (the blob is corrupted)", fname);
        return fmi2Error;
    }
    if (get_u64(b + 120) != 0) {
        log_error(inst, "%s: refused: reserved header field is %llu, not 0", fname,
                  (unsigned long long)get_u64(b + 120));
        return fmi2Error;
    }
    mode = (int)get_u32(b + 84);
    t0 = get_f64(b + 88);
    k = get_u64(b + 96);
    h = get_f64(b + 104);
    if (mode != MODE_INSTANTIATED && mode != MODE_INIT && mode != MODE_STEP_COMPLETE
        && mode != MODE_TERMINATED && mode != MODE_ERROR) {
        log_error(inst, "%s: refused: invalid FMU mode %d", fname, mode);
        return fmi2Error;
    }
    core_ready = (mode & MODE_CORE_READY) != 0;
    data = &inst->backup;   /* the instance's scratch copy (used by fmi2DoStep only) */
    memcpy(data, b + BLOB_HEADER, sizeof *data);
    /* time: before initialization nothing has run (k = 0, h not yet fixed);
     * after it h is the model's, and t0 + k h is a time on the grid */
    if (!isfinite(t0)
        || (!core_ready && (k != 0 || h != 0.0))
        || (core_ready && !(h > 0.0 && h == model_sample_period(data) && k <= MAX_SAMPLES
                            && isfinite(t0 + (double)k * h)))) {
        log_error(inst, "%s: refused: invalid time fields for state %s: t0 = %s, k = %llu, h = %s",
                  fname, mode_name(mode), real_text(t1, t0), (unsigned long long)k, real_text(t2, h));
        return fmi2Error;
    }
    bad_vr = invalid_variable(data, core_ready);
    if (bad_vr >= 0) {
        log_error(inst, "%s: refused: variable %s holds a value no instance can have (%s)", fname,
                  model_variables[bad_vr].name,
                  model_variables[bad_vr].type == MODEL_REAL ? "not finite" : "Boolean other than 0 or 1");
        return fmi2Error;
    }
    if (core_ready ? n_hist != model_history_needed(data) : n_hist != 0) {
        log_error(inst, "%s: refused: %llu history samples stored, the model needs %llu", fname,
                  (unsigned long long)n_hist, (unsigned long long)(core_ready ? model_history_needed(data) : 0));
        return fmi2Error;
    }
    if (n_hist > 0) {
        history = (double *)inst->cb.allocateMemory(n_hist, sizeof(double));
        if (history == NULL) {
            log_error(inst, "%s: out of memory for %llu history samples", fname, (unsigned long long)n_hist);
            return fmi2Error;
        }
        off = BLOB_HEADER + sizeof(ModelData);
        for (i = 0; i < n_hist; i++, off += 8)
            history[i] = get_f64(b + off);
    }
    fault = model_check_data(data, core_ready, t0, k, history, n_hist);
    if (fault != NULL) {
        log_error(inst, "%s: refused: invalid model data (%s)", fname, fault);
        if (history != NULL)
            inst->cb.freeMemory(history);
        return fmi2Error;
    }

    st = state_slot(inst, fname, FMUstate);
    if (st == NULL) {
        if (history != NULL)
            inst->cb.freeMemory(history);
        return fmi2Error;
    }
    if (st->history != NULL)
        inst->cb.freeMemory(st->history);
    st->history = history;
    st->history_capacity = n_hist;
    st->n_history = n_hist;
    st->mode = mode;
    st->t0 = t0;
    st->k = k;
    st->h = h;
    memcpy(&st->data, data, sizeof *data);
    *FMUstate = st;
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Not supported: directional derivatives and Model Exchange                 */

static fmi2Status unsupported(fmi2Component c, const char *fname, const char *why)
{
    fmu_instance *inst = get_instance(c, fname, MODE_ALL);
    if (inst != NULL)
        log_error(inst, "%s: not supported: %s", fname, why);
    return fmi2Error;
}

#define ME_ONLY "Model Exchange function; this FMU is Co-Simulation only"

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return unsupported(c, "fmi2GetDirectionalDerivative", "providesDirectionalDerivative = false");
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    return unsupported(c, "fmi2EnterEventMode", ME_ONLY);
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *fmi2eventInfo)
{
    (void)fmi2eventInfo;
    return unsupported(c, "fmi2NewDiscreteStates", ME_ONLY);
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    return unsupported(c, "fmi2EnterContinuousTimeMode", ME_ONLY);
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return unsupported(c, "fmi2CompletedIntegratorStep", ME_ONLY);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    (void)time;
    return unsupported(c, "fmi2SetTime", ME_ONLY);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    (void)x; (void)nx;
    return unsupported(c, "fmi2SetContinuousStates", ME_ONLY);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    (void)derivatives; (void)nx;
    return unsupported(c, "fmi2GetDerivatives", ME_ONLY);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    (void)eventIndicators; (void)ni;
    return unsupported(c, "fmi2GetEventIndicators", ME_ONLY);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    (void)x; (void)nx;
    return unsupported(c, "fmi2GetContinuousStates", ME_ONLY);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    (void)x_nominal; (void)nx;
    return unsupported(c, "fmi2GetNominalsOfContinuousStates", ME_ONLY);
}
