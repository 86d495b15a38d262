/* piezo_controller_check.c - the check of a restored controller state and of a parameter
 * change. See piezo_controller_internal.h. */
#include <math.h>
#include <string.h>
#include "piezo_controller_internal.h"
#include "piezo_controller_params.h"

/* A ring of values tagged 1 + the sample each is for (0: empty): each tag in its slot,
 * (tag - 1) % ring, and at most `last` */
static int ring_tags_valid(const uint64_t *tag, int ring, uint64_t last)
{
    int i;
    for (i = 0; i < ring; ++i)
        if (tag[i] != 0 && (tag[i] > last || (tag[i] - 1) % (uint64_t)ring != (uint64_t)i)) return 0;
    return 1;
}

const char *piezo_controller_check(const piezo_controller *c)
{
    const char *fault;
    const piezo_controller_output *o;
    int i, j, m;
    uint64_t k_loop;
    if (!c) return "controller missing";
    /* the safe state: its fault, the verdict's sample (the loop's state is of then), the ramp */
    if (c->fault < 0 || c->fault > PIEZO_SUP_FAULT_MAX) return "safe state's fault code out of range";
    if (c->fault ? (c->sup.reaction != PIEZO_SUP_REACT_SAFE || c->k_fault >= c->k || !isfinite(c->v_fault)
                    || (c->fault <= PIEZO_SUP_FROZEN && c->verdict.fault != c->fault)
                    || (c->sat_enabled && (c->v_fault > c->sat_v_max || c->v_fault < c->sat_v_min)))
                 : c->k_fault != 0 || c->v_fault != 0.0)
        return "safe state inconsistent (reaction, sample, start of the ramp or verdict)";
    if (!isfinite(c->y_fault) || (c->y_moved != 0 && c->y_moved != 1)
        || (!c->fault && (c->y_fault != 0.0 || c->y_moved)))
        return "safe state's reading at the verdict inconsistent";
    k_loop = c->fault ? c->k_fault : c->k;
    /* sup.reset: the loop restarted at k_start (>= 1, a safe state came before), v ramping until
     * k_ramp_end; the loop's counters run from k_start */
    if (c->k_start > k_loop || c->n_resets > c->k || !isfinite(c->y_start)
        || (c->n_resets == 0 ? c->k_start != 0 || c->k_ramp_end != 0
                             : c->k_start == 0 || c->k_ramp_end != c->k_start + c->sup.ramp_samples))
        return "restart (sup.reset) sample, ramp or count inconsistent";
    /* the plain parameters' copies, each within its declared range (piezo_controller_params.h) */
#define PLAIN_COPY_CHECK(field, copy, name, lo, hi, lo_open, hi_open) \
    if (!piezo_in_range((double)c->copy, lo, hi, lo_open, hi_open)) return name " out of range";
    PIEZO_CONTROLLER_PLAIN_COPIES(PLAIN_COPY_CHECK)
#undef PLAIN_COPY_CHECK
    if ((fault = piezo_pi_check(&c->fwd_pi)) != NULL) return fault;
    if ((fault = piezo_pi_inverse_check(&c->inv_pi)) != NULL) return fault;
    if (c->inv_pi.m != c->fwd_pi.m) return "inverse PI and forward PI differ in m";
    if ((fault = piezo_gl_check(&c->inv_creep)) != NULL) return fault;
    if (c->inv_creep.k != k_loop - c->k_start) return "inverse creep sample counter differs from the controller's";
    if (c->d < 1 || c->d > PIEZO_MV_MAX_D) return "loop delay d outside 1..9";
    if (c->head < 0 || c->head >= PIEZO_MV_Q_RING) return "q ring index out of range";
    if (c->sat_hold < 0 || c->sat_hold > (c->d > PIEZO_DETECT_N ? c->d : PIEZO_DETECT_N) + 1)
        return "adaptation pause outside 0..max(d, 3)+1";
    if ((c->auto_delay != 0 && c->auto_delay != 1) || (c->detecting != 0 && c->detecting != 1)
        || (c->detecting && !c->auto_delay) || (c->auto_delay && c->d > PIEZO_DETECT_N)
        || (c->detecting && c->d != PIEZO_DETECT_START_D))
        return "delay detection flags or d inconsistent";
    /* a choice leaves its leader with a run of PIEZO_DETECT_CONFIRM (PIEZO_DETECT_CONFIRM_BURIED
     * while the probes are buried in the noise) */
    if (c->det_leader < -1 || c->det_leader >= PIEZO_DETECT_N || c->det_run < 0
        || c->det_run > (PIEZO_DETECT_CONFIRM > PIEZO_DETECT_CONFIRM_BURIED ? PIEZO_DETECT_CONFIRM
                                                                             : PIEZO_DETECT_CONFIRM_BURIED)
        || (c->detecting && c->det_run >= (piezo_controller_probes_buried(c) ? PIEZO_DETECT_CONFIRM_BURIED
                                                                              : PIEZO_DETECT_CONFIRM))
        || (c->det_leader < 0 && c->det_run != 0))
        return "delay detection leader out of range";
    if (!(isfinite(c->det_noise) && c->det_noise >= 0.0)) return "the detection's noise out of range";
    if (c->det_trial > c->k || !(isfinite(c->det_probe) && c->det_probe >= 0.0 && c->det_probe <= c->probe_max)
        || c->det_probes < 0 || c->det_probes > PIEZO_DETECT_PROBES)
        return "delay detection trial out of range";
    if (c->k_delay > c->k || c->k_search > c->k_delay || c->det_clock > c->k - c->k_search
        || (c->auto_delay && (c->n_detections < 1 || c->n_detections > c->k + 1))
        || (!c->auto_delay && c->n_detections != 0))
        return "delay detection counters out of range";
    if (!piezo_ctl_all_finite(c->det_theta, PIEZO_DETECT_THETA) || !piezo_ctl_all_finite(c->det_P, PIEZO_DETECT_P)
        || !piezo_ctl_all_finite(c->det_score, PIEZO_DETECT_N) || !isfinite(c->r_prev)
        || !piezo_ctl_all_finite(c->preview_value, PIEZO_PREVIEW_RING))
        return "delay detection or preview values not finite";
    if ((c->rls_enabled != 0 && c->rls_enabled != 1) || (c->sat_enabled != 0 && c->sat_enabled != 1))
        return "rls.enabled or sat.enabled is not 0 or 1";
    if (c->inv_forgetting != 1.0 / c->forgetting) return "the reciprocal of rls.forgetting kept from init does not match rls.forgetting";
    if (!(isfinite(c->trace_max) && c->trace_max >= 4.0 * c->p0)) return "rls.trace_max out of range";
    if (!(isfinite(c->sat_v_min) && isfinite(c->sat_v_max) && (!c->sat_enabled || c->sat_v_max > c->sat_v_min)))
        return "sat.v_min or sat.v_max out of range";
    if (c->excitation_samples > 9007199254740992ULL
        || !(isfinite(c->p0_loop) && c->p0_loop > 0.0 && 4.0 * c->p0_loop <= c->trace_max))
        return "rls.excitation_time or rls.p0_loop out of range";
    if (!(isfinite(c->noise_y) && c->noise_y >= 0.0 && isfinite(c->noise_y2) && c->noise_y2 >= 0.0
          && isfinite(c->noise_e) && c->noise_e >= 0.0
          && isfinite(c->r_anchor) && isfinite(c->offset) && isfinite(c->integral) && isfinite(c->r_last)
          && isfinite(c->r_last2) && isfinite(c->r_velocity)
          && piezo_ctl_all_finite(c->yd_value, PIEZO_MV_Q_RING)) || c->excite_left > c->excitation_samples || c->jump_left > 2 * (PIEZO_MV_MAX_D + 2)
        || (!c->robust && (c->noise_y != 0.0 || c->noise_y2 != 0.0 || c->noise_e != 0.0 || c->offset != 0.0 || c->excite_left != 0
                           || c->r_anchor != 0.0 || c->r_velocity != 0.0))
        || (c->integral_gain == 0.0 && c->integral != 0.0))
        return "robust adaptation or integral action state out of range";
    if (!ring_tags_valid(c->yd_tag, PIEZO_MV_Q_RING, c->k + PIEZO_MV_Q_RING))
        return "a kept reference's sample is not its slot's or too far ahead";
    /* a stamped preview is kept for its sample at + 1 <= k - 1 + PIEZO_PREVIEW_RING - 1 + 1 (the commit
     * of sample k - 1 stamps at most PIEZO_PREVIEW_RING - 1 ahead) */
    if (!ring_tags_valid(c->preview_tag, PIEZO_PREVIEW_RING, c->k + PIEZO_PREVIEW_RING - 1))
        return "a stamped preview's sample is not its slot's or too far ahead";
    if (c->divergence_samples > 2147483647u) return "monitor.divergence_samples out of range";
    if (c->mon_forgetting != piezo_ctl_monitor_forgetting((int)c->divergence_samples))
        return "the monitor's window kept from init does not match monitor.divergence_samples";
    if (!(isfinite(c->mon_share) && isfinite(c->mon_weight) && c->mon_share >= 0.0 && c->mon_share <= c->mon_weight
          && c->mon_weight <= (double)c->k))
        return "monitor share out of range";
    if (!(piezo_ctl_all_finite(c->theta_nominal, 4) && c->theta_nominal[2] > 0.0)) return "nominal model not finite or b1 <= 0";
    if (!piezo_ctl_all_finite(c->theta, 4) || !piezo_ctl_all_finite(c->P, 16) || !piezo_ctl_all_finite(c->y_prev, 2)
        || !piezo_ctl_all_finite(c->q_ring, PIEZO_MV_Q_RING))
        return "estimates, covariance or past values not finite";
    /* the loop's covariance and each candidate's stay bitwise symmetric (rls_step) */
    for (m = 0; m <= PIEZO_DETECT_N; ++m) {
        const double *P = m == 0 ? c->P : &c->det_P[16 * (m - 1)];
        for (i = 0; i < 4; ++i)
            for (j = 0; j < i; ++j)
                if (memcmp(&P[4 * i + j], &P[4 * j + i], sizeof P[0]) != 0)
                    return m == 0 ? "covariance not symmetric" : "a delay candidate's covariance not symmetric";
    }
    if (!(isfinite(c->max_abs_pred_error) && c->max_abs_pred_error >= 0.0)) return "largest |pred_error| not finite";
    if (c->n_saturated > c->k || c->n_large_error > c->k || c->run_saturated > c->n_saturated
        || c->run_large_error > c->n_large_error || c->n_large_settled > c->n_large_error
        || (c->n_large_settled > 0 ? c->k_first_large_settled >= c->k || c->k_first_large_settled
                                     < c->k_first_large_error : c->k_first_large_settled != 0))
        return "monitor counts exceed the sample count";
    if ((c->n_saturated > 0 ? c->k_first_saturated >= c->k : c->k_first_saturated != 0)
        || (c->n_large_error > 0 ? c->k_first_large_error >= c->k : c->k_first_large_error != 0))
        return "monitor first-sample index beyond the sample count";
    /* a run reaching the window, or a share reaching its quarter, would have been refused */
    if (c->divergence_samples > 0 && c->run_large_error >= c->divergence_samples)
        return "monitor run at or beyond the divergence window";
    if (c->divergence_samples > 0 && k_loop - c->k_start > PIEZO_MONITOR_SHARE_MIN_SAMPLES
        && c->mon_share * 100.0 >= PIEZO_MONITOR_SHARE_PERCENT * (double)c->divergence_samples)
        return "monitor share at or beyond its bound";
    if ((fault = piezo_supervisor_check(&c->sup)) != NULL) return fault;
    if (c->sup.k != k_loop - c->k_start) return "supervisor sample counter differs from the controller's";
    if (c->verdict.fault < PIEZO_SUP_NONE || c->verdict.fault > PIEZO_SUP_FROZEN)
        return "supervision verdict out of range";
    /* outliers: sums within their weights, counts within the samples */
    if (!(isfinite(c->err_sum) && isfinite(c->err_weight) && isfinite(c->outlier_sum) && c->err_sum >= 0.0
          && c->err_weight >= 0.0 && c->err_weight <= (double)c->k && c->outlier_sum >= 0.0
          && c->outlier_sum <= (double)c->k && isfinite(c->first_outlier) && isfinite(c->first_outlier_error))
        || c->quiet > c->k || c->n_outliers > c->k || (c->suspect != 0 && c->suspect != 1)
        || (c->suspect && c->k == 0) || (c->stale != 0 && c->stale != 1) || (c->stale && c->k == 0)
        || !isfinite(c->suspect_y) || !isfinite(c->suspect_error)
        || (!c->suspect && (c->suspect_y != 0.0 || c->suspect_error != 0.0))
        || (c->n_outliers > 0 ? c->k_first_outlier >= c->k
                              : c->k_first_outlier != 0 || c->first_outlier != 0.0 || c->first_outlier_error != 0.0))
        return "outlier sums or counts out of range";
    /* estimates with guarantees: the set is the one its parameters draw around the nominal model,
     * and the loop's estimates are in it; the fallback's window and counts in range */
    {
        double rows[PIEZO_ADMISSIBLE_ROWS][4], bounds[PIEZO_ADMISSIBLE_ROWS];
        if (!(isfinite(c->zero_min) && isfinite(c->gain_lo) && isfinite(c->gain_hi)
              && c->gain_lo > 0.0 && c->gain_lo < 1.0 && c->gain_hi > 1.0))
            return "rls.zero_min or the admissible gain range out of range";
        piezo_ctl_admissible_rows(c->theta_nominal, c->zero_min, c->pole_min, c->gain_lo, c->gain_hi, rows, bounds);
        if (memcmp(rows, c->adm_c, sizeof rows) != 0 || memcmp(bounds, c->adm_d, sizeof bounds) != 0)
            return "the admissible set differs from the one rls.zero_min, rls.pole_min and the gain range draw";
        if (piezo_ctl_admissible_violated(c, c->theta_nominal) || (c->robust && piezo_ctl_admissible_violated(c, c->theta)))
            return "the estimates (or the nominal model) outside the admissible set";
    }
    if (c->fallback_samples < 1 || c->fallback_forgetting != 1.0 - 1.0 / (double)c->fallback_samples
        || !(isfinite(c->fb_adapted) && c->fb_adapted >= 0.0 && isfinite(c->fb_nominal) && c->fb_nominal >= 0.0
             && isfinite(c->learned_rate) && c->learned_rate >= 0.0)
        || c->n_projections > c->k || c->n_fallbacks > c->k
        || (c->n_fallbacks > 0 ? (c->k_first_fallback >= c->k || c->first_fallback < PIEZO_FALLBACK_JUMP
                                  || c->first_fallback > PIEZO_FALLBACK_RINGING)
                               : (c->k_first_fallback != 0 || c->first_fallback != PIEZO_FALLBACK_NONE
                                  || c->first_fallback_value != 0.0 || c->first_fallback_other != 0.0))
        || !(isfinite(c->first_fallback_value) && isfinite(c->first_fallback_other))
        || (!c->robust && (c->fb_adapted != 0.0 || c->fb_nominal != 0.0 || c->learned_rate != 0.0
                           || c->n_projections != 0 || c->n_fallbacks != 0)))
        return "the fallback's window, learned rate or counts out of range";
    o = &c->out;
    if (!(isfinite(o->v) && isfinite(o->q) && isfinite(o->pred_error) && piezo_ctl_all_finite(o->theta, 4)))
        return "controller outputs not finite";
    if (o->saturated != 0 && o->saturated != 1) return "saturated output is not 0 or 1";
    if (o->adapting != 0 && o->adapting != 1) return "adapting output is not 0 or 1";
    if (o->fallback < PIEZO_FALLBACK_NONE || o->fallback > PIEZO_FALLBACK_RINGING
        || (o->fallback != PIEZO_FALLBACK_NONE && !c->robust))
        return "fallback output out of range";
    if (!(isfinite(o->noise) && o->noise >= 0.0)) return "noise output not finite or negative";
    if (o->delay < 0 || o->delay > PIEZO_MV_MAX_D || (o->preview != 0 && o->preview != 1))
        return "delay or preview output out of range";
    if (c->fault && (o->v != piezo_ctl_safe_v(c, c->v_fault, c->k - 1 - c->k_fault) || o->q != 0.0 || o->pred_error != 0.0
                     || o->saturated || o->preview || o->adapting || memcmp(o->theta, c->theta, sizeof o->theta) != 0))
        return "safe state's outputs differ from its ramp";
    return NULL;
}

const char *piezo_controller_check_params(const piezo_controller *c, const piezo_controller_params *q)
{
    piezo_controller scratch;
    int differs = 0;
    if (!c || !q) return "controller missing";
    if (piezo_controller_init(&scratch, q, NULL) != PIEZO_OK) return "parameters out of range";
    /* the plain parameters' copies equal to the parameters (piezo_controller_params.h) */
#define PLAIN_DIFFERS(field, copy, name, lo, hi, lo_open, hi_open) differs = differs || c->copy != q->field;
    PIEZO_CONTROLLER_PLAIN_COPIES(PLAIN_DIFFERS)
#undef PLAIN_DIFFERS
#define SUP_PLAIN_DIFFERS(field, copy, name, lo, hi, lo_open, hi_open) differs = differs || c->sup.copy != q->sup.field;
    PIEZO_SUPERVISOR_PLAIN_COPIES(SUP_PLAIN_DIFFERS)
#undef SUP_PLAIN_DIFFERS
    if (differs || (q->mv_delay == PIEZO_MV_AUTO_DELAY) != c->auto_delay || (!c->auto_delay && c->d != 1 + q->mv_delay)
        || c->fwd_pi.m != q->pi.m || c->inv_creep.exact != (q->creep_exact ? 1 : 0)
        || c->inv_creep.alpha != -q->creep_alpha
        || c->rls_enabled != (q->rls_enabled ? 1 : 0) || c->sat_enabled != (q->sat_enabled ? 1 : 0)
        || c->trace_max != q->rls_trace_max || c->excitation_samples != scratch.excitation_samples
        || c->p0_loop != q->rls_p0_loop
        || c->divergence_samples != (uint64_t)q->monitor_divergence_samples
        || (c->sat_enabled && (c->sat_v_min != q->sat_v_min || c->sat_v_max != q->sat_v_max))
        || c->sup.forgetting != scratch.sup.forgetting
        || c->sup.clip_samples != scratch.sup.clip_samples || c->sup.detect_samples != scratch.sup.detect_samples
        || c->sup.window != scratch.sup.window || c->sup.reaction != q->sup.reaction
        || c->sup.ramp_samples != scratch.sup.ramp_samples
        || c->zero_min != scratch.zero_min || c->gain_lo != q->sup.gain_min || c->gain_hi != q->sup.gain_max
        || c->fallback_samples != scratch.fallback_samples)
        return "controller state does not match its parameters";
    return NULL;
}

