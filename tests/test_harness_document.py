"""The main job's report (report.md, report.html, provenance.json, figures) as a reader gets it.

References: tracking.csv of the same run (the numbers the report shows), the FMUs'
modelDescription.xml read here with zipfile + ElementTree (GUIDs and versions), git (the
commit), importlib.metadata (package versions), the PNG format (pHYs chunk: 150 dpi), and the
conditions actually run (notes must match them)."""

import csv
import datetime as dt
from importlib import metadata
import json
from pathlib import Path
import platform
import re
import struct
import subprocess
import xml.etree.ElementTree as ET
import zipfile

import pytest
from conftest import REPO, run_harness

FMU_DIR = REPO / "build" / "fmus"

USER = """
[[scenario]]
name = "user_short"
extends = "mismatch_5hz"
description = "0.5 s of the 5 Hz mismatch case"
duration = 0.5
metric_window = [0.25, 0.5]
"""

FIGURES = {"headline", "tracking_error", "tracking_period", "control_voltage", "rls_estimates",
           "hysteresis", "creep", "user_tracking_error", "stage_use_stage_step10_hold60s",
           "stage_use_stage_scan10hz_dwell10s", "stage_use_stage_hold5um_100nm",
           "stage_use_stage_staircase", "stage_day_frames", "stage_day_estimates", "sensor_faults",
           "fault_reset"}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The main job on the FMUs (fmpy, the default backend) with figures and a user scenario."""
    d = tmp_path_factory.mktemp("report")
    (d / "user.toml").write_text(USER)
    out = d / "out"
    proc = run_harness("--out", str(out), "--scenario-file", str(d / "user.toml"), check=True)
    md = (out / "report.md").read_text(encoding="utf-8")
    html = (out / "report.html").read_text(encoding="utf-8")
    rows = list(csv.DictReader(open(out / "tracking.csv")))
    return proc, out, md, html, rows


def _md_table_after(md, heading):
    """Rows (lists of cells) of the first Markdown table after a heading line."""
    lines = md.splitlines()
    i = lines.index(heading)
    while not lines[i].startswith("|"):
        i += 1
    table = []
    while i < len(lines) and lines[i].startswith("|"):
        cells = re.split(r"(?<!\\)\|", lines[i].strip()[1:-1])
        table.append([c.strip().replace("\\|", "|") for c in cells])
        i += 1
    return table[0], table[2:]


def test_report_leads_with_the_headline_table(report):
    """The first section is the headline; its table's numbers are tracking.csv's mismatch rows
    (ours to 4 digits, the paper's Table 4/5 values exactly, ratio = ours / paper)."""
    _, _, md, _, rows = report
    sections = [l for l in md.splitlines() if l.startswith("## ")]
    assert sections[0] == "## Headline: tracking error, ours vs the paper"
    head, body = _md_table_after(md, sections[0])
    assert head == ["scenario", "e_rms ours [nm]", "paper [nm]", "ratio", "e_r ours [%]",
                    "paper [%]", "ratio"]
    want = [r for r in rows if r["condition"] == "mismatch"]
    assert [b[0] for b in body] == [r["scenario"] for r in want]
    for b, r in zip(body, want):
        ours, paper = float(r["e_rms_um"]) * 1e3, float(r["paper_e_rms_um"]) * 1e3
        assert float(b[1]) == pytest.approx(ours, rel=1e-3)
        assert float(b[2]) == pytest.approx(paper, rel=1e-12)
        assert float(b[3]) == pytest.approx(ours / paper, rel=5e-3)   # 3 digits: half a unit in the last is up to 5e-3
        assert float(b[5]) == pytest.approx(float(r["paper_e_r"]) * 100, rel=1e-12)


def test_report_states_each_condition(report):
    """Every condition run is described under its label, with the facts of that run."""
    _, _, md, _, rows = report
    for key in ("mismatch", "mismatch_no_adaptation", "mismatch_no_preview", "nominal"):
        assert f"(`{key}`):" in md
    assert "Expected: exact tracking by construction" in md       # nominal with preview
    assert "the stage follows d = 2 samples late" in md            # the no-preview ablation
    assert "1 Hz 44 nm" in md and "20 Hz 888 nm" in md             # its lag error, per tone
    assert "Jacobi" not in md                                      # the master was Gauss-Seidel
    # the user's scenario: its own section, no paper value
    head, body = _md_table_after(md, "## User scenarios")
    assert head == ["scenario", "e_rms [nm]", "e_r [%]", "peak |v| [V]"]
    user = next(r for r in rows if r["scenario"] == "user_short")
    assert user["condition"] == "user" and user["paper_e_rms_um"] == ""
    assert float(body[0][1]) == pytest.approx(float(user["e_rms_um"]) * 1e3, rel=1e-3)


def test_the_report_shows_the_fault_reset_refused_then_accepted(report):
    """The report's section "Leaving the safe state (sup.reset)": one row per
    harness.studies.supervision_table.RESET_CASES case on the report's stage (20 nm); the sensor faults' and
    the reach's early resets refused with their cause, every late one accepted, the restarted loop's
    step within 5 % of the fault-free run's, the amplifier never cleared stopped again."""
    _, _, md, _, _ = report
    head, body = _md_table_after(md, "## Leaving the safe state (sup.reset)")
    assert head == ["case", "verdict", "reset at 2.6 s (cause persists)", "reset at 3 s", "after the restart"]
    rows = {r[0]: r for r in body}
    assert rows["sensor stuck, then back"][2] == "refused: y_meas still reads the verdict's value"
    assert rows["sensor dead (reads 0), then back"][2] == "refused: y_meas still reads the verdict's value"
    assert rows["reference out of reach, then back"][2] == \
        "refused: the reference still beyond the reading at the rail"
    assert all(r[3] == "accepted" for r in body) and len(body) == 4
    for name in ("sensor stuck, then back", "sensor dead (reads 0), then back", "reference out of reach, then back"):
        assert float(rows[name][4].split()[1]) <= 1.05
    assert rows["amplifier inverted, never cleared"][4].startswith("stopped again")


def _png_dpi(path):
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    i = 8
    while i < len(data):
        n, kind = struct.unpack(">I", data[i:i + 4])[0], data[i + 4:i + 8]
        if kind == b"pHYs":
            x, y, unit = struct.unpack(">IIB", data[i + 8:i + 17])
            assert unit == 1 and x == y
            return x * 0.0254
        i += 12 + n
    raise AssertionError(f"{path}: no pHYs chunk")


def test_every_figure_the_report_names_exists_at_150_dpi_with_its_svg(report):
    """Every PNG embedded in report.md exists at 150 dpi with an SVG beside it, report.html
    embeds the same figures, and every figure file in the folder is embedded (none of the
    nominal round-off run)."""
    _, out, md, html, _ = report
    pngs = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", md)
    assert {Path(p).stem for p in pngs} == FIGURES
    for p in pngs:
        assert _png_dpi(out / p) == pytest.approx(150, abs=0.05)     # integer px per metre
        svg = (out / p).with_suffix(".svg")
        assert svg.read_text(encoding="utf-8").lstrip().startswith("<?xml")
        assert "<svg" in svg.read_text(encoding="utf-8")[:2000]
        assert f'<img src="{p}"' in html and f'href="{Path(p).stem}.svg"' in html
    on_disk = {p.stem for p in out.iterdir() if p.suffix in (".png", ".svg")}
    assert on_disk == FIGURES
    assert "nominal" not in " ".join(pngs)
    # the validation figures say on their face (the title, SVG text) what they compare
    for name in ("hysteresis", "creep"):
        svg = (out / f"{name}.svg").read_text(encoding="utf-8")
        assert "model vs model (coupled vs Hammerstein), no measured data" in svg
    # units as the symbols, not 'um'
    svg = (out / "tracking_period.svg").read_text(encoding="utf-8")
    assert "[µm]" in svg and "[nm]" in svg and "[um]" not in svg


def _model_description(path):
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml")).attrib


def test_provenance(report):
    """Commit (git rev-parse HEAD), each FMU's GUID and version (its modelDescription.xml),
    fmpy and numpy versions (importlib.metadata), date (now), machine (this host) and the
    command, in provenance.json and in the report's Provenance section."""
    proc, out, md, html, _ = report
    prov = json.loads((out / "provenance.json").read_text())
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert prov["commit"].split()[0] == head
    assert prov["backend"] == "auto"        # the command line's default: the FMUs, fmpy or native
    fmus = {f["name"]: f for f in prov["fmus"]}
    assert set(fmus) == {"PiezoStage", "AdaptiveCompoundController"}
    for name, f in fmus.items():
        attrib = _model_description(FMU_DIR / f"{name}.fmu")
        assert f["guid"] == attrib["guid"] and f["version"] == attrib["version"]
        assert f["fmi_version"] == "2.0"
        assert f"| {name} | {attrib['guid']} | {attrib['version']} |" in md
    assert prov["versions"]["fmpy"] == metadata.version("fmpy")
    assert prov["versions"]["numpy"] == metadata.version("numpy")
    assert f"| fmpy | {metadata.version('fmpy')} |" in md
    assert f"| numpy | {metadata.version('numpy')} |" in md
    when = dt.datetime.fromisoformat(prov["date"])
    assert abs((dt.datetime.now(dt.timezone.utc) - when).total_seconds()) < 3600
    assert prov["machine"].startswith(platform.node())
    assert prov["command"].startswith("python -m harness all --out ")
    sections = [l for l in md.splitlines() if l.startswith("## ")]
    assert "## Provenance" in sections
    # the parameter sets used: the mismatched plant's overrides, the validation creep rows
    assert "tf.a1 = -1.442037" in md and "sensor.noise_rms = 0.001" in md
    assert "creep.k_c = 1.0172, creep.alpha = -0.0023" in md
    assert "<h2 id=\"provenance\">Provenance</h2>" in html


def test_notes_follow_the_conditions_run(tmp_path):
    """With --no-preview --jacobi the report never claims exact tracking, names the Jacobi
    master and the lag, drops the duplicate no-preview condition, and says it has no figures."""
    out = tmp_path / "o"
    proc = run_harness("--no-preview", "--jacobi", "--no-plots", "--backend", "core",
                       "--out", str(out), check=True)
    md = (out / "report.md").read_text(encoding="utf-8")
    assert "exact tracking by construction" not in md and "tracks exactly" not in md
    assert "Master: Jacobi" in md and "follows d = 2 samples late" in md
    assert "Expected: the lag error above and nothing else" in md
    assert "(`mismatch_no_preview`)" not in md
    head, _ = _md_table_after(md, "## All tracking conditions")
    assert head == ["reference", "paper", "headline", "RLS off", "nominal model"]
    assert "No figures: the run had plots switched off (`--no-plots`)." in md
    assert not list(out.glob("*.png")) and not list(out.glob("*.svg"))
    assert proc.stdout.startswith("Headline (mismatch, adaptation on, preview off, Jacobi "
                                  "master) vs the paper's Tables 4/5")
