"""What runs: one tracking scenario in closed loop, one validation input through two models.

:func:`evaluate_tracking` and :func:`evaluate_validation` run a scenario on a
backend (the FMUs through fmpy, or the C core), check the run and return its
metrics with the paper's values and, if asked, the time series.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import time as _time

import numpy as np

from .. import masters
from ..binding import core
from ..fmu import CONTROLLER_MODEL, PLANT_MODEL, LoopDivergedError, parameter_starts
from ..loop.checks import RunDivergedError, check_tracking_run
from ..loop.metrics import compute_metrics, window_mask
from ..scenarios import get_scenario

__all__ = [
    "TrackingResult",
    "ValidationResult",
    "evaluate_tracking",
    "evaluate_validation",
    "parameter_defaults",
    "validation_series",
]

def _ratio(a, b):
    if b is None or not math.isfinite(b) or b == 0:
        return math.nan
    return a / b


@dataclass
class TrackingResult:
    """Metrics of one closed-loop run and the paper's values.

    ``paper_*`` are ``nan`` for a scenario that is not one of the paper's.
    ``data`` is the run's structured array (fields of
    :func:`harness.masters.fmpy.simulate_closed_loop`) when kept.
    """

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
    spec: object = field(default=None, repr=False)

    @property
    def ratio_e_rms(self):
        return _ratio(self.e_rms_um, self.paper_e_rms_um)

    @property
    def ratio_e_r(self):
        return _ratio(self.e_r, self.paper_e_r)

    @property
    def has_paper(self):
        """The scenario is one of the paper's (Tables 4/5)."""
        return math.isfinite(self.paper_e_rms_um)


@dataclass
class ValidationResult:
    """Coupled vs Hammerstein model on one validation input.

    ``diff_*`` compare two models (the coupled output taken as the truth); the
    paper's values compare each model with measured data.
    """

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
    spec: object = field(default=None, repr=False)

    @property
    def has_paper(self):
        """The input is one of the paper's (Tables 1-3)."""
        return math.isfinite(self.paper_coupled_e_rms_um)


def parameter_defaults(model, backend="fmpy", fmu_dir=None, fmi_version=2):
    """A model's default parameters (its start values) on a backend, by FMU variable name.

    Parameters
    ----------
    model : {"PiezoStage", "AdaptiveCompoundController"}
    backend : {"auto", "fmpy", "native", "core"}
        The FMU backends: the ``start`` of every Real/Integer/Boolean parameter in the FMU's
        modelDescription (:func:`harness.fmu.parameter_starts`); core:
        :func:`harness.binding.core.default_plant_params` or
        :func:`harness.binding.core.default_controller_params`.
    fmu_dir : str or Path, optional
    fmi_version : {2, 3}
        The edition whose modelDescription is read; the elements of an FMI 3.0 array variable
        are returned by their FMI 2.0 names (``pi.w[1]`` ..), so both editions give the same
        dictionary.

    Returns
    -------
    dict
    """
    if model not in (PLANT_MODEL, CONTROLLER_MODEL):
        raise ValueError(f"model must be {PLANT_MODEL} or {CONTROLLER_MODEL}, got {model!r}")
    if backend == "core":
        return dict(core.default_plant_params() if model == PLANT_MODEL
                    else core.default_controller_params())
    return parameter_starts(model, fmu_dir, fmi_version)


def evaluate_tracking(scenario, *, condition="run", adaptation=None, preview=True,
                      master="gauss-seidel", fmu_dir=None, registry=None, backend="fmpy",
                      keep_data=True, progress=None, fmi_version=2):
    """Run one tracking scenario and compute its metrics.

    Parameters
    ----------
    scenario : str or Scenario
    condition : str
        Label stored in the result.
    adaptation, preview, master, fmu_dir, registry
        See :func:`harness.masters.fmpy.simulate_closed_loop`.
    backend : {"auto", "fmpy", "native", "core"}
        Run the FMUs (default) or the C core directly.
    fmi_version : {2, 3}
        The FMUs' FMI 2.0 (default) or FMI 3.0 editions (see :func:`harness.masters.closed_loop`).
    keep_data : bool
        Keep the time series in ``result.data``.
    progress : callable, optional
        ``progress(done, n)`` after every simulated second.

    Returns
    -------
    TrackingResult

    Raises
    ------
    harness.loop.checks.RunCheckError
        The run diverged (the controller stopped it, or its error exceeds the reference) or
        saturated persistently (:func:`harness.loop.checks.check_tracking_run`).
    """
    sc = get_scenario(scenario, registry)
    closed = masters.closed_loop(backend, fmi_version)
    label = f"{condition} / {sc.name}"
    t0 = _time.perf_counter()
    try:
        data = closed(sc, adaptation=adaptation, preview=preview, master=master, fmu_dir=fmu_dir,
                      progress=progress)
    except (LoopDivergedError, core.CoreDivergedError) as exc:
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
        data=data if keep_data else None, spec=sc,
    )


def evaluate_validation(scenario, *, fmu_dir=None, registry=None, backend="fmpy",
                        keep_data=True, progress=None, fmi_version=2):
    """Run a validation input through the coupled and the Hammerstein model.

    Parameters
    ----------
    scenario : str or Scenario
        A validation scenario (signal = input voltage).
    fmu_dir, registry, backend, keep_data, fmi_version
        As :func:`evaluate_tracking`.
    progress : callable, optional
        ``progress(done, n, model)`` after every simulated second, ``model`` being
        ``"coupled model"`` or ``"Hammerstein model"``.

    Returns
    -------
    ValidationResult
        ``diff_*`` compare the coupled output (taken as the truth, eq 36-37's
        ``y``) with the Hammerstein output (``y_m``).
    """
    sc = get_scenario(scenario, registry)
    if sc.kind != "validation":
        raise ValueError(f"scenario '{sc.name}' is a {sc.kind} scenario, not a validation input")
    open_loop = masters.open_loop(backend, fmi_version)
    t0 = _time.perf_counter()
    v = sc.signal.evaluate(sc.time_grid())
    params = dict(sc.plant)

    def part(model):
        return None if progress is None else (lambda done, n: progress(done, n, model))

    coupled = open_loop({**params, "creep.enabled": True}, v, step_size=sc.step_size,
                        fmu_dir=fmu_dir, progress=part("coupled model"))
    hamm = open_loop({**params, "creep.enabled": False}, v, step_size=sc.step_size,
                     fmu_dir=fmu_dir, progress=part("Hammerstein model"))
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
        spec=sc,
    )


def validation_series(result):
    """The time series of a validation run: time, v, y_coupled, y_hammerstein, difference."""
    c, hm = result.coupled, result.hammerstein
    series = np.zeros(c.size, dtype=[("time", "f8"), ("v", "f8"), ("y_coupled", "f8"),
                                     ("y_hammerstein", "f8"), ("difference", "f8")])
    series["time"], series["v"] = c["time"], c["v"]
    series["y_coupled"], series["y_hammerstein"] = c["y"], hm["y"]
    series["difference"] = c["y"] - hm["y"]
    return series

