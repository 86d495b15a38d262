"""harness.scenarios: built-in scenarios (paper Tables 1-5, docs/model.md, scenarios) and user files."""

import math

import numpy as np
import pytest

from harness.scenarios import (
    MISMATCH_SCENARIOS,
    TRACKING_SCENARIOS,
    VALIDATION_SCENARIOS,
    ScenarioFileError,
    UnknownScenarioError,
    get_scenario,
    load_scenario_file,
    load_scenarios,
    stage_use_scenarios,
)
from conftest import REPO


def test_builtin_names_and_paper_values():
    # Reference: paper Tables 4/5 and docs/model.md, scenarios (e_r "0.76 %" typo -> 0.11 %).
    reg = load_scenarios()
    assert (list(TRACKING_SCENARIOS) + list(VALIDATION_SCENARIOS) + list(MISMATCH_SCENARIOS)
            + stage_use_scenarios() == list(reg))
    e_rms = [reg[n].paper["e_rms_um"] for n in TRACKING_SCENARIOS]
    e_r = [reg[n].paper["e_r"] for n in TRACKING_SCENARIOS]
    assert e_rms == [0.0076, 0.0254, 0.056, 0.1153, 0.0600, 0.1787]
    assert e_r == [0.0011, 0.0036, 0.0080, 0.0163, 0.0049, 0.0146]
    for n in TRACKING_SCENARIOS + MISMATCH_SCENARIOS:
        sc = reg[n]
        assert (sc.duration, sc.metric_window, sc.n_samples) == (3.0, (1.0, 3.0), 6000)
        assert all(a == 10.0 for a in sc.signal.amplitudes)
    # Table 2 row 5/40/80 Hz
    v = reg["validate_5_40_80hz"]
    assert (v.paper["hammerstein_e_rms_um"], v.paper["coupled_e_rms_um"]) == (0.1195, 0.0682)


def test_builtin_signals():
    # Reference: y_d = 10 (sin 2 pi 1 t + sin 2 pi 5 t + sin 2 pi 10 t) (section 5.3 of the paper)
    sc = get_scenario("track_1_5_10hz")
    t = np.array([0.0, 0.01, 0.0125])
    expected = 10 * (np.sin(2 * np.pi * t) + np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 10 * t))
    np.testing.assert_allclose(sc.signal.evaluate(t), expected, rtol=0, atol=1e-12)
    # Reference: v = 6 (sin 2 pi 5t + sin 2 pi 40t + sin 2 pi 80t) + 18 (Tables 1-3)
    v = get_scenario("validate_5_40_80hz").signal.evaluate([0.0, 0.003])
    np.testing.assert_allclose(v, [18.0, 18 + 6 * sum(math.sin(2 * math.pi * f * 0.003) for f in (5, 40, 80))])


def test_validation_creep_rows_match_table_1():
    # Reference: paper Table 1 (f: k_c, alpha).
    table1 = {"1hz": (1.0463, 0.0002), "10hz": (1.0497, -0.0085), "20hz": (1.0386, -0.0077),
              "50hz": (1.0481, -0.0098), "100hz": (1.0327, -0.0059), "5_40_80hz": (1.0172, -0.0023)}
    for key, (k_c, alpha) in table1.items():
        sc = get_scenario(f"validate_{key}")
        assert (sc.plant["creep.k_c"], sc.plant["creep.alpha"]) == (k_c, alpha)


def test_mismatch_parameters_follow_design_section_4():
    # Reference: docs/model.md, scenarios: PI weights +10 %, creep row 10 Hz, numerator x1.05,
    # poles 0.992037 and 0.45, sensor 2 nm resolution + 1 nm rms noise; controller nominal.
    sc = get_scenario("mismatch_10hz")
    p = sc.plant
    for name, nominal in {"pi.w0": 0.3344, "pi.w[1]": 0.0714, "pi.w[2]": 0.0322, "pi.w[3]": 0.0072}.items():
        assert p[name] == pytest.approx(1.1 * nominal, rel=1e-12)
    assert (p["creep.k_c"], p["creep.alpha"]) == (1.0497, -0.0085)
    assert p["tf.b1"] == pytest.approx(1.05 * 0.5954, rel=1e-12)
    assert p["tf.b2"] == pytest.approx(1.05 * -0.5907, rel=1e-12)
    poles = np.sort(np.roots([1.0, p["tf.a1"], p["tf.a2"]]).real)
    np.testing.assert_allclose(poles, [0.45, 0.992037], rtol=0, atol=1e-12)
    dc = (p["tf.b1"] + p["tf.b2"]) / (1 + p["tf.a1"] + p["tf.a2"])
    assert dc / ((0.5954 - 0.5907) / (1 - 1.3767 + 0.3816)) == pytest.approx(1.175, abs=5e-4)
    assert (p["sensor.resolution"], p["sensor.noise_rms"]) == (0.002, 0.001)
    assert dict(sc.controller) == {}
    assert sc.signal == get_scenario("track_10hz").signal
    assert sc.paper == get_scenario("track_10hz").paper


def test_user_toml_with_sines_and_extends(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('''
[parameter_sets.stiff]
"tf.b1" = 0.6

[[scenario]]
name = "my_sines"
kind = "tracking"
duration = 0.5
metric_window = [0.25, 0.5]
reference = { type = "sines", amplitudes = [2.0, 1.0], frequencies = [4.0, 8.0], phases = [0.5, 0.0], offset = 1.0 }
controller = { "rls.forgetting" = 0.99, "mv.delay" = 0 }

[[scenario]]
name = "my_mismatch"
extends = "mismatch_5hz"
plant_set = "stiff"
plant = { "sensor.noise_rms" = 0.0 }
duration = 2.0
''')
    reg = load_scenarios([f])
    sc = reg["my_sines"]
    assert sc.n_samples == 1000 and sc.metric_window == (0.25, 0.5)
    assert sc.signal.evaluate([0.1])[0] == pytest.approx(
        1.0 + 2 * math.sin(2 * math.pi * 4 * 0.1 + 0.5) + math.sin(2 * math.pi * 8 * 0.1))
    assert sc.controller == {"rls.forgetting": 0.99, "mv.delay": 0}
    mm = reg["my_mismatch"]
    # inherited: mismatch plant, reference, window clipped to the new duration
    assert mm.plant["tf.b1"] == 0.6 and mm.plant["sensor.noise_rms"] == 0.0
    assert mm.plant["creep.alpha"] == -0.0085
    assert (mm.duration, mm.metric_window) == (2.0, (1.0, 2.0))   # inherited window, clipped
    assert mm.signal == get_scenario("track_5hz").signal
    # a user scenario is not the paper's experiment: no paper values, even through extends
    assert dict(mm.paper) == {} and dict(sc.paper) == {}
    assert dict(get_scenario("mismatch_5hz").paper) == {"e_rms_um": 0.0254, "e_r": 0.0036}


def test_csv_reference_is_interpolated(tmp_path):
    (tmp_path / "ref.csv").write_text("time,y_d\n0,0\n0.1,1.0\n0.2,3.0\n0.5,3.0\n")
    f = tmp_path / "csvcase.toml"
    f.write_text('[[scenario]]\nname = "from_csv"\nkind = "tracking"\nduration = 0.5\n'
                 'reference = { type = "csv", file = "ref.csv" }\n')
    sc = load_scenario_file(f)["from_csv"]
    # linear interpolation between the rows; held after the last row (preview only)
    np.testing.assert_allclose(sc.signal.evaluate([0.05, 0.15, 0.3, 0.6]), [0.5, 2.0, 3.0, 3.0])
    assert sc.metric_window == (0.0, 0.5)


@pytest.mark.parametrize("body, needle", [
    ("[[scenario]\nname = 'x'", "TOML syntax error"),
    ("[[scenario]]\nname = 'x'\nkind = 'tracking'\n", "field 'reference': missing"),
    ("[[scenario]]\nname = 'x'\nkind = 'trackin'\nreference = {type='sines', amplitudes=[1.0], frequencies=[1.0]}\n",
     "field 'kind': must be \"tracking\" or \"validation\""),
    ("[[scenario]]\nname = 'x'\nkind = 'tracking'\nduraton = 1.0\nreference = {type='sines', amplitudes=[1.0], frequencies=[1.0]}\n",
     "unknown key(s) 'duraton'"),
    ("[[scenario]]\nname = 'x'\nkind = 'tracking'\nreference = {type='sines', amplitudes=[1.0, 2.0], frequencies=[1.0]}\n",
     "same length"),
    ("[[scenario]]\nname = 'x'\nkind = 'tracking'\nduration = 1.0001\nreference = {type='sines', amplitudes=[1.0], frequencies=[1.0]}\n",
     "not a whole number of steps"),
    ("[[scenario]]\nname = 'x'\nkind = 'tracking'\nmetric_window = [2.0, 1.0]\nreference = {type='sines', amplitudes=[1.0], frequencies=[1.0]}\n",
     "field 'metric_window'"),
    ("[[scenario]]\nname = 'x'\nkind = 'tracking'\nplant = { \"pi.w0\" = 'big' }\nreference = {type='sines', amplitudes=[1.0], frequencies=[1.0]}\n",
     "field 'plant': 'pi.w0' must be a number or a boolean"),
    ("[[scenario]]\nname = 'x'\nextends = 'track_1hz'\nduration = 1.0\n",
     "inherited from 'track_1hz' is empty for duration 1 s; set metric_window"),
    ("[[scenario]]\nname = 'x'\nextends = 'no_such'\n", "field 'extends': 'no_such' is not a known scenario"),
    ("[[scenario]]\nname = 'x'\nextends = 'track_1hz'\nplant_set = 'nope'\n", "'nope' is not a known parameter set"),
    ("[[scenario]]\nname = 'x'\nkind = 'validation'\nreference = {type='sines', amplitudes=[1.0], frequencies=[1.0]}\n",
     "takes 'input', not 'reference'"),
])
def test_malformed_files_are_rejected_with_a_message(tmp_path, body, needle):
    f = tmp_path / "bad.toml"
    f.write_text(body)
    with pytest.raises(ScenarioFileError) as info:
        load_scenarios([f])
    assert isinstance(info.value, ValueError)
    assert str(f) in str(info.value)
    assert needle in str(info.value)


@pytest.mark.parametrize("csv_text, needle", [
    ("time,y_d\n0,0\n0.1,abc\n0.6,1\n", "line 3: 'abc' is not a number"),
    ("time,y_d\n0,0\n0.2,1\n0.1,2\n0.6,1\n", "line 4: time 0.1 is not greater than the previous 0.2"),
    ("time,y_d,extra\n0,0,0\n", "line 1: expected 2 columns"),
    ("time,y_d\n0,0\n", "needs at least 2 data rows"),
    ("time,y_d\n0,0\n0.2,1\n", "covers [0, 0.2] s but the run needs [0, 0.4995] s"),
    ("stamp,y_d\n0,0\n0.6,1\n", "header's first column must be 'time'"),
])
def test_malformed_csv_is_rejected_with_a_message(tmp_path, csv_text, needle):
    (tmp_path / "ref.csv").write_text(csv_text)
    f = tmp_path / "c.toml"
    f.write_text('[[scenario]]\nname = "c"\nkind = "tracking"\nduration = 0.5\n'
                 'reference = { type = "csv", file = "ref.csv" }\n')
    with pytest.raises(ScenarioFileError) as info:
        load_scenario_file(f)
    assert needle in str(info.value)
    assert "ref.csv" in str(info.value)


def test_missing_csv_and_missing_file(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('[[scenario]]\nname = "c"\nkind = "tracking"\n'
                 'reference = { type = "csv", file = "nowhere.csv" }\n')
    with pytest.raises(ScenarioFileError, match="nowhere.csv: cannot read the CSV file"):
        load_scenario_file(f)
    with pytest.raises(ScenarioFileError, match="cannot read the scenario file"):
        load_scenario_file(tmp_path / "absent.toml")


def test_unknown_scenario_lists_known_names():
    with pytest.raises(UnknownScenarioError) as info:
        get_scenario("track_2hz")
    assert isinstance(info.value, KeyError)
    msg = str(info.value)
    assert msg.startswith("unknown scenario 'track_2hz'; known scenarios: track_1hz, track_5hz")
    assert "mismatch_1_10_20hz" in msg and "validate_100hz" in msg


# ---------------------------------------------------------------------------
# rules a user file is checked against (harness/scenarios/__init__.py's docstring)
# ---------------------------------------------------------------------------

def _one(tmp_path, body, name="s.toml"):
    f = tmp_path / name
    f.write_text(body)
    return f


@pytest.mark.parametrize("freq,ok", [(999.0, True), (1000.0, False), (2500.0, False)])
def test_a_tone_must_lie_below_nyquist(tmp_path, freq, ok):
    # Reference: sampling theorem, f_N = 1 / (2 h) = 1000 Hz at h = 0.5 ms; a tone at f_N
    # samples to sin(pi k) = 0, one above aliases.
    f = _one(tmp_path, f'[[scenario]]\nname = "t"\nkind = "tracking"\nduration = 0.5\n'
                       f'reference = {{ type = "sines", amplitudes = [1.0, 1.0], '
                       f'frequencies = [5.0, {freq}] }}\n')
    if ok:
        assert load_scenario_file(f)["t"].signal.frequencies == (5.0, freq)
    else:
        with pytest.raises(ScenarioFileError, match=r"field 'reference.frequencies': "
                                                    rf"{freq:g} Hz is at or above the Nyquist"):
            load_scenario_file(f)


def test_a_silent_tone_above_nyquist_is_allowed(tmp_path):
    f = _one(tmp_path, '[[scenario]]\nname = "t"\nkind = "validation"\nduration = 0.5\n'
                       'input = { type = "sines", amplitudes = [1.0, 0.0], '
                       'frequencies = [5.0, 3000.0], offset = 5.0 }\n')
    assert load_scenario_file(f)["t"].signal.amplitudes == (1.0, 0.0)


def test_step_size_must_be_the_fmus_sample_period(tmp_path):
    # both FMUs' h set to the step: accepted; only the plant's: the controller's default
    # h = 0.5 ms still differs, refused naming it
    both = _one(tmp_path, '[[scenario]]\nname = "slow"\nextends = "track_5hz"\n'
                          'step_size = 0.001\nplant = { h = 0.001 }\ncontroller = { h = 0.001 }\n')
    sc = load_scenarios([both])["slow"]
    assert (sc.step_size, sc.n_samples) == (0.001, 3000)
    refused = [('name = "slow"\nextends = "track_5hz"\nstep_size = 0.001\nplant = { h = 0.001 }\n', "p.toml",
                r"field 'step_size': step_size 0.001 s differs from the sample period of AdaptiveCompoundController"),
               ('name = "fast_h"\nextends = "validate_1hz"\nplant = { h = 0.001 }\n', "h.toml",
                r"field 'plant': step_size 0.0005 s differs from the sample period of PiezoStage \(its plant "
                r"override \"h\" = 0.001\)")]
    for text, file, message in refused:
        with pytest.raises(ScenarioFileError, match=message):
            load_scenarios([_one(tmp_path, "[[scenario]]\n" + text, file)])


def test_default_step_size_is_the_fmus_h():
    # Reference: the start value of h in both model descriptions; the sample-period check
    # above compares with DEFAULT_STEP_SIZE, so it must be the FMUs' h.
    import xml.etree.ElementTree as ET
    from harness.scenarios import DEFAULT_STEP_SIZE

    root = REPO / "modelDescription"
    for model in ("PiezoStage", "AdaptiveCompoundController"):
        xml = ET.parse(root / f"{model}.xml").getroot()
        var = next(v for v in xml.iter("ScalarVariable") if v.get("name") == "h")
        assert float(var.find("Real").get("start")) == DEFAULT_STEP_SIZE, model


def test_validation_scenario_takes_no_controller(tmp_path):
    for body, field in [
        ('[[scenario]]\nname = "v"\nextends = "validate_1hz"\ncontroller_set = "x"\n',
         "controller_set"),
        ('[[scenario]]\nname = "t"\nextends = "track_1hz"\n'
         'controller = { "rls.forgetting" = 0.99 }\n'
         '[[scenario]]\nname = "v"\nextends = "t"\nkind = "validation"\n'
         'input = { type = "sines", amplitudes = [1.0], frequencies = [1.0], offset = 5.0 }\n',
         "extends"),
    ]:
        f = _one(tmp_path, body)
        with pytest.raises(ScenarioFileError, match=rf"scenario 'v': field '{field}': .*"
                                                    r"(do not apply|does not apply|which do not)"):
            load_scenarios([f])


def test_names_are_unique_across_files(tmp_path):
    a = _one(tmp_path, '[[scenario]]\nname = "mine"\nextends = "track_5hz"\n', "a.toml")
    b = _one(tmp_path, '[[scenario]]\nname = "mine"\nextends = "track_10hz"\n', "b.toml")
    with pytest.raises(ScenarioFileError, match=rf"{b}: scenario 'mine': field 'name': 'mine' "
                                                rf"is already the name of a scenario of {a}"):
        load_scenarios([a, b])
    c = _one(tmp_path, '[[scenario]]\nname = "mismatch_5hz"\nextends = "mismatch_5hz"\n', "c.toml")
    with pytest.raises(ScenarioFileError, match="already the name of a built-in scenario"):
        load_scenarios([c])


@pytest.mark.parametrize("header,kind,ok", [
    ("time,y_d", "tracking", True),
    ("time [s],y_d [um]", "tracking", True),
    ("t_s,y_d_um", "tracking", True),
    ("Time,Y_D (µm)", "tracking", True),
    ("time,v", "tracking", False),
    ("time,y", "tracking", False),
    ("time,v [V]", "validation", True),
    ("time,y_d", "validation", False),
])
def test_csv_header_must_name_the_signal(tmp_path, header, kind, ok):
    (tmp_path / "sig.csv").write_text(f"{header}\n0,1\n1,2\n")
    key = "reference" if kind == "tracking" else "input"
    f = _one(tmp_path, f'[[scenario]]\nname = "c"\nkind = "{kind}"\nduration = 0.5\n'
                       f'{key} = {{ type = "csv", file = "sig.csv" }}\n')
    if ok:
        assert load_scenario_file(f)["c"].signal.evaluate([0.5])[0] == pytest.approx(1.5)
    else:
        with pytest.raises(ScenarioFileError, match=rf"scenario 'c': field '{key}.file': "
                                                    r".*sig.csv: line 1: header's second column"):
            load_scenario_file(f)


def test_a_bad_value_in_the_first_row_is_not_taken_for_a_header(tmp_path):
    (tmp_path / "r.csv").write_text("0,abc\n1,2\n")
    f = _one(tmp_path, '[[scenario]]\nname = "c"\nkind = "tracking"\nduration = 0.5\n'
                       'reference = { type = "csv", file = "r.csv" }\n')
    with pytest.raises(ScenarioFileError, match="line 1: 'abc' is not a number"):
        load_scenario_file(f)


def test_a_new_signal_kind_is_one_entry_of_the_registry(tmp_path, monkeypatch):
    """Reference: harness.scenarios.SIGNAL_KINDS, the one place a kind of signal is declared. A
    kind added there alone (a constant, as a test stand-in) is read from a scenario file, checked,
    evaluated and described through it, is fed as the input y_d (not internal), and the file's
    error for an unknown type lists it; the built-in kinds keep their file types."""
    from harness import scenarios
    assert {k: (v.file_type, v.internal, v.tracking_only) for k, v in scenarios.SIGNAL_KINDS.items()} == {
        "sines": ("sines", True, False), "table": ("csv", False, False),
        "profile": ("profile", False, True)}

    def parse(spec, path, scenario, fieldname, value_name):
        return scenarios.Signal("constant", offset=float(spec["value"]), source=str(path))

    def check(signal, step, duration, path, name, fieldname):
        if signal.offset < 0:
            raise scenarios.ScenarioFileError(path, "must be >= 0", name, fieldname)

    monkeypatch.setitem(scenarios.SIGNAL_KINDS, "constant", scenarios.SignalKind(
        "constant", "constant", internal=False, tracking_only=False, parse=parse,
        evaluate=lambda signal, t: np.full(t.shape, signal.offset),
        describe=lambda signal: f"constant {signal.offset:g} um", check=check))
    f = tmp_path / "c.toml"
    f.write_text('[[scenario]]\nname = "c"\nkind = "tracking"\nduration = 0.01\n'
                 'reference = { type = "constant", value = 3.5 }\n')
    sc = load_scenario_file(f)["c"]
    assert sc.signal.evaluate([0.0, 0.005]).tolist() == [3.5, 3.5]
    assert sc.signal.describe() == "constant 3.5 um" and not sc.signal.internal
    f.write_text(f.read_text().replace("3.5", "-1.0"))
    with pytest.raises(ScenarioFileError, match="must be >= 0"):
        load_scenario_file(f)
    f.write_text(f.read_text().replace('"constant"', '"square"'))
    with pytest.raises(ScenarioFileError, match=r'\'type\' must be one of "sines", "csv", "profile", '
                                                r'"constant", got \'square\''):
        load_scenario_file(f)
