/*
 * PiezoStage/model.c - the PiezoStage FMU's model: variable table, start
 * values and calls into the core plant (piezo_plant.h). Everything FMI lives
 * in the shared glue (fmu_src/fmi/: fmu_glue_core.c
 * shared by fmi2_glue.c and fmi3_glue.c), so this file serves both FMI versions.
 *
 * Semantics: at t_k = t0 + k h the outputs are plant.out (u(k-1), x(k), y(k),
 * y_meas(k)); one model_step applies the held v as v(k) and advances to k+1.
 *
 * Input range: v is declared [PIEZOSTAGE_V_MIN, PIEZOSTAGE_V_MAX] = [-150, 150] V,
 * the stage's rated range. The FMI lets a master pass a value outside min/max
 * (a solver's iterate, a controller without limits) and asks the FMU to cope;
 * an amplifier cannot deliver more than its rating, so the stage applies
 *     v_applied(k) = min(max(v(k), V_MIN), V_MAX)
 * and counts those samples: the first is a warning, the count is reported at
 * terminate (like the controller's voltage limits). The held v reads back as set.
 */
#include <math.h>
#include <stdio.h>
#include <stddef.h>
#include "fmu_model.h"


const model_variable model_variables[MODEL_N_VARIABLES] = { MODEL_VARIABLE_TABLE };

void model_set_start_values(ModelData *data)
{
    piezo_plant_default_params(&data->params);
    data->v = 0.0;
    data->t0 = data->t_meas = 0.0;
}

/* t_k of the model's own t0 and h (fmu_sample_time, as the glue) */
static double sample_time(const ModelData *data, uint64_t k)
{
    return fmu_sample_time(data->t0, k, data->params.h);
}

piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag)
{
    /* time-invariant: the plant starts at rest whatever t0; t0 only stamps the outputs */
    data->t0 = start_time;
    data->t_meas = start_time;
    data->n_clamped = 0;
    data->k_first_clamped = 0;
    data->v_first_clamped = 0.0;
    data->said_clamped = 0;
    return piezo_plant_init(&data->plant, &data->params, diag);
}

size_t model_history_needed(const ModelData *data)
{
    return piezo_plant_history_needed(&data->plant);
}

piezo_status model_step(ModelData *data, double *history, size_t history_capacity,
                        int outputs_current)
{
    /* v_applied = min(max(v, V_MIN), V_MAX); v is finite (a NaN or Inf is refused when set) */
    double v = piezo_plant_rated_voltage(data->v);
    uint64_t k = data->plant.k;
    piezo_status st;
    (void)outputs_current;      /* no direct feedthrough: nothing evaluated ahead */
    st = piezo_plant_step(&data->plant, v, history, history_capacity, NULL);
    if (st == PIEZO_OK && v != data->v) {   /* counted once the sample is committed */
        if (data->n_clamped == 0) {
            data->k_first_clamped = k;
            data->v_first_clamped = data->v;
        }
        data->n_clamped += 1;
    }
    data->t_meas = sample_time(data, data->plant.k);
    return st;
}

piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity)
{
    /* No direct feedthrough: the outputs of sample k are already in plant.out. */
    (void)data;
    (void)history;
    (void)history_capacity;
    return PIEZO_OK;
}

int model_step_warning(ModelData *data, double start_time, char *text, size_t size)
{
    if (data->n_clamped > 0 && !data->said_clamped) {
        double applied = data->v_first_clamped < PIEZOSTAGE_V_MIN ? PIEZOSTAGE_V_MIN : PIEZOSTAGE_V_MAX;
        data->said_clamped = 1;
        snprintf(text, size, "v = %.16g V is outside its declared range [%g, %g] V: the stage applies %g V "
                 "(clamped: the amplifier cannot deliver more), first at t = %.9g s; further clamped samples "
                 "are counted, not logged: the terminate call reports the count", data->v_first_clamped,
                 PIEZOSTAGE_V_MIN, PIEZOSTAGE_V_MAX, applied,
                 start_time + (double)data->k_first_clamped * data->params.h);
        return 1;
    }
    return 0;
}

int model_terminate_warning(const ModelData *data, char *text, size_t size)
{
    if (data->n_clamped == 0)
        return 0;
    snprintf(text, size, "v was clamped to its declared range [%g, %g] V in %llu of %llu samples (the first "
             "held v = %.16g V)", PIEZOSTAGE_V_MIN, PIEZOSTAGE_V_MAX, (unsigned long long)data->n_clamped,
             (unsigned long long)data->plant.k, data->v_first_clamped);
    return 1;
}

int model_failure_text(const ModelData *data, piezo_status st, char *text, size_t size)
{
    (void)data; (void)st; (void)text; (void)size;
    return 0;           /* the glue's generic texts say it */
}

const char *model_check_data(const ModelData *data, int core_initialized, double t0, uint64_t k,
                             const double *history, size_t n_history)
{
    const piezo_plant *p = &data->plant;
    const piezo_plant_params *q = &data->params;
    const char *fault;
    /* the clamp counters: as model_init leaves them, or counting committed samples */
    if (data->said_clamped != 0 && data->said_clamped != 1)
        return "clamp warning flag is not 0 or 1";
    if (data->n_clamped == 0 ? data->k_first_clamped != 0 || data->v_first_clamped != 0.0 || data->said_clamped
                             : data->n_clamped > k || data->k_first_clamped > k - data->n_clamped
                                   || !isfinite(data->v_first_clamped)
                                   || (data->v_first_clamped >= PIEZOSTAGE_V_MIN
                                       && data->v_first_clamped <= PIEZOSTAGE_V_MAX))
        return "clamp counters out of range";
    if (!core_initialized)
        return NULL;    /* parameters are validated by model_init later */
    if ((fault = piezo_plant_check(p)) != NULL)
        return fault;
    if (p->k != k)
        return "plant sample counter differs from the FMU's k";
    if (data->t0 != t0 || data->t_meas != sample_time(data, k))
        return "time stamp t_meas differs from t0 + k h";
    /* a live core runs on parameters that passed init, and on the copies init made of them */
    if ((fault = piezo_plant_check_params(p, q)) != NULL)
        return fault;
    if (!p->creep_enabled)
        return n_history == 0 ? NULL : "history stored while creep is disabled";
    return piezo_gl_check_history(&p->creep, history, n_history);
}
