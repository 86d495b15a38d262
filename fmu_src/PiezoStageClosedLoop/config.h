/*
 * PiezoStageClosedLoop/config.h - identity, value references and flat data of
 * the PiezoStageClosedLoop FMU: the stage under its controller, with the
 * reference inside (docs/fmus.md). The value references are declared in
 * variables.toml, which composes the components' declarations, and generated
 * into variables.h; each FMI 3.0 array (pi.w, controller.pi.w, amplitude,
 * frequency, phase) has the value reference of its first element.
 *
 * Parameters: the stage's are PiezoStage's, under PiezoStage's names; the
 * controller's are AdaptiveCompoundController's under its names, but for its
 * nominal model (the names it shares with the stage: pi.*, tf.a1..b2,
 * creep.k_c, creep.alpha, creep.exact), which is controller.<name>; the
 * reference's are ReferenceSignal's under its names. One h for all three.
 */
#ifndef PIEZOSTAGECLOSEDLOOP_CONFIG_H
#define PIEZOSTAGECLOSEDLOOP_CONFIG_H

#include "piezo_plant.h"
#include "piezo_controller.h"
#include "piezo_reference.h"
#include "fmu_controller.h"

#define MODEL_IDENTIFIER_STRING "PiezoStageClosedLoop"
#define MODEL_GUID "{c11d5b6d-18c5-4b4e-9767-14b471b81c8a}"
/* optional hooks of fmu_model.h: messages (the controller's, the stage's clamp, the preview),
 * events (the controller's), and a communication step of any size */
#define MODEL_HAS_MESSAGES 1
#define MODEL_HAS_EVENTS 1
#define MODEL_HAS_ANY_STEP 1

/* y_d_lead: the input y_d may lead the stage's time by at most this many samples (the
 * controller keeps PIEZO_PREVIEW_RING - 1 samples of preview) */
#define CLOSED_LOOP_MAX_LEAD (PIEZO_PREVIEW_RING - 1)

/* the value references, MODEL_N_VARIABLES and the variable table's entries, generated
 * from variables.toml (the one declaration of this FMU's interface) */
#include "variables.h"

/* The core's parameter structs in ModelData (tests/model_table/model_table.c prints where). */
#define MODEL_PARAM_STRUCTS X(stage) X(control) X(ref_params)

/* Flat and pointer-free: an FMU state is a copy of this plus the history. */
typedef struct {
    /* parameters as set through the FMI */
    piezo_plant_params stage;           /* the stage's; stage.h is the loop's h */
    piezo_controller_params control;    /* the controller's; its h is set to stage.h at init */
    piezo_reference_params ref_params;  /* the reference's; its h is set to stage.h at init */
    int use_internal_reference;         /* 1: ReferenceSignal inside; 0: the input y_d */
    int y_d_lead;                       /* samples the input y_d leads the stage's time by */
    /* input, held over the communication step */
    double y_d;
    int sup_reset;                      /* input sup.reset (fmu_controller_reset_input) */
    /* model_latch_inputs: sample k reads y_d at its instant t_k; when a step ended between
     * t_k and t_(k+1), the y_d held at t_k is kept for it here */
    double y_d_latched;
    int latched;
    double t0;                          /* start time [s] */
    /* the loop: the three blocks of the core (committed samples only) */
    piezo_plant plant;
    piezo_controller ctrl;
    piezo_reference ref;
    fmu_controller_track track;         /* the delay of the committed samples, what was said */
    int lead_used;                      /* preview_lead of the committed samples */
    /* outputs computed from the state (model_update_outputs) */
    double reference;
    double error;
    int loop_delay;
    double loop_delay_time;
    int preview_lead;
    int sup_status;
    double sup_gain;
    int sup_delay;
    int sup_fault;
    double sup_fault_time;
    int fallbacks;                      /* est.fallbacks */
    /* what the stage and the preview said */
    uint64_t n_clamped;                 /* samples whose v was outside the rated range (applied clamped) */
    uint64_t k_first_clamped;           /* the first of them (valid when n_clamped > 0) */
    double v_first_clamped;             /* its v */
    int said_clamped;                   /* the first-clamping warning was logged */
    int said_preview;                   /* the warning that the preview cannot be aligned was logged */
    int refused_by;                     /* the block that refused the last refused sample (model.c) */
} ModelData;

#endif
