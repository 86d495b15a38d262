/*
 * piezo_controller.h - adaptive compound controller (docs/model.md, controller):
 *
 *     y_meas(k) -> RLS update -> MV law -> q(k) -> inverse creep -> r(k)
 *               -> inverse PI -> v(k) [-> saturation]
 *
 * Loop model seen from q: y(k) = -a1 y(k-1) - a2 y(k-2) + b1 q(k-d) + b2 q(k-d-1),
 * i.e. A(z^-1) y = z^-d B(z^-1) q, d = 1 + mv_delay, or detected (mv_delay = -1).
 * Diophantine with the observer polynomial T = 1 - t z^-1 (t = mv_observer):
 *     T = A E + z^-d Gd, deg E = d-1, deg Gd = 1, F = B E (deg d).
 * Predictor: T y(k+d) = Gd y(k) + F q(k). MV (with control weighting lambda_u):
 *     q(k) = f0 (T r(k) - Gd y(k) - sum_{i=1..d} f_i q(k-i)) / (f0^2 + lambda_u)
 * where r(k) = y_d(k+d) (reference preview) and T r(k) = r(k) - t r(k-1).
 * On the model, T (y(k+d) - r(k)) = 0: the tracking error decays like t^k;
 * the measurement noise reaches y through Gd / T (docs/cosimulation.md).
 *
 * Delay detection (mv_delay = -1, docs/cosimulation.md): until d is chosen, one
 * RLS per candidate d = 1..3 runs on its own regressor and sums its squared
 * a-priori errors; the law meanwhile is the start-up law (nominal model,
 * d = 2, t = 0.9), stable for each candidate. A candidate is chosen once its
 * sum stays below a tenth of every other's for 3 consecutive samples; its RLS
 * becomes the controller's. A chosen loop whose |pred_error| stays above the
 * monitor bound for 10 samples goes back to detection.
 *
 * Preview alignment: the input may carry a stamped preview, y_d at the
 * measurement's sample + preview_lead. The controller keeps them in a ring
 * and uses y_d(k + d) from it when present, y_ref otherwise.
 *
 * Robust adaptation (rls.robust, docs/model.md): the loop's RLS updates only
 * while the reference excites the loop (it left its straight-line extrapolation
 * from the last excitation by more than rls.excitation times the measured noise
 * of y_meas within the last rls.excitation_time),
 * regresses y - c on the model, c the offset it tracks while it does not
 * update, starts from rls.p0_loop I once d is chosen, and bounds trace(P) by
 * rls.variance_max / sigma_e^2 (sigma_e the measured noise of its prediction
 * error) as well as rls.trace_max. Integral action (mv.integral):
 *     z(k) = z(k-1) + gamma (y_d(k) - y_meas(k)),   the law tracks r(k) + z(k),
 * held on a reading unchanged for PIEZO_SUP_STUCK_SAME samples once sup.gain_min times the move the
 * supervision's model gives the stage since the reading last changed reaches one of its steps (a
 * stuck reading must not walk the stage; one that has not crossed its grid yet carries the error).
 *
 * Guarantees of the robust update (docs/model.md, "Estimates with guarantees"):
 * - the admissible set: after every update the estimates are projected (in the metric of
 *   P^-1, then radially towards the nominal model) into the polytope
 *       A's poles in the convex hull of real poles in [rls.pole_min, 1)
 *           (A(1) >= m, A(p) >= 0 at p = rls.pole_min, the chord a2 + (1+p)/2 a1 <= -p - m),
 *       B's zero -b2/b1 in [min(rls.zero_min, the nominal zero), 0.999],
 *       b1 and the static gain B(1)/A(1) within [sup.gain_min, sup.gain_max] times the nominal's
 *           (the supervision's range of a working loop's response gain);
 *   the law never uses an estimate outside it;
 * - the fallback to the nominal model (estimates and covariance p0_loop I, the law from the
 *   same sample): at a jump of the reference beyond monitor.pred_error_max and beyond
 *   PIEZO_FALLBACK_JUMP_RATIO times the largest change per sample the estimates learned on
 *   (a step after a tone: an excitation they never saw), and when the adapted model's
 *   squared a-priori errors exceed rls.fallback_ratio times the nominal model's over
 *   rls.fallback_window (exponential window), beyond the measured noise, and at one a-priori
 *   error beyond monitor.pred_error_max and 5 times the errors' measured noise (a loop that rings).
 */
#ifndef PIEZO_CONTROLLER_H
#define PIEZO_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>
#include "piezo_status.h"
#include "piezo_hysteresis.h"
#include "piezo_tf.h"
#include "piezo_creep.h"
#include "piezo_supervisor.h"

#define PIEZO_MV_MAX_EXTRA_DELAY 8   /* PIEZO_MV_MAX_D - 1 (PIEZO_MV_MAX_D: piezo_supervisor.h) */
#define PIEZO_MV_Q_RING 10        /* PIEZO_MV_MAX_D + 1 */
#define PIEZO_SAT_DEFAULT_V 150   /* default voltage limits +-150 V */
#define PIEZO_MONITOR_DEFAULT_SAMPLES 200   /* default divergence window [samples] */
#define PIEZO_MONITOR_SHARE_PERCENT 25      /* ... or this share of its samples beyond the bound */
#define PIEZO_MONITOR_SHARE_MIN_SAMPLES 32  /* (judged from this sample on) */
#define PIEZO_MONITOR_NOISE 8               /* the bound is at least this many times y_meas's measured noise */
#define PIEZO_MONITOR_NOISE_CAP 2           /* ... up to this many times monitor.pred_error_max */
#define PIEZO_MV_AUTO_DELAY -1   /* mv_delay: detect the loop delay */
#define PIEZO_DETECT_N 3         /* candidates d = 1, 2, 3 */
#define PIEZO_DETECT_THETA 12    /* PIEZO_DETECT_N * 4 */
#define PIEZO_DETECT_P 48        /* PIEZO_DETECT_N * 16 */
#define PIEZO_DETECT_START_D 2   /* the start-up law's d */
#define PIEZO_DETECT_CONFIRM 3   /* samples a clear leader must lead before it is chosen */
#define PIEZO_DETECT_CONFIRM_BURIED 40 /* the same while the probes are buried in the noise (20 ms) */
#define PIEZO_DETECT_RATIO_INV 10 /* clear: sum at most 1/10 of every other candidate's */
#define PIEZO_DETECT_REDETECT 10 /* samples beyond the monitor bound that restart detection */
#define PIEZO_DETECT_TRIAL 20    /* samples of one detection trial (the next one starts with a probe) */
#define PIEZO_DETECT_PROBES 8    /* probes per detection at most (then trials without probes) */
#define PIEZO_DETECT_HELD 200   /* a chosen d that holds this long ends the search for one */
#define PIEZO_PREVIEW_RING 16    /* stamped previews kept: leads 1..15 samples */
/* Outliers (docs/model.md, controller): a sample whose a-priori prediction error is beyond
 * PIEZO_OUTLIER_RATIO times the recent rms error and beyond PIEZO_OUTLIER_FLOOR_PERCENT % of
 * monitor.pred_error_max, after PIEZO_OUTLIER_QUIET samples within them, while outliers were fewer than
 * PIEZO_OUTLIER_MAX_PERCENT % of the last PIEZO_OUTLIER_WINDOW samples: the model's prediction
 * stands in for y_meas (law, adaptation, monitor, supervision) in that sample. */
#define PIEZO_OUTLIER_RATIO 10
#define PIEZO_OUTLIER_FLOOR_PERCENT 100
#define PIEZO_OUTLIER_MAX_PERCENT 5
#define PIEZO_OUTLIER_WINDOW 200
#define PIEZO_OUTLIER_MIN_SAMPLES 20
#define PIEZO_OUTLIER_QUIET 10   /* samples within the bound, no outlier among them, before one */
/* The admissible set (rls.zero_min, rls.pole_min, sup.gain_min .. sup.gain_max): its rows c^T theta <= d */
#define PIEZO_ADMISSIBLE_ROWS 9
/* The fallback to the nominal model (docs/model.md): its reasons (est.fallback_reason) */
#define PIEZO_FALLBACK_NONE 0
#define PIEZO_FALLBACK_JUMP 1       /* a jump of the reference the estimates never learned on */
#define PIEZO_FALLBACK_PREDICTION 2 /* the adapted model predicted worse than the nominal one */
#define PIEZO_FALLBACK_RINGING 3    /* one a-priori error beyond monitor.pred_error_max: a loop that rings */
#define PIEZO_FALLBACK_JUMP_RATIO 5 /* a jump beyond this many times the largest learned change */
#define PIEZO_FALLBACK_RINGING_NOISE 5 /* one error beyond this many times the errors' measured noise */
#define PIEZO_FALLBACK_JUMP_MEMORY 2000 /* adapted samples over which a learned change fades (1/e) */

typedef struct {
    piezo_pi_params pi;          /* nominal hysteresis model */
    double tf_a1, tf_a2, tf_b1, tf_b2;  /* nominal G (eq 21) */
    double creep_k_c;            /* > 0 */
    double creep_alpha;          /* [-1, 1] */
    int creep_exact;             /* 1: full-memory inverse creep */
    double h;                    /* [s], > 0 */
    int mv_delay;                /* loop delay beyond one sample, 0..8: d = 1 + mv_delay;
                                    -1 (PIEZO_MV_AUTO_DELAY): d detected in 1..3 */
    int mv_feedthrough;          /* 1: v(k) from the inputs of sample k (direct feedthrough) */
    int mv_hold_inputs;          /* FMU: 1 lets a doStep of n > 1 samples hold the inputs
                                    over them (validated here, used by the FMU) */
    double mv_lambda_u;          /* control weighting, >= 0 */
    double mv_observer;          /* t of the observer polynomial T = 1 - t z^-1, [0, 1) */
    int rls_enabled;
    double rls_forgetting;       /* (0, 1] */
    double rls_p0;               /* initial covariance P = p0 I, > 0 */
    double rls_trace_max;        /* bound on trace(P), >= 4 p0 */
    int rls_robust;              /* 1: the robust update (above); 0: the paper's, every sample */
    double rls_excitation;       /* robust: a reference change counts beyond this many times the
                                    measured noise of y_meas, >= 0 */
    double rls_excitation_time;  /* robust: [s] the RLS updates for this long after one, >= 0 */
    double rls_variance_max;     /* robust: trace(P) sigma_e^2 <= this, > 0 */
    double rls_p0_loop;          /* robust: P = rls_p0_loop I when the loop's d is chosen, > 0 */
    double mv_integral;          /* integral action gain gamma, [0, 1) (0: none, the paper's law) */
    int sat_enabled;
    double sat_v_min, sat_v_max; /* [V], v_min < v_max when enabled */
    double monitor_pred_error_max;   /* [um], > 0: bound on |pred_error| */
    int monitor_divergence_samples;  /* consecutive samples beyond the bound that mean the loop
                                        is unstable (PIEZO_ERR_UNSTABLE), or the window over which
                                        PIEZO_MONITOR_SHARE_PERCENT % beyond it do; 0 = never */
    piezo_supervisor_params sup;     /* supervision (piezo_supervisor.h): sup.* */
    double mv_probe_max;         /* [um] >= 0: largest delay probe on q (0: no probes) */
    double rls_zero_min;         /* robust: lowest zero of B, [-0.999, 0.999] (the nominal zero
                                    -tf.b2/tf.b1 when that is lower) */
    double rls_pole_min;         /* robust: poles in the hull of real poles in [pole_min, 1), [-1, 1);
                                    the nominal poles must be in it */
    double rls_fallback_ratio;   /* robust: fallback when the adapted model's squared errors exceed
                                    this many times the nominal's, >= 0 (0: never) */
    double rls_fallback_window;  /* robust: [s] the window of that comparison, (0, 3600], at least a
                                    sample */
} piezo_controller_params;

/* A sample's outputs. A new member is set in loop_eval and safe_sample and copied in
 * copy_output (piezo_controller.c): the commit copies them member by member, so that the
 * padding of the controller's copy stays zero (FMU states are hashed bytewise). */
typedef struct {
    double v;                    /* control voltage v(k) [V] */
    double q;                    /* virtual input q(k) [um] (after saturation back-calculation) */
    double theta[4];             /* estimates a1, a2, b1, b2 used for q(k) */
    double pred_error;           /* RLS one-step prediction error at k [um] */
    int saturated;               /* 1 if v(k) was clipped */
    int delay;                   /* loop delay d of the law; 0 while it is being detected */
    int preview;                 /* 1 if the law used a stamped preview, 0 if y_ref */
    int adapting;                /* 1 if the estimates were updated at k */
    double noise;                /* measured noise of y_meas after k [um] (robust update; 0 otherwise) */
    int fallback;                /* why the law fell back to the nominal model at k (PIEZO_FALLBACK_*) */
} piezo_controller_output;

/* The inputs of one sample. */
typedef struct {
    double y_ref;                /* y_d(k + d) [um], used when no stamped preview covers k + d */
    double y_meas;               /* measured displacement [um] */
    double y_preview;            /* y_d at the measurement's sample + preview_lead [um] */
    int preview_lead;            /* 1..PIEZO_PREVIEW_RING-1; 0: no stamped preview this sample */
} piezo_controller_input;

typedef struct {
    piezo_pi fwd_pi;             /* nominal forward PI: tracks the plant's hysteresis state */
    piezo_pi_inverse inv_pi;
    piezo_gl inv_creep;          /* order -alpha, gain h^alpha / k_c */
    int d;                       /* loop delay of the law (PIEZO_DETECT_START_D while detecting) */
    double lambda_u;
    double observer;             /* t of T after detection (mv_observer) */
    int auto_delay;              /* 1: d is detected */
    int detecting;               /* 1 until d is chosen: the start-up law runs */
    uint64_t k_delay;            /* sample at which d took its current value */
    uint64_t k_search;           /* sample since which no chosen d held for PIEZO_DETECT_HELD samples */
    uint64_t det_clock;          /* samples since k_search the watchdog (sup.detect_time) counted:
                                    all of them, but those whose noise asked for a probe beyond
                                    mv.probe_max (the detection waits for the reference then) */
    uint64_t n_detections;       /* detections started (1 at reset in auto mode, +1 per restart) */
    int det_leader;              /* candidate leading clearly (index, d - 1), -1: none */
    int det_run;                 /* consecutive samples it has led */
    uint64_t det_trial;          /* sample at which the current trial started */
    double det_probe;            /* the trial's probe amplitude [um] on q (0: none) */
    int det_probes;              /* probes started in this detection */
    double det_score[PIEZO_DETECT_N];        /* sums of squared a-priori errors in the trial */
    double det_theta[PIEZO_DETECT_THETA];    /* each candidate's estimates, 4 per candidate */
    double det_P[PIEZO_DETECT_P];            /* each candidate's covariance, 16 per candidate */
    double r_prev;               /* reference r(k-1) of the law */
    double preview_value[PIEZO_PREVIEW_RING];/* stamped previews by sample (index modulo the ring) */
    uint64_t preview_tag[PIEZO_PREVIEW_RING];/* 1 + the sample each value is for; 0: empty */
    int rls_enabled;
    double forgetting, p0, trace_max;
    double inv_forgetting;       /* 1 / forgetting, set at init (the RLS multiplies by it) */
    int robust;                  /* rls.robust */
    double excitation;           /* rls.excitation */
    uint64_t excitation_samples; /* rls.excitation_time / h, rounded */
    double variance_max;         /* rls.variance_max */
    double p0_loop;              /* rls.p0_loop */
    double integral_gain;        /* mv.integral */
    /* robust adaptation and integral action: the states of k (reset to 0) */
    double noise_y;              /* measured noise of y_meas [um] (0: not yet measured) */
    double noise_y2;             /* the same from its second differences, while the reference does not
                                    excite (a move's removed) [um] */
    double noise_e;              /* measured noise of the prediction error [um] (0: not yet) */
    double r_anchor;             /* the reference extrapolated from the last excitation to k-1 */
    uint64_t excite_left;        /* samples the RLS still updates (0: it holds its estimates) */
    uint64_t jump_left;          /* samples no reading is taken for an outlier after a jump of r */
    double offset;               /* the estimator's offset c [um] */
    double integral;             /* z(k-1) of the integral action [um] */
    double r_last;               /* the law's reference without z at k-1 (the excitation's) */
    double r_last2;              /* ... at k-2 */
    double r_velocity;           /* the reference's change per sample at the last excitation */
    double yd_value[PIEZO_MV_Q_RING];    /* y_d by sample: the law's reference without z, r(j) = */
    uint64_t yd_tag[PIEZO_MV_Q_RING];    /* y_d(j + d), kept at slot (j + d) mod ring with tag j + d + 1 */
    int sat_enabled;
    double sat_v_min, sat_v_max;
    double theta_nominal[4];
    double theta[4];             /* a1, a2, b1, b2 */
    double P[16];                /* RLS covariance, row-major 4x4 */
    double y_prev[2];            /* y(k-1), y(k-2) */
    double q_ring[PIEZO_MV_Q_RING];  /* q(k-1)..q(k-10), q_ring[head] newest */
    int head;
    int sat_hold;                /* samples until a clipped q leaves the regressor (no RLS meanwhile) */
    double pred_error_max;
    uint64_t divergence_samples;
    /* monitor counts since reset (see piezo_controller_diverged) */
    uint64_t n_saturated;        /* samples whose v was clipped */
    uint64_t n_large_error;      /* samples with |pred_error| > pred_error_max */
    uint64_t run_saturated;      /* consecutive clipped samples up to the last one */
    uint64_t run_large_error;    /* consecutive samples beyond the bound up to the last one */
    uint64_t k_first_saturated;  /* first clipped sample (valid when n_saturated > 0) */
    uint64_t k_first_large_error;/* first sample beyond the bound (valid when n_large_error > 0) */
    uint64_t n_large_settled;    /* those outside the answer to a jump of the reference (jump_left) */
    uint64_t k_first_large_settled;  /* the first of them (valid when n_large_settled > 0) */
    double max_abs_pred_error;   /* largest |pred_error| so far [um] */
    double mon_forgetting;       /* 1 - 1/monitor.divergence_samples (0 when the monitor is off) */
    double mon_share, mon_weight;/* sums of lambda^(k-j) [beyond the bound] and of lambda^(k-j) */
    uint64_t k;
    piezo_controller_output out; /* result of the last committed sample */
    piezo_supervisor sup;        /* supervision of the loop (piezo_supervisor.h) */
    piezo_sup_verdict verdict;   /* why the last sample was refused with PIEZO_ERR_FAULT: the one
                                    field a refused step writes (fault 0 when none was); in the
                                    safe state, the supervision's verdict that put it there */
    double probe_max;            /* mv.probe_max [um] */
    double det_noise;            /* rms a-priori error of the best candidate in the last trial that
                                    chose nothing (the noise the next probe was sized for) [um] */
    /* outliers: samples whose measurement the model's prediction replaced */
    double err_sum, err_weight;  /* sums of lambda^(k-j) e(j)^2 and lambda^(k-j) over accepted samples */
    double outlier_sum;          /* sum of lambda^(k-j) [j was an outlier] */
    uint64_t quiet;              /* consecutive samples neither outliers nor beyond the monitor's bound */
    int suspect;                 /* the last sample was taken for an outlier, not yet confirmed */
    int stale;                   /* the last sample's reading was stale: the next is while it holds */
    double suspect_y, suspect_error;    /* its y_meas and a-priori error [um] */
    uint64_t n_outliers;         /* outliers confirmed since reset (the sample after one within the bound) */
    uint64_t k_first_outlier;    /* the first (valid when n_outliers > 0) */
    double first_outlier;        /* its y_meas [um] */
    double first_outlier_error;  /* its a-priori prediction error [um] */
    /* the safe state (sup.reaction = safe): a verdict holds the loop, v ramps to 0 V */
    int fault;                   /* 0: running; else the fault code (piezo_sup_fault) */
    uint64_t k_fault;            /* the sample whose verdict it was (the loop's state is of then) */
    double v_fault;              /* v when it came (the ramp's start) [V] */
    double y_fault;              /* y_meas of the verdict's sample [um] */
    int y_moved;                 /* y_meas has read another value since (sup.reset's test of a stuck sensor) */
    /* sup.reset (piezo_controller_restart): the loop restarted from the safe state */
    uint64_t k_start;            /* the sample the loop (re)started at: 0, or the last accepted reset's */
    uint64_t k_ramp_end;         /* the law's reference ramps from y_start to y_d until this sample (0: none) */
    double y_start;              /* y_meas where the stage rested at the restart [um] */
    uint64_t n_resets;           /* resets accepted */
    /* estimates with guarantees (robust update): the admissible set, computed at init from the
     * nominal model and rls.zero_min, rls.pole_min, sup.gain_min (gain_lo), sup.gain_max (gain_hi), as
     * rows adm_c^T theta <= adm_d */
    double zero_min, pole_min, gain_lo, gain_hi;
    double adm_c[PIEZO_ADMISSIBLE_ROWS][4];
    double adm_d[PIEZO_ADMISSIBLE_ROWS];
    uint64_t n_projections;      /* updates the admissible set changed */
    /* the fallback to the nominal model */
    double fallback_ratio;       /* rls.fallback_ratio (0: the prediction test is off) */
    uint64_t fallback_samples;   /* rls.fallback_window / h, rounded (>= 1) */
    double fallback_forgetting;  /* 1 - 1 / fallback_samples */
    double fb_adapted, fb_nominal;   /* the window's sums of squared a-priori errors */
    double learned_rate;         /* the largest |r(k) - r(k-1)| the estimates learned on, fading */
    uint64_t n_fallbacks;        /* fallbacks since reset (est.fallbacks) */
    uint64_t k_first_fallback;   /* the first one's sample (valid when n_fallbacks > 0) */
    int first_fallback;          /* its reason (PIEZO_FALLBACK_*) */
    double first_fallback_value; /* its fallback_value and fallback_other (piezo_controller_sample) */
    double first_fallback_other;
} piezo_controller;

/*
 * One evaluated sample, for a caller that computes a sample before it decides
 * to commit it - e.g. an FMU whose outputs depend directly on its inputs: the
 * outputs read at a communication point are the very sample its doStep then
 * commits, computed once. Filled by piezo_controller_evaluate, consumed by
 * piezo_controller_commit. k, y_ref, y_meas and out say which sample it is
 * and what it gives; the other fields are the evaluation's next states.
 */
typedef struct {
    uint64_t k;                  /* the sample evaluated (ctrl->k at the evaluation) */
    double y_ref, y_meas;        /* its inputs */
    double y_preview;
    int preview_lead;
    int reaches_window;          /* committing it would complete the divergence window */
    piezo_controller_output out; /* its outputs */
    double theta[4], P[16];      /* RLS result (valid when rls_updated) */
    int rls_updated;
    /* The doubles of k+1 that a finite sample can overflow, one block from noise_y to learned_rate
     * (PIEZO_SAMPLE_CHECKED doubles; sample_state_finite checks them in a loop): robust adaptation
     * and integral action, the law's reference, the outlier test's sum, the fallback's sums */
    double noise_y, noise_y2, noise_e, r_anchor, offset, integral, r_velocity;
    double r_plain;              /* the reference of the law without z */
    double err_sum;              /* the outlier test's sum of squared errors of k+1 */
    double fb_adapted, fb_nominal, learned_rate;    /* the fallback's states of k+1 */
    uint64_t excite_left;
    uint64_t jump_left;
    int excited;                 /* the reference excites the loop at k */
    double inv_z[PIEZO_PI_MAX_OPERATORS];    /* inverse PI play states of k+1 */
    double fwd_z[PIEZO_PI_MAX_OPERATORS];    /* forward PI play states of k+1 */
    int sat_hold;
    int large_error;             /* |pred_error| > monitor_pred_error_max */
    uint64_t run_large_error;
    double mon_share, mon_weight;/* the monitor's sums of k+1 */
    double r;                    /* the reference the law used */
    /* delay detection: the states of k+1 */
    int d, detecting, det_leader, det_run, restarted, new_trial;
    int live;                    /* the detection can learn from this sample */
    int clock;                   /* the watchdog counts this sample (det_clock) */
    uint64_t k_delay;
    double probe;                /* probe added to q this sample [um] */
    double next_probe;           /* probe amplitude of the trial starting at k+1 (new_trial) */
    double det_score[PIEZO_DETECT_N];
    double det_theta[PIEZO_DETECT_THETA];
    double det_P[PIEZO_DETECT_P];
    /* supervision: what it was given and what it found */
    piezo_supervisor_input sup_in;
    piezo_supervisor_next sup;
    double next_noise;           /* det_noise of k+1 (new_trial) */
    int outlier;                 /* y_meas was replaced by the model's prediction */
    int held;                    /* y_meas has not changed for PIEZO_SUP_STUCK_SAME samples: the offset
                                    holds */
    int stale;                   /* held, and a live reading would have changed by now (robust update, loop
                                    chosen): the model's prediction stands in, the integral holds */
    double raw_error;            /* the a-priori error of y_meas as received [um] */
    double err_weight, outlier_sum;    /* the outlier test's weights of k+1 (with err_sum) */
    int fault;                   /* the safe state's fault code after this sample (0: none) */
    /* estimates with guarantees: the states of k+1 */
    int projected;               /* the update was projected into the admissible set */
    double fallback_value;       /* a fallback's jump [um], the adapted model's rms a-priori error, or |e_a| */
    double fallback_other;       /* ... and the largest change learned [um], or the nominal model's */
} piezo_controller_sample;

/* doubles in the sample's checked block, noise_y .. learned_rate (a static assertion in
 * piezo_controller.c holds the block to it: a field added inside it must be counted here) */
#define PIEZO_SAMPLE_CHECKED 12

/* Defaults of docs/fmus.md (nominal plant model). */
void piezo_controller_default_params(piezo_controller_params *params);
piezo_status piezo_controller_init(piezo_controller *ctrl, const piezo_controller_params *params,
                                   piezo_diag *diag);
void piezo_controller_reset(piezo_controller *ctrl);
/*
 * Compute the control of sample k from y_ref = y_d(k+d) and y_meas(k) and
 * commit it (RLS update, operator states, monitor, k -> k+1). Returns
 * PIEZO_ERR_UNSTABLE, committing nothing, when this sample would make the
 * run of samples with |pred_error| > monitor_pred_error_max reach
 * monitor_divergence_samples, or their exponentially weighted count over a window of
 * that length reach PIEZO_MONITOR_SHARE_PERCENT % of the window, from sample
 * PIEZO_MONITOR_SHARE_MIN_SAMPLES on (a loop that keeps restarting its
 * delay detection, or oscillates); while adaptation pauses on a clipped sample,
 * the larger of |pred_error| and the nominal model's prediction error counts.
 * Returns PIEZO_ERR_FAULT, committing nothing of the loop, when the supervisor
 * finds that the loop cannot work; ctrl->verdict then says why
 * (piezo_supervisor_explain). With sup.reaction = PIEZO_SUP_REACT_SAFE none of these
 * three verdicts (supervision, monitor, a value not finite) refuses the sample: it is
 * the first of the safe state (ctrl->fault its code, ctrl->k_fault its sample), whose
 * samples return PIEZO_OK with v ramping to 0 V over sup.ramp_time and nothing else of
 * the loop evaluated or committed. Exact mode writes
 * history[2k], history[2k+1] (capacity >= piezo_controller_history_needed). Non-finite inputs refused, state unchanged.
 */
piezo_status piezo_controller_step(piezo_controller *ctrl, double y_ref, double y_meas,
                                   double *history, size_t history_capacity,
                                   piezo_controller_output *out);
/* piezo_controller_step with every input of the sample, the stamped preview included. */
piezo_status piezo_controller_step_input(piezo_controller *ctrl, const piezo_controller_input *in,
                                         double *history, size_t history_capacity,
                                         piezo_controller_output *out);
/* Same result as piezo_controller_step without committing anything
 * (exact mode may write the unused slots history[2k], history[2k+1]); the
 * divergence window and the supervisor's verdict are not applied (the step
 * that commits the sample does). */
piezo_status piezo_controller_peek(const piezo_controller *ctrl, double y_ref, double y_meas,
                                   double *history, size_t history_capacity,
                                   piezo_controller_output *out);
/*
 * The two halves of piezo_controller_step: evaluate sample k into *sample
 * (nothing committed; the checks, refusals and history writes of a peek,
 * which it equals), then commit it: PIEZO_ERR_PARAM (nothing done) unless
 * sample->k == ctrl->k, PIEZO_ERR_UNSTABLE (nothing done) when it completes
 * the divergence window, PIEZO_ERR_FAULT (only ctrl->verdict written) when the
 * supervisor's verdict on it is a fault. Commit only the latest evaluation of the sample, with
 * the state it was evaluated on (exact mode: history[2k..2k+1] are its own).
 */
piezo_status piezo_controller_evaluate(const piezo_controller *ctrl, const piezo_controller_input *in,
                                       double *history, size_t history_capacity,
                                       piezo_controller_sample *sample);
piezo_status piezo_controller_commit(piezo_controller *ctrl, const piezo_controller_sample *sample,
                                     piezo_controller_output *out);
size_t piezo_controller_history_needed(const piezo_controller *ctrl);
/* 1 with *value = y_d(sample) when the ring of stamped previews holds that sample's, else 0. */
int piezo_controller_preview(const piezo_controller *ctrl, uint64_t sample, double *value);
/*
 * Why the controller refused a sample with status st, in its own words, into
 * text (NUL-terminated, at most size bytes; the core still does no I/O):
 * PIEZO_ERR_FAULT "supervision stopped the loop (<verdict>): ..." (the
 * supervisor's explanation of ctrl->verdict), PIEZO_ERR_UNSTABLE "the closed
 * loop is unstable: ..." with the monitor's counts and the supervisor's
 * evidence, PIEZO_ERR_DIVERGED "the closed loop diverged: ...". Returns the
 * length it wanted, 0 for another status (nothing written).
 */
int piezo_controller_explain(const piezo_controller *ctrl, int st, char *text, size_t size);
/* piezo_controller_explain in the words of where the loop is (piezo_sup_context: the times
 * t0 + k h, a wired loop's connections or one FMU's parameters). */
int piezo_controller_explain_in(const piezo_controller *ctrl, int st, const piezo_sup_context *context,
                                char *text, size_t size);
/* The safe state's message (sup.reaction = safe, ctrl->fault != 0): "sup.reaction = safe: from
 * t = ... the loop is held in its safe state (sup.fault = N): ... Why: " and the verdict's
 * explanation in the words of piezo_controller_explain_in. 0 when not in the safe state. */
int piezo_controller_explain_safe_state(const piezo_controller *ctrl, const piezo_sup_context *context,
                                        char *text, size_t size);
/* The status a sample would have been refused with, had sup.reaction been error, for the
 * fault code of the safe state (PIEZO_ERR_FAULT, _UNSTABLE, _DIVERGED; PIEZO_OK for 0). */
piezo_status piezo_controller_fault_status(int fault);
/*
 * Invariants of a restored controller (e.g. from a deserialized FMU state):
 * NULL when every index, count and flag is in range, the sample counters agree,
 * the monitor counts fit the sample count and every value is finite, else a
 * static text naming the first bad field. The exact-mode history is checked by
 * piezo_gl_check_history(&ctrl->inv_creep, ...).
 */
const char *piezo_controller_check(const piezo_controller *ctrl);
/* The divergence monitor's bound on |pred_error| now: monitor.pred_error_max, or PIEZO_MONITOR_NOISE
 * times the measured noise of y_meas when that is larger [um]. */
double piezo_controller_monitor_bound(const piezo_controller *ctrl);
/* The monitor's bound now in words, into text (snprintf's contract: the length it needed): "monitor.pred_error_max
 * = 1 um", or the bound it was raised to for y_meas's noise (to that noise's multiple, or to the cap). */
int piezo_controller_explain_bound(const piezo_controller *ctrl, char *text, size_t size);
/* 1: the delay probes are buried in the noise (the probe the measured noise of y_meas asks for is
 * beyond mv.probe_max): the detection waits, chooses nothing, and its watchdog stops. */
int piezo_controller_probes_buried(const piezo_controller *ctrl);
/* The response a delay probe needs, in times the measured noise (PROBE_SNR). */
double piezo_controller_probe_snr(void);
/* NULL when a controller runs on `params` (valid, and the copies piezo_controller_init keeps
 * of them equal them), else a static text saying which does not hold. */
const char *piezo_controller_check_params(const piezo_controller *ctrl, const piezo_controller_params *params);

/*
 * sup.reset, a drive's fault reset (docs/robustness.md, "Leaving the safe state"): why a reset
 * raised now, with the inputs of the sample it would restart at, is refused (PIEZO_RESET_*), or
 * PIEZO_RESET_ACCEPTED. Only the causes the safe state can see are judged: inputs not finite, v
 * still ramping to 0 V, a y_meas that has not left the verdict's reading (a frozen or silent
 * sensor), a reference still beyond what the stage reached at the rail. A fault of the
 * response (inverted, gain, delay, unstable) shows only in a moving loop: the restarted
 * supervision judges it again, as at the start.
 */
typedef enum {
    PIEZO_RESET_ACCEPTED = 0,
    PIEZO_RESET_NO_FAULT = 1,    /* not in the safe state: nothing to reset */
    PIEZO_RESET_RAMPING = 2,     /* v has not reached 0 V yet (sup.ramp_time) */
    PIEZO_RESET_INPUTS = 3,      /* y_ref or y_meas not finite */
    PIEZO_RESET_STUCK = 4,       /* y_meas still reads what it read at the verdict, to the bit */
    PIEZO_RESET_OUT_OF_REACH = 5 /* the reference is still beyond the reading at the rail */
} piezo_reset_refusal;
int piezo_controller_reset_refusal(const piezo_controller *ctrl, const piezo_controller_input *in);
/*
 * Leave the safe state (sup.reset accepted): the loop restarts at sample ctrl->k from its nominal
 * model, with its parameters, as a fresh controller would (estimates, covariance, delay
 * detection, supervision, integral action), but from where the stage rests: y_meas(k) as its past
 * readings, the hysteresis model's operators after v = 0 V, and the law's reference ramping from
 * there to y_d over sup.ramp_time, so that v ramps from 0 V. The counts of the run (clipping, outliers, fallbacks,
 * detections) go on. PIEZO_ERR_PARAM when ctrl is not in the safe state or y_meas is not finite.
 */
piezo_status piezo_controller_restart(piezo_controller *ctrl, double y_meas);
/* Why a reset raised at sample k with inputs in was refused (refusal from
 * piezo_controller_reset_refusal), or that it was accepted (ctrl restarted since), in words, into
 * text (at most size bytes); the length it wanted. */
int piezo_controller_explain_reset(const piezo_controller *ctrl, int refusal, const piezo_controller_input *in,
                                   uint64_t k, const piezo_sup_context *context, char *text, size_t size);

/* Diophantine 1 = A E + z^-d Gd for A = 1 + a1 z^-1 + a2 z^-2, 1 <= d <= 9:
 * e[0..d-1] (e[0] = 1), g[0..1]. */
piezo_status piezo_diophantine(double a1, double a2, int d, double *e, double *g);
/* The same with the observer polynomial: T = A E + z^-d Gd, T = 1 - t z^-1. */
piezo_status piezo_diophantine_observer(double a1, double a2, double t, int d, double *e, double *g);

#endif
