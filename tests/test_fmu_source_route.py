"""The source route, kept proven by builders that are not ours: a user on a platform we ship
no binary for (macOS, another CPU) builds the FMU from its own sources/ and
buildDescription.xml (FMI 3.0) or <SourceFiles> (FMI 2.0).

(a) fmpy's ``fmpy compile FMU`` (the README's one command; fmpy.build.build_platform_binary
    through CMake) adds this machine's binary to a copy of each FMU of both editions from
    which every binary was removed;
(b) fmu-manipulation-toolbox's ``fmutool -compile-sources`` (its own reader of the build
    description and its own FMI headers) does the same.
Each rebuilt FMU then re-runs its own reference experiment (FMI-LS-REF) with fmpy.
Reference: the FMU's reference CSV (computed on the C core, not through the FMU); the
rebuilt binary must equal it bit for bit.
"""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import subprocess
import sys
import zipfile

import fmpy
import numpy as np
import pytest

from conftest import FMU_NAMES
from fmu_experiments import load_experiment, simulate_experiment

FMI_VERSIONS = (2, 3)


def _without_binaries(fmu, out):
    """A copy of `fmu` with binaries/ left out: what a user on another platform has."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            if not info.filename.startswith("binaries/"):
                dst.writestr(info, src.read(info))
    return out


def _builder_command(builder, fmu, out):
    if builder == "fmpy":
        shutil.copy(fmu, out)
        return [sys.executable, "-m", "fmpy.cli", "compile", str(out)]
    fmutool = shutil.which("fmutool")
    assert fmutool, "fmutool (fmu-manipulation-toolbox, in the test extra) is not installed"
    return [fmutool, "-input", str(fmu), "-compile-sources", "-output", str(out)]


@pytest.mark.parametrize("builder", ["fmpy", "fmutool"])
@pytest.mark.parametrize("version", FMI_VERSIONS)
@pytest.mark.parametrize("name", FMU_NAMES)
def test_an_independent_builder_rebuilds_the_fmu_from_its_sources(fmu_paths, fmu3_paths,
                                                                  tmp_path, builder, version, name):
    assert shutil.which("cmake") and (os.environ.get("CC") or shutil.which("cc"))
    shipped = (fmu_paths if version == 2 else fmu3_paths)[name]
    bare = _without_binaries(shipped, tmp_path / f"bare_{name}.fmu")
    out = tmp_path / f"{name}.fmu"
    done = subprocess.run(_builder_command(builder, bare, out), cwd=tmp_path,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"{builder} failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    folder = fmpy.platform if version == 2 else fmpy.platform_tuple
    with zipfile.ZipFile(out) as zf:
        binaries = [n for n in zf.namelist() if n.startswith("binaries/") and not n.endswith("/")]
    assert binaries == [f"binaries/{folder}/{name}.so"], binaries

    exp = load_experiment(shipped)
    result = simulate_experiment(out, exp)
    assert np.array_equal(result["time"], exp.reference["time"])
    moving = [o for o in exp.outputs if np.ptp(exp.reference[o]) > 1.0]
    assert moving
    for output in exp.outputs:
        assert np.array_equal(np.asarray(result[output], dtype=float), exp.reference[output]), output
