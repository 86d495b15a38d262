"""The figure of a sweep: histogram and empirical CDF of e_rms per scenario."""

from __future__ import annotations

from pathlib import Path
import textwrap

import numpy as np

__all__ = ["CDF_POINTS", "cdf_points", "plot_errors"]


#: most points of a scenario's CDF drawn (the figure is some 500 pixels wide)
CDF_POINTS = 4000


def cdf_points(values, total, most=CDF_POINTS):
    """The empirical CDF of ``values`` (sorted) over ``total`` runs as step points ``(x, F)``,
    at most ``most`` of them: every value when there are few; else the values at evenly spaced
    ranks, the first and the last among them, so the steps drawn are off the exact CDF by less
    than the ranks between two kept ones (about ``1 / most`` of the runs) and a million runs
    draw as fast, and in as little memory, as a few thousand."""
    n = values.size
    ranks = np.arange(n) if n <= most else np.unique(np.linspace(0, n - 1, most).round().astype(np.int64))
    return values[ranks], (ranks + 1) / total


def plot_errors(result, path):
    """Histogram and empirical CDF of e_rms [nm] per scenario (PNG)."""
    import matplotlib                   # heavy (about 1 s): only when a figure is drawn
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, (ax_h, ax_c) = plt.subplots(1, 2, figsize=(11, 4.2))
    all_vals = np.concatenate([result.errors(n) * 1e3 for n in result.scenarios] or [np.zeros(0)])
    positive = all_vals[all_vals > 0]
    log = positive.size > 1 and positive.max() / positive.min() > 30
    if positive.size:
        lo, hi = positive.min(), positive.max()
        bins = (np.geomspace(lo, hi * 1.0001, 40) if log else np.linspace(lo, hi * 1.0001 + 1e-12, 40))
    else:
        bins = 10
    for name in result.scenarios:
        vals = np.sort(result.errors(name) * 1e3)
        c = result.counts(name)
        not_ok = len(result.runs[name]) - c["ok"]
        label = f"{name} ({c['ok']} ok" + (f", {not_ok} not ok)" if not_ok else ")")
        if vals.size:
            ax_h.hist(vals, bins=bins, histtype="step", linewidth=1.5, label=label)
            ax_c.step(*cdf_points(vals, len(result.runs[name])), where="post", label=label)
    for ax in (ax_h, ax_c):
        if log:
            ax.set_xscale("log")
            ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("e_rms [nm]")
        ax.grid(True, which="major", alpha=0.3)
    ax_h.set_ylabel("runs")
    ax_h.set_title("histogram of e_rms")
    ax_c.set_ylabel("fraction of all runs with e_rms <= x")
    ax_c.set_ylim(0, 1.02)
    ax_c.set_title("empirical CDF (not-ok runs count as above every x)")
    ax_h.legend(fontsize=8)
    spreads = "; ".join(s.describe() for s in result.spreads) or "no spread"
    title = (f"Monte Carlo sweep, {len(next(iter(result.runs.values())))} runs per scenario "
             f"(backend {result.options['backend']}): {spreads}")
    fig.suptitle(textwrap.fill(title, 150), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
