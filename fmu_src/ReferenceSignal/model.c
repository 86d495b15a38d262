/*
 * ReferenceSignal/model.c - the ReferenceSignal FMU's model: variable table,
 * start values and calls into the core (piezo_reference.h). Everything FMI
 * lives in the shared glue (fmu_src/fmi/: fmu_glue_core.c
 * shared by fmi2_glue.c and fmi3_glue.c), so this file serves both FMI versions.
 *
 * At t_k = t0 + k h the outputs are y_d(t_k), y_ref = y_d(t_(k+lead)), the
 * preview the controller's y_ref input needs (lead = its loop delay d), and
 * the stamped preview y_preview = y_d(t_preview), t_preview = t_(k+preview),
 * which the controller aligns with the loop delay it detects.
 * No inputs, so no feedthrough: any master order gives the same values.
 */
#include <stddef.h>
#include "fmu_model.h"

#define PARAM_REAL(name, field) { name, MODEL_REAL, MODEL_PARAMETER, offsetof(ModelData, params.field) }
#define OUTPUT_REAL(name, field) { name, MODEL_REAL, MODEL_OUTPUT, offsetof(ModelData, ref.field) }

const model_variable model_variables[MODEL_N_VARIABLES] = {
    [vr_y_d] = OUTPUT_REAL("y_d", y_d),
    [vr_y_ref] = OUTPUT_REAL("y_ref", y_ref),
    [vr_offset] = PARAM_REAL("offset", offset),
    [vr_amplitude1] = PARAM_REAL("amplitude[1]", amplitude[0]),
    [vr_amplitude2] = PARAM_REAL("amplitude[2]", amplitude[1]),
    [vr_amplitude3] = PARAM_REAL("amplitude[3]", amplitude[2]),
    [vr_amplitude4] = PARAM_REAL("amplitude[4]", amplitude[3]),
    [vr_amplitude5] = PARAM_REAL("amplitude[5]", amplitude[4]),
    [vr_amplitude6] = PARAM_REAL("amplitude[6]", amplitude[5]),
    [vr_amplitude7] = PARAM_REAL("amplitude[7]", amplitude[6]),
    [vr_amplitude8] = PARAM_REAL("amplitude[8]", amplitude[7]),
    [vr_frequency1] = PARAM_REAL("frequency[1]", frequency[0]),
    [vr_frequency2] = PARAM_REAL("frequency[2]", frequency[1]),
    [vr_frequency3] = PARAM_REAL("frequency[3]", frequency[2]),
    [vr_frequency4] = PARAM_REAL("frequency[4]", frequency[3]),
    [vr_frequency5] = PARAM_REAL("frequency[5]", frequency[4]),
    [vr_frequency6] = PARAM_REAL("frequency[6]", frequency[5]),
    [vr_frequency7] = PARAM_REAL("frequency[7]", frequency[6]),
    [vr_frequency8] = PARAM_REAL("frequency[8]", frequency[7]),
    [vr_phase1] = PARAM_REAL("phase[1]", phase[0]),
    [vr_phase2] = PARAM_REAL("phase[2]", phase[1]),
    [vr_phase3] = PARAM_REAL("phase[3]", phase[2]),
    [vr_phase4] = PARAM_REAL("phase[4]", phase[3]),
    [vr_phase5] = PARAM_REAL("phase[5]", phase[4]),
    [vr_phase6] = PARAM_REAL("phase[6]", phase[5]),
    [vr_phase7] = PARAM_REAL("phase[7]", phase[6]),
    [vr_phase8] = PARAM_REAL("phase[8]", phase[7]),
    [vr_lead] = { "lead", MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, params.lead) },
    [vr_h] = PARAM_REAL("h", h),
    [vr_y_preview] = OUTPUT_REAL("y_preview", y_preview),
    [vr_t_preview] = OUTPUT_REAL("t_preview", t_preview),
    [vr_preview] = { "preview", MODEL_INTEGER, MODEL_PARAMETER, offsetof(ModelData, params.preview) },
};

void model_set_start_values(ModelData *data)
{
    piezo_reference_default_params(&data->params);
}

piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag)
{
    return piezo_reference_init(&data->ref, &data->params, start_time, diag);
}

double model_sample_period(const ModelData *data)
{
    return data->params.h;
}

size_t model_history_needed(const ModelData *data)
{
    (void)data;
    return 0;
}

piezo_status model_step(ModelData *data, double *history, size_t history_capacity,
                        int outputs_current)
{
    (void)outputs_current;      /* no direct feedthrough: nothing evaluated ahead */
    (void)history;
    (void)history_capacity;
    return piezo_reference_step(&data->ref);
}

piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity)
{
    /* the outputs of sample k are already in ref */
    (void)data;
    (void)history;
    (void)history_capacity;
    return PIEZO_OK;
}

const char *model_check_data(const ModelData *data, int core_initialized, double t0, uint64_t k,
                             const double *history, size_t n_history)
{
    const char *fault;
    (void)history;
    if (n_history != 0)
        return "history stored for a model without history";
    if (!core_initialized)
        return NULL;    /* parameters are validated by model_init later */
    if ((fault = piezo_reference_check(&data->ref)) != NULL)
        return fault;
    return piezo_reference_check_params(&data->ref, &data->params, t0, k);
}
