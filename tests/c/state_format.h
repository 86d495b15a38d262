/*
 * state_format.h - the serialized FMU state as the test hosts and the fuzz
 * targets of tests/c/ tamper with it. The format (its fields, their offsets,
 * little-endian integers, the checksum) is declared once, in
 * fmu_src/fmi/fmu_state_format.h, which the FMUs' glue writes and reads.
 */
#ifndef STATE_FORMAT_H
#define STATE_FORMAT_H

#include "fmu_state_format.h"

#define BLOB_MODE_ERROR 16u     /* the mode field of a state saved in Error */

/* Make a tampered blob self-consistent again: size field and checksum. */
static inline void blob_reseal(unsigned char *b, size_t size)
{
    if (size < BLOB_HEADER + 8u)
        return;
    blob_put_u64(b + BLOB_OFF_TOTAL, (uint64_t)size);
    blob_put_u64(b + size - 8u, blob_fnv1a(b, size - 8u));
}

#endif
