"""Every FMU alone, as an importer's single-FMU smoke test runs it: default inputs, the default
experiment (0 to 3 s), the importer's own step. Each completes without an Error.

The importers (their source read for the protocol each test transcribes):

- ``fmpy simulate FILE`` (fmpy.simulate_fmu with its defaults): the step is the default
  experiment's 0.5 ms doubled until at most 1000 steps, 4 ms = 8 samples; it stops at a status
  above Warning.
- the FMU Compliance Checker (modelica-tools/FMUComplianceChecker, src/FMI2/fmi2_cs_sim.c): FMI
  1.0 and 2.0 only; the step is the stop time over its 500 output points, 6 ms = 12 samples,
  the last step trimmed to end at the stop time; no stop time given to the FMU; it stops at a
  status above Warning.
- fmusim (modelica/Reference-FMUs, fmusim/FMI2CSSimulation.c, FMI3CSSimulation.c): the step is
  the default experiment's, 0.5 ms; it stops at **any status above OK**, a Warning included
  (``CALL``), and exits with that status.

The controller alone has neither y_meas nor t_meas connected: it runs open loop (no
supervision verdict, a step may hold the inputs) and says so once, as a Warning message that
leaves the doStep OK so fmusim runs on. A loop that is connected keeps every Error of the
fault table (tests/test_supervision_family.py compares it with docs/robustness.md) and its
one-sample rule; here: the loops that show only one of the two connections.

``PIEZO_FMUCHECK`` / ``PIEZO_FMUSIM``, set to a fmuCheck or fmusim binary, also run the real
ones (neither is on a package registry: built from their sources, docs/fmus.md says how).
"""
import os
import re
import subprocess

import fmpy
import pytest

from harness.masters.wired import Fault, simulate_wired

from conftest import FMU_DIR, FMU3_DIR, FMU_NAMES

STOP = 3.0
H = 0.0005
#: the controller's open-loop message, by its words
OPEN_LOOP = "every input (y_ref, y_meas, t_meas, y_preview, t_preview) has kept its start value 0"
EDITIONS = [(2, name) for name in FMU_NAMES] + [(3, name) for name in FMU_NAMES]


def _path(fmi, name):
    return (FMU_DIR if fmi == 2 else FMU3_DIR) / f"{name}.fmu"


def _run(fmi, name, **kwargs):
    """simulate_fmu with a logger and an FMI call logger: (result, messages as (status,
    text), doStep statuses)."""
    messages, steps = [], []

    def logger(*args):       # FMI 2.0: (component, instance, status, category, message); 3.0 without instance
        status, _, message = args[-3:]
        messages.append((int(status), message.decode(errors="replace")))

    def calls(text):
        if "DoStep(" in text:
            steps.append(text.rsplit("-> ", 1)[-1].strip())

    result = fmpy.simulate_fmu(str(_path(fmi, name)), logger=logger, fmi_call_logger=calls, **kwargs)
    return result, messages, steps


def _check_open_loop_notice(name, messages):
    warnings = [text for status, text in messages if status == 1]
    assert not [text for status, text in messages if status >= 3]
    if name == "AdaptiveCompoundController":
        assert len(warnings) == 1 and OPEN_LOOP in warnings[0]
        for words in ("runs open loop", "PiezoStage.y_meas -> y_meas", "PiezoStage.t_meas -> t_meas"):
            assert words in warnings[0]
    else:
        assert warnings == []


@pytest.mark.parametrize("fmi, name", EDITIONS)
def test_fmpy_simulate_runs_every_fmu_to_its_end(fmu_paths, fmi, name):
    """``fmpy simulate`` (simulate_fmu with its defaults, 8-sample steps): every FMU of both
    editions reaches 3 s (751 rows: 0 to 3 s every 4 ms) without an Error; the controller logs
    exactly one Warning, the open-loop one naming the connections to make, and every other
    FMU none."""
    result, messages, steps = _run(fmi, name)
    assert len(result) == 751 and result["time"][-1] == pytest.approx(STOP, abs=1e-12)
    assert len(steps) == 750
    _check_open_loop_notice(name, messages)


@pytest.mark.parametrize("fmi, name", EDITIONS)
def test_fmusims_run_gets_ok_from_every_step(fmu_paths, fmi, name):
    """fmusim's run (steps of the default experiment's 0.5 ms, stopping at the first status above
    OK): every one of the 6000 doSteps of every FMU of both editions returns OK, so it runs to
    3 s; the controller's open-loop message is a Warning of the logger, its doStep OK."""
    result, messages, steps = _run(fmi, name, output_interval=H)
    assert len(steps) == 6000 and set(steps) == {"OK"}
    assert result["time"][-1] == pytest.approx(STOP, abs=1e-9)
    _check_open_loop_notice(name, messages)


def _checker_run(package, make_fmu, h_step):
    """fmi2_cs_sim.c transcribed: setup without a stop time, initialize, steps of h_step from
    tcur (accumulated), the last one trimmed to the stop time; a step fails at a status above
    Warning. Returns (the instance, the steps done)."""
    fmu = make_fmu(package)
    fmu.slave.setupExperiment(startTime=0.0)
    fmu.slave.enterInitializationMode()
    fmu.slave.exitInitializationMode()
    tcur, n = 0.0, 0
    while tcur < STOP:
        tnext = tcur + h_step
        step = h_step
        if tnext > STOP - 1e-3 * h_step:          # canHandleVariableCommunicationStepSize
            step, tnext = STOP - tcur, STOP
        fmu.slave.doStep(tcur, step)               # raises at a status above Warning
        tcur, n = tnext, n + 1
    fmu.slave.terminate()
    return fmu, n


@pytest.mark.parametrize("h_step", [STOP / 500, H])
def test_the_compliance_checkers_run_of_the_controller_completes(controller, make_fmu, h_step):
    """The checker's default run (6 ms = 12 samples a step) and its run at h (``-h 0.0005``):
    the controller alone completes to 3 s, logs the open-loop Warning once and no Error, never
    verifies a loop (sup.status 0) and holds v within a few volts (what the start-up law makes
    of y_ref = 0 and y_meas = 0: below 5 V). Before: refused at 6 ms (a step of 12 samples) and
    stopped by the supervision at 37 ms."""
    fmu, n = _checker_run(controller, make_fmu, h_step)
    assert n == round(STOP / h_step)
    assert fmu.errors() == []
    warnings = [text for status, _, text in fmu.messages if status == 1]
    assert len(warnings) == 1 and OPEN_LOOP in warnings[0]
    assert fmu.get("sup.status") == 0 and abs(fmu.get("v")) < 5.0


@pytest.mark.parametrize("name", ["PiezoStage", "ReferenceSignal", "PiezoStageClosedLoop"])
def test_the_compliance_checkers_run_of_the_other_fmus_completes(_fmu_packages, make_fmu, name):
    """The checker's default run of the other three FMUs: to 3 s, no Error, no Warning."""
    fmu, n = _checker_run(_fmu_packages[name], make_fmu, STOP / 500)
    assert n == 500 and fmu.errors() == []
    assert [text for status, _, text in fmu.messages if status == 1] == []


def test_open_loop_ends_at_the_first_sign_of_a_connection(controller, make_fmu):
    """Open loop lasts while y_meas and t_meas keep their start value: a t_meas that advances
    after 40 samples (a master that connects it late) makes the loop connected from there on,
    and a step of two samples, accepted before, is refused with the one-sample rule's words."""
    fmu = make_fmu(controller)
    fmu.initialize()
    fmu.slave.doStep(0.0, 2 * H)                        # nothing connected: held over 2 samples
    fmu.k = 2
    fmu.step(38)                                        # one sample at a time
    assert fmu.errors() == []
    fmu.set({"t_meas": fmu.time})
    with pytest.raises(Exception):
        fmu.slave.doStep(fmu.time, 2 * H)
    assert "2 samples of h = 0.0005: refused" in fmu.last_error()


def test_a_master_that_set_y_ref_at_initialization_is_refused_a_long_step_at_once(controller, make_fmu):
    """A step of several samples is held only while every input is at its start value: a master
    that exchanged initial values (y_ref = y_d(2 h) of the reference) gets the refusal at its
    first doStep, whatever y_meas and t_meas are (0 for a stage at rest at t = 0)."""
    fmu = make_fmu(controller)
    fmu.initialize()
    fmu.set({"y_ref": 0.0628})
    with pytest.raises(Exception):
        fmu.slave.doStep(0.0, 2 * H)
    assert "2 samples of h = 0.0005: refused" in fmu.last_error()


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("faults, verdict", [
    ((Fault("y_meas", "open"),), "no response"),                              # t_meas advances
    ((Fault("t_meas", "open"), Fault("v", "scale", -1.0)), "inverted response"),  # y_meas moves
])
def test_a_loop_that_shows_one_connection_keeps_its_error(fmu_paths, fmi, faults, verdict):
    """Reference: the fault table's times (docs/robustness.md, 14.5 ms for both faults under an
    exchanging master). A loop whose t_meas advances with y_meas unconnected, and one whose
    y_meas moves with t_meas unconnected (and v inverted), are connected loops: the supervision
    stops them at 14.5 ms with its verdict, in both editions, and no open-loop message comes."""
    run = simulate_wired("mismatch_5hz", "exchange", faults, duration=0.5, fmi_version=fmi)
    assert run.error_time == pytest.approx(0.0145, abs=1e-12)
    assert f"supervision stopped the loop ({verdict})" in run.error
    assert not [w for w in run.warnings["controller"] if OPEN_LOOP in w]


def test_a_loop_without_y_meas_and_t_meas_is_stopped_naming_y_meas(fmu_paths):
    """What the rule keeps: a loop wired with its reference but neither y_meas nor t_meas is no
    standalone run (y_ref moves), so the supervision judges it and stops it with the Error of
    the fault table's first row, naming PiezoStage.y_meas, within 15 ms; it never runs open
    loop with v pinned at a limit (which an open-loop rule on y_meas and t_meas alone did:
    v clipped at 150 V, a Warning only). Measured on mismatch_5hz, exchange master."""
    run = simulate_wired("mismatch_5hz", "exchange", (Fault("y_meas", "open"), Fault("t_meas", "open")),
                         duration=1.0)
    assert run.error_time is not None and run.error_time <= 0.015, run.error_time
    assert "PiezoStage.y_meas -> y_meas" in run.error
    assert not [w for w in run.warnings["controller"] if OPEN_LOOP in w]


def test_the_closed_loop_fmu_never_runs_open_loop(closed_loop, make_fmu):
    """PiezoStageClosedLoop has its loop wired inside: with its defaults (the internal reference,
    a 1 Hz tone from rest, the sensor on its 2 nm grid) it verifies its loop (sup.status 1, from
    sample 501 on: measured; the quantisation floor of the response test asks the tone to grow
    beyond the grid first) and says nothing of an open loop."""
    fmu = make_fmu(closed_loop)
    fmu.initialize()
    fmu.step(500)
    assert fmu.get("sup.status") == 0
    fmu.step(10)
    assert fmu.get("sup.status") == 1
    assert not [text for _, _, text in fmu.messages if OPEN_LOOP in text]


def _binary(variable):
    path = os.environ.get(variable)
    if not path:
        pytest.skip(f"{variable} is not set: the real tool is not on a package registry; build it "
                    f"from its sources (docs/fmus.md, the compatibility table) and set {variable}")
    return path


@pytest.mark.parametrize("name", FMU_NAMES)
def test_the_real_compliance_checker_reports_no_error(fmu_paths, tmp_path, name):
    """fmuCheck.linux64 with default inputs on each FMI 2.0 FMU: 'Simulation finished
    successfully at time 3', 0 errors of its own, and no Error from the FMU."""
    tool = _binary("PIEZO_FMUCHECK")
    run = subprocess.run([tool, "-o", str(tmp_path / "out.csv"), str(_path(2, name))],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "Simulation finished successfully at time 3" in run.stderr
    assert re.search(r"\n\s*0 Error\(s\)", run.stderr) and "[logStatusError]" not in run.stderr


@pytest.mark.parametrize("fmi, name", EDITIONS)
def test_the_real_fmusim_runs_every_fmu_to_its_end(fmu_paths, tmp_path, fmi, name):
    """fmusim with its defaults on each FMU of both editions: exit code 0 (it exits with the
    worst status it met, a Warning included) and 6001 rows to 3 s."""
    tool = _binary("PIEZO_FMUSIM")
    out = tmp_path / "out.csv"
    run = subprocess.run([tool, "--output-file", str(out), str(_path(fmi, name))], capture_output=True,
                         text=True, timeout=600, cwd=tmp_path)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert len(out.read_text().splitlines()) == 6002
