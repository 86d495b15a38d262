/*
 * fmu3_host.h - what the FMI 3.0 C test hosts share: load an FMI 3.0 FMU
 * binary with dlopen (every fmi3 function by name, RTLD_LOCAL), read its
 * variables from its FMI 3.0 modelDescription.xml (array variables with their
 * size), capture the FMU's log messages per instance, and address array
 * elements by their structured names ("pi.w[2]"). Built on fmu_host.h, whose
 * checks, message capture, blob helpers and drive signals it reuses (a host
 * may load FMI 2.0 binaries beside FMI 3.0 ones: the cross-edition checks).
 *
 * FMI 3.0 has no memory callbacks: the FMU allocates with calloc/free, so
 * leaks are found by valgrind and LeakSanitizer over the whole run, and per
 * case by the C library's count of bytes in use (host3_heap_in_use, exact with
 * GLIBC_TUNABLES=glibc.malloc.tcache_count=0).
 *
 * The hosts take their FMUs as pairs of arguments: MODEL.xml BINARY.so (the
 * unzipped FMU's files, or the build's).
 */
#ifndef FMU3_HOST_H
#define FMU3_HOST_H

#include "fmu_host.h"
#include "fmi3Functions.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

/* ------------------------------------------------------------------------ */
/* the FMI 3.0 API of one binary                                             */

#define FMI3_API(X) \
    X(GetVersion) X(SetDebugLogging) X(InstantiateModelExchange) X(InstantiateCoSimulation) \
    X(InstantiateScheduledExecution) X(FreeInstance) X(EnterInitializationMode) X(ExitInitializationMode) \
    X(EnterEventMode) X(Terminate) X(Reset) \
    X(GetFloat32) X(GetFloat64) X(GetInt8) X(GetUInt8) X(GetInt16) X(GetUInt16) X(GetInt32) X(GetUInt32) \
    X(GetInt64) X(GetUInt64) X(GetBoolean) X(GetString) X(GetBinary) X(GetClock) \
    X(SetFloat32) X(SetFloat64) X(SetInt8) X(SetUInt8) X(SetInt16) X(SetUInt16) X(SetInt32) X(SetUInt32) \
    X(SetInt64) X(SetUInt64) X(SetBoolean) X(SetString) X(SetBinary) X(SetClock) \
    X(GetNumberOfVariableDependencies) X(GetVariableDependencies) \
    X(GetFMUState) X(SetFMUState) X(FreeFMUState) X(SerializedFMUStateSize) X(SerializeFMUState) \
    X(DeserializeFMUState) X(GetDirectionalDerivative) X(GetAdjointDerivative) \
    X(EnterConfigurationMode) X(ExitConfigurationMode) \
    X(GetIntervalDecimal) X(GetIntervalFraction) X(GetShiftDecimal) X(GetShiftFraction) \
    X(SetIntervalDecimal) X(SetIntervalFraction) X(SetShiftDecimal) X(SetShiftFraction) \
    X(EvaluateDiscreteStates) X(UpdateDiscreteStates) \
    X(EnterContinuousTimeMode) X(CompletedIntegratorStep) X(SetTime) X(SetContinuousStates) \
    X(GetContinuousStateDerivatives) X(GetEventIndicators) X(GetContinuousStates) \
    X(GetNominalsOfContinuousStates) X(GetNumberOfEventIndicators) X(GetNumberOfContinuousStates) \
    X(EnterStepMode) X(GetOutputDerivatives) X(DoStep) X(ActivateModelPartition)

typedef struct {
#define FIELD3(name) fmi3##name##TYPE *name;
    FMI3_API(FIELD3)
#undef FIELD3
} fmi3_api;

#define VAR_INDEPENDENT 3       /* the causality of time (VAR_PARAMETER, VAR_INPUT, VAR_OUTPUT: fmu_host.h) */
#define HOST3_MAX_ELEMENTS 32

typedef struct {
    char name[64];
    fmi3ValueReference vr;
    int type;                   /* VAR_REAL (Float64), VAR_INTEGER (Int32), VAR_BOOLEAN */
    int causality;              /* VAR_PARAMETER, VAR_INPUT, VAR_OUTPUT, VAR_INDEPENDENT */
    int n;                      /* values: 1 for a scalar, the size of an array */
    double start[HOST3_MAX_ELEMENTS];   /* parameters and inputs, per element */
    int has_min, has_max;       /* the declared range, where the model description has one */
    double min, max;
} host3_var;

typedef struct {
    char id[64];                /* modelIdentifier */
    char token[64];             /* instantiationToken */
    double h;                   /* DefaultExperiment stepSize */
    void *lib;
    fmi3_api api;
    host3_var vars[HOST_MAX_VARS];
    int n_vars;
} host3_fmu;

/* ------------------------------------------------------------------------ */
/* the logger: messages into the host_log passed as instanceEnvironment      */

static inline void host3_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                                fmi3String message)
{
    host_log *log = (host_log *)env;
    (void)category;
    if (log == NULL)
        return;
    log->n_messages++;
    snprintf(log->last, sizeof log->last, "%s", message != NULL ? message : "(NULL)");
    if (status >= fmi3Error) {
        size_t used = strlen(log->errors);
        log->n_errors++;
        snprintf(log->last_error, sizeof log->last_error, "%s", log->last);
        snprintf(log->errors + used, sizeof log->errors - used, "%s%s", used ? "; " : "", log->last);
    }
}

/* Bytes the C library has handed out and not taken back, or -1 when it cannot
 * say exactly. glibc's count (mallinfo2) is exact only without its per-thread
 * cache, which keeps freed blocks counted as in use: the hosts are run with
 * GLIBC_TUNABLES=glibc.malloc.tcache_count=0 (CTest and pytest set it). Under a
 * sanitizer or valgrind the count is theirs; LeakSanitizer and memcheck check
 * leaks over the whole run anyway. */
static inline long host3_heap_in_use(void)
{
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
    const char *tunables = getenv("GLIBC_TUNABLES");
    if (tunables == NULL || strstr(tunables, "glibc.malloc.tcache_count=0") == NULL)
        return -1;
    return (long)mallinfo2().uordblks;
#else
    return -1;
#endif
}

/* "compared" or why not, for the hosts' first line. */
static inline const char *host3_heap_note(void)
{
    return host3_heap_in_use() >= 0 ? "bytes in use compared per case (glibc, tcache off)"
                                    : "bytes in use NOT compared (run with GLIBC_TUNABLES=glibc.malloc.tcache_count=0)";
}

/* 1 when the bytes in use are back to `before` (or cannot be counted). */
static inline int host3_heap_back_to(long before)
{
    return before < 0 || host3_heap_in_use() == before;
}

/* ------------------------------------------------------------------------ */
/* model description                                                         */

/* The value of attribute `name` of the opening tag at p (up to its first '>'). */
static inline int xml_tag_attribute(const char *p, const char *name, char *out, size_t size)
{
    const char *end = strchr(p, '>');
    return end != NULL && xml_attribute(p, end, name, out, size);
}

/* Our FMI 3.0 model descriptions are regular: one element per variable,
 * <Float64|Int32|Boolean name=... valueReference=... causality=... [start=...]>,
 * an array with a <Dimension start="n"/> child. */
static inline int host3_read_model_description(host3_fmu *f, const char *xml_path)
{
    static const char *const tags[] = {"<Float64 ", "<Int32 ", "<Boolean "};
    char *xml = read_file(xml_path), value[1024];
    const char *p, *vars_end;
    if (xml == NULL) {
        printf("FAIL cannot read %s\n", xml_path);
        return 0;
    }
    if (!xml_tag_attribute(strstr(xml, "<fmiModelDescription"), "instantiationToken", f->token, sizeof f->token)
        || !xml_tag_attribute(strstr(xml, "<CoSimulation"), "modelIdentifier", f->id, sizeof f->id)
        || !xml_tag_attribute(strstr(xml, "<DefaultExperiment"), "stepSize", value, sizeof value)) {
        printf("FAIL %s: instantiationToken, modelIdentifier or stepSize missing\n", xml_path);
        free(xml);
        return 0;
    }
    f->h = atof(value);
    f->n_vars = 0;
    p = strstr(xml, "<ModelVariables>");
    vars_end = p != NULL ? strstr(p, "</ModelVariables>") : NULL;
    while (p != NULL && vars_end != NULL && f->n_vars < HOST_MAX_VARS) {
        const char *next = NULL, *close;
        int t, which = -1;
        host3_var *v = &f->vars[f->n_vars];
        for (t = 0; t < 3; t++) {
            const char *q = strstr(p, tags[t]);
            if (q != NULL && q < vars_end && (next == NULL || q < next)) {
                next = q;
                which = t;
            }
        }
        if (next == NULL)
            break;
        close = strchr(next, '>');
        memset(v, 0, sizeof *v);
        v->type = which == 0 ? VAR_REAL : which == 1 ? VAR_INTEGER : VAR_BOOLEAN;
        xml_tag_attribute(next, "name", v->name, sizeof v->name);
        xml_tag_attribute(next, "valueReference", value, sizeof value);
        v->vr = (fmi3ValueReference)strtoul(value, NULL, 10);
        xml_tag_attribute(next, "causality", value, sizeof value);
        v->causality = strcmp(value, "output") == 0 ? VAR_OUTPUT
                     : strcmp(value, "input") == 0 ? VAR_INPUT
                     : strcmp(value, "independent") == 0 ? VAR_INDEPENDENT : VAR_PARAMETER;
        v->n = 1;
        if (close != NULL && close[-1] != '/') {
            /* an element with children: the Dimension of an array */
            const char *dim = strstr(close, "<Dimension"), *end = strstr(close, "</");
            if (dim != NULL && end != NULL && dim < end && xml_tag_attribute(dim, "start", value, sizeof value))
                v->n = atoi(value);
        }
        if (v->n < 1 || v->n > HOST3_MAX_ELEMENTS) {
            printf("FAIL %s: variable %s has %d elements\n", xml_path, v->name, v->n);
            free(xml);
            return 0;
        }
        if (xml_tag_attribute(next, "start", value, sizeof value)) {
            char *s = value, *end;
            int j;
            for (j = 0; j < v->n; j++) {
                while (*s == ' ')
                    s++;
                if (strncmp(s, "true", 4) == 0) {
                    v->start[j] = 1.0;
                    s += 4;
                } else if (strncmp(s, "false", 5) == 0) {
                    v->start[j] = 0.0;
                    s += 5;
                } else {
                    v->start[j] = strtod(s, &end);
                    s = end;
                }
            }
        }
        if ((v->has_min = xml_tag_attribute(next, "min", value, sizeof value)) != 0)
            v->min = atof(value);
        if ((v->has_max = xml_tag_attribute(next, "max", value, sizeof value)) != 0)
            v->max = atof(value);
        f->n_vars++;
        p = close != NULL ? close : next + 1;
    }
    free(xml);
    return f->n_vars > 0;
}

/* Load an FMU: its FMI 3.0 description and every fmi3 function of its binary. */
static inline int host3_load(host3_fmu *f, const char *xml_path, const char *so_path)
{
    memset(f, 0, sizeof *f);
    if (!host3_read_model_description(f, xml_path))
        return 0;
    f->lib = dlopen(so_path, RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        printf("FAIL dlopen %s: %s\n", so_path, dlerror());
        return 0;
    }
#define LOAD3(name)                                                         \
    *(void **)(&f->api.name) = dlsym(f->lib, "fmi3" #name);                 \
    if (f->api.name == NULL) {                                              \
        printf("FAIL %s: symbol fmi3%s missing\n", so_path, #name);          \
        return 0;                                                           \
    }
    FMI3_API(LOAD3)
#undef LOAD3
    return 1;
}

static inline void host3_unload(host3_fmu *f)
{
    if (f->lib != NULL)
        dlclose(f->lib);
    f->lib = NULL;
}

/* The first variable with this causality and type, or NULL. */
static inline const host3_var *host3_find(const host3_fmu *f, int causality, int type)
{
    int i;
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].causality == causality && f->vars[i].type == type)
            return &f->vars[i];
    return NULL;
}

/* The variable called name, or the array whose element name is ("pi.w[2]": *element = 1). */
static inline const host3_var *host3_named(const host3_fmu *f, const char *name, int *element)
{
    int i;
    const char *bracket = strchr(name, '[');
    *element = -1;
    for (i = 0; i < f->n_vars; i++)
        if (strcmp(f->vars[i].name, name) == 0)
            return &f->vars[i];
    if (bracket == NULL)
        return NULL;
    for (i = 0; i < f->n_vars; i++) {
        size_t len = strlen(f->vars[i].name);
        if (f->vars[i].n > 1 && len == (size_t)(bracket - name) && strncmp(f->vars[i].name, name, len) == 0) {
            int j = atoi(bracket + 1);
            if (j < 1 || j > f->vars[i].n)
                return NULL;
            *element = j - 1;
            return &f->vars[i];
        }
    }
    return NULL;
}

/* ------------------------------------------------------------------------ */
/* instances and values                                                      */

static inline fmi3Instance host3_instantiate(const host3_fmu *f, const char *name, host_log *log)
{
    return f->api.InstantiateCoSimulation(name, f->token, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0,
                                          log, host3_logger, NULL);
}

/* Set every value of v (all elements of an array) from one double. */
static inline fmi3Status host3_set(const host3_fmu *f, fmi3Instance c, const host3_var *v, double value)
{
    int j;
    if (v->type == VAR_REAL) {
        fmi3Float64 x[HOST3_MAX_ELEMENTS];
        for (j = 0; j < v->n; j++)
            x[j] = value;
        return f->api.SetFloat64(c, &v->vr, 1, x, (size_t)v->n);
    }
    if (v->type == VAR_INTEGER) {
        fmi3Int32 x[HOST3_MAX_ELEMENTS];
        for (j = 0; j < v->n; j++)
            x[j] = (fmi3Int32)value;
        return f->api.SetInt32(c, &v->vr, 1, x, (size_t)v->n);
    }
    {
        fmi3Boolean x[HOST3_MAX_ELEMENTS];
        for (j = 0; j < v->n; j++)
            x[j] = value != 0.0;
        return f->api.SetBoolean(c, &v->vr, 1, x, (size_t)v->n);
    }
}

/* Set a variable or one element of an array by name ("pi.w[2]": the array is read,
 * the element replaced and the array set whole, so the getters must be allowed:
 * InitializationMode or later). */
static inline fmi3Status host3_set_named(const host3_fmu *f, fmi3Instance c, const char *name, double value)
{
    int element;
    const host3_var *v = host3_named(f, name, &element);
    fmi3Float64 x[HOST3_MAX_ELEMENTS];
    fmi3Status st;
    if (v == NULL) {
        printf("FAIL %s has no variable %s\n", f->id, name);
        return fmi3Fatal;
    }
    if (element < 0)
        return host3_set(f, c, v, value);
    if (v->type != VAR_REAL) {
        printf("FAIL %s: host3_set_named of an element of a non-Float64 array\n", f->id);
        return fmi3Fatal;
    }
    st = f->api.GetFloat64(c, &v->vr, 1, x, (size_t)v->n);
    if (st != fmi3OK)
        return st;
    x[element] = value;
    return f->api.SetFloat64(c, &v->vr, 1, x, (size_t)v->n);
}

/* Every Float64 output into out[] (in variable order); returns how many, or -1 on fmi3Error. */
/* The controller refuses a doStep of several samples unless mv.hold_inputs is
 * true (a closed loop needs one exchange per sample); these hosts step several
 * samples at once to test the FMI layer, so they set it wherever the FMU has it. */
static inline int host3_hold_inputs(const host3_fmu *f, fmi3Instance c)
{
    int element;
    return host3_named(f, "mv.hold_inputs", &element) == NULL
           || host3_set_named(f, c, "mv.hold_inputs", 1.0) == fmi3OK;
}

static inline int host3_real_outputs(const host3_fmu *f, fmi3Instance c, double *out)
{
    int i, n = 0;
    for (i = 0; i < f->n_vars; i++) {
        if (f->vars[i].causality != VAR_OUTPUT || f->vars[i].type != VAR_REAL)
            continue;
        if (f->api.GetFloat64(c, &f->vars[i].vr, 1, &out[n], 1) != fmi3OK)
            return -1;
        n++;
    }
    return n;
}

/* One doStep, the out-arguments discarded. */
static inline fmi3Status host3_step(const host3_fmu *f, fmi3Instance c, double t, double H)
{
    fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
    fmi3Float64 last = 0.0;
    return f->api.DoStep(c, t, H, fmi3True, &event, &terminate, &early, &last);
}

/* A fresh instance in Step Mode at t0 = 0 with the start values, or NULL. */
static inline fmi3Instance host3_start(const host3_fmu *f, host_log *log, const char *name)
{
    fmi3Instance c = host3_instantiate(f, name, log);
    if (c == NULL)
        return NULL;
    if (f->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) != fmi3OK
        || f->api.ExitInitializationMode(c) != fmi3OK) {
        f->api.FreeInstance(c);
        return NULL;
    }
    return c;
}

/* The instance's current state as a serialized blob (malloc'ed, *size set), or NULL. */
static inline unsigned char *host3_snapshot(const host3_fmu *f, fmi3Instance c, size_t *size)
{
    fmi3FMUState s = NULL;
    unsigned char *blob = NULL;
    *size = 0;
    if (f->api.GetFMUState(c, &s) != fmi3OK)
        return NULL;
    if (f->api.SerializedFMUStateSize(c, s, size) == fmi3OK && (blob = (unsigned char *)malloc(*size)) != NULL
        && f->api.SerializeFMUState(c, s, blob, *size) != fmi3OK) {
        free(blob);
        blob = NULL;
    }
    f->api.FreeFMUState(c, &s);
    return blob;
}

/* 1 when the instance's state serializes to exactly `blob`. */
static inline int host3_same_state(const host3_fmu *f, fmi3Instance c, const unsigned char *blob, size_t size)
{
    size_t now_size;
    unsigned char *now = host3_snapshot(f, c, &now_size);
    int same = now != NULL && blob != NULL && now_size == size && memcmp(now, blob, size) == 0;
    free(now);
    return same;
}

/* Configuration i (the settings of host_apply_config in fmu_host.h, array elements by name). */
static inline int host3_apply_config(const host3_fmu *f, fmi3Instance c, int i)
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
        {"monitor.divergence_samples", 0.0},
    };
    size_t j;
    int element;
    for (j = 0; j < sizeof settings / sizeof settings[0]; j++)
        if (host3_named(f, settings[j].name, &element) != NULL
            && host3_set_named(f, c, settings[j].name, settings[j].value) != fmi3OK)
            return 0;
    return 1;
}

/* Sets every Float64 input of f to host_drive(i, j, k, h). */
static inline int host3_set_inputs(const host3_fmu *f, fmi3Instance c, int i, int k)
{
    int v, j = 0;
    for (v = 0; v < f->n_vars; v++)
        if (f->vars[v].causality == VAR_INPUT && f->vars[v].type == VAR_REAL) {
            double u = host_drive(i, j++, k, f->h);
            if (f->api.SetFloat64(c, &f->vars[v].vr, 1, &u, 1) != fmi3OK)
                return 0;
        }
    return 1;
}

#endif
