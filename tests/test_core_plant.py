"""The coupled plant model in the C core (piezo_plant.h) through harness.binding.core.Plant."""
import math

import numpy as np
import pytest

from harness.binding import core
import numpy_reference as ref

H = 0.0005
VALIDATION = ref.validation_inputs(H, 10.0)           # 20000 samples each
ROW = {"1 Hz": 1, "10 Hz": 10, "20 Hz": 20, "50 Hz": 50, "100 Hz": 100, "5/40/80 Hz": "5/40/80"}


def row_params(name):
    k_c, alpha = ref.TABLE1[ROW[name]]
    return {"creep.k_c": k_c, "creep.alpha": alpha}


def max_errs(sim, want):
    return {f: float(np.max(np.abs(sim[f] - want[f]))) for f in ("u", "x", "y")}


@pytest.mark.parametrize("name", list(VALIDATION))
def test_exact_creep_plant_matches_numpy_reference(name):
    """Reference: numpy_reference.plant_simulate (PI loop, difference equation, direct
    G-L convolution with gain k_c h^-alpha), each docs/model.md, scenarios validation input
    for 10 s (20000 samples) with its Table 1 creep row, creep.exact = true.
    Tolerance 1e-9 um on u, x and y."""
    v = VALIDATION[name]
    p = row_params(name)
    sim = core.Plant({**p, "creep.exact": True}).simulate(v)
    want = ref.plant_simulate(v, ref.plant_params(**p))
    errs = max_errs(sim, want)
    print(f"\n{name}: max |core - reference| u {errs['u']:.1e}, x {errs['x']:.1e}, y {errs['y']:.1e} um")
    assert max(errs.values()) <= 1e-9, errs
    assert np.array_equal(sim["y_meas"], sim["y"])          # sensor off by default
    assert np.array_equal(sim["time"], np.arange(v.size) * H)
    assert np.array_equal(sim["v"], v)


@pytest.mark.parametrize("name", list(VALIDATION))
def test_hammerstein_plant_matches_numpy_reference(name):
    """Reference: numpy_reference.plant_simulate with creep disabled (y = x), every
    validation input, 10 s; tolerance 1e-9 um on u, x, y; y must equal x exactly."""
    v = VALIDATION[name]
    sim = core.Plant({"creep.enabled": False}).simulate(v)
    want = ref.plant_simulate(v, ref.plant_params(**{"creep.enabled": False}))
    errs = max_errs(sim, want)
    assert max(errs.values()) <= 1e-9, errs
    assert np.array_equal(sim["y"], sim["x"])


@pytest.mark.parametrize("name", list(VALIDATION))
def test_soe_plant_close_to_exact_reference(name):
    """Reference: numpy_reference.plant_simulate (exact creep, direct G-L convolution), each
    validation input for 10 s with its Table 1 row, default SOE creep mode.
    Regression bound: max |y - y_ref| <= 5e-9 um (measured: 1.7e-11 um at 1 Hz, <= 1.1e-9 um
    for the other rows, worst 50 Hz). Acceptance bound (docs/model.md, plant: <= 0.001 nm for
    |alpha| <= 0.01), checked too: 1e-6 um."""
    v = VALIDATION[name]
    p = row_params(name)
    sim = core.Plant(p).simulate(v)
    want = ref.plant_simulate(v, ref.plant_params(**p))
    err = np.max(np.abs(sim["y"] - want["y"]))
    print(f"\n{name}: SOE plant vs exact reference: {err * 1e3:.2e} nm")
    assert err <= 1e-6
    assert err <= 5e-9


def test_extra_input_delay_matches_reference():
    """Reference: numpy_reference.plant_simulate with tf.delay = 3 (exact creep, 10 Hz row),
    5000 samples; tolerance 1e-9 um."""
    v = VALIDATION["10 Hz"][:5000]
    p = {**row_params("10 Hz"), "tf.delay": 3}
    sim = core.Plant({**p, "creep.exact": True}).simulate(v)
    want = ref.plant_simulate(v, ref.plant_params(**p))
    assert max(max_errs(sim, want).values()) <= 1e-9


def test_exact_history_growth_by_single_steps():
    """Reference: numpy_reference.plant_simulate. Stepping one sample at a time in exact mode
    makes the binding grow its history buffer by doubling (1024 -> 16384 doubles); growing must keep
    the old contents, so y stays within 1e-9 um of the reference over 5000 samples."""
    v = VALIDATION["20 Hz"][:5000]
    p = row_params("20 Hz")
    plant = core.Plant({**p, "creep.exact": True})
    ys = [plant.output.y]
    for x in v[:-1]:
        ys.append(plant.step(x).y)
    assert plant._hist.capacity >= 5000
    want = ref.plant_simulate(v, ref.plant_params(**p))
    assert np.max(np.abs(np.array(ys) - want["y"])) <= 1e-9


def test_step_output_semantics():
    """Reference: piezo_plant.h timing (numpy_reference convention). step(v(k)) returns the
    outputs of sample k+1 = plant.output; k counts; simulate rows equal a step loop
    bitwise; reset returns to rest."""
    v = VALIDATION["10 Hz"][:300]
    plant = core.Plant({"sensor.noise_rms": 0.01, "sensor.resolution": 0.002})
    assert plant.k == 0 and plant.output[:3] == (0.0, 0.0, 0.0)
    rows = []
    for x in v:
        rows.append(plant.output)
        o = plant.step(x)
        assert o == plant.output
    assert plant.k == 300
    assert rows[1].u == pytest.approx(ref.pi_forward(v[:1], 0.3344, ref.DOC_DEFAULTS["pi.w"],
                                                     ref.pi_thresholds(9, 20.0))[0][0], abs=1e-15)
    plant.reset()
    assert plant.k == 0
    sim = plant.simulate(v)
    for f in ("u", "x", "y", "y_meas"):
        assert np.array_equal(sim[f], np.array([getattr(r, f) for r in rows])), f


def test_simulate_continues_from_current_state():
    """Reference: one uninterrupted simulate call; two consecutive calls give the same
    rows bitwise (exact mode), times continue at k h."""
    v = VALIDATION["50 Hz"][:3000]
    a = core.Plant({"creep.exact": True}).simulate(v)
    p = core.Plant({"creep.exact": True})
    b = np.concatenate([p.simulate(v[:1111]), p.simulate(v[1111:])])
    assert np.array_equal(a, b)


def test_defaults_fact_1hz_span():
    """Reference: docs/model.md, scenarios: with the defaults, v = 10 sin(2 pi t) + 10 V gives
    y spanning 0.10-8.84 um in the second second (tolerance 0.01 um)."""
    v = VALIDATION["1 Hz"][:4000]
    sim = core.Plant().simulate(v)
    y = sim["y"][2000:4000]
    print(f"\ndefaults, 1 Hz: y spans {y.min():.4f} .. {y.max():.4f} um")
    assert y.min() == pytest.approx(0.10, abs=0.01)
    assert y.max() == pytest.approx(8.84, abs=0.01)


def test_defaults_fact_mixed_span():
    """Reference: docs/model.md, scenarios: v = 6(sin 2pi5t + sin 2pi40t + sin 2pi80t) + 18 V
    (5/40/80 row) gives y spanning 0.9-14.8 um (after the first second; tolerance 0.05 um)."""
    v = VALIDATION["5/40/80 Hz"]
    sim = core.Plant(row_params("5/40/80 Hz")).simulate(v)
    y = sim["y"][2000:]
    print(f"\n5/40/80 Hz: y spans {y.min():.4f} .. {y.max():.4f} um")
    assert y.min() == pytest.approx(0.9, abs=0.05)
    assert y.max() == pytest.approx(14.8, abs=0.05)


# ------------------------------------------------------------------ sensor
def test_sensor_quantization():
    """Reference: quantize(a) = res * round(a / res) (docs/model.md, plant) applied with NumPy
    to the true y; res = 2 nm, no noise, 10 Hz validation input. Tolerance 1e-12 um; every
    reading is an integer multiple of res and within res/2 of y."""
    res = 0.002
    sim = core.Plant({"sensor.resolution": res}).simulate(VALIDATION["10 Hz"][:6000])
    want = res * np.round(sim["y"] / res)
    assert np.max(np.abs(sim["y_meas"] - want)) <= 1e-12
    n = sim["y_meas"] / res
    assert np.max(np.abs(n - np.round(n))) <= 1e-9
    assert np.max(np.abs(sim["y_meas"] - sim["y"])) <= res / 2 + 1e-12
    assert np.unique(sim["y_meas"]).size > 100


def noise_run(seed, n=100000, rms=0.5, v=None):
    plant = core.Plant({"sensor.noise_rms": rms, "sensor.seed": seed})
    return plant.simulate(np.zeros(n) if v is None else v)


def test_sensor_noise_statistics():
    """Reference: N(0, rms^2) statistics. At rest (y = 0) over 1e5 samples: sample rms within
    3 % of noise_rms = 0.5 um, mean within 5 sigma/sqrt(N) of 0, |lag-1 autocorrelation|
    < 0.02 (white)."""
    sim = noise_run(1)
    e = sim["y_meas"] - sim["y"]
    assert np.all(sim["y"] == 0)
    rms = np.sqrt(np.mean(e ** 2))
    mean = np.mean(e)
    rho = np.corrcoef(e[:-1], e[1:])[0, 1]
    print(f"\nnoise: rms {rms:.5f} (set 0.5), mean {mean:.2e}, lag-1 corr {rho:.2e}")
    assert abs(rms / 0.5 - 1) <= 0.03
    assert abs(mean) <= 5 * 0.5 / np.sqrt(e.size)
    assert abs(rho) < 0.02


def test_sensor_seed_reproducibility():
    """Reference: the seeding contract. Same seed -> bitwise identical sequence (also after
    reset()); different seed -> different sequence."""
    v = VALIDATION["1 Hz"][:5000]
    a = noise_run(7, v=v)["y_meas"]
    b = noise_run(7, v=v)["y_meas"]
    c = noise_run(8, v=v)["y_meas"]
    assert np.array_equal(a, b)
    assert np.mean(a != c) > 0.99
    plant = core.Plant({"sensor.noise_rms": 0.5, "sensor.seed": 7})
    plant.simulate(v)
    plant.reset()
    assert np.array_equal(plant.simulate(v)["y_meas"], a)


def test_rng_exposed_functions():
    """Reference: uniform(0,1) statistics: 1e5 draws strictly inside (0, 1), mean 0.5 +-
    0.005, variance 1/12 within 2 %; normal draws mean 0 +- 0.02, std 1 within 2 %."""
    L = core.lib()
    rng = core.ffi.new("piezo_rng *")
    L.piezo_rng_seed(rng, 12345)
    u = np.array([L.piezo_rng_uniform(rng) for _ in range(100000)])
    assert u.min() > 0 and u.max() < 1
    assert abs(u.mean() - 0.5) < 0.005 and abs(u.var() * 12 - 1) < 0.02
    g = np.array([L.piezo_rng_normal(rng) for _ in range(100000)])
    assert abs(g.mean()) < 0.02 and abs(g.std() - 1) < 0.02


# ------------------------------------------------------------------ bad input
BAD = [
    ("creep.alpha", 1.5), ("creep.alpha", -1.01), ("creep.alpha", float("nan")),
    ("creep.k_c", 0.0), ("creep.k_c", -1.0), ("creep.k_c", float("inf")),
    ("pi.w0", 0.0), ("pi.w0", -0.3),
    ("pi.w[2]", -0.01), ("pi.w[1]", -1e-9), ("pi.w[9]", float("nan")),
    ("pi.m", 0), ("pi.m", 17), ("pi.m", -3),
    ("pi.v_max", 0.0), ("pi.v_max", -5.0),
    ("h", 0.0), ("h", -0.0005), ("h", float("nan")),
    ("tf.delay", -1), ("tf.delay", 33),
    ("sensor.resolution", -0.002), ("sensor.noise_rms", -1e-3),
    ("sensor.resolution", float("inf")), ("sensor.noise_rms", float("nan")),
]


@pytest.mark.parametrize("name,value", BAD, ids=[f"{n}={v}" for n, v in BAD])
def test_invalid_parameter_refused(name, value):
    """Reference: docs/model.md, plant; docs/fmus.md valid ranges. CoreParameterError naming exactly the
    FMU variable, carrying the value and a range, with the documented message format."""
    with pytest.raises(core.CoreParameterError) as ei:
        core.Plant({name: value})
    e = ei.value
    assert e.parameter == name
    assert e.value == value or (np.isnan(value) and np.isnan(e.value))
    assert e.valid_range.strip()
    assert str(e).startswith(f"{name} = ") and str(e).endswith(f"is out of range: valid range {e.valid_range}")
    assert isinstance(e, ValueError)


def test_unstable_a_refused_in_plant():
    """Reference: numpy.roots: tf.a1 = -1.9, tf.a2 = 1.05 has |poles| > 1."""
    assert np.max(np.abs(np.roots([1, -1.9, 1.05]))) > 1
    with pytest.raises(core.CoreParameterError) as ei:
        core.Plant({"tf.a1": -1.9, "tf.a2": 1.05})
    assert ei.value.parameter in ("tf.a1", "tf.a2")


def test_message_format_example():
    """Reference: the brief's example message."""
    with pytest.raises(core.CoreParameterError) as ei:
        core.Plant({"creep.alpha": 2})
    assert str(ei.value) == f"creep.alpha = 2 is out of range: valid range {ei.value.valid_range}"
    assert ei.value.valid_range.replace(" ", "") == "[-1,1]"


@pytest.mark.parametrize("exact", [False, True], ids=["soe", "exact"])
def test_nonfinite_input_refused_state_unchanged(exact):
    """Reference: an uninterrupted run (same parameters, noise on). NaN/+Inf/-Inf are refused
    with CoreInputError at several samples; the outputs and k do not change at the refusal
    and the continuation (incl. the noise sequence) is bitwise identical."""
    prm = {"creep.exact": exact, "sensor.noise_rms": 0.003, "sensor.resolution": 0.002,
           "creep.alpha": -0.0085, "creep.k_c": 1.0497}
    v = VALIDATION["20 Hz"][:2500]
    a = core.Plant(prm).simulate(v)
    plant = core.Plant(prm)
    rows = []
    for k, x in enumerate(v):
        rows.append(tuple(plant.output))
        if k in (0, 1, 1023, 1024, 2047, 2400):
            for bad in (np.nan, np.inf, -np.inf):
                before = (plant.k, tuple(plant.output))
                with pytest.raises(core.CoreInputError):
                    plant.step(bad)
                assert (plant.k, tuple(plant.output)) == before
        plant.step(x)
    rows = np.array(rows)
    for i, f in enumerate(("u", "x", "y", "y_meas")):
        assert np.array_equal(rows[:, i], a[f]), f
    with pytest.raises(core.CoreInputError):
        core.Plant(prm).simulate(np.array([1.0, np.nan, 2.0]))


# ------------------------------------------------------------------ sensor generator, bit exact
# A pure-Python transcription of the published algorithms (Blackman & Vigna,
# https://prng.di.unimi.it: splitmix64.c and xoshiro256starstar.c), with explicit 64-bit masks,
# plus the core's documented mappings (piezo_plant.h / README): uniform = ((x >> 11) + 0.5) 2^-53,
# normal = Box-Muller sqrt(-2 ln u1) cos(2 pi u2) with the second variate dropped, cos(2 pi u2)
# by the core's own quadrant reduction and Taylor polynomials (piezo_plant.c, cos_2pi).
MASK64 = (1 << 64) - 1
COS_TAYLOR = [(-1) ** n / math.factorial(2 * n) for n in range(10)]
SIN_TAYLOR = [(-1) ** n / math.factorial(2 * n + 1) for n in range(9)]


def estrin(c, z):
    """((c0 + c1 z) + z^2 (c2 + c3 z)) + z^4 ((c4 + c5 z) + z^2 (c6 + c7 z)) + z^8 (c8 [+ c9 z])."""
    z2 = z * z
    z4 = z2 * z2
    last = c[8] + c[9] * z if len(c) == 10 else c[8]
    return (((c[0] + c[1] * z) + z2 * (c[2] + c[3] * z))
            + z4 * ((c[4] + c[5] * z) + z2 * (c[6] + c[7] * z)) + (z4 * z4) * last)


def cos_2pi(u):
    """cos(2 pi u), u in (0, 1), as piezo_plant.c documents it: q = round(4u), t = u - q/4,
    x = 2 pi t; cos x, -sin x, -cos x, sin x for q mod 4 = 0..3."""
    q = int(4.0 * u + 0.5)
    t = u - 0.25 * q
    x = (2.0 * math.pi) * t
    z = x * x
    c, s = estrin(COS_TAYLOR, z), x * estrin(SIN_TAYLOR, z)
    return (c, -s, -c, s)[q & 3]


def splitmix64_next(state):
    """splitmix64: returns (new state, output)."""
    state = (state + 0x9E3779B97F4A7C15) & MASK64
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    return state, z ^ (z >> 31)


def rotl64(x, k):
    return ((x << k) | (x >> (64 - k))) & MASK64


class Xoshiro256StarStar:
    """xoshiro256** 1.0; seed(): the four state words are consecutive splitmix64 outputs."""

    def __init__(self, seed=None, state=None):
        if state is None:
            sm, state = seed & MASK64, []
            for _ in range(4):
                sm, out = splitmix64_next(sm)
                state.append(out)
        self.s = list(state)

    def next(self):
        s = self.s
        result = (rotl64((s[1] * 5) & MASK64, 7) * 9) & MASK64
        t = (s[1] << 17) & MASK64
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl64(s[3], 45)
        return result

    def uniform(self):
        return (float(self.next() >> 11) + 0.5) * (1.0 / 9007199254740992.0)   # 2^-53

    def normal(self):
        u1 = self.uniform()
        u2 = self.uniform()
        return math.sqrt(-2.0 * math.log(u1)) * cos_2pi(u2)


def test_python_generator_reproduces_published_vectors():
    """Reference: the published test vectors of the algorithms (anchor for the transcription
    used below): splitmix64 from state 0 gives 0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4,
    0x06C45D188009454F, 0xF88BB8A8724C81EC; xoshiro256** from the state {1, 2, 3, 4} gives
    the 10 outputs of the reference implementation (as in rand_xoshiro's test). Exact."""
    sm, outs = 0, []
    for _ in range(4):
        sm, o = splitmix64_next(sm)
        outs.append(o)
    assert outs == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F, 0xF88BB8A8724C81EC]
    g = Xoshiro256StarStar(state=[1, 2, 3, 4])
    assert [g.next() for _ in range(10)] == [
        11520, 0, 1509978240, 1215971899390074240, 1216172134540287360, 607988272756665600,
        16172922978634559625, 8476171486693032832, 10595114339597558777, 2904607092377533576]


@pytest.mark.parametrize("seed", [1, 12345, 2**32 - 5, 2**63 + 7])
def test_core_rng_equals_python_transcription(seed):
    """Reference: the pure-Python splitmix64 + xoshiro256** transcription above (checked against
    the published vectors). The core's piezo_rng_uniform (first 1000 draws) and, from a freshly
    seeded generator, piezo_rng_normal (first 1000 draws, 2 uniforms each, the second Box-Muller
    variate dropped) equal it exactly (tolerance 0: bitwise)."""
    L = core.lib()
    rng = core.ffi.new("piezo_rng *")
    L.piezo_rng_seed(rng, seed)
    py = Xoshiro256StarStar(seed)
    got = [L.piezo_rng_uniform(rng) for _ in range(1000)]
    assert got == [py.uniform() for _ in range(1000)]
    L.piezo_rng_seed(rng, seed)
    py = Xoshiro256StarStar(seed)
    got = [L.piezo_rng_normal(rng) for _ in range(1000)]
    want = [py.normal() for _ in range(1000)]
    assert got == want


def test_cos_2pi_is_cos_of_2_pi_u_to_an_ulp():
    """Reference: mpmath at 40 digits, cos(2 pi u) of the exact double u. The transcription of
    the core's cos_2pi is within 1.5 ulp of 1 (measured: 1.0; the C library's cos of the
    rounded 2 pi u: 2.9) at 20000 uniform draws and at the quadrant edges 1/8, 3/8, 5/8,
    7/8 (+- 1 ulp), where the reduction switches polynomials; and the core's normals are
    the transcription's, bit for bit."""
    import mpmath

    mpmath.mp.dps = 40
    g = Xoshiro256StarStar(11)
    us = [g.uniform() for _ in range(20000)]
    for edge in (0.125, 0.375, 0.625, 0.875):
        us += [edge, math.nextafter(edge, 0.0), math.nextafter(edge, 1.0)]
    worst = 0.0
    for u in us:
        exact = float(mpmath.cos(2 * mpmath.pi * mpmath.mpf(u)))
        worst = max(worst, abs(cos_2pi(u) - exact) / 2.0 ** -52)
    assert worst <= 1.5, worst
    # the core computes the same: its normal of (u1, u2) equals the transcription's
    L = core.lib()
    rng = core.ffi.new("piezo_rng *")
    for seed in (3, 4):
        L.piezo_rng_seed(rng, seed)
        py = Xoshiro256StarStar(seed)
        assert [L.piezo_rng_normal(rng) for _ in range(5000)] == [py.normal() for _ in range(5000)]


def python_normals(seed, n):
    g = Xoshiro256StarStar(seed)
    return np.array([g.normal() for _ in range(n)])


@pytest.mark.parametrize("seed", [1, -5])
def test_plant_noise_is_noise_rms_times_the_python_normals(seed):
    """Reference: the Python generator above seeded with the FMU Integer sensor.seed
    reinterpreted as uint32 (piezo_plant.c: -5 -> 2^32 - 5). Resolution 0, noise_rms 0.7 um,
    10 Hz validation input (moving y), 1000 rows: y_meas(k) = y(k) + noise_rms * n_k exactly
    (bitwise, the same double operations), with n_0 drawn at reset for y_meas(0) (y(0) = 0,
    so y_meas(0) = 0.7 n_0) and one draw per step after it."""
    rms = 0.7
    sim = core.Plant({"sensor.noise_rms": rms, "sensor.seed": seed}).simulate(VALIDATION["10 Hz"][:1000])
    n = python_normals(seed & 0xFFFFFFFF, 1000)
    assert sim["y"][0] == 0.0 and sim["y_meas"][0] == rms * n[0]
    assert np.array_equal(sim["y_meas"], sim["y"] + rms * n)
    assert np.max(np.abs((sim["y_meas"] - sim["y"]) - rms * n)) <= 1e-14
    assert np.ptp(sim["y"]) > 5.0                          # y really moves (not a rest test)


def test_plant_noise_is_added_before_quantization():
    """Reference: docs/model.md, plant, y_meas = quantize(y + noise), quantize(a) =
    res * round(a / res), computed with NumPy from the core's y and the Python generator's
    normals (seed 1). Resolution 2 nm, noise 1 nm rms, 10 Hz validation input, 6000 rows.
    Every y_meas is an integer multiple of res (to 1e-12 relative) and y_meas - quantize(y +
    noise) == 0 exactly (a plant that quantizes y first and adds the noise after fails both)."""
    res, rms = 0.002, 0.001
    sim = core.Plant({"sensor.resolution": res, "sensor.noise_rms": rms, "sensor.seed": 1}).simulate(
        VALIDATION["10 Hz"][:6000])
    n = sim["y_meas"] / res
    assert np.max(np.abs(n - np.round(n)) / np.maximum(np.abs(n), 1.0)) <= 1e-12
    noise = rms * python_normals(1, 6000)
    want = res * np.round((sim["y"] + noise) / res)
    assert np.max(np.abs(sim["y_meas"] - want)) == 0.0
    # the noise matters: without it, a sizeable share of the readings would differ
    assert np.mean(sim["y_meas"] != res * np.round(sim["y"] / res)) > 0.2


def _quantize_cases():
    """(reading, resolution) pairs at the edges of the core's fast quantiser: readings on and
    within a few ulps of the half steps (n + 1/2) res, at the fast path's margin (n + 1/2 +- 2^-8,
    2^-9) res, at its magnitude limit 2^36 res and up to 2^53 res, signed zeros, subnormal and
    huge readings, resolutions from 1e-300 to 2^1023 (whose reciprocal is subnormal), and
    random readings."""
    rng = np.random.default_rng(5)
    resolutions = [0.002, 0.001, 1e-3 / 3, 0.1, 1.0, 3.0, 1e-300, 1e300, 2.0 ** 1023, 0.0017]
    cases = []
    for res in resolutions:
        steps = [0, 1, 2, 3, 7, 1000, 123456, 2 ** 20 + 1, 2 ** 35 - 1, 2 ** 36 - 1, 2 ** 36,
                 2 ** 36 + 3, 2 ** 40, 2 ** 51 - 1, 2 ** 52, 2 ** 53]
        for n in steps:
            for sign in (1.0, -1.0):
                for off in (0.5, 0.5 + 2.0 ** -8, 0.5 - 2.0 ** -8, 0.5 + 2.0 ** -9, 0.5 - 2.0 ** -9,
                            0.0, 0.25, 1.0 - 2.0 ** -8):
                    a = sign * (n + off) * res
                    cases.append((a, res))
                    up = down = a
                    for _ in range(6):
                        up, down = math.nextafter(up, math.inf), math.nextafter(down, -math.inf)
                        cases += [(up, res), (down, res)]
        with np.errstate(over="ignore"):        # res = 2^1023: some readings are meant to be inf
            cases += [(float(a), res) for a in rng.normal(0.0, 50.0, 2000) * res]
        cases += [(float(a), res) for a in rng.uniform(-1e4, 1e4, 2000)]
        cases += [(0.0, res), (-0.0, res), (5e-324, res), (-5e-324, res), (2.2e-308, res),
                  (1e308, res), (-1e308, res), (1.7976931348623157e308, res)]
    return cases


def test_quantizer_equals_the_division_bitwise_at_its_edges():
    """Reference: res * floor(a / res + 0.5) in NumPy doubles (IEEE division, exact floor),
    the formula of docs/model.md, which the core computed with a division until it took the
    reciprocal fast path (piezo_plant.c, quantize, with its proof). Over 73000 readings
    at the edges listed in _quantize_cases the core's piezo_quantize gives the same bits,
    infinities included; a quantiser that rounded a * (1/res) to the nearest integer without
    the margin fails at the half steps (checked on the same cases)."""
    L = core.lib()
    cases = _quantize_cases()
    a = np.array([c[0] for c in cases])
    res = np.array([c[1] for c in cases])
    with np.errstate(over="ignore", invalid="ignore"):
        want = res * np.floor(a / res + 0.5)
        naive = res * np.round(a * (1.0 / res))
    got = np.array([L.piezo_quantize(x, r) for x, r in cases])
    bad = np.flatnonzero(got.view(np.uint64) != want.view(np.uint64))
    assert bad.size == 0, [(cases[i], got[i], want[i]) for i in bad[:5]]
    assert np.count_nonzero(naive.view(np.uint64) != want.view(np.uint64)) > 100
    assert np.isinf(want).sum() > 10 and len(cases) > 70000


def test_overflow_is_reported_as_divergence_not_as_bad_input():
    """Reference: IEEE overflow. With pi.w0 = 4, v = 1e308 is a finite input but
    u = 4 v + ... overflows to inf: the core refuses the step as diverged
    (CoreDivergedError, a FloatingPointError), not as a non-finite input, and the plant is
    unchanged (the next valid step equals that of an untouched twin, bitwise)."""
    plant, twin = core.Plant({"pi.w0": 4.0}), core.Plant({"pi.w0": 4.0})
    for p in (plant, twin):
        p.step(3.0)
    with pytest.raises(core.CoreDivergedError, match="diverged"):
        plant.step(1e308)
    assert not isinstance(core.CoreDivergedError("x"), ValueError)   # not "bad input"
    assert plant.k == twin.k == 1
    assert plant.step(5.0) == twin.step(5.0)
