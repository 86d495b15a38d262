/*
 * host_common.h - the part of the C test hosts' layer that knows no FMI
 * version: one "ok"/"FAIL" line per check and the summary line, the log of
 * what an instance said, the variables of a model description, the drive
 * signals and configurations of the suites' runs, the heap's count of bytes in
 * use, and files. The FMI 2.0 and FMI 3.0 adapters (host_fmi2.h, host_fmi3.h)
 * build on it; a suite includes host.h, which picks the adapter of FMI_VERSION.
 */
#ifndef HOST_COMMON_H
#define HOST_COMMON_H

#define _DEFAULT_SOURCE 1  /* glibc: POSIX 2008 plus MAP_ANONYMOUS */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "state_format.h"

/* the Real outputs a host's buffers hold (host_real_outputs fails beyond it; the closed-loop
 * FMU has 17) */
#define HOST_MAX_OUTPUTS 32

/* ------------------------------------------------------------------------ */
/* checks                                                                    */

static atomic_int host_passed, host_failed;
static int host_verbose = 1;    /* 0: print failures only */

static inline int check(int condition, const char *fmt, ...)
{
    va_list ap;
    if (condition)
        atomic_fetch_add(&host_passed, 1);
    else
        atomic_fetch_add(&host_failed, 1);
    if (!condition || host_verbose) {
        printf(condition ? "ok   " : "FAIL ");
        va_start(ap, fmt);
        vprintf(fmt, ap);
        va_end(ap);
        printf("\n");
    }
    return condition;
}

/* A failure that is not a check of its own (a file that cannot be read, a variable or a
 * symbol that is missing, a value the FMU refused where the suite needs it set): printed as
 * "FAIL ..." and counted, so the summary and the exit code show it. */
static inline void host_fail(const char *fmt, ...)
{
    va_list ap;
    atomic_fetch_add(&host_failed, 1);
    printf("FAIL ");
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
    printf("\n");
}

/* The last line every host prints: "N passed, M failed"; exit code 1 on failure. */
static inline int host_summary(void)
{
    printf("%d passed, %d failed\n", atomic_load(&host_passed), atomic_load(&host_failed));
    fflush(stdout);
    return atomic_load(&host_failed) ? 1 : 0;
}

/* ------------------------------------------------------------------------ */
/* what an instance said (its logger's environment)                          */

typedef struct {
    int n_messages;
    int n_errors;
    char last[1024];            /* the last message */
    char last_error[1024];      /* the last message of status Error or worse */
    char errors[4096];          /* every such message since the last clear, "; "-joined, truncated */
} host_log;

static inline void host_log_clear(host_log *log)
{
    memset(log, 0, sizeof *log);
}

/* One message into log (NULL: dropped); is_error: status Error or worse. */
static inline void host_log_record(host_log *log, int is_error, const char *text)
{
    if (log == NULL)
        return;
    log->n_messages++;
    snprintf(log->last, sizeof log->last, "%s", text != NULL ? text : "(NULL)");
    if (is_error) {
        size_t used = strlen(log->errors);
        log->n_errors++;
        snprintf(log->last_error, sizeof log->last_error, "%s", log->last);
        snprintf(log->errors + used, sizeof log->errors - used, "%s%s", used ? "; " : "", log->last);
    }
}

/* ------------------------------------------------------------------------ */
/* the C library's count of bytes in use                                     */

/* Bytes the C library has handed out and not taken back, or -1 when it cannot
 * say exactly. glibc's count (mallinfo2) is exact only without its per-thread
 * cache, which keeps freed blocks counted as in use: the hosts are run with
 * GLIBC_TUNABLES=glibc.malloc.tcache_count=0 (CTest and pytest set it). Under a
 * sanitizer or valgrind the count is theirs; LeakSanitizer and memcheck check
 * leaks over the whole run anyway. */
static inline long host_heap_in_use(void)
{
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
    const char *tunables = getenv("GLIBC_TUNABLES");
    if (tunables == NULL || strstr(tunables, "glibc.malloc.tcache_count=0") == NULL)
        return -1;
    return (long)mallinfo2().uordblks;
#else
    return -1;
#endif
}

/* "compared" or why not, for a host's first line. */
static inline const char *host_heap_note(void)
{
    return host_heap_in_use() >= 0 ? "bytes in use compared per case (glibc, tcache off)"
                                   : "bytes in use NOT compared (run with GLIBC_TUNABLES=glibc.malloc.tcache_count=0)";
}

/* ------------------------------------------------------------------------ */
/* files                                                                     */

/* The whole file, NUL-terminated (malloc'ed; *size its length unless NULL), or NULL. */
static inline char *host_read_file(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    char *text;
    long n;
    if (f == NULL)
        return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    text = n >= 0 ? (char *)malloc((size_t)n + 1) : NULL;
    if (text != NULL && fread(text, 1, (size_t)n, f) != (size_t)n) {
        free(text);
        text = NULL;
    }
    if (text != NULL) {
        text[n] = '\0';
        if (size != NULL)
            *size = (size_t)n;
    }
    fclose(f);
    return text;
}

static inline int host_write_file(const char *path, const void *data, size_t size)
{
    FILE *f = fopen(path, "wb");
    int ok = f != NULL && fwrite(data, 1, size, f) == size;
    if (f != NULL && fclose(f) != 0)
        ok = 0;
    return ok;
}

/* ------------------------------------------------------------------------ */
/* the variables of a model description                                      */

enum { VAR_REAL = 0, VAR_INTEGER = 1, VAR_BOOLEAN = 2 };    /* FMI 3.0: Float64, Int32, Boolean */
enum { VAR_PARAMETER = 0, VAR_INPUT = 1, VAR_OUTPUT = 2, VAR_INDEPENDENT = 3 };  /* independent: FMI 3.0's time */

#define HOST_MAX_VARS 256   /* PiezoStageClosedLoop has 141 (FMI 2.0); more is refused, loudly */
#define HOST_MAX_ELEMENTS 32

typedef struct {
    char name[64];
    unsigned int vr;            /* fmi2ValueReference and fmi3ValueReference alike */
    int type;                   /* VAR_REAL, VAR_INTEGER, VAR_BOOLEAN */
    int causality;              /* VAR_PARAMETER, VAR_INPUT, VAR_OUTPUT, VAR_INDEPENDENT */
    int n;                      /* values: 1 for a scalar, the size of an FMI 3.0 array */
    double start[HOST_MAX_ELEMENTS];    /* parameters and inputs, per element */
    int has_min, has_max;       /* the declared range, where the model description has one */
    double min, max;
} host_var;

/* An FMU as an adapter loads it (host2_fmu, host3_fmu): its description's names and
 * step, its binary and the version's functions (api, of type API), its variables. The
 * code written once over both adapters (host_adapter.h, host.h) reads these fields. */
#define HOST_FMU_STRUCT(API)                                                        \
    struct {                                                                        \
        char id[64];                /* modelIdentifier */                           \
        char token[64];             /* guid (FMI 2.0), instantiationToken (3.0) */  \
        double h;                   /* DefaultExperiment stepSize */                \
        void *lib;                                                                  \
        API api;                                                                    \
        host_var vars[HOST_MAX_VARS];                                               \
        int n_vars;                                                                 \
    }

/* The value of attribute `name` inside [p, end), copied into out; 0 if absent. */
static inline int xml_attribute(const char *p, const char *end, const char *name, char *out, size_t size)
{
    char key[80];
    const char *a, *q;
    if (p == NULL || end == NULL)
        return 0;
    snprintf(key, sizeof key, " %s=\"", name);
    a = strstr(p, key);
    if (a == NULL || a >= end)
        return 0;
    a += strlen(key);
    q = strchr(a, '"');
    if (q == NULL || q >= end || (size_t)(q - a) >= size)
        return 0;
    memcpy(out, a, (size_t)(q - a));
    out[q - a] = '\0';
    return 1;
}

/* The value of attribute `name` of the opening tag at p (up to its first '>'). */
static inline int xml_tag_attribute(const char *p, const char *name, char *out, size_t size)
{
    return p != NULL && xml_attribute(p, strchr(p, '>'), name, out, size);
}

/* Name, value reference, causality, start values and range of the variable
 * whose attributes stand in [p, end); v->type and v->n are the adapter's. */
static inline void host_var_attributes(host_var *v, const char *p, const char *end)
{
    char value[1024] = "";
    xml_attribute(p, end, "name", v->name, sizeof v->name);
    xml_attribute(p, end, "valueReference", value, sizeof value);
    v->vr = (unsigned int)strtoul(value, NULL, 10);
    value[0] = '\0';
    xml_attribute(p, end, "causality", value, sizeof value);
    v->causality = strcmp(value, "output") == 0 ? VAR_OUTPUT
                 : strcmp(value, "input") == 0 ? VAR_INPUT
                 : strcmp(value, "independent") == 0 ? VAR_INDEPENDENT : VAR_PARAMETER;
    if (xml_attribute(p, end, "start", value, sizeof value)) {
        /* one value per element, space-separated: true, false or a number */
        char *s = value, *after;
        int j;
        for (j = 0; j < v->n; j++) {
            while (*s == ' ')
                s++;
            if (strncmp(s, "true", 4) == 0) {
                v->start[j] = 1.0;
                s += 4;
            } else if (strncmp(s, "false", 5) == 0) {
                v->start[j] = 0.0;
                s += 5;
            } else {
                v->start[j] = strtod(s, &after);
                s = after;
            }
        }
    }
    if ((v->has_min = xml_attribute(p, end, "min", value, sizeof value)) != 0)
        v->min = atof(value);
    if ((v->has_max = xml_attribute(p, end, "max", value, sizeof value)) != 0)
        v->max = atof(value);
}

/* The first variable with this causality and type, or NULL. */
static inline const host_var *host_vars_find(const host_var *vars, int n_vars, int causality, int type)
{
    int i;
    for (i = 0; i < n_vars; i++)
        if (vars[i].causality == causality && vars[i].type == type)
            return &vars[i];
    return NULL;
}

/* The variable called name, or the FMI 3.0 array whose element name is
 * ("pi.w[2]": *element = 1; element may be NULL); NULL if there is none. */
static inline const host_var *host_vars_named(const host_var *vars, int n_vars, const char *name, int *element)
{
    int i, scratch;
    const char *bracket = strchr(name, '[');
    if (element == NULL)
        element = &scratch;
    *element = -1;
    for (i = 0; i < n_vars; i++)
        if (strcmp(vars[i].name, name) == 0)
            return &vars[i];
    if (bracket == NULL)
        return NULL;
    for (i = 0; i < n_vars; i++) {
        size_t len = strlen(vars[i].name);
        if (vars[i].n > 1 && len == (size_t)(bracket - name) && strncmp(vars[i].name, name, len) == 0) {
            int j = atoi(bracket + 1);
            if (j < 1 || j > vars[i].n)
                return NULL;
            *element = j - 1;
            return &vars[i];
        }
    }
    return NULL;
}

/* For an FMU of either adapter (both hold vars and n_vars). */
#define host_find(f, causality, type) host_vars_find((f)->vars, (f)->n_vars, (causality), (type))
#define host_named(f, name, element) host_vars_named((f)->vars, (f)->n_vars, (name), (element))

/* ------------------------------------------------------------------------ */
/* values, drives and configurations of the suites' runs                     */

/* What a doStep reports: where it left the FMU, and FMI 3.0's out-arguments
 * (FMI 2.0 has none: 0). */
typedef struct {
    double last;                /* lastSuccessfulTime */
    int event, terminate, early;    /* eventHandlingNeeded, terminateSimulation, earlyReturn */
} host_step_result;

static inline int all_finite(const double *x, int n)
{
    int i;
    for (i = 0; i < n; i++)
        if (!isfinite(x[i]))
            return 0;
    return 1;
}

/* Input j at sample k of configuration i: a few microns, a few hertz apart. */
static inline double host_drive(int i, int j, int k, double h)
{
    return (2.0 + i) * sin(2.0 * 3.14159265358979323846 * (1.0 + i + 3.0 * j) * k * h + j) + 0.5 * i;
}

/* Setting j of configuration i (0 past the last): exact or SOE creep, sensor
 * noise with its own seed, a creep row, controller tuning, reference tones, for
 * whichever of them the FMU has (host_apply_config in host.h). */
static inline int host_config_setting(int i, int j, const char **name, double *value)
{
    const struct { const char *name; double value; } settings[] = {
        {"creep.exact", (double)(i % 2)},
        {"sensor.noise_rms", 0.001 * (i % 4)},
        {"sensor.resolution", i % 3 == 0 ? 0.002 : 0.0},
        {"sensor.seed", (double)(17 + i)},
        {"creep.alpha", 0.0002 * (1 + i)},
        {"mv.lambda_u", 0.01 * (i % 3)},
        {"rls.forgetting", 0.99 + 0.001 * i},
        {"amplitude[1]", 1.0 + i},
        {"frequency[1]", 1.0 + 2.0 * i},
        {"amplitude[2]", 0.5},
        {"frequency[2]", 13.0 + i},
        {"offset", 0.25 * i},
        {"monitor.divergence_samples", 0.0},   /* the drive is no closed loop: never call it unstable, */
        {"sup.enabled", 0.0},                  /* nor stop it as one that cannot work */
    };
    if (j < 0 || j >= (int)(sizeof settings / sizeof settings[0]))
        return 0;
    *name = settings[j].name;
    *value = settings[j].value;
    return 1;
}

#endif
