/*
 * fmu_start_values.c - read resources/start_values once at instantiation and
 * apply it over the compiled defaults (see fmu_start_values.h for the format).
 *
 * Robustness: the resources location comes from the importer and the file
 * from whoever wrote the FMU, so neither is trusted. Every path through the
 * code is bounded (line length, one entry per variable), no byte of the file
 * is used before it is checked, and a bad file is refused with one error
 * naming the file, the line and what is wrong; it never crashes the host.
 */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_glue_core.h"
#include "fmu_start_values.h"

typedef struct {
    int vr;             /* value reference = index into model_variables */
    double real;        /* MODEL_REAL */
    int integer;        /* MODEL_INTEGER, MODEL_BOOLEAN (0 or 1) */
    int line;           /* where it was set, for duplicate messages */
} start_value;

struct fmu_start_values {
    size_t count;
    start_value entries[MODEL_N_VARIABLES];
};

#define log_msg glue_host_log

/* ------------------------------------------------------------------------ */
/* file URI -> local path                                                    */

static int lower(int c)
{
    return (c >= 'A' && c <= 'Z') ? c - 'A' + 'a' : c;
}

/* Case-insensitive: does s start with prefix? */
static int starts_with_ci(const char *s, const char *prefix)
{
    for (; *prefix != '\0'; s++, prefix++)
        if (lower((unsigned char)*s) != lower((unsigned char)*prefix))
            return 0;
    return 1;
}

static int hex_value(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    c = lower(c);
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

/* The local path of a file URI (file:///p, file://localhost/p, file:/p),
 * %XX decoded, query and fragment dropped, trailing '/' removed. Returns 1,
 * or 0 with *why set. */
static int uri_to_path(const char *uri, char *path, size_t size, const char **why)
{
    const char *p;
    size_t n = 0;
    if (!starts_with_ci(uri, "file:")) {
        *why = "only file: URIs name a local folder";
        return 0;
    }
    p = uri + 5;
    if (p[0] == '/' && p[1] == '/') {             /* authority: empty or localhost */
        const char *host = p + 2, *end = strchr(host, '/');
        size_t len = end != NULL ? (size_t)(end - host) : strlen(host);
        if (end == NULL) {
            *why = "no path after the host";
            return 0;
        }
        if (!(len == 0 || (len == 9 && starts_with_ci(host, "localhost")))) {
            *why = "the URI names another host";
            return 0;
        }
        p = end;
    }
    if (p[0] != '/') {
        *why = "the path is not absolute";
        return 0;
    }
    for (; *p != '\0' && *p != '?' && *p != '#'; p++) {
        int c = (unsigned char)*p;
        if (c == '%') {
            int hi = hex_value((unsigned char)p[1]), lo = hi < 0 ? -1 : hex_value((unsigned char)p[2]);
            if (hi < 0 || lo < 0) {
                *why = "a '%' is not followed by two hexadecimal digits";
                return 0;
            }
            c = hi * 16 + lo;
            if (c == 0) {
                *why = "%00 in the path";
                return 0;
            }
            p += 2;
        }
        if (n + 1 >= size) {
            *why = "the path is too long";
            return 0;
        }
        path[n++] = (char)c;
    }
    while (n > 1 && path[n - 1] == '/')
        n--;
    path[n] = '\0';
    return 1;
}

/* ------------------------------------------------------------------------ */
/* parsing                                                                   */

typedef enum { LINE_OK, LINE_EOF, LINE_TOO_LONG, LINE_NUL, LINE_READ_ERROR } line_status;

/* Read one line (without its '\n' or "\r\n") into buf of size
 * FMU_START_VALUES_LINE_MAX + 1; the rest of an over-long line is consumed. */
static line_status read_line(FILE *f, char *buf)
{
    size_t n = 0;
    int c, any = 0, too_long = 0, nul = 0;
    while ((c = getc(f)) != EOF) {
        any = 1;
        if (c == '\n')
            break;
        if (c == '\0')
            nul = 1;
        if (n < FMU_START_VALUES_LINE_MAX)
            buf[n++] = (char)c;
        else
            too_long = 1;
    }
    if (ferror(f))
        return LINE_READ_ERROR;
    if (!any)
        return LINE_EOF;
    if (n > 0 && buf[n - 1] == '\r')
        n--;
    buf[n] = '\0';
    return nul ? LINE_NUL : too_long ? LINE_TOO_LONG : LINE_OK;
}

static char *trim(char *s)
{
    char *end;
    while (*s == ' ' || *s == '\t')
        s++;
    end = s + strlen(s);
    while (end > s && (end[-1] == ' ' || end[-1] == '\t'))
        *--end = '\0';
    return s;
}

static int find_variable(const char *name)
{
    int i;
    for (i = 0; i < (int)MODEL_N_VARIABLES; i++)
        if (strcmp(model_variables[i].name, name) == 0)
            return i;
    return -1;
}

/* Parse text as a value of the given type into e; 0 with *why on failure. */
static int parse_value(const char *text, model_type type, start_value *e, const char **why)
{
    char *end;
    if (type == MODEL_REAL) {
        e->real = strtod(text, &end);
        if (end == text || *end != '\0') {
            *why = "is not a Real number";
            return 0;
        }
        if (!isfinite(e->real)) {               /* nan, inf, or an overflow to inf */
            *why = "is not finite";
            return 0;
        }
        return 1;                               /* an underflow keeps the nearest value */
    }
    if (type == MODEL_INTEGER) {
        long v;
        errno = 0;
        v = strtol(text, &end, 10);
        if (end == text || *end != '\0') {
            *why = "is not an Integer";
            return 0;
        }
        if (errno == ERANGE || v < INT_MIN || v > INT_MAX) {
            *why = "is outside the Integer range";
            return 0;
        }
        e->integer = (int)v;
        return 1;
    }
    if (strcmp(text, "true") == 0 || strcmp(text, "1") == 0) {
        e->integer = 1;
        return 1;
    }
    if (strcmp(text, "false") == 0 || strcmp(text, "0") == 0) {
        e->integer = 0;
        return 1;
    }
    *why = "is not a Boolean (true, false, 1 or 0)";
    return 0;
}

static const char *causality_name(model_causality c)
{
    return c == MODEL_INPUT ? "an input" : c == MODEL_OUTPUT ? "an output" : "a parameter";
}

/* Parse the open file into sv; 0 after logging the first problem. */
static int parse_file(FILE *f, const char *path, fmu_start_values *sv,
                      const glue_host *cb, const char *name, const char *where)
{
    char buf[FMU_START_VALUES_LINE_MAX + 1];
    int line = 0, seen[MODEL_N_VARIABLES];
    size_t i;
    line_status st;
    for (i = 0; i < (size_t)MODEL_N_VARIABLES; i++)
        seen[i] = 0;
    while ((st = read_line(f, buf)) != LINE_EOF) {
        char *text, *eq, *key, *value;
        const char *why = NULL;
        int vr;
        start_value e;
        line++;
        if (st == LINE_READ_ERROR) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: cannot be read: %s", where, path, line,
                    strerror(errno));
            return 0;
        }
        if (st == LINE_NUL) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: contains a NUL byte (not a text file?)",
                    where, path, line);
            return 0;
        }
        if (st == LINE_TOO_LONG) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: longer than %d characters", where, path,
                    line, FMU_START_VALUES_LINE_MAX);
            return 0;
        }
        text = trim(buf);
        if (text[0] == '\0' || text[0] == '#')
            continue;
        eq = strchr(text, '=');
        if (eq == NULL) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: expected 'name = value', got '%s'",
                    where, path, line, text);
            return 0;
        }
        *eq = '\0';
        key = trim(text);
        value = trim(eq + 1);
        if (key[0] == '\0' || value[0] == '\0') {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: expected 'name = value', the %s is empty",
                    where, path, line, key[0] == '\0' ? "name" : "value");
            return 0;
        }
        vr = find_variable(key);
        if (vr < 0) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: '%s' is not a variable of %s",
                    where, path, line, key, MODEL_IDENTIFIER_STRING);
            return 0;
        }
        if (model_variables[vr].causality != MODEL_PARAMETER) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: '%s' is %s, only parameters may be "
                    "given start values here", where, path, line, key,
                    causality_name(model_variables[vr].causality));
            return 0;
        }
        if (seen[vr]) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: '%s' was already set on line %d",
                    where, path, line, key, seen[vr]);
            return 0;
        }
        e.vr = vr;
        e.real = 0.0;
        e.integer = 0;
        e.line = line;
        if (!parse_value(value, model_variables[vr].type, &e, &why)) {
            log_msg(cb, name, GLUE_ERROR, "%s: %s line %d: %s = '%s' %s", where, path, line, key,
                    value, why);
            return 0;
        }
        seen[vr] = line;
        sv->entries[sv->count++] = e;
    }
    return 1;
}

/* ------------------------------------------------------------------------ */
/* public                                                                    */

int fmu_start_values_init(fmu_start_values **sv, const char *resource_location, int is_uri,
                          const char *fname, const char *location_arg, const glue_host *cb,
                          const char *instance_name, ModelData *data)
{
    char where[96];
    const char *why = NULL;
    char *path;
    size_t size;
    FILE *f;
    fmu_start_values *out;
    int ok;

    *sv = NULL;
    if (resource_location == NULL || resource_location[0] == '\0')
        return 1;                               /* no resources: the compiled defaults stand */
    snprintf(where, sizeof where, "%s: start values", fname);
    size = strlen(resource_location) + sizeof "/" FMU_START_VALUES_FILE;
    path = (char *)cb->alloc(size, 1);
    if (path == NULL) {
        log_msg(cb, instance_name, GLUE_ERROR, "%s: out of memory", where);
        return 0;
    }
    if (is_uri) {
        /* the decoded path is never longer than the URI: room is left for the file name */
        if (!uri_to_path(resource_location, path, size - (sizeof "/" FMU_START_VALUES_FILE - 1), &why)) {
            /* Cannot tell whether the FMU has a start_values file: warn, keep the defaults. */
            log_msg(cb, instance_name, GLUE_WARNING, "%s: %s '%s' is not read (%s); "
                    "the compiled start values are used", where, location_arg, resource_location, why);
            cb->release(path);
            return 1;
        }
    } else {
        /* a folder path; FMI 3.0 ends it with a separator */
        size_t n = strlen(resource_location);
        memcpy(path, resource_location, n + 1);
        while (n > 1 && (path[n - 1] == '/' || path[n - 1] == '\\'))
            path[--n] = '\0';
    }
    strcat(path, "/" FMU_START_VALUES_FILE);
    errno = 0;
    f = fopen(path, "rb");
    if (f == NULL) {
        int err = errno;
        ok = err == ENOENT || err == ENOTDIR;   /* no file: nothing to apply */
        if (!ok)
            log_msg(cb, instance_name, GLUE_ERROR, "%s: cannot open %s: %s", where, path,
                    strerror(err));
        cb->release(path);
        return ok;
    }
    out = (fmu_start_values *)cb->alloc(1, sizeof *out);
    if (out == NULL) {
        fclose(f);
        log_msg(cb, instance_name, GLUE_ERROR, "%s: out of memory", where);
        cb->release(path);
        return 0;
    }
    out->count = 0;
    ok = parse_file(f, path, out, cb, instance_name, where);
    fclose(f);
    cb->release(path);
    if (!ok) {
        cb->release(out);
        return 0;
    }
    fmu_start_values_apply(out, data);
    *sv = out;
    return 1;
}

void fmu_start_values_apply(const fmu_start_values *sv, ModelData *data)
{
    size_t i;
    if (sv == NULL)
        return;
    for (i = 0; i < sv->count; i++) {
        const start_value *e = &sv->entries[i];
        char *p = (char *)data + model_variables[e->vr].offset;
        if (model_variables[e->vr].type == MODEL_REAL)
            memcpy(p, &e->real, sizeof e->real);
        else
            memcpy(p, &e->integer, sizeof e->integer);
    }
}

void fmu_start_values_free(fmu_start_values **sv, const glue_host *cb)
{
    if (*sv != NULL)
        cb->release(*sv);
    *sv = NULL;
}
