"""What the report's figures say on themselves, for a reader who sees one PNG alone: what the
RLS estimates converge to (and that it is what the controller's loop really has), the symlog
scale, the units, and legends that hide no data.

Reference for the RLS claim: the closed-form gain of the chain the controller's RLS sees, from
q to y (harness.report.figures.effective_gain: the plant's G at the tone times the PI and creep
gain ratios), against the estimates of closed-loop runs on the C core."""

import numpy as np
import pytest

from harness.binding import core
from harness.report import figures
from harness.report.run import evaluate_tracking
from harness.scenarios import get_scenario
from conftest import mismatch_plant

SCENARIOS = ("mismatch_1hz", "mismatch_1_5_10hz")


def _params(scenario):
    nominal = dict(core.default_controller_params())
    nominal.update(get_scenario(scenario).controller)
    plant = dict(core.default_plant_params())
    plant.update(get_scenario(scenario).plant)
    return nominal, plant


@pytest.fixture(scope="module")
def runs():
    """{condition label: [TrackingResult]} on the C core: headline, RLS off, no preview."""
    out = {}
    for label, kw in (("headline", {}), ("RLS off", {"adaptation": False}),
                      ("no preview", {"preview": False})):
        out[label] = [evaluate_tracking(s, backend="core", **kw) for s in SCENARIOS]
    return out


@pytest.fixture
def drawn(monkeypatch):
    """The matplotlib figures the drawing functions save (kept for inspection)."""
    kept = []
    save = figures._save

    def keep(plt, fig, *args, **kwargs):
        kept.append(fig)
        return save(plt, fig, *args, **kwargs)

    monkeypatch.setattr(figures, "_save", keep)
    return kept


@pytest.mark.parametrize("scenario,freq", [("mismatch_1hz", 1.0), ("mismatch_5hz", 5.0),
                                           ("mismatch_20hz", 20.0)])
def test_rls_settles_at_the_effective_gain_not_the_plants(scenario, freq):
    """The figure's claim, measured: over the last second of a mismatch run the DC gain of the
    RLS estimate is within 1 % of the effective gain q -> y at the tone, and 6 % or more away
    from the plant's own G(1) (1.127; the effective gain is about 1.2)."""
    r = evaluate_tracking(scenario, backend="core")
    d = r.data
    last = d["time"] >= 2.0
    dc = np.mean((d["b1"] + d["b2"])[last] / (1 + d["a1"] + d["a2"])[last])
    nominal, plant = _params(scenario)
    effective = float(figures.effective_gain(nominal, plant, [freq], 5e-4)[0])
    own = (plant["tf.b1"] + plant["tf.b2"]) / (1 + plant["tf.a1"] + plant["tf.a2"])
    assert abs(dc / effective - 1) < 0.01, (dc, effective)
    assert abs(dc / own - 1) > 0.06, (dc, own)


def test_effective_gain_is_the_plants_without_mismatch():
    """Reference: with the controller's own PI and creep in the plant the chain is the plant's
    G alone, |G(e^{iwh})| evaluated here with scipy.signal.freqz."""
    from scipy.signal import freqz

    nominal, _ = _params("track_5hz")
    plant = {k: v for k, v in nominal.items() if k.startswith(("pi.", "creep."))}
    plant.update({k: v for k, v in mismatch_plant().items() if k.startswith("tf.")})
    f = np.array([1.0, 7.0, 300.0])
    _, g = freqz([0, plant["tf.b1"], plant["tf.b2"]], [1, plant["tf.a1"], plant["tf.a2"]],
                 worN=2 * np.pi * f * 5e-4)
    np.testing.assert_allclose(figures.effective_gain(nominal, plant, f, 5e-4), np.abs(g),
                               rtol=1e-12)
    plant = {**plant, **{k: 1.1 * v for k, v in nominal.items() if k.startswith("pi.w")}}
    np.testing.assert_allclose(figures.effective_gain(nominal, plant, f, 5e-4),
                               1.1 * np.abs(g), rtol=1e-12)


def _texts(fig):
    out = [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        out += [ax.get_title(loc="left"), ax.get_ylabel()]
    return "\n".join(out)


def test_rls_figure_says_what_the_estimates_converge_to_and_why(runs, drawn, tmp_path):
    nominal, plant = _params(SCENARIOS[0])
    figures.rls_figure(runs["headline"], tmp_path, nominal, [plant, plant], label="headline")
    (fig,) = drawn
    text = _texts(fig)
    assert "converging" not in fig._suptitle.get_text()
    assert "RLS does not converge to the plant's own G: it identifies the effective G" in text
    assert "PI ×1.1" in text and "One tone fixes G at its frequency" in text
    # the green band on the DC-gain panel spans the effective gains at the runs' tones
    dc_ax = next(ax for ax in fig.axes if ax.get_title(loc="left").startswith("DC gain"))
    band = [p for p in dc_ax.patches if "effective gain" in p.get_label()]
    assert len(band) == 1
    y0, y1 = band[0].get_y(), band[0].get_y() + band[0].get_height()
    gains = figures.effective_gain(nominal, plant, [1.0, 5.0, 10.0], 5e-4)
    assert y0 <= gains.min() and gains.max() <= y1 and y1 - y0 < 0.05
    assert (tmp_path / "rls_estimates.png").is_file()


def test_tracking_error_figure_explains_its_symlog_scale(runs, drawn, tmp_path):
    figures.tracking_error_figure(runs["headline"], tmp_path, label="headline")
    (fig,) = drawn
    text = _texts(fig)
    assert figures.SYMLOG_NOTE in text
    for ax in fig.axes[::2]:                   # the whole-run column
        assert ax.get_yscale() == "symlog"
        lin = ax.yaxis.get_transform().linthresh
        assert f"symlog scale: linear within ±{lin:g} nm, logarithmic beyond" \
            in ax.get_title(loc="left")


def test_tracking_period_legends_hide_no_data_and_the_zoom_has_its_unit(runs, drawn, tmp_path):
    """Every point of every error curve lies outside its panel's legend box (in display
    coordinates, after drawing), e.g. the no-preview and RLS-off peaks of the 1 Hz panel."""
    figures.tracking_period_figure(list(runs.items()), tmp_path)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    (fig,) = drawn
    canvas = FigureCanvasAgg(fig)          # the saved figure was closed: draw it again
    canvas.draw()
    renderer = canvas.get_renderer()
    errors = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("error over")]
    zooms = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("zoom")]
    assert len(errors) == len(zooms) == len(SCENARIOS)
    for ax in errors:
        box = ax.get_legend().get_window_extent(renderer)
        for line in ax.get_lines():
            xy = ax.transData.transform(line.get_xydata())
            inside = ((xy[:, 0] >= box.x0) & (xy[:, 0] <= box.x1)
                      & (xy[:, 1] >= box.y0) & (xy[:, 1] <= box.y1))
            assert not inside.any(), (ax.get_title(loc="left"), line.get_label())
    for ax in zooms:
        assert ax.get_ylabel().endswith("[µm]")


def test_run_figure_dc_gain_panel_has_its_caption(runs, drawn, tmp_path):
    nominal, plant = _params(SCENARIOS[0])
    figures.draw_scenario_figure(runs["headline"][0], tmp_path, nominal_g=nominal, plant=plant,
                                 label="run")
    (fig,) = drawn
    dc = next(ax for ax in fig.axes if ax.get_title(loc="left").startswith("DC gain"))
    title = dc.get_title(loc="left")
    assert "it settles at the effective gain q → y (band), not the plant's own G" in title
    assert any("effective gain" in p.get_label() for p in dc.patches)
