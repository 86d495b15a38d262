"""Tests of the cffi binding itself (harness/binding/core.py): struct layout, symbols,
library lookup, parameter naming."""
import os
import re
import shutil
import subprocess
import sys

import xml.etree.ElementTree as ET

import pytest

from harness import paths
from harness.binding import core
import numpy_reference as ref


def _struct_layouts():
    """(typedef name, sizeof, [(field, offset)]) for every typedef cffi knows."""
    typedefs, _, _ = core.ffi.list_types()
    out = []
    for name in sorted(typedefs):
        t = core.ffi.typeof(name)
        fields = [(f, c.offset) for f, c in t.fields] if t.kind == "struct" else []
        out.append((name, core.ffi.sizeof(t), fields))
    return out


@pytest.mark.skipif(shutil.which("cc") is None, reason="no system C compiler")
def test_struct_layout_matches_c_compiler(tmp_path):
    """Reference: the system C compiler. A generated C program prints sizeof and
    offsetof of every typedef and field as compiled from the real headers; cffi's
    layout must agree exactly (a mismatch would corrupt every call)."""
    layouts = _struct_layouts()
    assert {"piezo_plant", "piezo_controller", "piezo_gl", "piezo_pi_inverse"} <= {n for n, _, _ in layouts}
    lines = ['#include <stdio.h>', '#include <stddef.h>', '#include "piezo_core.h"', "int main(void) {"]
    for name, _, fields in layouts:
        lines.append(f'  printf("{name} %zu\\n", sizeof({name}));')
        for f, _ in fields:
            lines.append(f'  printf("{name}.{f} %zu\\n", offsetof({name}, {f}));')
    lines += ["  return 0;", "}"]
    src = tmp_path / "layout.c"
    src.write_text("\n".join(lines))
    exe = tmp_path / "layout"
    subprocess.run(["cc", "-std=c99", "-I", str(core.CORE_DIR), str(src), "-o", str(exe)], check=True)
    got = dict(l.rsplit(" ", 1) for l in subprocess.run([str(exe)], check=True, capture_output=True,
                                                         text=True).stdout.splitlines())
    expected = {}
    for name, size, fields in layouts:
        expected[name] = str(size)
        for f, off in fields:
            expected[f"{name}.{f}"] = str(off)
    mismatches = {k: (expected[k], got.get(k)) for k in expected if expected[k] != got.get(k)}
    assert not mismatches, f"cffi vs C (cffi, C): {mismatches}"


def _header_function_names():
    """Function names declared in the headers the umbrella piezo_core.h includes, found by
    a plain regex over the comment-stripped header text (independent of the binding's own
    header_cdef parser): '<return type> piezo_name(...);' at the start of a line."""
    umbrella = (core.CORE_DIR / "piezo_core.h").read_text()
    headers = re.findall(r'#\s*include\s*"([^"]+)"', umbrella)
    decl = re.compile(r"^[ \t]*(?:[A-Za-z_]\w*[ \t*]+)+?\**(piezo_\w+)\s*\([^;{}]*\)\s*;", re.M)
    names = []
    for h in headers:
        text = re.sub(r"/\*.*?\*/", " ", (core.CORE_DIR / h).read_text(), flags=re.S)
        names += decl.findall(text)
    return headers, names


def test_every_declared_function_is_exported():
    """Reference: the header declarations themselves (regex over the headers piezo_core.h
    includes). The binding declares exactly those functions (no more, none missing, no
    duplicate declarations), and every one resolves in the shared library (dlsym)."""
    headers, declared = _header_function_names()
    assert set(headers) == set(core.HEADER_ORDER)
    assert len(declared) == len(set(declared)) and declared
    L = core.lib()
    bound = {n for n in dir(L) if n.startswith("piezo_")}
    assert bound == set(declared), (sorted(bound ^ set(declared)))
    missing = []
    for n in declared:
        try:
            getattr(L, n)
        except AttributeError:
            missing.append(n)
    print(f"\n{len(declared)} functions declared in {len(headers)} headers")
    assert not missing, f"missing symbols: {missing}"


def test_missing_library_message(tmp_path):
    """Reference: the documented contract. A missing library raises FileNotFoundError
    naming the exact cmake command (checked in a fresh interpreter)."""
    code = ("import sys; sys.path.insert(0, %r)\n"
            "from harness.binding import core\n"
            "try:\n    core.lib()\nexcept FileNotFoundError as e:\n    print('FNF', e)\n") % str(paths.REPO_ROOT)
    env = dict(os.environ, PIEZO_CORE_LIB=str(tmp_path / "nope.so"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.startswith("FNF") and "cmake -S . -B build && cmake --build build" in out


def test_defaults_match_design():
    """Reference: docs/fmus.md defaults typed in tests/numpy_reference.py
    (DOC_DEFAULTS for the model, CONTROLLER_DOC_DEFAULTS for the controller's own
    parameters: the robust update, rls.forgetting 0.99, rls.trace_max 1000, rls.p0 1,
    rls.p0_loop 0.01, mv.integral 0.01, mv.delay -1, mv.lambda_u 0, limits +-150 V on,
    monitor 1 um / 200 samples),
    and the parameter name sets of the two modelDescription files."""
    p = core.default_plant_params()
    d = ref.DOC_DEFAULTS
    for k in ("pi.m", "pi.v_max", "pi.w0", "tf.a1", "tf.a2", "tf.b1", "tf.b2", "tf.delay",
              "creep.k_c", "creep.alpha", "h"):
        assert p[k] == pytest.approx(d[k], abs=0), k
    for j in range(1, 17):
        want = d["pi.w"][j - 1] if j <= len(d["pi.w"]) else 0.0
        assert p[f"pi.w[{j}]"] == want, j
    assert p["creep.enabled"] is True and p["creep.exact"] is False
    assert p["sensor.resolution"] == 0 and p["sensor.noise_rms"] == 0 and p["sensor.seed"] == 1
    c = core.default_controller_params()
    for k in ("pi.m", "pi.v_max", "pi.w0", "tf.a1", "tf.a2", "tf.b1", "tf.b2", "creep.k_c",
              "creep.alpha", "h"):
        assert c[k] == p[k], k
    for k, want in ref.CONTROLLER_DOC_DEFAULTS.items():
        assert c[k] == want, (k, c[k], want)
    assert set(core.PLANT_PARAMETER_NAMES) == set(p) == set(_fmu_parameters("PiezoStage"))
    assert (set(core.CONTROLLER_PARAMETER_NAMES) == set(c)
            == set(_fmu_parameters("AdaptiveCompoundController")))


def _fmu_parameters(model):
    """{name: start value as typed} of the causality="parameter" variables in
    modelDescription/<model>.xml (the FMU interface of docs/fmus.md)."""
    root = ET.parse(paths.REPO_ROOT / "modelDescription" / f"{model}.xml").getroot()
    out = {}
    for var in root.iter("ScalarVariable"):
        if var.get("causality") == "parameter":
            (typ,) = list(var)
            raw = typ.get("start")
            out[var.get("name")] = {"Real": float, "Integer": int,
                                    "Boolean": lambda t: t == "true"}[typ.tag](raw)
    return out


@pytest.mark.parametrize("model", ["PiezoStage", "AdaptiveCompoundController"])
def test_core_defaults_equal_model_description_start_values(model):
    """Reference: the start values in modelDescription/<model>.xml (what an FMI importer shows
    as defaults). Every core default equals its start value exactly, e.g. for the controller
    rls.p0 = 1, rls.trace_max = 1000, rls.forgetting = 0.99, mv.integral = 0.01."""
    want = _fmu_parameters(model)
    got = core.default_plant_params() if model == "PiezoStage" else core.default_controller_params()
    assert set(got) == set(want)
    diff = {k: (got[k], want[k]) for k in want if got[k] != want[k]}
    assert not diff, f"core default vs modelDescription start: {diff}"


def test_controller_initial_state_uses_p0_and_nominal_model():
    """Reference: docs/model.md, controller ('initialised from the nominal model') and the header.
    A fresh controller holds theta = nominal [a1, a2, b1, b2], its delay candidates start from
    P = rls.p0 I and the loop's estimator from rls.p0_loop I (the robust update; rls.p0 I with
    the paper's update), read through ffi: the defaults 1 and 0.01, then rls.p0 = 2.5 and
    rls.p0_loop = 0.5."""
    d = ref.DOC_DEFAULTS
    for over in ({}, {"rls.p0": 2.5, "rls.p0_loop": 0.5}, {"rls.p0": 2.5, **ref.PAPER_LAW}):
        c = core.Controller(over)
        params = {**ref.CONTROLLER_DOC_DEFAULTS, **over}
        loop_p0 = params["rls.p0_loop"] if params["rls.robust"] else params["rls.p0"]
        assert list(c.raw.theta) == [d["tf.a1"], d["tf.a2"], d["tf.b1"], d["tf.b2"]]
        assert list(c.raw.P) == [loop_p0 if i % 5 == 0 else 0.0 for i in range(16)], over
        assert list(c.raw.det_P) == [params["rls.p0"] if i % 16 % 5 == 0 else 0.0 for i in range(48)], over
        assert c.raw.trace_max == params["rls.trace_max"]
        assert c.raw.forgetting == params["rls.forgetting"]


def test_unknown_parameter_name_lists_valid_names():
    """Reference: the binding contract (KeyError listing the valid names)."""
    with pytest.raises(KeyError) as ei:
        core.Plant({"creep.alfa": 0.1})
    assert "creep.alpha" in str(ei.value) and "sensor.seed" in str(ei.value)
    with pytest.raises(KeyError) as ei:
        core.Controller({"sensor.seed": 3})      # a plant-only name
    assert "rls.forgetting" in str(ei.value)
    with pytest.raises(KeyError):
        core.Plant({"pi.w[17]": 0.0})
    with pytest.raises(TypeError):
        core.Plant({"pi.m": 2.5})


def test_parameter_round_trip_through_struct():
    """Reference: the values written. Every FMU name maps to its own struct field
    (no two names alias one field)."""
    names = [n for n in core.PLANT_PARAMETER_NAMES]
    vals = {}
    for i, n in enumerate(names):
        kind = core._PLANT_TABLE[n][1]
        vals[n] = (i % 2 == 0) if kind == "bool" else (i + 1 if kind == "int" else 0.001 * (i + 1))
    s = core.plant_params_struct(vals)
    back = core._to_dict(core._PLANT_TABLE, s)
    assert back == vals
    names = list(core.CONTROLLER_PARAMETER_NAMES)
    vals = {}
    for i, n in enumerate(names):
        kind = core._CONTROLLER_TABLE[n][1]
        vals[n] = (i % 2 == 0) if kind == "bool" else (i + 1 if kind == "int" else 0.001 * (i + 1))
    s = core.controller_params_struct(vals)
    assert core._to_dict(core._CONTROLLER_TABLE, s) == vals
