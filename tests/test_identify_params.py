"""harness.identify.params: parameter files (JSON of FMU variable names) and their use.

References: the FMUs' model descriptions (which names each FMU has) and JSON round trips.
"""
import pytest

from harness.identify.params import (
    ParameterFileError,
    override_scenarios,
    parameter_types,
    read_params,
    split_params,
    write_params,
)
from harness.scenarios import load_scenarios


@pytest.fixture(scope="module")
def types(fmu_paths):
    return (parameter_types("PiezoStage", fmu_dir=fmu_paths["PiezoStage"].parent),
            parameter_types("AdaptiveCompoundController",
                            fmu_dir=fmu_paths["PiezoStage"].parent))


def test_round_trip_is_exact(tmp_path):
    params = {"pi.m": 9, "pi.w0": 0.1 + 0.2, "tf.a1": -1.4420392160747462, "creep.exact": True,
              "h": 5e-4}
    path = write_params(tmp_path / "p.json", params)
    back = read_params(path)
    assert back == params and list(back) == list(params)
    assert isinstance(back["pi.m"], int) and back["creep.exact"] is True
    assert path.read_text().count("\n") == len(params) + 2       # one name per line


def test_core_tables_and_fmus_name_the_same_parameters(types):
    # The two sources of parameter names (--backend fmpy / core) agree, types included.
    assert parameter_types("PiezoStage", backend="core") == types[0]
    assert parameter_types("AdaptiveCompoundController", backend="core") == types[1]


def test_each_fmu_takes_the_names_it_has(types):
    params = {"pi.w0": 0.4, "tf.delay": 1, "mv.delay": 1, "sensor.seed": 3, "h": 0.0005,
              "rls.enabled": False, "pi.m": 9.0}
    plant, ctrl = split_params(params, *types, source="f.json")
    assert plant == {"pi.w0": 0.4, "tf.delay": 1, "sensor.seed": 3, "h": 0.0005, "pi.m": 9}
    assert ctrl == {"pi.w0": 0.4, "mv.delay": 1, "h": 0.0005, "rls.enabled": False, "pi.m": 9}
    assert isinstance(plant["pi.m"], int)


@pytest.mark.parametrize("params, message", [
    ({"tf.a3": 1.0}, "f.json: 'tf.a3' is a parameter of neither PiezoStage nor "
                     "AdaptiveCompoundController (did you mean tf.a2, tf.a1, tf.delay?)"),
    ({"y": 1.0}, "f.json: 'y' is a parameter of neither PiezoStage nor AdaptiveCompoundController"),
    ({"pi.m": 9.5}, "f.json: pi.m = 9.5: PiezoStage's pi.m is an Integer"),
    ({"pi.w0": True}, "f.json: pi.w0 = true: PiezoStage's pi.w0 is a Real, not a boolean"),
    ({"rls.enabled": 1}, "f.json: rls.enabled = 1: AdaptiveCompoundController's rls.enabled is "
                         "a Boolean (true or false)"),
])
def test_names_of_neither_fmu_and_wrong_types_are_refused(types, params, message):
    with pytest.raises(ParameterFileError) as info:
        split_params(params, *types, source="f.json")
    assert str(info.value) == message


@pytest.mark.parametrize("text, message", [
    ('{"pi.w0": NaN}', "NaN is not a valid value (every number must be finite)"),
    ('{"pi.w0": Infinity}', "Infinity is not a valid value (every number must be finite)"),
    ('{"pi.w0": 1, "pi.w0": 2}', "'pi.w0' appears twice"),
    ('[1, 2]', "expected a JSON object of parameter names and values, got a list"),
    ('{"pi.w0": "0.4"}', 'pi.w0 = "0.4" is not a number or a boolean'),
    ('{"pi.w0": [0.4]}', "pi.w0 = [0.4] is not a number or a boolean"),
    ('{"pi.w0": 0.4,}', "not valid JSON: Expecting property name enclosed in double quotes at "
                        "line 1, column 15"),
])
def test_bad_files_are_refused_in_one_line(tmp_path, text, message):
    path = tmp_path / "p.json"
    path.write_text(text)
    with pytest.raises(ParameterFileError) as info:
        read_params(path)
    assert str(info.value) == f"{path}: {message}"
    with pytest.raises(ParameterFileError, match="no such file"):
        read_params(tmp_path / "missing.json")


def test_override_scenarios_applies_after_each_scenarios_own():
    reg = load_scenarios()
    out = override_scenarios(reg, {"creep.alpha": -0.01}, {"mv.delay": 1})
    assert out.keys() == reg.keys()
    m = out["mismatch_1hz"]
    assert m.plant["creep.alpha"] == -0.01                       # the file wins
    assert m.plant["tf.a1"] == reg["mismatch_1hz"].plant["tf.a1"]   # the rest stays
    assert m.controller["mv.delay"] == 1
    assert reg["mismatch_1hz"].plant["creep.alpha"] == -0.0085   # the registry is not touched
    assert override_scenarios(reg) == reg
