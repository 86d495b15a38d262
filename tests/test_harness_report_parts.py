"""Parts of harness/report/ on their own: progress within a run, the time series files, the
conditions and their lag error, the figures' helpers, the document renderers."""

import io
import math

import numpy as np
import pytest

from harness.masters.c_core import simulate_closed_loop_core, simulate_open_loop_core
from harness.masters.fmpy import simulate_closed_loop, simulate_open_loop
from harness.report import conditions, document, figures, run_scenario
from harness.progress import Progress
from harness.scenarios import get_scenario, load_scenarios

SHORT = """
[[scenario]]
name = "short"
extends = "mismatch_10hz"
duration = 2.5
metric_window = [1.0, 2.5]
"""


@pytest.mark.parametrize("closed", [simulate_closed_loop, simulate_closed_loop_core])
def test_progress_is_called_every_simulated_second_and_changes_nothing(closed):
    """Reference: the run without a callback. The callback sees (2000, 5000), (4000, 5000),
    (5000, 5000) for a 2.5 s run at h = 0.5 ms, and every field is bit-identical."""
    calls = []
    with_cb = closed("mismatch_10hz", duration=2.5, progress=lambda d, n: calls.append((d, n)))
    plain = closed("mismatch_10hz", duration=2.5)
    assert calls == [(2000, 5000), (4000, 5000), (5000, 5000)]
    for f in plain.dtype.names:
        assert np.array_equal(with_cb[f], plain[f]), f


@pytest.mark.parametrize("open_loop", [simulate_open_loop, simulate_open_loop_core])
def test_open_loop_progress(open_loop):
    v = 10 + 10 * np.sin(2 * np.pi * np.arange(3000) * 0.0005)
    calls = []
    with_cb = open_loop({}, v, progress=lambda d, n: calls.append((d, n)))
    assert calls == [(2000, 3000), (3000, 3000)]
    assert np.array_equal(with_cb["y"], open_loop({}, v)["y"])


def test_progress_lines_within_a_run(tmp_path):
    """With no wall-time throttle, a 2.5 s run reports 1 and 2 simulated seconds, then its
    finished line; the final second is not reported twice."""
    f = tmp_path / "s.toml"
    f.write_text(SHORT)
    stream = io.StringIO()
    run_scenario(load_scenarios([f])["short"], tmp_path / "o", backend="core", plots=False,
                 timeseries=None, stream=None, progress=stream, progress_interval=0.0)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 3
    assert lines[0].startswith("[1/1] short: 1 of 2.5 s simulated (")
    assert lines[1].startswith("[1/1] short: 2 of 2.5 s simulated (")
    assert lines[2].startswith("[1/1] short: e_rms ")


def test_progress_is_throttled_by_wall_time():
    stream = io.StringIO()
    p = Progress(1, stream, interval=3600.0)
    cb = p.within("x", 0.0005)
    for k in range(2000, 20001, 2000):
        cb(k, 20000)
    assert stream.getvalue() == ""


def test_npz_and_csv_time_series_hold_the_same_numbers(tmp_path):
    """Reference: the CSV (repr round-trips a double exactly). The .npz holds each field as
    a float64 array equal to the CSV's column; --no-timeseries writes neither."""
    f = tmp_path / "s.toml"
    f.write_text(SHORT)
    sc = load_scenarios([f])["short"]
    run_scenario(sc, tmp_path / "csv", backend="core", plots=False, stream=None, progress=None)
    run_scenario(sc, tmp_path / "npz", backend="core", plots=False, stream=None, progress=None,
                 timeseries="npz")
    run_scenario(sc, tmp_path / "none", backend="core", plots=False, stream=None,
                 progress=None, timeseries=None)
    csv_data = np.genfromtxt(tmp_path / "csv" / "short_timeseries.csv", delimiter=",",
                             names=True)
    npz = np.load(tmp_path / "npz" / "short_timeseries.npz")
    assert sorted(npz.files) == sorted(csv_data.dtype.names)
    for name in npz.files:
        assert npz[name].dtype == np.float64 and np.array_equal(npz[name], csv_data[name])
    assert [p.name for p in (tmp_path / "npz").glob("*.csv")] == ["short.csv"]
    assert sorted(p.name for p in (tmp_path / "none").iterdir()) == ["short.csv"]
    size_csv = (tmp_path / "csv" / "short_timeseries.csv").stat().st_size
    size_npz = (tmp_path / "npz" / "short_timeseries.npz").stat().st_size
    assert size_npz < 0.5 * size_csv


def test_a_large_time_series_is_announced(tmp_path, monkeypatch):
    from harness.report import jobs

    monkeypatch.setattr(jobs, "LARGE_FILE_BYTES", 1000)
    f = tmp_path / "s.toml"
    f.write_text(SHORT)
    stream = io.StringIO()
    run_scenario(load_scenarios([f])["short"], tmp_path / "o", backend="core", plots=False,
                 stream=None, progress=stream)
    assert ("  writing short_timeseries.csv, about 1 MB (--timeseries-format npz writes less than "
            "half, --no-timeseries nothing)") in stream.getvalue()


def test_closed_loop_options_do_not_apply_to_validation(tmp_path):
    with pytest.raises(ValueError, match="'validate_1hz' is a validation scenario"):
        run_scenario("validate_1hz", tmp_path, preview=False, backend="core", stream=None)


# ---------------------------------------------------------------- conditions
@pytest.mark.parametrize("name", ["mismatch_1hz", "mismatch_20hz", "mismatch_1_10_20hz"])
def test_lag_error_formula_against_numpy(name):
    """Reference: rms over whole periods of y_d(t) - y_d(t - d h), computed here on a 1 s grid
    of 1e6 points (d = 2, h = 0.5 ms); and the README's small-angle 2 pi f A d h / sqrt(2)."""
    sc = get_scenario(name)
    t = np.arange(1_000_000) / 1e6
    lag = sc.signal.evaluate(t) - sc.signal.evaluate(t - 2 * 0.0005)
    assert conditions.lag_error_rms(sc) == pytest.approx(np.sqrt(np.mean(lag ** 2)), rel=1e-6)
    small = math.sqrt(sum((2 * math.pi * f * 10 * 2 * 0.0005 / math.sqrt(2)) ** 2
                          for f in sc.signal.frequencies))
    assert conditions.lag_error_rms(sc) == pytest.approx(small, rel=2e-3)


def test_conditions_order_and_duplicates():
    keys = [c.key for c in conditions.default_conditions()]
    assert keys == ["mismatch", "mismatch_no_adaptation", "mismatch_no_preview", "nominal"]
    no_adapt = conditions.default_conditions(adaptation=False)
    assert [c.key for c in no_adapt] == ["mismatch", "mismatch_no_preview", "nominal"]
    assert no_adapt[0].role == "headline" and not no_adapt[0].adaptation_on
    jac = conditions.default_conditions(preview=False, master="jacobi")
    assert [c.key for c in jac] == ["mismatch", "mismatch_no_adaptation", "nominal"]
    notes = " ".join(conditions.describe_condition(jac[-1]))
    assert "Jacobi" in notes and "lag error" in notes and "exact tracking" not in notes


# ---------------------------------------------------------------- figure helpers
def test_decimate_keeps_the_envelope():
    rng = np.random.default_rng(3)
    t = np.arange(1_000_001) * 1e-3
    y = rng.standard_normal(t.size)
    y[123_457] = 9.0
    tt, yy = figures._decimate(t, y)
    assert tt.size <= figures.MAX_POINTS and yy.max() == 9.0
    n = (t.size // (figures.MAX_POINTS // 2)) * (figures.MAX_POINTS // 2)
    assert yy.min() == y[:n].min()
    short_t, short_y = figures._decimate(t[:100], y[:100])
    assert np.array_equal(short_y, y[:100])


@pytest.mark.parametrize("lin,top,ticks", [
    (2.4, 180.0, [-100, -10, 0, 10, 100]),
    (5.0, 1200.0, [-1000, -100, -10, 0, 10, 100, 1000]),
    (0.86, 5.0, [-1, 0, 1]),
])
def test_symlog_ticks_are_decades(lin, top, ticks):
    plt = figures._pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [-top, top])
    figures._symlog(ax, lin, np.array([-top, top]))
    assert [float(v) for v in ax.get_yticks()] == [float(v) for v in ticks]
    plt.close(fig)


# ---------------------------------------------------------------- document
def test_markdown_and_html_say_the_same_thing():
    doc = document.Document("T").add(
        document.Heading("Results & notes"),
        document.Paragraph("a `code` and **bold** <tag>"),
        document.Table(("x", "peak |v| [V]"), (("1", "2 | 3"),)),
        document.Bullets(("one", "two"), "List:"),
        document.Figure("f.png", "f.svg", "caption", "f"))
    md = document.render_markdown(doc)
    assert md.startswith("# T\n\n## Results & notes\n")
    assert "| x | peak \\|v\\| [V] |" in md and "| 1 | 2 \\| 3 |" in md
    assert "![f](f.png)" in md and "- one\n- two" in md
    html = document.render_html(doc)
    assert '<h2 id="results-notes">Results &amp; notes</h2>' in html
    assert "a <code>code</code> and <strong>bold</strong> &lt;tag&gt;" in html
    assert "<th>peak |v| [V]</th>" in html and "<td>2 | 3</td>" in html
    assert '<a href="f.svg"><img src="f.png" alt="f"></a>' in html


def test_csv_files_have_lf_line_endings_and_shortest_exact_numbers(tmp_path):
    """Every CSV a run writes ends its lines with LF only, and the time series writes each
    value as Python's repr of the double: the shortest text that reads back as the same
    double (the time column of k h at h = 0.5 ms reads 0.0005, 0.001, ..., never the 17-digit
    0.00050000000000000001). Reference: float(text) == value for every cell, and repr itself
    (the shortest round-tripping form, Python's documented float repr)."""
    f = tmp_path / "s.toml"
    f.write_text(SHORT)
    sc = load_scenarios([f])["short"]
    run_scenario(sc, tmp_path / "o", backend="core", plots=False, stream=None, progress=None)
    series_path = tmp_path / "o" / "short_timeseries.csv"
    for path in (series_path, tmp_path / "o" / "short.csv"):
        raw = path.read_bytes()
        assert b"\r" not in raw and raw.endswith(b"\n"), path.name
    lines = series_path.read_text().splitlines()
    header = lines[0].split(",")
    assert header[0] == "time"
    rows = [line.split(",") for line in lines[1:]]
    assert len(rows) == 5000
    assert [r[0] for r in rows[:4]] == ["0.0", "0.0005", "0.001", "0.0015"]
    run_scenario(sc, tmp_path / "n", backend="core", plots=False, stream=None, progress=None,
                 timeseries="npz")
    npz = np.load(tmp_path / "n" / "short_timeseries.npz")
    for j, name in enumerate(header):
        values = npz[name]
        texts = [r[j] for r in rows]
        assert texts == [repr(float(x)) for x in values], name
        assert all(float(t) == x for t, x in zip(texts, values.tolist())), name
