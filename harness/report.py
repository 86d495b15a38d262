"""Run the experiments and report them next to the paper's Tables 2-5.

Tracking conditions (each on the six references of Tables 4/5):

* ``nominal``: plant = controller model, preview on, adaptation on;
* ``mismatch``: the docs/model.md, scenarios mismatched plant, adaptation on (headline);
* ``mismatch_no_adaptation``: same plant, RLS off (nominal model only);
* ``mismatch_no_preview``: same plant, controller fed ``y_d(k)`` instead of ``y_d(k+d)``.

Validation: the plant alone on the six inputs of Tables 1-3, coupled model
versus Hammerstein model (``creep.enabled = false``).

Outputs under the output folder: ``tracking.csv``, ``tracking.md``,
``validation.csv``, ``validation.md``, ``report.md`` and, unless disabled,
PNG figures in the style of the paper's Figures 4-7.

Identification (:func:`run_identification`): the paper's three steps on
records of the PiezoStage model, every parameter next to the value the plant
ran; ``identification.csv`` and ``identification.md``.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
import math
from pathlib import Path
import sys
import time as _time

import numpy as np

from .metrics import compute_metrics, window_mask
from .scenarios import (
    MISMATCH_SCENARIOS,
    TRACKING_SCENARIOS,
    VALIDATION_SCENARIOS,
    get_scenario,
    load_scenarios,
)

__all__ = [
    "Condition",
    "TrackingResult",
    "ValidationResult",
    "default_conditions",
    "evaluate_tracking",
    "evaluate_validation",
    "format_tracking_table",
    "format_validation_table",
    "write_tracking_csv",
    "write_validation_csv",
    "write_timeseries_csv",
    "plot_tracking",
    "plot_validation",
    "run_all",
    "run_scenario",
    "IdentificationRow",
    "IdentificationRun",
    "generate_identification_records",
    "format_identification_table",
    "write_identification_csv",
    "run_identification",
    "TRACKING_NOTES",
    "VALIDATION_NOTES",
]

TRACKING_NOTES = (
    "Paper values are the measured results of Tables 4/5 (e_r as %); ratio = ours / paper.",
    "nominal: the plant equals the controller's model and the reference is previewed, so the "
    "loop tracks exactly by construction (error at round-off level); it checks the "
    "implementation, it is not comparable with the paper's experiment.",
    "mismatch (headline): plant PI weights +10 %, creep row 10 Hz, G numerator x1.05 with the "
    "fast pole at 0.45 (DC gain +17.5 %), 2 nm sensor resolution + 1 nm rms noise; the "
    "controller keeps the nominal model and adapts G by RLS. Sensor noise floor ~1.2 nm.",
    "mismatch, adaptation off: the nominal model alone; the error grows with frequency.",
    "mismatch, preview off: the controller gets y_d(k) instead of y_d(k+d), so the stage "
    "follows the reference d samples late. This lag error is expected, not a fault: for a "
    "sine it is ~ 2 pi f A d h / sqrt(2) rms (44 nm at 1 Hz, 888 nm at 20 Hz for A = 10 um, "
    "d = 2, h = 0.5 ms).",
)

VALIDATION_NOTES = (
    "The paper's Tables 2/3 compare both MODELS with measured stage data, which we do not "
    "have; our rows compare the coupled model (Table 1 creep row of each input) with the "
    "Hammerstein model (creep.enabled = false) on the same input, i.e. they measure what the "
    "creep block adds, not model accuracy. e_r is normalised by the coupled output.",
    "y span: min-max of the coupled model's displacement over the metric window.",
)


@dataclass(frozen=True)
class Condition:
    """A tracking condition: which scenarios, and the closed-loop options.

    Attributes
    ----------
    key : str
        Short identifier used in file names.
    label : str
        Human-readable title.
    scenarios : tuple of str
    adaptation : bool or None
    preview : bool
    master : str
    """

    key: str
    label: str
    scenarios: tuple
    adaptation: object = None
    preview: bool = True
    master: str = "gauss-seidel"


@dataclass
class TrackingResult:
    """Metrics of one closed-loop run and the paper's values."""

    condition: str
    scenario: str
    adaptation: bool
    preview: bool
    master: str
    e_rms_um: float
    e_r: float
    paper_e_rms_um: float
    paper_e_r: float
    v_peak: float
    n_samples: int
    elapsed_s: float
    data: object = field(default=None, repr=False)
    display_span: float = math.inf

    @property
    def ratio_e_rms(self):
        return _ratio(self.e_rms_um, self.paper_e_rms_um)

    @property
    def ratio_e_r(self):
        return _ratio(self.e_r, self.paper_e_r)


@dataclass
class ValidationResult:
    """Coupled vs Hammerstein model on one validation input."""

    scenario: str
    k_c: float
    alpha: float
    diff_e_rms_um: float
    diff_e_r: float
    y_min_um: float
    y_max_um: float
    paper_hammerstein_e_rms_um: float
    paper_coupled_e_rms_um: float
    paper_hammerstein_e_r: float
    paper_coupled_e_r: float
    elapsed_s: float
    coupled: object = field(default=None, repr=False)
    hammerstein: object = field(default=None, repr=False)
    display_span: float = math.inf


def _display_span(sc, periods=3.0):
    """Seconds shown by the signal plots: a few periods of the slowest tone (whole run otherwise)."""
    freqs = [f for f, a in zip(sc.signal.frequencies, sc.signal.amplitudes) if f > 0 and a != 0]
    if sc.signal.kind != "sines" or not freqs:
        return math.inf
    return min(sc.duration, periods / min(freqs))


def _ratio(a, b):
    if b is None or not math.isfinite(b) or b == 0:
        return math.nan
    return a / b


def _label(base, adaptation, preview, master):
    parts = [base,
             "adaptation " + ("off" if adaptation is False else "on"),
             "preview " + ("on" if preview else "off")]
    if master == "jacobi":
        parts.append("Jacobi master")
    return ", ".join(parts)


def default_conditions(adaptation=None, preview=True, master="gauss-seidel"):
    """The four tracking conditions of the report, built on the base options.

    Parameters
    ----------
    adaptation : bool or None
        Base adaptation setting (``None``: on).
    preview : bool
        Base preview setting.
    master : str

    Returns
    -------
    list of Condition
        Duplicates (e.g. when the base already has preview off) are dropped.
    """
    conds = [
        Condition("nominal", _label("nominal model", adaptation, preview, master),
                  TRACKING_SCENARIOS, adaptation, preview, master),
        Condition("mismatch", _label("mismatch", adaptation, preview, master) + " [headline]",
                  MISMATCH_SCENARIOS, adaptation, preview, master),
        Condition("mismatch_no_adaptation", _label("mismatch", False, preview, master),
                  MISMATCH_SCENARIOS, False, preview, master),
        Condition("mismatch_no_preview", _label("mismatch", adaptation, False, master),
                  MISMATCH_SCENARIOS, adaptation, False, master),
    ]
    seen, out = set(), []
    for c in conds:
        sig = (c.scenarios, c.adaptation is False, c.preview, c.master)
        if sig not in seen:
            seen.add(sig)
            out.append(c)
    return out


def _simulator(backend):
    if backend == "fmpy":
        from .cosim import simulate_closed_loop, simulate_open_loop
        return simulate_closed_loop, simulate_open_loop
    if backend == "core":
        from .core_loop import simulate_closed_loop_core, simulate_open_loop_core
        return simulate_closed_loop_core, simulate_open_loop_core
    raise ValueError(f"backend must be 'fmpy' or 'core', got {backend!r}")


def evaluate_tracking(scenario, *, condition="run", adaptation=None, preview=True,
                      master="gauss-seidel", fmu_dir=None, registry=None, backend="fmpy",
                      keep_data=True):
    """Run one tracking scenario and compute its metrics.

    Parameters
    ----------
    scenario : str or Scenario
    condition : str
        Label stored in the result.
    adaptation, preview, master, fmu_dir, registry
        See :func:`harness.cosim.simulate_closed_loop`.
    backend : {"fmpy", "core"}
        Run the FMUs (default) or the C core directly.
    keep_data : bool
        Keep the time series in ``result.data``.

    Returns
    -------
    TrackingResult

    Raises
    ------
    harness.checks.RunCheckError
        The run diverged (the controller stopped it, or its error exceeds the reference) or
        saturated persistently (:func:`harness.checks.check_tracking_run`).
    """
    from .checks import RunDivergedError, check_tracking_run
    from .core import CoreDivergedError
    from .cosim import LoopDivergedError

    sc = get_scenario(scenario, registry)
    closed, _ = _simulator(backend)
    label = f"{condition} / {sc.name}"
    t0 = _time.perf_counter()
    try:
        data = closed(sc, adaptation=adaptation, preview=preview, master=master, fmu_dir=fmu_dir)
    except (LoopDivergedError, CoreDivergedError) as exc:
        raise RunDivergedError(f"{label}: {exc}") from None
    elapsed = _time.perf_counter() - t0
    check_tracking_run(data, sc, label)
    m = compute_metrics(data["time"], data["y_d"], data["y"], sc.metric_window, sc.step_size)
    return TrackingResult(
        condition=condition, scenario=sc.name, adaptation=adaptation is not False,
        preview=bool(preview), master=master, e_rms_um=m.e_rms, e_r=m.e_r,
        paper_e_rms_um=sc.paper.get("e_rms_um", math.nan),
        paper_e_r=sc.paper.get("e_r", math.nan),
        v_peak=float(np.max(np.abs(data["v"]))), n_samples=m.n_samples, elapsed_s=elapsed,
        data=data if keep_data else None, display_span=_display_span(sc),
    )


def evaluate_validation(scenario, *, fmu_dir=None, registry=None, backend="fmpy",
                        keep_data=True):
    """Run a validation input through the coupled and the Hammerstein model.

    Parameters
    ----------
    scenario : str or Scenario
        A validation scenario (signal = input voltage).
    fmu_dir, registry, backend, keep_data
        As :func:`evaluate_tracking`.

    Returns
    -------
    ValidationResult
        ``diff_*`` compare the coupled output (taken as the truth, eq 36-37's
        ``y``) with the Hammerstein output (``y_m``).
    """
    sc = get_scenario(scenario, registry)
    if sc.kind != "validation":
        raise ValueError(f"scenario '{sc.name}' is a {sc.kind} scenario, not a validation input")
    _, open_loop = _simulator(backend)
    t0 = _time.perf_counter()
    v = sc.signal.evaluate(sc.time_grid())
    params = dict(sc.plant)
    coupled = open_loop({**params, "creep.enabled": True}, v, step_size=sc.step_size,
                        fmu_dir=fmu_dir)
    hamm = open_loop({**params, "creep.enabled": False}, v, step_size=sc.step_size,
                     fmu_dir=fmu_dir)
    elapsed = _time.perf_counter() - t0
    t = coupled["time"]
    m = compute_metrics(t, coupled["y"], hamm["y"], sc.metric_window, sc.step_size,
                        normalizer=coupled["y"])
    win = window_mask(t, sc.metric_window, sc.step_size)
    p = sc.paper
    return ValidationResult(
        scenario=sc.name, k_c=float(params.get("creep.k_c", math.nan)),
        alpha=float(params.get("creep.alpha", math.nan)),
        diff_e_rms_um=m.e_rms, diff_e_r=m.e_r,
        y_min_um=float(coupled["y"][win].min()), y_max_um=float(coupled["y"][win].max()),
        paper_hammerstein_e_rms_um=p.get("hammerstein_e_rms_um", math.nan),
        paper_coupled_e_rms_um=p.get("coupled_e_rms_um", math.nan),
        paper_hammerstein_e_r=p.get("hammerstein_e_r", math.nan),
        paper_coupled_e_r=p.get("coupled_e_r", math.nan),
        elapsed_s=elapsed,
        coupled=coupled if keep_data else None, hammerstein=hamm if keep_data else None,
        display_span=_display_span(sc),
    )


# ---------------------------------------------------------------------------
# formatting
# ---------------------------------------------------------------------------

def _f(x, fmt):
    return "n/a" if x is None or not math.isfinite(x) else format(x, fmt)


def _tracking_cells(r):
    return [
        r.scenario,
        _f(r.e_rms_um * 1e3, ".4g"), _f(r.paper_e_rms_um * 1e3, ".4g"), _f(r.ratio_e_rms, ".3g"),
        _f(r.e_r * 100, ".4g"), _f(r.paper_e_r * 100, ".4g"), _f(r.ratio_e_r, ".3g"),
    ]


_TRACK_HEAD = ["scenario", "e_rms ours [nm]", "paper [nm]", "ratio",
               "e_r ours [%]", "paper [%]", "ratio"]
_VALID_HEAD = ["scenario", "k_c", "alpha", "coupled-Hammerstein e_rms [um]", "e_r [%]",
               "y span [um]", "paper Hammerstein e_rms [um]", "paper coupled e_rms [um]",
               "paper Hammerstein e_r [%]", "paper coupled e_r [%]"]


def _validation_cells(r):
    return [
        r.scenario, _f(r.k_c, ".4f"), _f(r.alpha, ".4f"), _f(r.diff_e_rms_um, ".4f"),
        _f(r.diff_e_r * 100, ".3f"), f"{_f(r.y_min_um, '.2f')}-{_f(r.y_max_um, '.2f')}",
        _f(r.paper_hammerstein_e_rms_um, ".4f"), _f(r.paper_coupled_e_rms_um, ".4f"),
        _f(r.paper_hammerstein_e_r * 100, ".2f"), _f(r.paper_coupled_e_r * 100, ".2f"),
    ]


def _text_table(head, rows):
    widths = [max(len(str(c)) for c in col) for col in zip(head, *rows)]
    lines = ["  ".join(str(c).rjust(w) if i else str(c).ljust(w)
                       for i, (c, w) in enumerate(zip(row, widths)))
             for row in [head] + rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _md_table(head, rows):
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def format_tracking_table(results, title=None, markdown=False):
    """Format tracking results next to the paper's Tables 4/5.

    Parameters
    ----------
    results : list of TrackingResult
    title : str, optional
    markdown : bool
        Markdown table instead of aligned text.

    Returns
    -------
    str
    """
    return _titled_table(_TRACK_HEAD, [_tracking_cells(r) for r in results], title, markdown)


def format_validation_table(results, title=None, markdown=False):
    """Format validation results next to the paper's Tables 2/3.

    Parameters
    ----------
    results : list of ValidationResult
    title : str, optional
    markdown : bool

    Returns
    -------
    str
    """
    return _titled_table(_VALID_HEAD, [_validation_cells(r) for r in results], title, markdown)


def _titled_table(head, rows, title, markdown):
    table = _md_table(head, rows) if markdown else _text_table(head, rows)
    if title:
        table = (f"### {title}\n\n" if markdown else f"{title}\n") + table
    return table


# ---------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------

_TRACK_CSV = ["condition", "scenario", "adaptation", "preview", "master", "e_rms_um", "e_r",
              "paper_e_rms_um", "paper_e_r", "ratio_e_rms", "ratio_e_r", "v_peak_V",
              "n_samples", "elapsed_s"]
_VALID_CSV = ["scenario", "k_c", "alpha", "diff_e_rms_um", "diff_e_r", "y_min_um", "y_max_um",
              "paper_hammerstein_e_rms_um", "paper_coupled_e_rms_um", "paper_hammerstein_e_r",
              "paper_coupled_e_r", "elapsed_s"]


def _num(x):
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else repr(float(x))


def write_tracking_csv(results, path):
    """Write tracking results as CSV (full precision; e_r as a fraction, lengths in um)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(_TRACK_CSV)
        for r in results:
            w.writerow([r.condition, r.scenario, int(r.adaptation), int(r.preview), r.master,
                        _num(r.e_rms_um), _num(r.e_r), _num(r.paper_e_rms_um),
                        _num(r.paper_e_r), _num(r.ratio_e_rms), _num(r.ratio_e_r),
                        _num(r.v_peak), r.n_samples, f"{r.elapsed_s:.3f}"])
    return Path(path)


def write_validation_csv(results, path):
    """Write validation results as CSV (full precision; e_r as a fraction)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(_VALID_CSV)
        for r in results:
            w.writerow([r.scenario] + [_num(getattr(r, k)) for k in _VALID_CSV[1:-1]]
                       + [f"{r.elapsed_s:.3f}"])
    return Path(path)


def write_timeseries_csv(data, path):
    """Write a structured result array as CSV with a header of its field names."""
    names = data.dtype.names
    arr = np.column_stack([data[n] for n in names])
    np.savetxt(path, arr, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return Path(path)


# ---------------------------------------------------------------------------
# plots (matplotlib imported lazily, Agg backend)
# ---------------------------------------------------------------------------

def _pyplot():
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    return plt


def _last(time, span):
    """Samples of the last ``span`` seconds of a run."""
    return time >= time[-1] - span if math.isfinite(span) else slice(None)


def _grid(n):
    cols = min(3, n)
    rows = int(math.ceil(n / cols))
    return rows, cols


def plot_tracking(results, path, title, error=False):
    """Tracking figure (paper Fig. 6: y_d and y) or error figure (Fig. 7: y_d - y in nm).

    Parameters
    ----------
    results : list of TrackingResult
        With ``data`` kept.
    path : str or Path
        PNG file.
    title : str
    error : bool
        Plot the tracking error instead of the signals.

    Returns
    -------
    Path
    """
    plt = _pyplot()
    nr, nc = _grid(len(results))
    fig, axes = plt.subplots(nr, nc, figsize=(5 * nc, 3.2 * nr), squeeze=False)
    for ax, r in zip(axes.flat, results):
        d = r.data
        if error:
            ax.plot(d["time"], (d["y_d"] - d["y"]) * 1e3, lw=0.7, color="C3")
            ax.set_ylabel("y_d - y [nm]")
            ax.set_title(f"{r.scenario}: e_rms {r.e_rms_um * 1e3:.3g} nm", fontsize=9)
        else:
            sel = _last(d["time"], r.display_span)
            ax.plot(d["time"][sel], d["y_d"][sel], lw=1.2, label="y_d")
            ax.plot(d["time"][sel], d["y"][sel], lw=0.8, ls="--", label="y")
            ax.set_ylabel("displacement [um]")
            ax.set_title(r.scenario, fontsize=9)
            ax.legend(fontsize=7, loc="upper right")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    return _save_figure(plt, fig, axes, len(results), title, path)


def _save_figure(plt, fig, axes, n_used, title, path):
    """Hide the unused panels, title, save as PNG and close the figure."""
    for ax in list(axes.flat)[n_used:]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Path(path)


def plot_validation(results, path, title, difference=False):
    """Validation figure: coupled vs Hammerstein output (Fig. 4) or their difference (Fig. 5).

    Parameters
    ----------
    results : list of ValidationResult
        With the time series kept.
    path : str or Path
    title : str
    difference : bool

    Returns
    -------
    Path
    """
    plt = _pyplot()
    nr, nc = _grid(len(results))
    fig, axes = plt.subplots(nr, nc, figsize=(5 * nc, 3.2 * nr), squeeze=False)
    for ax, r in zip(axes.flat, results):
        c, hm = r.coupled, r.hammerstein
        if difference:
            ax.plot(c["time"], c["y"] - hm["y"], lw=0.7, color="C3")
            ax.set_ylabel("coupled - Hammerstein [um]")
        else:
            sel = _last(c["time"], r.display_span)
            ax.plot(c["time"][sel], c["y"][sel], lw=1.0, label="coupled")
            ax.plot(hm["time"][sel], hm["y"][sel], lw=0.8, ls="--", label="Hammerstein")
            ax.set_ylabel("y [um]")
            ax.legend(fontsize=7, loc="upper right")
        ax.set_title(r.scenario, fontsize=9)
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    return _save_figure(plt, fig, axes, len(results), title, path)


# ---------------------------------------------------------------------------
# drivers
# ---------------------------------------------------------------------------

class _Progress:
    def __init__(self, total, stream):
        self.total, self.stream, self.i = total, stream, 0
        self.start = _time.perf_counter()

    def done(self, what, elapsed):
        self.i += 1
        if self.stream is not None:
            width = len(str(self.total))
            self.stream.write(f"[{self.i:>{width}}/{self.total}] {what}: {elapsed:.2f} s "
                              f"(total {_time.perf_counter() - self.start:.1f} s)\n")
            self.stream.flush()


def run_all(out_dir="out", *, adaptation=None, preview=True, master="gauss-seidel",
            fmu_dir=None, plots=True, backend="fmpy", registry=None, extra_scenarios=(),
            stream=sys.stdout, progress=sys.stderr):
    """Run every tracking condition and the validation inputs; write the report.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    adaptation, preview, master
        Base options of the tracking conditions (see :func:`default_conditions`).
    fmu_dir : str or Path, optional
    plots : bool
        Write the PNG figures.
    backend : {"fmpy", "core"}
    registry : dict, optional
        Scenario registry (built-in plus user files); default built-in.
    extra_scenarios : iterable of str
        Further scenarios (e.g. from user files) run with the base options and
        reported in their own table ("user") or validation rows.
    stream : file-like or None
        Where the tables are printed.
    progress : file-like or None
        Where one line per finished run is written.

    Returns
    -------
    dict
        ``{"tracking": {condition key: [TrackingResult]}, "validation": [ValidationResult],
        "files": [Path]}``
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    registry = load_scenarios() if registry is None else registry
    conditions = default_conditions(adaptation, preview, master)
    extra = [get_scenario(n, registry) for n in extra_scenarios]
    extra_track = tuple(s.name for s in extra if s.kind == "tracking")
    validation_names = list(VALIDATION_SCENARIOS) + [s.name for s in extra
                                                     if s.kind == "validation"]
    if extra_track:
        conditions.append(Condition("user", _label("user scenarios", adaptation, preview, master),
                                    extra_track, adaptation, preview, master))
    total = sum(len(c.scenarios) for c in conditions) + len(validation_names)
    prog = _Progress(total, progress)

    tracking = {}
    for cond in conditions:
        res = []
        for name in cond.scenarios:
            r = evaluate_tracking(name, condition=cond.key, adaptation=cond.adaptation,
                                  preview=cond.preview, master=cond.master, fmu_dir=fmu_dir,
                                  registry=registry, backend=backend, keep_data=plots)
            prog.done(f"{cond.key} / {name}: e_rms {r.e_rms_um * 1e3:.4g} nm", r.elapsed_s)
            res.append(r)
        tracking[cond.key] = res
    validation = []
    for name in validation_names:
        r = evaluate_validation(name, fmu_dir=fmu_dir, registry=registry, backend=backend,
                                keep_data=plots)
        prog.done(f"validation / {name}: coupled-Hammerstein e_rms {r.diff_e_rms_um:.4f} um",
                  r.elapsed_s)
        validation.append(r)

    files = []
    all_tracking = [r for c in conditions for r in tracking[c.key]]
    files.append(write_tracking_csv(all_tracking, out / "tracking.csv"))
    files.append(write_validation_csv(validation, out / "validation.csv"))

    text_parts, md_parts = [], ["# Piezo stage co-simulation report", ""]
    for cond in conditions:
        text_parts.append(format_tracking_table(tracking[cond.key], f"Tracking: {cond.label}"))
        md_parts += [format_tracking_table(tracking[cond.key], f"Tracking: {cond.label}",
                                           markdown=True), ""]
    notes_t = "\n".join(f"  - {n}" for n in TRACKING_NOTES)
    text_parts.append("Notes (tracking):\n" + notes_t)
    vtitle = "Validation: coupled vs Hammerstein model (plant alone, open loop)"
    text_parts.append(format_validation_table(validation, vtitle))
    notes_v = "\n".join(f"  - {n}" for n in VALIDATION_NOTES)
    text_parts.append("Notes (validation):\n" + notes_v)

    track_md = "\n\n".join(format_tracking_table(tracking[c.key], f"Tracking: {c.label}",
                                                 markdown=True) for c in conditions)
    track_md += "\n\nNotes:\n\n" + "\n".join(f"- {n}" for n in TRACKING_NOTES) + "\n"
    valid_md = format_validation_table(validation, vtitle, markdown=True)
    valid_md += "\n\nNotes:\n\n" + "\n".join(f"- {n}" for n in VALIDATION_NOTES) + "\n"
    (out / "tracking.md").write_text(track_md)
    (out / "validation.md").write_text(valid_md)
    (out / "report.md").write_text("# Piezo stage co-simulation report\n\n" + track_md
                                   + "\n" + valid_md)
    files += [out / "tracking.md", out / "validation.md", out / "report.md"]

    if plots:
        for cond in conditions:
            res = tracking[cond.key]
            files.append(plot_tracking(res, out / f"tracking_{cond.key}.png",
                                       f"Tracking: {cond.label}"))
            files.append(plot_tracking(res, out / f"error_{cond.key}.png",
                                       f"Tracking error: {cond.label}", error=True))
        files.append(plot_validation(validation, out / "validation.png",
                                     "Coupled vs Hammerstein model output"))
        files.append(plot_validation(validation, out / "validation_difference.png",
                                     "Coupled minus Hammerstein model output", difference=True))

    if stream is not None:
        stream.write("\n\n".join(text_parts) + "\n")
        stream.write(f"\nWrote {len(files)} files to {out}/\n")
        stream.flush()
    return {"tracking": tracking, "validation": validation, "files": files}


def run_scenario(name, out_dir="out", *, adaptation=None, preview=True, master="gauss-seidel",
                 fmu_dir=None, plots=True, registry=None, backend="fmpy", stream=sys.stdout,
                 progress=sys.stderr):
    """Run one scenario (tracking or validation), print its table line, write its files.

    Files: ``<name>.csv`` (metrics, same columns as ``tracking.csv`` or
    ``validation.csv``), ``<name>_timeseries.csv`` and, with plots, ``<name>.png``.

    Returns
    -------
    TrackingResult or ValidationResult
    """
    sc = get_scenario(name, registry)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    prog = _Progress(1, progress)
    if sc.kind == "tracking":
        label = _label("run", adaptation, preview, master)
        r = evaluate_tracking(sc, condition="run", adaptation=adaptation, preview=preview,
                              master=master, fmu_dir=fmu_dir, registry=registry, backend=backend)
        prog.done(f"{sc.name}: e_rms {r.e_rms_um * 1e3:.4g} nm", r.elapsed_s)
        write_tracking_csv([r], out / f"{sc.name}.csv")
        write_timeseries_csv(r.data, out / f"{sc.name}_timeseries.csv")
        if plots:
            _plot_single_tracking(r, out / f"{sc.name}.png", f"{sc.name} ({label})")
        table = format_tracking_table([r], f"Tracking: {sc.name} ({label})")
    else:
        r = evaluate_validation(sc, fmu_dir=fmu_dir, registry=registry, backend=backend)
        prog.done(f"{sc.name}: coupled-Hammerstein e_rms {r.diff_e_rms_um:.4f} um", r.elapsed_s)
        write_validation_csv([r], out / f"{sc.name}.csv")
        c, hm = r.coupled, r.hammerstein
        series = np.zeros(c.size, dtype=[("time", "f8"), ("v", "f8"), ("y_coupled", "f8"),
                                         ("y_hammerstein", "f8"), ("difference", "f8")])
        series["time"], series["v"] = c["time"], c["v"]
        series["y_coupled"], series["y_hammerstein"] = c["y"], hm["y"]
        series["difference"] = c["y"] - hm["y"]
        write_timeseries_csv(series, out / f"{sc.name}_timeseries.csv")
        if plots:
            plot_validation([r], out / f"{sc.name}.png", f"{sc.name}: coupled vs Hammerstein")
        table = format_validation_table([r], f"Validation: {sc.name}")
    if stream is not None:
        stream.write(table + "\n")
        stream.flush()
    return r


def _plot_single_tracking(r, path, title):
    plt = _pyplot()
    d = r.data
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot(d["time"], d["y_d"], lw=1.2, label="y_d")
    a1.plot(d["time"], d["y"], lw=0.8, ls="--", label="y")
    a1.set_ylabel("displacement [um]")
    a1.legend(fontsize=8, loc="upper right")
    a1.grid(alpha=0.3)
    a2.plot(d["time"], (d["y_d"] - d["y"]) * 1e3, lw=0.7, color="C3")
    a2.set_ylabel("y_d - y [nm]")
    a2.set_xlabel("time [s]")
    a2.grid(alpha=0.3)
    fig.suptitle(f"{title}: e_rms {r.e_rms_um * 1e3:.4g} nm, e_r {r.e_r * 100:.4g} %",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Path(path)


# ---------------------------------------------------------------------------
# identification (paper section 3)
# ---------------------------------------------------------------------------

#: Validation inputs (Tables 1-3) used by the identification: step 1, step 2, step 3.
IDENTIFICATION_PI_SCENARIO = "validate_1hz"
IDENTIFICATION_TF_SCENARIO = "validate_5_40_80hz"
IDENTIFICATION_CREEP_SCENARIOS = VALIDATION_SCENARIOS

_IDENT_HEAD = ["parameter", "true", "identified", "abs. error", "rel. error"]
_IDENT_CSV = ["parameter", "true", "identified", "abs_error", "rel_error"]


@dataclass(frozen=True)
class IdentificationRow:
    """One parameter of the identification table."""

    parameter: str
    true: float
    identified: float

    @property
    def abs_error(self):
        return self.identified - self.true

    @property
    def rel_error(self):
        return self.abs_error / abs(self.true) if self.true != 0 else math.nan


@dataclass
class IdentificationRun:
    """Result of :func:`run_identification`.

    Attributes
    ----------
    estimate : harness.identification.CoupledModelEstimate
    rows : list of IdentificationRow
        Every parameter: PI weights, ``w0 + w1``, ``G``, then ``k_c`` and
        ``alpha`` of each Table 1 row.
    truth : dict
        The plant parameters of each record, by label (FMU variable names).
    backend : str
    noise_rms_um : float
    displacement_only : bool
    elapsed_s : float
    """

    estimate: object
    rows: list
    truth: dict
    backend: str
    noise_rms_um: float
    displacement_only: bool
    elapsed_s: float


def _record_label(sc):
    if sc.signal.kind == "sines" and sc.signal.frequencies:
        return "/".join(f"{f:g}" for f in sc.signal.frequencies) + " Hz"
    return sc.name


def _true_params(sc):
    """The plant parameters that define a record: core defaults, then the scenario's overrides."""
    from . import core

    d = core.default_plant_params()
    names = ["pi.w0"] + [f"pi.w[{j}]" for j in range(1, d["pi.m"] + 1)]
    names += ["tf.a1", "tf.a2", "tf.b1", "tf.b2", "creep.k_c", "creep.alpha"]
    params = {n: d[n] for n in names}
    params.update({k: v for k, v in sc.plant.items() if k in params})
    params.update({"pi.m": d["pi.m"], "pi.v_max": d["pi.v_max"], "tf.delay": d["tf.delay"]})
    return params


def generate_identification_records(*, backend="fmpy", noise_rms_um=0.0, seed=1, fmu_dir=None,
                                    progress=None):
    """Run the PiezoStage model on the six inputs of Table 1 and record what is measured.

    Each record is one validation input (3 s from rest) with its Table 1
    creep row; PI and ``G`` are the plant's defaults, passed explicitly so the
    truth is what the plant ran.  Channels: ``u`` and ``x`` (the plant's
    outputs of those names) and ``y`` = ``y_meas``.

    Parameters
    ----------
    backend : {"fmpy", "core"}
        The FMU through fmpy, or the C core.
    noise_rms_um : float
        White measurement noise [um rms] on every recorded channel: on ``y``
        by the plant's own sensor (``sensor.noise_rms``, ``sensor.seed =
        seed + i`` for record i), on ``u`` and ``x`` from
        ``numpy.random.default_rng([seed, i])``.  0 (default): noise-free.
    seed : int
        Base seed (>= 0).
    fmu_dir : str or Path, optional
    progress : file-like, optional
        One line per record.

    Returns
    -------
    records : list of harness.identification.IdentificationRecord
        In the order of ``IDENTIFICATION_CREEP_SCENARIOS``.
    truth : dict
        ``{label: plant parameters}``.
    """
    from .identification import IdentificationRecord

    noise = float(noise_rms_um)
    if not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise rms must be a finite number >= 0 um, got {noise_rms_um!r}")
    seed = int(seed)
    top = 2 ** 31 - len(IDENTIFICATION_CREEP_SCENARIOS)     # sensor.seed is an FMI Integer
    if not 0 <= seed < top:
        raise ValueError(f"seed must be in [0, {top}), got {seed}")
    _, open_loop = _simulator(backend)
    prog = _Progress(len(IDENTIFICATION_CREEP_SCENARIOS), progress)
    records, truth = [], {}
    for i, name in enumerate(IDENTIFICATION_CREEP_SCENARIOS):
        t0 = _time.perf_counter()
        sc = get_scenario(name)
        label = _record_label(sc)
        params = _true_params(sc)
        v = sc.signal.evaluate(sc.time_grid())
        run = open_loop({**{k: p for k, p in params.items() if isinstance(p, float)},
                         "sensor.noise_rms": noise, "sensor.seed": seed + i},
                        v, step_size=sc.step_size, fmu_dir=fmu_dir)
        u, x = run["u"].copy(), run["x"].copy()
        if noise > 0:
            rng = np.random.default_rng([seed, i])
            u += noise * rng.standard_normal(u.size)
            x += noise * rng.standard_normal(x.size)
        records.append(IdentificationRecord(label, v, run["y_meas"].copy(), u, x))
        truth[label] = {**params, "h": sc.step_size}
        prog.done(f"record {label} ({backend})", _time.perf_counter() - t0)
    return records, truth


def _identification_rows(est, truth, pi_label, creep_labels):
    t = truth[pi_label]
    m = len(est.weights) - 1
    true_w = [t["pi.w0"]] + [t[f"pi.w[{j}]"] for j in range(1, m + 1)]
    rows = [IdentificationRow("w0 (fixed)" if est.w0_fixed else "w0", true_w[0], est.weights[0])]
    rows += [IdentificationRow(f"w{j}", true_w[j], est.weights[j]) for j in range(1, m + 1)]
    rows.append(IdentificationRow("w0 + w1", true_w[0] + true_w[1],
                                  est.weights[0] + est.weights[1]))
    rows += [IdentificationRow(n, t[f"tf.{n}"], getattr(est, n)) for n in ("a1", "a2", "b1", "b2")]
    for label in creep_labels:
        c = est.creep_row(label)
        rows.append(IdentificationRow(f"k_c ({label})", truth[label]["creep.k_c"], c.k_c))
        rows.append(IdentificationRow(f"alpha ({label})", truth[label]["creep.alpha"], c.alpha))
    return rows


def _err(x):
    if not math.isfinite(x):
        return "n/a"
    return "0" if x == 0 else f"{x:.2e}"


def format_identification_table(rows, title=None, markdown=False):
    """Format identification rows: parameter, true value, identified, absolute and relative error.

    Parameters
    ----------
    rows : list of IdentificationRow
    title : str, optional
    markdown : bool

    Returns
    -------
    str
    """
    cells = [[r.parameter, f"{r.true:.6g}", f"{r.identified:.10g}", _err(r.abs_error),
              _err(r.rel_error)] for r in rows]
    table = _md_table(_IDENT_HEAD, cells) if markdown else _text_table(_IDENT_HEAD, cells)
    if title:
        table = (f"### {title}\n\n" if markdown else f"{title}\n") + table
    return table


def write_identification_csv(rows, path):
    """Write identification rows as CSV (full precision; rel_error empty where the truth is 0)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(_IDENT_CSV)
        for r in rows:
            w.writerow([r.parameter, _num(r.true), _num(r.identified), _num(r.abs_error),
                        _num(r.rel_error)])
    return Path(path)


def _identification_notes(run):
    est = run.estimate
    where = ("every step fits the measured displacement y (the paper's experiment): the "
             "blocks bias each other" if run.displacement_only else
             "step 1 fits the PiezoStage output u (= P[v]), step 2 its output x (= G[u]), "
             "step 3 the measured displacement y_meas")
    notes = [
        f"Records: the six inputs of Table 1, 3 s each from rest, PiezoStage model ({run.backend}),"
        f" each with its Table 1 creep row; PI and G are the defaults (eq 21). Step 1 uses the "
        f"1 Hz record, step 2 the 5/40/80 Hz record, step 3 every record; {where}.",
        f"Noise: {run.noise_rms_um * 1e3:g} nm rms white noise on every recorded channel.",
        ("w0 is fixed at the plant's value: r_1 = 0 makes the first play operator the identity, "
         "so the data determine only w0 + w1." if est.w0_fixed else
         "w0 is fitted: r_1 = 0 makes the first play operator the identity, so only w0 + w1 is "
         "identifiable and w0 carries the sum (w1 = 0); compare the w0 + w1 row."),
        "Fit residual rms: step 1 {:.3g} nm, step 2 {:.3g} nm, step 3 {}.".format(
            est.pi_residual_rms * 1e3, est.tf_residual_rms * 1e3,
            ", ".join(f"{c.label} {c.residual_rms * 1e3:.3g} nm" for c in est.creep)),
    ]
    return notes


def run_identification(out_dir="out", *, backend="fmpy", noise_rms_um=0.0, seed=1, fmu_dir=None,
                       fix_w0=True, displacement_only=False, stream=sys.stdout,
                       progress=sys.stderr):
    """Identify the coupled model from records of the PiezoStage model; print and write the table.

    Generates the records (:func:`generate_identification_records`), runs
    :func:`harness.identification.identify_coupled_model` and compares every
    parameter with the value the plant ran.  Files: ``identification.csv``
    and ``identification.md`` under ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
    backend : {"fmpy", "core"}
    noise_rms_um : float
        Measurement noise [um rms] (see :func:`generate_identification_records`).
    seed : int
    fmu_dir : str or Path, optional
    fix_w0 : bool
        Give step 1 the plant's ``w0`` (default); otherwise fit ``w0 + w1`` into ``w0``.
    displacement_only : bool
        Fit every step to the measured displacement only (drop ``u`` and ``x``).
    stream, progress : file-like or None

    Returns
    -------
    IdentificationRun
    """
    from dataclasses import replace as _replace

    from .identification import identify_coupled_model

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = _time.perf_counter()
    records, truth = generate_identification_records(
        backend=backend, noise_rms_um=noise_rms_um, seed=seed, fmu_dir=fmu_dir, progress=progress)
    if displacement_only:
        records = [_replace(r, u=None, x=None) for r in records]
    by_label = {r.label: r for r in records}
    pi_label = _record_label(get_scenario(IDENTIFICATION_PI_SCENARIO))
    tf_label = _record_label(get_scenario(IDENTIFICATION_TF_SCENARIO))
    t_pi = truth[pi_label]
    est = identify_coupled_model(by_label[pi_label], by_label[tf_label], records, t_pi["h"],
                                 m=t_pi["pi.m"], v_max=t_pi["pi.v_max"],
                                 w0=t_pi["pi.w0"] if fix_w0 else None, delay=t_pi["tf.delay"])
    rows = _identification_rows(est, truth, pi_label, [r.label for r in records])
    run = IdentificationRun(est, rows, truth, backend, float(noise_rms_um), bool(displacement_only),
                            _time.perf_counter() - t0)

    title = (f"Identification (paper section 3): PiezoStage model, backend {backend}, "
             f"noise {run.noise_rms_um * 1e3:g} nm rms")
    notes = _identification_notes(run)
    files = [write_identification_csv(rows, out / "identification.csv")]
    md = (format_identification_table(rows, title, markdown=True) + "\n\nNotes:\n\n"
          + "\n".join(f"- {n}" for n in notes) + "\n")
    (out / "identification.md").write_text(md)
    files.append(out / "identification.md")
    if stream is not None:
        stream.write(format_identification_table(rows, title) + "\n")
        stream.write("Notes:\n" + "\n".join(f"  - {n}" for n in notes) + "\n")
        stream.write(f"\nWrote {len(files)} files to {out}/ ({run.elapsed_s:.1f} s)\n")
        stream.flush()
    return run
