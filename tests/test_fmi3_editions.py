"""The FMI 3.0 Co-Simulation editions (build/fmus/fmi3/) of the three FMUs.

Both editions compile the same model code; what differs is the FMI layer (fmi3_glue.c beside
fmi2_glue.c over fmu_glue_core.c) and the model description (arrays ``pi.w``, ``amplitude``,
``frequency``, ``phase`` where FMI 2.0 has numbered scalars). So the FMI 2.0 edition, which
the rest of the suite holds against scipy, NumPy and the paper, is the reference here:

(a) fmpy.validation.validate_fmu (FMI 3.0 schema and fmpy's own checks) reports nothing;
    the archive has the FMI 3.0 platform tuples, sources with buildDescription.xml,
    documentation and licence;
(b) every variable of the FMI 2.0 edition exists in the FMI 3.0 edition (as a scalar or as
    an array element) with the same causality, variability, unit, start, min and max; the
    outputs' dependencies are the same;
(c) the closed loop gives the same samples bit for bit on both editions: the six mismatch
    scenarios (each <= 3 nm rms), the Jacobi master, the other doStep order, parameters set
    through array elements; the plant alone on a validation input;
(d) the FMI-LS-REF reference experiment inside each FMI 3.0 FMU (computed on the C core)
    re-simulates in fmpy bit for bit;
(e) the contract: FMU state get/set and serialization mid-run continue bitwise; a bad
    parameter is refused at fmi3ExitInitializationMode naming it and its range; a NaN input
    is refused and the run continues as if it had never been offered; illegal calls return
    fmi3Error;
(f) the command line: ``run --fmi 3`` writes the same time series as ``--fmi 2``; the
    backends without an FMI 3.0 path refuse ``--fmi 3`` in one line with exit code 2.

The C-level negative, regression, thread and cross-process suites of the FMI 3.0 editions
run in tests/test_fmu_robustness.py (shipped FMUs, under valgrind) and in ctest (CI, under
ASan + UBSan).
"""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

import fmpy
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from conftest import FMU_NAMES, assert_refused, expected_binaries
from fmu_experiments import LS_REF, load_experiment, simulate_experiment

from harness.masters.fmpy import simulate_closed_loop, simulate_open_loop
from harness.loop.metrics import compute_metrics
from harness.scenarios import get_scenario

H = 5e-4
MISMATCH = ("mismatch_1hz", "mismatch_5hz", "mismatch_10hz", "mismatch_20hz",
            "mismatch_1_5_10hz", "mismatch_1_10_20hz")
FMI3_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean"}


# ---------------------------------------------------------------------------------------
# (a) the archive

@pytest.mark.parametrize("name", FMU_NAMES)
def test_validate_fmu_reports_nothing(fmu3_paths, name):
    assert fmpy.read_model_description(str(fmu3_paths[name])).fmiVersion == "3.0"
    assert validate_fmu(str(fmu3_paths[name])) == []


@pytest.mark.parametrize("name", FMU_NAMES)
def test_archive_has_fmi3_platforms_sources_and_documentation(fmu3_paths, name):
    with zipfile.ZipFile(fmu3_paths[name]) as zf:
        files = set(zf.namelist())
    binaries = sorted(f for f in files if f.startswith("binaries/") and not f.endswith("/"))
    # the cross platforms the build had compilers for (test_fmu_platforms.py requires them)
    assert binaries == expected_binaries(name, 3)
    assert f"binaries/x86_64-linux/{name}.so" in binaries
    for member in ("sources/buildDescription.xml", "sources/fmi3_glue.c", "sources/fmu_glue_core.c",
                   "sources/config.h", "documentation/index.html",
                   "documentation/licenses/license.txt", "model.png",
                   LS_REF + "fmi-ls-manifest.xml"):
        assert member in files, member
    assert "sources/fmi2_glue.c" not in files


# ---------------------------------------------------------------------------------------
# (b) the same variables as the FMI 2.0 edition

def _fmi3_variables(md):
    """{FMI 2.0 name: (variable, element index or None, start text)} of an FMI 3.0 description."""
    out = {}
    for v in md.modelVariables:
        if not v.dimensions:
            out[v.name] = (v, None, v.start)
            continue
        (dim,) = v.dimensions
        starts = str(v.start).split()
        assert len(starts) == int(dim.start), v.name
        for i in range(int(dim.start)):
            out[f"{v.name}[{i + 1}]"] = (v, i, starts[i])
    return out


def _number(text):
    return None if text is None else float({"true": 1, "false": 0}.get(str(text), text))


@pytest.mark.parametrize("name", FMU_NAMES)
def test_variables_match_the_fmi2_edition(fmu_paths, fmu3_paths, name):
    md2 = fmpy.read_model_description(str(fmu_paths[name]))
    md3 = fmpy.read_model_description(str(fmu3_paths[name]))
    v3 = _fmi3_variables(md3)
    names2 = {v.name for v in md2.modelVariables}
    # FMI 3.0 adds only the independent variable
    assert set(v3) - names2 == {"time"} and v3["time"][0].causality == "independent"
    arrays = {v.name for v, i, _ in v3.values() if i is not None}
    if name != "AdaptiveCompoundController":
        assert arrays, "pi.w / amplitude, frequency, phase should be arrays"
    for v2 in md2.modelVariables:
        var, _, start = v3[v2.name]
        assert FMI3_TYPES[var.type] == v2.type, v2.name
        assert (var.causality, var.variability) == (v2.causality, v2.variability), v2.name
        assert var.unit == v2.unit, v2.name
        assert _number(start) == _number(v2.start), v2.name
        assert _number(var.min) == _number(v2.min) and _number(var.max) == _number(v2.max), v2.name

    def deps(md):
        return {o.variable.name: sorted(d.name for d in (o.dependencies or [])) for o in md.outputs}
    assert deps(md3) == deps(md2)

    # the capability flags, from the XML (fmpy does not parse all of them for FMI 3.0)
    from xml.etree import ElementTree as ET
    with zipfile.ZipFile(fmu3_paths[name]) as zf:
        cs = ET.fromstring(zf.read("modelDescription.xml")).find("CoSimulation")
    assert cs.get("modelIdentifier") == md2.coSimulation.modelIdentifier == name
    assert float(cs.get("fixedInternalStepSize")) == H
    for flag in ("canHandleVariableCommunicationStepSize", "canGetAndSetFMUState",
                 "canSerializeFMUState"):
        assert cs.get(flag) == "true", flag
    assert cs.get("needsExecutionTool") == "false"


# ---------------------------------------------------------------------------------------
# (c) the closed loop, FMI 3.0 == FMI 2.0

def _assert_same_samples(a, b):
    assert a.dtype.names == b.dtype.names and a.shape == b.shape
    for field in a.dtype.names:
        assert np.array_equal(a[field], b[field]), field


@pytest.mark.parametrize("scenario", MISMATCH)
def test_closed_loop_equals_fmi2_in_the_mismatch_scenarios(scenario):
    fmi2 = simulate_closed_loop(scenario)
    fmi3 = simulate_closed_loop(scenario, fmi_version=3)
    _assert_same_samples(fmi3, fmi2)
    sc = get_scenario(scenario)
    m = compute_metrics(fmi3["time"], fmi3["y_d"], fmi3["y"], sc.metric_window, sc.step_size)
    print(f"\n{scenario}: FMI 3.0 == FMI 2.0 over {fmi3.size} samples, e_rms {m.e_rms * 1e3:.3f} nm")
    assert m.e_rms <= 3e-3           # um: the drop-in bound of the mismatch case
    assert np.ptp(fmi3["v"]) > 1.0   # the loop really drives the plant


@pytest.mark.parametrize("options", [
    {"master": "jacobi"},
    {"step_order": "controller-first"},
    {"plant_params": {"pi.w[2]": 0.04, "tf.a1": -1.38}, "controller_params": {"pi.w[1]": 0.07,
                                                                             "rls.forgetting": 0.999}},
], ids=["jacobi", "controller-first", "array-element-parameters"])
def test_closed_loop_equals_fmi2_under_other_masters_and_parameters(options):
    fmi2 = simulate_closed_loop("track_1_5_10hz", duration=0.5, **options)
    fmi3 = simulate_closed_loop("track_1_5_10hz", duration=0.5, fmi_version=3, **options)
    _assert_same_samples(fmi3, fmi2)
    if "plant_params" in options:      # the parameters reached the FMU: not the default run
        default = simulate_closed_loop("track_1_5_10hz", duration=0.5, fmi_version=3)
        assert not np.array_equal(default["y"], fmi3["y"])


def test_unknown_array_element_is_refused_by_name():
    from harness.fmu import UnknownParameterError
    with pytest.raises(UnknownParameterError, match=r"'pi\.w\[17\]' is not a parameter"):
        simulate_closed_loop("track_1hz", duration=0.01, fmi_version=3,
                             plant_params={"pi.w[17]": 0.1})


def test_plant_alone_equals_fmi2_on_a_validation_input():
    t = np.arange(4000) * H
    v = 40 + 30 * np.sin(2 * np.pi * 5 * t) + 10 * np.sin(2 * np.pi * 20 * t)
    params = {"creep.exact": True, "sensor.noise_rms": 0.002}
    fmi2 = simulate_open_loop(params, v)
    fmi3 = simulate_open_loop(params, v, fmi_version=3)
    _assert_same_samples(fmi3, fmi2)
    assert np.ptp(fmi3["y"]) > 5.0


# ---------------------------------------------------------------------------------------
# (d) the reference experiment inside each FMI 3.0 FMU

@pytest.mark.parametrize("name", FMU_NAMES)
def test_reference_experiment_resimulates_bit_for_bit(fmu_paths, fmu3_paths, name):
    fmu = fmu3_paths[name]
    exp = load_experiment(fmu)
    result = simulate_experiment(fmu, exp)
    assert np.array_equal(result["time"], exp.reference["time"])
    for output in exp.outputs:
        assert np.array_equal(np.asarray(result[output], dtype=float), exp.reference[output]), output
    # the same experiment and references as the FMI 2.0 edition's
    exp2 = load_experiment(fmu_paths[name])
    assert exp2.parameters == exp.parameters
    for output in exp.reference.dtype.names:
        assert np.array_equal(exp2.reference[output], exp.reference[output]), output


# ---------------------------------------------------------------------------------------
# (e) the contract, through fmpy's FMU3Slave

class Fmu3:
    """One FMI 3.0 instance with its log messages kept as (status, text)."""

    def __init__(self, path, name):
        self.md = fmpy.read_model_description(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.unzipdir = fmpy.extract(str(path))
        self.messages = []
        self.slave = FMU3Slave(guid=self.md.instantiationToken, unzipDirectory=self.unzipdir,
                               modelIdentifier=name, instanceName="fmi3-test")
        self.slave.instantiate(logMessage=self._log)
        self.k = 0

    def _log(self, env, status, category, message):
        self.messages.append((status, message.decode(errors="replace")))

    def vr(self, name):
        return [self.vars[name].valueReference]

    # what conftest.assert_refused reads
    def clear_messages(self):
        self.messages.clear()

    def last_error(self):
        errors = [text for status, text in self.messages if status >= 3]
        return errors[-1] if errors else ""

    def initialize(self, reals=None):
        self.slave.enterInitializationMode(startTime=0.0)
        for name, value in (reals or {}).items():
            self.slave.setFloat64(self.vr(name), [value])
        self.slave.exitInitializationMode()

    def step(self, v):
        self.slave.setFloat64(self.vr("v"), [v])
        self.slave.doStep(self.k * H, H)
        self.k += 1
        return self.slave.getFloat64(self.vr("y_meas") + self.vr("y"))

    def close(self):
        from fmpy.fmi1 import FMICallException
        try:
            self.slave.terminate()
        except FMICallException:           # not allowed before initialization ends
            pass
        self.slave.freeInstance()
        import shutil
        shutil.rmtree(self.unzipdir, ignore_errors=True)


def _drive(n):
    k = np.arange(n)
    return 50 + 40 * np.sin(2 * np.pi * 3 * k * H) * np.cos(2 * np.pi * 0.7 * k * H)


def test_state_get_set_and_serialization_continue_bitwise(fmu3_paths):
    v = _drive(2000)
    noisy = {"sensor.noise_rms": 0.003}     # the noise generator's state must be restored too
    whole = Fmu3(fmu3_paths["PiezoStage"], "PiezoStage")
    whole.initialize(noisy)
    expected = np.array([whole.step(x) for x in v])
    whole.close()

    fmu = Fmu3(fmu3_paths["PiezoStage"], "PiezoStage")
    fmu.initialize(noisy)
    first = [fmu.step(x) for x in v[:800]]
    state = fmu.slave.getFMUState()
    blob = fmu.slave.serializeFMUState(state)
    rest = [fmu.step(x) for x in v[800:]]
    assert np.array_equal(np.array(first + rest), expected)
    # back to sample 800 with the state, then with the deserialized copy
    for restore in ("state", "blob"):
        if restore == "state":
            fmu.slave.setFMUState(state)
        else:
            copy = fmu.slave.deserializeFMUState(blob)
            fmu.slave.setFMUState(copy)
            fmu.slave.freeFMUState(copy)
        fmu.k = 800
        again = [fmu.step(x) for x in v[800:]]
        assert np.array_equal(np.array(again), expected[800:]), restore
    fmu.slave.freeFMUState(state)
    fmu.close()
    assert np.std(expected[:, 0] - expected[:, 1]) > 1e-3      # the noise is really on


@pytest.mark.parametrize("name,value,message", [
    ("creep.alpha", 2.0, "creep.alpha = 2 is out of range: valid range [-1, 1]"),
    ("h", 0.0, "h = 0 is out of range: valid range (0, inf)"),
])
def test_bad_parameter_refused_at_exit_initialization(fmu3_paths, name, value, message):
    fmu = Fmu3(fmu3_paths["PiezoStage"], "PiezoStage")
    fmu.slave.enterInitializationMode(startTime=0.0)
    fmu.slave.setFloat64(fmu.vr(name), [value])
    assert_refused(fmu.slave.exitInitializationMode, fmu, f"fmi3ExitInitializationMode: {message}")
    # still in initialization mode: corrected, it is accepted
    fmu.slave.setFloat64(fmu.vr(name), [float(fmu.vars[name].start)])
    fmu.slave.exitInitializationMode()
    assert np.all(np.isfinite(fmu.step(10.0)))
    fmu.close()


def test_bad_array_element_refused_by_its_element_name(fmu3_paths):
    fmu = Fmu3(fmu3_paths["PiezoStage"], "PiezoStage")
    fmu.slave.enterInitializationMode(startTime=0.0)
    w = list(fmu.slave.getFloat64(fmu.vr("pi.w"), nValues=16))
    w[1] = -0.1
    fmu.slave.setFloat64(fmu.vr("pi.w"), w)
    assert_refused(fmu.slave.exitInitializationMode, fmu,
                   "fmi3ExitInitializationMode: pi.w[2] = -0.1 is out of range: valid range [0, inf)")
    fmu.close()


def test_nan_input_refused_and_the_run_unchanged(fmu3_paths):
    v = _drive(300)
    ref = Fmu3(fmu3_paths["PiezoStage"], "PiezoStage")
    ref.initialize()
    expected = np.array([ref.step(x) for x in v])
    ref.close()
    fmu = Fmu3(fmu3_paths["PiezoStage"], "PiezoStage")
    fmu.initialize()
    out = [fmu.step(x) for x in v[:150]]
    for bad in (float("nan"), float("inf")):
        assert_refused(lambda: fmu.slave.setFloat64(fmu.vr("v"), [bad]), fmu, f"v = {bad}",
                       "valid range: finite values")
    out += [fmu.step(x) for x in v[150:]]
    assert np.array_equal(np.array(out), expected)
    fmu.close()


def test_illegal_calls_return_fmi3_error(fmu3_paths):
    """Each illegal call is refused with fmi3Error and a message of its own that names it; the
    instance still works after them."""
    fmu = Fmu3(fmu3_paths["AdaptiveCompoundController"], "AdaptiveCompoundController")
    slave = fmu.slave
    assert_refused(lambda: slave.doStep(0.0, H), fmu,
                   "fmi3DoStep: illegal call sequence: the FMU is in state Instantiated (allowed in: StepMode)")
    assert_refused(slave.exitInitializationMode, fmu, "fmi3ExitInitializationMode: illegal call sequence: the FMU "
                                                      "is in state Instantiated (allowed in: InitializationMode)")
    fmu.initialize()
    assert_refused(lambda: slave.getFloat64([9999]), fmu, "fmi3GetFloat64: unknown value reference 9999")
    assert_refused(lambda: slave.getFloat64(fmu.vr("saturated")), fmu,
                   f"fmi3GetFloat64: variable saturated (value reference {fmu.vr('saturated')[0]}) is of type "
                   "Boolean, not Float64")
    assert_refused(lambda: slave.doStep(0.0, 0.3 * H), fmu,
                   "fmi3DoStep: communicationStepSize = 0.00015 is not a whole multiple of h = 0.0005",
                   "step refused, state and time unchanged")
    slave.setFloat64(fmu.vr("y_ref") + fmu.vr("y_meas"), [1.0, 0.0])
    slave.doStep(0.0, H)                            # the instance still works
    assert np.isfinite(slave.getFloat64(fmu.vr("v"))[0])
    fmu.close()


# ---------------------------------------------------------------------------------------
# (f) the command line

def test_cli_run_fmi3_writes_the_fmi2_time_series(tmp_path, capsys):
    from harness.cli import main

    for version in ("2", "3"):
        assert main(["run", "mismatch_10hz", "--fmi", version, "--no-plots",
                     "--out", str(tmp_path / version)]) == 0
    a = (tmp_path / "2" / "mismatch_10hz_timeseries.csv").read_bytes()
    b = (tmp_path / "3" / "mismatch_10hz_timeseries.csv").read_bytes()
    assert a == b and len(a) > 100_000


@pytest.mark.parametrize("backend", ["native", "core"])
def test_cli_refuses_fmi3_on_backends_without_it(tmp_path, capsys, backend):
    from harness.cli import main

    code = main(["run", "track_1hz", "--fmi", "3", "--backend", backend, "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1
    assert f"--fmi 3 does not apply to --backend {backend}" in err
    assert not any(tmp_path.iterdir())              # nothing ran, nothing written
