/*
 * fmu_state_format.h - the serialized FMU state's format: its one declaration, which the FMI
 * layer (fmu_glue_state.c) writes and reads and the C tests (tests/c/state_format.h) tamper with.
 * Standalone: C99 and <stdint.h>, <string.h> only.
 */
/*
 * The serialized FMU state (format version 2), the same in both FMI versions.
 * Version 2: the creep's SOE states are kept advanced to the next sample
 * (piezo_creep.h); a version 1 image holds them one sample behind, so it is
 * refused rather than restored one sample off.
 * Header integers and doubles are little-endian whatever the host; the
 * ModelData image is the host's native layout, guarded by its size and a
 * byte-order marker.
 *
 *   offset  size  field
 *        0     8  magic "PZFMUST1"
 *        8     4  format version (2)
 *       12     4  header size (128)
 *       16     8  total size of the blob, checksum included
 *       24    48  model GUID (the FMI 3.0 instantiationToken is the same string), NUL padded
 *       72     8  sizeof(ModelData)
 *       80     4  byte-order marker 0x01020304 written natively
 *       84     4  FMU mode (1 Instantiated, 2 InitializationMode, 4 StepComplete/StepMode,
 *                 8 Terminated, 16 Error)
 *       88     8  t0 (IEEE double)
 *       96     8  k, samples since t0
 *      104     8  h (IEEE double)
 *      112     8  n_history, doubles of exact-mode history
 *      120     8  t_off (IEEE double): 0 on the grid (every FMU but PiezoStageClosedLoop: always
 *                 0, as when this field was reserved); a model that takes steps of any size
 *                 (MODEL_ANY_STEP) may have its time past t0 + k h, 0 < t_off < h
 *      128     .  ModelData image (sizeof(ModelData) bytes)
 *        .     .  n_history doubles (IEEE, little-endian)
 *    end-8     8  FNV-1a 64 checksum of every preceding byte
 *
 * Because the modes, the GUID and the model data are the same, a state
 * serialized by the FMI 2.0 edition of a model restores in its FMI 3.0 edition
 * and the other way round.
 *
 * A blob is untrusted input: deserialization reads nothing it has not bounded
 * (sizes compared without arithmetic that can wrap) and accepts only what
 * a live instance could have saved: the exact GUID field, a known mode, the
 * time fields of that mode (before initialization k = 0 and h = 0; after it
 * h = the model's h, k <= 2^53, t0 + k h finite), t_off = 0 (a MODEL_ANY_STEP
 * model in a mode after initialization: 0 <= t_off < h), finite Reals
 * and 0/1 Booleans in every variable, and the model's own invariants
 * (model_check_data: indices, counts, flags, sample counters against k and the
 * history). Anything else is refused and nothing is changed.
 */
#ifndef FMU_STATE_FORMAT_H
#define FMU_STATE_FORMAT_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#define BLOB_MAGIC "PZFMUST1"
#define BLOB_VERSION 2u
#define BLOB_HEADER 128u
#define BLOB_GUID_LEN 48u
#define BLOB_BOM 0x01020304u

/* the header's fields: offsets, as in the table above */
#define BLOB_OFF_MAGIC 0u
#define BLOB_OFF_VERSION 8u
#define BLOB_OFF_HEADER_SIZE 12u
#define BLOB_OFF_TOTAL 16u
#define BLOB_OFF_GUID 24u
#define BLOB_OFF_DATA_SIZE 72u
#define BLOB_OFF_BOM 80u
#define BLOB_OFF_MODE 84u
#define BLOB_OFF_T0 88u
#define BLOB_OFF_K 96u
#define BLOB_OFF_H 104u
#define BLOB_OFF_N_HISTORY 112u
#define BLOB_OFF_T_OFF 120u

/* the checksum: FNV-1a 64 */
#define BLOB_FNV_OFFSET 0xcbf29ce484222325ull
#define BLOB_FNV_PRIME 0x100000001b3ull

/* the header's fields, each where the one before ends */
typedef char blob_assert_layout[(BLOB_OFF_VERSION == BLOB_OFF_MAGIC + 8u
                                 && BLOB_OFF_HEADER_SIZE == BLOB_OFF_VERSION + 4u
                                 && BLOB_OFF_TOTAL == BLOB_OFF_HEADER_SIZE + 4u && BLOB_OFF_GUID == BLOB_OFF_TOTAL + 8u
                                 && BLOB_OFF_DATA_SIZE == BLOB_OFF_GUID + BLOB_GUID_LEN
                                 && BLOB_OFF_BOM == BLOB_OFF_DATA_SIZE + 8u && BLOB_OFF_MODE == BLOB_OFF_BOM + 4u
                                 && BLOB_OFF_T0 == BLOB_OFF_MODE + 4u && BLOB_OFF_K == BLOB_OFF_T0 + 8u
                                 && BLOB_OFF_H == BLOB_OFF_K + 8u && BLOB_OFF_N_HISTORY == BLOB_OFF_H + 8u
                                 && BLOB_OFF_T_OFF == BLOB_OFF_N_HISTORY + 8u && BLOB_HEADER == BLOB_OFF_T_OFF + 8u)
                                ? 1 : -1];

/* little-endian integers of n bytes and IEEE doubles, whatever the host */
static inline void blob_put_le(unsigned char *p, uint64_t v, int n)
{
    int i;
    for (i = 0; i < n; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static inline uint64_t blob_get_le(const unsigned char *p, int n)
{
    uint64_t v = 0;
    int i;
    for (i = n - 1; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static inline void blob_put_u32(unsigned char *p, uint32_t v) { blob_put_le(p, v, 4); }
static inline void blob_put_u64(unsigned char *p, uint64_t v) { blob_put_le(p, v, 8); }
static inline uint32_t blob_get_u32(const unsigned char *p) { return (uint32_t)blob_get_le(p, 4); }
static inline uint64_t blob_get_u64(const unsigned char *p) { return blob_get_le(p, 8); }

static inline void blob_put_f64(unsigned char *p, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    blob_put_u64(p, v);
}

static inline double blob_get_f64(const unsigned char *p)
{
    uint64_t v = blob_get_u64(p);
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

/* FNV-1a 64 of the first n bytes: the checksum in the last 8 bytes */
static inline uint64_t blob_fnv1a(const unsigned char *p, size_t n)
{
    uint64_t h = BLOB_FNV_OFFSET;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= BLOB_FNV_PRIME;
    }
    return h;
}

#endif
