/*
 * fmu_controller.h - the adaptive compound controller as an FMU shows it, for
 * every FMU that runs one (AdaptiveCompoundController, PiezoStageClosedLoop):
 * the loop delay its committed samples ran (the outputs loop_delay and
 * loop_delay_time), and what it says: the events (the delay it chose, the loop
 * its supervision verified), the warnings (detection restarted, v clipped,
 * |pred_error| beyond its bound), the summary at terminate and why it refused a
 * sample (the supervision's verdict, the monitor's, a diverged value). One text
 * per fact, whichever FMU says it; the words harness/fmu.py LOOP_FAILURES knows
 * the Errors by are here.
 *
 * Times are the FMU's t0 + k h (fmu_sample_time). The struct is flat, part of
 * the FMU's ModelData, so an FMU state keeps what was already said.
 */
#ifndef FMU_CONTROLLER_H
#define FMU_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include "piezo_controller.h"

typedef struct {
    int delay;                  /* d of the law over the committed samples, 0 while detecting */
    double delay_time;          /* the time of the sample from which it has held [s] */
    int said_delay;             /* delay's value last logged as an event */
    int said_verified;          /* the loop the supervision verified was logged as an event */
    int said_redetect;          /* the restarted-detection warning was logged */
    int said_saturated;         /* the first-clipping warning was logged */
    int said_large_error;       /* the first large-pred_error warning was logged */
    int said_outlier;           /* the first-outlier warning was logged */
    int said_fault;             /* the safe state's warning was logged */
    int said_fallback;          /* the first fallback to the nominal model was logged */
    int said_wait;              /* the detection's first wait for the reference was logged as an event */
    /* sup.reset: a rising edge of the input is acted on at a sample and said after the step */
    int reset_input;            /* the input's value at the last sample (0 at initialization) */
    int reset_said;             /* 0: nothing to say; else 1 + the last reset's verdict (piezo_reset_refusal) */
    uint64_t reset_k;           /* the sample it was raised at */
    double reset_y_ref;         /* that sample's inputs, for the message */
    double reset_y_meas;
} fmu_controller_track;

/* At initialization (the controller just initialized, sample 0 at t0). */
void fmu_controller_track_init(fmu_controller_track *t, const piezo_controller *c, double t0);
/* After a sample was committed (c->k is the next one). */
void fmu_controller_track_commit(fmu_controller_track *t, const piezo_controller *c, double t0, double h);

/* sup.reset at the sample about to be evaluated (c->k) with its inputs in: on the input's rising
 * edge the controller leaves its safe state if the cause it can see is gone
 * (piezo_controller_reset_refusal, piezo_controller_restart), and what happened is said after the
 * step (an event when accepted or nothing to reset, a Warning when refused). 1 when it restarted. */
int fmu_controller_reset_input(fmu_controller_track *t, piezo_controller *c, int raised,
                               const piezo_controller_input *in);
/* What sup.reset's edge changes, kept so that a sample refused after it commits nothing, the
 * restart included: fmu_controller_reset_keep before fmu_controller_reset_input (it copies only
 * on the rising edge), fmu_controller_reset_undo on the refusal (the controller and its track as
 * they were, with the refused sample's verdict, which its message explains). */
typedef struct {
    int edge;
    piezo_controller ctrl;
    fmu_controller_track track;
} fmu_controller_reset_backup;
void fmu_controller_reset_keep(fmu_controller_reset_backup *u, const fmu_controller_track *t,
                               const piezo_controller *c, int raised);
void fmu_controller_reset_undo(const fmu_controller_reset_backup *u, fmu_controller_track *t, piezo_controller *c);
/* Where a loop is, for the messages: sample 0 at t0, sample period h, the controller wired to a
 * stage by hand (the other fields 0); an FMU with the stage inside sets those after. Inline: the
 * messages ask for it after every doStep. */
static inline piezo_sup_context fmu_controller_context(double t0, double h)
{
    piezo_sup_context ctx;
    memset(&ctx, 0, sizeof ctx);
    ctx.t0 = t0;
    ctx.h = h;
    return ctx;
}

/* At most one event / one warning per call, each thing once: 1 with the text written, else 0.
 * ctx: where the loop is (its t0 and h, wired or inside one FMU: piezo_sup_context). */
int fmu_controller_event(fmu_controller_track *t, const piezo_controller *c, double t0, double h,
                         char *text, size_t size);
int fmu_controller_warning(fmu_controller_track *t, const piezo_controller *c, const piezo_sup_context *ctx,
                           char *text, size_t size);
/* The counts worth a warning at terminate, 1 if written. */
int fmu_controller_summary(const piezo_controller *c, char *text, size_t size);
/* Why the controller refused a sample with st (PIEZO_ERR_FAULT: "supervision stopped the loop (...)",
 * PIEZO_ERR_UNSTABLE, PIEZO_ERR_DIVERGED), 1 if written; 0 for the glue's generic text. */
int fmu_controller_failure(const piezo_controller *c, const piezo_sup_context *ctx, piezo_status st,
                           char *text, size_t size);
/* The outputs sup.fault (0: none) and sup.fault_time (t0 + k h of the verdict's sample; 0 while none). */
void fmu_controller_fault_outputs(const piezo_controller *c, double t0, double h, int *fault, double *fault_time);

/* The output est.fallbacks: the controller's fallbacks to its nominal model, clamped to INT32_MAX. */
int fmu_controller_fallbacks(const piezo_controller *c);

/* A restored struct against the controller it belongs to: NULL, or what is wrong.
 * core_initialized: the state was saved after initialization (k samples since t0). */
const char *fmu_controller_track_check(const fmu_controller_track *t, int core_initialized, double t0,
                                       uint64_t k, double h);

#endif
