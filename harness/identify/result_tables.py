"""Tables of an identification: steps, parameters, paper Table 1 and Tables 2-3.

Plain text for the terminal, Markdown for files; every function takes an
:class:`harness.identify.fit.IdentificationResult` and, for the virtual
experiment, the true model (normalised) and the noise floors.
"""

from __future__ import annotations

import math

from ..text_tables import titled_table

__all__ = [
    "NORMALISATION_NOTE",
    "format_steps",
    "format_parameters",
    "format_creep_rows",
    "format_held_out",
    "format_search",
    "format_undetermined",
    "format_report",
]

NORMALISATION_NOTE = (
    "Normalisation: only the product of the PI, G and creep gains is identifiable, and only "
    "w0 + w1 (r_1 = 0), so parameters are reported with G(1) = 1, k_c = 1 and w1 = 0: the PI "
    "weights carry the static gain [um/V] and w0 is the static gain (w0 + w1) G(1) k_c.")


def _g(x, digits=6):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    if isinstance(x, complex):
        return f"{x.real:.{digits}g}{x.imag:+.{digits}g}j"
    return f"{x:.{digits}g}"


def _se(x):
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.2g}"


def _nm(x):
    return "n/a" if x is None or not math.isfinite(x) else f"{x * 1e3:.4g}"


def _pct(x):
    return "n/a" if x is None or not math.isfinite(x) else f"{x * 100:.4g}"


def format_steps(result, markdown=False):
    """One row per fit: step, records, e_rms [nm] and e_r [%] on the fit windows, samples."""
    rows, notes = [], []
    for s in result.steps:
        recs = s.records[0] if len(s.records) == 1 else f"{len(s.records)} records"
        rows.append([s.step, recs, _nm(s.e_rms), _pct(s.e_r), str(s.n_samples)])
        if s.note:
            notes.append(f"step {s.step} ({recs}): {s.note}")
    head = ["step", "records", "e_rms [nm]", "e_r [%]", "samples"]
    text = titled_table(head, rows, "Fits (on the fit windows, against the measured y)", markdown)
    if notes:
        text += "\n\n" + "\n".join(("- " if markdown else "  ") + n for n in notes)
    return text


def format_search(result, markdown=False):
    """The starts of the coupled model's search: where each began and ended, how well."""
    search = result.search
    if search is None:
        return ""
    rows = []
    for i, f in enumerate(search.fits, start=1):
        a, b = f.start, f.theta
        rows.append([str(i), f"{a.slow_pole:.4g}", f"{a.alpha:+.3g}", f"{b.slow_pole:.6f}",
                     f"{b.p2:.5f}", f"{b.zero:.6f}", f"{b.alpha:+.6f}", _nm(f.rms),
                     str(f.evaluations), "yes" if f.converged else "no", f"{f.elapsed_s:.1f}"])
    head = ["start", "slow pole from", "alpha from", "slow pole", "fast pole", "zero", "alpha",
            "rms [nm]", "evaluations", "converged", "time [s]"]
    title = (f"Search by variable projection ({len(search.fits)} starts, {search.agreed} at the "
             f"lowest minimum, {search.elapsed_s:.1f} s)")
    return titled_table(head, rows, title, markdown)


def format_undetermined(result, markdown=False):
    """The parameters the records do not determine, and what would (empty if none)."""
    if not result.undetermined:
        return ""
    lines = [("- " if markdown else "  ") + u.text() for u in result.undetermined]
    title = ("NOT DETERMINED by the records (no parameter file is written; standard errors with "
             "a noise of at least 1 nm rms)")
    return (f"### {title}\n\n" if markdown else f"{title}\n") + "\n".join(lines)


def _model_value(model, name):
    """A parameter of a CoupledModel by its table name (FMU name, pole i, zero, static gain)."""
    if model is None:
        return None
    p = model.plant_params()
    if name in p:
        return p[name]
    if name.startswith("pole "):
        return model.poles[int(name.split()[1]) - 1]
    return {"zero": model.zero, "static gain": model.static_gain}.get(name)


def format_parameters(result, truth=None, markdown=False):
    """Parameters of the stepwise and the joint fit, standard errors (and the truth, if known)."""
    head = ["parameter", "stepwise", "joint", "std. error"]
    if truth is not None:
        head += ["true", "joint - true"]
    rows = []
    for p in result.joint:
        row = [p.name, _g(_model_value(result.stepwise, p.name), 8), _g(p.value, 10),
               _se(p.std_error)]
        if truth is not None:
            t = _model_value(truth, p.name)
            row += [_g(t, 8), _se(p.value - t) if t is not None else "n/a"]
        rows.append(row)
    title = "Parameters under the normalisation G(1) = 1, k_c = 1, w1 = 0"
    if truth is not None:
        title += " (true: the virtual stage, normalised the same way)"
    return titled_table(head, rows, title, markdown)


def format_creep_rows(result, truth=None, markdown=False):
    """Paper Table 1: k_c and alpha of each creep record (joint PI and G fixed)."""
    head = ["record", "k_c", "std. error", "alpha", "std. error", "fit e_rms [nm]"]
    rows = []
    for r in result.creep_rows:
        k, a = r.parameters
        rows.append([r.records[0], f"{k.value:.6f}", _se(k.std_error), f"{a.value:.6f}",
                     _se(a.std_error), _nm(r.e_rms)])
    title = "Table 1: creep row of each record (joint PI and G fixed; k_c relative to the stage's)"
    if truth is not None:
        title += f"; true k_c = 1, alpha = {truth.alpha:g}"
    return titled_table(head, rows, title, markdown)


def format_held_out(result, floors=None, markdown=False):
    """Paper Tables 2-3 on the held-out samples: Hammerstein versus coupled model."""
    head = ["record", "Hammerstein e_rms [nm]", "coupled e_rms [nm]", "Hammerstein e_r [%]",
            "coupled e_r [%]"]
    if floors is not None:
        head.append("noise floor [nm]")
    rows = []
    for r in result.held_out:
        row = [r.label, _nm(r.hammerstein_e_rms), _nm(r.coupled_e_rms), _pct(r.hammerstein_e_r),
               _pct(r.coupled_e_r)]
        if floors is not None:
            row.append(_nm(floors.get(r.label, math.nan)))
        rows.append(row)
    title = (f"Tables 2-3: held-out samples (the last {result.holdout:.0%} of each record), "
             f"against the measured y")
    return titled_table(head, rows, title, markdown)


def format_report(result, *, truth=None, floors=None, header=(), markdown=False):
    """Every table of an identification, with a header and the normalisation note."""
    parts = []
    if header:
        parts.append(("\n\n" if markdown else "\n").join(header))
    if result.undetermined:
        parts.append(format_undetermined(result, markdown))
    parts.append(format_steps(result, markdown))
    if result.search is not None:
        parts.append(format_search(result, markdown))
    parts.append(format_parameters(result, truth, markdown))
    parts.append(format_creep_rows(result, truth, markdown))
    if result.held_out:
        parts.append(format_held_out(result, floors, markdown))
    parts.append(NORMALISATION_NOTE)
    return "\n\n".join(parts)
