/*
 * fmu_master.c - a second FMI 2.0 Co-Simulation importer, independent of fmpy:
 * dlopen + dlsym, the host's own callbacks, a fixed-step master, and the
 * abuse a careless host may commit (NULL components, wrong GUID, illegal call
 * sequences, NaN inputs, bad steps, corrupted blobs). Run by
 * tests/test_fmu_c_master.py, under valgrind when it is installed.
 *
 * usage: fmu_master [--off VR]... UNZIPDIR MODEL_ID GUID H N_SAMPLES OUT_VR IN_VR [IN_VR ...]
 * Every input is driven by u(k) = 10 sin(2 pi 5 k h) + 10; --off sets the Boolean
 * parameter VR to false in every run (before initialization, as an importer's start
 * value: the controller's sup.enabled, since this drive is no closed loop). Prints one line per
 * check ("ok ..." / "FAIL ..."), the output of every sample of the reference run
 * ("y K VALUE", 17 digits: for the bitwise comparison with fmpy), then
 * "N passed, M failed". Exit code 1 if any check failed.
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../c/fmi2_api.h"   /* fmi2Functions.h, and the list of its functions */

static int n_passed, n_failed;
static int messages_logged;

static void check(int condition, const char *what)
{
    if (condition) {
        ++n_passed;
        printf("ok   %s\n", what);
    } else {
        ++n_failed;
        printf("FAIL %s\n", what);
    }
}

static void host_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                        fmi2String category, fmi2String message, ...)
{
    char text[2048];
    va_list args;
    (void)env;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    ++messages_logged;
    printf("log  [%s] %d %s: %s\n", instance ? instance : "?", (int)status, category ? category : "?", text);
}

/* the whole fmi2 API (FMI2_API, fmi2_api: ../c/fmi2_api.h), looked up by name: a missing
 * symbol fails the run */
static int load_api(void *lib, fmi2_api *api)
{
    int missing = 0;
#define LOAD(name)                                                       \
    *(void **)(&api->name) = dlsym(lib, "fmi2" #name);                   \
    if (api->name == NULL) {                                             \
        printf("FAIL symbol fmi2%s missing\n", #name);                   \
        ++missing;                                                       \
    }
    FMI2_API(LOAD)
#undef LOAD
    return missing;
}

static double drive(size_t k, double h)
{
    return 10.0 * sin(2.0 * 3.14159265358979323846 * 5.0 * (double)k * h) + 10.0;
}

typedef struct {
    const fmi2_api *api;
    fmi2ValueReference out_vr;
    const fmi2ValueReference *in_vr;
    size_t n_in;
    double h;
} run_setup;

/* Steps samples [k0, k1) one h at a time; y[k] = output after setting the
 * inputs of sample k (direct feedthrough included). Returns 0 on success. */
static int run_samples(const run_setup *rs, fmi2Component c, size_t k0, size_t k1, double *y)
{
    size_t k, i;
    for (k = k0; k < k1; ++k) {
        double u = drive(k, rs->h);
        for (i = 0; i < rs->n_in; ++i)
            if (rs->api->SetReal(c, &rs->in_vr[i], 1, &u) != fmi2OK) return 1;
        if (rs->api->GetReal(c, &rs->out_vr, 1, &y[k]) != fmi2OK) return 1;
        /* fmi2Warning is a completed step (e.g. the controller logs a bound it saw) */
        if (rs->api->DoStep(c, (double)k * rs->h, rs->h, fmi2True) > fmi2Warning) return 1;
    }
    return 0;
}

/* the Boolean parameters --off sets to false */
static fmi2ValueReference off_vr[8];
static size_t n_off;

static int set_off(const fmi2_api *api, fmi2Component c)
{
    size_t i;
    fmi2Boolean no = fmi2False;
    for (i = 0; i < n_off; ++i)
        if (api->SetBoolean(c, &off_vr[i], 1, &no) != fmi2OK) return 1;
    return 0;
}

static fmi2Component start(const fmi2_api *api, const fmi2CallbackFunctions *cb, const char *id,
                           const char *guid, const char *resources, const char *name)
{
    fmi2Component c = api->Instantiate(name, fmi2CoSimulation, guid, resources, cb, fmi2False, fmi2False);
    if (c == NULL) return NULL;
    if (set_off(api, c) || api->SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
        api->EnterInitializationMode(c) != fmi2OK || api->ExitInitializationMode(c) != fmi2OK) {
        api->FreeInstance(c);
        return NULL;
    }
    (void)id;
    return c;
}

int main(int argc, char **argv)
{
    char path[4096], resources[4200];
    const char *unzipdir, *id, *guid;
    double h, nan_value = NAN, bad;
    size_t n, half, i, n_in, k;
    fmi2ValueReference out_vr, in_vr[8];
    fmi2_api api;
    void *lib;
    fmi2CallbackFunctions cb = {host_logger, calloc, free, NULL, NULL};
    fmi2Component c, c2;
    fmi2FMUstate state = NULL, restored = NULL;
    fmi2Byte *blob;
    size_t blob_size = 0;
    double *y_ref, *y_test;
    run_setup rs;
    int same;

    while (argc >= 3 && strcmp(argv[1], "--off") == 0 && n_off < 8) {
        off_vr[n_off++] = (fmi2ValueReference)atol(argv[2]);
        argv += 2;
        argc -= 2;
    }
    if (argc < 8) {
        fprintf(stderr, "usage: %s [--off VR]... UNZIPDIR MODEL_ID GUID H N_SAMPLES OUT_VR IN_VR...\n", argv[0]);
        return 2;
    }
    unzipdir = argv[1];
    id = argv[2];
    guid = argv[3];
    h = atof(argv[4]);
    n = (size_t)atol(argv[5]);
    out_vr = (fmi2ValueReference)atol(argv[6]);
    n_in = (size_t)(argc - 7);
    if (n_in > 8 || n < 4) return 2;
    for (i = 0; i < n_in; ++i) in_vr[i] = (fmi2ValueReference)atol(argv[7 + i]);
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", unzipdir, id);
    snprintf(resources, sizeof resources, "file://%s/resources", unzipdir);

    lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        printf("FAIL dlopen %s: %s\n", path, dlerror());
        return 1;
    }
    check(load_api(lib, &api) == 0, "every fmi2 function of the standard is exported");
    if (n_failed) return 1;
    check(strcmp(api.GetVersion(), "2.0") == 0, "fmi2GetVersion is 2.0");
    check(strcmp(api.GetTypesPlatform(), "default") == 0, "fmi2GetTypesPlatform is default");

    /* careless host: NULL component and a wrong GUID */
    api.FreeInstance(NULL);
    check(api.DoStep(NULL, 0.0, h, fmi2True) == fmi2Error, "fmi2DoStep(NULL) returns fmi2Error");
    check(api.Terminate(NULL) == fmi2Error, "fmi2Terminate(NULL) returns fmi2Error");
    check(api.Instantiate("wrong", fmi2CoSimulation, "{not-the-guid}", resources, &cb, fmi2False, fmi2False) == NULL,
          "a wrong GUID is refused at instantiation");
    check(api.Instantiate("me", fmi2ModelExchange, guid, resources, &cb, fmi2False, fmi2False) == NULL,
          "Model Exchange is refused (Co-Simulation only)");

    /* illegal sequences on a live instance */
    c = api.Instantiate("seq", fmi2CoSimulation, guid, resources, &cb, fmi2False, fmi2False);
    check(c != NULL, "instantiate");
    if (!c) return 1;
    check(api.DoStep(c, 0.0, h, fmi2True) == fmi2Error, "doStep before initialization is refused");
    check(api.ExitInitializationMode(c) == fmi2Error, "exitInitializationMode before enter is refused");
    check(set_off(&api, c) == 0 && api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK,
          "setupExperiment");
    check(api.EnterInitializationMode(c) == fmi2OK && api.ExitInitializationMode(c) == fmi2OK, "initialize");
    check(api.SetReal(c, in_vr, 1, &nan_value) == fmi2Error, "a NaN input is refused");
    check(api.GetReal(c, &out_vr, 1, NULL) == fmi2Error, "getReal into NULL is refused");
    {
        fmi2ValueReference bogus = 100000;
        check(api.GetReal(c, &bogus, 1, &bad) == fmi2Error, "an unknown value reference is refused");
    }
    check(api.DoStep(c, 0.0, 0.7 * h, fmi2True) == fmi2Error, "a step of 0.7 h is refused");
    check(api.DoStep(c, 5.0 * h, h, fmi2True) == fmi2Error, "a step from the wrong time is refused");
    check(api.GetFMUstate(c, NULL) == fmi2Error, "getFMUstate into NULL is refused");
    check(api.Terminate(c) == fmi2OK, "terminate");
    check(api.DoStep(c, 0.0, h, fmi2True) == fmi2Error, "doStep after terminate is refused");
    check(api.Reset(c) == fmi2OK, "reset after terminate");
    check(set_off(&api, c) == 0 && api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK &&
          api.EnterInitializationMode(c) == fmi2OK && api.ExitInitializationMode(c) == fmi2OK,
          "re-initialize after reset");
    api.FreeInstance(c);

    /* the reference run, then the same run interrupted by state save/restore */
    y_ref = calloc(n, sizeof *y_ref);
    y_test = calloc(n, sizeof *y_test);
    if (!y_ref || !y_test) return 1;
    rs.api = &api;
    rs.out_vr = out_vr;
    rs.in_vr = in_vr;
    rs.n_in = n_in;
    rs.h = h;
    half = n / 2;

    c = start(&api, &cb, id, guid, resources, "reference");
    check(c != NULL && run_samples(&rs, c, 0, n, y_ref) == 0, "reference run");
    if (c) api.FreeInstance(c);

    c = start(&api, &cb, id, guid, resources, "interrupted");
    check(c != NULL && run_samples(&rs, c, 0, half, y_test) == 0, "first half");
    check(c != NULL && api.GetFMUstate(c, &state) == fmi2OK, "getFMUstate mid-run");
    check(c != NULL && run_samples(&rs, c, half, n, y_test) == 0, "second half");
    check(c != NULL && api.SetFMUstate(c, state) == fmi2OK, "setFMUstate back to mid-run");
    check(c != NULL && run_samples(&rs, c, half, n, y_test) == 0, "second half again");
    same = memcmp(y_ref, y_test, n * sizeof *y_ref) == 0;
    check(same, "restored continuation is bitwise identical to the uninterrupted run");

    /* serialize, then continue in a fresh instance */
    check(api.SerializedFMUstateSize(c, state, &blob_size) == fmi2OK && blob_size > 0, "serialized size");
    blob = malloc(blob_size);
    check(blob != NULL && api.SerializeFMUstate(c, state, blob, blob_size) == fmi2OK, "serialize");
    api.FreeFMUstate(c, &state);
    check(state == NULL, "freeFMUstate clears the handle");
    api.FreeInstance(c);

    c2 = start(&api, &cb, id, guid, resources, "fresh");
    memset(y_test, 0, n * sizeof *y_test);
    blob[blob_size / 2] ^= 0x5a;   /* corrupt one byte: refused, instance unharmed */
    check(c2 != NULL && api.DeSerializeFMUstate(c2, blob, blob_size, &restored) == fmi2Error,
          "a corrupted blob is refused");
    blob[blob_size / 2] ^= 0x5a;
    check(c2 != NULL && api.DeSerializeFMUstate(c2, blob, blob_size / 3, &restored) == fmi2Error,
          "a truncated blob is refused");
    check(c2 != NULL && api.DeSerializeFMUstate(c2, blob, blob_size, &restored) == fmi2OK &&
          api.SetFMUstate(c2, restored) == fmi2OK, "deserialize into a fresh instance");
    check(c2 != NULL && run_samples(&rs, c2, half, n, y_test) == 0, "continue in the fresh instance");
    check(memcmp(y_ref + half, y_test + half, (n - half) * sizeof *y_ref) == 0,
          "fresh-instance continuation is bitwise identical");
    if (c2) {
        api.FreeFMUstate(c2, &restored);
        api.Terminate(c2);
        api.FreeInstance(c2);
    }
    free(blob);

    check(messages_logged > 0, "refusals were explained through the host's logger");
    for (k = 0; k < n; ++k) printf("y %zu %.17g\n", k, y_ref[k]);   /* every sample, for the comparison */
    free(y_ref);
    free(y_test);
    dlclose(lib);
    printf("%d passed, %d failed\n", n_passed, n_failed);
    return n_failed ? 1 : 0;
}
