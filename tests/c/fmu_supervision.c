/*
 * fmu_supervision.c - the controller's supervision, as an importer wiring the
 * three FMUs by hand sees it (docs/robustness.md, the fault table). Built once
 * per FMI version: fmu_supervision runs the FMI 2.0 editions, fmu3_supervision
 * the FMI 3.0 ones.
 *
 * The loop is the closed-loop SSP's: ReferenceSignal's y_ref, y_preview,
 * t_preview and PiezoStage's y_meas, t_meas to the controller's inputs of the
 * same names, the controller's v to PiezoStage's. The plant is the mismatch
 * case of docs/model.md (PI weights +10 %, Table 1's 10 Hz creep row, G's
 * numerator x1.05 with the fast pole at 0.45, a 2 nm / 1 nm sensor:
 * harness/scenarios/mismatch.toml, which tests/test_fmu_robustness.py checks
 * MISMATCH against), the reference a 10 um tone at 5 Hz. Two schedules: values
 * exchanged at communication points (read every output, set every input, step
 * every FMU: loop delay 2), and true Gauss-Seidel in the order plant,
 * controller, reference (each FMU gets the others' latest outputs: loop delay 1).
 *
 * One case per fault of the table (harness/studies/supervision_table.py FAULTS, by the
 * same name, in the schedules the table runs it in; the Python wrapper checks
 * that every fault is here and that each time printed is the table's), each with
 * what the controller must say: an Error from its doStep within 1 s of the
 * fault's onset whose message gives the diagnosis and the advice of the table's
 * message (the supervision's, or the divergence monitor's for a loop no model
 * explains), or, for a degraded loop, one Warning saying both and sup.status = 2.
 * The sound loop must run 2 s with no message from the controller and end
 * verified (sup.status = 1) at the loop's delay (2 exchanging, 1 sequential)
 * with the mismatch plant's gain (0.8 to 1.6 times the model's, as
 * tests/test_core_supervision.py), and the supervision switched off for
 * open-loop use (sup.enabled = false, with the divergence monitor off:
 * monitor.divergence_samples = 0) must let an open loop run (sup.status = 0).
 * Every value the suite sets must be accepted (host_set_required).
 *
 * The safe reaction (sup.reaction = 1): every case that fails the doStep runs
 * again in the exchanging master with it. No doStep fails; the controller's
 * Warning says "sup.reaction = safe" once with the case's phrase (the Error's
 * words); sup.fault is the verdict's code (1..10) and sup.fault_time the time
 * the Error came at; v is 0 V at the end.
 *
 * usage: fmu_supervision PiezoStage.xml PiezoStage.so AdaptiveCompoundController.xml
 *            AdaptiveCompoundController.so ReferenceSignal.xml ReferenceSignal.so
 * Prints one line per check and "N passed, M failed"; exit code 1 on failure.
 */
#include "host.h"

static host_fmu plant, ctrl, ref;
static int safe_reaction;       /* the next start() sets sup.reaction = 1 */

enum { REF, CTRL, PLANT, N_COMP };
enum { F_NONE, F_CONSTANT, F_STUCK, F_SCALE, F_OPEN, F_SOURCE, F_ALTERNATE };
/* the schedules a case runs in */
enum { EXCHANGE = 1, SEQUENTIAL = 2, BOTH = 3 };
/* what the controller must do */
enum { ERROR, WARNING, VERIFIED, NO_ERROR };

/* what one input receives instead of its connection's value, from `start` [s] on */
typedef struct {
    const char *input;          /* the controller's or the plant's input */
    int kind;
    double value;               /* the constant, the factor, the amplitude, or (F_SOURCE) the link fed from */
    double start;
} fault;

typedef struct {
    const char *name;           /* the fault's name in harness/studies/supervision_table.py FAULTS */
    fault faults[2];
    const char *plant_param;    /* a plant parameter set for the case (NULL: none) */
    double plant_value;
    const char *ctrl_param;     /* a controller parameter */
    double ctrl_value;
    double frequency, amplitude;    /* the reference tone */
    int schedules;
    int expect;
    const char *phrase;         /* the diagnosis, in the Error's or the Warning's message */
    const char *advice;         /* what it tells the user to do */
    const char *advice_seq;     /* the advice in the sequential schedule, where it differs (NULL: the same) */
} fault_case;

/* the mismatch plant of docs/model.md (sensor.seed keeps its start value, 1) */
static const struct { const char *name; double value; } MISMATCH[] = {
    {"pi.w0", 0.36784}, {"pi.w[1]", 0.07854}, {"pi.w[2]", 0.03542}, {"pi.w[3]", 0.00792},
    {"creep.k_c", 1.0497}, {"creep.alpha", -0.0085}, {"tf.a1", -1.442037}, {"tf.a2", 0.44641665},
    {"tf.b1", 0.62517}, {"tf.b2", -0.620235}, {"sensor.resolution", 0.002}, {"sensor.noise_rms", 0.001},
};

/* the links of the loop (LINKS below), for F_SOURCE */
enum { L_Y_REF, L_Y_PREVIEW, L_T_PREVIEW, L_Y_MEAS, L_T_MEAS, L_V };

#define NO_FAULT {{NULL, F_NONE, 0, 0}}
/* the advice of the verdicts */
#define CONNECT_Y_MEAS "Check the connections PiezoStage.y_meas -> y_meas and AdaptiveCompoundController.v -> PiezoStage.v"
#define CONNECT_V "Check the connections AdaptiveCompoundController.v -> PiezoStage.v and PiezoStage.y_meas -> y_meas, " \
                  "their units (V, um) and the amplifier"
#define CHECK_SIGN "Check the sign of the sensor, of the amplifier and of the connections y_meas and v"
#define CHECK_UNIT "Check the unit of y_meas (um)"
#define SET_D2 "Set mv.delay = 1 (d = 2), or -1 to detect delays of 1 to 3 samples"

static const fault_case CASES[] = {
    {"sound loop", NO_FAULT, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, VERIFIED, NULL, NULL, NULL},
    {"y_meas not connected (0)", {{"y_meas", F_CONSTANT, 0.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas has not changed at all", CONNECT_Y_MEAS, NULL},
    {"y_meas stuck at its first value", {{"y_meas", F_STUCK, 0.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas has not changed at all", CONNECT_Y_MEAS, NULL},
    {"y_meas stuck from t = 1 s (a sensor that fails)", {{"y_meas", F_STUCK, 0.0, 1.0}}, NULL, 0, NULL, 0, 5.0, 10.0,
     BOTH, ERROR, "y_meas has not changed at all", CONNECT_Y_MEAS, NULL},
    {"y_meas inverted", {{"y_meas", F_SCALE, -1.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas or v is inverted", CHECK_SIGN, NULL},
    {"y_meas inverted from t = 1 s", {{"y_meas", F_SCALE, -1.0, 1.0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas or v is inverted", CHECK_SIGN, NULL},
    {"y_meas in mm (x 0.001)", {{"y_meas", F_SCALE, 1e-3, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas is in mm instead of um", CHECK_UNIT, NULL},
    {"y_meas in nm (x 1000)", {{"y_meas", F_SCALE, 1e3, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas is in nm instead of um", CHECK_UNIT, NULL},
    {"y_meas alternating +-10 um, whatever v does", {{"y_meas", F_ALTERNATE, 10.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0,
     BOTH, ERROR, "the closed loop is unstable", "the loop's gain is far above the model's", NULL},
    /* the stage standing still behind the paper's quiet sensor (1 nm on its 2 nm grid) reads as a stuck
     * sensor would: the verdict names both, within a few samples */
    {"v not reaching the plant (0)", {{"v", F_CONSTANT, 0.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas is stuck, or v does not reach the stage", CONNECT_Y_MEAS, NULL},
    {"v lost from t = 1 s", {{"v", F_CONSTANT, 0.0, 1.0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas is stuck, or v does not reach the stage", CONNECT_Y_MEAS, NULL},
    {"v inverted (amplifier or wiring)", {{"v", F_SCALE, -1.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "y_meas or v is inverted", CHECK_SIGN, NULL},
    {"amplifier gain 0.1", {{"v", F_SCALE, 0.1, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "v does not reach the stage, or y_meas is not the stage's measurement", CONNECT_V, NULL},
    {"amplifier gain 10", {{"v", F_SCALE, 10.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "the loop's gain is far above the model's",
     "Check the amplifier's gain, the units of v (V) and y_meas (um), and that the controller's model "
     "(pi.*, tf.*, creep.*) is this stage's", NULL},
    {"y_ref and y_meas swapped", {{"y_meas", F_SOURCE, L_Y_REF, 0}, {"y_ref", F_SOURCE, L_Y_MEAS, 0}}, NULL, 0, NULL, 0,
     5.0, 10.0, BOTH, ERROR, "y_meas and y_ref are swapped",
     "Connect PiezoStage.y_meas -> y_meas and ReferenceSignal.y_ref -> y_ref", NULL},
    {"y_meas fed ReferenceSignal's y_ref", {{"y_meas", F_SOURCE, L_Y_REF, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "v does not reach the stage, or y_meas is not the stage's measurement", CONNECT_V, NULL},
    /* the loop's delay by construction: 2 exchanging, 1 sequential, plus the plant's 4 */
    {"plant input delay of 4 samples (tf.delay = 4)", NO_FAULT, "tf.delay", 4.0, NULL, 0, 5.0, 10.0, BOTH, ERROR,
     "the loop has more delay than a master and the stage add",
     "Set mv.delay = 5 (d = 6) for this loop, or remove the extra delay",
     "Set mv.delay = 4 (d = 5) for this loop, or remove the extra delay"},
    /* a set mv.delay is a fault in the exchanging master (d = 2); 0 is right in a sequential one */
    {"mv.delay = 0 set for a loop of d = 2", NO_FAULT, NULL, 0, "mv.delay", 0.0, 5.0, 10.0, EXCHANGE, ERROR,
     "but the controller runs d = 1 (mv.delay = 0)", SET_D2, NULL},
    {"mv.delay = 2 set for a loop of d = 2", NO_FAULT, NULL, 0, "mv.delay", 2.0, 5.0, 10.0, EXCHANGE, ERROR,
     "but the controller runs d = 3 (mv.delay = 2)", SET_D2, NULL},
    /* the reference needs its excursion: the clipping watchdog's 0.5 s plus the ramp */
    {"reference beyond reach (500 um at 0.25 Hz)", NO_FAULT, NULL, 0, NULL, 0, 0.25, 500.0, BOTH, ERROR,
     "the loop cannot reach the reference", "reduce the reference or widen sat.v_min .. sat.v_max", NULL},
    /* the stamps are judged where the loop needs them, in a sequential master */
    {"t_meas not connected", {{"t_meas", F_OPEN, 0.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, SEQUENTIAL, WARNING,
     "t_meas is not connected", "Connect PiezoStage.t_meas -> t_meas", NULL},
    {"t_preview not connected", {{"t_preview", F_OPEN, 0.0, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, SEQUENTIAL, WARNING,
     "t_preview is not connected",
     "Connect ReferenceSignal.y_preview -> y_preview and ReferenceSignal.t_preview -> t_preview", NULL},
    {"supervision off, y_meas not connected", {{"y_meas", F_CONSTANT, 0.0, 0}}, NULL, 0, "sup.enabled", 0.0, 5.0,
     10.0, BOTH, NO_ERROR, NULL, NULL, NULL},
};

/* the connections of the loop: (source component, output) -> (destination component, input) */
static const struct { int src; const char *out; int dst; const char *in; } LINKS[] = {
    {REF, "y_ref", CTRL, "y_ref"}, {REF, "y_preview", CTRL, "y_preview"}, {REF, "t_preview", CTRL, "t_preview"},
    {PLANT, "y_meas", CTRL, "y_meas"}, {PLANT, "t_meas", CTRL, "t_meas"}, {CTRL, "v", PLANT, "v"},
};
#define N_LINKS ((int)(sizeof LINKS / sizeof LINKS[0]))

typedef struct {
    host_inst in[N_COMP];
    const host_fmu *f[N_COMP];
    double out[N_LINKS];        /* the source value of each link, latest */
    double first[N_LINKS];      /* the first value each input received (F_STUCK) */
    int have_first[N_LINKS];
    int alternate;              /* samples of F_ALTERNATE so far */
} loop;

static const fault *fault_of(const fault_case *c, const char *input)
{
    int i;
    for (i = 0; i < 2; i++)
        if (c->faults[i].input != NULL && strcmp(c->faults[i].input, input) == 0)
            return &c->faults[i];
    return NULL;
}

/* when the case's fault begins [s] (0 for a parameter) */
static double onset(const fault_case *c)
{
    return c->faults[0].input != NULL ? c->faults[0].start : 0.0;
}

static double get_real(const host_fmu *f, host_inst *in, const char *name)
{
    const host_var *v = host_named(f, name, NULL);
    host_vr vr = (host_vr)v->vr;
    double x = NAN;
    if (host_get_reals(f, in->c, &vr, 1, &x, 1) != HOST_OK)
        host_fail("%s refused to give %s (%s)", f->id, name, in->log.last_error);
    return x;
}

static int get_int(const host_fmu *f, host_inst *in, const char *name)
{
    const host_var *v = host_named(f, name, NULL);
    host_vr vr = (host_vr)v->vr;
    host_int x = -1;
    if (host_get_ints(f, in->c, &vr, 1, &x, 1) != HOST_OK)
        host_fail("%s refused to give %s (%s)", f->id, name, in->log.last_error);
    return (int)x;
}

/* read component comp's outputs into the links it feeds */
static void read_outputs(loop *l, int comp)
{
    int i;
    for (i = 0; i < N_LINKS; i++)
        if (LINKS[i].src == comp)
            l->out[i] = get_real(l->f[comp], &l->in[comp], LINKS[i].out);
}

/* set component comp's inputs at time t from the links into it, through the case's faults
 * (as harness/masters/wired.py does); 0 if the FMU refused one */
static int write_inputs(loop *l, int comp, const fault_case *c, double t)
{
    int i;
    for (i = 0; i < N_LINKS; i++) {
        const fault *ft;
        double x;
        if (LINKS[i].dst != comp)
            continue;
        x = l->out[i];
        ft = fault_of(c, LINKS[i].in);
        if (ft != NULL && t >= ft->start - 0.5 * ctrl.h) {
            if (ft->kind == F_OPEN)
                continue;               /* never set: the input keeps its start value */
            if (ft->kind == F_CONSTANT)
                x = ft->value;
            else if (ft->kind == F_SCALE)
                x *= ft->value;
            else if (ft->kind == F_STUCK)
                x = l->have_first[i] ? l->first[i] : x;
            else if (ft->kind == F_SOURCE)      /* fed from another link's output */
                x = l->out[(int)ft->value];
            else if (ft->kind == F_ALTERNATE)   /* +-value, whatever v does */
                x = l->alternate++ % 2 ? -ft->value : ft->value;
        }
        if (!l->have_first[i]) {
            l->first[i] = x;
            l->have_first[i] = 1;
        }
        if (!host_set_required(l->f[comp], &l->in[comp], LINKS[i].in, x))
            return 0;
    }
    return 1;
}

/* start the three FMUs with the case's parameters (0 on failure) */
static int start(loop *l, const fault_case *c)
{
    static const char *names[N_COMP] = {"reference", "controller", "plant"};
    size_t i;
    int j, ok = 1;
    l->f[REF] = &ref;
    l->f[CTRL] = &ctrl;
    l->f[PLANT] = &plant;
    memset(l->out, 0, sizeof l->out);
    memset(l->have_first, 0, sizeof l->have_first);
    l->alternate = 0;
    for (j = 0; j < N_COMP; j++) {
        if (host_instantiate(&l->in[j], l->f[j], names[j]) == NULL
            || host_enter_init(l->f[j], l->in[j].c, 0.0, 0, 0.0) != HOST_OK)
            return 0;
    }
    for (i = 0; i < sizeof MISMATCH / sizeof MISMATCH[0]; i++)
        ok = host_set_required(&plant, &l->in[PLANT], MISMATCH[i].name, MISMATCH[i].value) && ok;
    if (c->plant_param != NULL)
        ok = host_set_required(&plant, &l->in[PLANT], c->plant_param, c->plant_value) && ok;
    if (c->ctrl_param != NULL)
        ok = host_set_required(&ctrl, &l->in[CTRL], c->ctrl_param, c->ctrl_value) && ok;
    /* open-loop use switches the divergence monitor off too */
    if (c->ctrl_param != NULL && strcmp(c->ctrl_param, "sup.enabled") == 0)
        ok = host_set_required(&ctrl, &l->in[CTRL], "monitor.divergence_samples", 0.0) && ok;
    ok = host_set_required(&ref, &l->in[REF], "frequency[1]", c->frequency) && ok;
    ok = host_set_required(&ref, &l->in[REF], "amplitude[1]", c->amplitude) && ok;
    if (safe_reaction)
        ok = host_set_required(&ctrl, &l->in[CTRL], "sup.reaction", 1.0) && ok;
    safe_reaction = 0;
    for (j = 0; j < N_COMP; j++)
        if (l->f[j]->api.ExitInitializationMode(l->in[j].c) != HOST_OK)
            return 0;
    for (j = 0; j < N_COMP; j++)
        read_outputs(l, j);
    return ok;
}

/* what a run did */
typedef struct {
    int failed;                 /* the sample whose doStep returned an Error, -1: none */
    int refused_set;            /* a set was refused (counted by host_set_required) */
    int said;                   /* controller messages that gave the case's phrase and advice */
} outcome;

/* after a step of the controller: did its new message say the phrase and the advice? */
static void listen(const loop *l, const fault_case *c, const char *advice, int before, outcome *o)
{
    const host_log *log = &l->in[CTRL].log;
    if (c->phrase != NULL && log->n_messages > before && strstr(log->last, c->phrase) != NULL
        && strstr(log->last, advice) != NULL)
        o->said++;
}

/* Run the case under a schedule (0: exchange, 1: plant, controller, reference) for n
 * samples or until a doStep fails or a set is refused. */
static outcome run(loop *l, const fault_case *c, int sequential, int n)
{
    static const int order[N_COMP] = {PLANT, CTRL, REF};
    const char *advice = sequential && c->advice_seq != NULL ? c->advice_seq : c->advice;
    double h = ctrl.h;
    int k, j;
    outcome o = {-1, 0, 0};
    for (k = 0; k < n; k++) {
        double t = k * h;
        if (!sequential) {
            for (j = 0; j < N_COMP; j++)
                if (!write_inputs(l, j, c, t)) {
                    o.refused_set = 1;
                    return o;
                }
            for (j = 0; j < N_COMP; j++) {
                int before = l->in[j].log.n_messages;
                if (host_step(l->f[j], l->in[j].c, t, h) > HOST_WARNING) {
                    o.failed = k;
                    return o;
                }
                if (j == CTRL)
                    listen(l, c, advice, before, &o);
            }
            for (j = 0; j < N_COMP; j++)
                read_outputs(l, j);
        } else {
            for (j = 0; j < N_COMP; j++) {
                int comp = order[j], before = l->in[comp].log.n_messages;
                if (!write_inputs(l, comp, c, t)) {
                    o.refused_set = 1;
                    return o;
                }
                if (host_step(l->f[comp], l->in[comp].c, t, h) > HOST_WARNING) {
                    o.failed = k;
                    return o;
                }
                if (comp == CTRL)
                    listen(l, c, advice, before, &o);
                read_outputs(l, comp);
            }
        }
    }
    return o;
}

/* count the controller's warnings that contain words (the log keeps the last message; a step
 * logs at most a few) */
static int run_counting(loop *l, const fault_case *c, int n, const char *words, int *count)
{
    double h = ctrl.h;
    int k, j;
    *count = 0;
    for (k = 0; k < n; k++) {
        double t = k * h;
        for (j = 0; j < N_COMP; j++)
            if (!write_inputs(l, j, c, t))
                return k;
        for (j = 0; j < N_COMP; j++) {
            int before = l->in[j].log.n_messages;
            if (host_step(l->f[j], l->in[j].c, t, h) > HOST_WARNING)
                return k;
            if (j == CTRL && l->in[j].log.n_messages > before && strstr(l->in[j].log.last, words) != NULL
                && strstr(l->in[j].log.last, c->phrase) != NULL)
                *count += 1;
        }
        for (j = 0; j < N_COMP; j++)
            read_outputs(l, j);
    }
    return -1;
}

static void stop(loop *l)
{
    int j;
    for (j = 0; j < N_COMP; j++)
        host_free_instance(&l->in[j]);
}

/* start() with sup.reaction = 1 set on the controller as well */
static int start_safe(loop *l, const fault_case *c)
{
    safe_reaction = 1;
    return start(l, c);
}

/* The case under a schedule; returns the sample its doStep failed at (-1: none). */
static int check_case(const fault_case *c, int sequential)
{
    const char *schedule = sequential ? "Gauss-Seidel (plant, controller, reference)" : "exchange";
    const char *advice = sequential && c->advice_seq != NULL ? c->advice_seq : c->advice;
    const char *errors;
    int n = 4000;               /* 2 s of h = 0.5 ms, as the fault table */
    int status, delay, messages;
    double gain, after;
    outcome o;
    loop l;
    if (!check(start(&l, c), "%s, %s: the three FMUs start with the case's parameters", c->name, schedule)) {
        stop(&l);
        return -1;
    }
    o = run(&l, c, sequential, n);
    errors = l.in[CTRL].log.errors[0] ? l.in[CTRL].log.errors : "no error";
    messages = l.in[CTRL].log.n_messages;
    status = o.failed < 0 ? get_int(&ctrl, &l.in[CTRL], "sup.status") : -1;
    switch (c->expect) {
    case ERROR:
        /* the supervision's verdict, or the divergence monitor's for a loop no model explains */
        after = o.failed * ctrl.h - onset(c);
        check(!o.refused_set && o.failed >= 0 && after >= 0.0 && after < 1.0
                  && strstr(l.in[CTRL].log.errors, c->phrase) != NULL && strstr(l.in[CTRL].log.errors, advice) != NULL
                  && (strstr(l.in[CTRL].log.errors, "supervision stopped the loop") != NULL
                      || strstr(l.in[CTRL].log.errors, "the closed loop is unstable") != NULL),
              "%s, %s: %s fails %.1f ms after the fault's onset (t = %.4g s, within 1 s), saying \"%s\" and \"%s\" (%s)",
              c->name, schedule, FMI_NAME("DoStep"), 1e3 * after, o.failed * ctrl.h, c->phrase, advice, errors);
        break;
    case WARNING:
        check(!o.refused_set && o.failed < 0 && o.said == 1 && status == 2,
              "%s, %s: runs 2 s with one warning saying \"%s\" and \"%s\" (%d) and sup.status = 2 (%d)", c->name,
              schedule, c->phrase, advice, o.said, status);
        break;
    case VERIFIED:
        gain = get_real(&ctrl, &l.in[CTRL], "sup.gain");
        delay = get_int(&ctrl, &l.in[CTRL], "sup.delay");
        check(!o.refused_set && o.failed < 0 && messages == 0 && status == 1 && delay == (sequential ? 1 : 2)
                  && gain > 0.8 && gain < 1.6,
              "%s, %s: runs 2 s with no message from the controller (%d), verified (sup.status = %d) at the loop's "
              "delay %d (sup.delay = %d) and the mismatch plant's gain, 0.8 to 1.6 (sup.gain = %.4g)",
              c->name, schedule, messages, status, sequential ? 1 : 2, delay, gain);
        break;
    default:
        check(!o.refused_set && o.failed < 0 && l.in[CTRL].log.n_errors == 0 && status == 0,
              "%s, %s: runs 2 s without an error (open-loop use), sup.status = 0 (%d) (%s)", c->name, schedule,
              status, errors);
        break;
    }
    stop(&l);
    return o.failed;
}

/* The case with sup.reaction = 1, in the exchanging master (the Error's sample: error_at). */
static void check_case_safe(const fault_case *c, int error_at)
{
    int limit = (c->frequency < 1.0 ? 4000 : 2000) + 100, failed, said, code;
    double when, v_end;
    loop l;
    if (!check(start_safe(&l, c), "%s, safe: the three FMUs start with sup.reaction = 1", c->name)) {
        stop(&l);
        return;
    }
    failed = run_counting(&l, c, limit, "sup.reaction = safe", &said);
    code = get_int(&ctrl, &l.in[CTRL], "sup.fault");
    when = get_real(&ctrl, &l.in[CTRL], "sup.fault_time");
    v_end = get_real(&ctrl, &l.in[CTRL], "v");
    check(failed < 0 && said == 1 && code >= 1 && code <= 10 && when == error_at * ctrl.h && v_end == 0.0,
          "%s, safe: runs %.3g s without an error, one Warning \"sup.reaction = safe ... %s\" (%d), sup.fault = %d, "
          "sup.fault_time = %.9g s (the Error's %.9g s), v = %g V at the end (%s)", c->name, limit * ctrl.h,
          c->phrase, said, code, when, error_at * ctrl.h, v_end,
          l.in[CTRL].log.errors[0] ? l.in[CTRL].log.errors : "no error");
    stop(&l);
}

int main(int argc, char **argv)
{
    size_t i;
    if (argc != 7) {
        fprintf(stderr, "usage: %s PiezoStage.xml PiezoStage.so AdaptiveCompoundController.xml "
                        "AdaptiveCompoundController.so ReferenceSignal.xml ReferenceSignal.so\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (!host_load(&plant, argv[1], argv[2]) || !host_load(&ctrl, argv[3], argv[4]) || !host_load(&ref, argv[5], argv[6]))
        return 2;
    for (i = 0; i < sizeof CASES / sizeof CASES[0]; i++) {
        if (CASES[i].schedules & EXCHANGE) {
            int error_at = check_case(&CASES[i], 0);
            if (CASES[i].expect == ERROR && error_at >= 0)
                check_case_safe(&CASES[i], error_at);
        }
        if (CASES[i].schedules & SEQUENTIAL)
            check_case(&CASES[i], 1);
    }
    host_unload(&plant);
    host_unload(&ctrl);
    host_unload(&ref);
    return host_summary();
}
