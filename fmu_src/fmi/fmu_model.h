/*
 * fmu_model.h - the contract between the FMI Co-Simulation glue (the shared
 * fmu_glue_core.c under fmi2_glue.c or fmi3_glue.c) and one model
 * (fmu_src/<Model>/model.c + config.h). The same model files serve the FMI 2.0
 * and the FMI 3.0 edition; nothing here depends on the FMI version (messages a
 * model writes say "doStep", "terminate", not a version's function names).
 *
 * The glue is compiled into every FMU with the model's directory first on the
 * include path, so "config.h" is that model's. config.h provides:
 *   MODEL_IDENTIFIER_STRING  the modelIdentifier (e.g. "PiezoStage")
 *   MODEL_GUID               the guid of modelDescription.xml (FMI 3.0: its
 *                            instantiationToken, the same string)
 *   an enum of value references 0..MODEL_N_VARIABLES-1 (FMI 3.0: scalars keep
 *                            them; a run name[1]..name[n] is one array variable
 *                            with the reference of name[1]) and the entries of
 *                            model_variables (MODEL_VARIABLE_TABLE), both from
 *                            variables.h, generated from the model's one
 *                            declaration variables.toml (packaging/fmu_interface.py)
 *   ModelData                flat, pointer-free model data (parameters,
 *                            held inputs, core state, output values)
 *
 * The glue owns everything FMI: the call-sequence state machine, argument and
 * value-reference checks, type and causality checks, time (t0 + k h), the
 * step-size check, logging, FMU states and their serialization, and the
 * exact-mode history buffer (grown before the model is asked to step).
 * The model only maps variables to ModelData and calls the core. Because
 * ModelData is flat, saving or restoring a state is a memcpy plus the history.
 */
#ifndef FMU_MODEL_H
#define FMU_MODEL_H

#include <stddef.h>
#include <stdint.h>
#include "piezo_status.h"
#include "config.h"

/* t_k = t0 + k h, the FMU's time at sample k, never accumulated: the one
 * expression of the glue (glue_time, the end of a step) and the models (their
 * stamps). k <= 2^53 + MAX_STEP_SAMPLES < 2^63 (the glue's bound), so the
 * signed conversion gives (double)k, in one instruction on x86-64 where the
 * unsigned one takes a branch and several. */
static inline double fmu_sample_time(double t0, uint64_t k, double h)
{
    return t0 + (double)(int64_t)k * h;
}

typedef enum { MODEL_REAL = 0, MODEL_INTEGER = 1, MODEL_BOOLEAN = 2 } model_type;

/* parameter: causality parameter, variability fixed (settable before the end
 * of initialization mode only); input: settable until terminate;
 * output: read only, computed by model_update_outputs. */
typedef enum { MODEL_PARAMETER = 0, MODEL_INPUT = 1, MODEL_OUTPUT = 2 } model_causality;

typedef struct {
    const char *name;          /* the XML name, used in log messages */
    model_type type;           /* Real: double, Integer/Boolean: int */
    model_causality causality;
    size_t offset;             /* offsetof(ModelData, ...) of the value */
} model_variable;

/* Indexed by value reference; entry i describes value reference i. */
extern const model_variable model_variables[MODEL_N_VARIABLES];

/* Start values of all parameters and inputs (must equal the XML starts). */
void model_set_start_values(ModelData *data);

/* Validate the parameters and (re)initialize the core state to sample 0 at
 * time start_time (fmi2SetupExperiment, fmi3EnterInitializationMode). On PIEZO_ERR_PARAM, diag names the
 * parameter. */
piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag);

/* The sample period h of an initialized model: its parameter "h", which every model declares
 * (the glue reads it where the generated table model_variables[vr_h] says it lies). */
double model_sample_period(const ModelData *data);

/* Doubles of exact-mode history the next step (or output update) needs;
 * 0 when the model keeps no history. Grows by two per step (x and w_j). */
size_t model_history_needed(const ModelData *data);

/* Advance one sample with the held inputs. A refusal changes nothing in
 * data (the core steps validate and evaluate before they commit), so the
 * glue copies the data only to roll back a step of several samples.
 * outputs_current: the output values were computed by model_update_outputs
 * from this very data and nothing changed since (no set, no step, no state
 * restored); a model with direct feedthrough then commits the sample it
 * evaluated for them instead of computing it again. */
piezo_status model_step(ModelData *data, double *history, size_t history_capacity,
                        int outputs_current);

/* Fill the output values of the current sample from the core and the held
 * inputs, committing nothing (direct feedthrough is computed here). */
piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity);

/*
 * Optional hooks. A model that has them defines in its config.h
 *   MODEL_HAS_FEEDTHROUGH  model_direct_feedthrough
 *   MODEL_HAS_MESSAGES     model_step_warning, model_terminate_warning, model_failure_text
 * and implements them; otherwise the inline defaults below apply (no
 * feedthrough, nothing to say).
 */
#ifdef MODEL_HAS_FEEDTHROUGH
/* 1 when the outputs currently depend directly on the inputs (the glue then
 * warns if a master reads them before setting the inputs of a step). */
int model_direct_feedthrough(const ModelData *data);
#else
static inline int model_direct_feedthrough(const ModelData *data)
{
    (void)data;
    return 0;
}
#endif

#ifdef MODEL_HAS_MESSAGES
/* After a successful doStep: write at most one warning into text (the model
 * keeps its "already said" flags in ModelData, so each thing is said once,
 * also across FMU state restores) and return 1, else return 0. */
int model_step_warning(ModelData *data, double start_time, char *text, size_t size);

/* At terminate: a summary worth a warning (e.g. counts), 1 if written. */
int model_terminate_warning(const ModelData *data, char *text, size_t size);

/* Why the model refused a step with status st, in its own terms (e.g. which
 * monitor bound was exceeded), 1 if written; else the glue's generic text. */
int model_failure_text(const ModelData *data, piezo_status st, char *text, size_t size);
#else
static inline int model_step_warning(ModelData *data, double start_time, char *text, size_t size)
{
    (void)data; (void)start_time; (void)text; (void)size;
    return 0;
}

static inline int model_terminate_warning(const ModelData *data, char *text, size_t size)
{
    (void)data; (void)text; (void)size;
    return 0;
}

static inline int model_failure_text(const ModelData *data, piezo_status st, char *text, size_t size)
{
    (void)data; (void)st; (void)text; (void)size;
    return 0;
}
#endif

#ifdef MODEL_HAS_EVENTS
/* After a successful doStep: write at most one event worth a log line (e.g. a
 * choice the model made) into text and return 1, else 0. Logged with status
 * OK in the category logEvents (debug logging). */
int model_step_event(ModelData *data, char *text, size_t size);
#else
static inline int model_step_event(ModelData *data, char *text, size_t size)
{
    (void)data; (void)text; (void)size;
    return 0;
}
#endif

#ifdef MODEL_HAS_NOTICES
/* After a successful doStep: write at most one notice into text and return 1, else 0
 * (each once, as the warnings). Logged as a Warning (status Warning, category
 * logStatusWarning, also with loggingOn = false), but the doStep still returns OK: a
 * fact about how the FMU is wired, not about its results, on which an importer that
 * stops at a Warning (fmusim, OMSimulator) must not stop. */
int model_step_notice(ModelData *data, char *text, size_t size);
#else
static inline int model_step_notice(ModelData *data, char *text, size_t size)
{
    (void)data; (void)text; (void)size;
    return 0;
}
#endif

#ifdef MODEL_HAS_STEP_CHECK
/* Before a doStep of n >= 1 samples: 1 with the reason in text when the model
 * refuses a step of n samples (the step is then refused, nothing changes). */
int model_check_step(const ModelData *data, uint64_t n, char *text, size_t size);
#else
static inline int model_check_step(const ModelData *data, uint64_t n, char *text, size_t size)
{
    (void)data; (void)n; (void)text; (void)size;
    return 0;
}
#endif

#ifdef MODEL_HAS_ANY_STEP
/*
 * A model that takes a communication step of any positive size (a master at
 * 1 ms, 10 ms or with variable steps), not only whole multiples of h. It is
 * still a sampled system: the glue computes the samples whose instants
 * t_k = t0 + k h the step passes and keeps the FMU's time t0 + k h + t_off,
 * 0 <= t_off < h, where the step ended; the outputs between two instants are
 * those of the last one (held). A sample reads its inputs at its instant: the
 * values held there. A step that ends between instants after passing the
 * instant of the next sample k (not yet computed: it completes at t_(k+1))
 * calls model_latch_inputs: the model keeps the inputs held now for sample k,
 * which the next step computes even if new inputs were set in between, and
 * forgets them once sample k is committed (model_step).
 */
#define MODEL_ANY_STEP 1
void model_latch_inputs(ModelData *data);
#else
#define MODEL_ANY_STEP 0
static inline void model_latch_inputs(ModelData *data)
{
    (void)data;
}
#endif

/* Validation of restored (deserialized, untrusted) data against the model's
 * invariants, the one place that knows them: NULL when data could have been
 * saved by a live instance, else a static description of the first fault.
 * The glue has already checked the header, the time fields, that every Real
 * variable is finite and every Boolean 0 or 1, and that n_history equals
 * model_history_needed(data). The model checks the rest: every index, count
 * and flag of its core state, its sample counters against k (and t0 where it
 * keeps time), that the core agrees with its parameters where it copies them,
 * and the exact-mode history (history[0..n_history-1], NULL when empty).
 * core_initialized: the state was saved after the end of initialization
 * (before it, only the parameters and inputs matter: model_init validates them). */
const char *model_check_data(const ModelData *data, int core_initialized, double t0, uint64_t k,
                             const double *history, size_t n_history);

#endif
