"""The core's side of issue 9 (robustness), through harness.binding.core: finite values in, finite
outputs out or a refused step that leaves the state as it was; parameters that make
overflow inevitable refused at init; the invariant checks a deserialized FMU state goes
through (piezo_*_check) accept every state a run produces and name what a tampered one
breaks; the exact-mode history size never wraps.

References: IEEE 754 overflow (1e308 / 0.1 and 1e200 * 1e200 are Inf in doubles; Python's
floats are the same doubles, so the tests compute the overflowing quantity themselves),
and the state before the refused call (compared field by field through cffi).
"""
import math

import pytest

from harness.binding import core
from harness.binding.core import ffi

SIZE_MAX = 2 ** (8 * ffi.sizeof("size_t")) - 1


def snapshot(cdata, ctype):
    """The bytes of a core struct (states are flat, so bytes equal means state equal)."""
    return bytes(ffi.buffer(cdata, ffi.sizeof(ctype)))


def check_text(result):
    return None if result == ffi.NULL else ffi.string(result).decode()


# ---------------------------------------------------------------------------- plant

@pytest.mark.parametrize("name, value, fragment", [
    ("sensor.resolution", 1e-310, "0 (off) or [1e-300, inf) um"),
    ("sensor.resolution", -0.1, "0 (off) or [1e-300, inf) um"),
    ("sensor.noise_rms", 1e308, "[0, 1e300] um"),
    ("sensor.noise_rms", 1e301, "[0, 1e300] um"),
])
def test_plant_refuses_sensor_parameters_that_make_the_reading_overflow(name, value, fragment):
    """1e-310 um: y / resolution overflows for every |y| > 1.8e-2 um (1.8e-2 / 1e-310 > DBL_MAX),
    i.e. for any real displacement; noise of 1e308 um overflows for |N(0,1)| > 1.8."""
    assert 1.8e-2 / 1e-310 == math.inf
    with pytest.raises(core.CoreParameterError) as info:
        core.Plant({name: value})
    assert info.value.parameter == name and fragment in info.value.valid_range


def test_plant_accepts_the_edges_of_the_sensor_ranges():
    for params in ({"sensor.resolution": 1e-300}, {"sensor.noise_rms": 1e300}, {"sensor.resolution": 0.0}):
        plant = core.Plant(params)
        plant.step(1.0)
        assert all(math.isfinite(x) for x in plant.output)


def test_plant_refuses_a_step_whose_reading_overflows_and_keeps_its_state():
    """v = 1e308 with resolution 0.1: u, x and y stay finite here (w0 v = 3.3e307), but
    y / 0.1 overflows, so the sample is refused as divergence (the sensor reading used to
    come out as Inf with PIEZO_OK). The plant is byte for byte the one before the step."""
    plant = core.Plant({"sensor.resolution": 0.1})
    plant.step(1.0)
    before = snapshot(plant.raw, "piezo_plant")
    with pytest.raises(core.CoreDivergedError):
        plant.step(1e308)
    assert snapshot(plant.raw, "piezo_plant") == before
    # without quantisation the same voltage is a finite sample
    plain = core.Plant()
    plain.step(1.0)
    out = plain.step(1e308)
    assert math.isfinite(out.y) and abs(out.y) > 1e306 and out.y / 0.1 == math.inf * (1 if out.y > 0 else -1)


def test_plant_check_accepts_runs_and_names_tampered_fields():
    lib = core.lib()
    for params in ({}, {"creep.exact": True}, {"creep.enabled": False}, {"sensor.noise_rms": 0.01}):
        plant = core.Plant(params)
        for k in range(300):
            plant.step(10.0 * math.sin(0.05 * k) + 10.0)
        assert check_text(lib.piezo_plant_check(plant.raw)) is None, params
    plant = core.Plant()
    plant.step(1.0)
    raw = plant.raw
    tampered = {
        ("tf", "head"): (34, "tf input ring index"),
        ("tf", "delay"): (33, "tf.delay"),
        ("creep", "head"): (17, "creep ring index"),
        ("creep", "n_terms"): (65, "SOE term count"),
        ("creep", "exact"): (2, "creep.exact"),
        ("creep", "k"): (7, "creep sample counter"),
        ("pi", "m"): (0, "pi.m"),
    }
    for (block, field), (value, fragment) in tampered.items():
        struct = getattr(raw, block)
        old = getattr(struct, field)
        setattr(struct, field, value)
        assert fragment in (check_text(lib.piezo_plant_check(raw)) or ""), (block, field)
        setattr(struct, field, old)
    # the creep's input ring and its mirror hold the same doubles (the window sum reads both)
    raw.creep.x_ring[17 + 3] = raw.creep.x_ring[3] + 1.0
    assert "mirror" in (check_text(lib.piezo_plant_check(raw)) or "")
    raw.creep.x_ring[17 + 3] = raw.creep.x_ring[3]
    assert check_text(lib.piezo_plant_check(raw)) is None
    # the SOE decays e^{-s} lie in (0, 1]; a restored one beyond made the next advance NaN, a state
    # the check then refused (CI's fuzzer, tests/c/fuzz_crashes/fuzz_deserialize_PiezoStage)
    assert 0.0 < min(raw.creep.soe_decay[i] for i in range(raw.creep.n_terms)) \
        and max(raw.creep.soe_decay[i] for i in range(raw.creep.n_terms)) <= 1.0
    for value in (1.5, 0.0, -0.5):
        old = raw.creep.soe_decay[2]
        raw.creep.soe_decay[2] = value
        assert "SOE decay outside (0, 1]" in (check_text(lib.piezo_plant_check(raw)) or ""), value
        raw.creep.soe_decay[2] = old
    assert check_text(lib.piezo_plant_check(raw)) is None
    raw.out.y_meas = math.nan
    assert "not finite" in check_text(lib.piezo_plant_check(raw))


@pytest.mark.parametrize("model", [core.Plant, core.Controller])
def test_pi_weights_whose_sum_overflows_are_refused(model):
    """Found by fuzz_run (tests/c/fuzz_crashes/): pi.w[6] = 1e308 and pi.w[9] = DBL_MAX
    are each finite, but the loading curve's slope w0 + sum w_j is 1e308 + 1.8e308 = Inf:
    the plant's u overflows for |v| > 1, and the controller's inverse started with a play
    state of Inf * 0 = NaN. Refused, naming the weight where the sum overflows."""
    assert 1e308 + 1.7976931348623157e308 == math.inf
    with pytest.raises(core.CoreParameterError) as info:
        model({"pi.w[6]": 1e308, "pi.w[9]": 1.7976931348623157e308})
    assert info.value.parameter == "pi.w[9]" and "sum" in info.value.valid_range
    model({"pi.w[6]": 1e300})                           # a large but finite slope is a model


# ---------------------------------------------------------------------------- creep

def test_exact_history_size_saturates_instead_of_wrapping():
    """2 (k + 1) for k = 2^63 + 5 is 2^64 + 12, which wraps to 12 in size_t: a buffer of
    12 doubles would then pass the capacity check. The size saturates at SIZE_MAX."""
    lib = core.lib()
    gl = ffi.new("piezo_gl *")
    gl.exact = 1
    gl.k = 1000
    assert lib.piezo_gl_history_needed(gl) == 2002
    gl.k = 2 ** 63 + 5
    assert (2 * (gl.k + 1)) % (SIZE_MAX + 1) == 12
    assert lib.piezo_gl_history_needed(gl) == SIZE_MAX
    gl.exact = 0
    assert lib.piezo_gl_history_needed(gl) == 0


def test_exact_history_check_recomputes_the_weights():
    """piezo_gl_check_history: the stored w_j must be eq 14's recursion bit for bit, the
    inputs finite, and the length 2 (k + 1)."""
    lib = core.lib()
    plant = core.Plant({"creep.exact": True})
    for k in range(50):
        plant.step(5.0 + k % 7)
    hist = plant._hist
    n = lib.piezo_plant_history_needed(plant.raw)
    creep = ffi.addressof(plant.raw, "creep")
    assert check_text(lib.piezo_gl_check_history(creep, hist.ptr, n)) is None
    assert "length" in check_text(lib.piezo_gl_check_history(creep, hist.ptr, n - 2))
    hist.ptr[2 * 10 + 1] *= 1.0 + 2 ** -52
    assert "weight" in check_text(lib.piezo_gl_check_history(creep, hist.ptr, n))
    hist.ptr[2 * 10 + 1] /= 1.0 + 2 ** -52
    hist.ptr[2 * 3] = math.inf
    assert "not finite" in check_text(lib.piezo_gl_check_history(creep, hist.ptr, n))


# ---------------------------------------------------------------------------- controller

@pytest.mark.parametrize("params, parameter", [
    ({"pi.w[1]": 1e308}, "pi.v_max"),                   # thresholds ~ w v_max overflow
    ({"pi.v_max": 1e308, "pi.w[1]": 10.0}, "pi.v_max"),
    ({"pi.w0": 1e-200, "pi.w[1]": 0.0}, "pi.w0"),       # w0^2 underflows: w'_1 = -0/0
])
def test_controller_refuses_pi_parameters_without_a_finite_inverse(params, parameter):
    assert 1e-200 * 1e-200 == 0.0 and 1e308 * 20 == math.inf
    with pytest.raises(core.CoreParameterError) as info:
        core.Controller(params)
    assert info.value.parameter == parameter


def test_controller_refuses_a_sample_that_overflows_its_covariance_and_keeps_its_state():
    """y_meas = 5e153 with mv.delay set (no detection) and rls.p0 = 25: at the second sample
    phi = [-5e153, 0, q, 0], so phi^T P phi = 25 * 2.5e307 overflows; P - P phi phi^T P /
    (lambda + phi^T P phi) is Inf / Inf = NaN while theta and every output stay finite (the
    update K e is 5e153 / Inf = 0), and so does the outlier test's sum of squared errors
    (2.5e307 (1 + lambda)). That sample is refused as divergence and the controller
    is the one before it (supervision off: its sums of squared changes overflow at the first
    sample). With y_meas = 1e200 and the delay detected (the default) the first sample already
    overflows: its squared a-priori error, 1e400, enters the candidates' sums; it is refused
    the same way, and so is it with the supervision on. (Voltage limits off: a clipped first
    sample would pause the adaptation over the second.) The loop's update is the paper's here
    (rls.robust = false): the robust update adapts only while the reference moves by more
    than rls.excitation times the measured noise of y_meas, which such a y_meas makes huge,
    so it holds its estimates (checked with y_meas = 1e150); at 1e200 its first sample is
    refused too, since the outlier test's sum of squared a-priori errors, 1e400, overflows
    (committing it left a state that its own check refuses: found by the fuzzer)."""
    assert 1e200 * 1e200 == math.inf and 25.0 * 5e153 * 5e153 == math.inf
    assert 5e153 * 5e153 * (2.0 - 1.0 / 200.0) < math.inf
    ctrl = core.Controller({"sat.enabled": False, "mv.delay": 1, "sup.enabled": False, "rls.robust": False,
                            "rls.p0": 25.0})
    ctrl.step(0.0, 5e153)
    before = snapshot(ctrl.raw, "piezo_controller")
    with pytest.raises(core.CoreDivergedError, match="not finite"):
        ctrl.step(0.0, 5e153)
    assert snapshot(ctrl.raw, "piezo_controller") == before
    assert ctrl.k == 1
    robust = core.Controller({"sat.enabled": False, "mv.delay": 1, "sup.enabled": False})
    for k in range(5):
        robust.step(float(k), 1e150)
        assert not robust.raw.out.adapting and list(robust.raw.P) == [0.01 if i % 5 == 0 else 0.0 for i in range(16)]
        assert check_text(core.lib().piezo_controller_check(robust.raw)) is None
    robust.reset()
    before = snapshot(robust.raw, "piezo_controller")
    with pytest.raises(core.CoreDivergedError, match="not finite"):
        robust.step(0.0, 1e200)
    assert snapshot(robust.raw, "piezo_controller") == before and robust.k == 0
    for params in ({"sat.enabled": False}, {"sat.enabled": False, "mv.delay": 1}):
        first = core.Controller(params)
        before = snapshot(first.raw, "piezo_controller")
        with pytest.raises(core.CoreDivergedError):
            first.step(0.0, 1e200)
        assert snapshot(first.raw, "piezo_controller") == before and first.k == 0, params


def test_controller_refuses_a_sample_that_overflows_its_outlier_sums_and_keeps_its_state():
    """Found by fuzz_deserialize (tests/c/fuzz_crashes/, outlier_err_sum_overflow): the
    outlier test's sum of squared a-priori errors, E(k+1) = lambda E(k) + e^2, overflowed
    while theta, P and every output stayed finite (adaptation paused on a clipped sample),
    and the controller committed E = Inf: a state its own check refuses, so it could no
    longer be saved and restored. Such a sample is refused as divergence, like any value
    not finite, and the controller is the one before it. Here E is set to DBL_MAX (a state
    the check accepts) and the next accepted error is 1e153: lambda DBL_MAX + 1e306 is Inf
    (lambda = 1 - 1/200)."""
    dbl_max = 1.7976931348623157e308
    assert (1.0 - 1.0 / 200.0) * dbl_max + 1e153 * 1e153 == math.inf
    ctrl = core.Controller()
    plant = core.Plant()
    y = 0.0
    for k in range(400):
        y = plant.step(ctrl.step(5.0 * math.sin(2.0 * math.pi * 5.0 * k * 5e-4), y).v).y_meas
    ctrl.raw.err_sum = dbl_max
    ctrl.raw.quiet = 0                       # not an isolated sample: not taken for an outlier
    assert check_text(core.lib().piezo_controller_check(ctrl.raw)) is None
    before = snapshot(ctrl.raw, "piezo_controller")
    with pytest.raises(core.CoreDivergedError, match="not finite"):
        ctrl.step(0.0, 1e153)
    assert snapshot(ctrl.raw, "piezo_controller") == before and ctrl.k == 400
    ctrl.raw.err_sum = 1.0                   # the same sample with room in the sum is accepted
    ctrl.step(0.0, 1e153)
    assert ctrl.raw.err_sum == (1.0 - 1.0 / 200.0) * 1.0 + 1e153 * 1e153
    assert check_text(core.lib().piezo_controller_check(ctrl.raw)) is None


def test_controller_check_accepts_runs_and_names_tampered_fields():
    lib = core.lib()
    for params in ({}, {"creep.exact": True}, {"rls.enabled": False}, {"mv.feedthrough": True, "mv.delay": 0}):
        # the inputs are no closed loop: keep the monitor and the supervision from stopping it
        ctrl = core.Controller({**params, "monitor.divergence_samples": 0, "sup.enabled": False})
        for k in range(300):
            ctrl.step(2.0 * math.sin(0.01 * (k + 2)), 2.0 * math.sin(0.01 * k))
        assert check_text(lib.piezo_controller_check(ctrl.raw)) is None, params
    raw = ctrl.raw
    for field, value, fragment in [("d", 10, "loop delay"), ("head", -1, "q ring"), ("sat_hold", 99, "adaptation"),
                                   ("n_saturated", 10 ** 6, "monitor counts"), ("k", 5, "sample counter"),
                                   ("detecting", 1, "delay detection flags"), ("det_leader", 3, "leader"),
                                   ("det_run", 41, "leader"), ("det_trial", 10 ** 6, "trial"),
                                   ("det_probe", -1.0, "trial"), ("k_delay", 10 ** 6, "counters"),
                                   ("det_clock", 10 ** 6, "counters"), ("r_prev", math.inf, "not finite")]:
        old = getattr(raw, field)
        setattr(raw, field, value)
        assert fragment in (check_text(lib.piezo_controller_check(raw)) or ""), field
        setattr(raw, field, old)
    # derived at init, so a restored state must carry the reciprocal of its own rls.forgetting
    old = raw.inv_forgetting
    raw.inv_forgetting = old * (1 + 2 ** -52)
    assert "rls.forgetting" in (check_text(lib.piezo_controller_check(raw)) or "")
    raw.inv_forgetting = old
    # the RLS reads P_ij as P_ji: a live P is symmetric bit for bit
    old = raw.P[1]
    raw.P[1] = raw.P[4] * (1 + 2 ** -52) if raw.P[4] != 0 else 1e-300
    assert "symmetric" in (check_text(lib.piezo_controller_check(raw)) or "")
    raw.P[1] = old
    assert check_text(lib.piezo_controller_check(raw)) is None
    # the outputs a restored state publishes (found by fuzz_deserialize: an adapting of 2
    # was accepted, published as est.adapting, and the state then no longer restored)
    for field, value, fragment in [("adapting", 2, "adapting output is not 0 or 1"),
                                   ("noise", -1e-9, "noise output"), ("noise", math.inf, "noise output")]:
        old = getattr(raw.out, field)
        setattr(raw.out, field, value)
        assert fragment in (check_text(lib.piezo_controller_check(raw)) or ""), field
        setattr(raw.out, field, old)
    assert check_text(lib.piezo_controller_check(raw)) is None
    # ... and so is each delay candidate's (the same update), while detecting or after
    auto = core.Controller({"monitor.divergence_samples": 0, "sup.enabled": False})
    for k in range(5):
        auto.step(2.0 * math.sin(0.01 * (k + 2)), 2.0 * math.sin(0.01 * k))
    det = auto.raw
    assert det.auto_delay == 1 and check_text(lib.piezo_controller_check(det)) is None
    old = det.det_P[16 + 1]
    det.det_P[16 + 1] = det.det_P[16 + 4] * (1 + 2 ** -52) if det.det_P[16 + 4] != 0 else 1e-300
    assert "candidate's covariance not symmetric" in (check_text(lib.piezo_controller_check(det)) or "")
    det.det_P[16 + 1] = old
    assert check_text(lib.piezo_controller_check(det)) is None
    raw.P[5] = math.nan
    assert "covariance" in check_text(lib.piezo_controller_check(raw))


# ---------------------------------------------------------------------------- reference

def reference_init(**values):
    lib = core.lib()
    params = ffi.new("piezo_reference_params *")
    lib.piezo_reference_default_params(params)
    for name, value in values.items():
        if name.startswith(("amplitude", "frequency", "phase")):
            field, index = name.rstrip("]").split("[")
            getattr(params, field)[int(index) - 1] = value
        else:
            setattr(params, name, value)
    ref = ffi.new("piezo_reference *")
    diag = ffi.new("piezo_diag *")
    status = lib.piezo_reference_init(ref, params, 0.0, diag)
    return status, ref, diag


def test_reference_refuses_amplitudes_whose_sum_overflows():
    """|y_d| <= |offset| + sum |a_i|: 1e308 + 1e308 = Inf, so y_d could be Inf at some t."""
    assert 1e308 + 1e308 == math.inf
    status, _, diag = reference_init(offset=1e308, **{"amplitude[1]": 1e308})
    assert status == core.PIEZO_ERR_PARAM and ffi.string(diag.parameter) == b"amplitude[1]"
    status, ref, _ = reference_init(offset=1e308, **{"amplitude[1]": 7e307, "frequency[1]": 1.0})
    assert status == core.PIEZO_OK and check_text(core.lib().piezo_reference_check(ref)) is None


def test_reference_refuses_a_step_whose_time_overflows_and_keeps_its_state():
    """h = 1e308, lead 0, one tone of frequency 0 (< 1/(2h)): t_1 = 1e308 is a time, t_2 =
    2e308 is not, and sin(0 * Inf) is NaN. The second step is refused and the reference
    keeps sample 1."""
    lib = core.lib()
    status, ref, _ = reference_init(h=1e308, lead=0, preview=0,
                                    **{"amplitude[1]": 1.0, "frequency[1]": 0.0, "phase[1]": 0.5})
    assert status == core.PIEZO_OK
    assert lib.piezo_reference_step(ref) == core.PIEZO_OK and ref.k == 1
    before = snapshot(ref, "piezo_reference")
    assert lib.piezo_reference_step(ref) == core.PIEZO_ERR_DIVERGED
    assert snapshot(ref, "piezo_reference") == before and math.isfinite(ref.y_d)
