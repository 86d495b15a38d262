/*
 * fmu_host.c - a minimal FMI 2.0 Co-Simulation host that builds for Linux (dlopen) and
 * for Windows (LoadLibrary, with MinGW-w64), so that the same experiment runs the linux64
 * .so natively and the win64 .dll under wine. Used by tests/test_fmu_win64.py.
 * Compiled with -DFMU_HOST_FMI3 it is the same host for FMI 3.0 Co-Simulation binaries
 * (x86_64-linux, x86_64-windows): the plan and the output are the same, the calls fmi3.
 *
 * usage: fmu_host PLAN BINARY
 *
 * PLAN is a text file of whitespace-separated tokens:
 *     identifier ID   guid GUID   step H   steps N
 *     real VR VALUE | integer VR VALUE | boolean VR 0|1     (parameters, set before init)
 *     reals VR N VALUE...   (FMI 3.0 only: a Float64 array parameter, all N elements)
 *     input VR ...          (Real inputs, one column each in the data)
 *     output VR ...         (Real outputs)   boutput VR ...   (Boolean outputs)
 *     data                  followed by N + 1 rows of input values (row k applies at t_k)
 * Prints N + 1 rows: t_k and the outputs at t_k (row 0 after initialization), "%.17g".
 * Exit code 0 on success, 1 if an FMI call failed (the FMU's messages go to stderr).
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
typedef HMODULE lib_handle;
#define LIB_OPEN(path) LoadLibraryA(path)
#define LIB_SYM(lib, name) ((void (*)(void))GetProcAddress((lib), (name)))
#else
#include <dlfcn.h>
typedef void *lib_handle;
#define LIB_OPEN(path) dlopen((path), RTLD_NOW | RTLD_LOCAL)
static void (*lib_sym(void *lib, const char *name))(void)
{
    void (*fn)(void);
    void *p = dlsym(lib, name);
    memcpy(&fn, &p, sizeof fn);     /* object to function pointer without a pedantic warning */
    return fn;
}
#define LIB_SYM(lib, name) lib_sym((lib), (name))
#endif

#ifdef FMU_HOST_FMI3
#include "fmi3Functions.h"
#else
#include "fmi2Functions.h"
#endif

#define MAX_VARS 64
#define MAX_ARRAY_VALUES 256

#ifdef FMU_HOST_FMI3
static void log_message(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                        fmi3String message)
{
    (void)env;
    fprintf(stderr, "[host] %d %s: %s\n", (int)status, category ? category : "?", message ? message : "");
}
#else

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list args;
    (void)env;
    va_start(args, message);
    fprintf(stderr, "[%s] %d %s: ", instance ? instance : "?", (int)status, category ? category : "?");
    vfprintf(stderr, message, args);
    fputc('\n', stderr);
    va_end(args);
}
#endif

static int fail(const char *what)
{
    fprintf(stderr, "fmu_host: %s\n", what);
    return 1;
}

#define LOAD(type, var, name)                                           \
    type *var = (type *)LIB_SYM(lib, name);                             \
    if (!var) return fail("missing symbol " name)

int main(int argc, char **argv)
{
    char token[256], id[256] = "", guid[256] = "";
    double h = 0.0, params_r[MAX_VARS];
    int steps = -1, params_i[MAX_VARS], params_b[MAX_VARS];
    unsigned vr_r[MAX_VARS], vr_i[MAX_VARS], vr_b[MAX_VARS], vr_a[MAX_VARS];
    unsigned in[MAX_VARS], out[MAX_VARS], bout[MAX_VARS];
    double array_values[MAX_ARRAY_VALUES];
    size_t array_len[MAX_VARS], n_values = 0, n_a = 0;
    size_t n_r = 0, n_i = 0, n_b = 0, n_in = 0, n_out = 0, n_bout = 0, i;
    double *data;
    FILE *plan;
    lib_handle lib;
    int k;

    if (argc != 3) return fail("usage: fmu_host PLAN BINARY");
    plan = fopen(argv[1], "r");
    if (!plan) return fail("cannot open the plan");
    while (fscanf(plan, "%255s", token) == 1) {
        unsigned vr;
        if (!strcmp(token, "identifier")) {
            if (fscanf(plan, "%255s", id) != 1) return fail("bad identifier");
        } else if (!strcmp(token, "guid")) {
            if (fscanf(plan, "%255s", guid) != 1) return fail("bad guid");
        } else if (!strcmp(token, "step")) {
            if (fscanf(plan, "%lf", &h) != 1) return fail("bad step");
        } else if (!strcmp(token, "steps")) {
            if (fscanf(plan, "%d", &steps) != 1) return fail("bad steps");
        } else if (!strcmp(token, "real") && n_r < MAX_VARS) {
            if (fscanf(plan, "%u %lf", &vr, &params_r[n_r]) != 2) return fail("bad real");
            vr_r[n_r++] = vr;
        } else if (!strcmp(token, "integer") && n_i < MAX_VARS) {
            if (fscanf(plan, "%u %d", &vr, &params_i[n_i]) != 2) return fail("bad integer");
            vr_i[n_i++] = vr;
        } else if (!strcmp(token, "boolean") && n_b < MAX_VARS) {
            if (fscanf(plan, "%u %d", &vr, &params_b[n_b]) != 2) return fail("bad boolean");
            vr_b[n_b++] = vr;
        } else if (!strcmp(token, "reals") && n_a < MAX_VARS) {
            unsigned long count;
            if (fscanf(plan, "%u %lu", &vr, &count) != 2 || count > MAX_ARRAY_VALUES - n_values)
                return fail("bad reals");
            for (i = 0; i < count; ++i)
                if (fscanf(plan, "%lf", &array_values[n_values + i]) != 1) return fail("bad reals value");
            vr_a[n_a] = vr;
            array_len[n_a++] = count;
            n_values += count;
        } else if (!strcmp(token, "input") && n_in < MAX_VARS) {
            if (fscanf(plan, "%u", &vr) != 1) return fail("bad input");
            in[n_in++] = vr;
        } else if (!strcmp(token, "output") && n_out < MAX_VARS) {
            if (fscanf(plan, "%u", &vr) != 1) return fail("bad output");
            out[n_out++] = vr;
        } else if (!strcmp(token, "boutput") && n_bout < MAX_VARS) {
            if (fscanf(plan, "%u", &vr) != 1) return fail("bad boutput");
            bout[n_bout++] = vr;
        } else if (!strcmp(token, "data")) {
            break;
        } else {
            return fail("unknown plan token (or too many variables)");
        }
    }
    if (!id[0] || !guid[0] || !(h > 0.0) || steps < 0) return fail("incomplete plan");
    data = calloc((size_t)(steps + 1) * (n_in ? n_in : 1), sizeof *data);
    if (!data) return fail("out of memory");
    for (i = 0; i < (size_t)(steps + 1) * n_in; ++i)
        if (fscanf(plan, "%lf", &data[i]) != 1) return fail("short data");
    fclose(plan);

#ifdef FMU_HOST_FMI3
    lib = LIB_OPEN(argv[2]);
    if (!lib) return fail("cannot load the binary");
    {
        LOAD(fmi3GetVersionTYPE, get_version, "fmi3GetVersion");
        LOAD(fmi3InstantiateCoSimulationTYPE, instantiate, "fmi3InstantiateCoSimulation");
        LOAD(fmi3EnterInitializationModeTYPE, enter_init, "fmi3EnterInitializationMode");
        LOAD(fmi3ExitInitializationModeTYPE, exit_init, "fmi3ExitInitializationMode");
        LOAD(fmi3SetFloat64TYPE, set_float64, "fmi3SetFloat64");
        LOAD(fmi3SetInt32TYPE, set_int32, "fmi3SetInt32");
        LOAD(fmi3SetBooleanTYPE, set_boolean, "fmi3SetBoolean");
        LOAD(fmi3GetFloat64TYPE, get_float64, "fmi3GetFloat64");
        LOAD(fmi3GetBooleanTYPE, get_boolean, "fmi3GetBoolean");
        LOAD(fmi3DoStepTYPE, do_step, "fmi3DoStep");
        LOAD(fmi3TerminateTYPE, terminate, "fmi3Terminate");
        LOAD(fmi3FreeInstanceTYPE, free_instance, "fmi3FreeInstance");
        fmi3Instance c;
        fmi3Float64 values[MAX_VARS];
        fmi3Boolean flags[MAX_VARS], event, stop, early;
        fmi3Int32 ints[MAX_VARS];
        fmi3Float64 last;
        size_t offset = 0;

        if (strcmp(get_version(), "3.0")) return fail("not an FMI 3.0 binary");
        c = instantiate("host", guid, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL,
                        log_message, NULL);
        if (!c) return fail("fmi3InstantiateCoSimulation failed");
        if (enter_init(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) > fmi3Warning)
            return fail("fmi3EnterInitializationMode failed");
        if (n_r && set_float64(c, vr_r, n_r, params_r, n_r) > fmi3Warning) return fail("set Float64 parameters");
        for (i = 0; i < n_a; offset += array_len[i], ++i)
            if (set_float64(c, &vr_a[i], 1, &array_values[offset], array_len[i]) > fmi3Warning)
                return fail("set a Float64 array parameter");
        for (i = 0; i < n_i; ++i) ints[i] = params_i[i];
        if (n_i && set_int32(c, vr_i, n_i, ints, n_i) > fmi3Warning) return fail("set Int32 parameters");
        for (i = 0; i < n_b; ++i) flags[i] = params_b[i] ? fmi3True : fmi3False;
        if (n_b && set_boolean(c, vr_b, n_b, flags, n_b) > fmi3Warning) return fail("set Boolean parameters");
        if (n_in && set_float64(c, in, n_in, data, n_in) > fmi3Warning) return fail("set inputs");
        if (exit_init(c) > fmi3Warning) return fail("fmi3ExitInitializationMode failed");
        for (k = 0; k <= steps; ++k) {
            const double t = k * h;     /* the grid t0 + k h, never accumulated */
            if (n_in && set_float64(c, in, n_in, &data[(size_t)k * n_in], n_in) > fmi3Warning)
                return fail("fmi3SetFloat64 (inputs) failed");
            if (get_float64(c, out, n_out, values, n_out) > fmi3Warning) return fail("fmi3GetFloat64 failed");
            if (n_bout && get_boolean(c, bout, n_bout, flags, n_bout) > fmi3Warning)
                return fail("fmi3GetBoolean failed");
            printf("%.17g", t);
            for (i = 0; i < n_out; ++i) printf(" %.17g", values[i]);
            for (i = 0; i < n_bout; ++i) printf(" %d", flags[i] ? 1 : 0);
            printf("\n");
            if (k < steps && do_step(c, t, h, fmi3True, &event, &stop, &early, &last) > fmi3Warning)
                return fail("fmi3DoStep failed");
        }
        terminate(c);
        free_instance(c);
    }
#else
    (void)vr_a; (void)array_len;
    if (n_a) return fail("reals (array parameters) need FMI 3.0");
    lib = LIB_OPEN(argv[2]);
    if (!lib) return fail("cannot load the binary");
    {
        LOAD(fmi2GetVersionTYPE, get_version, "fmi2GetVersion");
        LOAD(fmi2GetTypesPlatformTYPE, get_types_platform, "fmi2GetTypesPlatform");
        LOAD(fmi2InstantiateTYPE, instantiate, "fmi2Instantiate");
        LOAD(fmi2SetupExperimentTYPE, setup_experiment, "fmi2SetupExperiment");
        LOAD(fmi2EnterInitializationModeTYPE, enter_init, "fmi2EnterInitializationMode");
        LOAD(fmi2ExitInitializationModeTYPE, exit_init, "fmi2ExitInitializationMode");
        LOAD(fmi2SetRealTYPE, set_real, "fmi2SetReal");
        LOAD(fmi2SetIntegerTYPE, set_integer, "fmi2SetInteger");
        LOAD(fmi2SetBooleanTYPE, set_boolean, "fmi2SetBoolean");
        LOAD(fmi2GetRealTYPE, get_real, "fmi2GetReal");
        LOAD(fmi2GetBooleanTYPE, get_boolean, "fmi2GetBoolean");
        LOAD(fmi2DoStepTYPE, do_step, "fmi2DoStep");
        LOAD(fmi2TerminateTYPE, terminate, "fmi2Terminate");
        LOAD(fmi2FreeInstanceTYPE, free_instance, "fmi2FreeInstance");
        fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
        fmi2Component c;
        fmi2Real values[MAX_VARS];
        fmi2Boolean flags[MAX_VARS];
        fmi2Integer ints[MAX_VARS];

        if (strcmp(get_version(), "2.0") || strcmp(get_types_platform(), "default"))
            return fail("not an FMI 2.0 binary with the default types platform");
        c = instantiate("host", fmi2CoSimulation, guid, "file:///", &callbacks, fmi2False, fmi2False);
        if (!c) return fail("fmi2Instantiate failed");
        if (setup_experiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning ||
            enter_init(c) > fmi2Warning)
            return fail("setup or initialization mode failed");
        if (n_r && set_real(c, vr_r, n_r, params_r) > fmi2Warning) return fail("set real parameters");
        for (i = 0; i < n_i; ++i) ints[i] = params_i[i];
        if (n_i && set_integer(c, vr_i, n_i, ints) > fmi2Warning) return fail("set integer parameters");
        for (i = 0; i < n_b; ++i) flags[i] = params_b[i] ? fmi2True : fmi2False;
        if (n_b && set_boolean(c, vr_b, n_b, flags) > fmi2Warning) return fail("set boolean parameters");
        if (n_in && set_real(c, in, n_in, data) > fmi2Warning) return fail("set inputs");
        if (exit_init(c) > fmi2Warning) return fail("fmi2ExitInitializationMode failed");
        for (k = 0; k <= steps; ++k) {
            const double t = k * h;     /* the grid t0 + k h, never accumulated */
            if (n_in && set_real(c, in, n_in, &data[(size_t)k * n_in]) > fmi2Warning)
                return fail("fmi2SetReal (inputs) failed");
            if (get_real(c, out, n_out, values) > fmi2Warning) return fail("fmi2GetReal failed");
            if (n_bout && get_boolean(c, bout, n_bout, flags) > fmi2Warning)
                return fail("fmi2GetBoolean failed");
            printf("%.17g", t);
            for (i = 0; i < n_out; ++i) printf(" %.17g", values[i]);
            for (i = 0; i < n_bout; ++i) printf(" %d", flags[i] ? 1 : 0);
            printf("\n");
            if (k < steps && do_step(c, t, h, fmi2True) > fmi2Warning) return fail("fmi2DoStep failed");
        }
        terminate(c);
        free_instance(c);
    }
#endif
    free(data);
    return 0;
}
