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
 *
 * Time stamps (docs/cosimulation.md): t_meas (PiezoStage's) says which sample
 * y_meas is, t_preview (ReferenceSignal's) which sample y_preview is. A stamp
 * counts only when it advanced by h since the last sample (a connected one
 * does; an unconnected input keeps its start value), so an FMU wired as
 * before, y_ref and y_meas only, runs today's loop.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <stddef.h>
#include "fmu_model.h"


/* the start value of every input (the model descriptions'): a controller whose y_meas
 * and t_meas kept it since its start was never connected */
#define INPUT_START 0.0
/* a stamped measurement more than this many samples off the controller's time is ignored */
#define MEAS_OFFSET_MAX 8
/* the time stamps are judged once the loop delay is chosen and this many samples ran (a
 * stamp counts from the second sample it advanced, a player's first inputs are zeros) */
#define STAMP_WARN_SAMPLES 10

const model_variable model_variables[MODEL_N_VARIABLES] = { MODEL_VARIABLE_TABLE };

void model_set_start_values(ModelData *data)
{
    piezo_controller_default_params(&data->params);
    data->y_ref = INPUT_START;
    data->y_meas = INPUT_START;
    data->y_preview = INPUT_START;
    data->t_preview = INPUT_START;
    data->t_meas = INPUT_START;
    data->sup_reset = 0;
}

/* t_k of the model's own t0 and h (fmu_sample_time, as the glue) */
static double sample_time(const ModelData *data, uint64_t k)
{
    return fmu_sample_time(data->t0, k, data->params.h);
}

piezo_status model_init(ModelData *data, double start_time, piezo_diag *diag)
{
    piezo_status st;
    data->meas_stamped = data->preview_stamped = 0;
    data->preview_offset = 0;
    data->said_stamps = 0;
    data->sup_status = data->sup_delay = data->sup_fault = 0;
    data->sup_gain = data->sup_fault_time = 0.0;
    data->fallbacks = 0;
    data->loop_wired = data->said_open_loop = 0;
    /* the controller is time-invariant; t0 places the time stamps on its grid */
    data->t0 = start_time;
    data->last_t_preview = data->last_t_meas = 0.0;
    data->have_last = 0;
    st = piezo_controller_init(&data->ctrl, &data->params, diag);
    if (st != PIEZO_OK)
        return st;
    fmu_controller_track_init(&data->track, &data->ctrl, start_time);
    data->track_lead = data->track_offset = 0;
    data->loop_delay = data->track.delay;
    data->loop_delay_time = data->track.delay_time;
    data->preview_lead = data->meas_offset = 0;
    return PIEZO_OK;
}

/* Open loop: until an input leaves its start value, none is connected (a standalone run,
 * a checker's with default inputs); a connected loop shows it within its first samples
 * (y_ref or the preview move, t_meas advances, y_meas moves), long before the supervision's
 * first verdict (PIEZO_SUP_MIN_SAMPLES). Open loop, the supervision reaches no verdict.
 * A reference that moves while y_meas and t_meas never do is a loop whose feedback is not
 * connected: the supervision stops it (it would otherwise run with v pinned at a limit). */
static int loop_connected(const ModelData *data)
{
    return data->loop_wired || data->y_meas != INPUT_START || data->t_meas != INPUT_START
           || data->y_ref != INPUT_START || data->y_preview != INPUT_START || data->t_preview != INPUT_START;
}

/* Nothing connected at all: every input still at its start value (a checker's run with
 * default inputs). Only then may a step hold the inputs over several samples: a master that
 * exchanged initial values has set y_ref, and is refused at its first step. */
static int inputs_untouched(const ModelData *data)
{
    return !loop_connected(data);
}

/* Before a sample is evaluated with the held inputs: is the loop connected (once, for good)? */
static void note_loop_inputs(ModelData *data)
{
    data->loop_wired = loop_connected(data);
    data->ctrl.sup.open_loop = !data->loop_wired;
}

/* A time stamp input is connected when it advanced by one sample h since the
 * last committed sample (an unconnected input keeps its start value). */
static int stamp_advanced(const ModelData *data, double t, double last)
{
    double h = data->params.h;
    return data->have_last && fabs((t - last) - h) <= 1e-3 * h;
}

/* What the stamps of a sample said (for the supervision warnings). */
typedef struct {
    int meas;                   /* t_meas advanced by h: counted */
    int preview;                /* t_preview advanced by h */
    int lead;                   /* t_preview - origin in samples, clamped to +-99 (preview counted) */
} stamps_seen;

/*
 * The inputs of the current sample k: with a connected t_meas, the
 * measurement is of sample k + offset, offset = (t_meas - t_k) / h; with a
 * connected t_preview, y_preview is lead = (t_preview - t_meas) / h samples
 * ahead of the measurement (t_meas replaced by t_k without its stamp). The
 * core uses it when 1 <= lead < PIEZO_PREVIEW_RING.
 */
static piezo_controller_input sample_input(const ModelData *data, int *meas_offset, stamps_seen *seen)
{
    piezo_controller_input in;
    double h = data->params.h;
    int meas_stamped = 0;       /* origin = t_meas, else t_k */
    *meas_offset = 0;
    seen->meas = seen->preview = seen->lead = 0;
    if (stamp_advanced(data, data->t_meas, data->last_t_meas)) {
        double o = floor((data->t_meas - sample_time(data, data->ctrl.k)) / h + 0.5);
        seen->meas = 1;
        if (fabs(o) <= MEAS_OFFSET_MAX) {
            *meas_offset = (int)o;
            meas_stamped = 1;
        }
    }
    in.y_ref = data->y_ref;
    in.y_meas = data->y_meas;
    in.y_preview = data->y_preview;
    in.preview_lead = 0;
    if (stamp_advanced(data, data->t_preview, data->last_t_preview)) {
        /* t_k only where a stamp needs it (an unstamped loop runs without) */
        double origin = meas_stamped ? data->t_meas : sample_time(data, data->ctrl.k);
        double a = floor((data->t_preview - origin) / h + 0.5);
        seen->preview = 1;
        seen->lead = a > 99.0 ? 99 : (a < -99.0 ? -99 : (int)a);
        if (a >= 1.0 && a < (double)PIEZO_PREVIEW_RING)
            in.preview_lead = (int)a;
    }
    return in;
}

/* After sample k was committed with these inputs: the stamps it saw, and the
 * timing outputs of the default (published) timing. */
static void after_commit(ModelData *data, const piezo_controller_input *in, int meas_offset,
                         const stamps_seen *seen)
{
    const piezo_controller_output *o = &data->ctrl.out;
    data->meas_stamped |= seen->meas;
    data->preview_stamped |= seen->preview;
    if (seen->preview)
        data->preview_offset = seen->lead;
    data->last_t_preview = data->t_preview;
    data->last_t_meas = data->t_meas;
    data->have_last = 1;
    data->track_lead = o->preview ? in->preview_lead : 0;
    data->track_offset = meas_offset;
    fmu_controller_track_commit(&data->track, &data->ctrl, data->t0, data->params.h);
}

size_t model_history_needed(const ModelData *data)
{
    return piezo_controller_history_needed(&data->ctrl);
}

piezo_status model_step(ModelData *data, double *history, size_t history_capacity,
                        int outputs_current)
{
    int meas_offset;
    stamps_seen seen;
    piezo_controller_input in;
    piezo_status st;
    fmu_controller_reset_backup undo;   /* a refused sample commits nothing, sup.reset's restart included */
    int read_ahead = outputs_current && data->params.mv_feedthrough;
    note_loop_inputs(data);
    in = sample_input(data, &meas_offset, &seen);
    /* sup.reset: before this sample; with mv.feedthrough, whose outputs of this sample were read
     * before the step, after it (the restart takes effect at the next sample) */
    fmu_controller_reset_keep(&undo, &data->track, &data->ctrl, data->sup_reset && !read_ahead);
    if (!read_ahead)
        fmu_controller_reset_input(&data->track, &data->ctrl, data->sup_reset, &in);
    /* mv.feedthrough: the sample the outputs were read from is committed as is
     * (computed once, from these inputs); the commit refuses it if it is not
     * this sample's */
    if (read_ahead)
        st = piezo_controller_commit(&data->ctrl, &data->pending, NULL);
    else
        st = piezo_controller_step_input(&data->ctrl, &in, history, history_capacity, NULL);
    if (st == PIEZO_OK)
        after_commit(data, &in, meas_offset, &seen);
    else
        fmu_controller_reset_undo(&undo, &data->track, &data->ctrl);
    if (st == PIEZO_OK && read_ahead)
        fmu_controller_reset_input(&data->track, &data->ctrl, data->sup_reset, &in);
    return st;
}

piezo_status model_update_outputs(ModelData *data, double *history, size_t history_capacity)
{
    /* the supervision as of the last committed sample; 2 once it warned */
    data->sup_status = data->said_stamps ? 2 : data->ctrl.sup.status;
    data->sup_gain = data->ctrl.sup.gain;
    data->sup_delay = data->ctrl.sup.delay;
    fmu_controller_fault_outputs(&data->ctrl, data->t0, data->params.h, &data->sup_fault, &data->sup_fault_time);
    data->fallbacks = fmu_controller_fallbacks(&data->ctrl);
    if (data->params.mv_feedthrough) {
        int meas_offset;
        stamps_seen seen;
        piezo_controller_input in;
        piezo_status st;
        note_loop_inputs(data);
        in = sample_input(data, &meas_offset, &seen);
        st = piezo_controller_evaluate(&data->ctrl, &in, history, history_capacity, &data->pending);
        if (st != PIEZO_OK)
            return st;
        /* the outputs of sample k itself */
        data->out = data->pending.out;
        data->preview_lead = data->out.preview ? in.preview_lead : 0;
        data->meas_offset = meas_offset;
        data->loop_delay = data->out.delay;
        data->loop_delay_time = data->out.delay == data->track.delay ? data->track.delay_time
                                                                     : sample_time(data, data->ctrl.k);
        return PIEZO_OK;
    }
    /* published at the end of the last step */
    data->out = data->ctrl.out;
    data->preview_lead = data->track_lead;
    data->meas_offset = data->track_offset;
    data->loop_delay = data->track.delay;
    data->loop_delay_time = data->track.delay_time;
    return PIEZO_OK;
}

int model_direct_feedthrough(const ModelData *data)
{
    return data->params.mv_feedthrough != 0;
}

/* The supervision's warnings of the time stamps, each once: a loop that works,
 * degraded, because a stamp it needs is not connected or cannot be aligned
 * (docs/cosimulation.md, section 3.3). */
static int stamp_warning(ModelData *data, char *text, size_t size)
{
    const piezo_controller *c = &data->ctrl;
    int d = data->track.delay;
    if (!data->params.sup.enabled || d == 0 || c->k < STAMP_WARN_SAMPLES)
        return 0;
    if (!(data->said_stamps & 1) && !data->meas_stamped && data->preview_stamped && d == 1) {
        data->said_stamps |= 1;
        snprintf(text, size, "t_meas is not connected (it has not advanced by h from one sample to the next), "
                 "but the loop delay d = 1 chosen here shows a master that steps the FMUs one after another: "
                 "if it steps PiezoStage before this controller, y_meas is one sample newer than the "
                 "controller's time and the stamped preview is used one sample late (about sqrt(2) pi f A h "
                 "rms: 22 nm for a 10 um tone at 1 Hz). Connect PiezoStage.t_meas -> t_meas");
        return 1;
    }
    if (!(data->said_stamps & 2) && !data->preview_stamped && c->auto_delay && d != 2) {
        data->said_stamps |= 2;
        snprintf(text, size, "t_preview is not connected (with y_preview), so the controller takes y_ref as "
                 "y_d(k + d): ReferenceSignal's default lead of 2 samples fits the loop delay of a master that "
                 "exchanges values at communication points, but this loop has d = %d, so the reference may be "
                 "off by %d sample%s (about sqrt(2) pi f A h rms per sample). Connect ReferenceSignal.y_preview "
                 "-> y_preview and ReferenceSignal.t_preview -> t_preview", d, abs(d - 2), abs(d - 2) == 1 ? "" : "s");
        return 1;
    }
    if (!(data->said_stamps & 4) && data->preview_stamped
        && (data->preview_offset < d || data->preview_offset >= PIEZO_PREVIEW_RING)) {
        data->said_stamps |= 4;
        snprintf(text, size, "the stamped preview (t_preview) is %d samples ahead of the measurement, but the "
                 "loop delay d = %d needs it %d to %d samples ahead: it cannot be aligned and y_ref stands in. "
                 "Set ReferenceSignal's preview (default 4) so that t_preview leads y_meas by %d to %d samples",
                 data->preview_offset, d, d, PIEZO_PREVIEW_RING - 1, d, PIEZO_PREVIEW_RING - 1);
        return 1;
    }
    return 0;
}

/* Once, a notice (logged as a Warning, the step OK: a standalone check runs on): the
 * controller runs open loop, its loop inputs never connected (judged after
 * STAMP_WARN_SAMPLES samples: a connected loop has shown it by then). */
int model_step_notice(ModelData *data, char *text, size_t size)
{
    if (data->loop_wired || data->said_open_loop || !data->params.sup.enabled
        || data->ctrl.k < STAMP_WARN_SAMPLES)
        return 0;
    data->said_open_loop = 1;
    snprintf(text, size, "every input (y_ref, y_meas, t_meas, y_preview, t_preview) has kept its start value %g "
             "for the first %llu samples: none is connected, so the controller runs open loop and its supervision "
             "does not judge the loop. To close the loop connect PiezoStage.y_meas -> y_meas and PiezoStage.t_meas "
             "-> t_meas, the reference (ReferenceSignal.y_ref -> y_ref, .y_preview, .t_preview) and v -> "
             "PiezoStage.v; for open-loop use set sup.enabled = false", INPUT_START,
             (unsigned long long)data->ctrl.k);
    return 1;
}

/* Where this controller's loop is, for its messages: wired to a stage by hand, from t0. */
static piezo_sup_context context(const ModelData *data)
{
    return fmu_controller_context(data->t0, data->params.h);
}

int model_step_warning(ModelData *data, double start_time, char *text, size_t size)
{
    piezo_sup_context ctx = context(data);
    (void)start_time;   /* data->t0 is the same */
    if (stamp_warning(data, text, size))
        return 1;
    return fmu_controller_warning(&data->track, &data->ctrl, &ctx, text, size);
}

int model_step_event(ModelData *data, char *text, size_t size)
{
    return fmu_controller_event(&data->track, &data->ctrl, data->t0, data->params.h, text, size);
}

int model_check_step(const ModelData *data, uint64_t n, char *text, size_t size)
{
    if (n <= 1 || data->params.mv_hold_inputs || inputs_untouched(data))
        return 0;
    snprintf(text, size, "the controller computes one control per measurement, so a closed loop needs an "
             "exchange of y_meas and v every sample: a step of %llu samples would hold y_meas over them and run "
             "another loop, which is unstable. Set the master's communication step to h = %g s (OMSimulator: "
             "the fixed-step master's step size), or set mv.hold_inputs = true to hold the inputs over the step "
             "outside a closed loop", (unsigned long long)n, data->params.h);
    return 1;
}

int model_terminate_warning(const ModelData *data, char *text, size_t size)
{
    return fmu_controller_summary(&data->ctrl, text, size);
}

int model_failure_text(const ModelData *data, piezo_status st, char *text, size_t size)
{
    piezo_sup_context ctx = context(data);
    return fmu_controller_failure(&data->ctrl, &ctx, st, text, size);
}

const char *model_check_data(const ModelData *data, int core_initialized, double t0, uint64_t k,
                             const double *history, size_t n_history)
{
    const piezo_controller *c = &data->ctrl;
    const piezo_controller_params *q = &data->params;
    const char *fault;
    if ((fault = fmu_controller_track_check(&data->track, core_initialized, t0, k, data->params.h)) != NULL)
        return fault;
    if ((data->have_last != 0 && data->have_last != 1) || data->said_stamps < 0 || data->said_stamps > 7
        || (data->meas_stamped != 0 && data->meas_stamped != 1)
        || (data->preview_stamped != 0 && data->preview_stamped != 1)
        || (data->loop_wired != 0 && data->loop_wired != 1)
        || (data->said_open_loop != 0 && data->said_open_loop != 1))
        return "warning flags are not 0 or 1";
    if (abs(data->preview_offset) > 99 || data->sup_status < 0 || data->sup_status > 2
        || data->sup_delay < 0 || data->sup_delay > PIEZO_MV_MAX_D || !isfinite(data->sup_gain)
        || data->sup_fault < 0 || data->sup_fault > PIEZO_SUP_FAULT_MAX || !isfinite(data->sup_fault_time))
        return "supervision outputs out of range";
    if (data->fallbacks < 0)
        return "est.fallbacks negative";
    if (!(isfinite(data->t0) && isfinite(data->last_t_preview) && isfinite(data->last_t_meas)))
        return "time stamps not finite";
    if (data->loop_delay < 0 || data->loop_delay > PIEZO_MV_MAX_D
        || data->preview_lead < 0 || data->preview_lead >= PIEZO_PREVIEW_RING || data->track_lead < 0
        || data->track_lead >= PIEZO_PREVIEW_RING || abs(data->meas_offset) > MEAS_OFFSET_MAX
        || abs(data->track_offset) > MEAS_OFFSET_MAX)
        return "timing outputs out of range";
    if (!core_initialized)
        return NULL;    /* parameters are validated by model_init later */
    if ((fault = piezo_controller_check(c)) != NULL)
        return fault;
    if (data->track.said_fault && !c->fault)
        return "the safe state's warning said without a safe state";
    if (c->k != k)
        return "controller sample counter differs from the FMU's k";
    if (k > 0 && c->sup.open_loop == data->loop_wired)
        return "open-loop flag differs from the connection seen";
    if (data->t0 != t0 || data->have_last != (k > 0))
        return "controller time stamps differ from t0 + k h";
    /* a live core runs on parameters that passed init, and on the copies init made of them */
    if ((fault = piezo_controller_check_params(c, q)) != NULL)
        return fault;
    return piezo_gl_check_history(&c->inv_creep, history, n_history);
}
