"""harness.identification: the paper's steps 1-2 recover the DESIGN.md section 1 defaults
from a noise-free run of the core plant (creep disabled, i.e. the Hammerstein model)."""

import numpy as np
import pytest

from harness.core_loop import simulate_open_loop_core
from harness.identification import (
    identify_pi,
    identify_transfer_function,
    pi_thresholds,
    play_operator_outputs,
)


W_DEFAULT = np.array([0.3344, 0.0714, 0.0322, 0.0072, 0, 0, 0, 0, 0, 0])
G_DEFAULT = (-1.3767, 0.3816, 0.5954, -0.5907)
H = 0.0005


def _run(v):
    return simulate_open_loop_core({"creep.enabled": False}, v)


def test_thresholds_and_play_operator():
    # Reference: DESIGN.md section 1, r_j = (j-1)/m v_max; eq 3 play operator.
    np.testing.assert_allclose(pi_thresholds(9, 20.0), np.arange(9) * 20.0 / 9)
    z = play_operator_outputs([1.0, 3.0, 2.0, -1.0], [1.0])[:, 0]
    np.testing.assert_allclose(z, [0.0, 2.0, 2.0, 0.0])


def test_identify_pi_recovers_default_weights():
    # Paper step 1: v = 10 sin(2 pi 1 t) + 10 V, 2 s, fitted on the plant's PI output u.
    t = np.arange(4000) * H
    v = 10 * np.sin(2 * np.pi * t) + 10
    run = _run(v)
    w = identify_pi(v, run["u"], m=9, v_max=20.0, w0=0.3344)
    np.testing.assert_allclose(w, W_DEFAULT, rtol=0, atol=1e-6)
    # w0 unknown: r_1 = 0 makes z_1 = v, so only w0 + w1 is identifiable
    w_free = identify_pi(v, run["u"], m=9, v_max=20.0)
    assert w_free[0] == pytest.approx(0.3344 + 0.0714, abs=1e-6) and w_free[1] == 0.0
    np.testing.assert_allclose(w_free[2:], W_DEFAULT[2:], rtol=0, atol=1e-6)


def test_identify_transfer_function_recovers_default_g():
    # Paper step 2: v = 6 (sin 2 pi 5t + sin 2 pi 40t + sin 2 pi 80t) + 18 V, from u to x.
    t = np.arange(4000) * H
    v = 6 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t) + np.sin(2 * np.pi * 80 * t)) + 18
    run = _run(v)
    assert np.array_equal(run["x"], run["y"])   # creep disabled: Hammerstein output
    est = identify_transfer_function(run["u"], run["x"])
    np.testing.assert_allclose(est, G_DEFAULT, rtol=0, atol=1e-6)


def test_identification_errors():
    with pytest.raises(ValueError, match="same length"):
        identify_pi([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="need at least"):
        identify_transfer_function([1.0] * 3, [1.0] * 3)
