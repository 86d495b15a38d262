"""Identification validated on a family of stages (harness.identify.family), not on one demo.

Stages are drawn at random (fixed seeds) from around the paper's ranges (Table 1's creep
rows, the poles and zero of eq 21, 3 to 6 nonzero PI weights; FAMILY_RANGES), recorded on
the C core (the FMU's own code) and identified from v and y alone through
fit_coupled_model. The references are independent of the fit: the measured records'
held-out samples, and the stage's own noise-free displacement y on a voltage no record
uses (2/15/35 Hz), which only a simulated stage gives.

Bounds (issue 18): noise-free, held-out e_rms <= 1 nm for every stage; with the paper's
sensor (2 nm resolution, 1 nm rms noise), the model's error against the noise-free truth
<= 0.5 nm for every stage. Measured distributions are in docs/identification.md.
"""
import numpy as np
import pytest

from harness.identify.family import (FAMILY_RANGES, PAPER_DC_GAIN, draw_stage, validate_family)

NOISE_FLOOR = 1.155e-3      # sqrt(1^2 + 2^2/12) nm: 1 nm rms noise and a 2 nm quantiser


def _report(family):
    return "\n" + family.format()


def test_drawn_stages_cover_the_stated_ranges():
    """The draw itself: every stage inside FAMILY_RANGES, and the family spans them."""
    rng = np.random.default_rng(7)
    stages = [draw_stage(rng) for _ in range(200)]
    alpha = np.array([s["creep.alpha"] for s in stages])
    assert alpha.min() < -0.010 and alpha.max() > 0.013          # beyond Table 1's rows
    for s in stages:
        a1, a2, b1, b2 = s["tf.a1"], s["tf.a2"], s["tf.b1"], s["tf.b2"]
        p1, p2 = sorted(np.roots([1, a1, a2]).real, reverse=True)
        assert 0.985 <= p1 <= 0.996 and 0.3 <= p2 <= 0.6
        assert -1e-4 <= p1 - (-b2 / b1) <= 1e-3
        assert 0.8 <= (b1 + b2) / (1 + a1 + a2) / PAPER_DC_GAIN <= 1.2
        nonzero = 1 + sum(s[f"pi.w[{j}]"] > 0 for j in range(1, 10))
        assert 3 <= nonzero <= 6
        assert FAMILY_RANGES["pi.w0"][0] <= s["pi.w0"] <= FAMILY_RANGES["pi.w0"][1]


@pytest.fixture(scope="module")
def clean():
    return validate_family(50, seed=2026, noise=False)


@pytest.fixture(scope="module")
def noisy():
    return validate_family(50, seed=2027, noise=True)


def test_noise_free_family_every_stage_within_1_nm(clean):
    """50 stages, the standard records (1 Hz: PI and creep; 5/40/80 Hz: G; 10 Hz: creep;
    10 s each), noise-free: held-out e_rms <= 1 nm for every stage. Measured: worst
    about 1e-6 nm (the search converges to round-off on every stage)."""
    s = clean.summary()
    assert len(clean.stages) == 50
    assert s["held_out_e_rms"][1] <= 1e-3, _report(clean)
    assert s["truth_e_rms"][1] <= 1e-3, _report(clean)
    assert all(not st.undetermined for st in clean.stages), _report(clean)
    # far inside the bound: the model class is exact for these stages
    assert s["held_out_e_rms"][1] < 1e-7 and s["alpha_error"][1] < 1e-8, _report(clean)


def test_noisy_family_within_half_a_nanometre_of_the_truth(noisy):
    """50 stages, the same records with 2 nm quantisation and 1 nm rms noise: the model's
    error against the noise-free truth on the held-out 2/15/35 Hz input <= 0.5 nm for every
    stage, and the held-out error at the noise floor (no fit can beat the noise; a worse
    model would show above it). Measured: truth error median ~0.015 nm, worst ~0.04 nm."""
    s = noisy.summary()
    assert s["truth_e_rms"][1] <= 0.5e-3, _report(noisy)
    assert 0.95 * NOISE_FLOOR <= noisy.column("held_out_e_rms").min(), _report(noisy)
    assert s["held_out_e_rms"][1] <= 1.1 * NOISE_FLOOR, _report(noisy)
    assert all(not st.undetermined for st in noisy.stages), _report(noisy)


@pytest.mark.parametrize("record_set, duration, noise, n, seed", [
    ("two", 2.0, True, 10, 31),       # only a low-frequency record and a multi-sine, short
    ("six", 3.0, False, 6, 32),       # the paper's six validation inputs
    ("standard", 20.0, True, 4, 33),  # long records
])
def test_the_record_sets_users_have(record_set, duration, noise, n, seed):
    """The record sets users bring, at lengths from 2 s to 20 s: the same bounds hold.
    Measured: two records of 2 s with noise, truth error worst ~0.07 nm."""
    family = validate_family(n, seed=seed, record_set=record_set, duration=duration,
                             noise=noise)
    s = family.summary()
    assert s["truth_e_rms"][1] <= 0.5e-3, _report(family)
    if not noise:
        assert s["held_out_e_rms"][1] <= 1e-3, _report(family)
    assert all(not st.undetermined for st in family.stages), _report(family)
