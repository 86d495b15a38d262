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
#include "fmi2_api.h"        /* FMI2_API, fmi2_api */

typedef HOST_FMU_STRUCT(fmi2_api) host2_fmu;

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
/* loading, start, FMU states, values: written once for both versions       */

#define HOSTV(name) host2_##name
#define HOSTV_FMU host2_fmu
#define HOSTV_INST host2_inst
#define HOSTV_C fmi2Component
#define HOSTV_STATUS fmi2Status
#define HOSTV_OK fmi2OK
#define HOSTV_STATE fmi2FMUstate
#define HOSTV_BYTE fmi2Byte
#define HOSTV_API FMI2_API
#define HOSTV_PREFIX "fmi2"
#define HOSTV_GET_STATE GetFMUstate
#define HOSTV_SET_STATE SetFMUstate
#define HOSTV_FREE_STATE FreeFMUstate
#define HOSTV_STATE_SIZE SerializedFMUstateSize
#define HOSTV_SERIALIZE SerializeFMUstate
#define HOSTV_DESERIALIZE DeSerializeFMUstate
#define HOSTV_VR fmi2ValueReference
#define HOSTV_VALUE_TYPES(X) X(Real, reals, double) X(Integer, ints, fmi2Integer) X(Boolean, bools, fmi2Boolean)
/* FMI 2.0 has one value per value reference: n_values is FMI 3.0's */
#define HOSTV_VALUES_CALL(fn, c, vr, nvr, values, n_values) ((void)(n_values), fn((c), (vr), (nvr), (values)))
#include "host_adapter.h"

/* ------------------------------------------------------------------------ */
/* values                                                                    */

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

#endif
