/*
 * PiezoStageClosedLoop/config.h - identity, value references and flat data of
 * the PiezoStageClosedLoop FMU: the stage under its controller, with the
 * reference inside (docs/fmus.md). The value references follow the order of
 * modelDescription/PiezoStageClosedLoop.xml (value reference = position - 1);
 * the FMI 3.0 edition keeps them, each array (pi.w, controller.pi.w,
 * amplitude, frequency, phase) at the value reference of its first element.
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

typedef enum {
    vr_y_d = 0,             /* input  [um] desired displacement (use_internal_reference = false) */
    vr_y,                   /* output [um] true displacement y(k) */
    vr_y_meas,              /* output [um] sensor reading */
    vr_v,                   /* output [V] the controller's voltage */
    vr_reference,           /* output [um] y_d(k), the displacement the stage tracks */
    vr_error,               /* output [um] reference - y */
    vr_u,                   /* output [um] the stage's hysteresis output u(k-1) */
    vr_x,                   /* output [um] the stage's Hammerstein output x(k) */
    vr_q,                   /* output [um] */
    vr_est_a1,
    vr_est_a2,
    vr_est_b1,
    vr_est_b2,
    vr_pred_error,          /* output [um] */
    vr_saturated,           /* output Boolean */
    vr_loop_delay,          /* output Integer */
    vr_loop_delay_time,     /* output [s] */
    vr_preview_lead,        /* output Integer */
    vr_sup_status,          /* output Integer */
    vr_sup_gain,            /* output */
    vr_sup_delay,           /* output Integer */
    vr_use_internal_reference,  /* Boolean */
    vr_y_d_lead,            /* Integer [samples] */
    vr_h,
    /* the stage (PiezoStage) */
    vr_pi_m,
    vr_pi_v_max,
    vr_pi_w0,
    vr_pi_w1, vr_pi_w2, vr_pi_w3, vr_pi_w4, vr_pi_w5, vr_pi_w6, vr_pi_w7, vr_pi_w8,
    vr_pi_w9, vr_pi_w10, vr_pi_w11, vr_pi_w12, vr_pi_w13, vr_pi_w14, vr_pi_w15, vr_pi_w16,
    vr_tf_a1,
    vr_tf_a2,
    vr_tf_b1,
    vr_tf_b2,
    vr_tf_delay,
    vr_creep_enabled,
    vr_creep_k_c,
    vr_creep_alpha,
    vr_creep_exact,
    vr_sensor_resolution,
    vr_sensor_noise_rms,
    vr_sensor_seed,
    /* the controller's nominal model (AdaptiveCompoundController's pi.*, tf.*, creep.*) */
    vr_c_pi_m,
    vr_c_pi_v_max,
    vr_c_pi_w0,
    vr_c_pi_w1, vr_c_pi_w2, vr_c_pi_w3, vr_c_pi_w4, vr_c_pi_w5, vr_c_pi_w6, vr_c_pi_w7, vr_c_pi_w8,
    vr_c_pi_w9, vr_c_pi_w10, vr_c_pi_w11, vr_c_pi_w12, vr_c_pi_w13, vr_c_pi_w14, vr_c_pi_w15, vr_c_pi_w16,
    vr_c_tf_a1,
    vr_c_tf_a2,
    vr_c_tf_b1,
    vr_c_tf_b2,
    vr_c_creep_k_c,
    vr_c_creep_alpha,
    vr_c_creep_exact,
    /* the rest of the controller */
    vr_mv_delay,
    vr_mv_feedthrough,
    vr_mv_lambda_u,
    vr_mv_observer,
    vr_rls_enabled,
    vr_rls_forgetting,
    vr_rls_p0,
    vr_rls_trace_max,
    vr_sat_enabled,
    vr_sat_v_min,
    vr_sat_v_max,
    vr_monitor_pred_error_max,
    vr_monitor_divergence_samples,
    vr_sup_enabled,
    vr_sup_gain_min,
    vr_sup_gain_max,
    vr_sup_window,
    vr_sup_clip_time,
    vr_sup_detect_time,
    /* the reference (ReferenceSignal) */
    vr_offset,
    vr_amplitude1, vr_amplitude2, vr_amplitude3, vr_amplitude4,
    vr_amplitude5, vr_amplitude6, vr_amplitude7, vr_amplitude8,
    vr_frequency1, vr_frequency2, vr_frequency3, vr_frequency4,
    vr_frequency5, vr_frequency6, vr_frequency7, vr_frequency8,
    vr_phase1, vr_phase2, vr_phase3, vr_phase4,
    vr_phase5, vr_phase6, vr_phase7, vr_phase8,
    vr_lead,
    vr_preview,
    /* the controller's robust adaptation and integral action (added after the reference) */
    vr_rls_robust,
    vr_rls_excitation,
    vr_rls_excitation_time,
    vr_rls_variance_max,
    vr_rls_p0_loop,
    vr_mv_integral,
    vr_est_adapting,        /* output Boolean */
    vr_est_noise,           /* output [um] */
    /* added with the safe state (issue 36): the controller's, appended to keep the references */
    vr_sup_reaction,
    vr_sup_ramp_time,
    vr_sup_clip_error,
    vr_mv_probe_max,
    vr_sup_fault,           /* output Integer */
    vr_sup_fault_time,      /* output [s] */
    vr_rls_zero_min,        /* the admissible set of the estimates (piezo_controller.h) */
    vr_rls_pole_min,
    vr_rls_fallback_ratio,  /* the fallback to the nominal model */
    vr_rls_fallback_window, /* [s] */
    vr_est_fallbacks,       /* output Integer: fallbacks to the nominal model so far */
    vr_sup_reset,           /* input Boolean: the controller's fault reset */
    MODEL_N_VARIABLES
} ValueReference;

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
