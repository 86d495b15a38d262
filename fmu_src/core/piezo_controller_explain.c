/* piezo_controller_explain.c - what the controller says: its messages. See
 * piezo_controller_internal.h. */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "piezo_controller_internal.h"

int piezo_controller_explain_bound(const piezo_controller *c, char *text, size_t size)
{
    double bound;
    if (c == NULL) return 0;
    bound = piezo_controller_monitor_bound(c);
    if (bound >= PIEZO_MONITOR_NOISE_CAP * c->pred_error_max)
        return snprintf(text, size, "%.4g um (monitor.pred_error_max = %g um raised for y_meas's noise, %.4g um "
                        "rms, to its cap)", bound, c->pred_error_max, c->noise_y2);
    if (bound > c->pred_error_max)
        return snprintf(text, size, "%.4g um (monitor.pred_error_max = %g um raised to %d times y_meas's noise, "
                        "%.4g um rms)", bound, c->pred_error_max, PIEZO_MONITOR_NOISE, c->noise_y2);
    return snprintf(text, size, "monitor.pred_error_max = %g um", c->pred_error_max);
}
/* the running length of a text written piece by piece (what it wanted) */
static void said(int *used, int w)
{
    if (w > 0) *used += w;
}

piezo_status piezo_controller_fault_status(int fault)
{
    if (fault == PIEZO_SUP_UNSTABLE) return PIEZO_ERR_UNSTABLE;
    if (fault == PIEZO_SUP_DIVERGED) return PIEZO_ERR_DIVERGED;
    return fault > 0 && fault <= PIEZO_SUP_FAULT_MAX ? PIEZO_ERR_FAULT : PIEZO_OK;
}

int piezo_controller_explain(const piezo_controller *c, int st, char *text, size_t size)
{
    piezo_sup_context ctx;
    memset(&ctx, 0, sizeof ctx);
    ctx.h = c != NULL ? c->sup.h : 0.0;
    return piezo_controller_explain_in(c, st, &ctx, text, size);
}

int piezo_controller_explain_in(const piezo_controller *c, int st, const piezo_sup_context *ctx,
                                char *text, size_t size)
{
    int used = 0;
#define AT (used >= 0 && (size_t)used < size ? text + used : NULL)
#define LEFT (used >= 0 && (size_t)used < size ? size - (size_t)used : 0)
    if (text != NULL && size > 0) text[0] = '\0';
    if (c == NULL || ctx == NULL) return 0;
    if (st == PIEZO_ERR_FAULT) {
        /* the words harness/fmu.py LOOP_FAILURES knows this Error by */
        said(&used, snprintf(AT, LEFT, "supervision stopped the loop (%s): ",
                                         piezo_supervisor_fault_name(c->verdict.fault)));
        said(&used, piezo_supervisor_explain_in(&c->verdict, ctx, AT, LEFT));
        return used;
    }
    if (st == PIEZO_ERR_UNSTABLE) {
        /* the share the refused sample would have made, of the whole window */
        double share = 100.0 * (c->mon_forgetting * c->mon_share + 1.0) / (double)c->divergence_samples;
        char beyond[256];
        piezo_controller_explain_bound(c, beyond, sizeof beyond);
        said(&used, snprintf(AT, LEFT, "the closed loop is unstable: |pred_error| was beyond "
             "%s in %.0f %% of the monitor's window of %llu samples, %llu of them "
             "in a row now (the loop is stopped at monitor.divergence_samples = %llu in a row, or at %d %% of "
             "the window, older samples counting less; where v was clipped the nominal model's prediction "
             "error counts too; largest |pred_error| so far %.6g um). ",
             beyond, share, (unsigned long long)c->divergence_samples,
             (unsigned long long)(c->run_large_error + 1),
             (unsigned long long)c->divergence_samples, PIEZO_MONITOR_SHARE_PERCENT, c->max_abs_pred_error));
        /* the supervisor's evidence: how far y_meas went against the model's expectation */
        if (c->sup.enabled && c->sup.travel_model > 0.0 && c->sup.travel_meas > 2.0 * c->sup.travel_model)
            said(&used, snprintf(AT, LEFT, "y_meas travelled %.3g times as far as the model "
                 "expects (%.4g um against %.4g um over about the last %llu samples): the loop's gain is far "
                 "above the model's. %s", c->sup.travel_meas / c->sup.travel_model, c->sup.travel_meas,
                 c->sup.travel_model, (unsigned long long)c->sup.weight,
                 ctx->internal ? "Compare the stage's parameters (pi.w0, pi.w[j], tf.*, creep.*) with the "
                 "controller's model (controller.pi.w0, controller.pi.w[j], controller.tf.*, controller.creep.*)"
                 : "Check the amplifier's gain, the units of v (V) and y_meas (um), and that the controller's "
                 "model (pi.*, tf.*, creep.*) is this stage's"));
        else if (ctx->internal)
            said(&used, snprintf(AT, LEFT, "Usual causes: the controller's loop delay d = %d %s does not match "
                 "this loop's, tf.delay + %d = %d (the stage's input delay tf.delay = %d, mv.feedthrough = %s), or "
                 "the stage's parameters (pi.w0, pi.w[j], tf.*, creep.*) far from the controller's model "
                 "(controller.pi.w0, controller.pi.w[j], controller.tf.*, controller.creep.*)", c->d,
                 !c->auto_delay ? "(1 + mv.delay, set)"
                 : c->detecting ? "(the start-up law's, still detecting)" : "(detected)",
                 ctx->feedthrough ? 1 : 2, ctx->stage_delay + (ctx->feedthrough ? 1 : 2), ctx->stage_delay,
                 ctx->feedthrough ? "true" : "false"));
        else
            said(&used, snprintf(AT, LEFT, "Usual causes: the controller's loop delay d = %d %s "
                 "does not match the loop (a master that hands the plant the controller's post-step output "
                 "removes a sample, as does mv.feedthrough; an extra plant or actuation delay adds one), a gain of "
                 "the sensor or amplifier far from the model's, or a plant far from the nominal model", c->d,
                 !c->auto_delay ? "(1 + mv.delay, set)"
                 : c->detecting ? "(the start-up law's, still detecting)" : "(detected)"));
        return used;
    }
    if (st == PIEZO_ERR_DIVERGED) {
        said(&used, snprintf(AT, LEFT, "the closed loop diverged: a value computed by the controller "
             "is not finite although its inputs are (loop delay d = %d%s; check it against %s)", c->d,
             c->auto_delay ? ", mv.delay = -1: detected" : " = 1 + mv.delay",
             ctx->internal ? "the stage's tf.delay and its parameters" : "the master and the plant"));
        return used;
    }
#undef AT
#undef LEFT
    return 0;
}

int piezo_controller_explain_safe_state(const piezo_controller *c, const piezo_sup_context *ctx,
                                        char *text, size_t size)
{
    int used;
    if (text != NULL && size > 0) text[0] = '\0';
    if (c == NULL || ctx == NULL || !c->fault) return 0;
    /* the words harness/fmu.py SAFE_STATE_WORDS knows this Warning by */
    used = snprintf(text, size, "sup.reaction = safe: from t = %.9g s the loop is held in its safe state "
                    "(sup.fault = %d): v ramps to 0 V over sup.ramp_time = %g s and stays there, adaptation "
                    "is frozen, the simulation goes on. Why: ", ctx->t0 + (double)(int64_t)c->k_fault * ctx->h,
                    c->fault, c->sup.ramp_time);
    if (used < 0) return 0;
    return used + piezo_controller_explain_in(c, piezo_controller_fault_status(c->fault), ctx,
                                              (size_t)used < size ? text + used : NULL,
                                              (size_t)used < size ? size - (size_t)used : 0);
}

/* the time of sample k where the loop is */
static double context_time(const piezo_sup_context *ctx, uint64_t k)
{
    return ctx->t0 + (double)(int64_t)k * ctx->h;
}

int piezo_controller_explain_reset(const piezo_controller *c, int refusal, const piezo_controller_input *in,
                                   uint64_t k, const piezo_sup_context *ctx, char *text, size_t size)
{
    double now, y_ref = in ? in->y_ref : 0.0, y_meas = in ? in->y_meas : 0.0;
    if (text != NULL && size > 0) text[0] = '\0';
    if (c == NULL || ctx == NULL) return 0;
    now = context_time(ctx, k);
    switch (refusal) {
    case PIEZO_RESET_ACCEPTED:
        /* c has restarted: its fault is gone, its count says how many times */
        return snprintf(text, size, "sup.reset accepted at t = %.9g s (reset %llu): the loop leaves its safe state "
                        "and restarts from the nominal model, its parameters kept, from the stage at rest at "
                        "y_meas = %.6g um: the law's reference ramps from there to y_d over sup.ramp_time = %g s, so "
                        "v ramps from 0 V; the estimates and the supervision start anew (sup.status 0 until it "
                        "verifies the loop again), the loop delay chosen and the sensor's measured noise are kept. "
                        "A fault of the response (inverted, gain, delay, unstable) cannot be seen at rest: if it "
                        "persists, the supervision stops the loop again once the stage moves",
                        now, (unsigned long long)c->n_resets, y_meas, c->sup.ramp_time);
    case PIEZO_RESET_NO_FAULT:
        return snprintf(text, size, "sup.reset raised at t = %.9g s while the loop runs (sup.fault = 0): there is "
                        "no safe state to leave, nothing was done", now);
    case PIEZO_RESET_RAMPING:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: v is still ramping to 0 V (sup.ramp_time = "
                        "%g s, until t = %.9g s); the loop stays in its safe state (sup.fault = %d). Lower sup.reset "
                        "and raise it again once v is at 0 V", now, c->sup.ramp_time,
                        context_time(ctx, c->k_fault + c->sup.ramp_samples), c->fault);
    case PIEZO_RESET_INPUTS:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: y_ref = %g um or y_meas = %g um is not "
                        "finite; the loop stays in its safe state (sup.fault = %d)", now, y_ref, y_meas, c->fault);
    case PIEZO_RESET_STUCK:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: the cause persists. y_meas still reads "
                        "%.9g um, to the bit what it read at the verdict (t = %.9g s), although v went from %g V to "
                        "0 V since: the sensor is still frozen, or v still does not reach the stage (sup.fault = "
                        "%d, %s). Check the sensor, its cable and the amplifier, then lower sup.reset and raise "
                        "it again", now, y_meas, context_time(ctx, c->k_fault), c->v_fault, c->fault,
                        piezo_supervisor_fault_name(c->fault));
    case PIEZO_RESET_OUT_OF_REACH:
        return snprintf(text, size, "sup.reset refused at t = %.9g s: the cause persists. The reference y_ref = "
                        "%.6g um is still beyond what the stage reached with v held at %g V (y_meas = %.6g um), by "
                        "more than sup.clip_error = %g um: restarted, the loop would be held at the rail again "
                        "(sup.fault = %d, %s). Bring the reference within reach, or widen sat.v_min..sat.v_max, "
                        "then lower sup.reset and raise it again", now, y_ref, c->v_fault, c->y_fault,
                        c->sup.clip_error, c->fault, piezo_supervisor_fault_name(c->fault));
    default:
        return 0;
    }
}

