/*
 * state_format.h - the serialized FMU state as the test hosts and the fuzz
 * targets of tests/c/ read and tamper with it: the header fields they touch,
 * little-endian integers and the checksum. The format itself (both FMI
 * versions write the same bytes) is documented, field by field, in
 * fmu_src/fmi/fmu_glue_core.c: a 128-byte header, the model data, the creep
 * history, and an FNV-1a 64 checksum of everything before it in the last 8 bytes.
 */
#ifndef STATE_FORMAT_H
#define STATE_FORMAT_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#define BLOB_HEADER 128u
#define BLOB_OFF_TOTAL 16u
#define BLOB_OFF_DATA_SIZE 72u
#define BLOB_OFF_MODE 84u
#define BLOB_OFF_T0 88u
#define BLOB_OFF_K 96u
#define BLOB_OFF_H 104u
#define BLOB_OFF_N_HISTORY 112u
#define BLOB_OFF_RESERVED 120u

#define BLOB_MODE_ERROR 16u     /* the mode field of a state saved in Error */

static inline uint64_t blob_get_u64(const unsigned char *p)
{
    uint64_t v = 0;
    int i;
    for (i = 7; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static inline void blob_put_u64(unsigned char *p, uint64_t v)
{
    int i;
    for (i = 0; i < 8; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static inline void blob_put_f64(unsigned char *p, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    blob_put_u64(p, v);
}

/* FNV-1a 64 of the first n bytes, as the format's checksum. */
static inline uint64_t blob_fnv1a(const unsigned char *p, size_t n)
{
    uint64_t h = 0xcbf29ce484222325ull;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

/* Make a tampered blob self-consistent again: size field and checksum. */
static inline void blob_reseal(unsigned char *b, size_t size)
{
    if (size < BLOB_HEADER + 8u)
        return;
    blob_put_u64(b + BLOB_OFF_TOTAL, (uint64_t)size);
    blob_put_u64(b + size - 8u, blob_fnv1a(b, size - 8u));
}

#endif
