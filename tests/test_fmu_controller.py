"""AdaptiveCompoundController FMU: interface, timing (published at the end of a step by
default, direct feedthrough without commit as an option), stepping, FMU states,
refusals, call sequences, closed loop with PiezoStage.

Drives the built FMUs through fmpy's FMU2Slave (fixtures in conftest.py).
"""
import math
import re

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from harness.binding import core
from conftest import (assert_refused, assert_state_continues_bitwise, reset_after_a_non_default_run,
                      start_value, state_format)

OUTPUTS = ["v", "q", "est.a1", "est.a2", "est.b1", "est.b2", "pred_error"]   # the Real outputs of the law
TIMING = ["loop_delay", "loop_delay_time", "preview_lead", "meas_offset"]   # what it detected
INPUTS = ["y_ref", "y_meas", "y_preview", "t_preview", "t_meas", "sup.reset"]
H = 0.0005
# The direct-feedthrough option (d = 1): v at t_k from the inputs set at t_k.
FEEDTHROUGH = {"mv.feedthrough": True, "mv.delay": 0}
# Open loop on synthetic data (y_meas_of does not answer v): the supervision, which would
# rightly stop such a "loop" within 15 ms, is switched off as docs/model.md says for open-loop use,
# and so is the integral action, which winds up when y_meas does not answer v (here the
# divergence monitor stops the run at sample 288 with it).
OPEN_LOOP = {"sup.enabled": False, "mv.integral": 0.0}
SUPERVISION = {"sup.enabled": ("Boolean", True), "sup.gain_min": ("Real", 0.25), "sup.gain_max": ("Real", 4.0),
               "sup.window": ("Integer", 200), "sup.clip_time": ("Real", 0.5), "sup.detect_time": ("Real", 0.5),
               "sup.reaction": ("Integer", 0), "sup.ramp_time": ("Real", 0.01), "sup.clip_error": ("Real", 1.0),
               "mv.probe_max": ("Real", 1.0), "sup.sensor_noise": ("Real", 0.0)}
ADAPT_OUTPUTS = ["est.adapting", "est.noise"]
# the paper's law (tests/numpy_reference.py PAPER_LAW, docs/model.md, adaptation)
PAPER_LAW = {"rls.robust": False, "rls.forgetting": 0.995, "rls.trace_max": 100.0, "mv.integral": 0.0,
             "mv.observer": 0.4}
SUP_OUTPUTS = ["sup.status", "sup.gain", "sup.delay", "sup.fault", "sup.fault_time"]


def y_d(k):
    """1 Hz reference, 10 um amplitude (docs/model.md, scenarios)."""
    return 10.0 * math.sin(2.0 * math.pi * k * H)


def y_meas_of(k):
    """A plausible, exciting measurement sequence for open-loop runs."""
    return 9.0 * math.sin(2.0 * math.pi * (k - 3) * H) + 0.3 * math.sin(2.0 * math.pi * 37.0 * k * H)


def run(fmu, n, k0=0):
    rows = []
    for k in range(k0, k0 + n):
        fmu.set({"y_ref": y_d(k + 1), "y_meas": y_meas_of(k)})
        rows.append(fmu.get_reals(OUTPUTS))
        fmu.step()
    return np.array(rows)


def reference_and_twin(package, make_fmu, params, n, k):
    """The reference, an uninterrupted run of n samples with ``params``, and a twin instance
    run with the same to sample k: (the reference, its rows, the twin, the twin's rows)."""
    reference = make_fmu(package)
    reference.initialize(params)
    expected = run(reference, n)
    twin = make_fmu(package)
    twin.initialize(params)
    return reference, expected, twin, run(twin, k)


# ---------------------------------------------------------------------------- interface

def test_validate_fmu_reports_nothing(fmu_paths):
    assert validate_fmu(str(fmu_paths["AdaptiveCompoundController"])) == []


def test_model_description_matches_design(controller, piezo_stage):
    md = controller.md
    v = controller.variables
    assert md.variableNamingConvention == "structured"
    assert md.coSimulation.modelIdentifier == "AdaptiveCompoundController"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert md.coSimulation.canHandleVariableCommunicationStepSize and not md.coSimulation.canInterpolateInputs
    de = md.defaultExperiment
    assert (float(de.startTime), float(de.stopTime), float(de.stepSize)) == (0.0, 3.0, 0.0005)

    assert [n for n, x in v.items() if x.causality == "input"] == INPUTS
    assert [n for n, x in v.items() if x.causality == "output"] == \
        OUTPUTS + ["saturated"] + TIMING + SUP_OUTPUTS[:3] + ADAPT_OUTPUTS + SUP_OUTPUTS[3:] + ["est.fallbacks"]
    assert v["est.fallbacks"].type == "Integer"
    assert [v[n].type for n in SUP_OUTPUTS] == ["Integer", "Real", "Integer", "Integer", "Real"]
    assert [v[n].type for n in ADAPT_OUTPUTS] == ["Boolean", "Real"]
    assert v["est.noise"].unit == "um"
    assert v["saturated"].type == "Boolean"
    assert [v[n].type for n in TIMING] == ["Integer", "Real", "Integer", "Integer"]
    for name in ("y_ref", "y_meas", "y_preview", "q", "pred_error"):
        assert v[name].unit == "um" and v[name].displayUnit == "µm", name
    for name in ("v", "sat.v_min", "sat.v_max", "pi.v_max"):
        assert v[name].unit == "V", name
    for name in ("h", "t_preview", "t_meas", "loop_delay_time"):
        assert v[name].unit == "s", name

    # the nominal model uses the plant's names, types and defaults: one parameter set fits both
    shared = ["pi.m", "pi.v_max", "pi.w0"] + [f"pi.w[{j}]" for j in range(1, 17)] + \
        ["tf.a1", "tf.a2", "tf.b1", "tf.b2", "creep.k_c", "creep.alpha", "creep.exact", "h"]
    for name in shared:
        a, b = v[name], piezo_stage.variables[name]
        assert (a.causality, a.variability, a.type, a.unit, a.start) == \
            (b.causality, b.variability, b.type, b.unit, b.start), name
    # the drop-in defaults: loop delay detected, no feedthrough, one sample per step, the
    # observer pole 0.5, the robust update with integral action (docs/model.md, adaptation),
    # limits on at +-150 V, monitor on
    own = {"mv.delay": ("Integer", -1), "mv.feedthrough": ("Boolean", False),
           "mv.hold_inputs": ("Boolean", False), "mv.observer": ("Real", 0.5),
           "mv.lambda_u": ("Real", 0.0), "mv.integral": ("Real", 0.01), "rls.enabled": ("Boolean", True),
           "rls.forgetting": ("Real", 0.99), "rls.robust": ("Boolean", True),
           "rls.excitation": ("Real", 3.0), "rls.excitation_time": ("Real", 0.05),
           "rls.variance_max": ("Real", 0.004), "rls.p0_loop": ("Real", 0.01), "sat.enabled": ("Boolean", True),
           "sat.v_min": ("Real", -150.0), "sat.v_max": ("Real", 150.0),
           "monitor.pred_error_max": ("Real", 1.0), "monitor.divergence_samples": ("Integer", 200),
           "rls.zero_min": ("Real", 0.75), "rls.pole_min": ("Real", 0.0), "rls.fallback_ratio": ("Real", 2.0),
           "rls.fallback_window": ("Real", 0.5),
           **SUPERVISION}
    for name, (type_, start) in own.items():
        assert v[name].type == type_ and start_value(v[name]) == start, name
    for name in ("rls.p0", "rls.trace_max"):
        assert v[name].causality == "parameter" and v[name].type == "Real"
    params = {n for n, x in v.items() if x.causality == "parameter"}
    assert params == set(shared) | set(own) | {"rls.p0", "rls.trace_max"}

    # honest for the default: no output depends directly on an input
    deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.outputs}
    assert deps == {name: [] for name in OUTPUTS + ["saturated"] + TIMING + SUP_OUTPUTS + ADAPT_OUTPUTS
                    + ["est.fallbacks"]}


def test_start_values_in_the_binary_match_the_xml(controller, make_fmu):
    fmu = make_fmu(controller)
    fmu.setup()
    for name, var in controller.variables.items():
        if var.causality in ("parameter", "input"):
            assert fmu.get(name) == start_value(var), name


def _core_peek(params, y_ref, y_meas):
    """The core controller's sample-0 output for these inputs (harness.binding.core, cffi), in the
    order of OUTPUTS."""
    out = core.Controller(params).peek(y_ref, y_meas)
    return [out.v, out.q, out.a1, out.a2, out.b1, out.b2, out.pred_error]


OTHER_MODEL = {"mv.lambda_u": 0.05, "creep.k_c": 1.0497, "creep.alpha": -0.0085,
               "pi.w0": 0.35, "tf.b1": 0.61}


@pytest.mark.parametrize("params", [{}, {"mv.delay": 2, **OTHER_MODEL}])
def test_outputs_during_initialization_are_the_published_rest(controller, make_fmu, params):
    """Default timing: before the first step nothing is computed, so the outputs are the
    rest values whatever the inputs: v = q = pred_error = 0 and the estimates are the
    nominal tf.* (reference: the start values in the XML, or the overrides)."""
    fmu = make_fmu(controller)
    fmu.setup(params=params)
    nominal = [params.get(n, start_value(controller.variables[n])) for n in ("tf.a1", "tf.a2", "tf.b1", "tf.b2")]
    rest = [0.0, 0.0] + nominal + [0.0]
    assert fmu.get_reals(OUTPUTS) == rest
    for y_ref, y_meas in ((1.0, 0.0), (1.0, 0.3), (-2.5, 0.7)):
        fmu.set({"y_ref": y_ref, "y_meas": y_meas})
        assert fmu.get_reals(OUTPUTS) == rest, (y_ref, y_meas)
        assert fmu.get("saturated") is False


@pytest.mark.parametrize("params", [FEEDTHROUGH, {**FEEDTHROUGH, "mv.delay": 2, **OTHER_MODEL}])
def test_feedthrough_outputs_during_initialization(controller, make_fmu, params):
    """mv.feedthrough: in initialization mode the outputs are sample 0 of the current
    parameters and held inputs. Reference: harness.binding.core.Controller(params).peek(y_ref,
    y_meas) on the same C core through cffi, exact equality; at rest (zero inputs)
    v = q = 0 and the estimates are the nominal tf.* start values."""
    fmu = make_fmu(controller)
    fmu.setup(params=params)
    out = dict(zip(OUTPUTS, fmu.get_reals(OUTPUTS)))
    assert out["v"] == 0.0 and out["q"] == 0.0
    nominal = [params.get(n, start_value(controller.variables[n])) for n in ("tf.a1", "tf.a2", "tf.b1", "tf.b2")]
    assert [out[n] for n in ("est.a1", "est.a2", "est.b1", "est.b2")] == nominal
    assert list(out.values()) == _core_peek(params, 0.0, 0.0)
    for y_ref, y_meas in ((1.0, 0.0), (1.0, 0.3), (-2.5, 0.7)):
        fmu.set({"y_ref": y_ref, "y_meas": y_meas})
        outputs = fmu.get_reals(OUTPUTS)
        assert outputs == _core_peek(params, y_ref, y_meas), (y_ref, y_meas)
        assert outputs[0] != 0.0


def test_default_publishes_at_the_end_of_the_step(controller, make_fmu):
    """Default timing: the outputs read at t_(k+1) are the sample computed in the step from
    t_k with the inputs set before it, and setting other inputs afterwards changes nothing
    until the next step. Reference: the core controller stepped with the same inputs
    (harness.binding.core.Controller(...).step, cffi), exact equality, over 300 samples."""
    fmu = make_fmu(controller)
    fmu.initialize(OPEN_LOOP)
    twin = core.Controller(OPEN_LOOP)
    for k in range(300):
        fmu.set({"y_ref": y_d(k + 2), "y_meas": y_meas_of(k)})
        before = fmu.get_reals(OUTPUTS)
        fmu.step()
        out = twin.step(y_d(k + 2), y_meas_of(k))
        expected = [out.v, out.q, out.a1, out.a2, out.b1, out.b2, out.pred_error]
        assert fmu.get_reals(OUTPUTS) == expected
        assert fmu.get("saturated") is out.saturated
        fmu.set({"y_ref": -5.0, "y_meas": 3.0})          # not sampled before the next step
        assert fmu.get_reals(OUTPUTS) == expected
        if k:
            assert before != expected


# ---------------------------------------------------------------------------- direct feedthrough

def test_get_twice_gives_the_same_value_and_commits_nothing(controller, make_fmu):
    """mv.feedthrough: reading v computes the sample with the held inputs and commits
    nothing. Reference: a twin instance that is never probed, exact equality."""
    probed = make_fmu(controller)
    twin = make_fmu(controller)
    # open loop on synthetic data: the divergence monitor and the supervision have no loop to judge
    params = {**FEEDTHROUGH, "monitor.divergence_samples": 0, **OPEN_LOOP}
    probed.initialize(params)
    twin.initialize(params)
    for k in range(300):
        inputs = {"y_ref": y_d(k + 1), "y_meas": y_meas_of(k)}
        # probe with other inputs first: nothing may stick
        for other in (0.0, 5.0, -3.0):
            probed.set({"y_ref": other, "y_meas": other / 2})
            probed.get_reals(OUTPUTS)
        probed.set(inputs)
        twin.set(inputs)
        first = probed.get_reals(OUTPUTS)
        assert probed.get_reals(OUTPUTS) == first
        assert probed.get("v") == first[0]
        if k % 7 == 0:
            assert twin.get_reals(OUTPUTS) == first
        probed.step()
        twin.step()
    assert probed.get_reals(OUTPUTS) == twin.get_reals(OUTPUTS)


def test_model_structure_is_honest(controller, make_fmu):
    """Default: the XML says no output depends directly on an input; changing the inputs
    between steps must then change no output (exact equality)."""
    fmu = make_fmu(controller)
    fmu.initialize(OPEN_LOOP)
    run(fmu, 400)
    base = fmu.get_reals(OUTPUTS)
    for inputs in ({"y_ref": 3.0}, {"y_meas": -2.0}, {"y_ref": -7.0, "y_meas": 4.0}):
        fmu.set(inputs)
        assert fmu.get_reals(OUTPUTS) == base, inputs


def test_feedthrough_dependencies_are_what_the_option_documents(controller, make_fmu):
    """mv.feedthrough: v and q depend on y_ref and y_meas, the estimates and pred_error on
    y_meas only (the RLS update uses y_meas; y_ref enters only the MV law)."""
    fmu = make_fmu(controller)
    fmu.initialize({**FEEDTHROUGH, "sat.enabled": False, **OPEN_LOOP})     # no clipping to hide a change
    run(fmu, 400)
    fmu.set({"y_ref": y_d(401), "y_meas": y_meas_of(400)})
    base = dict(zip(OUTPUTS, fmu.get_reals(OUTPUTS)))
    fmu.set({"y_ref": y_d(401) + 0.5})
    ref_changed = dict(zip(OUTPUTS, fmu.get_reals(OUTPUTS)))
    fmu.set({"y_ref": y_d(401), "y_meas": y_meas_of(400) + 0.5})
    meas_changed = dict(zip(OUTPUTS, fmu.get_reals(OUTPUTS)))
    for name in OUTPUTS:
        if name in ("v", "q"):
            assert ref_changed[name] != base[name], name
        else:
            assert ref_changed[name] == base[name], name           # no dependency on y_ref
        assert meas_changed[name] != base[name], name               # all depend on y_meas


# ---------------------------------------------------------------------------- stepping

@pytest.mark.parametrize("exact", [False, True])
def test_many_samples_per_step_equal_one_sample_per_step(controller, make_fmu, exact):
    rng = np.random.default_rng(3)
    blocks = rng.integers(1, 30, size=50)
    fine = make_fmu(controller)
    coarse = make_fmu(controller)
    params = {"creep.exact": exact, "creep.alpha": -0.0085, "creep.k_c": 1.0497, "mv.hold_inputs": True,
              **OPEN_LOOP}
    fine.initialize(params)
    coarse.initialize(params)
    for i, n in enumerate(blocks):
        inputs = {"y_ref": 3.0 * math.sin(0.3 * i), "y_meas": 2.9 * math.sin(0.3 * i - 0.2)}
        fine.set(inputs)
        coarse.set(inputs)
        for _ in range(n):
            fine.step()
        coarse.step(int(n))
        assert fine.get_reals(OUTPUTS) == coarse.get_reals(OUTPUTS)


@pytest.mark.parametrize("exact", [False, True])
def test_state_save_restore_and_serialization_continue_bitwise(controller, make_fmu, exact):
    params = {"creep.exact": exact, "sat.enabled": True, "sat.v_min": -30.0, "sat.v_max": 30.0, **OPEN_LOOP}

    def carried(fresh):
        assert fresh.get("sat.enabled") is True and fresh.get("creep.exact") == exact

    assert_state_continues_bitwise(make_fmu, controller, params, run, 1200, 800, carried)


def _uninterrupted(controller, make_fmu, n, params=None):
    fmu = make_fmu(controller)
    fmu.initialize({**OPEN_LOOP, **(params or {})})
    return run(fmu, n)


# Every parameter away from its XML start value, all valid together (stable A,
# |tf.b2| <= 0.999 tf.b1, rls.trace_max >= 4 rls.p0, sat.v_min < sat.v_max).
NON_DEFAULT_PARAMETERS = {
    "pi.m": 12, "pi.v_max": 24.0, "pi.w0": 0.30,
    **{f"pi.w[{j}]": 0.001 * j for j in range(1, 17)},
    "tf.a1": -1.30, "tf.a2": 0.35, "tf.b1": 0.60, "tf.b2": -0.55,
    "creep.k_c": 1.0497, "creep.alpha": -0.0085, "creep.exact": True, "h": 0.001,
    "mv.delay": 2, "mv.feedthrough": True, "mv.lambda_u": 0.01, "mv.observer": 0.7,
    "mv.hold_inputs": True, "rls.enabled": False,
    "rls.forgetting": 0.98, "rls.p0": 2.0, "rls.trace_max": 50.0, "rls.robust": False,
    "rls.excitation": 2.0, "rls.excitation_time": 0.1, "rls.variance_max": 0.01, "rls.p0_loop": 0.5,
    "mv.integral": 0.02, "sat.enabled": False,
    "sat.v_min": -40.0, "sat.v_max": 60.0, "monitor.pred_error_max": 5.0,
    "monitor.divergence_samples": 0, "sup.enabled": False, "sup.gain_min": 0.1, "sup.gain_max": 8.0,
    "sup.window": 400, "sup.clip_time": 0.25, "sup.detect_time": 1.0, "sup.reaction": 1, "sup.ramp_time": 0.02,
    "sup.clip_error": 2.0, "mv.probe_max": 0.5, "sup.sensor_noise": 0.002,
    "rls.zero_min": 0.2, "rls.pole_min": 0.1, "rls.fallback_ratio": 3.0, "rls.fallback_window": 0.25,
}


@pytest.mark.parametrize("terminate_first", [False, True])
def test_reset_restores_every_start_value(controller, make_fmu, terminate_first):
    """fmi2Reset after a run with every parameter and input changed. Reference: the start
    values of modelDescription.xml as read by fmpy (every parameter and input, exact
    equality), and a fresh instance: its outputs in initialization mode and its 300-sample
    run must equal the reset instance's bitwise."""
    fmu, fresh = reset_after_a_non_default_run(make_fmu, controller, NON_DEFAULT_PARAMETERS, run, {"y_ref": 1.5, "y_meas": -0.5},
                                               terminate_first, OUTPUTS)
    for f in (fmu, fresh):                     # the same open-loop run on both: supervision off
        f.set(OPEN_LOOP)
    fmu.slave.exitInitializationMode()
    fresh.slave.exitInitializationMode()
    fmu.h, fmu.k, fresh.h, fresh.k = H, 0, H, 0
    assert np.array_equal(run(fmu, 300), run(fresh, 300))


def test_deserialize_refuses_garbage(controller, make_fmu):
    """Refused blobs leave the instance untouched. Reference: an uninterrupted 100-sample
    run, which the 50 samples before the refusals plus the 50 after must equal bitwise;
    the intact blob still restores into that continuation."""
    reference = _uninterrupted(controller, make_fmu, 100)
    fmu = make_fmu(controller)
    fmu.initialize(OPEN_LOOP)
    part = run(fmu, 50)
    state = fmu.slave.getFMUstate()
    blob = fmu.slave.serializeFMUstate(state)
    fmu.slave.freeFMUstate(state)
    corrupted = bytearray(blob)
    corrupted[200] ^= 1
    bad_version = bytearray(blob)
    bad_version[8] = 7
    assert_refused(lambda: fmu.slave.deSerializeFMUstate(bytes(corrupted)), fmu, "checksum")
    assert_refused(lambda: fmu.slave.deSerializeFMUstate(blob[: len(blob) // 2]), fmu, "truncated")
    assert_refused(lambda: fmu.slave.deSerializeFMUstate(b"\xff" * 64), fmu, "not a serialized")
    assert_refused(lambda: fmu.slave.deSerializeFMUstate(bytes(bad_version)), fmu, "format version")
    rest = run(fmu, 50, k0=50)
    assert np.array_equal(np.vstack([part, rest]), reference)
    # the intact blob still gives the same continuation
    restored = fmu.slave.deSerializeFMUstate(blob)
    fmu.slave.setFMUstate(restored)
    fmu.slave.freeFMUstate(restored)
    fmu.k = 50
    assert np.array_equal(run(fmu, 50, k0=50), reference[50:])


# ---------------------------------------------------------------------------- refusals

BAD_PARAMETERS = [
    ({"rls.forgetting": 0.0}, "rls.forgetting = 0 is out of range: valid range (0, 1]"),
    ({"rls.forgetting": 1.5}, "rls.forgetting = 1.5 is out of range: valid range (0, 1]"),
    ({"rls.forgetting": -0.1}, "rls.forgetting = -0.1 is out of range"),
    ({"rls.p0": -1.0}, "rls.p0 = -1 is out of range: valid range (0, inf)"),
    ({"rls.p0": 0.0}, "rls.p0 = 0 is out of range"),
    ({"rls.trace_max": 0.01}, "rls.trace_max = 0.01 is out of range"),
    ({"sat.enabled": True, "sat.v_min": 5.0, "sat.v_max": 5.0}, "sat.v_max = 5 is out of range: valid range finite, > sat.v_min"),
    ({"sat.enabled": True, "sat.v_min": 10.0, "sat.v_max": -10.0}, "sat.v_max = -10 is out of range"),
    ({"mv.delay": -2}, "mv.delay = -2 is out of range: valid range -1 (detect d in 1..3) or 0..8"),
    ({"mv.delay": 9}, "mv.delay = 9 is out of range: valid range -1 (detect d in 1..3) or 0..8"),
    ({"mv.observer": 1.0}, "mv.observer = 1 is out of range: valid range [0, 1)"),
    ({"mv.lambda_u": -1.0}, "mv.lambda_u = -1 is out of range"),
    ({"creep.alpha": 2.0}, "creep.alpha = 2 is out of range: valid range [-1, 1]"),
    ({"creep.k_c": 0.0}, "creep.k_c = 0 is out of range"),
    ({"pi.w0": 0.0}, "pi.w0 = 0 is out of range"),
    ({"pi.w[2]": -0.1}, "pi.w[2] = -0.1 is out of range: valid range [0, inf)"),
    ({"pi.m": 0}, "pi.m = 0 is out of range: valid range 1..16"),
    ({"pi.m": 17}, "pi.m = 17 is out of range"),
    ({"tf.a2": 1.2}, "tf.a2 = 1.2 is out of range"),
    ({"tf.b1": -0.5}, "tf.b1 = -0.5 is out of range"),
    ({"h": 0.0}, "h = 0 is out of range: valid range (0, inf)"),
]


@pytest.mark.parametrize("params,message", BAD_PARAMETERS)
def test_bad_parameter_refused_at_exit_initialization(controller, make_fmu, params, message):
    fmu = make_fmu(controller)
    fmu.setup(params=params)
    assert_refused(lambda: fmu.get("v"), fmu, message)
    assert_refused(fmu.slave.exitInitializationMode, fmu, "fmi2ExitInitializationMode", message)
    fmu.set({name: start_value(controller.variables[name]) for name in params})
    fmu.slave.exitInitializationMode()      # still in initialization mode: fixed and accepted
    fmu.h = H
    fmu.step()


def test_inconsistent_limits_are_fine_while_saturation_is_off(controller, make_fmu):
    """sat.v_min > sat.v_max is accepted while sat.enabled = false, and the limits are then
    ignored. Reference: a run without limits and the default limit values, bitwise equal;
    every control lies outside the empty interval the limits would allow, so any clipping
    would show."""
    reference = _uninterrupted(controller, make_fmu, 300, {"sat.enabled": False})
    fmu = make_fmu(controller)
    fmu.initialize({"sat.enabled": False, "sat.v_min": 10.0, "sat.v_max": -10.0, **OPEN_LOOP})
    assert (fmu.get("sat.v_min"), fmu.get("sat.v_max")) == (10.0, -10.0)
    out = run(fmu, 300)
    assert np.array_equal(out, reference)
    assert np.ptp(out[:, 0]) > 10.0                # v [V] really moves


def test_non_finite_input_refused_state_unchanged(controller, make_fmu):
    _, expected, fmu, part = reference_and_twin(controller, make_fmu, OPEN_LOOP, 60, 30)
    for name in ("y_ref", "y_meas"):
        for bad in (float("nan"), float("inf")):
            assert_refused(lambda: fmu.set({name: bad}), fmu, f"{name} = ", "valid range: finite values")
    rest = run(fmu, 30, k0=30)
    assert np.array_equal(np.vstack([part, rest]), expected)


def test_step_size_not_a_multiple_of_h_is_refused(controller, make_fmu):
    """Refused steps (not a multiple of h = 1 ms, or from the wrong time) change nothing.
    Reference: an uninterrupted run with h = 1 ms, which the samples before and after the
    refusals must equal bitwise; then a 3-sample step equals three 1-sample steps."""
    params = {"h": 0.001, "mv.hold_inputs": True, **OPEN_LOOP}
    reference, expected, fmu, part = reference_and_twin(controller, make_fmu, params, 40, 20)
    fmu.set({"y_ref": y_d(21), "y_meas": y_meas_of(20)})
    for bad in (0.0015, 0.0007, 0.001 * (1 + 1e-6), 0.3e-6, -0.001, float("nan")):
        assert_refused(lambda: fmu.slave.doStep(0.020, bad), fmu, "communicationStepSize", "h = 0.001")
    assert_refused(lambda: fmu.slave.doStep(0.019, 0.001), fmu, "does not match")
    assert_refused(lambda: fmu.slave.doStep(0.0203, 0.001), fmu, "does not match")
    rest = run(fmu, 20, k0=20)
    assert np.array_equal(np.vstack([part, rest]), expected)

    # many samples per step, then a wrong time, then the right one
    inputs = {"y_ref": 2.0, "y_meas": 1.5}
    for f in (reference, fmu):
        f.set(inputs)
    fmu.slave.doStep(0.040, 0.003)          # three samples
    assert_refused(lambda: fmu.slave.doStep(0.042, 0.001), fmu, "does not match")
    fmu.slave.doStep(0.043, 0.001)
    reference.step(4)
    assert fmu.get_reals(OUTPUTS) == reference.get_reals(OUTPUTS)


def test_illegal_call_sequences_return_error(controller, make_fmu):
    fmu = make_fmu(controller)
    assert_refused(lambda: fmu.slave.doStep(0.0, H), fmu, "illegal call sequence", "Instantiated")
    assert_refused(lambda: fmu.get("v"), fmu, "illegal call sequence")
    fmu.initialize()
    assert_refused(lambda: fmu.set({"rls.forgetting": 0.99}), fmu, "rls.forgetting", "fixed parameter")
    assert_refused(lambda: fmu.set({"v": 1.0}), fmu, "v is an output")
    assert_refused(fmu.slave.enterInitializationMode, fmu, "illegal call sequence", "StepComplete")
    fmu.step()
    fmu.slave.terminate()
    assert_refused(lambda: fmu.step(), fmu, "illegal call sequence", "Terminated")
    assert_refused(lambda: fmu.set({"y_ref": 1.0}), fmu, "illegal call sequence", "Terminated")
    assert_refused(fmu.slave.terminate, fmu, "illegal call sequence")
    fmu.get("v")                           # getters stay allowed after terminate


# ---------------------------------------------------------------------------- closed loop

@pytest.mark.parametrize("exact", [False, True])
@pytest.mark.parametrize("timing", ["default", "feedthrough"])
def test_closed_loop_with_the_nominal_plant_tracks_exactly(controller, piezo_stage, make_fmu, exact, timing):
    """Gauss-Seidel per sample in ModelStructure order. With the plant equal to the nominal
    model and the reference previewed d samples (d = 2 by default, d = 1 with
    mv.feedthrough and mv.delay = 0), the error is zero up to rounding (and the SOE creep
    approximation, far below a picometre)."""
    params = {"creep.exact": exact, **(FEEDTHROUGH if timing == "feedthrough" else {})}
    d = 1 if timing == "feedthrough" else 2
    plant = make_fmu(piezo_stage)
    ctrl = make_fmu(controller)
    plant.initialize({"creep.exact": exact})
    ctrl.initialize(params)
    errors, pred_errors = [], []
    for k in range(2000):
        y, y_meas = plant.get_reals(["y", "y_meas"])
        errors.append(y - y_d(k))
        ctrl.set({"y_ref": y_d(k + d), "y_meas": y_meas})
        v, pred_error = ctrl.get_reals(["v", "pred_error"])
        pred_errors.append(pred_error)
        plant.set({"v": v})
        plant.step()
        ctrl.step()
    errors = np.array(errors[1000:])
    assert np.sqrt(np.mean(errors ** 2)) < 1e-9            # um
    assert np.max(np.abs(pred_errors[10:])) < 1e-9


# ---------------------------------------------------------------------------- loud divergence

def _warnings(fmu):
    return [text for status, category, text in fmu.messages if status == 1]


def test_clipping_is_warned_once_and_counted_at_terminate(controller, make_fmu):
    """Limits +-5 V, open loop on y_meas_of, 400 samples. Reference: the saturated output
    read after every step (the samples whose v was clipped). The first doStep that clips
    returns fmi2Warning and logs one warning naming the limits and the time of the first
    clipped sample; no other step warns about clipping (with loggingOn = false); fmi2Terminate
    returns fmi2Warning with the count, equal to the number of clipped samples."""
    fmu = make_fmu(controller)
    fmu.initialize({"sat.v_min": -5.0, "sat.v_max": 5.0, "monitor.divergence_samples": 0, **OPEN_LOOP})
    statuses, clipped = [], []
    for k in range(400):
        fmu.set({"y_ref": y_d(k + 2), "y_meas": y_meas_of(k)})
        statuses.append(fmu.slave.fmi2DoStep(fmu.slave.component, fmu.time, H, 1))
        fmu.k += 1
        clipped.append(fmu.get("saturated"))
        if clipped[-1]:
            assert abs(fmu.get("v")) == 5.0
    first = clipped.index(True)
    clip_warnings = [w for w in _warnings(fmu) if "clipped" in w]
    assert len(clip_warnings) == 1
    assert "[-5, 5] V" in clip_warnings[0] and f"t = {first * H:.9g} s" in clip_warnings[0]
    # fmi2Warning exactly where something is said for the first time (clipping here; the
    # pred_error bound may be crossed once too), fmi2OK everywhere else
    assert statuses[first] == 1
    assert sum(1 for st in statuses if st == 1) == len(_warnings(fmu)) <= 2
    assert all(st in (0, 1) for st in statuses)
    assert fmu.slave.fmi2Terminate(fmu.slave.component) == 1
    summary = _warnings(fmu)[-1]
    assert f"of 400 samples, v was clipped in {sum(clipped)};" in summary
    assert sum(clipped) > 10


@pytest.mark.parametrize("supervision", [True, False])
def test_unstable_loop_fails_loudly(controller, piezo_stage, make_fmu, supervision):
    """The documented diverging configuration: plant with one extra input delay (tf.delay =
    1) and the controller in direct-feedthrough mode with d = 1 (mv.delay = 0), Gauss-Seidel
    ordered by ModelStructure, 10 Hz reference: the loop has d = 2. With the supervision (the
    default) the controller's doStep returns fmi2Error within 20 ms with a message that says
    y_meas answers v 2 samples later and how to set mv.delay (reference: the loop's delay by
    construction, 1 sample of G + 1 of tf.delay); without it (sup.enabled = false) the
    divergence monitor does within 0.2 s, naming its bound and window. Either way the FMU is
    then in state Error (getters allowed, doStep refused) and |v| never exceeded the +-150 V
    limits. The monitor's case runs the paper's law (PAPER_LAW): with the robust update's
    observer pole 0.5 this loop no longer diverges (a stable loop one sample off, 0.22 um rms
    behind a 10 um tone at 10 Hz), which only the supervision tells."""
    plant = make_fmu(piezo_stage)
    ctrl = make_fmu(controller)
    plant.initialize({"tf.delay": 1})
    ctrl.initialize({**FEEDTHROUGH, "sup.enabled": supervision, **({} if supervision else PAPER_LAW)})
    vmax = 0.0
    failed_at = None
    for k in range(400):
        ctrl.set({"y_ref": 10 * math.sin(2 * math.pi * 10 * (k + 1) * H), "y_meas": plant.get("y_meas")})
        v = ctrl.get("v")
        vmax = max(vmax, abs(v))
        plant.set({"v": v})
        plant.step()
        try:
            ctrl.step()
        except FMICallException as exc:
            assert exc.status == 3                  # fmi2Error
            failed_at = k
            break
    msg = " ".join(ctrl.errors())
    if supervision:
        assert failed_at is not None and failed_at * H < 0.02, failed_at
        assert "supervision stopped the loop (loop delay beyond the controller's)" in msg
        assert "y_meas answers v 2 samples later" in msg and "Set mv.delay = 1 (d = 2)" in msg
    else:
        assert failed_at is not None and failed_at * H < 0.2
        assert "the closed loop is unstable" in msg and "monitor.pred_error_max = 1 um" in msg
        assert "monitor.divergence_samples = 200" in msg
    assert "state Error" in msg
    assert vmax <= 150.0
    ctrl.get("v")                                   # getters stay allowed
    with pytest.raises(FMICallException):
        ctrl.step()


@pytest.mark.parametrize("exact", [False, True])
def test_a_refused_sample_rolls_the_whole_step_back(controller, make_fmu, exact):
    """The monitor's window (3 samples) completes at the third sample of a 5-sample doStep
    (open loop, y_meas held at 5 um against a model at rest: |pred_error| > 1 um from the
    first sample). The step fails and the FMU keeps the state of the step's start: every
    output equals the one read before the step, and a continuation from there equals a twin
    that never tried the step (bitwise). Reference for the sample count: the same inputs
    stepped one sample at a time fail exactly at the third sample."""
    params = {"monitor.divergence_samples": 3, "rls.enabled": False, "creep.exact": exact,
              "mv.hold_inputs": True, "mv.delay": 1, "mv.observer": 0.0}
    inputs = {"y_ref": 0.0, "y_meas": 5.0}
    single = make_fmu(controller)
    single.initialize(params)
    single.set(inputs)
    single.step()
    single.step()
    with pytest.raises(FMICallException):
        single.step()                                   # the third sample completes the window

    fmu, twin = make_fmu(controller), make_fmu(controller)
    for f in (fmu, twin):
        f.initialize(params)
        f.set({"y_ref": 1.0, "y_meas": 0.5})
        f.step()                                        # one ordinary sample first
    before = fmu.get_reals(OUTPUTS)
    fmu.set(inputs)
    with pytest.raises(FMICallException):
        fmu.slave.doStep(fmu.time, 5 * H)
    assert "the closed loop is unstable" in " ".join(fmu.errors())
    assert fmu.get_reals(OUTPUTS) == before             # rolled back to the start of the step
    state = fmu.slave.getFMUstate()                     # allowed in Error
    blob = fmu.slave.serializeFMUstate(state)
    fmu.slave.freeFMUstate(state)
    restored = twin.slave.deSerializeFMUstate(blob)
    twin.set(inputs)                                    # the held inputs are part of the state
    assert twin.get_reals(OUTPUTS) == before            # (and brings its cached outputs up to date)
    twin_state = twin.slave.getFMUstate()
    twin_blob = twin.slave.serializeFMUstate(twin_state)
    twin.slave.freeFMUstate(twin_state)
    twin.slave.freeFMUstate(restored)
    # the same model data bytes (sizeof(ModelData) at BLOB_OFF_DATA_SIZE, the image from
    # BLOB_HEADER; the mode at BLOB_OFF_MODE differs: Error 16 vs StepComplete 4). The exact-mode
    # history slots of the refused samples are written but not committed; the next step rewrites them.
    f = state_format()
    size = int.from_bytes(blob[f["BLOB_OFF_DATA_SIZE"]:f["BLOB_OFF_DATA_SIZE"] + 8], "little")
    assert blob[f["BLOB_OFF_MODE"]] == 16 and twin_blob[f["BLOB_OFF_MODE"]] == 4
    assert blob[f["BLOB_HEADER"]:f["BLOB_HEADER"] + size] == twin_blob[f["BLOB_HEADER"]:f["BLOB_HEADER"] + size]


# ---------------------------------------------------------------------------- timing (issue 21)

def _loop_with_stamps(controller, piezo_stage, make_fmu, *, t_meas_ahead=0, preview=4,
                      stamps=True, start_time=0.0, n=400, params=None, logging_on=False):
    """The exchange loop (read all outputs, set all inputs, step both) on the nominal plant
    with a 10 Hz reference, the controller's stamps as the FMUs would wire them: t_meas the
    plant's time plus t_meas_ahead samples (1: what a master that steps the plant first
    hands over), the stamped preview y_d(t_preview), t_preview = t_k + preview h. Returns
    the controller and its outputs (with the timing outputs) per sample."""
    ctrl, plant = make_fmu(controller, logging_on=logging_on), make_fmu(piezo_stage)
    ctrl.initialize(params, start_time=start_time)
    plant.initialize(None, start_time=start_time)
    rows = []
    for k in range(n):
        t_k = start_time + k * H
        v = ctrl.get("v")
        inputs = {"y_ref": y_d(k + 2), "y_meas": plant.get("y_meas")}
        if stamps:
            inputs.update({"y_preview": y_d(k + preview), "t_preview": t_k + preview * H,
                           "t_meas": plant.get("t_meas") + t_meas_ahead * H})
        ctrl.set(inputs)
        plant.set({"v": v})
        plant.step()
        ctrl.step()
        rows.append({name: ctrl.get(name) for name in TIMING + ["v"]})
    return ctrl, rows


def test_a_step_of_several_samples_is_refused_naming_the_step_and_h(controller, make_fmu):
    """Reference: the issue's requirement (a communication step that is not h is refused at
    the first doStep with a message naming the step and h, not a divergence later) and
    docs/cosimulation.md. OMSimulator's default 1e-3 s = 2 h: the first doStep fails with
    fmi2Error, the message names 0.001, 2 samples, h = 0.0005 and mv.hold_inputs, and
    nothing changed: a one-sample step afterwards gives the outputs of a twin that never
    tried (bitwise). With mv.hold_inputs = true the same step passes."""
    fmu, twin = make_fmu(controller), make_fmu(controller)
    for f in (fmu, twin):
        f.initialize()
        f.set({"y_ref": 1.0, "y_meas": 0.5})
    message = assert_refused(lambda: fmu.slave.doStep(0.0, 0.001), fmu, "communicationStepSize = 0.001",
                             "2 samples of h = 0.0005", "mv.hold_inputs = true")
    assert "state and time unchanged" in message
    fmu.step()
    twin.step()
    assert fmu.get_reals(OUTPUTS + ["loop_delay_time"]) == twin.get_reals(OUTPUTS + ["loop_delay_time"])
    held = make_fmu(controller)
    held.initialize({"mv.hold_inputs": True})
    held.slave.doStep(0.0, 0.001)


@pytest.mark.parametrize("t_meas_ahead, preview, lead", [(0, 4, 4), (1, 4, 3), (0, 6, 6)])
def test_time_stamps_set_the_preview_lead_and_the_measurement_offset(
        controller, piezo_stage, make_fmu, t_meas_ahead, preview, lead):
    """Reference: the stamps' definition (config.h, docs/cosimulation.md): meas_offset =
    (t_meas - t_k) / h, preview_lead = (t_preview - t_meas) / h once both stamps have
    advanced by h (from the second sample on), 0 before. Also with a start time of 10 s (the
    stamps are times, not sample counts)."""
    for start in (0.0, 10.0):
        _, rows = _loop_with_stamps(controller, piezo_stage, make_fmu, t_meas_ahead=t_meas_ahead,
                                    preview=preview, start_time=start, n=30)
        assert (rows[0]["preview_lead"], rows[0]["meas_offset"]) == (0, 0)
        assert {(r["preview_lead"], r["meas_offset"]) for r in rows[5:]} == {(lead, t_meas_ahead)}


def test_unconnected_stamps_keep_y_ref(controller, piezo_stage, make_fmu):
    """Reference: the core controller stepped with y_ref and y_meas only
    (harness.binding.core.Controller.step, today's inputs): an FMU whose new inputs are never set
    gives the same v at every sample bit for bit, reports preview_lead = meas_offset = 0,
    and still detects its loop delay (2 in this exchange loop)."""
    ctrl, rows = _loop_with_stamps(controller, piezo_stage, make_fmu, stamps=False, n=300)
    core_ctrl, core_plant = core.Controller(), core.Plant()
    published = 0.0
    for k in range(300):
        out = core_ctrl.step(y_d(k + 2), core_plant.output.y_meas)
        core_plant.step(published)
        published = out.v
        assert rows[k]["v"] == out.v, k
    assert {(r["preview_lead"], r["meas_offset"]) for r in rows} == {(0, 0)}
    assert rows[-1]["loop_delay"] == 2


def test_the_chosen_delay_and_its_time_are_outputs_and_an_event(controller, piezo_stage, make_fmu):
    """Reference: the core controller's own record of the choice (harness.binding.core: the first
    sample whose output delay is not 0) in the same loop. loop_delay is 0 with
    loop_delay_time = start time while detecting, then 2 with loop_delay_time = the time of
    that sample; with debug logging on, one logEvents message says
    'loop delay d = 2 chosen at t = ...'. A set mv.delay = 1 reports 2 from the start, with
    no such message."""
    ctrl, rows = _loop_with_stamps(controller, piezo_stage, make_fmu, n=50, logging_on=True)
    core_ctrl, core_plant = core.Controller(), core.Plant()
    published, delays = 0.0, []
    for k in range(50):
        out = core_ctrl.step_input(y_d(k + 2), core_plant.output.y_meas, y_d(k + 4), 4 if k else 0)
        core_plant.step(published)
        published = out.v
        delays.append(out.delay)
    chosen = delays.index(2)
    assert all(r["loop_delay"] == 0 and r["loop_delay_time"] == 0.0 for r in rows[:chosen])
    assert all(r["loop_delay"] == 2 and r["loop_delay_time"] == chosen * H for r in rows[chosen:])
    events = [text for status, category, text in ctrl.messages if category == "logEvents"
              and "loop delay d = 2 chosen" in text]
    assert len(events) == 1 and f"t = {chosen * H:.9g} s" in events[0]
    fixed, rows = _loop_with_stamps(controller, piezo_stage, make_fmu, n=20, params={"mv.delay": 1},
                                    logging_on=True)
    assert {(r["loop_delay"], r["loop_delay_time"]) for r in rows} == {(2, 0.0)}
    assert not [text for _, _, text in fixed.messages if "loop delay" in text]


def test_a_loop_that_rings_falls_back_in_one_sample_and_says_so(controller, piezo_stage, make_fmu):
    """The one-sample prediction fallback (docs/model.md, estimates with guarantees, item 3), as an
    importer sees it: PiezoStage and the controller (supervision off, as a sensor gain that
    changes would otherwise be its verdict), a 10 Hz, 4 um tone for 1.5 s behind a sensor of gain
    0.3 (the estimates learn b1 about 0.26), 0.1 s at rest with the gain back to 1 from 1.55 s,
    the tone again: the law drives the stage 2.3 times too hard and rings. Reference: the
    controller's own pred_error output, read after every step. One Warning says the fallback at
    a sample after the gain's return and before the tone resumes, with that sample's |pred_error|
    (beyond monitor.pred_error_max, 1 um) and the nominal model's error, smaller here; that step
    returns fmi2Warning, est.fallbacks counts it, no Error."""
    plant, ctrl = make_fmu(piezo_stage), make_fmu(controller)
    plant.initialize({"sensor.noise_rms": 0.001})
    ctrl.initialize({"sup.enabled": False})
    pred, status_at = {}, {}
    for k in range(3400):
        gain = 0.3 if k < 3100 else 1.0
        j = k + 2
        ctrl.set({"y_ref": 4.0 * math.sin(2 * math.pi * 10 * j * H) if (j < 3000 or j >= 3200) else 0.0,
                  "y_meas": plant.get("y_meas") * gain})
        status_at[k] = ctrl.slave.fmi2DoStep(ctrl.slave.component, ctrl.time, H, 1)
        ctrl.k += 1
        pred[k] = ctrl.get("pred_error")
        plant.set({"v": ctrl.get("v")})
        plant.step()
    said = [w for w in _warnings(ctrl) if "fell back to the nominal model" in w]
    assert len(said) == 1, said
    m = re.search(r"at t = ([0-9.]+) s: the adapted estimates mispredicted y_meas by ([0-9.e+-]+) um in one "
                  r"sample, beyond monitor.pred_error_max = 1 um and 5 times the measured noise of their "
                  r"predictions \(the nominal model: ([0-9.e+-]+) um\)", said[0])
    assert m, said[0]
    k = round(float(m.group(1)) / H)
    error, nominal = float(m.group(2)), float(m.group(3))
    assert 3100 < k < 3200 and error == float(f"{abs(pred[k]):.4g}") and error > 1.0
    assert nominal < error
    assert status_at[k] == 1 and all(st in (0, 1) for st in status_at.values())
    assert ctrl.get("est.fallbacks") >= 1
