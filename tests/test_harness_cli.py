"""python -m harness end to end (subprocess) and its error handling."""

import csv
import os
import subprocess
import sys

import numpy as np
import pytest

from harness.masters import fmpy as fmpy_master
from harness.loop.metrics import compute_metrics
from harness.scenarios import load_scenarios
from conftest import CROSS_PLATFORMS, HOST_PLATFORM, REPO, need_win64, run_harness


SHORT = """
[[scenario]]
name = "short_mismatch"
extends = "mismatch_5hz"
description = "0.5 s of the 5 Hz mismatch case"
duration = 0.5
metric_window = [0.25, 0.5]
"""


def test_run_short_user_scenario_end_to_end(tmp_path):
    scen = tmp_path / "short.toml"
    scen.write_text(SHORT)
    out = tmp_path / "out"
    proc = run_harness("run", "short_mismatch", "--scenario-file", str(scen), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    # progress: one line per scenario on stderr, with the elapsed time
    assert "[1/1] short_mismatch: e_rms" in proc.stderr and " s (total " in proc.stderr

    # metrics CSV written, and consistent with the time series and an in-process run
    rows = list(csv.DictReader(open(out / "short_mismatch.csv")))
    assert len(rows) == 1 and rows[0]["scenario"] == "short_mismatch"
    e_rms, e_r = float(rows[0]["e_rms_um"]), float(rows[0]["e_r"])
    series = np.genfromtxt(out / "short_mismatch_timeseries.csv", delimiter=",", names=True)
    assert series.shape == (1000,)
    m = compute_metrics(series["time"], series["y_d"], series["y"], (0.25, 0.5), 0.0005)
    assert m.n_samples == 500
    assert e_rms == pytest.approx(m.e_rms, rel=1e-12)
    assert e_r == pytest.approx(m.e_r, rel=1e-12)
    sc = load_scenarios([scen])["short_mismatch"]
    direct = fmpy_master.simulate_closed_loop(sc)
    m2 = compute_metrics(direct["time"], direct["y_d"], direct["y"], sc.metric_window, sc.step_size)
    assert e_rms == pytest.approx(m2.e_rms, rel=1e-12)
    # a user scenario is not the paper's experiment: no paper value, though it extends one
    assert rows[0]["paper_e_rms_um"] == "" and rows[0]["ratio_e_rms"] == ""

    # the printed table: ours only (nm, %, peak |v|), no paper column
    head = next(l for l in proc.stdout.splitlines() if l.startswith("scenario"))
    assert "paper" not in head and "ratio" not in head
    line = next(l for l in proc.stdout.splitlines() if l.startswith("short_mismatch"))
    cells = line.split()
    assert float(cells[1]) == pytest.approx(e_rms * 1e3, rel=1e-3)
    assert float(cells[2]) == pytest.approx(e_r * 100, rel=1e-3)
    assert float(cells[3]) == pytest.approx(np.max(np.abs(series["v"])), rel=1e-3)

    png = out / "short_mismatch.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (out / "short_mismatch.svg").read_bytes()[:2000]


def test_run_with_csv_reference_and_no_plots(tmp_path):
    t = np.arange(0, 0.2501, 0.01)
    np.savetxt(tmp_path / "ref.csv", np.column_stack([t, 5 * np.sin(2 * np.pi * 4 * t)]),
               delimiter=",", header="time,y_d", comments="")
    (tmp_path / "c.toml").write_text(
        '[[scenario]]\nname = "csv_ref"\nkind = "tracking"\nduration = 0.25\n'
        'metric_window = [0.05, 0.25]\n'
        'reference = { type = "csv", file = "ref.csv" }\n')
    out = tmp_path / "o"
    proc = run_harness("run", "csv_ref", "--scenario-file", str(tmp_path / "c.toml"),
                    "--out", str(out), "--no-plots", "--jacobi")
    assert proc.returncode == 0, proc.stderr
    assert (out / "csv_ref.csv").is_file() and not (out / "csv_ref.png").exists()
    # nominal model: exact tracking of the interpolated reference after the first d samples
    # (docs/cosimulation.md: Jacobi master, mv.delay = 1, d = 2)
    assert float(next(csv.DictReader(open(out / "csv_ref.csv")))["e_rms_um"]) <= 1e-6


def _one_line_error(proc):
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith("python -m harness: error: ")
    return lines[0]


def test_unknown_scenario_exits_2_with_the_known_names():
    msg = _one_line_error(run_harness("run", "track_3hz"))
    assert "unknown scenario 'track_3hz'" in msg
    assert "track_1hz" in msg and "mismatch_1_10_20hz" in msg


def test_malformed_scenario_file_exits_2_naming_file_and_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[scenario]]\nname = "b"\nkind = "tracking"\n'
                   'reference = { type = "sines", amplitudes = [1.0], frequencies = ["x"] }\n')
    msg = _one_line_error(run_harness("list", "--scenario-file", str(bad)))
    assert str(bad) in msg and "field 'reference.frequencies'" in msg and "'x'" in msg


def test_malformed_csv_exits_2(tmp_path):
    (tmp_path / "r.csv").write_text("time,y_d\n0,0\n0.1,oops\n")
    (tmp_path / "s.toml").write_text('[[scenario]]\nname = "s"\nkind = "tracking"\n'
                                     'reference = { type = "csv", file = "r.csv" }\n')
    msg = _one_line_error(run_harness("run", "s", "--scenario-file", str(tmp_path / "s.toml")))
    assert "r.csv" in msg and "line 3: 'oops' is not a number" in msg


def test_missing_fmu_in_a_chosen_folder_says_what_the_folder_lacks(tmp_path):
    """A folder the user chose (--fmu-dir or $PIEZO_FMU_DIR) gets no build or reinstall advice:
    building or reinstalling does not fill it. The message names what it lacks and holds."""
    (tmp_path / "AdaptiveCompoundController.fmu").write_bytes(b"")
    for args, env in (((["--fmu-dir", str(tmp_path)]), {}), ([], {"PIEZO_FMU_DIR": str(tmp_path)})):
        proc = subprocess.run([sys.executable, "-m", "harness", "run", "track_1hz", *args,
                               "--no-plots", "--out", str(tmp_path / "o")], cwd=REPO,
                              env=dict(os.environ, PYTHONPATH=str(REPO), **env),
                              capture_output=True, text=True, timeout=120)
        msg = _one_line_error(proc)
        folder = f"{tmp_path} ($PIEZO_FMU_DIR)" if env else str(tmp_path)
        assert (f"FMU not found: {tmp_path / 'PiezoStage.fmu'}; the folder {folder} has no "
                f"PiezoStage.fmu, it holds AdaptiveCompoundController.fmu") in msg, msg
        assert "cmake" not in msg and "install" not in msg, msg


def test_missing_fmu_in_the_default_folder_says_how_to_build_it(tmp_path, monkeypatch, capsys):
    """The default folder (a checkout's build/fmus, here one that was never built) is filled by
    the build: the message gives its command."""
    from harness import paths
    from harness.cli import main

    monkeypatch.delenv("PIEZO_FMU_DIR", raising=False)
    monkeypatch.setattr(paths, "fmu_dir", lambda: tmp_path / "build" / "fmus")
    assert main(["run", "track_1hz", "--no-plots", "--out", str(tmp_path / "o")]) == 2
    msg = capsys.readouterr().err
    assert f"FMU not found: {tmp_path / 'build' / 'fmus' / 'PiezoStage.fmu'}" in msg
    assert "cmake -S . -B build && cmake --build build" in msg


@pytest.mark.parametrize("sub", ["all", "run", "export", "bench"])
def test_fmu_dir_help_names_the_real_default(sub, monkeypatch, capsys):
    """--fmu-dir's help names the folder the FMUs are really taken from (reference:
    harness.paths.fmu_dir(), which the runs use): here the checkout's build/fmus, and
    $PIEZO_FMU_DIR when it is set. (tests/test_install.py checks the installed package's.)"""
    from harness import paths
    from harness.cli import main

    def says(text):
        """The help holds `text`, whatever argparse's wrapping (it also breaks at hyphens)."""
        assert main([sub, "--help"], prog="python -m harness") == 0
        return "".join(text.split()) in "".join(capsys.readouterr().out.split())

    monkeypatch.delenv("PIEZO_FMU_DIR", raising=False)
    assert paths.fmu_dir() == REPO / "build" / "fmus"
    assert says(f"(default: {REPO / 'build' / 'fmus'}, the checkout's build; $PIEZO_FMU_DIR "
                f"overrides)")
    monkeypatch.setenv("PIEZO_FMU_DIR", "/srv/my_fmus")
    assert says("(default: /srv/my_fmus, from $PIEZO_FMU_DIR)")


def test_list_shows_builtin_and_user_scenarios(tmp_path):
    (tmp_path / "u.toml").write_text(SHORT)
    proc = run_harness("list", "--scenario-file", str(tmp_path / "u.toml"))
    assert proc.returncode == 0
    names = [l.split()[0] for l in proc.stdout.splitlines() if l.startswith("  ")]
    assert names[:6] == ["track_1hz", "track_5hz", "track_10hz", "track_20hz",
                         "track_1_5_10hz", "track_1_10_20hz"]
    assert "short_mismatch" in names and "validate_5_40_80hz" in names


FAILING = """
[[scenario]]
name = "diverging_d1"
extends = "track_10hz"
description = "plant with one extra sample of input delay, controller assuming d = 1"
duration = 0.5
metric_window = [0.25, 0.5]
plant = { "tf.delay" = 1 }
controller = { "mv.feedthrough" = true, "mv.delay" = 0 }

[[scenario]]
name = "clipping"
extends = "track_10hz"
description = "voltage limits too tight for a 10 um tone"
duration = 0.5
metric_window = [0.25, 0.5]
controller = { "sat.v_min" = -15.0, "sat.v_max" = 15.0 }

[[scenario]]
name = "diverging_unsupervised"
extends = "diverging_d1"
description = "the same loop with the supervision off, under the paper's law: the divergence monitor catches it"
controller = { "mv.feedthrough" = true, "mv.delay" = 0, "sup.enabled" = false, "rls.robust" = false, "rls.forgetting" = 0.995, "mv.integral" = 0.0, "mv.observer" = 0.4 }

[[scenario]]
name = "diverging_unmonitored"
extends = "diverging_d1"
description = "the same loop with the supervision and the monitor off, under the paper's law: the error check of the harness catches it"
controller = { "mv.feedthrough" = true, "mv.delay" = 0, "monitor.divergence_samples" = 0, "sup.enabled" = false, "rls.robust" = false, "rls.forgetting" = 0.995, "mv.integral" = 0.0, "mv.observer" = 0.4 }
"""


@pytest.mark.parametrize("backend", ["fmpy", "core"])
@pytest.mark.parametrize("name,fragment", [
    ("diverging_d1", "supervision stopped the loop (loop delay beyond the controller's)"),
    ("clipping", "the controller clipped v in"),
    ("diverging_unsupervised", "the closed loop is unstable"),
    ("diverging_unmonitored", "the run diverged"),
])
def test_a_failing_run_exits_3_with_one_line(tmp_path, backend, name, fragment):
    """The documented diverging configuration (plant tf.delay = 1, controller in
    direct-feedthrough mode with d = 1): the supervision says the loop's delay is 2; with it
    off and the paper's law (the robust law runs this loop one sample off and tracks it, 0.15 nm
    rms: measured), the divergence monitor finds the loop unstable; with both off (the limits
    then hold v at +-150 V) the harness's own error check finds the error larger than the
    reference.
    And a reference the +-15 V limits cannot reach. Each exits with code 3 and a single
    stderr line naming the scenario and why."""
    scen = tmp_path / "failing.toml"
    scen.write_text(FAILING)
    proc = run_harness("run", name, "--scenario-file", str(scen), "--out", str(tmp_path / "out"),
                    "--no-plots", "--backend", backend)
    assert proc.returncode == 3, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "error:" in line]
    assert len(lines) == 1 and f"run / {name}:" in lines[0], proc.stderr
    assert fragment in lines[0], lines[0]          # the FMU's words and the core's alike


@pytest.mark.parametrize("values,count", [({"creep.alpha": 0.001}, "1 parameter"),
                                          ({"creep.alpha": 0.001, "creep.k_c": 1.0},
                                           "2 parameters")])
def test_parameter_file_count_is_in_words(tmp_path, values, count):
    """The note of --plant-params counts the file's parameters, singular for one."""
    import json

    f = tmp_path / "p.json"
    f.write_text(json.dumps(values))
    proc = run_harness("run", "validate_1hz", "--plant-params", str(f), "--backend", "core",
                    "--no-plots", "--no-timeseries", "--out", str(tmp_path / "o"))
    assert proc.returncode == 0, proc.stderr
    assert f"--plant-params {f}: {count} applied to the PiezoStage of every scenario" \
        in proc.stderr, proc.stderr


def _linux_only_copies(fmu_paths, fmu3_paths, folder):
    """The built FMUs (both editions) rewritten with the host's binaries only, as a build
    without the cross compilers makes them."""
    import zipfile

    (folder / "fmi3").mkdir(parents=True)
    for paths, sub in ((fmu_paths, folder), (fmu3_paths, folder / "fmi3")):
        for name, path in paths.items():
            with zipfile.ZipFile(path) as src, zipfile.ZipFile(sub / f"{name}.fmu", "w") as dst:
                for info in src.infolist():
                    if not info.filename.startswith("binaries/") or info.filename.startswith(
                            ("binaries/linux64/", "binaries/x86_64-linux/")):
                        dst.writestr(info, src.read(info))
    return folder


@pytest.mark.parametrize("where", ["--fmu-dir", "checkout", "installed"])
@pytest.mark.parametrize("fmi", ["2", "3"])
def test_fmus_without_windows_binaries_are_announced(fmu_paths, fmu3_paths, tmp_path, monkeypatch,
                                                      capsys, where, fmi):
    """pip hides CMake's output, so a build without MinGW-w64 is announced when the FMUs are
    used: one warning line before the run, saying how to get Windows binaries where a rebuild
    or a reinstall makes them (the default folder). Reference: the zip's binaries/ folders."""
    from harness import paths
    from harness.cli import main

    linux = _linux_only_copies(fmu_paths, fmu3_paths, tmp_path / "fmus")
    monkeypatch.delenv("PIEZO_FMU_DIR", raising=False)
    args = ["run", "track_5hz", "--no-plots", "--no-timeseries", "--out", str(tmp_path / "o"),
            "--fmi", fmi]
    if where == "--fmu-dir":
        args += ["--fmu-dir", str(linux)]
    else:
        monkeypatch.setattr(paths, "fmu_dir", lambda: linux)
        monkeypatch.setattr(paths, "IN_CHECKOUT", where == "checkout")
    assert main(args, prog="python -m harness") == 0
    err = capsys.readouterr().err.splitlines()
    folder, windows = (linux, "win64") if fmi == "2" else (linux / "fmi3", "x86_64-windows")
    warning = (f"python -m harness: warning: the FMUs in {folder} have no Windows binaries "
               f"(binaries/{windows}): MinGW-w64 was not found when they were built, so they "
               f"run on Linux only")
    fix = {"--fmu-dir": "",
           "checkout": "; for FMUs that also run on Windows install MinGW-w64 (Debian: "
                       "gcc-mingw-w64-x86-64), then rebuild (cmake -S . -B build && cmake "
                       "--build build)",
           "installed": "; for FMUs that also run on Windows install MinGW-w64 (Debian: "
                        "gcc-mingw-w64-x86-64), then reinstall the package from its source "
                        "folder (pip install .)"}[where]
    assert err[0] == warning + fix


def test_the_report_names_the_platforms_and_says_linux_only(fmu_paths, fmu3_paths, tmp_path):
    from harness.report import document, jobs
    from harness.report.provenance import collect_provenance

    linux = _linux_only_copies(fmu_paths, fmu3_paths, tmp_path / "fmus")
    for folder, linux_only in ((linux, True), (fmu_paths["PiezoStage"].parent, False)):
        prov = collect_provenance("fmpy", folder)
        platforms = [f.platforms for f in prov.fmus]
        if not linux_only and "win64" not in platforms[0]:
            need_win64("the build has no win64 binaries (MinGW-w64 was not found when it was built)")
        text = document.render_markdown(document.Document(
            "p", jobs._provenance_blocks(prov, [], "the FMUs' own")))
        assert ("**Linux only:** PiezoStage, AdaptiveCompoundController have no Windows "
                "binaries" in text) == linux_only
        if linux_only:
            assert platforms == [("linux64",), ("linux64",)]
        else:
            built = tuple(sorted(f for p in CROSS_PLATFORMS + (HOST_PLATFORM,)
                                 if (f := p.folder(2)) in platforms[0]))
            assert "win64" in built and platforms == [built, built]
            assert f"| {', '.join(built)} |" in text


@pytest.mark.parametrize("study, words", [
    ("timing", "--master"), ("supervision", "fault-family"), ("stage-use", "--quick"), ("stage-day", "--frames"),
])
def test_every_study_answers_help_under_python_m_harness(study, words):
    """Reference: harness.cli.STUDIES and each study's own parser. ``python -m harness STUDY --help``
    is the study's own help under that name (exit 0, an option only it has), the top-level help
    lists the study, and a command line the study does not take is refused by it (exit 2, its
    error line naming the program as the user called it)."""
    from harness.cli import STUDIES
    assert study in STUDIES
    proc = run_harness(study, "--help", check=True, timeout=120)
    assert proc.stdout.startswith(f"usage: python -m harness {study} ") and words in proc.stdout
    assert f"  {study}" in run_harness("--help", check=True, timeout=120).stdout
    bad = run_harness(study, "--no-such-option", timeout=120)
    assert bad.returncode == 2 and f"python -m harness {study}: error: " in bad.stderr, bad.stderr
