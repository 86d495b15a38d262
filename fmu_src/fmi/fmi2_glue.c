/*
 * fmi2_glue.c - the FMI 2.0 Co-Simulation layer, compiled into each FMU
 * together with that FMU's model.c (see fmu_model.h for the contract) and the
 * version-neutral part of the layer, fmu_glue_core.c, which does the work:
 * this file checks what only FMI 2.0 has (fmuType, the GUID argument, the
 * callback structure, the status functions) and maps the fmi2 functions onto
 * the core.
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
 * that made it, an FMU state only by the instance that made it; states still
 * allocated at fmi2FreeInstance are freed with it. A NULL logger callback is
 * refused at fmi2Instantiate (see there).
 *
 * Time is t0 + k h with an integer sample counter k. A communication step H
 * must be > 0 (FMI 2.0 and 3.0) and n h (|H - n h| <= 1e-9 max(1, n) h); the n
 * samples are computed with the inputs held. A positive step that rounds to no
 * sample (H below 1e-9 h, as importers issue when they step to input time
 * points that equal the FMU's grid up to round-off) is a no-op returning
 * fmi2OK; H <= 0 is refused. A step whose end passes the stopTime of
 * fmi2SetupExperiment is refused, and so is one that would do more work than a
 * host should wait for in one call (more than MAX_STEP_SAMPLES samples, or with
 * exact creep more than MAX_STEP_CREEP_TERMS terms of its sum: fmu_glue_core.c).
 * A model that takes steps of any size (MODEL_HAS_ANY_STEP, fmu_model.h:
 * PiezoStageClosedLoop) accepts every finite H > 0: the step computes the
 * samples whose instants it passes, and the FMU's time may end between two
 * of them, t0 + k h + t_off with 0 < t_off < h, the outputs held from the
 * last instant; an end within the time tolerance of an instant is on it.
 * After a step the model may ask for a warning (logged once per kind, e.g.
 * the first clipped voltage, with a count at fmi2Terminate); fmi2DoStep then
 * returns fmi2Warning. Logging: messages go through the host's
 * logger as (..., "%s", text). Categories logEvents, logStatusWarning,
 * logStatusError, logAll. Errors and warnings are logged even with
 * loggingOn = false (only the logEvents trace is debug logging), unless
 * switched off explicitly with fmi2SetDebugLogging.
 *
 * FMU states and their serialized form are the core's (fmu_glue_core.c
 * documents the blob format): the same in FMI 2.0 and FMI 3.0. Freeing a NULL
 * state (fmi2FreeFMUstate(c, NULL) or *FMUstate == NULL) is ignored, as the
 * standard says.
 */
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_glue_core.h"

typedef char vr_is_32_bits[sizeof(fmi2ValueReference) == sizeof(uint32_t) ? 1 : -1];
typedef char integer_is_int[sizeof(fmi2Integer) == sizeof(int) && sizeof(fmi2Boolean) == sizeof(int) ? 1 : -1];

static const glue_version fmi2 = {
    { "Instantiated", "InitializationMode", "StepComplete", "Terminated", "Error" },
    { "Real", "Integer", "Boolean" },
    "GUID",
    "fmi2ExitInitializationMode",
    "fmi2SetupExperiment",
    "fmi2DoStep",
    "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2DeSerializeFMUstate", "fmi2SerializedFMUstateSize", "fmi2Reset",
    0,      /* no arrays: every variable is a scalar, value reference = model table index */
    0       /* no time variable (FMI 2.0 has none) */
};

/* The host's logger takes a format: the text goes through "%s". */
static void deliver(const glue_host *host, const char *instance_name, glue_status status,
                    const char *category, const char *text)
{
    fmi2CallbackLogger logger = (fmi2CallbackLogger)host->logger;
    logger((fmi2ComponentEnvironment)host->env, instance_name, (fmi2Status)status, category, "%s", text);
}

static glue_host host_of(const fmi2CallbackFunctions *functions)
{
    glue_host host;
    host.deliver = deliver;
    host.logger = (glue_function)functions->logger;
    host.env = functions->componentEnvironment;
    host.alloc = functions->allocateMemory;
    host.release = functions->freeMemory;
    return host;
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
    static const char fname[] = "fmi2Instantiate";
    glue_host host;
    (void)visible;
    /* No logger, no instance (as the Modelica Reference FMUs do): every refusal
     * is explained only through the logger, and a host that cannot hear why a
     * call failed should learn that at once, not at its first fmi2Error. */
    if (functions == NULL || functions->logger == NULL)
        return NULL;
    host = host_of(functions);
    if (instanceName == NULL || instanceName[0] == '\0') {
        glue_host_log(&host, instanceName, GLUE_ERROR, "%s: missing instance name", fname);
        return NULL;
    }
    if (functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        glue_host_log(&host, instanceName, GLUE_ERROR,
                      "%s: the callbacks allocateMemory and freeMemory are required", fname);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        glue_host_log(&host, instanceName, GLUE_ERROR, "%s: %s supports Co-Simulation only (fmuType = %d)",
                      fname, MODEL_IDENTIFIER_STRING, (int)fmuType);
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MODEL_GUID) != 0) {
        glue_host_log(&host, instanceName, GLUE_ERROR, "%s: wrong GUID %s: this binary is %s %s", fname,
                      fmuGUID != NULL ? fmuGUID : "(NULL)", MODEL_IDENTIFIER_STRING, MODEL_GUID);
        return NULL;
    }
    return glue_instantiate(&host, &fmi2, fname, instanceName, fmuResourceLocation, 1,
                            "fmuResourceLocation", loggingOn != fmi2False);
}

void fmi2FreeInstance(fmi2Component c)
{
    glue_free_instance(c, "fmi2FreeInstance");
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    return (fmi2Status)glue_set_debug_logging(c, "fmi2SetDebugLogging", loggingOn != fmi2False, nCategories,
                                              categories);
}

/* ------------------------------------------------------------------------ */
/* Experiment, initialization, termination                                   */

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined;     /* a discrete-time model: no tolerance to honour */
    (void)tolerance;
    return (fmi2Status)glue_setup(c, "fmi2SetupExperiment", startTime, stopTimeDefined != fmi2False,
                                  stopTime, 0);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return (fmi2Status)glue_enter_init(c, "fmi2EnterInitializationMode");
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return (fmi2Status)glue_exit_init(c, "fmi2ExitInitializationMode");
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    return (fmi2Status)glue_terminate(c, "fmi2Terminate");
}

fmi2Status fmi2Reset(fmi2Component c)
{
    return (fmi2Status)glue_reset(c, "fmi2Reset");
}

/* ------------------------------------------------------------------------ */
/* Getting and setting variables                                             */

GLUE_HOT_PATH
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    return (fmi2Status)glue_get(c, "fmi2GetReal", vr, nvr, GLUE_VALUES_DOUBLE, value, nvr);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    return (fmi2Status)glue_get(c, "fmi2GetInteger", vr, nvr, GLUE_VALUES_INT, value, nvr);
}

GLUE_HOT_PATH
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    return (fmi2Status)glue_get(c, "fmi2GetBoolean", vr, nvr, GLUE_VALUES_BOOL_INT, value, nvr);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    glue_instance *inst = glue_instance_of(c, "fmi2GetString", GLUE_MASK_GET);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    if (glue_null_arg(inst, "fmi2GetString", "vr", vr))
        return fmi2Error;
    glue_log_error(inst, "fmi2GetString: value reference %u is not a String variable (the FMU has none)",
                   (unsigned)vr[0]);
    return fmi2Error;
}

GLUE_HOT_PATH
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    return (fmi2Status)glue_set(c, "fmi2SetReal", vr, nvr, GLUE_VALUES_DOUBLE, value, nvr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    return (fmi2Status)glue_set(c, "fmi2SetInteger", vr, nvr, GLUE_VALUES_INT, value, nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    return (fmi2Status)glue_set(c, "fmi2SetBoolean", vr, nvr, GLUE_VALUES_BOOL_INT, value, nvr);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    glue_instance *inst = glue_instance_of(c, "fmi2SetString", GLUE_MASK_SET);
    (void)value;
    if (inst == NULL)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    if (glue_null_arg(inst, "fmi2SetString", "vr", vr))
        return fmi2Error;
    glue_log_error(inst, "fmi2SetString: value reference %u is not a String variable (the FMU has none)",
                   (unsigned)vr[0]);
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* Stepping                                                                  */

GLUE_HOT_PATH
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)glue_do_step(c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize, NULL);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return (fmi2Status)glue_refuse(c, "fmi2CancelStep", GLUE_MODE_ALL, "%s",
                                   "no step is in progress (fmi2DoStep is synchronous and never returns fmi2Pending)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return (fmi2Status)glue_refuse(c, "fmi2SetRealInputDerivatives", GLUE_MODE_ALL, "%s",
                                   "not supported (canInterpolateInputs = false: inputs are held over a step)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return (fmi2Status)glue_refuse(c, "fmi2GetRealOutputDerivatives", GLUE_MODE_ALL, "%s",
                                   "not supported (maxOutputDerivativeOrder = 0)");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)value;
    return (fmi2Status)glue_refuse(c, "fmi2GetStatus", GLUE_MASK_STATUS,
                                   "status kind %d not available (fmi2DoStep never returns fmi2Pending)", (int)s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    glue_instance *inst = glue_instance_of(c, "fmi2GetRealStatus", GLUE_MASK_STATUS);
    if (inst == NULL)
        return fmi2Error;
    if (glue_null_arg(inst, "fmi2GetRealStatus", "value", value))
        return fmi2Error;
    if (s != fmi2LastSuccessfulTime) {
        glue_log_error(inst, "fmi2GetRealStatus: status kind %d not available (only fmi2LastSuccessfulTime)",
                       (int)s);
        return fmi2Error;
    }
    *value = glue_time(inst);
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)value;
    return (fmi2Status)glue_refuse(c, "fmi2GetIntegerStatus", GLUE_MASK_STATUS, "status kind %d not available",
                                   (int)s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    glue_instance *inst = glue_instance_of(c, "fmi2GetBooleanStatus", GLUE_MASK_STATUS);
    if (inst == NULL)
        return fmi2Error;
    if (glue_null_arg(inst, "fmi2GetBooleanStatus", "value", value))
        return fmi2Error;
    if (s != fmi2Terminated) {
        glue_log_error(inst, "fmi2GetBooleanStatus: status kind %d not available (only fmi2Terminated)", (int)s);
        return fmi2Error;
    }
    *value = fmi2False;     /* the slave never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)value;
    return (fmi2Status)glue_refuse(c, "fmi2GetStringStatus", GLUE_MASK_STATUS, "status kind %d not available",
                                   (int)s);
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    /* allowed in Error too (FMI 2.0): a host may keep the failed state for debugging */
    return (fmi2Status)glue_get_state(c, "fmi2GetFMUstate", FMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    return (fmi2Status)glue_set_state(c, "fmi2SetFMUstate", FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    return (fmi2Status)glue_free_state(c, "fmi2FreeFMUstate", FMUstate);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    return (fmi2Status)glue_state_size(c, "fmi2SerializedFMUstateSize", FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    return (fmi2Status)glue_serialize(c, "fmi2SerializeFMUstate", FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    return (fmi2Status)glue_deserialize(c, "fmi2DeSerializeFMUstate", (const unsigned char *)serializedState,
                                        size, FMUstate);
}

/* ------------------------------------------------------------------------ */
/* Not supported: directional derivatives and Model Exchange                 */

#define ME_ONLY "Model Exchange function; this FMU is Co-Simulation only"

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return (fmi2Status)glue_unsupported(c, "fmi2GetDirectionalDerivative", "providesDirectionalDerivative = false");
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    return (fmi2Status)glue_unsupported(c, "fmi2EnterEventMode", ME_ONLY);
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *fmi2eventInfo)
{
    (void)fmi2eventInfo;
    return (fmi2Status)glue_unsupported(c, "fmi2NewDiscreteStates", ME_ONLY);
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    return (fmi2Status)glue_unsupported(c, "fmi2EnterContinuousTimeMode", ME_ONLY);
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return (fmi2Status)glue_unsupported(c, "fmi2CompletedIntegratorStep", ME_ONLY);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    (void)time;
    return (fmi2Status)glue_unsupported(c, "fmi2SetTime", ME_ONLY);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    (void)x; (void)nx;
    return (fmi2Status)glue_unsupported(c, "fmi2SetContinuousStates", ME_ONLY);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    (void)derivatives; (void)nx;
    return (fmi2Status)glue_unsupported(c, "fmi2GetDerivatives", ME_ONLY);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    (void)eventIndicators; (void)ni;
    return (fmi2Status)glue_unsupported(c, "fmi2GetEventIndicators", ME_ONLY);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    (void)x; (void)nx;
    return (fmi2Status)glue_unsupported(c, "fmi2GetContinuousStates", ME_ONLY);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    (void)x_nominal; (void)nx;
    return (fmi2Status)glue_unsupported(c, "fmi2GetNominalsOfContinuousStates", ME_ONLY);
}
