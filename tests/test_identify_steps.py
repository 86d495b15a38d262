"""harness.identify.steps: the paper's steps 1-2 recover the model defaults
from a noise-free run of the core plant (creep disabled, i.e. the Hammerstein model)."""

import numpy as np
import pytest

from harness.masters.c_core import simulate_open_loop_core
from harness.identify import (
    identify_pi,
    identify_transfer_function,
    pi_thresholds,
    play_operator_outputs,
)


W_DEFAULT = np.array([0.3344, 0.0714, 0.0322, 0.0072, 0, 0, 0, 0, 0, 0])
G_DEFAULT = (-1.3767, 0.3816, 0.5954, -0.5907)
H = 0.0005


def _run(v):
    return simulate_open_loop_core({"creep.enabled": False}, v)


def test_thresholds_and_play_operator():
    # Reference: the model definition, r_j = (j-1)/m v_max; eq 3 play operator.
    np.testing.assert_allclose(pi_thresholds(9, 20.0), np.arange(9) * 20.0 / 9)
    z = play_operator_outputs([1.0, 3.0, 2.0, -1.0], [1.0])[:, 0]
    np.testing.assert_allclose(z, [0.0, 2.0, 2.0, 0.0])


def test_identify_pi_recovers_default_weights():
    # Paper step 1: v = 10 sin(2 pi 1 t) + 10 V, 2 s, fitted on the plant's PI output u.
    t = np.arange(4000) * H
    v = 10 * np.sin(2 * np.pi * t) + 10
    run = _run(v)
    w = identify_pi(v, run["u"], m=9, v_max=20.0, w0=0.3344)
    np.testing.assert_allclose(w, W_DEFAULT, rtol=0, atol=1e-6)
    # w0 unknown: r_1 = 0 makes z_1 = v, so only w0 + w1 is identifiable
    w_free = identify_pi(v, run["u"], m=9, v_max=20.0)
    assert w_free[0] == pytest.approx(0.3344 + 0.0714, abs=1e-6) and w_free[1] == 0.0
    np.testing.assert_allclose(w_free[2:], W_DEFAULT[2:], rtol=0, atol=1e-6)


def test_identify_transfer_function_recovers_default_g():
    # Paper step 2: v = 6 (sin 2 pi 5t + sin 2 pi 40t + sin 2 pi 80t) + 18 V, from u to x.
    t = np.arange(4000) * H
    v = 6 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t) + np.sin(2 * np.pi * 80 * t)) + 18
    run = _run(v)
    assert np.array_equal(run["x"], run["y"])   # creep disabled: Hammerstein output
    est = identify_transfer_function(run["u"], run["x"])
    np.testing.assert_allclose(est, G_DEFAULT, rtol=0, atol=1e-6)


def test_identification_errors():
    with pytest.raises(ValueError, match="same length"):
        identify_pi([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="need at least"):
        identify_transfer_function([1.0] * 3, [1.0] * 3)


# ---------------------------------------------------------------------------
# step 3 (identify_creep) and the three steps together (identify_coupled_model)
# ---------------------------------------------------------------------------
import csv

from harness.identify import (
    MIN_CREEP_SAMPLES,
    IdentificationInputError,
    IdentificationRecord,
    creep_output,
    identify_coupled_model,
    identify_creep,
    transfer_function_output,
)
from harness.identify import generate_identification_records
from conftest import run_harness


# Table 1 rows of the paper: label -> (k_c, alpha, input v(t) of that row)
TABLE1 = {
    "1 Hz": (1.0463, 0.0002, lambda t: 10 * np.sin(2 * np.pi * t) + 10),
    "10 Hz": (1.0497, -0.0085, lambda t: 10 * np.sin(2 * np.pi * 10 * t) + 10),
    "100 Hz": (1.0327, -0.0059, lambda t: 10 * np.sin(2 * np.pi * 100 * t) + 10),
    "5/40/80 Hz": (1.0172, -0.0023, lambda t: 6 * (np.sin(2 * np.pi * 5 * t)
                                                    + np.sin(2 * np.pi * 40 * t)
                                                    + np.sin(2 * np.pi * 80 * t)) + 18),
}
TABLE1_ALL = {"1 Hz": (1.0463, 0.0002), "10 Hz": (1.0497, -0.0085), "20 Hz": (1.0386, -0.0077),
              "50 Hz": (1.0481, -0.0098), "100 Hz": (1.0327, -0.0059),
              "5/40/80 Hz": (1.0172, -0.0023)}


@pytest.mark.parametrize("row", list(TABLE1))
def test_identify_creep_recovers_table1_row_from_core_plant(row):
    """Step 3 on a noise-free core plant run (3 s, the row's own input and creep row).

    The fit sees the plant's x and y and evaluates the plant's own G-L operator (SOE, as
    the plant), so the residual vanishes at the truth. Measured: |k_c error| <= 6e-13
    relative, |alpha error| <= 3e-15 absolute on these rows (solver round-off, tol 1e-12).
    Bounds: 1e-9 relative on k_c, 1e-12 absolute on alpha (5e-9 relative for the smallest
    order, 1 Hz: 0.0002).
    """
    k_c, alpha, signal = TABLE1[row]
    v = signal(np.arange(6000) * H)
    run = simulate_open_loop_core({"creep.k_c": k_c, "creep.alpha": alpha}, v)
    assert not np.array_equal(run["x"], run["y"])
    est_k_c, est_alpha = identify_creep(run["x"], run["y"], H)
    assert est_k_c == pytest.approx(k_c, rel=1e-9, abs=0)
    assert est_alpha == pytest.approx(alpha, rel=0, abs=1e-12)


def test_identify_creep_exact_mode_and_across_modes():
    """1 s of the 10 Hz row with the plant's full-memory creep (creep.exact = true).

    Exact model: measured errors at round-off (1e-16); bounds 1e-12 / 1e-14. SOE model on
    the exact plant: the SOE tail differs from the full sum by <= 3e-6 nm (README); measured
    4e-11 relative on k_c and 6e-12 absolute on alpha; bounds 1e-9 and 1e-10.
    """
    k_c, alpha, signal = TABLE1["10 Hz"]
    v = signal(np.arange(2000) * H)
    run = simulate_open_loop_core({"creep.k_c": k_c, "creep.alpha": alpha, "creep.exact": True}, v)
    est = identify_creep(run["x"], run["y"], H, exact=True)
    assert est[0] == pytest.approx(k_c, rel=1e-12, abs=0)
    assert est[1] == pytest.approx(alpha, rel=0, abs=1e-14)
    est = identify_creep(run["x"], run["y"], H)
    assert est[0] == pytest.approx(k_c, rel=1e-9, abs=0)
    assert est[1] == pytest.approx(alpha, rel=0, abs=1e-10)
    # creep_output is the plant's creep block (the same core operator)
    np.testing.assert_allclose(creep_output(run["x"], k_c, alpha, H, exact=True), run["y"],
                               rtol=1e-13, atol=1e-13)


def test_identify_creep_bounds_and_start():
    # alpha is kept in [-1, 1] and k_c > 0; a start far from the truth still converges.
    x = 5 + 5 * np.sin(2 * np.pi * 3 * np.arange(1500) * H)
    y = creep_output(x, 0.8, 0.35, H)
    k_c, alpha = identify_creep(x, y, H, alpha0=-0.9)
    assert k_c == pytest.approx(0.8, rel=1e-9) and alpha == pytest.approx(0.35, abs=1e-11)
    # y = -x: the best unconstrained gain is negative; the bounded fit stays feasible
    k_c, alpha = identify_creep(x, -x, H)
    assert k_c > 0 and -1.0 <= alpha <= 1.0


def test_identify_creep_bad_input():
    x = np.linspace(1.0, 2.0, 50)
    with pytest.raises(IdentificationInputError, match="same length"):
        identify_creep(x, x[:-1], H)
    with pytest.raises(IdentificationInputError, match=r"y\[3\] = nan is not finite"):
        identify_creep(x, np.where(np.arange(50) == 3, np.nan, x), H)
    with pytest.raises(IdentificationInputError, match=r"x\[0\] = inf is not finite"):
        identify_creep(np.r_[np.inf, x[1:]], x, H)
    with pytest.raises(IdentificationInputError, match=f"at least {MIN_CREEP_SAMPLES} samples"):
        identify_creep(x[:2], x[:2], H)
    with pytest.raises(IdentificationInputError, match="non-empty 1-D"):
        identify_creep(np.ones((5, 2)), np.ones((5, 2)), H)
    with pytest.raises(IdentificationInputError, match="identically zero"):
        identify_creep(np.zeros(50), x, H)
    with pytest.raises(ValueError, match="h must be"):
        identify_creep(x, x, 0.0)
    with pytest.raises(ValueError, match=r"alpha must be in \[-1, 1\]"):
        identify_creep(x, x, H, alpha0=1.5)
    assert issubclass(IdentificationInputError, ValueError)
    # the step 1-2 functions raise the same class for bad data
    with pytest.raises(IdentificationInputError, match="finite"):
        identify_transfer_function([1.0] * 9 + [np.nan], [1.0] * 10)


@pytest.fixture(scope="module")
def noise_free_records():
    return generate_identification_records(backend="core")


def _identify(records, truth, w0=0.3344):
    by = {r.label: r for r in records}
    return identify_coupled_model(by["1 Hz"], by["5/40/80 Hz"], records, H, m=9, v_max=20.0,
                                  w0=w0)


def test_coupled_model_recovers_defaults_from_noise_free_records(noise_free_records):
    """The paper's three steps on the six Table 1 records of the core plant (3 s each).

    Measured: PI weights within 5e-17, G within 2e-14 relative, k_c within 1.1e-13
    relative, alpha within 2e-14 absolute (k_c and alpha inherit G's round-off).
    Bounds: 1e-12 (weights, absolute), 1e-10 (G, k_c, relative), 1e-12 (alpha, absolute).
    """
    records, truth = noise_free_records
    assert [r.label for r in records] == list(TABLE1_ALL)
    est = _identify(records, truth)
    assert est.w0_fixed and len(est.weights) == 10
    np.testing.assert_allclose(est.weights, W_DEFAULT, rtol=0, atol=1e-12)
    np.testing.assert_allclose((est.a1, est.a2, est.b1, est.b2), G_DEFAULT, rtol=1e-10, atol=0)
    for label, (k_c, alpha) in TABLE1_ALL.items():
        c = est.creep_row(label)
        assert truth[label]["creep.k_c"] == k_c and truth[label]["creep.alpha"] == alpha
        assert c.k_c == pytest.approx(k_c, rel=1e-10, abs=0), label
        assert c.alpha == pytest.approx(alpha, rel=0, abs=1e-12), label
        assert c.residual_rms < 1e-12
    with pytest.raises(KeyError, match="no creep estimate"):
        est.creep_row("7 Hz")
    # the estimate, run as a plant, reproduces the record's displacement
    r = records[1]
    again = simulate_open_loop_core(est.plant_params(r.label), r.v)
    np.testing.assert_allclose(again["y"], r.y, rtol=0, atol=1e-11)


def test_coupled_model_free_w0_and_displacement_only(noise_free_records):
    records, truth = noise_free_records
    # w0 free: r_1 = 0 leaves only w0 + w1 identifiable; w0 carries the sum, the rest is exact
    est = _identify(records, truth, w0=None)
    assert not est.w0_fixed and est.weights[1] == 0.0
    assert est.weights[0] == pytest.approx(0.3344 + 0.0714, abs=1e-12)
    assert est.creep_row("10 Hz").k_c == pytest.approx(1.0497, rel=1e-10)
    # (v, y) only, as the paper's experiment: every step fits y and the blocks bias each other.
    # Measured: k_c 1.70-1.88 % low on every row, alpha 1.1e-3 to 2.6e-3 high.
    bare = [IdentificationRecord(r.label, r.v, r.y) for r in records]
    est = _identify(bare, truth)
    for label, (k_c, alpha) in TABLE1_ALL.items():
        c = est.creep_row(label)
        assert -0.025 < c.k_c / k_c - 1 < -0.012, label
        assert 5e-4 < c.alpha - alpha < 4e-3, label


def test_coupled_model_with_1nm_noise_stays_within_bounds(noise_free_records):
    """1 nm rms white noise on u, x and y of every record (seed 1).

    Measured over seeds 1..10 (core backend) with the output-error refinement of G:
    PI weights <= 4.6e-5 absolute, G <= 1.2e-4 relative, k_c <= 3.8e-5 relative,
    alpha <= 9.5e-6 absolute. Bounds, about 2-3x the worst seed: 1e-4, 3e-4, 1e-4, 3e-5.
    (ARX alone is biased to ~1 % on G here: see the test below.)
    """
    records, truth = generate_identification_records(backend="core", noise_rms_um=0.001, seed=1)
    # the noise is there, on every channel, at the requested level
    for r, c in zip(records, noise_free_records[0]):
        for ch in ("u", "x", "y"):
            assert np.std(getattr(r, ch) - getattr(c, ch)) == pytest.approx(1e-3, rel=0.05)
    est = _identify(records, truth)
    assert np.max(np.abs(np.array(est.weights) - W_DEFAULT)) < 1e-4
    g = np.array([est.a1, est.a2, est.b1, est.b2])
    assert np.max(np.abs(g / np.array(G_DEFAULT) - 1)) < 3e-4
    for label, (k_c, alpha) in TABLE1_ALL.items():
        c = est.creep_row(label)
        assert abs(c.k_c / k_c - 1) < 1e-4, label
        assert abs(c.alpha - alpha) < 3e-5, label
        assert 0.5e-3 < c.residual_rms < 2e-2, label     # noise-level fit, not exact


def test_output_error_removes_the_arx_noise_bias():
    """Reference: the true G (eq 21). On the 5/40/80 Hz record with 1 nm rms noise on u and
    x (seed 1), the equation-error (ARX) estimate is biased -- noise on x sits in its
    regressors -- by about 1 % (measured 1.0-1.2 % on seeds 1..20); the output-error
    refinement, started from it, is unbiased: measured 1.2e-4 worst over seeds 1..10."""
    records, _ = generate_identification_records(backend="core", noise_rms_um=0.001, seed=1)
    rec = next(r for r in records if "5/40/80" in r.label)
    true = np.array(G_DEFAULT)
    arx = np.array(identify_transfer_function(rec.u, rec.x, method="arx"))
    oe = np.array(identify_transfer_function(rec.u, rec.x))
    arx_error = np.max(np.abs(arx / true - 1))
    oe_error = np.max(np.abs(oe / true - 1))
    assert arx_error > 5e-3
    assert oe_error < 3e-4
    with pytest.raises(ValueError, match="method"):
        identify_transfer_function(rec.u, rec.x, method="ols")


def test_coupled_model_bad_records():
    r = IdentificationRecord("a", np.linspace(0, 10, 40), np.linspace(0, 4, 40))
    with pytest.raises(IdentificationInputError, match="unique"):
        identify_coupled_model(r, r, [r, r], H)
    bad = IdentificationRecord("b", np.linspace(0, 10, 40), np.linspace(0, 4, 39))
    with pytest.raises(IdentificationInputError, match="same length"):
        identify_coupled_model(bad, r, [r], H)


def test_transfer_function_output_matches_the_plant():
    t = np.arange(500) * H
    run = _run(6 * np.sin(2 * np.pi * 40 * t) + 6)
    np.testing.assert_allclose(transfer_function_output(run["u"], *G_DEFAULT), run["x"],
                               rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------
# python -m harness identify, end to end
# ---------------------------------------------------------------------------


def _printed_table(stdout):
    lines = stdout.splitlines()
    start = next(i for i, l in enumerate(lines) if l.startswith("parameter")) + 2
    rows = {}
    for line in lines[start:]:
        if line.startswith("Notes:"):
            break
        name, true, ident, abs_err, rel_err = line.rsplit(None, 4)
        rows[name.strip()] = (float(true), float(ident), rel_err)
    return rows


@pytest.mark.parametrize("backend", ["core", "fmpy"])
def test_cli_identify_end_to_end(tmp_path, backend):
    args = ["identify", "--internal-channels", "--out", str(tmp_path)]
    if backend == "core":
        args += ["--backend", "core"]          # fmpy is the default
    proc = run_harness(*args)
    assert proc.returncode == 0, proc.stderr
    assert f"backend {backend}, noise 0 nm rms" in proc.stdout
    assert "[6/6] record 5/40/80 Hz" in proc.stderr
    printed = _printed_table(proc.stdout)
    rows = list(csv.DictReader(open(tmp_path / "identification.csv")))
    names = [r["parameter"] for r in rows]
    assert names[:11] == ["w0 (fixed)"] + [f"w{j}" for j in range(1, 10)] + ["w0 + w1"]
    assert names[11:15] == ["a1", "a2", "b1", "b2"]
    assert names[15:] == [f"{p} ({lab})" for lab in TABLE1_ALL for p in ("k_c", "alpha")]
    assert list(printed) == names
    for r in rows:
        true, ident = float(r["true"]), float(r["identified"])
        assert printed[r["parameter"]][0] == pytest.approx(true, rel=1e-6)
        assert printed[r["parameter"]][1] == pytest.approx(ident, rel=1e-9, abs=1e-15)
        assert ident == pytest.approx(true, rel=1e-10, abs=1e-12), r["parameter"]
    table1 = {r["parameter"]: float(r["true"]) for r in rows}
    assert table1["k_c (1 Hz)"] == 1.0463 and table1["alpha (1 Hz)"] == 0.0002
    assert table1["k_c (10 Hz)"] == 1.0497 and table1["alpha (10 Hz)"] == -0.0085
    assert "| alpha (5/40/80 Hz) | -0.0023 |" in (tmp_path / "identification.md").read_text()


def test_cli_identify_noise_and_errors(tmp_path):
    proc = run_harness("identify", "--internal-channels", "--backend", "core", "--noise-rms", "0.001",
                    "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert "noise 1 nm rms" in proc.stdout
    rows = {r["parameter"]: r for r in csv.DictReader(open(tmp_path / "identification.csv"))}
    assert 1e-5 < abs(float(rows["k_c (1 Hz)"]["rel_error"])) < 1e-3
    for args, msg in [(["identify", "--internal-channels", "--noise-rms", "-1"],
                       "--noise-rms must be a finite number"),
                      (["list", "--noise-rms", "0.001"], "'list' does not take --noise-rms"),
                      (["identify", "extra"], "'identify' does not take extra"),
                      (["identify", "--internal-channels", "--fmu-dir", str(tmp_path)],
                       "PiezoStage.fmu")]:
        p = run_harness(*args)
        assert p.returncode == 2, (args, p.stderr)
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("python -m harness: error: ")
        assert msg in lines[0]
