"""Write the model descriptions of PiezoStageClosedLoop from the other three FMUs' own.

PiezoStageClosedLoop runs the loop of PiezoStage, AdaptiveCompoundController and
ReferenceSignal in one FMU, so most of its variables are theirs: each is declared as
the component declares it (type, unit, range, start value, description), taken from the
component's model description of the same FMI version. Which component a variable comes
from is written once, in the C table of ``fmu_src/PiezoStageClosedLoop/model.c``: each
entry's macro starts with STAGE_ (PiezoStage), CTRL_ (AdaptiveCompoundController; its
nominal model's names carry the prefix ``controller.``), REF_ (ReferenceSignal) or LOOP_
(the loop's own, declared in :data:`OWN` below). The order of the entries is the order of
the value references.

::

    python3 packaging/closed_loop_description.py           # (re)write both files
    python3 packaging/closed_loop_description.py --check   # exit 1 if a file differs

writes ``modelDescription/PiezoStageClosedLoop.xml`` (FMI 2.0) and
``modelDescription/fmi3/PiezoStageClosedLoop.xml`` (FMI 3.0); both are committed, and
tests/test_fmu_closed_loop.py fails when they are not what this writes.
"""

from __future__ import annotations

import argparse
from pathlib import Path
import re
import sys
from xml.etree import ElementTree as ET

REPO = Path(__file__).resolve().parents[1]
MODEL = "PiezoStageClosedLoop"
MODEL_C = REPO / "fmu_src" / MODEL / "model.c"
CONFIG_H = REPO / "fmu_src" / MODEL / "config.h"
CONTROLLER_PREFIX = "controller."
SOURCE_OF = {"STAGE": "PiezoStage", "CTRL": "AdaptiveCompoundController", "REF": "ReferenceSignal"}
#: the C files of the binary (FMI 2.0 lists them; CMakeLists.txt checks the list)
C_FILES = ("fmi2_glue.c", "fmu_controller.c", "fmu_glue_core.c", "fmu_glue_state.c", "fmu_start_values.c",
           "model.c", "piezo_controller.c", "piezo_controller_check.c", "piezo_controller_detect.c",
           "piezo_controller_explain.c", "piezo_controller_setup.c", "piezo_creep.c",
           "piezo_hysteresis.c", "piezo_plant.c", "piezo_reference.c", "piezo_status.c",
           "piezo_supervisor.c", "piezo_supervisor_explain.c", "piezo_tf.c")

DESCRIPTION = (
    "The piezoelectric-actuated positioning stage under its adaptive compound controller, after "
    "the paper &quot;Coupling Modeling and Adaptive Control for Piezoelectric-Actuated Positioning "
    "Stage&quot;: PiezoStage, AdaptiveCompoundController and ReferenceSignal wired in one FMU (the "
    "same C core). Takes the desired displacement (the internal reference, or the input y_d) and "
    "gives the displacement, at any communication step: the loop runs at h inside, and a step "
    "computes the samples whose instants it passes. No direct feedthrough but the reference outputs "
    "from y_d.")

# The loop's own variables (LOOP_ entries): type attributes (in order) and description; and
# the descriptions of the components' variables that say something else here.
OWN = {
    "y_d": ({"unit": "um", "displayUnit": "µm", "start": "0"},
            "Desired displacement y_d(t + y_d_lead h), used when use_internal_reference = false; "
            "held over the communication step and sampled at each sample's instant t_k = t0 + k h "
            "(a step that ends between two instants keeps the value held at the next one for it). "
            "The controller gets it as its y_ref and as a preview y_d_lead samples ahead"),
    "v": ({"unit": "V"},
          "Control voltage of the controller's last sample, v(k-1): the voltage the stage applies "
          "over [t_k, t_(k+1)), clamped to [-150, 150] V (with mv.feedthrough, v(k) is computed from "
          "y_meas(k) and applied at once, and this is the voltage of the sample before)"),
    "reference": ({"unit": "um", "displayUnit": "µm"},
                  "Desired displacement y_d(k) at t_k: the internal reference, or the input y_d "
                  "sampled y_d_lead samples before (until then, and with y_d_lead = 0, the input y_d "
                  "now)"),
    "error": ({"unit": "um", "displayUnit": "µm"},
              "Tracking error reference - y, y_d(k) - y(k)"),
    "preview_lead": ({},
                     "Samples by which the preview the law used led the sample (internal reference: "
                     "preview; input y_d: y_d_lead); 0 when the law used y_ref (or the newest y_d)"),
    "sup.status": ({},
                   "What the supervision has found: 0 not yet verified (no strong evidence yet), 1 "
                   "verified (y_meas answered v as the model says: sup.gain and sup.delay), 2 degraded "
                   "(the controller does not get y_d(k + d): a warning said why)"),
    "use_internal_reference": ({"start": "true"},
                               "true (default): the stage tracks the internal reference (offset, "
                               "amplitude[i], frequency[i], phase[i], lead, preview: ReferenceSignal's "
                               "parameters). false: it tracks the input y_d"),
    "y_d_lead": ({"min": "0", "max": "15", "start": "0"},
                 "Samples by which the input y_d leads the stage's time (y_d = y_d(t + y_d_lead h)); "
                 "with y_d_lead >= d, the loop delay (2 by default), the controller gets y_d(k + d) and "
                 "the stage follows y_d without lag; with 0 (default) the newest y_d stands in for "
                 "y_d(k + d) and the stage follows d samples late"),
    "h": ({"unit": "s", "min": "0", "start": "0.0005"},
          "Sample period of the loop (the paper's 0.5 ms), the stage's, the controller's and the "
          "reference's; a communication step may be any size; &gt; 0"),
}
OVERRIDES = {
    "mv.delay": "Loop delay beyond one sample, d = 1 + mv.delay. -1 (default): d is detected online "
                "among 1, 2, 3 (2 in this loop, 3 with tf.delay = 1, 1 with mv.feedthrough; a start-up "
                "law runs until the choice; loop_delay and loop_delay_time show it). 0..8 sets it",
    "mv.feedthrough": "false (default): the stage applies v(k) computed from y_meas(k) from the next "
                      "sample on (d = 2). true: it applies it at once, as under a master that reads v "
                      "after setting the controller's inputs (d = 1)",
    "lead": "Preview of the reference for the controller's y_ref in samples, y_d(t_(k+lead)), used "
            "when the preview (preview) does not cover the loop delay d; 2 fits d = 2",
    "preview": "Lead of the stamped preview in samples: the controller takes y_d(k + d) from it when "
               "d <= preview <= 15 (4 by default covers d = 1..3), from the second sample on",
}
LOG_CATEGORIES = {
    2: ("Mode changes: instantiate, setup, initialization, terminate, reset, state restore",
        "fmi2Warning", "fmi2Error"),
    3: ("Mode changes: instantiate, initialization, terminate, reset, state restore",
        "fmi3Warning", "fmi3Error"),
}
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
_ENTRY = re.compile(r'\[(vr_\w+)\]\s*=\s*(STAGE|CTRL|REF|LOOP)_(\w+)\("([^"]+)"')
_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


def c_table():
    """[(vr, source, name, kind)] of the C table in value-reference order (config.h's enum)."""
    enum = re.search(r"typedef enum \{(.*?)MODEL_N_VARIABLES", CONFIG_H.read_text(), re.S).group(1)
    order = re.findall(r"\b(vr_\w+)", re.sub(r"/\*.*?\*/", "", enum, flags=re.S))
    entries = {m.group(1): (m.group(2), m.group(4), m.group(3))
               for m in _ENTRY.finditer(MODEL_C.read_text())}
    if set(entries) != set(order):
        raise SystemExit(f"{MODEL_C}: the table's entries and config.h's value references differ: "
                         f"{sorted(set(entries) ^ set(order))}")
    return [(vr, *entries[name]) for vr, name in enumerate(order)]


def _component(model, fmi):
    path = REPO / "modelDescription" / ("fmi3" if fmi == 3 else "") / f"{model}.xml"
    return ET.parse(path).getroot()


def _attr(text):
    return (str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;"))


def _desc(text):
    """A description as written in OWN/OVERRIDES (&gt; already escaped) for an attribute."""
    return _attr(text).replace("&amp;gt;", "&gt;").replace("&amp;quot;", "&quot;")


class _Components:
    """The components' variables of one FMI version by name (FMI 3.0: arrays by name too)."""

    def __init__(self, fmi):
        self.fmi = fmi
        self.vars = {}
        self.units = {}
        for model in SOURCE_OF.values():
            root = _component(model, fmi)
            self.vars[model] = {v.get("name"): v for v in root.find("ModelVariables")}
            for unit in root.find("UnitDefinitions"):
                self.units.setdefault(unit.get("name"), unit)

    def variable(self, source, name):
        """(element, type attributes dict, description) of a component's variable."""
        model = SOURCE_OF[source]
        if source == "CTRL" and name.startswith(CONTROLLER_PREFIX):
            name = name[len(CONTROLLER_PREFIX):]
        var = self.vars[model][name]
        if self.fmi == 2:
            (typ,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean")]
            attrs = dict(typ.attrib)
        else:
            attrs = {k: v for k, v in var.attrib.items()
                     if k in ("unit", "displayUnit", "min", "max", "start")}
        return var, attrs, var.get("description")


def _variables(fmi):
    """[(vr, name, kind, causality, type attrs, description, array size)] for one version."""
    comps = _Components(fmi)
    table = c_table()
    out = []
    runs = {}
    for vr, source, name, kind in table:
        m = _ELEMENT.match(name)
        if m:
            runs.setdefault(m.group(1), []).append(vr)
    for vr, source, name, kind in table:
        m = _ELEMENT.match(name)
        causality = ("input" if kind.startswith("INPUT") else
                     "output" if kind.startswith("OUT") else "parameter")
        c_type = ("Boolean" if kind.endswith("BOOL") else
                  "Integer" if kind.endswith("INT") else "Real")
        if source == "LOOP":
            attrs, desc = OWN[name]
            out.append((vr, name, c_type, causality, dict(attrs), desc, None))
            continue
        if fmi == 3 and m:
            if m.group(2) != "1":
                continue                        # the array's other elements: one variable
            size = len(runs[m.group(1)])
            name = m.group(1)
            _, attrs, desc = comps.variable(source, name)
        else:
            size = None
            _, attrs, desc = comps.variable(source, name)
        if source == "CTRL" and name.startswith(CONTROLLER_PREFIX):
            desc = "The controller's nominal model: " + desc
        out.append((vr, name, c_type, causality, attrs, OVERRIDES.get(name, desc), size))
    return out, comps.units


def _units_xml(units, used):
    lines = ["  <UnitDefinitions>"]
    for name in sorted(used):
        unit = units[name]
        lines.append(f'    <Unit name="{_attr(name)}">')
        for child in unit:
            attrs = " ".join(f'{k}="{_attr(v)}"' for k, v in child.attrib.items())
            lines.append(f"      <{child.tag} {attrs}/>")
        lines.append("    </Unit>")
    lines.append("  </UnitDefinitions>")
    return lines


def _header(fmi, guid, units, used):
    events, warning, error = LOG_CATEGORIES[fmi]
    if fmi == 2:
        head = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            f'<fmiModelDescription fmiVersion="2.0" modelName="{MODEL}" guid="{guid}"',
            f'                     description="{DESCRIPTION}"',
            '                     author="The piezo_fmus authors" copyright="Copyright (c) 2026 The piezo_fmus authors"',
            '                     license="BSD-3-Clause (documentation/licenses/license.txt)" generationTool="piezo_fmus"',
            '                     variableNamingConvention="structured" numberOfEventIndicators="0">',
            f'  <CoSimulation modelIdentifier="{MODEL}" needsExecutionTool="false"',
            '                canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false"',
            '                maxOutputDerivativeOrder="0" canRunAsynchronuously="false"',
            '                canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="false"',
            '                canGetAndSetFMUstate="true" canSerializeFMUstate="true"',
            '                providesDirectionalDerivative="false">',
            '    <!-- FMI 2.0 source-code FMU: compile these files from sources/ (flat, the headers beside them)',
            '         with the importer\'s fmi2Functions.h on the include path, e.g.',
            '         cc -shared -fPIC -std=c99 -I sources -I <FMI 2.0 headers> sources/*.c -lm -->',
            '    <SourceFiles>',
            *[f'      <File name="{f}"/>' for f in C_FILES],
            '    </SourceFiles>',
            '  </CoSimulation>',
        ]
    else:
        head = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            f'<fmiModelDescription fmiVersion="3.0" modelName="{MODEL}" instantiationToken="{guid}"',
            f'                     description="{DESCRIPTION}"',
            '                     author="The piezo_fmus authors" copyright="Copyright (c) 2026 The piezo_fmus authors"',
            '                     license="BSD-3-Clause (documentation/licenses/license.txt)" generationTool="piezo_fmus"',
            '                     variableNamingConvention="structured">',
            f'  <CoSimulation modelIdentifier="{MODEL}" needsExecutionTool="false"',
            '                canBeInstantiatedOnlyOncePerProcess="false"',
            '                canGetAndSetFMUState="true" canSerializeFMUState="true"',
            '                providesDirectionalDerivatives="false" providesAdjointDerivatives="false"',
            '                providesPerElementDependencies="false"',
            '                canHandleVariableCommunicationStepSize="true" fixedInternalStepSize="0.0005"',
            '                maxOutputDerivativeOrder="0" providesIntermediateUpdate="false"',
            '                mightReturnEarlyFromDoStep="false" canReturnEarlyAfterIntermediateUpdate="false"',
            '                hasEventMode="false" providesEvaluateDiscreteStates="false"/>',
        ]
    return head + _units_xml(units, used) + [
        '  <LogCategories>',
        f'    <Category name="logEvents" description="{events}"/>',
        f'    <Category name="logStatusWarning" description="Messages with status {warning}"/>',
        f'    <Category name="logStatusError" description="Why a call returned {error} (on by default, even with loggingOn = false)"/>',
        '    <Category name="logAll" description="All of the above"/>',
        '  </LogCategories>',
        '  <DefaultExperiment startTime="0" stopTime="3" stepSize="0.0005"/>',
    ]


def _guid():
    return re.search(r'#define MODEL_GUID "([^"]+)"', CONFIG_H.read_text()).group(1)


def model_description(fmi):
    """The text of the FMI ``fmi`` (2 or 3) model description."""
    variables, units = _variables(fmi)
    used = {v[4]["unit"] for v in variables if "unit" in v[4]}
    lines = _header(fmi, _guid(), units, used)
    lines.append("  <ModelVariables>")
    n_vars = len(c_table())
    y_d_vr = next(v[0] for v in variables if v[1] == "y_d")
    feedthrough = {"reference", "error"}          # they read the input y_d (use_internal_reference = false)
    if fmi == 3:
        lines += [f"    <!-- the independent variable: value reference {n_vars}, the first after the "
                  f"model's {n_vars} variables -->",
                  f'    <Float64 name="time" valueReference="{n_vars}" causality="independent" '
                  'variability="continuous" unit="s"',
                  '             description="Simulation time of the FMU (read only): t0 + k h, or '
                  'between two samples where the last step ended"/>']
    for vr, name, kind, causality, attrs, desc, size in variables:
        variability = "fixed" if causality == "parameter" else "discrete"
        initial = {"parameter": ' initial="exact"', "output": ' initial="calculated"'}.get(causality, "")
        if fmi == 2:
            lines += [f"    <!-- index {vr + 1} -->",
                      f'    <ScalarVariable name="{_attr(name)}" valueReference="{vr}" causality="{causality}" '
                      f'variability="{variability}"{initial}',
                      f'                    description="{_desc(desc)}">',
                      "      <" + " ".join([kind] + [f'{k}="{_attr(v)}"' for k, v in attrs.items()]) + "/>",
                      "    </ScalarVariable>"]
            continue
        tag = FMI3_TYPES[kind]
        attr_text = "".join(f' {k}="{_attr(v)}"' for k, v in attrs.items())
        indent = " " * (len(tag) + 6)
        open_tag = (f'    <{tag} name="{_attr(name)}" valueReference="{vr}" causality="{causality}" '
                    f'variability="{variability}"{initial}{attr_text}')
        if size is None:
            lines += [open_tag, f'{indent}description="{_desc(desc)}"/>']
        else:
            lines += [f"    <!-- value reference {vr}: {name}[1..{size}], elements in order "
                      f"(references {vr + 1}..{vr + size - 1} are not used) -->",
                      open_tag, f'{indent}description="{_desc(desc)}">',
                      f'      <Dimension start="{size}"/>', f"    </{tag}>"]
    lines.append("  </ModelVariables>")
    outputs = [v for v in variables if v[3] == "output"]
    lines.append("  <ModelStructure>")
    if fmi == 2:
        lines.append("    <Outputs>")
        for v in outputs:
            deps = str(y_d_vr + 1) if v[1] in feedthrough else ""
            lines.append(f'      <Unknown index="{v[0] + 1}" dependencies="{deps}"/>')
        lines += ["    </Outputs>", "    <InitialUnknowns>"]
        lines += [f'      <Unknown index="{v[0] + 1}"/>' for v in outputs]
        lines.append("    </InitialUnknowns>")
    else:
        for v in outputs:
            deps = str(y_d_vr) if v[1] in feedthrough else ""
            lines.append(f'    <Output valueReference="{v[0]}" dependencies="{deps}"/>')
        lines += [f'    <InitialUnknown valueReference="{v[0]}"/>' for v in outputs]
    lines += ["  </ModelStructure>", "</fmiModelDescription>", ""]
    return "\n".join(lines)


def paths():
    return {2: REPO / "modelDescription" / f"{MODEL}.xml",
            3: REPO / "modelDescription" / "fmi3" / f"{MODEL}.xml"}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a written file differs")
    args = parser.parse_args(argv)
    stale = []
    for fmi, path in paths().items():
        text = model_description(fmi)
        if args.check:
            if not path.is_file() or path.read_text(encoding="utf-8") != text:
                stale.append(path)
        else:
            path.write_text(text, encoding="utf-8", newline="\n")
            print(f"wrote {path.relative_to(REPO)}")
    if stale:
        print("out of date (run python3 packaging/closed_loop_description.py): "
              + ", ".join(str(p.relative_to(REPO)) for p in stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
