/*
 * fuzz_deserialize.c - libFuzzer target: fmi2DeSerializeFMUstate of the FMU it
 * is compiled with (see fuzz_common.h for the oracle). The input is a
 * serialized state; before it is offered, its size field and its checksum are
 * recomputed, so mutations reach the validation behind them, and an absurd
 * history length is made to agree with the size modulo 2^64 (a wrap candidate). An accepted state
 * must serialize back to the same bytes, restore, give finite outputs, step
 * (when its mode allows) with finite outputs, and round-trip again.
 */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fmi2CallbackFunctions cb = fuzz_callbacks();
    fmi2Component c;
    fmi2FMUstate s = NULL;
    uint8_t *blob = (uint8_t *)malloc(size > 0 ? size : 1), *again = NULL;
    size_t again_size = 0;
    double t, h;
    int i;
    if (blob == NULL)
        return 0;
    memcpy(blob, data, size);
    if (size >= BLOB_HEADER + 8u) {
        /* n_history with any of its top 3 bits set is absurd; make it agree with the
         * size modulo 2^64 instead, so wrapping size arithmetic is tried:
         * 128 + data size + 8 n + 8 == size (mod 2^64), n + (top - 1) 2^61 */
        uint64_t n_history = blob_get_u64(blob + BLOB_OFF_N_HISTORY);
        uint64_t data_size = blob_get_u64(blob + BLOB_OFF_DATA_SIZE);
        if (n_history >> 61)
            blob_put_u64(blob + BLOB_OFF_N_HISTORY, ((uint64_t)size - BLOB_HEADER - 8u - data_size) / 8u
                                                        + (((n_history >> 61) - 1u) << 61));
        blob_reseal(blob, size);
    }
    c = fmi2Instantiate("fuzz", fmi2CoSimulation, MODEL_GUID, "", &cb, fmi2False, fmi2False);
    if (c == NULL)
        abort();
    if (fmi2DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, &s) == fmi2OK) {
        /* canonical: the accepted state is exactly these bytes */
        if (fmi2SerializedFMUstateSize(c, s, &again_size) != fmi2OK || again_size != size)
            abort();
        again = (uint8_t *)malloc(size);
        if (again == NULL || fmi2SerializeFMUstate(c, s, (fmi2Byte *)again, size) != fmi2OK
            || memcmp(again, blob, size) != 0)
            abort();
        if (fmi2SetFMUstate(c, s) != fmi2OK)
            abort();
        fuzz_outputs_finite(c);
        /* step on from the restored time, if the restored mode allows it */
        memcpy(&h, blob + BLOB_OFF_H, sizeof h);
        for (i = 0; i < 3 && fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t) == fmi2OK; i++) {
            fmi2Status st = fmi2DoStep(c, t, (double)(i + 1) * h, fmi2True);
            if (st > fmi2Warning)
                break;
            fuzz_outputs_finite(c);
        }
        fuzz_state_round_trip(c);
        fmi2FreeFMUstate(c, &s);
    } else if (s != NULL) {
        abort();    /* a refused call hands out nothing */
    }
    fmi2FreeInstance(c);
    free(blob);
    free(again);
    return 0;
}
