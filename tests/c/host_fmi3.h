/*
 * host_fmi3.h - the FMI 3.0 adapter of the C test hosts' layer: a binary's
 * fmi3 functions loaded with dlopen (RTLD_LOCAL), its variables read from its
 * FMI 3.0 modelDescription.xml (arrays with their size, elements addressed by
 * their structured names, "pi.w[2]"), and the operations the suites share done
 * through FMI 3.0 calls (host.h names them without the version; host_fmi2.h has
 * the same for FMI 2.0).
 *
 * FMI 3.0 has no memory callbacks: the FMU allocates with calloc/free, so
 * "nothing leaked" is the C library's count of bytes in use (host_heap_in_use,
 * exact with GLIBC_TUNABLES=glibc.malloc.tcache_count=0), and valgrind or
 * LeakSanitizer over the whole run.
 */
#ifndef HOST_FMI3_H
#define HOST_FMI3_H

#include "host_common.h"
#include "fmi3Functions.h"

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
#define FMI3_FIELD(name) fmi3##name##TYPE *name;
    FMI3_API(FMI3_FIELD)
#undef FMI3_FIELD
} fmi3_api;

typedef struct {
    char id[64];                /* modelIdentifier */
    char token[64];             /* instantiationToken */
    double h;                   /* DefaultExperiment stepSize */
    void *lib;
    fmi3_api api;
    host_var vars[HOST_MAX_VARS];
    int n_vars;
} host3_fmu;

/* One instance with its own log (which may not move while it lives). */
typedef struct {
    const host3_fmu *f;
    fmi3Instance c;
    host_log log;
    int k;                      /* samples since t0 = 0, where a suite counts them */
} host3_inst;

/* What the FMUs hold: the C library's bytes in use (-1: not countable). */
static inline long host3_mem_in_use(void)
{
    return host_heap_in_use();
}

/* The logger: messages into the host_log passed as instanceEnvironment. */
static inline void host3_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                                fmi3String message)
{
    (void)category;
    host_log_record((host_log *)env, status >= fmi3Error, message);
}

/* ------------------------------------------------------------------------ */
/* loading                                                                   */

/* Our FMI 3.0 model descriptions are regular: one element per variable,
 * <Float64|Int32|Boolean name=... valueReference=... causality=... [start=...]>,
 * an array with a <Dimension start="n"/> child. */
static inline int host3_read_model_description(host3_fmu *f, const char *xml_path)
{
    static const char *const tags[] = {"<Float64 ", "<Int32 ", "<Boolean "};
    char *xml = host_read_file(xml_path, NULL), value[128];
    const char *p, *vars_end;
    if (xml == NULL) {
        host_fail("cannot read %s", xml_path);
        return 0;
    }
    if (!xml_tag_attribute(strstr(xml, "<fmiModelDescription"), "instantiationToken", f->token, sizeof f->token)
        || !xml_tag_attribute(strstr(xml, "<CoSimulation"), "modelIdentifier", f->id, sizeof f->id)
        || !xml_tag_attribute(strstr(xml, "<DefaultExperiment"), "stepSize", value, sizeof value)) {
        host_fail("%s: instantiationToken, modelIdentifier or stepSize missing", xml_path);
        free(xml);
        return 0;
    }
    f->h = atof(value);
    f->n_vars = 0;
    p = strstr(xml, "<ModelVariables>");
    vars_end = p != NULL ? strstr(p, "</ModelVariables>") : NULL;
    while (p != NULL && vars_end != NULL) {
        const char *next = NULL, *close;
        int t, which = -1;
        host_var *v = &f->vars[f->n_vars < HOST_MAX_VARS ? f->n_vars : 0];
        for (t = 0; t < 3; t++) {
            const char *q = strstr(p, tags[t]);
            if (q != NULL && q < vars_end && (next == NULL || q < next)) {
                next = q;
                which = t;
            }
        }
        if (next == NULL)
            break;
        if (f->n_vars >= HOST_MAX_VARS) {
            printf("FAIL %s: more than HOST_MAX_VARS = %d variables\n", xml_path, HOST_MAX_VARS);
            free(xml);
            return 0;
        }
        close = strchr(next, '>');
        memset(v, 0, sizeof *v);
        v->type = which == 0 ? VAR_REAL : which == 1 ? VAR_INTEGER : VAR_BOOLEAN;
        v->n = 1;
        if (close != NULL && close[-1] != '/') {
            /* an element with children: the Dimension of an array */
            const char *dim = strstr(close, "<Dimension"), *end = strstr(close, "</");
            if (dim != NULL && end != NULL && dim < end && xml_tag_attribute(dim, "start", value, sizeof value))
                v->n = atoi(value);
        }
        xml_attribute(next, close, "name", v->name, sizeof v->name);
        if (v->n < 1 || v->n > HOST_MAX_ELEMENTS) {
            host_fail("%s: variable %s has %d elements", xml_path, v->name, v->n);
            free(xml);
            return 0;
        }
        host_var_attributes(v, next, close);
        f->n_vars++;
        p = close != NULL ? close : next + 1;
    }
    free(xml);
    return f->n_vars > 0;
}

/* An FMU: its FMI 3.0 description and every fmi3 function of its binary. */
static inline int host3_load(host3_fmu *f, const char *xml_path, const char *so_path)
{
    memset(f, 0, sizeof *f);
    if (!host3_read_model_description(f, xml_path))
        return 0;
    f->lib = dlopen(so_path, RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        host_fail("dlopen %s: %s", so_path, dlerror());
        return 0;
    }
#define FMI3_LOAD(name)                                                     \
    *(void **)(&f->api.name) = dlsym(f->lib, "fmi3" #name);                 \
    if (f->api.name == NULL) {                                              \
        host_fail("%s: symbol fmi3%s missing", so_path, #name);          \
        return 0;                                                           \
    }
    FMI3_API(FMI3_LOAD)
#undef FMI3_LOAD
    return 1;
}

static inline void host3_unload(host3_fmu *f)
{
    if (f->lib != NULL)
        dlclose(f->lib);
    f->lib = NULL;
}

/* ------------------------------------------------------------------------ */
/* instances                                                                 */

/* A Co-Simulation instance (in->c, NULL if refused) logging into in->log:
 * not visible, no logging of calls, no event mode, no early return. */
static inline fmi3Instance host3_instantiate(host3_inst *in, const host3_fmu *f, const char *name)
{
    memset(in, 0, sizeof *in);
    in->f = f;
    in->c = f->api.InstantiateCoSimulation(name, f->token, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0,
                                           &in->log, host3_logger, NULL);
    return in->c;
}

/* Instantiated -> InitializationMode (no tolerance). */
static inline fmi3Status host3_enter_init(const host3_fmu *f, fmi3Instance c, double start, int stop_defined,
                                          double stop)
{
    return f->api.EnterInitializationMode(c, fmi3False, 0.0, start, stop_defined ? fmi3True : fmi3False, stop);
}

/* A fresh instance in Step Mode at t0 = 0 with the start values (in->c NULL if not). */
static inline fmi3Instance host3_start(host3_inst *in, const host3_fmu *f, const char *name)
{
    if (host3_instantiate(in, f, name) != NULL
        && (host3_enter_init(f, in->c, 0.0, 0, 0.0) != fmi3OK || f->api.ExitInitializationMode(in->c) != fmi3OK)) {
        f->api.FreeInstance(in->c);
        in->c = NULL;
    }
    return in->c;
}

static inline void host3_free_instance(host3_inst *in)
{
    if (in->c != NULL)
        in->f->api.FreeInstance(in->c);
    in->c = NULL;
}

/* The doStep and its out-arguments (set to true and -1 before: the FMU must write them). */
static inline fmi3Status host3_step_out(const host3_fmu *f, fmi3Instance c, double t, double H, host_step_result *out)
{
    fmi3Boolean event = fmi3True, terminate = fmi3True, early = fmi3True;
    fmi3Float64 last = -1.0;
    fmi3Status st = f->api.DoStep(c, t, H, fmi3True, &event, &terminate, &early, &last);
    out->last = last;
    out->event = event;
    out->terminate = terminate;
    out->early = early;
    return st;
}

/* One doStep, the out-arguments discarded. */
static inline fmi3Status host3_step(const host3_fmu *f, fmi3Instance c, double t, double H)
{
    host_step_result out;
    return host3_step_out(f, c, t, H, &out);
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

static inline fmi3Status host3_get_state(const host3_fmu *f, fmi3Instance c, fmi3FMUState *s)
{
    return f->api.GetFMUState(c, s);
}

static inline fmi3Status host3_set_state(const host3_fmu *f, fmi3Instance c, fmi3FMUState s)
{
    return f->api.SetFMUState(c, s);
}

static inline fmi3Status host3_free_state(const host3_fmu *f, fmi3Instance c, fmi3FMUState *s)
{
    return f->api.FreeFMUState(c, s);
}

static inline fmi3Status host3_state_size(const host3_fmu *f, fmi3Instance c, fmi3FMUState s, size_t *size)
{
    return f->api.SerializedFMUStateSize(c, s, size);
}

static inline fmi3Status host3_serialize(const host3_fmu *f, fmi3Instance c, fmi3FMUState s, unsigned char *blob,
                                         size_t size)
{
    return f->api.SerializeFMUState(c, s, blob, size);
}

static inline fmi3Status host3_deserialize(const host3_fmu *f, fmi3Instance c, const unsigned char *blob,
                                           size_t size, fmi3FMUState *s)
{
    return f->api.DeserializeFMUState(c, blob, size, s);
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

/* ------------------------------------------------------------------------ */
/* values                                                                    */

/* host3_get_reals, host3_set_reals, host3_get_ints ... : f->api.<Get|Set><Type>(c, vr, nvr, values,
 * n_values) */
#define HOST3_VALUES(verb, fn, kind, ctype, qual)                                                   \
    static inline fmi3Status host3_##verb##_##kind(const host3_fmu *f, fmi3Instance c,              \
                                                   const fmi3ValueReference *vr, size_t nvr,        \
                                                   qual ctype *values, size_t n_values)             \
    {                                                                                               \
        return f->api.fn(c, vr, nvr, values, n_values);                                             \
    }
HOST3_VALUES(get, GetFloat64, reals, double, )
HOST3_VALUES(set, SetFloat64, reals, double, const)
HOST3_VALUES(get, GetInt32, ints, fmi3Int32, )
HOST3_VALUES(set, SetInt32, ints, fmi3Int32, const)
HOST3_VALUES(get, GetBoolean, bools, fmi3Boolean, )
HOST3_VALUES(set, SetBoolean, bools, fmi3Boolean, const)
#undef HOST3_VALUES

/* Set every value of v (all elements of an array) from one double. */
static inline fmi3Status host3_set(const host3_fmu *f, fmi3Instance c, const host_var *v, double value)
{
    int j;
    if (v->type == VAR_REAL) {
        fmi3Float64 x[HOST_MAX_ELEMENTS];
        for (j = 0; j < v->n; j++)
            x[j] = value;
        return f->api.SetFloat64(c, &v->vr, 1, x, (size_t)v->n);
    }
    if (v->type == VAR_INTEGER) {
        fmi3Int32 x[HOST_MAX_ELEMENTS];
        for (j = 0; j < v->n; j++)
            x[j] = (fmi3Int32)value;
        return f->api.SetInt32(c, &v->vr, 1, x, (size_t)v->n);
    }
    {
        fmi3Boolean x[HOST_MAX_ELEMENTS];
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
    const host_var *v = host_named(f, name, &element);
    fmi3Float64 x[HOST_MAX_ELEMENTS];
    fmi3Status st;
    if (v == NULL) {
        host_fail("%s has no variable %s", f->id, name);
        return fmi3Fatal;
    }
    if (element < 0)
        return host3_set(f, c, v, value);
    if (v->type != VAR_REAL) {
        host_fail("%s: host3_set_named of an element of a non-Float64 array", f->id);
        return fmi3Fatal;
    }
    st = f->api.GetFloat64(c, &v->vr, 1, x, (size_t)v->n);
    if (st != fmi3OK)
        return st;
    x[element] = value;
    return f->api.SetFloat64(c, &v->vr, 1, x, (size_t)v->n);
}

/* Every Float64 output into out[capacity] (in variable order); returns how many, or -1 on
 * fmi3Error or more outputs than capacity (a FAIL). */
static inline int host3_real_outputs(const host3_fmu *f, fmi3Instance c, double *out, int capacity)
{
    int i, n = 0;
    for (i = 0; i < f->n_vars; i++) {
        if (f->vars[i].causality != VAR_OUTPUT || f->vars[i].type != VAR_REAL)
            continue;
        if (n >= capacity) {
            host_fail("%s has more than %d Real outputs: the host's buffer is too small", f->id, capacity);
            return -1;
        }
        if (f->api.GetFloat64(c, &f->vars[i].vr, 1, &out[n], 1) != fmi3OK)
            return -1;
        n++;
    }
    return n;
}

#endif
