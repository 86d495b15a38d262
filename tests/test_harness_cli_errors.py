"""Every user mistake on the command line: one line on stderr naming the program, exit code 2,
no traceback, nothing run.  Reference: the issue's list of traps (item 3) and harness/cli.py's
documented exit codes (0 ok, 1 FMI fault, 2 user error, 3 a run failed its checks)."""

import os
import subprocess
import sys

import pytest

from harness.cli import main
from conftest import REPO, error_lines

PROG = "python -m harness"

NYQUIST = """
[[scenario]]
name = "too_fast"
kind = "tracking"
duration = 0.5
reference = { type = "sines", amplitudes = [1.0], frequencies = [1000.0] }
"""

STEP = """
[[scenario]]
name = "coarse"
extends = "track_5hz"
step_size = 0.001
"""

BUILTIN_NAME = """
[[scenario]]
name = "track_1hz"
kind = "tracking"
reference = { type = "sines", amplitudes = [1.0], frequencies = [1.0] }
"""

CONTROLLER_IN_VALIDATION = """
[[scenario]]
name = "v_ctrl"
extends = "validate_1hz"
controller = { "rls.forgetting" = 0.99 }
"""

PAPER_IN_USER_FILE = """
[[scenario]]
name = "claims_paper"
extends = "track_5hz"
paper = { e_rms_um = 0.001 }
"""

MISSING_CSV = """
[[scenario]]
name = "fine"
extends = "track_5hz"
duration = 1.5

[[scenario]]
name = "from_file"
kind = "tracking"
duration = 0.5
reference = { type = "csv", file = "nowhere.csv" }
"""

VOLTAGE_AS_REFERENCE = """
[[scenario]]
name = "wrong_header"
kind = "tracking"
duration = 0.5
reference = { type = "csv", file = "volts.csv" }
"""

UNKNOWN_PARAMETER = """
[[scenario]]
name = "typo"
extends = "track_5hz"
duration = 0.5
metric_window = [0.25, 0.5]
plant = { "pi.w00" = 0.3 }
"""

BAD_VALUE = """
[[scenario]]
name = "alpha_too_big"
extends = "track_5hz"
duration = 0.5
metric_window = [0.25, 0.5]
plant = { "creep.alpha" = 2.0 }
"""


@pytest.fixture
def files(tmp_path, fmu_paths, fmu3_paths):
    for name, text in [("nyquist", NYQUIST), ("step", STEP), ("builtin", BUILTIN_NAME),
                       ("ctrl", CONTROLLER_IN_VALIDATION), ("paper", PAPER_IN_USER_FILE),
                       ("csv", MISSING_CSV), ("header", VOLTAGE_AS_REFERENCE),
                       ("param", UNKNOWN_PARAMETER), ("value", BAD_VALUE)]:
        (tmp_path / f"{name}.toml").write_text(text)
    (tmp_path / "volts.csv").write_text("time,v\n0,0\n1,10\n")
    (tmp_path / "afile").write_text("not a folder")
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad.toml").write_text("[[scenario]\nname = 'x'\n")
    (tmp_path / "bad.json").write_text('{"pi.w0": ')
    # FMU folders a user may point --fmu-dir at by mistake
    for folder, paths in (("fmi2", fmu_paths), ("fmi3", fmu3_paths)):
        (tmp_path / folder).mkdir()
        for name, path in paths.items():
            (tmp_path / folder / f"{name}.fmu").symlink_to(path)
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "PiezoStage.fmu").symlink_to(fmu_paths["PiezoStage"])
    (tmp_path / "notzip").mkdir()
    (tmp_path / "notzip" / "PiezoStage.fmu").write_text("not a zip")
    (tmp_path / "notzip" / "AdaptiveCompoundController.fmu").symlink_to(
        fmu_paths["AdaptiveCompoundController"])
    (tmp_path / "foreign").mkdir()              # another model under PiezoStage's file name
    (tmp_path / "foreign" / "PiezoStage.fmu").symlink_to(fmu_paths["ReferenceSignal"])
    (tmp_path / "foreign" / "AdaptiveCompoundController.fmu").symlink_to(
        fmu_paths["AdaptiveCompoundController"])
    return tmp_path


# (arguments with {d} for the folder of the files above, exit code, what the one line says)
CASES = [
    (["foo"], 2, "argument SUBCOMMAND: invalid choice: 'foo'"),
    (["run"], 2, "the following arguments are required: SCENARIO "
                 "(see: python -m harness run --help)"),
    (["run", "track_1hz", "extra"], 2, "'run' does not take extra"),
    (["list", "--out", "x"], 2, "'list' does not take --out x (see: python -m harness list --help)"),
    (["all", "--noise-rms", "1"], 2, "'all' does not take --noise-rms 1"),
    (["run", "track_1hz", "--seed", "3"], 2, "'run' does not take --seed 3"),
    (["identify", "--scenario-file", "x.toml"], 2, "'identify' does not take --scenario-file"),
    (["identify", "--no-preview"], 2, "'identify' does not take --no-preview"),
    (["--out", "{d}/o", "run", "track_1hz"], 2, "options go after the subcommand"),
    (["run", "track_1hz", "--backend", "x"], 2, "argument --backend: invalid choice: 'x'"),
    (["run", "track_1hz", "--no-timeseries", "--timeseries-format", "npz"], 2,
     "argument --timeseries-format: not allowed with argument --no-timeseries"),
    (["run", "track_1hz", "--out", "{d}/afile"], 2,
     "--out: cannot create the output folder {d}/afile: {d}/afile is a file"),
    (["all", "--out", "{d}/afile/sub"], 2,
     "--out: cannot create the output folder {d}/afile/sub: {d}/afile is a file"),
    (["identify", "--demo", "--out", "{d}/afile"], 2, "--out: cannot create the output folder"),
    (["export", "--params", "p.json", "--out", "{d}/afile"], 2, "--out: cannot create the output folder"),
    (["export"], 2, "the following arguments are required: --params"),
    (["identify"], 2, "identify needs the records: --pi-data LOW.csv"),
    (["identify", "--demo", "--free-w0"], 2, "--free-w0 is only used by 'identify --internal-channels'"),
    (["run", "track_1hz", "--params", "p.json"], 2, "'run' does not take --params"),
    (["list", "--plant-params", "p.json"], 2, "'list' does not take --plant-params"),
    (["run", "validate_1hz", "--no-preview"], 2,
     "--no-preview does not apply to 'validate_1hz', a validation scenario"),
    (["run", "validate_1hz", "--jacobi"], 2, "--jacobi does not apply to 'validate_1hz'"),
    (["run", "validate_1hz", "--no-adaptation"], 2, "--no-adaptation does not apply"),
    (["run", "nope"], 2, "unknown scenario 'nope'; known scenarios: track_1hz"),
    (["identify", "--internal-channels", "--noise-rms", "-1"], 2,
     "--noise-rms must be a finite number >= 0"),
    (["identify", "--internal-channels", "--noise-rms", "nan"], 2,
     "--noise-rms must be a finite number >= 0"),
    (["identify", "--internal-channels", "--seed", "-2"], 2, "--seed must be >= 0, got -2"),
    (["list", "--scenario-file", "{d}/absent.toml"], 2,
     "{d}/absent.toml: cannot read the scenario file"),
    (["list", "--scenario-file", "{d}/bad.toml"], 2, "{d}/bad.toml: TOML syntax error"),
    (["run", "too_fast", "--scenario-file", "{d}/nyquist.toml"], 2,
     "{d}/nyquist.toml: scenario 'too_fast': field 'reference.frequencies': 1000 Hz is at or "
     "above the Nyquist frequency 1000 Hz of step_size 0.0005 s"),
    (["run", "coarse", "--scenario-file", "{d}/step.toml"], 2,
     "{d}/step.toml: scenario 'coarse': field 'step_size': step_size 0.001 s differs from the "
     "sample period of PiezoStage (h = 0.0005 s"),
    (["run", "track_1hz", "--scenario-file", "{d}/builtin.toml"], 2,
     "{d}/builtin.toml: scenario 'track_1hz': field 'name': 'track_1hz' is already the name of "
     "a built-in scenario"),
    (["run", "v_ctrl", "--scenario-file", "{d}/ctrl.toml"], 2,
     "scenario 'v_ctrl': field 'controller': a validation scenario runs the plant alone: "
     "controller overrides do not apply"),
    (["all", "--scenario-file", "{d}/paper.toml"], 2,
     "scenario 'claims_paper': field 'paper': paper values belong to the built-in scenarios"),
    (["run", "fine", "--scenario-file", "{d}/csv.toml"], 2,
     "{d}/csv.toml: scenario 'from_file': field 'reference.file': {d}/nowhere.csv: cannot read "
     "the CSV file"),
    (["run", "wrong_header", "--scenario-file", "{d}/header.toml"], 2,
     "scenario 'wrong_header': field 'reference.file': {d}/volts.csv: line 1: header's second "
     "column is 'v', expected 'y_d'"),
    (["run", "track_1hz", "--fmu-dir", "{d}/empty", "--no-plots", "--out", "{d}/o"], 2,
     "FMU not found: {d}/empty/PiezoStage.fmu; the folder {d}/empty has no PiezoStage.fmu, it "
     "holds no .fmu file at all (the harness runs PiezoStage.fmu and "
     "AdaptiveCompoundController.fmu from it)"),
    (["run", "track_1hz", "--fmu-dir", "{d}/nowhere", "--no-plots", "--out", "{d}/o"], 2,
     "FMU not found: {d}/nowhere/PiezoStage.fmu; the folder {d}/nowhere does not exist"),
    (["run", "track_1hz", "--fmu-dir", "{d}/afile", "--no-plots", "--out", "{d}/o"], 2,
     "{d}/afile is a file, not a folder"),
    (["run", "track_1hz", "--fmu-dir", "{d}/half", "--no-plots", "--out", "{d}/o"], 2,
     "the folder {d}/half has no AdaptiveCompoundController.fmu, it holds PiezoStage.fmu"),
    (["run", "track_5hz", "--fmu-dir", "{d}/fmi2", "--fmi", "3", "--no-plots", "--out", "{d}/o"],
     2, "{d}/fmi2/PiezoStage.fmu is not an FMI 3.0 Co-Simulation FMU (it is FMI 2.0) (the FMI "
        "3.0 editions are in the fmi3/ folder beside the FMI 2.0 FMUs)"),
    (["run", "track_5hz", "--fmu-dir", "{d}/fmi3", "--no-plots", "--out", "{d}/o"], 2,
     "{d}/fmi3/PiezoStage.fmu is not an FMI 2.0 Co-Simulation FMU (it is FMI 3.0) (an FMI 3.0 "
     "edition: run it with --fmi 3)"),
    (["run", "track_5hz", "--fmu-dir", "{d}/notzip", "--no-plots", "--out", "{d}/o"], 2,
     "{d}/notzip/PiezoStage.fmu is not an FMU (its model description cannot be read: "
     "BadZipFile"),
    (["run", "track_5hz", "--fmu-dir", "{d}/foreign", "--no-plots", "--out", "{d}/o"], 2,
     "{d}/foreign/PiezoStage.fmu has no variable 'y_meas': it is not this project's PiezoStage "
     "(its model is ReferenceSignal)"),
    (["run", "track_5hz", "--fmu-dir", "{d}/foreign", "--backend", "native", "--no-plots",
      "--out", "{d}/o"], 2, "it is not this project's PiezoStage (its model is ReferenceSignal)"),
    (["run", "validate_1hz", "--fmu-dir", "{d}/notzip", "--no-plots", "--out", "{d}/o"], 2,
     "{d}/notzip/PiezoStage.fmu is not an FMU"),
    (["run", "track_1hz", "--plant-params", "{d}/absent.json"], 2, "{d}/absent.json: no such file"),
    (["run", "track_1hz", "--plant-params", "{d}/bad.json"], 2, "{d}/bad.json: not valid JSON"),
    (["run", "track_1hz", "--controller-params", "{d}/empty"], 2,
     "{d}/empty: is a folder, not a parameter file"),
    (["run", "track_1hz", "--scenario-file", "{d}/empty"], 2,
     "{d}/empty: cannot read the scenario file"),
    (["export", "--params", "{d}/absent.json", "--out", "{d}/o"], 2, "{d}/absent.json: no such file"),
    (["run", "typo", "--scenario-file", "{d}/param.toml", "--no-plots", "--out", "{d}/o"], 2,
     "'pi.w00' is not a parameter of PiezoStage (did you mean pi.w0"),
    (["run", "alpha_too_big", "--scenario-file", "{d}/value.toml", "--no-plots", "--out",
      "{d}/o"], 2, "creep.alpha = 2 is out of range"),
]


@pytest.mark.parametrize("args,code,message", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_each_user_mistake_is_one_line_and_exit_2(files, capsys, args, code, message):
    """In process: main() returns (no exception escapes, so no traceback), with the exit code
    and a single stderr line that starts with the program's name and says what is wrong."""
    d = str(files)
    argv = [a.replace("{d}", d) for a in args]
    got = main(argv, prog=PROG)
    out, err = capsys.readouterr()
    assert got == code, err
    lines = error_lines(err)
    assert len(lines) == 1, err
    assert lines[0].startswith(f"{PROG}: error: "), lines[0]
    assert message.replace("{d}", d) in lines[0], lines[0]
    assert out == ""
    assert not (files / "o" / "track_1hz.csv").exists()


def _run(cmd, cwd):
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args,message", [
    (["run", "track_1hz", "--out", "{d}/afile"], "--out: cannot create the output folder"),
    (["run", "too_fast", "--scenario-file", "{d}/nyquist.toml"], "Nyquist frequency"),
    (["bogus"], "invalid choice: 'bogus'"),
])
def test_module_errors_have_no_traceback(files, args, message):
    """As a process (python -m harness): exit 2, one stderr line, no traceback."""
    d = str(files)
    proc = _run([sys.executable, "-m", "harness", *[a.replace("{d}", d) for a in args]], REPO)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("python -m harness: error: ")
    assert message in lines[0]


def test_console_script_names_itself(tmp_path):
    """A script named piezo-harness, written as pip writes a console-script wrapper, names
    piezo-harness in its errors and its usage line, not python -m harness."""
    script = tmp_path / "piezo-harness"
    script.write_text("import re, sys\nfrom harness.cli import main\n"
                      "if __name__ == '__main__':\n"
                      "    sys.argv[0] = re.sub(r'(-script\\.pyw|\\.exe)?$', '', sys.argv[0])\n"
                      "    sys.exit(main())\n")
    proc = _run([sys.executable, str(script), "run", "nope"], tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.startswith("piezo-harness: error: unknown scenario 'nope'")
    assert "python -m harness" not in proc.stderr
    proc = _run([sys.executable, str(script), "run", "--help"], tmp_path)
    assert proc.returncode == 0
    assert proc.stdout.startswith("usage: piezo-harness run [-h]")


@pytest.mark.parametrize("sub,own,foreign", [
    ("all", ["--out", "--backend", "--scenario-file", "--no-plots", "--no-adaptation",
             "--no-preview", "--jacobi", "--plant-params", "--controller-params"],
     ["--noise-rms", "--no-timeseries", "SCENARIO", "--params"]),
    ("run", ["SCENARIO", "--out", "--no-timeseries", "--timeseries-format", "--no-preview",
             "--plant-params"], ["--noise-rms", "--seed", "--params"]),
    ("list", ["--scenario-file"], ["--out", "--backend", "--no-plots", "--plant-params"]),
    ("identify", ["--pi-data", "--tf-data", "--creep-data", "--demo", "--internal-channels",
                  "--noise-rms", "--seed", "--free-w0", "--displacement-only", "--out"],
     ["--scenario-file", "--no-preview", "--no-plots", "--params"]),
    ("export", ["--params", "--out", "--fmu-dir"], ["--backend", "--scenario-file", "--demo"]),
])
def test_each_subcommand_has_its_own_help(capsys, sub, own, foreign):
    """`SUBCOMMAND --help` prints that subcommand's usage and options only (exit 0)."""
    assert main([sub, "--help"], prog=PROG) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: {PROG} {sub} [-h]")
    for opt in own:
        assert opt in out, opt
    for opt in foreign:
        assert opt not in out, opt


def test_top_level_help_lists_the_subcommands(capsys):
    assert main(["--help"], prog=PROG) == 0
    out = capsys.readouterr().out
    for sub in ("all", "run", "list", "identify", "export"):
        assert f"\n    {sub} " in out
    assert "Exit codes: 0 done, 1 FMI fault, 2 user error, 3 a run diverged or saturated" \
        in " ".join(out.split())
