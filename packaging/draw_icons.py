"""Draw the FMU icons (``model.png``) into packaging/icons/<id>.png.

Run by hand after changing a drawing (the build copies the committed PNGs, so it
needs no plotting library): ``python packaging/draw_icons.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "icons"
SIZE_IN, DPI = 2.0, 100          # 200 x 200 pixels


def _canvas():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(SIZE_IN, SIZE_IN), dpi=DPI)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.set_xlim(0, 10)
    ax.set_ylim(0, 10)
    ax.axis("off")
    ax.add_patch(plt.Rectangle((0.2, 0.2), 9.6, 9.6, facecolor="white", edgecolor="#335",
                               linewidth=2.5))
    return fig, ax, plt


def _save(fig, name):
    OUT.mkdir(exist_ok=True)
    # no tool/version text in the file: the same drawing gives the same bytes
    fig.savefig(OUT / f"{name}.png", dpi=DPI, metadata={"Software": None})


def piezo_stage():
    fig, ax, plt = _canvas()
    for i in range(7):                                  # the piezo stack
        ax.add_patch(plt.Rectangle((1.0, 2.0 + i * 0.75), 2.6, 0.62,
                                   facecolor="#e8963c" if i % 2 else "#f2c27a",
                                   edgecolor="#7a4a12", linewidth=1))
    ax.add_patch(plt.Rectangle((0.7, 1.4), 3.2, 0.6, facecolor="#777", edgecolor="black"))
    ax.add_patch(plt.Rectangle((4.4, 3.2), 3.4, 3.0, facecolor="#9ab", edgecolor="#234",
                               linewidth=1.5))           # the stage
    ax.plot([3.6, 4.4], [4.7, 4.7], color="#234", linewidth=3)
    ax.annotate("", xy=(9.3, 4.7), xytext=(7.9, 4.7),
                arrowprops=dict(arrowstyle="->", color="#c22", linewidth=2.5))
    ax.text(8.6, 5.2, "y", color="#c22", fontsize=15, ha="center", style="italic")
    ax.text(2.3, 7.9, "v", fontsize=15, ha="center", style="italic")
    ax.text(5.0, 0.55, "PiezoStage", fontsize=12, ha="center", color="#335", weight="bold")
    _save(fig, "PiezoStage")


def adaptive_compound_controller():
    fig, ax, plt = _canvas()
    blocks = [(0.8, "MV\nRLS", "#cfe0f5"), (3.7, "C\u207b\u00b9", "#e3f1d7"),
              (6.6, "P\u207b\u00b9", "#f7e2c6")]
    for x, label, colour in blocks:
        ax.add_patch(plt.Rectangle((x, 3.6), 2.4, 2.8, facecolor=colour, edgecolor="#234",
                                   linewidth=1.5))
        ax.text(x + 1.2, 5.0, label, fontsize=13 if "\n" in label else 17, ha="center",
                va="center")
    for x in (3.2, 6.1):
        ax.annotate("", xy=(x + 0.5, 5.0), xytext=(x, 5.0),
                    arrowprops=dict(arrowstyle="->", linewidth=1.8))
    ax.text(5.0, 8.0, "y_ref, y_meas \u2192 v", fontsize=11, ha="center")
    ax.text(5.0, 0.55, "Adaptive controller", fontsize=11, ha="center", color="#335",
            weight="bold")
    _save(fig, "AdaptiveCompoundController")


def reference_signal():
    fig, ax, plt = _canvas()
    t = np.linspace(0.0, 1.0, 400)
    y = (np.sin(2 * np.pi * t) + np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 10 * t)) / 3
    ax.plot(0.9 + 8.2 * t, 5.2 + 2.6 * y, color="#235", linewidth=2)
    ax.plot(0.9 + 8.2 * t, 5.2 + 2.6 * np.roll(y, -12), color="#c22", linewidth=1.2,
            linestyle="--")
    ax.plot([0.9, 9.1], [5.2, 5.2], color="#999", linewidth=0.8)
    ax.text(5.0, 0.55, "ReferenceSignal", fontsize=12, ha="center", color="#335",
            weight="bold")
    _save(fig, "ReferenceSignal")


def piezo_stage_closed_loop():
    fig, ax, plt = _canvas()
    boxes = [(0.8, "C", "#cfe0f5"), (5.6, "P", "#f2c27a")]     # controller, stage
    for x, label, colour in boxes:
        ax.add_patch(plt.Rectangle((x, 4.2), 3.4, 2.6, facecolor=colour, edgecolor="#234",
                                   linewidth=1.5))
        ax.text(x + 1.7, 5.5, label, fontsize=20, ha="center", va="center", style="italic")
    ax.annotate("", xy=(5.6, 5.5), xytext=(4.2, 5.5),
                arrowprops=dict(arrowstyle="->", linewidth=1.8))
    ax.plot([9.0, 9.4, 9.4, 0.4, 0.4, 0.8], [5.5, 5.5, 2.6, 2.6, 5.0, 5.0], color="#c22",
            linewidth=1.8)
    ax.annotate("", xy=(0.8, 5.0), xytext=(0.45, 5.0),
                arrowprops=dict(arrowstyle="->", color="#c22", linewidth=1.8))
    t = np.linspace(0.0, 1.0, 200)
    ax.plot(1.0 + 8.0 * t, 8.2 + 0.8 * np.sin(2 * np.pi * 2 * t), color="#235", linewidth=1.8)
    ax.text(5.0, 0.55, "Stage, closed loop", fontsize=11, ha="center", color="#335",
            weight="bold")
    _save(fig, "PiezoStageClosedLoop")


if __name__ == "__main__":
    piezo_stage()
    adaptive_compound_controller()
    reference_signal()
    piezo_stage_closed_loop()
    print(f"wrote the icons in {OUT}")
