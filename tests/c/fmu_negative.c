/*
 * fmu_negative.c - the negative test suite of the FMUs: everything a careless
 * or hostile host may do, for every FMU given, each case one check line. Built
 * once per FMI version: fmu_negative (FMI 2.0 editions), fmu3_negative (FMI 3.0
 * editions); what only FMI 3.0 has (arrays, nValues, its other types and
 * functions) stands under the version switch.
 *
 *   matrix     every call that takes an instance, in each reachable state of
 *              the Co-Simulation state machine (Instantiated, InitializationMode,
 *              StepComplete / StepMode, Terminated, Error; FMI 3.0 without event
 *              mode): a call the state machine forbids (or the FMU does not
 *              support: derivatives, Model Exchange, FMI 2.0's asynchronous
 *              steps, FMI 3.0's event and configuration modes, clocks,
 *              dependencies and Scheduled Execution) returns Error, is explained
 *              through the logger and changes nothing (the instance serializes to
 *              the same bytes before and after); an allowed call succeeds
 *   null       NULL for each pointer argument (FMI 3.0: the doStep's
 *              out-arguments too), a NULL instance for every function, garbage
 *              instances, another FMU's instance, another instance's FMU state
 *   vr         out-of-range value references (FMI 3.0: and the unused
 *              references of an array's other elements), wrong types (FMI 3.0:
 *              all 14), FMI 3.0's nValues that does not match the references,
 *              outputs, time and fixed parameters set, a bad reference after
 *              good ones (nothing set)
 *   instantiate  wrong GUIDs / instantiation tokens (another FMU's too), a
 *              missing name; FMI 2.0: a wrong fmuType, missing callbacks (the
 *              logger included); FMI 3.0: eventModeUsed, a NULL list of required
 *              intermediate variables, Model Exchange and Scheduled Execution:
 *              NULL, nothing allocated; FMI 3.0 also accepts a NULL logMessage
 *              (no logging)
 *   extreme    extreme finite values (+-DBL_MAX, +-DBL_MIN, +-5e-324, 0, -0,
 *              +-1e300, ...) for every parameter (each array element alone) and
 *              input, step sizes and communication points, start and stop
 *              times: refused with a message, or run with every output finite; a
 *              refused step leaves the outputs as they were
 *   free       FreeInstance in every state, with and without FMU states still
 *              allocated: everything the FMU allocated is freed
 *   fast paths a master's exchange (Real inputs set, scalars read, a doStep
 *              from exactly t over exactly h) leaves the same state and returns
 *              the same values as the same exchange through the full checks
 *   edges      the standard at its edges (issue 23): a step size of 0 or below
 *              refused, a positive one that rounds to no sample a no-op; a huge
 *              step refused at once, naming the bound of one doStep's work
 *              (samples, and the terms of the exact creep sum); value arrays of
 *              no value reference (FMI 3.0: nValues that does not match none, in
 *              every getter and setter); an input beyond its declared range
 *              clamped with one warning and a count at Terminate;
 *              FreeFMUState(c, NULL) ignored; the monitor's warning with
 *              monitor.divergence_samples = 0
 *
 * The oracle of "no NaN/Inf output": every Real output read after an
 * OK/Warning step is finite. Memory: FMI 2.0 allocates through the host's
 * callbacks, which count blocks; FMI 3.0 has none, so its oracle is the C
 * library's count of bytes in use (exact with
 * GLIBC_TUNABLES=glibc.malloc.tcache_count=0, which CTest and pytest set; the
 * first line says whether it was compared), and valgrind or LeakSanitizer over
 * the whole run.
 *
 * usage: fmu_negative MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]
 * (two or more FMUs: the cross-FMU identity cases run between each pair)
 * Prints failures and one summary line per group, then "N passed, M failed";
 * with FMU_NEGATIVE_VERBOSE set, every case.
 */
#include "host.h"

#include <float.h>
#include <limits.h>
#include <signal.h>
#include <unistd.h>

#define MAX_FMUS 4
static host_fmu fmus[MAX_FMUS];
static int n_fmus;

#define STEP_STATE BY_VERSION("StepComplete", "StepMode")
#define INSTANCE BY_VERSION("component", "instance")    /* what the standard calls it */
#define TOKEN BY_VERSION("GUID", "token")

enum { S_INST, S_INIT, S_STEP, S_TERM, S_ERR, N_STATES };
static const char *const state_names[N_STATES] = {
    "Instantiated", "InitializationMode", STEP_STATE, "Terminated", "Error"};
#define M(s) (1 << (s))
#define ALL_STATES (M(S_INST) | M(S_INIT) | M(S_STEP) | M(S_TERM) | M(S_ERR))
#define NEVER 0
#define GETTERS (M(S_INIT) | M(S_STEP) | M(S_TERM) | M(S_ERR))
#define SETTERS_PARAMETER (M(S_INST) | M(S_INIT))
#define SETTERS_INPUT (M(S_INST) | M(S_INIT) | M(S_STEP))

/* An instance of the suite: several-sample steps are what it tests, so the
 * controller holds its inputs over them (mv.hold_inputs, host_hold_inputs). */
static void *instantiate(host_inst *in, const host_fmu *f, const char *name)
{
    if (host_instantiate(in, f, name) != NULL && !host_hold_inputs(f, in->c)) {
        host_free_instance(in);
        in->c = NULL;
    }
    return in->c;
}

/* A fresh instance in state s (2 samples done for the states after initialization).
 * Error is entered by restoring a state saved in Error: the serialized
 * StepComplete state with its mode field set to Error (the model data of an
 * instance in Error is the restored start of the failed step, i.e. valid). */
static int enter_state(const host_fmu *f, host_inst *in, int s)
{
    if (instantiate(in, f, state_names[s]) == NULL)
        return 0;
    if (s == S_INST)
        return 1;
    if (host_enter_init(f, in->c, 0.0, 0, 0.0) != HOST_OK)
        return 0;
    if (s == S_INIT)
        return 1;
    if (f->api.ExitInitializationMode(in->c) != HOST_OK || host_step(f, in->c, 0.0, 2 * f->h) > HOST_WARNING)
        return 0;
    in->k = 2;
    if (s == S_STEP)
        return 1;
    if (s == S_TERM)
        return f->api.Terminate(in->c) <= HOST_WARNING;
    {
        size_t size;
        unsigned char *blob = host_snapshot(f, in->c, &size);
        host_state st = NULL;
        int ok;
        if (blob == NULL)
            return 0;
        blob[BLOB_OFF_MODE] = BLOB_MODE_ERROR;
        blob_reseal(blob, size);
        ok = host_deserialize(f, in->c, blob, size, &st) == HOST_OK && host_set_state(f, in->c, st) == HOST_OK
             && host_free_state(f, in->c, &st) == HOST_OK && host_step(f, in->c, 2 * f->h, f->h) == HOST_ERROR
             && strstr(in->log.last_error, "state Error") != NULL;
        free(blob);
        host_log_clear(&in->log);
        return ok;
    }
}

/* ------------------------------------------------------------------------ */
/* cases and groups                                                          */

static int group_passed, group_failed;

static int case_check(int condition, const char *fmt, ...)
{
    va_list ap;
    char text[1200];
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

/* What the FMUs hold now against `before`, for a case's text: FMI 2.0 counts
 * blocks ("0 left"), FMI 3.0 bytes in use. */
#define MEM_UNIT BY_VERSION("block", "byte")
static const char *mem_change(long before, char *text, size_t size)
{
#if FMI_VERSION == 2
    snprintf(text, size, "%ld left", host_mem_in_use() - before);
#else
    snprintf(text, size, "%ld bytes in use before, %ld after", before, host_mem_in_use());
#endif
    return text;
}

/* A call on an instance that must be refused: Error, a message, and the instance
 * serializes to `before` as it did before the call; the case's text is
 * "<FMU>: <fmt> (<the message>)". */
typedef struct {
    const host_fmu *f;
    host_inst *in;
    const unsigned char *before;
    size_t before_size;
} refusal;

#define REFUSED(x, call, fmt, ...)                                                                          \
    do {                                                                                                    \
        host_log_clear(&(x)->in->log);                                                                      \
        case_check((call) == HOST_ERROR && (x)->in->log.n_errors > 0                                        \
                       && host_same_state((x)->f, (x)->in->c, (x)->before, (x)->before_size),               \
                   "%s: " fmt " (%s)", (x)->f->id, __VA_ARGS__, (x)->in->log.last_error);                   \
    } while (0)

/* ------------------------------------------------------------------------ */
/* the call matrix                                                           */

/* What a call may use: a state and a blob of the instance, made before it. */
typedef struct {
    host_state state;
    unsigned char *blob;
    size_t blob_size;
} call_ctx;

typedef host_status (*call_fn)(host_inst *in, call_ctx *x);

typedef struct {
    const char *name;
    int allowed;                /* states in which the call succeeds */
    call_fn call;
    int needs;                  /* NEEDS_* */
} call_case;

/* NEEDS_INPUT, NEEDS_ARRAY: skipped without a Real input, an array; NEEDS_SET_INT/BOOL:
 * without an Integer/Boolean parameter the setter is called with nvr = 0, which only
 * tests the state (allowed wherever any setter is: Instantiated, Init, StepComplete). */
enum { NEEDS_NONE, NEEDS_INPUT, NEEDS_SET_INT, NEEDS_SET_BOOL, NEEDS_ARRAY };

static double scratch_real[64];
static host_int scratch_int[64];
static host_bool scratch_bool[64];
static const char *scratch_str[64];
static host_vr scratch_vr[64];
#if FMI_VERSION == 3
static fmi3Binary scratch_bin[64];
static size_t scratch_size[64];
static fmi3UInt64 scratch_u64[64];
static fmi3IntervalQualifier scratch_qual[64];
static fmi3DependencyKind scratch_kind[64];
#endif

static const host_var *first(const host_fmu *f, int causality, int type)
{
    return host_find(f, causality, type);
}

/* The first array variable (each FMI 3.0 edition has one), or NULL. */
static const host_var *first_array(const host_fmu *f)
{
    int i;
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].n > 1)
            return &f->vars[i];
    return NULL;
}

/* The last value reference in use (FMI 3.0: time's). */
static host_vr last_vr(const host_fmu *f)
{
    host_vr last = 0;
    int i;
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].vr > last)
            last = f->vars[i].vr;
    return last;
}

#define CALL(fn) static host_status fn(host_inst *in, call_ctx *x)

CALL(c_set_debug_logging) { (void)x; return in->f->api.SetDebugLogging(in->c, HOST_FALSE, 0, NULL); }
CALL(c_enter_init)
{
    (void)x;
    return BY_VERSION(in->f->api.EnterInitializationMode(in->c),
                      in->f->api.EnterInitializationMode(in->c, fmi3False, 0.0, 0.0, fmi3False, 0.0));
}
CALL(c_exit_init) { (void)x; return in->f->api.ExitInitializationMode(in->c); }
CALL(c_terminate) { (void)x; return in->f->api.Terminate(in->c); }
CALL(c_reset) { (void)x; return in->f->api.Reset(in->c); }
CALL(c_get_output)
{
    const host_var *v = first(in->f, VAR_OUTPUT, VAR_REAL);
    (void)x;
    return host_get_reals(in->f, in->c, &v->vr, 1, scratch_real, 1);
}
CALL(c_get_integer)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_INTEGER);
    (void)x;
    return host_get_ints(in->f, in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, scratch_int, v ? 1 : 0);
}
CALL(c_get_boolean)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_BOOLEAN);
    (void)x;
    return host_get_bools(in->f, in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, scratch_bool, v ? 1 : 0);
}
CALL(c_set_real_parameter)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_REAL);
    (void)x;
    return host_set_reals(in->f, in->c, &v->vr, 1, v->start, 1);
}
CALL(c_set_input)
{
    const host_var *v = first(in->f, VAR_INPUT, VAR_REAL);
    double value = 0.5;
    (void)x;
    return host_set_reals(in->f, in->c, &v->vr, 1, &value, 1);
}
CALL(c_set_integer)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_INTEGER);
    host_int value = v ? (host_int)v->start[0] : 0;
    (void)x;
    return host_set_ints(in->f, in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, &value, v ? 1 : 0);
}
CALL(c_set_boolean)
{
    const host_var *v = first(in->f, VAR_PARAMETER, VAR_BOOLEAN);
    host_bool value = v && v->start[0] != 0.0 ? HOST_TRUE : HOST_FALSE;
    (void)x;
    return host_set_bools(in->f, in->c, v ? &v->vr : scratch_vr, v ? 1 : 0, &value, v ? 1 : 0);
}
CALL(c_get_string)
{
    (void)x;
    return BY_VERSION(in->f->api.GetString(in->c, scratch_vr, 0, scratch_str),
                      in->f->api.GetString(in->c, scratch_vr, 0, scratch_str, 0));
}
CALL(c_set_string)
{
    (void)x;
    return BY_VERSION(in->f->api.SetString(in->c, scratch_vr, 0, scratch_str),
                      in->f->api.SetString(in->c, scratch_vr, 0, scratch_str, 0));
}
CALL(c_get_fmu_state)
{
    host_state s = NULL;
    host_status st = host_get_state(in->f, in->c, &s);
    (void)x;
    if (s != NULL)
        host_free_state(in->f, in->c, &s);
    return st;
}
CALL(c_set_fmu_state) { return host_set_state(in->f, in->c, x->state); }
CALL(c_free_fmu_state) { return host_free_state(in->f, in->c, &x->state); }
CALL(c_state_size)
{
    size_t size = 0;
    return host_state_size(in->f, in->c, x->state, &size);
}
CALL(c_serialize)
{
    static unsigned char buf[1 << 14];
    size_t size = 0;
    if (host_state_size(in->f, in->c, x->state, &size) != HOST_OK || size > sizeof buf)
        size = sizeof buf;
    return host_serialize(in->f, in->c, x->state, buf, size);
}
CALL(c_deserialize)
{
    host_state s = NULL;
    host_status st = host_deserialize(in->f, in->c, x->blob, x->blob_size, &s);
    if (s != NULL)
        host_free_state(in->f, in->c, &s);
    return st;
}
CALL(c_directional_derivative)
{
    double seed = 1.0, sensitivity = 0.0;
#if FMI_VERSION == 2
    fmi2ValueReference u = 0, k = 0;
    (void)x;
    return in->f->api.GetDirectionalDerivative(in->c, &u, 1, &k, 1, &seed, &sensitivity);
#else
    fmi3ValueReference u = first(in->f, VAR_OUTPUT, VAR_REAL)->vr, k = 0;
    (void)x;
    return in->f->api.GetDirectionalDerivative(in->c, &u, 1, &k, 1, &seed, 1, &sensitivity, 1);
#endif
}
CALL(c_do_step) { (void)x; return host_step(in->f, in->c, in->k * in->f->h, in->f->h); }
CALL(c_enter_event_mode) { (void)x; return in->f->api.EnterEventMode(in->c); }
CALL(c_enter_continuous_time_mode) { (void)x; return in->f->api.EnterContinuousTimeMode(in->c); }
CALL(c_completed_integrator_step)
{
    host_bool event = HOST_FALSE, terminate = HOST_FALSE;
    (void)x;
    return in->f->api.CompletedIntegratorStep(in->c, HOST_TRUE, &event, &terminate);
}
CALL(c_set_time) { (void)x; return in->f->api.SetTime(in->c, 0.0); }
CALL(c_set_continuous_states) { (void)x; return in->f->api.SetContinuousStates(in->c, scratch_real, 1); }
CALL(c_get_derivatives)
{
    (void)x;
    return BY_VERSION(in->f->api.GetDerivatives, in->f->api.GetContinuousStateDerivatives)(in->c, scratch_real, 1);
}
CALL(c_get_event_indicators) { (void)x; return in->f->api.GetEventIndicators(in->c, scratch_real, 1); }
CALL(c_get_continuous_states) { (void)x; return in->f->api.GetContinuousStates(in->c, scratch_real, 1); }
CALL(c_get_nominals) { (void)x; return in->f->api.GetNominalsOfContinuousStates(in->c, scratch_real, 1); }

#if FMI_VERSION == 2
CALL(c_setup) { (void)x; return in->f->api.SetupExperiment(in->c, fmi2False, 0.0, 0.0, fmi2False, 0.0); }
CALL(c_set_input_derivatives)
{
    fmi2ValueReference vr = 0;
    fmi2Integer order = 1;
    double value = 1.0;
    (void)x;
    return in->f->api.SetRealInputDerivatives(in->c, &vr, 1, &order, &value);
}
CALL(c_get_output_derivatives)
{
    fmi2ValueReference vr = 0;
    fmi2Integer order = 1;
    double value = 0.0;
    (void)x;
    return in->f->api.GetRealOutputDerivatives(in->c, &vr, 1, &order, &value);
}
CALL(c_cancel_step) { (void)x; return in->f->api.CancelStep(in->c); }
CALL(c_get_status)
{
    fmi2Status value;
    (void)x;
    return in->f->api.GetStatus(in->c, fmi2DoStepStatus, &value);
}
CALL(c_get_real_status)
{
    double value;
    (void)x;
    return in->f->api.GetRealStatus(in->c, fmi2LastSuccessfulTime, &value);
}
CALL(c_get_integer_status)
{
    fmi2Integer value;
    (void)x;
    return in->f->api.GetIntegerStatus(in->c, fmi2DoStepStatus, &value);
}
CALL(c_get_boolean_status)
{
    fmi2Boolean value;
    (void)x;
    return in->f->api.GetBooleanStatus(in->c, fmi2Terminated, &value);
}
CALL(c_get_string_status)
{
    fmi2String value;
    (void)x;
    return in->f->api.GetStringStatus(in->c, fmi2PendingStatus, &value);
}
CALL(c_new_discrete_states)
{
    fmi2EventInfo info;
    (void)x;
    return in->f->api.NewDiscreteStates(in->c, &info);
}
#else
static const host_var *time_var(const host_fmu *f)
{
    return host_find(f, VAR_INDEPENDENT, VAR_REAL);
}
CALL(c_get_time)
{
    const host_var *v = time_var(in->f);
    (void)x;
    return in->f->api.GetFloat64(in->c, &v->vr, 1, scratch_real, 1);
}
CALL(c_get_array)
{
    const host_var *v = first_array(in->f);
    (void)x;
    return in->f->api.GetFloat64(in->c, &v->vr, 1, scratch_real, (size_t)v->n);
}
CALL(c_set_array)
{
    const host_var *v = first_array(in->f);
    (void)x;
    return in->f->api.SetFloat64(in->c, &v->vr, 1, v->start, (size_t)v->n);
}
/* the types without variables, nvr = 0: only the state is tested */
CALL(c_get_float32) { (void)x; return in->f->api.GetFloat32(in->c, scratch_vr, 0, (fmi3Float32 *)scratch_real, 0); }
CALL(c_get_int8) { (void)x; return in->f->api.GetInt8(in->c, scratch_vr, 0, (fmi3Int8 *)scratch_real, 0); }
CALL(c_get_uint8) { (void)x; return in->f->api.GetUInt8(in->c, scratch_vr, 0, (fmi3UInt8 *)scratch_real, 0); }
CALL(c_get_int16) { (void)x; return in->f->api.GetInt16(in->c, scratch_vr, 0, (fmi3Int16 *)scratch_real, 0); }
CALL(c_get_uint16) { (void)x; return in->f->api.GetUInt16(in->c, scratch_vr, 0, (fmi3UInt16 *)scratch_real, 0); }
CALL(c_get_uint32) { (void)x; return in->f->api.GetUInt32(in->c, scratch_vr, 0, (fmi3UInt32 *)scratch_real, 0); }
CALL(c_get_int64) { (void)x; return in->f->api.GetInt64(in->c, scratch_vr, 0, (fmi3Int64 *)scratch_real, 0); }
CALL(c_get_uint64) { (void)x; return in->f->api.GetUInt64(in->c, scratch_vr, 0, scratch_u64, 0); }
CALL(c_get_binary) { (void)x; return in->f->api.GetBinary(in->c, scratch_vr, 0, scratch_size, scratch_bin, 0); }
CALL(c_get_clock) { (void)x; return in->f->api.GetClock(in->c, scratch_vr, 0, scratch_bool); }
CALL(c_set_float32) { (void)x; return in->f->api.SetFloat32(in->c, scratch_vr, 0, (const fmi3Float32 *)scratch_real, 0); }
CALL(c_set_int8) { (void)x; return in->f->api.SetInt8(in->c, scratch_vr, 0, (const fmi3Int8 *)scratch_real, 0); }
CALL(c_set_uint8) { (void)x; return in->f->api.SetUInt8(in->c, scratch_vr, 0, (const fmi3UInt8 *)scratch_real, 0); }
CALL(c_set_int16) { (void)x; return in->f->api.SetInt16(in->c, scratch_vr, 0, (const fmi3Int16 *)scratch_real, 0); }
CALL(c_set_uint16) { (void)x; return in->f->api.SetUInt16(in->c, scratch_vr, 0, (const fmi3UInt16 *)scratch_real, 0); }
CALL(c_set_uint32) { (void)x; return in->f->api.SetUInt32(in->c, scratch_vr, 0, (const fmi3UInt32 *)scratch_real, 0); }
CALL(c_set_int64) { (void)x; return in->f->api.SetInt64(in->c, scratch_vr, 0, (const fmi3Int64 *)scratch_real, 0); }
CALL(c_set_uint64) { (void)x; return in->f->api.SetUInt64(in->c, scratch_vr, 0, scratch_u64, 0); }
CALL(c_set_binary) { (void)x; return in->f->api.SetBinary(in->c, scratch_vr, 0, scratch_size, scratch_bin, 0); }
CALL(c_set_clock) { (void)x; return in->f->api.SetClock(in->c, scratch_vr, 0, scratch_bool); }
CALL(c_n_dependencies)
{
    size_t n = 0;
    (void)x;
    return in->f->api.GetNumberOfVariableDependencies(in->c, first(in->f, VAR_OUTPUT, VAR_REAL)->vr, &n);
}
CALL(c_dependencies)
{
    (void)x;
    return in->f->api.GetVariableDependencies(in->c, first(in->f, VAR_OUTPUT, VAR_REAL)->vr, scratch_size,
                                              scratch_vr, scratch_size, scratch_kind, 0);
}
CALL(c_adjoint)
{
    fmi3ValueReference u = first(in->f, VAR_OUTPUT, VAR_REAL)->vr, k = 0;
    double seed = 1.0, sens = 0.0;
    (void)x;
    return in->f->api.GetAdjointDerivative(in->c, &u, 1, &k, 1, &seed, 1, &sens, 1);
}
CALL(c_enter_configuration) { (void)x; return in->f->api.EnterConfigurationMode(in->c); }
CALL(c_exit_configuration) { (void)x; return in->f->api.ExitConfigurationMode(in->c); }
CALL(c_get_interval_decimal) { (void)x; return in->f->api.GetIntervalDecimal(in->c, scratch_vr, 1, scratch_real, scratch_qual); }
CALL(c_get_interval_fraction)
{
    (void)x;
    return in->f->api.GetIntervalFraction(in->c, scratch_vr, 1, scratch_u64, scratch_u64 + 1, scratch_qual);
}
CALL(c_get_shift_decimal) { (void)x; return in->f->api.GetShiftDecimal(in->c, scratch_vr, 1, scratch_real); }
CALL(c_get_shift_fraction) { (void)x; return in->f->api.GetShiftFraction(in->c, scratch_vr, 1, scratch_u64, scratch_u64 + 1); }
CALL(c_set_interval_decimal) { (void)x; return in->f->api.SetIntervalDecimal(in->c, scratch_vr, 1, scratch_real); }
CALL(c_set_interval_fraction)
{
    (void)x;
    return in->f->api.SetIntervalFraction(in->c, scratch_vr, 1, scratch_u64, scratch_u64 + 1);
}
CALL(c_set_shift_decimal) { (void)x; return in->f->api.SetShiftDecimal(in->c, scratch_vr, 1, scratch_real); }
CALL(c_set_shift_fraction) { (void)x; return in->f->api.SetShiftFraction(in->c, scratch_vr, 1, scratch_u64, scratch_u64 + 1); }
CALL(c_evaluate_discrete) { (void)x; return in->f->api.EvaluateDiscreteStates(in->c); }
CALL(c_update_discrete)
{
    fmi3Boolean a, b, c, d, e;
    fmi3Float64 t;
    (void)x;
    return in->f->api.UpdateDiscreteStates(in->c, &a, &b, &c, &d, &e, &t);
}
CALL(c_n_event_indicators)
{
    size_t n = 0;
    (void)x;
    return in->f->api.GetNumberOfEventIndicators(in->c, &n);
}
CALL(c_n_continuous_states)
{
    size_t n = 0;
    (void)x;
    return in->f->api.GetNumberOfContinuousStates(in->c, &n);
}
CALL(c_enter_step_mode) { (void)x; return in->f->api.EnterStepMode(in->c); }
CALL(c_output_derivatives)
{
    fmi3ValueReference vr = first(in->f, VAR_OUTPUT, VAR_REAL)->vr;
    fmi3Int32 order = 1;
    double value = 0.0;
    (void)x;
    return in->f->api.GetOutputDerivatives(in->c, &vr, 1, &order, &value, 1);
}
CALL(c_activate_partition) { (void)x; return in->f->api.ActivateModelPartition(in->c, 0, 0.0); }
#endif

/* The Co-Simulation state machine (FMI 2.0 section 4.2.4, FMI 3.0 section 4.2)
 * with this FMU's capabilities: no directional or output derivatives, not Model
 * Exchange; FMI 2.0: no input derivatives, no asynchronous steps (no status
 * kinds but fmi2LastSuccessfulTime and fmi2Terminated); FMI 3.0: no event mode,
 * no configuration mode, no clocks, no dependency functions, not Scheduled
 * Execution. Get/Set of the types the FMU has no variable of, with nvr = 0, only
 * test the state. */
static const call_case calls[] = {
    {FMI_NAME("SetDebugLogging"), ALL_STATES, c_set_debug_logging, NEEDS_NONE},
#if FMI_VERSION == 2
    {"fmi2SetupExperiment", M(S_INST), c_setup, NEEDS_NONE},
#endif
    {FMI_NAME("EnterInitializationMode"), M(S_INST), c_enter_init, NEEDS_NONE},
    {FMI_NAME("ExitInitializationMode"), M(S_INIT), c_exit_init, NEEDS_NONE},
#if FMI_VERSION == 3
    {"fmi3EnterEventMode", NEVER, c_enter_event_mode, NEEDS_NONE},
#endif
    {FMI_NAME("Terminate"), M(S_STEP), c_terminate, NEEDS_NONE},
    {FMI_NAME("Reset"), ALL_STATES, c_reset, NEEDS_NONE},
    {BY_VERSION("fmi2GetReal(output)", "fmi3GetFloat64(output)"), GETTERS, c_get_output, NEEDS_NONE},
#if FMI_VERSION == 3
    {"fmi3GetFloat64(time)", GETTERS, c_get_time, NEEDS_NONE},
    {"fmi3GetFloat64(array)", GETTERS, c_get_array, NEEDS_ARRAY},
#endif
    {BY_VERSION("fmi2GetInteger", "fmi3GetInt32"), GETTERS, c_get_integer, NEEDS_NONE},
    {FMI_NAME("GetBoolean"), GETTERS, c_get_boolean, NEEDS_NONE},
#if FMI_VERSION == 2
    {"fmi2GetString(nvr = 0)", GETTERS, c_get_string, NEEDS_NONE},
#endif
    {BY_VERSION("fmi2SetReal(parameter)", "fmi3SetFloat64(parameter)"), SETTERS_PARAMETER, c_set_real_parameter,
     NEEDS_NONE},
#if FMI_VERSION == 3
    {"fmi3SetFloat64(array)", SETTERS_PARAMETER, c_set_array, NEEDS_ARRAY},
#endif
    {BY_VERSION("fmi2SetReal(input)", "fmi3SetFloat64(input)"), SETTERS_INPUT, c_set_input, NEEDS_INPUT},
    {BY_VERSION("fmi2SetInteger(parameter)", "fmi3SetInt32(parameter)"), SETTERS_PARAMETER, c_set_integer,
     NEEDS_SET_INT},
    {FMI_NAME("SetBoolean(parameter)"), SETTERS_PARAMETER, c_set_boolean, NEEDS_SET_BOOL},
#if FMI_VERSION == 2
    {"fmi2SetString(nvr = 0)", SETTERS_INPUT, c_set_string, NEEDS_NONE},
#else
    {"fmi3GetFloat32(nvr = 0)", GETTERS, c_get_float32, NEEDS_NONE},
    {"fmi3GetInt8(nvr = 0)", GETTERS, c_get_int8, NEEDS_NONE},
    {"fmi3GetUInt8(nvr = 0)", GETTERS, c_get_uint8, NEEDS_NONE},
    {"fmi3GetInt16(nvr = 0)", GETTERS, c_get_int16, NEEDS_NONE},
    {"fmi3GetUInt16(nvr = 0)", GETTERS, c_get_uint16, NEEDS_NONE},
    {"fmi3GetUInt32(nvr = 0)", GETTERS, c_get_uint32, NEEDS_NONE},
    {"fmi3GetInt64(nvr = 0)", GETTERS, c_get_int64, NEEDS_NONE},
    {"fmi3GetUInt64(nvr = 0)", GETTERS, c_get_uint64, NEEDS_NONE},
    {"fmi3GetString(nvr = 0)", GETTERS, c_get_string, NEEDS_NONE},
    {"fmi3GetBinary(nvr = 0)", GETTERS, c_get_binary, NEEDS_NONE},
    {"fmi3GetClock(nvr = 0)", GETTERS, c_get_clock, NEEDS_NONE},
    {"fmi3SetFloat32(nvr = 0)", SETTERS_INPUT, c_set_float32, NEEDS_NONE},
    {"fmi3SetInt8(nvr = 0)", SETTERS_INPUT, c_set_int8, NEEDS_NONE},
    {"fmi3SetUInt8(nvr = 0)", SETTERS_INPUT, c_set_uint8, NEEDS_NONE},
    {"fmi3SetInt16(nvr = 0)", SETTERS_INPUT, c_set_int16, NEEDS_NONE},
    {"fmi3SetUInt16(nvr = 0)", SETTERS_INPUT, c_set_uint16, NEEDS_NONE},
    {"fmi3SetUInt32(nvr = 0)", SETTERS_INPUT, c_set_uint32, NEEDS_NONE},
    {"fmi3SetInt64(nvr = 0)", SETTERS_INPUT, c_set_int64, NEEDS_NONE},
    {"fmi3SetUInt64(nvr = 0)", SETTERS_INPUT, c_set_uint64, NEEDS_NONE},
    {"fmi3SetString(nvr = 0)", SETTERS_INPUT, c_set_string, NEEDS_NONE},
    {"fmi3SetBinary(nvr = 0)", SETTERS_INPUT, c_set_binary, NEEDS_NONE},
    {"fmi3SetClock(nvr = 0)", SETTERS_INPUT, c_set_clock, NEEDS_NONE},
    {"fmi3GetNumberOfVariableDependencies", NEVER, c_n_dependencies, NEEDS_NONE},
    {"fmi3GetVariableDependencies", NEVER, c_dependencies, NEEDS_NONE},
#endif
    {BY_VERSION("fmi2GetFMUstate", "fmi3GetFMUState"), ALL_STATES, c_get_fmu_state, NEEDS_NONE},
    {BY_VERSION("fmi2SetFMUstate", "fmi3SetFMUState"), ALL_STATES, c_set_fmu_state, NEEDS_NONE},
    {BY_VERSION("fmi2FreeFMUstate", "fmi3FreeFMUState"), ALL_STATES, c_free_fmu_state, NEEDS_NONE},
    {BY_VERSION("fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"), ALL_STATES, c_state_size, NEEDS_NONE},
    {BY_VERSION("fmi2SerializeFMUstate", "fmi3SerializeFMUState"), ALL_STATES, c_serialize, NEEDS_NONE},
    {BY_VERSION("fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"), ALL_STATES, c_deserialize, NEEDS_NONE},
    {FMI_NAME("GetDirectionalDerivative"), NEVER, c_directional_derivative, NEEDS_NONE},
#if FMI_VERSION == 2
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
#else
    {"fmi3GetAdjointDerivative", NEVER, c_adjoint, NEEDS_NONE},
    {"fmi3EnterConfigurationMode", NEVER, c_enter_configuration, NEEDS_NONE},
    {"fmi3ExitConfigurationMode", NEVER, c_exit_configuration, NEEDS_NONE},
    {"fmi3GetIntervalDecimal", NEVER, c_get_interval_decimal, NEEDS_NONE},
    {"fmi3GetIntervalFraction", NEVER, c_get_interval_fraction, NEEDS_NONE},
    {"fmi3GetShiftDecimal", NEVER, c_get_shift_decimal, NEEDS_NONE},
    {"fmi3GetShiftFraction", NEVER, c_get_shift_fraction, NEEDS_NONE},
    {"fmi3SetIntervalDecimal", NEVER, c_set_interval_decimal, NEEDS_NONE},
    {"fmi3SetIntervalFraction", NEVER, c_set_interval_fraction, NEEDS_NONE},
    {"fmi3SetShiftDecimal", NEVER, c_set_shift_decimal, NEEDS_NONE},
    {"fmi3SetShiftFraction", NEVER, c_set_shift_fraction, NEEDS_NONE},
    {"fmi3EvaluateDiscreteStates", NEVER, c_evaluate_discrete, NEEDS_NONE},
    {"fmi3UpdateDiscreteStates", NEVER, c_update_discrete, NEEDS_NONE},
#endif
    {FMI_NAME("EnterContinuousTimeMode"), NEVER, c_enter_continuous_time_mode, NEEDS_NONE},
    {FMI_NAME("CompletedIntegratorStep"), NEVER, c_completed_integrator_step, NEEDS_NONE},
    {FMI_NAME("SetTime"), NEVER, c_set_time, NEEDS_NONE},
    {FMI_NAME("SetContinuousStates"), NEVER, c_set_continuous_states, NEEDS_NONE},
    {BY_VERSION("fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives"), NEVER, c_get_derivatives, NEEDS_NONE},
    {FMI_NAME("GetEventIndicators"), NEVER, c_get_event_indicators, NEEDS_NONE},
    {FMI_NAME("GetContinuousStates"), NEVER, c_get_continuous_states, NEEDS_NONE},
    {FMI_NAME("GetNominalsOfContinuousStates"), NEVER, c_get_nominals, NEEDS_NONE},
#if FMI_VERSION == 3
    {"fmi3GetNumberOfEventIndicators", NEVER, c_n_event_indicators, NEEDS_NONE},
    {"fmi3GetNumberOfContinuousStates", NEVER, c_n_continuous_states, NEEDS_NONE},
    {"fmi3EnterStepMode", NEVER, c_enter_step_mode, NEEDS_NONE},
    {"fmi3GetOutputDerivatives", NEVER, c_output_derivatives, NEEDS_NONE},
    {"fmi3DoStep", M(S_STEP), c_do_step, NEEDS_NONE},
    {"fmi3ActivateModelPartition", NEVER, c_activate_partition, NEEDS_NONE},
#endif
};
#define N_CALLS ((int)(sizeof calls / sizeof calls[0]))

static void matrix(const host_fmu *f)
{
    int s, i;
    group_start();
    for (s = 0; s < N_STATES; s++) {
        for (i = 0; i < N_CALLS; i++) {
            const call_case *cc = &calls[i];
            host_inst in;
            call_ctx x;
            unsigned char *before;
            size_t before_size;
            host_status st;
            int allowed_mask = cc->allowed, allowed;
            if ((cc->needs == NEEDS_INPUT && first(f, VAR_INPUT, VAR_REAL) == NULL)
                || (cc->needs == NEEDS_ARRAY && first_array(f) == NULL))
                continue;
            if ((cc->needs == NEEDS_SET_INT && first(f, VAR_PARAMETER, VAR_INTEGER) == NULL)
                || (cc->needs == NEEDS_SET_BOOL && first(f, VAR_PARAMETER, VAR_BOOLEAN) == NULL))
                allowed_mask = SETTERS_INPUT;       /* nvr = 0: any state a setter is allowed in */
            allowed = (allowed_mask & M(s)) != 0;
            memset(&x, 0, sizeof x);
            if (!case_check(enter_state(f, &in, s), "%s: reach %s", f->id, state_names[s])) {
                host_free_instance(&in);
                continue;
            }
            host_get_state(f, in.c, &x.state);
            x.blob = host_snapshot(f, in.c, &x.blob_size);
            before = host_snapshot(f, in.c, &before_size);
            host_log_clear(&in.log);
            st = cc->call(&in, &x);
            if (allowed)
                case_check(st == HOST_OK || st == HOST_WARNING, "%s in %s: %s is allowed (status %d: %s)", f->id,
                           state_names[s], cc->name, (int)st, in.log.last_error);
            else
                case_check(st == HOST_ERROR && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size),
                           "%s in %s: %s returns " FMI_NAME("Error") ", says why, changes nothing (status %d: %s)",
                           f->id, state_names[s], cc->name, (int)st, in.log.last_error);
            if (x.state != NULL)
                host_free_state(f, in.c, &x.state);
            free(x.blob);
            free(before);
            host_free_instance(&in);
        }
    }
    group_end("matrix", f->id);
}

/* ------------------------------------------------------------------------ */
/* NULL and foreign arguments                                                */

#define REFUSES(call) case_check((call) == HOST_ERROR, "%s: %s refuses %s", f->id, #call, what)

/* Calls every function that takes an instance on c with harmless other
 * arguments; each must return Error (FreeInstance must not crash). */
static void every_function_refuses(const host_fmu *f, void *c, const char *what)
{
    host_state state = NULL;
    unsigned char buf[256];
#if FMI_VERSION == 2
    fmi2ValueReference vr = 0;
    double real = 0.0;
    fmi2Integer integer = 0;
    fmi2Boolean boolean = fmi2False;
    fmi2String string = "";
    fmi2Status status;
    fmi2EventInfo info;
    size_t size = 0;
    memset(buf, 0, sizeof buf);
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
#else
    fmi3ValueReference vr = 0;
    double real = 0.0;
    fmi3Int32 integer = 0;
    fmi3Boolean boolean = fmi3False, b2 = fmi3False, b3 = fmi3False, b4 = fmi3False, b5 = fmi3False;
    fmi3Float32 f32 = 0.0f;
    fmi3Int8 i8 = 0;
    fmi3UInt8 u8 = 0;
    fmi3Int16 i16 = 0;
    fmi3UInt16 u16 = 0;
    fmi3UInt32 u32 = 0;
    fmi3Int64 i64 = 0;
    fmi3UInt64 u64 = 0, u64b = 0;
    fmi3String string = "";
    fmi3Binary binary = NULL;
    fmi3IntervalQualifier qualifier;
    fmi3DependencyKind kind;
    size_t size = 0, index = 0;
    memset(buf, 0, sizeof buf);
    REFUSES(f->api.SetDebugLogging(c, fmi3True, 0, NULL));
    REFUSES(f->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0));
    REFUSES(f->api.ExitInitializationMode(c));
    REFUSES(f->api.EnterEventMode(c));
    REFUSES(f->api.Terminate(c));
    REFUSES(f->api.Reset(c));
    REFUSES(f->api.GetFloat32(c, &vr, 1, &f32, 1));
    REFUSES(f->api.GetFloat64(c, &vr, 1, &real, 1));
    REFUSES(f->api.GetInt8(c, &vr, 1, &i8, 1));
    REFUSES(f->api.GetUInt8(c, &vr, 1, &u8, 1));
    REFUSES(f->api.GetInt16(c, &vr, 1, &i16, 1));
    REFUSES(f->api.GetUInt16(c, &vr, 1, &u16, 1));
    REFUSES(f->api.GetInt32(c, &vr, 1, &integer, 1));
    REFUSES(f->api.GetUInt32(c, &vr, 1, &u32, 1));
    REFUSES(f->api.GetInt64(c, &vr, 1, &i64, 1));
    REFUSES(f->api.GetUInt64(c, &vr, 1, &u64, 1));
    REFUSES(f->api.GetBoolean(c, &vr, 1, &boolean, 1));
    REFUSES(f->api.GetString(c, &vr, 1, &string, 1));
    REFUSES(f->api.GetBinary(c, &vr, 1, &size, &binary, 1));
    REFUSES(f->api.GetClock(c, &vr, 1, &boolean));
    REFUSES(f->api.SetFloat32(c, &vr, 1, &f32, 1));
    REFUSES(f->api.SetFloat64(c, &vr, 1, &real, 1));
    REFUSES(f->api.SetInt8(c, &vr, 1, &i8, 1));
    REFUSES(f->api.SetUInt8(c, &vr, 1, &u8, 1));
    REFUSES(f->api.SetInt16(c, &vr, 1, &i16, 1));
    REFUSES(f->api.SetUInt16(c, &vr, 1, &u16, 1));
    REFUSES(f->api.SetInt32(c, &vr, 1, &integer, 1));
    REFUSES(f->api.SetUInt32(c, &vr, 1, &u32, 1));
    REFUSES(f->api.SetInt64(c, &vr, 1, &i64, 1));
    REFUSES(f->api.SetUInt64(c, &vr, 1, &u64, 1));
    REFUSES(f->api.SetBoolean(c, &vr, 1, &boolean, 1));
    REFUSES(f->api.SetString(c, &vr, 1, &string, 1));
    REFUSES(f->api.SetBinary(c, &vr, 1, &size, &binary, 1));
    REFUSES(f->api.SetClock(c, &vr, 1, &boolean));
    REFUSES(f->api.GetNumberOfVariableDependencies(c, vr, &size));
    REFUSES(f->api.GetVariableDependencies(c, vr, &index, &vr, &index, &kind, 0));
    REFUSES(f->api.GetFMUState(c, &state));
    REFUSES(f->api.SetFMUState(c, state));
    REFUSES(f->api.FreeFMUState(c, &state));
    REFUSES(f->api.SerializedFMUStateSize(c, state, &size));
    REFUSES(f->api.SerializeFMUState(c, state, buf, sizeof buf));
    REFUSES(f->api.DeserializeFMUState(c, buf, sizeof buf, &state));
    REFUSES(f->api.GetDirectionalDerivative(c, &vr, 1, &vr, 1, &real, 1, &real, 1));
    REFUSES(f->api.GetAdjointDerivative(c, &vr, 1, &vr, 1, &real, 1, &real, 1));
    REFUSES(f->api.EnterConfigurationMode(c));
    REFUSES(f->api.ExitConfigurationMode(c));
    REFUSES(f->api.GetIntervalDecimal(c, &vr, 1, &real, &qualifier));
    REFUSES(f->api.GetIntervalFraction(c, &vr, 1, &u64, &u64b, &qualifier));
    REFUSES(f->api.GetShiftDecimal(c, &vr, 1, &real));
    REFUSES(f->api.GetShiftFraction(c, &vr, 1, &u64, &u64b));
    REFUSES(f->api.SetIntervalDecimal(c, &vr, 1, &real));
    REFUSES(f->api.SetIntervalFraction(c, &vr, 1, &u64, &u64b));
    REFUSES(f->api.SetShiftDecimal(c, &vr, 1, &real));
    REFUSES(f->api.SetShiftFraction(c, &vr, 1, &u64, &u64b));
    REFUSES(f->api.EvaluateDiscreteStates(c));
    REFUSES(f->api.UpdateDiscreteStates(c, &boolean, &b2, &b3, &b4, &b5, &real));
    REFUSES(f->api.EnterContinuousTimeMode(c));
    REFUSES(f->api.CompletedIntegratorStep(c, fmi3True, &boolean, &b2));
    REFUSES(f->api.SetTime(c, 0.0));
    REFUSES(f->api.SetContinuousStates(c, &real, 1));
    REFUSES(f->api.GetContinuousStateDerivatives(c, &real, 1));
    REFUSES(f->api.GetEventIndicators(c, &real, 1));
    REFUSES(f->api.GetContinuousStates(c, &real, 1));
    REFUSES(f->api.GetNominalsOfContinuousStates(c, &real, 1));
    REFUSES(f->api.GetNumberOfEventIndicators(c, &size));
    REFUSES(f->api.GetNumberOfContinuousStates(c, &size));
    REFUSES(f->api.EnterStepMode(c));
    REFUSES(f->api.GetOutputDerivatives(c, &vr, 1, &integer, &real, 1));
    REFUSES(host3_step(f, c, 0.0, f->h));
    REFUSES(f->api.ActivateModelPartition(c, vr, 0.0));
#endif
    f->api.FreeInstance(c);
    case_check(state == NULL, "%s: no FMU state came out of %s", f->id, what);
}

/* Each NULL pointer argument of a call allowed in StepComplete / StepMode:
 * Error, a message, no change. */
static void null_arguments(const host_fmu *f)
{
    host_inst in;
    refusal x;
    host_state state = NULL, null_state = NULL;
    unsigned char *blob, *before;
    size_t blob_size = 0, before_size = 0, size = 0;
    host_vr vr = first(f, VAR_OUTPUT, VAR_REAL)->vr;
    double real[4] = {0};
    host_int integer[4] = {0};
    host_bool boolean[4] = {0};
    const char *strings[4] = {NULL};
    const char *null_category[1] = {NULL};
    static unsigned char buf[1 << 14];
#if FMI_VERSION == 3
    fmi3Float32 f32[4] = {0};
    fmi3UInt64 u64[4] = {0};
    fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
    fmi3Float64 last = 0.0;
#endif
    group_start();
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach %s", f->id, state_names[S_STEP]))
        return;
    host_get_state(f, in.c, &state);
    blob = host_snapshot(f, in.c, &blob_size);
    before = host_snapshot(f, in.c, &before_size);
    x.f = f;
    x.in = &in;
    x.before = before;
    x.before_size = before_size;
#define NULL_REFUSED(call) REFUSED(&x, call, "%s is refused with a message, nothing changed", #call)
#if FMI_VERSION == 2
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
#else
    NULL_REFUSED(f->api.GetFloat64(in.c, NULL, 1, real, 1));
    NULL_REFUSED(f->api.GetFloat64(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.GetInt32(in.c, NULL, 1, integer, 1));
    NULL_REFUSED(f->api.GetInt32(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.GetBoolean(in.c, NULL, 1, boolean, 1));
    NULL_REFUSED(f->api.GetBoolean(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.GetFloat32(in.c, NULL, 1, f32, 1));
    NULL_REFUSED(f->api.GetFloat32(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.GetUInt64(in.c, NULL, 1, u64, 1));
    NULL_REFUSED(f->api.GetString(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.GetBinary(in.c, &vr, 1, NULL, NULL, 1));
    NULL_REFUSED(f->api.GetClock(in.c, NULL, 1, boolean));
    NULL_REFUSED(f->api.SetFloat64(in.c, NULL, 1, real, 1));
    NULL_REFUSED(f->api.SetFloat64(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.SetInt32(in.c, NULL, 1, integer, 1));
    NULL_REFUSED(f->api.SetInt32(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.SetBoolean(in.c, NULL, 1, boolean, 1));
    NULL_REFUSED(f->api.SetBoolean(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.SetFloat32(in.c, &vr, 1, NULL, 1));
    NULL_REFUSED(f->api.SetString(in.c, NULL, 1, strings, 1));
    NULL_REFUSED(f->api.SetBinary(in.c, &vr, 1, NULL, NULL, 1));
    NULL_REFUSED(f->api.SetClock(in.c, &vr, 1, NULL));
    NULL_REFUSED(f->api.GetFMUState(in.c, NULL));
    NULL_REFUSED(f->api.SetFMUState(in.c, NULL));
    NULL_REFUSED(f->api.SerializedFMUStateSize(in.c, NULL, &size));
    NULL_REFUSED(f->api.SerializedFMUStateSize(in.c, state, NULL));
    NULL_REFUSED(f->api.SerializeFMUState(in.c, NULL, buf, sizeof buf));
    NULL_REFUSED(f->api.SerializeFMUState(in.c, state, NULL, sizeof buf));
    NULL_REFUSED(f->api.SerializeFMUState(in.c, state, buf, 0));
    NULL_REFUSED(f->api.DeserializeFMUState(in.c, NULL, blob_size, &null_state));
    NULL_REFUSED(f->api.DeserializeFMUState(in.c, blob, blob_size, NULL));
    NULL_REFUSED(f->api.DeserializeFMUState(in.c, blob, 0, &null_state));
    NULL_REFUSED(f->api.SetDebugLogging(in.c, fmi3True, 1, NULL));
    NULL_REFUSED(f->api.SetDebugLogging(in.c, fmi3True, 1, null_category));
    NULL_REFUSED(f->api.DoStep(in.c, in.k * f->h, f->h, fmi3True, NULL, &terminate, &early, &last));
    NULL_REFUSED(f->api.DoStep(in.c, in.k * f->h, f->h, fmi3True, &event, NULL, &early, &last));
    NULL_REFUSED(f->api.DoStep(in.c, in.k * f->h, f->h, fmi3True, &event, &terminate, NULL, &last));
    NULL_REFUSED(f->api.DoStep(in.c, in.k * f->h, f->h, fmi3True, &event, &terminate, &early, NULL));
    NULL_REFUSED(f->api.GetNumberOfVariableDependencies(in.c, vr, NULL));
    NULL_REFUSED(f->api.GetVariableDependencies(in.c, vr, NULL, NULL, NULL, NULL, 1));
    NULL_REFUSED(f->api.GetDirectionalDerivative(in.c, NULL, 1, NULL, 1, NULL, 1, NULL, 1));
    NULL_REFUSED(f->api.GetAdjointDerivative(in.c, NULL, 1, NULL, 1, NULL, 1, NULL, 1));
    NULL_REFUSED(f->api.GetOutputDerivatives(in.c, NULL, 1, NULL, NULL, 1));
    NULL_REFUSED(f->api.UpdateDiscreteStates(in.c, NULL, NULL, NULL, NULL, NULL, NULL));
    NULL_REFUSED(f->api.CompletedIntegratorStep(in.c, fmi3True, NULL, NULL));
    NULL_REFUSED(f->api.SetContinuousStates(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetContinuousStateDerivatives(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetEventIndicators(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetContinuousStates(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetNominalsOfContinuousStates(in.c, NULL, 1));
    NULL_REFUSED(f->api.GetNumberOfEventIndicators(in.c, NULL));
    NULL_REFUSED(f->api.GetNumberOfContinuousStates(in.c, NULL));
    NULL_REFUSED(f->api.GetIntervalDecimal(in.c, NULL, 1, NULL, NULL));
#endif
#undef NULL_REFUSED
    case_check(null_state == NULL, "%s: no FMU state came out of the refused deserializations", f->id);
    /* freeing a NULL state is a no-op; freeing twice through the cleared handle too */
    case_check(host_free_state(f, in.c, &null_state) == HOST_OK,
               "%s: " BY_VERSION("fmi2FreeFMUstate", "fmi3FreeFMUState") " of a NULL state is a no-op", f->id);
    case_check(host_free_state(f, in.c, &state) == HOST_OK && state == NULL
                   && host_free_state(f, in.c, &state) == HOST_OK,
               "%s: " BY_VERSION("fmi2FreeFMUstate", "fmi3FreeFMUState")
               " clears the handle, so freeing twice through it is harmless", f->id);
    free(blob);
    free(before);
    host_free_instance(&in);

    /* a NULL instance, and instances that are not instances at all */
    every_function_refuses(f, NULL, "a NULL " INSTANCE);
    {
        unsigned char *zeros = calloc(1, 1 << 16), *pattern = malloc(1 << 16);
        if (zeros && pattern) {
            memset(pattern, 0xa5, 1 << 16);
            every_function_refuses(f, zeros, "a zeroed block as " INSTANCE);
            every_function_refuses(f, pattern, "a 0xa5-filled block as " INSTANCE);
        }
        free(zeros);
        free(pattern);
    }
    group_end("null", f->id);
}

/* Another FMU's instance through f's functions, and FMU states across instances. */
static void foreign(const host_fmu *f, const host_fmu *g)
{
    host_inst other, mine, second;
    unsigned char *before;
    size_t before_size;
    host_state theirs = NULL, state = NULL;
    char what[160];
    group_start();
    if (!case_check(enter_state(g, &other, S_STEP), "%s: reach %s", g->id, state_names[S_STEP]))
        return;
    before = host_snapshot(g, other.c, &before_size);
    snprintf(what, sizeof what, "a %s instance", g->id);
    every_function_refuses(f, other.c, what);   /* FreeInstance included: it must not free it */
    case_check(host_same_state(g, other.c, before, before_size) && host_step(g, other.c, 2 * g->h, g->h) <= HOST_WARNING,
               "%s: the %s instance is unchanged and still runs after %s's functions refused it", f->id, g->id, f->id);
    host_get_state(g, other.c, &theirs);
    free(before);

    /* states belong to the instance that made them */
    if (enter_state(f, &mine, S_STEP) && enter_state(f, &second, S_STEP)) {
        static unsigned char buf[1 << 14];
        size_t size;
        host_get_state(f, second.c, &state);
        case_check(host_set_state(f, mine.c, theirs) == HOST_ERROR,
                   "%s: " BY_VERSION("fmi2SetFMUstate", "fmi3SetFMUState") " refuses a %s state", f->id, g->id);
        case_check(host_set_state(f, mine.c, state) == HOST_ERROR,
                   "%s: " BY_VERSION("fmi2SetFMUstate", "fmi3SetFMUState") " refuses a state of another %s instance",
                   f->id, f->id);
        case_check(host_state_size(f, mine.c, state, &size) == HOST_ERROR
                       && host_serialize(f, mine.c, state, buf, sizeof buf) == HOST_ERROR,
                   "%s: serializing a state of another instance is refused", f->id);
        {
            size_t blob_size;
            unsigned char *blob = host_snapshot(f, mine.c, &blob_size);
            host_state slot = state;
            case_check(blob != NULL && host_deserialize(f, mine.c, blob, blob_size, &slot) == HOST_ERROR
                           && slot == state,
                       "%s: deserializing into another instance's state is refused", f->id);
            free(blob);
        }
        case_check(host_free_state(f, mine.c, &state) == HOST_ERROR && state != NULL,
                   "%s: " BY_VERSION("fmi2FreeFMUstate", "fmi3FreeFMUState") " refuses a state of another instance",
                   f->id);
        host_free_state(f, second.c, &state);
    }
    host_free_instance(&mine);
    host_free_instance(&second);
    host_free_state(g, other.c, &theirs);
    host_free_instance(&other);
    snprintf(what, sizeof what, "%s functions, %s instance", f->id, g->id);
    group_end("foreign", what);
}

/* ------------------------------------------------------------------------ */
/* value references                                                          */

#define VR_REFUSED(x, call, fmt, ...) REFUSED(x, call, fmt " is refused, nothing changed", __VA_ARGS__)

/* Get and set of the value reference at vr (n_values values) through each typed
 * function but those of type `spared` (-1: none, vr is no variable's): refused.
 * FMI 2.0 has Real, Integer, Boolean and, at a reference of no variable,
 * String; FMI 3.0 all its 14 types. */
static void typed_calls_refused(refusal *x, const host_vr *vr, int n_values, int spared, const char *label)
{
    const host_fmu *f = x->f;
    void *c = x->in->c;
#if FMI_VERSION == 2
    double real = 1.0;
    fmi2Integer integer = 1;
    fmi2Boolean boolean = fmi2True;
    fmi2String string = "x";
    (void)n_values;
    if (spared != VAR_REAL) {
        VR_REFUSED(x, f->api.GetReal(c, vr, 1, &real), "fmi2GetReal(%s)", label);
        VR_REFUSED(x, f->api.SetReal(c, vr, 1, &real), "fmi2SetReal(%s)", label);
    }
    if (spared != VAR_INTEGER) {
        VR_REFUSED(x, f->api.GetInteger(c, vr, 1, &integer), "fmi2GetInteger(%s)", label);
        VR_REFUSED(x, f->api.SetInteger(c, vr, 1, &integer), "fmi2SetInteger(%s)", label);
    }
    if (spared != VAR_BOOLEAN) {
        VR_REFUSED(x, f->api.GetBoolean(c, vr, 1, &boolean), "fmi2GetBoolean(%s)", label);
        VR_REFUSED(x, f->api.SetBoolean(c, vr, 1, &boolean), "fmi2SetBoolean(%s)", label);
    }
    if (spared < 0) {
        VR_REFUSED(x, f->api.GetString(c, vr, 1, &string), "fmi2GetString(%s)", label);
        VR_REFUSED(x, f->api.SetString(c, vr, 1, &string), "fmi2SetString(%s)", label);
    }
#else
    static fmi3Float64 r64[HOST_MAX_ELEMENTS];
    static fmi3Float32 r32[HOST_MAX_ELEMENTS];
    static fmi3Int8 i8[HOST_MAX_ELEMENTS];
    static fmi3UInt8 u8[HOST_MAX_ELEMENTS];
    static fmi3Int16 i16[HOST_MAX_ELEMENTS];
    static fmi3UInt16 u16[HOST_MAX_ELEMENTS];
    static fmi3Int32 i32[HOST_MAX_ELEMENTS];
    static fmi3UInt32 u32[HOST_MAX_ELEMENTS];
    static fmi3Int64 i64[HOST_MAX_ELEMENTS];
    static fmi3UInt64 u64[HOST_MAX_ELEMENTS];
    static fmi3Boolean bo[HOST_MAX_ELEMENTS];
    static fmi3String st[HOST_MAX_ELEMENTS];
    static fmi3Binary bi[HOST_MAX_ELEMENTS];
    static size_t sz[HOST_MAX_ELEMENTS];
    size_t nv = (size_t)n_values;
    if (spared != VAR_REAL) {
        VR_REFUSED(x, f->api.GetFloat64(c, vr, 1, r64, nv), "fmi3GetFloat64(%s)", label);
        VR_REFUSED(x, f->api.SetFloat64(c, vr, 1, r64, nv), "fmi3SetFloat64(%s)", label);
    }
    if (spared != VAR_INTEGER) {
        VR_REFUSED(x, f->api.GetInt32(c, vr, 1, i32, nv), "fmi3GetInt32(%s)", label);
        VR_REFUSED(x, f->api.SetInt32(c, vr, 1, i32, nv), "fmi3SetInt32(%s)", label);
    }
    if (spared != VAR_BOOLEAN) {
        VR_REFUSED(x, f->api.GetBoolean(c, vr, 1, bo, nv), "fmi3GetBoolean(%s)", label);
        VR_REFUSED(x, f->api.SetBoolean(c, vr, 1, bo, nv), "fmi3SetBoolean(%s)", label);
    }
    VR_REFUSED(x, f->api.GetFloat32(c, vr, 1, r32, nv), "fmi3GetFloat32(%s)", label);
    VR_REFUSED(x, f->api.SetFloat32(c, vr, 1, r32, nv), "fmi3SetFloat32(%s)", label);
    VR_REFUSED(x, f->api.GetInt8(c, vr, 1, i8, nv), "fmi3GetInt8(%s)", label);
    VR_REFUSED(x, f->api.SetInt8(c, vr, 1, i8, nv), "fmi3SetInt8(%s)", label);
    VR_REFUSED(x, f->api.GetUInt8(c, vr, 1, u8, nv), "fmi3GetUInt8(%s)", label);
    VR_REFUSED(x, f->api.SetUInt8(c, vr, 1, u8, nv), "fmi3SetUInt8(%s)", label);
    VR_REFUSED(x, f->api.GetInt16(c, vr, 1, i16, nv), "fmi3GetInt16(%s)", label);
    VR_REFUSED(x, f->api.SetInt16(c, vr, 1, i16, nv), "fmi3SetInt16(%s)", label);
    VR_REFUSED(x, f->api.GetUInt16(c, vr, 1, u16, nv), "fmi3GetUInt16(%s)", label);
    VR_REFUSED(x, f->api.SetUInt16(c, vr, 1, u16, nv), "fmi3SetUInt16(%s)", label);
    VR_REFUSED(x, f->api.GetUInt32(c, vr, 1, u32, nv), "fmi3GetUInt32(%s)", label);
    VR_REFUSED(x, f->api.SetUInt32(c, vr, 1, u32, nv), "fmi3SetUInt32(%s)", label);
    VR_REFUSED(x, f->api.GetInt64(c, vr, 1, i64, nv), "fmi3GetInt64(%s)", label);
    VR_REFUSED(x, f->api.SetInt64(c, vr, 1, i64, nv), "fmi3SetInt64(%s)", label);
    VR_REFUSED(x, f->api.GetUInt64(c, vr, 1, u64, nv), "fmi3GetUInt64(%s)", label);
    VR_REFUSED(x, f->api.SetUInt64(c, vr, 1, u64, nv), "fmi3SetUInt64(%s)", label);
    VR_REFUSED(x, f->api.GetString(c, vr, 1, st, nv), "fmi3GetString(%s)", label);
    VR_REFUSED(x, f->api.SetString(c, vr, 1, st, nv), "fmi3SetString(%s)", label);
    VR_REFUSED(x, f->api.GetBinary(c, vr, 1, sz, bi, nv), "fmi3GetBinary(%s)", label);
    VR_REFUSED(x, f->api.SetBinary(c, vr, 1, sz, bi, nv), "fmi3SetBinary(%s)", label);
    VR_REFUSED(x, f->api.GetClock(c, vr, 1, bo), "fmi3GetClock(%s)", label);
    VR_REFUSED(x, f->api.SetClock(c, vr, 1, bo), "fmi3SetClock(%s)", label);
#endif
}

static void value_references(const host_fmu *f)
{
    static const host_vr far[] = {1000, 0x7fffffffu, 0xffffffffu};
    host_inst in;
    refusal x;
    unsigned char *before;
    size_t before_size;
    host_vr past = last_vr(f) + 1;      /* the first reference past the last variable (FMI 3.0: time) */
    char label[96];
    int i;
    group_start();
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach %s", f->id, state_names[S_STEP]))
        return;
    before = host_snapshot(f, in.c, &before_size);
    x.f = f;
    x.in = &in;
    x.before = before;
    x.before_size = before_size;
    /* past the last variable, far out */
    for (i = 0; i < 5; i++) {
        host_vr vr = i < 2 ? past + (host_vr)i : far[i - 2];
        snprintf(label, sizeof label, "vr = %u", (unsigned)vr);
        typed_calls_refused(&x, &vr, 1, -1, label);
    }
#if FMI_VERSION == 3
    /* the references of an array's other elements are not value references */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        int j;
        if (v->n < 2)
            continue;
        for (j = 1; j < v->n; j += v->n - 2 > 0 ? v->n - 2 : 1) {
            host_vr vr = v->vr + (host_vr)j;
            snprintf(label, sizeof label, "vr = %u, element %d of %s", (unsigned)vr, j + 1, v->name);
            typed_calls_refused(&x, &vr, 1, -1, label);
        }
    }
#endif
    /* every variable through the functions of the other types (with its own nValues) */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        typed_calls_refused(&x, &v->vr, v->n, v->type, v->name);
        /* outputs and time are never set; fixed parameters not after initialization */
        if (v->causality != VAR_INPUT)
            VR_REFUSED(&x, host_set(f, in.c, v, v->start[0] + 1.0), "setting %s %s in %s",
                       v->causality == VAR_OUTPUT ? "output" : v->causality == VAR_INDEPENDENT ? "independent variable"
                                                                                              : "parameter",
                       v->name, state_names[S_STEP]);
    }
#if FMI_VERSION == 3
    /* nValues that does not match the references */
    {
        const host_var *a = first_array(f), *out = first(f, VAR_OUTPUT, VAR_REAL);
        static double values[64];
        fmi3ValueReference two[2];
        VR_REFUSED(&x, f->api.GetFloat64(in.c, &a->vr, 1, values, 1), "fmi3GetFloat64(%s, nValues = 1)", a->name);
        VR_REFUSED(&x, f->api.GetFloat64(in.c, &a->vr, 1, values, (size_t)a->n + 1),
                   "fmi3GetFloat64(%s, nValues = %d)", a->name, a->n + 1);
        VR_REFUSED(&x, f->api.GetFloat64(in.c, &a->vr, 1, values, 0), "fmi3GetFloat64(%s, nValues = 0)", a->name);
        VR_REFUSED(&x, f->api.GetFloat64(in.c, &out->vr, 1, values, 2), "fmi3GetFloat64(%s, nValues = 2)", out->name);
        VR_REFUSED(&x, f->api.GetFloat64(in.c, &out->vr, 1, values, 0), "fmi3GetFloat64(%s, nValues = 0)", out->name);
        two[0] = out->vr;
        two[1] = a->vr;
        VR_REFUSED(&x, f->api.GetFloat64(in.c, two, 2, values, (size_t)a->n), "fmi3GetFloat64(%s, %s, nValues = %d)",
                   out->name, a->name, a->n);
        VR_REFUSED(&x, f->api.GetFloat64(in.c, two, 2, values, 2), "fmi3GetFloat64(%s, %s, nValues = 2)", out->name,
                   a->name);
    }
#endif
    /* a good reference followed by a bad one, or a good value then a NaN: nothing set */
    {
        const host_var *input = first(f, VAR_INPUT, VAR_REAL);
        const host_var *param = first(f, VAR_PARAMETER, VAR_REAL);
        host_vr pair[2];
        double values[2] = {0.75, 0.75};
        pair[0] = input ? input->vr : param->vr;
        pair[1] = past;
        VR_REFUSED(&x, host_set_reals(f, in.c, pair, 2, values, 2),
                   BY_VERSION("fmi2SetReal", "fmi3SetFloat64") "(%s, vr = %u) in one call",
                   input ? input->name : param->name, (unsigned)pair[1]);
        if (input) {
            values[1] = NAN;
            pair[1] = input->vr;
            VR_REFUSED(&x, host_set_reals(f, in.c, pair, 2, values, 2),
                       BY_VERSION("fmi2SetReal", "fmi3SetFloat64") "(%s = 0.75, %s = NaN) in one call", input->name,
                       input->name);
#if FMI_VERSION == 3
            values[1] = 0.75;
            VR_REFUSED(&x, f->api.SetFloat64(in.c, pair, 2, values, 3), "fmi3SetFloat64(%s, %s, nValues = 3) in one call",
                       input->name, input->name);
#endif
        }
    }
    free(before);
    host_free_instance(&in);
    group_end("vr", f->id);
}

/* ------------------------------------------------------------------------ */
/* instantiation                                                             */

static void instantiation(const host_fmu *f)
{
    host_log log;
    long mem = host_mem_in_use();
    char token[80];
    void *c;
    int i;
#if FMI_VERSION == 2
    fmi2CallbackFunctions cb = host2_callbacks(&log), partial;
    /* a Co-Simulation instance called name, of this token, logging into log */
#define TRY(name, tok) f->api.Instantiate(name, fmi2CoSimulation, tok, "", &cb, fmi2False, fmi2False)
#else
    char change[96];
    fmi3ValueReference required = 0;
#define TRY(name, tok) f->api.InstantiateCoSimulation(name, tok, NULL, fmi3False, fmi3False, fmi3False, fmi3False, \
                                                      NULL, 0, &log, host3_logger, NULL)
#endif
    group_start();
    /* NULL, and (FMI 3.0, where a logger is always there to say it) a message */
#define NOT_INSTANTIATED(call, fmt, ...)                                                                    \
    do {                                                                                                    \
        host_log_clear(&log);                                                                               \
        c = (call);                                                                                         \
        case_check(c == NULL && (FMI_VERSION == 2 || log.n_errors > 0),                                     \
                   BY_VERSION("%s: fmi2Instantiate with " fmt " returns NULL (%s)",                         \
                              "%s: " fmt " returns NULL, says why (%s)"), f->id, __VA_ARGS__, log.last_error); \
        if (c != NULL)                                                                                      \
            f->api.FreeInstance(c);                                                                         \
    } while (0)
    NOT_INSTANTIATED(TRY("x", "{00000000-0000-0000-0000-000000000000}"), "%s", "a wrong " TOKEN);
    NOT_INSTANTIATED(TRY("x", ""), "%s", "an empty " TOKEN);
    NOT_INSTANTIATED(TRY("x", NULL), "%s", "a NULL " TOKEN);
    for (i = 0; i < n_fmus; i++)
        if (&fmus[i] != f)
            NOT_INSTANTIATED(TRY("x", fmus[i].token), "the " TOKEN " of %s", fmus[i].id);
    snprintf(token, sizeof token, "%s", f->token);
    token[strlen(token) - 1] = '\0';
    NOT_INSTANTIATED(TRY("x", token), "%s", "its " TOKEN " without the closing brace");
    snprintf(token, sizeof token, "%s ", f->token);
    NOT_INSTANTIATED(TRY("x", token), "%s", "its " TOKEN " and a trailing space");
    snprintf(token, sizeof token, "%s", f->token);
    for (i = 0; token[i]; i++)
        if (token[i] >= 'a' && token[i] <= 'f')
            token[i] = (char)(token[i] - 'a' + 'A');
    NOT_INSTANTIATED(TRY("x", token), "%s", "its " TOKEN " in upper case");
#if FMI_VERSION == 2
    NOT_INSTANTIATED(f->api.Instantiate("x", fmi2ModelExchange, f->token, "", &cb, fmi2False, fmi2False), "%s",
                     "fmuType = fmi2ModelExchange");
    NOT_INSTANTIATED(f->api.Instantiate("x", (fmi2Type)2, f->token, "", &cb, fmi2False, fmi2False), "%s", "fmuType = 2");
    NOT_INSTANTIATED(f->api.Instantiate("x", (fmi2Type)-1, f->token, "", &cb, fmi2False, fmi2False), "%s",
                     "fmuType = -1");
#else
    NOT_INSTANTIATED(f->api.InstantiateCoSimulation("x", f->token, NULL, fmi3False, fmi3False, fmi3True, fmi3False,
                                                    NULL, 0, &log, host3_logger, NULL),
                     "%s", "eventModeUsed = true (no event mode)");
#endif
    NOT_INSTANTIATED(TRY(NULL, f->token), "%s", "a NULL instance name");
    NOT_INSTANTIATED(TRY("", f->token), "%s", "an empty instance name");
#if FMI_VERSION == 2
    NOT_INSTANTIATED(f->api.Instantiate("x", fmi2CoSimulation, f->token, "", NULL, fmi2False, fmi2False), "%s",
                     "NULL callbacks");
    partial = cb;
    partial.allocateMemory = NULL;
    NOT_INSTANTIATED(f->api.Instantiate("x", fmi2CoSimulation, f->token, "", &partial, fmi2False, fmi2False), "%s",
                     "no allocateMemory");
    partial = cb;
    partial.freeMemory = NULL;
    NOT_INSTANTIATED(f->api.Instantiate("x", fmi2CoSimulation, f->token, "", &partial, fmi2False, fmi2False), "%s",
                     "no freeMemory");
    partial = cb;
    partial.logger = NULL;
    NOT_INSTANTIATED(f->api.Instantiate("x", fmi2CoSimulation, f->token, "", &partial, fmi2False, fmi2False), "%s",
                     "no logger");
    case_check(host_mem_back_to(mem), "%s: the refused instantiations allocated nothing", f->id);
#else
    NOT_INSTANTIATED(f->api.InstantiateCoSimulation("x", f->token, NULL, fmi3False, fmi3False, fmi3False, fmi3False,
                                                    NULL, 3, &log, host3_logger, NULL),
                     "%s", "3 required intermediate variables at NULL");
    NOT_INSTANTIATED(f->api.InstantiateModelExchange("x", f->token, NULL, fmi3False, fmi3False, &log, host3_logger),
                     "%s", "fmi3InstantiateModelExchange");
    NOT_INSTANTIATED(f->api.InstantiateScheduledExecution("x", f->token, NULL, fmi3False, fmi3False, &log, host3_logger,
                                                          NULL, NULL, NULL),
                     "%s", "fmi3InstantiateScheduledExecution");
    case_check(host_mem_back_to(mem), "%s: the refused instantiations allocated nothing (%s)", f->id,
               mem_change(mem, change, sizeof change));
#endif
#undef NOT_INSTANTIATED
    /* and the refusals said why (FMI 2.0: all but the two without a logger to say it to) */
    host_log_clear(&log);
    c = TRY("x", "{wrong}");
    case_check(c == NULL && strstr(log.last_error, BY_VERSION("wrong GUID", "wrong instantiationToken")) != NULL,
               "%s: a wrong " TOKEN " is explained (%s)", f->id, log.last_error);
    if (c != NULL)
        f->api.FreeInstance(c);
#undef TRY
#if FMI_VERSION == 3
    /* an intermediate-variable list, earlyReturnAllowed and a resource path that has
     * no start_values file are accepted */
    c = f->api.InstantiateCoSimulation("x", f->token, "/nonexistent/resources/", fmi3False, fmi3False, fmi3False,
                                       fmi3True, &required, 1, &log, host3_logger, NULL);
    case_check(c != NULL, "%s: earlyReturnAllowed, 1 required intermediate variable and a resource folder "
               "without start_values are accepted (%s)", f->id, log.last_error);
    if (c != NULL)
        f->api.FreeInstance(c);
    {
        /* FMI 3.0 lets the importer pass no logger: the FMU runs, and says nothing */
        fmi3ValueReference bad = 100000;
        double value = 0.0;
        c = f->api.InstantiateCoSimulation("silent", f->token, NULL, fmi3False, fmi3True, fmi3False, fmi3False, NULL, 0,
                                           NULL, NULL, NULL);
        case_check(c != NULL && f->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) == fmi3OK
                       && f->api.ExitInitializationMode(c) == fmi3OK && host3_step(f, c, 0.0, f->h) <= fmi3Warning
                       && f->api.GetFloat64(c, &bad, 1, &value, 1) == fmi3Error
                       && host3_step(f, c, 0.0, f->h) == fmi3Error,
                   "%s: logMessage = NULL: it runs, and refusals still return fmi3Error", f->id);
        if (c != NULL)
            f->api.FreeInstance(c);
        c = f->api.InstantiateCoSimulation("silent", "{wrong}", NULL, fmi3False, fmi3True, fmi3False, fmi3False, NULL,
                                           0, NULL, NULL, NULL);
        case_check(c == NULL, "%s: logMessage = NULL and a wrong token: NULL, no crash", f->id);
        if (c != NULL)
            f->api.FreeInstance(c);
    }
#endif
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

/* Runs n single-sample steps; every OK/Warning step must leave finite outputs;
 * a refused step (Error) must leave the outputs as they were. */
static int run_checked(host_inst *in, int n, char *why, size_t why_size)
{
    const host_fmu *f = in->f;
    double before[HOST_MAX_OUTPUTS], after[HOST_MAX_OUTPUTS];
    int i, n_out;
    n_out = host_real_outputs(f, in->c, before, HOST_MAX_OUTPUTS);
    if (n_out < 0) {
        snprintf(why, why_size, "outputs not readable: %s", in->log.last_error);
        return 0;
    }
    if (!all_finite(before, n_out)) {
        snprintf(why, why_size, "non-finite output before stepping");
        return 0;
    }
    for (i = 0; i < n; i++) {
        host_status st = host_step(f, in->c, in->k * f->h, f->h);
        if (st == HOST_ERROR) {
            if (host_real_outputs(f, in->c, after, HOST_MAX_OUTPUTS) != n_out || memcmp(before, after, (size_t)n_out * sizeof *after)) {
                snprintf(why, why_size, "a refused step changed the outputs");
                return 0;
            }
            snprintf(why, why_size, "refused: %s", in->log.last_error);
            return 1;
        }
        if (st > HOST_ERROR || host_real_outputs(f, in->c, after, HOST_MAX_OUTPUTS) != n_out || !all_finite(after, n_out)) {
            snprintf(why, why_size, "status %d with a non-finite or unreadable output", (int)st);
            return 0;
        }
        memcpy(before, after, sizeof after);
        in->k++;
    }
    snprintf(why, why_size, "ran %d samples, outputs finite", n);
    return 1;
}

/* Initialization outputs (read in InitializationMode): Error with a message, or finite values. */
static int init_outputs_ok(host_inst *in)
{
    double out[HOST_MAX_OUTPUTS];
    int n;
    host_log_clear(&in->log);
    n = host_real_outputs(in->f, in->c, out, HOST_MAX_OUTPUTS);
    return n < 0 ? in->log.n_errors > 0 : all_finite(out, n);
}

/* One parameter (element `element` of an array, -1: a scalar) at one value:
 * refused at ExitInitializationMode with a message naming a parameter and its
 * range, or a run with finite outputs. */
static void parameter_case(const host_fmu *f, const host_var *v, int element, double value, double input)
{
    host_inst in;
    char why[1200] = "", name[80];
    int ok = 0, i;
    host_status st;
    if (element >= 0)
        snprintf(name, sizeof name, "%s[%d]", v->name, element + 1);
    else
        snprintf(name, sizeof name, "%s", v->name);
    if (!enter_state(f, &in, S_INIT)) {
        case_check(0, "%s: reach InitializationMode", f->id);
        host_free_instance(&in);
        return;
    }
    st = host_set_named(f, in.c, name, value);
    if (st != HOST_OK) {
        snprintf(why, sizeof why, "set refused: %s", in.log.last_error);
    } else if (!init_outputs_ok(&in)) {
        snprintf(why, sizeof why, "initialization outputs not finite");
    } else {
        host_log_clear(&in.log);
        st = f->api.ExitInitializationMode(in.c);
        if (st == HOST_ERROR) {
            ok = strstr(in.log.last_error, "out of range: valid range") != NULL;
            snprintf(why, sizeof why, "refused: %s", in.log.last_error);
        } else if (st == HOST_OK) {
            for (i = 0; i < f->n_vars; i++)
                if (f->vars[i].causality == VAR_INPUT)
                    host_set(f, in.c, &f->vars[i], input);
            ok = run_checked(&in, 8, why, sizeof why);
        } else {
            snprintf(why, sizeof why, "status %d", (int)st);
        }
    }
    case_check(ok, "%s: %s = %g (inputs %g): %s", f->id, name, value, input, why);
    host_free_instance(&in);
}

static void extreme_values(const host_fmu *f)
{
    int i, j, e, n;
    group_start();
    /* every parameter (each element of an array alone) at every extreme value, inputs at 1 */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
        if (v->causality != VAR_PARAMETER)
            continue;
        for (e = v->n > 1 ? 0 : -1; e < v->n; e++) {
            if (v->type == VAR_REAL)
                for (j = 0; j < N_EXTREME_REALS; j++)
                    parameter_case(f, v, e, extreme_reals[j], 1.0);
            else if (v->type == VAR_INTEGER)
                for (j = 0; j < N_EXTREME_INTS; j++)
                    parameter_case(f, v, e, (double)extreme_ints[j], 1.0);
            else
                for (j = 0; j < 2; j++)
                    parameter_case(f, v, e, (double)j, 1.0);
            if (v->n == 1)
                break;
        }
    }
    /* Booleans set with values other than true and false mean true */
    for (i = 0; i < f->n_vars; i++) {
        const host_var *v = &f->vars[i];
#if FMI_VERSION == 2
        static const int odd[] = {2, -1, INT_MAX};      /* fmi2Boolean is an int */
#else
        static const int odd[] = {2, 0x80, 0xff};       /* fmi3Boolean is a C bool: other values of its byte */
#endif
        host_inst in;
        if (v->causality != VAR_PARAMETER || v->type != VAR_BOOLEAN)
            continue;
        for (j = 0; j < 3; j++) {
            host_bool value = HOST_FALSE, got = HOST_FALSE;
#if FMI_VERSION == 2
            value = odd[j];
#else
            unsigned char byte = (unsigned char)odd[j];
            memcpy(&value, &byte, 1);
#endif
            enter_state(f, &in, S_INIT);
            case_check(host_set_bools(f, in.c, &v->vr, 1, &value, 1) == HOST_OK
                           && host_get_bools(f, in.c, &v->vr, 1, &got, 1) == HOST_OK && got == HOST_TRUE,
                       BY_VERSION("%s: fmi2SetBoolean(%s, %d) reads back as fmi2True",
                                  "%s: fmi3SetBoolean(%s, byte %d) reads back as fmi3True"), f->id, v->name, odd[j]);
            host_free_instance(&in);
        }
    }
    /* every input at every extreme value (all inputs alike, then pairs) */
    for (j = 0; j < N_EXTREME_REALS; j++) {
        host_inst in;
        char why[1200];
        if (first(f, VAR_INPUT, VAR_REAL) == NULL)
            break;
        enter_state(f, &in, S_STEP);
        for (i = 0; i < f->n_vars; i++)
            if (f->vars[i].causality == VAR_INPUT)
                host_set(f, in.c, &f->vars[i], extreme_reals[j]);
        case_check(run_checked(&in, 8, why, sizeof why), "%s: every input = %g: %s", f->id, extreme_reals[j], why);
        host_free_instance(&in);
    }
    for (n = 0, i = 0; i < f->n_vars; i++)
        n += f->vars[i].causality == VAR_INPUT;
    if (n == 2) {
        int a, b;
        for (a = 0; a < N_EXTREME_REALS; a++)
            for (b = 0; b < N_EXTREME_REALS; b++) {
                host_inst in;
                char why[1200];
                int which = 0;
                enter_state(f, &in, S_STEP);
                for (i = 0; i < f->n_vars; i++)
                    if (f->vars[i].causality == VAR_INPUT)
                        host_set(f, in.c, &f->vars[i], which++ == 0 ? extreme_reals[a] : extreme_reals[b]);
                case_check(run_checked(&in, 4, why, sizeof why), "%s: inputs (%g, %g): %s", f->id, extreme_reals[a],
                           extreme_reals[b], why);
                host_free_instance(&in);
            }
    }
    /* step sizes and communication points; lastSuccessfulTime says where the FMU is */
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
            host_inst in;
            unsigned char *before;
            size_t before_size;
            double t_at, H;
            host_step_result out;
            host_status st;
            enter_state(f, &in, S_STEP);
            /* t in samples from the current time unless extreme; H in units of h unless extreme */
            t_at = fabs(steps[i].t) >= 1e300 || isnan(steps[i].t) || steps[i].t == DBL_MIN ? steps[i].t
                                                                                               : (in.k + steps[i].t) * h;
            if (steps[i].t == DBL_MIN)
                t_at = in.k * h + DBL_MIN;    /* round-off within the tolerance */
            H = fabs(steps[i].H) >= 0.5 && fabs(steps[i].H) < 1e15 ? steps[i].H * h : steps[i].H;
            before = host_snapshot(f, in.c, &before_size);
            host_log_clear(&in.log);
            st = host_step_out(f, in.c, t_at, H, &out);
            if (!steps[i].ok && host_any_step(f) && t_at == in.k * h && H > 0.0 && H < 10.0 * h) {
                /* a step that is no whole multiple of h: taken, the FMU's time t + H */
                case_check(st <= HOST_WARNING && fabs(out.last - (t_at + H)) <= 1e-12 * h && !out.event
                               && !out.terminate && !out.early,
                           "%s: " FMI_NAME("DoStep") "(t = %g, H = %g) passes, ending between two samples (t -> %.17g)",
                           f->id, t_at, H, out.last);
            } else if (steps[i].ok) {
                double expected_end = (in.k + floor(H / h + 0.5)) * h;
                case_check(st <= HOST_WARNING && out.last == expected_end && !out.event && !out.terminate && !out.early,
                           BY_VERSION("%s: fmi2DoStep(t = %g, H = %g) passes (t -> %g)",
                                      "%s: fmi3DoStep(t = %g, H = %g) passes (lastSuccessfulTime %g, no event, no "
                                      "early return)"), f->id, t_at, H, out.last);
            } else {
                char where[64] = "";
                if (FMI_VERSION == 3)
                    snprintf(where, sizeof where, ", lastSuccessfulTime %g", out.last);
                case_check(st == HOST_ERROR && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size)
                               && out.last == in.k * h,
                           "%s: " FMI_NAME("DoStep") "(t = %g, H = %g) is refused, nothing changed%s (%s)", f->id, t_at,
                           H, where, in.log.last_error);
            }
            free(before);
            host_free_instance(&in);
        }
    }
    /* start and stop times */
    {
        static const double starts[] = {DBL_MAX, -DBL_MAX, 1e300, -1e300, 4.9406564584124654e-324, -1e9, 1e15};
        for (i = 0; i < (int)(sizeof starts / sizeof starts[0]); i++) {
            host_inst in;
            char why[1200] = "";
            int ok = 0;
            instantiate(&in, f, "start");
            if (host_enter_init(f, in.c, starts[i], 0, 0.0) == HOST_OK) {
                host_status st = f->api.ExitInitializationMode(in.c);
                if (st == HOST_ERROR) {
                    ok = in.log.n_errors > 0;
                    snprintf(why, sizeof why, "refused: %s", in.log.last_error);
                } else {
                    /* step from t0 by whole samples: refused when t0 + k h leaves the doubles */
                    double out[HOST_MAX_OUTPUTS];
                    int n_out, s;
                    ok = 1;
                    for (s = 1; s <= 3 && ok; s++) {
                        st = host_step(f, in.c, starts[i] + (s - 1) * f->h, f->h);
                        n_out = host_real_outputs(f, in.c, out, HOST_MAX_OUTPUTS);
                        if (st <= HOST_WARNING)
                            ok = n_out >= 0 && all_finite(out, n_out);
                        else
                            break;
                    }
                    snprintf(why, sizeof why, "%s", ok ? "outputs finite or step refused" : "non-finite output");
                }
            }
            case_check(ok, "%s: startTime = %g: %s", f->id, starts[i], why);
            host_free_instance(&in);
        }
        {
            struct { double start, stop; int defined; } bad[] = {
                {NAN, 0, 0}, {INFINITY, 0, 0}, {-INFINITY, 0, 0}, {1.0, 0.5, 1}, {0.0, NAN, 1}, {0.0, -DBL_MIN, 1}};
            for (i = 0; i < (int)(sizeof bad / sizeof bad[0]); i++) {
                host_inst in;
                unsigned char *before;
                size_t before_size;
                instantiate(&in, f, "setup");
                before = host_snapshot(f, in.c, &before_size);
                case_check(host_enter_init(f, in.c, bad[i].start, bad[i].defined, bad[i].stop) == HOST_ERROR
                               && host_same_state(f, in.c, before, before_size),
                           BY_VERSION("%s: fmi2SetupExperiment(startTime = %g, stopTime = %g) is refused, nothing "
                                      "changed (%s)",
                                      "%s: fmi3EnterInitializationMode(startTime = %g, stopTime = %g) is refused, "
                                      "still Instantiated (%s)"),
                           f->id, bad[i].start, bad[i].stop, in.log.last_error);
                free(before);
                host_free_instance(&in);
            }
        }
    }
    group_end("extreme", f->id);
}

/* ------------------------------------------------------------------------ */
/* FreeInstance in every state                                               */

static void free_in_every_state(const host_fmu *f)
{
    int s, with_states;
    char change[96];
    group_start();
    for (s = 0; s < N_STATES; s++)
        for (with_states = 0; with_states < 2; with_states++) {
            long mem = host_mem_in_use();
            host_inst in;
            int reached = enter_state(f, &in, s);
            if (reached && with_states) {
                host_state a = NULL, b = NULL, d = NULL;
                size_t size;
                unsigned char *blob = host_snapshot(f, in.c, &size);
                host_get_state(f, in.c, &a);
                host_get_state(f, in.c, &b);
                if (blob != NULL)
                    host_deserialize(f, in.c, blob, size, &d);
                free(blob);
                reached = a != NULL && b != NULL && d != NULL;
            }
            host_free_instance(&in);
            case_check(reached && host_mem_back_to(mem), "%s: " FMI_NAME("FreeInstance") " in %s%s frees every "
                       MEM_UNIT " (%s)", f->id, state_names[s], with_states ? " with 3 FMU states still allocated" : "",
                       mem_change(mem, change, sizeof change));
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

/* One doStep of H from the instance's time; *out: where it left the FMU. */
static host_status step_within_a_minute(host_inst *in, double H, host_step_result *out)
{
    host_status st;
    signal(SIGALRM, on_hang);
    alarm(60);
    st = host_step_out(in->f, in->c, in->k * in->f->h, H, out);
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

/* A step size of 0 or below is refused (communicationStepSize > 0); a positive
 * one below 1e-9 h rounds to no sample and is a no-op. */
static void edge_zero_step(const host_fmu *f)
{
    const double refused[] = {0.0, -0.0, -1e-20, -5.6e-17, -f->h};
    const double no_ops[] = {1e-20, 5.6e-17, 1e-10 * f->h};
    host_inst in;
    host_step_result out;
    unsigned char *before;
    size_t before_size, i;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach %s", f->id, state_names[S_STEP]))
        return;
    before = host_snapshot(f, in.c, &before_size);
    for (i = 0; i < sizeof refused / sizeof refused[0]; i++) {
        host_status st;
        host_log_clear(&in.log);
        st = step_within_a_minute(&in, refused[i], &out);
        case_check(st == HOST_ERROR && strstr(in.log.last_error, "communicationStepSize") != NULL
                       && strstr(in.log.last_error, "> 0") != NULL && out.last == in.k * f->h
                       && host_same_state(f, in.c, before, before_size),
                   "%s: " FMI_NAME("DoStep") "(H = %g) is refused: the step size must be > 0, nothing changed (%s)",
                   f->id, refused[i], in.log.last_error);
    }
    for (i = 0; i < sizeof no_ops / sizeof no_ops[0]; i++) {
        host_status st;
        host_log_clear(&in.log);
        st = step_within_a_minute(&in, no_ops[i], &out);
        case_check(st == HOST_OK && in.log.n_errors == 0 && out.last == in.k * f->h
                       && host_same_state(f, in.c, before, before_size),
                   "%s: " FMI_NAME("DoStep") "(H = %g) rounds to no sample: a no-op returning " FMI_NAME("OK") " (%s)",
                   f->id, no_ops[i], in.log.last_error);
    }
    free(before);
    host_free_instance(&in);
}

/* A step of more samples than one doStep may compute is refused at once with
 * the bound (FMI 3.0: no early return, documented); in exact creep mode (work
 * O(k) a sample) the bound on the terms of the creep sum too, with the longest
 * step that passes from here. */
static void edge_huge_step(const host_fmu *f)
{
    host_inst in;
    host_step_result out;
    unsigned char *before;
    size_t before_size;
    unsigned long long bound, terms_bound, longest;
    host_status st;
    double a;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach %s", f->id, state_names[S_STEP]))
        return;
    before = host_snapshot(f, in.c, &before_size);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, 1e9, &out);
    bound = number_after(in.log.last_error, "computes at most ");
    case_check(st == HOST_ERROR && bound > 0 && out.last == in.k * f->h && host_same_state(f, in.c, before, before_size),
               "%s: " FMI_NAME("DoStep") "(H = 1e9 s) is refused at once, naming the bound of one doStep (%s)", f->id,
               in.log.last_error);
    /* the harness steps h, its longest experiments are minutes: they all pass */
    case_check((double)bound * f->h >= 1000.0, "%s: the bound, %llu samples, is at least 1000 s of h = %g s", f->id,
               bound, f->h);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, (double)(bound + 1) * f->h, &out);
    case_check(st == HOST_ERROR && number_after(in.log.last_error, "computes at most ") == bound
                   && host_same_state(f, in.c, before, before_size),
               "%s: " FMI_NAME("DoStep") " of bound + 1 = %llu samples is refused (%s)", f->id, bound + 1,
               in.log.last_error);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, 1e300, &out);
    case_check(st == HOST_ERROR && in.log.n_errors > 0 && host_same_state(f, in.c, before, before_size),
               "%s: " FMI_NAME("DoStep") "(H = 1e300 s) is refused (%s)", f->id, in.log.last_error);
    free(before);
    host_free_instance(&in);

    if (host_named(f, "creep.exact", NULL) == NULL)
        return;
    /* exact creep: 2 samples done, the next sums a = 3 terms */
    instantiate(&in, f, "exact");
    host_enter_init(f, in.c, 0.0, 0, 0.0);
    host_set_named(f, in.c, "creep.exact", 1.0);
    if (!case_check(f->api.ExitInitializationMode(in.c) == HOST_OK
                        && host_step(f, in.c, 0.0, 2 * f->h) <= HOST_WARNING,
                    "%s: exact creep, 2 samples", f->id)) {
        host_free_instance(&in);
        return;
    }
    in.k = 2;
    a = 3.0;
    before = host_snapshot(f, in.c, &before_size);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, (double)bound * f->h, &out);
    terms_bound = number_after(in.log.last_error, "sums at most ");
    longest = number_after(in.log.last_error, "a step of at most ");
    case_check(st == HOST_ERROR && terms_bound > 0 && host_same_state(f, in.c, before, before_size),
               "%s: with creep.exact a step of %llu samples is refused at once, naming the bound on the terms of "
               "the creep sum (%s)", f->id, bound, in.log.last_error);
    /* reference: the closed form of the sum a + (a + 1) + ... */
    case_check(longest >= 1 && creep_terms((double)longest, a) <= (double)terms_bound
                   && creep_terms((double)longest + 1.0, a) > (double)terms_bound,
               "%s: the longest step it names, %llu samples, is the longest whose creep sums stay within %llu terms",
               f->id, longest, terms_bound);
    host_log_clear(&in.log);
    st = step_within_a_minute(&in, (double)(longest + 1) * f->h, &out);
    case_check(st == HOST_ERROR && number_after(in.log.last_error, "sums at most ") == terms_bound
                   && host_same_state(f, in.c, before, before_size),
               "%s: with creep.exact a step of %llu samples is refused (%s)", f->id, longest + 1, in.log.last_error);
    free(before);
    host_free_instance(&in);
}

/* No value reference: FMI 2.0 (no nValues) needs no arrays for nvr = 0 and both
 * for nvr > 0; FMI 3.0's nValues must equal the values the references hold
 * (FMI 3.0, 2.2.6.2), with none that is 0, in every getter and setter. */
static void edge_value_counts(const host_fmu *f)
{
    host_inst in;
    unsigned char *before;
    size_t before_size;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach %s", f->id, state_names[S_STEP]))
        return;
    before = host_snapshot(f, in.c, &before_size);
    /* OK without a message, or Error (FMI 3.0: naming nValues); nothing changed */
#define COUNT_CASE(call, text, expected, what)                                                           \
    do {                                                                                                 \
        host_status st_;                                                                                 \
        host_log_clear(&in.log);                                                                         \
        st_ = (call);                                                                                    \
        case_check(st_ == (expected)                                                                     \
                       && (st_ == HOST_OK ? in.log.n_errors == 0                                         \
                                          : FMI_VERSION == 2 ? in.log.n_errors > 0                       \
                                                             : strstr(in.log.last_error, "nValues") != NULL) \
                       && host_same_state(f, in.c, before, before_size),                                 \
                   "%s: %s: %s (%s)", f->id, text, what, in.log.last_error);                             \
    } while (0)
#if FMI_VERSION == 2
    {
        fmi2ValueReference vr = first(f, VAR_OUTPUT, VAR_REAL)->vr;
        double real = 0.0;
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
    }
#else
#define NO_VR_REFUSED(call) COUNT_CASE(call, #call, fmi3Error, "nValues = 1 without a value reference is refused")
#define NO_VR_PASSES(call) COUNT_CASE(call, #call, fmi3OK, "nValues = 0 without a value reference: nothing to do")
    NO_VR_REFUSED(f->api.GetFloat64(in.c, NULL, 0, scratch_real, 1));
    NO_VR_REFUSED(f->api.GetInt32(in.c, NULL, 0, scratch_int, 1));
    NO_VR_REFUSED(f->api.GetBoolean(in.c, NULL, 0, scratch_bool, 1));
    NO_VR_REFUSED(f->api.GetFloat32(in.c, NULL, 0, (fmi3Float32 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetInt8(in.c, NULL, 0, (fmi3Int8 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetUInt8(in.c, NULL, 0, (fmi3UInt8 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetInt16(in.c, NULL, 0, (fmi3Int16 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetUInt16(in.c, NULL, 0, (fmi3UInt16 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetUInt32(in.c, NULL, 0, (fmi3UInt32 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetInt64(in.c, NULL, 0, (fmi3Int64 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.GetUInt64(in.c, NULL, 0, scratch_u64, 1));
    NO_VR_REFUSED(f->api.GetString(in.c, NULL, 0, scratch_str, 1));
    NO_VR_REFUSED(f->api.GetBinary(in.c, NULL, 0, scratch_size, scratch_bin, 1));
    NO_VR_REFUSED(f->api.SetFloat64(in.c, NULL, 0, scratch_real, 1));
    NO_VR_REFUSED(f->api.SetInt32(in.c, NULL, 0, scratch_int, 1));
    NO_VR_REFUSED(f->api.SetBoolean(in.c, NULL, 0, scratch_bool, 1));
    NO_VR_REFUSED(f->api.SetFloat32(in.c, NULL, 0, (const fmi3Float32 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetInt8(in.c, NULL, 0, (const fmi3Int8 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetUInt8(in.c, NULL, 0, (const fmi3UInt8 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetInt16(in.c, NULL, 0, (const fmi3Int16 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetUInt16(in.c, NULL, 0, (const fmi3UInt16 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetUInt32(in.c, NULL, 0, (const fmi3UInt32 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetInt64(in.c, NULL, 0, (const fmi3Int64 *)scratch_real, 1));
    NO_VR_REFUSED(f->api.SetUInt64(in.c, NULL, 0, scratch_u64, 1));
    NO_VR_REFUSED(f->api.SetString(in.c, NULL, 0, scratch_str, 1));
    NO_VR_REFUSED(f->api.SetBinary(in.c, NULL, 0, scratch_size, scratch_bin, 1));
    NO_VR_PASSES(f->api.GetFloat64(in.c, NULL, 0, NULL, 0));
    NO_VR_PASSES(f->api.SetFloat64(in.c, NULL, 0, NULL, 0));
    NO_VR_PASSES(f->api.GetFloat32(in.c, NULL, 0, NULL, 0));
    NO_VR_PASSES(f->api.SetBinary(in.c, NULL, 0, NULL, NULL, 0));
#undef NO_VR_REFUSED
#undef NO_VR_PASSES
#endif
#undef COUNT_CASE
    free(before);
    host_free_instance(&in);
}

/* One run of n single-sample steps with input v at `value` (set before
 * initialization or after it): the outputs after each step, the statuses,
 * the first warning, Terminate's status and message, v read back. */
typedef struct {
    double out[8][HOST_MAX_OUTPUTS];
    int n_out;
    host_status status[8], terminate;
    char first_warning[1024], terminate_message[1024];
    double v_read;
} ranged_run;

static int run_with_input(const host_fmu *f, const host_var *v, double value, int before_init, int n, ranged_run *r)
{
    host_inst in;
    int k;
    memset(r, 0, sizeof *r);
    if (instantiate(&in, f, "range") == NULL)
        return 0;
    if (before_init && host_set_reals(f, in.c, &v->vr, 1, &value, 1) != HOST_OK)
        return host_free_instance(&in), 0;
    if (host_enter_init(f, in.c, 0.0, 0, 0.0) != HOST_OK || f->api.ExitInitializationMode(in.c) != HOST_OK
        || (!before_init && host_set_reals(f, in.c, &v->vr, 1, &value, 1) != HOST_OK))
        return host_free_instance(&in), 0;
    for (k = 0; k < n; k++) {
        host_log_clear(&in.log);
        r->status[k] = host_step(f, in.c, k * f->h, f->h);
        if (r->status[k] == HOST_WARNING && r->first_warning[0] == '\0')
            snprintf(r->first_warning, sizeof r->first_warning, "%s", in.log.last);
        r->n_out = host_real_outputs(f, in.c, r->out[k], HOST_MAX_OUTPUTS);
    }
    host_get_reals(f, in.c, &v->vr, 1, &r->v_read, 1);
    host_log_clear(&in.log);
    r->terminate = f->api.Terminate(in.c);
    snprintf(r->terminate_message, sizeof r->terminate_message, "%s", in.log.last);
    host_free_instance(&in);
    return r->n_out > 0;
}

/* An input beyond its declared [min, max] is clamped to it: the run equals the
 * run at the bound (the reference), the first doStep that clamps returns
 * Warning saying so, and Terminate reports the count. */
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
            const char *when = cases[c].before_init ? "set before initialization" : "set in " STEP_STATE;
            if (!case_check(run_with_input(f, v, cases[c].bound, cases[c].before_init, n, &at_bound)
                                && run_with_input(f, v, cases[c].value, cases[c].before_init, n, &beyond),
                            "%s: runs with %s = %g and %g", f->id, v->name, cases[c].bound, cases[c].value))
                continue;
            for (k = 0; k < n; k++) {
                same = same && memcmp(at_bound.out[k], beyond.out[k], (size_t)at_bound.n_out * sizeof(double)) == 0;
                quiet = quiet && at_bound.status[k] == HOST_OK && (k == 0 || beyond.status[k] == HOST_OK);
            }
            case_check(same && beyond.n_out == at_bound.n_out,
                       "%s: %s = %g (%s) gives the outputs of %s = %g at every sample", f->id, v->name,
                       cases[c].value, when, v->name, cases[c].bound);
            case_check(beyond.status[0] == HOST_WARNING && strstr(beyond.first_warning, "clamped") != NULL
                           && strstr(beyond.first_warning, range) != NULL && quiet,
                       "%s: the first doStep with %s = %g warns once, naming the range %s; %s = %g warns never (%s)",
                       f->id, v->name, cases[c].value, range, v->name, cases[c].bound, beyond.first_warning);
            case_check(beyond.terminate == HOST_WARNING && strstr(beyond.terminate_message, count) != NULL
                           && at_bound.terminate == HOST_OK,
                       "%s: " FMI_NAME("Terminate") " reports the count: %s (%s)", f->id, count,
                       beyond.terminate_message);
            case_check(beyond.v_read == cases[c].value, "%s: %s reads back as set, %g", f->id, v->name,
                       beyond.v_read);
        }
    }
}

/* FreeFMUState(c, NULL) is ignored (FMI 2.0 and 3.0: "If a null pointer is
 * provided, the call is ignored"); the monitor's warning says what
 * monitor.divergence_samples = 0 means (never unstable). */
static void edge_small_ones(const host_fmu *f)
{
    host_inst in;
    unsigned char *before;
    size_t before_size;
    host_status st;
    int k, window;
    if (!case_check(enter_state(f, &in, S_STEP), "%s: reach %s", f->id, state_names[S_STEP]))
        return;
    before = host_snapshot(f, in.c, &before_size);
    host_log_clear(&in.log);
    st = host_free_state(f, in.c, NULL);
    case_check(st == HOST_OK && in.log.n_errors == 0 && host_same_state(f, in.c, before, before_size),
               "%s: " BY_VERSION("fmi2FreeFMUstate", "fmi3FreeFMUState") "(c, NULL) is ignored: " FMI_NAME("OK")
               ", nothing changed (%s)", f->id, in.log.last_error);
    free(before);
    host_free_instance(&in);

    if (host_named(f, "monitor.divergence_samples", NULL) == NULL)
        return;
    for (window = 0; window <= 1000; window += 1000) {
        char warning[1024] = "", expected[128];
        int failed = 0;
        instantiate(&in, f, "monitor");
        host_enter_init(f, in.c, 0.0, 0, 0.0);
        /* an FMU with the stage inside: a noisy sensor (10 nm rms) puts |pred_error| above 1e-3 um */
        if (host_named(f, "y_meas", NULL) != NULL && host_named(f, "y_meas", NULL)->causality != VAR_INPUT)
            host_set_named(f, in.c, "sensor.noise_rms", 0.01);
        host_set_named(f, in.c, "monitor.divergence_samples", window);
        host_set_named(f, in.c, "monitor.pred_error_max", 1e-3);
        host_set_named(f, in.c, "sup.enabled", 0.0);    /* no loop: the supervision would stop it */
        f->api.ExitInitializationMode(in.c);
        host_set_named(f, in.c, "y_meas", 5.0);     /* the model predicts 0: |pred_error| is far above 1e-3 um */
        /* 20 samples: the monitor's share of large errors is judged from sample 32 on and would stop
         * this drive there (PIEZO_MONITOR_SHARE_MIN_SAMPLES) */
        for (k = 0; k < 20; k++) {
            host_log_clear(&in.log);
            st = host_step(f, in.c, k * f->h, f->h);
            failed = failed || st == HOST_ERROR;
            if (st == HOST_WARNING && strstr(in.log.last, "pred_error") != NULL && warning[0] == '\0')
                snprintf(warning, sizeof warning, "%s", in.log.last);
        }
        if (window == 0) {
            case_check(!failed && strstr(warning, "never") != NULL && strstr(warning, "= 0 consecutive") == NULL,
                       "%s: with monitor.divergence_samples = 0 the loop is never declared unstable, and the "
                       "warning says so (%s)", f->id, warning);
        } else {
            snprintf(expected, sizeof expected, "monitor.divergence_samples = %d consecutive samples, or in 25 %% "
                     "of the last %d,", window, window);
            case_check(!failed && strstr(warning, expected) != NULL,
                       "%s: with monitor.divergence_samples = %d the warning names the window (%s)", f->id, window,
                       warning);
        }
        host_free_instance(&in);
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

/* ------------------------------------------------------------------------ */
/* fast paths                                                                */

/*
 * A master's exchange skips the checks it passes (fmu_glue_core.c): a set of
 * finite Real inputs, a get of scalars of the getter's type, a doStep from
 * exactly the FMU's time over exactly h. Each case runs the same exchange in
 * two instances, once through the fast path and once through the full one,
 * and compares what they hold afterwards byte for byte (the serialized
 * state) and what they return: a fast path that diverged would differ here.
 */
static void fast_paths(const host_fmu *f)
{
    host_inst a, b;
    unsigned char *blob_a = NULL, *blob_b = NULL;
    size_t size_a = 0, size_b = 0;
    const host_var *param = host_find(f, VAR_PARAMETER, VAR_REAL);
    int v, k, same;
    group_start();
    /* sets: each Real input alone (the fast path) in a, with a Real parameter at
     * its start value (a parameter: the full path) in b, before initialization */
    if (case_check(instantiate(&a, f, "fast") != NULL && instantiate(&b, f, "full") != NULL && param != NULL,
                   "%s: two instances and a Real parameter", f->id)) {
        int ok = 1;
        for (v = 0; v < f->n_vars; v++) {
            const host_var *in = &f->vars[v];
            host_vr both[2];
            double value = 0.375 + v, values[2];
            if (in->causality != VAR_INPUT || in->type != VAR_REAL)
                continue;
            both[0] = in->vr;
            both[1] = param->vr;
            values[0] = value;
            values[1] = param->start[0];
            ok = ok && host_set_reals(f, a.c, &in->vr, 1, &value, 1) == HOST_OK
                 && host_set_reals(f, a.c, &param->vr, 1, &param->start[0], 1) == HOST_OK
                 && host_set_reals(f, b.c, both, 2, values, 2) == HOST_OK;
        }
        blob_a = host_snapshot(f, a.c, &size_a);
        blob_b = host_snapshot(f, b.c, &size_b);
        same = blob_a != NULL && blob_b != NULL && size_a == size_b && memcmp(blob_a, blob_b, size_a) == 0;
        case_check(ok && same, "%s: Real inputs set alone (fast path) and beside a parameter (full path): "
                   "the same state", f->id);
        free(blob_a);
        free(blob_b);
        /* doSteps: from t = k h over h (the fast path) in a; from the next double
         * after t over the next double after h (within the tolerances: the full
         * path) in b; the same statuses and states, every sample */
        ok = host_enter_init(f, a.c, 0.0, 0, 0.0) == HOST_OK && host_enter_init(f, b.c, 0.0, 0, 0.0) == HOST_OK
             && f->api.ExitInitializationMode(a.c) == HOST_OK && f->api.ExitInitializationMode(b.c) == HOST_OK;
        for (k = 0; ok && k < 6; k++) {
            double t = k * f->h;
            host_status sa = host_step(f, a.c, t, f->h);
            host_status sb = host_step(f, b.c, nextafter(t, 1.0), nextafter(f->h, 1.0));
            blob_a = host_snapshot(f, a.c, &size_a);
            blob_b = host_snapshot(f, b.c, &size_b);
            ok = sa <= HOST_WARNING && sa == sb && blob_a != NULL && blob_b != NULL && size_a == size_b
                 && memcmp(blob_a, blob_b, size_a) == 0;
            free(blob_a);
            free(blob_b);
        }
        case_check(ok, "%s: " FMI_NAME("DoStep") " from t = k h over h (fast path) and from t + 1 ulp over "
                   "h + 1 ulp (full path): the same statuses and states over 6 samples (k = %d)", f->id, k);
#if FMI_VERSION == 3
        /* gets: every scalar Real alone (the fast path) and beside time (the full path) */
        {
            const host_var *time = host_find(f, VAR_INDEPENDENT, VAR_REAL);
            ok = time != NULL;
            for (v = 0; ok && v < f->n_vars; v++) {
                const host_var *x = &f->vars[v];
                host_vr both[2];
                double alone, pair[2];
                if (x->type != VAR_REAL || x->n != 1 || x->causality == VAR_INDEPENDENT)
                    continue;
                both[0] = x->vr;
                both[1] = time->vr;
                ok = host_get_reals(f, a.c, &x->vr, 1, &alone, 1) == HOST_OK
                     && host_get_reals(f, b.c, both, 2, pair, 2) == HOST_OK
                     && memcmp(&alone, &pair[0], sizeof alone) == 0 && pair[1] == 6 * f->h;
            }
            case_check(ok, "%s: every scalar Real read alone (fast path) and beside time (full path): "
                       "the same bits", f->id);
        }
#endif
    }
    host_free_instance(&a);
    host_free_instance(&b);
    group_end("fast paths", f->id);
}

/* stdout's buffer: static, so that printing allocates nothing on the heap whose use FMI 3.0 compares */
static char stdout_buffer[1 << 14];

int main(int argc, char **argv)
{
    int i, j;
    long mem;
    char change[96];
    if (argc < 3 || argc % 2 == 0 || (argc - 1) / 2 > MAX_FMUS) {
        fprintf(stderr, "usage: %s MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, stdout_buffer, _IOLBF, sizeof stdout_buffer);
    host_verbose = getenv("FMU_NEGATIVE_VERBOSE") != NULL;
    for (i = 1; i + 1 < argc; i += 2)
        if (!host_load(&fmus[n_fmus++], argv[i], argv[i + 1]))
            return 2;
#if FMI_VERSION == 3
    printf("heap: %s\n", host_heap_note());
#endif
    mem = host_mem_in_use();
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
        fast_paths(&fmus[i]);
    for (i = 0; i < n_fmus; i++)
        edges(&fmus[i]);     /* last: before issue 23 its huge step ran for hours */
    case_check(host_mem_back_to(mem), "every " MEM_UNIT " the FMUs allocated was freed (%s)",
               mem_change(mem, change, sizeof change));
    for (i = 0; i < n_fmus; i++)
        host_unload(&fmus[i]);
    return host_summary();
}
