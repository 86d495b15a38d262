/*
 * AdaptiveCompoundController/config.h - identity, value references and flat
 * data of the AdaptiveCompoundController FMU (docs/fmus.md). The value
 * references are declared in variables.toml and generated into variables.h.
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

/* the value references, MODEL_N_VARIABLES and the variable table's entries, generated
 * from variables.toml (the one declaration of this FMU's interface) */
#include "variables.h"

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
