"""Validation on a family of stages: identification checked on many stages, not on one demo.

:func:`draw_stage` draws a stage at random from around the paper's ranges
(:data:`FAMILY_RANGES`); :func:`validate_stage` records it with a record set
(:data:`RECORD_SETS`) on the C core (the FMU's own code), identifies it from ``v``
and ``y`` alone, and measures

* the held-out error: rms of ``y_model - y_meas`` on the last quarter of each
  record (the worst record), as a user would see it;
* the error against the truth: rms of ``y_model - y_true`` on a held-out input
  (:data:`HELD_OUT_INPUT`, a voltage used by no record set) against the stage's
  noise-free displacement, which only a simulated stage gives;

and :func:`validate_family` does it for ``n`` stages drawn with one seed and
summarises the distribution (median and worst).  ``python -m harness identify
--family N`` prints it; ``tests/test_identify_family.py`` holds the acceptance
bounds.

The ranges (Table 1 of the paper spans alpha -0.0098 .. 0.0002 and k_c 1.017 ..
1.050; a stage of another make may sit a little outside):

=====================  =========================================================
creep order alpha      uniform in [-0.012, 0.015]
creep gain k_c         uniform in [1.0, 1.06]
slow pole p1           uniform in [0.985, 0.996]
fast pole p2           uniform in [0.3, 0.6]
zero                   ``p1 - delta``, delta uniform in [-1e-4, 1e-3] (the paper's
                       zero sits 6.9e-5 beyond its slow pole)
static gain of G       the paper's 0.959 times a factor uniform in [0.8, 1.2]
PI weights             w0 uniform in [0.25, 0.4]; 2 to 5 of w1 .. w9 nonzero
                       (3 to 6 nonzero weights in all), each uniform in [0.003, 0.1],
                       decreasing with the threshold; m = 9, v_max = 20 V
=====================  =========================================================
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time as _time

import numpy as np

from .. import masters
from .fit import fit_coupled_model
from .steps import IdentificationRecord

__all__ = ["FAMILY_RANGES", "RECORD_SETS", "HELD_OUT_INPUT", "SENSOR", "StageResult",
           "FamilyResult", "draw_stage", "record_inputs", "simulate_records", "validate_stage",
           "validate_family"]

H = 0.0005
#: The ranges stages are drawn from (see the module docstring).
FAMILY_RANGES = {
    "creep.alpha": (-0.012, 0.015),
    "creep.k_c": (1.0, 1.06),
    "slow pole": (0.985, 0.996),
    "fast pole": (0.3, 0.6),
    "zero below the slow pole": (-1e-4, 1e-3),
    "static gain of G / 0.959": (0.8, 1.2),
    "pi.w0": (0.25, 0.4),
    "nonzero w1..w9": (2, 5),
    "w_j": (0.003, 0.1),
}
#: The paper's G (eq 21) static gain, around which the family's gains are drawn.
PAPER_DC_GAIN = (0.5954 - 0.5907) / (1 - 1.3767 + 0.3816)
#: The sensor of the noisy records: 2 nm resolution, 1 nm rms noise (the paper's sensor).
SENSOR = {"sensor.resolution": 0.002, "sensor.noise_rms": 0.001}


def _sine(f, amplitude=10.0, offset=10.0):
    return lambda t: amplitude * np.sin(2 * np.pi * f * t) + offset


def _mixed(t):
    return 6.0 * (np.sin(2 * np.pi * 5 * t) + np.sin(2 * np.pi * 40 * t)
                  + np.sin(2 * np.pi * 80 * t)) + 18.0


#: The voltage of each record, by label (the paper's validation inputs, Tables 1-3).
INPUTS = {"1Hz": _sine(1.0), "10Hz": _sine(10.0), "20Hz": _sine(20.0), "50Hz": _sine(50.0),
          "100Hz": _sine(100.0), "5-40-80Hz": _mixed}
#: Record sets: (PI record, G record, creep records), by label.
RECORD_SETS = {
    "standard": ("1Hz", "5-40-80Hz", ("1Hz", "5-40-80Hz", "10Hz")),
    "two": ("1Hz", "5-40-80Hz", ("1Hz", "5-40-80Hz")),
    "six": ("1Hz", "5-40-80Hz", ("1Hz", "10Hz", "20Hz", "50Hz", "100Hz", "5-40-80Hz")),
}
#: A voltage no record set uses: 2, 15 and 35 Hz tones around 12 V, 3 s.
HELD_OUT_INPUT = ("2-15-35Hz", lambda t: 4.0 * (np.sin(2 * np.pi * 2 * t)
                                                + np.sin(2 * np.pi * 15 * t)
                                                + np.sin(2 * np.pi * 35 * t)) + 12.0, 3.0)


def draw_stage(rng):
    """A stage drawn from :data:`FAMILY_RANGES`, as PiezoStage parameters.

    Parameters
    ----------
    rng : numpy.random.Generator

    Returns
    -------
    dict
        ``pi.*``, ``tf.*``, ``creep.*`` by FMU variable name.
    """
    lo_hi = FAMILY_RANGES
    p1 = rng.uniform(*lo_hi["slow pole"])
    p2 = rng.uniform(*lo_hi["fast pole"])
    zeta = p1 - rng.uniform(*lo_hi["zero below the slow pole"])
    gain = PAPER_DC_GAIN * rng.uniform(*lo_hi["static gain of G / 0.959"])
    b1 = gain * (1 - p1) * (1 - p2) / (1 - zeta)
    k = int(rng.integers(lo_hi["nonzero w1..w9"][0], lo_hi["nonzero w1..w9"][1] + 1))
    w = np.zeros(9)
    w[:k] = np.sort(rng.uniform(*lo_hi["w_j"], size=k))[::-1]
    params = {"pi.m": 9, "pi.v_max": 20.0, "pi.w0": float(rng.uniform(*lo_hi["pi.w0"]))}
    params.update({f"pi.w[{j + 1}]": float(w[j]) for j in range(9)})
    params.update({"tf.a1": -(p1 + p2), "tf.a2": p1 * p2, "tf.b1": b1, "tf.b2": -b1 * zeta,
                   "creep.k_c": float(rng.uniform(*lo_hi["creep.k_c"])),
                   "creep.alpha": float(rng.uniform(*lo_hi["creep.alpha"]))})
    return params


def record_inputs(record_set="standard"):
    """The distinct record labels of a record set, in order of first use."""
    pi, tf, creep = RECORD_SETS[record_set]
    return list(dict.fromkeys([pi, tf, *creep]))


def _run(params, v, noise, seed):
    p = dict(params)
    if noise:
        p.update(SENSOR)
        p["sensor.seed"] = int(seed)
    run = masters.open_loop("core")(p, v, step_size=H)
    return np.asarray(run["y_meas"], dtype=float), np.asarray(run["y"], dtype=float)


def simulate_records(params, record_set="standard", *, duration=10.0, noise=False, seed=1):
    """Records of a stage on the C core: ``{label: IdentificationRecord}`` (``y`` = ``y_meas``)."""
    n = int(round(duration / H))
    t = np.arange(n) * H
    out = {}
    for i, label in enumerate(record_inputs(record_set)):
        v = INPUTS[label](t)
        y_meas, _ = _run(params, v, noise, seed * 100 + i)
        out[label] = IdentificationRecord(label, v, y_meas)
    return out


@dataclass(frozen=True)
class StageResult:
    """One stage of a family: its truth, and how well it was identified.

    Attributes
    ----------
    index : int
    truth : dict
        The stage's parameters.
    held_out_e_rms : float
        Worst record's rms of ``y_model - y_meas`` on its held-out samples [um].
    truth_e_rms : float
        rms of ``y_model - y_true`` on :data:`HELD_OUT_INPUT` [um].
    alpha_error : float
        Identified minus true creep order.
    undetermined : tuple of str
        Parameters the identification could not determine (should be empty).
    starts : int
        Starts of the search that ran.
    elapsed_s : float
        Identification time (records excluded) [s].
    """

    index: int
    truth: dict
    held_out_e_rms: float
    truth_e_rms: float
    alpha_error: float
    undetermined: tuple
    starts: int
    elapsed_s: float


def validate_stage(params, *, record_set="standard", duration=10.0, noise=False, seed=1,
                   index=0, hammerstein=False):
    """Identify one stage from its records and measure the errors (a :class:`StageResult`)."""
    pi, tf, creep = RECORD_SETS[record_set]
    records = simulate_records(params, record_set, duration=duration, noise=noise, seed=seed)
    t0 = _time.perf_counter()
    result = fit_coupled_model(records[pi], records[tf], [records[c] for c in creep], h=H,
                               v_max=20.0, hammerstein=hammerstein)
    elapsed = _time.perf_counter() - t0
    label, signal, seconds = HELD_OUT_INPUT
    t = np.arange(int(round(seconds / H))) * H
    v = signal(t)
    _, y_true = _run(params, v, False, 0)
    e_truth = float(np.sqrt(np.mean((result.model.simulate(v) - y_true) ** 2)))
    return StageResult(index=index, truth=dict(params),
                       held_out_e_rms=max(h.coupled_e_rms for h in result.held_out),
                       truth_e_rms=e_truth, alpha_error=result.model.alpha - params["creep.alpha"],
                       undetermined=tuple(u.parameter for u in result.undetermined),
                       starts=len(result.search.fits), elapsed_s=elapsed)


@dataclass(frozen=True)
class FamilyResult:
    """A family's results and their distribution."""

    stages: tuple
    record_set: str
    duration: float
    noise: bool
    seed: int

    def column(self, name):
        return np.array([getattr(s, name) for s in self.stages], dtype=float)

    def summary(self):
        """``{quantity: (median, worst)}`` of the errors [um], |alpha error| and time [s]."""
        out = {}
        for name in ("held_out_e_rms", "truth_e_rms", "elapsed_s"):
            c = self.column(name)
            out[name] = (float(np.median(c)), float(np.max(c)))
        a = np.abs(self.column("alpha_error"))
        out["alpha_error"] = (float(np.median(a)), float(np.max(a)))
        return out

    def format(self):
        """A few lines: the family, the medians and the worst cases."""
        s = self.summary()
        undetermined = sum(bool(st.undetermined) for st in self.stages)
        sensor = "2 nm resolution + 1 nm rms noise" if self.noise else "noise-free"
        lines = [f"{len(self.stages)} stages (seed {self.seed}), record set '{self.record_set}' "
                 f"({', '.join(record_inputs(self.record_set))}), {self.duration:g} s each, "
                 f"{sensor}",
                 f"  held-out e_rms vs measured y [nm]: median {s['held_out_e_rms'][0] * 1e3:.4g}, "
                 f"worst {s['held_out_e_rms'][1] * 1e3:.4g}",
                 f"  error vs noise-free truth on {HELD_OUT_INPUT[0]} [nm]: median "
                 f"{s['truth_e_rms'][0] * 1e3:.4g}, worst {s['truth_e_rms'][1] * 1e3:.4g}",
                 f"  |alpha error|: median {s['alpha_error'][0]:.3g}, worst "
                 f"{s['alpha_error'][1]:.3g}",
                 f"  identification time [s]: median {s['elapsed_s'][0]:.2f}, worst "
                 f"{s['elapsed_s'][1]:.2f}",
                 f"  stages with an undetermined parameter: {undetermined}"]
        return "\n".join(lines)


def validate_family(n=50, *, seed=2026, record_set="standard", duration=10.0, noise=False,
                    progress=None):
    """Draw ``n`` stages with ``seed`` and validate each (a :class:`FamilyResult`).

    Parameters
    ----------
    n : int
    seed : int
        Seed of the stages (the sensor noise of stage i uses ``seed + i``).
    record_set : {"standard", "two", "six"}
    duration : float
        Length of each record [s].
    noise : bool
        With :data:`SENSOR`, or noise-free.
    progress : callable, optional
        Called with one line per stage.
    """
    if record_set not in RECORD_SETS:
        raise ValueError(f"record set must be one of {', '.join(RECORD_SETS)}, got {record_set!r}")
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be a positive number of seconds, got {duration!r}")
    rng = np.random.default_rng(seed)
    stages = []
    for i in range(int(n)):
        params = draw_stage(rng)
        st = validate_stage(params, record_set=record_set, duration=duration, noise=noise,
                            seed=seed + i, index=i)
        stages.append(st)
        if progress is not None:
            progress(f"stage {i + 1}/{n}: alpha {params['creep.alpha']:+.4f}, held-out "
                     f"{st.held_out_e_rms * 1e3:.4g} nm, vs truth {st.truth_e_rms * 1e3:.4g} nm, "
                     f"{st.starts} starts, {st.elapsed_s:.2f} s")
    return FamilyResult(tuple(stages), record_set, float(duration), bool(noise), int(seed))
