/*
 * fmu_host.c - a minimal FMI 2.0 Co-Simulation host that builds for Linux (dlopen; native,
 * or cross-compiled and run under qemu-user) and for Windows (LoadLibrary, with MinGW-w64,
 * run under wine), so that the same experiment runs every platform's binary of an FMU.
 * Used by tests/test_fmu_platforms.py. Compiled with -DFMU_HOST_FMI3 it is the same host
 * for FMI 3.0 Co-Simulation binaries: the plan and the output are the same, the calls fmi3.
 *
 * usage: fmu_host PLAN BINARY [BINARY...]     (one binary per "fmu" of the plan, in order)
 *
 * PLAN is a text file of whitespace-separated tokens:
 *     step H   steps N
 *     fmu ID TOKEN          starts an FMU (model identifier, GUID or instantiation token);
 *                           what follows, up to the next "fmu", is about it:
 *     real VR VALUE | integer VR VALUE | boolean VR 0|1     (parameters, set before init)
 *     reals VR N VALUE...   (FMI 3.0 only: a Float64 array parameter, all N elements)
 *     input VR ...          (Real inputs, one column each in the data)
 *     output VR ...         (Real outputs)   boutput VR ...   (Boolean outputs)
 *     connect FROM VR TO VR (FMU indices from 0: a Real output of FROM to an input of TO,
 *                            passed at every communication point, in the plan's order)
 *     data                  followed by N + 1 rows of input values (row k applies at t_k)
 * At each t_k = k H: the inputs of row k are set, the connections passed, the outputs
 * printed ("%.17g"; booleans 0/1), then every FMU steps from t_k to t_(k+1) in plan order.
 * Prints N + 1 rows: t_k and the outputs at t_k (row 0 after initialization).
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

#define MAX_FMUS 8
#define MAX_VARS 64
#define MAX_ARRAY_VALUES 256

typedef struct {
    char id[256], token[256];
    lib_handle lib;
    unsigned vr_r[MAX_VARS], vr_i[MAX_VARS], vr_b[MAX_VARS], vr_a[MAX_VARS];
    double params_r[MAX_VARS];
    int params_i[MAX_VARS], params_b[MAX_VARS];
    double array_values[MAX_ARRAY_VALUES];
    size_t array_len[MAX_VARS], n_values, n_a, n_r, n_i, n_b;
    unsigned in[MAX_VARS];
    size_t n_in, first_column;       /* its inputs are data columns first_column.. */
#ifdef FMU_HOST_FMI3
    fmi3Instance c;
    fmi3SetFloat64TYPE *set_real;
    fmi3GetFloat64TYPE *get_real;
    fmi3GetBooleanTYPE *get_boolean;
    fmi3DoStepTYPE *do_step;
    fmi3TerminateTYPE *terminate;
    fmi3FreeInstanceTYPE *free_instance;
#else
    fmi2Component c;
    fmi2SetRealTYPE *set_real;
    fmi2GetRealTYPE *get_real;
    fmi2GetBooleanTYPE *get_boolean;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
#endif
} fmu_t;

typedef struct { size_t fmu; unsigned vr; int boolean; } output_t;
typedef struct { size_t from, to; unsigned from_vr, to_vr; } connection_t;

static fmu_t fmus[MAX_FMUS];
static size_t n_fmus;
static output_t outputs[MAX_FMUS * MAX_VARS];
static size_t n_outputs;
static connection_t connections[MAX_FMUS * MAX_VARS];
static size_t n_connections;

#ifdef FMU_HOST_FMI3
static void log_message(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                        fmi3String message)
{
    (void)env;
    fprintf(stderr, "[host] %d %s: %s\n", (int)status, category ? category : "?", message ? message : "");
}
#define STATUS_OK(s) ((s) <= fmi3Warning)
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
static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
#define STATUS_OK(s) ((s) <= fmi2Warning)
#endif

static int fail(const char *what, const char *id)
{
    fprintf(stderr, "fmu_host: %s%s%s\n", what, id ? " in " : "", id ? id : "");
    return 1;
}

#define LOAD(f, type, var, name)                                        \
    type *var = (type *)LIB_SYM((f)->lib, name);                        \
    if (!var) return fail("missing symbol " name, (f)->id)
/* LOAD of a function both editions name alike: fmi2DoStep or fmi3DoStep, of its edition's type */
#ifdef FMU_HOST_FMI3
#define LOAD_FMI(f, name, var) LOAD(f, fmi3##name##TYPE, var, "fmi3" #name)
#else
#define LOAD_FMI(f, name, var) LOAD(f, fmi2##name##TYPE, var, "fmi2" #name)
#endif

/* load, instantiate, set the parameters and the first inputs; initialization mode entered */
static int start(fmu_t *f, const char *binary, const double *row0)
{
    size_t i;
    f->lib = LIB_OPEN(binary);
    if (!f->lib) return fail("cannot load the binary", f->id);
    {
        /* the binary's functions, in the order each edition looks them up */
        LOAD_FMI(f, GetVersion, get_version);
#ifdef FMU_HOST_FMI3
        LOAD(f, fmi3InstantiateCoSimulationTYPE, instantiate, "fmi3InstantiateCoSimulation");
        LOAD_FMI(f, EnterInitializationMode, enter_init);
        LOAD(f, fmi3SetInt32TYPE, set_int32, "fmi3SetInt32");
        LOAD_FMI(f, SetBoolean, set_boolean);
        LOAD(f, fmi3SetFloat64TYPE, set_float64, "fmi3SetFloat64");
        LOAD(f, fmi3GetFloat64TYPE, get_float64, "fmi3GetFloat64");
#else
        LOAD(f, fmi2GetTypesPlatformTYPE, get_types_platform, "fmi2GetTypesPlatform");
        LOAD(f, fmi2InstantiateTYPE, instantiate, "fmi2Instantiate");
        LOAD(f, fmi2SetupExperimentTYPE, setup_experiment, "fmi2SetupExperiment");
        LOAD_FMI(f, EnterInitializationMode, enter_init);
        LOAD(f, fmi2SetIntegerTYPE, set_integer, "fmi2SetInteger");
        LOAD_FMI(f, SetBoolean, set_boolean);
        LOAD(f, fmi2SetRealTYPE, set_real, "fmi2SetReal");
        LOAD(f, fmi2GetRealTYPE, get_real, "fmi2GetReal");
#endif
        LOAD_FMI(f, GetBoolean, get_boolean);
        LOAD_FMI(f, DoStep, do_step);
        LOAD_FMI(f, Terminate, terminate);
        LOAD_FMI(f, FreeInstance, free_instance);
        f->get_boolean = get_boolean; f->do_step = do_step; f->terminate = terminate; f->free_instance = free_instance;
#ifdef FMU_HOST_FMI3
        fmi3Boolean flags[MAX_VARS];
        fmi3Int32 ints[MAX_VARS];
        size_t offset = 0;
        f->set_real = set_float64; f->get_real = get_float64;

        if (strcmp(get_version(), "3.0")) return fail("not an FMI 3.0 binary", f->id);
        f->c = instantiate(f->id, f->token, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0,
                           NULL, log_message, NULL);
        if (!f->c) return fail("fmi3InstantiateCoSimulation failed", f->id);
        if (!STATUS_OK(enter_init(f->c, fmi3False, 0.0, 0.0, fmi3False, 0.0)))
            return fail("fmi3EnterInitializationMode failed", f->id);
        if (f->n_r && !STATUS_OK(set_float64(f->c, f->vr_r, f->n_r, f->params_r, f->n_r)))
            return fail("set Float64 parameters", f->id);
        for (i = 0; i < f->n_a; offset += f->array_len[i], ++i)
            if (!STATUS_OK(set_float64(f->c, &f->vr_a[i], 1, &f->array_values[offset], f->array_len[i])))
                return fail("set a Float64 array parameter", f->id);
        for (i = 0; i < f->n_i; ++i) ints[i] = f->params_i[i];
        if (f->n_i && !STATUS_OK(set_int32(f->c, f->vr_i, f->n_i, ints, f->n_i)))
            return fail("set Int32 parameters", f->id);
        for (i = 0; i < f->n_b; ++i) flags[i] = f->params_b[i] ? fmi3True : fmi3False;
        if (f->n_b && !STATUS_OK(set_boolean(f->c, f->vr_b, f->n_b, flags, f->n_b)))
            return fail("set Boolean parameters", f->id);
        if (f->n_in && !STATUS_OK(set_float64(f->c, f->in, f->n_in, row0 + f->first_column, f->n_in)))
            return fail("set inputs", f->id);
#else
        fmi2Boolean flags[MAX_VARS];
        fmi2Integer ints[MAX_VARS];
        f->set_real = set_real; f->get_real = get_real;

        if (f->n_a) return fail("reals (array parameters) need FMI 3.0", f->id);
        if (strcmp(get_version(), "2.0") || strcmp(get_types_platform(), "default"))
            return fail("not an FMI 2.0 binary with the default types platform", f->id);
        f->c = instantiate(f->id, fmi2CoSimulation, f->token, "file:///", &callbacks, fmi2False, fmi2False);
        if (!f->c) return fail("fmi2Instantiate failed", f->id);
        if (!STATUS_OK(setup_experiment(f->c, fmi2False, 0.0, 0.0, fmi2False, 0.0)) ||
            !STATUS_OK(enter_init(f->c)))
            return fail("setup or initialization mode failed", f->id);
        if (f->n_r && !STATUS_OK(set_real(f->c, f->vr_r, f->n_r, f->params_r)))
            return fail("set real parameters", f->id);
        for (i = 0; i < f->n_i; ++i) ints[i] = f->params_i[i];
        if (f->n_i && !STATUS_OK(set_integer(f->c, f->vr_i, f->n_i, ints)))
            return fail("set integer parameters", f->id);
        for (i = 0; i < f->n_b; ++i) flags[i] = f->params_b[i] ? fmi2True : fmi2False;
        if (f->n_b && !STATUS_OK(set_boolean(f->c, f->vr_b, f->n_b, flags)))
            return fail("set boolean parameters", f->id);
        if (f->n_in && !STATUS_OK(set_real(f->c, f->in, f->n_in, row0 + f->first_column)))
            return fail("set inputs", f->id);
#endif
    }
    return 0;
}

static int exit_init(fmu_t *f)
{
    LOAD_FMI(f, ExitInitializationMode, exit_init_mode);
    return STATUS_OK(exit_init_mode(f->c)) ? 0 : fail("exit of initialization mode failed", f->id);
}

static int get_real(fmu_t *f, unsigned vr, double *value)
{
#ifdef FMU_HOST_FMI3
    return STATUS_OK(f->get_real(f->c, &vr, 1, value, 1)) ? 0 : fail("fmi3GetFloat64 failed", f->id);
#else
    return STATUS_OK(f->get_real(f->c, &vr, 1, value)) ? 0 : fail("fmi2GetReal failed", f->id);
#endif
}

static int set_real(fmu_t *f, const unsigned *vr, size_t n, const double *value)
{
#ifdef FMU_HOST_FMI3
    return STATUS_OK(f->set_real(f->c, vr, n, value, n)) ? 0 : fail("fmi3SetFloat64 failed", f->id);
#else
    return STATUS_OK(f->set_real(f->c, vr, n, value)) ? 0 : fail("fmi2SetReal failed", f->id);
#endif
}

static int get_boolean(fmu_t *f, unsigned vr, int *value)
{
#ifdef FMU_HOST_FMI3
    fmi3Boolean b;
    if (!STATUS_OK(f->get_boolean(f->c, &vr, 1, &b, 1))) return fail("fmi3GetBoolean failed", f->id);
#else
    fmi2Boolean b;
    if (!STATUS_OK(f->get_boolean(f->c, &vr, 1, &b))) return fail("fmi2GetBoolean failed", f->id);
#endif
    *value = b ? 1 : 0;
    return 0;
}

static int do_step(fmu_t *f, double t, double h)
{
#ifdef FMU_HOST_FMI3
    fmi3Boolean event, stop, early;
    fmi3Float64 last;
    return STATUS_OK(f->do_step(f->c, t, h, fmi3True, &event, &stop, &early, &last)) ? 0
        : fail("fmi3DoStep failed", f->id);
#else
    return STATUS_OK(f->do_step(f->c, t, h, fmi2True)) ? 0 : fail("fmi2DoStep failed", f->id);
#endif
}

static int read_plan(FILE *plan, double *h, int *steps)
{
    char token[256];
    fmu_t *f = NULL;
    size_t n_columns = 0;
    while (fscanf(plan, "%255s", token) == 1) {
        unsigned vr;
        if (!strcmp(token, "step")) {
            if (fscanf(plan, "%lf", h) != 1) return fail("bad step", NULL);
        } else if (!strcmp(token, "steps")) {
            if (fscanf(plan, "%d", steps) != 1) return fail("bad steps", NULL);
        } else if (!strcmp(token, "fmu")) {
            if (n_fmus == MAX_FMUS) return fail("too many FMUs", NULL);
            f = &fmus[n_fmus++];
            if (fscanf(plan, "%255s %255s", f->id, f->token) != 2) return fail("bad fmu", NULL);
            f->first_column = n_columns;
        } else if (!strcmp(token, "connect")) {
            connection_t *c = &connections[n_connections];
            unsigned long from, to;
            if (n_connections == MAX_FMUS * MAX_VARS ||
                fscanf(plan, "%lu %u %lu %u", &from, &c->from_vr, &to, &c->to_vr) != 4)
                return fail("bad connect", NULL);
            c->from = from;
            c->to = to;
            ++n_connections;
        } else if (!strcmp(token, "data")) {
            return 0;
        } else if (!f) {
            return fail("a variable before the first fmu", NULL);
        } else if (!strcmp(token, "real") && f->n_r < MAX_VARS) {
            if (fscanf(plan, "%u %lf", &vr, &f->params_r[f->n_r]) != 2) return fail("bad real", f->id);
            f->vr_r[f->n_r++] = vr;
        } else if (!strcmp(token, "integer") && f->n_i < MAX_VARS) {
            if (fscanf(plan, "%u %d", &vr, &f->params_i[f->n_i]) != 2) return fail("bad integer", f->id);
            f->vr_i[f->n_i++] = vr;
        } else if (!strcmp(token, "boolean") && f->n_b < MAX_VARS) {
            if (fscanf(plan, "%u %d", &vr, &f->params_b[f->n_b]) != 2) return fail("bad boolean", f->id);
            f->vr_b[f->n_b++] = vr;
        } else if (!strcmp(token, "reals") && f->n_a < MAX_VARS) {
            unsigned long count, i;
            if (fscanf(plan, "%u %lu", &vr, &count) != 2 || count > MAX_ARRAY_VALUES - f->n_values)
                return fail("bad reals", f->id);
            for (i = 0; i < count; ++i)
                if (fscanf(plan, "%lf", &f->array_values[f->n_values + i]) != 1)
                    return fail("bad reals value", f->id);
            f->vr_a[f->n_a] = vr;
            f->array_len[f->n_a++] = count;
            f->n_values += count;
        } else if (!strcmp(token, "input") && f->n_in < MAX_VARS) {
            if (fscanf(plan, "%u", &vr) != 1) return fail("bad input", f->id);
            f->in[f->n_in++] = vr;
            ++n_columns;
        } else if ((!strcmp(token, "output") || !strcmp(token, "boutput")) &&
                   n_outputs < MAX_FMUS * MAX_VARS) {
            if (fscanf(plan, "%u", &vr) != 1) return fail("bad output", f->id);
            outputs[n_outputs].fmu = (size_t)(f - fmus);
            outputs[n_outputs].vr = vr;
            outputs[n_outputs++].boolean = token[0] == 'b';
        } else {
            return fail("unknown plan token (or too many variables)", f->id);
        }
    }
    return fail("no data section", NULL);
}

int main(int argc, char **argv)
{
    double h = 0.0, *data;
    int steps = -1, k;
    size_t i, n_columns = 0;
    FILE *plan;

    if (argc < 3) return fail("usage: fmu_host PLAN BINARY [BINARY...]", NULL);
    plan = fopen(argv[1], "r");
    if (!plan) return fail("cannot open the plan", NULL);
    if (read_plan(plan, &h, &steps)) return 1;
    if (!n_fmus || !(h > 0.0) || steps < 0) return fail("incomplete plan", NULL);
    if ((size_t)argc != 2 + n_fmus) return fail("one binary per fmu of the plan", NULL);
    for (i = 0; i < n_connections; ++i)
        if (connections[i].from >= n_fmus || connections[i].to >= n_fmus)
            return fail("a connection names an FMU the plan does not have", NULL);
    for (i = 0; i < n_fmus; ++i) n_columns += fmus[i].n_in;
    data = calloc((size_t)(steps + 1) * (n_columns ? n_columns : 1), sizeof *data);
    if (!data) return fail("out of memory", NULL);
    for (i = 0; i < (size_t)(steps + 1) * n_columns; ++i)
        if (fscanf(plan, "%lf", &data[i]) != 1) return fail("short data", NULL);
    fclose(plan);

    for (i = 0; i < n_fmus; ++i)
        if (start(&fmus[i], argv[2 + i], data)) return 1;
    for (i = 0; i < n_fmus; ++i)
        if (exit_init(&fmus[i])) return 1;
    for (k = 0; k <= steps; ++k) {
        const double t = k * h;     /* the grid t0 + k h, never accumulated */
        const double *row = &data[(size_t)k * n_columns];
        for (i = 0; i < n_fmus; ++i)
            if (fmus[i].n_in && set_real(&fmus[i], fmus[i].in, fmus[i].n_in, row + fmus[i].first_column))
                return 1;
        for (i = 0; i < n_connections; ++i) {
            double value;
            if (get_real(&fmus[connections[i].from], connections[i].from_vr, &value) ||
                set_real(&fmus[connections[i].to], &connections[i].to_vr, 1, &value))
                return 1;
        }
        printf("%.17g", t);
        for (i = 0; i < n_outputs; ++i) {
            fmu_t *f = &fmus[outputs[i].fmu];
            if (outputs[i].boolean) {
                int b;
                if (get_boolean(f, outputs[i].vr, &b)) return 1;
                printf(" %d", b);
            } else {
                double value;
                if (get_real(f, outputs[i].vr, &value)) return 1;
                printf(" %.17g", value);
            }
        }
        printf("\n");
        if (k < steps)
            for (i = 0; i < n_fmus; ++i)
                if (do_step(&fmus[i], t, h)) return 1;
    }
    for (i = 0; i < n_fmus; ++i) {
        fmus[i].terminate(fmus[i].c);
        fmus[i].free_instance(fmus[i].c);
    }
    free(data);
    return 0;
}
