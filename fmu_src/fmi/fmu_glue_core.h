/*
 * fmu_glue_core.h - the part of the FMI layer that does not depend on the FMI
 * version, shared by fmi2_glue.c (FMI 2.0) and fmi3_glue.c (FMI 3.0). Compiled
 * into every FMU with the model's config.h (see fmu_model.h), like the glues.
 *
 * The core owns: the instance and its identity (an instance is accepted only
 * by the functions of the binary that made it), the modes and which calls each
 * allows, argument, value-reference and type checks, parameter validation
 * through the model, time (t0 + k h, the step-size check, stopTime), stepping
 * with roll-back, the model's warnings, logging through a version-neutral
 * sink, FMU states, and the serialized-state format with its validation of
 * untrusted blobs (fmu_glue_state.c, fmu_state_format.h). A glue maps its version's functions onto these: it checks
 * what only its version has (fmuType, GUID or instantiation token argument,
 * event-mode flags, the memory callbacks), converts statuses and value types,
 * and says how its version names things (glue_version).
 *
 * Every core function that takes a component first checks that it is one of
 * this binary's instances and that its mode allows the call; a refused call
 * logs why, returns GLUE_ERROR and changes nothing (fmi2_glue.c has the table
 * of modes and calls).
 */
#ifndef FMU_GLUE_CORE_H
#define FMU_GLUE_CORE_H

#include <stddef.h>
#include <stdint.h>

#include "fmu_model.h"
#include "fmu_start_values.h"

/* The numbering of fmi2Status and fmi3Status (OK 0, Warning 1, Error 3). */
typedef enum { GLUE_OK = 0, GLUE_WARNING = 1, GLUE_ERROR = 3 } glue_status;

/* Modes, one bit each; the same bits in FMI 2.0 and 3.0 (StepComplete = StepMode)
 * and in the mode field of a serialized state. */
enum {
    GLUE_MODE_INSTANTIATED = 1,
    GLUE_MODE_INIT = 2,
    GLUE_MODE_STEP = 4,
    GLUE_MODE_TERMINATED = 8,
    GLUE_MODE_ERROR = 16
};
#define GLUE_MODE_ALL (GLUE_MODE_INSTANTIATED | GLUE_MODE_INIT | GLUE_MODE_STEP | GLUE_MODE_TERMINATED \
                       | GLUE_MODE_ERROR)
#define GLUE_MODE_CORE_READY (GLUE_MODE_STEP | GLUE_MODE_TERMINATED | GLUE_MODE_ERROR)
#define GLUE_MASK_GET (GLUE_MODE_INIT | GLUE_MODE_STEP | GLUE_MODE_TERMINATED | GLUE_MODE_ERROR)
#define GLUE_MASK_SET (GLUE_MODE_INSTANTIATED | GLUE_MODE_INIT | GLUE_MODE_STEP)
#define GLUE_MASK_STATUS (GLUE_MODE_STEP | GLUE_MODE_TERMINATED)

/* The layout of the values of a get/set call. */
typedef enum {
    GLUE_VALUES_DOUBLE,         /* fmi2Real, fmi3Float64 */
    GLUE_VALUES_INT,            /* fmi2Integer (int) */
    GLUE_VALUES_INT32,          /* fmi3Int32 */
    GLUE_VALUES_BOOL_INT,       /* fmi2Boolean (int; any non-zero value is true) */
    GLUE_VALUES_BOOL_BYTE       /* fmi3Boolean (C bool; read as a byte, non-zero is true) */
} glue_values;

typedef void (*glue_function)(void);

/* The importer's side: where messages go and where memory comes from. */
typedef struct glue_host glue_host;
struct glue_host {
    /* Hands one formatted message to the importer's logger (the version glue's
     * adapter); never called while `logger` is NULL. */
    void (*deliver)(const glue_host *host, const char *instance_name, glue_status status,
                    const char *category, const char *text);
    glue_function logger;       /* the importer's logger; NULL: nothing is logged */
    void *env;                  /* componentEnvironment / instanceEnvironment */
    void *(*alloc)(size_t n, size_t size);  /* zero-filled, like calloc */
    void (*release)(void *p);
};

/* How a version names things in messages, and its variable layout. */
typedef struct {
    const char *mode_names[5];      /* Instantiated, InitializationMode, StepComplete or StepMode,
                                       Terminated, Error */
    const char *type_names[3];      /* by model_type: Real/Integer/Boolean, Float64/Int32/Boolean */
    const char *token_name;         /* "GUID", "instantiationToken" */
    const char *exit_init;          /* the function after which fixed parameters are fixed */
    const char *stop_time_source;   /* the function that set stopTime */
    const char *do_step;            /* the function that commits a sample */
    const char *get_fmu_state, *set_fmu_state, *deserialize, *serialized_size, *reset;
    int arrays;                     /* variables name[1]..name[n] (n >= 2) form one array variable
                                       whose value reference is that of name[1] */
    int time_variable;              /* GLUE_VR_TIME is the independent variable time (read only) */
} glue_version;

/* The bits of glue_instance.scalar. */
#define GLUE_SCALAR_OF(type) (1u << (type))    /* a scalar variable of that model_type */
#define GLUE_SCALAR_INPUT 8u
#define GLUE_SCALAR_OUTPUT 16u

/* The value reference of the independent variable (FMI 3.0): the first after the model's. */
#define GLUE_VR_TIME ((uint32_t)MODEL_N_VARIABLES)

typedef struct glue_state glue_state;

typedef struct {
    uint32_t magic;
    const char *model;          /* the identity of the binary that made it */
    const glue_version *version;
    char *name;
    glue_host host;
    unsigned log_mask;
    int mode;
    double t0;                  /* start time */
    uint64_t k;                 /* samples since t0 */
    double h;                   /* sample period, fixed at the end of initialization */
    double t_off;               /* the FMU's time past t0 + k h: 0 on the grid, in (0, h) between
                                   two samples (MODEL_ANY_STEP models only; else always 0) */
    int stop_time_defined;      /* a stopTime applies */
    double stop_time;
    int outputs_valid;          /* the output values match data (no set/step since) */
    int outputs_read;           /* outputs were read since the last doStep */
    int warned_read_before_set; /* that warning is given once per instance */
    double *history;            /* exact-mode history, grown by doubling */
    size_t history_capacity;    /* in doubles */
    glue_state *states;         /* FMU states not yet freed: freed with the instance */
    fmu_start_values *start_values;  /* resources/start_values, applied at instantiation and reset */
    /* values behind value reference vr: 1 for a scalar, n for the head of an array
     * of n elements (model variables vr .. vr + n - 1), 0 if vr is not a value
     * reference of this version (an array's other elements) */
    unsigned char n_values[MODEL_N_VARIABLES];
    /* what a master's exchange needs to know of vr, in one byte (map_variables):
     * GLUE_SCALAR_OF(type) when vr is a scalar of that type (n_values[vr] = 1),
     * and whether it is an input or an output */
    unsigned char scalar[MODEL_N_VARIABLES];
    ModelData data;
    ModelData backup;           /* data at the start of a doStep; scratch for deserialization */
} glue_instance;

/* ------------------------------------------------------------------------ */
/* logging                                                                   */

#if defined(__GNUC__)
#define GLUE_PRINTF(f, a) __attribute__((format(printf, f, a)))
/* a slow path, kept out of the hot function it is called from */
#define GLUE_NOINLINE __attribute__((noinline))
/* A function of a master's exchange, called every sample (the getter and
 * setter of Reals and Booleans, doStep): everything it calls is inlined into
 * it, the glue, the model and the core's step, which saves the calls and the
 * spills between them; the slow paths (GLUE_NOINLINE) and the logging stay out. */
#define GLUE_HOT_PATH __attribute__((flatten))
#else
#define GLUE_PRINTF(f, a)
#define GLUE_NOINLINE
#define GLUE_HOT_PATH
#endif

/* Before an instance exists: one message through the host (category from status). */
void glue_host_log(const glue_host *host, const char *instance_name, glue_status status,
                   const char *fmt, ...) GLUE_PRINTF(4, 5);
void glue_log_error(const glue_instance *inst, const char *fmt, ...) GLUE_PRINTF(2, 3);
void glue_log_warning(const glue_instance *inst, const char *fmt, ...) GLUE_PRINTF(2, 3);
void glue_log_event(const glue_instance *inst, const char *fmt, ...) GLUE_PRINTF(2, 3);

/* The shortest decimal text that reads back as x (messages for people, still exact). */
#define GLUE_REAL_TEXT_SIZE 32
const char *glue_real_text(char buf[GLUE_REAL_TEXT_SIZE], double x);

/* ------------------------------------------------------------------------ */
/* instances                                                                 */

/* The instance if c is one of this binary's and its mode is in mask, else NULL
 * (logged when c is an instance). */
glue_instance *glue_instance_of(void *c, const char *fname, int mask);

/* 1 (logged) when p is NULL. */
int glue_null_arg(const glue_instance *inst, const char *fname, const char *arg, const void *p);

/* Everything after the version's own argument checks: allocate, set the start
 * values (resources/start_values over the compiled ones: resource_location is a
 * file: URI when location_is_uri, else a folder path), log. NULL after logging
 * why. The host must have alloc and release; name must be non-empty. */
glue_instance *glue_instantiate(const glue_host *host, const glue_version *version, const char *fname,
                                const char *name, const char *resource_location, int location_is_uri,
                                const char *location_arg, int logging_on);
void glue_free_instance(void *c, const char *fname);

glue_status glue_set_debug_logging(void *c, const char *fname, int logging_on, size_t n_categories,
                                   const char *const categories[]);

/* Start and stop time (Instantiated only); enter_init: also enter initialization mode. */
glue_status glue_setup(void *c, const char *fname, double start_time, int stop_time_defined,
                       double stop_time, int enter_init);
glue_status glue_enter_init(void *c, const char *fname);
glue_status glue_exit_init(void *c, const char *fname);
glue_status glue_terminate(void *c, const char *fname);
glue_status glue_reset(void *c, const char *fname);

/* ------------------------------------------------------------------------ */
/* variables                                                                 */

/* n_values must equal the values the value references hold (FMI 2.0: nvr),
 * with no value reference 0. */
glue_status glue_get(void *c, const char *fname, const uint32_t vr[], size_t nvr, glue_values kind,
                     void *values, size_t n_values);
glue_status glue_set(void *c, const char *fname, const uint32_t vr[], size_t nvr, glue_values kind,
                     const void *values, size_t n_values);
/* Get/set of a type the FMU has no variable of: the state is checked, nvr = 0
 * passes with n_values = 0, otherwise refused naming the first reference's
 * type (or that it is unknown). */
glue_status glue_no_such_type(void *c, const char *fname, int mask, const uint32_t vr[], size_t nvr,
                              const void *values, size_t n_values, const char *type_name);

/* ------------------------------------------------------------------------ */
/* time and stepping                                                         */

/* The FMU's time: t0 + k h (+ t_off, between two samples of a MODEL_ANY_STEP model) */
double glue_time(const glue_instance *inst);

/* A communication step from t over H (see fmi2_glue.c for the rules). *t_end,
 * when not NULL, receives the FMU's time after the call, also when refused. */
glue_status glue_do_step(void *c, const char *fname, double t, double H, double *t_end);

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

glue_status glue_get_state(void *c, const char *fname, void **state);
glue_status glue_set_state(void *c, const char *fname, void *state);
glue_status glue_free_state(void *c, const char *fname, void **state);
glue_status glue_state_size(void *c, const char *fname, void *state, size_t *size);
glue_status glue_serialize(void *c, const char *fname, void *state, unsigned char *blob, size_t size);
glue_status glue_deserialize(void *c, const char *fname, const unsigned char *blob, size_t size,
                             void **state);

/* ------------------------------------------------------------------------ */
/* between the glue's own files (fmu_glue_core.c, fmu_glue_state.c)          */

#define STATE_MAGIC 0x50535441u                 /* "PSTA" */
/* Most samples since t0: (double)k stays exact and t0 + k h keeps its meaning. */
#define MAX_SAMPLES 9007199254740992ull         /* 2^53 */

/* An FMU state: a copy of everything that defines the instance's future. It
 * belongs to the instance that made it (get or deserialize) and sits in that
 * instance's list until freed. */
struct glue_state {
    uint32_t magic;
    const glue_instance *owner;
    glue_state *prev, *next;    /* the owner's list */
    int mode;
    double t0;
    uint64_t k;
    double h;
    double t_off;
    ModelData data;
    size_t n_history;
    size_t history_capacity;
    double *history;
};

/* The name the instance's FMI version gives mode (messages). */
const char *glue_mode_name(const glue_instance *inst, int mode);
/* Room for `needed` doubles of exact-mode history (doubling, content kept); 0 (logged) if none. */
int glue_ensure_history(glue_instance *inst, size_t needed, const char *fname);
/* Unlinks st from its owner's list and frees it. */
void glue_state_free(glue_instance *inst, glue_state *st);

/* ------------------------------------------------------------------------ */
/* refusals                                                                  */

/* A function the FMU does not support: "<fname>: not supported: <why>". */
glue_status glue_unsupported(void *c, const char *fname, const char *why);
/* In the modes of mask: "<fname>: <text>" as an error; outside them: the call-sequence error. */
glue_status glue_refuse(void *c, const char *fname, int mask, const char *fmt, ...) GLUE_PRINTF(4, 5);

#endif
