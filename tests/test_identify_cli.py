"""python -m harness identify / export / --plant-params: end to end and every refusal.

End to end in a subprocess (as a user runs it); the refusals through harness.cli.main
in-process (the same code, faster), each with its own one-line message and exit code 2.
Records: core plant runs of the paper's inputs, 2 s, with the 2 nm / 1 nm sensor.
"""
import csv
import json
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from conftest import error_lines, run_harness
from harness.masters.c_core import simulate_open_loop_core
from harness.identify.data import write_record
from harness.identify.demo import DEMO_PLANT, DEMO_SENSOR
from harness.identify.params import read_params
from harness.identify.from_files import identify_files

H = 0.0005


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    folder = tmp_path_factory.mktemp("records")
    t = np.arange(4000) * H
    inputs = {"low": 10 * np.sin(2 * np.pi * t) + 10,
              "mixed": 6 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t)
                            + np.sin(2 * np.pi * 80 * t)) + 18,
              "fast": 10 * np.sin(2 * np.pi * 50 * t) + 10}
    paths = {}
    for i, (name, v) in enumerate(inputs.items()):
        run = simulate_open_loop_core({**DEMO_PLANT, **DEMO_SENSOR, "sensor.seed": i + 1}, v)
        paths[name] = write_record(folder / f"{name}.csv", t, v, run["y_meas"],
                                   extra={"y_true": run["y"]})
    return paths


def test_identify_export_and_run_end_to_end(records, tmp_path):
    out = tmp_path / "stage.json"
    proc = run_harness("identify", "--pi-data", str(records["low"]), "--tf-data",
                    str(records["mixed"]), "--creep-data", str(records["low"]),
                    str(records["fast"]), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    for title in ("Fits (on the fit windows", "Parameters under the normalisation",
                  "Table 1: creep row of each record", "Tables 2-3: held-out samples"):
        assert title in proc.stdout
    assert f"Wrote {out} (parameters" in proc.stdout
    # the file is what the same identification gives in-process
    result, recs = identify_files(records["low"], records["mixed"],
                                  [records["low"], records["fast"]])
    params = read_params(out)
    assert params == result.model.plant_params()
    assert [r.label for r in recs] == ["low", "mixed", "fast"]
    report = json.loads((tmp_path / "stage.report.json").read_text())
    assert report["parameters"] == params
    assert [h["record"] for h in report["held_out"]] == ["low", "mixed", "fast"]
    assert "| record | Hammerstein e_rms [nm]" in (tmp_path / "stage.report.md").read_text()

    # export: both FMUs with those start values
    fmus = tmp_path / "fmus"
    proc = run_harness("export", "--params", str(out), "--out", str(fmus))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith(f"{fmus / 'PiezoStage.fmu'}: 20 start values from {out}")
    assert lines[1].startswith(f"{fmus / 'AdaptiveCompoundController.fmu'}: 19 start values")

    # run a validation input with the identified stage as the plant
    proc = run_harness("run", "validate_50hz", "--plant-params", str(out), "--out",
                    str(tmp_path / "run"), "--no-plots")
    assert proc.returncode == 0, proc.stderr
    assert f"--plant-params {out}: 20 parameters applied to the PiezoStage" in proc.stderr
    row = next(csv.DictReader(open(tmp_path / "run" / "validate_50hz.csv")))
    assert float(row["k_c"]) == 1.0 and float(row["alpha"]) == params["creep.alpha"]


def test_identify_demo_end_to_end(tmp_path):
    # the virtual experiment, short and noise-free, on the core backend (the FMU is the
    # default; test_identify_demo runs it): exit 0, the checks pass, records written
    proc = run_harness("identify", "--demo", "--duration", "2.5", "--noise-free", "--backend", "core",
                    "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "Virtual experiment: the PiezoStage model (C core) with known parameters" in proc.stdout
    assert "coupled beats Hammerstein on every record: passed." in proc.stdout
    assert "[6/6] record 5-40-80Hz: 2.5 s" in proc.stderr
    assert {p.name for p in (tmp_path / "demo_records").iterdir()} == {
        "1Hz.csv", "10Hz.csv", "20Hz.csv", "50Hz.csv", "100Hz.csv", "5-40-80Hz.csv"}
    assert (tmp_path / "params.json").is_file() and (tmp_path / "params.report.md").is_file()


def _fails(capsys, argv, message, code=2):
    assert main(argv) == code
    err = error_lines(capsys.readouterr().err)
    assert len(err) == 1 and err[0] == f"python -m harness: error: {message}", err


def test_option_refusals(capsys, records, tmp_path):
    low, mixed = str(records["low"]), str(records["mixed"])
    cases = [
        (["identify"], "identify needs the records: --pi-data LOW.csv --tf-data MIXED.csv "
                       "--creep-data A.csv [B.csv ...] (or --demo for the virtual experiment)"),
        (["identify", "--pi-data", low], "identify needs --pi-data, --tf-data and --creep-data "
                                         "(missing: --tf-data, --creep-data)"),
        (["identify", "--demo", "--pi-data", low],
         "identify takes one of: the records, --demo, --internal-channels, --family (got records and --demo)"),
        (["list", "--pi-data", low],
         f"'list' does not take --pi-data {low} (see: python -m harness list --help)"),
        (["run", "track_1hz", "--demo"],
         "'run' does not take --demo (see: python -m harness run --help)"),
        (["identify", "--demo", "--params", low],
         f"'identify' does not take --params {low} (see: python -m harness identify --help)"),
        (["identify", "--demo", "--plant-params", low],
         f"'identify' does not take --plant-params {low} (see: python -m harness identify --help)"),
        (["export"], "the following arguments are required: --params "
                     "(see: python -m harness export --help)"),
        (["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low, "--duration", "3"],
         "--duration is only used by 'identify --demo' and 'identify --family'"),
        (["identify", "--demo", "--noise-rms", "0.001"],
         "--noise-rms is only used by 'identify --internal-channels'"),
        (["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low, "--seed", "2"],
         "--seed is only used by 'identify --demo', 'identify --family' and 'identify --internal-channels'"),
        (["identify", "--internal-channels", "--holdout", "0.1"],
         "--holdout is not used by 'identify --internal-channels'"),
        (["identify", "--demo", "--operators", "5"],
         "--operators is not used by 'identify --demo' (the virtual stage fixes it)"),
        (["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low, "--holdout", "1.5"],
         "--holdout must be in [0, 0.9], got 1.5"),
        (["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low, "--operators", "0"],
         "--operators must be in 1..16, got 0"),
        (["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low,
          "--sample-period", "-1"], "--sample-period must be a finite number > 0 (s), got -1"),
        (["identify", "--demo", "--duration", "0"], "--duration must be a finite number > 0 (s), got 0"),
    ]
    for argv, message in cases:
        _fails(capsys, argv, message)


def test_data_and_parameter_file_errors_are_one_line_exit_2(capsys, records, tmp_path):
    low, mixed = str(records["low"]), str(records["mixed"])
    bad = tmp_path / "bad.csv"
    bad.write_text("time,volts,y\n0,1,2\n")
    _fails(capsys, ["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", str(bad)],
           f"{bad}: missing column 'v'; the header has: time, volts, y; a record needs the "
           f"columns time [s], v [V], y [um]")
    _fails(capsys, ["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low,
                    "--sample-period", "0.001"],
           f"{low}: sample period 0.0005 s (2000 Hz) is not the model's h = 0.001 s (1000 Hz); "
           f"record at 1000 Hz, or identify a model sampled at 0.0005 s (--sample-period 0.0005)")
    params = tmp_path / "p.json"
    params.write_text('{"pi.w0": 0.4, "creep.kc": 1.0}')
    message = (f"{params}: 'creep.kc' is a parameter of neither PiezoStage nor "
               f"AdaptiveCompoundController (did you mean creep.k_c, creep.exact, creep.alpha?)")
    _fails(capsys, ["run", "track_1hz", "--plant-params", str(params)], message)
    _fails(capsys, ["run", "track_1hz", "--controller-params", str(params), "--backend", "core"],
           message)
    _fails(capsys, ["export", "--params", str(params), "--out", str(tmp_path / "x")], message)
    assert not (tmp_path / "x").exists()


def test_failed_checks_exit_3_with_one_line(capsys, monkeypatch, records):
    # The wiring of the two "run failed its own checks" outcomes (the computations are
    # replaced; what they detect is tested in test_identify_demo and test_identify_fit).
    from types import SimpleNamespace

    import harness.identify.demo as demo
    import harness.identify.from_files as run
    from harness.identify.fit import IdentificationFitError

    monkeypatch.setattr(demo, "run_demo", lambda *a, **k: SimpleNamespace(
        failures=["10Hz: held-out e_rms 2 nm exceeds 1.5 x the noise floor (1.7 nm)", "x"]))
    _fails(capsys, ["identify", "--demo"], "the virtual experiment failed 2 of its checks; "
           "first: 10Hz: held-out e_rms 2 nm exceeds 1.5 x the noise floor (1.7 nm)", 3)

    def no_convergence(*a, **k):
        raise IdentificationFitError("the joint refinement did not converge in 300 evaluations "
                                     "(cost 1 um^2); check the records")

    monkeypatch.setattr(run, "identify_files", no_convergence)
    low, mixed = str(records["low"]), str(records["mixed"])
    _fails(capsys, ["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low],
           "the joint refinement did not converge in 300 evaluations (cost 1 um^2); check the "
           "records", 3)


def test_a_search_at_its_limit_names_the_limit_not_the_records(capsys, records):
    """Issue 18: 'never blame the records when the optimiser stopped'. With a limit no start
    can converge within, the one line names the limit and the option to raise it."""
    low, mixed = str(records["low"]), str(records["mixed"])
    code = main(["identify", "--pi-data", low, "--tf-data", mixed, "--creep-data", low,
                 "--max-evaluations", "2", "--out", str(Path(low).parent / "limit.json")])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 3
    assert "stopped at its limit of 2 evaluations per start before converging" in err, err
    assert err.endswith("rerun with --max-evaluations 8"), err
    assert "record" not in err


def test_records_that_do_not_determine_a_parameter_exit_2(capsys, tmp_path):
    """Issue 18: records that never move the play operators apart (v = 10 + sin, a 1 V swing,
    with --v-max 20) determine the static gain but not the PI weights: the run names the
    first weight and what would fix it, exits 2, writes the reports (the list on top) and
    no parameter file (an older one is removed)."""
    t = np.arange(4000) * H
    paths = {}
    for name, v in {"small": 10 + np.sin(2 * np.pi * t),
                    "smallmix": 10 + 0.4 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t)
                                            + np.sin(2 * np.pi * 80 * t))}.items():
        run = simulate_open_loop_core({}, v)
        paths[name] = str(write_record(tmp_path / f"{name}.csv", t, v, run["y"]))
    out = tmp_path / "stage.json"
    out.write_text("{}")
    code = main(["identify", "--pi-data", paths["small"], "--tf-data", paths["smallmix"],
                 "--creep-data", paths["small"], "--v-max", "20", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2
    assert err.startswith("python -m harness: error: the records do not determine pi.w["), err
    assert "record voltage swings over the whole range" in err
    assert err.endswith(f"no parameter file written, see {tmp_path / 'stage.report.md'}"), err
    assert not out.exists()
    report = (tmp_path / "stage.report.md").read_text()
    assert report.index("NOT DETERMINED") < report.index("Fits")
    js = json.loads((tmp_path / "stage.report.json").read_text())
    assert {u["parameter"] for u in js["undetermined"]} >= {"pi.w[9]"}


def test_family_prints_the_distribution(tmp_path):
    proc = run_harness("identify", "--family", "2", "--record-set", "two", "--duration", "2",
                    "--noise-free", "--backend", "core", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "2 stages (seed 2026), record set 'two' (1Hz, 5-40-80Hz), 2 s each, noise-free" \
        in proc.stdout
    lines = [ln for ln in proc.stdout.splitlines() if "held-out e_rms vs measured y" in ln]
    worst = float(lines[0].split("worst")[1])
    assert worst <= 1e-3                       # nm: noise-free, the bound of the family test
    assert proc.stderr.count("identify: stage ") == 2


def test_demo_duration_too_short_is_refused_before_writing(capsys, tmp_path):
    """Issue 19: 'identify --demo --duration 0.01' wrote six records before refusing."""
    code = main(["identify", "--demo", "--duration", "0.01", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.endswith("--duration 0.01 s is too short: each record needs 200 samples and the "
                        "1Hz record 4 voltage reversals; use --duration 1.8 or more"), err
    assert not (tmp_path / "o" / "demo_records").exists()
