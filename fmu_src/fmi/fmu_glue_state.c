/*
 * fmu_glue_state.c - FMU states: get, set and free them, and their serialized form
 * (fmu_state_format.h), the same in both FMI versions. See fmu_glue_core.h.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_glue_core.h"
#include "fmu_state_format.h"

static glue_state *checked_state(const glue_instance *inst, const char *fname, void *s)
{
    glue_state *st = (glue_state *)s;
    if (st == NULL) {
        glue_log_error(inst, "%s: the FMU state is NULL", fname);
        return NULL;
    }
    if (st->magic != STATE_MAGIC || st->owner != inst) {
        glue_log_error(inst, "%s: not an FMU state of this %s instance (a state belongs to the instance "
                       "that made it with %s or %s)", fname, MODEL_IDENTIFIER_STRING,
                       inst->version->get_fmu_state, inst->version->deserialize);
        return NULL;
    }
    return st;
}

/* A state to fill: *slot if it is one of ours, else a new one in the list. */
static glue_state *state_slot(glue_instance *inst, const char *fname, void **slot)
{
    glue_state *st = (glue_state *)*slot;
    if (st != NULL)
        return checked_state(inst, fname, st);
    st = (glue_state *)inst->host.alloc(1, sizeof(glue_state));
    if (st == NULL) {
        glue_log_error(inst, "%s: out of memory", fname);
        return NULL;
    }
    memset(st, 0, sizeof *st);
    st->magic = STATE_MAGIC;
    st->owner = inst;
    st->next = inst->states;
    if (inst->states != NULL)
        inst->states->prev = st;
    inst->states = st;
    return st;
}

/* Unlink st from its owner's list and free it. */
void glue_state_free(glue_instance *inst, glue_state *st)
{
    if (st->prev != NULL)
        st->prev->next = st->next;
    else
        inst->states = st->next;
    if (st->next != NULL)
        st->next->prev = st->prev;
    if (st->history != NULL)
        inst->host.release(st->history);
    st->magic = 0;
    st->owner = NULL;
    inst->host.release(st);
}

static int state_reserve_history(glue_instance *inst, const char *fname, glue_state *st, size_t n)
{
    double *p;
    if (n <= st->history_capacity)
        return 1;
    p = (double *)inst->host.alloc(n, sizeof(double));
    if (p == NULL) {
        glue_log_error(inst, "%s: out of memory for %llu history samples", fname, (unsigned long long)n);
        return 0;
    }
    if (st->history != NULL)
        inst->host.release(st->history);
    st->history = p;
    st->history_capacity = n;
    return 1;
}

/* After a failure: a state made by this call goes, a reused one stays. */
static void state_release(glue_instance *inst, glue_state *st, int was_new)
{
    if (was_new)
        glue_state_free(inst, st);
}

glue_status glue_get_state(void *c, const char *fname, void **state)
{
    /* allowed in Error too: a host may keep the failed state for debugging */
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    glue_state *st;
    size_t n_hist = 0;
    int was_new;
    if (inst == NULL || glue_null_arg(inst, fname, "FMUstate", state))
        return GLUE_ERROR;
    was_new = *state == NULL;
    st = state_slot(inst, fname, state);
    if (st == NULL)
        return GLUE_ERROR;
    if (inst->mode & GLUE_MODE_CORE_READY) {
        /* the whole buffer the next step needs (slots not yet written are
         * rewritten before they are read) */
        n_hist = model_history_needed(&inst->data);
        if (!glue_ensure_history(inst, n_hist, fname)) {
            state_release(inst, st, was_new);
            return GLUE_ERROR;
        }
    }
    if (!state_reserve_history(inst, fname, st, n_hist)) {
        state_release(inst, st, was_new);
        return GLUE_ERROR;
    }
    st->mode = inst->mode;
    st->t0 = inst->t0;
    st->k = inst->k;
    st->h = inst->h;
    st->t_off = inst->t_off;
    memcpy(&st->data, &inst->data, sizeof st->data);
    if (n_hist > 0)
        memcpy(st->history, inst->history, n_hist * sizeof(double));
    st->n_history = n_hist;
    *state = st;
    return GLUE_OK;
}

glue_status glue_set_state(void *c, const char *fname, void *state)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    glue_state *st;
    if (inst == NULL)
        return GLUE_ERROR;
    st = checked_state(inst, fname, state);
    if (st == NULL)
        return GLUE_ERROR;
    if (!glue_ensure_history(inst, st->n_history, fname))
        return GLUE_ERROR;
    if (st->n_history > 0)
        memcpy(inst->history, st->history, st->n_history * sizeof(double));
    memcpy(&inst->data, &st->data, sizeof inst->data);
    inst->mode = st->mode;
    inst->t0 = st->t0;
    inst->k = st->k;
    inst->h = st->h;
    inst->t_off = st->t_off;
    inst->outputs_valid = 0;
    glue_log_event(inst, "%s: restored a state in %s at t = %.16g", fname, glue_mode_name(inst, inst->mode),
                   glue_time(inst));
    return GLUE_OK;
}

glue_status glue_free_state(void *c, const char *fname, void **state)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    glue_state *st;
    if (inst == NULL)
        return GLUE_ERROR;
    /* "If a null pointer is provided, the call is ignored" (FMI 2.0 and 3.0):
     * no handle, or a handle holding no state */
    if (state == NULL || *state == NULL) {
        glue_log_event(inst, "%s: no FMU state given: nothing to free", fname);
        return GLUE_OK;
    }
    st = checked_state(inst, fname, *state);
    if (st == NULL)
        return GLUE_ERROR;
    glue_state_free(inst, st);
    *state = NULL;
    return GLUE_OK;
}

/* The serialized state (fmu_state_format.h): the header, the model data, the history, the checksum */
#define BLOB_MIN_SIZE (BLOB_HEADER + sizeof(ModelData) + 8u)   /* no history */

static size_t blob_size(size_t n_history)
{
    return BLOB_MIN_SIZE + n_history * sizeof(double);
}

glue_status glue_state_size(void *c, const char *fname, void *state, size_t *size)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    glue_state *st;
    if (inst == NULL || glue_null_arg(inst, fname, "size", size))
        return GLUE_ERROR;
    st = checked_state(inst, fname, state);
    if (st == NULL)
        return GLUE_ERROR;
    *size = blob_size(st->n_history);
    return GLUE_OK;
}

glue_status glue_serialize(void *c, const char *fname, void *state, unsigned char *b, size_t size)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    glue_state *st;
    uint32_t bom = BLOB_BOM;
    size_t total, i, off;
    if (inst == NULL || glue_null_arg(inst, fname, "serializedState", b))
        return GLUE_ERROR;
    st = checked_state(inst, fname, state);
    if (st == NULL)
        return GLUE_ERROR;
    total = blob_size(st->n_history);
    if (size < total) {
        glue_log_error(inst, "%s: buffer of %llu bytes is too small: the state needs %llu (%s)",
                       fname, (unsigned long long)size, (unsigned long long)total,
                       inst->version->serialized_size);
        return GLUE_ERROR;
    }
    memset(b, 0, total);
    memcpy(b + BLOB_OFF_MAGIC, BLOB_MAGIC, 8);
    blob_put_u32(b + BLOB_OFF_VERSION, BLOB_VERSION);
    blob_put_u32(b + BLOB_OFF_HEADER_SIZE, BLOB_HEADER);
    blob_put_u64(b + BLOB_OFF_TOTAL, (uint64_t)total);
    memcpy(b + BLOB_OFF_GUID, MODEL_GUID, strlen(MODEL_GUID) < BLOB_GUID_LEN ? strlen(MODEL_GUID) : BLOB_GUID_LEN - 1);
    blob_put_u64(b + BLOB_OFF_DATA_SIZE, (uint64_t)sizeof(ModelData));
    memcpy(b + BLOB_OFF_BOM, &bom, 4);
    blob_put_u32(b + BLOB_OFF_MODE, (uint32_t)st->mode);
    blob_put_f64(b + BLOB_OFF_T0, st->t0);
    blob_put_u64(b + BLOB_OFF_K, st->k);
    blob_put_f64(b + BLOB_OFF_H, st->h);
    blob_put_u64(b + BLOB_OFF_N_HISTORY, (uint64_t)st->n_history);
    blob_put_f64(b + BLOB_OFF_T_OFF, st->t_off);
    memcpy(b + BLOB_HEADER, &st->data, sizeof(ModelData));
    off = BLOB_HEADER + sizeof(ModelData);
    for (i = 0; i < st->n_history; i++, off += 8)
        blob_put_f64(b + off, st->history[i]);
    blob_put_u64(b + off, blob_fnv1a(b, off));
    return GLUE_OK;
}

/* The first variable whose value a live instance could not hold (a non-finite
 * Real, a Boolean other than 0 or 1), or -1. Outputs count only once the core
 * is initialized (before that they are recomputed when read). */
static int invalid_variable(const ModelData *data, int core_ready)
{
    int vr;
    for (vr = 0; vr < (int)MODEL_N_VARIABLES; vr++) {
        const model_variable *var = &model_variables[vr];
        const char *p = (const char *)data + var->offset;
        if (var->causality == MODEL_OUTPUT && !core_ready)
            continue;
        if (var->type == MODEL_REAL && !isfinite(*(const double *)p))
            return vr;
        if (var->type == MODEL_BOOLEAN && *(const int *)p != 0 && *(const int *)p != 1)
            return vr;
    }
    return -1;
}

glue_status glue_deserialize(void *c, const char *fname, const unsigned char *b, size_t size, void **state)
{
    glue_instance *inst = glue_instance_of(c, fname, GLUE_MODE_ALL);
    char guid[BLOB_GUID_LEN], expected_guid[BLOB_GUID_LEN];
    char t1[GLUE_REAL_TEXT_SIZE], t2[GLUE_REAL_TEXT_SIZE];
    uint32_t bom = BLOB_BOM;
    uint64_t total, n_hist64, k;
    size_t n_hist, i, off;
    int mode, core_ready, bad_vr;
    double t0, h, t_off, *history = NULL;
    const char *fault;
    glue_state *st;
    ModelData *data;

    if (inst == NULL || glue_null_arg(inst, fname, "serializedState", b)
        || glue_null_arg(inst, fname, "FMUstate", state))
        return GLUE_ERROR;
    if (size < BLOB_HEADER + 8u || memcmp(b + BLOB_OFF_MAGIC, BLOB_MAGIC, 8) != 0) {
        glue_log_error(inst, "%s: refused: not a serialized %s state (bad magic or %llu bytes only)",
                       fname, MODEL_IDENTIFIER_STRING, (unsigned long long)size);
        return GLUE_ERROR;
    }
    if (blob_get_u32(b + BLOB_OFF_VERSION) != BLOB_VERSION
        || blob_get_u32(b + BLOB_OFF_HEADER_SIZE) != BLOB_HEADER) {
        glue_log_error(inst, "%s: refused: format version %u (header %u bytes) is not the supported version %u",
                       fname, (unsigned)blob_get_u32(b + BLOB_OFF_VERSION),
                       (unsigned)blob_get_u32(b + BLOB_OFF_HEADER_SIZE), (unsigned)BLOB_VERSION);
        return GLUE_ERROR;
    }
    total = blob_get_u64(b + BLOB_OFF_TOTAL);
    if (total != (uint64_t)size) {
        glue_log_error(inst, "%s: refused: the blob says %llu bytes but %llu were given (truncated or padded)",
                       fname, (unsigned long long)total, (unsigned long long)size);
        return GLUE_ERROR;
    }
    /* the whole field, padding included: serialization writes exactly this */
    memset(expected_guid, 0, sizeof expected_guid);
    memcpy(expected_guid, MODEL_GUID, strlen(MODEL_GUID) < BLOB_GUID_LEN ? strlen(MODEL_GUID) : BLOB_GUID_LEN - 1);
    if (memcmp(b + BLOB_OFF_GUID, expected_guid, BLOB_GUID_LEN) != 0) {
        memcpy(guid, b + BLOB_OFF_GUID, BLOB_GUID_LEN);
        guid[BLOB_GUID_LEN - 1] = '\0';
        for (i = 0; guid[i] != '\0'; i++)
            if ((unsigned char)guid[i] < 0x20 || (unsigned char)guid[i] > 0x7e)
                guid[i] = '?';
        glue_log_error(inst, "%s: refused: the state belongs to %s %s, not %s %s",
                       fname, inst->version->token_name, guid, MODEL_IDENTIFIER_STRING, MODEL_GUID);
        return GLUE_ERROR;
    }
    if (blob_get_u64(b + BLOB_OFF_DATA_SIZE) != (uint64_t)sizeof(ModelData) || memcmp(b + BLOB_OFF_BOM, &bom, 4) != 0) {
        glue_log_error(inst, "%s: refused: model data layout differs (size %llu vs %llu, or byte order): "
                       "the state comes from another build or platform",
                       fname, (unsigned long long)blob_get_u64(b + BLOB_OFF_DATA_SIZE),
                       (unsigned long long)sizeof(ModelData));
        return GLUE_ERROR;
    }
    /* total = BLOB_MIN_SIZE + 8 n_history, compared without arithmetic that can wrap */
    n_hist64 = blob_get_u64(b + BLOB_OFF_N_HISTORY);
    if (total < (uint64_t)BLOB_MIN_SIZE || (total - BLOB_MIN_SIZE) % 8u != 0
        || (total - BLOB_MIN_SIZE) / 8u != n_hist64) {
        glue_log_error(inst, "%s: refused: history length %llu does not match the blob size %llu",
                       fname, (unsigned long long)n_hist64, (unsigned long long)total);
        return GLUE_ERROR;
    }
    n_hist = (size_t)n_hist64;  /* < size, so it fits */
    off = (size_t)total - 8u;
    if (blob_fnv1a(b, off) != blob_get_u64(b + off)) {
        glue_log_error(inst, "%s: refused: checksum mismatch (the blob is corrupted)", fname);
        return GLUE_ERROR;
    }
    mode = (int)blob_get_u32(b + BLOB_OFF_MODE);
    t_off = blob_get_f64(b + BLOB_OFF_T_OFF);
    /* all bits 0 (not -0), or a part of a sample past t0 + k h of a model that takes any step */
    if (blob_get_u64(b + BLOB_OFF_T_OFF) != 0
        && !(MODEL_ANY_STEP && (mode & GLUE_MODE_CORE_READY) && t_off > 0.0 && t_off < blob_get_f64(b + BLOB_OFF_H))) {
        glue_log_error(inst, "%s: refused: the time past the last sample t_off = %s is not %s", fname,
                       glue_real_text(t1, t_off), MODEL_ANY_STEP ? "0 or in (0, h) after initialization" : "0");
        return GLUE_ERROR;
    }
    t0 = blob_get_f64(b + BLOB_OFF_T0);
    k = blob_get_u64(b + BLOB_OFF_K);
    h = blob_get_f64(b + BLOB_OFF_H);
    if (mode != GLUE_MODE_INSTANTIATED && mode != GLUE_MODE_INIT && mode != GLUE_MODE_STEP
        && mode != GLUE_MODE_TERMINATED && mode != GLUE_MODE_ERROR) {
        glue_log_error(inst, "%s: refused: invalid FMU mode %d", fname, mode);
        return GLUE_ERROR;
    }
    core_ready = (mode & GLUE_MODE_CORE_READY) != 0;
    data = &inst->backup;   /* the instance's scratch copy (used by the doStep only) */
    memcpy(data, b + BLOB_HEADER, sizeof *data);
    /* time: before initialization nothing has run (k = 0, h not yet fixed);
     * after it h is the model's, and t0 + k h is a time on the grid */
    if (!isfinite(t0)
        || (!core_ready && (k != 0 || h != 0.0))
        || (core_ready && !(h > 0.0 && h == model_sample_period(data) && k <= MAX_SAMPLES
                            && isfinite(t0 + (double)k * h + t_off)))) {
        glue_log_error(inst, "%s: refused: invalid time fields for state %s: t0 = %s, k = %llu, h = %s",
                       fname, glue_mode_name(inst, mode), glue_real_text(t1, t0), (unsigned long long)k,
                       glue_real_text(t2, h));
        return GLUE_ERROR;
    }
    bad_vr = invalid_variable(data, core_ready);
    if (bad_vr >= 0) {
        glue_log_error(inst, "%s: refused: variable %s holds a value no instance can have (%s)", fname,
                       model_variables[bad_vr].name,
                       model_variables[bad_vr].type == MODEL_REAL ? "not finite" : "Boolean other than 0 or 1");
        return GLUE_ERROR;
    }
    if (core_ready ? n_hist != model_history_needed(data) : n_hist != 0) {
        glue_log_error(inst, "%s: refused: %llu history samples stored, the model needs %llu", fname,
                       (unsigned long long)n_hist, (unsigned long long)(core_ready ? model_history_needed(data) : 0));
        return GLUE_ERROR;
    }
    if (n_hist > 0) {
        history = (double *)inst->host.alloc(n_hist, sizeof(double));
        if (history == NULL) {
            glue_log_error(inst, "%s: out of memory for %llu history samples", fname, (unsigned long long)n_hist);
            return GLUE_ERROR;
        }
        off = BLOB_HEADER + sizeof(ModelData);
        for (i = 0; i < n_hist; i++, off += 8)
            history[i] = blob_get_f64(b + off);
    }
    fault = model_check_data(data, core_ready, t0, k, history, n_hist);
    if (fault != NULL) {
        glue_log_error(inst, "%s: refused: invalid model data (%s)", fname, fault);
        if (history != NULL)
            inst->host.release(history);
        return GLUE_ERROR;
    }

    st = state_slot(inst, fname, state);
    if (st == NULL) {
        if (history != NULL)
            inst->host.release(history);
        return GLUE_ERROR;
    }
    if (st->history != NULL)
        inst->host.release(st->history);
    st->history = history;
    st->history_capacity = n_hist;
    st->n_history = n_hist;
    st->mode = mode;
    st->t0 = t0;
    st->k = k;
    st->h = h;
    st->t_off = t_off;
    memcpy(&st->data, data, sizeof *data);
    *state = st;
    return GLUE_OK;
}

/* ------------------------------------------------------------------------ */
/* Refusals                                                                  */
