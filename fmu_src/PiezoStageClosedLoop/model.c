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

/* The table is generated from variables.toml, which composes the components' declarations
 * (packaging/fmu_interface.py). The prefix of the controller's nominal model's names there: */
#define CONTROLLER_PREFIX "controller."

const model_variable model_variables[MODEL_N_VARIABLES] = { MODEL_VARIABLE_TABLE };

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
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++)
        if (strncmp(model_variables[vr].name, CONTROLLER_PREFIX, n) == 0
            && strcmp(model_variables[vr].name + n, diag->parameter) == 0) {
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
    piezo_sup_context ctx = fmu_controller_context(data->t0, data->stage.h);
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
