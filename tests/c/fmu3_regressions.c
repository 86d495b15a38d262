/*
 * fmu3_regressions.c - the defect checks of fmu_regressions.c (issue 9's
 * independent abuse test) that apply to the FMI 3.0 editions, through the
 * FMI 3.0 API; the serialized-state format and its validation are shared with
 * the FMI 2.0 editions (fmu_glue_core.c), so the same tampered blobs must be
 * refused:
 *
 *   1  fmi3DeserializeFMUState of a blob whose sizes wrap modulo 2^64 (it ends
 *      at a PROT_NONE page: an over-read is a SIGSEGV)
 *   2  header and counter fields of a blob cross-checked (exact-mode counter
 *      >= 2^63, k = 2^64-1, h = 5e-324, NaN t0, reserved field, mode, NaN
 *      held input)
 *   3  stopTime of fmi3EnterInitializationMode enforced
 *   4  no Inf output returned with fmi3OK from finite inputs and accepted
 *      parameters (the sensor's quantisation, pred_error, an overflowing
 *      amplitude sum of the ReferenceSignal array)
 *   5  FMU states still allocated at fmi3FreeInstance freed with it
 *   6  one FMU's functions refuse another FMU's instance; with the FMI 2.0
 *      binaries given too, the FMI 3.0 functions of a model refuse its FMI 2.0
 *      instance and the other way round (the same glue core, other binaries)
 *   7  fmi3GetFMUState allowed in the Error state, and the state round-trips
 *
 * usage: fmu3_regressions [--defect N] PiezoStage.xml PiezoStage.so
 *            AdaptiveCompoundController.xml AdaptiveCompoundController.so
 *            ReferenceSignal.xml ReferenceSignal.so            (FMI 3.0 editions)
 *            [PiezoStage2.xml PiezoStage2.so ... ]             (FMI 2.0 editions, optional)
 * Prints one line per check and "N passed, M failed"; exit code 1 on failure.
 */
#include "fmu3_host.h"

#include <float.h>
#include <sys/mman.h>
#include <unistd.h>

static host3_fmu plant, ctrl, ref;
static host_fmu plant2, ctrl2, ref2;
static int have_fmi2;

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

/* A serialized StepMode state of f after n samples with its inputs at `input`. */
static unsigned char *saved_blob(const host3_fmu *f, host_log *log, const char *param, double value, int n,
                                 double input, size_t *size)
{
    fmi3Instance c = host3_instantiate(f, "saved", log);
    unsigned char *blob = NULL;
    int i, k;
    if (c == NULL)
        return NULL;
    f->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    if (param != NULL)
        host3_set_named(f, c, param, value);
    if (f->api.ExitInitializationMode(c) == fmi3OK) {
        for (i = 0; i < f->n_vars; i++)
            if (f->vars[i].causality == VAR_INPUT)
                host3_set(f, c, &f->vars[i], input);
        for (k = 0; k < n; k++)
            if (host3_step(f, c, k * f->h, f->h) > fmi3Warning)
                break;
        blob = host3_snapshot(f, c, size);
    }
    f->api.FreeInstance(c);
    return blob;
}

static int find_in_model_data(const unsigned char *blob, size_t size, const void *pattern, size_t *offsets, int max)
{
    size_t data_size = (size_t)blob_get_u64(blob + BLOB_OFF_DATA_SIZE), off;
    int n = 0;
    for (off = BLOB_HEADER; off + 8 <= BLOB_HEADER + data_size && off + 8 <= size && n < max; off += 8)
        if (memcmp(blob + off, pattern, 8) == 0)
            offsets[n++] = off;
    return n;
}

static fmi3Status deserialize_tampered(const host3_fmu *f, host_log *log, const unsigned char *blob, size_t size,
                                       size_t offset, const void *bytes, size_t n)
{
    unsigned char *copy = malloc(size);
    fmi3Instance c = host3_instantiate(f, "tampered", log);
    fmi3FMUState s = NULL;
    fmi3Status status = fmi3Fatal;
    if (copy != NULL && c != NULL) {
        memcpy(copy, blob, size);
        memcpy(copy + offset, bytes, n);
        blob_reseal(copy, size);
        status = f->api.DeserializeFMUState(c, copy, size, &s);
        if (s != NULL)
            f->api.FreeFMUState(c, &s);
    }
    if (c != NULL)
        f->api.FreeInstance(c);
    free(copy);
    return status;
}

static void defect1_size_wrap(const host3_fmu *f)
{
    host_log log;
    size_t size, data_size;
    unsigned char *blob;
    guarded_blob g;
    fmi3Instance c;
    fmi3FMUState s = NULL;
    fmi3Status status;
    uint64_t n_history;

    host_log_clear(&log);
    blob = saved_blob(f, &log, NULL, 0.0, 5, 0.5, &size);
    if (!check(blob != NULL, "defect 1 %s: a real blob to start from", f->id))
        return;
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
    c = host3_instantiate(f, "wrap", &log);
    status = f->api.DeserializeFMUState(c, g.blob, BLOB_HEADER + 8u, &s);
    check(status == fmi3Error && s == NULL && strstr(log.last_error, "history length") != NULL,
          "defect 1 %s: a 136-byte blob claiming n_history = 2^64/8 - %llu (sizes wrap to 136) is refused "
          "without reading past it (%s)", f->id, (unsigned long long)(data_size / 8u), log.last_error);
    if (s != NULL)
        f->api.FreeFMUState(c, &s);
    f->api.FreeInstance(c);
    guarded_free(&g);
    free(blob);
}

static void defect2_header_and_counters(const host3_fmu *f, int exact)
{
    host_log log;
    size_t size, offsets[8];
    unsigned char *blob, bytes[8];
    const int n_steps = 1237;
    uint64_t counter = (uint64_t)n_steps, huge;
    double held = 0.00123456789, nan_value = NAN;
    int n_found, i;

    host_log_clear(&log);
    blob = saved_blob(f, &log, exact ? "creep.exact" : NULL, 1.0, n_steps, held, &size);
    if (!check(blob != NULL, "defect 2 %s: a real blob to start from", f->id))
        return;
    check(deserialize_tampered(f, &log, blob, size, 0, blob, 0) == fmi3OK,
          "defect 2 %s: the untampered blob (resealed) is accepted", f->id);
    n_found = find_in_model_data(blob, size, &counter, offsets, 8);
    check(n_found >= 1, "defect 2 %s: sample counters found in the model data (%d)", f->id, n_found);
    huge = counter + (1ull << 63);
    for (i = 0; i < n_found; i++)
        check(deserialize_tampered(f, &log, blob, size, offsets[i], &huge, 8) == fmi3Error,
              "defect 2 %s: a counter of 2^63 + %d at model-data byte %llu is refused (%s)", f->id, n_steps,
              (unsigned long long)(offsets[i] - BLOB_HEADER), log.last_error);
    blob_put_u64(bytes, UINT64_MAX);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_K, bytes, 8) == fmi3Error,
          "defect 2 %s: header k = 2^64 - 1 is refused (%s)", f->id, log.last_error);
    blob_put_u64(bytes, counter + 1);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_K, bytes, 8) == fmi3Error,
          "defect 2 %s: header k one off the model's counter is refused (%s)", f->id, log.last_error);
    blob_put_f64(bytes, 4.9406564584124654e-324);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_H, bytes, 8) == fmi3Error,
          "defect 2 %s: h = 5e-324 is refused (%s)", f->id, log.last_error);
    blob_put_f64(bytes, NAN);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_T0, bytes, 8) == fmi3Error,
          "defect 2 %s: t0 = NaN is refused (%s)", f->id, log.last_error);
    blob_put_u64(bytes, 1);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_RESERVED, bytes, 8) == fmi3Error,
          "defect 2 %s: a non-zero reserved field is refused (%s)", f->id, log.last_error);
    bytes[0] = 32; bytes[1] = bytes[2] = bytes[3] = 0;
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_MODE, bytes, 4) == fmi3Error,
          "defect 2 %s: mode 32 is refused (%s)", f->id, log.last_error);
    n_found = find_in_model_data(blob, size, &held, offsets, 8);
    for (i = 0; i < n_found; i++)
        check(deserialize_tampered(f, &log, blob, size, offsets[i], &nan_value, 8) == fmi3Error,
              "defect 2 %s: a NaN in place of the held input %g (model-data byte %llu) is refused (%s)", f->id,
              held, (unsigned long long)(offsets[i] - BLOB_HEADER), log.last_error);
    free(blob);
}

static void defect3_stop_time(const host3_fmu *f)
{
    host_log log;
    fmi3Instance c;
    host_log_clear(&log);
    c = host3_instantiate(f, "stop", &log);
    host3_hold_inputs(f, c);
    f->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3True, 10 * f->h);
    f->api.ExitInitializationMode(c);
    check(host3_step(f, c, 0.0, 10 * f->h) <= fmi3Warning, "defect 3 %s: a step to stopTime passes", f->id);
    check(host3_step(f, c, 10 * f->h, f->h) == fmi3Error && strstr(log.last_error, "stopTime") != NULL
              && strstr(log.last_error, "fmi3EnterInitializationMode") != NULL,
          "defect 3 %s: a step past the stopTime of fmi3EnterInitializationMode is refused (%s)", f->id,
          log.last_error);
    f->api.FreeInstance(c);
}

static int finite_or_refused2(const host3_fmu *f, const char *param, double value, const char *param2,
                              double value2, double input, double input2, int n, int *refused, host_log *log)
{
    fmi3Instance c;
    double out[32];
    int k, i, n_out, ok = 1, first_input = 1;
    host_log_clear(log);
    *refused = 0;
    c = host3_instantiate(f, "inf", log);
    f->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    if (param != NULL)
        host3_set_named(f, c, param, value);
    if (param2 != NULL)
        host3_set_named(f, c, param2, value2);
    if (f->api.ExitInitializationMode(c) != fmi3OK) {
        *refused = 1;
        f->api.FreeInstance(c);
        return 1;
    }
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].causality == VAR_INPUT) {
            host3_set(f, c, &f->vars[i], first_input ? input : input2);
            first_input = 0;
        }
    for (k = 0; k < n; k++) {
        fmi3Status st = host3_step(f, c, k * f->h, f->h);
        if (st == fmi3Error) {
            *refused = 1;
            break;
        }
        n_out = host3_real_outputs(f, c, out);
        if (n_out < 0 || !all_finite(out, n_out))
            ok = 0;
    }
    f->api.FreeInstance(c);
    return ok;
}

/* The same with one parameter set. */
static int finite_or_refused(const host3_fmu *f, const char *param, double value, double input, double input2,
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
    for (i = 0; i < sizeof extremes / sizeof extremes[0]; i++)
        for (j = 0; j < sizeof extremes / sizeof extremes[0]; j++)
            check(finite_or_refused(&ctrl, "rls.enabled", 0.0, extremes[i], extremes[j], 20, &refused, &log),
                  "defect 4 AdaptiveCompoundController: rls.enabled = false, y_ref = %g, y_meas = %g: no "
                  "non-finite output with fmi3OK (%s)", extremes[i], extremes[j], refused ? "refused" : "ran");
    {
        /* the amplitude array: element 1 makes offset + sum |amplitude| overflow */
        fmi3Instance c = host3_instantiate(&ref, "ref", &log);
        host_log_clear(&log);
        ref.api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
        host3_set_named(&ref, c, "offset", 1e308);
        host3_set_named(&ref, c, "amplitude[1]", 1e308);
        host3_set_named(&ref, c, "phase[1]", 1.5707963267948966);
        check(ref.api.ExitInitializationMode(c) == fmi3Error && strstr(log.last_error, "amplitude[1]") != NULL,
              "defect 4 ReferenceSignal: offset + amplitude[1] = 2e308 is refused at initialization, naming the "
              "element (%s)", log.last_error);
        ref.api.FreeInstance(c);
    }
}

static void defect5_states_freed(const host3_fmu *f)
{
    host_log log;
    long before = host3_heap_in_use();
    fmi3Instance c = host3_start(f, &log, "leak");
    fmi3FMUState s1 = NULL, s2 = NULL, s3 = NULL;
    size_t size = 0;
    unsigned char *blob;
    check(c != NULL && f->api.GetFMUState(c, &s1) == fmi3OK && host3_step(f, c, 0.0, f->h) <= fmi3Warning
              && f->api.GetFMUState(c, &s2) == fmi3OK,
          "defect 5 %s: two states taken", f->id);
    blob = host3_snapshot(f, c, &size);
    check(blob != NULL && f->api.DeserializeFMUState(c, blob, size, &s3) == fmi3OK,
          "defect 5 %s: a third one deserialized", f->id);
    free(blob);
    f->api.FreeInstance(c);     /* with s1, s2, s3 still allocated */
    check(host3_heap_back_to(before),
          "defect 5 %s: fmi3FreeInstance freed the states still allocated (%ld bytes in use before, %ld after; %s)",
          f->id, before, host3_heap_in_use(), host3_heap_note());
}

static void defect6_identity(void)
{
    host_log log;
    fmi3Instance p = host3_start(&plant, &log, "plant");
    fmi3ValueReference vr = 0;
    double value = 1.0, out = 0.0;
    size_t size = 0;
    unsigned char *before = host3_snapshot(&plant, p, &size);
    fmi3FMUState s = NULL;

    check(ctrl.api.SetFloat64(p, &vr, 1, &value, 1) == fmi3Error,
          "defect 6: the controller's fmi3SetFloat64 refuses a PiezoStage instance");
    check(ctrl.api.GetFloat64(p, &vr, 1, &out, 1) == fmi3Error,
          "defect 6: the controller's fmi3GetFloat64 refuses a PiezoStage instance");
    check(ctrl.api.GetFMUState(p, &s) == fmi3Error && s == NULL,
          "defect 6: the controller's fmi3GetFMUState refuses a PiezoStage instance");
    check(ctrl.api.Terminate(p) == fmi3Error, "defect 6: the controller's fmi3Terminate refuses a PiezoStage instance");
    check(ref.api.Reset(p) == fmi3Error, "defect 6: the reference's fmi3Reset refuses a PiezoStage instance");
    check(host3_step(&ctrl, p, 0.0, plant.h) == fmi3Error,
          "defect 6: the controller's fmi3DoStep refuses a PiezoStage instance");
    ctrl.api.FreeInstance(p);   /* must not free it */
    check(host3_same_state(&plant, p, before, size) && host3_step(&plant, p, 0.0, plant.h) == fmi3OK,
          "defect 6: the PiezoStage instance is untouched and still runs");
    free(before);

    if (have_fmi2) {
        /* the editions of one model: the same glue core, but each binary knows its own instances */
        const host3_fmu *ed3[3] = {&plant, &ctrl, &ref};
        const host_fmu *ed2[3] = {&plant2, &ctrl2, &ref2};
        int i;
        for (i = 0; i < 3; i++) {
            host_log log2;
            fmi2CallbackFunctions cb = host_callbacks(&log2);
            fmi2Component c2;
            fmi3Instance c3 = host3_start(ed3[i], &log, "fmi3");
            unsigned char *before2, *before3;
            size_t size2 = 0, size3 = 0;
            fmi3FMUState s3 = NULL;
            fmi2FMUstate s2 = NULL;
            host_log_clear(&log2);
            c2 = host_start(ed2[i], &cb, "fmi2");
            before2 = host_snapshot(ed2[i], c2, &size2);
            before3 = host3_snapshot(ed3[i], c3, &size3);
            check(c2 != NULL && c3 != NULL && host3_step(ed3[i], c2, 0.0, ed3[i]->h) == fmi3Error
                      && ed3[i]->api.GetFMUState(c2, &s3) == fmi3Error && s3 == NULL
                      && ed3[i]->api.Reset(c2) == fmi3Error,
                  "defect 6 editions: the FMI 3.0 functions of %s refuse its FMI 2.0 instance", ed3[i]->id);
            check(c2 != NULL && c3 != NULL && ed2[i]->api.DoStep(c3, 0.0, ed2[i]->h, fmi2True) == fmi2Error
                      && ed2[i]->api.GetFMUstate(c3, &s2) == fmi2Error && s2 == NULL
                      && ed2[i]->api.Reset(c3) == fmi2Error,
                  "defect 6 editions: the FMI 2.0 functions of %s refuse its FMI 3.0 instance", ed2[i]->id);
            ed3[i]->api.FreeInstance(c2);   /* must not free them */
            ed2[i]->api.FreeInstance(c3);
            check(host_same_state(ed2[i], c2, before2, size2) && host3_same_state(ed3[i], c3, before3, size3),
                  "defect 6 editions: both %s instances are untouched", ed3[i]->id);
            free(before2);
            free(before3);
            ed2[i]->api.FreeInstance(c2);
            ed3[i]->api.FreeInstance(c3);
        }
    }
    plant.api.FreeInstance(p);
}

static void defect7_state_in_error(void)
{
    host_log log;
    fmi3Instance c;
    fmi3FMUState s = NULL, back = NULL;
    size_t size = 0;
    unsigned char *blob = NULL;
    host_log_clear(&log);
    c = host3_instantiate(&plant, "err", &log);
    plant.api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    host3_set_named(&plant, c, "pi.w0", 1e307);
    plant.api.ExitInitializationMode(c);
    host3_set_named(&plant, c, "v", 150.0);
    /* u = pi.w0 v = 1.5e309 overflows: the core refuses the sample */
    check(host3_step(&plant, c, 0.0, plant.h) == fmi3Error && strstr(log.last_error, "state Error"),
          "defect 7: v = 150 with pi.w0 = 1e307 puts PiezoStage in Error");
    check(plant.api.GetFMUState(c, &s) == fmi3OK, "defect 7: fmi3GetFMUState is allowed in Error (%s)",
          log.last_error);
    if (s != NULL && plant.api.SerializedFMUStateSize(c, s, &size) == fmi3OK && (blob = malloc(size)) != NULL)
        plant.api.SerializeFMUState(c, s, blob, size);
    check(blob != NULL && plant.api.DeserializeFMUState(c, blob, size, &back) == fmi3OK
              && plant.api.Reset(c) == fmi3OK && plant.api.SetFMUState(c, back) == fmi3OK
              && host3_step(&plant, c, 0.0, plant.h) == fmi3Error && strstr(log.last_error, "state Error"),
          "defect 7: the Error state serializes, deserializes and brings Error back");
    free(blob);
    plant.api.FreeInstance(c);
}

int main(int argc, char **argv)
{
    const host3_fmu *all[3] = {&plant, &ctrl, &ref};
    int i, only = 0;
    if (argc >= 3 && strcmp(argv[1], "--defect") == 0) {
        only = atoi(argv[2]);
        argv += 2;
        argc -= 2;
    }
    if (argc != 7 && argc != 13) {
        fprintf(stderr, "usage: %s [--defect N] PiezoStage.xml PiezoStage.so AdaptiveCompoundController.xml "
                        "AdaptiveCompoundController.so ReferenceSignal.xml ReferenceSignal.so (FMI 3.0) "
                        "[the same of the FMI 2.0 editions]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (!host3_load(&plant, argv[1], argv[2]) || !host3_load(&ctrl, argv[3], argv[4])
        || !host3_load(&ref, argv[5], argv[6]))
        return 2;
    have_fmi2 = argc == 13;
    if (have_fmi2 && (!host_load(&plant2, argv[7], argv[8]) || !host_load(&ctrl2, argv[9], argv[10])
                      || !host_load(&ref2, argv[11], argv[12])))
        return 2;
    printf("heap: %s\n", host3_heap_note());
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
    host3_unload(&plant);
    host3_unload(&ctrl);
    host3_unload(&ref);
    if (have_fmi2) {
        host_unload(&plant2);
        host_unload(&ctrl2);
        host_unload(&ref2);
    }
    return host_summary();
}
