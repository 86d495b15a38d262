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
 * numerator x1.05 with the fast pole at 0.45, a 2 nm / 1 nm sensor), the
 * reference a 10 um tone. Two schedules: values exchanged at communication
 * points (read every output, set every input, step every FMU: loop delay 2),
 * and true Gauss-Seidel in the order plant, controller, reference (each FMU
 * gets the others' latest outputs: loop delay 1).
 *
 * One case per fault of the table, each with what the controller must say: an
 * Error from its doStep within 1 s of simulated time whose message names the
 * signal at fault (the phrase checked; the supervision's, or the divergence
 * monitor's for a loop no model explains), or, for a degraded loop, a Warning
 * once and sup.status = 2. The sound loop must run 2 s without an Error or a
 * supervision warning and end verified (sup.status = 1), and the supervision
 * switched off for open-loop use (sup.enabled = false, with the divergence
 * monitor off: monitor.divergence_samples = 0) must let an open loop run.
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
enum { F_NONE, F_CONSTANT, F_STUCK, F_SCALE, F_OPEN, F_SWAP, F_ALTERNATE };

/* what one input receives instead of its connection's value */
typedef struct {
    const char *input;          /* the controller's or the plant's input */
    int kind;
    double value;               /* the constant or the factor */
} fault;

typedef struct {
    const char *name;
    fault faults[2];
    const char *plant_param;    /* a plant parameter set for the case (NULL: none) */
    double plant_value;
    const char *ctrl_param;     /* a controller parameter */
    double ctrl_value;
    double frequency, amplitude;    /* the reference tone */
    int expect;                 /* 0 an Error, 1 a warning (sup.status 2), 2 nothing (sup.status 1),
                                   3 no Error (supervision off) */
    const char *phrase;         /* in the Error's or the warning's message */
} fault_case;

/* the mismatch plant of docs/model.md */
static const struct { const char *name; double value; } MISMATCH[] = {
    {"pi.w0", 0.36784}, {"pi.w[1]", 0.07854}, {"pi.w[2]", 0.03542}, {"pi.w[3]", 0.00792},
    {"creep.k_c", 1.0497}, {"creep.alpha", -0.0085}, {"tf.a1", -1.442037}, {"tf.a2", 0.44641665},
    {"tf.b1", 0.62517}, {"tf.b2", -0.620235}, {"sensor.resolution", 0.002}, {"sensor.noise_rms", 0.001},
};

static const fault_case CASES[] = {
    {"sound loop", {{NULL, F_NONE, 0}}, NULL, 0, NULL, 0, 5.0, 10.0, 2, NULL},
    {"y_meas not connected (0)", {{"y_meas", F_CONSTANT, 0.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0,
     "y_meas has not changed at all"},
    {"y_meas stuck at its first value", {{"y_meas", F_STUCK, 0.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0,
     "y_meas does not follow v"},
    {"y_meas inverted", {{"y_meas", F_SCALE, -1.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0, "y_meas moves against v"},
    {"y_meas in mm", {{"y_meas", F_SCALE, 1e-3}}, NULL, 0, NULL, 0, 5.0, 10.0, 0, "in mm instead of um"},
    {"y_meas in nm", {{"y_meas", F_SCALE, 1e3}}, NULL, 0, NULL, 0, 5.0, 10.0, 0, "in nm instead of um"},
    {"v not reaching the plant (0)", {{"v", F_CONSTANT, 0.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0,
     "y_meas does not follow v"},
    {"v inverted", {{"v", F_SCALE, -1.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0, "y_meas moves against v"},
    {"amplifier gain 0.1", {{"v", F_SCALE, 0.1}}, NULL, 0, NULL, 0, 5.0, 10.0, 0, "y_meas does not follow v"},
    {"amplifier gain 10", {{"v", F_SCALE, 10.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0, "gain is far above the model's"},
    {"y_meas alternating +-10 um", {{"y_meas", F_ALTERNATE, 10.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0,
     "the closed loop is unstable"},
    {"y_ref and y_meas swapped", {{"y_meas", F_SWAP, 0.0}, {"y_ref", F_SWAP, 0.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 0,
     "y_meas and y_ref are swapped"},
    {"plant input delay of 4 samples", {{NULL, F_NONE, 0}}, "tf.delay", 4.0, NULL, 0, 5.0, 10.0, 0,
     "Set mv.delay ="},
    {"mv.delay set one sample short", {{NULL, F_NONE, 0}}, NULL, 0, "mv.delay", -2.0, 5.0, 10.0, 0,
     "Set mv.delay ="},
    {"reference beyond the actuator's reach", {{NULL, F_NONE, 0}}, NULL, 0, NULL, 0, 0.25, 500.0, 0,
     "the reference asks for more than the stage reaches"},
    {"t_meas not connected", {{"t_meas", F_OPEN, 0.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 1, "t_meas is not connected"},
    {"t_preview not connected", {{"t_preview", F_OPEN, 0.0}}, NULL, 0, NULL, 0, 5.0, 10.0, 1,
     "t_preview is not connected"},
    {"supervision off, y_meas not connected", {{"y_meas", F_CONSTANT, 0.0}}, NULL, 0, "sup.enabled", 0.0, 5.0,
     10.0, 3, NULL},
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

static double get_real(const host_fmu *f, host_inst *in, const char *name)
{
    const host_var *v = host_named(f, name, NULL);
    host_vr vr = (host_vr)v->vr;
    double x = NAN;
    host_get_reals(f, in->c, &vr, 1, &x, 1);
    return x;
}

static int get_int(const host_fmu *f, host_inst *in, const char *name)
{
    const host_var *v = host_named(f, name, NULL);
    host_vr vr = (host_vr)v->vr;
    host_int x = -1;
    host_get_ints(f, in->c, &vr, 1, &x, 1);
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

/* set component comp's inputs from the links into it, through the case's faults */
static void write_inputs(loop *l, int comp, const fault_case *c)
{
    int i;
    for (i = 0; i < N_LINKS; i++) {
        const fault *ft;
        double x;
        if (LINKS[i].dst != comp)
            continue;
        x = l->out[i];
        ft = fault_of(c, LINKS[i].in);
        if (ft != NULL) {
            if (ft->kind == F_OPEN)
                continue;               /* never set: the input keeps its start value */
            if (ft->kind == F_CONSTANT)
                x = ft->value;
            else if (ft->kind == F_SCALE)
                x *= ft->value;
            else if (ft->kind == F_STUCK)
                x = l->have_first[i] ? l->first[i] : x;
            else if (ft->kind == F_SWAP)    /* y_meas <- the reference's y_ref and the other way round */
                x = l->out[strcmp(LINKS[i].in, "y_meas") == 0 ? 0 : 3];
            else if (ft->kind == F_ALTERNATE)   /* +-value, whatever v does */
                x = l->alternate++ % 2 ? -ft->value : ft->value;
        }
        if (!l->have_first[i]) {
            l->first[i] = x;
            l->have_first[i] = 1;
        }
        host_set_named(l->f[comp], l->in[comp].c, LINKS[i].in, x);
    }
}

/* start the three FMUs with the case's parameters (0 on failure) */
static int start(loop *l, const fault_case *c)
{
    static const char *names[N_COMP] = {"reference", "controller", "plant"};
    size_t i;
    int j;
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
        host_set_named(&plant, l->in[PLANT].c, MISMATCH[i].name, MISMATCH[i].value);
    if (c->plant_param != NULL)
        host_set_named(&plant, l->in[PLANT].c, c->plant_param, c->plant_value);
    /* mv.delay -2 stands for "one sample short of the exchanging master's d = 2": 0 */
    if (c->ctrl_param != NULL)
        host_set_named(&ctrl, l->in[CTRL].c, c->ctrl_param,
                       strcmp(c->ctrl_param, "mv.delay") == 0 && c->ctrl_value < -1.5 ? 0.0 : c->ctrl_value);
    /* open-loop use switches the divergence monitor off too */
    if (c->ctrl_param != NULL && strcmp(c->ctrl_param, "sup.enabled") == 0)
        host_set_named(&ctrl, l->in[CTRL].c, "monitor.divergence_samples", 0.0);
    host_set_named(&ref, l->in[REF].c, "frequency[1]", c->frequency);
    host_set_named(&ref, l->in[REF].c, "amplitude[1]", c->amplitude);
    if (safe_reaction)
        host_set_named(&ctrl, l->in[CTRL].c, "sup.reaction", 1.0);
    safe_reaction = 0;
    for (j = 0; j < N_COMP; j++)
        if (l->f[j]->api.ExitInitializationMode(l->in[j].c) != HOST_OK)
            return 0;
    for (j = 0; j < N_COMP; j++)
        read_outputs(l, j);
    return 1;
}

/* Run the case under a schedule (0: exchange, 1: plant, controller, reference) for
 * n samples or until a doStep fails; returns the sample of the failure or -1. *said:
 * whether a controller warning contained the case's phrase. */
static int run(loop *l, const fault_case *c, int sequential, int n, int *said)
{
    static const int order[N_COMP] = {PLANT, CTRL, REF};
    double h = ctrl.h;
    int k, j;
    *said = 0;
    for (k = 0; k < n; k++) {
        double t = k * h;
        if (!sequential) {
            for (j = 0; j < N_COMP; j++)
                write_inputs(l, j, c);
            for (j = 0; j < N_COMP; j++) {
                int before = l->in[j].log.n_messages;
                if (host_step(l->f[j], l->in[j].c, t, h) > HOST_WARNING)
                    return k;
                if (j == CTRL && c->phrase != NULL && l->in[j].log.n_messages > before
                    && strstr(l->in[j].log.last, c->phrase) != NULL)
                    *said = 1;
            }
            for (j = 0; j < N_COMP; j++)
                read_outputs(l, j);
        } else {
            for (j = 0; j < N_COMP; j++) {
                int comp = order[j], before = l->in[comp].log.n_messages;
                write_inputs(l, comp, c);
                if (host_step(l->f[comp], l->in[comp].c, t, h) > HOST_WARNING)
                    return k;
                if (comp == CTRL && c->phrase != NULL && l->in[comp].log.n_messages > before
                    && strstr(l->in[comp].log.last, c->phrase) != NULL)
                    *said = 1;
                read_outputs(l, comp);
            }
        }
    }
    return -1;
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
            write_inputs(l, j, c);
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
    /* the reference beyond reach needs its excursion: the clipping watchdog's 0.5 s plus the ramp */
    int limit = c->frequency < 1.0 ? 4000 : 2000;      /* samples of h = 0.5 ms */
    int n = c->expect == 0 ? limit : 4000, failed, said, status;
    loop l;
    if (!check(start(&l, c), "%s, %s: the three FMUs start", c->name, schedule)) {
        stop(&l);
        return -1;
    }
    failed = run(&l, c, sequential, n, &said);
    status = failed < 0 ? get_int(&ctrl, &l.in[CTRL], "sup.status") : -1;
    switch (c->expect) {
    case 0:
        /* the supervision's verdict, or the divergence monitor's for a loop no model explains */
        check(failed >= 0 && strstr(l.in[CTRL].log.errors, c->phrase) != NULL
                  && (strstr(l.in[CTRL].log.errors, "supervision stopped the loop") != NULL
                      || strstr(l.in[CTRL].log.errors, "the closed loop is unstable") != NULL),
              "%s, %s: %s fails at t = %.4g s (within %.3g s), saying \"%s\" (%s)", c->name, schedule,
              FMI_NAME("DoStep"), failed * ctrl.h, limit * ctrl.h, c->phrase,
              l.in[CTRL].log.errors[0] ? l.in[CTRL].log.errors : "no error");
        break;
    case 1:
        check(failed < 0 && said && status == 2,
              "%s, %s: runs 2 s with a warning saying \"%s\" and sup.status = 2 (%d)", c->name, schedule,
              c->phrase, status);
        break;
    case 2:
        check(failed < 0 && status == 1 && get_real(&ctrl, &l.in[CTRL], "sup.gain") > 0.25,
              "%s, %s: runs 2 s without an error, verified (sup.status = %d, sup.gain = %.4g, sup.delay = %d)",
              c->name, schedule, status, get_real(&ctrl, &l.in[CTRL], "sup.gain"),
              get_int(&ctrl, &l.in[CTRL], "sup.delay"));
        break;
    default:
        check(failed < 0 && l.in[CTRL].log.n_errors == 0,
              "%s, %s: runs 2 s without an error (open-loop use) (%s)", c->name, schedule,
              l.in[CTRL].log.errors[0] ? l.in[CTRL].log.errors : "no error");
        break;
    }
    stop(&l);
    return failed;
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
        /* the stamps are judged where the loop needs them, in a sequential master; there
         * mv.delay = 0 is right */
        if (CASES[i].expect != 1) {
            int error_at = check_case(&CASES[i], 0);
            if (CASES[i].expect == 0 && error_at >= 0)
                check_case_safe(&CASES[i], error_at);
        }
        if (CASES[i].ctrl_param == NULL || strcmp(CASES[i].ctrl_param, "mv.delay") != 0)
            check_case(&CASES[i], 1);
    }
    host_unload(&plant);
    host_unload(&ctrl);
    host_unload(&ref);
    return host_summary();
}
