/*
 * ReferenceSignal/config.h - identity, value references and flat data of the
 * ReferenceSignal FMU: the tracking reference y_d and its preview y_ref for
 * the controller. The value references follow the order of
 * modelDescription/ReferenceSignal.xml (value reference = position - 1).
 * The FMI 3.0 edition (modelDescription/fmi3/) uses the same numbers: each of
 * its arrays amplitude, frequency, phase has the value reference of its first
 * element (vr_amplitude1, ...).
 */
#ifndef REFERENCESIGNAL_CONFIG_H
#define REFERENCESIGNAL_CONFIG_H

#include "piezo_reference.h"

#define MODEL_IDENTIFIER_STRING "ReferenceSignal"
#define MODEL_GUID "{b640bddf-33fa-4670-af07-891cc16f73d7}"

typedef enum {
    vr_y_d = 0,             /* output [um] reference at t_k */
    vr_y_ref,               /* output [um] reference at t_(k+lead) */
    vr_offset,
    vr_amplitude1, vr_amplitude2, vr_amplitude3, vr_amplitude4,
    vr_amplitude5, vr_amplitude6, vr_amplitude7, vr_amplitude8,
    vr_frequency1, vr_frequency2, vr_frequency3, vr_frequency4,
    vr_frequency5, vr_frequency6, vr_frequency7, vr_frequency8,
    vr_phase1, vr_phase2, vr_phase3, vr_phase4,
    vr_phase5, vr_phase6, vr_phase7, vr_phase8,
    vr_lead,                /* Integer [samples] */
    vr_h,
    vr_y_preview,           /* output [um] reference at t_preview */
    vr_t_preview,           /* output [s] t_(k+preview): the time y_preview refers to */
    vr_preview,             /* Integer [samples] */
    MODEL_N_VARIABLES
} ValueReference;

/* Flat and pointer-free: an FMU state is a copy of this. */
typedef struct {
    piezo_reference_params params;  /* parameters as set through the FMI */
    piezo_reference ref;            /* core state; outputs in ref.y_d, ref.y_ref */
} ModelData;

#endif
