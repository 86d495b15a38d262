/*
 * fmu_regressions.c - one check per defect of issue 9 (an independent abuse
 * test of the FMUs), each written to fail on the code before its fix. Built
 * once per FMI version: fmu_regressions (FMI 2.0 editions), fmu3_regressions
 * (FMI 3.0 editions; the serialized-state format and its validation are shared
 * with the FMI 2.0 editions in fmu_glue_core.c, so the same tampered blobs must
 * be refused):
 *
 *   1  fmi2DeSerializeFMUstate read past the caller's buffer: its size check
 *      wrapped modulo 2^64 (the blob here ends at a PROT_NONE page, so an
 *      over-read is a SIGSEGV even without a sanitizer)
 *   2  header and counter fields of a blob were not cross-checked (exact-mode
 *      counter >= 2^63, k = 2^64-1, h = 5e-324, NaN t0, reserved field, mode,
 *      NaN held input)
 *   3  stopTime (of fmi2SetupExperiment, fmi3EnterInitializationMode) must be
 *      enforced
 *   4  Inf outputs returned with fmi2OK from finite inputs and accepted
 *      parameters (the sensor's quantisation, pred_error, an overflowing sum of
 *      the ReferenceSignal's amplitudes)
 *   5  FMU states still allocated at fmi2FreeInstance leaked
 *   6  one FMU's functions accepted another FMU's instance (heap corruption);
 *      FMI 3.0 with the FMI 2.0 binaries given too: the FMI 3.0 functions of a
 *      model refuse its FMI 2.0 instance and the other way round (the same glue
 *      core, other binaries)
 *   7  fmi2GetFMUstate was refused in the Error state (and the state round-trips)
 *   8  FMI 2.0: a NULL logger was accepted silently (now refused at
 *      fmi2Instantiate; FMI 3.0 allows it: fmu3_negative checks that)
 *
 * usage: fmu_regressions [--defect N] PiezoStage.xml PiezoStage.so
 *            AdaptiveCompoundController.xml AdaptiveCompoundController.so
 *            ReferenceSignal.xml ReferenceSignal.so
 *        fmu3_regressions [--defect N] (the same of the FMI 3.0 editions)
 *            [PiezoStage2.xml PiezoStage2.so ...]   (FMI 2.0 editions, optional)
 * Prints one line per check and "N passed, M failed"; exit code 1 on failure.
 */
#if FMI_VERSION == 3
#include "host_fmi2.h"      /* defect 6 across editions */
#endif
#include "host.h"

#include <float.h>
#include <sys/mman.h>
#include <unistd.h>

static host_fmu plant, ctrl, ref;
#if FMI_VERSION == 3
static host2_fmu plant2, ctrl2, ref2;
static int have_fmi2;
#endif

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

/* A serialized state of f after n samples (StepComplete / StepMode) with its inputs at `input`. */
static unsigned char *saved_blob(const host_fmu *f, const char *param, double value, int n, double input,
                                 size_t *size)
{
    host_inst in;
    unsigned char *blob = NULL;
    int i, k;
    if (host_instantiate(&in, f, "saved") == NULL)
        return NULL;
    host_enter_init(f, in.c, 0.0, 0, 0.0);
    if (param != NULL)
        host_set_required(f, &in, param, value);
    /* constant inputs are no closed loop: the controller's supervision would stop them */
    if (host_named(f, "sup.enabled", NULL) != NULL)
        host_set_required(f, &in, "sup.enabled", 0.0);
    if (f->api.ExitInitializationMode(in.c) == HOST_OK) {
        for (i = 0; i < f->n_vars; i++)
            if (f->vars[i].causality == VAR_INPUT)
                host_set(f, in.c, &f->vars[i], input);
        for (k = 0; k < n; k++)
            if (host_step(f, in.c, k * f->h, f->h) > HOST_WARNING)
                break;
        blob = host_snapshot(f, in.c, size);
    }
    host_free_instance(&in);
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

/* Deserializing a tampered copy (resealed: size field and checksum) into a fresh
 * instance; *log: what that instance said. */
static host_status deserialize_tampered(const host_fmu *f, host_log *log, const unsigned char *blob, size_t size,
                                        size_t offset, const void *bytes, size_t n)
{
    unsigned char *copy = malloc(size);
    host_inst in;
    host_state s = NULL;
    host_status status = HOST_FATAL;
    if (copy != NULL && host_instantiate(&in, f, "tampered") != NULL) {
        memcpy(copy, blob, size);
        memcpy(copy + offset, bytes, n);
        blob_reseal(copy, size);
        status = host_deserialize(f, in.c, copy, size, &s);
        if (s != NULL)
            host_free_state(f, in.c, &s);
    }
    if (copy != NULL) {
        *log = in.log;
        host_free_instance(&in);
    }
    free(copy);
    return status;
}

static void defect1_size_wrap(const host_fmu *f)
{
    host_inst in;
    size_t size, data_size;
    unsigned char *blob;
    guarded_blob g;
    host_state s = NULL;
    host_status status;
    uint64_t n_history;

    blob = saved_blob(f, NULL, 0.0, 5, 0.5, &size);
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
    host_instantiate(&in, f, "wrap");
    status = host_deserialize(f, in.c, g.blob, BLOB_HEADER + 8u, &s);
    check(status == HOST_ERROR && s == NULL && strstr(in.log.last_error, "history length") != NULL,
          "defect 1 %s: a 136-byte blob claiming n_history = 2^64/8 - %llu (sizes wrap to 136) is refused "
          "without reading past it (%s)", f->id, (unsigned long long)(data_size / 8u), in.log.last_error);
    if (s != NULL)
        host_free_state(f, in.c, &s);
    host_free_instance(&in);
    guarded_free(&g);
    free(blob);
}

static void defect2_header_and_counters(const host_fmu *f, int exact)
{
    host_log log;
    size_t size, offsets[8];
    unsigned char *blob, bytes[8];
    const int n_steps = 1237;     /* a counter value that appears nowhere else in the image */
    uint64_t counter = (uint64_t)n_steps, huge;
    double held = 0.00123456789, nan_value = NAN;  /* small: the controller's monitor stays quiet */
    int n_found, i;

    host_log_clear(&log);
    blob = saved_blob(f, exact ? "creep.exact" : NULL, 1.0, n_steps, held, &size);
    if (!check(blob != NULL, "defect 2 %s: a real blob to start from", f->id))
        return;
    check(deserialize_tampered(f, &log, blob, size, 0, blob, 0) == HOST_OK,
          "defect 2 %s: the untampered blob (resealed) is accepted", f->id);

    /* every sample counter inside the model data (e.g. the exact-mode creep
     * counter k): 2^63 + k makes 2 (k + 1) wrap to the stored history length */
    n_found = find_in_model_data(blob, size, &counter, offsets, 8);
    check(n_found >= 1, "defect 2 %s: sample counters found in the model data (%d)", f->id, n_found);
    huge = counter + (1ull << 63);
    for (i = 0; i < n_found; i++)
        check(deserialize_tampered(f, &log, blob, size, offsets[i], &huge, 8) == HOST_ERROR,
              "defect 2 %s: a counter of 2^63 + %d at model-data byte %llu is refused (%s)", f->id, n_steps,
              (unsigned long long)(offsets[i] - BLOB_HEADER), log.last_error);

    blob_put_u64(bytes, UINT64_MAX);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_K, bytes, 8) == HOST_ERROR,
          "defect 2 %s: header k = 2^64 - 1 is refused (%s)", f->id, log.last_error);
    blob_put_u64(bytes, counter + 1);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_K, bytes, 8) == HOST_ERROR,
          "defect 2 %s: header k one off the model's counter is refused (%s)", f->id, log.last_error);
    blob_put_f64(bytes, 4.9406564584124654e-324);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_H, bytes, 8) == HOST_ERROR,
          "defect 2 %s: h = 5e-324 is refused (%s)", f->id, log.last_error);
    blob_put_f64(bytes, NAN);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_T0, bytes, 8) == HOST_ERROR,
          "defect 2 %s: t0 = NaN is refused (%s)", f->id, log.last_error);
    blob_put_u64(bytes, 1);
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_T_OFF, bytes, 8) == HOST_ERROR,
          "defect 2 %s: a non-zero reserved field is refused (%s)", f->id, log.last_error);
    bytes[0] = 32; bytes[1] = bytes[2] = bytes[3] = 0;
    check(deserialize_tampered(f, &log, blob, size, BLOB_OFF_MODE, bytes, 4) == HOST_ERROR,
          "defect 2 %s: mode 32 is refused (%s)", f->id, log.last_error);
    /* the held input (only models with inputs hold one) */
    n_found = find_in_model_data(blob, size, &held, offsets, 8);
    for (i = 0; i < n_found; i++)
        check(deserialize_tampered(f, &log, blob, size, offsets[i], &nan_value, 8) == HOST_ERROR,
              "defect 2 %s: a NaN in place of the held input %g (model-data byte %llu) is refused (%s)", f->id,
              held, (unsigned long long)(offsets[i] - BLOB_HEADER), log.last_error);
    free(blob);
}

static void defect3_stop_time(const host_fmu *f)
{
    host_inst in;
    host_instantiate(&in, f, "stop");
    host_hold_inputs(f, in.c);
    host_enter_init(f, in.c, 0.0, 1, 10 * f->h);
    f->api.ExitInitializationMode(in.c);
    check(host_step(f, in.c, 0.0, 10 * f->h) <= HOST_WARNING, "defect 3 %s: a step to stopTime passes", f->id);
    check(host_step(f, in.c, 10 * f->h, f->h) == HOST_ERROR && strstr(in.log.last_error, "stopTime") != NULL
              && strstr(in.log.last_error, BY_VERSION("fmi2SetupExperiment", "fmi3EnterInitializationMode")) != NULL,
          BY_VERSION("defect 3 %s: a step past stopTime is refused (%s)",
                     "defect 3 %s: a step past the stopTime of fmi3EnterInitializationMode is refused (%s)"),
          f->id, in.log.last_error);
    host_free_instance(&in);
}

/* Runs n steps from a fresh instance (in) with param = value (and param2 = value2), the first
 * input at `input` and the others at `input2`; 1 when no step returned OK/Warning with a
 * non-finite output. *refused: a set, ExitInitializationMode or a step said Error (the
 * message in in->log); *ran: the samples that completed. */
static int finite_or_refused2(const host_fmu *f, host_inst *in, const char *param, double value, const char *param2,
                              double value2, double input, double input2, int n, int *refused, int *ran)
{
    double out[HOST_MAX_OUTPUTS];
    int k, i, n_out, ok = 1, first_input = 1;
    *refused = 0;
    *ran = 0;
    host_instantiate(in, f, "inf");
    host_enter_init(f, in->c, 0.0, 0, 0.0);
    if ((param != NULL && host_set_named(f, in->c, param, value) != HOST_OK)
        || (param2 != NULL && host_set_named(f, in->c, param2, value2) != HOST_OK)
        || f->api.ExitInitializationMode(in->c) != HOST_OK) {
        *refused = 1;
        host_free_instance(in);
        return 1;
    }
    for (i = 0; i < f->n_vars; i++)
        if (f->vars[i].causality == VAR_INPUT) {
            if (host_set(f, in->c, &f->vars[i], first_input ? input : input2) != HOST_OK) {
                *refused = 1;
                host_free_instance(in);
                return 1;
            }
            first_input = 0;
        }
    for (k = 0; k < n; k++) {
        host_status st = host_step(f, in->c, k * f->h, f->h);
        if (st == HOST_ERROR) {
            *refused = 1;
            break;
        }
        n_out = host_real_outputs(f, in->c, out, HOST_MAX_OUTPUTS);
        if (n_out < 0 || !all_finite(out, n_out))
            ok = 0;
        *ran = k + 1;
    }
    host_free_instance(in);
    return ok;
}

/* The same with one parameter set. */
static int finite_or_refused(const host_fmu *f, host_inst *in, const char *param, double value, double input,
                             double input2, int n, int *refused, int *ran)
{
    return finite_or_refused2(f, in, param, value, NULL, 0.0, input, input2, n, refused, ran);
}

static void defect4_inf_outputs(void)
{
    host_inst in;
    int refused, ran, i_large;
    double extremes[] = {1e308, -1e308, DBL_MAX, -DBL_MAX, 8.9e307, -8.9e307};
    size_t i, j;

    /* PiezoStage: the sensor's quantisation turned a finite y into Inf */
    check(finite_or_refused(&plant, &in, "sensor.resolution", 1e-310, 1.0, 0.0, 50, &refused, &ran) && refused
              && strstr(in.log.last_error, "sensor.resolution") != NULL,
          "defect 4 PiezoStage: sensor.resolution = 1e-310 is refused at initialization (%s)", in.log.last_error);
    check(finite_or_refused(&plant, &in, "sensor.noise_rms", 1e308, 1.0, 0.0, 50, &refused, &ran) && refused
              && strstr(in.log.last_error, "sensor.noise_rms") != NULL,
          "defect 4 PiezoStage: sensor.noise_rms = 1e308 is refused at initialization (%s)", in.log.last_error);
    /* y = 4.5e307 um is finite, y / resolution is not (v is clamped to its declared
     * 150 V since issue 23, so the huge y comes from the hysteresis gain pi.w0) */
    check(finite_or_refused2(&plant, &in, "sensor.resolution", 0.1, "pi.w0", 3e305, 150.0, 0.0, 50, &refused, &ran)
              && refused && strstr(in.log.errors, "diverged") != NULL,
          "defect 4 PiezoStage: v = 150 with pi.w0 = 3e305 and sensor.resolution = 0.1 is a refused step, "
          "not y_meas = Inf (%s)", in.log.errors);
    check(finite_or_refused2(&plant, &in, "sensor.resolution", 0.0, "pi.w0", 3e305, 150.0, 0.0, 5, &refused, &ran)
              && !refused && ran == 5,
          "defect 4 PiezoStage: the same without quantisation runs its first 5 samples, y finite (%s)", in.log.errors);
    check(finite_or_refused(&plant, &in, "sensor.resolution", 0.1, 1.0, 0.0, 50, &refused, &ran) && !refused && ran == 50,
          "defect 4 PiezoStage: sensor.resolution = 0.1 with v = 1 runs");

    /* AdaptiveCompoundController: pred_error with the adaptation off and inputs near +-1e308.
     * A run passes when every sample gives finite outputs, or when the controller refuses it
     * because what it computed is not finite (not for any other reason); the large but
     * representable inputs (+-1e10 um) must run all their samples with finite outputs. */
    for (i = 0; i < sizeof extremes / sizeof extremes[0]; i++)
        for (j = 0; j < sizeof extremes / sizeof extremes[0]; j++) {
            int finite = finite_or_refused(&ctrl, &in, "rls.enabled", 0.0, extremes[i], extremes[j], 20, &refused, &ran);
            check(finite && (refused ? strstr(in.log.errors, "is not finite") != NULL : ran == 20),
                  "defect 4 AdaptiveCompoundController: rls.enabled = false, y_ref = %g, y_meas = %g: no "
                  "non-finite output with " FMI_NAME("OK") " (%s after %d samples%s%s)", extremes[i], extremes[j],
                  refused ? "refused" : "ran", ran, refused ? ": " : "", refused ? in.log.errors : "");
        }
    for (i_large = 0; i_large < 4; i_large++) {
        double y_ref = i_large & 1 ? -1e10 : 1e10, y_meas = i_large & 2 ? -1e10 : 1e10;
        int finite = finite_or_refused(&ctrl, &in, "rls.enabled", 0.0, y_ref, y_meas, 20, &refused, &ran);
        check(finite && !refused && ran == 20,
              "defect 4 AdaptiveCompoundController: rls.enabled = false, y_ref = %g, y_meas = %g: runs its 20 "
              "samples (%d), every output finite (%s)", y_ref, y_meas, ran, refused ? in.log.errors : "no error");
    }

    /* ReferenceSignal: amplitudes whose sum overflows (FMI 3.0: element 1 of the array) */
    host_instantiate(&in, &ref, "ref");
    host_enter_init(&ref, in.c, 0.0, 0, 0.0);
    host_set_required(&ref, &in, "offset", 1e308);
    host_set_required(&ref, &in, "amplitude[1]", 1e308);
    host_set_required(&ref, &in, "phase[1]", 1.5707963267948966);
    check(ref.api.ExitInitializationMode(in.c) == HOST_ERROR && strstr(in.log.last_error, "amplitude[1]") != NULL,
          "defect 4 ReferenceSignal: offset + amplitude[1] = 2e308 is refused at initialization"
          BY_VERSION("", ", naming the element") " (%s)", in.log.last_error);
    host_free_instance(&in);
}

static void defect5_states_freed(const host_fmu *f)
{
    long before = host_mem_in_use();
    host_inst in;
    host_state s1 = NULL, s2 = NULL, s3 = NULL;
    size_t size = 0;
    unsigned char *blob;
    host_start(&in, f, "leak");
    check(in.c != NULL && host_get_state(f, in.c, &s1) == HOST_OK && host_step(f, in.c, 0.0, f->h) <= HOST_WARNING
              && host_get_state(f, in.c, &s2) == HOST_OK,
          "defect 5 %s: two states taken", f->id);
    blob = host_snapshot(f, in.c, &size);
    check(blob != NULL && host_deserialize(f, in.c, blob, size, &s3) == HOST_OK,
          "defect 5 %s: a third one deserialized", f->id);
    free(blob);
    host_free_instance(&in);     /* with s1, s2, s3 still allocated */
#if FMI_VERSION == 2
    check(host_mem_back_to(before), "defect 5 %s: fmi2FreeInstance freed the states still allocated (%ld blocks left)",
          f->id, host_mem_in_use() - before);
#else
    check(host_mem_back_to(before),
          "defect 5 %s: fmi3FreeInstance freed the states still allocated (%ld bytes in use before, %ld after; %s)",
          f->id, before, host_mem_in_use(), host_heap_note());
#endif
}

#if FMI_VERSION == 3
/* The editions of one model: the same glue core, but each binary knows its own instances. */
static void defect6_editions(void)
{
    const host_fmu *ed3[3] = {&plant, &ctrl, &ref};
    const host2_fmu *ed2[3] = {&plant2, &ctrl2, &ref2};
    int i;
    for (i = 0; i < 3; i++) {
        host2_inst in2;
        host_inst in3;
        unsigned char *before2, *before3;
        size_t size2 = 0, size3 = 0;
        fmi3FMUState s3 = NULL;
        fmi2FMUstate s2 = NULL;
        void *c3 = host_start(&in3, ed3[i], "fmi3"), *c2 = host2_start(&in2, ed2[i], "fmi2");
        before2 = host2_snapshot(ed2[i], c2, &size2);
        before3 = host_snapshot(ed3[i], c3, &size3);
        check(c2 != NULL && c3 != NULL && host_step(ed3[i], c2, 0.0, ed3[i]->h) == fmi3Error
                  && ed3[i]->api.GetFMUState(c2, &s3) == fmi3Error && s3 == NULL && ed3[i]->api.Reset(c2) == fmi3Error,
              "defect 6 editions: the FMI 3.0 functions of %s refuse its FMI 2.0 instance", ed3[i]->id);
        check(c2 != NULL && c3 != NULL && ed2[i]->api.DoStep(c3, 0.0, ed2[i]->h, fmi2True) == fmi2Error
                  && ed2[i]->api.GetFMUstate(c3, &s2) == fmi2Error && s2 == NULL && ed2[i]->api.Reset(c3) == fmi2Error,
              "defect 6 editions: the FMI 2.0 functions of %s refuse its FMI 3.0 instance", ed2[i]->id);
        ed3[i]->api.FreeInstance(c2);   /* must not free them */
        ed2[i]->api.FreeInstance(c3);
        check(host2_same_state(ed2[i], c2, before2, size2) && host_same_state(ed3[i], c3, before3, size3),
              "defect 6 editions: both %s instances are untouched", ed3[i]->id);
        free(before2);
        free(before3);
        host2_free_instance(&in2);
        host_free_instance(&in3);
    }
}
#endif

static void defect6_identity(void)
{
    host_inst in;
    host_vr vr = 0;
    double value = 1.0, out = 0.0;
    size_t size = 0;
    void *p = host_start(&in, &plant, "plant");
    unsigned char *before = host_snapshot(&plant, p, &size);
    host_state s = NULL;

    check(host_set_reals(&ctrl, p, &vr, 1, &value, 1) == HOST_ERROR,
          "defect 6: the controller's " BY_VERSION("fmi2SetReal", "fmi3SetFloat64") " refuses a PiezoStage instance");
    check(host_get_reals(&ctrl, p, &vr, 1, &out, 1) == HOST_ERROR,
          "defect 6: the controller's " BY_VERSION("fmi2GetReal", "fmi3GetFloat64") " refuses a PiezoStage instance");
    check(host_get_state(&ctrl, p, &s) == HOST_ERROR && s == NULL,
          "defect 6: the controller's " BY_VERSION("fmi2GetFMUstate", "fmi3GetFMUState") " refuses a PiezoStage instance");
    check(ctrl.api.Terminate(p) == HOST_ERROR,
          "defect 6: the controller's " FMI_NAME("Terminate") " refuses a PiezoStage instance");
    check(ref.api.Reset(p) == HOST_ERROR, "defect 6: the reference's " FMI_NAME("Reset") " refuses a PiezoStage instance");
    check(host_step(&ctrl, p, 0.0, plant.h) == HOST_ERROR,
          "defect 6: the controller's " FMI_NAME("DoStep") " refuses a PiezoStage instance"
          BY_VERSION(" (it wrote past the block)", ""));
    ctrl.api.FreeInstance(p);   /* must not free it */
    check(host_same_state(&plant, p, before, size) && host_step(&plant, p, 0.0, plant.h) == HOST_OK,
          "defect 6: the PiezoStage instance is untouched and still runs");
    free(before);
#if FMI_VERSION == 3
    if (have_fmi2)
        defect6_editions();
#endif
    host_free_instance(&in);
}

static void defect7_state_in_error(void)
{
    host_inst in;
    host_state s = NULL, back = NULL;
    size_t size = 0;
    unsigned char *blob = NULL;
    host_instantiate(&in, &plant, "err");
    host_enter_init(&plant, in.c, 0.0, 0, 0.0);
    host_set_required(&plant, &in, "pi.w0", 1e307);
    plant.api.ExitInitializationMode(in.c);
    host_set_required(&plant, &in, "v", 150.0);
    /* u = pi.w0 v = 1.5e309 overflows: the core refuses the sample */
    check(host_step(&plant, in.c, 0.0, plant.h) == HOST_ERROR && strstr(in.log.last_error, "state Error"),
          "defect 7: v = 150 with pi.w0 = 1e307 puts PiezoStage in Error");
    check(host_get_state(&plant, in.c, &s) == HOST_OK,
          "defect 7: " BY_VERSION("fmi2GetFMUstate", "fmi3GetFMUState") " is allowed in Error (%s)",
          in.log.last_error);
    if (s != NULL && host_state_size(&plant, in.c, s, &size) == HOST_OK && (blob = malloc(size)) != NULL)
        host_serialize(&plant, in.c, s, blob, size);
    check(blob != NULL && host_deserialize(&plant, in.c, blob, size, &back) == HOST_OK
              && plant.api.Reset(in.c) == HOST_OK && host_set_state(&plant, in.c, back) == HOST_OK
              && host_step(&plant, in.c, 0.0, plant.h) == HOST_ERROR && strstr(in.log.last_error, "state Error"),
          "defect 7: the Error state serializes, deserializes and brings Error back");
    free(blob);
    host_free_instance(&in);
}

#if FMI_VERSION == 2
static void defect8_null_logger(const host_fmu *f)
{
    fmi2CallbackFunctions cb = host2_callbacks(NULL);
    fmi2Component c;
    cb.logger = NULL;
    c = f->api.Instantiate("nolog", fmi2CoSimulation, f->token, "", &cb, fmi2False, fmi2False);
    check(c == NULL, "defect 8 %s: a NULL logger is refused at fmi2Instantiate", f->id);
    if (c != NULL)
        f->api.FreeInstance(c);
}
#endif

int main(int argc, char **argv)
{
    const host_fmu *all[3] = {&plant, &ctrl, &ref};
    int i, only = 0;
    if (argc >= 3 && strcmp(argv[1], "--defect") == 0) {
        only = atoi(argv[2]);
        argv += 2;
        argc -= 2;
    }
    if (argc != 7 && (FMI_VERSION == 2 || argc != 13)) {
        fprintf(stderr, "usage: %s [--defect N] PiezoStage.xml PiezoStage.so AdaptiveCompoundController.xml "
                        "AdaptiveCompoundController.so ReferenceSignal.xml ReferenceSignal.so%s\n", argv[0],
                BY_VERSION("", " (FMI 3.0) [the same of the FMI 2.0 editions]"));
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (!host_load(&plant, argv[1], argv[2]) || !host_load(&ctrl, argv[3], argv[4]) || !host_load(&ref, argv[5], argv[6]))
        return 2;
#if FMI_VERSION == 3
    have_fmi2 = argc == 13;
    if (have_fmi2 && (!host2_load(&plant2, argv[7], argv[8]) || !host2_load(&ctrl2, argv[9], argv[10])
                      || !host2_load(&ref2, argv[11], argv[12])))
        return 2;
    printf("heap: %s\n", host_heap_note());
#endif
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
#if FMI_VERSION == 2
    for (i = 0; i < 3 && (only == 0 || only == 8); i++)
        defect8_null_logger(all[i]);
#endif
    host_unload(&plant);
    host_unload(&ctrl);
    host_unload(&ref);
#if FMI_VERSION == 3
    if (have_fmi2) {
        host2_unload(&plant2);
        host2_unload(&ctrl2);
        host2_unload(&ref2);
    }
#endif
    return host_summary();
}
