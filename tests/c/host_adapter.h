/*
 * host_adapter.h - what the FMI 2.0 and the FMI 3.0 adapter do alike, written
 * once: host_fmi2.h and host_fmi3.h each include it with their version's names
 * defined (the list below), after their own model-description reader,
 * instantiate and enter_init, and get from it their
 *
 *   hostV_load, hostV_unload            the binary and its description
 *   hostV_start, hostV_free_instance    a fresh instance in Step Mode, and its end
 *   hostV_get_state ... hostV_deserialize   the six FMU-state calls
 *   hostV_snapshot, hostV_same_state    the state as a blob, and a comparison with one
 *   hostV_get_reals, hostV_set_reals, hostV_get_ints ... hostV_set_bools
 *                                       the typed value calls
 *   hostV_real_outputs                  every Real (Float64) output
 *
 * The names the including adapter defines (this file undefines them at its
 * end, so both adapters may stand in one suite, as the cross-edition checks do):
 *
 *   HOSTV(name)          the adapter's function names (host2_##name)
 *   HOSTV_FMU, HOSTV_INST    its FMU and instance types
 *   HOSTV_C, HOSTV_STATUS, HOSTV_OK, HOSTV_STATE, HOSTV_BYTE
 *                        the version's instance handle, status, OK, FMU state and Byte
 *   HOSTV_API, HOSTV_PREFIX  its list of functions (FMI2_API) and their prefix ("fmi2")
 *   HOSTV_GET_STATE, HOSTV_SET_STATE, HOSTV_FREE_STATE, HOSTV_STATE_SIZE,
 *   HOSTV_SERIALIZE, HOSTV_DESERIALIZE
 *                        f->api's names of the six FMU-state functions (the
 *                        versions spell them differently: GetFMUstate, GetFMUState)
 *   HOSTV_VR             its value reference type
 *   HOSTV_VALUE_TYPES(X) X(api name, kind, C type) of the three value types:
 *                        X(Real, reals, double) ... (FMI 3.0: Float64, Int32)
 *   HOSTV_VALUES_CALL(fn, c, vr, nvr, values, n_values)
 *                        a call of the get or set function fn (FMI 2.0 has
 *                        one value per value reference: no n_values)
 *
 * No include guard: it is meant to be included once per version.
 */

/* ------------------------------------------------------------------------ */
/* loading                                                                   */

/* An FMU: its description and every function of its binary. */
static inline int HOSTV(load)(HOSTV_FMU *f, const char *xml_path, const char *so_path)
{
    memset(f, 0, sizeof *f);
    if (!HOSTV(read_model_description)(f, xml_path))
        return 0;
    f->lib = dlopen(so_path, RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        host_fail("dlopen %s: %s", so_path, dlerror());
        return 0;
    }
#define HOSTV_LOAD(name)                                                    \
    *(void **)(&f->api.name) = dlsym(f->lib, HOSTV_PREFIX #name);           \
    if (f->api.name == NULL) {                                              \
        host_fail("%s: symbol %s%s missing", so_path, HOSTV_PREFIX, #name); \
        return 0;                                                           \
    }
    HOSTV_API(HOSTV_LOAD)
#undef HOSTV_LOAD
    return 1;
}

static inline void HOSTV(unload)(HOSTV_FMU *f)
{
    if (f->lib != NULL)
        dlclose(f->lib);
    f->lib = NULL;
}

/* ------------------------------------------------------------------------ */
/* instances                                                                 */

/* A fresh instance in Step Mode (FMI 2.0: StepComplete) at t0 = 0 with the start
 * values (in->c NULL if not). */
static inline HOSTV_C HOSTV(start)(HOSTV_INST *in, const HOSTV_FMU *f, const char *name)
{
    if (HOSTV(instantiate)(in, f, name) != NULL
        && (HOSTV(enter_init)(f, in->c, 0.0, 0, 0.0) != HOSTV_OK || f->api.ExitInitializationMode(in->c) != HOSTV_OK)) {
        f->api.FreeInstance(in->c);
        in->c = NULL;
    }
    return in->c;
}

static inline void HOSTV(free_instance)(HOSTV_INST *in)
{
    if (in->c != NULL)
        in->f->api.FreeInstance(in->c);
    in->c = NULL;
}

/* ------------------------------------------------------------------------ */
/* FMU states                                                                */

static inline HOSTV_STATUS HOSTV(get_state)(const HOSTV_FMU *f, HOSTV_C c, HOSTV_STATE *s)
{
    return f->api.HOSTV_GET_STATE(c, s);
}

static inline HOSTV_STATUS HOSTV(set_state)(const HOSTV_FMU *f, HOSTV_C c, HOSTV_STATE s)
{
    return f->api.HOSTV_SET_STATE(c, s);
}

static inline HOSTV_STATUS HOSTV(free_state)(const HOSTV_FMU *f, HOSTV_C c, HOSTV_STATE *s)
{
    return f->api.HOSTV_FREE_STATE(c, s);
}

static inline HOSTV_STATUS HOSTV(state_size)(const HOSTV_FMU *f, HOSTV_C c, HOSTV_STATE s, size_t *size)
{
    return f->api.HOSTV_STATE_SIZE(c, s, size);
}

static inline HOSTV_STATUS HOSTV(serialize)(const HOSTV_FMU *f, HOSTV_C c, HOSTV_STATE s, unsigned char *blob,
                                            size_t size)
{
    return f->api.HOSTV_SERIALIZE(c, s, (HOSTV_BYTE *)blob, size);
}

static inline HOSTV_STATUS HOSTV(deserialize)(const HOSTV_FMU *f, HOSTV_C c, const unsigned char *blob,
                                              size_t size, HOSTV_STATE *s)
{
    return f->api.HOSTV_DESERIALIZE(c, (const HOSTV_BYTE *)blob, size, s);
}

/* The instance's current state as a serialized blob (malloc'ed, *size set), or NULL. */
static inline unsigned char *HOSTV(snapshot)(const HOSTV_FMU *f, HOSTV_C c, size_t *size)
{
    HOSTV_STATE s = NULL;
    unsigned char *blob = NULL;
    *size = 0;
    if (f->api.HOSTV_GET_STATE(c, &s) != HOSTV_OK)
        return NULL;
    if (f->api.HOSTV_STATE_SIZE(c, s, size) == HOSTV_OK && (blob = (unsigned char *)malloc(*size)) != NULL
        && f->api.HOSTV_SERIALIZE(c, s, (HOSTV_BYTE *)blob, *size) != HOSTV_OK) {
        free(blob);
        blob = NULL;
    }
    f->api.HOSTV_FREE_STATE(c, &s);
    return blob;
}

/* 1 when the instance's state serializes to exactly `blob`. */
static inline int HOSTV(same_state)(const HOSTV_FMU *f, HOSTV_C c, const unsigned char *blob, size_t size)
{
    size_t now_size;
    unsigned char *now = HOSTV(snapshot)(f, c, &now_size);
    int same = now != NULL && blob != NULL && now_size == size && memcmp(now, blob, size) == 0;
    free(now);
    return same;
}

/* ------------------------------------------------------------------------ */
/* values                                                                    */

/* hostV_get_reals, hostV_set_reals, hostV_get_ints ... : f->api.<Get|Set><Type> */
#define HOSTV_GET_SET(api_name, kind, ctype)                                                            \
    static inline HOSTV_STATUS HOSTV(get_##kind)(const HOSTV_FMU *f, HOSTV_C c, const HOSTV_VR *vr,    \
                                                 size_t nvr, ctype *values, size_t n_values)           \
    {                                                                                                   \
        return HOSTV_VALUES_CALL(f->api.Get##api_name, c, vr, nvr, values, n_values);                   \
    }                                                                                                   \
    static inline HOSTV_STATUS HOSTV(set_##kind)(const HOSTV_FMU *f, HOSTV_C c, const HOSTV_VR *vr,    \
                                                 size_t nvr, const ctype *values, size_t n_values)     \
    {                                                                                                   \
        return HOSTV_VALUES_CALL(f->api.Set##api_name, c, vr, nvr, values, n_values);                   \
    }
HOSTV_VALUE_TYPES(HOSTV_GET_SET)
#undef HOSTV_GET_SET

/* Every Real (Float64) output into out[capacity] (in variable order); returns how many,
 * or -1 on an error status or more outputs than capacity (a FAIL). */
static inline int HOSTV(real_outputs)(const HOSTV_FMU *f, HOSTV_C c, double *out, int capacity)
{
    int i, n = 0;
    for (i = 0; i < f->n_vars; i++) {
        if (f->vars[i].causality != VAR_OUTPUT || f->vars[i].type != VAR_REAL)
            continue;
        if (n >= capacity) {
            host_fail("%s has more than %d Real outputs: the host's buffer is too small", f->id, capacity);
            return -1;
        }
        if (HOSTV(get_reals)(f, c, &f->vars[i].vr, 1, &out[n], 1) != HOSTV_OK)
            return -1;
        n++;
    }
    return n;
}

#undef HOSTV
#undef HOSTV_FMU
#undef HOSTV_INST
#undef HOSTV_C
#undef HOSTV_STATUS
#undef HOSTV_OK
#undef HOSTV_STATE
#undef HOSTV_BYTE
#undef HOSTV_API
#undef HOSTV_PREFIX
#undef HOSTV_GET_STATE
#undef HOSTV_SET_STATE
#undef HOSTV_FREE_STATE
#undef HOSTV_STATE_SIZE
#undef HOSTV_SERIALIZE
#undef HOSTV_DESERIALIZE
#undef HOSTV_VR
#undef HOSTV_VALUE_TYPES
#undef HOSTV_VALUES_CALL
