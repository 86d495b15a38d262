"""Each FMU's interface is declared once (``fmu_src/<Model>/variables.toml``) and generated from there.

Reference: ``packaging/fmu_interface.py``, which writes from the declarations each model's
``variables.h`` (value references and the C table's entries) and its two model descriptions;
PiezoStageClosedLoop's declaration composes its components'. What the binaries then serve is
checked independently in ``test_variable_sources.py`` (the compiled C table against the model
descriptions, harness/binding/core.py and the docs).

(a) the committed generated files (and the Interfaces table of docs/fmus.md) are exactly what
    the declarations give, and say so in their first lines;
(b) one declaration reaches every FMU and edition: a parameter appended to the controller's
    declaration (in a scratch copy) appears in its C table and both its model descriptions, in
    PiezoStageClosedLoop's (through ``"controller:*"``) and in the harness's names, with the
    start value the compiled model gives, while every other variable keeps its value reference
    and text;
(c) a declaration that cannot be generated stops with a message naming the file and variable
    (a component's variable the loop neither takes nor lists, an unknown key, a name twice,
    ``controller:*`` not last).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from conftest import FMU_NAMES, REPO

sys.path.insert(0, str(REPO / "packaging"))
import fmu_interface as fi  # noqa: E402

CONTROLLER = "AdaptiveCompoundController"
LOOP = "PiezoStageClosedLoop"
#: a parameter added as the adaptation and supervision issues add theirs; it shares
#: rls.fallback_window's C field so that the scratch model compiles without a core change
NEW_PARAMETER = '''
[[variable]]
name = "rls.new_window"
type = "Real"
causality = "parameter"
field = "params.rls_fallback_window"
unit = "s"
min = 0
max = 3600
description = "A new parameter, declared in this one place"
'''


def _scratch(tmp_path: Path) -> Path:
    """A copy of what the generator reads: fmu_src, modelDescription, model_table.c, CMakeLists,
    docs/fmus.md."""
    root = tmp_path / "repo"
    shutil.copytree(REPO / "fmu_src", root / "fmu_src",
                    ignore=shutil.ignore_patterns("bench", "runner"))
    shutil.copytree(REPO / "modelDescription", root / "modelDescription")
    (root / "tests").mkdir()
    shutil.copytree(REPO / "tests" / "model_table", root / "tests" / "model_table")
    shutil.copy(REPO / "CMakeLists.txt", root / "CMakeLists.txt")
    (root / "harness" / "binding").mkdir(parents=True)
    (root / "docs").mkdir()
    shutil.copy(REPO / "docs" / "fmus.md", root / "docs" / "fmus.md")
    return root


def _variables(text: str) -> dict:
    """{valueReference: (name, attributes but valueReference, type element's attributes)}."""
    out = {}
    for v in ET.fromstring(text.encode("utf-8")).find("ModelVariables"):
        attrs = dict(v.attrib)
        vr = int(attrs.pop("valueReference"))
        typ = next((dict(c.attrib) for c in v if c.tag in ("Real", "Integer", "Boolean")), None)
        out[vr] = (attrs.pop("name"), attrs, typ)
    return out


def test_the_generated_files_are_what_the_declarations_give():
    """Reference: the generator run now; a hand edit of a generated file, or a declaration changed
    without running ``python3 packaging/fmu_interface.py``, fails here naming the file."""
    stale = fi.stale_files()
    assert stale == [], f"out of date (run python3 packaging/fmu_interface.py): {stale}"
    assert set(fi.MODELS) == set(FMU_NAMES)


@pytest.mark.parametrize("model", FMU_NAMES)
def test_each_generated_file_says_so_in_its_first_lines(model):
    """Reference: the generator's header comments: they name the generator and the declaration."""
    for path in (REPO / "fmu_src" / model / "variables.h", REPO / "modelDescription" / f"{model}.xml",
                 REPO / "harness" / "binding" / "fmu_variables.py",
                 REPO / "modelDescription" / "fmi3" / f"{model}.xml"):
        head = "\n".join(path.read_text(encoding="utf-8").splitlines()[:4])
        assert "packaging/fmu_interface.py" in head, path
        assert f"fmu_src/{model}/variables.toml" in head or "fmu_src/<Model>/variables.toml" in head, path


def test_a_parameter_declared_once_reaches_every_fmu_and_edition(tmp_path):
    """Reference: the committed files. Appending one [[variable]] to the controller's declaration
    adds exactly that variable, after the last one, to the controller's and the closed loop's C
    tables and both editions of their model descriptions, with rls.fallback_window's start value
    0.5 s (the field it shares, read from the compiled model), and to the harness's names
    (harness/binding/fmu_variables.py, harness/binding/core.py's parameter table); everything
    else is unchanged, the other two FMUs' files are identical, and so is docs/fmus.md's
    Interfaces table (it lists the controller's parameters as `rls.*`)."""
    root = _scratch(tmp_path)
    decl = root / "fmu_src" / CONTROLLER / "variables.toml"
    decl.write_text(decl.read_text(encoding="utf-8") + NEW_PARAMETER, encoding="utf-8")
    files = fi.generated_files(root)
    changed = sorted(str(p.relative_to(root)) for p, text in files.items()
                     if text != (REPO / p.relative_to(root)).read_text(encoding="utf-8"))
    assert changed == sorted([f"fmu_src/{m}/variables.h" for m in (CONTROLLER, LOOP)]
                             + [f"modelDescription/{m}.xml" for m in (CONTROLLER, LOOP)]
                             + [f"modelDescription/fmi3/{m}.xml" for m in (CONTROLLER, LOOP)]
                             + ["harness/binding/fmu_variables.py"])
    names = {}
    module = files[root / "harness" / "binding" / "fmu_variables.py"]
    exec(compile(module, "fmu_variables.py", "exec"), names)
    assert names["PARAMETERS"][CONTROLLER]["rls.new_window"] == (("rls_fallback_window",), "float")
    assert names["COMPOSED"][LOOP]["rls.new_window"] == (CONTROLLER, "rls.new_window")
    expected_vr = {CONTROLLER: 88, LOOP: 148}
    expected_field = {CONTROLLER: "params.rls_fallback_window", LOOP: "control.rls_fallback_window"}
    for model, vr in expected_vr.items():
        header = files[root / "fmu_src" / model / "variables.h"]
        assert (f'[vr_rls_new_window] = {{ "rls.new_window", MODEL_REAL, MODEL_PARAMETER, '
                f'offsetof(ModelData, {expected_field[model]}) }}') in header
        for sub in ("", "fmi3"):
            path = Path("modelDescription") / sub / f"{model}.xml"
            old = _variables((REPO / path).read_text(encoding="utf-8"))
            new = _variables(files[root / path])
            name, attrs, typ = new[vr]
            assert name == "rls.new_window" and attrs["causality"] == "parameter"
            start = typ["start"] if typ else attrs["start"]
            assert float(start) == 0.5
            if sub:                     # FMI 3.0: time moves to the reference after the new one
                assert old[vr][0] == "time" and new[vr + 1][0] == "time"
                del old[vr], new[vr], new[vr + 1]
            else:
                del new[vr]
            assert new == old, path


def _write(root: Path, model: str, text: str, append: bool = True):
    decl = root / "fmu_src" / model / "variables.toml"
    decl.write_text((decl.read_text(encoding="utf-8") if append else "") + text, encoding="utf-8")


def test_a_new_parameter_group_shows_in_the_interfaces_table(tmp_path):
    """Reference: the table's rule (a structured name's group, `name.*`): a stage parameter of a
    new group ``mount.*`` adds `mount.*` to PiezoStage's parameters cell, and to the loop's
    (which takes it), and nothing else in docs/fmus.md changes."""
    root = _scratch(tmp_path)
    _write(root, "PiezoStage", NEW_PARAMETER.replace("rls.new_window", "mount.tilt").replace(
        "params.rls_fallback_window", "params.h"))
    loop = root / "fmu_src" / LOOP / "variables.toml"
    loop.write_text(loop.read_text(encoding="utf-8").replace(
        '  "stage:sensor.seed",\n', '  "stage:sensor.seed",\n  "stage:mount.tilt",\n'), encoding="utf-8")
    interfaces = [fi.load(m, root) for m in fi.MODELS]
    old = (REPO / "docs" / "fmus.md").read_text(encoding="utf-8")
    new = fi.doc_with_table(root / "docs" / "fmus.md", old, fi.interfaces_table(interfaces))
    changed = [(a, b) for a, b in zip(old.splitlines(), new.splitlines()) if a != b]
    assert len(old.splitlines()) == len(new.splitlines()) and len(changed) == 2
    assert changed[0][1] == changed[0][0].replace("`sensor.*`, `h` |", "`sensor.*`, `h`, `mount.*` |")
    assert changed[1][1] == changed[1][0].replace("`sensor.*`, `controller.*`",
                                                  "`sensor.*`, `mount.*`, `controller.*`")


def test_a_component_variable_the_loop_neither_takes_nor_lists_stops_the_generation(tmp_path):
    """Reference: the rule of the loop's declaration: a stage parameter added without a place in
    the loop is named, with where to put it."""
    root = _scratch(tmp_path)
    _write(root, "PiezoStage", NEW_PARAMETER.replace("rls.new_window", "sensor.new").replace(
        "params.rls_fallback_window", "params.h"))
    fi.load("PiezoStage", root)             # the stage's own declaration is fine
    with pytest.raises(fi.InterfaceError, match=r"PiezoStage's variable 'sensor.new' is neither "
                                                r"composed into the loop nor listed in "
                                                r"\[component.stage\] not_composed"):
        fi.load(LOOP, root)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t + '\n[[variable]]\nname = "x"\ntype = "Real"\ncausality = "parameter"\n'
                   'field = "params.h"\ndescription = "d"\ncolour = "red"\n',
     r"variable 'x': unknown keys \['colour'\]"),
    (lambda t: t + '\n[[variable]]\nname = "h"\ntype = "Real"\ncausality = "parameter"\n'
                   'field = "params.h"\ndescription = "d"\n',
     r"declared twice: \['h'\]"),
    (lambda t: t + '\n[[variable]]\nname = "x"\ntype = "Float"\ncausality = "parameter"\n'
                   'field = "params.h"\ndescription = "d"\n',
     r"variable 'x': type 'Float' not one of"),
    (lambda t: t + '\n[[variable]]\nname = "x"\ntype = "Real"\ncausality = "parameter"\n'
                   'field = "params.h"\nunit = "mm"\ndescription = "d"\n',
     r"variable 'x': unit 'mm' not in"),
    (lambda t: t + '\n[[variable]]\nname = "x"\ntype = "Real"\ncausality = "parameter"\n'
                   'field = "params.h); exit(1); (void)(0"\ndescription = "d"\n',
     r"variable 'x': field .* is not a C member path of ModelData"),
    (lambda t: t + '\n[[variable]]\nname = "x"\ntype = "Real"\ncausality = "parameter"\n'
                   'field = "params.h"\ncore = { range = "(0, 1)", default = 0.5 }\ndescription = "d"\n',
     r"core tables are read from AdaptiveCompoundController's declaration only, not here: \['x'\]"),
])
def test_a_bad_declaration_is_refused_naming_the_file_and_variable(tmp_path, edit, message):
    """Reference: the generator's checks (fmu_interface._variable, load)."""
    root = _scratch(tmp_path)
    decl = root / "fmu_src" / "PiezoStage" / "variables.toml"
    decl.write_text(edit(decl.read_text(encoding="utf-8")), encoding="utf-8")
    with pytest.raises(fi.InterfaceError, match=message) as info:
        fi.load("PiezoStage", root)
    assert "PiezoStage/variables.toml" in str(info.value)


def test_the_controller_wildcard_must_come_last(tmp_path):
    """Reference: the value-reference rule: an entry after ``controller:*`` would move whenever
    the controller grows, so the generator refuses it."""
    root = _scratch(tmp_path)
    decl = root / "fmu_src" / LOOP / "variables.toml"
    text = decl.read_text(encoding="utf-8")
    assert text.count('  "controller:*",\n') == 1
    decl.write_text(text.replace('  "controller:*",\n', '  "controller:*",\n  "stage:sensor.seed",\n'),
                    encoding="utf-8")
    with pytest.raises(fi.InterfaceError, match=r"'controller:\*' must come last"):
        fi.load(LOOP, root)


#: a plain controller parameter as the adaptation and supervision issues add theirs: its
#: declaration (with its core range, default and the controller's copy), its two C members,
#: and the code that uses it (here the driver below): three files
PLAIN_PARAMETER = '''
[[variable]]
name = "rls.new_gain"
type = "Real"
causality = "parameter"
field = "params.rls_new_gain"
core = { range = "(0, 2] (a new gain)", default = 0.25, copy = "new_gain" }
description = "A new plain parameter, declared in this one place"

[[variable]]
name = "sup.new_margin"
type = "Real"
causality = "parameter"
field = "params.sup.new_margin"
core = { range = "[1, 10) (a new margin)", default = 3.0, copy = "new_margin" }
description = "A new plain parameter of the supervisor"
'''

#: the use: init with the defaults, a value out of range, the restore checks
PLAIN_DRIVER = r'''
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "piezo_controller.h"
static piezo_controller c;
int main(void)
{
    piezo_controller_params p;
    piezo_diag diag;
    const char *m;
    int st;
    piezo_controller_default_params(&p);
    printf("default %.17g\n", p.rls_new_gain);
    st = (int)piezo_controller_init(&c, &p, &diag);
    printf("init %d copy %.17g\n", st, c.new_gain);
    printf("params %s\n", (m = piezo_controller_check_params(&c, &p)) ? m : "ok");
    printf("state %s\n", (m = piezo_controller_check(&c)) ? m : "ok");
    c.new_gain = 0.5;
    printf("tampered params %s\n", (m = piezo_controller_check_params(&c, &p)) ? m : "ok");
    c.new_gain = NAN;
    printf("tampered state %s\n", (m = piezo_controller_check(&c)) ? m : "ok");
    p.rls_new_gain = 2.5;
    memset(&diag, 0, sizeof diag);
    st = (int)piezo_controller_init(&c, &p, &diag);
    printf("refused %d %s %s %g\n", st, diag.parameter, diag.valid_range, diag.value);
    piezo_controller_default_params(&p);
    st = (int)piezo_controller_init(&c, &p, &diag);
    printf("sup default %.17g init %d copy %.17g\n", p.sup.new_margin, st, c.sup.new_margin);
    c.sup.new_margin = 4.0;
    printf("sup tampered params %s\n", (m = piezo_controller_check_params(&c, &p)) ? m : "ok");
    c.sup.new_margin = 10.0;
    printf("sup tampered state %s\n", (m = piezo_controller_check(&c)) ? m : "ok");
    p.sup.new_margin = 0.5;
    memset(&diag, 0, sizeof diag);
    st = (int)piezo_controller_init(&c, &p, &diag);
    printf("sup refused %d %s %s %g\n", st, diag.parameter, diag.valid_range, diag.value);
    return 0;
}
'''


def test_a_plain_controller_parameter_takes_its_declaration_its_members_and_its_use(tmp_path):
    """Reference: the issue's "at most 3 files" and the C core compiled from a scratch copy. A
    parameter declared with a ``core`` table in the controller's declaration (1), given its
    member in piezo_controller_params and its copy in piezo_controller (piezo_controller.h,
    2) and used (3: a driver here) gets, with no other line: its default 0.25 (the model
    descriptions' start, and piezo_controller_default_params), its range (0, 2] as the
    descriptions' min/max and as init's refusal of 2.5 naming it and the range, its copy in
    the controller, which the restore checks hold to the parameter (0.5: "does not match") and
    to the range (NaN: "rls.new_gain out of range"). The same for a supervisor parameter
    (sup.new_margin, its members in piezo_supervisor.h): default 3, a copy of 4 "does not
    match", 10 is "sup.new_margin out of range" (the open end), 0.5 refused naming it."""
    root = _scratch(tmp_path)
    _write(root, CONTROLLER, PLAIN_PARAMETER)
    header = root / "fmu_src" / "core" / "piezo_controller.h"
    text = header.read_text(encoding="utf-8")
    assert text.count("} piezo_controller_params;") == 1 and text.count("} piezo_controller;") == 1
    header.write_text(text.replace("} piezo_controller_params;", "    double rls_new_gain;\n} piezo_controller_params;")
                      .replace("} piezo_controller;", "    double new_gain;\n} piezo_controller;"), encoding="utf-8")
    header = root / "fmu_src" / "core" / "piezo_supervisor.h"
    text = header.read_text(encoding="utf-8")
    assert text.count("} piezo_supervisor_params;") == 1 and text.count("} piezo_supervisor;") == 1
    header.write_text(text.replace("} piezo_supervisor_params;", "    double new_margin;\n} piezo_supervisor_params;")
                      .replace("} piezo_supervisor;", "    double new_margin;\n} piezo_supervisor;"), encoding="utf-8")
    files = fi.generated_files(root)
    for path, content in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(content, encoding="utf-8")
    core_header = files[root / fi.CORE_HEADER]
    assert ('X(rls_new_gain, "rls.new_gain", 0.25, 0.0, 2.0, 1, 0, "(0, 2] (a new gain)")' in core_header)
    assert 'X(rls_new_gain, new_gain, "rls.new_gain", 0.0, 2.0, 1, 0)' in core_header
    assert 'X(new_margin, new_margin, "sup.new_margin", 1.0, 10.0, 0, 1)' in core_header.split(
        "PIEZO_SUPERVISOR_PLAIN_COPIES")[1].split("PIEZO_CONTROLLER")[0]
    for sub in ("", "fmi3"):
        for model in (CONTROLLER, LOOP):
            found = [(attrs, typ) for name, attrs, typ in
                     _variables(files[root / "modelDescription" / sub / f"{model}.xml"]).values()
                     if name == "rls.new_gain"]
            assert len(found) == 1, (sub, model)
            attrs, typ = found[0]
            values = typ if typ else attrs
            assert (float(values["start"]), float(values["min"]), float(values["max"])) == (0.25, 0.0, 2.0)
    cc = shutil.which("cc") or shutil.which("gcc")
    core = root / "fmu_src" / "core"
    (tmp_path / "driver.c").write_text(PLAIN_DRIVER, encoding="utf-8")
    import subprocess
    subprocess.run([cc, "-std=c99", "-O0", "-w", "-I", str(core), str(tmp_path / "driver.c"),
                    *sorted(str(p) for p in core.glob("*.c")), "-lm", "-o", str(tmp_path / "driver")],
                   check=True)
    out = subprocess.run([str(tmp_path / "driver")], check=True, capture_output=True, text=True).stdout
    assert out.splitlines() == [
        "default 0.25",
        "init 0 copy 0.25",
        "params ok",
        "state ok",
        "tampered params controller state does not match its parameters",
        "tampered state rls.new_gain out of range",
        "refused 2 rls.new_gain (0, 2] (a new gain) 2.5",
        "sup default 3 init 0 copy 3",
        "sup tampered params controller state does not match its parameters",
        "sup tampered state sup.new_margin out of range",
        "sup refused 2 sup.new_margin [1, 10) (a new margin) 0.5",
    ], out
