/*
 * fmu_regressions.c - one check per defect of issue 9 (an independent abuse
 * test of the FMUs), each written to fail on the code before its fix:
 *
 *   1  fmi2DeSerializeFMUstate read past the caller's buffer: its size check
 *      wrapped modulo 2^64 (the blob here ends at a PROT_NONE page, so an
 *      over-read is a SIGSEGV even without a sanitizer)
 *   2  header and counter fields of a blob were not cross-checked (exact-mode
 *      counter >= 2^63, k = 2^64-1, h = 5e-324, NaN held input, reserved field)
 *   3  stopTime of fmi2SetupExperiment must be enforced
 *   4  Inf outputs returned with fmi2OK from finite inputs and accepted parameters
 *   5  FMU states still allocated at fmi2FreeInstance leaked
 *   6  one FMU's functions accepted another FMU's instance (heap corruption)
 *   7  fmi2GetFMUstate was refused in the Error state
 *   8  a NULL logger was accepted silently (now refused at fmi2Instantiate)
 *
 * usage: fmu_regressions [--defect N] PiezoStage.xml PiezoStage.so
 *            AdaptiveCompoundController.xml AdaptiveCompoundController.so
 *            ReferenceSignal.xml ReferenceSignal.so
 * Prints one line per check and "N passed, M failed"; exit code 1 on failure.
 */
#include "fmu_host.h"

#include <float.h>
#include <sys/mman.h>
#include <unistd.h>

static host_fmu plant, ctrl, ref;

/* A blob of `size` bytes placed so that its last byte is the last byte before a
 * PROT_NONE page: reading one byte past it faults. */
typedef struct {
    unsigned char *pages;
    size_t pages_size;
    unsigned char *blob;
} guarded_blob;

static int guarded_alloc(guarded_blob *g, size_t size)
{
    size_t page = (size_t)sysconf(_SC_PAGESIZE);
    size_t data_pages = (size + page - 1) / page;
    g->pages_size = (data_pages + 1) * page;
    g->pages = mmap(NULL, g->pages_size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (g->pages == MAP_FAILED)
        return 0;
    if (mprotect(g->pages + data_pages * page, page, PROT_NONE) != 0)
        return 0;
    g->blob = g->pages + data_pages * page - size;
    return 1;
}

static void guarded_free(guarded_blob *g)
{
    munmap(g->pages, g->pages_size);
}

/* A serialized StepComplete state of f after n samples with its inputs at `input`. */
static unsigned char *saved_blob(const host_fmu *f, const fmi2CallbackFunctions *cb, const char *param,
                                 double value, int n, double input, size_t *size)
{
    fmi2Component c = f->api.Instantiate("saved", fmi2CoSimulation, f->guid, "", cb, fmi2False, fmi2False);
    unsigned char *blob = NULL;
    int i, k;
    if (c == NULL)
        return NULL;
    f->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    f->api.EnterInitializationMode(c);
    if (param != NULL)
        host_set_named(f, c, param, value);
    if (f->api.ExitInitializationMode(c) == fmi2OK) {
        for (i = 0; i < f->n_vars; i++)
            if (f->vars[i].causality == VAR_INPUT)
                host_set(f, c, &f->vars[i], input);
        for (k = 0; k < n; k++)
            if (f->api.DoStep(c, k * f->h, f->h, fmi2True) > fmi2Warning)
                break;
        blob = host_snapshot(f, c, size);
    }
    f->api.FreeInstance(c);
    return blob;
}

/* Offsets (8-byte aligned, inside the ModelData image) whose 8 bytes equal `pattern`. */
static int find_in_model_data(const unsigned char *blob, size_t size, const void *pattern, size_t *offsets, int max)
{
    size_t data_size = (size_t)blob_get_u64(blob + BLOB_OFF_DATA_SIZE), off;
    int n = 0;
    for (off = BLOB_HEADER; off + 8 <= BLOB_HEADER + data_size && off + 8 <= size && n < max; off += 8)
        if (memcmp(blob + off, pattern, 8) == 0)
            offsets[n++] = off;
    return n;
}

/* fmi2DeSerializeFMUstate of a tampered copy (resealed: size field and checksum) into a fresh instance. */
static fmi2Status deserialize_tampered(const host_fmu *f, const fmi2CallbackFunctions *cb, const unsigned char *blob,
                                       size_t size, size_t offset, const void *bytes, size_t n)
{
    unsigned char *copy = malloc(size);
    fmi2Component c = f->api.Instantiate("tampered", fmi2CoSimulation, f->guid, "", cb, fmi2False, fmi2False);
    fmi2FMUstate s = NULL;
    fmi2Status status = fmi2Fatal;
    if (copy != NULL && c != NULL) {
        memcpy(copy, blob, size);
        memcpy(copy + offset, bytes, n);
        blob_reseal(copy, size);
        status = f->api.DeSerializeFMUstate(c, (const fmi2Byte *)copy, size, &s);
        if (s != NULL)
            f->api.FreeFMUstate(c, &s);
    }
    if (c != NULL)
        f->api.FreeInstance(c);
    free(copy);
    return status;
}

static void defect1_size_wrap(const host_fmu *f)
{
    host_log log;
    fmi2CallbackFunctions cb;
    size_t size, data_size;
    unsigned char *blob;
    guarded_blob g;
    fmi2Component c;
    fmi2FMUstate s = NULL;
    fmi2Status status;
    uint64_t n_history;

    host_log_clear(&log);
    cb = host_callbacks(&log);
    blob = saved_blob(f, &cb, NULL, 0.0, 5, 0.5, &size);
    if (!check(blob != NULL, "defect 1 %s: a real blob to start from", f->id))
        return;
    /* header + checksum only: 136 bytes. n_history chosen so that
     * 136 + sizeof(ModelData) + 8 n_history wraps to 136 */
    data_size = (size_t)blob_get_u64(blob + BLOB_OFF_DATA_SIZE);
    n_history = (0 - (uint64_t)data_size) / 8u;
    if (!guarded_alloc(&g, BLOB_HEADER + 8u)) {
        check(0, "defect 1 %s: guard page", f->id);
        free(blob);
        return;
    }
    memcpy(g.blob, blob, BLOB_HEADER);
    blob_put_u64(g.blob + BLOB_OFF_N_HISTORY, n_history);
    blob_reseal(g.blob, BLOB_HEADER + 8u);
    c = f->api.Instantiate("wrap", fmi2CoSimulation, f->guid, "", &cb, fmi2False, fmi2False);
    status = f->api.DeSerializeFMUstate(c, (const fmi2Byte *)g.blob, BLOB_HEADER + 8u, &s);
    check(status == fmi2Error && s == NULL && strstr(log.last_error, "history length") != NULL,
          "defect 1 %s: a 136-byte blob claiming n_history = 2^64/8 - %llu (sizes wrap to 136) is refused "
          "without reading past it (%s)", f->id, (unsigned long long)(data_size / 8u), log.last_error);
    if (s != NULL)
        f->api.FreeFMUstate(c, &s);
    f->api.FreeInstance(c);
    guarded_free(&g);
    free(blob);
}

static void defect2_header_and_counters(const host_fmu *f, int exact)
{
    host_log log;
    fmi2CallbackFunctions cb;
    size_t size, offsets[8];
    unsigned char *blob, bytes[8];
    const int n_steps = 1237;     /* a counter value that appears nowhere else in the image */
    uint64_t counter = (uint64_t)n_steps, huge;
    double held = 0.00123456789, nan_value = NAN;  /* small: the controller's monitor stays quiet */
    int n_found, i;

    host_log_clear(&log);
    cb = host_callbacks(&log);
    blob = saved_blob(f, &cb, exact ? "creep.exact" : NULL, 1.0, n_steps, held, &size);
    if (!check(blob != NULL, "defect 2 %s: a real blob to start from", f->id))
        return;
    check(deserialize_tampered(f, &cb, blob, size, 0, blob, 0) == fmi2OK,
          "defect 2 %s: the untampered blob (resealed) is accepted", f->id);

    /* every sample counter inside the model data (e.g. the exact-mode creep
     * counter k): 2^63 + k makes 2 (k + 1) wrap to the stored history length */
    n_found = find_in_model_data(blob, size, &counter, offsets, 8);
    check(n_found >= 1, "defect 2 %s: sample counters found in the model data (%d)", f->id, n_found);
    huge = counter + (1ull << 63);
    for (i = 0; i < n_found; i++)
        check(deserialize_tampered(f, &cb, blob, size, offsets[i], &huge, 8) == fmi2Error,
              "defect 2 %s: a counter of 2^63 + %d at model-data byte %llu is refused (%s)", f->id, n_steps,
              (unsigned long long)(offsets[i] - BLOB_HEADER), log.last_error);

    blob_put_u64(bytes, UINT64_MAX);
    check(deserialize_tampered(f, &cb, blob, size, BLOB_OFF_K, bytes, 8) == fmi2Error,
          "defect 2 %s: header k = 2^64 - 1 is refused (%s)", f->id, log.last_error);
    blob_put_u64(bytes, counter + 1);
    check(deserialize_tampered(f, &cb, blob, size, BLOB_OFF_K, bytes, 8) == fmi2Error,
          "defect 2 %s: header k one off the model's counter is refused (%s)", f->id, log.last_error);
    blob_put_f64(bytes, 4.9406564584124654e-324);
    check(deserialize_tampered(f, &cb, blob, size, BLOB_OFF_H, bytes, 8) == fmi2Error,
          "defect 2 %s: h = 5e-324 is refused (%s)", f->id, log.last_error);
    blob_put_f64(bytes, NAN);
    check(deserialize_tampered(f, &cb, blob, size, BLOB_OFF_T0, bytes, 8) == fmi2Error,
          "defect 2 %s: t0 = NaN is refused (%s)", f->id, log.last_error);
    blob_put_u64(bytes, 1);
    check(deserialize_tampered(f, &cb, blob, size, BLOB_OFF_RESERVED, bytes, 8) == fmi2Error,
          "defect 2 %s: a non-zero reserved field is refused (%s)", f->id, log.last_error);
    bytes[0] = 32; bytes[1] = bytes[2] = bytes[3] = 0;
    check(deserialize_tampered(f, &cb, blob, size, BLOB_OFF_MODE, bytes, 4) == fmi2Error,
          "defect 2 %s: mode 32 is refused (%s)", f->id, log.last_error);
    /* the held input (only models with inputs hold one) */
    n_found = find_in_model_data(blob, size, &held, offsets, 8);
    for (i = 0; i < n_found; i++)
        check(deserialize_tampered(f, &cb, blob, size, offsets[i], &nan_value, 8) == fmi2Error,
              "defect 2 %s: a NaN in place of the held input %g (model-data byte %llu) is refused (%s)", f->id,
              held, (unsigned long long)(offsets[i] - BLOB_HEADER), log.last_error);
    free(blob);
}

static void defect3_stop_time(const host_fmu *f)
{
    host_log log;
    fmi2CallbackFunctions cb = host_callbacks(&log);
    fmi2Component c;
    host_log_clear(&log);
    c = f->api.Instantiate("stop", fmi2CoSimulation, f->guid, "", &cb, fmi2False, fmi2False);
    host_hold_inputs(f, c);
    f->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, 10 * f->h);
    f->api.EnterInitializationMode(c);
    f->api.ExitInitializationMode(c);
    check(f->api.DoStep(c, 0.0, 10 * f->h, fmi2True) <= fmi2Warning, "defect 3 %s: a step to stopTime passes", f->id);
    check(f->api.DoStep(c, 10 * f->h, f->h, fmi2True) == fmi2Error && strstr(log.last_error, "stopTime") != NULL,
          "defect 3 %s: a step past stopTime is refused (%s)", f->id, log.last_error);
    f->api.FreeInstance(c);
}

/* Runs n steps from a fresh instance with param = value and every input at
 * `input`; 1 when no step returned fmi2OK/fmi2Warning with a non-finite output
 * (*refused: ExitInitializationMode or a step said fmi2Error). */
static int finite_or_refused2(const host_fmu *f, const char *param, double value, const char *param2,
                              double value2, double input, double input2, int n, int *refused, host_log *log)
{
    fmi2CallbackFunctions cb = host_callbacks(log);
    fmi2Component c;
    double out[32];
    int k, i, n_out, ok = 1, first_input = 1;
    host_log_clear(log);
    *refused = 0;
    c = f->api.Instantiate("inf", fmi2CoSimulation, f->guid, "", &cb, fmi2False, fmi2False);
    f->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    f->api.EnterInitializationMode(c);
    if (param != NULL)
        host_set_named(f, c, param, value);
    if (param2 != NULL)
        host_set_named(f, c, param2, value2);
    if (f->api.ExitInitializationMode(c) != fmi2OK) {
        *refused = 1;
        f->api.FreeInstance(c);
        return 1;
    }
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].causality == VAR_INPUT) {
            host_set(f, c, &f->vars[i], first_input ? input : input2);
            first_input = 0;
        }
    for (k = 0; k < n; k++) {
        fmi2Status st = f->api.DoStep(c, k * f->h, f->h, fmi2True);
        if (st == fmi2Error) {
            *refused = 1;
            break;
        }
        n_out = host_real_outputs(f, c, out);
        if (n_out < 0 || !all_finite(out, n_out))
            ok = 0;
    }
    f->api.FreeInstance(c);
    return ok;
}

/* The same with one parameter set. */
static int finite_or_refused(const host_fmu *f, const char *param, double value, double input, double input2,
                             int n, int *refused, host_log *log)
{
    return finite_or_refused2(f, param, value, NULL, 0.0, input, input2, n, refused, log);
}

static void defect4_inf_outputs(void)
{
    host_log log;
    int refused;
    double extremes[] = {1e308, -1e308, DBL_MAX, -DBL_MAX, 8.9e307, -8.9e307};
    size_t i, j;

    /* PiezoStage: the sensor's quantisation turned a finite y into Inf */
    check(finite_or_refused(&plant, "sensor.resolution", 1e-310, 1.0, 0.0, 50, &refused, &log) && refused
              && strstr(log.last_error, "sensor.resolution") != NULL,
          "defect 4 PiezoStage: sensor.resolution = 1e-310 is refused at initialization (%s)", log.last_error);
    check(finite_or_refused(&plant, "sensor.noise_rms", 1e308, 1.0, 0.0, 50, &refused, &log) && refused
              && strstr(log.last_error, "sensor.noise_rms") != NULL,
          "defect 4 PiezoStage: sensor.noise_rms = 1e308 is refused at initialization (%s)", log.last_error);
    /* y = 4.5e307 um is finite, y / resolution is not (v is clamped to its declared
     * 150 V since issue 23, so the huge y comes from the hysteresis gain pi.w0) */
    check(finite_or_refused2(&plant, "sensor.resolution", 0.1, "pi.w0", 3e305, 150.0, 0.0, 50, &refused, &log)
              && refused && strstr(log.errors, "diverged") != NULL,
          "defect 4 PiezoStage: v = 150 with pi.w0 = 3e305 and sensor.resolution = 0.1 is a refused step, "
          "not y_meas = Inf (%s)", log.errors);
    check(finite_or_refused2(&plant, "sensor.resolution", 0.0, "pi.w0", 3e305, 150.0, 0.0, 5, &refused, &log)
              && !refused,
          "defect 4 PiezoStage: the same without quantisation runs its first 5 samples, y finite (%s)", log.errors);
    check(finite_or_refused(&plant, "sensor.resolution", 0.1, 1.0, 0.0, 50, &refused, &log) && !refused,
          "defect 4 PiezoStage: sensor.resolution = 0.1 with v = 1 runs");

    /* AdaptiveCompoundController: pred_error with the adaptation off and inputs near +-1e308 */
    for (i = 0; i < sizeof extremes / sizeof extremes[0]; i++)
        for (j = 0; j < sizeof extremes / sizeof extremes[0]; j++)
            check(finite_or_refused(&ctrl, "rls.enabled", 0.0, extremes[i], extremes[j], 20, &refused, &log),
                  "defect 4 AdaptiveCompoundController: rls.enabled = false, y_ref = %g, y_meas = %g: no "
                  "non-finite output with fmi2OK (%s)", extremes[i], extremes[j],
                  refused ? "refused" : "ran");

    /* ReferenceSignal: amplitudes whose sum overflows */
    {
        fmi2CallbackFunctions cb = host_callbacks(&log);
        fmi2Component c = ref.api.Instantiate("ref", fmi2CoSimulation, ref.guid, "", &cb, fmi2False, fmi2False);
        host_log_clear(&log);
        ref.api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        ref.api.EnterInitializationMode(c);
        host_set_named(&ref, c, "offset", 1e308);
        host_set_named(&ref, c, "amplitude[1]", 1e308);
        host_set_named(&ref, c, "phase[1]", 1.5707963267948966);
        check(ref.api.ExitInitializationMode(c) == fmi2Error && strstr(log.last_error, "amplitude[1]") != NULL,
              "defect 4 ReferenceSignal: offset + amplitude[1] = 2e308 is refused at initialization (%s)",
              log.last_error);
        ref.api.FreeInstance(c);
    }
}

static void defect5_states_freed(const host_fmu *f)
{
    host_log log;
    fmi2CallbackFunctions cb = host_callbacks(&log);
    long before = atomic_load(&host_live_blocks);
    fmi2Component c = host_start(f, &cb, "leak");
    fmi2FMUstate s1 = NULL, s2 = NULL, s3 = NULL;
    size_t size = 0;
    unsigned char *blob;
    check(c != NULL && f->api.GetFMUstate(c, &s1) == fmi2OK && f->api.DoStep(c, 0.0, f->h, fmi2True) <= fmi2Warning
              && f->api.GetFMUstate(c, &s2) == fmi2OK,
          "defect 5 %s: two states taken", f->id);
    blob = host_snapshot(f, c, &size);
    check(blob != NULL && f->api.DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, &s3) == fmi2OK,
          "defect 5 %s: a third one deserialized", f->id);
    free(blob);
    f->api.FreeInstance(c);     /* with s1, s2, s3 still allocated */
    check(atomic_load(&host_live_blocks) == before,
          "defect 5 %s: fmi2FreeInstance freed the states still allocated (%ld blocks left)", f->id,
          atomic_load(&host_live_blocks) - before);
}

static void defect6_identity(void)
{
    host_log log;
    fmi2CallbackFunctions cb = host_callbacks(&log);
    fmi2Component p = host_start(&plant, &cb, "plant");
    fmi2ValueReference vr = 0;
    double value = 1.0, out = 0.0;
    size_t size = 0;
    unsigned char *before = host_snapshot(&plant, p, &size);
    fmi2FMUstate s = NULL;

    check(ctrl.api.SetReal(p, &vr, 1, &value) == fmi2Error,
          "defect 6: the controller's fmi2SetReal refuses a PiezoStage instance");
    check(ctrl.api.GetReal(p, &vr, 1, &out) == fmi2Error,
          "defect 6: the controller's fmi2GetReal refuses a PiezoStage instance");
    check(ctrl.api.GetFMUstate(p, &s) == fmi2Error && s == NULL,
          "defect 6: the controller's fmi2GetFMUstate refuses a PiezoStage instance");
    check(ctrl.api.Terminate(p) == fmi2Error, "defect 6: the controller's fmi2Terminate refuses a PiezoStage instance");
    check(ref.api.Reset(p) == fmi2Error, "defect 6: the reference's fmi2Reset refuses a PiezoStage instance");
    check(ctrl.api.DoStep(p, 0.0, plant.h, fmi2True) == fmi2Error,
          "defect 6: the controller's fmi2DoStep refuses a PiezoStage instance (it wrote past the block)");
    ctrl.api.FreeInstance(p);   /* must not free it */
    check(host_same_state(&plant, p, before, size) && plant.api.DoStep(p, 0.0, plant.h, fmi2True) == fmi2OK,
          "defect 6: the PiezoStage instance is untouched and still runs");
    free(before);
    plant.api.FreeInstance(p);
}

static void defect7_state_in_error(void)
{
    host_log log;
    fmi2CallbackFunctions cb = host_callbacks(&log);
    fmi2Component c;
    fmi2FMUstate s = NULL, back = NULL;
    size_t size = 0;
    unsigned char *blob = NULL;
    host_log_clear(&log);
    c = plant.api.Instantiate("err", fmi2CoSimulation, plant.guid, "", &cb, fmi2False, fmi2False);
    plant.api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    plant.api.EnterInitializationMode(c);
    host_set_named(&plant, c, "pi.w0", 1e307);
    plant.api.ExitInitializationMode(c);
    host_set_named(&plant, c, "v", 150.0);
    /* u = pi.w0 v = 1.5e309 overflows: the core refuses the sample */
    check(plant.api.DoStep(c, 0.0, plant.h, fmi2True) == fmi2Error && strstr(log.last_error, "state Error"),
          "defect 7: v = 150 with pi.w0 = 1e307 puts PiezoStage in Error");
    check(plant.api.GetFMUstate(c, &s) == fmi2OK, "defect 7: fmi2GetFMUstate is allowed in Error (%s)",
          log.last_error);
    if (s != NULL && plant.api.SerializedFMUstateSize(c, s, &size) == fmi2OK && (blob = malloc(size)) != NULL)
        plant.api.SerializeFMUstate(c, s, (fmi2Byte *)blob, size);
    check(blob != NULL && plant.api.DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, &back) == fmi2OK
              && plant.api.Reset(c) == fmi2OK && plant.api.SetFMUstate(c, back) == fmi2OK
              && plant.api.DoStep(c, 0.0, plant.h, fmi2True) == fmi2Error && strstr(log.last_error, "state Error"),
          "defect 7: the Error state serializes, deserializes and brings Error back");
    free(blob);
    plant.api.FreeInstance(c);
}

static void defect8_null_logger(const host_fmu *f)
{
    fmi2CallbackFunctions cb = host_callbacks(NULL);
    fmi2Component c;
    cb.logger = NULL;
    c = f->api.Instantiate("nolog", fmi2CoSimulation, f->guid, "", &cb, fmi2False, fmi2False);
    check(c == NULL, "defect 8 %s: a NULL logger is refused at fmi2Instantiate", f->id);
    if (c != NULL)
        f->api.FreeInstance(c);
}

int main(int argc, char **argv)
{
    const host_fmu *all[3] = {&plant, &ctrl, &ref};
    int i, only = 0;
    if (argc == 9 && strcmp(argv[1], "--defect") == 0) {
        only = atoi(argv[2]);
        argv += 2;
        argc -= 2;
    }
    if (argc != 7) {
        fprintf(stderr, "usage: %s [--defect N] PiezoStage.xml PiezoStage.so AdaptiveCompoundController.xml "
                        "AdaptiveCompoundController.so ReferenceSignal.xml ReferenceSignal.so\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (!host_load(&plant, argv[1], argv[2]) || !host_load(&ctrl, argv[3], argv[4]) || !host_load(&ref, argv[5], argv[6]))
        return 2;
    for (i = 0; i < 3 && (only == 0 || only == 1); i++)
        defect1_size_wrap(all[i]);
    if (only == 0 || only == 2) {
        defect2_header_and_counters(&plant, 1);
        defect2_header_and_counters(&ctrl, 1);
        defect2_header_and_counters(&ref, 0);
    }
    for (i = 0; i < 3 && (only == 0 || only == 3); i++)
        defect3_stop_time(all[i]);
    if (only == 0 || only == 4)
        defect4_inf_outputs();
    for (i = 0; i < 3 && (only == 0 || only == 5); i++)
        defect5_states_freed(all[i]);
    if (only == 0 || only == 6)
        defect6_identity();
    if (only == 0 || only == 7)
        defect7_state_in_error();
    for (i = 0; i < 3 && (only == 0 || only == 8); i++)
        defect8_null_logger(all[i]);
    host_unload(&plant);
    host_unload(&ctrl);
    host_unload(&ref);
    return host_summary();
}
