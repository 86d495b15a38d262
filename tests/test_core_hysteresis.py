"""PI hysteresis model and its inverse in the C core (piezo_hysteresis.h)."""

import numpy as np
import pytest

from harness.binding import core
import numpy_reference as ref

DEF = ref.DOC_DEFAULTS
W = np.array(DEF["pi.w"])
R = ref.pi_thresholds(9, 20.0)
# A second parameter set exercising all 16 operators with positive weights.
RICH = {"pi.m": 16, "pi.v_max": 25.0, "pi.w0": 0.21,
        **{f"pi.w[{j}]": 0.05 / j + 0.002 * j for j in range(1, 17)}}
RICH_W = np.array([RICH[f"pi.w[{j}]"] for j in range(1, 17)])
RICH_R = ref.pi_thresholds(16, 25.0)


def random_walk(seed, n=4000, step=0.4, lim=30.0):
    rng = np.random.default_rng(seed)
    v = np.cumsum(rng.normal(0, step, n))
    return np.clip(v, -lim, lim)


def bipolar(seed, n=4000, amp=30.0):
    """Sum of tones with random phases and a random-amplitude envelope, within +-amp."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.0005
    s = sum(rng.uniform(0.2, 1) * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3))
            for f in rng.uniform(0.5, 40, 5))
    s *= (0.5 + 0.5 * np.sin(2 * np.pi * 0.7 * t))
    return amp * s / np.max(np.abs(s))


INPUTS = [("walk", s) for s in (1, 2, 3)] + [("bipolar", s) for s in (4, 5, 6)]


def make_input(kind, seed):
    return random_walk(seed) if kind == "walk" else bipolar(seed)


def test_play_operator_matches_numpy_loop():
    """Reference: numpy_reference.play (eq 3 as a plain loop). max/min are exact,
    so the core must agree bit for bit (tolerance 0)."""
    L = core.lib()
    v = bipolar(11)
    for r in (0.0, 0.5, 2.2222, 7.0, 19.9, 40.0):
        for z0 in (0.0, -3.0, 12.5):
            want = ref.play(v, r, z0)
            z = z0
            got = np.empty(len(v))
            for k, vk in enumerate(v):
                z = L.piezo_play(vk, r, z)
                got[k] = z
            assert np.max(np.abs(got - want)) == 0.0, (r, z0)


def test_thresholds_and_weights_in_struct():
    """Reference: eq 5, r_j = (j-1)/m v_max (numpy_reference.pi_thresholds)."""
    for params, w, r in (({}, W, R), (RICH, RICH_W, RICH_R)):
        pi = core.pi_model(params)
        m = pi.raw.m
        assert m == len(w)
        assert np.max(np.abs(np.array([pi.raw.r[i] for i in range(m)]) - r)) <= 1e-15
        assert np.array_equal(np.array([pi.raw.w[i] for i in range(m)]), w)
        assert pi.raw.r[0] == 0.0 and np.all(pi.z == 0)


@pytest.mark.parametrize("params,w,r", [({}, W, R), (RICH, RICH_W, RICH_R)], ids=["default", "m16"])
@pytest.mark.parametrize("kind,seed", INPUTS)
def test_pi_forward_matches_reference(params, w, r, kind, seed):
    """Reference: numpy_reference.pi_forward (eq 18 with a vectorised play loop).
    Tolerance 1e-12 um (different summation order only)."""
    v = make_input(kind, seed)
    want, _ = ref.pi_forward(v, params.get("pi.w0", DEF["pi.w0"]), w, r)
    pi = core.pi_model(params)
    got = np.array([pi.step(x) for x in v])
    assert np.max(np.abs(got - want)) <= 1e-12


def test_inverse_design_facts():
    """Reference: docs/model.md (controller) gives the values w'_0 = 2.99043, w'_1..3 =
    -0.526163, -0.181163, -0.036924, r'_1..3 = 0, 0.901778, 1.875111 (6 significant
    digits, so tolerance 6e-6), and the full inverse parameter set against
    numpy_reference.pi_inverse_params to 1e-14."""
    inv = core.pi_model().inverse().raw
    assert inv.m == 9
    assert inv.w0 == pytest.approx(2.99043, abs=6e-6)
    for i, (wi, ri) in enumerate(zip((-0.526163, -0.181163, -0.036924), (0.0, 0.901778, 1.875111))):
        assert inv.w[i] == pytest.approx(wi, abs=6e-7), i
        assert inv.r[i] == pytest.approx(ri, abs=6e-7), i
    w0i, wi, ri = ref.pi_inverse_params(DEF["pi.w0"], W, R)
    assert abs(inv.w0 - w0i) <= 1e-14
    assert np.max(np.abs(np.array([inv.w[i] for i in range(9)]) - wi)) <= 1e-14
    assert np.max(np.abs(np.array([inv.r[i] for i in range(9)]) - ri)) <= 1e-14
    assert all(inv.z[i] == 0 for i in range(9))


@pytest.mark.parametrize("params,w", [({}, W), (RICH, RICH_W)], ids=["default", "m16"])
def test_inverse_initial_states_eq28(params, w):
    """Reference: numpy_reference.pi_inverse_initial_states (corrected eq 28) applied to
    the forward play states after driving the forward model; tolerance 1e-13."""
    pi = core.pi_model(params)
    for x in bipolar(21, 1500):
        pi.step(x)
    z = pi.z
    assert np.max(np.abs(z)) > 1.0
    inv = pi.inverse().raw
    want = ref.pi_inverse_initial_states(params.get("pi.w0", DEF["pi.w0"]), w, z)
    got = np.array([inv.z[i] for i in range(len(w))])
    assert np.max(np.abs(got - want)) <= 1e-13


@pytest.mark.parametrize("params", [{}, RICH], ids=["default", "m16"])
@pytest.mark.parametrize("warm", [False, True], ids=["zero-state", "nonzero-state"])
@pytest.mark.parametrize("kind,seed", INPUTS)
def test_round_trip_inverse_after_forward(params, warm, kind, seed):
    """Reference: the identity. P^-1(P(v)) = v within 1e-12 V on +-30 V random walks
    and bipolar inputs, from rest and from a non-zero play-state history (the forward
    model first driven by another input; the inverse initialised from it by eq 28)."""
    pi = core.pi_model(params)
    if warm:
        for x in make_input(kind, seed + 100)[:1234]:
            pi.step(x)
    inv = pi.inverse()
    v = make_input(kind, seed)
    back = np.array([inv.step(pi.step(x)) for x in v])
    err = np.max(np.abs(back - v))
    assert err <= 1e-12, err


@pytest.mark.parametrize("params", [{}, RICH], ids=["default", "m16"])
@pytest.mark.parametrize("warm", [False, True], ids=["zero-state", "nonzero-state"])
@pytest.mark.parametrize("seed", [7, 8])
def test_round_trip_forward_after_inverse(params, warm, seed):
    """Reference: the identity. P(P^-1(u)) = u within 1e-12 um (u a +-12 um random
    walk / bipolar signal), from rest and from a consistent non-zero state."""
    pi = core.pi_model(params)
    if warm:
        for x in bipolar(seed + 50)[:777]:
            pi.step(x)
    inv = pi.inverse()
    for u in (0.4 * random_walk(seed), 0.4 * bipolar(seed)):
        fwd = np.array([pi.step(inv.step(x)) for x in u])
        err = np.max(np.abs(fwd - u))
        assert err <= 1e-12, err


def test_inverse_against_numpy_reference():
    """Reference: numpy_reference.pi_inverse (the inverse PI built from the corrected
    eqs 25-28 in NumPy), from a non-zero state; tolerance 1e-12 V."""
    pi = core.pi_model()
    for x in bipolar(31, 999):
        pi.step(x)
    z = pi.z
    inv = pi.inverse()
    u = 0.4 * bipolar(32)
    got = np.array([inv.step(x) for x in u])
    want = ref.pi_inverse(u, DEF["pi.w0"], W, R, z)
    assert np.max(np.abs(got - want)) <= 1e-12


def test_nonfinite_input_refused_state_unchanged():
    """Reference: an uninterrupted run. NaN/Inf are refused (CoreInputError) and the
    play states are untouched, so the continuation is bitwise identical."""
    v = bipolar(41, 600)
    a, b = core.pi_model(), core.pi_model()
    ia, ib = None, None
    out_a, out_b = [], []
    for k, x in enumerate(v):
        if k == 300:
            ia, ib = a.inverse(), b.inverse()
        if k in (100, 350, 599):
            for bad in (np.nan, np.inf, -np.inf):
                with pytest.raises(core.CoreInputError):
                    b.step(bad)
                if ib is not None:
                    with pytest.raises(core.CoreInputError):
                        ib.step(bad)
        out_a.append(a.step(x))
        out_b.append(b.step(x))
        if ia is not None:
            out_a.append(ia.step(0.3 * x))
            out_b.append(ib.step(0.3 * x))
    assert out_a == out_b
