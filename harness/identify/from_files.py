"""Identify from record files and write the outputs (what ``python -m harness identify`` runs).

:func:`read_records` reads the files of the three steps through
:mod:`harness.identify.data` (a file named for several steps is read once),
:func:`identify_files` fits them (:func:`harness.identify.fit.fit_coupled_model`),
and :func:`write_outputs` writes

* the parameter file (a flat JSON of FMU variable names, see
  :mod:`harness.identify.params`), ready for ``--plant-params``,
  ``--controller-params`` and ``export``;
* ``<stem>.report.md``: the tables (:mod:`harness.identify.result_tables`);
* ``<stem>.report.json``: everything, machine-readable (every fit with its
  parameters, standard errors and errors, the creep rows, the held-out errors).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ..paths import sha256_of
from .data import read_record
from .fit import DEFAULT_HOLDOUT, DEFAULT_MAX_EVALUATIONS, fit_coupled_model
from .params import write_params
from .result_tables import NORMALISATION_NOTE, format_report

__all__ = ["PI_MIN_REVERSALS", "read_records", "identify_files", "output_paths", "write_outputs",
           "result_to_dict"]

#: Voltage reversals the PI and G records must hold (two periods of a periodic input).
PI_MIN_REVERSALS = 4


def read_records(pi_path, tf_path, creep_paths, *, h=0.0005):
    """Read and validate the records of the three steps.

    Parameters
    ----------
    pi_path, tf_path : str or Path
        Low-frequency and mixed-frequency records (at least
        ``PI_MIN_REVERSALS`` voltage reversals each).
    creep_paths : sequence of str or Path
        Creep records (a voltage step is fine).
    h : float
        The model's sample period [s].

    Returns
    -------
    pi, tf : MeasuredRecord
    creep : list of MeasuredRecord
        The same object wherever the same file is named twice.

    Raises
    ------
    harness.identify.data.RecordError
    """
    paths = [Path(pi_path), Path(tf_path)] + [Path(p) for p in creep_paths]
    if len(paths) < 3:
        raise ValueError("need at least one creep record")
    keys = [str(p.resolve()) for p in paths]
    stems = {}
    for key, p in zip(keys, paths):
        stems.setdefault(p.stem, set()).add(key)
    need = {keys[0]: PI_MIN_REVERSALS, keys[1]: PI_MIN_REVERSALS}
    records = {}
    for key, p in zip(keys, paths):
        if key not in records:
            label = p.stem if len(stems[p.stem]) == 1 else str(p)
            records[key] = read_record(p, h=h, label=label, min_reversals=need.get(key, 0))
    return records[keys[0]], records[keys[1]], [records[k] for k in keys[2:]]


def identify_files(pi_path, tf_path, creep_paths, *, h=0.0005, m=9, v_max=None, delay=0,
                   holdout=DEFAULT_HOLDOUT, max_evaluations=DEFAULT_MAX_EVALUATIONS,
                   progress=None):
    """Read the records and identify the coupled model from their ``v`` and ``y``.

    Parameters
    ----------
    pi_path, tf_path, creep_paths, h
        As :func:`read_records`.
    m, v_max, delay, holdout, max_evaluations, progress
        As :func:`harness.identify.fit.fit_coupled_model`.

    Returns
    -------
    result : IdentificationResult
    records : list of MeasuredRecord
        The distinct records, in order of first use.
    """
    pi, tf, creep = read_records(pi_path, tf_path, creep_paths, h=h)
    result = fit_coupled_model(pi, tf, creep, h=h, m=m, v_max=v_max, delay=delay,
                               holdout=holdout, max_evaluations=max_evaluations,
                               progress=progress)
    distinct = []
    for r in [pi, tf, *creep]:
        if all(r is not d for d in distinct):
            distinct.append(r)
    return result, distinct


def output_paths(out):
    """(parameter file, Markdown report, JSON report) for ``--out``: a ``.json`` file or a folder."""
    out = Path(out)
    params = out if out.suffix.lower() == ".json" else out / "params.json"
    stem = params.with_suffix("")
    return params, Path(f"{stem}.report.md"), Path(f"{stem}.report.json")


def _num(x):
    if isinstance(x, complex):
        return [x.real, x.imag]
    x = float(x)
    return x if math.isfinite(x) else None


def _fit_dict(s):
    d = {"step": s.step, "records": list(s.records), "e_rms_um": _num(s.e_rms),
         "e_r": _num(s.e_r), "n_samples": s.n_samples,
         "parameters": {p.name: {"value": _num(p.value), "std_error": _num(p.std_error)}
                        for p in s.parameters}}
    if s.note:
        d["note"] = s.note
    return d


def _theta_dict(th):
    return {"slow_pole": th.slow_pole, "fast_pole": th.p2, "zero": th.zero, "alpha": th.alpha}


def _search_dict(search):
    if search is None:
        return None
    return {"elapsed_s": search.elapsed_s, "agreed": search.agreed,
            "starts": [{"from": _theta_dict(f.start), "to": _theta_dict(f.theta),
                        "rms_um": _num(f.rms), "evaluations": f.evaluations,
                        "converged": f.converged, "elapsed_s": f.elapsed_s}
                       for f in search.fits]}


def _record_dict(record):
    """A record's file, length and SHA-256 (what the identification was made from)."""
    d = {"path": str(record.path), "samples": record.n_samples}
    if Path(record.path).is_file():
        d["sha256"] = sha256_of(record.path)
    return d


def result_to_dict(result, records=(), truth=None, floors=None):
    """Everything of an identification as JSON-ready data."""
    d = {
        "normalisation": NORMALISATION_NOTE,
        "holdout": result.holdout,
        "records": {r.label: _record_dict(r) for r in records},
        "parameters": result.model.plant_params(),
        "joint": {p.name: {"value": _num(p.value), "std_error": _num(p.std_error)}
                  for p in result.joint},
        "stepwise_parameters": (None if result.stepwise is None
                                else result.stepwise.plant_params()),
        "hammerstein_parameters": (None if result.hammerstein is None
                                   else result.hammerstein.plant_params()),
        "fits": [_fit_dict(s) for s in result.steps],
        "creep_rows": [_fit_dict(s) for s in result.creep_rows],
        "held_out": [{"record": h.label, "samples": h.n_samples,
                      "hammerstein_e_rms_um": _num(h.hammerstein_e_rms),
                      "hammerstein_e_r": _num(h.hammerstein_e_r),
                      "coupled_e_rms_um": _num(h.coupled_e_rms),
                      "coupled_e_r": _num(h.coupled_e_r)} for h in result.held_out],
        "search": _search_dict(result.search),
        "undetermined": [{"parameter": u.parameter, "std_error": _num(u.std_error),
                          "limit": u.limit, "remedy": u.remedy} for u in result.undetermined],
        "elapsed_s": result.elapsed_s,
    }
    if truth is not None:
        d["true_parameters"] = truth.plant_params()
    if floors is not None:
        d["noise_floor_um"] = {k: _num(v) for k, v in floors.items()}
    return d


def write_outputs(result, out, *, records=(), truth=None, floors=None, header=()):
    """Write the parameter file and the two reports.

    Parameters
    ----------
    result : IdentificationResult
    out : str or Path
        A ``.json`` path for the parameter file, or a folder (``params.json`` in it).
    records : sequence of MeasuredRecord
    truth : CoupledModel, optional
        The true model, normalised (virtual experiment only).
    floors : dict, optional
        Noise floor [um] per record label (virtual experiment only).
    header : sequence of str
        Lines on top of the Markdown report.

    Returns
    -------
    list of Path
    """
    params, md, js = output_paths(out)
    if result.undetermined:
        params.unlink(missing_ok=True)      # never leave an older parameter file beside it
    else:
        write_params(params, result.model.plant_params())
    md.write_text(format_report(result, truth=truth, floors=floors, header=header,
                                markdown=True) + "\n")
    js.write_text(json.dumps(result_to_dict(result, records, truth, floors), indent=1) + "\n")
    return [params, md, js]
