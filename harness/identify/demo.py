"""The virtual experiment: identify a stage whose true parameters are known.

A virtual stage, the PiezoStage FMU with parameters that differ from the
defaults (:data:`DEMO_PLANT`: other PI weight ratios, the paper's 10 Hz creep
row for every input, the mismatch case's ``G``) and a realistic sensor (2 nm
resolution, 1 nm rms noise), is driven with the paper's six validation inputs
(Tables 1-3), 10 s each from rest.  The records (``time, v, y`` with
``y = y_meas``) are written as CSV and read back through the same path as a
user's data (:func:`harness.identify.from_files.identify_files`); the fit sees only
``v`` and ``y``.  The result is compared with the truth, normalised the same
way, and with the sensor's noise floor on the held-out samples (``rms(y_meas
- y)``, ``y`` the stage's true displacement, which only a virtual stage gives).

:func:`run_demo` also checks what the identification promises and lists any
failure in :attr:`DemoResult.failures` (the command line then exits 3):

* noise-free records: held-out ``e_rms <= 1 nm``; weight ratios ``w_j/w0``,
  poles and zero within 1e-3; ``alpha`` within 1e-3; static gain within 0.1 %;
* with the sensor: held-out ``e_rms`` within 1.5 times the noise floor;
* always: the coupled model beats the Hammerstein model on every record.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
import sys
import time as _time

import numpy as np

from .. import masters
from ..scenarios import get_scenario
from .data import MIN_RECORD_SAMPLES, count_reversals, write_record
from .fit import DEFAULT_MAX_EVALUATIONS, CoupledModel
from .from_files import PI_MIN_REVERSALS, identify_files, output_paths, write_outputs
from .result_tables import format_report

__all__ = ["DEMO_PLANT", "DEMO_SENSOR", "DEMO_INPUTS", "DemoResult", "demo_truth",
           "generate_demo_records", "check_demo_duration", "run_demo", "check_demo"]

#: The virtual stage: PI weights (w_j/w0 differ from the defaults', w7..w9 = 0), the paper's
#: 10 Hz creep row, and G of the mismatch case (numerator x 1.05, fast pole 0.45).
DEMO_PLANT = {
    "pi.m": 9, "pi.v_max": 20.0,
    "pi.w0": 0.28, "pi.w[1]": 0.085, "pi.w[2]": 0.05, "pi.w[3]": 0.025, "pi.w[4]": 0.012,
    "pi.w[5]": 0.006, "pi.w[6]": 0.003, "pi.w[7]": 0.0, "pi.w[8]": 0.0, "pi.w[9]": 0.0,
    "tf.a1": -1.442037, "tf.a2": 0.44641665, "tf.b1": 0.62517, "tf.b2": -0.620235,
    "creep.k_c": 1.0497, "creep.alpha": -0.0085,
}
#: The sensor of the virtual stage: 2 nm resolution, 1 nm rms noise.
DEMO_SENSOR = {"sensor.resolution": 0.002, "sensor.noise_rms": 0.001}
#: The paper's validation inputs (Tables 1-3): scenario name of each, in order.
DEMO_INPUTS = ("validate_1hz", "validate_10hz", "validate_20hz", "validate_50hz",
               "validate_100hz", "validate_5_40_80hz")
#: Inputs of steps 1 and 2.
PI_INPUT, TF_INPUT = "validate_1hz", "validate_5_40_80hz"


@dataclass
class DemoResult:
    """Result of :func:`run_demo`.

    Attributes
    ----------
    result : IdentificationResult
    truth : CoupledModel
        The virtual stage, normalised.
    floors : dict
        Noise floor [um] on each record's held-out samples.
    records : dict
        Record label -> CSV path.
    files : list of Path
        Parameter file and reports.
    noise : bool
    failures : list of str
        Checks that failed (empty: every promise held).
    elapsed_generate_s, elapsed_fit_s : float
    """

    result: object
    truth: object
    floors: dict
    records: dict
    files: list
    noise: bool
    failures: list
    elapsed_generate_s: float
    elapsed_fit_s: float


def demo_truth(h=0.0005):
    """The virtual stage as a :class:`CoupledModel` (not normalised)."""
    p = DEMO_PLANT
    m = p["pi.m"]
    weights = (p["pi.w0"],) + tuple(p[f"pi.w[{j}]"] for j in range(1, m + 1))
    return CoupledModel(weights, p["pi.v_max"], p["tf.a1"], p["tf.a2"], p["tf.b1"], p["tf.b2"],
                        p["creep.k_c"], p["creep.alpha"], h)


def _label(scenario):
    return "-".join(f"{f:g}" for f in scenario.signal.frequencies) + "Hz"


def generate_demo_records(folder, *, duration=10.0, noise=True, seed=1, fmu_dir=None,
                          backend="fmpy", holdout=0.25, progress=None):
    """Run the virtual stage on the validation inputs and write one CSV record per input.

    Parameters
    ----------
    folder : str or Path
        Where ``<label>.csv`` go (created).
    duration : float
        Length of each record [s].
    noise : bool
        With the sensor of :data:`DEMO_SENSOR` (seed ``seed + i`` for input i),
        or noise-free.
    seed : int
    fmu_dir : str or Path, optional
        Folder of PiezoStage.fmu.
    backend : {"fmpy", "core"}
        Run the FMU (default) or the C core (the same code without FMI).
    holdout : float
        Fraction at the end of each record over which the noise floor is taken.
    progress : file-like, optional

    Returns
    -------
    paths : dict
        Label -> CSV path, in :data:`DEMO_INPUTS` order.
    floors : dict
        Label -> ``rms(y_meas - y)`` over the held-out samples [um].
    """
    if backend not in masters.OPEN_LOOP_BACKENDS:
        raise ValueError(f"backend must be 'fmpy' or 'core', got {backend!r}")
    simulate_open_loop = masters.open_loop(backend)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths, floors = {}, {}
    for i, name in enumerate(DEMO_INPUTS):
        t0 = _time.perf_counter()
        sc = get_scenario(name)
        h = sc.step_size
        n = int(round(duration / h))
        time = np.arange(n) * h
        v = sc.signal.evaluate(time)
        params = dict(DEMO_PLANT)
        if noise:
            params.update(DEMO_SENSOR)
            params["sensor.seed"] = int(seed) + i
        run = simulate_open_loop(params, v, step_size=h, fmu_dir=fmu_dir)
        label = _label(sc)
        paths[label] = write_record(folder / f"{label}.csv", time, v, run["y_meas"])
        k = int(round(n * (1.0 - holdout)))
        floors[label] = float(np.sqrt(np.mean((run["y_meas"][k:] - run["y"][k:]) ** 2)))
        if progress is not None:
            progress.write(f"[{i + 1}/{len(DEMO_INPUTS)}] record {label}: {duration:g} s, "
                           f"{_time.perf_counter() - t0:.2f} s\n")
            progress.flush()
    return paths, floors


def check_demo(result, truth, floors, noise):
    """The promises of the identification, checked against the truth; a list of failures."""
    fail = []
    for h in result.held_out:
        if not h.coupled_e_rms < h.hammerstein_e_rms:
            fail.append(f"{h.label}: the coupled model ({h.coupled_e_rms * 1e3:.4g} nm) does not "
                        f"beat the Hammerstein model ({h.hammerstein_e_rms * 1e3:.4g} nm)")
        bound = 1.5 * floors[h.label] if noise else 1e-3
        what = "1.5 x the noise floor" if noise else "1 nm"
        if not h.coupled_e_rms <= bound:
            fail.append(f"{h.label}: held-out e_rms {h.coupled_e_rms * 1e3:.4g} nm exceeds "
                        f"{what} ({bound * 1e3:.4g} nm)")
    if noise:
        return fail
    m = result.model
    ratios = np.array(m.weights[2:]) / m.weights[0] - np.array(truth.weights[2:]) / truth.weights[0]
    errors = {
        "weight ratios w_j/w0": (float(np.max(np.abs(ratios))), 1e-3),
        "poles": (float(np.max(np.abs(np.subtract(m.poles, truth.poles)))), 1e-3),
        "zero": (abs(m.zero - truth.zero), 1e-3),
        "alpha": (abs(m.alpha - truth.alpha), 1e-3),
        "static gain (relative)": (abs(m.static_gain / truth.static_gain - 1), 1e-3),
    }
    for what, (err, bound) in errors.items():
        if not err <= bound:
            fail.append(f"{what}: error {err:.3g} exceeds {bound:g}")
    return fail


def check_demo_duration(duration, h=0.0005):
    """Refuse a record length the identification would refuse, before anything is written.

    Each record needs :data:`harness.identify.data.MIN_RECORD_SAMPLES` samples, and the
    records of steps 1 and 2 need :data:`harness.identify.from_files.PI_MIN_REVERSALS` voltage
    reversals (the check :func:`harness.identify.data.read_record` makes on the files).

    Raises
    ------
    ValueError
        One line naming the shortest length that works.
    """
    def enough(d):
        n = int(round(d / h))
        if n < MIN_RECORD_SAMPLES:
            return False
        t = np.arange(n) * h
        return all(count_reversals(get_scenario(name).signal.evaluate(t)) >= PI_MIN_REVERSALS
                   for name in (PI_INPUT, TF_INPUT))

    duration = float(duration)
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be a positive number of seconds, got {duration!r}")
    if not enough(duration):
        shortest = next(d / 10 for d in range(1, 601) if enough(d / 10))
        raise ValueError(f"--duration {duration:g} s is too short: each record needs "
                         f"{MIN_RECORD_SAMPLES} samples and the {_label(get_scenario(PI_INPUT))} "
                         f"record {PI_MIN_REVERSALS} voltage reversals; use --duration "
                         f"{shortest:g} or more")


def run_demo(out="out", *, duration=10.0, noise=True, seed=1, holdout=0.25, fmu_dir=None,
             backend="fmpy", stream=sys.stdout, progress=sys.stderr, max_evaluations=None):
    """The virtual experiment end to end: records, identification, tables, checks.

    Parameters
    ----------
    out : str or Path
        A ``.json`` path for the parameter file, or a folder (``params.json``
        in it); the records go to ``demo_records/`` beside it.
    duration : float
        Record length [s] (10 s in the demo; at least about 2 s, see
        :func:`check_demo_duration`).
    noise : bool
        With the 2 nm / 1 nm sensor (default) or noise-free.
    seed : int
    holdout : float
        Fraction of each record held out.
    fmu_dir : str or Path, optional
    backend : {"fmpy", "core"}
        Generate the records with the FMU (default) or the C core.
    stream, progress : file-like or None
        Where the tables and the progress lines go.
    max_evaluations : int, optional
        As :func:`harness.identify.fit.fit_coupled_model`.

    Returns
    -------
    DemoResult
    """
    check_demo_duration(duration)
    duration = float(duration)
    params_path, _, _ = output_paths(out)
    folder = params_path.parent / "demo_records"
    t0 = _time.perf_counter()
    paths, floors = generate_demo_records(folder, duration=duration, noise=noise, seed=seed,
                                          fmu_dir=fmu_dir, backend=backend, holdout=holdout,
                                          progress=progress)
    t1 = _time.perf_counter()
    pi_label, tf_label = _label(get_scenario(PI_INPUT)), _label(get_scenario(TF_INPUT))
    say = None
    if progress is not None:
        def say(line):
            progress.write(f"identify: {line}\n")
            progress.flush()
    result, records = identify_files(paths[pi_label], paths[tf_label], list(paths.values()),
                                     h=get_scenario(PI_INPUT).step_size, holdout=holdout,
                                     max_evaluations=max_evaluations or DEFAULT_MAX_EVALUATIONS,
                                     progress=say)
    t2 = _time.perf_counter()
    truth = demo_truth(result.model.h).normalized()
    failures = check_demo(result, truth, floors, noise)
    sensor = ("2 nm resolution, 1 nm rms noise" if noise else "noise-free")
    header = [
        f"Virtual experiment: the PiezoStage {'FMU' if backend == 'fmpy' else 'model (C core)'} with known parameters (other PI weights, the "
        f"10 Hz creep row, another G), sensor {sensor}; the six validation inputs, "
        f"{duration:g} s each, written as CSV to {folder} and identified from v and y only.",
        f"Step 1: {pi_label}, step 2: {tf_label}, step 3 and joint refinement: all six records; "
        f"the last {holdout:.0%} of each record held out. Records {t1 - t0:.1f} s, "
        f"identification {t2 - t1:.1f} s.",
    ]
    files = write_outputs(result, out, records=records, truth=truth, floors=floors,
                          header=header)
    if stream is not None:
        stream.write(format_report(result, truth=truth, floors=floors, header=header) + "\n\n")
        if failures:
            stream.write("CHECKS FAILED:\n" + "\n".join(f"  - {f}" for f in failures) + "\n")
        else:
            stream.write("Checks: " + ("held-out e_rms within 1.5 x the noise floor" if noise
                                       else "held-out e_rms <= 1 nm; weight ratios, poles, "
                                            "zero and alpha within 1e-3; static gain within "
                                            "0.1 %")
                         + "; coupled beats Hammerstein on every record: passed.\n")
        stream.write(f"Wrote {params_path} and its reports ({files[1].name}, {files[2].name}); "
                     f"records in {folder}/\n")
        stream.flush()
    return DemoResult(result, truth, floors, {k: Path(v) for k, v in paths.items()}, files,
                      bool(noise), failures, t1 - t0, t2 - t1)
