/*
 * PiezoStage/config.h - identity, value references and flat data of the
 * PiezoStage FMU (docs/fmus.md). The value references follow the
 * order of modelDescription/PiezoStage.xml (value reference = position - 1).
 * The FMI 3.0 edition (modelDescription/fmi3/) uses the same numbers: its
 * array pi.w has the value reference of its first element, vr_pi_w1.
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

typedef enum {
    vr_v = 0,               /* input  [V] */
    vr_y,                   /* output [um] true displacement */
    vr_y_meas,              /* output [um] sensor reading */
    vr_u,                   /* output [um] hysteresis output u(k-1) */
    vr_x,                   /* output [um] Hammerstein output */
    vr_pi_m,                /* Integer, 1..16 */
    vr_pi_v_max,
    vr_pi_w0,
    vr_pi_w1, vr_pi_w2, vr_pi_w3, vr_pi_w4, vr_pi_w5, vr_pi_w6, vr_pi_w7, vr_pi_w8,
    vr_pi_w9, vr_pi_w10, vr_pi_w11, vr_pi_w12, vr_pi_w13, vr_pi_w14, vr_pi_w15, vr_pi_w16,
    vr_tf_a1,
    vr_tf_a2,
    vr_tf_b1,
    vr_tf_b2,
    vr_tf_delay,            /* Integer */
    vr_creep_enabled,       /* Boolean */
    vr_creep_k_c,
    vr_creep_alpha,
    vr_creep_exact,         /* Boolean */
    vr_sensor_resolution,
    vr_sensor_noise_rms,
    vr_sensor_seed,         /* Integer */
    vr_h,
    vr_t_meas,              /* output [s] the time of the outputs, t0 + k h */
    MODEL_N_VARIABLES
} ValueReference;

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
