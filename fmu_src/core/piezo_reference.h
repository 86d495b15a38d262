/*
 * piezo_reference.h - the reference signal of the tracking scenarios, with
 * the preview the minimum-variance controller needs:
 *
 *     y_d(t) = offset + sum_{i=1..8} a_i sin(2 pi f_i t + phi_i)      [um]
 *     y_d(k)   = y_d(t0 + k h)              (the reference at t_k)
 *     y_ref(k) = y_d(t0 + (k + lead) h)     (lead samples ahead, lead = d)
 *     y_preview(k) = y_d(t_preview(k)),  t_preview(k) = t0 + (k + preview) h
 *                                         (the stamped preview: the controller
 *                                          aligns it with its own loop delay)
 *
 * Frequencies must lie in [0, 1/(2h)): a tone at or above the Nyquist
 * frequency aliases on the sample grid and is refused at init. So must
 * |offset| + sum |a_i| be finite, which bounds |y_d| at every t.
 * Time is t0 + k h with an integer k, never accumulated.
 */
#ifndef PIEZO_REFERENCE_H
#define PIEZO_REFERENCE_H

#include <stdint.h>
#include "piezo_status.h"

#define PIEZO_REF_MAX_TONES 8
#define PIEZO_REF_MAX_LEAD 1000000

typedef struct {
    double offset;                          /* [um] */
    double amplitude[PIEZO_REF_MAX_TONES];  /* [um] */
    double frequency[PIEZO_REF_MAX_TONES];  /* [Hz], [0, 1/(2h)) */
    double phase[PIEZO_REF_MAX_TONES];      /* [rad] */
    int lead;                               /* preview [samples], 0..PIEZO_REF_MAX_LEAD */
    int preview;                            /* lead of the stamped preview [samples], same range */
    double h;                               /* sample period [s], > 0 */
} piezo_reference_params;

typedef struct {
    piezo_reference_params p;               /* validated copy */
    double t0;                              /* start time [s] */
    uint64_t k;                             /* current sample */
    double y_d;                             /* y_d(k) [um] */
    double y_ref;                           /* y_d(k + lead) [um] */
    double y_preview;                       /* y_d(k + preview) [um] */
    double t_preview;                       /* t0 + (k + preview) h [s] */
} piezo_reference;

/* The paper's 1 Hz, 10 um tone (amplitude[1] = 10, frequency[1] = 1, the other tones 0),
 * lead 2 (the loop delay of a master that exchanges at communication points),
 * preview 4 (covers every loop delay the controller detects, docs/cosimulation.md),
 * h = 0.5 ms. */
void piezo_reference_default_params(piezo_reference_params *params);
/* Validate (diag names the first bad parameter), start at t0, sample 0. */
piezo_status piezo_reference_init(piezo_reference *ref, const piezo_reference_params *params,
                                  double t0, piezo_diag *diag);
/* Back to sample 0. */
void piezo_reference_reset(piezo_reference *ref);
/* Advance to sample k + 1 and update y_d, y_ref. PIEZO_ERR_DIVERGED, state
 * unchanged, when the time or a tone's phase 2 pi f t overflows. */
piezo_status piezo_reference_step(piezo_reference *ref);
/* Invariants of a restored reference (e.g. from a deserialized FMU state):
 * NULL when its parameters are valid and its outputs finite, else why not. */
const char *piezo_reference_check(const piezo_reference *ref);
/* NULL when a reference runs on `params` from t0 at sample k (valid, its copy of them equal,
 * its outputs those of sample k), else a static text saying which does not hold. */
const char *piezo_reference_check_params(const piezo_reference *ref, const piezo_reference_params *params,
                                         double t0, uint64_t k);
/* y_d at time t [s]. */
double piezo_reference_value(const piezo_reference *ref, double t);

#endif
