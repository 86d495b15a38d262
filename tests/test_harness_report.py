"""The README's main job (``python -m harness``) and ``run`` end to end, as subprocesses, on the
C core backend: the files and tables of harness/report/ checked against the scenarios of docs/model.md and their
bounds, the README's lag formula, the paper's Tables 4/5 and tests/numpy_reference.py; the
report (headline table, provenance, figures) in tests/test_harness_document.py."""

import csv
import math

import numpy as np
import pytest

import numpy_reference as ref
from conftest import run_harness

H = 0.0005
WINDOW = slice(2000, 6000)          # metric window [1, 3) s of a 3 s run (docs/model.md, scenarios)
SCEN = ("1hz", "5hz", "10hz", "20hz", "1_5_10hz", "1_10_20hz")
FREQS = {"1hz": (1,), "5hz": (5,), "10hz": (10,), "20hz": (20,), "1_5_10hz": (1, 5, 10),
         "1_10_20hz": (1, 10, 20)}
# docs/model.md, scenarios / paper Tables 4/5: e_rms [nm], e_r [%]
PAPER = {"1hz": (7.6, 0.11), "5hz": (25.4, 0.36), "10hz": (56.0, 0.80), "20hz": (115.3, 1.63),
         "1_5_10hz": (60.0, 0.49), "1_10_20hz": (178.7, 1.46)}
# report order: the headline, its two ablations, the nominal-model check
CONDITIONS = (("mismatch", "mismatch_", 1, 1), ("mismatch_no_adaptation", "mismatch_", 0, 1),
              ("mismatch_no_preview", "mismatch_", 1, 0), ("nominal", "track_", 1, 1))
VALIDATION = (("validate_1hz", "1 Hz", 1), ("validate_10hz", "10 Hz", 10),
              ("validate_20hz", "20 Hz", 20), ("validate_50hz", "50 Hz", 50),
              ("validate_100hz", "100 Hz", 100), ("validate_5_40_80hz", "5/40/80 Hz", "5/40/80"))


def _csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def lag_rms(freqs, amplitude=10.0, d=2, h=H):
    """README: a sine followed d samples late has a lag error of ~ 2 pi f A d h / sqrt(2) rms;
    tones of distinct frequencies over whole periods are orthogonal, so their rms add in
    quadrature."""
    return math.sqrt(sum((2 * math.pi * f * amplitude * d * h / math.sqrt(2)) ** 2 for f in freqs))


def reference_validation(label, row):
    """tests/numpy_reference.py plant (exact creep) run twice on the docs/model.md, scenarios
    validation input: creep on with the Table 1 row, creep off (Hammerstein). Returns the
    metrics of eqs 36-37 over [1, 3) s (coupled taken as the truth, e_r normalised by it) and
    both outputs."""
    v = ref.validation_inputs(H, 3.0)[label]
    k_c, alpha = ref.TABLE1[row]
    coupled = ref.plant_simulate(v, ref.plant_params(**{"creep.k_c": k_c, "creep.alpha": alpha}))["y"]
    hamm = ref.plant_simulate(v, ref.plant_params(**{"creep.k_c": k_c, "creep.alpha": alpha,
                                                     "creep.enabled": False}))["y"]
    d = coupled[WINDOW] - hamm[WINDOW]
    return {"e_rms": math.sqrt(np.mean(d * d)),
            "e_r": math.sqrt(np.sum(d * d) / np.sum(coupled[WINDOW] ** 2)),
            "y_min": coupled[WINDOW].min(), "y_max": coupled[WINDOW].max(),
            "coupled": coupled, "hammerstein": hamm, "k_c": k_c, "alpha": alpha}


# ---------------------------------------------------------------- the main job
@pytest.fixture(scope="module")
def main_job(tmp_path_factory):
    out = tmp_path_factory.mktemp("main_job")
    proc = run_harness("--backend", "core", "--no-plots", "--out", str(out), check=True)
    return proc, out, _csv(out / "tracking.csv")


def _rows(tracking, condition):
    return {r["scenario"].split("_", 1)[1]: r for r in tracking if r["condition"] == condition}


def test_main_job_writes_four_conditions_of_six_scenarios(main_job):
    """Reference: harness/report/'s documented layout (4 conditions x the 6 scenarios of
    Tables 4/5, headline first, flags as the condition says), the paper's values of docs/model.md
    section 4 in every row (um and fraction, exact), 4000 samples in the [1, 3) s window,
    and the five report files; no figure with --no-plots."""
    _, out, tracking = main_job
    want = [(c, p + s, a, pv) for c, p, a, pv in CONDITIONS for s in SCEN]
    got = [(r["condition"], r["scenario"], int(r["adaptation"]), int(r["preview"])) for r in tracking]
    assert got == want
    for r in tracking:
        s = r["scenario"].split("_", 1)[1]
        assert float(r["paper_e_rms_um"]) == PAPER[s][0] / 1000
        assert float(r["paper_e_r"]) == pytest.approx(PAPER[s][1] / 100, rel=1e-12)
        assert int(r["n_samples"]) == 4000 and r["master"] == "gauss-seidel"
    names = sorted(p.name for p in out.iterdir())
    assert names == ["provenance.json", "report.html", "report.md", "stage_day.csv", "stage_use.csv", "tracking.csv",
                     "validation.csv"]


def test_main_job_nominal_and_mismatch_rows_meet_the_bounds(main_job):
    """Reference: docs/model.md, scenarios and the issue's acceptance bounds. Nominal model with
    preview: e_rms <= 1e-11 um (exact by construction but for rounding; measured <= 1.6e-12 um). Mismatch,
    adaptation on: e_rms <= 3 nm and e_r <= 0.05 % (measured 1.18-1.94 nm, <= 0.018 %).
    Adaptation off must be worse than on in every scenario, by more than 3x (measured
    6.5x at 1 Hz to 46x at 20 Hz)."""
    _, _, tracking = main_job
    nominal, on, off = (_rows(tracking, c) for c in ("nominal", "mismatch", "mismatch_no_adaptation"))
    for s in SCEN:
        assert float(nominal[s]["e_rms_um"]) <= 1e-11, (s, nominal[s]["e_rms_um"])
        assert float(on[s]["e_rms_um"]) <= 3e-3, s
        assert float(on[s]["e_r"]) <= 5e-4, s
        assert float(off[s]["e_rms_um"]) > 3 * float(on[s]["e_rms_um"]), s


def test_main_job_preview_off_rows_follow_the_lag_formula(main_job):
    """Reference: the README's lag error 2 pi f A d h / sqrt(2) rms (A = 10 um, d = 2,
    h = 0.5 ms) for the single tones, within 5 % (measured within 0.3 %); the three-tone
    references within 5 % of the quadrature sum of their tones' lag errors (measured 0.02 %)."""
    _, _, tracking = main_job
    rows = _rows(tracking, "mismatch_no_preview")
    for s in SCEN:
        assert float(rows[s]["e_rms_um"]) == pytest.approx(lag_rms(FREQS[s]), rel=0.05), s


def test_main_job_prints_the_headline_table_first(main_job):
    """Reference: the paper's Tables 4/5 (docs/model.md, scenarios). The first table printed is the
    headline (mismatch, adaptation on, preview on): every scenario line shows our e_rms and
    e_r equal to the CSV's to the 4 printed digits (rel. 1e-3), the paper's e_rms (7.6, 25.4,
    56, 115.3, 60.0, 178.7 nm) and e_r (0.11, 0.36, 0.80, 1.63, 0.49, 1.46 %) exactly, and
    ratio = ours / paper to its 3 printed digits (5e-3 relative)."""
    proc, _, tracking = main_job
    rows = _rows(tracking, "mismatch")
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("Headline (mismatch, adaptation on, preview on) vs the paper")
    assert lines[1].split() == ["scenario", "e_rms", "ours", "[nm]", "paper", "[nm]", "ratio",
                                "e_r", "ours", "[%]", "paper", "[%]", "ratio"]
    for j, s in enumerate(SCEN):
        cells = lines[3 + j].split()
        assert cells[0] == "mismatch_" + s
        assert (float(cells[2]), float(cells[5])) == PAPER[s], cells
        ours_nm, ours_pct = float(rows[s]["e_rms_um"]) * 1e3, float(rows[s]["e_r"]) * 100
        assert float(cells[1]) == pytest.approx(ours_nm, rel=1e-3)
        assert float(cells[4]) == pytest.approx(ours_pct, rel=1e-3)
        # the ratio has 3 printed digits: half a unit in the last is up to 5e-3 relative
        assert float(cells[3]) == pytest.approx(ours_nm / PAPER[s][0], rel=5e-3)
        assert float(cells[6]) == pytest.approx(ours_pct / PAPER[s][1], rel=5e-3)


def test_main_job_prints_every_condition_side_by_side(main_job):
    """Reference: tracking.csv. The second table has one row per reference (1 Hz ... 1/10/20
    Hz), the paper's e_rms, then the e_rms [nm] of the headline, RLS off, no preview and the
    nominal model, each equal to the CSV's to its printed digits (3, or 2 for round-off in
    e-notation); and no printed line is wider than 100 characters (the validation table
    included)."""
    proc, out, tracking = main_job
    lines = proc.stdout.splitlines()
    i = lines.index("All conditions: e_rms [nm] per reference")
    assert lines[i + 1].split() == ["reference", "paper", "headline", "RLS", "off", "no",
                                    "preview", "nominal", "model"]
    labels = ("1 Hz", "5 Hz", "10 Hz", "20 Hz", "1/5/10 Hz", "1/10/20 Hz")
    for j, (s, label) in enumerate(zip(SCEN, labels)):
        line = lines[i + 3 + j]
        assert line.startswith(label + " ")
        cells = line[len(label):].split()
        assert float(cells[0]) == PAPER[s][0]
        for cell, (cond, _, _, _) in zip(cells[1:], CONDITIONS):
            want = float(_rows(tracking, cond)[s]["e_rms_um"]) * 1e3
            digits_rel = 5e-2 if "e" in cell else 5e-3      # round-off printed as 1.4e-10
            assert float(cell) == pytest.approx(want, rel=digits_rel), (cond, s)
    assert max(len(line) for line in lines if str(out) not in line) <= 100


def test_main_job_validation_csv_equals_numpy_reference(main_job):
    """Reference: reference_validation() (tests/numpy_reference.py, exact creep) for each of
    the six validation inputs. validation.csv has the 6 rows in order with the Table 1 row
    (exact), coupled-minus-Hammerstein e_rms and e_r within 1e-8 relative (measured <= 9.3e-10:
    the core's default SOE creep is within ~1e-9 um of the exact sum, i.e. ~4e-9 relative of
    a 0.25 um e_rms at most; 1e-8 leaves room for SOE changes that keep the documented accuracy) and the coupled y span
    within 5e-9 um."""
    _, out, _ = main_job
    rows = _csv(out / "validation.csv")
    assert [r["scenario"] for r in rows] == [v[0] for v in VALIDATION]
    for r, (name, label, row) in zip(rows, VALIDATION):
        want = reference_validation(label, row)
        assert (float(r["k_c"]), float(r["alpha"])) == (want["k_c"], want["alpha"])
        assert float(r["diff_e_rms_um"]) == pytest.approx(want["e_rms"], rel=1e-8), name
        assert float(r["diff_e_r"]) == pytest.approx(want["e_r"], rel=1e-8), name
        assert float(r["y_min_um"]) == pytest.approx(want["y_min"], abs=5e-9), name
        assert float(r["y_max_um"]) == pytest.approx(want["y_max"], abs=5e-9), name


# ---------------------------------------------------------------- run SCENARIO
def test_run_validate_10hz_equals_numpy_reference(tmp_path):
    """Reference: reference_validation("10 Hz") (tests/numpy_reference.py's plant, exact creep,
    run with creep on and the Table 1 10 Hz row, and with creep off, same input, window
    [1, 3) s). The reported coupled-minus-Hammerstein e_rms and e_r equal it to 1e-8 relative
    (measured 8.4e-10, from the default SOE creep's ~1e-9 um; see the test above); the time series' y_coupled within 5e-9 um and
    y_hammerstein within 1e-9 um of the reference; the printed line shows the same e_rms."""
    proc = run_harness("run", "validate_10hz", "--backend", "core", "--no-plots", "--out", str(tmp_path),
                check=True)
    want = reference_validation("10 Hz", 10)
    rows = _csv(tmp_path / "validate_10hz.csv")
    assert len(rows) == 1 and rows[0]["scenario"] == "validate_10hz"
    assert float(rows[0]["diff_e_rms_um"]) == pytest.approx(want["e_rms"], rel=1e-8)
    assert float(rows[0]["diff_e_r"]) == pytest.approx(want["e_r"], rel=1e-8)
    series = np.genfromtxt(tmp_path / "validate_10hz_timeseries.csv", delimiter=",", names=True)
    assert series.shape == (6000,)
    assert np.max(np.abs(series["y_coupled"] - want["coupled"])) <= 5e-9
    assert np.max(np.abs(series["y_hammerstein"] - want["hammerstein"])) <= 1e-9
    line = next(l for l in proc.stdout.splitlines() if l.startswith("validate_10hz"))
    assert float(line.split()[3]) == pytest.approx(want["e_rms"], abs=5e-5)
    assert not list(tmp_path.glob("*.png"))


def _run_tracking(tmp_path, *flags):
    out = tmp_path / ("run" + "".join(flags).replace("-", "_"))
    run_harness("run", "mismatch_10hz", "--backend", "core", "--no-plots", "--out", str(out), *flags, check=True)
    row = _csv(out / "mismatch_10hz.csv")
    assert len(row) == 1
    series = np.genfromtxt(out / "mismatch_10hz_timeseries.csv", delimiter=",", names=True)
    return row[0], series


def test_run_flags_no_adaptation_and_no_preview(tmp_path):
    """Reference: y_d = 10 sin(2 pi 10 t) computed here, docs/model.md, scenarios bounds and the
    README's lag formula, mismatch_10hz (3 s, window [1, 3) s).
    Base run: e_rms <= 3 nm (measured 1.20 nm), flags 1/1.
    --no-adaptation: flags 0/1, the estimates stay the nominal G of docs/model.md, plant
    (-1.3767, 0.3816, 0.5954, -0.5907) exactly, e_rms > 3x the base run's (measured 28.3 nm).
    --no-preview: flags 1/0, e_rms within 5 % of 2 pi f A d h / sqrt(2) = 444.3 nm (d = 2), and
    the stage follows y_d two samples late: rms(y(k) - y_d(k-2)) <= 3 nm."""
    t = np.arange(6000) * H
    y_d = 10 * np.sin(2 * np.pi * 10 * t)
    base, s0 = _run_tracking(tmp_path)
    noad, s1 = _run_tracking(tmp_path, "--no-adaptation")
    noprev, s2 = _run_tracking(tmp_path, "--no-preview")
    for s in (s0, s1, s2):
        assert np.array_equal(s["y_d"], y_d)
    assert (base["adaptation"], base["preview"]) == ("1", "1")
    assert (noad["adaptation"], noad["preview"]) == ("0", "1")
    assert (noprev["adaptation"], noprev["preview"]) == ("1", "0")
    e0 = float(base["e_rms_um"])
    assert e0 <= 3e-3
    assert math.sqrt(np.mean((s0["y"][WINDOW] - y_d[WINDOW]) ** 2)) == pytest.approx(e0, rel=1e-12)
    assert float(noad["e_rms_um"]) > 3 * e0
    for f, v in zip(("a1", "a2", "b1", "b2"), (-1.3767, 0.3816, 0.5954, -0.5907)):
        assert np.all(s1[f] == v), f
    assert np.ptp(s0["a1"]) > 0                                   # the base run does adapt
    assert float(noprev["e_rms_um"]) == pytest.approx(lag_rms((10,)), rel=0.05)
    lagged = s2["y"][WINDOW] - y_d[1998:5998]
    assert math.sqrt(np.mean(lagged ** 2)) <= 3e-3
