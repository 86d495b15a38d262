/* piezo_reference.c - sum-of-sines reference with preview. See piezo_reference.h. */
#include <math.h>
#include <string.h>
#include "piezo_reference.h"

#define PI_D 3.14159265358979323846

void piezo_reference_default_params(piezo_reference_params *p)
{
    if (!p) return;
    memset(p, 0, sizeof *p);
    /* a plain run of the FMU shows the paper's 1 Hz, 10 um tone, not a flat line */
    p->amplitude[0] = 10.0;
    p->frequency[0] = 1.0;
    p->lead = 2;
    p->preview = 4;
    p->h = 0.0005;
}

/* Valid-range texts name the index, so a refusal says which tone is wrong. */
static const char *const amplitude_names[PIEZO_REF_MAX_TONES] = {
    "amplitude[1]", "amplitude[2]", "amplitude[3]", "amplitude[4]",
    "amplitude[5]", "amplitude[6]", "amplitude[7]", "amplitude[8]"};
static const char *const frequency_names[PIEZO_REF_MAX_TONES] = {
    "frequency[1]", "frequency[2]", "frequency[3]", "frequency[4]",
    "frequency[5]", "frequency[6]", "frequency[7]", "frequency[8]"};
static const char *const phase_names[PIEZO_REF_MAX_TONES] = {
    "phase[1]", "phase[2]", "phase[3]", "phase[4]",
    "phase[5]", "phase[6]", "phase[7]", "phase[8]"};

/* Every parameter in its range (diag names the first that is not). */
static piezo_status validate(const piezo_reference_params *p, double t0, piezo_diag *diag)
{
    int i;
    double nyquist, bound;
    if (!(isfinite(p->h) && p->h > 0.0)) return piezo_refuse(diag, "h", "(0, inf) s", p->h);
    if (!isfinite(p->offset)) return piezo_refuse(diag, "offset", "finite values (um)", p->offset);
    nyquist = 0.5 / p->h;
    /* |y_d| <= |offset| + sum |a_i|: finite bound, finite reference at every t */
    bound = fabs(p->offset);
    for (i = 0; i < PIEZO_REF_MAX_TONES; ++i) {
        if (!isfinite(p->amplitude[i]))
            return piezo_refuse(diag, amplitude_names[i], "finite values (um)", p->amplitude[i]);
        bound += fabs(p->amplitude[i]);
        if (!isfinite(bound))
            return piezo_refuse(diag, amplitude_names[i],
                                "finite values with |offset| + sum of |amplitude[i]| finite (um)", p->amplitude[i]);
        /* f >= 1/(2h) aliases onto a lower frequency on the sample grid */
        if (!(isfinite(p->frequency[i]) && p->frequency[i] >= 0.0 && p->frequency[i] < nyquist))
            return piezo_refuse(diag, frequency_names[i],
                                "[0, 1/(2 h)) Hz: below the Nyquist frequency (1000 Hz for h = 0.5 ms)",
                                p->frequency[i]);
        if (!isfinite(p->phase[i])) return piezo_refuse(diag, phase_names[i], "finite values (rad)", p->phase[i]);
    }
    if (p->lead < 0 || p->lead > PIEZO_REF_MAX_LEAD)
        return piezo_refuse(diag, "lead", "0..1000000 samples", (double)p->lead);
    if (p->preview < 0 || p->preview > PIEZO_REF_MAX_LEAD)
        return piezo_refuse(diag, "preview", "0..1000000 samples", (double)p->preview);
    if (!isfinite(t0)) return piezo_refuse(diag, "startTime", "finite values (s)", t0);
    return PIEZO_OK;
}

/* The tone argument 2 pi f t + phi of the first tone for which it overflows at
 * time t, or -1 when all are finite (sin of a finite argument is finite). */
static int overflowing_tone(const piezo_reference_params *p, double t)
{
    int i;
    if (!isfinite(t)) return 0;
    for (i = 0; i < PIEZO_REF_MAX_TONES; ++i)
        if (p->amplitude[i] != 0.0 && !isfinite(2.0 * PI_D * p->frequency[i] * t + p->phase[i]))
            return i;
    return -1;
}

piezo_status piezo_reference_init(piezo_reference *ref, const piezo_reference_params *p,
                                  double t0, piezo_diag *diag)
{
    int tone;
    piezo_status st;
    if (!ref || !p) return PIEZO_ERR_NULL;
    st = validate(p, t0, diag);
    if (st != PIEZO_OK) return st;
    /* sample 0 needs y_d(t0), y_d(t0 + lead h) and y_d(t0 + preview h) */
    tone = overflowing_tone(p, t0);
    if (tone < 0) tone = overflowing_tone(p, t0 + (double)p->lead * p->h);
    if (tone < 0) tone = overflowing_tone(p, t0 + (double)p->preview * p->h);
    if (tone >= 0)
        return piezo_refuse(diag, frequency_names[tone],
                            "[0, 1/(2 h)) Hz with 2 pi frequency t finite at t = startTime, startTime + lead h "
                            "and startTime + preview h", p->frequency[tone]);
    memset(ref, 0, sizeof *ref);
    ref->p = *p;
    ref->t0 = t0;
    piezo_reference_reset(ref);
    return PIEZO_OK;
}

/* y_d(t) = offset + sum_i a_i sin(2 pi f_i t + phi_i); zero amplitudes are skipped. */
double piezo_reference_value(const piezo_reference *ref, double t)
{
    double y = ref->p.offset;
    int i;
    for (i = 0; i < PIEZO_REF_MAX_TONES; ++i)
        if (ref->p.amplitude[i] != 0.0)
            y += ref->p.amplitude[i] * sin(2.0 * PI_D * ref->p.frequency[i] * t + ref->p.phase[i]);
    return y;
}

/* t_k = t0 + k h from the integer counter, never accumulated; 0 when the
 * time or a tone's argument overflowed (nothing is written then). */
static int update(piezo_reference *ref, uint64_t k)
{
    double t = ref->t0 + (double)k * ref->p.h;
    double t_lead = ref->t0 + (double)(k + (uint64_t)ref->p.lead) * ref->p.h;
    double t_preview = ref->t0 + (double)(k + (uint64_t)ref->p.preview) * ref->p.h;
    if (overflowing_tone(&ref->p, t) >= 0 || overflowing_tone(&ref->p, t_lead) >= 0
        || overflowing_tone(&ref->p, t_preview) >= 0)
        return 0;
    ref->y_d = piezo_reference_value(ref, t);
    ref->y_ref = piezo_reference_value(ref, t_lead);
    ref->y_preview = piezo_reference_value(ref, t_preview);
    ref->t_preview = t_preview;
    ref->k = k;
    return 1;
}

void piezo_reference_reset(piezo_reference *ref)
{
    if (!ref) return;
    /* init checked sample 0; a struct that never passed init gets 0, 0 */
    if (!update(ref, 0)) {
        ref->k = 0;
        ref->y_d = ref->y_ref = ref->y_preview = ref->t_preview = 0.0;
    }
}

piezo_status piezo_reference_step(piezo_reference *ref)
{
    if (!ref) return PIEZO_ERR_NULL;
    /* finite parameters and times give a finite reference (|y_d| <= |offset| + sum |a_i|) */
    return update(ref, ref->k + 1) ? PIEZO_OK : PIEZO_ERR_DIVERGED;
}

const char *piezo_reference_check(const piezo_reference *ref)
{
    if (!ref) return "reference missing";
    if (validate(&ref->p, ref->t0, NULL) != PIEZO_OK) return "reference parameters out of range";
    if (!(isfinite(ref->y_d) && isfinite(ref->y_ref) && isfinite(ref->y_preview) && isfinite(ref->t_preview)))
        return "reference outputs not finite";
    return NULL;
}

const char *piezo_reference_check_params(const piezo_reference *r, const piezo_reference_params *q,
                                         double t0, uint64_t k)
{
    piezo_reference scratch;
    int i;
    if (!r || !q) return "reference missing";
    if (piezo_reference_init(&scratch, q, t0, NULL) != PIEZO_OK) return "parameters out of range";
    if (r->k != k || r->t0 != t0) return "reference time (t0, k) differs from the FMU's";
    /* the core's parameters are a copy of the FMU's */
    if (r->p.offset != q->offset || r->p.lead != q->lead || r->p.preview != q->preview || r->p.h != q->h)
        return "reference state does not match its parameters";
    for (i = 0; i < PIEZO_REF_MAX_TONES; i++)
        if (r->p.amplitude[i] != q->amplitude[i] || r->p.frequency[i] != q->frequency[i]
            || r->p.phase[i] != q->phase[i])
            return "reference state does not match its parameters";
    /* the outputs are a function of (parameters, t0, k): they must be that value (update's times) */
    if (r->y_d != piezo_reference_value(r, t0 + (double)k * r->p.h)
        || r->y_ref != piezo_reference_value(r, t0 + (double)(k + (uint64_t)r->p.lead) * r->p.h)
        || r->t_preview != t0 + (double)(k + (uint64_t)r->p.preview) * r->p.h
        || r->y_preview != piezo_reference_value(r, r->t_preview))
        return "reference outputs differ from y_d at t0 + k h";
    return NULL;
}
