"""What is written as numbers: the tables (terminal text and Markdown) and the CSV/NPZ files.

Lengths are printed in nm for tracking errors and in µm for displacements;
``e_r`` in %; the CSV files keep full precision in µm and fractions.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ..scenarios import reference_label
from ..text_tables import fmt, num, titled_table

__all__ = [
    "TIMESERIES_FORMATS",
    "format_tracking_table",
    "format_conditions_table",
    "format_validation_table",
    "tracking_table_rows",
    "conditions_table_rows",
    "validation_table_rows",
    "write_tracking_csv",
    "write_validation_csv",
    "write_timeseries",
    "write_timeseries_csv",
    "write_timeseries_npz",
]

TIMESERIES_FORMATS = ("csv", "npz")


# ---------------------------------------------------------------------------
# tracking
# ---------------------------------------------------------------------------

def tracking_table_rows(results):
    """Head and rows of a tracking table; paper columns only if a result is one of the paper's."""
    with_paper = any(r.has_paper for r in results)
    if with_paper:
        head = ["scenario", "e_rms ours [nm]", "paper [nm]", "ratio",
                "e_r ours [%]", "paper [%]", "ratio"]
        rows = [[r.scenario,
                 fmt(r.e_rms_um * 1e3, ".4g"), fmt(r.paper_e_rms_um * 1e3, ".4g"),
                 fmt(r.ratio_e_rms, ".3g"),
                 fmt(r.e_r * 100, ".4g"), fmt(r.paper_e_r * 100, ".4g"), fmt(r.ratio_e_r, ".3g")]
                for r in results]
    else:
        head = ["scenario", "e_rms [nm]", "e_r [%]", "peak |v| [V]"]
        rows = [[r.scenario, fmt(r.e_rms_um * 1e3, ".4g"), fmt(r.e_r * 100, ".4g"),
                 fmt(r.v_peak, ".4g")] for r in results]
    return head, rows


def format_tracking_table(results, title=None, markdown=False):
    """Format tracking results; next to the paper's Tables 4/5 when they are the paper's scenarios.

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
    head, rows = tracking_table_rows(results)
    return titled_table(head, rows, title, markdown)


def _tiny(x, digits=3):
    """e_rms in nm, readable from round-off (1.4e-10) to hundreds."""
    if x is None or not math.isfinite(x):
        return "n/a"
    return format(x, f".{digits}g") if x >= 0.01 else format(x, ".1e")


def conditions_table_rows(conditions, tracking):
    """One row per reference, one e_rms [nm] column per condition, paper first.

    Parameters
    ----------
    conditions : list of Condition
        Built-in conditions (same references in the same order).
    tracking : dict
        Condition key -> list of TrackingResult.
    """
    head = ["reference", "paper"] + [c.short_label for c in conditions]
    first = tracking[conditions[0].key]
    rows = []
    for i, r0 in enumerate(first):
        row = [reference_label(r0.spec) if r0.spec is not None else r0.scenario,
               _tiny(r0.paper_e_rms_um * 1e3, 4)]
        row += [_tiny(tracking[c.key][i].e_rms_um * 1e3) for c in conditions]
        rows.append(row)
    return head, rows


def format_conditions_table(conditions, tracking, title=None, markdown=False):
    """The e_rms [nm] of every built-in condition side by side, with the paper's Table 4."""
    head, rows = conditions_table_rows(conditions, tracking)
    return titled_table(head, rows, title, markdown)


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------

def validation_table_rows(results, markdown=False):
    """Head and rows of the validation table (≤ 100 columns as text).

    ``C − H``: coupled minus Hammerstein model output; ``paper H / C``: the
    paper's e_rms of the Hammerstein and the coupled model against measured
    data (Table 2), for reference only.  Markdown adds the paper's e_r (Table 3).
    """
    with_paper = any(r.has_paper for r in results)
    head = ["input", "k_c", "α", "C − H e_rms [µm]", "C − H e_r [%]", "y span [µm]"]
    if with_paper:
        head.append("paper H / C [µm]")
        if markdown:
            head.append("paper H / C e_r [%]")
    rows = []
    for r in results:
        row = [r.scenario, fmt(r.k_c, ".4f"), fmt(r.alpha, ".4f"), fmt(r.diff_e_rms_um, ".4f"),
               fmt(r.diff_e_r * 100, ".3f"), f"{fmt(r.y_min_um, '.2f')}–{fmt(r.y_max_um, '.2f')}"]
        if with_paper:
            row.append(f"{fmt(r.paper_hammerstein_e_rms_um, '.4f')} / "
                       f"{fmt(r.paper_coupled_e_rms_um, '.4f')}")
            if markdown:
                row.append(f"{fmt(r.paper_hammerstein_e_r * 100, '.2f')} / "
                           f"{fmt(r.paper_coupled_e_r * 100, '.2f')}")
        rows.append(row)
    return head, rows


def format_validation_table(results, title=None, markdown=False):
    """Format validation results (coupled vs Hammerstein model), the paper's Tables 2/3 beside.

    Parameters
    ----------
    results : list of ValidationResult
    title : str, optional
    markdown : bool

    Returns
    -------
    str
    """
    head, rows = validation_table_rows(results, markdown)
    return titled_table(head, rows, title, markdown)


# ---------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------

_TRACK_CSV = ["condition", "scenario", "adaptation", "preview", "master", "e_rms_um", "e_r",
              "paper_e_rms_um", "paper_e_r", "ratio_e_rms", "ratio_e_r", "v_peak_V",
              "n_samples", "elapsed_s"]
_VALID_CSV = ["scenario", "k_c", "alpha", "diff_e_rms_um", "diff_e_r", "y_min_um", "y_max_um",
              "paper_hammerstein_e_rms_um", "paper_coupled_e_rms_um", "paper_hammerstein_e_r",
              "paper_coupled_e_r", "elapsed_s"]


def write_tracking_csv(results, path):
    """Write tracking results as CSV (full precision; e_r as a fraction, lengths in um)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(_TRACK_CSV)
        for r in results:
            w.writerow([r.condition, r.scenario, int(r.adaptation), int(r.preview), r.master,
                        num(r.e_rms_um), num(r.e_r), num(r.paper_e_rms_um),
                        num(r.paper_e_r), num(r.ratio_e_rms), num(r.ratio_e_r),
                        num(r.v_peak), r.n_samples, f"{r.elapsed_s:.3f}"])
    return Path(path)


def write_validation_csv(results, path):
    """Write validation results as CSV (full precision; e_r as a fraction)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(_VALID_CSV)
        for r in results:
            w.writerow([r.scenario] + [num(getattr(r, k)) for k in _VALID_CSV[1:-1]]
                       + [f"{r.elapsed_s:.3f}"])
    return Path(path)


#: rows formatted at a time by :func:`write_timeseries_csv`
_CSV_BLOCK_ROWS = 8192


def write_timeseries_csv(data, path):
    """Write a structured result array as CSV with a header of its field names.

    Every value is written as the shortest text that reads back as the same double
    (Python's ``repr``: ``0.0005``, not ``0.00050000000000000001``), with LF line
    endings on every platform.  Blocks of rows go through ``str`` of a list, which
    formats each float with ``repr`` in C, as fast as ``numpy.savetxt``.
    """
    names = data.dtype.names
    arr = np.column_stack([np.asarray(data[n], dtype=np.float64) for n in names])
    with open(path, "w", newline="\n", encoding="ascii") as fh:
        fh.write(",".join(names) + "\n")
        for start in range(0, arr.shape[0], _CSV_BLOCK_ROWS):
            text = str(arr[start:start + _CSV_BLOCK_ROWS].tolist())   # "[[a, b], [c, d]]"
            fh.write(text[2:-2].replace("], [", "\n").replace(", ", ",") + "\n")
    return Path(path)


def write_timeseries_npz(data, path):
    """Write a structured result array as NumPy ``.npz``: one float64 array per field.

    8 bytes per value instead of about 23 characters in the CSV, and no
    formatting: ``numpy.load(path)["y"]`` reads a column back exactly.
    """
    np.savez(path, **{n: np.ascontiguousarray(data[n]) for n in data.dtype.names})
    return Path(path)


def write_timeseries(data, stem, fmt="csv"):
    """Write a time series as ``<stem>.csv`` or ``<stem>.npz``; return the path."""
    if fmt == "csv":
        return write_timeseries_csv(data, Path(f"{stem}.csv"))
    if fmt == "npz":
        return write_timeseries_npz(data, Path(f"{stem}.npz"))
    raise ValueError(f"timeseries format must be one of {', '.join(TIMESERIES_FORMATS)}, "
                     f"got {fmt!r}")


def timeseries_size(data, fmt):
    """Approximate size in bytes of a time series written in a format (CSV: about 18
    characters per value, measured on a 600 s closed-loop run)."""
    values = data.size * len(data.dtype.names)
    return values * (8 if fmt == "npz" else 18)
