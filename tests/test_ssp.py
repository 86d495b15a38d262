"""The closed-loop SSP written by the build (build/fmus/PiezoStageClosedLoop.ssp)."""
import dataclasses
import re
import zipfile

import numpy as np
import pytest

from harness.buildtime import ssp_file
from harness.masters.ssp import simulate_closed_loop_ssp
from harness.loop.metrics import compute_metrics
from harness.scenarios import Signal, get_scenario
from test_masters import FIELDS, zero_start_jacobi


@pytest.fixture(scope="module")
def built(fmu_paths):
    path = next(iter(fmu_paths.values())).parent / ssp_file.SSP_FILENAME
    assert path.is_file(), "the build writes the SSP beside the FMUs"
    return path


def test_structure(built):
    """fmpy's reader validates the SSD against the SSP 1.0 schema; the file holds the three
    FMUs, the documented connections, the mismatch 1/5/10 Hz set bound on every component
    (resources/mismatch_1_5_10hz/<component>.ssv, each an ssv:ParameterSet of that one name)
    and nothing bound at the system level (libcosim and Ecos read component bindings only), the
    nominal set beside it, a 3 s default experiment and the step h where each player reads it:
    OMSimulator's oms:FixedStepMaster, libcosim's osp:FixedStepAlgorithm, and osp:StepSizeHint
    on each component (libcosim, Ecos)."""
    from fmpy.ssp.ssd import read_ssd

    ssd = read_ssd(str(built), validate=True)
    comps = {c.name: c.source for c in ssd.system.elements}
    assert comps == {"reference": "resources/ReferenceSignal.fmu",
                     "controller": "resources/AdaptiveCompoundController.fmu",
                     "plant": "resources/PiezoStage.fmu"}
    links = {(c.startElement, c.startConnector, c.endElement, c.endConnector)
             for c in ssd.system.connections}
    assert links == {("reference", "y_ref", "controller", "y_ref"),
                     ("reference", "y_preview", "controller", "y_preview"),
                     ("reference", "t_preview", "controller", "t_preview"),
                     ("plant", "y_meas", "controller", "y_meas"),
                     ("plant", "t_meas", "controller", "t_meas"),
                     ("controller", "v", "plant", "v")}
    assert ssd.system.parameterBindings == []
    for element in ssd.system.elements:
        assert [b.source for b in element.parameterBindings] == [f"resources/mismatch_1_5_10hz/{element.name}.ssv"]
        assert [ps.name for b in element.parameterBindings for ps in b.parameterValues] == ["mismatch_1_5_10hz"]
    with zipfile.ZipFile(built) as zf:
        names = set(zf.namelist())
        text = zf.read("SystemStructure.ssd").decode()
        for fmu in comps.values():
            assert zf.read(fmu) == (built.parent / fmu.split("/")[1]).read_bytes()
    for pset in ("mismatch_1_5_10hz", "track_1_5_10hz"):
        assert {f"resources/{pset}.ssv"} | {f"resources/{pset}/{c}.ssv" for c in comps} <= names
    assert re.search(r'<ssd:DefaultExperiment startTime="0" stopTime="3.0"', text)
    assert re.search(r'<oms:FixedStepMaster description="oms-ma" stepSize="0.0005"/>', text)
    assert re.search(r'<ssc:Annotation type="com.opensimulationplatform">\s*<osp:Algorithm>\s*'
                     r'<osp:FixedStepAlgorithm baseStepSize="0.0005"/>', text)
    assert len(re.findall(r'<osp:StepSizeHint value="0.0005"/>', text)) == 3
    assert 'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"' in text


def test_bound_parameters_are_the_scenario(built):
    """Reference: the mismatch_1_5_10hz scenario (harness.scenarios): every plant override,
    the three tones and h, read back from the components' bindings through fmpy's SSV reader
    (read_bound_parameter_set prefixes them); no lead and no mv.delay (the FMUs' defaults: the
    controller detects its delay and aligns the stamped preview). The prefixed SSV for fmpy
    holds exactly the same names and values."""
    from fmpy.ssp.ssd import read_ssv

    pset = ssp_file.read_bound_parameter_set(built)
    assert pset.name == "mismatch_1_5_10hz"
    values = {p.name: p.value for p in pset.parameters}
    sc = get_scenario("mismatch_1_5_10hz")
    for key, value in sc.plant.items():
        assert values[f"plant.{key}"] == value, key
        assert type(values[f"plant.{key}"]) is type(value), key
    for i, f in enumerate((1.0, 5.0, 10.0), start=1):
        assert values[f"reference.amplitude[{i}]"] == 10.0
        assert values[f"reference.frequency[{i}]"] == f
    for i in range(4, 9):       # the unused tones are set to 0, not left to the FMU's defaults
        assert values[f"reference.amplitude[{i}]"] == 0.0
    assert "reference.lead" not in values and "controller.mv.delay" not in values
    assert values["plant.h"] == values["controller.h"] == values["reference.h"] == 0.0005
    flat = read_ssv(str(built), "resources/mismatch_1_5_10hz.ssv")
    assert {p.name: float(p.value) for p in flat.parameters} == {k: float(v) for k, v in values.items()}


def test_a_boolean_is_read_back_as_a_bool(tmp_path, built):
    """A set with a Boolean (sat.enabled = false on the controller): read_bound_parameter_set
    gives Python's False, which fmpy's player sets as false (it sets value != 0.0, which the
    SSV's text "false" would pass as true)."""
    pset = ssp_file.parameter_set_for_scenario("mismatch_5hz")
    pset = dataclasses.replace(pset, values={**pset.values, "controller.sat.enabled": False})
    path = ssp_file.write_closed_loop_ssp(tmp_path / "b.ssp", built.parent, [pset])
    values = {p.name: p.value for p in ssp_file.read_bound_parameter_set(path).parameters}
    assert values["controller.sat.enabled"] is False


def test_two_sets_of_one_name_are_refused(tmp_path, built):
    pset = ssp_file.parameter_set_for_scenario("mismatch_5hz")
    with pytest.raises(ValueError, match="each needs its own name"):
        ssp_file.write_closed_loop_ssp(tmp_path / "b.ssp", built.parent, [pset, pset])


def test_fmpy_runs_it_and_it_tracks(built):
    """fmpy's SSP player runs the built SSP with its bound parameters: e_rms <= 3 nm over
    [1, 3) s, and every sample equals the zero-start Jacobi loop of tests/test_masters.py
    (the player's schedule) within 1e-12."""
    res = simulate_closed_loop_ssp(built)
    n = 6000
    got = {"y_d": res["reference.y_d"][:n], "y": res["plant.y"][:n],
           "y_meas": res["plant.y_meas"][:n], "v": res["controller.v"][:n]}
    ref = zero_start_jacobi("mismatch_1_5_10hz")
    for f in FIELDS:
        assert np.max(np.abs(got[f] - ref[f])) <= 1e-12, f
    sc = get_scenario("mismatch_1_5_10hz")
    m = compute_metrics(ref["time"], got["y_d"], got["y"], sc.metric_window, sc.step_size)
    assert m.e_rms <= 3e-3


def test_the_readmes_pure_fmpy_recipe_tracks(built):
    """The README's recipe with fmpy alone (no harness): the bound SSV read with fmpy's
    read_ssv, step 5e-4, stop 3. Reference: the harness's simulate_closed_loop_ssp on the same
    file, sample for sample, and the 3 nm bound of the mismatch case over [1, 3) s."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    result = simulate_ssp(str(built), stop_time=3.0, step_size=5e-4,
                          parameter_set=read_ssv(str(built), "resources/mismatch_1_5_10hz.ssv"))
    harness_run = simulate_closed_loop_ssp(built)
    n = 6000
    for f in ("reference.y_d", "plant.y", "controller.v"):
        assert np.array_equal(result[f][:n], harness_run[f][:n]), f
    sc = get_scenario("mismatch_1_5_10hz")
    time = np.arange(n) * sc.step_size
    m = compute_metrics(time, result["reference.y_d"][:n], result["plant.y"][:n],
                        sc.metric_window, sc.step_size)
    assert np.ptp(result["reference.y_d"][:n]) > 20 and m.e_rms <= 3e-3


def test_writing_is_reproducible(tmp_path, built):
    """The same FMUs and parameter sets give the same bytes (fixed zip timestamps)."""
    a = ssp_file.write_closed_loop_ssp(tmp_path / "a.ssp", built.parent)
    b = ssp_file.write_closed_loop_ssp(tmp_path / "b.ssp", built.parent)
    assert a.read_bytes() == b.read_bytes()


def test_only_sines_scenarios_fit_an_ssp():
    sc = get_scenario("track_1hz")
    table = {"t": sc.with_overrides(signal=Signal("table", table_time=(0.0, 3.0),
                                                  table_value=(0.0, 1.0)))}
    nine = {"n": sc.with_overrides(signal=Signal("sines", amplitudes=(1.0,) * 9,
                                                 frequencies=(1.0,) * 9, phases=(0.0,) * 9))}
    with pytest.raises(ValueError, match="sines reference"):
        ssp_file.parameter_set_for_scenario("t", table)
    with pytest.raises(ValueError, match="9 tones; ReferenceSignal has 8"):
        ssp_file.parameter_set_for_scenario("n", nine)
    with pytest.raises(ValueError, match="not a tracking scenario"):
        ssp_file.parameter_set_for_scenario("validate_1hz")
