"""Source-code FMUs: sources/buildDescription.xml (FMI 2.0.4, in FMI 3.0's format) says how
to build each FMU, and following it with nothing but the FMU and the FMI headers gives a
binary with identical outputs.

(a) the file validates against FMI 3.0's schema (fmpy's copy), names the model identifier,
    lists exactly the <SourceFiles> of the model description, the include folder, the
    optional MinGW definition and the math library;
(b) for each of the three FMUs, only modelDescription.xml and sources/ are extracted, the
    listed files are compiled with the listed include folders and (non-optional) definitions
    plus fmpy's FMI 2.0 headers (C99, -Wall -Wextra -Wpedantic -Werror) into a fresh FMU,
    which re-runs the FMU's reference experiment with fmpy. Reference: the shipped FMU's
    reference CSV (computed on the C core); the rebuilt binary must equal it bit for bit.
"""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import subprocess
import zipfile
from xml.etree import ElementTree as ET

import fmpy
from fmpy.model_description import read_build_description
import numpy as np
import pytest

from fmu_experiments import load_experiment, simulate_experiment, zip_fmu
from conftest import FMU_NAMES

FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"
NAMES = FMU_NAMES


def _unzip_sources(fmu, folder):
    """modelDescription.xml and sources/ only: no binary, no reference files."""
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder, [n for n in zf.namelist()
                               if n == "modelDescription.xml" or n.startswith("sources/")])
    return folder


@pytest.mark.parametrize("name", NAMES)
def test_build_description_lists_sources_includes_and_defines(fmu_paths, name, tmp_path):
    folder = _unzip_sources(fmu_paths[name], tmp_path)
    xml = folder / "sources" / "buildDescription.xml"
    (config,) = read_build_description(str(xml), validate=True)    # FMI 3.0 schema
    assert config.modelIdentifier == name
    (file_set,) = config.sourceFileSets
    assert file_set.language == "C99"
    md = ET.parse(folder / "modelDescription.xml").getroot()
    assert sorted(file_set.sourceFiles) == sorted(f.get("name") for f in md.iter("File"))
    assert file_set.includeDirectories == ["."]
    assert [(d.name, d.value, d.optional) for d in file_set.preprocessorDefinitions] == \
        [("__USE_MINGW_ANSI_STDIO", "1", True)]
    libraries = [(lib.get("name"), lib.get("external"))
                 for lib in ET.parse(xml).getroot().iter("Library")]
    assert libraries == [("m", "true")]
    assert all((folder / "sources" / f).is_file() for f in file_set.sourceFiles)


@pytest.fixture(scope="module")
def rebuilt(fmu_paths, tmp_path_factory):
    """{id: FMU rebuilt from its sources/ and buildDescription.xml alone}."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    assert cc, "a C compiler (cc) is needed"
    root = tmp_path_factory.mktemp("rebuilt")
    out = {}
    for name in NAMES:
        folder = _unzip_sources(fmu_paths[name], root / name)
        (config,) = read_build_description(str(folder / "sources" / "buildDescription.xml"))
        (file_set,) = config.sourceFileSets
        sources = folder / "sources"
        binary = folder / "binaries" / fmpy.platform / f"{name}.so"
        binary.parent.mkdir(parents=True)
        command = [cc, "-shared", "-fPIC", "-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra",
                   "-Wpedantic", "-Werror", "-I", str(FMI_HEADERS)]
        command += [f"-I{sources / d}" for d in file_set.includeDirectories]
        command += [f"-D{d.name}" + (f"={d.value}" if d.value else "")
                    for d in file_set.preprocessorDefinitions if not d.optional]
        command += [str(sources / f) for f in file_set.sourceFiles]
        command += ["-Wl,--no-undefined", "-lm", "-o", str(binary)]
        done = subprocess.run(command, capture_output=True, text=True)
        assert done.returncode == 0, f"{name} does not build from its sources:\n{done.stderr}"
        out[name] = zip_fmu(folder, root / f"{name}.fmu")
    return out


@pytest.mark.parametrize("name", NAMES)
def test_rebuilt_fmu_reproduces_the_reference_results(fmu_paths, rebuilt, name):
    with zipfile.ZipFile(rebuilt[name]) as zf, zipfile.ZipFile(fmu_paths[name]) as shipped:
        built = zf.read(f"binaries/{fmpy.platform}/{name}.so")
        assert built != shipped.read(f"binaries/{fmpy.platform}/{name}.so")   # really rebuilt
    exp = load_experiment(fmu_paths[name])
    result = simulate_experiment(rebuilt[name], exp)
    assert np.array_equal(result["time"], exp.reference["time"])
    for output in exp.outputs:
        assert np.array_equal(np.asarray(result[output], dtype=float), exp.reference[output]), output
