"""harness.identify.model and fit.CoupledModel: the forward model the fits evaluate.

References: the C core (the plant's own code, through the cffi binding) for the creep
operator and the whole plant; scipy-free recursions (transfer_function_output) for G;
the model's own output for the normalisation (it must not change the output).
"""
from dataclasses import replace

import numpy as np
import pytest

from harness.binding import core
from harness.masters.c_core import simulate_open_loop_core
from harness.identify.fit import CoupledModel
from harness.identify.model import (
    creep_output,
    g_filter,
    gl_convolve,
    gl_weights,
    transfer_function_output,
)

H = 0.0005


def test_gl_weights_are_the_core_recursion():
    # Reference: the core's piezo_gl_weights (eq 14), and the closed form w_j = (-1)^j C(alpha, j).
    from scipy.special import binom

    for alpha in (-0.0085, 0.0, 0.35, -1.0, 1.0):
        w = gl_weights(alpha, 500)
        np.testing.assert_allclose(w, core.gl_weights(alpha, 500), rtol=1e-14, atol=1e-300)
        if abs(alpha) < 1:      # scipy's binom is nan at alpha = -1
            j = np.arange(20)
            np.testing.assert_allclose(w[:20], (-1.0) ** j * binom(alpha, j), rtol=1e-12,
                                       atol=1e-15)
    np.testing.assert_array_equal(gl_weights(-1.0, 50), np.ones(50))   # (1 - z^-1)^-1: a sum


@pytest.mark.parametrize("alpha", [-0.0085, 0.0002, 0.3, -0.6])
def test_gl_convolve_equals_the_cores_full_memory_sum(alpha):
    """Reference: the core's exact mode (creep.exact = true), O(N^2) sum. Measured agreement
    1e-14 um on 3000 samples of a 0-20 um signal; bound 1e-11 um."""
    t = np.arange(3000) * H
    x = 10 + 10 * np.sin(2 * np.pi * 7 * t) + np.sin(2 * np.pi * 91 * t)
    gain = 1.0497 * H ** -alpha
    ref = creep_output(x, 1.0497, alpha, H, exact=True)
    np.testing.assert_allclose(gl_convolve(x, alpha, gain), ref, rtol=0, atol=1e-11)
    # columns are independent series
    both = gl_convolve(np.column_stack([x, 2 * x]), alpha, gain)
    np.testing.assert_allclose(both[:, 0], ref, rtol=0, atol=1e-11)
    np.testing.assert_allclose(both[:, 1], 2 * ref, rtol=0, atol=2e-11)


def test_g_filter_equals_the_recursion_with_delay():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((400, 3))
    for delay in (0, 2):
        out = g_filter(u, -1.3767, 0.3816, 0.5954, -0.5907, delay)
        for c in range(3):
            ref = transfer_function_output(u[:, c], -1.3767, 0.3816, 0.5954, -0.5907, delay)
            np.testing.assert_allclose(out[:, c], ref, rtol=0, atol=1e-12)


MODEL = CoupledModel((0.28, 0.085, 0.05, 0.025, 0.012, 0.006, 0.003, 0.0, 0.0, 0.0), 20.0,
                     -1.442037, 0.44641665, 0.62517, -0.620235, 1.0497, -0.0085, H)


def test_coupled_model_simulates_the_plant():
    """Reference: the core plant with the same parameters and full-memory creep: the model
    output equals it to round-off (measured 2e-14 um; bound 1e-11 um)."""
    v = 6 * (np.sin(2 * np.pi * 5 * np.arange(3000) * H) + np.sin(2 * np.pi * 40 * np.arange(3000) * H)) + 18
    run = simulate_open_loop_core({**MODEL.plant_params(), "creep.exact": True}, v)
    np.testing.assert_allclose(MODEL.simulate(v), run["y"], rtol=0, atol=1e-11)
    hamm = replace(MODEL, creep=False)
    np.testing.assert_allclose(hamm.simulate(v), run["x"], rtol=0, atol=1e-11)
    assert hamm.plant_params()["creep.enabled"] is False


def test_normalisation_keeps_the_output_and_fixes_the_gains():
    n = MODEL.normalized()
    assert n.dc_gain == pytest.approx(1.0, abs=1e-12) and n.k_c == 1.0 and n.weights[1] == 0.0
    assert n.static_gain == pytest.approx(MODEL.static_gain, rel=1e-12)
    assert n.weights[0] == pytest.approx(n.static_gain, rel=1e-12)
    # ratios w_j / (w0 + w1), poles, zero and alpha do not change
    np.testing.assert_allclose(np.array(n.weights[2:]) / n.weights[0],
                               np.array(MODEL.weights[2:]) / (MODEL.weights[0] + MODEL.weights[1]),
                               rtol=1e-12)
    np.testing.assert_allclose(n.poles, MODEL.poles, rtol=1e-12)
    assert n.zero == pytest.approx(MODEL.zero, rel=1e-12) and n.alpha == MODEL.alpha
    v = 10 * np.sin(2 * np.pi * 10 * np.arange(2000) * H) + 10
    np.testing.assert_allclose(n.simulate(v), MODEL.simulate(v), rtol=0, atol=1e-12)
    assert n.normalized().weights == pytest.approx(n.weights, rel=1e-15)
    np.testing.assert_allclose(MODEL.poles, [0.992037, 0.45], rtol=1e-9)
    with pytest.raises(ValueError, match=r"G\(1\) = -1 is not a positive number"):
        CoupledModel((1.0, 0.0), 20.0, -0.5, 0.0, -0.5, 0.0, 1.0, 0.0, H).normalized()
