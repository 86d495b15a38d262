"""Reference results inside the FMUs (FMI-LS-REF 1.0.0-alpha.1) and their re-simulation.

(a) the manifest follows the layered standard: root <fmiReferences> with the fixed fmi-ls
    name, version and description; every <Related> has a valid role and points to a file in
    the FMU; the experiments file has start, stop, step, tolerance, and its files exist;
(b) fmpy re-simulates each FMU from those files alone and matches the references:
    fmpy.util.validate_result finds no outlier, and every sample is within the experiment's
    tolerance |y - y_ref| <= tol (1 + |y_ref|) (on this platform: bit for bit); a parameter
    changed by a tiny amount fails the same comparison, so it can fail;
(c) the references are right, not only self-consistent. Independent references:
    PiezoStage u, x, y against tests/numpy_reference.py (the model written again in NumPy,
    exact creep sum), its y_meas against the sensor's definition; ReferenceSignal against the
    closed form; the controller's v, fed to the NumPy plant, reproduces the y_meas it was
    given within the sensor noise (the closed loop the stimuli were recorded from).
"""

from __future__ import annotations

import re
import zipfile

import numpy as np
import pytest

import fmpy
from fmpy.util import validate_result

import numpy_reference as ref
from fmu_experiments import LS, LS_REF, load_experiment, manifest, simulate_experiment, worst_violation
from conftest import FMU_NAMES

NAMES = FMU_NAMES
ROLE = re.compile(r"(document|requirement|specification|model|parameter|system|testcase|"
                  r"experiment(/(smoke-test|validation|uncertainty-analysis))?|result|method|"
                  r"rationale|report|request|delivery|configuration|signature|"
                  r"serialized-state(/.*)?|meta-data|other)")


def _resolve(source):
    """Path inside the FMU of a manifest source (relative to the manifest's folder)."""
    parts = (LS_REF + source).split("/")
    out = []
    for part in parts:
        if part == "..":
            out.pop()
        elif part and part != ".":
            out.append(part)
    return "/".join(out)


# ---------------------------------------------------------------------------------------
# (a) structure

@pytest.mark.parametrize("name", NAMES)
def test_manifest_follows_fmi_ls_ref(fmu_paths, name):
    root = manifest(fmu_paths[name])
    assert root.tag == "fmiReferences"
    assert root.get(f"{LS}fmi-ls-name") == "org.fmi-standard.fmi-ls-ref"
    assert root.get(f"{LS}fmi-ls-version") == "1.0.0-alpha.1"
    assert root.get(f"{LS}fmi-ls-description") == \
        "Layered Standard providing information on related files included in an FMU."
    related = list(root)
    assert related and all(r.tag == "Related" for r in related)
    with zipfile.ZipFile(fmu_paths[name]) as zf:
        names = set(zf.namelist())
    roles = set()
    for r in related:
        assert ROLE.fullmatch(r.get("role")), r.get("role")
        assert _resolve(r.get("source")) in names, r.get("source")
        assert r.get("type") and r.get("description")
        roles.add(r.get("role"))
    assert {"experiment/validation", "result", "document"} <= roles


@pytest.mark.parametrize("name", NAMES)
def test_experiment_is_complete(fmu_paths, name):
    exp = load_experiment(fmu_paths[name])
    assert (exp.start, exp.stop, exp.step) == (0.0, 0.5, 0.0005) and 0 < exp.tolerance <= 1e-9
    n = exp.steps + 1
    assert np.array_equal(exp.reference["time"], np.arange(n) * exp.step)
    # stimuli for exactly the inputs the experiment reads: an FMU with such inputs has them, one
    # without has none (PiezoStageClosedLoop reads its y_d only with use_internal_reference =
    # false; the default, true, follows its internal reference; no experiment has a safe state,
    # so the fault reset sup.reset keeps its start value, false)
    inputs = {v for v, var in exp.variables.items() if var.causality == "input"} - {"sup.reset"}
    internal = exp.variables.get("use_internal_reference")
    if internal is not None and str(exp.parameters.get("use_internal_reference", internal.start)).lower() == "true":
        inputs.discard("y_d")
    if inputs:
        assert exp.stimuli is not None, f"{name} has inputs {sorted(inputs)} but no stimuli"
        assert np.array_equal(exp.stimuli["time"], exp.reference["time"])
        assert set(exp.stimuli.dtype.names[1:]) == inputs
    else:
        assert exp.stimuli is None
    assert all(exp.variables[o].causality == "output" for o in exp.outputs)
    assert set(exp.outputs) == {v for v, var in exp.variables.items() if var.causality == "output"}


# ---------------------------------------------------------------------------------------
# (b) re-simulation with fmpy

def _simulate(fmu, exp, parameters=None):
    return simulate_experiment(fmu, exp, parameters)


#: a change too small to see in a plot that the comparison must still catch
PERTURBATION = {"PiezoStage": ("creep.alpha", 1e-6), "AdaptiveCompoundController": ("rls.forgetting", -1e-6),
                "ReferenceSignal": ("phase[1]", 1e-6), "PiezoStageClosedLoop": ("creep.alpha", 1e-6)}


@pytest.mark.parametrize("name", NAMES)
def test_fmpy_resimulation_matches_the_references(fmu_paths, name):
    exp = load_experiment(fmu_paths[name])
    result = _simulate(fmu_paths[name], exp)
    assert np.array_equal(result["time"], exp.reference["time"])
    assert validate_result(result, exp.reference) == 0
    worst = worst_violation(result, exp)
    print(f"\n{name}: worst |y - y_ref| / (tol (1 + |y_ref|)) = {worst:.3g}")
    assert worst <= 1.0
    for output in exp.outputs:       # same platform as the reference: equal
        assert np.array_equal(np.asarray(result[output], dtype=float), exp.reference[output]), output

    parameter, delta = PERTURBATION[name]
    changed = dict(exp.parameters)
    changed[parameter] = changed.get(parameter, float(exp.variables[parameter].start)) + delta
    assert worst_violation(_simulate(fmu_paths[name], exp, changed), exp) > 1.0


# ---------------------------------------------------------------------------------------
# (c) the references against independent computations

def _numpy_plant_params(values):
    p = ref.plant_params()
    w = list(p["pi.w"]) + [0.0] * (16 - len(p["pi.w"]))
    for key, value in values.items():
        m = re.fullmatch(r"pi\.w\[(\d+)\]", key)
        if m:
            w[int(m.group(1)) - 1] = value
        else:
            p[key] = value
    p["pi.w"] = w
    return p


def test_piezostage_references_against_numpy_model(fmu_paths):
    """Reference: tests/numpy_reference.plant_simulate (PI, lfilter-style recursion, exact
    G-L sum). u to 1e-12 um, x to 1e-12 um, y to 1e-8 um (the FMU's default creep is the
    constant-cost sum of exponentials); y_meas is y + noise quantized to the 2 nm grid, the
    noise with 1 nm rms (within 10 % over 1001 samples)."""
    exp = load_experiment(fmu_paths["PiezoStage"])
    p = _numpy_plant_params(exp.parameters)
    v = exp.stimuli["v"][:-1]
    model = ref.plant_simulate(np.concatenate([v, [0.0]]), p)
    r = exp.reference
    assert np.max(np.abs(r["u"] - model["u"])) < 1e-12
    assert np.max(np.abs(r["x"] - model["x"])) < 1e-12
    assert np.max(np.abs(r["y"] - model["y"])) < 1e-8
    assert np.ptp(r["y"]) > 5.0                                   # the stage moved microns
    res = exp.parameters["sensor.resolution"]
    steps = r["y_meas"] / res
    assert np.max(np.abs(steps - np.round(steps))) < 1e-6        # on the 2 nm grid
    noise = r["y_meas"] - r["y"]
    assert 0.9e-3 < np.std(noise) < 1.1 * np.sqrt(1e-6 + res ** 2 / 12)


def test_reference_signal_references_against_closed_form(fmu_paths):
    """Reference: y_d(t) = sum 10 sin(2 pi f t), f = 1, 5, 10 Hz, y_ref(t) = y_d(t + 2 h)."""
    exp = load_experiment(fmu_paths["ReferenceSignal"])
    t = exp.reference["time"]
    p = exp.parameters
    lead = p["lead"] * exp.step

    def y_d(tt):
        return sum(p[f"amplitude[{i}]"] * np.sin(2 * np.pi * p[f"frequency[{i}]"] * tt)
                   for i in (1, 2, 3))

    assert np.max(np.abs(exp.reference["y_d"] - y_d(t))) < 1e-12
    assert np.max(np.abs(exp.reference["y_ref"] - y_d(t + lead))) < 1e-12


def test_controller_references_close_the_loop_they_came_from(fmu_paths):
    """Reference: the NumPy plant (tests/numpy_reference.py) with the mismatch parameters
    (harness/scenarios/mismatch.toml), driven by the controller's reference v as the
    experiment's loop applied it: the v published at t_(k+1), computed from the inputs of t_k,
    acts over [t_k, t_(k+1)) (a master passing the post-step output, d = 1). Its displacement
    must reproduce the y_meas the controller was given, within the sensor (2 nm steps,
    1 nm rms), and track y_ref one sample later to a few nm once the RLS has settled."""
    from harness.scenarios import load_scenarios

    exp = load_experiment(fmu_paths["AdaptiveCompoundController"])
    assert exp.parameters == {"mv.delay": 0}
    plant = _numpy_plant_params(load_scenarios()["mismatch_1_5_10hz"].plant)
    v = exp.reference["v"]
    y = ref.plant_simulate(v[1:], plant)["y"]                 # y(0..n-1)
    y_meas = exp.stimuli["y_meas"][:-1]
    assert np.ptp(v) > 10 and np.ptp(y) > 20                  # a real trajectory
    error = y_meas - y
    assert np.max(np.abs(error)) < 6e-3 and np.std(error) < 1.5e-3
    tracking = y[400:] - exp.stimuli["y_ref"][399:-2]          # y(k) vs y_d(k) = y_ref(k - 1)
    rms = np.sqrt(np.mean(tracking ** 2))
    print(f"\ncontroller reference: tracking error after 0.2 s, rms {rms * 1e3:.2f} nm")
    assert rms < 0.005
    assert np.ptp(exp.reference["est.b1"]) > 1e-4             # the RLS adapted
    assert not exp.reference["saturated"].any()


def test_controller_replay_is_well_conditioned(fmu_paths):
    """Why the controller's experiment runs d = 1: its replay must not amplify a last-bit
    change of an input beyond the tolerance (here 1e-15 relative on y_meas: the outputs move
    by far less than tol (1 + |y_ref|)). Reference: the unperturbed re-simulation."""
    exp = load_experiment(fmu_paths["AdaptiveCompoundController"])
    stimuli = exp.stimuli.copy()
    stimuli["y_meas"] = stimuli["y_meas"] * (1 + 1e-15)
    result = fmpy.simulate_fmu(str(fmu_paths["AdaptiveCompoundController"]), stop_time=exp.stop,
                               output_interval=exp.step, input=stimuli,
                               start_values=exp.parameters, output=exp.outputs)
    worst = worst_violation(result, exp)
    print(f"\ncontroller replay, inputs changed by 1e-15: {worst:.2g} of the tolerance")
    assert 0 < worst < 0.05
