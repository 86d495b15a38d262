/*
 * fuzz_run.c - libFuzzer target: fuzzed parameters and input sequences
 * through fmi2Instantiate / fmi2ExitInitializationMode / fmi2DoStep of the FMU
 * it is compiled with, with FMU-state round trips on the way (program format
 * and oracle in fuzz_common.h): no crash, no non-finite output returned with
 * fmi2OK or fmi2Warning, every live state restorable.
 */
#include "fuzz_common.h"

typedef struct {
    const uint8_t *p;
    size_t n;
} reader;

static uint8_t take_byte(reader *r)
{
    uint8_t b = 0;
    if (r->n > 0) {
        b = *r->p++;
        r->n--;
    }
    return b;
}

static uint64_t take_u64(reader *r)
{
    uint8_t bytes[8] = {0};
    size_t i;
    for (i = 0; i < 8; i++)
        bytes[i] = take_byte(r);
    return blob_get_u64(bytes);     /* little-endian, as the serialized state's integers */
}

/* Sets variable vr from a fuzzed kind and value (status ignored: refusals are fine). */
static void set_variable(fmi2Component c, int vr, uint8_t kind, uint64_t bits, const ModelData *start)
{
    const model_variable *v = &model_variables[vr];
    const char *p = (const char *)start + v->offset;
    fmi2ValueReference ref = (fmi2ValueReference)vr;
    if (v->type == MODEL_REAL) {
        double value = fuzz_value(kind, bits, *(const double *)p);
        fmi2SetReal(c, &ref, 1, &value);
    } else if (v->type == MODEL_INTEGER) {
        int base = *(const int *)p;
        fmi2Integer value = kind % 2 ? (fmi2Integer)(int32_t)(uint32_t)bits : base + (int)(int8_t)(bits & 0xff) / 16;
        fmi2SetInteger(c, &ref, 1, &value);
    } else {
        fmi2Boolean value = (fmi2Boolean)(bits & 1);
        fmi2SetBoolean(c, &ref, 1, &value);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int params[MODEL_N_VARIABLES], inputs[MODEL_N_VARIABLES];
    int n_params = 0, n_inputs = 0, i, vr, samples = 0, n_set, round_trips = 0;
    fmi2CallbackFunctions cb = fuzz_callbacks();
    reader r = {data, size};
    ModelData start;
    fmi2Component c;
    fmi2FMUstate saved = NULL;
    uint8_t head;
    double t0, t, h = 0.0;
    fmi2ValueReference h_ref = 0;

    memset(&start, 0, sizeof start);
    model_set_start_values(&start);
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++) {
        if (model_variables[vr].causality == MODEL_PARAMETER)
            params[n_params++] = vr;
        else if (model_variables[vr].causality == MODEL_INPUT)
            inputs[n_inputs++] = vr;
        if (strcmp(model_variables[vr].name, "h") == 0)
            h_ref = (fmi2ValueReference)vr;     /* every FMU here has its sample period as parameter h */
    }
    head = take_byte(&r);
    n_set = head % 32;
    t0 = FUZZ_START_TIMES[head / 32];
    c = fmi2Instantiate("fuzz", fmi2CoSimulation, MODEL_GUID, "", &cb, fmi2False, fmi2False);
    if (c == NULL || fmi2SetupExperiment(c, fmi2False, 0.0, t0, fmi2False, 0.0) != fmi2OK
        || fmi2EnterInitializationMode(c) != fmi2OK)
        abort();
    for (i = 0; i < n_set; i++) {
        int which = take_byte(&r) % n_params;
        uint8_t kind = take_byte(&r);
        set_variable(c, params[which], kind, take_u64(&r), &start);
    }
    fuzz_outputs_finite(c);     /* outputs in initialization mode */
    if (fmi2ExitInitializationMode(c) != fmi2OK) {
        fuzz_state_round_trip(c);
        fmi2FreeInstance(c);
        return 0;
    }
    fuzz_outputs_finite(c);
    if (fmi2GetReal(c, &h_ref, 1, &h) != fmi2OK)
        abort();
    while (r.n > 0 && samples < FUZZ_MAX_SAMPLES) {
        uint8_t op = take_byte(&r);
        int n_steps = 0;
        fmi2Status st;
        switch (op % 8) {
        case 5:
            n_steps = 1;
            break;
        case 6:
            /* a few per input: a round trip serializes the whole (exact-mode) history */
            if (round_trips++ < 4)
                fuzz_state_round_trip(c);
            break;
        case 7:
            if (saved == NULL) {
                if (fmi2GetFMUstate(c, &saved) != fmi2OK)
                    abort();
            } else if (fmi2SetFMUstate(c, saved) != fmi2OK) {
                abort();
            }
            break;
        default:
            for (i = 0; i < n_inputs; i++) {
                uint8_t kind = take_byte(&r);
                set_variable(c, inputs[i], kind, take_u64(&r), &start);
            }
            n_steps = (op / 8) % 8;
            break;
        }
        if (n_steps > 0 && fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t) == fmi2OK) {
            /* in Terminated the step is refused; in Error GetRealStatus already was */
            st = fmi2DoStep(c, t, n_steps * h, fmi2True);
            if (st == fmi2OK || st == fmi2Warning)
                fuzz_outputs_finite(c);
        }
        samples += n_steps;
    }
    fuzz_state_round_trip(c);
    if (saved != NULL)
        fmi2FreeFMUstate(c, &saved);
    fmi2FreeInstance(c);
    return 0;
}
