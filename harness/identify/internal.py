"""``identify --internal-channels``: the paper's three steps (section 3), each alone, on
records of the PiezoStage model that include its internal outputs, and every parameter
next to the value the plant ran.

:func:`generate_identification_records` runs the model on the six inputs of Table 1;
:func:`run_identification` identifies them and writes ``identification.csv`` and
``identification.md``.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, replace
import math
from pathlib import Path
import sys
import time as _time

import numpy as np

from .. import masters
from ..binding import core
from ..progress import Progress
from ..scenarios import VALIDATION_SCENARIOS, get_scenario, reference_label
from ..text_tables import markdown_table, num, text_table
from .steps import IdentificationRecord, identify_coupled_model

__all__ = [
    "IDENTIFICATION_PI_SCENARIO",
    "IDENTIFICATION_TF_SCENARIO",
    "IDENTIFICATION_CREEP_SCENARIOS",
    "IdentificationRow",
    "IdentificationRun",
    "generate_identification_records",
    "format_identification_table",
    "write_identification_csv",
    "run_identification",
]

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
    estimate : harness.identify.CoupledModelEstimate
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


def _true_params(sc):
    """The plant parameters that define a record: core defaults, then the scenario's overrides."""
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
    records : list of harness.identify.IdentificationRecord
        In the order of ``IDENTIFICATION_CREEP_SCENARIOS``.
    truth : dict
        ``{label: plant parameters}``.
    """
    noise = float(noise_rms_um)
    if not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise rms must be a finite number >= 0 um, got {noise_rms_um!r}")
    seed = int(seed)
    top = 2 ** 31 - len(IDENTIFICATION_CREEP_SCENARIOS)     # sensor.seed is an FMI Integer
    if not 0 <= seed < top:
        raise ValueError(f"seed must be in [0, {top}), got {seed}")
    open_loop = masters.open_loop(backend)
    prog = Progress(len(IDENTIFICATION_CREEP_SCENARIOS), progress)
    records, truth = [], {}
    for i, name in enumerate(IDENTIFICATION_CREEP_SCENARIOS):
        t0 = _time.perf_counter()
        sc = get_scenario(name)
        label = reference_label(sc)
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
    table = markdown_table(_IDENT_HEAD, cells) if markdown else text_table(_IDENT_HEAD, cells)
    if title:
        table = (f"### {title}\n\n" if markdown else f"{title}\n") + table
    return table


def write_identification_csv(rows, path):
    """Write identification rows as CSV (full precision; rel_error empty where the truth is 0)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(_IDENT_CSV)
        for r in rows:
            w.writerow([r.parameter, num(r.true), num(r.identified), num(r.abs_error),
                        num(r.rel_error)])
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
    :func:`harness.identify.identify_coupled_model` and compares every
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
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = _time.perf_counter()
    records, truth = generate_identification_records(
        backend=backend, noise_rms_um=noise_rms_um, seed=seed, fmu_dir=fmu_dir, progress=progress)
    if displacement_only:
        records = [replace(r, u=None, x=None) for r in records]
    by_label = {r.label: r for r in records}
    pi_label = reference_label(get_scenario(IDENTIFICATION_PI_SCENARIO))
    tf_label = reference_label(get_scenario(IDENTIFICATION_TF_SCENARIO))
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
