"""harness.loop.metrics: eqs 36-37 of the paper as fixed by docs/model.md, scenarios."""

import math

import numpy as np
import pytest

from harness.loop.metrics import compute_metrics, relative_error, rms_error, window_mask


def test_rms_and_relative_error_hand_computed():
    # Reference: hand computation. y_d - y = [-0.5, 0, 1, 0]:
    # e_rms = sqrt((0.25 + 1) / 4) = sqrt(0.3125);
    # e_r = sqrt(1.25 / (1.5^2 + 2^2 + 2^2 + 4^2)) = sqrt(1.25 / 26.25).
    y_d = [1.0, 2.0, 3.0, 4.0]
    y = [1.5, 2.0, 2.0, 4.0]
    assert rms_error(y_d, y) == pytest.approx(math.sqrt(0.3125), rel=1e-15)
    assert relative_error(y_d, y) == pytest.approx(math.sqrt(1.25 / 26.25), rel=1e-15)
    assert rms_error(y_d, y) == pytest.approx(0.5590169943749474, rel=1e-15)
    assert relative_error(y_d, y) == pytest.approx(0.2182178902359924, rel=1e-15)


def test_window_is_half_open_on_the_sample_grid():
    # Reference: docs/model.md, scenarios, metrics over t in [1, 3) s: with h = 0.5,
    # the window [0.5, 1.5) keeps samples 1 and 2 only -> errors 0 and 1.
    t = np.arange(4) * 0.5
    m = compute_metrics(t, [1.0, 2.0, 3.0, 4.0], [1.5, 2.0, 2.0, 4.0], window=(0.5, 1.5))
    assert m.n_samples == 2
    assert m.e_rms == pytest.approx(math.sqrt(0.5), rel=1e-15)
    assert m.e_r == pytest.approx(math.sqrt(1.0 / 8.0), rel=1e-15)


def test_window_counts_samples_of_the_paper_window():
    # [1, 3) s at h = 0.5 ms holds exactly 4000 samples, round-off of k*h notwithstanding.
    t = np.arange(6000) * 0.0005
    assert int(window_mask(t, (1.0, 3.0), 0.0005).sum()) == 4000
    assert int(np.flatnonzero(window_mask(t, (1.0, 3.0), 0.0005))[0]) == 2000


def test_sine_error_matches_analytic_rms():
    # Reference: rms of A sin over whole periods is A / sqrt(2); e_r of a 1 % gain
    # error is 0.01 / 0.99 relative to y = 0.99 y_d.
    t = np.arange(6000) * 0.0005
    y_d = 10 * np.sin(2 * np.pi * 5 * t)
    y = 0.99 * y_d
    m = compute_metrics(t, y_d, y, (1.0, 3.0), 0.0005)
    assert m.e_rms == pytest.approx(0.1 / math.sqrt(2), rel=1e-12)
    assert m.e_r == pytest.approx(0.01 / 0.99, rel=1e-12)


def test_normalizer_and_errors():
    # e_r with an explicit normalizer (validation: divide by the coupled output)
    assert relative_error([2.0, 2.0], [1.0, 1.0], normalizer=[2.0, 2.0]) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="shape mismatch"):
        rms_error([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="holds no samples"):
        compute_metrics([0.0, 1.0], [1.0, 1.0], [1.0, 1.0], window=(5.0, 6.0))


def test_metrics_from_sums_are_the_metrics_of_the_signals():
    # Reference: eq 36 and 37 written out with np.mean and np.sum (the definitions before
    # the sums got their own functions), on random windows of many lengths: rms_from_sum and
    # relative_from_sums, given np.sum's sums, give the same bits, for one window and for a
    # column of them; a normalizer of energy 0 gives nan.
    from harness.loop.metrics import relative_from_sums, rms_from_sum
    rng = np.random.default_rng(2)
    sums, want_rms, want_r, ns = [], [], [], []
    for n in (1, 7, 8, 129, 4000, 8193):
        y_d, y = rng.standard_normal(n), rng.standard_normal(n) * 1e-3
        err = y_d - y
        want_rms.append(math.sqrt(float(np.mean(err * err))))
        want_r.append(math.sqrt(float(np.sum(err * err)) / float(np.sum(y * y))))
        sums.append((np.sum(err * err), np.sum(y * y)))
        ns.append(n)
        assert rms_error(y_d, y) == want_rms[-1] and relative_error(y_d, y) == want_r[-1]
    e2, y2 = np.array(sums).T
    assert np.array_equal(rms_from_sum(e2, np.array(ns)), want_rms)
    assert np.array_equal(relative_from_sums(e2, y2), want_r)
    assert math.isnan(relative_from_sums(1.0, 0.0)) and relative_error([1.0], [0.0]) != relative_error([1.0], [0.0])


def test_check_rules_decide_columns_as_single_runs():
    # Reference: check_tracking_run's own decisions on hand-made runs. The rules it applies
    # decide arrays the same way, element by element: an error above the reference's rms
    # diverges (not when the reference is 0, nor at equality); clipping in more than 1 % of
    # the window saturates (exactly 1 % does not).
    from harness.loop.checks import (MAX_SATURATED_FRACTION, RunDivergedError, RunSaturatedError,
                                     check_tracking_run, clipped_too_often, error_above_reference)
    from harness.loop import CLOSED_LOOP_DTYPE
    from harness.scenarios import get_scenario
    sc = get_scenario("track_1hz")
    n = sc.n_samples
    t = np.arange(n) * sc.step_size

    def run(gain, clipped):
        r = np.zeros(n, CLOSED_LOOP_DTYPE)
        r["time"], r["y_d"] = t, np.sin(2 * np.pi * t)
        r["y"] = gain * r["y_d"]
        r["saturated"][np.flatnonzero(window_mask(t, sc.metric_window, sc.step_size))[:clipped]] = 1
        return r

    window = int(window_mask(t, sc.metric_window, sc.step_size).sum())
    at_limit = int(MAX_SATURATED_FRACTION * window)
    outcomes = []
    for gain, clipped in ((1.0, 0), (0.5, 0), (2.5, 0), (1.0, at_limit), (1.0, at_limit + 1)):
        try:
            check_tracking_run(run(gain, clipped), sc)
            outcomes.append("ok")
        except RunDivergedError:
            outcomes.append("diverged")
        except RunSaturatedError:
            outcomes.append("saturated")
    assert outcomes == ["ok", "ok", "diverged", "ok", "saturated"]
    # the same decisions on columns: the error is |1 - gain| times the reference's rms
    ref = 1 / math.sqrt(2)
    errors = np.abs(1 - np.array([1.0, 0.5, 2.5, 1.0, 1.0])) * ref
    fractions = np.array([0, 0, 0, at_limit, at_limit + 1]) / window
    diverged = error_above_reference(errors, ref)
    saturated = clipped_too_often(fractions)
    assert diverged.tolist() == [False, False, True, False, False]
    assert saturated.tolist() == [False, False, False, False, True]
    assert not error_above_reference(1.0, 0.0) and not error_above_reference(ref, ref)
