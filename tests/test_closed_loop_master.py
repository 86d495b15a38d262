"""The master closed-loop-fmu (harness.masters.closed_loop_fmu): the harness's closed loop run
by PiezoStageClosedLoop, one FMU, instead of PiezoStage and AdaptiveCompoundController.

Independent reference: the fmpy master on the two FMUs (harness.masters.fmpy), itself checked
against the core, the native runner and other tools' masters (tests/test_masters.py,
tests/test_native_runner.py): every field of every sample equal, bit for bit, and the report's
tables the same numbers.
"""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from harness import masters
from harness.scenarios import Signal, get_scenario
from conftest import run_harness


CASES = [
    ("mismatch_1_5_10hz", {}),
    ("mismatch_1_10_20hz", {"adaptation": False}),
    ("mismatch_5hz", {"preview": False}),
    ("track_20hz", {"master": "jacobi"}),
    ("track_10hz", {"controller_params": {"mv.delay": 0, "mv.feedthrough": True}}),
    ("track_1hz", {"plant_params": {"tf.delay": 1}}),
    ("mismatch_1hz", {"controller_params": {"mv.delay": 1, "mv.observer": 0.0}}),
]


def _same(a, b):
    return [f for f in a.dtype.names if not np.array_equal(a[f], b[f])]


@pytest.mark.parametrize("scenario, options", CASES)
def test_the_closed_loop_fmu_gives_the_two_fmus_samples(scenario, options):
    """Reference: the fmpy master on PiezoStage and AdaptiveCompoundController, every field of
    every sample of 3 s (the mismatch benchmark; adaptation or the preview off; Jacobi; the
    controller's feedthrough, d = 1; the stage's extra delay, d = 3 detected; a set delay), and
    what the controller detected."""
    t_fmpy, t_fmu = {}, {}
    want = masters.closed_loop("fmpy")(scenario, timing=t_fmpy, **options)
    got = masters.closed_loop("closed-loop-fmu")(scenario, timing=t_fmu, **options)
    assert len(got) == len(want) == 6000
    assert _same(got, want) == []
    if options.get("controller_params", {}).get("mv.feedthrough"):
        # the controller FMU's outputs with feedthrough are those of the sample it would compute
        # next, from the inputs held since the last: a stamp that has not advanced, no preview;
        # the closed loop's are those of its last sample
        assert (t_fmpy.pop("preview_lead"), t_fmu.pop("preview_lead")) == (0, 4)
    assert t_fmu == t_fmpy


def test_the_fmi3_edition_gives_the_same_samples():
    """Reference: the FMI 2.0 edition through the same master (and so the fmpy master)."""
    a = masters.closed_loop("closed-loop-fmu", 2)("mismatch_1_5_10hz", duration=1.0)
    b = masters.closed_loop("closed-loop-fmu", 3)("mismatch_1_5_10hz", duration=1.0)
    assert _same(a, b) == []


def test_a_table_reference_goes_through_the_input_y_d():
    """Reference: the fmpy master on the same table reference (a 2 um step smoothed over 50 ms
    and a 5 Hz ramp, a CSV's rows): the same samples, the controller's y_d(k + 2) given through
    the FMU's input y_d, y_d_lead = 2 samples ahead (the loop delay d = 2 of both)."""
    sc = get_scenario("mismatch_5hz")
    t = np.arange(0.0, 3.0005, 0.0005)
    values = np.clip((t - 0.5) / 0.05, 0.0, 1.0) * 2.0 + 3.0 * np.sin(2 * np.pi * 5 * t) * (t > 1.5)
    table = sc.with_overrides(name="table_case", signal=Signal("table", table_time=tuple(t),
                                                                table_value=tuple(values)))
    registry = {"table_case": table}
    want = masters.closed_loop("fmpy")("table_case", registry=registry)
    got = masters.closed_loop("closed-loop-fmu")("table_case", registry=registry)
    assert np.ptp(got["y"]) > 4.0
    assert _same(got, want) == []


def test_a_jacobi_master_with_feedthrough_is_refused_naming_it():
    with pytest.raises(ValueError, match="mv.feedthrough = true; a Jacobi master's stale v"):
        masters.closed_loop("closed-loop-fmu")("track_1hz", master="jacobi",
                                               controller_params={"mv.delay": 0, "mv.feedthrough": True})


def test_a_stopped_loop_raises_the_fmpy_masters_error():
    """Reference: the fmpy master on a stage with an inverted response: the same LoopFaultError
    class, at the same sample, with the controller's words."""
    from harness.fmu import LoopFaultError
    stage = {"tf.b1": -0.5954, "tf.b2": 0.5907}
    errors = {}
    for name in ("fmpy", "closed-loop-fmu"):
        with pytest.raises(LoopFaultError) as info:
            masters.closed_loop(name)("track_1hz", plant_params=stage)
        errors[name] = str(info.value)
    assert "supervision stopped the loop (inverted response)" in errors["closed-loop-fmu"]
    at = lambda text: text.split(" at t = ")[1].split(")")[0]     # noqa: E731
    assert at(errors["closed-loop-fmu"]) == at(errors["fmpy"])


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_the_report_shows_the_same_numbers(tmp_path):
    """Reference: the main job's report with --backend fmpy: tracking.csv and validation.csv
    equal field for field but the elapsed time, the printed tables the same; the provenance
    names the closed-loop FMU (and PiezoStage, whose open loop the validation runs)."""
    runs = {}
    for master in ("fmpy", "closed-loop-fmu"):
        out = tmp_path / master
        option = "--backend" if master == "fmpy" else "--master"
        proc = run_harness(option, master, "--no-plots", "--out", str(out), check=True)
        runs[master] = (proc.stdout, _rows(out / "tracking.csv"), _rows(out / "validation.csv"),
                        json.loads((out / "provenance.json").read_text()))
    (out_a, track_a, valid_a, prov_a), (out_b, track_b, valid_b, prov_b) = runs["fmpy"], runs["closed-loop-fmu"]
    assert len(track_a) == len(track_b) == 24 and len(valid_a) == len(valid_b) == 6
    drop = lambda rows: [{k: v for k, v in r.items() if "elapsed" not in k} for r in rows]   # noqa: E731
    assert drop(track_a) == drop(track_b)
    assert drop(valid_a) == drop(valid_b)
    assert prov_b["backend"] == "closed-loop-fmu"
    assert [f["name"] for f in prov_b["fmus"]] == ["PiezoStageClosedLoop", "PiezoStage"]
    headline = lambda text: [line for line in text.splitlines() if "mismatch_" in line]   # noqa: E731
    assert headline(out_a) == headline(out_b) and headline(out_a)
