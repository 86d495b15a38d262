/*
 * fmu_negative.c - the negative test suite of the FMUs: everything a careless
 * or hostile host may do, for every FMU given, each case one check line.
 *
 *   matrix     every fmi2 call that takes a component, in each reachable state
 *              of the FMI 2.0 Co-Simulation state machine (Instantiated,
 *              InitializationMode, StepComplete, Terminated, Error): a call the
 *              state machine forbids (or the FMU does not support) returns
 *              fmi2Error, is explained through the logger and changes nothing
 *              (the instance serializes to the same bytes before and after); an
 *              allowed call succeeds
 *   null       NULL for each pointer argument, a NULL component for every
 *              function, garbage components, another FMU's instance, another
 *              instance's FMU state
 *   vr         out-of-range value references, wrong types, outputs and fixed
 *              parameters set, a bad reference after good ones (nothing set)
 *   instantiate  wrong GUIDs (another FMU's too), wrong fmuType, missing name,
 *              missing callbacks (the logger included): NULL, nothing leaked
 *   extreme    extreme finite values (+-DBL_MAX, +-DBL_MIN, +-5e-324, 0, -0,
 *              +-1e300, ...) for every parameter and input, step sizes and
 *              communication points, start and stop times: refused with a
 *              message, or run with every output finite; a refused step leaves
 *              the outputs as they were
 *   free       fmi2FreeInstance in every state, with and without FMU states
 *              still allocated: every block the FMU allocated is freed
 *   edges      the standard at its edges (issue 23): a step size of 0 or below
 *              refused, a positive one that rounds to no sample a no-op; a huge
 *              step refused at once, naming the bound of one doStep's work
 *              (samples, and the terms of the exact creep sum); value arrays
 *              of no value reference; an input beyond its declared range
 *              clamped with one warning and a count at fmi2Terminate;
 *              fmi2FreeFMUstate(c, NULL) ignored; the monitor's warning with
 *              monitor.divergence_samples = 0
 *
 * The oracle of "no NaN/Inf output": every Real output read after an
 * fmi2OK/fmi2Warning step is finite. Allocations go through counting callbacks.
 *
 * usage: fmu_negative MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]
 * (two or more FMUs: the cross-FMU identity cases run between each pair)
 * Prints failures and one summary line per group, then "N passed, M failed".
 */
#include "fmu_host.h"

#include <float.h>
#include <limits.h>
#include <signal.h>
#include <unistd.h>

#define MAX_FMUS 4
static host_fmu fmus[MAX_FMUS];
static int n_fmus;

enum { S_INST, S_INIT, S_STEP, S_TERM, S_ERR, N_STATES };
static const char *const state_names[N_STATES] = {
    "Instantiated", "InitializationMode", "StepComplete", "Terminated", "Error"};
#define M(s) (1 << (s))
#define ALL_STATES (M(S_INST) | M(S_INIT) | M(S_STEP) | M(S_TERM) | M(S_ERR))
#define NEVER 0

#define FMI2_MODE_ERROR 16u     /* the mode field of a serialized state in Error */

/* One live instance with its own log and callbacks. */
typedef struct {
    const host_fmu *f;
    fmi2Component c;
    host_log log;
    fmi2CallbackFunctions cb;
    int k;                      /* samples since t0 = 0 */
} inst_t;

static fmi2Component instantiate(const host_fmu *f, inst_t *in, const char *name)
{
    memset(in, 0, sizeof *in);
    in->f = f;
    in->cb = host_callbacks(&in->log);
    in->c = f->api.Instantiate(name, fmi2CoSimulation, f->guid, "", &in->cb, fmi2False, fmi2False);
    if (in->c != NULL && !host_hold_inputs(f, in->c))
        return NULL;
    return in->c;
}

/* A fresh instance in state s (2 samples done for the states after initialization).
 * Error is entered by restoring a state saved in Error: the serialized
 * StepComplete state with its mode field set to Error (the model data of an
 * instance in Error is the restored start of the failed step, i.e. valid). */
static int enter_state(const host_fmu *f, inst_t *in, int s)
{
    if (instantiate(f, in, state_names[s]) == NULL)
        return 0;
    if (s == S_INST)
        return 1;
    if (f->api.SetupExperiment(in->c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK
        || f->api.EnterInitializationMode(in->c) != fmi2OK)
        return 0;
    if (s == S_INIT)
        return 1;
    if (f->api.ExitInitializationMode(in->c) != fmi2OK || f->api.DoStep(in->c, 0.0, 2 * f->h, fmi2True) > fmi2Warning)
        return 0;
    in->k = 2;
    if (s == S_STEP)
        return 1;
    if (s == S_TERM)
        return f->api.Terminate(in->c) <= fmi2Warning;
    {
        size_t size;
        unsigned char *blob = host_snapshot(f, in->c, &size);
        fmi2FMUstate st = NULL;
        int ok;
        if (blob == NULL)
            return 0;
        blob[BLOB_OFF_MODE] = FMI2_MODE_ERROR;
        blob_reseal(blob, size);
        ok = f->api.DeSerializeFMUstate(in->c, (const fmi2Byte *)blob, size, &st) == fmi2OK
             && f->api.SetFMUstate(in->c, st) == fmi2OK && f->api.FreeFMUstate(in->c, &st) == fmi2OK
             && f->api.DoStep(in->c, 2 * f->h, f->h, fmi2True) == fmi2Error
             && strstr(in->log.last_error, "state Error") != NULL;
        free(blob);
        host_log_clear(&in->log);
        return ok;
    }
}

static void leave(inst_t *in)
{
    if (in->c != NULL)
        in->f->api.FreeInstance(in->c);
    in->c = NULL;
}

/* ------------------------------------------------------------------------ */
/* the call matrix                                                           */

/* What a call may use: a state and a blob of the instance, made before it. */
typedef struct {
    fmi2FMUstate state;
    unsigned char *blob;
    size_t blob_size;
} call_ctx;

typedef fmi2Status (*call_fn)(inst_t *in, call_ctx *x);

typedef struct {
    const char *name;
    int allowed;                /* states in which the call succeeds */
    call_fn call;
    int needs;                  /* 0, or which variable kind it needs (see needs_var) */
} call_case;

/* NEEDS_INPUT: skipped without a Real input; NEEDS_SET_INT/BOOL: without an
 * Integer/Boolean parameter the setter is called with nvr = 0, which only tests
 * the state (allowed wherever any setter is: Instantiated, Init, StepComplete). */
enum { NEEDS_NONE, NEEDS_INPUT, NEEDS_SET_INT, NEEDS_SET_BOOL };

static double scratch_real[64];
static fmi2Integer scratch_int[64];
static fmi2Boolean scratch_bool[64];
static fmi2String scratch_str[64];
static fmi2ValueReference scratch_vr[64];

static const host_var *first(const host_fmu *f, int causality, int type)
{
    return host_find(f, causality, type);
}

static fmi2Status c_set_debug_logging(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.SetDebugLogging(in->c, fmi2False, 0, NULL);
}
static fmi2Status c_setup(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.SetupExperiment(in->c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
}
static fmi2Status c_enter_init(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.EnterInitializationMode(in->c);
}
static fmi2Status c_exit_init(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.ExitInitializationMode(in->c);
}
static fmi2Status c_terminate(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.Terminate(in->c);
}
static fmi2Status c_reset(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.Reset(in->c);
}
static fmi2Status c_get_real(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_OUTPUT, VAR_REAL);
    (void)x;
    return in->f->api.GetReal(in->c, &v->vr, 1, scratch_real);
}
static fmi2Status c_get_integer(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_INTEGER);
    (void)x;
    return in->f->api.GetInteger(in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, scratch_int);
}
static fmi2Status c_get_boolean(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_BOOLEAN);
    (void)x;
    return in->f->api.GetBoolean(in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, scratch_bool);
}
static fmi2Status c_get_string(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.GetString(in->c, scratch_vr, 0, scratch_str);
}
static fmi2Status c_set_real_parameter(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_REAL);
    (void)x;
    return in->f->api.SetReal(in->c, &v->vr, 1, &v->start);
}
static fmi2Status c_set_real_input(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_INPUT, VAR_REAL);
    double value = 0.5;
    (void)x;
    return in->f->api.SetReal(in->c, &v->vr, 1, &value);
}
static fmi2Status c_set_integer(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_INTEGER);
    fmi2Integer value = v ? (fmi2Integer)v->start : 0;
    (void)x;
    return in->f->api.SetInteger(in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, &value);
}
static fmi2Status c_set_boolean(inst_t *in, call_ctx *x)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_BOOLEAN);
    fmi2Boolean value = v && v->start != 0.0 ? fmi2True : fmi2False;
    (void)x;
    return in->f->api.SetBoolean(in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, &value);
}
static fmi2Status c_set_string(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.SetString(in->c, scratch_vr, 0, scratch_str);
}
static fmi2Status c_get_fmu_state(inst_t *in, call_ctx *x)
{
    fmi2FMUstate s = NULL;
    fmi2Status st = in->f->api.GetFMUstate(in->c, &s);
    (void)x;
    if (s != NULL)
        in->f->api.FreeFMUstate(in->c, &s);
    return st;
}
static fmi2Status c_set_fmu_state(inst_t *in, call_ctx *x)
{
    return in->f->api.SetFMUstate(in->c, x->state);
}
static fmi2Status c_free_fmu_state(inst_t *in, call_ctx *x)
{
    return in->f->api.FreeFMUstate(in->c, &x->state);
}
static fmi2Status c_state_size(inst_t *in, call_ctx *x)
{
    size_t size = 0;
    return in->f->api.SerializedFMUstateSize(in->c, x->state, &size);
}
static fmi2Status c_serialize(inst_t *in, call_ctx *x)
{
    unsigned char buf[1 << 14];
    size_t size = 0;
    if (in->f->api.SerializedFMUstateSize(in->c, x->state, &size) != fmi2OK || size > sizeof buf)
        size = sizeof buf;
    return in->f->api.SerializeFMUstate(in->c, x->state, (fmi2Byte *)buf, size);
}
static fmi2Status c_deserialize(inst_t *in, call_ctx *x)
{
    fmi2FMUstate s = NULL;
    fmi2Status st = in->f->api.DeSerializeFMUstate(in->c, (const fmi2Byte *)x->blob, x->blob_size, &s);
    if (s != NULL)
        in->f->api.FreeFMUstate(in->c, &s);
    return st;
}
static fmi2Status c_directional_derivative(inst_t *in, call_ctx *x)
{
    fmi2ValueReference u = 0, k = 0;
    double dk = 1.0, du = 0.0;
    (void)x;
    return in->f->api.GetDirectionalDerivative(in->c, &u, 1, &k, 1, &dk, &du);
}
static fmi2Status c_set_input_derivatives(inst_t *in, call_ctx *x)
{
    fmi2ValueReference vr = 0;
    fmi2Integer order = 1;
    double value = 1.0;
    (void)x;
    return in->f->api.SetRealInputDerivatives(in->c, &vr, 1, &order, &value);
}
static fmi2Status c_get_output_derivatives(inst_t *in, call_ctx *x)
{
    fmi2ValueReference vr = 0;
    fmi2Integer order = 1;
    double value = 0.0;
    (void)x;
    return in->f->api.GetRealOutputDerivatives(in->c, &vr, 1, &order, &value);
}
static fmi2Status c_do_step(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.DoStep(in->c, in->k * in->f->h, in->f->h, fmi2True);
}
static fmi2Status c_cancel_step(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.CancelStep(in->c);
}
static fmi2Status c_get_status(inst_t *in, call_ctx *x)
{
    fmi2Status value;
    (void)x;
    return in->f->api.GetStatus(in->c, fmi2DoStepStatus, &value);
}
static fmi2Status c_get_real_status(inst_t *in, call_ctx *x)
{
    double value;
    (void)x;
    return in->f->api.GetRealStatus(in->c, fmi2LastSuccessfulTime, &value);
}
static fmi2Status c_get_integer_status(inst_t *in, call_ctx *x)
{
    fmi2Integer value;
    (void)x;
    return in->f->api.GetIntegerStatus(in->c, fmi2DoStepStatus, &value);
}
static fmi2Status c_get_boolean_status(inst_t *in, call_ctx *x)
{
    fmi2Boolean value;
    (void)x;
    return in->f->api.GetBooleanStatus(in->c, fmi2Terminated, &value);
}
static fmi2Status c_get_string_status(inst_t *in, call_ctx *x)
{
    fmi2String value;
    (void)x;
    return in->f->api.GetStringStatus(in->c, fmi2PendingStatus, &value);
}
static fmi2Status c_enter_event_mode(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.EnterEventMode(in->c);
}
static fmi2Status c_new_discrete_states(inst_t *in, call_ctx *x)
{
    fmi2EventInfo info;
    (void)x;
    return in->f->api.NewDiscreteStates(in->c, &info);
}
static fmi2Status c_enter_continuous_time_mode(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.EnterContinuousTimeMode(in->c);
}
static fmi2Status c_completed_integrator_step(inst_t *in, call_ctx *x)
{
    fmi2Boolean event = fmi2False, terminate = fmi2False;
    (void)x;
    return in->f->api.CompletedIntegratorStep(in->c, fmi2True, &event, &terminate);
}
static fmi2Status c_set_time(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.SetTime(in->c, 0.0);
}
static fmi2Status c_set_continuous_states(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.SetContinuousStates(in->c, scratch_real, 1);
}
static fmi2Status c_get_derivatives(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.GetDerivatives(in->c, scratch_real, 1);
}
static fmi2Status c_get_event_indicators(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.GetEventIndicators(in->c, scratch_real, 1);
}
static fmi2Status c_get_continuous_states(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.GetContinuousStates(in->c, scratch_real, 1);
}
static fmi2Status c_get_nominals(inst_t *in, call_ctx *x)
{
    (void)x;
    return in->f->api.GetNominalsOfContinuousStates(in->c, scratch_real, 1);
}

#define GETTERS (M(S_INIT) | M(S_STEP) | M(S_TERM) | M(S_ERR))
#define SETTERS_PARAMETER (M(S_INST) | M(S_INIT))
#define SETTERS_INPUT (M(S_INST) | M(S_INIT) | M(S_STEP))

/* FMI 2.0 section 4.2.4 (Co-Simulation state machine) with this FMU's
 * capabilities: no directional or input/output derivatives, no asynchronous
 * steps (no status kinds but fmi2LastSuccessfulTime and fmi2Terminated), not
 * Model Exchange. Get/SetXXX with no value reference (nvr = 0) only test the state. */
static const call_case calls[] = {
    {"fmi2SetDebugLogging", ALL_STATES, c_set_debug_logging, NEEDS_NONE},
    {"fmi2SetupExperiment", M(S_INST), c_setup, NEEDS_NONE},
    {"fmi2EnterInitializationMode", M(S_INST), c_enter_init, NEEDS_NONE},
    {"fmi2ExitInitializationMode", M(S_INIT), c_exit_init, NEEDS_NONE},
    {"fmi2Terminate", M(S_STEP), c_terminate, NEEDS_NONE},
    {"fmi2Reset", ALL_STATES, c_reset, NEEDS_NONE},
    {"fmi2GetReal(output)", GETTERS, c_get_real, NEEDS_NONE},
    {"fmi2GetInteger", GETTERS, c_get_integer, NEEDS_NONE},
    {"fmi2GetBoolean", GETTERS, c_get_boolean, NEEDS_NONE},
    {"fmi2GetString(nvr = 0)", GETTERS, c_get_string, NEEDS_NONE},
    {"fmi2SetReal(parameter)", SETTERS_PARAMETER, c_set_real_parameter, NEEDS_NONE},
    {"fmi2SetReal(input)", SETTERS_INPUT, c_set_real_input, NEEDS_INPUT},
    {"fmi2SetInteger(parameter)", SETTERS_PARAMETER, c_set_integer, NEEDS_SET_INT},
    {"fmi2SetBoolean(parameter)", SETTERS_PARAMETER, c_set_boolean, NEEDS_SET_BOOL},
    {"fmi2SetString(nvr = 0)", SETTERS_INPUT, c_set_string, NEEDS_NONE},
    {"fmi2GetFMUstate", ALL_STATES, c_get_fmu_state, NEEDS_NONE},
    {"fmi2SetFMUstate", ALL_STATES, c_set_fmu_state, NEEDS_NONE},
    {"fmi2FreeFMUstate", ALL_STATES, c_free_fmu_state, NEEDS_NONE},
    {"fmi2SerializedFMUstateSize", ALL_STATES, c_state_size, NEEDS_NONE},
    {"fmi2SerializeFMUstate", ALL_STATES, c_serialize, NEEDS_NONE},
    {"fmi2DeSerializeFMUstate", ALL_STATES, c_deserialize, NEEDS_NONE},
    {"fmi2GetDirectionalDerivative", NEVER, c_directional_derivative, NEEDS_NONE},
    {"fmi2SetRealInputDerivatives", NEVER, c_set_input_derivatives, NEEDS_NONE},
    {"fmi2GetRealOutputDerivatives", NEVER, c_get_output_derivatives, NEEDS_NONE},
    {"fmi2DoStep", M(S_STEP), c_do_step, NEEDS_NONE},
    {"fmi2CancelStep", NEVER, c_cancel_step, NEEDS_NONE},
    {"fmi2GetStatus(fmi2DoStepStatus)", NEVER, c_get_status, NEEDS_NONE},
    {"fmi2GetRealStatus(fmi2LastSuccessfulTime)", M(S_STEP) | M(S_TERM), c_get_real_status, NEEDS_NONE},
    {"fmi2GetIntegerStatus", NEVER, c_get_integer_status, NEEDS_NONE},
    {"fmi2GetBooleanStatus(fmi2Terminated)", M(S_STEP) | M(S_TERM), c_get_boolean_status, NEEDS_NONE},
    {"fmi2GetStringStatus", NEVER, c_get_string_status, NEEDS_NONE},
    {"fmi2EnterEventMode", NEVER, c_enter_event_mode, NEEDS_NONE},
    {"fmi2NewDiscreteStates", NEVER, c_new_discrete_states, NEEDS_NONE},
    {"fmi2EnterContinuousTimeMode", NEVER, c_enter_continuous_time_mode, NEEDS_NONE},
    {"fmi2CompletedIntegratorStep", NEVER, c_completed_integrator_step, NEEDS_NONE},
    {"fmi2SetTime", NEVER, c_set_time, NEEDS_NONE},
    {"fmi2SetContinuousStates", NEVER, c_set_continuous_states, NEEDS_NONE},
    {"fmi2GetDerivatives", NEVER, c_get_derivatives, NEEDS_NONE},
    {"fmi2GetEventIndicators", NEVER, c_get_event_indicators, NEEDS_NONE},
    {"fmi2GetContinuousStates", NEVER, c_get_continuous_states, NEEDS_NONE},
    {"fmi2GetNominalsOfContinuousStates", NEVER, c_get_nominals, NEEDS_NONE},
};
#define N_CALLS ((int)(sizeof calls / sizeof calls[0]))

static int group_passed, group_failed;

static int case_check(int condition, const char *fmt, ...)
{
    va_list ap;
    char text[1024];
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    if (condition)
        group_passed++;
    else
        group_failed++;
    return check(condition, "%s", text);
}

static void group_start(void)
{
    group_passed = group_failed = 0;
}

static void group_end(const char *group, const char *what)
{
    printf("group %-12s %-50s %d cases, %d failed\n", group, what, group_passed + group_failed, group_failed);
}

static void matrix(const host_fmu *f)
{
    int s, i;
    group_start();
    for (s = 0; s < N_STATES; s++) {
        for (i = 0; i < N_CALLS; i++) {
            const call_case *cc = &calls[i];
            inst_t in;
            call_ctx x;
            unsigned char *before;
            size_t before_size;
            fmi2Status st;
            int allowed_mask = cc->allowed, allowed;
            if (cc->needs == NEEDS_INPUT && first(f, VAR_INPUT, VAR_REAL) == NULL)
                continue;
            if ((cc->needs == NEEDS_SET_INT && first(f, VAR_PARAMETER, VAR_INTEGER) == NULL)
                || (cc->needs == NEEDS_SET_BOOL && first(f, VAR_PARAMETER, VAR_BOOLEAN) == NULL))
                allowed_mask = SETTERS_INPUT;
            allowed = (allowed_mask & M(s)) != 0;
            memset(&x, 0, sizeof x);
            if (!case_check(enter_state(f, &in, s), "%s: reach %s", f->id, state_names[s])) {
                leave(&in);
                continue;
            }
            f->api.GetFMUstate(in.c, &x.state);
            x.blob = host_snapshot(f, in.c, &x.blob_size);
            before = host_snapshot(f, in.c, &before_size);
            host_log_clear(&in.log);
            st = cc->call(&in, &x);
            if (allowed)
                case_check(st == fmi2OK || st == fmi2Warning, "%s in %s: %s is allowed (status %d: %s)", f->id,
                           state_names[s], cc->name, (int)st, in.log.last_error);
            else
                case_check(st == fmi2Error && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size),
                           "%s in %s: %s returns fmi2Error, says why, changes nothing (status %d: %s)", f->id,
                           state_names[s], cc->name, (int)st, in.log.last_error);
            if (x.state != NULL)
                f->api.FreeFMUstate(in.c, &x.state);
            free(x.blob);
            free(before);
            leave(&in);
        }
    }
    group_end("matrix", f->id);
}

/* ------------------------------------------------------------------------ */
/* NULL and foreign arguments                                                */

/* Calls every function that takes a component on c with harmless other
 * arguments; each must return fmi2Error (FreeInstance must not crash). */
static void every_function_refuses(const host_fmu *f, fmi2Component c, const char *what)
{
    fmi2ValueReference vr = 0;
    double real = 0.0;
    fmi2Integer integer = 0;
    fmi2Boolean boolean = fmi2False;
    fmi2String string = "";
    fmi2FMUstate state = NULL;
    fmi2Status status;
    fmi2EventInfo info;
    size_t size = 0;
    unsigned char buf[256];
    memset(buf, 0, sizeof buf);
#define REFUSES(call) case_check((call) == fmi2Error, "%s: %s refuses %s", f->id, #call, what)
    REFUSES(f->api.SetDebugLogging(c, fmi2True, 0, NULL));
    REFUSES(f->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    REFUSES(f->api.EnterInitializationMode(c));
    REFUSES(f->api.ExitInitializationMode(c));
    REFUSES(f->api.Terminate(c));
    REFUSES(f->api.Reset(c));
    REFUSES(f->api.GetReal(c, &vr, 1, &real));
    REFUSES(f->api.GetInteger(c, &vr, 1, &integer));
    REFUSES(f->api.GetBoolean(c, &vr, 1, &boolean));
    REFUSES(f->api.GetString(c, &vr, 1, &string));
    REFUSES(f->api.SetReal(c, &vr, 1, &real));
    REFUSES(f->api.SetInteger(c, &vr, 1, &integer));
    REFUSES(f->api.SetBoolean(c, &vr, 1, &boolean));
    REFUSES(f->api.SetString(c, &vr, 1, &string));
    REFUSES(f->api.GetFMUstate(c, &state));
    REFUSES(f->api.SetFMUstate(c, state));
    REFUSES(f->api.FreeFMUstate(c, &state));
    REFUSES(f->api.SerializedFMUstateSize(c, state, &size));
    REFUSES(f->api.SerializeFMUstate(c, state, (fmi2Byte *)buf, sizeof buf));
    REFUSES(f->api.DeSerializeFMUstate(c, (const fmi2Byte *)buf, sizeof buf, &state));
    REFUSES(f->api.GetDirectionalDerivative(c, &vr, 1, &vr, 1, &real, &real));
    REFUSES(f->api.SetRealInputDerivatives(c, &vr, 1, &integer, &real));
    REFUSES(f->api.GetRealOutputDerivatives(c, &vr, 1, &integer, &real));
    REFUSES(f->api.DoStep(c, 0.0, f->h, fmi2True));
    REFUSES(f->api.CancelStep(c));
    REFUSES(f->api.GetStatus(c, fmi2DoStepStatus, &status));
    REFUSES(f->api.GetRealStatus(c, fmi2LastSuccessfulTime, &real));
    REFUSES(f->api.GetIntegerStatus(c, fmi2DoStepStatus, &integer));
    REFUSES(f->api.GetBooleanStatus(c, fmi2Terminated, &boolean));
    REFUSES(f->api.GetStringStatus(c, fmi2PendingStatus, &string));
    REFUSES(f->api.EnterEventMode(c));
    REFUSES(f->api.NewDiscreteStates(c, &info));
    REFUSES(f->api.EnterContinuousTimeMode(c));
    REFUSES(f->api.CompletedIntegratorStep(c, fmi2True, &boolean, &boolean));
    REFUSES(f->api.SetTime(c, 0.0));
    REFUSES(f->api.SetContinuousStates(c, &real, 1));
    REFUSES(f->api.GetDerivatives(c, &real, 1));
    REFUSES(f->api.GetEventIndicators(c, &real, 1));
    REFUSES(f->api.GetContinuousStates(c, &real, 1));
    REFUSES(f->api.GetNominalsOfContinuousStates(c, &real, 1));
#undef REFUSES
    f->api.FreeInstance(c);
    case_check(state == NULL, "%s: no FMU state came out of %s", f->id, what);
}

/* Each NULL pointer argument of a call allowed in StepComplete: fmi2Error, a
 * message, no change. */
static void null_arguments(const host_fmu *f)
{
    inst_t in;
    fmi2FMUstate state = NULL, null_state = NULL;
    unsigned char *blob, *before;
    size_t blob_size = 0, before_size = 0, size = 0;
    const host_var *out = first(f, VAR_OUTPUT, VAR_REAL);
    fmi2ValueReference vr = out->vr;
    double real[4] = {0};
    fmi2Integer integer[4] = {0};
    fmi2Boolean boolean[4] = {0};
    fmi2String strings[4] = {NULL};
    fmi2String null_category[1] = {NULL};
    fmi2Status status;
    unsigned char buf[1 << 14];
    group_start();
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach StepComplete", f->id))
        return;
    f->api.GetFMUstate(in.c, &state);
    blob = host_snapshot(f, in.c, &blob_size);
    before = host_snapshot(f, in.c, &before_size);
#define NULL_REFUSED(call)                                                                      \
    do {                                                                                        \
        host_log_clear(&in.log);                                                                \
        case_check((call) == fmi2Error && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size), \
                   "%s: %s is refused with a message, nothing changed (%s)", f->id, #call, in.log.last_error); \
    } while (0)
    NULL_REFUSED(f->api.GetReal(in.c, NULL, 1, real));
    NULL_REFUSED(f->api.GetReal(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.GetInteger(in.c, NULL, 1, integer));
    NULL_REFUSED(f->api.GetInteger(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.GetBoolean(in.c, NULL, 1, boolean));
    NULL_REFUSED(f->api.GetBoolean(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.GetString(in.c, NULL, 1, strings));
    NULL_REFUSED(f->api.GetString(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.SetReal(in.c, NULL, 1, real));
    NULL_REFUSED(f->api.SetReal(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.SetInteger(in.c, NULL, 1, integer));
    NULL_REFUSED(f->api.SetInteger(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.SetBoolean(in.c, NULL, 1, boolean));
    NULL_REFUSED(f->api.SetBoolean(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.SetString(in.c, NULL, 1, strings));
    NULL_REFUSED(f->api.SetString(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.GetFMUstate(in.c, NULL));
    NULL_REFUSED(f->api.SetFMUstate(in.c, NULL));
    NULL_REFUSED(f->api.SerializedFMUstateSize(in.c, NULL, &size));
    NULL_REFUSED(f->api.SerializedFMUstateSize(in.c, state, NULL));
    NULL_REFUSED(f->api.SerializeFMUstate(in.c, NULL, (fmi2Byte *)buf, sizeof buf));
    NULL_REFUSED(f->api.SerializeFMUstate(in.c, state, NULL, sizeof buf));
    NULL_REFUSED(f->api.SerializeFMUstate(in.c, state, (fmi2Byte *)buf, 0));
    NULL_REFUSED(f->api.DeSerializeFMUstate(in.c, NULL, blob_size, &null_state));
    NULL_REFUSED(f->api.DeSerializeFMUstate(in.c, (const fmi2Byte *)blob, blob_size, NULL));
    NULL_REFUSED(f->api.DeSerializeFMUstate(in.c, (const fmi2Byte *)blob, 0, &null_state));
    NULL_REFUSED(f->api.SetDebugLogging(in.c, fmi2True, 1, NULL));
    NULL_REFUSED(f->api.SetDebugLogging(in.c, fmi2True, 1, null_category));
    NULL_REFUSED(f->api.GetStatus(in.c, fmi2DoStepStatus, NULL));
    NULL_REFUSED(f->api.GetRealStatus(in.c, fmi2LastSuccessfulTime, NULL));
    NULL_REFUSED(f->api.GetIntegerStatus(in.c, fmi2DoStepStatus, NULL));
    NULL_REFUSED(f->api.GetBooleanStatus(in.c, fmi2Terminated, NULL));
    NULL_REFUSED(f->api.GetStringStatus(in.c, fmi2PendingStatus, NULL));
    NULL_REFUSED(f->api.GetDirectionalDerivative(in.c, NULL, 1, NULL, 1, NULL, NULL));
    NULL_REFUSED(f->api.SetRealInputDerivatives(in.c, NULL, 1, NULL, NULL));
    NULL_REFUSED(f->api.GetRealOutputDerivatives(in.c, NULL, 1, NULL, NULL));
    NULL_REFUSED(f->api.NewDiscreteStates(in.c, NULL));
    NULL_REFUSED(f->api.CompletedIntegratorStep(in.c, fmi2True, NULL, NULL));
    NULL_REFUSED(f->api.SetContinuousStates(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetDerivatives(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetEventIndicators(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetContinuousStates(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetNominalsOfContinuousStates(in.c, NULL, 1));
#undef NULL_REFUSED
    case_check(null_state == NULL, "%s: no FMU state came out of the refused deserializations", f->id);
    /* freeing a NULL state is a no-op; freeing twice through the cleared handle too */
    case_check(f->api.FreeFMUstate(in.c, &null_state) == fmi2OK, "%s: fmi2FreeFMUstate of a NULL state is a no-op",
               f->id);
    case_check(f->api.FreeFMUstate(in.c, &state) == fmi2OK && state == NULL
                   && f->api.FreeFMUstate(in.c, &state) == fmi2OK,
               "%s: fmi2FreeFMUstate clears the handle, so freeing twice through it is harmless", f->id);
    (void)status;
    free(blob);
    free(before);
    leave(&in);

    /* a NULL component, and components that are not instances at all */
    every_function_refuses(f, NULL, "a NULL component");
    {
        unsigned char *zeros = calloc(1, 1 << 16), *pattern = malloc(1 << 16);
        if (zeros && pattern) {
            memset(pattern, 0xa5, 1 << 16);
            every_function_refuses(f, zeros, "a zeroed block as component");
            every_function_refuses(f, pattern, "a 0xa5-filled block as component");
        }
        free(zeros);
        free(pattern);
    }
    group_end("null", f->id);
}

/* Another FMU's instance through f's functions, and FMU states across instances. */
static void foreign(const host_fmu *f, const host_fmu *g)
{
    inst_t other, mine, second;
    unsigned char *before;
    size_t before_size;
    fmi2FMUstate theirs = NULL, state = NULL;
    char what[160];
    group_start();
    if (!case_check(enter_state(g, &other, S_STEP), "%s: reach StepComplete", g->id))
        return;
    before = host_snapshot(g, other.c, &before_size);
    snprintf(what, sizeof what, "a %s instance", g->id);
    every_function_refuses(f, other.c, what);   /* FreeInstance included: it must not free it */
    case_check(host_same_state(g, other.c, before, before_size)
                   && g->api.DoStep(other.c, 2 * g->h, g->h, fmi2True) <= fmi2Warning,
               "%s: the %s instance is unchanged and still runs after %s's functions refused it", f->id, g->id, f->id);
    g->api.GetFMUstate(other.c, &theirs);
    free(before);

    /* states belong to the instance that made them */
    if (enter_state(f, &mine, S_STEP) && enter_state(f, &second, S_STEP)) {
        unsigned char buf[1 << 14];
        size_t size;
        f->api.GetFMUstate(second.c, &state);
        case_check(f->api.SetFMUstate(mine.c, theirs) == fmi2Error,
                   "%s: fmi2SetFMUstate refuses a %s state", f->id, g->id);
        case_check(f->api.SetFMUstate(mine.c, state) == fmi2Error,
                   "%s: fmi2SetFMUstate refuses a state of another %s instance", f->id, f->id);
        case_check(f->api.SerializedFMUstateSize(mine.c, state, &size) == fmi2Error
                       && f->api.SerializeFMUstate(mine.c, state, (fmi2Byte *)buf, sizeof buf) == fmi2Error,
                   "%s: serializing a state of another instance is refused", f->id);
        {
            size_t blob_size;
            unsigned char *blob = host_snapshot(f, mine.c, &blob_size);
            fmi2FMUstate slot = state;
            case_check(blob != NULL
                           && f->api.DeSerializeFMUstate(mine.c, (const fmi2Byte *)blob, blob_size, &slot) == fmi2Error
                           && slot == state,
                       "%s: deserializing into another instance's state is refused", f->id);
            free(blob);
        }
        case_check(f->api.FreeFMUstate(mine.c, &state) == fmi2Error && state != NULL,
                   "%s: fmi2FreeFMUstate refuses a state of another instance", f->id);
        f->api.FreeFMUstate(second.c, &state);
    }
    leave(&mine);
    leave(&second);
    g->api.FreeFMUstate(other.c, &theirs);
    leave(&other);
    snprintf(what, sizeof what, "%s functions, %s instance", f->id, g->id);
    group_end("foreign", what);
}

/* ------------------------------------------------------------------------ */
/* value references                                                          */

static void value_references(const host_fmu *f)
{
    static const fmi2ValueReference bad[] = {0, 1, 1000, 0x7fffffffu, 0xffffffffu};
    inst_t in;
    unsigned char *before;
    size_t before_size;
    int i, t, n_bad = (int)(sizeof bad / sizeof bad[0]);
    group_start();
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach StepComplete", f->id))
        return;
    before = host_snapshot(f, in.c, &before_size);
#define VR_REFUSED(call, fmt, ...)                                                                      \
    do {                                                                                                \
        host_log_clear(&in.log);                                                                        \
        case_check((call) == fmi2Error && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size), \
                   "%s: " fmt " is refused, nothing changed (%s)", f->id, __VA_ARGS__, in.log.last_error);     \
    } while (0)
    for (i = 0; i < n_bad; i++) {
        /* bad[0], bad[1]: the first references past the last variable */
        fmi2ValueReference vr = i < 2 ? (fmi2ValueReference)f->n_vars + bad[i] : bad[i];
        double real = 1.0;
        fmi2Integer integer = 1;
        fmi2Boolean boolean = fmi2True;
        fmi2String string = "x";
        VR_REFUSED(f->api.GetReal(in.c, &vr, 1, &real), "fmi2GetReal(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.SetReal(in.c, &vr, 1, &real), "fmi2SetReal(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.GetInteger(in.c, &vr, 1, &integer), "fmi2GetInteger(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.SetInteger(in.c, &vr, 1, &integer), "fmi2SetInteger(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.GetBoolean(in.c, &vr, 1, &boolean), "fmi2GetBoolean(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.SetBoolean(in.c, &vr, 1, &boolean), "fmi2SetBoolean(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.GetString(in.c, &vr, 1, &string), "fmi2GetString(vr = %u)", (unsigned)vr);
        VR_REFUSED(f->api.SetString(in.c, &vr, 1, &string), "fmi2SetString(vr = %u)", (unsigned)vr);
    }
    /* every variable through the getters and setters of the other types */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        for (t = 0; t < 3; t++) {
            double real = 0.0;
            fmi2Integer integer = 0;
            fmi2Boolean boolean = fmi2False;
            if (t == v->type)
                continue;
            if (t == VAR_REAL) {
                VR_REFUSED(f->api.GetReal(in.c, &v->vr, 1, &real), "fmi2GetReal(%s)", v->name);
                VR_REFUSED(f->api.SetReal(in.c, &v->vr, 1, &real), "fmi2SetReal(%s)", v->name);
            } else if (t == VAR_INTEGER) {
                VR_REFUSED(f->api.GetInteger(in.c, &v->vr, 1, &integer), "fmi2GetInteger(%s)", v->name);
                VR_REFUSED(f->api.SetInteger(in.c, &v->vr, 1, &integer), "fmi2SetInteger(%s)", v->name);
            } else {
                VR_REFUSED(f->api.GetBoolean(in.c, &v->vr, 1, &boolean), "fmi2GetBoolean(%s)", v->name);
                VR_REFUSED(f->api.SetBoolean(in.c, &v->vr, 1, &boolean), "fmi2SetBoolean(%s)", v->name);
            }
        }
        /* outputs are never set; fixed parameters not after initialization */
        if (v->causality != VAR_INPUT)
            VR_REFUSED(host_set(f, in.c, v, v->start + 1.0), "setting %s %s in StepComplete",
                       v->causality == VAR_OUTPUT ? "output" : "parameter", v->name);
    }
    /* a good reference followed by a bad one: the good one is not set either */
    {
        const host_var *input = first(f, VAR_INPUT, VAR_REAL);
        const host_var *param = first(f, VAR_PARAMETER, VAR_REAL);
        fmi2ValueReference pair[2];
        double values[2] = {0.75, 0.75};
        pair[0] = input ? input->vr : param->vr;
        pair[1] = (fmi2ValueReference)f->n_vars;
        VR_REFUSED(f->api.SetReal(in.c, pair, 2, values), "fmi2SetReal(%s, vr = %u) in one call",
                   input ? input->name : param->name, (unsigned)pair[1]);
        if (input) {
            values[1] = NAN;
            pair[1] = input->vr;
            VR_REFUSED(f->api.SetReal(in.c, pair, 2, values), "fmi2SetReal(%s = 0.75, %s = NaN) in one call",
                       input->name, input->name);
        }
    }
#undef VR_REFUSED
    free(before);
    leave(&in);
    group_end("vr", f->id);
}

/* ------------------------------------------------------------------------ */
/* instantiation                                                             */

static void instantiation(const host_fmu *f)
{
    host_log log;
    fmi2CallbackFunctions cb = host_callbacks(&log), partial;
    long blocks = atomic_load(&host_live_blocks);
    char guid[80];
    int i;
    group_start();
#define NOT_INSTANTIATED(name, type, guid_arg, callbacks, fmt, ...)                                         \
    do {                                                                                                    \
        fmi2Component c;                                                                                    \
        host_log_clear(&log);                                                                               \
        c = f->api.Instantiate(name, type, guid_arg, "", callbacks, fmi2False, fmi2False);                  \
        case_check(c == NULL, "%s: fmi2Instantiate with " fmt " returns NULL (%s)", f->id, __VA_ARGS__,      \
                   log.last_error);                                                                          \
        if (c != NULL)                                                                                      \
            f->api.FreeInstance(c);                                                                         \
    } while (0)
    NOT_INSTANTIATED("x", fmi2CoSimulation, "{00000000-0000-0000-0000-000000000000}", &cb, "%s", "a wrong GUID");
    NOT_INSTANTIATED("x", fmi2CoSimulation, "", &cb, "%s", "an empty GUID");
    NOT_INSTANTIATED("x", fmi2CoSimulation, NULL, &cb, "%s", "a NULL GUID");
    for (i = 0; i < n_fmus; i++)
        if (&fmus[i] != f)
            NOT_INSTANTIATED("x", fmi2CoSimulation, fmus[i].guid, &cb, "the GUID of %s", fmus[i].id);
    snprintf(guid, sizeof guid, "%s", f->guid);
    guid[strlen(guid) - 1] = '\0';
    NOT_INSTANTIATED("x", fmi2CoSimulation, guid, &cb, "%s", "its GUID without the closing brace");
    snprintf(guid, sizeof guid, "%s ", f->guid);
    NOT_INSTANTIATED("x", fmi2CoSimulation, guid, &cb, "%s", "its GUID and a trailing space");
    snprintf(guid, sizeof guid, "%s", f->guid);
    for (i = 0; guid[i]; i++)
        if (guid[i] >= 'a' && guid[i] <= 'f')
            guid[i] = (char)(guid[i] - 'a' + 'A');
    NOT_INSTANTIATED("x", fmi2CoSimulation, guid, &cb, "%s", "its GUID in upper case");
    NOT_INSTANTIATED("x", fmi2ModelExchange, f->guid, &cb, "%s", "fmuType = fmi2ModelExchange");
    NOT_INSTANTIATED("x", (fmi2Type)2, f->guid, &cb, "%s", "fmuType = 2");
    NOT_INSTANTIATED("x", (fmi2Type)-1, f->guid, &cb, "%s", "fmuType = -1");
    NOT_INSTANTIATED(NULL, fmi2CoSimulation, f->guid, &cb, "%s", "a NULL instance name");
    NOT_INSTANTIATED("", fmi2CoSimulation, f->guid, &cb, "%s", "an empty instance name");
    NOT_INSTANTIATED("x", fmi2CoSimulation, f->guid, NULL, "%s", "NULL callbacks");
    partial = cb;
    partial.allocateMemory = NULL;
    NOT_INSTANTIATED("x", fmi2CoSimulation, f->guid, &partial, "%s", "no allocateMemory");
    partial = cb;
    partial.freeMemory = NULL;
    NOT_INSTANTIATED("x", fmi2CoSimulation, f->guid, &partial, "%s", "no freeMemory");
    partial = cb;
    partial.logger = NULL;
    NOT_INSTANTIATED("x", fmi2CoSimulation, f->guid, &partial, "%s", "no logger");
#undef NOT_INSTANTIATED
    case_check(atomic_load(&host_live_blocks) == blocks, "%s: the refused instantiations allocated nothing", f->id);
    {
        /* and the refusals said why (all but the two without a logger to say it to) */
        fmi2Component c;
        host_log_clear(&log);
        c = f->api.Instantiate("x", fmi2CoSimulation, "{wrong}", "", &cb, fmi2False, fmi2False);
        case_check(c == NULL && strstr(log.last_error, "wrong GUID") != NULL,
                   "%s: a wrong GUID is explained (%s)", f->id, log.last_error);
    }
    group_end("instantiate", f->id);
}

/* ------------------------------------------------------------------------ */
/* extreme finite values                                                     */

static const double extreme_reals[] = {
    DBL_MAX, -DBL_MAX, 1e308, -1e308, 1e300, -1e300, DBL_MIN, -DBL_MIN,
    4.9406564584124654e-324, -4.9406564584124654e-324, 1e-300, 0.0, -0.0, 1e6, -1e6};
#define N_EXTREME_REALS ((int)(sizeof extreme_reals / sizeof extreme_reals[0]))
static const int extreme_ints[] = {INT_MIN, -1000001, -1, 0, 1, 2, 8, 9, 16, 17, 33, 1000001, INT_MAX};
#define N_EXTREME_INTS ((int)(sizeof extreme_ints / sizeof extreme_ints[0]))

/* Runs n single-sample steps; every fmi2OK/fmi2Warning step must leave finite
 * outputs; a refused step (fmi2Error) must leave the outputs as they were. */
static int run_checked(inst_t *in, int n, char *why, size_t why_size)
{
    const host_fmu *f = in->f;
    double before[32], after[32];
    int i, n_out;
    n_out = host_real_outputs(f, in->c, before);
    if (n_out < 0) {
        snprintf(why, why_size, "outputs not readable: %s", in->log.last_error);
        return 0;
    }
    if (!all_finite(before, n_out)) {
        snprintf(why, why_size, "non-finite output before stepping");
        return 0;
    }
    for (i = 0; i < n; i++) {
        fmi2Status st = f->api.DoStep(in->c, in->k * f->h, f->h, fmi2True);
        if (st == fmi2Error) {
            if (host_real_outputs(f, in->c, after) != n_out || memcmp(before, after, (size_t)n_out * sizeof *after)) {
                snprintf(why, why_size, "a refused step changed the outputs");
                return 0;
            }
            snprintf(why, why_size, "refused: %s", in->log.last_error);
            return 1;
        }
        if (st > fmi2Error || host_real_outputs(f, in->c, after) != n_out || !all_finite(after, n_out)) {
            snprintf(why, why_size, "status %d with a non-finite or unreadable output", (int)st);
            return 0;
        }
        memcpy(before, after, sizeof after);
        in->k++;
    }
    snprintf(why, why_size, "ran %d samples, outputs finite", n);
    return 1;
}

/* Initialization outputs (GetReal in InitializationMode): fmi2Error with a
 * message, or finite values. */
static int init_outputs_ok(inst_t *in)
{
    double out[32];
    int n;
    host_log_clear(&in->log);
    n = host_real_outputs(in->f, in->c, out);
    return n < 0 ? in->log.n_errors > 0 : all_finite(out, n);
}

/* One parameter at one value: refused at fmi2ExitInitializationMode with a
 * message naming a parameter and its range, or a run with finite outputs. */
static void parameter_case(const host_fmu *f, const host_var *v, double value, double input)
{
    inst_t in;
    char why[1200] = "";
    int ok = 0, i;
    fmi2Status st;
    if (!enter_state(f, &in, S_INIT)) {
        case_check(0, "%s: reach InitializationMode", f->id);
        leave(&in);
        return;
    }
    st = host_set(f, in.c, v, value);
    if (st != fmi2OK) {
        snprintf(why, sizeof why, "set refused: %s", in.log.last_error);
    } else if (!init_outputs_ok(&in)) {
        snprintf(why, sizeof why, "initialization outputs not finite");
    } else {
        host_log_clear(&in.log);
        st = f->api.ExitInitializationMode(in.c);
        if (st == fmi2Error) {
            ok = strstr(in.log.last_error, "out of range: valid range") != NULL;
            snprintf(why, sizeof why, "refused: %s", in.log.last_error);
        } else if (st == fmi2OK) {
            for (i = 0; i < f->n_vars; i++)
                if (f->vars[i].causality == VAR_INPUT)
                    host_set(f, in.c, &f->vars[i], input);
            ok = run_checked(&in, 8, why, sizeof why);
        } else {
            snprintf(why, sizeof why, "status %d", (int)st);
        }
    }
    case_check(ok, "%s: %s = %g (inputs %g): %s", f->id, v->name, value, input, why);
    leave(&in);
}

static void extreme_values(const host_fmu *f)
{
    int i, j, n;
    group_start();
    /* every parameter at every extreme value, inputs at 1 */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        if (v->causality != VAR_PARAMETER)
            continue;
        if (v->type == VAR_REAL)
            for (j = 0; j < N_EXTREME_REALS; j++)
                parameter_case(f, v, extreme_reals[j], 1.0);
        else if (v->type == VAR_INTEGER)
            for (j = 0; j < N_EXTREME_INTS; j++)
                parameter_case(f, v, (double)extreme_ints[j], 1.0);
        else
            for (j = 0; j < 2; j++)
                parameter_case(f, v, (double)j, 1.0);
    }
    /* Booleans set with values other than fmi2True/fmi2False mean true */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        static const fmi2Boolean odd[] = {2, -1, INT_MAX};
        inst_t in;
        if (v->causality != VAR_PARAMETER || v->type != VAR_BOOLEAN)
            continue;
        for (j = 0; j < 3; j++) {
            fmi2Boolean got = 0;
            enter_state(f, &in, S_INIT);
            case_check(f->api.SetBoolean(in.c, &v->vr, 1, &odd[j]) == fmi2OK
                           && f->api.GetBoolean(in.c, &v->vr, 1, &got) == fmi2OK && got == fmi2True,
                       "%s: fmi2SetBoolean(%s, %d) reads back as fmi2True", f->id, v->name, (int)odd[j]);
            leave(&in);
        }
    }
    /* every input at every extreme value (all inputs alike, then pairs) */
    for (j = 0; j < N_EXTREME_REALS; j++) {
        inst_t in;
        char why[1200];
        if (first(f, VAR_INPUT, VAR_REAL) == NULL)
            break;
        enter_state(f, &in, S_STEP);
        for (i = 0; i < f->n_vars; i++)
            if (f->vars[i].causality == VAR_INPUT)
                host_set(f, in.c, &f->vars[i], extreme_reals[j]);
        case_check(run_checked(&in, 8, why, sizeof why), "%s: every input = %g: %s", f->id, extreme_reals[j], why);
        leave(&in);
    }
    for (n = 0, i = 0; i < f->n_vars; i++)
        n += f->vars[i].causality == VAR_INPUT;
    if (n == 2) {
        int a, b;
        for (a = 0; a < N_EXTREME_REALS; a++)
            for (b = 0; b < N_EXTREME_REALS; b++) {
                inst_t in;
                char why[1200];
                int which = 0;
                enter_state(f, &in, S_STEP);
                for (i = 0; i < f->n_vars; i++)
                    if (f->vars[i].causality == VAR_INPUT)
                        host_set(f, in.c, &f->vars[i], which++ == 0 ? extreme_reals[a] : extreme_reals[b]);
                case_check(run_checked(&in, 4, why, sizeof why), "%s: inputs (%g, %g): %s", f->id, extreme_reals[a],
                           extreme_reals[b], why);
                leave(&in);
            }
    }
    /* step sizes and communication points */
    {
        const double h = f->h, nan_value = NAN, inf = INFINITY;
        struct { double t, H; int ok; } steps[] = {
            {0, 0.0, 0}, {0, -0.0, 0}, {0, DBL_MIN, 1}, {0, 4.9406564584124654e-324, 1}, {0, 1e-12 * 0.0005, 1},
            {0, DBL_MAX, 0}, {0, 1e308, 0}, {0, -DBL_MIN, 0}, {0, -1.0, 0}, {0, -DBL_MAX, 0},
            {0, 0.5, 0}, {0, 1.5, 0}, {0, 1e16, 0}, {0, nan_value, 0}, {0, inf, 0}, {0, -inf, 0},
            {1, 1.0, 0}, {-1, 1.0, 0}, {DBL_MAX, 1.0, 0}, {-DBL_MAX, 1.0, 0}, {nan_value, 1.0, 0},
            {inf, 1.0, 0}, {-inf, 1.0, 0}, {DBL_MIN, 1.0, 1}, {0, 1.0, 1}, {0, 3.0, 1}};
        int n_steps = (int)(sizeof steps / sizeof steps[0]);
        for (i = 0; i < n_steps; i++) {
            inst_t in;
            unsigned char *before;
            size_t before_size;
            double t_at, H, t_after = -1.0;
            fmi2Status st;
            enter_state(f, &in, S_STEP);
            /* t in samples from the current time unless extreme; H in units of h unless extreme */
            t_at = fabs(steps[i].t) >= 1e300 || isnan(steps[i].t) || steps[i].t == DBL_MIN ? steps[i].t
                                                                                               : (in.k + steps[i].t) * h;
            if (steps[i].t == DBL_MIN)
                t_at = in.k * h + DBL_MIN;    /* round-off within the tolerance */
            H = fabs(steps[i].H) >= 0.5 && fabs(steps[i].H) < 1e15 ? steps[i].H * h : steps[i].H;
            before = host_snapshot(f, in.c, &before_size);
            host_log_clear(&in.log);
            st = f->api.DoStep(in.c, t_at, H, fmi2True);
            f->api.GetRealStatus(in.c, fmi2LastSuccessfulTime, &t_after);
            if (steps[i].ok)
                case_check(st <= fmi2Warning && isfinite(t_after), "%s: fmi2DoStep(t = %g, H = %g) passes (t -> %g)",
                           f->id, t_at, H, t_after);
            else
                case_check(st == fmi2Error && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size),
                           "%s: fmi2DoStep(t = %g, H = %g) is refused, nothing changed (%s)", f->id, t_at, H,
                           in.log.last_error);
            free(before);
            leave(&in);
        }
    }
    /* start and stop times */
    {
        static const double starts[] = {DBL_MAX, -DBL_MAX, 1e300, -1e300, 4.9406564584124654e-324, -1e9, 1e15};
        for (i = 0; i < (int)(sizeof starts / sizeof starts[0]); i++) {
            inst_t in;
            char why[1200] = "";
            int ok = 0;
            instantiate(f, &in, "start");
            if (f->api.SetupExperiment(in.c, fmi2False, 0.0, starts[i], fmi2False, 0.0) == fmi2OK
                && f->api.EnterInitializationMode(in.c) == fmi2OK) {
                fmi2Status st = f->api.ExitInitializationMode(in.c);
                if (st == fmi2Error) {
                    ok = in.log.n_errors > 0;
                    snprintf(why, sizeof why, "refused: %s", in.log.last_error);
                } else {
                    /* step from t0 by whole samples: refused when t0 + k h leaves the doubles */
                    double out[32];
                    int n_out, s;
                    ok = 1;
                    for (s = 1; s <= 3 && ok; s++) {
                        st = f->api.DoStep(in.c, starts[i] + (s - 1) * f->h, f->h, fmi2True);
                        n_out = host_real_outputs(f, in.c, out);
                        if (st <= fmi2Warning)
                            ok = n_out >= 0 && all_finite(out, n_out);
                        else
                            break;
                    }
                    snprintf(why, sizeof why, "%s", ok ? "outputs finite or step refused" : "non-finite output");
                }
            }
            case_check(ok, "%s: startTime = %g: %s", f->id, starts[i], why);
            leave(&in);
        }
        {
            struct { double start, stop; int defined; } bad[] = {
                {NAN, 0, 0}, {INFINITY, 0, 0}, {-INFINITY, 0, 0}, {1.0, 0.5, 1}, {0.0, NAN, 1}, {0.0, -DBL_MIN, 1}};
            for (i = 0; i < (int)(sizeof bad / sizeof bad[0]); i++) {
                inst_t in;
                unsigned char *before;
                size_t before_size;
                instantiate(f, &in, "setup");
                before = host_snapshot(f, in.c, &before_size);
                case_check(f->api.SetupExperiment(in.c, fmi2False, 0.0, bad[i].start, bad[i].defined ? fmi2True : fmi2False,
                                                  bad[i].stop) == fmi2Error
                               && host_same_state(f, in.c, before, before_size),
                           "%s: fmi2SetupExperiment(startTime = %g, stopTime = %g) is refused, nothing changed (%s)",
                           f->id, bad[i].start, bad[i].stop, in.log.last_error);
                free(before);
                leave(&in);
            }
        }
    }
    group_end("extreme", f->id);
}

/* ------------------------------------------------------------------------ */
/* fmi2FreeInstance in every state                                           */

static void free_in_every_state(const host_fmu *f)
{
    int s, with_states;
    group_start();
    for (s = 0; s < N_STATES; s++)
        for (with_states = 0; with_states < 2; with_states++) {
            long blocks = atomic_load(&host_live_blocks);
            inst_t in;
            int reached = enter_state(f, &in, s);
            if (reached && with_states) {
                fmi2FMUstate a = NULL, b = NULL, d = NULL;
                size_t size;
                unsigned char *blob = host_snapshot(f, in.c, &size);
                f->api.GetFMUstate(in.c, &a);
                f->api.GetFMUstate(in.c, &b);
                if (blob != NULL)
                    f->api.DeSerializeFMUstate(in.c, (const fmi2Byte *)blob, size, &d);
                free(blob);
                reached = a != NULL && b != NULL && d != NULL;
            }
            leave(&in);
            case_check(reached && atomic_load(&host_live_blocks) == blocks,
                       "%s: fmi2FreeInstance in %s%s frees every block (%ld left)", f->id, state_names[s],
                       with_states ? " with 3 FMU states still allocated" : "",
                       atomic_load(&host_live_blocks) - blocks);
        }
    group_end("free", f->id);
}

/* ------------------------------------------------------------------------ */
/* the standard at its edges (issue 23)                                      */

/* A refusal does no work, so it returns at once: a doStep still running after
 * a minute (a huge step computed instead of refused) ends the host with FAIL. */
static void on_hang(int sig)
{
    static const char text[] = "FAIL a doStep did not return within 60 s: a huge step was computed, not refused\n";
    (void)sig;
    if (write(STDOUT_FILENO, text, sizeof text - 1) < 0)
        _exit(1);
    _exit(1);
}

static fmi2Status step_within_a_minute(inst_t *in, double H)
{
    fmi2Status st;
    signal(SIGALRM, on_hang);
    alarm(60);
    st = in->f->api.DoStep(in->c, in->k * in->f->h, H, fmi2True);
    alarm(0);
    return st;
}

/* The unsigned integer after `key` in text, or 0. */
static unsigned long long number_after(const char *text, const char *key)
{
    const char *p = strstr(text, key);
    return p != NULL ? strtoull(p + strlen(key), NULL, 10) : 0;
}

/* Terms the exact creep sum adds up over n samples when the first sums a
 * (sample k sums its k + 1 past inputs): a + (a + 1) + ... + (a + n - 1). */
static double creep_terms(double n, double a)
{
    return n * a + n * (n - 1.0) / 2.0;
}

/* A step size of 0 or below is refused (FMI 2.0: communicationStepSize > 0);
 * a positive one below 1e-9 h rounds to no sample and is a no-op. */
static void edge_zero_step(const host_fmu *f)
{
    const double refused[] = {0.0, -0.0, -1e-20, -5.6e-17, -f->h};
    const double no_ops[] = {1e-20, 5.6e-17, 1e-10 * f->h};
    inst_t in;
    unsigned char *before;
    size_t before_size, i;
    double t = -1.0;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach StepComplete", f->id))
        return;
    before = host_snapshot(f, in.c, &before_size);
    for (i = 0; i < sizeof refused / sizeof refused[0]; i++) {
        fmi2Status st;
        host_log_clear(&in.log);
        st = f->api.DoStep(in.c, in.k * f->h, refused[i], fmi2True);
        case_check(st == fmi2Error && strstr(in.log.last_error, "communicationStepSize") != NULL
                       && strstr(in.log.last_error, "> 0") != NULL && host_same_state(f, in.c, before, before_size),
                   "%s: fmi2DoStep(H = %g) is refused: the step size must be > 0, nothing changed (%s)", f->id,
                   refused[i], in.log.last_error);
    }
    for (i = 0; i < sizeof no_ops / sizeof no_ops[0]; i++) {
        fmi2Status st;
        host_log_clear(&in.log);
        st = f->api.DoStep(in.c, in.k * f->h, no_ops[i], fmi2True);
        f->api.GetRealStatus(in.c, fmi2LastSuccessfulTime, &t);
        case_check(st == fmi2OK && in.log.n_errors == 0 && t == in.k * f->h
                       && host_same_state(f, in.c, before, before_size),
                   "%s: fmi2DoStep(H = %g) rounds to no sample: a no-op returning fmi2OK (%s)", f->id, no_ops[i],
                   in.log.last_error);
    }
    free(before);
    leave(&in);
}

/* A step of more samples than one doStep may compute is refused at once with
 * the bound; in exact creep mode (work O(k) a sample) the bound on the terms
 * of the creep sum too, with the longest step that passes from here. */
static void edge_huge_step(const host_fmu *f)
{
    inst_t in;
    unsigned char *before;
    size_t before_size;
    unsigned long long bound, terms_bound, longest;
    fmi2Status st;
    double t = -1.0, a;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach StepComplete", f->id))
        return;
    before = host_snapshot(f, in.c, &before_size);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, 1e9);
    f->api.GetRealStatus(in.c, fmi2LastSuccessfulTime, &t);
    bound = number_after(in.log.last_error, "computes at most ");
    case_check(st == fmi2Error && bound > 0 && t == in.k * f->h && host_same_state(f, in.c, before, before_size),
               "%s: fmi2DoStep(H = 1e9 s) is refused at once, naming the bound of one doStep (%s)", f->id,
               in.log.last_error);
    /* the harness steps h, its longest experiments are minutes: they all pass */
    case_check((double)bound * f->h >= 1000.0, "%s: the bound, %llu samples, is at least 1000 s of h = %g s", f->id,
               bound, f->h);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, (double)(bound + 1) * f->h);
    case_check(st == fmi2Error && number_after(in.log.last_error, "computes at most ") == bound
                   && host_same_state(f, in.c, before, before_size),
               "%s: fmi2DoStep of bound + 1 = %llu samples is refused (%s)", f->id, bound + 1, in.log.last_error);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, 1e300);
    case_check(st == fmi2Error && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size),
               "%s: fmi2DoStep(H = 1e300 s) is refused (%s)", f->id, in.log.last_error);
    free(before);
    leave(&in);

    if (host_named(f, "creep.exact") == NULL)
        return;
    /* exact creep: 2 samples done, the next sums a = 3 terms */
    instantiate(f, &in, "exact");
    f->api.SetupExperiment(in.c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    f->api.EnterInitializationMode(in.c);
    host_set_named(f, in.c, "creep.exact", 1.0);
    if (!case_check(f->api.ExitInitializationMode(in.c) == fmi2OK
                        && f->api.DoStep(in.c, 0.0, 2 * f->h, fmi2True) <= fmi2Warning,
                    "%s: exact creep, 2 samples", f->id)) {
        leave(&in);
        return;
    }
    in.k = 2;
    a = 3.0;
    before = host_snapshot(f, in.c, &before_size);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, (double)bound * f->h);
    terms_bound = number_after(in.log.last_error, "sums at most ");
    longest = number_after(in.log.last_error, "a step of at most ");
    case_check(st == fmi2Error && terms_bound > 0 && host_same_state(f, in.c, before, before_size),
               "%s: with creep.exact a step of %llu samples is refused at once, naming the bound on the terms of "
               "the creep sum (%s)", f->id, bound, in.log.last_error);
    /* reference: the closed form of the sum a + (a + 1) + ... */
    case_check(longest >= 1 && creep_terms((double)longest, a) <= (double)terms_bound
                   && creep_terms((double)longest + 1.0, a) > (double)terms_bound,
               "%s: the longest step it names, %llu samples, is the longest whose creep sums stay within %llu terms",
               f->id, longest, terms_bound);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, (double)(longest + 1) * f->h);
    case_check(st == fmi2Error && number_after(in.log.last_error, "sums at most ") == terms_bound
                   && host_same_state(f, in.c, before, before_size),
               "%s: with creep.exact a step of %llu samples is refused (%s)", f->id, longest + 1, in.log.last_error);
    free(before);
    leave(&in);
}

/* FMI 2.0 has no nValues: nvr = 0 needs no arrays, nvr > 0 needs both. */
static void edge_value_counts(const host_fmu *f)
{
    inst_t in;
    fmi2ValueReference vr = first(f, VAR_OUTPUT, VAR_REAL)->vr;
    double real = 0.0;
    unsigned char *before;
    size_t before_size;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach StepComplete", f->id))
        return;
    before = host_snapshot(f, in.c, &before_size);
#define COUNT_CASE(call, text, expected, what)                                                           \
    do {                                                                                                 \
        fmi2Status st_;                                                                                  \
        host_log_clear(&in.log);                                                                         \
        st_ = (call);                                                                                    \
        case_check(st_ == (expected) && (st_ == fmi2OK) == (in.log.n_errors == 0)                        \
                       && host_same_state(f, in.c, before, before_size),                                 \
                   "%s: %s: %s (%s)", f->id, text, what, in.log.last_error);                             \
    } while (0)
#define NO_VR_PASSES(call) COUNT_CASE(call, #call, fmi2OK, "no value reference and no array: nothing to do")
#define NULL_ARRAY_REFUSED(call) COUNT_CASE(call, #call, fmi2Error, "a missing array is refused")
    NO_VR_PASSES(f->api.GetReal(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.GetInteger(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.GetBoolean(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.GetString(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.SetReal(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.SetInteger(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.SetBoolean(in.c, NULL, 0, NULL));
    NO_VR_PASSES(f->api.SetString(in.c, NULL, 0, NULL));
    NULL_ARRAY_REFUSED(f->api.GetReal(in.c, &vr, 1, NULL));
    NULL_ARRAY_REFUSED(f->api.SetReal(in.c, NULL, 1, &real));
#undef NO_VR_PASSES
#undef NULL_ARRAY_REFUSED
#undef COUNT_CASE
    free(before);
    leave(&in);
}

/* One run of n single-sample steps with input v at `value` (set before
 * initialization or after it): the outputs after each step, the statuses,
 * the first warning, fmi2Terminate's status and message, v read back. */
typedef struct {
    double out[8][32];
    int n_out;
    fmi2Status status[8], terminate;
    char first_warning[1024], terminate_message[1024];
    double v_read;
} ranged_run;

static int run_with_input(const host_fmu *f, const host_var *v, double value, int before_init, int n, ranged_run *r)
{
    inst_t in;
    int k;
    memset(r, 0, sizeof *r);
    if (instantiate(f, &in, "range") == NULL)
        return 0;
    if (before_init && f->api.SetReal(in.c, &v->vr, 1, &value) != fmi2OK)
        return leave(&in), 0;
    if (f->api.SetupExperiment(in.c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK
        || f->api.EnterInitializationMode(in.c) != fmi2OK || f->api.ExitInitializationMode(in.c) != fmi2OK
        || (!before_init && f->api.SetReal(in.c, &v->vr, 1, &value) != fmi2OK))
        return leave(&in), 0;
    for (k = 0; k < n; k++) {
        host_log_clear(&in.log);
        r->status[k] = f->api.DoStep(in.c, k * f->h, f->h, fmi2True);
        if (r->status[k] == fmi2Warning && r->first_warning[0] == '\0')
            snprintf(r->first_warning, sizeof r->first_warning, "%s", in.log.last);
        r->n_out = host_real_outputs(f, in.c, r->out[k]);
    }
    f->api.GetReal(in.c, &v->vr, 1, &r->v_read);
    host_log_clear(&in.log);
    r->terminate = f->api.Terminate(in.c);
    snprintf(r->terminate_message, sizeof r->terminate_message, "%s", in.log.last);
    leave(&in);
    return r->n_out > 0;
}

/* An input beyond its declared [min, max] is clamped to it: the run equals the
 * run at the bound (the reference), the first doStep that clamps returns
 * fmi2Warning saying so, and fmi2Terminate reports the count. */
static void edge_input_range(const host_fmu *f)
{
    int i, c, k;
    const int n = 5;
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        char range[96], count[160];
        ranged_run at_bound, beyond;
        struct { double value, bound; int before_init; } cases[] = {
            {0, 0, 0}, {0, 0, 0}, {1e300, 0, 0}, {-1e300, 0, 0}, {DBL_MAX, 0, 0}, {0, 0, 1}};
        if (v->causality != VAR_INPUT || v->type != VAR_REAL || !v->has_min || !v->has_max)
            continue;
        cases[0].value = v->max + 1.5;
        cases[1].value = v->min - 1.5;
        cases[5].value = v->max + 1.5;
        for (c = 0; c < 6; c++)
            cases[c].bound = cases[c].value > v->max ? v->max : v->min;
        snprintf(range, sizeof range, "[%g, %g]", v->min, v->max);
        snprintf(count, sizeof count, "clamped to its declared range %s V in %d of %d samples", range, n, n);
        for (c = 0; c < 6; c++) {
            int same = 1, quiet = 1;
            const char *when = cases[c].before_init ? "set before initialization" : "set in StepComplete";
            if (!case_check(run_with_input(f, v, cases[c].bound, cases[c].before_init, n, &at_bound)
                                && run_with_input(f, v, cases[c].value, cases[c].before_init, n, &beyond),
                            "%s: runs with %s = %g and %g", f->id, v->name, cases[c].bound, cases[c].value))
                continue;
            for (k = 0; k < n; k++) {
                same = same && memcmp(at_bound.out[k], beyond.out[k], (size_t)at_bound.n_out * sizeof(double)) == 0;
                quiet = quiet && at_bound.status[k] == fmi2OK && (k == 0 || beyond.status[k] == fmi2OK);
            }
            case_check(same && beyond.n_out == at_bound.n_out,
                       "%s: %s = %g (%s) gives the outputs of %s = %g at every sample", f->id, v->name,
                       cases[c].value, when, v->name, cases[c].bound);
            case_check(beyond.status[0] == fmi2Warning && strstr(beyond.first_warning, "clamped") != NULL
                           && strstr(beyond.first_warning, range) != NULL && quiet,
                       "%s: the first doStep with %s = %g warns once, naming the range %s; %s = %g warns never (%s)",
                       f->id, v->name, cases[c].value, range, v->name, cases[c].bound, beyond.first_warning);
            case_check(beyond.terminate == fmi2Warning && strstr(beyond.terminate_message, count) != NULL
                           && at_bound.terminate == fmi2OK,
                       "%s: fmi2Terminate reports the count: %s (%s)", f->id, count, beyond.terminate_message);
            case_check(beyond.v_read == cases[c].value, "%s: %s reads back as set, %g", f->id, v->name,
                       beyond.v_read);
        }
    }
}

/* fmi2FreeFMUstate(c, NULL) is ignored (FMI 2.0: "If a null pointer is provided,
 * the call is ignored"); the monitor's warning says what
 * monitor.divergence_samples = 0 means (never unstable). */
static void edge_small_ones(const host_fmu *f)
{
    inst_t in;
    unsigned char *before;
    size_t before_size;
    fmi2Status st;
    int k, window;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach StepComplete", f->id))
        return;
    before = host_snapshot(f, in.c, &before_size);
    host_log_clear(&in.log);
    st = f->api.FreeFMUstate(in.c, NULL);
    case_check(st == fmi2OK && in.log.n_errors == 0 && host_same_state(f, in.c, before, before_size),
               "%s: fmi2FreeFMUstate(c, NULL) is ignored: fmi2OK, nothing changed (%s)", f->id, in.log.last_error);
    free(before);
    leave(&in);

    if (host_named(f, "monitor.divergence_samples") == NULL)
        return;
    for (window = 0; window <= 1000; window += 1000) {
        char warning[1024] = "", expected[96];
        int failed = 0;
        instantiate(f, &in, "monitor");
        f->api.SetupExperiment(in.c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        f->api.EnterInitializationMode(in.c);
        host_set_named(f, in.c, "monitor.divergence_samples", window);
        host_set_named(f, in.c, "monitor.pred_error_max", 1e-3);
        f->api.ExitInitializationMode(in.c);
        host_set_named(f, in.c, "y_meas", 5.0);     /* the model predicts 0: |pred_error| is far above 1e-3 um */
        for (k = 0; k < 50; k++) {
            host_log_clear(&in.log);
            st = f->api.DoStep(in.c, k * f->h, f->h, fmi2True);
            failed = failed || st == fmi2Error;
            if (st == fmi2Warning && strstr(in.log.last, "pred_error") != NULL && warning[0] == '\0')
                snprintf(warning, sizeof warning, "%s", in.log.last);
        }
        if (window == 0) {
            case_check(!failed && strstr(warning, "never") != NULL && strstr(warning, "= 0 consecutive") == NULL,
                       "%s: with monitor.divergence_samples = 0 the loop is never declared unstable, and the "
                       "warning says so (%s)", f->id, warning);
        } else {
            snprintf(expected, sizeof expected, "monitor.divergence_samples = %d consecutive samples", window);
            case_check(!failed && strstr(warning, expected) != NULL,
                       "%s: with monitor.divergence_samples = %d the warning names the window (%s)", f->id, window,
                       warning);
        }
        leave(&in);
    }
}

static void edges(const host_fmu *f)
{
    group_start();
    edge_zero_step(f);
    edge_value_counts(f);
    edge_input_range(f);
    edge_small_ones(f);
    edge_huge_step(f);      /* last: before issue 23 it ran for hours */
    group_end("edges", f->id);
}

int main(int argc, char **argv)
{
    int i, j;
    if (argc < 3 || argc % 2 == 0 || (argc - 1) / 2 > MAX_FMUS) {
        fprintf(stderr, "usage: %s MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    host_verbose = getenv("FMU_NEGATIVE_VERBOSE") != NULL;
    for (i = 1; i + 1 < argc; i += 2)
        if (!host_load(&fmus[n_fmus++], argv[i], argv[i + 1]))
            return 2;
    for (i = 0; i < n_fmus; i++) {
        matrix(&fmus[i]);
        null_arguments(&fmus[i]);
        value_references(&fmus[i]);
        instantiation(&fmus[i]);
        extreme_values(&fmus[i]);
        free_in_every_state(&fmus[i]);
    }
    for (i = 0; i < n_fmus; i++)
        for (j = 0; j < n_fmus; j++)
            if (i != j)
                foreign(&fmus[i], &fmus[j]);
    for (i = 0; i < n_fmus; i++)
        edges(&fmus[i]);     /* last: before issue 23 its huge step ran for hours */
    case_check(atomic_load(&host_live_blocks) == 0, "every block the FMUs allocated was freed (%ld left)",
               atomic_load(&host_live_blocks));
    for (i = 0; i < n_fmus; i++)
        host_unload(&fmus[i]);
    return host_summary();
}
