"""Both FMUs under a second importer: tests/c_master/fmu_master.c, a plain C host
(dlopen/dlsym, its own callbacks, no fmpy), run under valgrind's memcheck (any error, or any
byte left at exit, fails the run: conftest.memcheck_prefix). valgrind is required when the environment variable
CI is set (.ci/run installs it); elsewhere, without valgrind, the host runs bare and the
test says so (printed note and a warning in pytest's summary), it does not skip.

Reference: fmpy running the same fixed-step loop on the same FMU. The two importers must
produce bitwise identical outputs at every one of the N_SAMPLES samples, and the C host's checks of the FMI contract (every fmi2
symbol exported, wrong GUID and NULL component refused, illegal call sequences, NaN input,
bad step, state save/restore and serialization into a fresh instance, corrupted blob) must
all pass.
"""
import math
import os
import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import memcheck_clean, memcheck_prefix

HERE = Path(__file__).resolve().parent
MASTER_SOURCE = HERE / "c_master" / "fmu_master.c"
N_SAMPLES = 1000


def n_checks_in_master():
    """The number of check(...) calls in fmu_master.c (the definition excluded). They all
    sit in main's straight-line path (no loop, no branch around them), so a successful run
    passes each exactly once."""
    text = re.sub(r"/\*.*?\*/", "", MASTER_SOURCE.read_text(), flags=re.S)
    return len(re.findall(r"^\s*check\(", text, flags=re.M))


def run_master(master, unzipdir, md, output, inputs, off=()):
    """Run the C host on the unzipped FMU (under memcheck, see conftest.memcheck_prefix): it must
    exit 0 with every one of its checks passed (as many as it has check(...) calls) and print
    the output of each of the N_SAMPLES samples; returns them (an array)."""
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    h = float(md.defaultExperiment.stepSize)
    cmd = [str(master)] + [a for name in off for a in ("--off", str(vrs[name]))] + \
        [str(unzipdir), md.coSimulation.modelIdentifier, md.guid, repr(h), str(N_SAMPLES), str(vrs[output])] + \
        [str(vrs[name]) for name in inputs]
    prefix = memcheck_prefix("the C host (tests/c_master)")
    proc = subprocess.run(prefix + cmd, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "LC_ALL": "C"})
    report = proc.stdout[-5000:] + proc.stderr[-5000:]
    assert proc.returncode == 0, report
    if prefix:
        assert memcheck_clean(proc.stderr), report
    n_checks = n_checks_in_master()
    assert proc.stdout.strip().splitlines()[-1] == f"{n_checks} passed, 0 failed", report
    assert "FAIL" not in proc.stdout, report
    assert sum(line.startswith("ok ") for line in proc.stdout.splitlines()) == n_checks, report
    y = [line.split() for line in proc.stdout.splitlines() if line.startswith("y ")]
    assert [int(k) for _, k, _ in y] == list(range(N_SAMPLES)), report
    return np.array([float(v) for _, _, v in y])


def fmi_headers_dir():
    import fmpy
    return Path(fmpy.__file__).resolve().parent / "c-code"


@pytest.fixture(scope="module")
def master(tmp_path_factory):
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "a C compiler is needed (the FMUs are built with one)"
    exe = tmp_path_factory.mktemp("c_master") / "fmu_master"
    subprocess.run([cc, "-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-Wpedantic", "-Werror",
                    "-I", str(fmi_headers_dir()), str(HERE / "c_master" / "fmu_master.c"),
                    "-o", str(exe), "-ldl", "-lm"], check=True)
    return exe


def drive(k, h):
    return 10.0 * math.sin(2.0 * math.pi * 5.0 * k * h) + 10.0


def fmpy_run(fmu_path, unzipdir, md, out_name, in_names, n, off=()):
    """The same loop as run_samples() in fmu_master.c, on fmpy's FMU2Slave (the Boolean
    parameters ``off`` set to false, as the master's --off does)."""
    from fmpy.fmi2 import FMU2Slave
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    h = float(md.defaultExperiment.stepSize)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="fmpy")
    fmu.instantiate()
    for name in off:
        fmu.setBoolean([vrs[name]], [False])
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    y = np.empty(n)
    in_vrs = [vrs[name] for name in in_names]
    for k in range(n):
        u = drive(k, h)
        fmu.setReal(in_vrs, [u] * len(in_vrs))
        y[k] = fmu.getReal([vrs[out_name]])[0]
        fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
    fmu.terminate()
    fmu.freeInstance()
    return y


# the controller driven by the same sine on both inputs is no closed loop: its supervision
# (which would stop it as a measurement that does not answer v) is switched off
@pytest.mark.parametrize("model, output, inputs, off", [
    ("PiezoStage", "y", ["v"], []),
    ("AdaptiveCompoundController", "v", ["y_ref", "y_meas"], ["sup.enabled"]),
])
def test_second_importer_agrees_with_fmpy_and_the_fmi_contract_holds(
        fmu_paths, master, tmp_path, model, output, inputs, off):
    import fmpy
    fmu_path = fmu_paths[model]
    unzipdir = tmp_path / "unzipped"
    with zipfile.ZipFile(fmu_path) as z:
        z.extractall(unzipdir)
    md = fmpy.read_model_description(str(fmu_path))
    y_c = run_master(master, unzipdir, md, output, inputs, off)
    y_fmpy = fmpy_run(fmu_path, str(unzipdir), md, output, inputs, N_SAMPLES, off)
    assert np.array_equal(y_c, y_fmpy), np.flatnonzero(y_c != y_fmpy)[:5]
    # the trajectory is not trivially constant
    assert np.ptp(y_fmpy) > 1.0
