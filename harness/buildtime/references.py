"""Reference results of one FMU for regression tests (FMI-LS-REF 1.0.0-alpha.1).

Writes into ``--out`` the files the build puts in the FMU's
``extra/org.fmi-standard.fmi-ls-ref/``:

* ``fmi-ls-manifest.xml``: the layered standard's manifest (``<fmiReferences>``), one
  ``<Related>`` per file below;
* ``experiments.exp``: the experiment (``<Experiments>``, MIME type
  ``application/x-ma-ls-experiments``): start, stop, step size, tolerance, and the
  parameters, stimuli and references files;
* ``<id>_params.ssv``: the experiment's parameter values (SSP 1.0 SSV), if any;
* ``<id>_in.csv``: the stimuli, one row per sample ``t_k = k h`` (none for ReferenceSignal);
* ``<id>_ref.csv``: the reference outputs at every ``t_k``.

The reference outputs are computed on the C core through the cffi binding
(``harness.binding.core``), not through the FMU, so an FMU that re-simulates them checks its
FMI layer against the core. CSV values are written with Python's shortest round-trip
``repr``, so they read back bit for bit. The tolerance of an experiment means: at every
sample, ``|y - y_ref| <= tolerance * (1 + |y_ref|)``.

Two kinds of FMU have experiments here:

* the built FMUs (no start values given): the experiments of :data:`EXPERIMENTS`, on
  the project's benchmark (the mismatched plant);
* an FMU that ``python -m harness export`` parameterised with an identified stage
  (``start_values``: every parameter of that FMU): the experiments of
  :data:`EXPORT_EXPERIMENTS`, which run the FMU's own start values, so that its
  references test the model it now carries.

CMake runs ``python -m harness.buildtime.references`` with ``PIEZO_CORE_LIB`` and
``PIEZO_CORE_INCLUDE`` set to the build's core library and headers
(cmake/PiezoFmu.cmake, ``piezo_fmu_reference_results``).
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
import sys
from xml.etree import ElementTree as ET
from xml.sax.saxutils import quoteattr

from ..binding import core
from ..binding.closed_loop import CLOSED_LOOP_MODEL, closed_loop_parameters, component_parameters
from ..loop import REFERENCE_PREVIEW, loop_delay, reference_parameters
from ..scenarios import load_scenarios

LS_REF_VERSION = "1.0.0-alpha.1"
LS_REF_DESCRIPTION = "Layered Standard providing information on related files included in an FMU."
EXPERIMENTS_FILE = "experiments.exp"
#: see the module docstring
TOLERANCE = 1e-9
STEP = 0.0005
DURATION = 0.5

#: what each FMU's experiment is (name, description)
EXPERIMENTS = {
    "PiezoStage": (
        "mismatch_plant_mixed_voltage",
        "Open loop: the paper's mixed validation voltage v = 6 (sin 2 pi 5 t + sin 2 pi 40 t + "
        "sin 2 pi 80 t) + 18 V on the mismatched plant of the tracking benchmark (PI weights +10 %, "
        "creep of Table 1's 10 Hz row, G numerator x1.05 with the fast pole at 0.45, sensor with "
        "2 nm resolution and 1 nm rms noise, seed 1)."),
    "AdaptiveCompoundController": (
        "closed_loop_mismatch_1_5_10hz_d1",
        "The controller with mv.delay = 0 (d = 1) replaying the inputs it received in a closed "
        "loop with the mismatched plant tracking 10 um at 1, 5 and 10 Hz, run by a master that "
        "hands the plant the controller's post-step output: y_ref = y_d(t + h), the plant's "
        "noisy y_meas and its time stamp t_meas = t, and ReferenceSignal's stamped preview "
        "y_preview = y_d(t + 4 h), t_preview = t + 4 h (used from the second sample on: "
        "preview_lead = 4). The RLS adapts; the outputs include the estimates. (The detected "
        "delay and the default d = 2 are not replayable: without the plant's feedback a "
        "last-bit difference grows to volts within 50 samples.)"),
    "ReferenceSignal": (
        "sines_1_5_10hz",
        "Three 10 um tones at 1, 5 and 10 Hz with the preview lead = 2 samples and the "
        "stamped preview 4 samples ahead."),
    CLOSED_LOOP_MODEL: (
        "closed_loop_mismatch_1_5_10hz",
        "The tracking benchmark: the mismatched stage (PI weights +10 %, creep of Table 1's 10 Hz "
        "row, G numerator x1.05 with the fast pole at 0.45, sensor with 1 nm rms noise, seed 1, "
        "without the benchmark's 2 nm quantisation, which would turn a last-bit difference of "
        "another platform's sines into a 2 nm reading) under the controller with its nominal model, "
        "tracking the internal reference of three 10 um tones at 1, 5 and 10 Hz; the loop delay "
        "detected, the RLS adapting, the supervision on. The samples of PiezoStage, "
        "AdaptiveCompoundController and ReferenceSignal wired in a master that exchanges values at "
        "communication points."),
}
#: the experiments of an exported (parameterised) FMU: they run its own start values
EXPORT_EXPERIMENTS = {
    "PiezoStage": (
        "exported_stage_mixed_voltage",
        "Open loop: the paper's mixed validation voltage v = 6 (sin 2 pi 5 t + sin 2 pi 40 t + "
        "sin 2 pi 80 t) + 18 V on this FMU's own parameters (its start values: the stage it was "
        "exported for). No parameter is set."),
    "AdaptiveCompoundController": (
        "closed_loop_exported_stage_1_5_10hz_d1",
        "The controller with its own nominal model (its start values: the stage it was exported "
        "for) and mv.delay = 0 (d = 1), replaying the inputs it received in a closed loop with "
        "that stage (with a 2 nm resolution, 1 nm rms sensor, seed 1) tracking 10 um at 1, 5 and "
        "10 Hz, run by a master that hands the plant the controller's post-step output: "
        "y_ref = y_d(t + h), the plant's y_meas and its time stamp t_meas = t, and the stamped "
        "preview y_preview = y_d(t + 4 h), t_preview = t + 4 h (used from the second sample on). "
        "The RLS adapts; the outputs include the estimates."),
    CLOSED_LOOP_MODEL: (
        "closed_loop_exported_stage_1_5_10hz",
        "This FMU's own parameters (its start values: the stage it was exported for, and the "
        "controller with that stage as its nominal model) tracking the internal reference of "
        "three 10 um tones at 1, 5 and 10 Hz. Only the reference's tones are set."),
}
#: the sensor of the exported controller's closed loop
EXPORT_SENSOR = {"sensor.resolution": 0.002, "sensor.noise_rms": 0.001, "sensor.seed": 1}


# ---------------------------------------------------------------------------
# the model description: variable types, for typed parameter values
# ---------------------------------------------------------------------------

#: FMI 3.0 type elements -> the SSP 1.0 type of their values
FMI3_TYPES = {"Float64": "Real", "Float32": "Real", "Int8": "Integer", "UInt8": "Integer",
              "Int16": "Integer", "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer",
              "Int64": "Integer", "UInt64": "Integer", "Boolean": "Boolean", "String": "String"}


def variable_types(model_description):
    """{name: "Real" | "Integer" | "Boolean" | ...} of a modelDescription.xml.

    FMI 3.0: the types are named as in SSP 1.0 (Float64 -> Real, Int32 -> Integer), and an
    array variable ``name`` of n elements gives its elements ``name[1]`` .. ``name[n]``, the
    names the experiment's parameter file uses (FMI 3.0 structured names of the elements).
    ``model_description`` is a path, or the XML text itself.
    """
    if isinstance(model_description, str) and model_description.lstrip().startswith("<"):
        root = ET.fromstring(model_description.encode("utf-8"))
    else:
        root = ET.parse(model_description).getroot()
    types = {}
    if root.get("fmiVersion", "").startswith("3"):
        for var in root.find("ModelVariables"):
            kind = FMI3_TYPES.get(var.tag)
            if kind is None:
                continue
            dims = var.findall("Dimension")
            if not dims:
                types[var.get("name")] = kind
                continue
            (dim,) = dims                           # our arrays are one-dimensional
            for i in range(1, int(dim.get("start")) + 1):
                types[f"{var.get('name')}[{i}]"] = kind
        return types
    for var in root.iter("ScalarVariable"):
        (typ,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean", "String", "Enumeration")]
        types[var.get("name")] = typ.tag
    return types


# ---------------------------------------------------------------------------
# the experiments, on the C core
# ---------------------------------------------------------------------------

def _grid(n):
    return [k * STEP for k in range(n + 1)]


def piezo_stage(start_values=None, plant_start_values=None):
    """(parameters, stimuli columns, reference columns) of the PiezoStage experiment.

    ``start_values``: every parameter of an exported PiezoStage (its experiment then sets
    none and runs them); None for the built FMU (the mismatched plant's parameters).
    """
    if start_values is None:
        params, base = dict(load_scenarios()["mismatch_1_5_10hz"].plant), {}
    else:
        params, base = {}, dict(start_values)
    n = int(round(DURATION / STEP))
    time = _grid(n)
    v = [6.0 * (math.sin(2 * math.pi * 5 * t) + math.sin(2 * math.pi * 40 * t)
                + math.sin(2 * math.pi * 80 * t)) + 18.0 for t in time]
    plant = core.Plant(dict(base, **params, h=STEP))
    names = ("y", "y_meas", "u", "x")
    rows = {name: [] for name in names}
    out = plant.output
    for k in range(n + 1):
        for name in names:
            rows[name].append(getattr(out, name))
        if k < n:
            out = plant.step(v[k])
    # t_meas: the time of the outputs, t0 + k h
    return params, {"time": time, "v": v}, {"time": time, **rows, "t_meas": list(time)}


def adaptive_compound_controller(start_values=None, plant_start_values=None):
    """(parameters, stimuli, references) of the controller experiment: the inputs it saw in a
    core closed loop of the mismatch 1/5/10 Hz scenario, sample by sample.

    For an exported controller (``start_values``: its every parameter) the loop's plant is
    the stage it was exported for (``plant_start_values``, with :data:`EXPORT_SENSOR`),
    and the controller runs its own start values.

    The loop is the one of a master that hands the plant the controller's post-step output
    (the plant applies over [t_k, t_(k+1)) the v computed from the inputs of t_k), so the
    controller runs with mv.delay = 0 (d = 1) and y_ref = y_d(t + h). Not the default d = 2:
    replayed without the plant's feedback, the d = 2 law is unstable (its Diophantine factor
    E has a root at -a1, about -1.38, outside the unit circle), and a difference in the last
    bit of an input grows to 150 V within 50 samples, so no tolerance could hold across
    compilers. With d = 1 the replay's recursion has its pole at the zero of B (0.992) and a
    relative input change of 1e-15 moves v by about 4e-11 V.
    """
    scenario = load_scenarios()["mismatch_1_5_10hz"]
    params = {"mv.delay": 0}
    n = int(round(DURATION / STEP))
    time = _grid(n)
    base = {} if start_values is None else dict(start_values)
    plant_params = (dict(scenario.plant) if start_values is None
                    else dict(plant_start_values or {}, **EXPORT_SENSOR))
    ctrl = core.Controller(dict(base, **params, h=STEP))
    d, preview = loop_delay(params), REFERENCE_PREVIEW
    y_ref = [float(x) for x in scenario.signal.evaluate([(k + d) * STEP for k in range(n + 1)])]
    y_preview = [float(x) for x in scenario.signal.evaluate([(k + preview) * STEP for k in range(n + 1)])]
    t_preview = [(k + preview) * STEP for k in range(n + 1)]
    plant = core.Plant(dict(plant_params, h=STEP))
    stimuli = {"time": time, "y_ref": y_ref, "y_meas": [], "y_preview": y_preview,
               "t_preview": t_preview, "t_meas": list(time)}
    fields = (("v", "v"), ("q", "q"), ("est.a1", "a1"), ("est.a2", "a2"), ("est.b1", "b1"),
              ("est.b2", "b2"), ("pred_error", "pred_error"), ("saturated", "saturated"),
              ("est.adapting", "adapting"), ("est.noise", "noise"))
    refs = {"time": time, **{name: [] for name, _ in fields},
            "loop_delay": [], "loop_delay_time": [], "preview_lead": [], "meas_offset": [],
            "sup.status": [], "sup.gain": [], "sup.delay": [], "sup.fault": [], "sup.fault_time": [],
            "est.fallbacks": []}
    published, out, lead_used = ctrl.output, plant.output, 0
    sup = ctrl.raw.sup
    for k in range(n + 1):
        stimuli["y_meas"].append(out.y_meas)
        for name, field in fields:
            value = getattr(published, field)
            refs[name].append(int(value) if name in ("saturated", "est.adapting") else value)
        # the set delay holds from t0; the stamps count once they have advanced (sample 1 on)
        refs["loop_delay"].append(d)
        refs["loop_delay_time"].append(0.0)
        refs["preview_lead"].append(lead_used)
        refs["meas_offset"].append(0)
        # the supervision as of the last sample (every stamp connected: no warning, status 0 or 1)
        refs["sup.status"].append(int(sup.status))
        refs["sup.gain"].append(float(sup.gain))
        refs["sup.delay"].append(int(sup.delay))
        # the safe state (sup.reaction = 1 only; the experiment runs no fault): 0 throughout
        refs["sup.fault"].append(ctrl.fault)
        refs["sup.fault_time"].append(0.0 if not ctrl.fault else ctrl.fault_sample * STEP)
        refs["est.fallbacks"].append(int(ctrl.raw.n_fallbacks))
        if k < n:
            lead = preview if k > 0 else 0
            published = ctrl.step_input(y_ref[k], out.y_meas, y_preview[k], lead)  # published at t_(k+1) ...
            out = plant.step(published.v)                                         # ... applied over [t_k, t_(k+1))
            lead_used = lead if published.preview else 0
    return params, stimuli, refs


def _reference(params, h):
    """A core reference (cffi ``piezo_reference *``) at sample 0 of t0 = 0: the defaults with
    ReferenceSignal's parameters ``params`` by name."""
    lib, ffi = core.lib(), core.ffi
    p = ffi.new("piezo_reference_params *")
    lib.piezo_reference_default_params(p)
    p.h = h
    for name, value in params.items():
        if "[" in name:
            array, index = name[:-1].split("[")
            getattr(p, array)[int(index) - 1] = value
        else:
            setattr(p, name, value)
    ref = ffi.new("piezo_reference *")
    diag = ffi.new("piezo_diag *")
    if lib.piezo_reference_init(ref, p, 0.0, diag) != core.PIEZO_OK:
        raise RuntimeError("piezo_reference_init refused the experiment's parameters")
    return ref


def reference_signal(start_values=None, plant_start_values=None):
    """(parameters, no stimuli, references) of the ReferenceSignal experiment (never exported)."""
    params = {"lead": 2, "preview": 4}
    for i, f in enumerate((1.0, 5.0, 10.0), start=1):
        params[f"amplitude[{i}]"] = 10.0
        params[f"frequency[{i}]"] = f
    lib = core.lib()
    ref = _reference(params, STEP)
    n = int(round(DURATION / STEP))
    time = _grid(n)
    refs = {"time": time, "y_d": [], "y_ref": [], "y_preview": [], "t_preview": []}
    for k in range(n + 1):
        for name in refs:
            if name != "time":
                refs[name].append(getattr(ref, name))
        if k < n and lib.piezo_reference_step(ref) != core.PIEZO_OK:
            raise RuntimeError(f"piezo_reference_step failed at sample {k}")
    return params, None, refs


def piezo_stage_closed_loop(start_values=None, plant_start_values=None):
    """(parameters, no stimuli, references) of the closed-loop experiment: the loop of the
    three FMUs computed on the core's three blocks sample by sample as PiezoStageClosedLoop
    runs it (fmu_src/PiezoStageClosedLoop/model.c: the controller gets y_ref(k) and, from
    sample 1 on, the stamped preview; the stage applies the v of the sample before, clamped to
    its rated range; with mv.feedthrough, this sample's).

    ``start_values``: every parameter of an exported closed-loop FMU (its experiment sets only
    the reference's tones); None for the built FMU (the mismatched stage of the benchmark).
    """
    scenario = load_scenarios()["mismatch_1_5_10hz"]
    reference = reference_parameters(scenario)
    if start_values is None:
        # the sensor without its 2 nm grid: a last-bit difference of a libm (the reference's sines on
        # another platform) would round a reading to the neighbouring step, 2 nm off, beyond the
        # tolerance; the noise stays
        stage = dict(scenario.plant, **{"sensor.resolution": 0.0})
        params, base = closed_loop_parameters(plant=stage, reference=reference), {}
    else:
        params, base = dict(reference), dict(start_values)
    plant_p, ctrl_p, rest = component_parameters({**base, **params})
    loop_own = ("use_internal_reference", "y_d_lead")
    ref = _reference({k: v for k, v in rest.items() if k not in loop_own}, STEP)
    plant = core.Plant({**plant_p, "h": STEP})
    ctrl = core.Controller({**ctrl_p, "h": STEP})
    lib = core.lib()
    preview = int(ref.p.preview)
    preview = preview if 1 <= preview < lib.PIEZO_PREVIEW_RING else 0
    feedthrough = bool(ctrl.params["mv.feedthrough"])
    n = int(round(DURATION / STEP))
    time = _grid(n)
    fields = (("y", None), ("y_meas", None), ("v", "v"), ("reference", None), ("error", None),
              ("u", None), ("x", None), ("q", "q"), ("est.a1", "a1"), ("est.a2", "a2"),
              ("est.b1", "b1"), ("est.b2", "b2"), ("pred_error", "pred_error"),
              ("saturated", "saturated"), ("loop_delay", None), ("loop_delay_time", None),
              ("preview_lead", None), ("sup.status", None), ("sup.gain", None), ("sup.delay", None),
              ("est.adapting", "adapting"), ("est.noise", "noise"),
              ("sup.fault", None), ("sup.fault_time", None), ("est.fallbacks", None))
    refs = {"time": time, **{name: [] for name, _ in fields}}
    published, out = ctrl.output, plant.output
    sup = ctrl.raw.sup
    # the delay of the committed samples and the sample from which it has held (0 while detecting)
    delay, delay_time, lead_used = (0 if ctrl.raw.detecting else int(ctrl.raw.d)), 0.0, 0
    for k in range(n + 1):
        loop = {"y": out.y, "y_meas": out.y_meas, "u": out.u, "x": out.x,
                "reference": ref.y_d, "error": ref.y_d - out.y, "loop_delay": delay,
                "loop_delay_time": delay_time, "preview_lead": lead_used,
                "sup.status": int(sup.status), "sup.gain": sup.gain, "sup.delay": int(sup.delay),
                "sup.fault": ctrl.fault, "sup.fault_time": 0.0 if not ctrl.fault else ctrl.fault_sample * STEP,
                "est.fallbacks": int(ctrl.raw.n_fallbacks)}
        for name, field in fields:
            value = loop[name] if field is None else getattr(published, field)
            refs[name].append(int(value) if name in ("saturated", "est.adapting") else value)
        if k < n:
            lead = preview if k > 0 else 0
            c = ctrl.step_input(ref.y_ref, out.y_meas, ref.y_preview, lead)
            out = plant.step(lib.piezo_plant_rated_voltage(c.v if feedthrough else published.v))
            published = c
            if lib.piezo_reference_step(ref) != core.PIEZO_OK:
                raise RuntimeError(f"piezo_reference_step failed at sample {k}")
            lead_used = lead if c.preview else 0
            if c.delay != delay:
                delay, delay_time = c.delay, k * STEP
    return params, None, refs


GENERATORS = {"PiezoStage": piezo_stage,
              "AdaptiveCompoundController": adaptive_compound_controller,
              "ReferenceSignal": reference_signal,
              CLOSED_LOOP_MODEL: piezo_stage_closed_loop}


# ---------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------

def _number(value):
    if isinstance(value, bool) or isinstance(value, int):
        return str(int(value))
    if not math.isfinite(value):
        raise ValueError(f"non-finite value {value!r} in a reference result")
    return repr(float(value))


def csv_text(columns):
    """CSV in the FMI cross-check layout: quoted header, ``time`` first."""
    names = list(columns)
    assert names[0] == "time"
    lines = [",".join(f'"{n}"' for n in names)]
    for row in zip(*(columns[n] for n in names)):
        lines.append(",".join(_number(x) for x in row))
    return "\n".join(lines) + "\n"


def ssv_text(name, values, types):
    """An SSP 1.0 parameter set; values typed as the model description declares them."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"'
             f' version="1.0" name={quoteattr(name)}>',
             '  <ssv:Parameters>']
    for key in sorted(values):
        kind = types[key]
        value = values[key]
        if kind == "Boolean":
            text = "true" if value else "false"
        elif kind == "Integer":
            text = str(int(value))
        else:
            text = repr(float(value))
        lines.append(f'    <ssv:Parameter name={quoteattr(key)}>'
                     f'<ssv:{kind} value="{text}"/></ssv:Parameter>')
    lines += ['  </ssv:Parameters>', '</ssv:ParameterSet>', '']
    return "\n".join(lines)


def experiments_text(model, experiment, description, has_params, has_stimuli):
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<Experiments name={quoteattr(model + " regression tests")}',
             '    description="Re-simulate and compare with the reference at every sample: '
             f'|y - y_ref| &lt;= tolerance (1 + |y_ref|). Reference computed on the C core.">',
             f'  <Experiment name={quoteattr(experiment)} description={quoteattr(description)}',
             f'      startTime="0" stopTime="{DURATION!r}" stepSize="{STEP!r}" tolerance="{TOLERANCE!r}">']
    if has_params:
        lines.append(f'    <Parameters source="{model}_params.ssv"/>')
    if has_stimuli:
        lines.append(f'    <Stimuli source="{model}_in.csv"/>')
    lines.append(f'    <References source="{model}_ref.csv"/>')
    lines += ['  </Experiment>', '</Experiments>', '']
    return "\n".join(lines)


def manifest_text(model, has_params, has_stimuli):
    related = [(EXPERIMENTS_FILE, "application/x-ma-ls-experiments", "experiment/validation",
                "Regression experiment: parameters, stimuli, reference outputs, tolerance")]
    if has_params:
        related.append((f"{model}_params.ssv", "application/x-ssp-parameter-set", "parameter",
                        "Parameter values of the regression experiment"))
    if has_stimuli:
        related.append((f"{model}_in.csv", "text/csv", "other",
                        "Stimuli (input values at every sample) of the regression experiment"))
    related.append((f"{model}_ref.csv", "text/csv", "result",
                    "Reference outputs of the regression experiment, computed on the C core"))
    related.append(("../../documentation/fmi-ls-ref.html", "text/html", "document",
                    "How the reference results were made and how to compare with them"))
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<fmiReferences',
             '    xmlns:fmi-ls="http://fmi-standard.org/fmi-ls-manifest"',
             '    fmi-ls:fmi-ls-name="org.fmi-standard.fmi-ls-ref"',
             f'    fmi-ls:fmi-ls-version="{LS_REF_VERSION}"',
             f'    fmi-ls:fmi-ls-description="{LS_REF_DESCRIPTION}">']
    for source, mime, role, description in related:
        lines.append(f'  <Related type="{mime}" source="{source}" role="{role}" '
                     f'description={quoteattr(description)}/>')
    lines += ['</fmiReferences>', '']
    return "\n".join(lines)


def write_reference_results(model, model_description, out, start_values=None,
                            plant_start_values=None):
    """Write the reference-result files of `model` into the folder `out`; return their names.

    Parameters
    ----------
    model : str
        Model identifier.
    model_description : str or Path
        The FMU's model description (the types of the parameters).
    out : str or Path
        Folder (emptied of files first).
    start_values : dict, optional
        Every parameter of an exported FMU by name: write :data:`EXPORT_EXPERIMENTS`'s
        experiment on them instead of the built FMU's.
    plant_start_values : dict, optional
        The exported PiezoStage's parameters (the plant of the exported controller's loop).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for old in out.iterdir():
        if old.is_file():
            old.unlink()
    types = variable_types(model_description)
    params, stimuli, refs = GENERATORS[model](start_values, plant_start_values)
    for name in list(params) + list(stimuli or {}) + list(refs):
        if name != "time" and name not in types:
            raise KeyError(f"{model} has no variable '{name}'")
    experiment, description = (EXPERIMENTS if start_values is None else EXPORT_EXPERIMENTS)[model]
    files = {}
    if params:
        files[f"{model}_params.ssv"] = ssv_text(experiment, params, types)
    if stimuli:
        files[f"{model}_in.csv"] = csv_text(stimuli)
    files[f"{model}_ref.csv"] = csv_text(refs)
    files[EXPERIMENTS_FILE] = experiments_text(model, experiment, description, bool(params),
                                               bool(stimuli))
    files["fmi-ls-manifest.xml"] = manifest_text(model, bool(params), bool(stimuli))
    for name, text in files.items():
        (out / name).write_text(text, encoding="utf-8", newline="\n")
    return sorted(files)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", required=True, choices=sorted(GENERATORS))
    p.add_argument("--model-description", required=True, type=Path)
    p.add_argument("--out", required=True, type=Path)
    p.add_argument("--stamp", type=Path, help="file touched when done (for the build)")
    args = p.parse_args(argv)
    names = write_reference_results(args.model, args.model_description, args.out)
    if args.stamp:
        args.stamp.write_text("\n".join(names) + "\n")
    print(f"{args.model}: wrote {', '.join(names)} in {args.out}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    sys.exit(main())
