/*
 * host.h - the host layer every C test suite of tests/c/ includes: each suite
 * is written once and compiled once per FMI version (-DFMI_VERSION=2 or 3, the
 * way the Reference FMUs build one model per version), and this header gives
 * it the names without the version:
 *
 *   host_fmu, host_inst        an FMU (description, binary, f->api: the
 *                              version's functions) and one instance of it
 *   host_status, HOST_OK ...   the version's status, Boolean, Integer, FMU state
 *   host_load ... host_real_outputs   the adapter's operations (host_fmi2.h,
 *                              host_fmi3.h; what they do alike is written
 *                              once, host_adapter.h), host_find and host_named
 *                              (host_common.h), and the helpers below
 *   BY_VERSION(a2, a3)         a2 in the FMI 2.0 build, a3 in the FMI 3.0 one:
 *                              the words and values that differ between them
 *   FMI_NAME("DoStep")         "fmi2DoStep" or "fmi3DoStep"
 *
 * What a suite does with one version only (FMI 3.0 arrays, nValues, the
 * functions FMI 2.0 lacks) stands under #if FMI_VERSION == 3 in the suite; a
 * suite may include the other version's adapter too (the cross-edition checks).
 *
 * The hosts take their FMUs as pairs of arguments: MODEL.xml BINARY.so (the
 * unzipped FMU's files, or the build's).
 */
#ifndef HOST_H
#define HOST_H

#if !defined(FMI_VERSION)
#error "compile the suite with -DFMI_VERSION=2 or -DFMI_VERSION=3"
#elif FMI_VERSION == 2

#include "host_fmi2.h"
#define BY_VERSION(fmi2, fmi3) fmi2

typedef host2_fmu host_fmu;
typedef host2_inst host_inst;
typedef fmi2Status host_status;
typedef fmi2Boolean host_bool;
typedef fmi2Integer host_int;
typedef fmi2FMUstate host_state;
typedef fmi2ValueReference host_vr;
#define HOST_OK fmi2OK
#define HOST_WARNING fmi2Warning
#define HOST_ERROR fmi2Error
#define HOST_FATAL fmi2Fatal
#define HOST_TRUE fmi2True
#define HOST_FALSE fmi2False

#define host_load host2_load
#define host_unload host2_unload
#define host_mem_in_use host2_mem_in_use
#define host_instantiate host2_instantiate
#define host_enter_init host2_enter_init
#define host_start host2_start
#define host_free_instance host2_free_instance
#define host_step host2_step
#define host_step_out host2_step_out
#define host_get_state host2_get_state
#define host_set_state host2_set_state
#define host_free_state host2_free_state
#define host_state_size host2_state_size
#define host_serialize host2_serialize
#define host_deserialize host2_deserialize
#define host_snapshot host2_snapshot
#define host_same_state host2_same_state
#define host_get_reals host2_get_reals
#define host_set_reals host2_set_reals
#define host_get_ints host2_get_ints
#define host_set_ints host2_set_ints
#define host_get_bools host2_get_bools
#define host_set_bools host2_set_bools
#define host_set host2_set
#define host_set_named host2_set_named
#define host_real_outputs host2_real_outputs

#elif FMI_VERSION == 3

#include "host_fmi3.h"
#define BY_VERSION(fmi2, fmi3) fmi3

typedef host3_fmu host_fmu;
typedef host3_inst host_inst;
typedef fmi3Status host_status;
typedef fmi3Boolean host_bool;
typedef fmi3Int32 host_int;
typedef fmi3FMUState host_state;
typedef fmi3ValueReference host_vr;
#define HOST_OK fmi3OK
#define HOST_WARNING fmi3Warning
#define HOST_ERROR fmi3Error
#define HOST_FATAL fmi3Fatal
#define HOST_TRUE fmi3True
#define HOST_FALSE fmi3False

#define host_load host3_load
#define host_unload host3_unload
#define host_mem_in_use host3_mem_in_use
#define host_instantiate host3_instantiate
#define host_enter_init host3_enter_init
#define host_start host3_start
#define host_free_instance host3_free_instance
#define host_step host3_step
#define host_step_out host3_step_out
#define host_get_state host3_get_state
#define host_set_state host3_set_state
#define host_free_state host3_free_state
#define host_state_size host3_state_size
#define host_serialize host3_serialize
#define host_deserialize host3_deserialize
#define host_snapshot host3_snapshot
#define host_same_state host3_same_state
#define host_get_reals host3_get_reals
#define host_set_reals host3_set_reals
#define host_get_ints host3_get_ints
#define host_set_ints host3_set_ints
#define host_get_bools host3_get_bools
#define host_set_bools host3_set_bools
#define host_set host3_set
#define host_set_named host3_set_named
#define host_real_outputs host3_real_outputs

#else
#error "FMI_VERSION must be 2 or 3"
#endif

#define FMI_NAME(name) BY_VERSION("fmi2", "fmi3") name

/* ------------------------------------------------------------------------ */
/* written once over the adapter                                             */

/* 1 when what the FMUs hold is back to `before` (or cannot be counted, -1). */
static inline int host_mem_back_to(long before)
{
    return before < 0 || host_mem_in_use() == before;
}

/* host_set_named of a value the suite needs set: a refusal is a failure (host_fail: counted,
 * with the FMU's message), so a case never runs silently on the value it had before.
 * 1 when set. */
static inline int host_set_required(const host_fmu *f, host_inst *in, const char *name, double value)
{
    host_status st = host_set_named(f, in->c, name, value);
    if (st != HOST_OK && host_named(f, name, NULL) != NULL)
        host_fail("%s refused %s = %.17g (status %d: %s)", f->id, name, value, (int)st, in->log.last_error);
    return st == HOST_OK;
}

/* Configuration i (host_config_setting) on an instance in InitializationMode;
 * 0 if a setting was refused. */
static inline int host_apply_config(const host_fmu *f, void *c, int i)
{
    const char *name;
    double value;
    int j;
    for (j = 0; host_config_setting(i, j, &name, &value); j++)
        if (host_named(f, name, NULL) != NULL && host_set_named(f, c, name, value) != HOST_OK)
            return 0;
    return 1;
}

/* The controller refuses a doStep of several samples unless mv.hold_inputs is
 * true (a closed loop needs one exchange per sample); a suite that steps
 * several samples at once to test the FMI layer sets it on an instance in
 * Instantiated or InitializationMode, wherever the FMU has it. 0 if refused. */
static inline int host_hold_inputs(const host_fmu *f, void *c)
{
    return host_named(f, "mv.hold_inputs", NULL) == NULL || host_set_named(f, c, "mv.hold_inputs", 1.0) == HOST_OK;
}

/* The FMUs whose doStep takes a step of any size (fmu_model.h, MODEL_HAS_ANY_STEP in their
 * config.h: the samples whose instants the step passes are computed, and the FMU's time may
 * end between two); the others take whole multiples of h only. */
static inline int host_any_step(const host_fmu *f)
{
    return strcmp(f->id, "PiezoStageClosedLoop") == 0;
}

/* Sets the j-th Real input of f to host_drive(i, j, k, h). */
static inline int host_set_inputs(const host_fmu *f, void *c, int i, int k)
{
    int v, j = 0;
    for (v = 0; v < f->n_vars; v++)
        if (f->vars[v].causality == VAR_INPUT && f->vars[v].type == VAR_REAL) {
            double u = host_drive(i, j++, k, f->h);
            if (host_set_reals(f, c, &f->vars[v].vr, 1, &u, 1) != HOST_OK)
                return 0;
        }
    return 1;
}

#endif
