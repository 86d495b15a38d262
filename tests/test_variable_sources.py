"""The variables as the binaries serve them: each model's C table, and everything checked against it.

Each FMU's variables are declared once, in ``fmu_src/<Model>/variables.toml``; the generator
(``packaging/fmu_interface.py``, checked in ``test_fmu_interface.py``) writes from it the C table's
entries (``variables.h``) and both model descriptions. This file checks the results against the
binaries' own view, independently of the generator: ``tests/model_table/model_table.c`` is
compiled against each model's ``config.h`` and ``model.c`` (and the core, for the start values;
the compile is the generator's, ``fmu_interface.compile_table``, with every warning an error)
and prints the table ``model_variables`` as JSON. Nothing below lists a variable by hand, so
variables added later are covered as they come.

(a) the C table itself: an entry at every value reference, names and offsets unique, every
    offset inside ``ModelData``, and a run ``name[1..n]`` (an FMI 3.0 array) laid out as one C
    array in element order;
(b) each model description (FMI 2.0 and FMI 3.0): at each value reference the variable of the C
    table's entry, with its name, type, causality, variability, initial and start value (the
    value ``model_set_start_values`` leaves at the entry's offset); FMI 3.0 arrays element by
    element; the same model identifier and guid/instantiationToken; FMI 3.0's ``time`` at the
    value reference after the table. Ranges (min/max) are not in the C table; they are checked
    against what the core refuses in ``test_fmu_packaging.py``;
(c) the checks can fail: a scratch copy with two value references swapped (in a model
    description, in the C table) or two array elements swapped is caught, naming them;
(d) ``harness/binding/core.py``'s parameter tables: the same names, each mapped to the C field the FMU
    writes (offset and C type through cffi), its default equal to the C start value;
(e) the docs: every variable named in a "FMU variables" column of README.md or docs/ exists (the
    Interfaces table of ``docs/fmus.md`` is generated from the declarations:
    ``test_fmu_interface.py``).
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from conftest import FMU_NAMES, REPO

sys.path.insert(0, str(REPO / "packaging"))
import fmu_interface as fi  # noqa: E402

#: the compile of the model's table here: every warning an error
STRICT_WARNINGS = ("-Wall", "-Wextra", "-Wpedantic", "-Werror")

# FMI 3.0 type names of the model's three types (FMI 2.0 uses the C table's: Real, Integer, Boolean)
FMI3_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean"}
# The variability and initial an entry's causality implies (fmu_model.h): a parameter is settable
# only before the end of initialization mode, its start is its value (fixed, exact); inputs are
# held over the communication step and outputs are computed by model_update_outputs at the
# sample times t0 + k h (discrete; outputs calculated, inputs have no initial).
VARIABILITY = {"parameter": "fixed", "input": "discrete", "output": "discrete"}
INITIAL = {"parameter": "exact", "input": None, "output": "calculated"}
_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


# ---------------------------------------------------------------------------------------
# the C table, printed by the C code


def compile_table(model: str, out_dir: Path, source_dir: Path | None = None) -> dict:
    """Compile model_table.c against fmu_src/<model> (or a scratch copy of its config.h, model.c
    and variables.h in ``source_dir``) and return its JSON: the generator's compile
    (``fmu_interface.compile_table``, the same sources and the same <model>_PARTS), with every
    warning an error. Only the compile is shared: what the table is checked against below is
    read from the committed files, not from the generator."""
    return fi.compile_table(model, source_dir or REPO / "fmu_src" / model,
                            out_dir / f"model_table_{model}", warnings=STRICT_WARNINGS)


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    out = tmp_path_factory.mktemp("model_table")
    return {model: compile_table(model, out) for model in FMU_NAMES}


def type_size(table: dict, entry: dict) -> int:
    return table["real_size"] if entry["type"] == "Real" else table["int_size"]


def table_faults(table: dict) -> list[str]:
    """What is wrong with a C table on its own (a)."""
    faults = []
    entries = table["variables"]
    missing = [e["vr"] for e in entries if e["name"] is None]
    if missing:
        return [f"value references {missing} have no entry in model_variables"]
    for key in ("name", "offset"):
        seen = {}
        for e in entries:
            if e[key] in seen:
                faults.append(f"vr {seen[e[key]]} and vr {e['vr']} share the {key} {e[key]!r}")
            seen[e[key]] = e["vr"]
    by_name = {e["name"]: e for e in entries}
    for e in entries:
        if e["offset"] + type_size(table, e) > table["data_size"]:
            faults.append(f"vr {e['vr']} {e['name']}: offset {e['offset']} is past ModelData "
                          f"({table['data_size']} bytes)")
        m = _ELEMENT.match(e["name"])
        if m and int(m.group(2)) > 1:
            prev = by_name.get(f"{m.group(1)}[{int(m.group(2)) - 1}]")
            want = None if prev is None else (prev["vr"] + 1, prev["offset"] + type_size(table, prev),
                                               prev["type"], prev["causality"])
            got = (e["vr"], e["offset"], e["type"], e["causality"])
            if want != got:
                faults.append(f"{e['name']} is not the element after {m.group(1)}[{int(m.group(2)) - 1}] "
                              f"(vr, offset, type, causality): {got}, expected {want}")
    return faults


# ---------------------------------------------------------------------------------------
# the model descriptions, read as XML (FMI 3.0 arrays expanded into elements)


def _start(text: str | None, typ: str):
    if text is None:
        return None
    if typ == "Real":
        return float(text)
    if typ == "Integer":
        return int(text)
    return {"true": 1, "false": 0, "1": 1, "0": 0}[text]


def read_model_description(text: str) -> dict:
    """{'version', 'identifier', 'token', 'variables': {vr: {...}}, 'faults': [...]} of one XML."""
    root = ET.fromstring(text)
    version = root.get("fmiVersion")
    out = {"version": version, "variables": {}, "faults": [], "time": None,
           "identifier": root.find("CoSimulation").get("modelIdentifier"),
           "token": root.get("guid") if version == "2.0" else root.get("instantiationToken")}

    def add(vr, record):
        if vr in out["variables"]:
            out["faults"].append(f"vr {vr} is held by both {out['variables'][vr]['name']} "
                                 f"and {record['name']}")
        out["variables"][vr] = record

    for position, var in enumerate(root.find("ModelVariables")):
        if version == "2.0":
            (typed,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean", "String", "Enumeration")]
            typ, attrs = typed.tag, typed.attrib
            if int(var.get("valueReference")) != position:
                out["faults"].append(f"{var.get('name')}: value reference {var.get('valueReference')} "
                                     f"at position {position + 1} (config.h: value reference = position - 1)")
        else:
            typ, attrs = FMI3_TYPES.get(var.tag, var.tag), var.attrib
        record = {"name": var.get("name"), "type": typ, "causality": var.get("causality", "local"),
                  "variability": var.get("variability", "continuous"), "initial": var.get("initial")}
        vr = int(var.get("valueReference"))
        if record["causality"] == "independent":
            out["time"] = (vr, record["name"])
            continue
        dims = [d for d in var if d.tag == "Dimension"]
        if not dims:
            add(vr, {**record, "start": _start(attrs.get("start"), typ)})
            continue
        (dim,) = dims
        n = int(dim.get("start"))
        starts = attrs.get("start")
        starts = [None] * n if starts is None else [_start(s, typ) for s in starts.split()]
        if len(starts) != n:
            out["faults"].append(f"{record['name']}: {len(starts)} start values for {n} elements")
        for i, start in enumerate(starts, start=1):
            add(vr + i - 1, {**record, "name": f"{record['name']}[{i}]", "start": start})
    return out


def model_description_paths(model: str) -> dict[str, Path]:
    return {"2.0": REPO / "modelDescription" / f"{model}.xml",
            "3.0": REPO / "modelDescription" / "fmi3" / f"{model}.xml"}


def mismatches(table: dict, md: dict) -> list[str]:
    """Where a model description differs from the C table (b), one line each."""
    where = f"{table['model']} FMI {md['version']}"
    out = [f"{where}: {fault}" for fault in md["faults"]]
    if md["identifier"] != table["model"]:
        out.append(f"{where}: modelIdentifier {md['identifier']!r}, C {table['model']!r}")
    if md["token"] != table["guid"]:
        out.append(f"{where}: guid/instantiationToken {md['token']!r}, C MODEL_GUID {table['guid']!r}")
    c_vrs = {e["vr"] for e in table["variables"]}
    for vr in sorted(set(md["variables"]) - c_vrs):
        out.append(f"{where}: vr {vr} ({md['variables'][vr]['name']}) is not in the C table")
    for e in table["variables"]:
        x = md["variables"].get(e["vr"])
        if x is None:
            out.append(f"{where}: vr {e['vr']} ({e['name']}) is not in the model description")
            continue
        start = None if e["start"] is None else (float(e["start"]) if e["type"] == "Real" else e["start"])
        want = {"name": e["name"], "type": e["type"], "causality": e["causality"],
                "variability": VARIABILITY[e["causality"]], "initial": INITIAL[e["causality"]],
                "start": start}
        for key, value in want.items():
            if x[key] != value:
                out.append(f"{where}: vr {e['vr']}: {key} is {x[key]!r} in the model description, "
                           f"{value!r} in the C table ({e['name']})")
    if md["version"] == "3.0" and md["time"] != (table["n_variables"], "time"):
        out.append(f"{where}: the independent variable is {md['time']}, expected (vr "
                   f"{table['n_variables']}, 'time'), the value reference after the table")
    return out


# ---------------------------------------------------------------------------------------
# (a), (b)


def test_every_model_source_is_an_fmu_checked_here():
    """Reference: the folders fmu_src/<Model>/ holding a model.c, each an FMU of FMU_NAMES."""
    assert {p.parent.name for p in (REPO / "fmu_src").glob("*/model.c")} == set(FMU_NAMES)


@pytest.mark.parametrize("model", FMU_NAMES)
def test_c_table_has_one_entry_per_value_reference_laid_out_as_named(tables, model):
    """Reference: the C table printed by the C code; fmu_model.h (entry i is value reference i)
    and fmu_glue_core.c map_variables (a run name[1..n] of one type and causality is an array)."""
    table = tables[model]
    assert table["model"] == model and len(table["variables"]) == table["n_variables"] > 0
    assert [e["vr"] for e in table["variables"]] == list(range(table["n_variables"]))
    faults = table_faults(table)
    assert not faults, "\n".join(faults)


@pytest.mark.parametrize("version", ["2.0", "3.0"])
@pytest.mark.parametrize("model", FMU_NAMES)
def test_model_description_has_the_c_table_variable_at_each_value_reference(tables, model, version):
    """Reference: the C table, printed by the C code (name, type, causality, start value as
    model_set_start_values leaves it; variability and initial as fmu_model.h implies)."""
    md = read_model_description(model_description_paths(model)[version].read_text())
    assert md["version"] == version
    found = mismatches(tables[model], md)
    assert not found, "\n".join(found)
    # every element of the C table is covered, and nothing else
    assert sorted(md["variables"]) == list(range(tables[model]["n_variables"]))


# ---------------------------------------------------------------------------------------
# (c) the checks can fail


def _swap_value_references(text: str, a: str, b: str) -> str:
    """The model description with the valueReference attributes of variables a and b exchanged."""
    pattern = r'(name="{}" valueReference=")(\d+)"'
    vr_a = re.search(pattern.format(re.escape(a)), text).group(2)
    vr_b = re.search(pattern.format(re.escape(b)), text).group(2)
    text = re.sub(pattern.format(re.escape(a)), rf'\g<1>{vr_b}"', text)
    return re.sub(pattern.format(re.escape(b)), rf'\g<1>{vr_a}"', text)


def test_swapped_value_references_in_a_model_description_are_caught(tables):
    """Reference: a scratch copy of modelDescription/PiezoStage.xml with the value references of
    pi.w[4] (11) and pi.w[5] (12) exchanged: same type, same start 0, so only the name tells."""
    text = model_description_paths("PiezoStage")["2.0"].read_text()
    md = read_model_description(_swap_value_references(text, "pi.w[4]", "pi.w[5]"))
    found = mismatches(tables["PiezoStage"], md)
    for vr, md_name, c_name in ((11, "pi.w[5]", "pi.w[4]"), (12, "pi.w[4]", "pi.w[5]")):
        assert (f"PiezoStage FMI 2.0: vr {vr}: name is {md_name!r} in the model description, "
                f"{c_name!r} in the C table ({c_name})") in found
    # ... and the position rule of config.h sees it too
    assert any("pi.w[5]: value reference 11 at position 13" in f for f in found)


def test_swapped_array_elements_in_the_fmi3_description_are_caught(tables):
    """Reference: a scratch copy of modelDescription/fmi3/PiezoStage.xml with the first two start
    values of the array pi.w exchanged (0.0714 0.0322 -> 0.0322 0.0714)."""
    text = model_description_paths("PiezoStage")["3.0"].read_text()
    assert text.count('start="0.0714 0.0322 ') == 1
    md = read_model_description(text.replace('start="0.0714 0.0322 ', 'start="0.0322 0.0714 '))
    found = mismatches(tables["PiezoStage"], md)
    assert found == [f"PiezoStage FMI 3.0: vr {vr}: start is {md} in the model description, {c} in the C "
                     f"table (pi.w[{vr - 7}])" for vr, md, c in ((8, 0.0322, 0.0714), (9, 0.0714, 0.0322))]


def _exchange(text: str, a: str, b: str) -> str:
    """text with the one occurrence of a and the one of b exchanged."""
    assert text.count(a) == 1 and text.count(b) == 1, (a, b)
    return re.sub("|".join(map(re.escape, (a, b))), lambda m: b if m.group(0) == a else a, text)


def test_swapped_entries_in_the_c_table_are_caught(tmp_path, tables):
    """Reference: scratch copies of fmu_src/PiezoStage (its table's entries are in the generated
    variables.h). (1) pi.w[4] and pi.w[5] under each other's value reference: both model
    descriptions disagree at vr 11 and 12. (2) the names kept but the C fields exchanged
    (pi.w[4] -> w[4], pi.w[5] -> w[3]): no model description can see it (both start at 0), the
    array layout check and core.py's offsets do."""
    model_dir = REPO / "fmu_src" / "PiezoStage"
    source = (model_dir / "variables.h").read_text()
    scratch = {"vr": _exchange(source, "[vr_pi_w4] =", "[vr_pi_w5] ="),
               "field": _exchange(source, "pi.w[3]) }", "pi.w[4]) }")}
    table = {}
    for case, text in scratch.items():
        (tmp_path / case).mkdir()
        for name in ("config.h", "model.c"):
            shutil.copy(model_dir / name, tmp_path / case / name)
        (tmp_path / case / "variables.h").write_text(text)
        table[case] = compile_table("PiezoStage", tmp_path / case, tmp_path / case)
    for path in model_description_paths("PiezoStage").values():
        md = read_model_description(path.read_text())
        found = mismatches(table["vr"], md)
        assert [f.split(": ")[1] for f in found] == ["vr 11", "vr 12"], found
        assert mismatches(table["field"], md) == []     # blind to it: both start at 0
    faults = table_faults(table["field"])
    assert any(f.startswith("pi.w[4] is not the element after pi.w[3]") for f in faults), faults
    assert any(f.startswith("pi.w[6] is not the element after pi.w[5]") for f in faults), faults
    wrong = {f.split(":")[0] for f in core_table_mismatches("PiezoStage", table["field"])}
    assert wrong == {"pi.w[4]", "pi.w[5]"}


# ---------------------------------------------------------------------------------------
# (d) harness/binding/core.py's parameter tables


def _core_tables():
    from harness.binding import core
    # which core.py table and core parameter struct (ModelData.params) serve which FMU
    return {"PiezoStage": (core._PLANT_TABLE, "piezo_plant_params", core.default_plant_params),
            "AdaptiveCompoundController": (core._CONTROLLER_TABLE, "piezo_controller_params",
                                           core.default_controller_params)}


# core.py's kinds as C table types; the C type the glue reads at an offset per type (fmu_model.h)
_KIND = {"float": "Real", "int": "Integer", "bool": "Boolean"}
_C_TYPE = {"Real": "double", "Integer": "int", "Boolean": "int"}


def core_table_mismatches(model: str, table: dict) -> list[str]:
    """Where core.py's table for model differs from the C table's parameters, one line each."""
    from harness.binding.core import ffi
    py_table, struct, defaults = _core_tables()[model]
    params = {e["name"]: e for e in table["variables"] if e["causality"] == "parameter"}
    out = [f"{n}: in core.py, not a parameter of the C table" for n in py_table if n not in params]
    out += [f"{n}: a parameter of the C table, not in core.py" for n in params if n not in py_table]
    default = defaults()
    for name, (path, kind) in py_table.items():
        e = params.get(name)
        if e is None:
            continue
        ctype = ffi.typeof(struct)
        for step in path:
            ctype = ctype.item if isinstance(step, int) else dict(ctype.fields)[step].type
        got = (_KIND[kind], ctype.cname, table["param_structs"]["params"][0] + ffi.offsetof(struct, *path),
               int(default[name]) if kind != "float" else default[name])
        want = (e["type"], _C_TYPE[e["type"]], e["offset"], e["start"])
        if got != want:
            out.append(f"{name}: core.py (type, C type, offset in ModelData, default) {got}, "
                       f"C table {want}")
    return out


@pytest.mark.parametrize("model", ["PiezoStage", "AdaptiveCompoundController"])
def test_core_py_tables_map_each_parameter_to_the_c_tables_field(tables, model):
    """Reference: the C table printed by the C code (names, types, offsets, start values) and the
    core's own struct layout, read by cffi from fmu_src/core's headers."""
    found = core_table_mismatches(model, tables[model])
    assert not found, "\n".join(found)


def test_every_core_py_table_is_checked():
    """Reference: harness/binding/core.py's module namespace: each *_TABLE of FMU names is one above."""
    from harness.binding import core
    tables = {name for name in vars(core) if re.fullmatch(r"_[A-Z]+_TABLE", name)}
    assert tables == {"_PLANT_TABLE", "_CONTROLLER_TABLE"}


# ---------------------------------------------------------------------------------------
# (e) the docs


def _unit(attrs) -> str | None:
    return attrs.get("displayUnit") or attrs.get("unit")


def _fmi2_variables(model: str) -> list[dict]:
    """[{name, causality, unit}] of modelDescription/<model>.xml in value-reference order."""
    root = ET.parse(model_description_paths(model)["2.0"]).getroot()
    out = []
    for var in root.find("ModelVariables"):
        (typed,) = list(var)
        out.append({"name": var.get("name"), "causality": var.get("causality"), "unit": _unit(typed.attrib),
                    "vr": int(var.get("valueReference"))})
    return sorted(out, key=lambda v: v["vr"])


def _markdown_files():
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def _cells_of_column(text: str, column: str) -> list[str]:
    """The cells under the header `column` of every Markdown table in text."""
    cells, index = [], None
    for line in text.splitlines():
        if not line.startswith("|"):
            index = None
            continue
        row = [c.strip() for c in line.strip().strip("|").split("|")]
        if index is None:
            index = row.index(column) if column in row else -1
        elif index >= 0 and not set(line) <= set("|-: ") and index < len(row):
            cells.append(row[index])
    return cells


def _names_in(cell: str) -> list[str]:
    return [token for span in re.findall(r"`([^`]+)`", cell) for token in span.split()]


def _resolves(token: str, names: set[str]) -> bool:
    """token names a variable: exactly, as `group.*`, as `name[1..n]` (all exist) or `name[j]`."""
    if token.endswith(".*"):
        return any(n.startswith(token[:-1]) for n in names)
    m = re.fullmatch(r"(.*)\[(\d+)\.\.(\d+)\]", token)
    if m:
        return all(f"{m.group(1)}[{i}]" in names for i in range(int(m.group(2)), int(m.group(3)) + 1))
    m = re.fullmatch(r"(.*)\[[a-z]\]", token)
    if m:
        return f"{m.group(1)}[1]" in names
    return token in names


def test_every_variable_named_in_an_fmu_variables_column_exists():
    """Reference: the variable names of the FMI 2.0 model descriptions of all FMUs. Every name in
    a column headed "FMU variables" (README.md, docs/*.md) is one of them, a group `prefix.*`
    with members, a range `name[1..n]` whose elements all exist, or `name[j]`."""
    names = {v["name"] for model in FMU_NAMES for v in _fmi2_variables(model)}
    tokens = [(path.name, token) for path in _markdown_files()
              for cell in _cells_of_column(path.read_text(), "FMU variables") for token in _names_in(cell)]
    assert len(tokens) > 20          # the columns were found (README and model.md hold them today)
    assert [t for t in tokens if not _resolves(t[1], names)] == []


def test_a_misnamed_variable_in_an_fmu_variables_column_is_caught():
    """Reference: a scratch Markdown table naming a misspelt variable, an element past the array,
    a group with no members and an existing name."""
    names = {v["name"] for v in _fmi2_variables("PiezoStage")}
    text = ("| block | FMU variables |\n|---|---|\n"
            "| creep | `creep.alfa`, `pi.w[1..17]`, `rls.*` |\n| dynamics | `tf.a1 tf.delay` |\n")
    tokens = [t for cell in _cells_of_column(text, "FMU variables") for t in _names_in(cell)]
    assert tokens == ["creep.alfa", "pi.w[1..17]", "rls.*", "tf.a1", "tf.delay"]
    assert [t for t in tokens if not _resolves(t, names)] == ["creep.alfa", "pi.w[1..17]", "rls.*"]
