/*
 * PiezoStage/config.h - identity, value references and flat data of the
 * PiezoStage FMU (docs/fmus.md). The value references are declared in
 * variables.toml (value reference = position, an array taking one per element)
 * and generated into variables.h; the FMI 3.0 edition's array pi.w has the
 * value reference of its first element, vr_pi_w1.
 */
#ifndef PIEZOSTAGE_CONFIG_H
#define PIEZOSTAGE_CONFIG_H

#include "piezo_plant.h"

#define MODEL_IDENTIFIER_STRING "PiezoStage"
#define MODEL_GUID "{ef01aaba-a721-42bc-89a7-48ea3affdc56}"
/* optional hooks of fmu_model.h: messages (v clamped to its declared range) */
#define MODEL_HAS_MESSAGES 1

/* The declared range of the input v, [min, max] in both model descriptions, the stage's
 * rated range (piezo_plant.h): the stage applies v clamped to it (model.c; tests/test_fmu_edges.py reads
 * the range from the model descriptions and checks the clamp against it). */
#define PIEZOSTAGE_V_MIN (-(double)PIEZO_PLANT_V_RATED)
#define PIEZOSTAGE_V_MAX ((double)PIEZO_PLANT_V_RATED)

/* the value references, MODEL_N_VARIABLES and the variable table's entries, generated
 * from variables.toml (the one declaration of this FMU's interface) */
#include "variables.h"

/* Flat and pointer-free: an FMU state is a copy of this plus the history. */
typedef struct {
    piezo_plant_params params;  /* parameters as set through the FMI */
    double v;                   /* input held over the communication step, as set */
    piezo_plant plant;          /* core state; outputs in plant.out */
    uint64_t n_clamped;         /* samples whose v was outside [V_MIN, V_MAX] (applied clamped) */
    uint64_t k_first_clamped;   /* the first of them (valid when n_clamped > 0) */
    double v_first_clamped;     /* the v held then */
    int said_clamped;           /* the first-clamping warning was logged */
    double t0;                  /* start time [s] */
    double t_meas;              /* output: t0 + k h, the time y_meas (every output) belongs to */
} ModelData;

#endif
