/*
 * piezo_plant.h - the coupled piezo stage model (docs/model.md, plant):
 *
 *     v --PI--> u --G(z)--> x --creep--> y,   y_meas = quantize(y + noise)
 *
 * Sample k: the outputs u(k-1), x(k), y(k), y_meas(k) are known before v(k)
 * is applied (no direct feedthrough from v). piezo_plant_step consumes v(k)
 * and advances to k+1: u(k) = P[v](k), x(k+1) = G..., y(k+1) = creep(x)(k+1).
 * Outputs live in the struct (`out`), so the FMU reads them without work.
 *
 * Sensor: quantize(a) = resolution * floor(a / resolution + 0.5) (off when 0),
 * computed exactly but mostly without the division (piezo_quantize);
 * noise ~ N(0, noise_rms^2) from the core's own xoshiro256** generator seeded
 * by splitmix64(seed): reproducible, independent of the C library.
 * A step whose reading overflows (e.g. y near 1e308) is refused as divergence
 * like any other non-finite result: every output of an accepted step is finite.
 */
#ifndef PIEZO_PLANT_H
#define PIEZO_PLANT_H

#include <stddef.h>
#include <stdint.h>
#include "piezo_status.h"
#include "piezo_hysteresis.h"
#include "piezo_tf.h"
#include "piezo_creep.h"

/* The stage's rated drive range, [-PIEZO_PLANT_V_RATED, PIEZO_PLANT_V_RATED] V: an amplifier
 * cannot deliver more, so an FMU applies its v clamped to it (piezo_plant_rated_voltage). */
#define PIEZO_PLANT_V_RATED 150

typedef struct {
    piezo_pi_params pi;
    piezo_tf_params tf;
    int creep_enabled;          /* 0: Hammerstein model, y = x */
    double creep_k_c;           /* > 0 */
    double creep_alpha;         /* [-1, 1] */
    int creep_exact;            /* 1: full-memory G-L, 0: SOE */
    double sensor_resolution;   /* [um], 0 = off, or >= 1e-300 */
    double sensor_noise_rms;    /* [um], 0..1e300 */
    int sensor_seed;            /* any integer */
    double h;                   /* sample period [s], > 0 */
} piezo_plant_params;

typedef struct {
    double u;                   /* PI output of the last applied voltage, u(k-1) [um] */
    double x;                   /* Hammerstein output x(k) [um] */
    double y;                   /* true displacement y(k) [um] */
    double y_meas;              /* sensor reading [um] */
} piezo_plant_output;

typedef struct {
    uint64_t s[4];
} piezo_rng;

typedef struct {
    piezo_pi pi;
    piezo_tf tf;
    piezo_gl creep;
    int creep_enabled;
    double sensor_resolution;
    double sensor_inv_resolution;   /* 1 / sensor_resolution (0 when off), set at init */
    double sensor_noise_rms;
    int sensor_seed;
    piezo_rng rng;
    uint64_t k;                 /* current sample index */
    piezo_plant_output out;     /* outputs at sample k */
} piezo_plant;

/*
 * One evaluated sample, for a caller that must know a sample is accepted before it
 * commits anything (PiezoStageClosedLoop steps the plant and the controller of one
 * sample, and either may refuse): piezo_plant_evaluate fills it, nothing changed;
 * piezo_plant_commit makes it the plant's state. piezo_plant_step is the two.
 */
typedef struct {
    uint64_t k;                 /* the sample evaluated (plant->k then) */
    double z[PIEZO_PI_MAX_OPERATORS];   /* the play operators' states of k+1 */
    piezo_rng rng;              /* the sensor's generator after the sample */
    piezo_plant_output out;     /* u(k), x(k+1), y(k+1), y_meas(k+1) */
} piezo_plant_sample;

/* Defaults of docs/fmus.md. */
void piezo_plant_default_params(piezo_plant_params *params);
/* Validate every parameter (diag names the first bad one), derive, reset. */
piezo_status piezo_plant_init(piezo_plant *plant, const piezo_plant_params *params, piezo_diag *diag);
/* Back to k = 0, rest, generator reseeded; outputs of sample 0 computed. */
void piezo_plant_reset(piezo_plant *plant);
/*
 * Apply v(k), advance to k+1. creep_history/capacity: exact-mode buffer of
 * the creep input (see piezo_gl_step); may be NULL in SOE mode or when creep
 * is disabled. Refused steps (non-finite v, small buffer) leave the state as it was.
 * `out` may be NULL; the outputs are also in plant->out.
 */
piezo_status piezo_plant_step(piezo_plant *plant, double v, double *creep_history,
                              size_t history_capacity, piezo_plant_output *out);
/* piezo_plant_step without the commit: the same checks, refusals and result, into *sample
 * (exact mode writes the unused slots creep_history[2k], [2k+1]); nothing else changes. */
piezo_status piezo_plant_evaluate(const piezo_plant *plant, double v, double *creep_history,
                                  size_t history_capacity, piezo_plant_sample *sample);
/* Make an evaluated sample the state (k -> k+1): PIEZO_ERR_PARAM, nothing done, unless
 * sample->k == plant->k. Commit only the latest evaluation of the sample. */
piezo_status piezo_plant_commit(piezo_plant *plant, const piezo_plant_sample *sample);
/* History doubles the next step needs, 2(k+1) (0 unless exact creep is on). */
size_t piezo_plant_history_needed(const piezo_plant *plant);
/*
 * Invariants of a restored plant (e.g. from a deserialized FMU state): NULL
 * when every index, count and flag is in range, the sample counters agree and
 * every value is finite, else a static text naming the first bad field. The
 * exact-mode history is checked by piezo_gl_check_history(&plant->creep, ...).
 */
const char *piezo_plant_check(const piezo_plant *plant);
/* NULL when a plant runs on `params` (valid, and the copies piezo_plant_init keeps of them
 * equal them), else a static text saying which does not hold. */
const char *piezo_plant_check_params(const piezo_plant *plant, const piezo_plant_params *params);
/* v clamped to the rated range: min(max(v, -PIEZO_PLANT_V_RATED), PIEZO_PLANT_V_RATED). */
double piezo_plant_rated_voltage(double v);

/* The sensor's quantiser, resolution * floor(reading / resolution + 0.5) for a
 * resolution > 0, bit for bit (exposed for tests; the plant keeps 1/resolution). */
double piezo_quantize(double reading, double resolution);
/* The sensor's generator, exposed for tests. */
void piezo_rng_seed(piezo_rng *rng, uint64_t seed);
double piezo_rng_uniform(piezo_rng *rng);   /* (0, 1) */
double piezo_rng_normal(piezo_rng *rng);    /* N(0, 1), Box-Muller */

#endif
