/*
 * host_fmi2.h - the FMI 2.0 adapter of the C test hosts' layer: a binary's
 * fmi2 functions loaded with dlopen (RTLD_LOCAL, so several FMUs live in one
 * process), its variables read from its FMI 2.0 modelDescription.xml, and the
 * operations the suites share done through FMI 2.0 calls (host.h names them
 * without the version; host_fmi3.h has the same for FMI 3.0). The memory
 * callbacks count the blocks the FMUs hold, so "nothing leaked" is exact.
 *
 * An FMI 3.0 suite may include it beside its own adapter: the cross-edition
 * checks hand one edition's instances to the other's functions.
 */
#ifndef HOST_FMI2_H
#define HOST_FMI2_H

#include "host_common.h"
#include "fmi2Functions.h"

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
#define FMI2_FIELD(name) fmi2##name##TYPE *name;
    FMI2_API(FMI2_FIELD)
#undef FMI2_FIELD
} fmi2_api;

typedef struct {
    char id[64];                /* modelIdentifier */
    char token[64];             /* guid */
    double h;                   /* DefaultExperiment stepSize */
    void *lib;
    fmi2_api api;
    host_var vars[HOST_MAX_VARS];
    int n_vars;
} host2_fmu;

/* One instance with its own log and callbacks (neither may move while it lives). */
typedef struct {
    const host2_fmu *f;
    fmi2Component c;
    host_log log;
    fmi2CallbackFunctions cb;
    int k;                      /* samples since t0 = 0, where a suite counts them */
} host2_inst;

/* ------------------------------------------------------------------------ */
/* callbacks: counted allocations, messages per instance                     */

static atomic_long host2_live_blocks;   /* blocks allocated through the callbacks and not freed */

static inline void *host2_calloc(size_t n, size_t size)
{
    void *p = calloc(n, size);
    if (p != NULL)
        atomic_fetch_add(&host2_live_blocks, 1);
    return p;
}

static inline void host2_free(void *p)
{
    if (p != NULL)
        atomic_fetch_sub(&host2_live_blocks, 1);
    free(p);
}

/* What the FMUs hold: blocks allocated through the callbacks and not freed. */
static inline long host2_mem_in_use(void)
{
    return atomic_load(&host2_live_blocks);
}

static inline void host2_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                                fmi2String category, fmi2String message, ...)
{
    char text[1024];
    va_list ap;
    (void)instance;
    (void)category;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    host_log_record((host_log *)env, status >= fmi2Error, text);
}

static inline fmi2CallbackFunctions host2_callbacks(host_log *log)
{
    fmi2CallbackFunctions cb;
    memset(&cb, 0, sizeof cb);
    cb.logger = host2_logger;
    cb.allocateMemory = host2_calloc;
    cb.freeMemory = host2_free;
    cb.componentEnvironment = log;
    return cb;
}

/* ------------------------------------------------------------------------ */
/* loading                                                                   */

/* Our model descriptions are regular: one <ScalarVariable ...> element per
 * variable with name, valueReference, causality, then its type element. */
static inline int host2_read_model_description(host2_fmu *f, const char *xml_path)
{
    char *xml = host_read_file(xml_path, NULL), value[128];
    const char *p, *end;
    if (xml == NULL) {
        host_fail("cannot read %s", xml_path);
        return 0;
    }
    end = xml + strlen(xml);
    if (!xml_attribute(xml, end, "guid", f->token, sizeof f->token)
        || !xml_attribute(xml, end, "modelIdentifier", f->id, sizeof f->id)
        || !xml_attribute(xml, end, "stepSize", value, sizeof value)) {
        host_fail("%s: guid, modelIdentifier or stepSize missing", xml_path);
        free(xml);
        return 0;
    }
    f->h = atof(value);
    f->n_vars = 0;
    for (p = strstr(xml, "<ScalarVariable "); p != NULL; p = strstr(p + 1, "<ScalarVariable ")) {
        const char *close = strstr(p, "</ScalarVariable>");
        host_var *v;
        if (f->n_vars >= HOST_MAX_VARS) {
            printf("FAIL %s: more than HOST_MAX_VARS = %d variables\n", xml_path, HOST_MAX_VARS);
            free(xml);
            return 0;
        }
        v = &f->vars[f->n_vars];
        if (close == NULL)
            break;
        memset(v, 0, sizeof *v);
        v->type = strstr(p, "<Integer") && strstr(p, "<Integer") < close ? VAR_INTEGER
                : strstr(p, "<Boolean") && strstr(p, "<Boolean") < close ? VAR_BOOLEAN : VAR_REAL;
        v->n = 1;
        host_var_attributes(v, p, close);
        f->n_vars++;
    }
    free(xml);
    return f->n_vars > 0;
}

/* An FMU: its description and every fmi2 function of its binary. */
static inline int host2_load(host2_fmu *f, const char *xml_path, const char *so_path)
{
    memset(f, 0, sizeof *f);
    if (!host2_read_model_description(f, xml_path))
        return 0;
    f->lib = dlopen(so_path, RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        host_fail("dlopen %s: %s", so_path, dlerror());
        return 0;
    }
#define FMI2_LOAD(name)                                                     \
    *(void **)(&f->api.name) = dlsym(f->lib, "fmi2" #name);                 \
    if (f->api.name == NULL) {                                              \
        host_fail("%s: symbol fmi2%s missing", so_path, #name);          \
        return 0;                                                           \
    }
    FMI2_API(FMI2_LOAD)
#undef FMI2_LOAD
    return 1;
}

static inline void host2_unload(host2_fmu *f)
{
    if (f->lib != NULL)
        dlclose(f->lib);
    f->lib = NULL;
}

/* ------------------------------------------------------------------------ */
/* instances                                                                 */

/* A Co-Simulation instance (in->c, NULL if refused) logging into in->log. */
static inline fmi2Component host2_instantiate(host2_inst *in, const host2_fmu *f, const char *name)
{
    memset(in, 0, sizeof *in);
    in->f = f;
    in->cb = host2_callbacks(&in->log);
    in->c = f->api.Instantiate(name, fmi2CoSimulation, f->token, "", &in->cb, fmi2False, fmi2False);
    return in->c;
}

/* Instantiated -> InitializationMode: fmi2SetupExperiment (no tolerance), then
 * fmi2EnterInitializationMode unless the setup was refused. */
static inline fmi2Status host2_enter_init(const host2_fmu *f, fmi2Component c, double start, int stop_defined,
                                          double stop)
{
    fmi2Status st = f->api.SetupExperiment(c, fmi2False, 0.0, start, stop_defined ? fmi2True : fmi2False, stop);
    return st != fmi2OK ? st : f->api.EnterInitializationMode(c);
}

/* A fresh instance in StepComplete at t0 = 0 with the start values (in->c NULL if not). */
static inline fmi2Component host2_start(host2_inst *in, const host2_fmu *f, const char *name)
{
    if (host2_instantiate(in, f, name) != NULL
        && (host2_enter_init(f, in->c, 0.0, 0, 0.0) != fmi2OK || f->api.ExitInitializationMode(in->c) != fmi2OK)) {
        f->api.FreeInstance(in->c);
        in->c = NULL;
    }
    return in->c;
}

static inline void host2_free_instance(host2_inst *in)
{
    if (in->c != NULL)
        in->f->api.FreeInstance(in->c);
    in->c = NULL;
}

static inline fmi2Status host2_step(const host2_fmu *f, fmi2Component c, double t, double H)
{
    return f->api.DoStep(c, t, H, fmi2True);
}

/* The doStep and where it left the FMU (fmi2GetRealStatus(fmi2LastSuccessfulTime)). */
static inline fmi2Status host2_step_out(const host2_fmu *f, fmi2Component c, double t, double H, host_step_result *out)
{
    fmi2Status st = f->api.DoStep(c, t, H, fmi2True);
    memset(out, 0, sizeof *out);
    out->last = -1.0;
    f->api.GetRealStatus(c, fmi2LastSuccessfulTime, &out->last);
    return st;
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

static inline fmi2Status host2_get_state(const host2_fmu *f, fmi2Component c, fmi2FMUstate *s)
{
    return f->api.GetFMUstate(c, s);
}

static inline fmi2Status host2_set_state(const host2_fmu *f, fmi2Component c, fmi2FMUstate s)
{
    return f->api.SetFMUstate(c, s);
}

static inline fmi2Status host2_free_state(const host2_fmu *f, fmi2Component c, fmi2FMUstate *s)
{
    return f->api.FreeFMUstate(c, s);
}

static inline fmi2Status host2_state_size(const host2_fmu *f, fmi2Component c, fmi2FMUstate s, size_t *size)
{
    return f->api.SerializedFMUstateSize(c, s, size);
}

static inline fmi2Status host2_serialize(const host2_fmu *f, fmi2Component c, fmi2FMUstate s, unsigned char *blob,
                                         size_t size)
{
    return f->api.SerializeFMUstate(c, s, (fmi2Byte *)blob, size);
}

static inline fmi2Status host2_deserialize(const host2_fmu *f, fmi2Component c, const unsigned char *blob,
                                           size_t size, fmi2FMUstate *s)
{
    return f->api.DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, s);
}

/* The instance's current state as a serialized blob (malloc'ed, *size set), or NULL. */
static inline unsigned char *host2_snapshot(const host2_fmu *f, fmi2Component c, size_t *size)
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
static inline int host2_same_state(const host2_fmu *f, fmi2Component c, const unsigned char *blob, size_t size)
{
    size_t now_size;
    unsigned char *now = host2_snapshot(f, c, &now_size);
    int same = now != NULL && blob != NULL && now_size == size && memcmp(now, blob, size) == 0;
    free(now);
    return same;
}

/* ------------------------------------------------------------------------ */
/* values (FMI 2.0 has one value per value reference: n_values is FMI 3.0's) */

/* host2_get_reals, host2_set_reals, host2_get_ints ... : f->api.<Get|Set><Type>(c, vr, nvr, values) */
#define HOST2_VALUES(verb, fn, kind, ctype, qual)                                                   \
    static inline fmi2Status host2_##verb##_##kind(const host2_fmu *f, fmi2Component c,             \
                                                   const fmi2ValueReference *vr, size_t nvr,        \
                                                   qual ctype *values, size_t n_values)             \
    {                                                                                               \
        (void)n_values;                                                                             \
        return f->api.fn(c, vr, nvr, values);                                                       \
    }
HOST2_VALUES(get, GetReal, reals, double, )
HOST2_VALUES(set, SetReal, reals, double, const)
HOST2_VALUES(get, GetInteger, ints, fmi2Integer, )
HOST2_VALUES(set, SetInteger, ints, fmi2Integer, const)
HOST2_VALUES(get, GetBoolean, bools, fmi2Boolean, )
HOST2_VALUES(set, SetBoolean, bools, fmi2Boolean, const)
#undef HOST2_VALUES

/* Set one variable of any type from a double. */
static inline fmi2Status host2_set(const host2_fmu *f, fmi2Component c, const host_var *v, double value)
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

static inline fmi2Status host2_set_named(const host2_fmu *f, fmi2Component c, const char *name, double value)
{
    const host_var *v = host_named(f, name, NULL);
    if (v == NULL) {
        host_fail("%s has no variable %s", f->id, name);
        return fmi2Fatal;
    }
    return host2_set(f, c, v, value);
}

/* Every Real output into out[capacity] (in variable order); returns how many, or -1 on fmi2Error
 * or more outputs than capacity (a FAIL). */
static inline int host2_real_outputs(const host2_fmu *f, fmi2Component c, double *out, int capacity)
{
    int i, n = 0;
    for (i = 0; i < f->n_vars; i++) {
        if (f->vars[i].causality != VAR_OUTPUT || f->vars[i].type != VAR_REAL)
            continue;
        if (n >= capacity) {
            host_fail("%s has more than %d Real outputs: the host's buffer is too small", f->id, capacity);
            return -1;
        }
        if (f->api.GetReal(c, &f->vars[i].vr, 1, &out[n]) != fmi2OK)
            return -1;
        n++;
    }
    return n;
}

#endif
