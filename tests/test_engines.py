"""The loop in libcosim and Ecos, the engines users co-simulate in besides fmpy: the three FMUs
wired, PiezoStageClosedLoop, and the closed-loop SSP, in FMI 2.0 (both) and FMI 3.0 (Ecos;
libcosim has no FMI 3.0), once through Ecos's ``proxyfmu://`` (one process per FMU).

Reference: the harness's fmpy master (``masters.closed_loop("fmpy")``), sample for sample, bit
for bit: both engines exchange values at communication points after passing the outputs of
initialization to the inputs (tests/engine_runs.py says where their source does it), the
schedule whose samples the fmpy master gives (tests/test_masters.py). The engines report the
samples after each step (t_1 .. t_n), the master at t_0 .. t_(n-1): compared over t_1 ..
t_(n-1). And the parameters an engine's FMUs hold after initialization, read back from the
engine: the scenario's, not the FMUs' defaults (an SSP whose set a player does not apply
runs the nominal stage, silently, and tracks too).

Each engine is optional (``pip install '.[engines]'``; Ecos's library needs libtbb 12): a test
without it skips saying so; .ci/run installs both and sets PIEZO_REQUIRE_ENGINES=1.
"""
import numpy as np
import pytest

from harness import masters
from harness.binding.closed_loop import CLOSED_LOOP_MODEL
from harness.loop import prepare_closed_loop
from harness.masters.closed_loop_fmu import closed_loop_fmu_parameters
from harness.masters.wired import COMPONENTS
from harness.scenarios import get_scenario
from harness.buildtime.ssp_file import SSP_FILENAME, SSP_SCENARIO, component_values, parameter_set_for_scenario

from conftest import FMU3_DIR, FMU_DIR, need_engine
import engine_runs as er

FIELDS = ("y_d", "y", "y_meas", "v")
SCENARIO = SSP_SCENARIO          # the mismatch case the SSP binds: 1/5/10 Hz on the mismatched stage


@pytest.fixture(scope="module")
def libcosim():
    try:
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    except ImportError as exc:
        need_engine("libcosim", f"libcosimpy does not import ({exc})")
    log_output_level(CosimLogLevel.WARNING)


@pytest.fixture(scope="module")
def ecos():
    try:
        import ecospy
    except ImportError as exc:
        need_engine("Ecos", f"ecospy does not import ({exc})")
    except OSError as exc:          # its libecosc.so without libtbb.so.12
        need_engine("Ecos", f"ecospy's library does not load ({exc})")
    ecospy.EcosLib.set_log_level("warn")


@pytest.fixture(scope="module")
def reference(fmu_paths):
    """The fmpy master's samples of the mismatch case, FMI 2.0."""
    return masters.closed_loop("fmpy")(SCENARIO)


def _fmus(fmi):
    folder = FMU_DIR if fmi == 2 else FMU3_DIR
    return {comp: folder / f"{model}.fmu" for comp, model in COMPONENTS.items()}


def _same_samples(run, ref):
    """Bit for bit over t_1 .. t_(n-1); the controller chose d = 2 (an exchanging master)."""
    for f in FIELDS:
        assert np.array_equal(run[f][:-1], ref[f][1:]), f
    assert run["loop_delay"][-1] == 2


def _applied(params, expected):
    """Every value of the set, read back from the engine after initialization, is the set's."""
    for name, value in expected.items():
        if isinstance(value, bool):
            continue
        assert params[name] == value, name


def _scenario_params():
    pset = parameter_set_for_scenario(SCENARIO)
    return component_values(pset), pset.values


# -- libcosim ----------------------------------------------------------------------------------

def test_libcosim_runs_the_three_fmus_as_the_fmpy_master(libcosim, reference):
    """libcosim, the three FMI 2.0 FMUs added and connected by hand, the scenario's parameters as
    initial values, step h: the fmpy master's samples bit for bit, d = 2, and every parameter
    read back as set."""
    params, flat = _scenario_params()
    sc = get_scenario(SCENARIO)
    run = er.libcosim_loop(_fmus(2), params, sc.n_samples, sc.step_size)
    _same_samples(run, reference)
    _applied(run["params"], flat)


def test_libcosim_runs_the_closed_loop_fmu_as_the_fmpy_master(libcosim, reference):
    """libcosim, PiezoStageClosedLoop (FMI 2.0) with the scenario's parameters, step h: the
    three FMUs' samples bit for bit (its loop is theirs under an exchanging master)."""
    sc = get_scenario(SCENARIO)
    params = closed_loop_fmu_parameters(prepare_closed_loop(SCENARIO))
    run = er.libcosim_closed_loop_fmu(FMU_DIR / f"{CLOSED_LOOP_MODEL}.fmu", params, sc.n_samples, sc.step_size)
    _same_samples(run, reference)


@pytest.mark.parametrize("step", [None, 0.0005])
def test_libcosim_loads_the_ssp_and_applies_its_set(libcosim, fmu_paths, reference, step):
    """libcosim loads PiezoStageClosedLoop.ssp without a step (its osp:FixedStepAlgorithm gives
    h) and with one, applies the bound set on every component (the mismatched stage's
    pi.w0 = 0.36784 where the FMU's default is another, the three tones) and gives the fmpy
    master's samples bit for bit."""
    sc = get_scenario(SCENARIO)
    run = er.libcosim_ssp(FMU_DIR / SSP_FILENAME, sc.n_samples, step)
    _, flat = _scenario_params()
    _applied(run["params"], flat)
    assert run["params"]["plant.pi.w0"] == 0.36784
    _same_samples(run, reference)


# -- Ecos --------------------------------------------------------------------------------------

def test_ecos_runs_the_three_fmus_as_the_fmpy_master(ecos, reference):
    """Ecos, the three FMI 2.0 FMUs added and connected by hand, the scenario's parameters one
    parameter set applied at init: the fmpy master's samples bit for bit, every value applied."""
    params, flat = _scenario_params()
    sc = get_scenario(SCENARIO)
    run = er.ecos_loop(_fmus(2), params, sc.n_samples, sc.step_size)
    _same_samples(run, reference)
    _applied(run["params"], flat)


def test_ecos_runs_the_three_fmus_each_in_its_own_process(ecos, reference, tmp_path, monkeypatch):
    """Ecos through proxyfmu:// (one proxyfmu process per FMU, FMI 2.0): the same samples bit for
    bit, over 0.5 s (each call crosses a process). proxyfmu writes logs/ in the working folder:
    here a temporary one."""
    monkeypatch.chdir(tmp_path)
    why = er.ecos_proxy_ready()
    if why:
        need_engine("Ecos", why)
    params, _ = _scenario_params()
    n = 1000
    run = er.ecos_loop(_fmus(2), params, n, get_scenario(SCENARIO).step_size, proxy=True)
    _same_samples(run, reference[:n])


def test_ecos_runs_the_fmi3_editions_at_their_defaults(ecos, fmu_paths):
    """Ecos, the three FMI 3.0 FMUs at their defaults (the 1 Hz, 10 um tone on the nominal stage:
    track_1hz; Ecos cannot set an FMI 3.0 array element, docs/fmus.md): the fmpy master's
    samples of track_1hz on the FMI 3.0 editions bit for bit."""
    sc = get_scenario("track_1hz")
    ref = masters.closed_loop("fmpy")("track_1hz", fmi_version=3)
    run = er.ecos_loop(_fmus(3), {}, sc.n_samples, sc.step_size)
    _same_samples(run, ref)


def test_ecos_runs_the_closed_loop_fmu_as_the_fmpy_master(ecos, reference):
    """Ecos, PiezoStageClosedLoop (FMI 2.0) with the scenario's parameters: the three FMUs'
    samples bit for bit."""
    sc = get_scenario(SCENARIO)
    params = closed_loop_fmu_parameters(prepare_closed_loop(SCENARIO))
    run = er.ecos_closed_loop_fmu(FMU_DIR / f"{CLOSED_LOOP_MODEL}.fmu", params, sc.n_samples, sc.step_size)
    _same_samples(run, reference)


def test_ecos_applies_the_ssps_set_by_its_name(ecos, fmu_paths, reference):
    """Ecos, PiezoStageClosedLoop.ssp, init(parameter_set="mismatch_1_5_10hz"): the set bound on
    every component under that name is applied to all three (read back), and the samples are
    the fmpy master's bit for bit."""
    sc = get_scenario(SCENARIO)
    _, flat = _scenario_params()
    run = er.ecos_ssp(FMU_DIR / SSP_FILENAME, sc.n_samples, sc.step_size, parameter_set=SCENARIO, names=flat)
    _applied(run["params"], flat)
    _same_samples(run, reference)


def test_ecos_at_a_fifth_of_h_steps_each_fmu_at_h(ecos, fmu_paths, reference):
    """Ecos at a base step of h / 5: the SSP's osp:StepSizeHint (h) on each component makes Ecos
    step every FMU every fifth base step with h, so every fifth sample is the fmpy master's
    (bit for bit over 0.5 s)."""
    n = 1000
    run = er.ecos_ssp(FMU_DIR / SSP_FILENAME, 5 * n, 0.0001, parameter_set=SCENARIO)
    fifth = {f: run[f][4::5] for f in FIELDS}
    fifth["loop_delay"] = run["loop_delay"][4::5]
    _same_samples(fifth, reference[:n])


def test_ecos_without_the_sets_name_runs_the_fmus_defaults(ecos, fmu_paths):
    """What Ecos does when init() is not given the set's name: no binding is applied (Ecos applies
    a component's binding only by name), so the plant runs its defaults (the default pi.w0, not
    the set's 0.36784): the name is part of how to run the SSP in Ecos (docs/fmus.md)."""
    from harness.binding.core import default_plant_params
    run = er.ecos_ssp(FMU_DIR / SSP_FILENAME, 10, 0.0005, names={"plant.pi.w0": 0.0})
    assert run["params"]["plant.pi.w0"] == default_plant_params()["pi.w0"] != 0.36784
