"""What is drawn: one figure per question, each saved as a 150 dpi PNG and an SVG.

Main job (:func:`draw_main_figures`):

* ``headline``: our e_rms next to the paper's per reference (log scale);
* ``tracking_error``: the headline's error over the whole run (the metric
  window shaded, symmetric-log scale so the start-up transient and the
  steady state both show) and a zoom on the metric window;
* ``tracking_period``: over one period of each reference, y_d and y [µm],
  a zoom on the steepest zero crossing (where a late output shows) and the
  error [nm] of every mismatch condition;
* ``control_voltage``: the voltage over one period, with its peak over the run;
* ``rls_estimates``: the RLS estimates converging (with the DC gain and the
  prediction error), when the headline adapts;
* ``user_tracking_error``: as ``tracking_error``, for the user's scenarios;
* ``hysteresis``: y against v over the last period of each validation input,
  both models;
* ``creep``: what the creep block adds (coupled minus Hammerstein) over the
  run: its per-period mean (the drift) and range;
* ``stage_use_<scenario>``: a stage-use scenario under both laws (y_d and y, the error,
  est.a1 .. est.b2 with est.adapting shaded) on a symmetric-log time axis around its last
  motion, so a minute's hold and a 10 ms move both read (:func:`stage_use_figure`).

``run SCENARIO`` draws one figure (:func:`draw_scenario_figure`).

The validation figures compare two models, not a model with data, and say so
in their titles.  The nominal-model condition (round-off error by construction)
is a table row only.

matplotlib is imported on first use, with the Agg backend.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np

from ..loop.metrics import window_mask
from ..loop.profiles import motions
from ..scenarios import reference_label

__all__ = [
    "DPI",
    "FigureFile",
    "draw_main_figures",
    "draw_scenario_figure",
    "headline_figure",
    "tracking_error_figure",
    "tracking_period_figure",
    "control_voltage_figure",
    "rls_figure",
    "hysteresis_figure",
    "creep_figure",
    "stage_use_figure",
    "draw_stage_use_figures",
    "STAGE_USE_FIGURES",
]

DPI = 150
#: Most points drawn per line; longer series are drawn as their min/max envelope.
MAX_POINTS = 4000
NM = "nm"
UM = "µm"
MINUS = "−"


@dataclass(frozen=True)
class FigureFile:
    """A saved figure: its name, the question it answers, and its files."""

    name: str
    caption: str
    png: Path
    svg: Path

    @property
    def files(self):
        return [self.png, self.svg]


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------

def _pyplot():
    """pyplot on the Agg backend. matplotlib is imported here, when a figure is drawn: the
    build imports this package without it, and it costs about 1 s at import."""
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    return plt


def _style(plt):
    plt.rcParams.update({
        "font.size": 8.5, "axes.titlesize": 9, "axes.labelsize": 8.5, "legend.fontsize": 7.5,
        "xtick.labelsize": 7.5, "ytick.labelsize": 7.5, "axes.grid": True, "grid.alpha": 0.3,
        "axes.spines.top": False, "axes.spines.right": False, "svg.hashsalt": "piezo",
        "svg.fonttype": "none", "lines.linewidth": 0.9,
    })


def _save(plt, fig, out_dir, name, caption, title=None, layout=True):
    """Title, lay out, save ``name.png`` (150 dpi) and ``name.svg``, close."""
    if title:
        fig.suptitle(title, fontsize=10, fontweight="bold")
    if layout:
        fig.tight_layout()
    out_dir = Path(out_dir)
    png, svg = out_dir / f"{name}.png", out_dir / f"{name}.svg"
    fig.savefig(png, dpi=DPI, metadata={"Software": None})
    fig.savefig(svg, metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return FigureFile(name, caption, png, svg)


def _decimate(t, y, max_points=MAX_POINTS):
    """At most ``max_points`` pairs: the min/max envelope of equal bins for a long series."""
    t, y = np.asarray(t), np.asarray(y)
    if t.size <= max_points:
        return t, y
    bins = max_points // 2
    n = (t.size // bins) * bins
    tb = t[:n].reshape(bins, -1)
    yb = y[:n].reshape(bins, -1)
    tt = np.repeat(tb[:, 0], 2)
    yy = np.column_stack([yb.min(axis=1), yb.max(axis=1)]).ravel()
    return tt, yy


def _period(spec):
    """Seconds of one period of the slowest tone; ``nan`` for a table reference."""
    sig = spec.signal
    freqs = [f for f, a in zip(sig.frequencies, sig.amplitudes) if f > 0 and a != 0]
    if not freqs:
        return math.nan
    return 1.0 / min(freqs)


def _last_period(time, spec, at_least=0.05):
    """Mask of the run's last period of the slowest tone (last 20 % for a table)."""
    end = time[-1] + spec.step_size
    span = _period(spec)
    if not math.isfinite(span):
        span = 0.2 * spec.duration
    span = min(max(span, at_least), spec.duration)
    mask = time >= end - span - 1e-12
    first = int(np.argmax(mask))
    if first > 0:
        mask[first - 1] = True       # one sample more closes a loop drawn over the period
    return mask


def _grid(plt, n, cols=3, width=3.3, height=2.4, **kw):
    cols = min(cols, n)
    rows = int(math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows + 0.5),
                             squeeze=False, **kw)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    return fig, axes


def _title(r):
    """Panel title: reference and scenario name."""
    return f"{reference_label(r.spec)}  ({r.scenario})" if r.spec is not None else r.scenario


def _decade_up(x):
    """The smallest power of ten that is >= x (x > 0)."""
    return 10.0 ** math.ceil(math.log10(x) - 1e-12)


def _symlog(ax, linthresh, values):
    """A symmetric-log y axis, linear within ±linthresh, with readable ticks.

    ``linthresh`` is rounded up to a power of ten; ticks at 0, ±linthresh and the
    decades above it, labelled as plain numbers, so the ticks near zero do not pile up
    as they do with matplotlib's default locator.
    """
    import matplotlib.ticker as mticker        # matplotlib: only once a figure is drawn

    lin = _decade_up(linthresh)
    ax.set_yscale("symlog", linthresh=lin, linscale=1.0)
    top = float(np.nanmax(np.abs(values))) if np.size(values) else lin
    decades = [lin]
    while decades[-1] * 10 <= top * 1.0001:
        decades.append(decades[-1] * 10)
    step = -(-len(decades) // 4)             # at most 4 decades labelled on each side
    ticks = [0.0] + decades[::step]
    ticks = sorted({-x for x in ticks} | set(ticks))
    ax.yaxis.set_major_locator(mticker.FixedLocator(ticks))
    ax.yaxis.set_minor_locator(mticker.NullLocator())
    ax.yaxis.set_major_formatter(mticker.FuncFormatter(
        lambda v, _: "0" if v == 0 else f"{v:g}".replace("-", MINUS)))
    return lin


def _moving_average(y, k):
    """Centred moving average over k samples (edges averaged over what exists)."""
    if k <= 1 or y.size < k:
        return y
    c = np.convolve(y, np.ones(k), mode="same")
    n = np.convolve(np.ones(y.size), np.ones(k), mode="same")
    return c / n


def _shade_window(ax, window, label=True):
    ax.axvspan(window[0], window[1], color="tab:green", alpha=0.09, lw=0,
               label="metric window" if label else None)


# ---------------------------------------------------------------------------
# tracking
# ---------------------------------------------------------------------------

def headline_figure(results, out_dir, name="headline", label="ours"):
    """Bar chart, log scale: our e_rms next to the paper's for each reference.

    Parameters
    ----------
    results : list of TrackingResult
        The headline condition (paper values needed).
    out_dir : str or Path
    name : str
    label : str
        What "ours" is (the condition's label).
    """
    plt = _pyplot()
    _style(plt)
    rs = [r for r in results if r.has_paper]
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    x = np.arange(len(rs))
    ours = np.array([r.e_rms_um * 1e3 for r in rs])
    paper = np.array([r.paper_e_rms_um * 1e3 for r in rs])
    w = 0.38
    ax.bar(x - w / 2, paper, w, color="0.62", label="paper, Tables 4/5 (real stage, measured)")
    ax.bar(x + w / 2, ours, w, color="tab:blue", label=f"ours: {label}")
    ax.set_yscale("log")
    for xi, o, p in zip(x, ours, paper):
        ax.annotate(f"{o:.3g} nm\n×{o / p:.2g}", (xi + w / 2, o), textcoords="offset points",
                    xytext=(0, 2), ha="center", va="bottom", fontsize=7)
        ax.annotate(f"{p:.4g}", (xi - w / 2, p), textcoords="offset points", xytext=(0, 2),
                    ha="center", va="bottom", fontsize=7, color="0.3")
    ax.set_xticks(x, [reference_label(r.spec) for r in rs])
    ax.set_xlabel("reference (10 µm per tone)")
    ax.set_ylabel(f"tracking error e_rms [{NM}], log scale")
    lo = min(ours.min(), paper.min()) / 3
    hi = max(ours.max(), paper.max()) * 6
    ax.set_ylim(lo, hi)
    ax.grid(axis="x", visible=False)
    ax.legend(loc="upper left", frameon=False)
    caption = ("Headline: tracking error e_rms over the metric window, ours next to the paper's "
               "measured values, one pair of bars per reference (log scale; ×: ours / paper).")
    return _save(plt, fig, out_dir, name, caption,
                 "Tracking error: ours vs the paper (Tables 4/5)")


def _error_panels(ax_full, ax_zoom, r, first=False):
    """Whole run on a symmetric-log scale with the window shaded; the window alone, linear."""
    d, sc = r.data, r.spec
    t = d["time"]
    err = (d["y_d"] - d["y"]) * 1e3
    e_rms = r.e_rms_um * 1e3
    tt, ee = _decimate(t, err)
    ax_full.plot(tt, ee, color="tab:red", lw=0.6)
    _shade_window(ax_full, sc.metric_window, first)
    lin = _symlog(ax_full, max(2 * e_rms, 1e-9), ee)
    ax_full.set_ylabel(f"y_d {MINUS} y [{NM}], symlog")
    ax_full.set_title(f"{_title(r)}: whole run\nsymlog scale: linear within ±{lin:g} {NM}, "
                      f"logarithmic beyond", loc="left")
    win = window_mask(t, sc.metric_window, sc.step_size)
    tw, ew = _decimate(t[win], err[win])
    ax_zoom.plot(tw, ew, color="tab:red", lw=0.4, alpha=0.45, label="error")
    k = max(1, int(round(0.01 / sc.step_size)))
    tm, em = _decimate(t[win], _moving_average(err, k)[win])
    ax_zoom.plot(tm, em, color="darkred", lw=1.0, label="10 ms moving average")
    for s in (1, -1):
        ax_zoom.axhline(s * e_rms, color="k", lw=0.8, ls="--",
                        label=f"± e_rms = {e_rms:.3g} {NM}" if s == 1 else None)
    ax_zoom.set_xlim(sc.metric_window)
    ax_zoom.set_title(f"metric window [{sc.metric_window[0]:g}, {sc.metric_window[1]:g}) s",
                      loc="left")
    if first:
        ax_zoom.legend(loc="upper right", frameon=True, framealpha=0.85, ncol=3)
    else:
        ax_zoom.legend(handles=ax_zoom.get_lines()[2:3], loc="upper right", frameon=True,
                       framealpha=0.85)
    ax_zoom.set_ylabel(f"[{NM}]")


def tracking_error_figure(results, out_dir, name="tracking_error", label=""):
    """The tracking error over time: whole run (window shaded) and the metric window zoomed."""
    plt = _pyplot()
    _style(plt)
    n = len(results)
    fig, axes = plt.subplots(n, 2, figsize=(10, 1.95 * n + 1.0), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1.3]})
    for i, r in enumerate(results):
        _error_panels(axes[i, 0], axes[i, 1], r, first=(i == 0))
    axes[0, 0].legend(loc="upper right", frameon=True, framealpha=0.8)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.text(0.5, 1 - 0.45 / fig.get_figheight(), SYMLOG_NOTE, ha="center", va="top",
             fontsize=7.5, color="0.2")
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.7 / fig.get_figheight()))
    caption = ("Tracking error y_d − y over time. Left: the whole run on a symmetric-log scale "
               "(linear near zero, logarithmic beyond) so the start-up transient and the steady "
               "state both show; the metric window is shaded. Right: the metric window alone, "
               "linear: the error, its 10 ms moving average (what is not sensor noise) and "
               "± e_rms.")
    return _save(plt, fig, out_dir, name, caption, f"Tracking error: {label}", layout=False)


#: the symmetric-log scale of the whole-run error panels, said on the figures that use it
SYMLOG_NOTE = ("Left, the whole run: symmetric-log scale, linear near zero (within the ± value "
               "in each title) and logarithmic beyond, so the start-up transient (up to 100s of "
               "nm)\nand the steady state (a few nm) both show; the metric window is shaded. "
               "Right: the metric window alone, linear.")


def _steepest_crossing(t, y_d, margin=0.0):
    """Time of the steepest zero crossing of y_d (around its mean), at least ``margin``
    from both ends of t when there is one."""
    yc = y_d - y_d.mean()
    cross = np.flatnonzero(np.signbit(yc[:-1]) != np.signbit(yc[1:]))
    inside = cross[(t[cross] - margin >= t[0]) & (t[cross] + margin <= t[-1])]
    cross = inside if inside.size else cross
    if cross.size == 0:
        return t[t.size // 2]
    slope = np.abs(yc[cross + 1] - yc[cross])
    return t[cross[int(np.argmax(slope))]]


def tracking_period_figure(by_condition, out_dir, name="tracking_period"):
    """One period of each reference: y_d and y [µm], a zoom where a lag shows, the error [nm].

    Parameters
    ----------
    by_condition : list of (str, list of TrackingResult)
        Condition labels and their results, same references in the same order;
        the first is the headline.
    """
    plt = _pyplot()
    _style(plt)
    first = by_condition[0][1]
    n = len(first)
    fig, axes = plt.subplots(n, 3, figsize=(11.5, 2.1 * n + 0.6), squeeze=False,
                             gridspec_kw={"width_ratios": [1.35, 0.8, 1.35]})
    colors = ["tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:gray"]
    for i, r0 in enumerate(first):
        d, sc = r0.data, r0.spec
        sel = _last_period(d["time"], sc)
        t = d["time"][sel]
        a, z, b = axes[i]
        outputs = [(lab, res[i], colors[j % len(colors)])
                   for j, (lab, res) in enumerate(by_condition)]
        errors = []
        # the zoom: the steepest zero crossing, where a late output shows most
        half = 6 * sc.step_size
        tc = _steepest_crossing(t, d["y_d"][sel], half)
        zm = (d["time"] >= tc - half - 1e-12) & (d["time"] <= tc + half + 1e-12)
        a.axvspan(tc - half, tc + half, color="0.8", lw=0)
        a.plot(t, d["y_d"][sel], color="k", lw=1.6, label="y_d (reference)")
        z.plot(d["time"][zm], d["y_d"][zm], color="k", lw=1.6, marker="o", ms=2.5,
               label="y_d (reference)")
        for lab, r, col in outputs:
            a.plot(t, r.data["y"][sel], color=col, lw=0.9, ls="--", label=f"y, {lab}")
            z.plot(d["time"][zm], r.data["y"][zm], color=col, lw=1.0, ls="--",
                   label=f"y, {lab}")
            e = (r.data["y_d"] - r.data["y"])[sel] * 1e3
            b.plot(t, e, color=col, lw=0.9, label=f"{lab} {r.e_rms_um * 1e3:.3g}")
            errors.append(e)
        a.set_ylabel(f"y_d, y [{UM}]")
        a.set_title(f"{_title(r0)}: last period", loc="left")
        z.set_title(f"zoom (grey band): ±{half * 1e3:g} ms", loc="left")
        z.set_ylabel(f"y_d, y [{UM}]")
        z.xaxis.set_major_locator(plt.MaxNLocator(3))
        b.set_ylabel(f"y_d {MINUS} y [{NM}]")
        b.set_title(f"error over the period (legend: e_rms [{NM}])", loc="left")
        # the legend gets a band of its own above the curves, so it hides no peak
        lo = min(float(np.min(x)) for x in errors)
        hi = max(float(np.max(x)) for x in errors)
        span = max(hi - lo, 1e-9)
        b.set_ylim(lo - 0.05 * span, hi + 0.42 * span)
        b.legend(loc="upper center", ncol=len(outputs), frameon=False, fontsize=6.5,
                 handlelength=1.2, columnspacing=0.9, borderaxespad=0.2)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    _figure_legend(fig, [axes[0, 1]])
    fig.tight_layout(rect=(0, 0.02, 1, 0.97))
    caption = ("One period of each reference at the end of the run, for every mismatch "
               "condition. Left: reference y_d and stage output y [µm]; at full scale they "
               "overlap. Middle: a zoom on the steepest zero crossing (grey band; dots: the "
               "samples of y_d), where a late output shows most. Right: the error [nm] over "
               "the period: what adaptation and preview each contribute.")
    return _save(plt, fig, out_dir, name, caption,
                 "Reference vs output over one period, and the error of each condition",
                 layout=False)


def _num_text(x):
    """A number with a real minus sign."""
    return f"{x:g}".replace("-", MINUS)


def control_voltage_figure(results, out_dir, name="control_voltage", label="", limits=None):
    """The control voltage over one period of each reference, with its peak over the run.

    Parameters
    ----------
    limits : tuple of float, optional
        The controller's voltage limits (said in the title).
    """
    plt = _pyplot()
    _style(plt)
    fig, axes = _grid(plt, len(results), height=2.5)
    for ax, r in zip(axes.flat, results):
        d = r.data
        sel = _last_period(d["time"], r.spec)
        ax.plot(d["time"][sel], d["v"][sel], color="tab:green", lw=1.0)
        k = int(np.argmax(np.abs(d["v"])))
        peak = abs(float(d["v"][k]))
        ax.set_title(f"{reference_label(r.spec)}: last period\npeak |v| over the run "
                     f"{peak:.3g} V (t = {d['time'][k]:.3g} s)", loc="left")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("v [V]")
        ax.yaxis.set_major_formatter(plt.FuncFormatter(lambda v, _: _num_text(v)))
    title = f"Control voltage: {label}"
    if limits is not None and all(math.isfinite(x) for x in limits):
        title += f" (limits {_num_text(limits[0])} … {_num_text(limits[1])} V)"
    caption = ("Control voltage v over one period of each reference at the end of the run; "
               "each panel gives the peak |v| over the whole run, the title the controller's "
               "voltage limits.")
    return _save(plt, fig, out_dir, name, caption, title)


_G_NAMES = ("a1", "a2", "b1", "b2")


def _dc_gain(a1, a2, b1, b2):
    with np.errstate(divide="ignore", invalid="ignore"):
        return (b1 + b2) / (1.0 + a1 + a2)


def _pi_gain(params):
    """w0 + Σ w_j: the PI model's steepest slope, by which a uniform scaling of the weights
    scales its output."""
    m = int(params.get("pi.m", 0)) or sum(1 for k in params if k.startswith("pi.w["))
    return params.get("pi.w0", math.nan) + sum(params.get(f"pi.w[{j}]", 0.0)
                                                for j in range(1, m + 1))


def effective_gain(nominal, plant, freqs, h):
    """The gain the controller's RLS identifies at each tone: |effective G| from the control
    q to the displacement y, the plant's chain behind the controller's inverse of its nominal
    one (the loop "sees" C_p G_p P_p P_n⁻¹ C_n⁻¹, and C_n⁻¹ commutes with G_p)::

        |G_p(e^{iωh})| · c_PI · (k_c,p / k_c,n) · |(1 − e^{−iωh}) / h|^(α_p − α_n)

    with c_PI the ratio of the PI models' w0 + Σ w_j (exact when the plant's weights are the
    nominal ones times c_PI) and the G-L creep operators' gain ratio at ω = 2π f.

    Parameters
    ----------
    nominal, plant : dict
        The controller's and the plant's parameters by FMU variable name (``tf.*``,
        ``pi.*``, ``creep.k_c``, ``creep.alpha``).
    freqs : sequence of float
        Tone frequencies [Hz].
    h : float
        Sample period [s].

    Returns
    -------
    ndarray
        One gain per frequency.
    """
    w = 2 * np.pi * np.asarray(freqs, dtype=float) * h
    z1 = np.exp(-1j * w)
    a1, a2, b1, b2 = (plant.get(f"tf.{n}", nominal[f"tf.{n}"]) for n in _G_NAMES)
    g = np.abs((b1 * z1 + b2 * z1 ** 2) / (1 + a1 * z1 + a2 * z1 ** 2))
    c_pi = _pi_gain({**nominal, **{k: v for k, v in plant.items() if k.startswith("pi.")}}) \
        / _pi_gain(nominal)
    k_ratio = plant.get("creep.k_c", nominal["creep.k_c"]) / nominal["creep.k_c"]
    d_alpha = plant.get("creep.alpha", nominal["creep.alpha"]) - nominal["creep.alpha"]
    creep = np.abs((1 - z1) / h) ** d_alpha
    return g * c_pi * k_ratio * creep


def _tones(spec):
    sig = spec.signal
    return [f for f, a in zip(sig.frequencies, sig.amplitudes) if f > 0 and a != 0]


def _effective_band(ax, runs, nominal, plants):
    """Shade the effective gain at the tones of the runs (see effective_gain); return its
    (lo, hi), or None when no run is a sum of tones."""
    gains = [effective_gain(nominal, pl, _tones(r.spec), r.spec.step_size)
             for r, pl in zip(runs, plants) if _tones(r.spec)]
    if not gains:
        return None
    allg = np.concatenate(gains)
    lo, hi = float(allg.min()), float(allg.max())
    half = max(0.5 * (hi - lo), 0.002 * abs(hi))
    mid = 0.5 * (lo + hi)
    ax.axhspan(mid - half, mid + half, color="tab:green", alpha=0.22, lw=0,
               label="effective gain q → y (what RLS identifies)")
    return lo, hi


def _robust_limits(values, refs, start=0):
    """y limits that hold every series from sample ``start`` on and the reference lines."""
    v = np.concatenate([np.asarray(x)[start:] for x in values] + [np.asarray(refs, float)])
    v = v[np.isfinite(v)]
    lo, hi = float(v.min()), float(v.max())
    # at least 1 % of the values' size: a constant estimate is a flat line, not round-off
    pad = max(0.08 * (hi - lo), 0.01 * max(abs(lo), abs(hi)), 1e-12)
    return lo - pad, hi + pad


def _rls_series(r):
    """The six panels' signals of one run: a1..b2, DC gain, prediction error rms [nm]."""
    d, h = r.data, r.spec.step_size
    k = max(1, int(round(0.02 / h)))
    pe_rms = np.sqrt(np.convolve(d["pred_error"] ** 2, np.ones(k) / k, mode="same")) * 1e3
    out = {p: d[p] for p in _G_NAMES}
    out["dc"] = _dc_gain(d["a1"], d["a2"], d["b1"], d["b2"])
    out["pred"] = pe_rms
    return out


def rls_figure(results, out_dir, nominal, plants, name="rls_estimates", label=""):
    """The RLS estimates of G over time, with the nominal start and the plant's G.

    Parameters
    ----------
    results : list of TrackingResult
    nominal : dict
        The controller's nominal G (``tf.a1`` ... ``tf.b2``).
    plants : list of dict
        Each run's plant parameters (``tf.a1`` ... ``tf.b2`` used), in the order of ``results``.
    """
    plt = _pyplot()
    _style(plt)
    fig, axes = plt.subplots(2, 3, figsize=(10.5, 6.6), squeeze=False)
    panels = list(_G_NAMES) + ["dc", "pred"]
    titles = {p: f"estimate of {p}" for p in _G_NAMES}
    titles.update({"dc": "DC gain of the estimated G, (b1 + b2)/(1 + a1 + a2)",
                   "pred": f"prediction error (rms over 20 ms) [{NM}]"})
    g_nom = [nominal[f"tf.{n}"] for n in _G_NAMES]
    g_plants = sorted({tuple(pl.get(f"tf.{n}", nominal[f"tf.{n}"]) for n in _G_NAMES)
                       for pl in plants})
    runs = [(r, _rls_series(r)) for r in results]
    for j, (p, ax) in enumerate(zip(panels, axes.flat)):
        kept = []
        for i, (r, ser) in enumerate(runs):
            skip = int(round(0.05 / r.spec.step_size))
            tt, yy = _decimate(r.data["time"], ser[p])
            ax.plot(tt, yy, color=f"C{i % 10}", lw=0.8, label=reference_label(r.spec))
            kept.append(ser[p][skip:])
        ax.set_title(titles[p], loc="left")
        if p == "pred":
            ax.set_yscale("log")
            continue
        if p in _G_NAMES:
            nom, truth = g_nom[j], [g[j] for g in g_plants]
        else:
            nom, truth = float(_dc_gain(*g_nom)), [float(_dc_gain(*g)) for g in g_plants]
            band = _effective_band(ax, results, nominal, plants)
            truth = truth + (list(band) if band else [])
        ax.axhline(nom, color="k", ls=":", lw=1.1, label="nominal model (start)")
        for k, tv in enumerate(truth[:len(g_plants)]):
            ax.axhline(tv, color="k", ls="--", lw=0.9,
                       label="plant's own G (not what RLS sees)" if k == 0 else None)
        ax.set_ylim(*_robust_limits(kept, [nom] + truth, 0))
    handles = {}
    for ax in (axes[0, 0], axes[1, 1]):
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center", ncol=5,
               frameon=False, fontsize=7.5)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    explanation = rls_explanation(nominal, plants)
    fig.text(0.5, 0.925, explanation, ha="center", va="top", fontsize=7.5, color="0.2",
             linespacing=1.35)
    fig.tight_layout(rect=(0, 0.075, 1, 0.845))
    caption = ("The RLS estimates of G = (b1 z⁻¹ + b2 z⁻²)/(1 + a1 z⁻¹ + a2 z⁻²) over time for "
               "each reference, starting from the nominal model (dotted); dashed: the plant's "
               "own G. " + explanation.replace("\n", " ") + " The first 50 ms are outside "
               "the vertical range.")
    return _save(plt, fig, out_dir, name, caption, f"RLS estimates of G: {label}",
                 layout=False)


def rls_explanation(nominal, plants):
    """What the RLS estimates converge to, and why (three lines, for the figure itself)."""
    ratios = sorted({round(_pi_gain({**nominal, **{k: v for k, v in pl.items()
                                                   if k.startswith("pi.")}})
                           / _pi_gain(nominal), 4) for pl in plants})
    pi = "/".join(f"×{c:.3g}" for c in ratios)
    return ("RLS does not converge to the plant's own G: it identifies the effective G from the "
            "controller's output q to the measured y, that is\nthe plant's G times what the "
            "controller's inverse PI and inverse creep leave of the plant's PI and creep (here: "
            f"PI {pi}, and the creep mismatch).\nIts gain at the tones (green band, DC-gain "
            "panel) settles within a fraction of a second. One tone fixes G at its frequency "
            "only, so a1, a2, b1, b2\ndrift along the directions it leaves unexcited; three "
            "tones (the mixes) fix all four.")


# ---------------------------------------------------------------------------
# validation (model vs model)
# ---------------------------------------------------------------------------

_MODEL_VS_MODEL = "model vs model (coupled vs Hammerstein), no measured data"


def _loop_panel(ax, r, legend=False):
    """y against v over the last period of the input, both models."""
    c, hm = r.coupled, r.hammerstein
    sel = _last_period(c["time"], r.spec)
    ax.plot(c["v"][sel], c["y"][sel], color="tab:blue", lw=0.9, label="coupled (with creep)")
    ax.plot(hm["v"][sel], hm["y"][sel], color="tab:orange", lw=0.9, ls="--",
            label="Hammerstein (no creep)")
    ax.set_xlabel("v [V]")
    ax.set_ylabel(f"y [{UM}]")
    if legend:
        ax.legend(loc="upper left", frameon=True, framealpha=0.8)


def _per_period(t, y, period, h):
    """Mean, min and max of y over consecutive whole periods (the drift and its ripple)."""
    k = max(1, int(round(period / h)))
    n = (y.size // k) * k
    yb = y[:n].reshape(-1, k)
    tb = t[:n].reshape(-1, k)
    return tb.mean(axis=1), yb.mean(axis=1), yb.min(axis=1), yb.max(axis=1)


def _creep_panel(ax, r):
    """Coupled minus Hammerstein over the run: per-period mean and range, or as is."""
    c, hm = r.coupled, r.hammerstein
    t, diff = c["time"], c["y"] - hm["y"]
    period = _period(r.spec)
    h = r.spec.step_size
    if math.isfinite(period) and period / h >= 4 and period < r.spec.duration / 4:
        tm, mean, lo, hi = _per_period(t, diff, period, h)
        ax.fill_between(tm, lo, hi, color="tab:purple", alpha=0.25, lw=0,
                        label="range within each period")
        ax.plot(tm, mean, color="tab:purple", lw=1.2, label="mean over each period")
    else:
        tt, dd = _decimate(t, diff)
        ax.plot(tt, dd, color="tab:purple", lw=0.8, label="coupled − Hammerstein, as is")
    ax.axhline(0, color="k", lw=0.6)
    _shade_window(ax, r.spec.metric_window, True)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"y_coupled {MINUS} y_Hammerstein [{UM}]")


def _figure_legend(fig, axes):
    """One legend for the figure, below the panels, each label once."""
    handles = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center",
               ncol=len(handles), frameon=False)


def hysteresis_figure(results, out_dir, name="hysteresis"):
    """y against v over the last period of each validation input, both models."""
    plt = _pyplot()
    _style(plt)
    fig, axes = _grid(plt, len(results), width=3.2, height=2.7)
    for i, (ax, r) in enumerate(zip(axes.flat, results)):
        _loop_panel(ax, r, legend=(i == 0))
        ax.set_title(f"{reference_label(r.spec)} input ({r.scenario})", loc="left")
    caption = ("Hysteresis loops: stage displacement y against the input voltage v over the "
               "last period of each validation input (the slowest tone's period for several "
               "tones), coupled model (solid) and Hammerstein model (dashed). Both are models: "
               "the paper's loops are measured, and we have no measured data.")
    return _save(plt, fig, out_dir, name, caption, f"Hysteresis, {_MODEL_VS_MODEL}")


def creep_figure(results, out_dir, name="creep"):
    """What the creep block adds over the run: coupled minus Hammerstein output."""
    plt = _pyplot()
    _style(plt)
    fig, axes = _grid(plt, len(results), width=3.2, height=2.5)
    for ax, r in zip(axes.flat, results):
        _creep_panel(ax, r)
        ax.set_title(f"{reference_label(r.spec)} input: C − H e_rms {r.diff_e_rms_um:.3g} {UM}",
                     loc="left")
    _figure_legend(fig, axes.flat)
    fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    caption = ("Creep response: what the creep block adds, the coupled model's output minus the "
               "Hammerstein model's on the same input, over the whole run from rest. The line is "
               "the mean over each period of the input (the slow creep drift), the band its range "
               "within the period (an input whose period is too long for that is drawn as is). "
               "Model vs model: no measured data.")
    return _save(plt, fig, out_dir, name, caption, f"Creep response, {_MODEL_VS_MODEL}",
                 layout=False)


# ---------------------------------------------------------------------------
# stage use
# ---------------------------------------------------------------------------

#: the stage-use scenarios the report draws (each under both laws)
STAGE_USE_FIGURES = ("stage_step10_hold60s", "stage_scan10hz_dwell10s", "stage_hold5um_100nm",
                     "stage_staircase")
_LAW_STYLE = {"ours": dict(color="tab:blue", ls="-", lw=0.9),
              "paper": dict(color="tab:orange", ls="--", lw=0.9)}
_LAW_LABEL = {"ours": "ours (defaults)", "paper": "paper's law"}


def _runs(mask):
    """``(start, stop)`` index pairs of the runs of True in a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2], edges[1::2]))


def _time_symlog(ax, linthresh, lo, hi):
    """A symmetric-log time axis over ``[lo, hi]`` around 0 (the last motion's start): linear
    within ±linthresh, ticks at 0, ±linthresh times the decades and at both ends."""
    import matplotlib.ticker as mticker        # matplotlib: only once a figure is drawn

    ax.set_xscale("symlog", linthresh=linthresh, linscale=1.0)
    ax.set_xlim(lo, hi)
    ticks = {0.0, lo, hi}
    x = linthresh
    while x <= max(-lo, hi) * 1.0001:
        ticks |= {v for v in (-x, x) if lo <= v <= hi}
        x *= 10.0
    span = max(-lo, hi)
    ticks = sorted(v for v in ticks if v in (lo, hi, 0.0) or
                   min(abs(v - lo), abs(v - hi)) > 0.15 * max(abs(v), linthresh))
    ax.xaxis.set_major_locator(mticker.FixedLocator(ticks))
    ax.xaxis.set_minor_locator(mticker.NullLocator())
    ax.xaxis.set_major_formatter(mticker.FuncFormatter(
        lambda v, _: "0" if v == 0 else f"{v:.3g}".replace("-", MINUS)))
    return span


def stage_use_figure(pair, out_dir, nominal_g, plant=None, name=None):
    """One stage-use scenario under both laws, around its last motion (x = t − t_0 on a
    symmetric-log axis, linear within ±linthresh: a 10 ms move and the minute before it).

    Parameters
    ----------
    pair : dict
        ``{"ours": StageUseRun, "paper": StageUseRun}`` with their rows.
    out_dir : str or Path
    nominal_g : dict
        The controller's nominal ``tf.*``.
    plant : dict, optional
        The plant's parameters (its own ``tf.*`` drawn as a reference).
    """
    plt = _pyplot()
    _style(plt)
    ours = pair["ours"]
    sc = ours.spec
    h = sc.step_size
    moved = motions(sc.signal)
    last = moved[-1][1] if moved else None
    t0 = last.first * h if last is not None else 0.0
    scan = last is not None and last.kind == "scan"
    # linear over the last frame of a scan, over the first 20 ms of a move
    linthresh = last.samples * h if scan else 0.02
    fig, axes = plt.subplots(4, 1, figsize=(8.2, 9.2), sharex=True)
    a_y, a_e, a_a, a_b = axes
    for law in ("ours", "paper"):
        r = pair[law]
        d = r.data
        x = d["time"] - t0
        st = _LAW_STYLE[law]
        # every row (communication points: dense around motions, 10 ms apart in holds)
        if law == "ours":
            a_y.plot(x, d["y_d"], color="k", lw=1.4, label="y_d", drawstyle="steps-post")
        a_y.plot(x, d["y"], label=f"y, {_LAW_LABEL[law]}", **st)
        err = np.maximum(np.abs(d["y_d"] - d["y"]) * 1e3, 0.1)
        moves = ", ".join(f"{m.worst:.3g}" for m in r.moves)
        a_e.plot(x, err, label=f"{_LAW_LABEL[law]}" + (f" (moves: {moves} {UM})" if moves else ""), **st)
        for field, ax in (("a1", a_a), ("a2", a_a), ("b1", a_b), ("b2", a_b)):
            ax.plot(x, d[field], drawstyle="steps-post",
                    label=f"est.{field}, {law}" if field in ("a1", "b1") else None,
                    **{**st, "color": st["color"] if field in ("a1", "b1") else
                       ("tab:cyan" if law == "ours" else "tab:red")})
    for field, ax in (("a1", a_a), ("a2", a_a), ("b1", a_b), ("b2", a_b)):
        nom = nominal_g.get(f"tf.{field}")
        if nom is not None:
            ax.axhline(nom, color="k", ls=":", lw=0.8,
                       label="controller's model" if field in ("a1", "b1") else None)
        if plant is not None and f"tf.{field}" in plant:
            ax.axhline(plant[f"tf.{field}"], color="0.5", ls="-.", lw=0.8,
                       label="plant's own G" if field in ("a1", "b1") else None)
    d = ours.data
    x = d["time"] - t0
    spans = _runs(d["adapting"] > 0.5)
    for ax in (a_a, a_b):
        for i, (a, b) in enumerate(spans[:200]):
            ax.axvspan(x[a], x[min(b, x.size - 1)], color="tab:green", alpha=0.15, lw=0,
                       label="ours adapting (est.adapting)" if i == 0 and ax is a_a else None)
    a_y.set_ylabel(f"[{UM}]")
    a_y.set_title(f"reference and displacement: {ours.description}", loc="left")
    a_e.set_yscale("log")
    a_e.set_ylabel(f"|y_d {MINUS} y| [{NM}]")
    a_e.set_title("tracking error (0.1 nm floor on a log axis)", loc="left")
    a_a.set_title("estimates of the denominator of G: est.a1 (upper), est.a2 (lower)", loc="left")
    a_b.set_title("estimates of the numerator of G: est.b1 (upper), est.b2 (lower)", loc="left")
    a_a.set_ylim(-2.0, 1.2)
    a_b.set_ylim(-1.2, 1.2)
    lo, hi = float(d["time"][0] - t0), float(d["time"][-1] - t0)
    for ax in axes:
        _time_symlog(ax, linthresh, lo, hi)
        ax.axvline(0.0, color="0.6", lw=0.6)
        ax.legend(loc="best", fontsize=6.3, framealpha=0.85)
    what = "the last frame's start" if scan else "the last move's start"
    a_b.set_xlabel(f"t {MINUS} t_0 [s], t_0 = {t0:g} s ({what}); symmetric-log axis, linear "
                   f"within ±{linthresh:g} s")
    name = name or f"stage_use_{sc.name}"
    caption = (f"Stage use, {sc.name}: {ours.description}. The controller's defaults (ours) and "
               f"the paper's law on the mismatch plant: y_d and y, the tracking error, and the RLS "
               f"estimates (ours adapt only in the shaded spans, while the reference excites the "
               f"loop), on a time axis around {what}.")
    return _save(plt, fig, out_dir, name, caption, f"Stage use: {sc.name}")


# ---------------------------------------------------------------------------
# drivers
# ---------------------------------------------------------------------------

def draw_main_figures(out_dir, tracking, conditions, validation, *, nominal_g, plants,
                      v_limits=None):
    """Every figure of the main job.

    Parameters
    ----------
    out_dir : str or Path
    tracking : dict
        Condition key -> list of TrackingResult (with data).
    conditions : list of Condition
    validation : list of ValidationResult (with data)
    nominal_g : dict
        The controller's nominal ``tf.*``.
    plants : dict
        Scenario name -> effective plant parameters.
    v_limits : tuple, optional

    Returns
    -------
    list of FigureFile
    """
    head = next(c for c in conditions if c.role == "headline")
    mismatch = [c for c in conditions if c.plant == "mismatch"]
    hr = tracking[head.key]
    figs = [
        headline_figure(hr, out_dir, label=head.label),
        tracking_error_figure(hr, out_dir, label=head.label),
        tracking_period_figure([(c.short_label, tracking[c.key]) for c in mismatch], out_dir),
        control_voltage_figure(hr, out_dir, label=head.label, limits=v_limits),
    ]
    if head.adaptation_on:
        figs.append(rls_figure(hr, out_dir, nominal_g, [plants[r.scenario] for r in hr],
                               label=head.label))
    user = [c for c in conditions if c.role == "user"]
    for c in user:
        figs.append(tracking_error_figure(tracking[c.key], out_dir, "user_tracking_error",
                                          label=c.label))
    if validation:
        figs.append(hysteresis_figure(validation, out_dir))
        figs.append(creep_figure(validation, out_dir))
    return figs


def draw_stage_use_figures(out_dir, runs, *, nominal_g, plants):
    """The stage-use figures of the main job: :data:`STAGE_USE_FIGURES`, each under both laws.

    Parameters
    ----------
    out_dir : str or Path
    runs : list of StageUseRun
        With their rows.
    nominal_g : dict
        The controller's parameters (its nominal ``tf.*``).
    plants : dict
        Scenario name -> effective plant parameters.

    Returns
    -------
    list of FigureFile
    """
    pairs = {}
    for r in runs:
        if r.data is not None:
            pairs.setdefault(r.scenario, {})[r.law] = r
    return [stage_use_figure(pairs[n], out_dir, nominal_g, plants.get(n))
            for n in STAGE_USE_FIGURES if len(pairs.get(n, {})) == 2]


def draw_scenario_figure(result, out_dir, *, nominal_g=None, plant=None, label="", name=None):
    """The figure of one scenario (``run``): tracking or validation.

    Tracking: error over the run and in the metric window, one period of y_d
    and y with the error, the voltage, and the RLS DC gain.  Validation: the
    hysteresis loop and the creep response.
    """
    plt = _pyplot()
    _style(plt)
    name = name or result.scenario
    if hasattr(result, "coupled"):
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.9))
        _loop_panel(a, result)
        a.set_title("hysteresis loop, last period", loc="left")
        _creep_panel(b, result)
        b.set_title(f"creep response: C − H e_rms {result.diff_e_rms_um:.3g} {UM}", loc="left")
        _figure_legend(fig, [a, b])
        fig.tight_layout(rect=(0, 0.07, 1, 0.93))
        caption = (f"{result.scenario}: hysteresis loop of both models and what the creep block "
                   f"adds (model vs model, no measured data).")
        return _save(plt, fig, out_dir, name, caption,
                     f"{result.scenario}: {_MODEL_VS_MODEL}", layout=False)

    d, sc = result.data, result.spec
    fig, axes = plt.subplots(3, 2, figsize=(10, 8.4), squeeze=False)
    _error_panels(axes[0, 0], axes[0, 1], result, first=True)
    axes[0, 0].legend(loc="upper right")
    sel = _last_period(d["time"], sc)
    t = d["time"][sel]
    a = axes[1, 0]
    a.plot(t, d["y_d"][sel], color="k", lw=1.6, label="y_d")
    a.plot(t, d["y"][sel], color="tab:cyan", lw=0.9, ls="--", label="y")
    a.set_ylabel(f"[{UM}]")
    a.set_title("reference and output, last period", loc="left")
    a.legend(loc="upper right")
    b = axes[1, 1]
    b.plot(t, (d["y_d"] - d["y"])[sel] * 1e3, color="tab:red", lw=0.8)
    b.set_ylabel(f"y_d {MINUS} y [{NM}]")
    b.set_title("error, last period", loc="left")
    c = axes[2, 0]
    c.plot(t, d["v"][sel], color="tab:green", lw=1.0)
    c.set_ylabel("v [V]")
    c.set_title(f"control voltage, last period (peak |v| over the run {result.v_peak:.3g} V)",
                loc="left")
    g = axes[2, 1]
    tt, dc = _decimate(d["time"], _dc_gain(d["a1"], d["a2"], d["b1"], d["b2"]))
    g.plot(tt, dc, color="tab:blue", lw=0.9, label="estimated")
    refs = []
    note = ""
    if nominal_g is not None:
        nom = float(_dc_gain(*[nominal_g[f"tf.{n}"] for n in _G_NAMES]))
        g.axhline(nom, color="k", ls=":", label="nominal model (start)")
        refs.append(nom)
        if plant is not None:
            tv = float(_dc_gain(*[plant.get(f"tf.{n}", nominal_g[f"tf.{n}"]) for n in _G_NAMES]))
            g.axhline(tv, color="k", ls="--", label="plant's own G")
            refs.append(tv)
            band = _effective_band(g, [result], nominal_g, [plant])
            if band:
                refs += list(band)
                note = (":\nit settles at the effective gain q → y (band), not the plant's "
                        "own G:\nthe controller's inverse PI and creep leave the plant's PI and"
                        "\ncreep mismatch in the loop, and RLS identifies the loop")
    skip = min(d.size - 1, int(round(0.05 / sc.step_size)))
    g.set_ylim(*_robust_limits([_dc_gain(d["a1"], d["a2"], d["b1"], d["b2"])], refs, skip))
    g.set_title("DC gain of the RLS estimate of G, (b1 + b2)/(1 + a1 + a2)" + note, loc="left")
    g.legend(loc="lower right", fontsize=6.5, framealpha=0.85)
    for ax in axes[1:].flat:
        ax.set_xlabel("time [s]")
    caption = (f"{result.scenario}: tracking error over the run and in the metric window, one "
               f"period of reference and output, the control voltage and the RLS estimate.")
    return _save(plt, fig, out_dir, name, caption, f"{result.scenario} ({label})")
