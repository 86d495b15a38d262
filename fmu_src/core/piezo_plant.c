/* piezo_plant.c - coupled hysteresis-dynamics-creep plant with sensor.
 * See piezo_plant.h. */
#include <float.h>
#include <math.h>
#include <string.h>
#include "piezo_plant.h"

#define PI_D 3.14159265358979323846
#define SENSOR_RESOLUTION_MIN 1e-300   /* [um] smallest non-zero sensor.resolution */
#define SENSOR_NOISE_MAX 1e300         /* [um] largest sensor.noise_rms */

void piezo_plant_default_params(piezo_plant_params *p)
{
    if (!p) return;
    memset(p, 0, sizeof *p);
    /* PI model identified at 1 Hz (paper section 3.1, docs/model.md, plant) */
    p->pi.m = 9;
    p->pi.v_max = 20.0;
    p->pi.w0 = 0.3344;
    p->pi.w[0] = 0.0714;
    p->pi.w[1] = 0.0322;
    p->pi.w[2] = 0.0072;
    /* eq 21 */
    p->tf.a1 = -1.3767;
    p->tf.a2 = 0.3816;
    p->tf.b1 = 0.5954;
    p->tf.b2 = -0.5907;
    p->tf.delay = 0;
    /* Table 1, 1 Hz row */
    p->creep_enabled = 1;
    p->creep_k_c = 1.0463;
    p->creep_alpha = 0.0002;
    p->creep_exact = 0;
    p->sensor_resolution = 0.0;
    p->sensor_noise_rms = 0.0;
    p->sensor_seed = 1;
    p->h = 0.0005;
}

/* ---- sensor generator: xoshiro256** seeded by splitmix64 ---------------- */

static uint64_t splitmix64(uint64_t *x)
{
    uint64_t z = (*x += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

void piezo_rng_seed(piezo_rng *rng, uint64_t seed)
{
    int i;
    if (!rng) return;
    for (i = 0; i < 4; ++i) rng->s[i] = splitmix64(&seed);
}

static uint64_t rng_next(piezo_rng *rng)
{
    uint64_t *s = rng->s;
    uint64_t result = rotl(s[1] * 5, 7) * 9;
    uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

/* Top 53 bits, shifted by half an ulp so the result is never 0 or 1. Static,
 * so the plant's step inlines it; exported below. */
static double rng_uniform(piezo_rng *rng)
{
    return ((double)(rng_next(rng) >> 11) + 0.5) * (1.0 / 9007199254740992.0);
}

/* Taylor coefficients (-1)^n / (2n)! of cos x and (-1)^n / (2n+1)! of sin x / x,
 * in powers of z = x^2 */
static const double COS_TAYLOR[10] = {
    1.0, -1.0 / 2, 1.0 / 24, -1.0 / 720, 1.0 / 40320, -1.0 / 3628800, 1.0 / 479001600,
    -1.0 / 87178291200.0, 1.0 / 20922789888000.0, -1.0 / 6402373705728000.0};
static const double SIN_TAYLOR[9] = {
    1.0, -1.0 / 6, 1.0 / 120, -1.0 / 5040, 1.0 / 362880, -1.0 / 39916800, 1.0 / 6227020800.0,
    -1.0 / 1307674368000.0, 1.0 / 355687428096000.0};

/*
 * cos(2 pi u) for u in (0, 1), with basic operations only: the same bits from
 * every C library and compiler (given no contraction), and no data-dependent
 * branch (a library cos branches on the argument's range, and a uniform
 * argument makes those branches unpredictable).
 * Quadrant: q = round(4u), t = u - q/4 in [-1/8, 1/8] (exact: u and q/4 are
 * within a factor 2), x = 2 pi t in [-pi/4, pi/4], and
 *     cos(2 pi u) = cos(x + q pi/2) = cos x, -sin x, -cos x, sin x  for q mod 4 = 0..3.
 * cos x and sin x by their Taylor series to x^18 and x^17, whose next terms are
 * below 3e-21 and 8e-20 for |x| <= pi/4, evaluated in z = x^2 by Estrin's
 * scheme (pairs c_2n + c_2n+1 z, then z^2, z^4, z^8: four steps deep instead of
 * nine, so the draw's latency does not hold up the sample):
 *     P(z) = ((c0 + c1 z) + z^2 (c2 + c3 z)) + z^4 ((c4 + c5 z) + z^2 (c6 + c7 z)) + z^8 (c8 + c9 z).
 */
static double cos_2pi(double u)
{
    const double *c = COS_TAYLOR, *s = SIN_TAYLOR;
    int q = (int)(4.0 * u + 0.5);
    double t = u - 0.25 * (double)q;
    double x = (2.0 * PI_D) * t, z = x * x, z2 = z * z, z4 = z2 * z2, z8 = z4 * z4, r[4];
    double cos_x = ((c[0] + c[1] * z) + z2 * (c[2] + c[3] * z))
                   + z4 * ((c[4] + c[5] * z) + z2 * (c[6] + c[7] * z)) + z8 * (c[8] + c[9] * z);
    double sin_x = x * (((s[0] + s[1] * z) + z2 * (s[2] + s[3] * z))
                        + z4 * ((s[4] + s[5] * z) + z2 * (s[6] + s[7] * z)) + z8 * s[8]);
    r[0] = cos_x;
    r[1] = -sin_x;
    r[2] = -cos_x;
    r[3] = sin_x;
    return r[q & 3];
}

/* Box-Muller, sqrt(-2 ln u1) cos(2 pi u2); the second variate is dropped so the
 * state stays one generator. */
static double rng_normal(piezo_rng *rng)
{
    double u1 = rng_uniform(rng);
    double u2 = rng_uniform(rng);
    return sqrt(-2.0 * log(u1)) * cos_2pi(u2);
}

double piezo_rng_uniform(piezo_rng *rng)
{
    return rng_uniform(rng);
}

double piezo_rng_normal(piezo_rng *rng)
{
    return rng_normal(rng);
}

/* ---- plant --------------------------------------------------------------- */

piezo_status piezo_plant_init(piezo_plant *plant, const piezo_plant_params *p, piezo_diag *diag)
{
    piezo_status st;
    double gain;
    if (!plant || !p) return PIEZO_ERR_NULL;
    if (!(isfinite(p->h) && p->h > 0.0)) return piezo_refuse(diag, "h", "(0, inf) s", p->h);
    if (!(isfinite(p->creep_k_c) && p->creep_k_c > 0.0))
        return piezo_refuse(diag, "creep.k_c", "(0, inf)", p->creep_k_c);
    if (!(isfinite(p->creep_alpha) && p->creep_alpha >= -1.0 && p->creep_alpha <= 1.0))
        return piezo_refuse(diag, "creep.alpha", "[-1, 1]", p->creep_alpha);
    /* A resolution below 1e-300 um makes y / resolution overflow for any real
     * displacement (1e-310 um: every |y| > 0.018 um), so the reading is Inf. */
    if (!(isfinite(p->sensor_resolution)
          && (p->sensor_resolution == 0.0 || p->sensor_resolution >= SENSOR_RESOLUTION_MIN)))
        return piezo_refuse(diag, "sensor.resolution", "0 (off) or [1e-300, inf) um", p->sensor_resolution);
    /* |N(0, 1)| <= 8.7 from the generator, so noise up to 1e300 um stays finite */
    if (!(isfinite(p->sensor_noise_rms) && p->sensor_noise_rms >= 0.0 && p->sensor_noise_rms <= SENSOR_NOISE_MAX))
        return piezo_refuse(diag, "sensor.noise_rms", "[0, 1e300] um", p->sensor_noise_rms);

    memset(plant, 0, sizeof *plant);
    st = piezo_pi_init(&plant->pi, &p->pi, diag);
    if (st != PIEZO_OK) return st;
    st = piezo_tf_init(&plant->tf, &p->tf, diag);
    if (st != PIEZO_OK) return st;
    /* eq 17: y(k) = k_c h^-alpha sum_j w_j x(k-j) */
    gain = p->creep_k_c * pow(p->h, -p->creep_alpha);
    st = piezo_gl_init(&plant->creep, p->creep_alpha, gain, p->creep_exact, diag);
    if (st != PIEZO_OK) return st;
    plant->creep_enabled = p->creep_enabled ? 1 : 0;
    plant->sensor_resolution = p->sensor_resolution;
    plant->sensor_inv_resolution = p->sensor_resolution > 0.0 ? 1.0 / p->sensor_resolution : 0.0;
    plant->sensor_noise_rms = p->sensor_noise_rms;
    plant->sensor_seed = p->sensor_seed;
    piezo_plant_reset(plant);
    /* sample 0 reads quantize(noise): huge noise on a fine grid overflows */
    if (!isfinite(plant->out.y_meas))
        return piezo_refuse(diag, "sensor.noise_rms",
                            "[0, 1e300] um and small enough against sensor.resolution for a finite reading",
                            p->sensor_noise_rms);
    return PIEZO_OK;
}

/* The sensor noise of one sample, noise_rms N(0, 1) drawn from *rng; nothing
 * is drawn (0 returned) when the noise is off. */
static double sensor_noise(const piezo_plant *plant, piezo_rng *rng)
{
    return plant->sensor_noise_rms > 0.0 ? plant->sensor_noise_rms * rng_normal(rng) : 0.0;
}

/*
 * quantize(a) = res * floor(a / res + 0.5), the same bits, mostly without the
 * division (inv = 1/res, rounded, kept by the caller). With p = a * inv rounded:
 *   p = (a/res)(1 + e1)(1 + e2) (+ at most 2^-1075 if the product underflows), where
 *   |e2| <= 2^-53 and |e1| <= 2^-51 (2^-53 when inv is normal, i.e. res < 2^1022),
 *   so p and Q = a / res rounded differ by less than 2^-50 |p| + 2^-1074.
 * n = (p + M) - M with M = 1.5 * 2^52 is the integer nearest p for |p| < 2^51 (p + M
 * lies in (2^52, 2^53), where doubles are the integers; subtracting M is exact), and
 * p - n is exact (Sterbenz, or n = 0). The fast path takes |p| < 2^36 and
 * |p - n| <= 0.5 - 2^-8: then |p - Q| < 2^-14, so Q + 0.5 lies in
 * (n + 2^-8 - 2^-14, n + 1 - 2^-8 + 2^-14), rounding it moves it by at most 2^-17
 * (it is below 2^37), and floor(Q + 0.5) = n: res * n is the division's result.
 * Zero is +0 either way (M - M and floor of a value in (0, 1)). Anything else
 * (near a half step, huge, Inf or NaN) takes the division. It needs doubles
 * evaluated as doubles (FLT_EVAL_METHOD 0: SSE2 on x86-64, not x87), and always
 * divides otherwise.
 */
static double quantize(double a, double res, double inv)
{
#if defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 0
    const double round_shift = 6755399441055744.0;     /* 1.5 * 2^52 */
    double p = a * inv;
    double n = (p + round_shift) - round_shift;
    if (fabs(p) < 68719476736.0 && fabs(p - n) <= 0.5 - 1.0 / 256)     /* 2^36, 2^-8 */
        return res * n;
#else
    (void)inv;
#endif
    return res * floor(a / res + 0.5);
}

double piezo_quantize(double reading, double resolution)
{
    return quantize(reading, resolution, 1.0 / resolution);
}

/* y_meas = quantize(y + noise), quantize(a) = res * floor(a / res + 0.5); noise
 * from sensor_noise (not added when the noise is off) */
static double sense(const piezo_plant *plant, double y, double noise)
{
    double reading = y;
    if (plant->sensor_noise_rms > 0.0) reading += noise;
    if (plant->sensor_resolution > 0.0)
        reading = quantize(reading, plant->sensor_resolution, plant->sensor_inv_resolution);
    return reading;
}

void piezo_plant_reset(piezo_plant *plant)
{
    if (!plant) return;
    piezo_pi_reset(&plant->pi);
    piezo_tf_reset(&plant->tf);
    piezo_gl_reset(&plant->creep);
    /* the seed is an FMU Integer: any value, reinterpreted bit for bit */
    piezo_rng_seed(&plant->rng, (uint64_t)(uint32_t)plant->sensor_seed);
    plant->k = 0;
    /* sample 0: at rest */
    plant->out.u = 0.0;
    plant->out.x = 0.0;
    plant->out.y = 0.0;
    plant->out.y_meas = sense(plant, 0.0, sensor_noise(plant, &plant->rng));
}

size_t piezo_plant_history_needed(const piezo_plant *plant)
{
    if (!plant || !plant->creep_enabled) return 0;
    /* the creep consumes x(k+1) at the next step */
    return piezo_gl_history_needed(&plant->creep);
}

/*
 * Every stage is first evaluated without committing (the only refusal after the input
 * checks is an overflow, PIEZO_ERR_DIVERGED, which shows in u, x or y), then committed.
 */
static inline piezo_status plant_eval(const piezo_plant *plant, double v, double *creep_history,
                                      size_t history_capacity, piezo_plant_sample *s)
{
    double u, x, y, y_meas, noise;
    if (!isfinite(v)) return PIEZO_ERR_NONFINITE;
    if (plant->creep_enabled && plant->creep.exact) {
        if (!creep_history) return PIEZO_ERR_NULL;
        if (history_capacity < piezo_plant_history_needed(plant)) return PIEZO_ERR_CAPACITY;
    }
    /* The reading's noise first: it does not depend on the sample, so its libm
     * calls overlap the operators below. The generator advances on a copy until
     * the sample is accepted. */
    s->rng = plant->rng;
    noise = sensor_noise(plant, &s->rng);
    /* v is finite, so a non-finite value from here on was computed: overflow, not bad input */
    piezo_pi_eval(&plant->pi, v, s->z, &u);                           /* u(k) = P[v](k) */
    if (!isfinite(u)) return PIEZO_ERR_DIVERGED;
    piezo_tf_eval(&plant->tf, u, &x);                                 /* x(k+1)         */
    if (!isfinite(x)) return PIEZO_ERR_DIVERGED;
    if (plant->creep_enabled) {
        piezo_status st = piezo_gl_eval(&plant->creep, x, creep_history, history_capacity,
                                        &y);                          /* y(k+1)         */
        if (st != PIEZO_OK) return st;
        if (!isfinite(y)) return PIEZO_ERR_DIVERGED;
    } else {
        y = x;
    }
    /* the reading before the commit: quantising a finite y can overflow (y / resolution) */
    y_meas = sense(plant, y, noise);
    if (!isfinite(y_meas)) return PIEZO_ERR_DIVERGED;
    s->k = plant->k;
    s->out.u = u;
    s->out.x = x;
    s->out.y = y;
    s->out.y_meas = y_meas;
    return PIEZO_OK;
}

static inline void plant_commit(piezo_plant *plant, const piezo_plant_sample *s)
{
    memcpy(plant->pi.z, s->z, (size_t)plant->pi.m * sizeof *s->z);
    piezo_tf_commit(&plant->tf, s->out.u, s->out.x);
    if (plant->creep_enabled) piezo_gl_commit(&plant->creep, s->out.x);
    plant->rng = s->rng;
    plant->k += 1;
    plant->out = s->out;
}

/* In place, without copying the plant: evaluated, then committed. */
piezo_status piezo_plant_step(piezo_plant *plant, double v, double *creep_history,
                              size_t history_capacity, piezo_plant_output *out)
{
    piezo_plant_sample s;
    piezo_status st;
    if (!plant) return PIEZO_ERR_NULL;
    st = plant_eval(plant, v, creep_history, history_capacity, &s);
    if (st != PIEZO_OK) return st;
    plant_commit(plant, &s);
    if (out) *out = plant->out;
    return PIEZO_OK;
}

piezo_status piezo_plant_evaluate(const piezo_plant *plant, double v, double *creep_history,
                                  size_t history_capacity, piezo_plant_sample *sample)
{
    if (!plant || !sample) return PIEZO_ERR_NULL;
    return plant_eval(plant, v, creep_history, history_capacity, sample);
}

piezo_status piezo_plant_commit(piezo_plant *plant, const piezo_plant_sample *sample)
{
    if (!plant || !sample) return PIEZO_ERR_NULL;
    if (sample->k != plant->k) return PIEZO_ERR_PARAM;
    plant_commit(plant, sample);
    return PIEZO_OK;
}

const char *piezo_plant_check(const piezo_plant *plant)
{
    const char *fault;
    if (!plant) return "plant missing";
    if ((fault = piezo_pi_check(&plant->pi)) != NULL) return fault;
    if ((fault = piezo_tf_check(&plant->tf)) != NULL) return fault;
    if ((fault = piezo_gl_check(&plant->creep)) != NULL) return fault;
    if (plant->creep_enabled != 0 && plant->creep_enabled != 1) return "creep.enabled is not 0 or 1";
    /* the creep consumes one sample per plant step when enabled, none otherwise */
    if (plant->creep.k != (plant->creep_enabled ? plant->k : 0)) return "creep sample counter differs from the plant's";
    if (!(isfinite(plant->sensor_resolution)
          && (plant->sensor_resolution == 0.0 || plant->sensor_resolution >= SENSOR_RESOLUTION_MIN)))
        return "sensor.resolution out of range";
    if (plant->sensor_inv_resolution != (plant->sensor_resolution > 0.0 ? 1.0 / plant->sensor_resolution : 0.0))
        return "the reciprocal of sensor.resolution kept from init does not match sensor.resolution";
    if (!(isfinite(plant->sensor_noise_rms) && plant->sensor_noise_rms >= 0.0
          && plant->sensor_noise_rms <= SENSOR_NOISE_MAX))
        return "sensor.noise_rms out of range";
    /* xoshiro256** never reaches the all-zero state (it would stay there) */
    if ((plant->rng.s[0] | plant->rng.s[1] | plant->rng.s[2] | plant->rng.s[3]) == 0)
        return "sensor generator state is all zero";
    if (!(isfinite(plant->out.u) && isfinite(plant->out.x) && isfinite(plant->out.y) && isfinite(plant->out.y_meas)))
        return "plant outputs not finite";
    return NULL;
}

const char *piezo_plant_check_params(const piezo_plant *p, const piezo_plant_params *q)
{
    piezo_plant scratch;
    if (!p || !q) return "plant missing";
    if (piezo_plant_init(&scratch, q, NULL) != PIEZO_OK) return "parameters out of range";
    if (p->pi.m != q->pi.m || p->tf.delay != q->tf.delay || p->creep.exact != (q->creep_exact ? 1 : 0)
        || p->creep_enabled != (q->creep_enabled ? 1 : 0) || p->creep.alpha != q->creep_alpha
        || p->sensor_resolution != q->sensor_resolution || p->sensor_noise_rms != q->sensor_noise_rms
        || p->sensor_seed != q->sensor_seed)
        return "plant state does not match its parameters";
    return NULL;
}

double piezo_plant_rated_voltage(double v)
{
    const double limit = (double)PIEZO_PLANT_V_RATED;
    return v < -limit ? -limit : v > limit ? limit : v;
}
