/*
 * fmu_controller.c - the controller as an FMU shows it (see fmu_controller.h).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmu_controller.h"
#include "fmu_model.h"

/* A message said once: marks it said (*said = 1) and writes it into text; 1, a message. */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static int say_once(int *said, char *text, size_t size, const char *fmt, ...)
{
    va_list ap;
    *said = 1;
    va_start(ap, fmt);
    vsnprintf(text, size, fmt, ap);
    va_end(ap);
    return 1;
}

void fmu_controller_track_init(fmu_controller_track *t, const piezo_controller *c, double t0)
{
    t->delay = c->detecting ? 0 : c->d;
    t->delay_time = t0;
    t->said_delay = t->delay;
    t->said_verified = 0;
    t->said_redetect = 0;
    t->said_saturated = 0;
    t->said_large_error = 0;
    t->said_outlier = 0;
    t->said_fault = 0;
    t->said_fallback = 0;
    t->said_wait = 0;
    t->reset_input = 0;
    t->reset_said = 0;
    t->reset_k = 0;
    t->reset_y_ref = t->reset_y_meas = 0.0;
}

int fmu_controller_reset_input(fmu_controller_track *t, piezo_controller *c, int raised,
                               const piezo_controller_input *in)
{
    int edge = raised && !t->reset_input, refusal;
    t->reset_input = raised ? 1 : 0;
    if (!edge)
        return 0;
    refusal = piezo_controller_reset_refusal(c, in);
    t->reset_said = 1 + refusal;
    t->reset_k = c->k;
    t->reset_y_ref = isfinite(in->y_ref) ? in->y_ref : 0.0;
    t->reset_y_meas = isfinite(in->y_meas) ? in->y_meas : 0.0;
    if (refusal != PIEZO_RESET_ACCEPTED || piezo_controller_restart(c, in->y_meas) != PIEZO_OK)
        return 0;
    /* a new safe state is said again; the restarted loop's verification and waits too */
    t->said_fault = 0;
    t->said_verified = 0;
    t->said_wait = 0;
    return 1;
}

void fmu_controller_reset_keep(fmu_controller_reset_backup *u, const fmu_controller_track *t,
                               const piezo_controller *c, int raised)
{
    u->edge = raised && !t->reset_input;
    if (u->edge) {
        u->ctrl = *c;
        u->track = *t;
    }
}

void fmu_controller_reset_undo(const fmu_controller_reset_backup *u, fmu_controller_track *t, piezo_controller *c)
{
    piezo_sup_verdict why;
    if (!u->edge) return;
    why = c->verdict;
    *c = u->ctrl;
    c->verdict = why;
    *t = u->track;
}

/* the reset's message (t->reset_said), 1 if written: the event's (accepted, nothing to reset) when
 * warning is 0, the Warning's (refused) when 1 */
static int reset_message(fmu_controller_track *t, const piezo_controller *c, const piezo_sup_context *ctx,
                         int warning, char *text, size_t size)
{
    piezo_controller_input in;
    int refusal = t->reset_said - 1;
    int is_warning = refusal != PIEZO_RESET_ACCEPTED && refusal != PIEZO_RESET_NO_FAULT;
    if (t->reset_said == 0 || is_warning != warning)
        return 0;
    t->reset_said = 0;
    in.y_ref = t->reset_y_ref;
    in.y_meas = t->reset_y_meas;
    in.y_preview = 0.0;
    in.preview_lead = 0;
    piezo_controller_explain_reset(c, refusal, &in, t->reset_k, ctx, text, size);
    return 1;
}

void fmu_controller_track_commit(fmu_controller_track *t, const piezo_controller *c, double t0, double h)
{
    if (c->out.delay != t->delay) {
        t->delay = c->out.delay;
        t->delay_time = fmu_sample_time(t0, c->k - 1, h);
    }
}

int fmu_controller_event(fmu_controller_track *t, const piezo_controller *c, double t0, double h,
                         char *text, size_t size)
{
    piezo_sup_context ctx = fmu_controller_context(t0, h);
    if (reset_message(t, c, &ctx, 0, text, size))
        return 1;
    if (c->sup.status && !t->said_verified)
        return say_once(&t->said_verified, text, size, "supervision: y_meas answers v as the model says (%.3g "
                        "times its response, %d samples after it), verified at t = %.9g s", c->sup.verified_gain,
                        c->sup.delay, fmu_sample_time(t0, c->sup.k_verified, h));
    if (c->detecting && c->auto_delay && !t->said_wait && piezo_controller_probes_buried(c))
        return say_once(&t->said_wait, text, size, "delay detection waits (t = %.9g s): y_meas's noise, %.3g um "
                        "rms, buries a probe of mv.probe_max = %g um (it needs %g times the noise over the model's "
                        "first response tf.b1). While the noise stays this high no loop delay is chosen: the "
                        "start-up law (d = %d, the nominal model) runs on, sup.status stays 0 (not verified) and "
                        "sup.detect_time does not run. Set mv.delay to the loop's delay to run the adaptive law",
                        fmu_sample_time(t0, c->k - 1, h), c->noise_y2, c->probe_max, piezo_controller_probe_snr(),
                        PIEZO_DETECT_START_D);
    if (t->delay == t->said_delay)
        return 0;
    t->said_delay = t->delay;
    if (t->delay > 0)
        snprintf(text, size, "loop delay d = %d chosen at t = %.9g s (sample %llu): its sum of squared "
                 "prediction errors was at most %g times every other candidate's (d = 1, 2, 3) for %d samples; "
                 "the law uses d = %d and the observer pole mv.observer = %g from then on",
                 t->delay, t->delay_time, (unsigned long long)((t->delay_time - t0) / h + 0.5),
                 1.0 / PIEZO_DETECT_RATIO_INV, PIEZO_DETECT_CONFIRM, t->delay, c->observer);
    else
        snprintf(text, size, "loop delay detection restarted at t = %.9g s: the start-up law runs until "
                 "a delay is chosen", t->delay_time);
    return 1;
}

int fmu_controller_warning(fmu_controller_track *t, const piezo_controller *c, const piezo_sup_context *ctx,
                           char *text, size_t size)
{
    double t0 = ctx->t0, h = ctx->h;
    if (reset_message(t, c, ctx, 1, text, size))
        return 1;
    if (c->fault && !t->said_fault) {
        /* the safe state: said once, with the verdict in the words of an Error */
        t->said_fault = 1;
        piezo_controller_explain_safe_state(c, ctx, text, size);
        return 1;
    }
    if (c->n_outliers > 0 && !t->said_outlier)
        return say_once(&t->said_outlier, text, size, "y_meas = %.6g um at t = %.9g s was %.4g um from what the "
                        "model predicted, between samples it predicted well: an outlier (a reading dropped or "
                        "glitched), for which the model's prediction stood in (the law, the adaptation and the "
                        "monitor did not see it); further outliers are counted, not logged: the terminate call "
                        "reports the count", c->first_outlier, fmu_sample_time(t0, c->k_first_outlier, h),
                        c->first_outlier_error);
    if (c->n_fallbacks > 0 && !t->said_fallback) {
        t->said_fallback = 1;
        if (c->first_fallback == PIEZO_FALLBACK_JUMP)
            snprintf(text, size, "the law fell back to the nominal model at t = %.9g s: the reference jumped "
                     "%.4g um in one sample, beyond %d times the largest change the estimates had learned on "
                     "(%.4g um a sample; a step after a tone or a scan, which taught them one kind of motion); "
                     "the estimator restarts from the nominal model (rls.p0_loop). Harmless: the jump is "
                     "answered as by a fresh controller. Further fallbacks are counted (est.fallbacks, and at "
                     "terminate), not logged", fmu_sample_time(t0, c->k_first_fallback, h), c->first_fallback_value,
                     PIEZO_FALLBACK_JUMP_RATIO, c->first_fallback_other);
        else if (c->first_fallback == PIEZO_FALLBACK_RINGING)
            snprintf(text, size, "the law fell back to the nominal model at t = %.9g s: the adapted estimates "
                     "mispredicted y_meas by %.4g um in one sample, beyond monitor.pred_error_max = %g um and %d "
                     "times the measured noise of their predictions (the nominal model: %.4g um), while no jump of "
                     "the reference was being answered (a loop that rings on its estimates); the estimator "
                     "restarts from the nominal model (rls.p0_loop). Further fallbacks are counted (est.fallbacks, "
                     "and at terminate), not logged", fmu_sample_time(t0, c->k_first_fallback, h),
                     c->first_fallback_value, c->pred_error_max, PIEZO_FALLBACK_RINGING_NOISE,
                     c->first_fallback_other);
        else
            snprintf(text, size, "the law fell back to the nominal model at t = %.9g s: over the last "
                     "rls.fallback_window = %g s the adapted estimates predicted y_meas worse than the nominal model "
                     "(rms a-priori errors %.4g um against %.4g um, beyond rls.fallback_ratio = %g times); the "
                     "estimator restarts from the nominal model (rls.p0_loop). Further fallbacks are counted "
                     "(est.fallbacks, and at terminate), not logged", fmu_sample_time(t0, c->k_first_fallback, h),
                     (double)c->fallback_samples * h, c->first_fallback_value, c->first_fallback_other,
                     c->fallback_ratio);
        return 1;
    }
    if (c->n_detections > 1 && !t->said_redetect)
        return say_once(&t->said_redetect, text, size, "the chosen loop delay no longer predicts the measurement "
                        "(|pred_error| above monitor.pred_error_max = %g um for %d samples): delay detection "
                        "restarted at t = %.9g s with the start-up law; later restarts are not logged (the "
                        "terminate call counts them)", c->pred_error_max, PIEZO_DETECT_REDETECT,
                        fmu_sample_time(t0, c->k_delay, h));
    if (c->n_saturated > 0 && !t->said_saturated)
        return say_once(&t->said_saturated, text, size, "v was clipped to [sat.v_min, sat.v_max] = [%g, %g] V, "
                        "first at t = %.9g s (adaptation pauses while a clipped sample is in the regressor); "
                        "further clipping is counted, not logged: the terminate call reports the count",
                        c->sat_v_min, c->sat_v_max, fmu_sample_time(t0, c->k_first_saturated, h));
    if (c->n_large_settled > 0 && !t->said_large_error) {
        char consequence[192], bound[256];
        /* monitor.divergence_samples = 0 switches the verdict off: say so, not "after 0 samples" */
        if (c->divergence_samples > 0)
            snprintf(consequence, sizeof consequence, "If it stays above for monitor.divergence_samples = %llu "
                     "consecutive samples, or in %d %% of the last %llu, the loop is declared unstable and the "
                     "doStep fails", (unsigned long long)c->divergence_samples, PIEZO_MONITOR_SHARE_PERCENT,
                     (unsigned long long)c->divergence_samples);
        else
            snprintf(consequence, sizeof consequence, "With monitor.divergence_samples = 0 the loop is never "
                     "declared unstable, however long it stays above");
        piezo_controller_explain_bound(c, bound, sizeof bound);
        return say_once(&t->said_large_error, text, size, "|pred_error| exceeded %s, first at t = %.9g s "
                        "(not in the answer to a jump of the reference, which is counted but not logged): the model "
                        "of G no longer predicts the measurement. %s; further exceedances are counted, not logged",
                        bound, fmu_sample_time(t0, c->k_first_large_settled, h), consequence);
    }
    return 0;
}

int fmu_controller_summary(const piezo_controller *c, char *text, size_t size)
{
    int used;
    if (c->n_saturated == 0 && c->n_large_error == 0 && c->n_detections <= 1 && c->n_outliers == 0 && !c->fault
        && c->n_fallbacks == 0)
        return 0;
    used = snprintf(text, size, "of %llu samples, v was clipped in %llu; |pred_error| exceeded "
                    "monitor.pred_error_max = %g um in %llu (largest %.6g um); delay detection ran %llu times",
                    (unsigned long long)c->k, (unsigned long long)c->n_saturated, c->pred_error_max,
                    (unsigned long long)c->n_large_error, c->max_abs_pred_error,
                    (unsigned long long)c->n_detections);
    if (c->n_outliers > 0 && used > 0 && (size_t)used < size)
        used += snprintf(text + used, size - (size_t)used, "; %llu outliers of y_meas were replaced by the "
                         "model's prediction", (unsigned long long)c->n_outliers);
    if (c->n_fallbacks > 0 && used > 0 && (size_t)used < size)
        used += snprintf(text + used, size - (size_t)used, "; the law fell back to the nominal model %llu times "
                         "(est.fallbacks), the admissible set bounded %llu updates of the estimates",
                         (unsigned long long)c->n_fallbacks, (unsigned long long)c->n_projections);
    if (c->fault && used > 0 && (size_t)used < size)
        snprintf(text + used, size - (size_t)used, "; the loop was held in its safe state for the last %llu "
                 "(sup.fault = %d, %s)", (unsigned long long)(c->k - c->k_fault), c->fault,
                 piezo_supervisor_fault_name(c->fault));
    return 1;
}

int fmu_controller_failure(const piezo_controller *c, const piezo_sup_context *ctx, piezo_status st,
                           char *text, size_t size)
{
    /* the core's words (one home: the Python binding and every FMU that runs the controller) */
    return piezo_controller_explain_in(c, st, ctx, text, size) > 0;
}

int fmu_controller_fallbacks(const piezo_controller *c)
{
    return c->n_fallbacks > (uint64_t)INT32_MAX ? INT32_MAX : (int)c->n_fallbacks;
}

void fmu_controller_fault_outputs(const piezo_controller *c, double t0, double h, int *fault, double *fault_time)
{
    *fault = c->fault;
    *fault_time = c->fault ? fmu_sample_time(t0, c->k_fault, h) : 0.0;
}

const char *fmu_controller_track_check(const fmu_controller_track *t, int core_initialized, double t0,
                                       uint64_t k, double h)
{
    if ((t->said_verified != 0 && t->said_verified != 1) || (t->said_redetect != 0 && t->said_redetect != 1)
        || (t->said_saturated != 0 && t->said_saturated != 1)
        || (t->said_large_error != 0 && t->said_large_error != 1)
        || (t->said_outlier != 0 && t->said_outlier != 1) || (t->said_fault != 0 && t->said_fault != 1)
        || (t->said_fallback != 0 && t->said_fallback != 1) || (t->said_wait != 0 && t->said_wait != 1)
        || (t->reset_input != 0 && t->reset_input != 1))
        return "warning flags are not 0 or 1";
    if (t->reset_said < 0 || t->reset_said > 1 + PIEZO_RESET_OUT_OF_REACH || t->reset_k > k
        || !isfinite(t->reset_y_ref) || !isfinite(t->reset_y_meas))
        return "sup.reset's record out of range";
    if (!isfinite(t->delay_time))
        return "time stamps not finite";
    if (t->delay < 0 || t->delay > PIEZO_MV_MAX_D || t->said_delay < 0 || t->said_delay > PIEZO_MV_MAX_D)
        return "timing outputs out of range";
    if (core_initialized && (t->delay_time < t0 || t->delay_time > fmu_sample_time(t0, k, h)))
        return "controller time stamps differ from t0 + k h";
    return NULL;
}
