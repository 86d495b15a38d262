/*
 * fmi3_glue.c - the FMI 3.0 Co-Simulation layer, compiled into each FMI 3.0
 * FMU with that FMU's model.c and config.h (the same files as the FMI 2.0
 * edition, see fmu_model.h) and the version-neutral fmu_glue_core.c, which
 * does the work. This file checks what only FMI 3.0 has (the instantiation
 * arguments, the doStep's out-arguments, the types without variables) and
 * maps the fmi3 functions onto the core.
 *
 * State machine: FMI 3.0 Co-Simulation without event mode (hasEventMode =
 * false) and without configuration mode (no structural parameters), so the
 * modes and the calls they allow are those of the FMI 2.0 edition:
 *
 *   function                         Inst  Init  Step  Term  Err
 *   SetDebugLogging, Reset,            x     x     x     x    x
 *     FreeInstance, Get/SetFMUState,
 *     FreeFMUState, (De)Serialize*
 *   EnterInitializationMode            x     .     .     .    .
 *   ExitInitializationMode             .     x     .     .    .
 *   Get{Float64,Int32,Boolean}         .     x     x     x    x
 *   Set* of a parameter (fixed)        x     x     .     .    .
 *   Set* of an input                   x     x     x     .    .
 *   DoStep, Terminate                  .     .     x     .    .
 *   never (fmi3Error, logged): EnterEventMode, EnterStepMode,
 *     UpdateDiscreteStates, EvaluateDiscreteStates (no event mode), Enter/
 *     ExitConfigurationMode (no structural parameters), the clock functions
 *     (no clocks), variable dependencies, directional and adjoint derivatives,
 *     output derivatives, Model Exchange and Scheduled Execution.
 *   Get/Set of the other types (Float32, Int8..UInt64, String, Binary, Clock):
 *     the FMU has no such variable: nvr = 0 with nValues = 0 passes, anything
 *     else is refused naming the variable's real type (or nValues).
 *
 * ExitInitializationMode enters Step Mode directly (no event mode), so an
 * instantiation with eventModeUsed = true is refused. The FMU never returns
 * early from a doStep and has no intermediate update: earlyReturnAllowed and
 * the intermediateUpdate callback are accepted and not used; a step longer than
 * one doStep may compute is refused (fmu_glue_core.c), lastSuccessfulTime
 * staying at the current time. Time, the step rules, the warnings, the FMU
 * states and their serialized form are the core's and the same as in the FMI
 * 2.0 edition (see fmi2_glue.c, fmu_glue_core.c); the stopTime is
 * fmi3EnterInitializationMode's.
 *
 * Variables: a scalar has the value reference of its model variable (the FMI
 * 2.0 edition's); an array name[1..n] (e.g. pi.w) is one variable whose value
 * reference is that of name[1], holding n values in element order; the value
 * references of its other elements are not used (value references need not be
 * contiguous). Get/set calls give nValues = the values the references hold
 * (0 without references); any other nValues is refused.
 *
 * Memory: FMI 3.0 has no memory callbacks; the FMU uses calloc/free, and only
 * outside a step of one sample (instances, states, the exact-mode history).
 * Logging: through logMessage (the text as is); a NULL logMessage means no
 * messages. Categories as in the FMI 2.0 edition.
 */
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_glue_core.h"

typedef char vr_is_32_bits[sizeof(fmi3ValueReference) == sizeof(uint32_t) ? 1 : -1];
typedef char boolean_is_a_byte[sizeof(fmi3Boolean) == 1 ? 1 : -1];

static const glue_version fmi3 = {
    { "Instantiated", "InitializationMode", "StepMode", "Terminated", "Error" },
    { "Float64", "Int32", "Boolean" },
    "instantiationToken",
    "fmi3ExitInitializationMode",
    "fmi3EnterInitializationMode",
    "fmi3DoStep",
    "fmi3GetFMUState", "fmi3SetFMUState", "fmi3DeserializeFMUState", "fmi3SerializedFMUStateSize", "fmi3Reset",
    1,      /* name[1..n] is one array variable */
    1       /* the independent variable time: value reference MODEL_N_VARIABLES */
};

static void deliver(const glue_host *host, const char *instance_name, glue_status status,
                    const char *category, const char *text)
{
    fmi3LogMessageCallback logger = (fmi3LogMessageCallback)host->logger;
    (void)instance_name;        /* FMI 3.0 passes the instance environment instead */
    logger((fmi3InstanceEnvironment)host->env, (fmi3Status)status, category, text);
}

static void *allocate(size_t n, size_t size)
{
    return calloc(n, size);
}

static glue_host host_of(fmi3InstanceEnvironment env, fmi3LogMessageCallback logMessage)
{
    glue_host host;
    host.deliver = deliver;
    host.logger = (glue_function)logMessage;
    host.env = env;
    host.alloc = allocate;
    host.release = free;
    return host;
}

#define ME_ONLY "Model Exchange function; this FMU is Co-Simulation only"
#define NO_EVENT_MODE "this FMU has no event mode (hasEventMode = false): fmi3ExitInitializationMode " \
                      "enters Step Mode directly and every doStep runs to its end"
#define NO_CLOCKS "the FMU has no clocks"

/* ------------------------------------------------------------------------ */
/* Inquiry, instantiation, logging control                                   */

const char *fmi3GetVersion(void)
{
    return fmi3Version;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    return (fmi3Status)glue_set_debug_logging(instance, "fmi3SetDebugLogging", loggingOn, nCategories, categories);
}

static fmi3Instance not_co_simulation(const char *fname, fmi3String instanceName, fmi3InstanceEnvironment env,
                                      fmi3LogMessageCallback logMessage, const char *interface_type)
{
    glue_host host = host_of(env, logMessage);
    glue_host_log(&host, instanceName, GLUE_ERROR, "%s: %s supports Co-Simulation only, not %s", fname,
                  MODEL_IDENTIFIER_STRING, interface_type);
    return NULL;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    return not_co_simulation("fmi3InstantiateModelExchange", instanceName, instanceEnvironment, logMessage,
                             "Model Exchange");
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    return not_co_simulation("fmi3InstantiateScheduledExecution", instanceName, instanceEnvironment, logMessage,
                             "Scheduled Execution");
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    static const char fname[] = "fmi3InstantiateCoSimulation";
    glue_host host = host_of(instanceEnvironment, logMessage);
    (void)visible;
    (void)earlyReturnAllowed;   /* never returns early */
    (void)intermediateUpdate;   /* providesIntermediateUpdate = false: never called */
    if (instanceName == NULL || instanceName[0] == '\0') {
        glue_host_log(&host, instanceName, GLUE_ERROR, "%s: missing instance name", fname);
        return NULL;
    }
    if (instantiationToken == NULL || strcmp(instantiationToken, MODEL_GUID) != 0) {
        glue_host_log(&host, instanceName, GLUE_ERROR, "%s: wrong instantiationToken %s: this binary is %s %s",
                      fname, instantiationToken != NULL ? instantiationToken : "(NULL)", MODEL_IDENTIFIER_STRING,
                      MODEL_GUID);
        return NULL;
    }
    if (eventModeUsed) {
        glue_host_log(&host, instanceName, GLUE_ERROR, "%s: eventModeUsed = true refused: %s", fname,
                      NO_EVENT_MODE);
        return NULL;
    }
    if (nRequiredIntermediateVariables > 0 && requiredIntermediateVariables == NULL) {
        glue_host_log(&host, instanceName, GLUE_ERROR,
                      "%s: argument requiredIntermediateVariables is NULL (nRequiredIntermediateVariables = %llu)",
                      fname, (unsigned long long)nRequiredIntermediateVariables);
        return NULL;
    }
    return glue_instantiate(&host, &fmi3, fname, instanceName, resourcePath, 0, "resourcePath", loggingOn);
}

void fmi3FreeInstance(fmi3Instance instance)
{
    glue_free_instance(instance, "fmi3FreeInstance");
}

/* ------------------------------------------------------------------------ */
/* Initialization, termination                                               */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined;     /* a discrete-time model: no tolerance to honour */
    (void)tolerance;
    return (fmi3Status)glue_setup(instance, "fmi3EnterInitializationMode", startTime, stopTimeDefined, stopTime, 1);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    return (fmi3Status)glue_exit_init(instance, "fmi3ExitInitializationMode");
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    return (fmi3Status)glue_unsupported(instance, "fmi3EnterEventMode", NO_EVENT_MODE);
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    return (fmi3Status)glue_terminate(instance, "fmi3Terminate");
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    return (fmi3Status)glue_reset(instance, "fmi3Reset");
}

/* ------------------------------------------------------------------------ */
/* Getting and setting variables                                             */

GLUE_HOT_PATH
fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    return (fmi3Status)glue_get(instance, "fmi3GetFloat64", valueReferences, nValueReferences, GLUE_VALUES_DOUBLE,
                                values, nValues);
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues)
{
    return (fmi3Status)glue_get(instance, "fmi3GetInt32", valueReferences, nValueReferences, GLUE_VALUES_INT32,
                                values, nValues);
}

GLUE_HOT_PATH
fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    return (fmi3Status)glue_get(instance, "fmi3GetBoolean", valueReferences, nValueReferences,
                                GLUE_VALUES_BOOL_BYTE, values, nValues);
}

GLUE_HOT_PATH
fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    return (fmi3Status)glue_set(instance, "fmi3SetFloat64", valueReferences, nValueReferences, GLUE_VALUES_DOUBLE,
                                values, nValues);
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues)
{
    return (fmi3Status)glue_set(instance, "fmi3SetInt32", valueReferences, nValueReferences, GLUE_VALUES_INT32,
                                values, nValues);
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    return (fmi3Status)glue_set(instance, "fmi3SetBoolean", valueReferences, nValueReferences,
                                GLUE_VALUES_BOOL_BYTE, values, nValues);
}

/* The types the FMU has no variable of. */
#define NO_SUCH_GETTER(T)                                                                                   \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],                \
                          size_t nValueReferences, fmi3##T values[], size_t nValues)                         \
    {                                                                                                       \
        return (fmi3Status)glue_no_such_type(instance, "fmi3Get" #T, GLUE_MASK_GET, valueReferences,        \
                                             nValueReferences, values, nValues, #T);                        \
    }
#define NO_SUCH_SETTER(T)                                                                                   \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],                \
                          size_t nValueReferences, const fmi3##T values[], size_t nValues)                   \
    {                                                                                                       \
        return (fmi3Status)glue_no_such_type(instance, "fmi3Set" #T, GLUE_MASK_SET, valueReferences,        \
                                             nValueReferences, values, nValues, #T);                        \
    }
#define NO_SUCH_TYPE(T) NO_SUCH_GETTER(T) NO_SUCH_SETTER(T)

NO_SUCH_TYPE(Float32)
NO_SUCH_TYPE(Int8)
NO_SUCH_TYPE(UInt8)
NO_SUCH_TYPE(Int16)
NO_SUCH_TYPE(UInt16)
NO_SUCH_TYPE(UInt32)
NO_SUCH_TYPE(Int64)
NO_SUCH_TYPE(UInt64)
NO_SUCH_TYPE(String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueSizes;
    return (fmi3Status)glue_no_such_type(instance, "fmi3GetBinary", GLUE_MASK_GET, valueReferences,
                                         nValueReferences, values, nValues, "Binary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[], const fmi3Binary values[],
                         size_t nValues)
{
    (void)valueSizes;
    return (fmi3Status)glue_no_such_type(instance, "fmi3SetBinary", GLUE_MASK_SET, valueReferences,
                                         nValueReferences, values, nValues, "Binary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[])
{
    /* no nValues: a clock is a scalar, one value a reference */
    return (fmi3Status)glue_no_such_type(instance, "fmi3GetClock", GLUE_MASK_GET, valueReferences,
                                         nValueReferences, values, nValueReferences, "Clock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[])
{
    /* no nValues: a clock is a scalar, one value a reference */
    return (fmi3Status)glue_no_such_type(instance, "fmi3SetClock", GLUE_MASK_SET, valueReferences,
                                         nValueReferences, values, nValueReferences, "Clock");
}

/* ------------------------------------------------------------------------ */
/* Variable dependencies, derivatives, configuration: not supported          */

#define NO_DEPENDENCIES "providesPerElementDependencies = false; the ModelStructure of the model " \
                        "description lists the dependencies"

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetNumberOfVariableDependencies", NO_DEPENDENCIES);
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetVariableDependencies", NO_DEPENDENCIES);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetDirectionalDerivative",
                                        "providesDirectionalDerivatives = false");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                    const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                    size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives = false");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return (fmi3Status)glue_unsupported(instance, "fmi3EnterConfigurationMode",
                                        "the FMU has no structural parameters (array sizes are fixed)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return (fmi3Status)glue_unsupported(instance, "fmi3ExitConfigurationMode",
                                        "the FMU has no structural parameters (array sizes are fixed)");
}

/* ------------------------------------------------------------------------ */
/* Clocks and events: not supported                                          */

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    return (fmi3Status)glue_unsupported(instance, "fmi3SetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return (fmi3Status)glue_unsupported(instance, "fmi3SetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return (fmi3Status)glue_unsupported(instance, "fmi3SetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return (fmi3Status)glue_unsupported(instance, "fmi3SetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    return (fmi3Status)glue_unsupported(instance, "fmi3EvaluateDiscreteStates", NO_EVENT_MODE);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    return (fmi3Status)glue_unsupported(instance, "fmi3UpdateDiscreteStates", NO_EVENT_MODE);
}

/* ------------------------------------------------------------------------ */
/* Model Exchange: not supported                                             */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    return (fmi3Status)glue_unsupported(instance, "fmi3EnterContinuousTimeMode", ME_ONLY);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return (fmi3Status)glue_unsupported(instance, "fmi3CompletedIntegratorStep", ME_ONLY);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    return (fmi3Status)glue_unsupported(instance, "fmi3SetTime", ME_ONLY);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    return (fmi3Status)glue_unsupported(instance, "fmi3SetContinuousStates", ME_ONLY);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    (void)derivatives; (void)nContinuousStates;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetContinuousStateDerivatives", ME_ONLY);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators; (void)nEventIndicators;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetEventIndicators", ME_ONLY);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetContinuousStates", ME_ONLY);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates)
{
    (void)nominals; (void)nContinuousStates;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetNominalsOfContinuousStates", ME_ONLY);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    (void)nEventIndicators;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetNumberOfEventIndicators", ME_ONLY);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    (void)nContinuousStates;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetNumberOfContinuousStates", ME_ONLY);
}

/* ------------------------------------------------------------------------ */
/* Co-Simulation                                                             */

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    return (fmi3Status)glue_unsupported(instance, "fmi3EnterStepMode", NO_EVENT_MODE);
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    return (fmi3Status)glue_unsupported(instance, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder = 0");
}

GLUE_HOT_PATH
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    static const char fname[] = "fmi3DoStep";
    glue_instance *inst = glue_instance_of(instance, fname, GLUE_MODE_STEP);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst == NULL || glue_null_arg(inst, fname, "eventHandlingNeeded", eventHandlingNeeded)
        || glue_null_arg(inst, fname, "terminateSimulation", terminateSimulation)
        || glue_null_arg(inst, fname, "earlyReturn", earlyReturn)
        || glue_null_arg(inst, fname, "lastSuccessfulTime", lastSuccessfulTime))
        return fmi3Error;
    /* no events, never asks to stop, never returns early */
    *eventHandlingNeeded = false;
    *terminateSimulation = false;
    *earlyReturn = false;
    return (fmi3Status)glue_do_step(instance, fname, currentCommunicationPoint, communicationStepSize,
                                    lastSuccessfulTime);
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    return (fmi3Status)glue_get_state(instance, "fmi3GetFMUState", FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    return (fmi3Status)glue_set_state(instance, "fmi3SetFMUState", FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    return (fmi3Status)glue_free_state(instance, "fmi3FreeFMUState", FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    return (fmi3Status)glue_state_size(instance, "fmi3SerializedFMUStateSize", FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    return (fmi3Status)glue_serialize(instance, "fmi3SerializeFMUState", FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    return (fmi3Status)glue_deserialize(instance, "fmi3DeserializeFMUState", serializedState, size, FMUState);
}

/* ------------------------------------------------------------------------ */
/* Scheduled Execution: not supported                                        */

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    return (fmi3Status)glue_unsupported(instance, "fmi3ActivateModelPartition",
                                        "Scheduled Execution function; this FMU is Co-Simulation only");
}
