"""harness.metrics: eqs 36-37 of the paper as fixed by docs/model.md, scenarios."""

import math

import numpy as np
import pytest

from harness.metrics import compute_metrics, relative_error, rms_error, window_mask


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
