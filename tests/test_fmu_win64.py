"""win64 binaries: built by the one CMake build with MinGW-w64, checked as a Windows
importer would meet them.

(a) every FMU has binaries/linux64/<id>.so and binaries/win64/<id>.dll and nothing else in
    binaries/ (no import library, no debug file);
(b) the DLL exports exactly the FMI 2.0 API, imports only system DLLs (KERNEL32, msvcrt:
    libgcc is linked statically), carries no debug sections and no time stamp;
(c) a small C host (tests/wine_host/fmu_host.c), built natively and with MinGW, runs the
    FMU's own reference experiment on the linux64 .so and, under Debian's wine64, on the
    win64 .dll. Reference for (c): the linux64 run, which must equal the FMU's reference CSV
    (computed on the C core, not through the FMU) bit for bit; the win64 run must agree with
    it within 1e-12 in the outputs' units (um, V), the libm functions of the two C run-times
    being allowed to differ in their last bits.

(d) the same for the FMI 3.0 editions (binaries/x86_64-linux, binaries/x86_64-windows): the
    DLL exports exactly the functions of fmi3Functions.h (fmpy's copy), imports only system
    DLLs, and the same host compiled with -DFMU_HOST_FMI3 runs the FMI 3.0 edition's reference
    experiment on both binaries with the same tolerances.

The cross compiler and wine64 are optional (tests/conftest.py, need_win64): without them, or
with FMUs built without MinGW-w64, these tests skip and say what is missing. .ci/run installs
both (Debian: gcc-mingw-w64-x86-64, wine64) and sets PIEZO_REQUIRE_WIN64=1, which turns each
such skip into a failure.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

import fmpy

from conftest import FMU_NAMES, mingw_tool, need_windows_binaries, wine64
from fmu_experiments import SSP_TYPE, load_experiment, start_values, unzip

REPO = Path(__file__).resolve().parents[1]
HOST_SOURCE = REPO / "tests" / "wine_host" / "fmu_host.c"
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
NAMES = FMU_NAMES

FMI2_FUNCTIONS = {
    "fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
    "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal", "fmi2GetInteger",
    "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean",
    "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2EnterEventMode", "fmi2NewDiscreteStates",
    "fmi2EnterContinuousTimeMode", "fmi2CompletedIntegratorStep", "fmi2SetTime",
    "fmi2SetContinuousStates", "fmi2GetDerivatives", "fmi2GetEventIndicators",
    "fmi2GetContinuousStates", "fmi2GetNominalsOfContinuousStates",
    "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives", "fmi2DoStep",
    "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus",
}
#: DLLs every 64-bit Windows has
SYSTEM_DLLS = {"kernel32.dll", "msvcrt.dll"}


@pytest.fixture(scope="module")
def dlls(fmu_paths, tmp_path_factory):
    """{modelIdentifier: path of the win64 DLL extracted from the FMU}."""
    root = tmp_path_factory.mktemp("dlls")
    out = {}
    for name in NAMES:
        need_windows_binaries(fmu_paths[name])
        with zipfile.ZipFile(fmu_paths[name]) as zf:
            (root / f"{name}.dll").write_bytes(zf.read(f"binaries/win64/{name}.dll"))
        out[name] = root / f"{name}.dll"
    return out


def _objdump(path, *flags):
    return subprocess.run([mingw_tool("objdump"), *flags, str(path)],
                          capture_output=True, text=True, check=True).stdout


# ---------------------------------------------------------------------------------------
# (a) what binaries/ holds

@pytest.mark.parametrize("name", NAMES)
def test_binaries_are_one_so_and_one_dll(fmu_paths, name):
    need_windows_binaries(fmu_paths[name])
    with zipfile.ZipFile(fmu_paths[name]) as zf:
        files = sorted(n for n in zf.namelist() if n.startswith("binaries/") and not n.endswith("/"))
    assert files == [f"binaries/linux64/{name}.so", f"binaries/win64/{name}.dll"]


# ---------------------------------------------------------------------------------------
# (b) the DLL as Windows sees it

@pytest.mark.parametrize("name", NAMES)
def test_dll_exports_exactly_the_fmi2_api(dlls, name):
    text = _objdump(dlls[name], "-p")
    table = text.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
    exported = set(re.findall(r"\]\s+(\S+)", table))
    assert exported == FMI2_FUNCTIONS, (sorted(exported - FMI2_FUNCTIONS),
                                        sorted(FMI2_FUNCTIONS - exported))


@pytest.mark.parametrize("name", NAMES)
def test_dll_imports_only_system_dlls(dlls, name):
    text = _objdump(dlls[name], "-p")
    imported = {m.lower() for m in re.findall(r"DLL Name: (\S+)", text)}
    assert imported and imported <= SYSTEM_DLLS, imported
    assert "pe32+" in text.lower() and "x86-64" in _objdump(dlls[name], "-f").lower()
    # no time stamp in the header: the same commit gives the same bytes
    assert re.search(r"Time/Date\s+Thu Jan  1 00:00:00 1970", text), "PE time stamp set"


@pytest.mark.parametrize("name", NAMES)
def test_dll_has_no_debug_information(dlls, name):
    sections = _objdump(dlls[name], "-h")
    assert ".text" in sections
    assert ".debug" not in sections and ".stab" not in sections
    assert "no symbols" in _objdump(dlls[name], "-t")


# ---------------------------------------------------------------------------------------
# (c) the same experiment on linux64 and, under wine, on win64

def _build_hosts(root, *defines):
    """(native host, win64 host.exe), both built from tests/wine_host/fmu_host.c."""
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-I", str(FMI_HEADERS),
             *defines]
    native, exe = root / "fmu_host", root / "fmu_host.exe"
    cross = mingw_tool("gcc")
    cc = os.environ.get("CC") or shutil.which("cc")
    assert cc, "no C compiler (cc) for the native host"
    subprocess.run([cc, *flags, str(HOST_SOURCE), "-ldl", "-o", str(native)], check=True)
    subprocess.run([cross, *flags, "-static", str(HOST_SOURCE),
                    "-o", str(exe)], check=True)
    return native, exe


@pytest.fixture(scope="module")
def hosts(tmp_path_factory):
    return _build_hosts(tmp_path_factory.mktemp("hosts"))


@pytest.fixture(scope="module")
def hosts3(tmp_path_factory):
    return _build_hosts(tmp_path_factory.mktemp("hosts3"), "-DFMU_HOST_FMI3")


@pytest.fixture(scope="module")
def wine_env(tmp_path_factory):
    """(wine64, its environment with a prefix of its own); the wineserver is stopped at the end."""
    wine = wine64()
    env = dict(os.environ, WINEPREFIX=str(tmp_path_factory.mktemp("wineprefix")),
               WINEDEBUG="-all", WINEDLLOVERRIDES="mscoree,mshtml=")
    yield wine, env
    server = shutil.which("wineserver") or str(Path(wine).parent / "wineserver")
    subprocess.run([server, "-k"], env=env, check=False, timeout=60)
    subprocess.run([server, "-w"], env=env, check=False, timeout=60)


def _plan(experiment, token, identifier):
    """The host's plan for `experiment` (see fmu_host.c), for either FMI version: an FMI 3.0
    array touched by an element is set whole ("reals")."""
    v = experiment.variables
    lines = [f"identifier {identifier}", f"guid {token}", f"step {experiment.step!r}",
             f"steps {experiment.steps}"]
    for name, value in start_values(v, experiment.parameters).items():
        if isinstance(value, list):
            lines.append(f"reals {v[name].valueReference} {len(value)} "
                         + " ".join(repr(float(x)) for x in value))
            continue
        kind = {"Real": "real", "Integer": "integer", "Boolean": "boolean"}[SSP_TYPE[v[name].type]]
        lines.append(f"{kind} {v[name].valueReference} {float(value)!r}" if kind == "real"
                     else f"{kind} {v[name].valueReference} {int(value)}")
    inputs = [] if experiment.stimuli is None else list(experiment.stimuli.dtype.names[1:])
    lines += [f"input {v[n].valueReference}" for n in inputs]
    reals = [n for n in experiment.outputs if SSP_TYPE[v[n].type] == "Real"]
    bools = [n for n in experiment.outputs if v[n].type == "Boolean"]
    lines += [f"output {v[n].valueReference}" for n in reals]
    lines += [f"boutput {v[n].valueReference}" for n in bools]
    lines.append("data")
    for k in range(experiment.steps + 1 if inputs else 0):
        lines.append(" ".join(repr(float(experiment.stimuli[n][k])) for n in inputs))
    return "\n".join(lines) + "\n", reals + bools


def _run(command, env=None):
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, f"{command[0]} failed:\n{done.stderr[-3000:]}"
    return np.array([[float(x) for x in line.split()] for line in done.stdout.splitlines()])


@pytest.mark.parametrize("name", NAMES)
def test_win64_under_wine_matches_linux64(fmu_paths, hosts, wine_env, tmp_path, name):
    native, exe = hosts
    fmu = fmu_paths[name]
    need_windows_binaries(fmu)
    experiment = load_experiment(fmu)
    md = fmpy.read_model_description(str(fmu))
    plan, columns = _plan(experiment, md.guid, md.coSimulation.modelIdentifier)
    (tmp_path / "plan.txt").write_text(plan)
    unzip(fmu, tmp_path / "fmu")
    so = tmp_path / "fmu" / "binaries" / "linux64" / f"{name}.so"
    dll = tmp_path / "fmu" / "binaries" / "win64" / f"{name}.dll"

    linux = _run([str(native), str(tmp_path / "plan.txt"), str(so)])
    windows_path = "Z:" + str(dll).replace("/", "\\")
    wine, env = wine_env
    windows = _run([wine, str(exe), "Z:" + str(tmp_path / "plan.txt").replace("/", "\\"),
                    windows_path], env=env)

    n = experiment.steps + 1
    assert linux.shape == windows.shape == (n, 1 + len(columns))
    assert np.array_equal(linux[:, 0], experiment.reference["time"])
    for j, column in enumerate(columns, start=1):
        ref = experiment.reference[column]
        assert np.array_equal(linux[:, j], ref), f"linux64 {column} differs from the reference"
    moving = [c for c in columns if np.ptp(experiment.reference[c]) > 1.0]
    assert moving, "the experiment should move at least one output by more than 1 unit"
    worst = np.max(np.abs(windows[:, 1:] - linux[:, 1:]))
    print(f"\n{name}: win64 (wine) vs linux64, worst |difference| over {n} samples and "
          f"{len(columns)} outputs: {worst:.3g}")
    assert worst <= 1e-12, f"win64 and linux64 differ by {worst:.3g}"


# ---------------------------------------------------------------------------------------
# (d) the FMI 3.0 editions

FMI3_HEADER = FMI_HEADERS / "fmi3Functions.h"


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_binaries_and_dll_exports(fmu3_paths, tmp_path, name):
    need_windows_binaries(fmu3_paths[name], "x86_64-windows")
    with zipfile.ZipFile(fmu3_paths[name]) as zf:
        files = sorted(n for n in zf.namelist() if n.startswith("binaries/") and not n.endswith("/"))
        assert files == [f"binaries/x86_64-linux/{name}.so", f"binaries/x86_64-windows/{name}.dll"]
        dll = tmp_path / f"{name}.dll"
        dll.write_bytes(zf.read(f"binaries/x86_64-windows/{name}.dll"))
    api = set(re.findall(r"#define\s+(fmi3\w+)\s+fmi3FullName", FMI3_HEADER.read_text()))
    assert len(api) > 70
    text = _objdump(dll, "-p")
    table = text.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
    exported = set(re.findall(r"\]\s+(\S+)", table))
    assert exported == api, (sorted(exported - api), sorted(api - exported))
    imported = {m.lower() for m in re.findall(r"DLL Name: (\S+)", text)}
    assert imported and imported <= SYSTEM_DLLS, imported
    assert re.search(r"Time/Date\s+Thu Jan  1 00:00:00 1970", text), "PE time stamp set"
    assert ".debug" not in _objdump(dll, "-h")


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_win64_under_wine_matches_linux64(fmu3_paths, hosts3, wine_env, tmp_path, name):
    """Reference: the FMI 3.0 edition's own experiment and reference CSV (the same as the FMI
    2.0 edition's, tests/test_fmi3_editions.py), equal bit for bit on x86_64-linux."""
    native, exe = hosts3
    need_windows_binaries(fmu3_paths[name], "x86_64-windows")
    experiment = load_experiment(fmu3_paths[name])
    md3 = fmpy.read_model_description(str(fmu3_paths[name]))
    plan, columns = _plan(experiment, md3.instantiationToken, name)
    if name != "AdaptiveCompoundController" and experiment.parameters:
        assert "reals " in plan, "the experiment should set an array parameter"
    (tmp_path / "plan.txt").write_text(plan)
    unzip(fmu3_paths[name], tmp_path / "fmu")
    so = tmp_path / "fmu" / "binaries" / "x86_64-linux" / f"{name}.so"
    dll = tmp_path / "fmu" / "binaries" / "x86_64-windows" / f"{name}.dll"

    linux = _run([str(native), str(tmp_path / "plan.txt"), str(so)])
    wine, env = wine_env
    windows = _run([wine, str(exe), "Z:" + str(tmp_path / "plan.txt").replace("/", "\\"),
                    "Z:" + str(dll).replace("/", "\\")], env=env)
    n = experiment.steps + 1
    assert linux.shape == windows.shape == (n, 1 + len(columns))
    for j, column in enumerate(columns, start=1):
        assert np.array_equal(linux[:, j], experiment.reference[column]), column
    worst = np.max(np.abs(windows[:, 1:] - linux[:, 1:]))
    print(f"\n{name} FMI 3.0: x86_64-windows (wine) vs x86_64-linux, worst |difference| "
          f"over {n} samples: {worst:.3g}")
    assert worst <= 1e-12, f"win64 and linux64 differ by {worst:.3g}"


# ---------------------------------------------------------------------------------------
# (e) without MinGW-w64: visible skips, and failures where CI requires win64

HIDDEN = ("x86_64-w64-mingw32-", "wine")


def path_without_mingw_and_wine(root):
    """$PATH with every folder that holds a MinGW-w64 or wine program replaced by a folder of
    links to everything else in it: the tools are hidden, not uninstalled."""
    out = []
    for i, folder in enumerate(os.environ.get("PATH", "").split(os.pathsep)):
        entries = sorted(os.listdir(folder)) if os.path.isdir(folder) else []
        if not any(e.startswith(HIDDEN) for e in entries):
            out.append(folder)
            continue
        farm = root / f"path{i}"
        farm.mkdir()
        for e in entries:
            if not e.startswith(HIDDEN):
                (farm / e).symlink_to(os.path.join(folder, e))
        out.append(str(farm))
    return os.pathsep.join(out)


def test_without_mingw_the_tests_skip_and_say_why_unless_ci_requires_win64(tmp_path, fmu_paths):
    """The README's test command on a machine without MinGW-w64: this file's tests that need
    it are skipped, each with the missing tool and how to install it (pytest -rs shows it);
    with PIEZO_REQUIRE_WIN64=1, as .ci/run sets, they fail with the same reason instead.
    The first reason depends on the build: FMUs built with MinGW-w64 (then hidden here) lack
    its objdump, FMUs built without it lack binaries/win64.
    Reference: shutil.which finds no x86_64-w64-mingw32-gcc on the hidden PATH."""
    with zipfile.ZipFile(fmu_paths["PiezoStage"]) as z:
        built_with_mingw = any(n.startswith("binaries/win64/") for n in z.namelist())
    how = ("install MinGW-w64 and wine64 (Debian: gcc-mingw-w64-x86-64 wine64, as .ci/run does) "
           "and rebuild")
    first = (f"x86_64-w64-mingw32-objdump not found on PATH: {how}" if built_with_mingw else
             f"PiezoStage.fmu has no binaries/win64/ (MinGW-w64 was not found when it was built): {how}")
    hidden = path_without_mingw_and_wine(tmp_path)
    assert shutil.which("x86_64-w64-mingw32-gcc", path=hidden) is None
    assert shutil.which("cmake", path=hidden) and shutil.which("cc", path=hidden)
    command = [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
               str(Path(__file__)), "-k", "(dll or wine or fmi3_binaries) and not without"]

    def run(require):
        env = dict(os.environ, PATH=hidden, PIEZO_REQUIRE_WIN64=require)
        return subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True,
                              timeout=600)

    done = run("")
    assert done.returncode == 0, done.stdout[-3000:]
    assert re.search(r"\b(\d+) skipped", done.stdout), done.stdout[-3000:]
    assert first in done.stdout, done.stdout[-3000:]
    assert "x86_64-w64-mingw32-gcc not found on PATH" in done.stdout
    assert " failed" not in done.stdout and " error" not in done.stdout

    required = run("1")
    assert required.returncode == 1, required.stdout[-3000:]
    assert "skipped" not in required.stdout.splitlines()[-1], required.stdout[-3000:]
    assert f"{first} (PIEZO_REQUIRE_WIN64=1 makes this a failure, not a skip)" in required.stdout, \
        required.stdout[-3000:]


def test_an_fmu_without_windows_binaries_is_a_visible_skip(tmp_path, fmu_paths):
    """An FMU built without MinGW-w64 (here: a copy with binaries/win64 left out) skips the
    tests that need its DLL, naming the FMU and the folder; with PIEZO_REQUIRE_WIN64=1 it
    fails them."""
    linux_only = tmp_path / "PiezoStage.fmu"
    with zipfile.ZipFile(fmu_paths["PiezoStage"]) as src, zipfile.ZipFile(linux_only, "w") as dst:
        for info in src.infolist():
            if not info.filename.startswith("binaries/win64"):
                dst.writestr(info, src.read(info))
    test = tmp_path / "test_probe.py"
    test.write_text("from conftest import need_windows_binaries\n"
                    f"def test_probe():\n    need_windows_binaries({str(linux_only)!r})\n")
    for require, code, outcome in (("", 0, "skipped"), ("1", 1, "failed")):
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p",
                               "no:cacheprovider", "--rootdir", str(REPO / "tests"), "-c",
                               os.devnull, "--confcutdir", str(REPO / "tests"), str(test)],
                              cwd=REPO / "tests", capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, PIEZO_REQUIRE_WIN64=require,
                                       PYTHONPATH=f"{REPO / 'tests'}{os.pathsep}{REPO}"))
        assert done.returncode == code, done.stdout[-3000:]
        assert f"1 {outcome}" in done.stdout, done.stdout[-3000:]
        assert ("PiezoStage.fmu has no binaries/win64/ (MinGW-w64 was not found when it was "
                "built): install MinGW-w64") in done.stdout, done.stdout[-3000:]
