"""The harness as a package: ``pip install .`` (not editable) into a fresh virtual environment
builds the core library and the FMUs through CMake (scikit-build-core) and installs them
inside the package, so that ``python -m harness`` works from any folder.

Reference: the session's build in build/ (same sources): the installed FMUs must be the same
bytes (the build is reproducible across build environments), and the run from another folder
must find the FMUs, the core library and the core headers inside the installed package.
PIEZO_FMU_DIR still overrides where the FMUs are taken from. The installed package names the
commit it was built from (git is the reference), --fmu-dir's help its own FMU folder, and a
run warns when its FMUs have no Windows binaries (a build without MinGW-w64), since pip shows
nothing of CMake's output.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
import subprocess
import sys
import time
import zipfile

from conftest import FMU_NAMES, REPO

NAMES = FMU_NAMES


def _env():
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PIEZO_") and k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def _run(command, cwd, env, ok=True):
    done = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=1800)
    if ok:
        assert done.returncode == 0, (f"{' '.join(map(str, command))} failed:\n"
                                      f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    return done


def test_pip_install_then_run_a_scenario_from_another_folder(fmu_paths, tmp_path):
    env = _env()
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], tmp_path, env)
    python = venv / "bin" / "python"
    start = time.monotonic()
    _run([python, "-m", "pip", "install", "--quiet", REPO], tmp_path, env)
    print(f"\npip install . into a fresh venv: {time.monotonic() - start:.0f} s")

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    where = _run([python, "-c",
                  "import harness, harness.fmu as c, harness.binding.core as k; "
                  "print(harness.__file__); print(c.default_fmu_dir()); print(k.library_path()); "
                  "print(k.CORE_DIR)"], elsewhere, env).stdout.split()
    package = Path(where[0]).parent
    assert venv in package.parents, where
    data = package / "_data"
    assert [Path(p) for p in where[1:]] == [data / "fmus", data / "lib" / "libpiezo_core.so",
                                            data / "include"]
    for name in NAMES:
        installed = data / "fmus" / f"{name}.fmu"
        assert installed.read_bytes() == fmu_paths[name].read_bytes(), name
    with zipfile.ZipFile(data / "fmus" / "PiezoStage.fmu") as zf:
        has_win64 = "binaries/win64/PiezoStage.dll" in zf.namelist()

    # provenance: the commit it was built from (git is the reference), in the report's words
    # and in the FMUs (the same bytes as the build's, whose generationTool names it)
    head = _run(["git", "-C", REPO, "rev-parse", "HEAD"], REPO, env).stdout.strip()
    dirty = _run(["git", "-C", REPO, "status", "--porcelain", "--untracked-files=no"], REPO,
                 env).stdout.strip()
    source = head + (" with uncommitted changes" if dirty else "")
    commit = _run([python, "-c", "from harness.report.provenance import commit_id; "
                   "print(commit_id())"], elsewhere, env).stdout.strip()
    assert commit == f"{source} (recorded at build time, installed package)"
    # --fmu-dir's help names the installed FMUs as the default
    help_text = "".join(_run([python, "-m", "harness", "run", "--help"], elsewhere,
                             env).stdout.split())
    assert f"(default:{data / 'fmus'},theFMUsinstalledwiththepackage;" in help_text
    assert (data / "fmus" / "PiezoStageClosedLoop.ssp").is_file()
    for name in NAMES:                          # the FMI 3.0 editions beside them
        installed = data / "fmus" / "fmi3" / f"{name}.fmu"
        assert installed.read_bytes() == (fmu_paths[name].parent / "fmi3" / f"{name}.fmu").read_bytes()

    assert (data / "lib" / "libpiezo_runner.so").is_file() and (data / "include" / "piezo_runner.h").is_file()
    e_rms = {}
    for backend, fmi in (("fmpy", "2"), ("native", "2"), ("core", "2"), ("fmpy", "3"), ("closed-loop-fmu", "2")):
        label = f"{backend}{fmi}"
        done = _run([python, "-m", "harness", "run", "mismatch_5hz", "--no-plots", "--out",
                     f"out_{label}", "--backend", backend, "--fmi", fmi], elsewhere, env)
        out = done.stdout
        assert "mismatch_5hz" in out and "e_rms" in out, out
        # a build without MinGW-w64 is announced (pip hides CMake's output), one with it is not
        warned = "have no Windows binaries" in done.stderr and "pip install ." in done.stderr
        assert warned == (backend != "core" and not has_win64), done.stderr
        assert any((elsewhere / f"out_{label}").iterdir())
        with open(elsewhere / f"out_{label}" / "mismatch_5hz.csv") as fh:
            e_rms[label] = next(csv.DictReader(fh))["e_rms_um"]
    # one loop, four masters (the closed-loop FMU one of them), two FMI versions
    assert (e_rms["fmpy2"] == e_rms["native2"] == e_rms["core2"] == e_rms["fmpy3"]
            == e_rms["closed-loop-fmu2"]), e_rms

    empty = tmp_path / "no_fmus"
    empty.mkdir()
    done = _run([python, "-m", "harness", "run", "mismatch_5hz", "--no-plots"], elsewhere,
                dict(env, PIEZO_FMU_DIR=str(empty)), ok=False)
    assert done.returncode == 2
    assert f"FMU not found: {empty}" in done.stderr, done.stderr
    assert "it holds no .fmu file at all" in done.stderr
    assert "reinstall" not in done.stderr and "pip install" not in done.stderr
