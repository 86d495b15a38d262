"""The FMI standard at its edges, as a user of the FMUs sees it (issue 23), in both editions.

- An input beyond its declared range: PiezoStage's ``v`` is declared [-150, 150] V. The FMI
  (3.0, "Handling min/max Range Violations") says the FMU should not rely on a master keeping
  to min/max, and a master may pass a value slightly beyond it; an amplifier cannot deliver
  more than its rating. So the stage applies ``v`` clamped to the range, warns once and counts
  the clamped samples at terminate. Reference: the same run with ``v`` at the bound.
- The work of one doStep is bounded: a step longer than the documented bound (docs/fmus.md)
  is refused at once with a message naming the bound; the longest step it allows passes.
  Reference: docs/fmus.md's figures and the closed form of the exact creep's work.
- nValues without value references is refused (FMI 3.0); fmi3FreeFMUState(NULL) is ignored.
- The controller's warning with ``monitor.divergence_samples = 0`` says the loop is never
  declared unstable (0 switches the verdict off), not "after 0 consecutive samples".

The C suites (tests/c/fmu_negative.c, built as fmu_negative and fmu3_negative, group "edges")
check the same at the level of single calls, for all three FMUs, under valgrind.
"""
import contextlib
import ctypes
import re
import shutil

import numpy as np
import pytest

import fmpy
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

from conftest import REPO, assert_refused

H = 0.0005
FMI2_WARNING = 1


def _range_of_v(path):
    """(min, max) of PiezoStage's input v, read from the FMU's model description."""
    md = fmpy.read_model_description(str(path))
    v = next(var for var in md.modelVariables if var.name == "v")
    assert v.causality == "input"
    return float(v.min), float(v.max)


def _simulate_plant(path, fmi_version, v, n=100):
    """fmpy.simulate_fmu of the plant for n samples with v held; (outputs, messages)."""
    messages = []
    if fmi_version == 2:
        def logger(env, instance, status, category, message):
            messages.append((status, message.decode()))
    else:
        def logger(env, status, category, message):
            messages.append((status, message.decode()))
    signal = np.array([(0.0, v), (n * H, v)], dtype=[("time", np.float64), ("v", np.float64)])
    result = fmpy.simulate_fmu(str(path), stop_time=n * H, output_interval=H, input=signal,
                               output=["y", "y_meas", "u", "x"], logger=logger)
    outputs = np.column_stack([result[name] for name in ("y", "y_meas", "u", "x")])
    return outputs, messages


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("beyond", ["max + 1.5", "min - 1.5", "1e300"])
def test_a_voltage_beyond_the_declared_range_is_clamped(fmu_paths, fmu3_paths, fmi_version, beyond):
    """fmpy run, 100 samples, v held beyond its declared range. Reference: the run with v at
    the nearest bound. Every output at every sample equals the reference bitwise; the run logs
    one warning naming the range and the applied bound, and the terminate call the count of
    clamped samples (100 of 100); the run at the bound logs no warning."""
    path = (fmu_paths if fmi_version == 2 else fmu3_paths)["PiezoStage"]
    v_min, v_max = _range_of_v(path)
    assert (v_min, v_max) == (-150.0, 150.0)        # the rated range the docs name
    value = {"max + 1.5": v_max + 1.5, "min - 1.5": v_min - 1.5, "1e300": 1e300}[beyond]
    bound = v_max if value > v_max else v_min
    clamped, messages = _simulate_plant(path, fmi_version, value)
    at_bound, quiet = _simulate_plant(path, fmi_version, bound)
    assert np.array_equal(clamped, at_bound)
    assert np.ptp(at_bound[:, 0]) > 1.0              # the stage really moved (um)
    assert [m for m in quiet if m[0] >= FMI2_WARNING] == []
    warnings = [text for status, text in messages if status == FMI2_WARNING]
    assert len(warnings) == 2, messages
    assert f"is outside its declared range [{v_min:g}, {v_max:g}] V: the stage applies {bound:g} V" in warnings[0]
    assert f"clamped to its declared range [{v_min:g}, {v_max:g}] V in 100 of 100 samples" in warnings[1]


def test_a_voltage_at_the_bound_is_not_clamped(piezo_stage, make_fmu):
    """v = 150 V exactly and 149.999999 V: no warning, nothing counted (fmi2Terminate returns
    fmi2OK); v = 150.000001 V: clamped (the bound is inclusive, as FMI's min/max)."""
    for value, clamped in ((150.0, False), (149.999999, False), (-150.0, False), (150.000001, True)):
        fmu = make_fmu(piezo_stage)
        fmu.initialize()
        fmu.set({"v": value})
        status = fmu.slave.fmi2DoStep(fmu.slave.component, 0.0, H, 1)
        assert status == (FMI2_WARNING if clamped else 0), value
        assert fmu.slave.fmi2Terminate(fmu.slave.component) == (FMI2_WARNING if clamped else 0), value


# ---------------------------------------------------------------------------------------
# the bound on the work of one doStep

def _documented_bounds():
    """(samples, creep terms) as docs/fmus.md states them."""
    text = (REPO / "docs" / "fmus.md").read_text()
    samples = re.search(r"at most ([\d,]+) samples", text)
    terms = re.search(r"at most ([\d,]+) terms", text)
    assert samples and terms, "docs/fmus.md states the bounds of one doStep"
    return int(samples.group(1).replace(",", "")), int(terms.group(1).replace(",", ""))


def _creep_terms(n, a):
    """Terms the exact creep sums over n samples whose first sums a: a + ... + (a + n - 1)."""
    return n * a + n * (n - 1) // 2


#: what lets each FMU take a step of many samples: the controller holds its inputs over one only
#: when told to (and its monitor has no loop to judge); the closed loop takes any step
# the controller holds its inputs over a step of several samples only when told to (open loop:
# no monitor, no supervision)
LONG_STEP_PARAMS = {"PiezoStage": {},
                    "AdaptiveCompoundController": {"monitor.divergence_samples": 0, "mv.hold_inputs": True,
                                                   "sup.enabled": False},
                    "PiezoStageClosedLoop": {}}


@pytest.mark.parametrize("name", list(LONG_STEP_PARAMS))
def test_the_longest_step_passes_and_one_sample_more_is_refused(_fmu_packages, make_fmu, name):
    """Reference: the bound docs/fmus.md states. A step of exactly that many samples passes (it
    ends at t = bound h); one of a sample more is refused, naming the bound, and changes
    nothing (the time stays); so is a step of 1e9 s."""
    samples, _ = _documented_bounds()
    fmu = make_fmu(_fmu_packages[name])
    fmu.initialize(LONG_STEP_PARAMS[name] or None)
    for n in (samples + 1, round(1e9 / H)):
        assert_refused(lambda: fmu.slave.doStep(0.0, n * H), fmu,
                       f" is {n} samples of h = 0.0005: refused, one doStep computes at most {samples} samples",
                       "state and time unchanged")
        assert fmu.slave.getRealStatus(2) == 0.0                  # fmi2LastSuccessfulTime
    fmu.step(samples)
    assert fmu.slave.getRealStatus(2) == samples * H


@pytest.mark.parametrize("name", list(LONG_STEP_PARAMS))
def test_with_exact_creep_the_longest_step_it_names_passes(_fmu_packages, make_fmu, name):
    """creep.exact = true: the sample at k sums its k + 1 past values. After 10 samples a step
    of the documented sample bound is refused, naming the bound on the terms (docs/fmus.md)
    and the longest step that passes from there; that step is the longest whose sums stay
    within the bound (closed form), it passes, and one sample more is refused."""
    samples, terms = _documented_bounds()
    params = {"creep.exact": True, **LONG_STEP_PARAMS[name]}
    fmu = make_fmu(_fmu_packages[name])
    fmu.initialize(params)
    fmu.step(10)
    message = assert_refused(lambda: fmu.slave.doStep(fmu.time, samples * H), fmu,
                             f"one doStep sums at most {terms} (about a second of work)")
    longest = int(re.search(r"a step of at most (\d+) samples", message).group(1))
    assert _creep_terms(longest, 11) <= terms < _creep_terms(longest + 1, 11)
    assert_refused(lambda: fmu.slave.doStep(fmu.time, (longest + 1) * H), fmu,
                   f"one doStep sums at most {terms} (about a second of work)")
    fmu.step(longest)
    assert fmu.slave.getRealStatus(2) == pytest.approx((10 + longest) * H, rel=1e-15)


@contextlib.contextmanager
def _fmi3_in_step_mode(path, name):
    """An FMI 3.0 instance in Step Mode at t0 = 0 and the texts it logs; freed and its folder
    removed afterwards."""
    unzipdir = fmpy.extract(str(path))
    md = fmpy.read_model_description(str(path))
    messages = []
    slave = FMU3Slave(guid=md.instantiationToken, unzipDirectory=unzipdir, modelIdentifier=name,
                      instanceName="edges")
    slave.instantiate(logMessage=lambda env, status, category, message: messages.append(message.decode()))
    try:
        slave.enterInitializationMode(startTime=0.0)
        slave.exitInitializationMode()
        yield slave, messages
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(unzipdir, ignore_errors=True)


def test_fmi3_refuses_a_step_beyond_the_bound_without_returning_early(fmu3_paths):
    """FMI 3.0: no early return; a step of 1e9 s in Step Mode is refused at once naming the
    bound, lastSuccessfulTime stays at the current time, and the instance runs on."""
    samples, _ = _documented_bounds()
    with _fmi3_in_step_mode(fmu3_paths["ReferenceSignal"], "ReferenceSignal") as (slave, messages):
        slave.doStep(0.0, 4 * H)
        messages.clear()
        with pytest.raises(FMICallException) as info:
            slave.doStep(4 * H, 1e9)
        assert info.value.status == 3 and len(messages) == 1, messages
        assert f"one doStep computes at most {samples} samples" in messages[-1]
        *_, last_successful_time = slave.doStep(4 * H, H)
        assert last_successful_time == 5 * H


# ---------------------------------------------------------------------------------------
# value counts, FMU states, the monitor's message

def test_fmi3_nvalues_without_value_references_is_refused(fmu3_paths):
    """fmi3SetFloat64 with no value reference and one value (nValues = 1) is refused with a
    message naming nValues; with no value either it is a no-op; fmi3FreeFMUState(NULL) is
    ignored (fmi3OK)."""
    with _fmi3_in_step_mode(fmu3_paths["PiezoStage"], "PiezoStage") as (slave, messages):
        messages.clear()
        with pytest.raises(FMICallException) as info:
            slave.setFloat64([], [1.0])
        assert info.value.status == 3 and len(messages) == 1, messages
        assert "nValues = 1, but no value reference is given" in messages[-1]
        slave.setFloat64([], [])
        free_state = slave.dll.fmi3FreeFMUState
        free_state.argtypes, free_state.restype = [ctypes.c_void_p, ctypes.c_void_p], ctypes.c_int
        assert free_state(slave.component, None) == 0              # fmi3OK


@pytest.mark.parametrize("window", [0, 200])
def test_the_monitor_warning_says_what_divergence_samples_means(controller, make_fmu, window):
    """|pred_error| above monitor.pred_error_max = 0.001 um (y_meas = 5 um, the model predicts
    0): the warning names the window and the share of it that stops the loop (PIEZO_MONITOR_SHARE_*)
    when there is one, and says the loop is never declared unstable when
    monitor.divergence_samples = 0 (no "0 consecutive samples")."""
    fmu = make_fmu(controller)
    fmu.initialize({"monitor.divergence_samples": window, "monitor.pred_error_max": 0.001,
                    "mv.hold_inputs": True, "sup.enabled": False})
    fmu.set({"y_meas": 5.0})
    fmu.step(20)
    warning = next(text for status, _, text in fmu.messages if status == FMI2_WARNING and "pred_error" in text)
    if window:
        assert (f"monitor.divergence_samples = {window} consecutive samples, or in 25 % of the last {window}, "
                "the loop is declared unstable") in warning
    else:
        assert "With monitor.divergence_samples = 0 the loop is never declared unstable" in warning
        assert "0 consecutive" not in warning
