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


const model_variable model_variables[MODEL_N_VARIABLES] = { MODEL_VARIABLE_TABLE };

void model_set_start_values(ModelData *data)
{
    piezo_reference_default_params(&data->params);
}

piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag)
{
    return piezo_reference_init(&data->ref, &data->params, start_time, diag);
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
