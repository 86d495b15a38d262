/*
 * AdaptiveCompoundController/model.c - the controller FMU's model: variable
 * table, start values and calls into the core controller (piezo_controller.h).
 * Everything FMI lives in the glues (fmu_src/fmi/: fmu_glue_core.c shared by
 * fmi2_glue.c and fmi3_glue.c), so this file serves both FMI versions.
 *
 * Timing (default, mv.feedthrough = false): a doStep from t_k samples the
 * held inputs y_ref = y_d(k+d), y_meas(k), computes and commits sample k,
 * and the outputs at t_(k+1) are that sample's v, q, estimates. No output
 * depends directly on an input, so every master (Jacobi, Gauss-Seidel in
 * either order, SSP players) runs the same loop, with delay d = 2.
 * With mv.feedthrough = true the outputs at t_k are piezo_controller_peek
 * with the held inputs of t_k (committed by the doStep from t_k): d = 1 for a
 * master that reads v after setting the inputs.
 */
#include <math.h>
#include <stdio.h>
#include <stddef.h>
#include "fmu_model.h"

#define PARAM_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define PARAM_INT(name, field) { name, MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define PARAM_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define OUTPUT_REAL(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, out.field) }
#define OUTPUT_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_OUTPUT, offsetof(ModelData, out.field) }

const model_variable model_variables[MODEL_N_VARIABLES] = {
    [vr_y_ref] = { "y_ref", MODEL_REAL, MODEL_INPUT, offsetof(ModelData, y_ref) },
    [vr_y_meas] = { "y_meas", MODEL_REAL, MODEL_INPUT, offsetof(ModelData, y_meas) },
    [vr_v] = OUTPUT_REAL("v", v),
    [vr_q] = OUTPUT_REAL("q", q),
    [vr_est_a1] = OUTPUT_REAL("est.a1", theta[0]),
    [vr_est_a2] = OUTPUT_REAL("est.a2", theta[1]),
    [vr_est_b1] = OUTPUT_REAL("est.b1", theta[2]),
    [vr_est_b2] = OUTPUT_REAL("est.b2", theta[3]),
    [vr_pred_error] = OUTPUT_REAL("pred_error", pred_error),
    [vr_saturated] = OUTPUT_BOOL("saturated", saturated),
    [vr_pi_m] = PARAM_INT("pi.m", pi.m),
    [vr_pi_v_max] = PARAM_REAL("pi.v_max", pi.v_max),
    [vr_pi_w0] = PARAM_REAL("pi.w0", pi.w0),
    [vr_pi_w1] = PARAM_REAL("pi.w[1]", pi.w[0]),
    [vr_pi_w2] = PARAM_REAL("pi.w[2]", pi.w[1]),
    [vr_pi_w3] = PARAM_REAL("pi.w[3]", pi.w[2]),
    [vr_pi_w4] = PARAM_REAL("pi.w[4]", pi.w[3]),
    [vr_pi_w5] = PARAM_REAL("pi.w[5]", pi.w[4]),
    [vr_pi_w6] = PARAM_REAL("pi.w[6]", pi.w[5]),
    [vr_pi_w7] = PARAM_REAL("pi.w[7]", pi.w[6]),
    [vr_pi_w8] = PARAM_REAL("pi.w[8]", pi.w[7]),
    [vr_pi_w9] = PARAM_REAL("pi.w[9]", pi.w[8]),
    [vr_pi_w10] = PARAM_REAL("pi.w[10]", pi.w[9]),
    [vr_pi_w11] = PARAM_REAL("pi.w[11]", pi.w[10]),
    [vr_pi_w12] = PARAM_REAL("pi.w[12]", pi.w[11]),
    [vr_pi_w13] = PARAM_REAL("pi.w[13]", pi.w[12]),
    [vr_pi_w14] = PARAM_REAL("pi.w[14]", pi.w[13]),
    [vr_pi_w15] = PARAM_REAL("pi.w[15]", pi.w[14]),
    [vr_pi_w16] = PARAM_REAL("pi.w[16]", pi.w[15]),
    [vr_tf_a1] = PARAM_REAL("tf.a1", tf_a1),
    [vr_tf_a2] = PARAM_REAL("tf.a2", tf_a2),
    [vr_tf_b1] = PARAM_REAL("tf.b1", tf_b1),
    [vr_tf_b2] = PARAM_REAL("tf.b2", tf_b2),
    [vr_creep_k_c] = PARAM_REAL("creep.k_c", creep_k_c),
    [vr_creep_alpha] = PARAM_REAL("creep.alpha", creep_alpha),
    [vr_creep_exact] = PARAM_BOOL("creep.exact", creep_exact),
    [vr_h] = PARAM_REAL("h", h),
    [vr_mv_delay] = PARAM_INT("mv.delay", mv_delay),
    [vr_mv_feedthrough] = PARAM_BOOL("mv.feedthrough", mv_feedthrough),
    [vr_mv_lambda_u] = PARAM_REAL("mv.lambda_u", mv_lambda_u),
    [vr_rls_enabled] = PARAM_BOOL("rls.enabled", rls_enabled),
    [vr_rls_forgetting] = PARAM_REAL("rls.forgetting", rls_forgetting),
    [vr_rls_p0] = PARAM_REAL("rls.p0", rls_p0),
    [vr_rls_trace_max] = PARAM_REAL("rls.trace_max", rls_trace_max),
    [vr_sat_enabled] = PARAM_BOOL("sat.enabled", sat_enabled),
    [vr_sat_v_min] = PARAM_REAL("sat.v_min", sat_v_min),
    [vr_sat_v_max] = PARAM_REAL("sat.v_max", sat_v_max),
    [vr_monitor_pred_error_max] = PARAM_REAL("monitor.pred_error_max", monitor_pred_error_max),
    [vr_monitor_divergence_samples] = PARAM_INT("monitor.divergence_samples", monitor_divergence_samples),
};

void model_set_start_values(ModelData *data)
{
    piezo_controller_default_params(&data->params);
    data->y_ref = 0.0;
    data->y_meas = 0.0;
}

piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag)
{
    (void)start_time;   /* time-invariant */
    data->said_saturated = 0;
    data->said_large_error = 0;
    return piezo_controller_init(&data->ctrl, &data->params, diag);
}

double model_sample_period(const ModelData *data)
{
    return data->params.h;
}

size_t model_history_needed(const ModelData *data)
{
    return piezo_controller_history_needed(&data->ctrl);
}

piezo_status model_step(ModelData *data, double *history, size_t history_capacity,
                        int outputs_current)
{
    /* mv.feedthrough: the sample the outputs were read from is committed as is
     * (computed once); the commit refuses it if it is not this sample's */
    if (outputs_current && data->params.mv_feedthrough)
        return piezo_controller_commit(&data->ctrl, &data->pending, NULL);
    return piezo_controller_step(&data->ctrl, data->y_ref, data->y_meas,
                                 history, history_capacity, NULL);
}

piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity)
{
    if (data->params.mv_feedthrough) {
        piezo_status st = piezo_controller_evaluate(&data->ctrl, data->y_ref, data->y_meas,
                                                    history, history_capacity, &data->pending);
        if (st == PIEZO_OK)
            data->out = data->pending.out;
        return st;
    }
    data->out = data->ctrl.out;     /* published at the end of the last step */
    return PIEZO_OK;
}

int model_direct_feedthrough(const ModelData *data)
{
    return data->params.mv_feedthrough != 0;
}

static double sample_time(const ModelData *data, double start_time, uint64_t k)
{
    return start_time + (double)k * data->params.h;
}

int model_step_warning(ModelData *data, double start_time, char *text, size_t size)
{
    const piezo_controller *c = &data->ctrl;
    if (c->n_saturated > 0 && !data->said_saturated) {
        data->said_saturated = 1;
        snprintf(text, size, "v was clipped to [sat.v_min, sat.v_max] = [%g, %g] V, first at "
                 "t = %.9g s (adaptation pauses while a clipped sample is in the regressor); "
                 "further clipping is counted, not logged: the terminate call reports the count",
                 c->sat_v_min, c->sat_v_max, sample_time(data, start_time, c->k_first_saturated));
        return 1;
    }
    if (c->n_large_error > 0 && !data->said_large_error) {
        char consequence[192];
        data->said_large_error = 1;
        /* monitor.divergence_samples = 0 switches the verdict off: say so, not "after 0 samples" */
        if (c->divergence_samples > 0)
            snprintf(consequence, sizeof consequence, "If it stays above for monitor.divergence_samples = %llu "
                     "consecutive samples the loop is declared unstable and the doStep fails",
                     (unsigned long long)c->divergence_samples);
        else
            snprintf(consequence, sizeof consequence, "With monitor.divergence_samples = 0 the loop is never "
                     "declared unstable, however long it stays above");
        snprintf(text, size, "|pred_error| exceeded monitor.pred_error_max = %g um, first at t = %.9g s: "
                 "the model of G no longer predicts the measurement. %s; further exceedances are counted, "
                 "not logged", c->pred_error_max, sample_time(data, start_time, c->k_first_large_error),
                 consequence);
        return 1;
    }
    return 0;
}

int model_terminate_warning(const ModelData *data, char *text, size_t size)
{
    const piezo_controller *c = &data->ctrl;
    if (c->n_saturated == 0 && c->n_large_error == 0)
        return 0;
    snprintf(text, size, "of %llu samples, v was clipped in %llu; |pred_error| exceeded "
             "monitor.pred_error_max = %g um in %llu (largest %.6g um)",
             (unsigned long long)c->k, (unsigned long long)c->n_saturated, c->pred_error_max,
             (unsigned long long)c->n_large_error, c->max_abs_pred_error);
    return 1;
}

int model_failure_text(const ModelData *data, piezo_status st, char *text, size_t size)
{
    const piezo_controller *c = &data->ctrl;
    if (st == PIEZO_ERR_UNSTABLE) {
        snprintf(text, size, "the closed loop is unstable: |pred_error| stayed above "
                 "monitor.pred_error_max = %g um for monitor.divergence_samples = %llu consecutive "
                 "samples (largest so far %.6g um). Usual causes: the controller's loop delay "
                 "d = 1 + mv.delay = %d does not match the loop (a master that hands the plant the "
                 "controller's post-step output removes a sample, as does mv.feedthrough; an extra "
                 "plant or actuation delay adds one), or the plant is far from the nominal model",
                 c->pred_error_max, (unsigned long long)c->divergence_samples,
                 c->max_abs_pred_error, c->d);
        return 1;
    }
    if (st == PIEZO_ERR_DIVERGED) {
        snprintf(text, size, "the closed loop diverged: a value computed by the controller is not "
                 "finite although its inputs are (d = 1 + mv.delay = %d; check it against the master "
                 "and the plant)", c->d);
        return 1;
    }
    return 0;
}

const char *model_check_data(const ModelData *data, int core_initialized, double t0, uint64_t k,
                             const double *history, size_t n_history)
{
    const piezo_controller *c = &data->ctrl;
    const piezo_controller_params *q = &data->params;
    piezo_controller scratch;
    const char *fault;
    (void)t0;           /* time-invariant: the controller keeps no time */
    if ((data->said_saturated != 0 && data->said_saturated != 1)
        || (data->said_large_error != 0 && data->said_large_error != 1))
        return "warning flags are not 0 or 1";
    if (!core_initialized)
        return NULL;    /* parameters are validated by model_init later */
    /* a live core runs on parameters that passed init ... */
    if (piezo_controller_init(&scratch, q, NULL) != PIEZO_OK)
        return "parameters out of range";
    if ((fault = piezo_controller_check(c)) != NULL)
        return fault;
    if (c->k != k)
        return "controller sample counter differs from the FMU's k";
    /* ... and on the copies init made of them */
    if (c->d != 1 + q->mv_delay || c->fwd_pi.m != q->pi.m || c->inv_creep.exact != (q->creep_exact ? 1 : 0)
        || c->inv_creep.alpha != -q->creep_alpha || c->lambda_u != q->mv_lambda_u
        || c->rls_enabled != (q->rls_enabled ? 1 : 0) || c->sat_enabled != (q->sat_enabled ? 1 : 0)
        || c->forgetting != q->rls_forgetting || c->p0 != q->rls_p0 || c->trace_max != q->rls_trace_max
        || c->pred_error_max != q->monitor_pred_error_max
        || c->divergence_samples != (uint64_t)q->monitor_divergence_samples
        || (c->sat_enabled && (c->sat_v_min != q->sat_v_min || c->sat_v_max != q->sat_v_max)))
        return "controller state does not match its parameters";
    return piezo_gl_check_history(&c->inv_creep, history, n_history);
}
