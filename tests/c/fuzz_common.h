/*
 * fuzz_common.h - what the libFuzzer targets of tests/c/ share. Each target is
 * compiled once per FMU, together with that FMU's glue, model and core (so
 * fmu_model.h describes the FMU: MODEL_GUID, model_variables).
 *
 *   fuzz_deserialize_<FMU>  input = a serialized FMU state; the size field and
 *                           the checksum are recomputed so mutations get past them
 *   fuzz_run_<FMU>          input = a program: parameters, then steps with inputs
 *                           and FMU-state round trips (format below)
 *
 * The oracle (any violation aborts, which libFuzzer reports as a crash):
 *   - no crash, no sanitizer report (ASan + UBSan, every error fatal)
 *   - every Real output read after fmi2OK or fmi2Warning is finite
 *   - a deserialized state serializes back to the same bytes
 *   - every state a live instance is in passes fmi2GetFMUstate ->
 *     fmi2SerializeFMUstate -> fmi2DeSerializeFMUstate -> fmi2SetFMUstate
 *     (the validation of restored states refuses nothing a live instance can be in)
 *
 * Program format of fuzz_run (read front to back; missing bytes read as 0):
 *   byte      n_params = b % 32, start time index = b / 32 (FUZZ_START_TIMES)
 *   n_params x [byte parameter index (mod the FMU's parameters), byte kind, 8 bytes value]
 *   then until the end: byte op
 *     op % 8 in 0..4: [byte kind, 8 bytes value] per input, then step (op / 8) % 8 samples
 *     op % 8 == 5:    step one sample with the inputs held
 *     op % 8 == 6:    FMU-state round trip through a serialized blob (the first 4 per input)
 *     op % 8 == 7:    save the state (first time) or restore the saved one
 * A value is decoded by fuzz_value(kind, bits, start value).
 */
#ifndef FUZZ_COMMON_H
#define FUZZ_COMMON_H

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"
#include "state_format.h"

#define FUZZ_MAX_SAMPLES 1024   /* per input, so one execution stays short (exact creep is O(k^2)) */

static const double FUZZ_START_TIMES[8] = {0.0, 1.25, -3.5, 1e9, 0.0005, 1e-300, -1e15, 7.0};

static const double FUZZ_SPECIALS[16] = {
    0.0, -0.0, 1.0, -1.0, DBL_MAX, -DBL_MAX, DBL_MIN, -DBL_MIN, 4.9406564584124654e-324,
    1e308, -1e308, 1e-310, 1e300, 0.5, 2.0, 150.0};

/* A parameter or input value from 8 fuzzed bytes:
 *   kind % 4 == 0  the bits as an IEEE double (any value, NaN and Inf included)
 *   kind % 4 == 1  the start value (0.001 for 0) times 2^(int8 / 16), maybe negated: near the valid region
 *   kind % 4 == 2  int16 / 64: small numbers, integers, halves
 *   kind % 4 == 3  one of FUZZ_SPECIALS */
static inline double fuzz_value(uint8_t kind, uint64_t bits, double start)
{
    double d;
    switch (kind % 4) {
    case 0:
        memcpy(&d, &bits, sizeof d);
        return d;
    case 1: {
        double base = start != 0.0 ? start : 0.001;
        d = base * exp2((double)(int8_t)(bits & 0xff) / 16.0) * (1.0 + (double)(int8_t)((bits >> 8) & 0xff) / 512.0);
        return (bits >> 16) & 1 ? -d : d;
    }
    case 2:
        return (double)(int16_t)(bits & 0xffff) / 64.0;
    default:
        return FUZZ_SPECIALS[bits % 16];
    }
}

/* Silent, unless PIEZO_FUZZ_LOG is set (to see why a crash input was refused). */
static inline void fuzz_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                               fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env; (void)name; (void)category;
    if (getenv("PIEZO_FUZZ_LOG") == NULL)
        return;
    va_start(ap, message);
    fprintf(stderr, "[%d] ", (int)status);
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

static inline fmi2CallbackFunctions fuzz_callbacks(void)
{
    fmi2CallbackFunctions cb;
    memset(&cb, 0, sizeof cb);
    cb.logger = fuzz_logger;
    cb.allocateMemory = calloc;
    cb.freeMemory = free;
    return cb;
}

/* Every Real output finite when it can be read (abort otherwise). */
static inline void fuzz_outputs_finite(fmi2Component c)
{
    int vr;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++) {
        fmi2ValueReference ref = (fmi2ValueReference)vr;
        double value;
        if (model_variables[vr].causality != MODEL_OUTPUT || model_variables[vr].type != MODEL_REAL)
            continue;
        if (fmi2GetReal(c, &ref, 1, &value) == fmi2OK && !isfinite(value))
            abort();
    }
}

/* Get -> serialize -> deserialize -> set must work in whatever state c is,
 * and the deserialized state must serialize to the same bytes (abort otherwise). */
static inline void fuzz_state_round_trip(fmi2Component c)
{
    fmi2FMUstate s = NULL, back = NULL;
    size_t size = 0, size2 = 0;
    uint8_t *blob, *blob2;
    if (fmi2GetFMUstate(c, &s) != fmi2OK || fmi2SerializedFMUstateSize(c, s, &size) != fmi2OK)
        abort();
    blob = (uint8_t *)malloc(size);
    blob2 = (uint8_t *)malloc(size);
    if (blob == NULL || blob2 == NULL || fmi2SerializeFMUstate(c, s, (fmi2Byte *)blob, size) != fmi2OK
        || fmi2DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, &back) != fmi2OK
        || fmi2SerializedFMUstateSize(c, back, &size2) != fmi2OK || size2 != size
        || fmi2SerializeFMUstate(c, back, (fmi2Byte *)blob2, size) != fmi2OK || memcmp(blob, blob2, size) != 0
        || fmi2SetFMUstate(c, back) != fmi2OK)
        abort();
    fmi2FreeFMUstate(c, &s);
    fmi2FreeFMUstate(c, &back);
    free(blob);
    free(blob2);
}

#endif
