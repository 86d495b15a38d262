"""Source-code FMUs: each .fmu carries, flat in sources/, the C files its binary is built from.

(a) sources/ holds the <SourceFiles> of the model description and every header they
    include (transitively), byte-identical to the repository's files, nothing else but
    project headers and buildDescription.xml, and no FMI header (fmi2*.h is the importer's);
(b) a binary built from the FMU's sources only (cc, C99, -Wall -Wextra -Wpedantic -Werror,
    the FMI headers of fmpy) and re-zipped as a new FMU
(c) gives exactly the outputs of the shipped binary: PiezoStage open loop through
    fmpy.simulate_fmu, the two FMUs in a closed loop with a mismatched plant (RLS
    adapting, sensor noise on), and PiezoStageClosedLoop on the mismatch benchmark through
    fmpy.simulate_fmu at 10 ms steps.
"""
import os
import pathlib
import re
import shutil
import subprocess
import zipfile

import fmpy
import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

from conftest import FMU_NAMES, REPO
from fmu_experiments import zip_fmu

FMI_HEADERS_DIR = pathlib.Path(fmpy.__file__).parent / "c-code"
FMI_HEADERS = {"fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"}
NAMES = FMU_NAMES
INCLUDE = re.compile(r'^[ \t]*#[ \t]*include[ \t]*"([^"]+)"', re.MULTILINE)
H = 0.0005


def _source_files(fmu):
    """<SourceFiles> of the CoSimulation element, as fmpy reads them."""
    md = read_model_description(str(fmu))
    (config,) = md.buildConfigurations
    assert config.modelIdentifier == md.coSimulation.modelIdentifier
    (file_set,) = config.sourceFileSets
    return list(file_set.sourceFiles)


def _zipped_sources(fmu):
    with zipfile.ZipFile(fmu) as zf:
        names = zf.namelist()
        sources = {n[len("sources/"):]: zf.read(n) for n in names
                   if n.startswith("sources/") and not n.endswith("/")}
    return names, sources


def _repo_file(model, name):
    for folder in (REPO / "fmu_src" / model, REPO / "fmu_src" / "fmi", REPO / "fmu_src" / "core"):
        if (folder / name).is_file():
            return folder / name
    raise AssertionError(f"{name} is in the FMU but not in fmu_src/")


# ---------------------------------------------------------------------------------------
# (a) what sources/ holds

@pytest.mark.parametrize("name", NAMES)
def test_sources_are_the_source_files_and_the_headers_they_include(fmu_paths, name):
    listed = _source_files(fmu_paths[name])
    names, sources = _zipped_sources(fmu_paths[name])
    # the FMI 2.0.4 build description, checked in test_fmu_build_description.py
    assert sources.pop("buildDescription.xml").startswith(b"<?xml")

    assert listed and len(set(listed)) == len(listed)
    assert all(f.endswith(".c") and "/" not in f for f in listed), listed
    assert {"fmi2_glue.c", "model.c"} <= set(listed)
    assert set(listed) <= set(sources), "a listed source file is missing from sources/"

    # headers reached from the listed .c files through #include "...", resolved in sources/
    headers, todo = set(), list(listed)
    while todo:
        text = sources[todo.pop()].decode("utf-8")
        for include in INCLUDE.findall(text):
            if include in FMI_HEADERS:
                continue
            assert include in sources, f'#include "{include}" is not in sources/'
            if include not in headers:
                headers.add(include)
                todo.append(include)
    assert {"fmu_model.h", "config.h", "piezo_status.h"} <= headers
    assert all(f.endswith(".h") for f in set(sources) - set(listed)), sorted(sources)

    assert not [n for n in names if pathlib.PurePosixPath(n).name.startswith("fmi2")
                and n.endswith(".h")], "FMI headers belong to the importer"
    assert "piezo_bench.c" not in sources
    for file, data in sources.items():      # the very code of the repository
        assert data == _repo_file(name, file).read_bytes(), file


def test_the_fmi_headers_are_not_in_the_repository():
    assert not [p for p in (REPO / "fmu_src").rglob("*.h") if p.name in FMI_HEADERS]


# ---------------------------------------------------------------------------------------
# (b) a binary built from the sources only, in a new FMU

@pytest.fixture(scope="module")
def source_built(fmu_paths, tmp_path_factory):
    """{modelIdentifier: path of a new .fmu whose binary was compiled from its sources/}."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    assert cc, "a C compiler (cc) is needed"
    assert (FMI_HEADERS_DIR / "fmi2Functions.h").is_file()
    root = tmp_path_factory.mktemp("source_fmus")
    jobs = {}
    for name in NAMES:
        unzipdir = root / name
        with zipfile.ZipFile(fmu_paths[name]) as zf:   # only the XML and sources/, no binary
            zf.extractall(unzipdir, [n for n in zf.namelist()
                                     if n == "modelDescription.xml" or n.startswith("sources/")])
        assert not (unzipdir / "binaries").exists()
        out = unzipdir / "binaries" / fmpy.platform / f"{name}.so"
        out.parent.mkdir(parents=True)
        command = [cc, "-shared", "-fPIC", "-std=c99", "-O2", "-ffp-contract=off",
                   "-Wall", "-Wextra", "-Wpedantic", "-Werror",
                   "-I", "sources", "-I", str(FMI_HEADERS_DIR),
                   *[f"sources/{f}" for f in _source_files(fmu_paths[name])],
                   "-Wl,--no-undefined", "-lm", "-o", str(out)]
        jobs[name] = subprocess.Popen(command, cwd=unzipdir, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True)
    fmus = {}
    for name, job in jobs.items():
        log = job.communicate()[0]
        assert job.returncode == 0, f"{name} does not build from its sources:\n{log}"
        fmus[name] = zip_fmu(root / name, root / f"{name}.fmu")
    return fmus


@pytest.mark.parametrize("name", NAMES)
def test_source_built_fmu_is_valid(source_built, fmu_paths, name):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(source_built[name])) == []
    with zipfile.ZipFile(source_built[name]) as zf, zipfile.ZipFile(fmu_paths[name]) as shipped:
        built = zf.read(f"binaries/{fmpy.platform}/{name}.so")
        assert built != shipped.read(f"binaries/{fmpy.platform}/{name}.so")   # really rebuilt


# ---------------------------------------------------------------------------------------
# (c) same outputs as the shipped binary

def test_piezostage_from_sources_matches_shipped_binary(fmu_paths, source_built):
    t = np.arange(0, 1001) * H                       # 0.5 s
    signal = np.zeros(t.size, dtype=[("time", np.float64), ("v", np.float64)])
    signal["time"] = t
    signal["v"] = 10 * np.sin(2 * np.pi * 5 * t) + 10
    outputs = ["y", "y_meas", "u", "x"]
    start = {"sensor.noise_rms": 0.002, "sensor.resolution": 0.001, "sensor.seed": 7}

    def run(fmu):
        return fmpy.simulate_fmu(str(fmu), start_time=0, stop_time=0.5, output_interval=H,
                                 input=signal, output=outputs, start_values=start)

    shipped, built = run(fmu_paths["PiezoStage"]), run(source_built["PiezoStage"])
    assert shipped.size == built.size > 1000
    assert 7.0 < shipped["y"].max() < 10.0 and shipped["y"].min() < 0.5
    assert not np.array_equal(shipped["y"], shipped["y_meas"])      # noise and quantization on
    for field in ["time"] + outputs:
        assert np.array_equal(shipped[field], built[field]), field


class _Slave:
    """One initialized FMU2Slave on its own extraction of `fmu`."""

    def __init__(self, fmu, params):
        self.unzipdir = fmpy.extract(str(fmu))
        md = read_model_description(self.unzipdir)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        types = {v.name: v.type for v in md.modelVariables}
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName=md.modelName)
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)
        for key, value in params.items():
            if types[key] == "Real":
                self.slave.setReal([self.vr[key]], [value])
            else:
                self.slave.setInteger([self.vr[key]], [value])
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def get(self, names):
        return self.slave.getReal([self.vr[n] for n in names])

    def set(self, values):
        self.slave.setReal([self.vr[n] for n in values], list(values.values()))

    def close(self):
        self.slave.terminate()
        self.slave.freeInstance()
        shutil.rmtree(self.unzipdir, ignore_errors=True)


PLANT_OUT = ["y", "y_meas", "u", "x"]
CTRL_OUT = ["v", "q", "est.a1", "est.a2", "est.b1", "est.b2", "pred_error"]


def _closed_loop(plant_fmu, ctrl_fmu, n=1000):
    """Gauss-Seidel loop, y_ref = y_d(k+1); the plant does not match the controller's model."""
    plant = _Slave(plant_fmu, {"tf.a1": -1.36, "tf.b1": 0.65, "sensor.noise_rms": 0.002,
                               "sensor.resolution": 0.001, "sensor.seed": 3})
    ctrl = _Slave(ctrl_fmu, {})
    rows = np.empty((n, len(PLANT_OUT) + len(CTRL_OUT)))
    try:
        for k in range(n):
            t = k * H
            y_meas = plant.get(["y_meas"])[0]
            ctrl.set({"y_ref": 5 + 5 * np.sin(2 * np.pi * 5 * (k + 1) * H), "y_meas": y_meas})
            c = ctrl.get(CTRL_OUT)
            plant.set({"v": c[0]})
            rows[k] = plant.get(PLANT_OUT) + c
            plant.slave.doStep(t, H)
            ctrl.slave.doStep(t, H)
    finally:
        plant.close()
        ctrl.close()
    return rows


def test_closed_loop_from_sources_matches_shipped_binaries(fmu_paths, source_built):
    shipped = _closed_loop(fmu_paths["PiezoStage"], fmu_paths["AdaptiveCompoundController"])
    built = _closed_loop(source_built["PiezoStage"], source_built["AdaptiveCompoundController"])
    y, v, b1 = shipped[:, 0], shipped[:, 4], shipped[:, 4 + CTRL_OUT.index("est.b1")]
    assert np.ptp(v) > 5 and np.ptp(y) > 5                 # a real trajectory
    assert np.ptp(b1) > 1e-3                                # the RLS adapted
    assert np.max(np.abs(y[200:] - 5 - 5 * np.sin(2 * np.pi * 5 * np.arange(200, 1000) * H))) < 0.1
    assert np.array_equal(shipped, built)


def test_closed_loop_fmu_from_sources_matches_shipped_binary(fmu_paths, source_built):
    """The mismatch benchmark (harness.binding.closed_loop's names) through fmpy.simulate_fmu, 1 s at
    10 ms steps: the RLS adapting, the sensor noisy, the supervision on."""
    from harness.binding.closed_loop import closed_loop_parameters
    from harness.loop import reference_parameters
    from harness.scenarios import get_scenario
    sc = get_scenario("mismatch_1_5_10hz")
    start = closed_loop_parameters(plant=sc.plant, reference=reference_parameters(sc))
    outputs = ["y", "y_meas", "v", "error", "est.b1"]

    def run(fmu):
        return fmpy.simulate_fmu(str(fmu), start_time=0, stop_time=1.0, output_interval=0.01,
                                 output=outputs, start_values=start)

    shipped, built = run(fmu_paths["PiezoStageClosedLoop"]), run(source_built["PiezoStageClosedLoop"])
    assert shipped.size == built.size == 101
    # tracking from 0.2 s on: 11.6 nm at worst (the robust law's start-up at 0.2 s, measured)
    assert np.ptp(shipped["y"]) > 20 and np.max(np.abs(shipped["error"][20:])) < 0.015
    for field in ["time"] + outputs:
        assert np.array_equal(shipped[field], built[field]), field
