/* piezo_supervisor_explain.c - what the supervision says: its verdicts' names and messages.
 * See piezo_supervisor.h. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include "piezo_supervisor.h"

const char *piezo_supervisor_fault_name(int fault)
{
    switch (fault) {
    case PIEZO_SUP_NONE: return "none";
    case PIEZO_SUP_NO_RESPONSE: return "no response";
    case PIEZO_SUP_INVERTED: return "inverted response";
    case PIEZO_SUP_GAIN_HIGH: return "response far above the model";
    case PIEZO_SUP_DELAY: return "loop delay beyond the controller's";
    case PIEZO_SUP_CLIPPED: return "v held at a limit";
    case PIEZO_SUP_UNDETECTED: return "no loop delay found";
    case PIEZO_SUP_GAIN_CHANGED: return "response gain changed";
    case PIEZO_SUP_FROZEN: return "y_meas frozen";
    case PIEZO_SUP_UNSTABLE: return "loop unstable";
    case PIEZO_SUP_DIVERGED: return "value not finite";
    default: return "unknown";
    }
}

/* appends to text[*used .. size): snprintf that keeps a running length */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static void add(char *text, size_t size, int *used, const char *fmt, ...)
{
    va_list ap;
    int w;
    size_t at = *used < 0 ? 0 : (size_t)*used;
    va_start(ap, fmt);
    w = vsnprintf(at < size ? text + at : NULL, at < size ? size - at : 0, fmt, ap);
    va_end(ap);
    if (w > 0) *used += w;
}

/* t0 + k h: the time of sample k, as the FMUs stamp it */
static double time_of(const piezo_sup_context *c, uint64_t k)
{
    return c->t0 + (double)(int64_t)k * c->h;
}

/* "over the last N samples (t = a to b s), what v did should have moved y_meas by c um in all
 * (the sum of its sample-to-sample moves, by the controller's model); it moved e um" */
static void add_evidence(char *t, size_t size, int *u, const piezo_sup_verdict *v, const piezo_sup_context *c)
{
    add(t, size, u, "over the last %llu samples (t = %.9g to %.9g s), what v did should have moved y_meas "
        "by %.4g um in all (the sum of its sample-to-sample moves, by the controller's model); it moved "
        "%.4g um", (unsigned long long)v->window, time_of(c, v->k + 1 - v->window), time_of(c, v->k),
        v->travel_model, v->travel_meas);
}

/* PiezoStageClosedLoop: what to compare when its stage does not answer as the controller's model */
#define COMPARE_MODEL "Compare the stage's parameters with the controller's model: pi.w0 and pi.w[j] with " \
    "controller.pi.w0 and controller.pi.w[j], tf.a1, tf.a2, tf.b1, tf.b2 with controller.tf.a1, " \
    "controller.tf.a2, controller.tf.b1, controller.tf.b2, creep.k_c and creep.alpha with controller.creep.k_c " \
    "and controller.creep.alpha"

/* the loop delay of PiezoStageClosedLoop's loop: the stage's input delay plus the controller's */
static int internal_delay(const piezo_sup_context *c)
{
    return c->stage_delay + (c->feedthrough ? 1 : 2);
}

static void explain_no_response(char *t, size_t size, int *u, const piezo_sup_verdict *v,
                                const piezo_sup_context *c)
{
    if (v->stuck_move > 0.0) {
        /* y_meas stuck against the model: the stage moved, by the model, beyond what y_meas shows */
        add(t, size, u, "y_meas does not follow v: y_meas has not changed at all for the last %llu samples (t = %.9g "
            "to %.9g s; it stays at %.6g um), while the controller's model says the stage moved %.4g um in that "
            "time: even sup.gain_min = %g of that move is beyond what y_meas would show (%.3g um: two of its "
            "steps, %d times its measured noise, at least %d nm). ", (unsigned long long)(v->y_same + 1),
            time_of(c, v->k - v->y_same), time_of(c, v->k), v->y_meas, v->stuck_move, v->gain_min,
            v->stuck_bound, PIEZO_SUP_STUCK_NOISE, PIEZO_SUP_STUCK_MOVE_NM);
        if (c->internal)
            add(t, size, u, "The stage does not move in answer to v as its model says, or its sensor model stopped. "
                COMPARE_MODEL ", and check sensor.resolution");
        else
            add(t, size, u, "y_meas is stuck, or v does not reach the stage: a quiet reading does not tell them "
                "apart, and the stage may move unseen. Check the connections PiezoStage.y_meas -> y_meas and "
                "AdaptiveCompoundController.v -> PiezoStage.v, and the sensor");
        return;
    }
    add(t, size, u, "y_meas does not follow v: ");
    add_evidence(t, size, u, v, c);
    if (v->y_constant) {
        add(t, size, u, ". y_meas has not changed at all for the last %llu samples (it stays at %.6g um): ",
            (unsigned long long)(v->y_same + 1), v->y_meas);
        if (c->internal)
            add(t, size, u, "the stage does not move in answer to v, or moves less than its sensor's step "
                "(sensor.resolution). " COMPARE_MODEL ", and check sensor.resolution");
        else
            add(t, size, u, "it is not connected or the sensor is stuck, or v does not reach the stage. Check "
                "the connections PiezoStage.y_meas -> y_meas and AdaptiveCompoundController.v -> PiezoStage.v");
    } else if (!c->internal && v->ref_fit >= 0.5 && v->ref_gain >= 0.25 && v->ref_gain <= 4.0) {
        add(t, size, u, ", not in answer to v; y_ref moves as y_meas should (%.3g times the model's "
            "response): y_meas and y_ref are swapped. Connect PiezoStage.y_meas -> y_meas and "
            "ReferenceSignal.y_ref -> y_ref", v->ref_gain);
    } else if (!c->internal && v->fit >= 0.5 && fabs(v->gain) >= 3e-4 && fabs(v->gain) <= 3e-3) {
        add(t, size, u, ", and its moves are %.3g times the model's: y_meas is in mm instead of um? "
            "Check the unit of y_meas (um)", v->gain);
    } else if (c->internal) {
        add(t, size, u, ", and its moves are %.3g times the model's (explaining %.0f %% of them): the stage "
            "answers v far less than the controller's model says. " COMPARE_MODEL " (or widen sup.gain_min)",
            v->gain, 100.0 * v->fit);
    } else {
        add(t, size, u, ", and its moves are %.3g times the model's (explaining %.0f %% of them): "
            "v does not reach the stage, or y_meas is not the stage's measurement. Check the "
            "connections AdaptiveCompoundController.v -> PiezoStage.v and PiezoStage.y_meas -> "
            "y_meas, their units (V, um) and the amplifier", v->gain, 100.0 * v->fit);
    }
}

static void explain_delay(char *t, size_t size, int *u, const piezo_sup_verdict *v, const piezo_sup_context *c)
{
    add(t, size, u, "y_meas answers v %d samples later (%.3g ms, %.0f %% of its changes explained), "
        "but the controller ", v->delay, 1e3 * c->h * (double)v->delay, 100.0 * v->fit);
    if (c->internal) {
        if (v->auto_delay)
            add(t, size, u, "detects loop delays of 1 to 3 samples (mv.delay = -1), and this loop's is "
                "tf.delay + %d = %d (the stage's input delay tf.delay = %d, mv.feedthrough = %s). Set "
                "mv.delay = %d (d = %d), or reduce tf.delay", c->feedthrough ? 1 : 2, internal_delay(c),
                c->stage_delay, c->feedthrough ? "true" : "false", v->delay - 1, v->delay);
        else
            add(t, size, u, "runs d = %d (mv.delay = %d), and this loop's delay is tf.delay + %d = %d (the "
                "stage's input delay tf.delay = %d, mv.feedthrough = %s). Set mv.delay = %d (d = %d), or -1 "
                "to detect delays of 1 to 3 samples", v->loop_delay, v->loop_delay - 1, c->feedthrough ? 1 : 2,
                internal_delay(c), c->stage_delay, c->feedthrough ? "true" : "false", v->delay - 1, v->delay);
    } else if (v->auto_delay) {
        add(t, size, u, "detects loop delays of 1 to 3 samples (mv.delay = -1): the loop has more delay "
            "than a master and the stage add (a plant input delay, or an extra one in the master). "
            "Set mv.delay = %d (d = %d) for this loop, or remove the extra delay", v->delay - 1, v->delay);
    } else {
        add(t, size, u, "runs d = %d (mv.delay = %d). Set mv.delay = %d (d = %d), or -1 to detect "
            "delays of 1 to 3 samples", v->loop_delay, v->loop_delay - 1, v->delay - 1, v->delay);
    }
}

/* a noise-like y_meas whose steps are this many times the candidates' prediction errors is a loop
 * that oscillates, not a noisy sensor */
#define OSCILLATION_RATIO 10.0

static void explain_undetected(char *t, size_t size, int *u, const piezo_sup_verdict *v,
                               const piezo_sup_context *c)
{
    add(t, size, u, "no loop delay of 1 to 3 samples explains y_meas after %llu samples (%.3g s, "
        "sup.detect_time, since t = %.9g s): ", (unsigned long long)v->clip_samples,
        c->h * (double)v->clip_samples, time_of(c, v->k + 1 - v->clip_samples));
    if (v->noise > 0.0 && v->reversal_share * 100.0 >= PIEZO_SUP_NOISY_PERCENT
        && v->step_rms > OSCILLATION_RATIO * v->noise) {
        /* y_meas reverses as noise would, but by steps far beyond what the candidates fail to
         * predict: the loop itself swings from sample to sample (a sensor's noise gives steps of
         * about 1.4 times its rms, and the candidates' errors are at least that noise) */
        add(t, size, u, "y_meas swings from sample to sample: it reversed its direction in %.0f %% of the samples "
            "by steps of %.3g um rms, while the candidates' prediction errors were %.3g um rms: the loop "
            "oscillates, and the loop's gain is far above the model's. ", 100.0 * v->reversal_share, v->step_rms,
            v->noise);
        if (c->internal)
            add(t, size, u, COMPARE_MODEL " (or widen sup.gain_max)");
        else
            add(t, size, u, "Check the amplifier's gain, the units of v (V) and y_meas (um), and that the "
                "controller's model (pi.*, tf.*, creep.*) is this stage's");
    } else if (v->noise > 0.0 && v->probe_wanted > v->probe_max && v->reversal_share * 100.0 >= PIEZO_SUP_NOISY_PERCENT) {
        /* a noise-dominated measurement (it reverses its direction often), and the probes that
         * would show the delay through it are beyond mv.probe_max */
        add(t, size, u, "the measurement's noise buries the delay probes. y_meas reversed its direction in %.0f %% "
            "of the samples (steps of %.3g um rms) and the candidates' prediction errors were %.3g um rms; a probe of p um on q moves y_meas by %.3g p um at first (tf.b1), and the "
            "delay shows once that is %.3g times the noise: p = %.3g um. mv.probe_max = %.3g um caps it (%d probe%s "
            "made). Raise mv.probe_max to %.3g um if the stage may move that much, set mv.delay to the loop's "
            "delay (", 100.0 * v->reversal_share, v->step_rms, v->noise, v->probe_gain, v->probe_snr,
            v->probe_wanted, v->probe_max, v->probes,
            v->probes == 1 ? "" : "s", v->probe_wanted);
        if (c->internal)
            add(t, size, u, "mv.delay = %d here: tf.delay = %d, mv.feedthrough = %s", internal_delay(c) - 1,
                c->stage_delay, c->feedthrough ? "true" : "false");
        else
            add(t, size, u, "mv.delay = 1 for a master that exchanges values at communication points, 0 for "
                "true Gauss-Seidel, plus a plant input delay");
        add(t, size, u, "), or lower the sensor's noise");
    } else if (c->internal) {
        add(t, size, u, "y_meas does not answer v as the controller's model says, or the loop's delay is "
            "beyond 3 samples (tf.delay = %d, mv.feedthrough = %s: set mv.delay = %d). " COMPARE_MODEL,
            c->stage_delay, c->feedthrough ? "true" : "false", internal_delay(c) - 1);
    } else {
        add(t, size, u, "y_meas does not answer v as a closed loop would. Check the connections of y_meas "
            "and v, or set mv.delay if the loop has a known longer delay");
    }
}

int piezo_supervisor_explain_in(const piezo_sup_verdict *v, const piezo_sup_context *c, char *t, size_t size)
{
    int u = 0;
    if (t != NULL && size > 0) t[0] = '\0';
    if (v == NULL || c == NULL) return 0;
    switch (v->fault) {
    case PIEZO_SUP_NO_RESPONSE:
        explain_no_response(t, size, &u, v, c);
        break;
    case PIEZO_SUP_INVERTED:
        add(t, size, &u, "y_meas moves against v: ");
        add_evidence(t, size, &u, v, c);
        add(t, size, &u, ", and its moves are %.3g times the model's (explaining %.0f %% of them): ", v->gain,
            100.0 * v->fit);
        if (c->internal)
            add(t, size, &u, "the stage answers v with the opposite sign of the controller's model. Compare the "
                "signs of pi.w0, pi.w[j], tf.b1 and tf.b2 with controller.pi.w0, controller.pi.w[j], "
                "controller.tf.b1 and controller.tf.b2");
        else
            add(t, size, &u, "y_meas or v is inverted. Check the sign of the sensor, of the amplifier and of "
                "the connections y_meas and v");
        break;
    case PIEZO_SUP_GAIN_HIGH:
        add(t, size, &u, "y_meas moves %.3g times as much as the model expects: ", v->gain);
        add_evidence(t, size, &u, v, c);
        if (c->internal)
            add(t, size, &u, ". The stage answers v far more than the controller's model says. " COMPARE_MODEL
                " (or widen sup.gain_max)");
        else if (v->gain >= 300.0 && v->gain <= 3000.0)
            add(t, size, &u, ". y_meas is in nm instead of um? Check the unit of y_meas (um)");
        else
            add(t, size, &u, ". Check the units of y_meas (um) and v (V), the amplifier's gain, and that the "
                "controller's model (pi.*, tf.*, creep.*) is this stage's");
        break;
    case PIEZO_SUP_DELAY:
        explain_delay(t, size, &u, v, c);
        break;
    case PIEZO_SUP_CLIPPED:
        add(t, size, &u, "v has been held at %.4g V (a limit of sat.v_min .. sat.v_max) for %llu samples "
            "(%.3g s, sup.clip_time, since t = %.9g s) while |y_d - y_meas| averaged %.4g um (above "
            "sup.clip_error = %.4g um): the loop cannot reach the reference. ", v->clip_v,
            (unsigned long long)v->clip_samples, c->h * (double)v->clip_samples,
            time_of(c, v->k - v->clip_samples), v->error, v->error_bound);
        if (v->y_constant)
            add(t, size, &u, "y_meas has not changed at all for the last %llu samples (it stays at %.6g um) while v "
                "went to the limit: the measurement is stuck, not the reference out of reach. %s",
                (unsigned long long)(v->y_same + 1), v->y_meas, c->internal
                ? "The stage's sensor model stopped (sensor.noise_rms, sensor.resolution)"
                : "Check the sensor and the connection PiezoStage.y_meas -> y_meas");
        else if (v->verified_gain > 0.0)
            add(t, size, &u, "y_meas answered v as the model expects (%.3g times its response), so the "
                "reference asks for more than the stage reaches within the limits: reduce the reference%s "
                "or widen sat.v_min .. sat.v_max", v->verified_gain,
                c->internal ? " (offset, amplitude[i], or the input y_d)" : "");
        else if (c->internal)
            add(t, size, &u, "y_meas never answered v as the model expects. " COMPARE_MODEL ", and check the "
                "limits sat.v_min .. sat.v_max");
        else
            add(t, size, &u, "y_meas never answered v as the model expects: check y_meas and v (connections, "
                "units, sign) and the limits sat.v_min .. sat.v_max");
        break;
    case PIEZO_SUP_UNDETECTED:
        explain_undetected(t, size, &u, v, c);
        break;
    case PIEZO_SUP_GAIN_CHANGED:
        add(t, size, &u, "y_meas answers v %.3g times as much as before: its response is %.3g times the "
            "model's now, and was %.3g times since the loop was verified: ", v->followed_gain > 0.0
            ? v->gain / v->followed_gain : 0.0, v->gain, v->followed_gain);
        add_evidence(t, size, &u, v, c);
        if (c->internal)
            add(t, size, &u, ". The stage's response changed: its model differs from the controller's where the "
                "loop went since. " COMPARE_MODEL);
        else
            add(t, size, &u, ". A sensor or an amplifier whose gain changed: the controller would adapt to it, "
                "and the stage would then follow y_d times %.3g. Check the sensor's and the amplifier's gains "
                "(PiezoStage.y_meas -> y_meas, AdaptiveCompoundController.v -> PiezoStage.v)",
                v->gain != 0.0 ? v->followed_gain / v->gain : 0.0);
        break;
    case PIEZO_SUP_FROZEN:
        if (v->bridged_error != 0.0)
            add(t, size, &u, "y_meas is stuck: it jumped to %.6g um, %.4g um from what the controller's model "
                "predicted (an outlier: the prediction stood in for it), and has held that value to the bit for "
                "%llu samples (t = %.9g to %.9g s), while the model's prediction kept standing in: a sensor "
                "that died or stuck. ", v->y_meas, v->bridged_error, (unsigned long long)(v->y_same + 1),
                time_of(c, v->k - v->y_same), time_of(c, v->k));
        else if (v->declared_noise > 0.0)
            add(t, size, &u, "y_meas has frozen: it has not changed at all for the last %llu samples (t = %.9g to "
                "%.9g s; it stays at %.6g um). A live sensor with the noise declared, sup.sensor_noise = %.4g um "
                "rms, on its step of %.4g um repeats a reading with a chance of %.3g at most, and %llu repeats "
                "in a row with a chance below e^-%d: ", (unsigned long long)(v->y_same + 1), time_of(c, v->k - v->y_same),
                time_of(c, v->k), v->y_meas, v->declared_noise, v->grid_step, v->repeat_chance,
                (unsigned long long)v->y_same, PIEZO_SUP_STUCK_LOG_ODDS);
        else
            add(t, size, &u, "y_meas has frozen: it has not changed at all for the last %llu samples (t = %.9g to "
                "%.9g s; it stays at %.6g um), although before it reversed its direction from one sample to the "
                "next in %.0f %% of the samples (its sample-to-sample changes were %.3g um rms: the sensor's noise) "
                "and repeated a value in %.0f %% of them. A live sensor does not stop its noise: ",
                (unsigned long long)(v->y_same + 1), time_of(c, v->k - v->y_same), time_of(c, v->k), v->y_meas,
                100.0 * v->reversal_share, v->step_rms, 100.0 * v->repeat_share);
        if (c->internal)
            add(t, size, &u, "the stage's sensor model stopped (sensor.noise_rms, sensor.resolution)");
        else
            add(t, size, &u, "the sensor or its connection is stuck (the stage may drift unseen). Check the "
                "sensor and the connection PiezoStage.y_meas -> y_meas");
        if (v->declared_noise > 0.0)
            add(t, size, &u, c->internal ? ", or sup.sensor_noise declares more than sensor.noise_rms"
                : ", or sup.sensor_noise declares more noise than the sensor has (declare at most its rms at rest)");
        break;
    default:
        add(t, size, &u, "no fault");
        break;
    }
    return u;
}

int piezo_supervisor_explain(const piezo_sup_verdict *v, double h, char *t, size_t size)
{
    piezo_sup_context c;
    memset(&c, 0, sizeof c);
    c.h = h;
    return piezo_supervisor_explain_in(v, &c, t, size);
}
