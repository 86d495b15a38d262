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

typedef HOST_FMU_STRUCT(fmi3_api) host3_fmu;

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
/* loading, start, FMU states, values: written once for both versions       */

#define HOSTV(name) host3_##name
#define HOSTV_FMU host3_fmu
#define HOSTV_INST host3_inst
#define HOSTV_C fmi3Instance
#define HOSTV_STATUS fmi3Status
#define HOSTV_OK fmi3OK
#define HOSTV_STATE fmi3FMUState
#define HOSTV_BYTE fmi3Byte
#define HOSTV_API FMI3_API
#define HOSTV_PREFIX "fmi3"
#define HOSTV_GET_STATE GetFMUState
#define HOSTV_SET_STATE SetFMUState
#define HOSTV_FREE_STATE FreeFMUState
#define HOSTV_STATE_SIZE SerializedFMUStateSize
#define HOSTV_SERIALIZE SerializeFMUState
#define HOSTV_DESERIALIZE DeserializeFMUState
#define HOSTV_VR fmi3ValueReference
#define HOSTV_VALUE_TYPES(X) X(Float64, reals, double) X(Int32, ints, fmi3Int32) X(Boolean, bools, fmi3Boolean)
#define HOSTV_VALUES_CALL(fn, c, vr, nvr, values, n_values) fn((c), (vr), (nvr), (values), (n_values))
#include "host_adapter.h"

/* ------------------------------------------------------------------------ */
/* values                                                                    */

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

#endif
