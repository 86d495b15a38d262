/*
 * AdaptiveCompoundController/config.h - identity, value references and flat
 * data of the AdaptiveCompoundController FMU (docs/fmus.md). The value
 * references follow the order of modelDescription/AdaptiveCompoundController.xml.
 */
#ifndef ADAPTIVECOMPOUNDCONTROLLER_CONFIG_H
#define ADAPTIVECOMPOUNDCONTROLLER_CONFIG_H

#include "piezo_controller.h"
#include "fmu_controller.h"

#define MODEL_IDENTIFIER_STRING "AdaptiveCompoundController"
/* optional hooks of fmu_model.h: it has direct feedthrough (mv.feedthrough), messages,
 * events (the loop delay it chose), a notice (it runs open loop) and a check of the step
 * size (one sample per step) */
#define MODEL_HAS_FEEDTHROUGH 1
#define MODEL_HAS_MESSAGES 1
#define MODEL_HAS_EVENTS 1
#define MODEL_HAS_NOTICES 1
#define MODEL_HAS_STEP_CHECK 1

#define MODEL_GUID "{16db41db-eca1-4957-ad18-19b12743e5cb}"

typedef enum {
    vr_y_ref = 0,           /* input  [um] reference d samples ahead */
    vr_y_meas,              /* input  [um] */
    vr_v,                   /* output [V] */
    vr_q,                   /* output [um] */
    vr_est_a1,
    vr_est_a2,
    vr_est_b1,
    vr_est_b2,
    vr_pred_error,          /* output [um] */
    vr_saturated,           /* output Boolean: v(k) was clipped */
    vr_pi_m,                /* Integer */
    vr_pi_v_max,
    vr_pi_w0,
    vr_pi_w1, vr_pi_w2, vr_pi_w3, vr_pi_w4, vr_pi_w5, vr_pi_w6, vr_pi_w7, vr_pi_w8,
    vr_pi_w9, vr_pi_w10, vr_pi_w11, vr_pi_w12, vr_pi_w13, vr_pi_w14, vr_pi_w15, vr_pi_w16,
    vr_tf_a1,
    vr_tf_a2,
    vr_tf_b1,
    vr_tf_b2,
    vr_creep_k_c,
    vr_creep_alpha,
    vr_creep_exact,         /* Boolean */
    vr_h,
    vr_mv_delay,            /* Integer, d = 1 + mv.delay */
    vr_mv_feedthrough,      /* Boolean */
    vr_mv_lambda_u,
    vr_rls_enabled,         /* Boolean */
    vr_rls_forgetting,
    vr_rls_p0,
    vr_rls_trace_max,
    vr_sat_enabled,         /* Boolean */
    vr_sat_v_min,
    vr_sat_v_max,
    vr_monitor_pred_error_max,
    vr_monitor_divergence_samples,  /* Integer */
    vr_y_preview,           /* input  [um] stamped preview: y_d(t_preview) */
    vr_t_preview,           /* input  [s] the time y_preview refers to */
    vr_t_meas,              /* input  [s] the time y_meas refers to */
    vr_loop_delay,          /* output Integer: d of the law, 0 while detecting */
    vr_loop_delay_time,     /* output [s] the time loop_delay took its value */
    vr_preview_lead,        /* output Integer: lead of the stamped preview used, 0: y_ref used */
    vr_meas_offset,         /* output Integer: t_meas - t_k in samples (0 without a t_meas stamp) */
    vr_mv_observer,
    vr_mv_hold_inputs,      /* Boolean */
    vr_sup_enabled,         /* Boolean: supervision (piezo_supervisor.h) */
    vr_sup_gain_min,
    vr_sup_gain_max,
    vr_sup_window,          /* Integer [samples] */
    vr_sup_clip_time,       /* [s] */
    vr_sup_detect_time,     /* [s] */
    vr_sup_status,          /* output Integer: 0 not verified yet, 1 verified, 2 degraded */
    vr_sup_gain,            /* output: response gain, times the model's */
    vr_sup_delay,           /* output Integer: the delay y_meas answers at [samples] */
    vr_rls_robust,          /* Boolean: the robust update (piezo_controller.h) */
    vr_rls_excitation,
    vr_rls_excitation_time, /* [s] */
    vr_rls_variance_max,
    vr_rls_p0_loop,
    vr_mv_integral,
    vr_est_adapting,        /* output Boolean: the estimates were updated at the last sample */
    vr_est_noise,           /* output [um] the measured noise of y_meas */
    vr_sup_reaction,        /* Integer: 0 error (a verdict fails the doStep), 1 safe (the safe state) */
    vr_sup_ramp_time,       /* [s] the safe state's ramp of v to 0 V */
    vr_sup_clip_error,      /* [um] the clipping watchdog's bound */
    vr_mv_probe_max,        /* [um] largest delay probe */
    vr_sup_fault,           /* output Integer: the fault code of the safe state (0: none) */
    vr_sup_fault_time,      /* output [s] the time of its verdict */
    vr_rls_zero_min,        /* the admissible set of the estimates (piezo_controller.h) */
    vr_rls_pole_min,
    vr_rls_fallback_ratio,  /* the fallback to the nominal model */
    vr_rls_fallback_window, /* [s] */
    vr_est_fallbacks,       /* output Integer: fallbacks to the nominal model so far */
    vr_sup_reset,           /* input Boolean: the fault reset (its rising edge leaves the safe state) */
    MODEL_N_VARIABLES
} ValueReference;

/* Flat and pointer-free: an FMU state is a copy of this plus the history. */
typedef struct {
    piezo_controller_params params; /* parameters as set through the FMI */
    double y_ref;                   /* inputs, held over the communication step */
    double y_meas;
    double y_preview;
    double t_preview;
    double t_meas;
    int sup_reset;                  /* input sup.reset (fmu_controller_reset_input) */
    double t0;                      /* start time [s] */
    double last_t_preview;          /* the stamps of the last committed sample: a stamp is */
    double last_t_meas;             /* trusted when it advanced by h since (connected) */
    int have_last;                  /* 1 once a sample was committed */
    int loop_delay;                 /* outputs: d of the law (0 while detecting) ... */
    double loop_delay_time;         /* ... and the time of the sample from which it has held */
    int preview_lead;               /* lead of the stamped preview used (0: y_ref) */
    int meas_offset;                /* t_meas - t_k in samples */
    fmu_controller_track track;     /* the delay of the committed samples (the outputs of the
                                       default timing, the base of the feedthrough's) and what
                                       was said (fmu_controller.h) */
    int track_lead;                 /* preview_lead and meas_offset of the committed samples */
    int track_offset;
    int meas_stamped;               /* t_meas has advanced by h at some sample (connected) */
    int preview_stamped;            /* t_preview has */
    int preview_offset;             /* its last lead over the measurement [samples], clamped to +-99 */
    int said_stamps;                /* supervision warnings logged: 1 t_meas, 2 t_preview, 4 alignment */
    int sup_status;                 /* outputs: sup.status, ... */
    double sup_gain;                /* ... sup.gain, ... */
    int sup_delay;                  /* ... sup.delay, ... */
    int sup_fault;                  /* ... sup.fault, ... */
    double sup_fault_time;          /* ... sup.fault_time */
    int fallbacks;                  /* est.fallbacks: the controller's count, clamped to INT32 */
    int loop_wired;                 /* an input left its start value at some sample: the loop is
                                       connected (until then it runs open loop) */
    int said_open_loop;             /* the open-loop warning was logged */

    piezo_controller ctrl;          /* core state (committed samples only) */
    piezo_controller_output out;    /* outputs: the last committed sample, or with
                                       mv.feedthrough a peek with the held inputs */
    piezo_controller_sample pending;/* mv.feedthrough: the sample evaluated for the
                                       outputs, committed by the next doStep when
                                       nothing changed in between (never trusted
                                       otherwise, so a restored copy is never used) */
} ModelData;

#endif
