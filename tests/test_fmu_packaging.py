"""What a receiver finds inside each FMU, and that the build makes the same bytes twice.

(a) the file list of every FMU and fmpy's validation (nothing reported);
(b) the model description's identity: author, version (pyproject.toml's), copyright, licence,
    generation tool with the commit it was built from and date (the commit's: git), and
    min/max that match what the C core refuses (every bounded parameter is refused just
    outside its range, naming it);
(c) documentation/index.html: its variable table equals the model description, row for
    row; it has the equations, the loop connections of harness/buildtime/ssp_file.py, the citation and the
    licence; documentation/licenses/license.txt is the repository's LICENSE; model.png is a
    200 x 200 PNG;
(d) a second build tree, configured and built from scratch, zips byte-identical FMUs
    (fixed entry order, dates and permissions; no time stamp in the binaries).
"""

from __future__ import annotations

import atexit
import datetime as dt
import functools
from html.parser import HTMLParser
import os
import re
import shutil
import struct
import subprocess
import sys
import tomllib
import zipfile
from xml.etree import ElementTree as ET

import pytest
from fmpy.fmi1 import FMICallException

from conftest import FMU_NAMES, REPO, FmuPackage, expected_binaries
from test_repository import FORBIDDEN

NAMES = FMU_NAMES
LS_REF = "extra/org.fmi-standard.fmi-ls-ref/"
VERSION = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]


def _names(fmu):
    with zipfile.ZipFile(fmu) as zf:
        return [n for n in zf.namelist() if not n.endswith("/")]


def _xml(fmu):
    with zipfile.ZipFile(fmu) as zf:
        return ET.fromstring(zf.read("modelDescription.xml"))


def _source_files(root):
    return [f.get("name") for f in root.iter("File")]


# ---------------------------------------------------------------------------------------
# (a) layout

@pytest.mark.parametrize("name", NAMES)
def test_fmu_holds_binaries_sources_documentation_licence_and_references(fmu_paths, name):
    names = set(_names(fmu_paths[name]))
    root = _xml(fmu_paths[name])
    # the cross platforms' binaries the build had compilers for (test_fmu_platforms.py
    # requires them, or skips)
    expected = set(expected_binaries(name, 2)) | {
        "modelDescription.xml", "model.png",
        f"binaries/linux64/{name}.so",
        "sources/buildDescription.xml",
        "documentation/index.html", "documentation/fmi-ls-ref.html",
        "documentation/licenses/license.txt",
        LS_REF + "fmi-ls-manifest.xml", LS_REF + "experiments.exp", LS_REF + f"{name}_ref.csv",
    }
    expected |= {f"sources/{f}" for f in _source_files(root)}
    assert expected <= names, sorted(expected - names)
    extra = names - expected
    # the rest: the headers beside the sources, and the experiment's parameter and stimuli files
    assert all(re.fullmatch(rf"sources/[\w]+\.h|{LS_REF}{name}_(params\.ssv|in\.csv)", n)
               for n in extra), sorted(extra)


@pytest.mark.parametrize("name", NAMES)
def test_fmu_passes_fmpy_validation(fmu_paths, name):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmu_paths[name])) == []


# ---------------------------------------------------------------------------------------
# (b) the model description

def _commit_date():
    env = os.environ.get("SOURCE_DATE_EPOCH")
    if env:
        return int(env)
    out = subprocess.run(["git", "-C", str(REPO), "log", "-1", "--format=%ct"],
                         capture_output=True, text=True, check=True).stdout
    return int(out)


@pytest.mark.parametrize("name", NAMES)
def test_model_description_says_who_what_when_and_under_which_licence(fmu_paths, name):
    root = _xml(fmu_paths[name])
    assert root.get("author") == "The piezo_fmus authors"
    assert root.get("version") == VERSION
    assert re.fullmatch(r"Copyright \(c\) 20\d\d The piezo_fmus authors", root.get("copyright"))
    assert root.get("license").startswith("BSD-3-Clause")
    # the source it was built from: git is the reference (HEAD, and whether tracked files differ)
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain",
                            "--untracked-files=no"], capture_output=True, text=True,
                           check=True).stdout.strip()
    assert root.get("generationTool") == (f"piezo_fmus {VERSION}, commit {head}"
                                          + (" with uncommitted changes" if dirty else ""))
    # the commit's date (git is the reference), not the time of the build
    want = dt.datetime.fromtimestamp(_commit_date(), dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    assert root.get("generationDateAndTime") == want
    assert "Coupling Modeling and Adaptive Control" in root.get("description")
    text = ET.tostring(root, encoding="unicode")
    assert not [word for word in FORBIDDEN if word in text]


def _bounded_parameters(name):
    """(parameter, bound, value just outside, value just inside) for every min and max."""
    root = ET.parse(REPO / "modelDescription" / f"{name}.xml").getroot()
    out = []
    for var in root.iter("ScalarVariable"):
        if var.get("causality") != "parameter":
            continue
        (typ,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean")]
        for bound, side in (("min", -1), ("max", +1)):
            if typ.get(bound) is None:
                continue
            value = float(typ.get(bound))
            if typ.tag == "Integer":
                outside, inside = int(value) + side, int(value)
            else:
                delta = 1e-9 * max(1.0, abs(value))
                outside, inside = value + side * delta, value - side * delta
            out.append((var.get("name"), bound, outside, inside))
    return out


#: bounds that depend on another parameter, reached only with that one at its own limit:
#: |tf.a1| < 1 + tf.a2 (stable A) and rls.trace_max >= 4 rls.p0
COMPANIONS = {"tf.a1": {"tf.a2": 1 - 1e-12}, "rls.trace_max": {"rls.p0": 1e-12}}


def _companions(parameter):
    """COMPANIONS of a parameter; the closed-loop FMU's controller.<name> has controller.<its>."""
    prefix = "controller."
    if parameter.startswith(prefix):
        return {prefix + k: v for k, v in COMPANIONS.get(parameter[len(prefix):], {}).items()} or None
    return COMPANIONS.get(parameter)


def _refusal(name, parameter, value, others=None):
    """The parameter the C core names when refusing `parameter` = `value`, or None."""
    from harness.binding import core
    if name == "PiezoStageClosedLoop":
        return _closed_loop_refusal(parameter, value, others)
    if name == "PiezoStage":
        make = core.Plant
    elif name == "AdaptiveCompoundController":
        make = core.Controller
    else:
        return _reference_refusal(parameter, value)
    try:
        make({**(others or {}), parameter: value})
    except core.CoreParameterError as exc:
        return exc.parameter
    return None


def _closed_loop_refusal(parameter, value, others=None):
    """The closed-loop FMU's parameter refused (its component's core, the name mapped back), or
    None; its own parameter y_d_lead through the FMU itself (it checks it, no core block)."""
    from harness.binding.closed_loop import CONTROLLER_PREFIX, component_parameters
    plant, controller, rest = component_parameters({**(others or {}), parameter: value})
    if parameter == "y_d_lead":
        return _fmu_refusal("PiezoStageClosedLoop", parameter, value)
    for comp, given in (("PiezoStage", plant), ("AdaptiveCompoundController", controller)):
        if parameter in given or parameter.removeprefix(CONTROLLER_PREFIX) in given:
            name = parameter.removeprefix(CONTROLLER_PREFIX)
            found = _refusal(comp, name, value, {k: v for k, v in given.items() if k != name})
            if found is None:
                return None
            return parameter if found == name else found
    return _reference_refusal(parameter, value)


@functools.lru_cache(maxsize=None)
def _package(model):
    package = FmuPackage(REPO / "build" / "fmus" / f"{model}.fmu")
    atexit.register(shutil.rmtree, package.unzipdir, True)
    return package


def _fmu_refusal(model, parameter, value):
    """The parameter the FMU's initialization names when it refuses `parameter` = `value` alone
    (fmi2Error and "NAME = VALUE is out of range" logged), or None when it accepts it."""
    fmu = _package(model).instantiate()
    try:
        fmu.setup(0.0, {parameter: value})
        try:
            fmu.slave.exitInitializationMode()
        except FMICallException as exc:
            assert exc.status == 3, exc                     # fmi2Error, not a crash or a Fatal
            found = re.match(r"fmi2ExitInitializationMode: (\S+) = \S+ is out of range", fmu.last_error())
            assert found, fmu.errors()
            return found.group(1)
        return None
    finally:
        fmu.free()


def _reference_refusal(parameter, value):
    from harness.binding import core
    lib, ffi = core.lib(), core.ffi
    p = ffi.new("piezo_reference_params *")
    lib.piezo_reference_default_params(p)
    m = re.fullmatch(r"(\w+)\[(\d+)\]", parameter)
    if m:
        getattr(p, m.group(1))[int(m.group(2)) - 1] = value
    else:
        setattr(p, parameter, value)
    diag = ffi.new("piezo_diag *")
    if lib.piezo_reference_init(ffi.new("piezo_reference *"), p, 0.0, diag) == core.PIEZO_OK:
        return None
    return ffi.string(diag.parameter).decode()


@pytest.mark.parametrize("name", NAMES)
def test_min_max_match_what_the_core_refuses(name):
    """Reference: the C core's validation (piezo_*_init). Every parameter with a min or max in
    the model description is refused just outside it, with its own name in the message; just
    inside, its own rule does not refuse it (another parameter's rule may: tf.a2 near -1 is
    refused as tf.a1, whose bound 1 + tf.a2 then shrinks; bounds that depend on another
    parameter are checked with that one at its limit, COMPANIONS). A range declared wider or
    narrower than the core's fails one of the two."""
    bounded = _bounded_parameters(name)
    assert len(bounded) >= {"PiezoStage": 20, "AdaptiveCompoundController": 25,
                            "ReferenceSignal": 10, "PiezoStageClosedLoop": 55}[name]
    not_refused = [(p, bound, out) for p, bound, out, _ in bounded if _refusal(name, p, out) != p]
    refused_inside = [(p, bound, inside) for p, bound, _, inside in bounded
                      if _refusal(name, p, inside, _companions(p)) == p]
    assert not not_refused, f"accepted outside the declared range: {not_refused}"
    assert not refused_inside, f"refused inside the declared range: {refused_inside}"


# ---------------------------------------------------------------------------------------
# (c) documentation, licence, icon

class _Tables(HTMLParser):
    """The cells of every <table> of a page, as text."""

    def __init__(self):
        super().__init__()
        self.tables, self._row, self._cell = [], None, None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._row.append(self._cell)
            self._cell = None
        elif tag == "tr":
            self.tables[-1].append(self._row)

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data


def _fmt(text):
    return text.replace("-", "\u2212")


@pytest.mark.parametrize("name", NAMES)
def test_documentation_variable_table_is_the_model_description(fmu_paths, name):
    with zipfile.ZipFile(fmu_paths[name]) as zf:
        page = zf.read("documentation/index.html").decode("utf-8")
        root = ET.fromstring(zf.read("modelDescription.xml"))
    parser = _Tables()
    parser.feed(page)
    (table,) = [t for t in parser.tables if t and t[0][:2] == ["Name", "Causality"]]
    header, rows = table[0], table[1:]
    assert header == ["Name", "Causality", "Variability", "Type", "Unit", "Default", "Range",
                      "Description"]
    variables = list(root.iter("ScalarVariable"))
    assert [r[0] for r in rows] == [v.get("name") for v in variables]
    display = {u.get("name"): d.get("name") for u in root.iter("Unit") for d in u.iter("DisplayUnit")}
    for row, var in zip(rows, variables):
        (typ,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean")]
        assert row[1] == var.get("causality") and row[3] == typ.tag, row
        assert row[4] == (typ.get("displayUnit") or display.get(typ.get("unit"), typ.get("unit") or ""))
        assert row[5] == _fmt(typ.get("start") or "")
        if typ.get("min") is not None:
            assert row[6].startswith("[" + _fmt(typ.get("min")) + ","), row
        if typ.get("max") is not None:
            assert row[6].endswith(", " + _fmt(typ.get("max")) + "]"), row
        assert row[7] == var.get("description")


@pytest.mark.parametrize("name", NAMES)
def test_documentation_explains_model_loop_paper_and_licence(fmu_paths, name):
    from harness.buildtime.ssp_file import SSP_CONNECTIONS
    with zipfile.ZipFile(fmu_paths[name]) as zf:
        page = zf.read("documentation/index.html").decode("utf-8")
        licence = zf.read("documentation/licenses/license.txt")
        png = zf.read("model.png")
    # the closed-loop FMU has the loop inside: how it goes into a system model instead
    loop = "Using it in a system model" if name == "PiezoStageClosedLoop" else "Connecting the closed loop"
    for heading in ("What it models", "Equations", "Variables", loop,
                    "Building from the sources", "Reference results", "Source", "Licence"):
        assert f">{heading}</h2>" in page, heading
    for _, out, _, inp in SSP_CONNECTIONS if name != "PiezoStageClosedLoop" else ():
        assert f"<code>{out}</code>" in page and f"<code>{inp}</code>" in page   # the SSP's wiring
    assert "https://www.hindawi.com/journals/mse/2022/2534439/" in page
    assert "BSD-3-Clause" in page and 'href="licenses/license.txt"' in page
    assert not [word for word in FORBIDDEN if word in page]
    assert licence == (REPO / "LICENSE").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png[16:24])
    assert (width, height) == (200, 200)
    assert png == (REPO / "packaging" / "icons" / f"{name}.png").read_bytes()


# ---------------------------------------------------------------------------------------
# (d) reproducibility

@pytest.mark.parametrize("name", NAMES)
def test_zip_entries_have_fixed_order_dates_and_permissions(fmu_paths, name):
    with zipfile.ZipFile(fmu_paths[name]) as zf:
        infos = zf.infolist()
    names = [i.filename for i in infos]
    assert names == sorted(names)
    date = dt.datetime.fromtimestamp(_commit_date(), dt.timezone.utc).timetuple()[:6]
    date = date[:5] + (date[5] // 2 * 2,)                    # zip stores even seconds
    assert {i.date_time for i in infos} == {date}
    for i in infos:
        mode = i.external_attr >> 16
        assert mode in (0o40755, 0o100644, 0o100755), (i.filename, oct(mode))
        assert not i.extra, i.filename


def test_a_second_build_gives_the_same_bytes(fmu_paths, tmp_path):
    """Reference: the FMUs of build/ (the session's build). A build tree configured and built
    from nothing in another folder, with the same sources, must zip the very same bytes."""
    cmake = shutil.which("cmake")
    assert cmake
    build = tmp_path / "build"
    subprocess.run([cmake, "-S", str(REPO), "-B", str(build), f"-DPIEZO_PYTHON={sys.executable}"],
                   check=True, stdout=subprocess.DEVNULL)
    subprocess.run([cmake, "--build", str(build), "-j", "2", "--target",
                    *[f"{n}_fmu" for n in NAMES]], check=True, stdout=subprocess.DEVNULL)
    for name in NAMES:
        again = (build / "fmus" / f"{name}.fmu").read_bytes()
        assert again == fmu_paths[name].read_bytes(), f"{name}.fmu differs between two builds"
