/*
 * fmu_host.h - what the C test hosts in tests/c/ share: load an FMU binary
 * with dlopen (every fmi2 function by name, RTLD_LOCAL so several FMUs live in
 * one process), read its variables from its modelDescription.xml, count the
 * host's allocations, capture the FMU's log messages per instance, and print
 * one "ok"/"FAIL" line per check. Header-only: each host is one .c file.
 *
 * The hosts take their FMUs as pairs of arguments: MODEL_DESCRIPTION.xml
 * BINARY.so (the unzipped FMU's files, or the build's).
 */
#ifndef FMU_HOST_H
#define FMU_HOST_H

#define _DEFAULT_SOURCE 1  /* glibc: POSIX 2008 plus MAP_ANONYMOUS */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

/* ------------------------------------------------------------------------ */
/* checks                                                                    */

static atomic_int host_passed, host_failed;
static int host_verbose = 1;    /* 0: print failures only */

static inline int check(int condition, const char *fmt, ...)
{
    va_list ap;
    if (condition)
        atomic_fetch_add(&host_passed, 1);
    else
        atomic_fetch_add(&host_failed, 1);
    if (!condition || host_verbose) {
        printf(condition ? "ok   " : "FAIL ");
        va_start(ap, fmt);
        vprintf(fmt, ap);
        va_end(ap);
        printf("\n");
    }
    return condition;
}

/* The last line every host prints: "N passed, M failed"; exit code 1 on failure. */
static inline int host_summary(void)
{
    printf("%d passed, %d failed\n", atomic_load(&host_passed), atomic_load(&host_failed));
    fflush(stdout);
    return atomic_load(&host_failed) ? 1 : 0;
}

/* ------------------------------------------------------------------------ */
/* callbacks: counted allocations, messages per instance                     */

static atomic_long host_live_blocks;    /* blocks allocated through the callbacks and not freed */

static inline void *host_calloc(size_t n, size_t size)
{
    void *p = calloc(n, size);
    if (p != NULL)
        atomic_fetch_add(&host_live_blocks, 1);
    return p;
}

static inline void host_free(void *p)
{
    if (p != NULL)
        atomic_fetch_sub(&host_live_blocks, 1);
    free(p);
}

/* What an instance said; passed as componentEnvironment. */
typedef struct {
    int n_messages;
    int n_errors;
    char last[1024];            /* the last message */
    char last_error[1024];      /* the last fmi2Error message */
    char errors[4096];          /* every fmi2Error message since the last clear, "; "-joined, truncated */
} host_log;

static inline void host_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                        fmi2String category, fmi2String message, ...)
{
    host_log *log = (host_log *)env;
    char text[1024];
    va_list ap;
    (void)instance;
    (void)category;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    if (log == NULL)
        return;
    log->n_messages++;
    memcpy(log->last, text, sizeof text);
    if (status >= fmi2Error) {
        size_t used = strlen(log->errors);
        log->n_errors++;
        memcpy(log->last_error, text, sizeof text);
        snprintf(log->errors + used, sizeof log->errors - used, "%s%s", used ? "; " : "", text);
    }
}

static inline void host_log_clear(host_log *log)
{
    memset(log, 0, sizeof *log);
}

static inline fmi2CallbackFunctions host_callbacks(host_log *log)
{
    fmi2CallbackFunctions cb;
    memset(&cb, 0, sizeof cb);
    cb.logger = host_logger;
    cb.allocateMemory = host_calloc;
    cb.freeMemory = host_free;
    cb.componentEnvironment = log;
    return cb;
}

/* ------------------------------------------------------------------------ */
/* the FMI 2.0 API of one binary                                             */

#define FMI2_API(X) \
    X(GetTypesPlatform) X(GetVersion) X(SetDebugLogging) X(Instantiate) X(FreeInstance) \
    X(SetupExperiment) X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset) \
    X(GetReal) X(GetInteger) X(GetBoolean) X(GetString) X(SetReal) X(SetInteger) X(SetBoolean) \
    X(SetString) X(GetFMUstate) X(SetFMUstate) X(FreeFMUstate) X(SerializedFMUstateSize) \
    X(SerializeFMUstate) X(DeSerializeFMUstate) X(GetDirectionalDerivative) \
    X(EnterEventMode) X(NewDiscreteStates) X(EnterContinuousTimeMode) X(CompletedIntegratorStep) \
    X(SetTime) X(SetContinuousStates) X(GetDerivatives) X(GetEventIndicators) \
    X(GetContinuousStates) X(GetNominalsOfContinuousStates) \
    X(SetRealInputDerivatives) X(GetRealOutputDerivatives) X(DoStep) X(CancelStep) X(GetStatus) \
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus)

typedef struct {
#define FIELD(name) fmi2##name##TYPE *name;
    FMI2_API(FIELD)
#undef FIELD
} fmi2_api;

enum { VAR_REAL = 0, VAR_INTEGER = 1, VAR_BOOLEAN = 2 };
enum { VAR_PARAMETER = 0, VAR_INPUT = 1, VAR_OUTPUT = 2 };

typedef struct {
    char name[64];
    fmi2ValueReference vr;
    int type;                   /* VAR_REAL, VAR_INTEGER, VAR_BOOLEAN */
    int causality;              /* VAR_PARAMETER, VAR_INPUT, VAR_OUTPUT */
    double start;               /* parameters and inputs */
    int has_min, has_max;       /* the declared range, where the model description has one */
    double min, max;
} host_var;

#define HOST_MAX_VARS 128

typedef struct {
    char id[64];                /* modelIdentifier */
    char guid[64];
    double h;                   /* DefaultExperiment stepSize */
    void *lib;
    fmi2_api api;
    host_var vars[HOST_MAX_VARS];
    int n_vars;
} host_fmu;

/* The value of attribute `name` inside [p, end), copied into out; 0 if absent. */
static inline int xml_attribute(const char *p, const char *end, const char *name, char *out, size_t size)
{
    char key[80];
    const char *a, *q;
    snprintf(key, sizeof key, " %s=\"", name);
    a = strstr(p, key);
    if (a == NULL || a >= end)
        return 0;
    a += strlen(key);
    q = strchr(a, '"');
    if (q == NULL || q >= end || (size_t)(q - a) >= size)
        return 0;
    memcpy(out, a, (size_t)(q - a));
    out[q - a] = '\0';
    return 1;
}

static inline char *read_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    char *text;
    long n;
    if (f == NULL)
        return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    text = (char *)malloc((size_t)n + 1);
    if (text != NULL && fread(text, 1, (size_t)n, f) != (size_t)n) {
        free(text);
        text = NULL;
    }
    if (text != NULL)
        text[n] = '\0';
    fclose(f);
    return text;
}

/* Our model descriptions are regular: one <ScalarVariable ...> element per
 * variable with name, valueReference, causality, then its type element. */
static inline int host_read_model_description(host_fmu *f, const char *xml_path)
{
    char *xml = read_file(xml_path), value[128];
    const char *p, *end;
    if (xml == NULL) {
        printf("FAIL cannot read %s\n", xml_path);
        return 0;
    }
    end = xml + strlen(xml);
    if (!xml_attribute(xml, end, "guid", f->guid, sizeof f->guid)
        || !xml_attribute(xml, end, "modelIdentifier", f->id, sizeof f->id)
        || !xml_attribute(xml, end, "stepSize", value, sizeof value)) {
        printf("FAIL %s: guid, modelIdentifier or stepSize missing\n", xml_path);
        free(xml);
        return 0;
    }
    f->h = atof(value);
    f->n_vars = 0;
    for (p = strstr(xml, "<ScalarVariable "); p != NULL; p = strstr(p + 1, "<ScalarVariable ")) {
        const char *close = strstr(p, "</ScalarVariable>");
        host_var *v = &f->vars[f->n_vars];
        if (close == NULL || f->n_vars >= HOST_MAX_VARS)
            break;
        memset(v, 0, sizeof *v);
        xml_attribute(p, close, "name", v->name, sizeof v->name);
        xml_attribute(p, close, "valueReference", value, sizeof value);
        v->vr = (fmi2ValueReference)strtoul(value, NULL, 10);
        xml_attribute(p, close, "causality", value, sizeof value);
        v->causality = strcmp(value, "output") == 0 ? VAR_OUTPUT
                     : strcmp(value, "input") == 0 ? VAR_INPUT : VAR_PARAMETER;
        v->type = strstr(p, "<Integer") && strstr(p, "<Integer") < close ? VAR_INTEGER
                : strstr(p, "<Boolean") && strstr(p, "<Boolean") < close ? VAR_BOOLEAN : VAR_REAL;
        if (xml_attribute(p, close, "start", value, sizeof value))
            v->start = strcmp(value, "true") == 0 ? 1.0 : strcmp(value, "false") == 0 ? 0.0 : atof(value);
        if ((v->has_min = xml_attribute(p, close, "min", value, sizeof value)) != 0)
            v->min = atof(value);
        if ((v->has_max = xml_attribute(p, close, "max", value, sizeof value)) != 0)
            v->max = atof(value);
        f->n_vars++;
    }
    free(xml);
    return f->n_vars > 0;
}

/* Load an FMU: its description and every fmi2 function of its binary. */
static inline int host_load(host_fmu *f, const char *xml_path, const char *so_path)
{
    memset(f, 0, sizeof *f);
    if (!host_read_model_description(f, xml_path))
        return 0;
    f->lib = dlopen(so_path, RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        printf("FAIL dlopen %s: %s\n", so_path, dlerror());
        return 0;
    }
#define LOAD(name)                                                          \
    *(void **)(&f->api.name) = dlsym(f->lib, "fmi2" #name);                 \
    if (f->api.name == NULL) {                                              \
        printf("FAIL %s: symbol fmi2%s missing\n", so_path, #name);          \
        return 0;                                                           \
    }
    FMI2_API(LOAD)
#undef LOAD
    return 1;
}

static inline void host_unload(host_fmu *f)
{
    if (f->lib != NULL)
        dlclose(f->lib);
    f->lib = NULL;
}

/* The first variable with this causality and type, or NULL. */
static inline const host_var *host_find(const host_fmu *f, int causality, int type)
{
    int i;
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].causality == causality && f->vars[i].type == type)
            return &f->vars[i];
    return NULL;
}

static inline const host_var *host_named(const host_fmu *f, const char *name)
{
    int i;
    for (i = 0; i < f->n_vars; i++)
        if (strcmp(f->vars[i].name, name) == 0)
            return &f->vars[i];
    return NULL;
}

/* Set one variable of any type from a double. */
static inline fmi2Status host_set(const host_fmu *f, fmi2Component c, const host_var *v, double value)
{
    if (v->type == VAR_REAL)
        return f->api.SetReal(c, &v->vr, 1, &value);
    if (v->type == VAR_INTEGER) {
        fmi2Integer i = (fmi2Integer)value;
        return f->api.SetInteger(c, &v->vr, 1, &i);
    }
    {
        fmi2Boolean b = value != 0.0 ? fmi2True : fmi2False;
        return f->api.SetBoolean(c, &v->vr, 1, &b);
    }
}

static inline fmi2Status host_set_named(const host_fmu *f, fmi2Component c, const char *name, double value)
{
    const host_var *v = host_named(f, name);
    if (v == NULL) {
        printf("FAIL %s has no variable %s\n", f->id, name);
        return fmi2Fatal;
    }
    return host_set(f, c, v, value);
}

/* The controller refuses a doStep of several samples unless mv.hold_inputs is
 * true (a closed loop needs one exchange per sample); these hosts step several
 * samples at once to test the FMI layer, so they set it wherever the FMU has it. */
static inline int host_hold_inputs(const host_fmu *f, fmi2Component c)
{
    return host_named(f, "mv.hold_inputs") == NULL || host_set_named(f, c, "mv.hold_inputs", 1.0) == fmi2OK;
}

/* Every Real output into out[] (in variable order); returns how many, or -1 on fmi2Error. */
static inline int host_real_outputs(const host_fmu *f, fmi2Component c, double *out)
{
    int i, n = 0;
    for (i = 0; i < f->n_vars; i++) {
        if (f->vars[i].causality != VAR_OUTPUT || f->vars[i].type != VAR_REAL)
            continue;
        if (f->api.GetReal(c, &f->vars[i].vr, 1, &out[n]) != fmi2OK)
            return -1;
        n++;
    }
    return n;
}

static inline int all_finite(const double *x, int n)
{
    int i;
    for (i = 0; i < n; i++)
        if (!isfinite(x[i]))
            return 0;
    return 1;
}

/* A fresh instance in StepComplete at t0 = 0 with the start values, or NULL. */
static inline fmi2Component host_start(const host_fmu *f, const fmi2CallbackFunctions *cb, const char *name)
{
    fmi2Component c = f->api.Instantiate(name, fmi2CoSimulation, f->guid, "", cb, fmi2False, fmi2False);
    if (c == NULL)
        return NULL;
    if (f->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK
        || f->api.EnterInitializationMode(c) != fmi2OK || f->api.ExitInitializationMode(c) != fmi2OK) {
        f->api.FreeInstance(c);
        return NULL;
    }
    return c;
}

/* The instance's current state as a serialized blob (malloc'ed, *size set), or NULL. */
static inline unsigned char *host_snapshot(const host_fmu *f, fmi2Component c, size_t *size)
{
    fmi2FMUstate s = NULL;
    unsigned char *blob = NULL;
    *size = 0;
    if (f->api.GetFMUstate(c, &s) != fmi2OK)
        return NULL;
    if (f->api.SerializedFMUstateSize(c, s, size) == fmi2OK && (blob = (unsigned char *)malloc(*size)) != NULL
        && f->api.SerializeFMUstate(c, s, (fmi2Byte *)blob, *size) != fmi2OK) {
        free(blob);
        blob = NULL;
    }
    f->api.FreeFMUstate(c, &s);
    return blob;
}

/* 1 when the instance's state serializes to exactly `blob`. */
static inline int host_same_state(const host_fmu *f, fmi2Component c, const unsigned char *blob, size_t size)
{
    size_t now_size;
    unsigned char *now = host_snapshot(f, c, &now_size);
    int same = now != NULL && blob != NULL && now_size == size && memcmp(now, blob, size) == 0;
    free(now);
    return same;
}

/* ------------------------------------------------------------------------ */
/* distinct runs: configuration i of an FMU and its input sequence           */

/* Parameters of configuration i, for whichever of them the FMU has: exact or
 * SOE creep, sensor noise with its own seed, a creep row, controller tuning,
 * reference tones. Returns 0 if a setting was refused. */
static inline int host_apply_config(const host_fmu *f, fmi2Component c, int i)
{
    struct { const char *name; double value; } settings[] = {
        {"creep.exact", (double)(i % 2)},
        {"sensor.noise_rms", 0.001 * (i % 4)},
        {"sensor.resolution", i % 3 == 0 ? 0.002 : 0.0},
        {"sensor.seed", (double)(17 + i)},
        {"creep.alpha", 0.0002 * (1 + i)},
        {"mv.lambda_u", 0.01 * (i % 3)},
        {"rls.forgetting", 0.99 + 0.001 * i},
        {"amplitude[1]", 1.0 + i},
        {"frequency[1]", 1.0 + 2.0 * i},
        {"amplitude[2]", 0.5},
        {"frequency[2]", 13.0 + i},
        {"offset", 0.25 * i},
        {"monitor.divergence_samples", 0.0},   /* the drive is no closed loop: never call it unstable */
    };
    size_t j;
    for (j = 0; j < sizeof settings / sizeof settings[0]; j++)
        if (host_named(f, settings[j].name) != NULL
            && host_set_named(f, c, settings[j].name, settings[j].value) != fmi2OK)
            return 0;
    return 1;
}

/* Input j at sample k of configuration i: a few microns, a few hertz apart. */
static inline double host_drive(int i, int j, int k, double h)
{
    return (2.0 + i) * sin(2.0 * 3.14159265358979323846 * (1.0 + i + 3.0 * j) * k * h + j) + 0.5 * i;
}

/* Sets every Real input of f to host_drive(i, j, k, h). */
static inline int host_set_inputs(const host_fmu *f, fmi2Component c, int i, int k)
{
    int v, j = 0;
    for (v = 0; v < f->n_vars; v++)
        if (f->vars[v].causality == VAR_INPUT && f->vars[v].type == VAR_REAL) {
            double u = host_drive(i, j++, k, f->h);
            if (f->api.SetReal(c, &f->vars[v].vr, 1, &u) != fmi2OK)
                return 0;
        }
    return 1;
}

/* ------------------------------------------------------------------------ */
/* the serialized-state format (documented in fmu_src/fmi/fmi2_glue.c)       */

#define BLOB_HEADER 128u
#define BLOB_OFF_TOTAL 16u
#define BLOB_OFF_DATA_SIZE 72u
#define BLOB_OFF_MODE 84u
#define BLOB_OFF_T0 88u
#define BLOB_OFF_K 96u
#define BLOB_OFF_H 104u
#define BLOB_OFF_N_HISTORY 112u
#define BLOB_OFF_RESERVED 120u

static inline uint64_t blob_get_u64(const unsigned char *p)
{
    uint64_t v = 0;
    int i;
    for (i = 7; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static inline void blob_put_u64(unsigned char *p, uint64_t v)
{
    int i;
    for (i = 0; i < 8; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static inline void blob_put_f64(unsigned char *p, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    blob_put_u64(p, v);
}

/* FNV-1a 64 of the first n bytes, as the format's checksum. */
static inline uint64_t blob_fnv1a(const unsigned char *p, size_t n)
{
    uint64_t h = 0xcbf29ce484222325ull;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

/* Make a tampered blob self-consistent again: size field and checksum. */
static inline void blob_reseal(unsigned char *b, size_t size)
{
    if (size < BLOB_HEADER + 8u)
        return;
    blob_put_u64(b + BLOB_OFF_TOTAL, (uint64_t)size);
    blob_put_u64(b + size - 8u, blob_fnv1a(b, size - 8u));
}

#endif
