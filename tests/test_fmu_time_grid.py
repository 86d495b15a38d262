"""The time grid every FMU keeps (t0 + k h): no-op steps, stopTime, irregular master steps.

Importers that step to input-file time points (fmusim with --input-file) issue steps of a
few 1e-17 s when an input time equals a grid point up to round-off; those must be no-ops,
not refusals. A step size of 0 or below is refused (FMI 2.0 and 3.0: communicationStepSize
> 0). A step past the stopTime of fmi2SetupExperiment is refused (FMI 2.0).
"""
import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

H = 0.0005
# model -> (input name, value of the input at sample k, outputs to compare)
DRIVES = {
    "PiezoStage": ("v", lambda k: 10 * math.sin(2 * math.pi * 7 * k * H) + 10, ["y", "y_meas", "x", "u"]),
    "AdaptiveCompoundController": ("y_meas", lambda k: 3 * math.sin(2 * math.pi * 5 * k * H),
                                   ["v", "q", "pred_error"]),
    "ReferenceSignal": (None, None, ["y_d", "y_ref"]),
}
PARAMS = {"ReferenceSignal": {"amplitude[1]": 10.0, "frequency[1]": 5.0},
          # open loop on synthetic data: no loop for the monitor or the supervision to judge
          "AdaptiveCompoundController": {"monitor.divergence_samples": 0, "sup.enabled": False}}


def do_step(fmu, t, step):
    """fmi2DoStep through the raw function, returning its status (fmpy's wrapper returns None
    and raises on fmi2Error)."""
    return fmu.slave.fmi2DoStep(fmu.slave.component, t, step, 1)


@pytest.fixture(params=list(DRIVES))
def package(request, _fmu_packages):
    return _fmu_packages[request.param]


def _model(package):
    return package.md.coSimulation.modelIdentifier


def _reference_run(package, make_fmu, n):
    """Exact steps of h, the input set before each: the outputs at every grid point."""
    name = _model(package)
    inp, drive, outs = DRIVES[name]
    fmu = make_fmu(package)
    fmu.initialize(PARAMS.get(name))
    rows = [fmu.get_reals(outs)]
    for k in range(n):
        if inp:
            fmu.set({inp: drive(k)})
        fmu.step()
        rows.append(fmu.get_reals(outs))
    return np.array(rows)


def test_steps_that_round_to_no_sample_are_no_ops(package, make_fmu):
    """Reference: the exact-step run. doStep(t, H) with H in {1e-20 s, 5.6e-17 s, 1e-10 h}
    returns fmi2OK and changes nothing, and H = 0 or -5.6e-17 s returns fmi2Error (the
    standard asks for a step size > 0) and changes nothing either: interleaved before every
    sample of a 200-sample run, the outputs at every grid point equal the reference bitwise."""
    name = _model(package)
    inp, drive, outs = DRIVES[name]
    want = _reference_run(package, make_fmu, 200)
    fmu = make_fmu(package)
    fmu.initialize(PARAMS.get(name))
    got = [fmu.get_reals(outs)]
    for k in range(200):
        if inp:
            fmu.set({inp: drive(k)})
        for tiny in (1e-20, 5.6e-17, 1e-10 * H):
            assert do_step(fmu, fmu.time, tiny) == 0          # fmi2OK
        for not_positive in (0.0, -5.6e-17):
            with pytest.raises(FMICallException) as refused:
                do_step(fmu, fmu.time, not_positive)
            assert refused.value.status == 3                  # fmi2Error
        fmu.step()
        got.append(fmu.get_reals(outs))
    assert np.array_equal(np.array(got), want)
    assert "communicationStepSize = 0 refused: the step size must be > 0" in fmu.errors()[0]


def test_fmusim_like_irregular_time_points(package, make_fmu):
    """An fmusim-like master: it steps from one time point to the next of the union of the
    output grid (k h) and input-file time points that equal grid points up to round-off
    (k h +- 5.6e-17 s, k h + 1.1e-16 s), passing its own point as currentCommunicationPoint
    and setting the input at each input point. Reference: the exact-step run; the outputs at
    every grid point equal it bitwise, and no call is refused."""
    name = _model(package)
    inp, drive, outs = DRIVES[name]
    n = 300
    want = _reference_run(package, make_fmu, n)
    rng = np.random.default_rng(7)
    points = {k * H: k for k in range(n + 1)}
    for k in rng.choice(np.arange(1, n), size=80, replace=False):
        points[k * H + rng.choice([5.6e-17, -5.6e-17, 1.1e-16])] = int(k)
    times = sorted(points)
    fmu = make_fmu(package)
    fmu.initialize(PARAMS.get(name))
    got = {0: fmu.get_reals(outs)}
    for t, t_next in zip(times[:-1], times[1:]):
        k = points[t]
        if inp:
            fmu.set({inp: drive(k)})
        status = do_step(fmu, t, t_next - t)
        assert status in (0, 1), (t, t_next - t)            # fmi2OK or fmi2Warning
        k_next = points[t_next]
        if abs(t_next - k_next * H) == 0.0:
            got[k_next] = fmu.get_reals(outs)
    assert np.array_equal(np.array([got[k] for k in range(n + 1)]), want)


def test_stop_time_is_enforced(package, make_fmu):
    """fmi2SetupExperiment(stopTime = 20.2 h): steps up to t = 20 h pass; a step of h to
    21 h is refused (fmi2Error, message naming stopTime), so is a 5-sample step from 18 h;
    the refusals change nothing (outputs equal the reference run bitwise) and the FMU stays
    usable up to its stop time. Without a stopTime the same steps pass."""
    name = _model(package)
    inp, drive, outs = DRIVES[name]
    want = _reference_run(package, make_fmu, 21)
    fmu = make_fmu(package)
    fmu.slave.setupExperiment(startTime=0.0, stopTime=20.2 * H)
    if PARAMS.get(name):
        fmu.set(PARAMS[name])
    fmu.slave.enterInitializationMode()
    fmu.slave.exitInitializationMode()
    fmu.h, fmu.k = H, 0
    for k in range(18):
        if inp:
            fmu.set({inp: drive(k)})
        fmu.step()
    fmu.clear_messages()
    with pytest.raises(FMICallException):
        fmu.slave.doStep(fmu.time, 5 * H)
    assert "passes stopTime" in fmu.last_error()
    for k in (18, 19):
        if inp:
            fmu.set({inp: drive(k)})
        fmu.step()
    assert np.array_equal(np.array(fmu.get_reals(outs)), want[20])
    with pytest.raises(FMICallException):
        fmu.slave.doStep(fmu.time, H)
    assert "passes stopTime" in fmu.last_error() and "t = 0.0105" in fmu.last_error()
    assert np.array_equal(np.array(fmu.get_reals(outs)), want[20])
    # the same run without a stop time goes on
    free = make_fmu(package)
    free.initialize(PARAMS.get(name))
    for k in range(21):
        if inp:
            free.set({inp: drive(k)})
        free.step()
    assert np.array_equal(np.array(free.get_reals(outs)), want[21])
