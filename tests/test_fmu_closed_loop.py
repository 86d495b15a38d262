"""PiezoStageClosedLoop: the loop of PiezoStage, AdaptiveCompoundController and ReferenceSignal in
one FMU (issue 30), through its FMI 2.0 and FMI 3.0 editions.

Independent references:
  * the three FMUs wired by hand in a master that exchanges values at communication points
    (harness.masters.wired, schedule "exchange"): the closed-loop FMU at one-sample steps gives
    their samples bit for bit, at the defaults and on the mismatch benchmark;
  * for any other step, the FMU's own one-sample run (checked against the three FMUs): the
    outputs at a communication point t are those of the last sample instant at or before t;
  * for the input y_d, the documented rule (docs/fmus.md) written out here on the core binding
    (harness.binding.core), and the lag of a stage that follows a tone d samples late,
    sqrt(2) A sin(pi f d h) rms;
  * the components' model descriptions and C tables for the parameters' names, types, ranges,
    defaults and the core fields they set.
"""
from __future__ import annotations

import ctypes
import math
import random
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import FMU3_DIR, REPO, assert_refused
from harness.binding import core
from harness.binding.closed_loop import (CLOSED_LOOP_MODEL, CONTROLLER_PREFIX, NOMINAL_MODEL_NAMES,
                                         closed_loop_parameters)
from harness.fmu import LOOP_FAILURES, LoopFaultError, loop_error_class
from harness.loop import reference_parameters
from harness.masters.wired import simulate_wired
from harness.scenarios import get_scenario

H = 0.0005
OUTPUTS = ("y", "y_meas", "v", "reference", "error", "q", "pred_error")
# the wired master's fields of the same signals
WIRED = {"y": "y", "y_meas": "y_meas", "v": "v", "reference": "y_d", "q": "q",
         "pred_error": "pred_error"}


def initialized(fmu, params=None, start_time=0.0):
    fmu.setup(start_time, params)
    fmu.slave.exitInitializationMode()
    fmu.t = start_time
    return fmu


def read(fmu, names=OUTPUTS):
    """Real outputs by name; an Integer one (loop_delay) read as such."""
    reals = [n for n in names if fmu.package.variables[n].type == "Real"]
    values = dict(zip(reals, fmu.get_reals(reals)))
    return [values[n] if n in values else float(fmu.get(n)) for n in names]


def one_sample_run(fmu, n, names=OUTPUTS):
    """Rows of the outputs at t_0 .. t_(n-1), a step of h each."""
    rows = np.zeros((n, len(names)))
    for k in range(n):
        rows[k] = read(fmu, names)
        fmu.slave.doStep(k * H, H)
    return rows


def run_steps(fmu, sizes, names=OUTPUTS, inputs=None):
    """The outputs after each step of the given sizes (from t = 0), with y_d set before each
    step to inputs(t) when given; returns (times, rows)."""
    t, times, rows = 0.0, [], []
    vr = fmu.package.variables["y_d"].valueReference
    for size in sizes:
        if inputs is not None:
            fmu.slave.setReal([vr], [inputs(t)])
        fmu.slave.doStep(t, size)
        t += size
        times.append(t)
        rows.append(read(fmu, names))
    return np.array(times), np.array(rows)


def sample_index(t):
    """The last sample instant at or before t (the grid's tolerance)."""
    return int(math.floor(t / H + 1e-6))


# ---------------------------------------------------------------------------------------------
# the three FMUs, bit for bit


@pytest.mark.parametrize("scenario", ["track_1hz", "mismatch_1_5_10hz"])
def test_one_sample_steps_give_the_three_fmus_samples_bit_for_bit(closed_loop, make_fmu, scenario):
    """Reference: the three FMUs wired by hand, exchange schedule (harness.masters.wired), 3 s.
    track_1hz is every FMU at its defaults (ReferenceSignal's default is that tone); the
    mismatch benchmark sets the stage apart from the controller's model and adds sensor noise."""
    sc = get_scenario(scenario)
    wired = simulate_wired(scenario, "exchange")
    assert wired.error == "" and len(wired.samples) == 6000
    params = {} if scenario == "track_1hz" else closed_loop_parameters(
        plant=sc.plant, controller=sc.controller, reference=reference_parameters(sc))
    fmu = initialized(make_fmu(closed_loop), params)
    rows = one_sample_run(fmu, 6000, OUTPUTS + ("loop_delay",))
    for i, name in enumerate(OUTPUTS):
        if name in WIRED:
            assert np.array_equal(rows[:, i], wired.samples[WIRED[name]]), name
    assert np.array_equal(rows[:, 4], wired.samples["y_d"] - wired.samples["y"])   # error
    assert np.array_equal(rows[:, -1], wired.samples["loop_delay"])
    assert rows[-1, -1] == 2                        # the delay of an exchanging master, detected


def test_the_fmi3_edition_gives_the_fmi2_editions_samples(closed_loop, make_fmu):
    """Reference: the FMI 2.0 edition (same model code, other glue), with 10 ms steps."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave
    fmu = initialized(make_fmu(closed_loop))
    _, want = run_steps(fmu, [0.01] * 100)
    path = FMU3_DIR / f"{CLOSED_LOOP_MODEL}.fmu"
    md = read_model_description(str(path))
    f3 = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=CLOSED_LOOP_MODEL,
                   instanceName="fmi3")
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    f3.instantiate()
    f3.enterInitializationMode(startTime=0.0)
    f3.exitInitializationMode()
    got = []
    t = 0.0
    for _ in range(100):
        f3.doStep(t, 0.01)
        t += 0.01
        got.append(f3.getFloat64([vrs[n] for n in OUTPUTS]))
    assert f3.getFloat64([vrs["time"]])[0] == pytest.approx(1.0, abs=1e-12)
    f3.terminate()
    f3.freeInstance()
    assert np.array_equal(np.array(got), want)


# ---------------------------------------------------------------------------------------------
# any communication step


def test_steps_of_10_ms_end_on_the_samples_of_one_sample_steps(closed_loop, make_fmu):
    """Reference: the one-sample run: after a step of 10 ms (20 samples) the outputs are those of
    sample 20 j, bit for bit; the step ends on the grid (FMI 2.0 lastSuccessfulTime)."""
    from fmpy.fmi2 import fmi2LastSuccessfulTime
    want = one_sample_run(initialized(make_fmu(closed_loop)), 3001)
    fmu = initialized(make_fmu(closed_loop))
    times, got = run_steps(fmu, [0.01] * 150)
    assert np.array_equal(got, want[20::20])
    assert fmu.slave.getRealStatus(fmi2LastSuccessfulTime) == pytest.approx(1.5, abs=1e-12)


def test_variable_steps_that_end_between_samples_hold_the_last_samples_outputs(closed_loop, make_fmu):
    """Reference: the one-sample run: at any communication point t the outputs are those of
    sample floor(t / h) (the last instant at or before t), for 400 steps drawn from 0.1 h to
    7.3 h, grid-aligned ones among them; time after the last step is their sum."""
    rng = random.Random(30)
    sizes = [rng.choice((0.1, 0.37, 1.0, 1.5, 2.0, 2.25, 7.3)) * H for _ in range(400)]
    total = sum(sizes)
    want = one_sample_run(initialized(make_fmu(closed_loop)), sample_index(total) + 1)
    fmu = initialized(make_fmu(closed_loop))
    times, got = run_steps(fmu, sizes)
    for t, row in zip(times, got):
        assert np.array_equal(row, want[sample_index(t)]), t
    assert fmu.errors() == []


def test_each_sample_reads_y_d_at_its_own_instant(closed_loop, make_fmu):
    """Reference: the same FMU at one-sample steps given, at each t_k, the y_d that a master of
    steps of 0.7 h held at t_k (the value set at its last point at or before t_k): samples whose
    instant lies inside a step that ended past it read that (latched) value, not the one set at
    the next point. The outputs of the stage and the controller agree at every point; reference
    is the y_d of the last instant's sample (between instants: the latched value; on an
    instant: the input as set, which the next sample reads), and error = reference - y."""
    step, n = 0.7 * H, 600
    def y_d(t):                     # changes at every point of the master of 0.7 h steps
        return 5.0 * math.sin(2 * math.pi * 3.0 * t) + 1e3 * t
    params = {"use_internal_reference": False, "y_d_lead": 0}
    fmu = initialized(make_fmu(closed_loop), params)
    times, got = run_steps(fmu, [step] * n, inputs=y_d)
    points = [0.0] + list(times[:-1])           # where that master set y_d (its own sums)

    def held_at(k):                 # its last point at or before t_k
        return max(p for p in points if p <= k * H + 1e-9 * H)
    ref = initialized(make_fmu(closed_loop), params)
    vr = closed_loop.variables["y_d"].valueReference
    want, last = [], sample_index(times[-1])
    for k in range(last + 1):
        ref.slave.setReal([vr], [y_d(held_at(k))])
        want.append(read(ref))
        if k < last:
            ref.slave.doStep(k * H, H)
    state = [OUTPUTS.index(name) for name in ("y", "y_meas", "v", "q", "pred_error")]
    on_instant = 0
    for t, row in zip(times, got):
        k = sample_index(t)
        assert np.array_equal(row[state], np.array(want[k])[state]), t
        if abs(t - k * H) < 1e-9 * H:           # on the instant: the value set before it, at t - step
            on_instant += 1
            assert row[OUTPUTS.index("reference")] == y_d(points[list(times).index(t)]), t
        else:
            assert row[OUTPUTS.index("reference")] == y_d(held_at(k)), t
        assert row[OUTPUTS.index("error")] == row[OUTPUTS.index("reference")] - row[0]
    assert on_instant == n // 10                # every 10th point (7 samples) is on an instant


def test_a_step_of_zero_or_below_or_not_finite_is_refused_naming_it(closed_loop, make_fmu):
    """Each refused with fmi2Error and its own message, which names the value; nothing changes:
    the state's bytes stay those before, and the FMU steps on from t = 0, after which a step
    from the old time is refused naming the FMU's."""
    fmu = initialized(make_fmu(closed_loop))

    def state():
        return fmu.slave.serializeFMUstate(fmu.slave.getFMUstate())

    before = state()
    for size, shown in ((0.0, "0"), (-H, "-0.0005"), (math.inf, "inf"), (math.nan, "nan")):
        assert_refused(lambda: fmu.slave.doStep(0.0, size), fmu,
                       f"fmi2DoStep: communicationStepSize = {shown} refused: the step size must be > 0 and finite",
                       "state and time unchanged")
        assert state() == before, size
    fmu.slave.doStep(0.0, 0.3 * H)           # still usable: nothing changed
    assert_refused(lambda: fmu.slave.doStep(0.0, H), fmu,    # the FMU's time is 0.3 h now
                   "currentCommunicationPoint = 0 does not match the FMU time", "= 0.00015 (k = 0, h = 0.0005)")


def test_a_state_saved_between_two_samples_continues_there(closed_loop, make_fmu):
    """Reference: an uninterrupted run of the same steps. The state is saved and serialized at
    t = 1.3 h (between samples, y_d latched for sample 1), restored into another instance, which
    continues as the first did."""
    params = {"use_internal_reference": False, "y_d_lead": 2}
    sizes = [1.3 * H] + [0.9 * H] * 50
    inputs = lambda t: 3.0 + 10.0 * t      # noqa: E731
    fmu = initialized(make_fmu(closed_loop), params)
    _, want = run_steps(fmu, sizes, inputs=inputs)
    a = initialized(make_fmu(closed_loop), params)
    run_steps(a, sizes[:1], inputs=inputs)
    blob = a.slave.serializeFMUstate(a.slave.getFMUstate())
    b = initialized(make_fmu(closed_loop), params)
    b.slave.setFMUstate(b.slave.deSerializeFMUstate(blob))
    vr = closed_loop.variables["y_d"].valueReference
    t, got = sizes[0], []
    for size in sizes[1:]:
        b.slave.setReal([vr], [inputs(t)])
        b.slave.doStep(t, size)
        t += size
        got.append(read(b))
    assert np.array_equal(np.array(got), want[1:])


# ---------------------------------------------------------------------------------------------
# the input y_d


def _documented_external_loop(n, lead, y_d_at):
    """The documented rule on the core binding: at sample k the controller gets y_ref = y_d(k +
    lead) (the sampled input) and the same value as a preview of lead `lead`; the stage applies
    the v of the sample before; reference(k) is the input sampled lead samples before (the
    input now until then)."""
    plant, ctrl = core.Plant({"h": H}), core.Controller({"h": H})
    lib = core.lib()
    out, published = plant.output, ctrl.output
    rows, inputs = [], []
    for k in range(n):
        now = y_d_at(k + lead)
        inputs.append(now)
        reference = inputs[k - lead] if k >= lead else now
        rows.append((out.y, out.y_meas, published.v, reference, reference - out.y))
        c = ctrl.step_input(now, out.y_meas, now, lead if 1 <= lead < 16 else 0)
        out = plant.step(lib.piezo_plant_rated_voltage(published.v))
        published = c
    return np.array(rows)


@pytest.mark.parametrize("lead", [0, 4])
def test_the_input_y_d_follows_the_documented_rule(closed_loop, make_fmu, lead):
    """Reference: the rule of docs/fmus.md written out on the core binding (above), 2 s of the
    default 10 um, 1 Hz tone given y_d_lead samples ahead at one-sample steps, bit for bit."""
    n = 4000
    tone = lambda k: 10.0 * math.sin(2 * math.pi * 1.0 * k * H)    # noqa: E731
    fmu = initialized(make_fmu(closed_loop), {"use_internal_reference": False, "y_d_lead": lead})
    vr = closed_loop.variables["y_d"].valueReference
    got = []
    for k in range(n):
        fmu.slave.setReal([vr], [tone(k + lead)])
        got.append(read(fmu, OUTPUTS[:5]))
        fmu.slave.doStep(k * H, H)
    assert np.array_equal(np.array(got), _documented_external_loop(n, lead, tone))


def test_without_lead_the_stage_follows_y_d_d_samples_late(closed_loop, make_fmu):
    """Reference: a stage that follows a tone of amplitude A and frequency f d samples late is
    off by sqrt(2) A sin(pi f d h) rms (d = 2: 44.4 nm for 10 um at 1 Hz); with y_d_lead = 4
    (>= d) it follows without lag (below 1 nm on the nominal stage). y_d set from the tone at each
    point of a master of 10 ms steps; the error y_d(t) - y(t) over [1, 3) s."""
    tone = lambda t: 10.0 * math.sin(2 * math.pi * t)       # noqa: E731
    errors = {}
    for lead in (0, 4):
        fmu = initialized(make_fmu(closed_loop), {"use_internal_reference": False, "y_d_lead": lead})
        times, rows = run_steps(fmu, [H] * 6000, names=("y",), inputs=lambda t, l=lead: tone(t + l * H))
        e = np.array([tone(t) for t in times]) - rows[:, 0]
        errors[lead] = float(np.sqrt(np.mean(e[1999:5999] ** 2)))
        warnings = [text for status, _, text in fmu.messages if status == 1]
        assert any("follows y_d 2 samples" in w for w in warnings) == (lead == 0), warnings
    lag = math.sqrt(2) * 10.0 * math.sin(math.pi * 1.0 * 2 * H)
    assert errors[0] == pytest.approx(lag, rel=0.02)
    assert errors[4] < 1e-3


# ---------------------------------------------------------------------------------------------
# the controller's supervision and the parameters


@pytest.mark.parametrize("stage, fault", [({"tf.b1": -0.5954, "tf.b2": 0.5907}, "inverted response"),
                                          ({"tf.b1": 0.05954, "tf.b2": -0.05907}, None)])
def test_the_supervisions_error_surfaces_from_the_doStep(closed_loop, make_fmu, stage, fault):
    """Reference: the three FMUs wired by hand (exchange schedule) with the same stage: the
    controller's Error at the same sample, with the same verdict and evidence word for word (up
    to "it moved ... um"); then each says what to check where it is: the wired controller names
    the connections, this FMU its own parameters, the stage's against the controller's model
    (pi.w* and controller.pi.w*, tf.* and controller.tf.*), and no connection it does not have.
    A stage whose response is inverted (tf.b1, tf.b2 negated: the fault table of
    docs/robustness.md) and one with a tenth of the model's gain; harness.fmu classifies the
    Error as a LoopFaultError by its first words (LOOP_FAILURES). The FMU is then in state
    Error."""
    wired = simulate_wired("track_1hz", "exchange", duration=2.0, plant_params=stage)
    assert wired.error.startswith("fmi2DoStep: supervision stopped the loop ("), wired.error
    if fault is not None:
        assert wired.error.startswith(f"fmi2DoStep: supervision stopped the loop ({fault})")
    fmu = initialized(make_fmu(closed_loop), stage)
    k = 0
    with pytest.raises(Exception):
        for k in range(4000):
            fmu.slave.doStep(k * H, H)
    assert k * H == pytest.approx(wired.error_time, abs=1e-12)
    evidence = re.compile(r"^(.*?it moved \S+ um)")
    own = fmu.errors()[0]
    assert evidence.match(own).group(1) == evidence.match(wired.error).group(1)
    assert "Check the connections" in wired.error or "Check the sign" in wired.error, wired.error
    assert "controller.pi.w0" in own and "controller.tf.b1" in own, own
    assert not re.search(r"connection|PiezoStage\.|AdaptiveCompoundController\.|amplifier", own), own
    assert LOOP_FAILURES[0][0] in own
    assert loop_error_class([f"[Error] {e}" for e in fmu.errors()]) is LoopFaultError
    assert "enters state Error" in fmu.errors()[-1]


@pytest.mark.parametrize("name, value, words", [
    ("controller.tf.b1", -1.0, "controller.tf.b1 = -1 is out of range: valid range (0, inf)"),
    ("tf.a2", 1.5, "tf.a2 = 1.5 is out of range: valid range |tf.a2| < 1"),
    ("y_d_lead", 16, "y_d_lead = 16 is out of range: valid range 0..15 samples"),
    ("frequency[2]", 1000.0, "frequency[2] = 1000 is out of range"),
    ("sup.window", 5, "sup.window = 5 is out of range: valid range 20..1000000"),
])
def test_a_bad_parameter_is_refused_naming_it_and_its_range(closed_loop, make_fmu, name, value, words):
    fmu = make_fmu(closed_loop)
    fmu.setup(0.0, {name: value})
    with pytest.raises(Exception):
        fmu.slave.exitInitializationMode()
    assert words in fmu.last_error(), fmu.last_error()


def test_both_creep_operators_exact_is_refused_naming_the_controllers(closed_loop, make_fmu):
    fmu = make_fmu(closed_loop)
    fmu.setup(0.0, {"creep.exact": True, "controller.creep.exact": True})
    with pytest.raises(Exception):
        fmu.slave.exitInitializationMode()
    assert "controller.creep.exact = 1 is out of range: valid range false while the stage's " \
           "creep.exact is true" in fmu.last_error()
    for exact in ("creep.exact", "controller.creep.exact"):   # either alone runs, on the grid's history
        one = initialized(make_fmu(closed_loop), {exact: True})
        _, rows = run_steps(one, [0.01] * 10)
        assert np.all(np.isfinite(rows)) and one.errors() == []


def _xml_variables(model, fmi="2.0"):
    from xml.etree import ElementTree as ET
    path = REPO / "modelDescription" / ("fmi3" if fmi == "3.0" else "") / f"{model}.xml"
    out = {}
    for var in ET.parse(path).getroot().find("ModelVariables"):
        (typ,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean")]
        out[var.get("name")] = (var.get("causality"), typ.tag,
                                {k: v for k, v in typ.attrib.items() if k in ("unit", "min", "max", "start")})
    return out


def test_every_component_parameter_is_here_under_its_name_range_and_default():
    """Reference: the components' FMI 2.0 model descriptions: every parameter of PiezoStage and
    ReferenceSignal under its name, AdaptiveCompoundController's under its name or, for its
    nominal model, controller.<name>, with the same type, unit, range and start; mv.hold_inputs
    alone missing; h once."""
    loop = _xml_variables(CLOSED_LOOP_MODEL)
    expected = {}
    for model in ("PiezoStage", "ReferenceSignal", "AdaptiveCompoundController"):
        for name, (causality, typ, attrs) in _xml_variables(model).items():
            if causality != "parameter" or name in ("h", "mv.hold_inputs"):
                continue
            here = CONTROLLER_PREFIX + name if (model == "AdaptiveCompoundController"
                                                and name in NOMINAL_MODEL_NAMES) else name
            assert here not in expected, here
            expected[here] = (causality, typ, attrs)
    own = {"h", "use_internal_reference", "y_d_lead"}
    params = {n: v for n, v in loop.items() if v[0] == "parameter"}
    assert set(params) == set(expected) | own
    for name, want in expected.items():
        assert params[name] == want, name
    assert params["h"][2] == {"unit": "s", "min": "0", "start": "0.0005"}


def test_every_parameter_sets_the_core_field_the_components_parameter_sets(tmp_path):
    """Reference: the C tables of the four models (tests/model_table): each closed-loop
    parameter lies in the closed loop's stage, control or ref_params struct at the offset the
    component's lies in its params struct, with its start value."""
    from test_variable_sources import compile_table
    loop = compile_table(CLOSED_LOOP_MODEL, tmp_path)
    structs = loop["param_structs"]
    comps = {"stage": compile_table("PiezoStage", tmp_path),
             "control": compile_table("AdaptiveCompoundController", tmp_path),
             "ref_params": compile_table("ReferenceSignal", tmp_path)}
    checked = 0
    for e in loop["variables"]:
        if e["causality"] != "parameter" or e["name"] in ("use_internal_reference", "y_d_lead"):
            continue
        struct = next(s for s, (off, size) in structs.items() if off <= e["offset"] < off + size)
        name = e["name"]
        if struct == "control" and name.startswith(CONTROLLER_PREFIX):
            name = name[len(CONTROLLER_PREFIX):]
        comp = {c["name"]: c for c in comps[struct]["variables"]}[name]
        assert (e["offset"] - structs[struct][0], e["type"], e["start"]) == \
               (comp["offset"] - comps[struct]["param_structs"]["params"][0], comp["type"], comp["start"]), e
        checked += 1
    assert checked == len([e for e in loop["variables"] if e["causality"] == "parameter"]) - 2
