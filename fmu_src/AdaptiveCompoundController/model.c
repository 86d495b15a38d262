/*
 * AdaptiveCompoundController/model.c - the controller FMU's model: variable
 * table, start values and calls into the core controller (piezo_controller.h).
 * Everything FMI lives in the shared glue (fmu_src/fmi/fmi2_glue.c).
 *
 * Direct feedthrough: the outputs of sample k are piezo_controller_peek with
 * the held inputs (y_ref = y_d(k+d), y_meas(k)); nothing is committed until
 * model_step (piezo_controller_step with the same inputs).
 */
#include <stddef.h>
#include "fmu_model.h"

#define PARAM_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define PARAM_INT(name, field) { name, MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define PARAM_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define OUTPUT_REAL(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, out.field) }

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
    [vr_mv_lambda_u] = PARAM_REAL("mv.lambda_u", mv_lambda_u),
    [vr_rls_enabled] = PARAM_BOOL("rls.enabled", rls_enabled),
    [vr_rls_forgetting] = PARAM_REAL("rls.forgetting", rls_forgetting),
    [vr_rls_p0] = PARAM_REAL("rls.p0", rls_p0),
    [vr_rls_trace_max] = PARAM_REAL("rls.trace_max", rls_trace_max),
    [vr_sat_enabled] = PARAM_BOOL("sat.enabled", sat_enabled),
    [vr_sat_v_min] = PARAM_REAL("sat.v_min", sat_v_min),
    [vr_sat_v_max] = PARAM_REAL("sat.v_max", sat_v_max),
};

void model_set_start_values(ModelData *data)
{
    piezo_controller_default_params(&data->params);
    data->y_ref = 0.0;
    data->y_meas = 0.0;
}

piezo_status model_init(ModelData *data, piezo_diag *diag)
{
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

piezo_status model_step(ModelData *data, double *history, size_t history_capacity)
{
    return piezo_controller_step(&data->ctrl, data->y_ref, data->y_meas,
                                 history, history_capacity, NULL);
}

piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity)
{
    return piezo_controller_peek(&data->ctrl, data->y_ref, data->y_meas,
                                 history, history_capacity, &data->out);
}

const char *model_check_data(const ModelData *data, int core_initialized)
{
    const piezo_controller *c = &data->ctrl;
    if (!core_initialized)
        return NULL;    /* parameters are validated by model_init later */
    if (c->fwd_pi.m < 1 || c->fwd_pi.m > PIEZO_PI_MAX_OPERATORS)
        return "ctrl.fwd_pi.m out of range";
    if (c->inv_pi.m < 1 || c->inv_pi.m > PIEZO_PI_MAX_OPERATORS)
        return "ctrl.inv_pi.m out of range";
    if (c->inv_creep.head < 0 || c->inv_creep.head >= PIEZO_GL_HEAD_LEN)
        return "ctrl.inv_creep.head out of range";
    if (c->inv_creep.n_terms < 0 || c->inv_creep.n_terms > PIEZO_GL_MAX_TERMS)
        return "ctrl.inv_creep.n_terms out of range";
    if (c->inv_creep.exact != 0 && c->inv_creep.exact != 1)
        return "ctrl.inv_creep.exact is not a boolean";
    if (c->d < 1 || c->d > PIEZO_MV_MAX_D)
        return "ctrl.d out of range";
    if (c->head < 0 || c->head >= PIEZO_MV_Q_RING)
        return "ctrl.head out of range";
    return NULL;
}
