"""Generate each FMU's interface from its one declaration, ``fmu_src/<Model>/variables.toml``.

A variable of an FMU is declared once, in its model's ``variables.toml``: name, type,
causality, where its value lies in the model's ``ModelData``, unit, range, description
(and, for the stage's outputs that read an input directly, that input). The order of the
declarations is the order of the value references. From it this writes, and ``--check``
compares with what is committed:

- ``fmu_src/<Model>/variables.h``: the value references (config.h includes them) and the
  entries of model.c's table ``model_variables``;
- ``modelDescription/<Model>.xml`` (FMI 2.0) and ``modelDescription/fmi3/<Model>.xml``
  (FMI 3.0). Their start values are the model's own: the values ``model_set_start_values``
  leaves (the core's defaults), read from the compiled model (tests/model_table/model_table.c),
  so a default is written once, in the core;
- ``harness/binding/fmu_variables.py``: the parameter tables through which
  harness/binding/core.py sets the core's parameter structs by FMU name, and what
  PiezoStageClosedLoop takes from whom (harness/binding/closed_loop.py's names);
- the Interfaces table of ``docs/fmus.md`` (between its markers);
- ``fmu_src/core/piezo_controller_params.h``: the controller's plain parameters (those
  AdaptiveCompoundController declares with a ``core`` table: a default, a range, perhaps the
  controller's copy), from which the core sets its defaults, refuses a value out of range,
  checks a restored state's copies and compares them with the parameters. The range is
  also the variable's min/max in the model descriptions.

PiezoStageClosedLoop's declaration composes its components': a line ``"controller:rls.p0"``
takes AdaptiveCompoundController's variable (type, unit, range, description) into the loop,
its C field moved by the component's ``fields`` rule; ``"controller:*"`` takes every one of
the controller's variables not taken yet (a parameter added to the controller reaches the
closed loop with no line of its own). A stage or reference variable neither taken nor listed
in ``not_composed`` stops the generation, so nothing is forgotten silently.

::

    python3 packaging/fmu_interface.py            # (re)write every generated file
    python3 packaging/fmu_interface.py --check    # exit 1 naming the files that differ

Needs a C compiler (the start values); CMakeLists.txt builds the FMUs from the files written.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field as dc_field, replace
import json
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib

REPO = Path(__file__).resolve().parents[1]
#: the FMUs, in the order of CMakeLists.txt's FMU_IDS
MODELS = ("PiezoStage", "AdaptiveCompoundController", "ReferenceSignal", "PiezoStageClosedLoop")
TYPES = ("Real", "Integer", "Boolean")
CAUSALITIES = ("parameter", "input", "output")
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
C_TYPES = {"Real": "MODEL_REAL", "Integer": "MODEL_INTEGER", "Boolean": "MODEL_BOOLEAN"}
C_CAUSALITIES = {"parameter": "MODEL_PARAMETER", "input": "MODEL_INPUT", "output": "MODEL_OUTPUT"}
#: every unit a variable may have: its base unit (FMI's BaseUnit attributes), its display unit,
#: and whether a variable in it shows that display unit (µm does; µm/V is defined, not shown)
UNITS = {
    "Hz": ({"s": "-1"}, None, False),
    "V": ({"kg": "1", "m": "2", "s": "-3", "A": "-1"}, None, False),
    "rad": ({"rad": "1"}, None, False),
    "s": ({"s": "1"}, None, False),
    "um": ({"m": "1", "factor": "1e-6"}, "µm", True),
    "um/V": ({"kg": "-1", "m": "-1", "s": "3", "A": "1", "factor": "1e-6"}, "µm/V", False),
}
KEYS = {"name", "type", "causality", "field", "size", "unit", "min", "max", "description",
        "element_description", "element_descriptions", "depends_on", "initial_depends_on", "core"}
#: the keys of a plain controller parameter's ``core`` table: its range (the refusal's text,
#: an interval first), its default, the controller's copy (a piezo_controller member), and
#: which ends of the range the model descriptions state as min/max (``described``, default
#: both; an end another parameter's rule narrows is left out)
CORE_KEYS = {"range", "default", "copy", "described"}
CORE_MODEL = "AdaptiveCompoundController"
CORE_HEADER = Path("fmu_src") / "core" / "piezo_controller_params.h"
_BOUND = r"(-?inf|-?\d+(?:\.\d+)?(?:e-?\d+)?)"
_INTERVAL = re.compile(rf"([\[(])\s*{_BOUND}\s*,\s*{_BOUND}\s*([\])])")
LOG_EVENTS = {2: "Mode changes: instantiate, setup, initialization, terminate, reset, state restore",
              3: "Mode changes: instantiate, initialization, terminate, reset, state restore"}


class InterfaceError(ValueError):
    """A declaration that cannot be generated (names the file and the variable)."""


@dataclass
class Variable:
    """One declared variable (an FMI 3.0 array: ``size`` elements, FMI 2.0 ``name[i]``)."""

    name: str
    type: str
    causality: str
    field: str
    description: str
    size: int | None = None
    unit: str | None = None
    min: object = None
    max: object = None
    element_descriptions: list[str] = dc_field(default_factory=list)
    depends_on: list[str] = dc_field(default_factory=list)
    initial_depends_on: list[str] | None = None     # None: on every known (FMI's default)
    core: dict | None = None        # a plain controller parameter: range, default, copy
    origin: tuple | None = None     # a composed variable's (component model, its name there)
    start: object = None            # from the compiled model: a value, or a list for an array

    def elements(self):
        """[(FMI 2.0 name, C field, description)] of each scalar (one for a scalar)."""
        if self.size is None:
            return [(self.name, self.field, self.description)]
        return [(f"{self.name}[{i + 1}]", f"{self.field}[{i}]", self.element_descriptions[i])
                for i in range(self.size)]

    @property
    def count(self):
        return self.size or 1


@dataclass
class Interface:
    """A model's declaration: its header facts and its variables in value-reference order."""

    model: str
    description: str
    sources: list[str]
    time_description: str
    variables: list[Variable]
    #: a composing model's: the prefix it puts before a component's renamed names, {component
    #: model: prefix} (its declaration's [component.<key>] prefix)
    prefixes: dict[str, str] = dc_field(default_factory=dict)

    def value_references(self):
        """{name: first value reference} (an array: that of its first element)."""
        out, vr = {}, 0
        for v in self.variables:
            out[v.name] = vr
            vr += v.count
        return out

    @property
    def n_scalars(self):
        return sum(v.count for v in self.variables)


def declaration_path(model, root=REPO):
    return root / "fmu_src" / model / "variables.toml"


def _read(model, root):
    path = declaration_path(model, root)
    try:
        with open(path, "rb") as f:
            return path, tomllib.load(f)
    except FileNotFoundError:
        raise InterfaceError(f"{model}: no declaration {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InterfaceError(f"{path}: {exc}") from None


def _variable(path, decl):
    where = f"{path}: variable {decl.get('name', '?')!r}"
    unknown = set(decl) - KEYS
    if unknown:
        raise InterfaceError(f"{where}: unknown keys {sorted(unknown)}")
    for key in ("name", "type", "causality", "field", "description"):
        if key not in decl:
            raise InterfaceError(f"{where}: '{key}' missing")
    if decl["type"] not in TYPES:
        raise InterfaceError(f"{where}: type {decl['type']!r} not one of {TYPES}")
    if decl["causality"] not in CAUSALITIES:
        raise InterfaceError(f"{where}: causality {decl['causality']!r} not one of {CAUSALITIES}")
    if decl.get("unit") is not None and decl["unit"] not in UNITS:
        raise InterfaceError(f"{where}: unit {decl['unit']!r} not in fmu_interface.UNITS")
    if not re.fullmatch(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*", decl["name"]):
        raise InterfaceError(f"{where}: not a structured name (a.b.c, array elements by size)")
    if not re.fullmatch(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*|\[\d+\])*", decl["field"]):
        raise InterfaceError(f"{where}: field {decl['field']!r} is not a C member path of ModelData")
    size = decl.get("size")
    elements = []
    if size is not None:
        if not isinstance(size, int) or size < 2:
            raise InterfaceError(f"{where}: size must be an integer >= 2")
        template = decl.get("element_description")
        if template is None:
            raise InterfaceError(f"{where}: an array needs element_description (with {{i}})")
        elements = [template.format(i=i) for i in range(1, size + 1)]
        for i, text in decl.get("element_descriptions", {}).items():
            if not 1 <= int(i) <= size:
                raise InterfaceError(f"{where}: element_descriptions names element {i} of {size}")
            elements[int(i) - 1] = text
    low, high = decl.get("min"), decl.get("max")
    core = decl.get("core")
    if core is not None:
        core = _core(where, decl, core)
        low, high = core["hull"]
    return Variable(name=decl["name"], type=decl["type"], causality=decl["causality"],
                    field=decl["field"], description=decl["description"], size=size,
                    unit=decl.get("unit"), min=low, max=high, core=core,
                    element_descriptions=elements, depends_on=list(decl.get("depends_on", [])),
                    initial_depends_on=decl.get("initial_depends_on"))


def _core(where, decl, core):
    """A plain controller parameter's ``core`` table, checked, with its interval and the
    closed hull of it (the variable's min/max; an infinite end has none)."""
    unknown = set(core) - CORE_KEYS
    if unknown:
        raise InterfaceError(f"{where}: unknown keys in core {sorted(unknown)}")
    if "range" not in core or "default" not in core:
        raise InterfaceError(f"{where}: core needs a range and a default")
    if decl["causality"] != "parameter" or decl["type"] == "Integer" or "size" in decl:
        raise InterfaceError(f"{where}: core is for a scalar Real or Boolean parameter")
    if "min" in decl or "max" in decl:
        raise InterfaceError(f"{where}: min/max come from core's range; declare them once")
    if not decl["field"].startswith("params.") or "[" in decl["field"] or decl["field"].count(".") > (
            2 if decl["field"].startswith("params.sup.") else 1):
        raise InterfaceError(f"{where}: core needs a field params.<member of piezo_controller_params> "
                             "or params.sup.<member of piezo_supervisor_params>")
    if "copy" in core and not re.fullmatch(r"[A-Za-z_]\w*", core["copy"]):
        raise InterfaceError(f"{where}: core's copy {core['copy']!r} is not a member name")
    text, default = core["range"], core["default"]
    if decl["type"] == "Boolean":
        if text != "false or true" or not isinstance(default, bool):
            raise InterfaceError(f"{where}: a Boolean's core range is 'false or true', its default a bool")
        return {**core, "interval": (0.0, 1.0, False, False), "hull": (None, None)}
    m = _INTERVAL.match(text)
    if not m:
        raise InterfaceError(f"{where}: core's range {text!r} does not begin with an interval "
                             "such as [0, 1) or (0, inf)")
    lo, hi = float(m.group(2)), float(m.group(3))
    interval = (lo, hi, m.group(1) == "(", m.group(4) == ")")
    if not lo < hi or isinstance(default, bool) or not isinstance(default, (int, float)):
        raise InterfaceError(f"{where}: core's range {text!r} or default {default!r} is not a real interval and value")
    if not ((default > lo if interval[2] else default >= lo) and (default < hi if interval[3] else default <= hi)):
        raise InterfaceError(f"{where}: core's default {default!r} is outside its range {text!r}")
    described = core.get("described", ["min", "max"])
    if not set(described) <= {"min", "max"}:
        raise InterfaceError(f"{where}: core's described lists min and/or max, not {described!r}")
    hull = tuple(None if abs(x) == float("inf") or end not in described else (int(x) if x == int(x) else x)
                 for x, end in ((lo, "min"), (hi, "max")))
    return {**core, "interval": interval, "hull": hull}


def _move_field(rules, field, where):
    """A component's C field as the composing model has it: the longest matching prefix rule."""
    for prefix in sorted(rules, key=len, reverse=True):
        if field.startswith(prefix):
            return rules[prefix] + field[len(prefix):]
    raise InterfaceError(f"{where}: no fields rule moves {field!r}")


def _compose(path, doc, root, cache):
    """The variables of a model that composes others (PiezoStageClosedLoop)."""
    own = {name: _variable(path, {"name": name, **decl}) for name, decl in doc.get("own", {}).items()}
    comps = {}
    for key, comp in doc["component"].items():
        comps[key] = (load(comp["model"], root, cache), comp)
    overrides = doc.get("describe", {})
    out, used_own, taken = [], set(), {key: set() for key in comps}

    def take(key, var):
        interface, comp = comps[key]
        where = f"{path}: {key}:{var.name}"
        name, desc, elements = var.name, var.description, var.element_descriptions
        for prefix in comp.get("prefixed", []):
            if name.startswith(prefix):
                name = comp["prefix"] + name
                desc = comp["prefixed_description"] + desc
                elements = [comp["prefixed_description"] + e for e in elements]
                break
        taken[key].add(var.name)
        moved = replace(var, name=name, field=_move_field(comp["fields"], var.field, where),
                        description=overrides.get(name, desc), element_descriptions=elements,
                        origin=(interface.model, var.name), depends_on=[], initial_depends_on=None,
                        start=None)
        out.append(moved)

    for entry in doc["order"]:
        key, sep, name = entry.partition(":")
        if not sep:
            if entry not in own:
                raise InterfaceError(f"{path}: order names {entry!r}, which [own] does not declare")
            out.append(own[entry])
            used_own.add(entry)
            continue
        if key not in comps:
            raise InterfaceError(f"{path}: order names component {key!r}, not in [component]")
        interface, comp = comps[key]
        by_name = {v.name: v for v in interface.variables}
        if name == "*":
            if entry != doc["order"][-1]:
                raise InterfaceError(f"{path}: {entry!r} must come last (the value references of "
                                     "what follows would move when the component grows)")
            names = {v.name for v in out}
            for var in interface.variables:
                if (var.name not in taken[key] and var.name not in comp.get("not_composed", [])
                        and var.name not in names):
                    take(key, var)
            continue
        if name not in by_name:
            raise InterfaceError(f"{path}: {entry!r}: {interface.model} has no variable {name!r}")
        take(key, by_name[name])
    unused = set(own) - used_own
    if unused:
        raise InterfaceError(f"{path}: [own] declares {sorted(unused)}, which order does not place")
    names = [v.name for v in out]
    for key, (interface, comp) in comps.items():
        for var in interface.variables:
            if (var.name not in taken[key] and var.name not in comp.get("not_composed", [])
                    and var.name not in names):
                raise InterfaceError(
                    f"{path}: {interface.model}'s variable {var.name!r} is neither composed into "
                    f"the loop nor listed in [component.{key}] not_composed")
    stale = set(overrides) - set(names)
    if stale:
        raise InterfaceError(f"{path}: [describe] names {sorted(stale)}, not variables of the loop")
    return out


def load(model, root=REPO, cache=None):
    """The :class:`Interface` of ``model`` as declared (start values not yet filled in)."""
    cache = {} if cache is None else cache
    if model in cache:
        return cache[model]
    path, doc = _read(model, root)
    head = doc.get("model", {})
    for key in ("description", "sources", "time_description"):
        if key not in head:
            raise InterfaceError(f"{path}: [model] {key} missing")
    prefixes = {}
    if "order" in doc:
        variables = _compose(path, doc, root, cache)
        prefixes = {comp["model"]: comp["prefix"] for comp in doc["component"].values()
                    if "prefix" in comp}
    else:
        variables = [_variable(path, decl) for decl in doc.get("variable", [])]
    stray = [v.name for v in variables if v.core is not None and v.origin is None and model != CORE_MODEL]
    if stray:
        raise InterfaceError(f"{path}: core tables are read from {CORE_MODEL}'s declaration only, "
                             f"not here: {stray}")
    names = [v.name for v in variables]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InterfaceError(f"{path}: declared twice: {dup}")
    causality = {v.name: v.causality for v in variables}
    for v in variables:
        if any(causality.get(d) != "input" for d in v.depends_on) or (v.depends_on and v.causality != "output"):
            raise InterfaceError(f"{path}: {v.name}: depends_on must name inputs of an output")
        initial = v.initial_depends_on or []
        if any(causality.get(d) not in ("input", "parameter") for d in initial) or (
                v.initial_depends_on is not None and v.causality != "output"):
            raise InterfaceError(f"{path}: {v.name}: initial_depends_on must name inputs or "
                                 "parameters of an output")
    cache[model] = Interface(model, head["description"], list(head["sources"]),
                             head["time_description"], variables, prefixes)
    return cache[model]


# ---------------------------------------------------------------------------------------
# the C header


def c_identifier(name):
    """vr_<name> of a scalar name: pi.w[3] -> vr_pi_w3, controller.tf.a1 -> vr_controller_tf_a1."""
    return "vr_" + re.sub(r"\[(\d+)\]", r"\1", name).replace(".", "_")


def c_header(interface):
    """The text of fmu_src/<Model>/variables.h."""
    model = interface.model
    guard = f"{model.upper()}_VARIABLES_H"
    lines = [
        "/*",
        f" * {model}/variables.h - GENERATED by packaging/fmu_interface.py from",
        f" * fmu_src/{model}/variables.toml: edit that declaration and run",
        " * `python3 packaging/fmu_interface.py`, never this file.",
        " *",
        " * The value references (config.h includes this; FMI 3.0: an array has the value",
        " * reference of its first element) and the entries of model.c's model_variables",
        " * (fmu_model.h): name, type, causality and where in ModelData the value lies.",
        " */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        "typedef enum {",
    ]
    first = True
    for v in interface.variables:
        for name, _, _ in v.elements():
            lines.append(f"    {c_identifier(name)}{' = 0' if first else ''},")
            first = False
    lines += ["    MODEL_N_VARIABLES", "} ValueReference;", "",
              "/* const model_variable model_variables[MODEL_N_VARIABLES] = { MODEL_VARIABLE_TABLE }; */",
              "#define MODEL_VARIABLE_TABLE \\"]
    rows = []
    for v in interface.variables:
        for name, field, _ in v.elements():
            rows.append(f"    [{c_identifier(name)}] = {{ \"{name}\", {C_TYPES[v.type]}, "
                        f"{C_CAUSALITIES[v.causality]}, offsetof(ModelData, {field}) }}")
    lines += [row + (", \\" if i < len(rows) - 1 else "") for i, row in enumerate(rows)]
    lines += ["", f"#endif /* {guard} */", ""]
    return "\n".join(lines)


def _c_double(x):
    if x == float("inf"):
        return "HUGE_VAL"
    if x == -float("inf"):
        return "-HUGE_VAL"
    text = repr(float(x))
    return text if ("." in text or "e" in text) else text + ".0"


#: the core blocks a ``core`` table may feed: {field prefix below ModelData: list name}, the
#: longest prefix first (the supervisor's parameters are the controller's ``sup`` member)
CORE_BLOCKS = {"params.sup.": "PIEZO_SUPERVISOR", "params.": "PIEZO_CONTROLLER"}


def _block(v):
    """(list name, member path in the block's parameter struct) of a ``core`` parameter."""
    prefix = next(p for p in CORE_BLOCKS if v.field.startswith(p))
    return CORE_BLOCKS[prefix], v.field[len(prefix):]


def core_header(interface):
    """The text of fmu_src/core/piezo_controller_params.h, from the controller's declaration."""
    params = [v for v in interface.variables if v.core is not None]
    source = f"fmu_src/{interface.model}/variables.toml"
    lines = [
        "/*",
        " * piezo_controller_params.h - GENERATED by packaging/fmu_interface.py from",
        f" * {source} (its parameters with a `core` table): edit that",
        " * declaration and run `python3 packaging/fmu_interface.py`, never this file.",
        " *",
        " * The plain parameters of the controller and of its supervisor (sup.*): a default, a",
        " * range and (most) a copy in the block. *_default_params set the defaults, *_init refuse",
        " * a value outside its range (naming it and the range), *_check hold a restored copy to",
        " * the range and piezo_controller_check_params to the parameter. Parameters with rules",
        " * across each other (rls.trace_max, sat.*, rls.zero_min, sup.window, ...) are by hand.",
        " *",
        " * <BLOCK>_PLAIN_PARAMS(X): X(field, name, default, lo, hi, lo_open, hi_open, range)",
        " * <BLOCK>_PLAIN_COPIES(X): X(field, copy, name, lo, hi, lo_open, hi_open)",
        " * (BLOCK: PIEZO_CONTROLLER, fields of piezo_controller_params and piezo_controller;",
        " * PIEZO_SUPERVISOR, of piezo_supervisor_params and piezo_supervisor)",
        " */",
        "#ifndef PIEZO_CONTROLLER_PARAMS_H",
        "#define PIEZO_CONTROLLER_PARAMS_H",
        "",
        "#include <math.h>",
        "",
    ]

    def interval(v):
        lo, hi, lo_open, hi_open = v.core["interval"]
        return f"{_c_double(lo)}, {_c_double(hi)}, {int(lo_open)}, {int(hi_open)}"

    def table(macro, rows):
        out = [f"#define {macro}(X) \\"]
        out += [f"    {row} \\" for row in rows]
        out.append("    /* end */")
        return out

    def default(v):
        d = v.core["default"]
        return str(int(d)) if v.type == "Boolean" else _c_double(d)

    for block in CORE_BLOCKS.values():
        mine = [(v, _block(v)[1]) for v in params if _block(v)[0] == block]
        lines += table(f"{block}_PLAIN_PARAMS", [
            f'X({field}, "{v.name}", {default(v)}, {interval(v)}, "{v.core["range"]}")' for v, field in mine])
        lines.append("")
        lines += table(f"{block}_PLAIN_COPIES", [
            f'X({field}, {v.core["copy"]}, "{v.name}", {interval(v)})' for v, field in mine if "copy" in v.core])
        lines.append("")
    lines += ["#endif /* PIEZO_CONTROLLER_PARAMS_H */", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
# the start values, from the compiled model


def model_parts(model, root=REPO):
    """The FMU-layer files ``model`` shares with others (fmu_src/fmi/fmu_<part>.c), as
    CMakeLists.txt's ``<model>_PARTS`` lists them."""
    m = re.search(rf"^set\({model}_PARTS ([^)]*)\)", (root / "CMakeLists.txt").read_text(), re.M)
    return [root / "fmu_src" / "fmi" / f"fmu_{part}.c" for part in (m.group(1).split() if m else [])]


def compile_table(model, source_dir, exe, root=REPO, warnings=("-w",), core_dir=None):
    """The JSON of tests/model_table/model_table.c compiled against a model's sources.

    Parameters
    ----------
    model : str
        The model whose FMU-layer parts (:func:`model_parts`) are compiled in.
    source_dir : Path
        Where its ``config.h``, ``model.c`` and ``variables.h`` are (fmu_src/<model> or a
        scratch copy).
    exe : Path
        The program to write.
    root : Path
        The checkout (its ``fmu_src/fmi``, ``fmu_src/core`` and ``tests/model_table``).
    warnings : sequence of str
        The compiler's warning options: the generator ignores warnings (``-w``),
        tests/test_variable_sources.py makes every warning an error.
    core_dir : Path, optional
        The C core to compile (default: the checkout's fmu_src/core).

    Raises
    ------
    InterfaceError
        No C compiler, or the model does not compile (with the compiler's message).
    """
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise InterfaceError("a C compiler is needed (the start values are the compiled model's)")
    source_dir = Path(source_dir)
    core = Path(core_dir) if core_dir is not None else root / "fmu_src" / "core"
    proc = subprocess.run(
        [cc, "-std=c99", "-O0", *warnings, "-I", str(source_dir),
         "-I", str(root / "fmu_src" / "fmi"), "-I", str(core),
         str(root / "tests" / "model_table" / "model_table.c"),
         str(source_dir / "model.c"), *(str(p) for p in model_parts(model, root)),
         *sorted(str(p) for p in core.glob("*.c")), "-lm", "-o", str(exe)],
        capture_output=True, text=True)
    if proc.returncode != 0:
        raise InterfaceError(f"{model}: the model does not compile with the generated "
                             f"variables.h:\n{proc.stderr.strip()}")
    return json.loads(subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout)


def compiled_table(model, header_text, root=REPO, core_text=None):
    """model_table.c's JSON for ``model`` built with ``header_text`` as its variables.h (and
    ``core_text``, when given, as the core's piezo_controller_params.h)."""
    model_dir = root / "fmu_src" / model
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # the core as it will be: a quoted include finds its own folder's header first
        core = tmp / "core"
        shutil.copytree(root / "fmu_src" / "core", core)
        if core_text is not None:
            (core / CORE_HEADER.name).write_text(core_text, encoding="utf-8")
        for name in ("config.h", "model.c"):
            shutil.copy(model_dir / name, tmp / name)
        (tmp / "variables.h").write_text(header_text, encoding="utf-8")
        return compile_table(model, tmp, tmp / "model_table", root, core_dir=core)


def fill_starts(interface, table):
    """Set each parameter's and input's start from the compiled table (checks names and types)."""
    entries = table["variables"]
    vr = 0
    for v in interface.variables:
        starts = []
        for name, _, _ in v.elements():
            e = entries[vr]
            if e["name"] != name or e["type"] != v.type or e["causality"] != v.causality:
                raise InterfaceError(f"{interface.model}: value reference {vr} compiles as {e}, "
                                     f"declared {name} {v.type} {v.causality}")
            starts.append(e["start"])
            vr += 1
        if v.causality != "output":
            v.start = starts if v.size else starts[0]
    return interface


# ---------------------------------------------------------------------------------------
# the model descriptions


def _attr(text):
    return (str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;"))


def _number(x):
    """A number as the model descriptions write it: the shortest text that reads back to it."""
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int):
        return str(x)
    x = float(x)
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _start(v, value):
    if v.type == "Boolean":
        return "true" if value else "false"
    if v.type == "Integer":
        return str(int(value))
    return _number(value)


def _type_attrs(v):
    """[(attribute, text)] of the type: unit, displayUnit, min, max, start."""
    out = []
    if v.unit:
        out.append(("unit", v.unit))
        _, display, shown = UNITS[v.unit]
        if shown:
            out.append(("displayUnit", display))
    for key in ("min", "max"):
        value = getattr(v, key)
        if value is not None:
            out.append((key, _number(value)))
    if v.start is not None:
        values = v.start if isinstance(v.start, list) else [v.start]
        out.append(("start", " ".join(_start(v, x) for x in values)))
    return out


def _units_xml(used):
    lines = ["  <UnitDefinitions>"]
    for name in sorted(used):
        base, display, _ = UNITS[name]
        lines.append(f'    <Unit name="{_attr(name)}">')
        lines.append("      <BaseUnit " + " ".join(f'{k}="{v}"' for k, v in base.items()) + "/>")
        if display:
            lines.append(f'      <DisplayUnit name="{display}"/>')
        lines.append("    </Unit>")
    lines.append("  </UnitDefinitions>")
    return lines


def _header(interface, fmi, guid):
    model, desc = interface.model, _attr(interface.description)
    generated = (f"<!-- Generated by packaging/fmu_interface.py from fmu_src/{model}/variables.toml: "
                 "edit that declaration, not this file. -->")
    if fmi == 2:
        head = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            generated,
            f'<fmiModelDescription fmiVersion="2.0" modelName="{model}" guid="{guid}"',
            f'                     description="{desc}"',
            '                     author="The piezo_fmus authors" copyright="Copyright (c) 2026 The piezo_fmus authors"',
            '                     license="BSD-3-Clause (documentation/licenses/license.txt)" generationTool="piezo_fmus"',
            '                     variableNamingConvention="structured" numberOfEventIndicators="0">',
            f'  <CoSimulation modelIdentifier="{model}" needsExecutionTool="false"',
            '                canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false"',
            '                maxOutputDerivativeOrder="0" canRunAsynchronuously="false"',
            '                canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="false"',
            '                canGetAndSetFMUstate="true" canSerializeFMUstate="true"',
            '                providesDirectionalDerivative="false">',
            '    <!-- FMI 2.0 source-code FMU: compile these files from sources/ (flat, the headers beside them)',
            '         with the importer\'s fmi2Functions.h on the include path, e.g.',
            '         cc -shared -fPIC -std=c99 -I sources -I <FMI 2.0 headers> sources/*.c -lm -->',
            '    <SourceFiles>',
            *[f'      <File name="{f}"/>' for f in interface.sources],
            '    </SourceFiles>',
            '  </CoSimulation>',
        ]
    else:
        head = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            generated,
            f'<fmiModelDescription fmiVersion="3.0" modelName="{model}" instantiationToken="{guid}"',
            f'                     description="{desc}"',
            '                     author="The piezo_fmus authors" copyright="Copyright (c) 2026 The piezo_fmus authors"',
            '                     license="BSD-3-Clause (documentation/licenses/license.txt)" generationTool="piezo_fmus"',
            '                     variableNamingConvention="structured">',
            f'  <CoSimulation modelIdentifier="{model}" needsExecutionTool="false"',
            '                canBeInstantiatedOnlyOncePerProcess="false"',
            '                canGetAndSetFMUState="true" canSerializeFMUState="true"',
            '                providesDirectionalDerivatives="false" providesAdjointDerivatives="false"',
            '                providesPerElementDependencies="false"',
            '                canHandleVariableCommunicationStepSize="true" fixedInternalStepSize="0.0005"',
            '                maxOutputDerivativeOrder="0" providesIntermediateUpdate="false"',
            '                mightReturnEarlyFromDoStep="false" canReturnEarlyAfterIntermediateUpdate="false"',
            '                hasEventMode="false" providesEvaluateDiscreteStates="false"/>',
        ]
    used = {v.unit for v in interface.variables if v.unit}
    return head + _units_xml(used) + [
        '  <LogCategories>',
        f'    <Category name="logEvents" description="{LOG_EVENTS[fmi]}"/>',
        f'    <Category name="logStatusWarning" description="Messages with status fmi{fmi}Warning"/>',
        f'    <Category name="logStatusError" description="Why a call returned fmi{fmi}Error (on by default, even with loggingOn = false)"/>',
        '    <Category name="logAll" description="All of the above"/>',
        '  </LogCategories>',
        '  <DefaultExperiment startTime="0" stopTime="3" stepSize="0.0005"/>',
    ]


def guid(model, root=REPO):
    """MODEL_GUID of the model's config.h (FMI 3.0: the instantiationToken)."""
    text = (root / "fmu_src" / model / "config.h").read_text()
    return re.search(r'#define MODEL_GUID "([^"]+)"', text).group(1)


def model_description(interface, fmi, guid_text):
    """The text of the FMI ``fmi`` (2 or 3) model description of a filled-in interface."""
    lines = _header(interface, fmi, guid_text)
    lines.append("  <ModelVariables>")
    n = interface.n_scalars
    vrs = interface.value_references()
    if fmi == 3:
        lines += [f"    <!-- the independent variable: value reference {n}, the first after the "
                  f"model's {n} variables -->",
                  f'    <Float64 name="time" valueReference="{n}" causality="independent" '
                  'variability="continuous" unit="s"',
                  f'             description="{_attr(interface.time_description)}"/>']
    for v in interface.variables:
        vr = vrs[v.name]
        variability = "fixed" if v.causality == "parameter" else "discrete"
        initial = {"parameter": ' initial="exact"', "output": ' initial="calculated"'}.get(v.causality, "")
        attrs = _type_attrs(v)
        if fmi == 2:
            starts = v.start if isinstance(v.start, list) else [v.start] * v.count
            for i, (name, _, desc) in enumerate(v.elements()):
                element_attrs = [(k, _start(v, starts[i]) if k == "start" else x) for k, x in attrs]
                lines += [f"    <!-- index {vr + i + 1} -->",
                          f'    <ScalarVariable name="{_attr(name)}" valueReference="{vr + i}" '
                          f'causality="{v.causality}" variability="{variability}"{initial}',
                          f'                    description="{_attr(desc)}">',
                          "      <" + " ".join([v.type] + [f'{k}="{_attr(x)}"' for k, x in element_attrs])
                          + "/>",
                          "    </ScalarVariable>"]
            continue
        tag = FMI3_TYPES[v.type]
        attr_text = "".join(f' {k}="{_attr(x)}"' for k, x in attrs)
        indent = " " * (len(tag) + 6)
        open_tag = (f'    <{tag} name="{_attr(v.name)}" valueReference="{vr}" causality="{v.causality}" '
                    f'variability="{variability}"{initial}{attr_text}')
        if v.size is None:
            lines += [open_tag, f'{indent}description="{_attr(v.description)}"/>']
        else:
            lines += [f"    <!-- value reference {vr}: {v.name}[1..{v.size}], elements in order "
                      f"(references {vr + 1}..{vr + v.size - 1} are not used) -->",
                      open_tag, f'{indent}description="{_attr(v.description)}">',
                      f'      <Dimension start="{v.size}"/>', f"    </{tag}>"]
    lines.append("  </ModelVariables>")
    outputs = [v for v in interface.variables if v.causality == "output"]
    lines.append("  <ModelStructure>")
    base = 1 if fmi == 2 else 0
    deps = {v.name: " ".join(str(vrs[d] + base) for d in v.depends_on) for v in outputs}
    # an initial unknown without the attribute depends on every known (FMI 2.0 and 3.0)
    initial = {v.name: "" if v.initial_depends_on is None else
               ' dependencies="' + " ".join(str(vrs[d] + base) for d in v.initial_depends_on) + '"'
               for v in outputs}
    if fmi == 2:
        lines.append("    <Outputs>")
        lines += [f'      <Unknown index="{vrs[v.name] + 1}" dependencies="{deps[v.name]}"/>' for v in outputs]
        lines += ["    </Outputs>", "    <InitialUnknowns>"]
        lines += [f'      <Unknown index="{vrs[v.name] + 1}"{initial[v.name]}/>' for v in outputs]
        lines.append("    </InitialUnknowns>")
    else:
        lines += [f'    <Output valueReference="{vrs[v.name]}" dependencies="{deps[v.name]}"/>'
                  for v in outputs]
        lines += [f'    <InitialUnknown valueReference="{vrs[v.name]}"{initial[v.name]}/>' for v in outputs]
    lines += ["  </ModelStructure>", "</fmiModelDescription>", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
# the harness's names

HARNESS_MODULE = Path("harness") / "binding" / "fmu_variables.py"
_KINDS = {"Real": "float", "Integer": "int", "Boolean": "bool"}


def _path(field):
    """("pi", "w", 3) of a C field "params.pi.w[3]" below ModelData.params."""
    out = []
    for part in field.split(".")[1:]:
        m = re.fullmatch(r"(\w+)\[(\d+)\]", part)
        out += [m.group(1), int(m.group(2))] if m else [part]
    return tuple(out)


def harness_module(interfaces):
    """The text of harness/binding/fmu_variables.py: each component's parameters as fields of its
    core parameter struct (harness/binding/core.py's tables), and what a composing FMU takes from
    whom."""
    lines = ['"""GENERATED by packaging/fmu_interface.py from fmu_src/<Model>/variables.toml: edit',
             "those declarations and run `python3 packaging/fmu_interface.py`, never this file.",
             "",
             "PARAMETERS: the parameters of each FMU that wraps one core block, {name: (path of the",
             "field in the block's parameter struct, kind)}: harness/binding/core.py's tables.",
             "SIGNALS: each FMU's inputs and outputs, {model: {name: (causality, type, unit)}}",
             "(the SSP's connectors).",
             "COMPOSED: the variables an FMU takes from its components (arrays element by element),",
             "{model: {its name: (component, the component's name)}}: harness/binding/closed_loop.py's names.",
             "PREFIXES: the prefix a composing FMU puts before the names of a component it renames",
             "(the controller's nominal model), {model: {component: prefix}}.",
             '"""', "", "PARAMETERS = {"]
    for interface in interfaces:
        params = [v for v in interface.variables if v.causality == "parameter"]
        if not params or not all(v.field.startswith("params.") for v in params):
            continue
        lines.append(f"    {interface.model!r}: {{")
        for v in params:
            if v.size is None:
                lines.append(f"        {v.name!r}: ({_path(v.field)!r}, {_KINDS[v.type]!r}),")
            else:           # an array's elements name[1]..name[size] at field[0]..field[size - 1]
                lines.append(f"        **{{f'{v.name}[{{i + 1}}]': ({_path(v.field)!r} + (i,), "
                             f"{_KINDS[v.type]!r}) for i in range({v.size})}},")
        lines.append("    },")
    lines += ["}", "", "SIGNALS = {"]
    for interface in interfaces:
        lines.append(f"    {interface.model!r}: {{")
        for v in interface.variables:
            if v.causality != "parameter" and v.size is None:
                lines.append(f"        {v.name!r}: ({v.causality!r}, {v.type!r}, {v.unit or ''!r}),")
        lines.append("    },")
    lines += ["}", "", "COMPOSED = {"]
    for interface in interfaces:
        composed = [v for v in interface.variables if v.origin]
        if composed:
            lines.append(f"    {interface.model!r}: {{")
            for v in composed:
                model, name = v.origin
                if v.size is None:
                    lines.append(f"        {v.name!r}: {(model, name)!r},")
                else:
                    lines.append(f"        **{{f'{v.name}[{{i}}]': ({model!r}, f'{name}[{{i}}]') "
                                 f"for i in range(1, {v.size + 1})}},")
            lines.append("    },")
    lines += ["}", "", "PREFIXES = {"]
    for interface in interfaces:
        if interface.prefixes:
            lines.append(f"    {interface.model!r}: {interface.prefixes!r},")
    lines += ["}", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
# the documentation's variable table

DOC = Path("docs") / "fmus.md"
DOC_BEGIN = "<!-- the Interfaces table, generated by packaging/fmu_interface.py from the declarations -->"
DOC_END = "<!-- end of the generated Interfaces table -->"


def _signals_cell(variables):
    """Inputs or outputs: the names in order, each run of one unit followed by [unit]."""
    groups = []
    for name, unit in variables:
        if groups and groups[-1][0] == unit:
            groups[-1][1].append(name)
        else:
            groups.append((unit, [name]))
    parts = [", ".join(f"`{n}`" for n in names) + (f" [{unit}]" if unit else "") for unit, names in groups]
    return ", ".join(parts) or "none"


def _parameters_cell(variables):
    """Parameters: `group.*` for structured names, `name[1..n]` for arrays, else the name."""
    out = []
    for v in variables:
        item = (f"`{v.name.split('.')[0]}.*`" if "." in v.name else
                f"`{v.name}[1..{v.size}]`" if v.size else f"`{v.name}`")
        if item not in out:
            out.append(item)
    return ", ".join(out) or "none"


def _shown_unit(v):
    if not v.unit:
        return None
    _, display, shown = UNITS[v.unit]
    return display if shown else v.unit


def interfaces_table(interfaces):
    """The Interfaces table of docs/fmus.md: each FMU's inputs, outputs and parameters."""
    rows = [DOC_BEGIN, "| FMU | inputs | outputs | parameters |", "|---|---|---|---|"]
    for interface in interfaces:
        cells = []
        for causality in ("input", "output"):
            cells.append(_signals_cell([(name, _shown_unit(v)) for v in interface.variables
                                        if v.causality == causality for name, _, _ in v.elements()]))
        cells.append(_parameters_cell([v for v in interface.variables if v.causality == "parameter"]))
        rows.append(f"| {interface.model} | " + " | ".join(cells) + " |")
    return "\n".join(rows + [DOC_END])


def doc_with_table(path, text, table):
    """``text`` of docs/fmus.md with the generated table between its markers."""
    begin, end = text.find(DOC_BEGIN), text.find(DOC_END)
    if begin < 0 or end < begin:
        raise InterfaceError(f"{path}: the markers of the generated Interfaces table are missing")
    return text[:begin] + table + text[end + len(DOC_END):]


# ---------------------------------------------------------------------------------------
# the files


def generated_files(root=REPO, models=MODELS):
    """{path: text} of every file generated from the declarations under ``root``."""
    cache, out = {}, {}
    if set(models) == set(MODELS):
        interfaces = [load(m, root, cache) for m in MODELS]
        out[root / HARNESS_MODULE] = harness_module(interfaces)
        doc = root / DOC
        if doc.is_file():
            out[doc] = doc_with_table(doc, doc.read_text(encoding="utf-8"), interfaces_table(interfaces))
    core_text = core_header(load(CORE_MODEL, root, cache))
    out[root / CORE_HEADER] = core_text
    for model in models:
        interface = load(model, root, cache)
        header = c_header(interface)
        out[root / "fmu_src" / model / "variables.h"] = header
        filled = replace(interface, variables=[replace(v) for v in interface.variables])
        fill_starts(filled, compiled_table(model, header, root, core_text))
        g = guid(model, root)
        out[root / "modelDescription" / f"{model}.xml"] = model_description(filled, 2, g)
        out[root / "modelDescription" / "fmi3" / f"{model}.xml"] = model_description(filled, 3, g)
    return out


def _stale(files):
    """The paths of ``files`` ({path: text}) whose committed text differs (or that are missing)."""
    return [p for p, text in files.items() if not p.is_file() or p.read_text(encoding="utf-8") != text]


def stale_files(root=REPO, models=MODELS):
    """The generated files whose committed text differs from what the declarations give."""
    return _stale(generated_files(root, models))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a generated file differs")
    parser.add_argument("models", nargs="*", default=list(MODELS), metavar="MODEL",
                        help=f"models to generate (default: all: {', '.join(MODELS)})")
    args = parser.parse_args(argv)
    unknown = set(args.models) - set(MODELS)
    if unknown:
        parser.error(f"unknown models {sorted(unknown)}; known: {', '.join(MODELS)}")
    try:
        files = generated_files(REPO, args.models)
    except InterfaceError as exc:
        print(f"fmu_interface: {exc}", file=sys.stderr)
        return 2
    stale = _stale(files)
    if args.check:
        if stale:
            print("out of date (run python3 packaging/fmu_interface.py): "
                  + ", ".join(str(p.relative_to(REPO)) for p in stale), file=sys.stderr)
            return 1
        return 0
    for path in stale:
        path.write_text(files[path], encoding="utf-8", newline="\n")
        print(f"wrote {path.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
