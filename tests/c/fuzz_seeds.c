/*
 * fuzz_seeds.c - writes the seed corpora of the fuzz targets of the FMU it is
 * compiled with: real serialized states (every mode: Instantiated,
 * InitializationMode, StepComplete at several times, exact-mode creep where the
 * FMU has it, feedthrough and time-stamped inputs (a chosen loop delay, a filled
 * preview ring) where it has them, Terminated, Error) for
 * fuzz_deserialize, and programs for fuzz_run (defaults, each parameter nudged,
 * exact creep, state round trips and restores).
 *
 * usage: fuzz_seeds DIR   (writes DIR/deserialize/ and DIR/run/, which must exist)
 */
#include <stdio.h>

#include "fuzz_common.h"

static const char *out_dir;
static int n_written;

static void write_seed(const char *kind, const char *name, const void *data, size_t size)
{
    char path[4096];
    FILE *f;
    snprintf(path, sizeof path, "%s/%s/%s.bin", out_dir, kind, name);
    f = fopen(path, "wb");
    if (f == NULL || fwrite(data, 1, size, f) != size) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(1);
    }
    fclose(f);
    n_written++;
}

static int vr_named(const char *name)
{
    int vr;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++)
        if (strcmp(model_variables[vr].name, name) == 0)
            return vr;
    return -1;
}

static void set_named(fmi2Component c, const char *name, double value)
{
    int vr = vr_named(name);
    fmi2ValueReference ref = (fmi2ValueReference)vr;
    if (vr < 0)
        return;
    if (model_variables[vr].type == MODEL_REAL)
        fmi2SetReal(c, &ref, 1, &value);
    else if (model_variables[vr].type == MODEL_INTEGER) {
        fmi2Integer i = (fmi2Integer)value;
        fmi2SetInteger(c, &ref, 1, &i);
    } else {
        fmi2Boolean b = value != 0.0;
        fmi2SetBoolean(c, &ref, 1, &b);
    }
}

static void set_inputs(fmi2Component c, int k, double h)
{
    int vr, j = 0;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++)
        if (model_variables[vr].causality == MODEL_INPUT) {
            double u = 3.0 * sin(2.0 * 3.14159265358979323846 * (5.0 + j) * k * h) + 2.0 + j;
            fmi2ValueReference ref = (fmi2ValueReference)vr;
            fmi2SetReal(c, &ref, 1, &u);
            j++;
        }
}

static void save_state(fmi2Component c, const char *name, unsigned force_mode)
{
    fmi2FMUstate s = NULL;
    size_t size = 0;
    uint8_t *blob;
    if (fmi2GetFMUstate(c, &s) != fmi2OK || fmi2SerializedFMUstateSize(c, s, &size) != fmi2OK)
        exit(1);
    blob = (uint8_t *)malloc(size);
    if (blob == NULL || fmi2SerializeFMUstate(c, s, (fmi2Byte *)blob, size) != fmi2OK)
        exit(1);
    if (force_mode != 0) {
        blob[BLOB_OFF_MODE] = (uint8_t)force_mode;
        blob_reseal(blob, size);
    }
    write_seed("deserialize", name, blob, size);
    if (strcmp(name, "step300") == 0) {
        /* the header alone, with the checksum after it: a truncated real state */
        char header_name[64];
        memcpy(blob + BLOB_HEADER, blob + size - 8, 8);
        snprintf(header_name, sizeof header_name, "%s_header_only", name);
        write_seed("deserialize", header_name, blob, BLOB_HEADER + 8u);
    }
    free(blob);
    fmi2FreeFMUstate(c, &s);
}

static int stamped;   /* run(): set the time stamp inputs t_meas, t_preview as a master would */
static int supervised;   /* run(): keep a controller's supervision and monitor on */

/* A controller driven here open loop: its inputs are synthetic sines, a y_meas that does not
 * answer v, which its supervision and divergence monitor rightly stop within 15 to 100 ms;
 * the seeds switch both off, as the tests that drive it open loop do, but for one short run. */
static int open_loop_controller(void)
{
    int vr = vr_named("y_meas");
    return vr >= 0 && model_variables[vr].causality == MODEL_INPUT && vr_named("sup.enabled") >= 0;
}

/* An instance initialized with up to two named parameters, stepped n samples. */
static fmi2Component run(const char *p1, double v1, const char *p2, double v2, int n)
{
    fmi2CallbackFunctions cb = fuzz_callbacks();
    fmi2Component c = fmi2Instantiate("seed", fmi2CoSimulation, MODEL_GUID, "", &cb, fmi2False, fmi2False);
    double h = 0.0;
    fmi2ValueReference h_ref = (fmi2ValueReference)vr_named("h");
    int k;
    fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    fmi2EnterInitializationMode(c);
    if (open_loop_controller() && !supervised) {
        set_named(c, "sup.enabled", 0);
        set_named(c, "monitor.divergence_samples", 0);
    }
    if (p1)
        set_named(c, p1, v1);
    if (p2)
        set_named(c, p2, v2);
    if (fmi2ExitInitializationMode(c) != fmi2OK)
        exit(1);
    fmi2GetReal(c, &h_ref, 1, &h);
    for (k = 0; k < n; k++) {
        set_inputs(c, k, h);
        if (stamped) {
            /* the controller's time stamps as a master wires them: the measurement of
             * t_k, the stamped preview 4 samples ahead */
            set_named(c, "t_meas", k * h);
            set_named(c, "t_preview", (k + 4) * h);
        }
        if (fmi2DoStep(c, k * h, h, fmi2True) > fmi2Warning)
            exit(1);
    }
    return c;
}

/* The seed `name`: the state after run(p1, v1, p2, v2, n), the instance freed after. */
static void run_seed(const char *name, const char *p1, double v1, const char *p2, double v2, int n)
{
    fmi2Component c = run(p1, v1, p2, v2, n);
    save_state(c, name, 0);
    fmi2FreeInstance(c);
}

static void deserialize_seeds(void)
{
    fmi2CallbackFunctions cb = fuzz_callbacks();
    fmi2Component c = fmi2Instantiate("seed", fmi2CoSimulation, MODEL_GUID, "", &cb, fmi2False, fmi2False);
    save_state(c, "instantiated", 0);
    fmi2SetupExperiment(c, fmi2False, 0.0, 1.25, fmi2False, 0.0);
    fmi2EnterInitializationMode(c);
    save_state(c, "initialization", 0);
    fmi2FreeInstance(c);

    run_seed("step0", NULL, 0, NULL, 0, 0);
    c = run(NULL, 0, NULL, 0, 300);
    save_state(c, "step300", 0);
    fmi2Terminate(c);
    save_state(c, "terminated", 0);
    fmi2FreeInstance(c);
    c = run(NULL, 0, NULL, 0, 40);
    save_state(c, "error", 16);   /* a state saved in Error has this model data */
    fmi2FreeInstance(c);
    if (vr_named("creep.exact") >= 0)
        run_seed("exact64", "creep.exact", 1, NULL, 0, 64);
    if (vr_named("sensor.noise_rms") >= 0)
        run_seed("sensor100", "sensor.noise_rms", 0.001, "sensor.resolution", 0.002, 100);
    if (vr_named("mv.feedthrough") >= 0)
        run_seed("feedthrough100", "mv.feedthrough", 1, "mv.delay", 0, 100);
    if (vr_named("t_preview") >= 0) {
        stamped = 1;
        run_seed("stamped300", NULL, 0, NULL, 0, 300);
        stamped = 0;
    }
    if (open_loop_controller()) {
        /* the supervisor's and the monitor's sums filled, before a verdict can come
         * (PIEZO_SUP_MIN_SAMPLES + PIEZO_SUP_CONFIRM samples, a quarter of the monitor's window) */
        supervised = 1;
        run_seed("supervised25", NULL, 0, NULL, 0, 25);
        supervised = 0;
    }
    if (vr_named("amplitude[1]") >= 0)
        run_seed("tone100", "amplitude[1]", 5, "frequency[1]", 10, 100);
}

/* fuzz_run programs */
typedef struct {
    uint8_t bytes[4096];
    size_t n;
} program;

static void put(program *p, uint8_t b)
{
    if (p->n < sizeof p->bytes)
        p->bytes[p->n++] = b;
}

static void put_value(program *p, uint8_t kind, uint64_t bits)
{
    int i;
    put(p, kind);
    for (i = 0; i < 8; i++)
        put(p, (uint8_t)(bits >> (8 * i)));
}

static int param_index(const char *name)
{
    int vr, i = 0;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++) {
        if (model_variables[vr].causality != MODEL_PARAMETER)
            continue;
        if (strcmp(model_variables[vr].name, name) == 0)
            return i;
        i++;
    }
    return -1;
}

static int count(model_causality causality)
{
    int vr, n = 0;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++)
        n += model_variables[vr].causality == causality;
    return n;
}

/* steps of `samples` samples each with the inputs at k-dependent small values */
static void put_steps(program *p, int n_ops, int samples)
{
    int i, j, n_inputs = count(MODEL_INPUT);
    for (i = 0; i < n_ops; i++) {
        put(p, (uint8_t)(8 * samples));   /* op % 8 == 0: set inputs, then step */
        for (j = 0; j < n_inputs; j++)
            put_value(p, 2, (uint64_t)(uint16_t)(int16_t)(64.0 * 3.0 * sin(0.3 * i + j)));
    }
}

static void run_seeds(void)
{
    program p;
    char name[64];
    int i, n_params = count(MODEL_PARAMETER);

    memset(&p, 0, sizeof p);
    put(&p, 0);
    put_steps(&p, 120, 1);
    write_seed("run", "defaults", p.bytes, p.n);

    memset(&p, 0, sizeof p);
    put(&p, 0);
    put_steps(&p, 40, 3);
    put(&p, 6);                 /* round trip */
    put(&p, 7);                 /* save */
    put_steps(&p, 20, 2);
    put(&p, 7);                 /* restore */
    put_steps(&p, 20, 1);
    write_seed("run", "states", p.bytes, p.n);

    if (param_index("creep.exact") >= 0) {
        memset(&p, 0, sizeof p);
        put(&p, 1);
        put(&p, (uint8_t)param_index("creep.exact"));
        put_value(&p, 2, 1);
        put_steps(&p, 60, 2);
        put(&p, 6);
        write_seed("run", "exact", p.bytes, p.n);
    }
    /* each parameter nudged from its start value (kind 1: start x 2^(1/16)) */
    for (i = 0; i < n_params; i++) {
        memset(&p, 0, sizeof p);
        put(&p, 1 | (uint8_t)(32 * (i % 8)));
        put(&p, (uint8_t)i);
        put_value(&p, 1, 1);
        put_steps(&p, 30, 1);
        snprintf(name, sizeof name, "param%02d", i);
        write_seed("run", name, p.bytes, p.n);
    }
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s DIR\n", argv[0]);
        return 2;
    }
    out_dir = argv[1];
    deserialize_seeds();
    run_seeds();
    printf("%s: %d seeds written to %s\n", MODEL_IDENTIFIER_STRING, n_written, out_dir);
    return 0;
}
