/*
 * ReferenceSignal/config.h - identity, value references and flat data of the
 * ReferenceSignal FMU: the tracking reference y_d and its preview y_ref for
 * the controller. The value references are declared in variables.toml and
 * generated into variables.h; each of the FMI 3.0 edition's arrays amplitude,
 * frequency, phase has the value reference of its first element
 * (vr_amplitude1, ...).
 */
#ifndef REFERENCESIGNAL_CONFIG_H
#define REFERENCESIGNAL_CONFIG_H

#include "piezo_reference.h"

#define MODEL_IDENTIFIER_STRING "ReferenceSignal"
#define MODEL_GUID "{b640bddf-33fa-4670-af07-891cc16f73d7}"

/* the value references, MODEL_N_VARIABLES and the variable table's entries, generated
 * from variables.toml (the one declaration of this FMU's interface) */
#include "variables.h"

/* Flat and pointer-free: an FMU state is a copy of this. */
typedef struct {
    piezo_reference_params params;  /* parameters as set through the FMI */
    piezo_reference ref;            /* core state; outputs in ref.y_d, ref.y_ref */
} ModelData;

#endif
