"""The controller's supervision seen from outside: its statistics recomputed from what a run
recorded, and how close the run came to each of its verdicts.

:func:`statistics` is a NumPy transcription of ``fmu_src/core/piezo_supervisor.c`` (the
response regression per loop delay, the evidence sums) and of the divergence monitor's share of
large prediction errors (``piezo_controller.c``),
computed from a run's samples; ``tests/test_core_supervision.py`` holds it against the C
core's own sums. :func:`margins` says, for a run that raised no verdict, how near it came to
each threshold (docs/robustness.md: the margins of the validation family): the weakest and
the strongest response gain seen with strong evidence against ``sup.gain_min`` and
``sup.gain_max``, the share of the response the law's delays left unexplained where another
delay fitted better, the longest run of a fault candidate, the largest share of large
prediction errors over the divergence monitor's window, the longest clipping and the longest
delay detection.

The thresholds are the core's: the ``PIEZO_SUP_*`` constants of ``piezo_supervisor.h`` and
the defaults of the ``sup.*`` parameters (read through :mod:`harness.binding.core`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from ..binding import core

__all__ = ["Thresholds", "thresholds", "statistics", "margins", "Margins", "controller_samples"]


@dataclass(frozen=True)
class Thresholds:
    """The supervision's thresholds (``piezo_supervisor.h`` and the ``sup.*`` defaults)."""

    gain_min: float
    gain_max: float
    window: int
    clip_time: float
    detect_time: float
    evidence: float
    delay_fraction: float
    monitor_share: float
    monitor_share_min: int
    travel_fraction: float
    confirm: int
    min_samples: int
    max_delay: int
    detectable: int
    judge_every: int
    gain_drop: float
    gain_rise: float
    frozen_share: float
    big_step: float
    frozen_big: float


def thresholds(controller_params=None):
    """The thresholds in force for a controller with these parameter overrides."""
    p = {**core.default_controller_params(), **(controller_params or {})}
    lib = core.lib()
    return Thresholds(
        gain_min=float(p["sup.gain_min"]), gain_max=float(p["sup.gain_max"]), window=int(p["sup.window"]),
        clip_time=float(p["sup.clip_time"]), detect_time=float(p["sup.detect_time"]),
        evidence=float(lib.PIEZO_SUP_EVIDENCE), delay_fraction=lib.PIEZO_SUP_DELAY_PERCENT / 100.0,
        monitor_share=lib.PIEZO_MONITOR_SHARE_PERCENT / 100.0,
        monitor_share_min=int(lib.PIEZO_MONITOR_SHARE_MIN_SAMPLES),
        travel_fraction=lib.PIEZO_SUP_TRAVEL_PERCENT / 100.0, confirm=int(lib.PIEZO_SUP_CONFIRM),
        min_samples=int(lib.PIEZO_SUP_MIN_SAMPLES), max_delay=int(lib.PIEZO_MV_MAX_D),
        detectable=int(lib.PIEZO_SUP_DEFAULT_DETECTABLE), judge_every=int(lib.PIEZO_SUP_JUDGE_EVERY),
        gain_drop=lib.PIEZO_SUP_DROP_PERCENT / 100.0, gain_rise=lib.PIEZO_SUP_RISE_PERCENT / 100.0,
        frozen_share=lib.PIEZO_SUP_FROZEN_PERCENT / 100.0, big_step=lib.PIEZO_SUP_BIG_STEP_PERCENT / 100.0,
        frozen_big=lib.PIEZO_SUP_FROZEN_BIG_PERMILLE / 1000.0)


def _ew(x, lam):
    """sum_j lam^(k-j) x(j), from zero."""
    return lfilter([1.0], [1.0, -lam], x)


def statistics(y_meas, q, pred_error, nominal, window, error_bound, monitor_window=200):
    """The supervisor's per-sample sums, as the core computes them (``piezo_supervisor.c``).

    Parameters
    ----------
    y_meas : array_like
        The measurement the controller received at each of its samples k [um].
    q : array_like
        Its virtual input q(k) of each sample [um] (the back-calculated one where v was clipped).
    pred_error : array_like
        Its a-priori prediction error of each sample [um].
    nominal : tuple of float
        The model's ``tf.a1, tf.a2, tf.b1, tf.b2``.
    window : int
        ``sup.window`` [samples].
    error_bound : float
        ``monitor.pred_error_max`` [um].
    monitor_window : int
        ``monitor.divergence_samples`` (the divergence monitor's window, 0: off).

    Returns
    -------
    dict of ndarray
        ``szz``, ``szw`` and ``sww`` (one row per delay 1..9), ``travel_model``, ``yhat_slow``
        (the model's yhat averaged with the time constant ``PIEZO_SUP_CREEP_SAMPLES``),
        ``travel_meas``, ``weight``, ``reversals`` (samples where y_meas reversed its direction,
        the last change kept over equal samples), ``steps2`` (its squared sample-to-sample
        changes), ``big_steps`` (its reversals by more than ``PIEZO_SUP_BIG_STEP_PERCENT`` % of the
        smallest nonzero step before), ``min_step`` (that smallest step, 0 before the first), ``y_same`` (samples y_meas equalled the one before, in a row), ``repeats`` (the samples
        y_meas equalled the one before): the
        supervisor's sums after each sample; ``mon_share``,
        ``mon_weight``: the divergence monitor's (samples with ``|pred_error|`` beyond the
        bound; where v was clipped the core also counts the nominal model's error, which a
        working loop keeps far below the bound).
    """
    a1, a2, b1, b2 = (float(x) for x in nominal)
    y = np.asarray(y_meas, dtype=float)
    q = np.asarray(q, dtype=float)
    lam = 1.0 - 1.0 / window
    n = y.size
    z = lfilter([1.0, a1, a2], [1.0], y)
    w = lfilter([0.0, b1, b2], [1.0], q)              # w(k) = b1 q(k-1) + b2 q(k-2)
    dz = np.diff(z, prepend=0.0)
    dw = np.diff(w, prepend=0.0)
    sww1 = _ew(dw * dw, lam)
    dmax = core.lib().PIEZO_MV_MAX_D
    szw = np.empty((dmax, n))
    sww = np.zeros((dmax, n))
    for d in range(1, dmax + 1):
        shifted = np.concatenate([np.zeros(d - 1), dw[:n - d + 1]])
        szw[d - 1] = _ew(dz * shifted, lam)
        sww[d - 1, d - 1:] = sww1[:n - d + 1]
    yhat = lfilter([1.0], [1.0, a1, a2], w)
    dy = np.diff(y, prepend=y[:1]) if n else y
    last = np.zeros(n)                              # the last nonzero change before each sample
    smallest = np.zeros(n)                          # the smallest nonzero |change| before each sample
    prev, low = 0.0, 0.0
    for i in range(n):
        last[i], smallest[i] = prev, low
        if dy[i] != 0.0:
            prev = dy[i]
            low = abs(dy[i]) if low == 0.0 else min(low, abs(dy[i]))
    big_step = core.lib().PIEZO_SUP_BIG_STEP_PERCENT
    creep = core.lib().PIEZO_SUP_CREEP_SAMPLES
    same = np.zeros(n, dtype=np.int64)
    for i in range(1, n):
        same[i] = same[i - 1] + 1 if y[i] == y[i - 1] else 0
    lam_m = 1.0 - 1.0 / monitor_window if monitor_window > 0 else 0.0
    return {
        "szz": _ew(dz * dz, lam), "szw": szw, "sww": sww,
        "travel_model": _ew(np.abs(np.diff(yhat, prepend=0.0)), lam),
        "yhat_slow": lfilter([1.0 / creep], [1.0, 1.0 / creep - 1.0], yhat),
        "travel_meas": _ew(np.abs(np.diff(y, prepend=0.0)), lam),
        "weight": _ew(np.ones(n), lam),
        "reversals": _ew((dy * last < 0.0).astype(float), lam), "steps2": _ew(dy * dy, lam), "y_same": same,
        "big_steps": _ew(((smallest > 0.0) & (dy * last < 0.0)
                          & (np.abs(dy) * 100.0 > big_step * smallest)).astype(float), lam),
        "min_step": smallest, "repeats": _ew((same > 0).astype(float), lam),
        "mon_share": _ew((np.abs(np.asarray(pred_error, dtype=float)) > error_bound).astype(float), lam_m),
        "mon_weight": _ew(np.ones(n), lam_m),
    }


@dataclass
class Margins:
    """How close one run came to each verdict (None where it never came into play).

    Attributes
    ----------
    gain_low, gain_high : float or None
        The weakest and the strongest response gain seen with strong evidence (thresholds
        ``sup.gain_min`` and ``sup.gain_max``).
    delay_unexplained : float or None
        Where a delay the law does not run fitted best with strong evidence: the largest share
        of the response the law's delays left unexplained (threshold ``PIEZO_SUP_DELAY_PERCENT``).
    candidate_run : int
        The longest run of samples with one fault candidate (threshold ``PIEZO_SUP_CONFIRM``).
    monitor_share : float
        The largest exponentially weighted count of samples with ``|pred_error|`` beyond
        ``monitor.pred_error_max``, as a share of the divergence monitor's whole window
        (``monitor.divergence_samples``), from its 33rd sample on (threshold
        ``PIEZO_MONITOR_SHARE_PERCENT``).
    clip_run : int
        The longest run of clipped samples (threshold ``sup.clip_time`` / h).
    detection_run : int
        The longest run of samples without a chosen loop delay (threshold
        ``sup.detect_time`` / h).
    monitor_run : int
        The longest run of samples with ``|pred_error|`` above ``monitor.pred_error_max``
        (the divergence window, 200 samples).
    gain_drop, gain_rise : float or None
        After the loop was verified: the largest ratio of the gain followed to a strongly
        evidenced gain (threshold ``PIEZO_SUP_DROP_PERCENT``) and of such a gain to the gain
        followed (``PIEZO_SUP_RISE_PERCENT``), over the judged samples.
    frozen_run : int
        The longest run of equal y_meas samples whose reversal share before it reached
        ``PIEZO_SUP_FROZEN_PERCENT`` and whose share of big steps (beyond
        ``PIEZO_SUP_BIG_STEP_PERCENT`` % of the smallest) reached ``PIEZO_SUP_FROZEN_BIG_PERMILLE``
        per mille (threshold ``sup.window``).
    frozen_ratio : float
        The largest such run over the run that makes it a verdict: ``PIEZO_SUP_STUCK_SAME`` at
        least, ``sup.window`` at most, and between them as many samples m as the share p of equal
        samples before makes improbable, p^m = e^-``PIEZO_SUP_STUCK_LOG_ODDS`` (p at least 1e-3).
        A verdict at 1.
    """

    gain_low: float | None
    gain_high: float | None
    delay_unexplained: float | None
    candidate_run: int
    monitor_share: float
    clip_run: int
    detection_run: int
    monitor_run: int
    gain_drop: float | None = None
    gain_rise: float | None = None
    frozen_run: int = 0
    frozen_ratio: float = 0.0


def _longest_run(mask):
    best = run = 0
    for m in np.asarray(mask, dtype=bool):
        run = run + 1 if m else 0
        best = max(best, run)
    return best


def margins(samples, nominal, controller_params=None):
    """The margins of one run (:class:`Margins`).

    Parameters
    ----------
    samples : dict of array_like
        Per controller sample: ``y_meas``, ``q``, ``pred_error``, ``clipped`` (v was
        clipped), ``loop_delay`` (the law's d, 0 while detecting) (:func:`controller_samples`).
    nominal : tuple of float
        The controller's ``tf.a1, tf.a2, tf.b1, tf.b2``.
    controller_params : dict, optional
        The controller's overrides (its ``sup.*``, ``monitor.pred_error_max``, ``mv.delay``).
    """
    p = {**core.default_controller_params(), **(controller_params or {})}
    th = thresholds(p)
    bound = float(p["monitor.pred_error_max"])
    window = int(p["monitor.divergence_samples"])
    st = statistics(samples["y_meas"], samples["q"], samples["pred_error"], nominal, th.window, bound, window)
    szz, szw, sww = st["szz"], st["szw"], st["sww"]
    n = szz.size
    k = np.arange(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        explained_d = np.where(sww > 0, szw * szw / sww, -np.inf)
    best = np.argmax(explained_d, axis=0)              # ties: the shorter delay, as the core
    idx = np.arange(n)
    sww_b, szw_b = sww[best, idx], szw[best, idx]
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(sww_b > 0, szw_b / sww_b, np.nan)
        e_best = np.maximum(szz - szw_b * np.nan_to_num(g), 0.0)
        # the quantisation floor (piezo_supervisor.c): the grid hides q^2/12 sum c^2 a sample
        a1, a2 = nominal[0], nominal[1]
        c2 = 1.0 + (a1 - 1.0) ** 2 + (a2 - a1) ** 2 + a2 ** 2
        e_best = np.maximum(e_best, st["weight"] * st["min_step"] ** 2 / 12.0 * c2)
        explained = sww_b * np.maximum(1.0, np.nan_to_num(g) ** 2)
    strong = ((sww_b > 0) & (k >= th.min_samples) & (explained >= th.evidence * e_best)
              & (st["travel_model"] >= th.travel_fraction * bound))
    loop_delay = np.asarray(samples["loop_delay"], dtype=int)
    auto = int(p["mv.delay"]) < 0
    law = th.detectable if auto else 1 + int(p["mv.delay"])
    with np.errstate(divide="ignore", invalid="ignore"):
        unexplained = np.where(sww > 0, szz - szw * szw / sww, szz)
    if auto:
        e_law = unexplained[:th.detectable].min(axis=0)
        off_law = best + 1 > th.detectable
    else:
        e_law = unexplained[law - 1] if law <= th.max_delay else np.zeros(n)
        off_law = best + 1 != law
    kind = np.zeros(n, dtype=int)
    gs = np.where(strong, g, np.nan)
    kind[strong & (g <= -th.gain_min)] = 2
    kind[strong & (np.abs(g) < th.gain_min)] = 1
    kind[strong & (g > th.gain_max)] = 3
    in_range = strong & (g >= th.gain_min) & (g <= th.gain_max)
    delay_share = np.where(in_range & off_law, e_law / np.where(explained > 0, explained, np.inf), np.nan)
    kind[in_range & off_law & (delay_share >= th.delay_fraction)] = 4
    cand_run = run = prev = 0
    for x in kind:
        run = run + 1 if x and x == prev else (1 if x else 0)
        prev = x
        cand_run = max(cand_run, run)
    # the monitor judges its count of large errors against the whole window (piezo_controller.c)
    share = np.where(k >= th.monitor_share_min, st["mon_share"] / window, 0.0) if window > 0 \
        else np.zeros(n)
    # the gain followed once verified, moved at each judged verified sample (piezo_supervisor.c):
    # the mean of its first ones, then an exponential mean; judged once it holds `confirm` of them
    followed, count, drop, rise = 0.0, 0, None, None
    rate = th.judge_every / th.window
    for i in np.flatnonzero(strong & (k % th.judge_every == 0)):
        if kind[i] != 0 or not in_range[i]:
            continue
        g_i = float(g[i])
        if count >= th.confirm:
            drop = max(drop or 0.0, followed / g_i)
            rise = max(rise or 0.0, g_i / followed)
            if followed > th.gain_drop * g_i or g_i > th.gain_rise * followed:
                continue                            # a candidate: the gain followed holds
        count += 1
        followed += (g_i - followed) * max(rate, 1.0 / count)
    # a measurement that froze after showing noise (its reversal share before the stretch)
    lam = 1.0 - 1.0 / th.window
    same = st["y_same"]
    stretch = (1.0 - lam ** same) / (1.0 - lam)
    before = st["weight"] - stretch
    with np.errstate(divide="ignore", invalid="ignore"):
        noisy = (before >= 1.0) & (st["reversals"] >= th.frozen_share * before) \
            & (st["big_steps"] >= th.frozen_big * before)
    frozen_run = int(same[noisy & (same > 0)].max()) if np.any(noisy & (same > 0)) else 0
    lib = core.lib()
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.maximum((st["repeats"] - stretch) / before, 1e-3)
        log_p = np.log(np.minimum(p, 1.0))
        needed = np.where(log_p < 0.0, lib.PIEZO_SUP_STUCK_LOG_ODDS / -log_p, np.inf)
    needed = np.clip(needed, lib.PIEZO_SUP_STUCK_SAME, th.window)
    hit = noisy & (same > 0)
    frozen_ratio = float(np.max(same[hit] / needed[hit])) if np.any(hit) else 0.0
    return Margins(
        gain_low=float(np.nanmin(gs)) if np.isfinite(gs).any() else None,
        gain_high=float(np.nanmax(gs)) if np.isfinite(gs).any() else None,
        delay_unexplained=float(np.nanmax(delay_share)) if np.isfinite(delay_share).any() else None,
        candidate_run=int(cand_run),
        monitor_share=float(share.max()) if n else 0.0,
        clip_run=_longest_run(samples["clipped"]),
        detection_run=_longest_run(loop_delay == 0) if auto else 0,
        monitor_run=_longest_run(np.abs(np.asarray(samples["pred_error"], dtype=float)) > bound),
        gain_drop=drop, gain_rise=rise, frozen_run=frozen_run, frozen_ratio=frozen_ratio,
    )


def controller_samples(run):
    """Per controller sample, from a run of :func:`harness.masters.wired.simulate_wired`: what the
    controller received (``y_meas``) and its outputs of that sample (``q``, ``pred_error``,
    ``clipped``, ``loop_delay``), published one row later."""
    s = run.samples if hasattr(run, "samples") else run
    return {"y_meas": s["y_meas_in"][:-1], "q": s["q"][1:], "pred_error": s["pred_error"][1:],
            "clipped": s["saturated"][1:] != 0, "loop_delay": s["loop_delay"][1:]}
