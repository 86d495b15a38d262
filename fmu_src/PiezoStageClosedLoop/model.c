/*
 * PiezoStageClosedLoop/model.c - the PiezoStageClosedLoop FMU's model: the stage
 * (piezo_plant.h) under the adaptive compound controller (piezo_controller.h),
 * tracking the internal reference (piezo_reference.h) or the input y_d; the
 * loop of the three FMUs PiezoStage, AdaptiveCompoundController and
 * ReferenceSignal, in one FMU, from the same core. Everything FMI lives in the
 * shared glue (fmu_src/fmi/), so this file serves both FMI versions.
 *
 * One sample k (from t_k to t_(k+1)) is the sample of the three FMUs wired as
 * the closed-loop SSP wires them, in a master that exchanges values at
 * communication points: the controller gets the reference's y_ref(k), its
 * stamped preview y_preview(k) (counted from sample 1 on, as the controller FMU
 * counts a time stamp once it has advanced by h) and the stage's y_meas(k); the
 * stage applies the controller's v of sample k - 1 (with mv.feedthrough, that
 * of sample k, as under a Gauss-Seidel master that reads v after setting the
 * controller's inputs), clamped to its rated range as PiezoStage applies it.
 * The outputs at t_k are the three FMUs' outputs at t_k.
 *
 * The reference (docs/fmus.md): use_internal_reference = true (default) runs
 * ReferenceSignal's y_d(t) with its parameters (its lead and preview feed the
 * controller as above). false takes the input y_d, sampled at each sample's
 * instant t_k, as the desired displacement y_d_lead samples ahead,
 * y_d(t_k + y_d_lead h): the controller gets it as y_ref and as a preview of
 * lead y_d_lead, which it aligns with its loop delay d when y_d_lead >= d; with
 * a smaller y_d_lead (0 by default: the displacement now) the newest value
 * stands in for y_d(k + d), and the stage follows d - y_d_lead samples late.
 * The output reference is y_d(k): the input sampled y_d_lead samples before
 * (until then, and with y_d_lead = 0, the input sampled now).
 *
 * A communication step of any size (MODEL_HAS_ANY_STEP, fmu_model.h): the glue
 * computes the samples whose instants the step passes; a step that ends
 * between two instants holds the outputs of the last one and latches the y_d
 * of the next sample's instant (model_latch_inputs).
 *
 * A sample either commits in all three blocks or in none: the controller, the
 * stage and the reference are evaluated first, each of which may refuse it,
 * then committed (piezo_controller_commit may refuse it too, before anything
 * else is committed).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <stddef.h>
#include "fmu_model.h"

/* Table entries by where their name, range and description come from (the model
 * descriptions are generated from the components': packaging/closed_loop_description.py
 * reads these macro names). STAGE_*: PiezoStage's variable of that name; CTRL_*:
 * AdaptiveCompoundController's (without the "controller." of its nominal model's
 * names); REF_*: ReferenceSignal's; LOOP_*: this FMU's own. */
#define STAGE_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, stage.field) }
#define STAGE_INT(name, field) { name, MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, stage.field) }
#define STAGE_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_PARAMETER, offsetof(ModelData, stage.field) }
#define STAGE_OUT(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, plant.out.field) }
#define CTRL_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, control.field) }
#define CTRL_INT(name, field) { name, MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, control.field) }
#define CTRL_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_PARAMETER, offsetof(ModelData, control.field) }
#define CTRL_INPUT_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_INPUT, offsetof(ModelData, field) }
#define CTRL_OUT(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, ctrl.out.field) }
#define CTRL_OUT_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_OUTPUT, offsetof(ModelData, ctrl.out.field) }
#define CTRL_OUT_REAL(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, field) }
#define CTRL_OUT_INT(name, field) { name, MODEL_INTEGER, MODEL_OUTPUT, offsetof(ModelData, field) }
#define REF_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, ref_params.field) }
#define REF_INT(name, field) { name, MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, ref_params.field) }
#define LOOP_INPUT(name, field) { name, MODEL_REAL, MODEL_INPUT, offsetof(ModelData, field) }
#define LOOP_OUT(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, field) }
#define LOOP_OUT_INT(name, field) { name, MODEL_INTEGER, MODEL_OUTPUT, offsetof(ModelData, field) }
#define LOOP_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, field) }
#define LOOP_INT(name, field) { name, MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, field) }
#define LOOP_BOOL(name, field) { name, MODEL_BOOLEAN, MODEL_PARAMETER, offsetof(ModelData, field) }

/* the prefix of the controller's nominal model */
#define CONTROLLER_PREFIX "controller."

const model_variable model_variables[MODEL_N_VARIABLES] = {
    [vr_y_d] = LOOP_INPUT("y_d", y_d),
    [vr_y] = STAGE_OUT("y", y),
    [vr_y_meas] = STAGE_OUT("y_meas", y_meas),
    [vr_v] = LOOP_OUT("v", ctrl.out.v),
    [vr_reference] = LOOP_OUT("reference", reference),
    [vr_error] = LOOP_OUT("error", error),
    [vr_u] = STAGE_OUT("u", u),
    [vr_x] = STAGE_OUT("x", x),
    [vr_q] = CTRL_OUT("q", q),
    [vr_est_a1] = CTRL_OUT("est.a1", theta[0]),
    [vr_est_a2] = CTRL_OUT("est.a2", theta[1]),
    [vr_est_b1] = CTRL_OUT("est.b1", theta[2]),
    [vr_est_b2] = CTRL_OUT("est.b2", theta[3]),
    [vr_pred_error] = CTRL_OUT("pred_error", pred_error),
    [vr_saturated] = CTRL_OUT_BOOL("saturated", saturated),
    [vr_loop_delay] = CTRL_OUT_INT("loop_delay", loop_delay),
    [vr_loop_delay_time] = CTRL_OUT_REAL("loop_delay_time", loop_delay_time),
    [vr_preview_lead] = LOOP_OUT_INT("preview_lead", preview_lead),
    [vr_sup_status] = LOOP_OUT_INT("sup.status", sup_status),
    [vr_sup_gain] = CTRL_OUT_REAL("sup.gain", sup_gain),
    [vr_sup_delay] = CTRL_OUT_INT("sup.delay", sup_delay),
    [vr_use_internal_reference] = LOOP_BOOL("use_internal_reference", use_internal_reference),
    [vr_y_d_lead] = LOOP_INT("y_d_lead", y_d_lead),
    [vr_h] = LOOP_REAL("h", stage.h),
    [vr_pi_m] = STAGE_INT("pi.m", pi.m),
    [vr_pi_v_max] = STAGE_REAL("pi.v_max", pi.v_max),
    [vr_pi_w0] = STAGE_REAL("pi.w0", pi.w0),
    [vr_pi_w1] = STAGE_REAL("pi.w[1]", pi.w[0]),
    [vr_pi_w2] = STAGE_REAL("pi.w[2]", pi.w[1]),
    [vr_pi_w3] = STAGE_REAL("pi.w[3]", pi.w[2]),
    [vr_pi_w4] = STAGE_REAL("pi.w[4]", pi.w[3]),
    [vr_pi_w5] = STAGE_REAL("pi.w[5]", pi.w[4]),
    [vr_pi_w6] = STAGE_REAL("pi.w[6]", pi.w[5]),
    [vr_pi_w7] = STAGE_REAL("pi.w[7]", pi.w[6]),
    [vr_pi_w8] = STAGE_REAL("pi.w[8]", pi.w[7]),
    [vr_pi_w9] = STAGE_REAL("pi.w[9]", pi.w[8]),
    [vr_pi_w10] = STAGE_REAL("pi.w[10]", pi.w[9]),
    [vr_pi_w11] = STAGE_REAL("pi.w[11]", pi.w[10]),
    [vr_pi_w12] = STAGE_REAL("pi.w[12]", pi.w[11]),
    [vr_pi_w13] = STAGE_REAL("pi.w[13]", pi.w[12]),
    [vr_pi_w14] = STAGE_REAL("pi.w[14]", pi.w[13]),
    [vr_pi_w15] = STAGE_REAL("pi.w[15]", pi.w[14]),
    [vr_pi_w16] = STAGE_REAL("pi.w[16]", pi.w[15]),
    [vr_tf_a1] = STAGE_REAL("tf.a1", tf.a1),
    [vr_tf_a2] = STAGE_REAL("tf.a2", tf.a2),
    [vr_tf_b1] = STAGE_REAL("tf.b1", tf.b1),
    [vr_tf_b2] = STAGE_REAL("tf.b2", tf.b2),
    [vr_tf_delay] = STAGE_INT("tf.delay", tf.delay),
    [vr_creep_enabled] = STAGE_BOOL("creep.enabled", creep_enabled),
    [vr_creep_k_c] = STAGE_REAL("creep.k_c", creep_k_c),
    [vr_creep_alpha] = STAGE_REAL("creep.alpha", creep_alpha),
    [vr_creep_exact] = STAGE_BOOL("creep.exact", creep_exact),
    [vr_sensor_resolution] = STAGE_REAL("sensor.resolution", sensor_resolution),
    [vr_sensor_noise_rms] = STAGE_REAL("sensor.noise_rms", sensor_noise_rms),
    [vr_sensor_seed] = STAGE_INT("sensor.seed", sensor_seed),
    [vr_c_pi_m] = CTRL_INT("controller.pi.m", pi.m),
    [vr_c_pi_v_max] = CTRL_REAL("controller.pi.v_max", pi.v_max),
    [vr_c_pi_w0] = CTRL_REAL("controller.pi.w0", pi.w0),
    [vr_c_pi_w1] = CTRL_REAL("controller.pi.w[1]", pi.w[0]),
    [vr_c_pi_w2] = CTRL_REAL("controller.pi.w[2]", pi.w[1]),
    [vr_c_pi_w3] = CTRL_REAL("controller.pi.w[3]", pi.w[2]),
    [vr_c_pi_w4] = CTRL_REAL("controller.pi.w[4]", pi.w[3]),
    [vr_c_pi_w5] = CTRL_REAL("controller.pi.w[5]", pi.w[4]),
    [vr_c_pi_w6] = CTRL_REAL("controller.pi.w[6]", pi.w[5]),
    [vr_c_pi_w7] = CTRL_REAL("controller.pi.w[7]", pi.w[6]),
    [vr_c_pi_w8] = CTRL_REAL("controller.pi.w[8]", pi.w[7]),
    [vr_c_pi_w9] = CTRL_REAL("controller.pi.w[9]", pi.w[8]),
    [vr_c_pi_w10] = CTRL_REAL("controller.pi.w[10]", pi.w[9]),
    [vr_c_pi_w11] = CTRL_REAL("controller.pi.w[11]", pi.w[10]),
    [vr_c_pi_w12] = CTRL_REAL("controller.pi.w[12]", pi.w[11]),
    [vr_c_pi_w13] = CTRL_REAL("controller.pi.w[13]", pi.w[12]),
    [vr_c_pi_w14] = CTRL_REAL("controller.pi.w[14]", pi.w[13]),
    [vr_c_pi_w15] = CTRL_REAL("controller.pi.w[15]", pi.w[14]),
    [vr_c_pi_w16] = CTRL_REAL("controller.pi.w[16]", pi.w[15]),
    [vr_c_tf_a1] = CTRL_REAL("controller.tf.a1", tf_a1),
    [vr_c_tf_a2] = CTRL_REAL("controller.tf.a2", tf_a2),
    [vr_c_tf_b1] = CTRL_REAL("controller.tf.b1", tf_b1),
    [vr_c_tf_b2] = CTRL_REAL("controller.tf.b2", tf_b2),
    [vr_c_creep_k_c] = CTRL_REAL("controller.creep.k_c", creep_k_c),
    [vr_c_creep_alpha] = CTRL_REAL("controller.creep.alpha", creep_alpha),
    [vr_c_creep_exact] = CTRL_BOOL("controller.creep.exact", creep_exact),
    [vr_mv_delay] = CTRL_INT("mv.delay", mv_delay),
    [vr_mv_feedthrough] = CTRL_BOOL("mv.feedthrough", mv_feedthrough),
    [vr_mv_lambda_u] = CTRL_REAL("mv.lambda_u", mv_lambda_u),
    [vr_mv_observer] = CTRL_REAL("mv.observer", mv_observer),
    [vr_rls_enabled] = CTRL_BOOL("rls.enabled", rls_enabled),
    [vr_rls_forgetting] = CTRL_REAL("rls.forgetting", rls_forgetting),
    [vr_rls_p0] = CTRL_REAL("rls.p0", rls_p0),
    [vr_rls_trace_max] = CTRL_REAL("rls.trace_max", rls_trace_max),
    [vr_sat_enabled] = CTRL_BOOL("sat.enabled", sat_enabled),
    [vr_sat_v_min] = CTRL_REAL("sat.v_min", sat_v_min),
    [vr_sat_v_max] = CTRL_REAL("sat.v_max", sat_v_max),
    [vr_monitor_pred_error_max] = CTRL_REAL("monitor.pred_error_max", monitor_pred_error_max),
    [vr_monitor_divergence_samples] = CTRL_INT("monitor.divergence_samples", monitor_divergence_samples),
    [vr_sup_enabled] = CTRL_BOOL("sup.enabled", sup.enabled),
    [vr_sup_gain_min] = CTRL_REAL("sup.gain_min", sup.gain_min),
    [vr_sup_gain_max] = CTRL_REAL("sup.gain_max", sup.gain_max),
    [vr_sup_window] = CTRL_INT("sup.window", sup.window),
    [vr_sup_clip_time] = CTRL_REAL("sup.clip_time", sup.clip_time),
    [vr_sup_detect_time] = CTRL_REAL("sup.detect_time", sup.detect_time),
    [vr_offset] = REF_REAL("offset", offset),
    [vr_amplitude1] = REF_REAL("amplitude[1]", amplitude[0]),
    [vr_amplitude2] = REF_REAL("amplitude[2]", amplitude[1]),
    [vr_amplitude3] = REF_REAL("amplitude[3]", amplitude[2]),
    [vr_amplitude4] = REF_REAL("amplitude[4]", amplitude[3]),
    [vr_amplitude5] = REF_REAL("amplitude[5]", amplitude[4]),
    [vr_amplitude6] = REF_REAL("amplitude[6]", amplitude[5]),
    [vr_amplitude7] = REF_REAL("amplitude[7]", amplitude[6]),
    [vr_amplitude8] = REF_REAL("amplitude[8]", amplitude[7]),
    [vr_frequency1] = REF_REAL("frequency[1]", frequency[0]),
    [vr_frequency2] = REF_REAL("frequency[2]", frequency[1]),
    [vr_frequency3] = REF_REAL("frequency[3]", frequency[2]),
    [vr_frequency4] = REF_REAL("frequency[4]", frequency[3]),
    [vr_frequency5] = REF_REAL("frequency[5]", frequency[4]),
    [vr_frequency6] = REF_REAL("frequency[6]", frequency[5]),
    [vr_frequency7] = REF_REAL("frequency[7]", frequency[6]),
    [vr_frequency8] = REF_REAL("frequency[8]", frequency[7]),
    [vr_phase1] = REF_REAL("phase[1]", phase[0]),
    [vr_phase2] = REF_REAL("phase[2]", phase[1]),
    [vr_phase3] = REF_REAL("phase[3]", phase[2]),
    [vr_phase4] = REF_REAL("phase[4]", phase[3]),
    [vr_phase5] = REF_REAL("phase[5]", phase[4]),
    [vr_phase6] = REF_REAL("phase[6]", phase[5]),
    [vr_phase7] = REF_REAL("phase[7]", phase[6]),
    [vr_phase8] = REF_REAL("phase[8]", phase[7]),
    [vr_lead] = REF_INT("lead", lead),
    [vr_preview] = REF_INT("preview", preview),
    [vr_rls_robust] = CTRL_BOOL("rls.robust", rls_robust),
    [vr_rls_excitation] = CTRL_REAL("rls.excitation", rls_excitation),
    [vr_rls_excitation_time] = CTRL_REAL("rls.excitation_time", rls_excitation_time),
    [vr_rls_variance_max] = CTRL_REAL("rls.variance_max", rls_variance_max),
    [vr_rls_p0_loop] = CTRL_REAL("rls.p0_loop", rls_p0_loop),
    [vr_mv_integral] = CTRL_REAL("mv.integral", mv_integral),
    [vr_est_adapting] = CTRL_OUT_BOOL("est.adapting", adapting),
    [vr_est_noise] = CTRL_OUT("est.noise", noise),
    [vr_sup_reaction] = CTRL_INT("sup.reaction", sup.reaction),
    [vr_sup_ramp_time] = CTRL_REAL("sup.ramp_time", sup.ramp_time),
    [vr_sup_clip_error] = CTRL_REAL("sup.clip_error", sup.clip_error),
    [vr_mv_probe_max] = CTRL_REAL("mv.probe_max", mv_probe_max),
    [vr_sup_fault] = CTRL_OUT_INT("sup.fault", sup_fault),
    [vr_sup_fault_time] = CTRL_OUT_REAL("sup.fault_time", sup_fault_time),
    [vr_rls_zero_min] = CTRL_REAL("rls.zero_min", rls_zero_min),
    [vr_rls_pole_min] = CTRL_REAL("rls.pole_min", rls_pole_min),
    [vr_rls_fallback_ratio] = CTRL_REAL("rls.fallback_ratio", rls_fallback_ratio),
    [vr_rls_fallback_window] = CTRL_REAL("rls.fallback_window", rls_fallback_window),
    [vr_est_fallbacks] = CTRL_OUT_INT("est.fallbacks", fallbacks),
    [vr_sup_reset] = CTRL_INPUT_BOOL("sup.reset", sup_reset),
};

/* ModelData.refused_by: which block refused the last refused sample (for its message), or
 * REFUSED_ERROR: the outputs' error = reference - y overflowed */
enum { REFUSED_NONE = 0, REFUSED_CONTROLLER, REFUSED_STAGE, REFUSED_REFERENCE, REFUSED_ERROR };

/* A refusal: nothing of the loop changed; only what says why (as the controller's verdict). */
static piezo_status refused(ModelData *data, int block, piezo_status st)
{
    data->refused_by = block;
    return st;
}

/* A refusal in model_step: sup.reset's restart at this sample undone too */
static piezo_status refused_undo(ModelData *data, const fmu_controller_reset_backup *undo, int block,
                                 piezo_status st)
{
    fmu_controller_reset_undo(undo, &data->track, &data->ctrl);
    return refused(data, block, st);
}

void model_set_start_values(ModelData *data)
{
    piezo_plant_default_params(&data->stage);
    piezo_controller_default_params(&data->control);
    piezo_reference_default_params(&data->ref_params);
    data->use_internal_reference = 1;
    data->y_d_lead = 0;
    data->y_d = 0.0;
    data->sup_reset = 0;
}

/* t_k of the model's own t0 and h (fmu_sample_time, as the glue) */
static double sample_time(const ModelData *data, uint64_t k)
{
    return fmu_sample_time(data->t0, k, data->stage.h);
}

static int stage_exact(const ModelData *data)
{
    return data->stage.creep_enabled && data->stage.creep_exact;
}

/* The controller's refusal of a parameter of its nominal model, under this FMU's name. */
static void controller_name(piezo_diag *diag)
{
    size_t n = sizeof CONTROLLER_PREFIX - 1;
    int vr;
    if (diag == NULL || diag->parameter == NULL)
        return;
    for (vr = vr_c_pi_m; vr <= vr_c_creep_exact; vr++)
        if (strcmp(model_variables[vr].name + n, diag->parameter) == 0) {
            diag->parameter = model_variables[vr].name;
            return;
        }
}

piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag)
{
    piezo_status st;
    /* one sample period for the loop */
    data->control.h = data->ref_params.h = data->stage.h;
    data->control.mv_hold_inputs = 0;
    if (data->y_d_lead < 0 || data->y_d_lead > CLOSED_LOOP_MAX_LEAD)
        return piezo_refuse(diag, "y_d_lead", "0..15 samples (the controller keeps up to 15 samples of "
                            "preview)", (double)data->y_d_lead);
    st = piezo_plant_init(&data->plant, &data->stage, diag);
    if (st != PIEZO_OK)
        return st;
    st = piezo_controller_init(&data->ctrl, &data->control, diag);
    if (st != PIEZO_OK) {
        controller_name(diag);
        return st;
    }
    /* one FMU keeps one exact-mode history (fmu_model.h), so one block at most sums all of it */
    if (stage_exact(data) && data->control.creep_exact)
        return piezo_refuse(diag, "controller.creep.exact", "false while the stage's creep.exact is true "
                            "(one exact-mode history per FMU: the stage's or the controller's)", 1.0);
    st = piezo_reference_init(&data->ref, &data->ref_params, start_time, diag);
    if (st != PIEZO_OK)
        return st;
    data->t0 = start_time;
    data->y_d_latched = 0.0;
    data->latched = 0;
    fmu_controller_track_init(&data->track, &data->ctrl, start_time);
    data->lead_used = 0;
    data->n_clamped = 0;
    data->k_first_clamped = 0;
    data->v_first_clamped = 0.0;
    data->said_clamped = 0;
    data->said_preview = 0;
    data->refused_by = REFUSED_NONE;
    return PIEZO_OK;
}

double model_sample_period(const ModelData *data)
{
    return data->stage.h;
}

size_t model_history_needed(const ModelData *data)
{
    return stage_exact(data) ? piezo_plant_history_needed(&data->plant)
                             : piezo_controller_history_needed(&data->ctrl);
}

void model_latch_inputs(ModelData *data)
{
    data->y_d_latched = data->y_d;
    data->latched = 1;
}

/* The input y_d of the current sample: the value held at its instant. */
static double sampled_y_d(const ModelData *data)
{
    return data->latched ? data->y_d_latched : data->y_d;
}

/* The lead of the preview the controller gets (0: none), by the rules of the file's comment. */
static int preview_lead(const ModelData *data)
{
    int lead = data->use_internal_reference ? data->ref_params.preview : data->y_d_lead;
    if (lead < 1 || lead >= PIEZO_PREVIEW_RING)
        return 0;
    /* the controller FMU counts ReferenceSignal's time stamp once it advanced, from sample 1 on */
    return data->use_internal_reference && data->ctrl.k == 0 ? 0 : lead;
}

piezo_status model_step(ModelData *data, double *history, size_t history_capacity,
                        int outputs_current)
{
    piezo_controller_input in;
    piezo_controller_sample cs;
    piezo_plant_sample ps;
    piezo_reference ref = data->ref;
    fmu_controller_reset_backup undo;   /* a refused sample commits nothing, sup.reset's restart included */
    int exact = stage_exact(data);
    double v, v_applied;
    piezo_status st;
    (void)outputs_current;      /* no direct feedthrough: nothing evaluated ahead */
    /* the inputs of sample k, as the three FMUs' exchange at t_k gives them */
    in.y_meas = data->plant.out.y_meas;
    if (data->use_internal_reference) {
        in.y_ref = data->ref.y_ref;
        in.y_preview = data->ref.y_preview;
    } else {
        in.y_ref = in.y_preview = sampled_y_d(data);
    }
    in.preview_lead = preview_lead(data);
    fmu_controller_reset_keep(&undo, &data->track, &data->ctrl, data->sup_reset);
    fmu_controller_reset_input(&data->track, &data->ctrl, data->sup_reset, &in);
    st = piezo_controller_evaluate(&data->ctrl, &in, exact ? NULL : history, exact ? 0 : history_capacity, &cs);
    if (st != PIEZO_OK)
        return refused_undo(data, &undo, REFUSED_CONTROLLER, st);
    /* the stage applies the controller's v of the sample before (with mv.feedthrough: this
     * sample's), clamped to its rated range as PiezoStage applies it */
    v = data->control.mv_feedthrough ? cs.out.v : data->ctrl.out.v;
    v_applied = piezo_plant_rated_voltage(v);
    st = piezo_plant_evaluate(&data->plant, v_applied, exact ? history : NULL,
                              exact ? history_capacity : 0, &ps);
    if (st != PIEZO_OK)
        return refused_undo(data, &undo, REFUSED_STAGE, st);
    if (data->use_internal_reference) {
        st = piezo_reference_step(&ref);
        if (st != PIEZO_OK)
            return refused_undo(data, &undo, REFUSED_REFERENCE, st);
    }
    /* everything evaluated: the controller's commit is the last that may refuse */
    st = piezo_controller_commit(&data->ctrl, &cs, NULL);
    if (st != PIEZO_OK)
        return refused_undo(data, &undo, REFUSED_CONTROLLER, st);
    piezo_plant_commit(&data->plant, &ps);
    if (data->use_internal_reference)
        data->ref = ref;
    if (v != v_applied) {
        if (data->n_clamped == 0) {
            data->k_first_clamped = ps.k;
            data->v_first_clamped = v;
        }
        data->n_clamped += 1;
    }
    data->latched = 0;
    data->lead_used = data->ctrl.out.preview ? in.preview_lead : 0;
    fmu_controller_track_commit(&data->track, &data->ctrl, data->t0, data->stage.h);
    return PIEZO_OK;
}

piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity)
{
    double r;
    (void)history;
    (void)history_capacity;
    if (data->use_internal_reference)
        r = data->ref.y_d;
    else if (!piezo_controller_preview(&data->ctrl, data->ctrl.k, &r))
        r = sampled_y_d(data);      /* y_d_lead = 0, or fewer than y_d_lead samples so far */
    data->reference = r;
    data->error = r - data->plant.out.y;
    if (!isfinite(data->error))      /* both finite, but |r - y| beyond the doubles */
        return refused(data, REFUSED_ERROR, PIEZO_ERR_DIVERGED);
    data->loop_delay = data->track.delay;
    data->loop_delay_time = data->track.delay_time;
    data->preview_lead = data->lead_used;
    /* the supervision as of the last committed sample; 2 once the preview was found misaligned */
    data->sup_status = data->said_preview ? 2 : data->ctrl.sup.status;
    data->sup_gain = data->ctrl.sup.gain;
    data->sup_delay = data->ctrl.sup.delay;
    fmu_controller_fault_outputs(&data->ctrl, data->t0, data->stage.h, &data->sup_fault, &data->sup_fault_time);
    data->fallbacks = fmu_controller_fallbacks(&data->ctrl);
    return PIEZO_OK;
}

/* Once the loop delay d is chosen: whether the controller gets y_d(k + d). Internal: from
 * the preview when d <= preview < 16, or y_ref when lead = d. External: from the preview
 * when d <= y_d_lead (y_ref, the newest value, is y_d(k + d) only when y_d_lead = d). */
static int preview_warning(ModelData *data, char *text, size_t size)
{
    int d = data->track.delay;
    double h = data->stage.h;
    if (data->said_preview || d == 0)
        return 0;
    if (data->use_internal_reference) {
        int p = data->ref_params.preview, lead = data->ref_params.lead;
        if ((p >= d && p < PIEZO_PREVIEW_RING) || lead == d)
            return 0;
        data->said_preview = 1;
        snprintf(text, size, "the loop delay is d = %d, but neither the preview (preview = %d: it is used "
                 "when d <= preview <= %d) nor y_ref (lead = %d) gives the controller y_d(k + d): the stage "
                 "follows the reference %d sample%s off (about sqrt(2) pi f A h rms per sample and tone). "
                 "Set preview = 4 (the default) or lead = %d", d, p, PIEZO_PREVIEW_RING - 1, lead,
                 abs(lead - d), abs(lead - d) == 1 ? "" : "s", d);
        return 1;
    }
    if (data->y_d_lead >= d)
        return 0;
    data->said_preview = 1;
    snprintf(text, size, "the loop delay is d = %d, but the input y_d leads the stage's time by y_d_lead = %d "
             "sample%s only: the controller takes the newest y_d for y_d(k + d), so the stage follows y_d %d "
             "sample%s (%.9g s) late (about sqrt(2) pi f A %g s rms per tone). Give y_d ahead of time and set "
             "y_d_lead to that many samples, %d to %d", d, data->y_d_lead, data->y_d_lead == 1 ? "" : "s",
             d - data->y_d_lead, d - data->y_d_lead == 1 ? "" : "s", (d - data->y_d_lead) * h,
             (d - data->y_d_lead) * h, d, CLOSED_LOOP_MAX_LEAD);
    return 1;
}

/* Where this controller's loop is, for its messages: inside this FMU (its parameters are
 * named, the stage's against the controller's model's), from t0. */
static piezo_sup_context context(const ModelData *data)
{
    piezo_sup_context ctx;
    memset(&ctx, 0, sizeof ctx);
    ctx.t0 = data->t0;
    ctx.h = data->stage.h;
    ctx.internal = 1;
    ctx.stage_delay = data->stage.tf.delay;
    ctx.feedthrough = data->control.mv_feedthrough;
    return ctx;
}

int model_step_warning(ModelData *data, double start_time, char *text, size_t size)
{
    piezo_sup_context ctx = context(data);
    (void)start_time;   /* data->t0 is the same */
    if (fmu_controller_warning(&data->track, &data->ctrl, &ctx, text, size))
        return 1;
    if (data->n_clamped > 0 && !data->said_clamped) {
        double applied = piezo_plant_rated_voltage(data->v_first_clamped);
        data->said_clamped = 1;
        snprintf(text, size, "the controller's v = %.16g V is outside the stage's rated range [%d, %d] V: the "
                 "stage applies %g V (clamped: the amplifier cannot deliver more), first at t = %.9g s; further "
                 "clamped samples are counted, not logged: the terminate call reports the count",
                 data->v_first_clamped, -PIEZO_PLANT_V_RATED, PIEZO_PLANT_V_RATED, applied,
                 sample_time(data, data->k_first_clamped));
        return 1;
    }
    return preview_warning(data, text, size);
}

int model_step_event(ModelData *data, char *text, size_t size)
{
    return fmu_controller_event(&data->track, &data->ctrl, data->t0, data->stage.h, text, size);
}

int model_terminate_warning(const ModelData *data, char *text, size_t size)
{
    int used = 0;
    if (fmu_controller_summary(&data->ctrl, text, size)) {
        used = (int)strlen(text);
        if (data->n_clamped == 0)
            return 1;
        if ((size_t)used + 2 < size) {
            strcpy(text + used, "; ");
            used += 2;
        }
    } else if (data->n_clamped == 0) {
        return 0;
    }
    if ((size_t)used < size)
        snprintf(text + used, size - (size_t)used, "the stage's v was clamped to its rated range [%d, %d] V in "
                 "%llu of %llu samples (the first v = %.16g V)", -PIEZO_PLANT_V_RATED, PIEZO_PLANT_V_RATED,
                 (unsigned long long)data->n_clamped, (unsigned long long)data->plant.k, data->v_first_clamped);
    return 1;
}

int model_failure_text(const ModelData *data, piezo_status st, char *text, size_t size)
{
    if (data->refused_by == REFUSED_CONTROLLER) {
        piezo_sup_context ctx = context(data);
        return fmu_controller_failure(&data->ctrl, &ctx, st, text, size);
    }
    if (data->refused_by == REFUSED_STAGE && st == PIEZO_ERR_DIVERGED) {
        snprintf(text, size, "the stage diverged: a value its model computed is not finite although v is "
                 "(v within [%d, %d] V: the stage's parameters, e.g. pi.w0 or tf.b1, make it overflow)",
                 -PIEZO_PLANT_V_RATED, PIEZO_PLANT_V_RATED);
        return 1;
    }
    if (data->refused_by == REFUSED_ERROR) {
        snprintf(text, size, "the tracking error reference - y = %.6g - (%.6g) um is beyond the doubles: "
                 "the outputs cannot be given (an input y_d of that size is no displacement)",
                 data->reference, data->plant.out.y);
        return 1;
    }
    if (data->refused_by == REFUSED_REFERENCE && st == PIEZO_ERR_DIVERGED) {
        snprintf(text, size, "the reference's time or the phase 2 pi frequency[i] t of a tone overflowed: "
                 "y_d(t) cannot be computed at t = %.9g s", sample_time(data, data->ctrl.k + 1));
        return 1;
    }
    return 0;
}

const char *model_check_data(const ModelData *data, int core_initialized, double t0, uint64_t k,
                             const double *history, size_t n_history)
{
    const char *fault;
    if ((fault = fmu_controller_track_check(&data->track, core_initialized, t0, k, data->stage.h)) != NULL)
        return fault;
    if ((data->latched != 0 && data->latched != 1) || (data->said_clamped != 0 && data->said_clamped != 1)
        || (data->said_preview != 0 && data->said_preview != 1))
        return "flags are not 0 or 1";
    if (!(isfinite(data->t0) && isfinite(data->y_d_latched)))
        return "time or latched input not finite";
    if (data->refused_by < REFUSED_NONE || data->refused_by > REFUSED_ERROR)
        return "refusing block out of range";
    if (data->lead_used < 0 || data->lead_used >= PIEZO_PREVIEW_RING || data->preview_lead < 0
        || data->preview_lead >= PIEZO_PREVIEW_RING || data->loop_delay < 0 || data->loop_delay > PIEZO_MV_MAX_D
        || data->sup_status < 0 || data->sup_status > 2 || data->sup_delay < 0 || data->sup_delay > PIEZO_MV_MAX_D
        || !isfinite(data->sup_gain) || data->sup_fault < 0 || data->sup_fault > PIEZO_SUP_FAULT_MAX
        || !isfinite(data->sup_fault_time) || data->fallbacks < 0)
        return "outputs out of range";
    if (data->control.mv_hold_inputs != 0)
        return "mv.hold_inputs set (this FMU has no such parameter)";
    if (data->n_clamped == 0 ? data->k_first_clamped != 0 || data->v_first_clamped != 0.0 || data->said_clamped
                             : data->n_clamped > k || data->k_first_clamped > k - data->n_clamped
                                   || !isfinite(data->v_first_clamped)
                                   || data->v_first_clamped == piezo_plant_rated_voltage(data->v_first_clamped))
        return "clamp counters out of range";
    if (!core_initialized)
        return NULL;    /* parameters are validated by model_init later */
    if (data->control.h != data->stage.h || data->ref_params.h != data->stage.h || data->t0 != t0)
        return "the blocks' sample periods or start time differ";
    if (data->y_d_lead < 0 || data->y_d_lead > CLOSED_LOOP_MAX_LEAD)
        return "y_d_lead out of range";
    if (stage_exact(data) && data->control.creep_exact)
        return "both creep operators exact";
    if ((fault = piezo_plant_check(&data->plant)) != NULL || (fault = piezo_controller_check(&data->ctrl)) != NULL
        || (fault = piezo_reference_check(&data->ref)) != NULL)
        return fault;
    if (data->plant.k != k || data->ctrl.k != k)
        return "sample counters differ from the FMU's k";
    if (data->track.said_fault && !data->ctrl.fault)
        return "the safe state's warning said without a safe state";
    if ((fault = piezo_plant_check_params(&data->plant, &data->stage)) != NULL
        || (fault = piezo_controller_check_params(&data->ctrl, &data->control)) != NULL
        || (fault = piezo_reference_check_params(&data->ref, &data->ref_params, t0,
                                                 data->use_internal_reference ? k : 0)) != NULL)
        return fault;
    return stage_exact(data) ? piezo_gl_check_history(&data->plant.creep, history, n_history)
                             : piezo_gl_check_history(&data->ctrl.inv_creep, history, n_history);
}
