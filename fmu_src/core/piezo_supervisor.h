/*
 * piezo_supervisor.h - supervision of the closed loop (docs/model.md, supervision):
 * does the measurement answer the controller's output as the controller's model
 * says it should? The controller is the only block that sees both what it
 * commands (q, v) and what comes back (y_meas), so this block, fed by it once a
 * sample, tells a loop that cannot work (a measurement that does not answer,
 * answers with the wrong sign, far off the model's gain or later than the
 * controller handles; v held at a limit; a loop delay never found) from one
 * that works, and says why.
 *
 * Response test. With the controller's model A(z^-1) y = z^-d B(z^-1) q, the
 * measurement filtered by A and the output filtered by B, both differenced
 * (which removes offsets and what a held signal adds),
 *     dz(k) = Delta[A y_meas](k),   dw(k) = Delta[B q](k - 1),
 * satisfy dz(k) = g dw(k - d + 1) + noise on a loop with delay d whose stage
 * has g times the model's gain. For every d = 1..PIEZO_MV_MAX_D the block
 * keeps exponentially weighted sums (forgetting lambda = 1 - 1/sup.window):
 *     Szz = sum lambda^(k-j) dz(j)^2,  Sww_d(k) = Sww_1(k - d + 1),
 *     Szw_d = sum lambda^(k-j) dz(j) dw(j - d + 1).
 * The least-squares gain of delay d is g_d = Szw_d / Sww_d, its unexplained
 * energy E_d = Szz - Szw_d^2 / Sww_d. The best delay b has the least E_d.
 * Evidence is strong when the response the fit explains (or, for a gain below
 * 1, the response the model expects) is PIEZO_SUP_EVIDENCE times what it leaves
 * unexplained: Sww_b max(1, g_b^2) >= PIEZO_SUP_EVIDENCE E_b (E_b at least the
 * energy a quantised reading hides: weight q^2/12 sum c_i^2, q the smallest step
 * y_meas made, c the coefficients of Delta A; a response below the grid is no
 * evidence of none), at least
 * PIEZO_SUP_MIN_SAMPLES samples were seen, and the model expected y_meas to
 * travel at least PIEZO_SUP_TRAVEL_PERCENT % of monitor.pred_error_max over the
 * window (the sum of its sample-to-sample moves). With strong evidence:
 *     g_b <= -gain_min               the measurement answers inverted
 *     |g_b| < gain_min                it does not answer (or far too little)
 *     g_b > gain_max                  it answers far more than the model
 *     b not a delay the law runs (1..3 detected, or 1 + mv.delay), and those
 *     leave PIEZO_SUP_DELAY_PERCENT % of the response unexplained: the loop
 *     delay is beyond the controller's
 * and otherwise the loop is verified (status 1). The response is judged every
 * PIEZO_SUP_JUDGE_EVERY samples, and every sample once a fault kind appears; a
 * fault kind held for PIEZO_SUP_CONFIRM consecutive samples is the verdict. Measured on 12,808
 * legitimate runs (docs/robustness.md) and on every fault of the fault table.
 *
 * A loop whose response no linear model explains (a far too high gain makes
 * it oscillate between the limits of the stage's hysteresis) gives no strong
 * evidence; the controller's divergence monitor stops it (a quarter of its
 * window's prediction errors above their bound), and the supervisor's travel
 * sums give its message the evidence.
 *
 * A gain that changes. The gain verified is followed: the mean of the strongly
 * evidenced gains of the judged samples that verified the loop, the n-th weighing
 * 1/n until 1/n reaches PIEZO_SUP_JUDGE_EVERY / sup.window, that weight from then on
 * (an exponentially weighted mean of about the last window). Once it holds
 * PIEZO_SUP_CONFIRM of them (the start-up's first gains averaged, not taken for
 * the loop's), a strongly evidenced gain below it by the factor
 * PIEZO_SUP_DROP_PERCENT / 100 or above it by PIEZO_SUP_RISE_PERCENT / 100 is a
 * fault kind (confirmed as the others): a sensor or an amplifier whose gain
 * changed during the run, which the adaptive law would follow, the stage then
 * tracking y_d scaled by the change. Evidence that one sample carries (its
 * dw^2 more than PIEZO_SUP_PEAK_PERCENT % of Sww_1, the largest term kept as
 * max(lambda M, dw^2): a stop, a start, a reversal, where a stage answers
 * through its own hysteresis' local slope, not the model's) is judged against
 * the lower of that gain and the mean of such judgements alone (the higher for
 * a rise), followed alike, and, while none of them was followed yet, by the
 * factor PIEZO_SUP_DROP_FIRST_PERCENT / 100 down.
 *
 * Watchdogs: v clipped for sup.clip_time without a pause while the mean
 * |y_d - y_meas| over that time exceeds sup.clip_error; a loop delay still not
 * chosen after sup.detect_time (counted over the samples whose probes are not buried
 * in the noise: piezo_controller_probes_buried).
 *
 * A measurement that stops answering (issue 44), four ways (all but the second are
 * y_meas frozen; the second "no response", since a quiet reading that does not change while
 * the model says the stage moved is a stuck y_meas or a v that does not reach the stage):
 * - held on an outlier: the reading jumped away from the model's prediction (the
 *   controller took it for an outlier, and its prediction stood in) and has held that
 *   value to the bit for PIEZO_SUP_STUCK_SAME samples: a sensor that died or stuck on a
 *   glitch, bridged by the model from its first sample;
 * - against the model: y_meas has not changed while the model says the stage moved, so
 *   far that sup.gain_min of the move is beyond two of the reading's steps, four times
 *   its measured noise and PIEZO_SUP_STUCK_MOVE_NM (since v last reversed; or
 *   PIEZO_SUP_STUCK_FAR_NM whatever v did), less PIEZO_SUP_STUCK_SPEED samples of the
 *   model's mean speed (its transient after a fast move) and less PIEZO_SUP_STUCK_CREEP_PERMILLE
 *   per mille of how far the model's yhat is from its mean over the last second (the creep
 *   and hysteresis the law holds the stage against after a move, which the model lacks);
 * - by its noise: y_meas exactly constant for m samples although, over the window
 *   before, it reversed its direction from one sample to the next in
 *   PIEZO_SUP_FROZEN_PERCENT % of the samples or more and stepped by more than
 *   PIEZO_SUP_BIG_STEP_PERCENT % of the smallest step it ever made in
 *   PIEZO_SUP_FROZEN_BIG_PERMILLE per mille of them while reversing (a sensor whose
 *   noise showed; a sensor at rest whose noise is below its resolution repeats its value
 *   legitimately and reverses seldom, and a noise-free quantised one that dithers by one
 *   step and settles never reverses by more than one: a move's big steps keep their
 *   direction), m at least PIEZO_SUP_STUCK_SAME and as many as the share p of equal
 *   samples before makes improbable, p^m <= e^-PIEZO_SUP_STUCK_LOG_ODDS (sup.window at
 *   most);
 * - against its declared noise (sup.sensor_noise = sigma > 0): y_meas exactly constant for m
 *   samples, m at least PIEZO_SUP_STUCK_SAME and p^m <= e^-PIEZO_SUP_STUCK_LOG_ODDS for
 *   p = erf(q / (2 sqrt(2) sigma)), q the smallest step y_meas ever made: the most a live
 *   reading quantize(y + n), n white N(0, sigma^2) on a grid of step q (or a multiple of it),
 *   repeats its value with, whatever the stage does. Whether the model says the stage moved or not:
 *   a faint sensor stuck in a hold, which the other three cannot tell from a noise-free loop at rest.
 * Meanwhile the controller holds its integral action and its estimator's offset on a
 * reading unchanged for PIEZO_SUP_STUCK_SAME samples: they never walk the stage on it.
 *
 * The evidence a message gives: over the window, the distance the model
 * expected y_meas to travel in answer to q (the sum of its sample-to-sample
 * moves), the distance y_meas travelled, and the gain and fit of the best
 * delay.
 *
 * Evaluate / commit: piezo_supervisor_evaluate computes a sample's statistics and
 * verdict into a piezo_supervisor_next (nothing changed), piezo_supervisor_commit
 * makes them the state, as the controller evaluates and commits its samples.
 */
#ifndef PIEZO_SUPERVISOR_H
#define PIEZO_SUPERVISOR_H

#include <stddef.h>
#include <stdint.h>
#include "piezo_status.h"

/* The longest loop delay, d = 1 + mv.delay <= 9 samples: the one home of the delays the MV
 * law runs (piezo_controller.h) and the supervisor tests (1..9). */
#define PIEZO_MV_MAX_D 9
#define PIEZO_SUP_REF_RING 10        /* references kept: r(k-1)..r(k-10) (>= PIEZO_MV_MAX_D) */
#define PIEZO_SUP_MIN_SAMPLES 20     /* no verdict before this many samples */
#define PIEZO_SUP_CONFIRM 10         /* consecutive samples of one fault kind make the verdict */
#define PIEZO_SUP_JUDGE_EVERY 4      /* the response is judged every 4th sample (every sample while
                                        a fault candidate runs) */
#define PIEZO_SUP_EVIDENCE 32        /* explained (or expected) / unexplained response energy */
#define PIEZO_SUP_DELAY_PERCENT 25   /* the law's delays leave this much of the response unexplained */
#define PIEZO_SUP_TRAVEL_PERCENT 5   /* evidence needs the model to expect y_meas to travel this share
                                        of monitor.pred_error_max over the window (a probe below a
                                        quantised sensor's step proves nothing) */
#define PIEZO_SUP_DEFAULT_WINDOW 200 /* sup.window [samples] */
#define PIEZO_SUP_DEFAULT_DETECTABLE 3   /* delays the controller detects: 1..3 */
#define PIEZO_SUP_DROP_PERCENT 130   /* the gain followed over the gain now: beyond it, the gain fell */
#define PIEZO_SUP_RISE_PERCENT 200   /* the gain now over the gain followed: beyond it, the gain rose */
#define PIEZO_SUP_PEAK_PERCENT 50    /* evidence carried by one sample: its change of B q is beyond this share
                                        of the window's Sww_1 (a stop, a start, a reversal) */
#define PIEZO_SUP_DROP_FIRST_PERCENT 175 /* DROP_PERCENT for such evidence while none of its kind was
                                        followed yet */
#define PIEZO_SUP_FROZEN_PERCENT 30  /* share of reversals of y_meas before a frozen stretch */
#define PIEZO_SUP_BIG_STEP_PERCENT 150   /* a step of y_meas beyond this share of its smallest is noise's */
#define PIEZO_SUP_FROZEN_BIG_PERMILLE 400 /* share of such steps before a frozen stretch [per mille] */
#define PIEZO_SUP_FROZEN_FLOOR 4     /* ... and what the model's best fit leaves of those changes beyond this many
                                        times the reading's quantisation floor (the noise-free sensor on the
                                        stage's day: 0.4 and 1.3 times where the loop chattered and then
                                        settled; 20 still names every 5 nm sensor stuck in a hold of the
                                        stuck family, 60 misses 14 of 100) */
#define PIEZO_SUP_STUCK_SAME 4       /* a frozen y_meas: at least this many equal samples (held on an outlier,
                                        or by its noise) */
#define PIEZO_SUP_STUCK_LOG_ODDS 28  /* ... and as many as its share of equal samples before makes a chance
                                        of e^-28 = 7e-13 */
#define PIEZO_SUP_STUCK_NOISE 4      /* a stuck y_meas against the model: beyond 2 steps and this many times
                                        the measured noise */
#define PIEZO_SUP_STUCK_MOVE_NM 50   /* ... and at least this move [nm] since v last reversed: the model's
                                        transient after a move differs from a stage's by tens of nm (at the
                                        end of a 5 um S-curve the model moved 17 nm while a noise-free
                                        reading stood still) */
#define PIEZO_SUP_STUCK_SPEED 2     /* ... beyond this many samples of the model's mean speed (its tail
                                        after the stop of a 50 Hz, 10 um scan: 207 nm) */
#define PIEZO_SUP_STUCK_CREEP_PERMILLE 40   /* ... and beyond this share [per mille] of the distance from
                                        the model's yhat to its mean over the last PIEZO_SUP_CREEP_SAMPLES:
                                        after a move the law pushes q on to hold the stage against its
                                        creep and hysteresis, which the model does not have (after 30 um
                                        down, 0.2-0.4 um of the model's move in 0.17 s while a noise-free
                                        reading stood still; 7 false stops in the stage's day's hours at
                                        0 nm, which need 1-2.5 %) */
#define PIEZO_SUP_CREEP_SAMPLES 2000 /* ... that mean's time constant [samples] (1 s) */
#define PIEZO_SUP_STUCK_FAR_NM 250   /* ... or at least this move [nm] whatever v did: right after a reversal
                                        a stage answers by its hysteresis' initial slope, far below the
                                        model's (the end of a 50 Hz scan: 207 nm by the model, none by the
                                        stage) */
#define PIEZO_SUP_NOISY_PERCENT 33   /* y_meas reversing in this share of the samples is noise-dominated
                                        (white noise at rest: 2/3; a moving stage: seldom) */
#define PIEZO_SUP_REACT_ERROR 0      /* sup.reaction: a verdict fails the step (the default) */
#define PIEZO_SUP_REACT_SAFE 1       /* sup.reaction: a verdict holds the loop in the safe state */

/* What the supervisor found (the verdict of a refused sample). */
typedef enum {
    PIEZO_SUP_NONE = 0,          /* nothing wrong */
    PIEZO_SUP_NO_RESPONSE = 1,   /* y_meas does not answer v (|gain| < sup.gain_min) */
    PIEZO_SUP_INVERTED = 2,      /* y_meas answers v inverted (gain <= -sup.gain_min) */
    PIEZO_SUP_GAIN_HIGH = 3,     /* y_meas answers v far more than the model (gain > sup.gain_max) */
    PIEZO_SUP_DELAY = 4,         /* y_meas answers v later than the law's delays */
    PIEZO_SUP_CLIPPED = 5,       /* v held at a limit for sup.clip_time, the error not small */
    PIEZO_SUP_UNDETECTED = 6,    /* no loop delay chosen within sup.detect_time */
    PIEZO_SUP_GAIN_CHANGED = 7,  /* the response gain changed from the one verified */
    PIEZO_SUP_FROZEN = 8,        /* y_meas frozen: constant for sup.window samples after noise */
    /* the controller's own verdicts (the codes of sup.fault, which also counts these) */
    PIEZO_SUP_UNSTABLE = 9,      /* the divergence monitor: |pred_error| beyond its bound too long */
    PIEZO_SUP_DIVERGED = 10      /* a value the controller computed is not finite */
} piezo_sup_fault;
#define PIEZO_SUP_FAULT_MAX 10       /* the largest fault code */

typedef struct {
    int enabled;                 /* 0: off (open-loop use): no statistics, no verdicts */
    double gain_min;             /* (0, 1): weakest response gain of a working loop */
    double gain_max;             /* (1, inf): strongest */
    int window;                  /* [20, 1e6] samples: time constant of the statistics */
    double clip_time;            /* [s] > 0: v clipped this long (error not small) is a fault */
    double detect_time;          /* [s] > 0: delay detection running this long is a fault */
    int reaction;                /* PIEZO_SUP_REACT_ERROR (0, default) or PIEZO_SUP_REACT_SAFE (1) */
    double ramp_time;            /* [s] >= 0: the safe state ramps v to 0 V over this time */
    double clip_error;           /* [um] > 0: the mean |y_d - y_meas| a clipped run must exceed */
    double sensor_noise;         /* [um] >= 0: the declared rms noise of y_meas (0: not declared) */
} piezo_supervisor_params;

/* Evidence of the verdict, for its message. */
typedef struct {
    int fault;                   /* piezo_sup_fault */
    uint64_t k;                  /* the sample refused */
    double gain;                 /* best delay's gain (response / model's) */
    double fit;                  /* its share of the measured change explained, [0, 1] */
    int delay;                   /* the best delay, samples */
    int loop_delay;              /* the law's delay then (0: detecting) */
    int auto_delay;              /* 1: the controller detects its delay */
    double ref_gain, ref_fit;    /* the same for y_ref as if it were the measurement (d = 1..3) */
    uint64_t window;             /* the window's samples: its weight sum_j lambda^j, rounded down
                                    (k + 1 at first, up to sup.window - 1) */
    double travel_model;         /* the distance the model expected y_meas to travel in it [um] */
    double travel_meas;          /* the distance y_meas travelled [um] */
    double y_meas;               /* y_meas of the refused sample [um] */
    double v;                    /* v of the sample before [V] */
    int y_constant;              /* 1: y_meas did not change at all in the window */
    double clip_v;               /* CLIPPED: the limit v was held at [V] */
    uint64_t clip_samples;       /* CLIPPED: samples held; UNDETECTED: samples detecting */
    uint64_t y_same;             /* samples y_meas had not changed */
    double error;                /* CLIPPED: mean |y_d - y_meas| over them [um] */
    double error_bound;          /* CLIPPED: the bound it exceeded, sup.clip_error [um] */
    double verified_gain;        /* the last verified gain (0: the loop was never verified) */
    double followed_gain;        /* GAIN_CHANGED: the gain followed until the change */
    double reversal_share;       /* FROZEN: share of samples y_meas reversed in before it froze */
    double step_rms;             /* FROZEN: rms of its sample-to-sample changes then [um] */
    double stuck_move;           /* FROZEN against the model: the stage's least move since [um] (0: by
                                    its noise) */
    double stuck_bound;          /* the move y_meas would have shown [um] */
    double repeat_share;         /* FROZEN by its noise: share of equal samples before */
    double declared_noise;       /* FROZEN against the declared noise: sup.sensor_noise [um] (0: not this case) */
    double repeat_chance;        /* ... the most a live reading of that noise repeats with, p */
    double grid_step;            /* ... the reading's smallest step, the grid p is taken on [um] */
    double bridged_error;        /* FROZEN on an outlier: how far the held value is from the model [um]
                                    (0: not this case) */
    double gain_min;             /* sup.gain_min */
    /* UNDETECTED, filled by the controller: the delay probes against the noise */
    double noise;                /* rms a-priori error of the best candidate in the last trial [um] */
    double probe;                /* the last probe's amplitude on q [um] (0: none yet) */
    double probe_wanted;         /* the amplitude the noise asked for [um] */
    double probe_max;            /* mv.probe_max [um] */
    double probe_gain;           /* the model's first response to a probe, tf.b1 */
    double probe_snr;            /* the response a probe needs, in times the noise */
    int probes;                  /* probes made in the detection */
} piezo_sup_verdict;

/* What a message says besides the verdict: where the loop is and when it started. */
typedef struct {
    double t0;                   /* the time of sample 0 [s]: a message's times are t0 + k h */
    double h;                    /* the sample period [s] */
    int internal;                /* 0: the controller wired to a stage by hand (the connections of
                                    AdaptiveCompoundController and PiezoStage are named); 1: the stage
                                    inside the same FMU (PiezoStageClosedLoop: its parameters are
                                    named, the stage's against the controller's model's) */
    int stage_delay;             /* internal: the stage's tf.delay [samples] */
    int feedthrough;             /* internal: mv.feedthrough */
} piezo_sup_context;

/* The controller's part of one sample, as the supervisor needs it. */
typedef struct {
    double y_meas;               /* y_meas(k) [um] */
    double y_ref;                /* the y_ref input of sample k [um] (the swap check) */
    double q1, q2;               /* q(k-1), q(k-2) [um] */
    double v1;                   /* v(k-1) [V] */
    int clipped1;                /* v(k-1) was clipped */
    uint64_t clip_run;           /* consecutive clipped samples up to k-1 */
    double clip_v;               /* the limit v(k-1) was clipped to */
    double error_bound;          /* monitor.pred_error_max [um] */
    int law_delay;               /* d of the law (the start-up law's while detecting) */
    int loop_delay;              /* d of the law, 0 while detecting */
    int auto_delay;              /* 1: the controller detects d */
    uint64_t detecting_for;      /* samples of the current detection (0: not detecting) */
    double noise;                /* the measured noise of y_meas [um] (0: not measured) */
    int bridged;                 /* y_meas(k) was taken for an outlier: the model's prediction stood in */
    double bridged_error;        /* then: y_meas(k) less that prediction [um] */
} piezo_supervisor_input;

typedef struct {
    /* configuration */
    int enabled;
    int open_loop;               /* set by the caller while the loop inputs were never connected (the
                                    FMU: y_meas and t_meas at their start values since the start):
                                    the statistics run, but no response verdict and no delay
                                    watchdog; v held at a limit is still stopped */
    double forgetting;           /* lambda = 1 - 1/window */
    double gain_min, gain_max;
    uint64_t clip_samples, detect_samples;
    uint64_t window;             /* sup.window [samples] */
    double clip_error;           /* sup.clip_error [um] */
    double sensor_noise;         /* sup.sensor_noise [um] (0: not declared) */
    int reaction;                /* sup.reaction */
    double ramp_time;            /* sup.ramp_time [s] */
    uint64_t ramp_samples;       /* samples the safe state ramps v over (0: at once) */
    double a1, a2, b1, b2;       /* the model the response is judged by */
    double h;
    /* statistics */
    uint64_t k;                  /* samples seen */
    double y1, y2;               /* y_meas(k-1), y_meas(k-2) */
    double r1, r2;               /* y_ref(k-1), y_ref(k-2) */
    double z1, zr1;              /* A y_meas and A y_ref at k-1 */
    double w1;                   /* B q at k-1: b1 q(k-2) + b2 q(k-3) */
    double dw[PIEZO_MV_MAX_D];   /* dw(k-1) .. dw(k-9): dw[i] = dw(k-1-i) */
    double sww[PIEZO_MV_MAX_D];  /* Sww_1(k-1) .. Sww_1(k-9), the same way */
    double szz, srr;             /* Szz, and the same for y_ref */
    double szw[PIEZO_MV_MAX_D];  /* Szw_d, d = 1..9 */
    double srw[PIEZO_SUP_DEFAULT_DETECTABLE];    /* y_ref against d = 1..3 */
    /* the model's prediction of y_meas from q (delay 1), for the messages */
    double yhat1, yhat2;         /* at k-1 and k-2 */
    /* verdict */
    int candidate;               /* fault kind of the last sample (0: none) */
    int candidate_run;           /* consecutive samples it held */
    int status;                  /* 0 not verified yet, 1 verified */
    double gain;                 /* the last strongly evidenced gain (0: none yet) */
    int delay;                   /* its delay (0: none yet) */
    uint64_t k_verified;         /* first sample verified (valid when status 1) */
    double verified_gain;        /* the gain then */
    double clip_error_sum;       /* sum of |y_d - y_meas| over the current clipping run */
    uint64_t y_same;             /* consecutive samples y_meas equalled the one before */
    double ref[PIEZO_SUP_REF_RING];   /* the law's references r(k-1) .. r(k-10), ring at ref_head */
    int ref_head;
    /* the evidence's sums, weighted as the statistics */
    double weight;               /* sum of lambda^(k-j): the window's weight */
    double travel_model;         /* sum of lambda^(k-j) |yhat(j) - yhat(j-1)| */
    double travel_meas;          /* sum of lambda^(k-j) |y_meas(j) - y_meas(j-1)| */
    /* a gain that changes, a measurement that freezes */
    double followed_gain;        /* the strongly evidenced gains followed since verified (0: none yet) */
    uint64_t followed_n;         /* judged samples it holds (the weights 1/n while they are larger) */
    double followed_peak;        /* the same, of the judged samples whose evidence one sample carried */
    uint64_t followed_peak_n;    /* judged samples it holds */
    double dw_peak;              /* the largest term of Sww_1 as it weighs now: max_j lambda^(k-j) dw(j)^2 */
    double reversals;            /* sum of lambda^(k-j) [y_meas reversed its direction at j] */
    double steps2;               /* sum of lambda^(k-j) (y_meas(j) - y_meas(j-1))^2 */
    double dy1;                  /* y_meas(k-1) - y_meas(k-2) (0 when equal: the last change kept) */
    double min_step;             /* the smallest nonzero |y_meas(j) - y_meas(j-1)| so far (0: none) */
    double big_steps;            /* sum of lambda^(k-j) [|step| > PIEZO_SUP_BIG_STEP_PERCENT % of min_step] */
    double repeats;              /* sum of lambda^(k-j) [y_meas(j) = y_meas(j-1)] */
    double yhat_frozen[3];       /* the model's yhat at the last sample y_meas changed, and at the one
                                    and two before it (the loop delays 1, 2, 3) */
    double yhat_turned[3];       /* the same at the last sample y_meas changed or v reversed */
    double yhat_slow;            /* the model's yhat averaged over PIEZO_SUP_CREEP_SAMPLES: where the
                                    stage has been, for the creep the stuck test allows */
    double v2;                   /* v(k-2) [V] */
    uint64_t bridged_run;        /* consecutive samples the model's prediction stood in for y_meas */
    int v_dir;                   /* the direction v last moved in: +1, -1 (0: not yet) */
} piezo_supervisor;

/* One evaluated sample: the statistics of k+1 and the verdict. */
typedef struct {
    double z, zr, w, dw, szz, srr, sww1, yhat;
    double szw[PIEZO_MV_MAX_D];
    double srw[PIEZO_SUP_DEFAULT_DETECTABLE];
    double weight, travel_model, travel_meas;
    double followed_gain, reversals, steps2, dy1, min_step, big_steps, repeats, followed_peak, dw_peak;
    double yhat_frozen[3], yhat_turned[3], yhat_slow;
    double stuck_move;           /* FROZEN against the model: the move since y_meas froze, by the model [um] */
    double clip_error_sum;       /* the last double: z .. clip_error_sum are the doubles checked finite */
    uint64_t y_same;
    uint64_t bridged_run;
    int v_dir;
    int candidate, candidate_run, status, delay;
    double gain;
    uint64_t followed_n, followed_peak_n;
    int fault;                   /* piezo_sup_fault: the verdict of this sample */
} piezo_supervisor_next;

void piezo_supervisor_default_params(piezo_supervisor_params *params);
/* Validate (names a bad parameter in diag) and set up with the model's A, B and h. */
piezo_status piezo_supervisor_init(piezo_supervisor *sup, const piezo_supervisor_params *params,
                                   double a1, double a2, double b1, double b2, double h,
                                   piezo_diag *diag);
void piezo_supervisor_reset(piezo_supervisor *sup);
/* Reset, for a loop that restarts from rest (sup.reset): the stage at y [um] with the model's
 * B q at w, its past readings, references and predictions those of a stage at rest there. */
void piezo_supervisor_restart(piezo_supervisor *sup, double y, double w);
/* The statistics and the verdict of sample k (sup->k) into *next; *sup unchanged.
 * Disabled (sup.enabled = false): nothing computed, next->fault 0 (the rest of
 * next is not set), no verdict. */
void piezo_supervisor_evaluate(const piezo_supervisor *sup, const piezo_supervisor_input *in,
                               piezo_supervisor_next *next);
/* Whether a reading unchanged since sample f may still be a live sensor's (sample k = sup->k, enabled,
 * the reading the same as at k-1; q1, q2 the past outputs q(k-1), q(k-2) as piezo_supervisor_input takes
 * them; d the loop's delay):
 *     gain_min |yhat(k - d + 1) - yhat(f - d + 1)| < q,
 * the model's move over the samples the readings answer (yhat(k) as piezo_supervisor_evaluate computes
 * it, the model of a loop of delay 1) times sup.gain_min (a working loop's weakest gain) below the
 * reading's smallest step q (0 before it ever stepped: not live); live for a d beyond 1..3.
 * The stuck test asks the same with its wider bound; the controller's law and integral action take such
 * a reading as it is, and the model's prediction in place of one that is not. */
int piezo_supervisor_may_be_live(const piezo_supervisor *sup, double q1, double q2, int d);
/* What a reading cannot tell apart from where it is: two of its smallest steps and PIEZO_SUP_STUCK_NOISE
 * times its measured noise [um] (the stuck test's floor; noise as piezo_supervisor_input.noise) */
double piezo_supervisor_reading_floor(const piezo_supervisor *sup, double noise);
/* Make the evaluated sample the state; r: the reference the law used at k. */
void piezo_supervisor_commit(piezo_supervisor *sup, const piezo_supervisor_input *in,
                             const piezo_supervisor_next *next, double r);
/* The evidence of a verdict reached by the evaluation of the sample of in (next->fault != 0). */
void piezo_supervisor_verdict(const piezo_supervisor *sup, const piezo_supervisor_input *in,
                              const piezo_supervisor_next *next, piezo_sup_verdict *verdict);
/* The message of a verdict: the signal at fault, the evidence, what to check, in the
 * words of where the loop is (context: the times t0 + k h, the connections of a wired
 * loop or the parameters of one FMU). Writes at most size bytes (NUL-terminated);
 * returns the length it wanted. */
int piezo_supervisor_explain_in(const piezo_sup_verdict *verdict, const piezo_sup_context *context,
                                char *text, size_t size);
/* piezo_supervisor_explain_in for a wired loop started at t0 = 0. */
int piezo_supervisor_explain(const piezo_sup_verdict *verdict, double h, char *text, size_t size);
/* The verdict's fault as a short name ("no response", "inverted", ...). */
const char *piezo_supervisor_fault_name(int fault);
/* Invariants of a restored supervisor: NULL or the first bad field. */
const char *piezo_supervisor_check(const piezo_supervisor *sup);

#endif
