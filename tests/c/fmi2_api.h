/*
 * fmi2_api.h - every function of the FMI 2.0 standard, listed once for the C
 * hosts that look them up by name (the test hosts' host_fmi2.h and the plain
 * importer tests/c_master/fmu_master.c): FMI2_API(X) applies X to each name
 * without its prefix, and fmi2_api holds a pointer to each, api.DoStep for
 * fmi2DoStep. How a missing symbol is reported is each host's own.
 */
#ifndef FMI2_API_H
#define FMI2_API_H

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

#endif
