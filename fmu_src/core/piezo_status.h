/*
 * piezo_status.h - status codes and parameter diagnostics shared by the core.
 *
 * The core never prints: a failing init reports which parameter is wrong
 * through a piezo_diag (FMU variable name, offending value, valid range) and
 * the FMI layer turns that into a log message.
 *
 * Header rules (the cffi binding in harness/ parses these headers): only
 * size_t, uint64_t, int, double and const char * types, and integer-literal
 * #defines; no static inline functions, no expressions in array sizes.
 */
#ifndef PIEZO_STATUS_H
#define PIEZO_STATUS_H

typedef enum {
    PIEZO_OK = 0,            /* success */
    PIEZO_ERR_NULL = 1,      /* a required pointer argument was NULL */
    PIEZO_ERR_PARAM = 2,     /* a parameter is out of range: see piezo_diag */
    PIEZO_ERR_NONFINITE = 3, /* NaN or Inf input refused; state unchanged */
    PIEZO_ERR_CAPACITY = 4,  /* exact-mode history buffer too small; state unchanged */
    PIEZO_ERR_DIVERGED = 5,  /* finite inputs, non-finite result (the loop diverged); state unchanged */
    PIEZO_ERR_UNSTABLE = 6,  /* the controller's monitor found the loop unstable: |pred_error| above
                                its bound for the whole divergence window in a row, or in a quarter
                                of it (an exponentially weighted count); state unchanged */
    PIEZO_ERR_FAULT = 7      /* the controller's supervisor found a loop that cannot work (a
                                measurement that does not answer, answers inverted, ...): the loop's
                                state unchanged, the verdict recorded (piezo_supervisor.h) */
} piezo_status;

/* Which parameter an init refused, and why. Strings are static literals. */
typedef struct {
    const char *parameter;   /* FMU variable name, e.g. "creep.alpha" */
    const char *valid_range; /* e.g. "[-1, 1]" */
    double value;            /* the offending value */
} piezo_diag;

/* Fill *diag (may be NULL) and return PIEZO_ERR_PARAM: the one way inits refuse. */
piezo_status piezo_refuse(piezo_diag *diag, const char *parameter, const char *valid_range, double value);

/* 1 when v is finite and in [lo, hi], an end open where lo_open / hi_open: the declared range of
 * a plain parameter (piezo_controller_params.h) */
int piezo_in_range(double v, double lo, double hi, int lo_open, int hi_open);

#endif
