"""The closed loop in other people's masters: fmpy's SSP player and FMU containers.

Our own masters (:mod:`harness.cosim`) exchange values at communication points.
Other importers schedule differently, and that decides which loop they run
(read in their sources, measured in ``tests/test_masters.py``):

* ``fmpy.ssp.simulation.simulate_ssp`` steps every component, then copies
  outputs to inputs: a Jacobi master.  It starts every connector at 0 instead
  of reading the outputs after initialization, so the controller's first
  sample sees ``y_ref = 0`` (not ``y_d(2h)``) and ``y_meas = 0``; from there on it
  runs our loop.
* fmu-manipulation-toolbox's container FMU in **parallel** mode sets all
  inputs, steps all FMUs, gets all outputs (it reads the outputs after
  initialization first): our loop, sample for sample.
* The same container in **sequential** mode sets one FMU's inputs, steps it
  and gets its outputs before the next FMU: each FMU receives the post-step
  outputs of the FMUs before it (true Gauss-Seidel).  Whatever the order, one
  link of the loop is post-step, so the loop has one sample less delay:
  d = 1.  With the default controller (d = 2) that loop is unstable, and the
  controller's monitor stops it within 0.1 s.  Configured for it
  (``mv.delay = 0``; ``lead = 0`` with the reference before the controller),
  it runs the d = 1 loop of a ModelStructure-ordered Gauss-Seidel master with
  ``mv.feedthrough``, sample for sample.

Every function returns a structured array like
:func:`harness.cosim.simulate_closed_loop`'s first fields, ``time, y_d, y,
y_meas, v``, one row per sample time ``t_k`` for which the importer reports
values (``v`` is the voltage the plant applies over ``[t_k, t_(k+1))``).
"""

from __future__ import annotations

import math
from pathlib import Path
import shutil
import tempfile

import numpy as np

__all__ = [
    "IMPORTER_FIELDS",
    "CONTAINER_ORDER",
    "simulate_ssp_scenario",
    "build_closed_loop_container",
    "simulate_container",
    "MissingImporterError",
]

IMPORTER_FIELDS = ("time", "y_d", "y", "y_meas", "v", "loop_delay", "loop_delay_time", "preview_lead",
                   "meas_offset")
_DTYPE = np.dtype([(f, "f8") for f in IMPORTER_FIELDS])
#: FMU files of the loop, in the topological order of its links (reference -> controller -> plant)
CONTAINER_ORDER = ("ReferenceSignal.fmu", "AdaptiveCompoundController.fmu", "PiezoStage.fmu")
_FMU_OF = {"reference": "ReferenceSignal.fmu", "controller": "AdaptiveCompoundController.fmu",
           "plant": "PiezoStage.fmu"}


class MissingImporterError(ImportError):
    """An optional importer package is not installed; the message says how to get it."""


def _fmu_dir(fmu_dir):
    from .cosim import default_fmu_dir
    return Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()


def simulate_ssp_scenario(scenario, *, fmu_dir=None, registry=None, workdir=None, plant_params=None,
                          controller_params=None, reference_params=None):
    """Write the closed-loop SSP of a scenario and run it with fmpy's SSP player.

    Parameters
    ----------
    scenario : str
        A tracking scenario with a sines reference (see :mod:`harness.ssp`).
    fmu_dir : str or Path, optional
    registry : dict, optional
    workdir : str or Path, optional
        Where the SSP is written (default: a temporary folder, removed).
    plant_params, controller_params, reference_params : dict, optional
        Overrides on top of the scenario's, written into the bound SSV.

    Returns
    -------
    ndarray
        ``time, y_d, y, y_meas, v`` and the controller's timing outputs (``loop_delay``,
        ``loop_delay_time``, ``preview_lead``, ``meas_offset``) at ``t_1 .. t_n`` (the player
        reports the values after each step; it has no row for the initial values).
    """
    import dataclasses

    from .ssp import parameter_set_for_scenario, simulate_closed_loop_ssp, write_closed_loop_ssp

    pset = parameter_set_for_scenario(scenario, registry)
    values = dict(pset.values)
    for comp, over in (("plant", plant_params), ("controller", controller_params),
                       ("reference", reference_params)):
        values.update({f"{comp}.{k}": v for k, v in (over or {}).items()})
    pset = dataclasses.replace(pset, values=values)
    tmp = None
    if workdir is None:
        tmp = workdir = tempfile.mkdtemp(prefix="harness_ssp_")
    try:
        path = write_closed_loop_ssp(Path(workdir) / f"{pset.name}.ssp", _fmu_dir(fmu_dir), [pset])
        res = simulate_closed_loop_ssp(path, stop_time=pset.stop_time, step_size=pset.step_size)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    h = pset.step_size
    n = int(round(pset.stop_time / h))
    res = res[:n]          # the player may step once more when its float time falls short of stop
    out = np.zeros(n, dtype=_DTYPE)
    out["time"] = (np.arange(n) + 1) * h
    out["y_d"] = res["reference.y_d"]
    out["y"] = res["plant.y"]
    out["y_meas"] = res["plant.y_meas"]
    out["v"] = res["controller.v"]       # published at t_(k+1): applied over [t_(k+1), t_(k+2))
    for name in IMPORTER_FIELDS[5:]:
        out[name] = res[f"controller.{name}"]
    return out


def _container_class():
    try:
        from fmu_manipulation_toolbox.container import FMUContainer
    except ImportError as exc:    # pragma: no cover - the test extra installs it
        raise MissingImporterError(
            "fmu-manipulation-toolbox is needed for container FMUs: "
            "pip install fmu-manipulation-toolbox") from exc
    return FMUContainer


def _start_text(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def build_closed_loop_container(scenario, path, *, sequential=False, order=CONTAINER_ORDER,
                                controller_params=None, reference_params=None, plant_params=None,
                                fmu_dir=None, registry=None):
    """Build an FMU container (fmu-manipulation-toolbox) of the closed loop of a scenario.

    Parameters
    ----------
    scenario : str
        A tracking scenario with a sines reference; its parameters become start values.
    path : str or Path
        The container ``.fmu`` to write.
    sequential : bool
        The container's sequential mode (true Gauss-Seidel in ``order``); parallel otherwise.
    order : sequence of str
        The embedded FMU files in the container's order.
    controller_params, reference_params, plant_params : dict, optional
        Overrides on top of the scenario's (e.g. ``{"mv.delay": 0}``, ``{"lead": 0}``,
        ``{"tf.delay": 1}``).
    fmu_dir : str or Path, optional
    registry : dict, optional

    Returns
    -------
    Path
    """
    import logging

    from .cosim import TIMING_OUTPUTS
    from .ssp import SSP_CONNECTIONS, parameter_set_for_scenario

    FMUContainer = _container_class()
    pset = parameter_set_for_scenario(scenario, registry)
    starts = {comp: {} for comp in _FMU_OF}
    for key, value in pset.values.items():
        comp, var = key.split(".", 1)
        starts[comp][var] = value
    starts["controller"].update(controller_params or {})
    starts["reference"].update(reference_params or {})
    starts["plant"].update(plant_params or {})
    path = Path(path)
    work = Path(tempfile.mkdtemp(prefix="harness_container_"))
    quiet = logging.getLogger("fmu_manipulation_toolbox")
    level = quiet.level
    quiet.setLevel(logging.ERROR)      # its notes on unconnected ports and the loop are expected
    try:
        src = _fmu_dir(fmu_dir)
        for fmu in CONTAINER_ORDER:
            shutil.copy(src / fmu, work / fmu)
        c = FMUContainer(path.stem, work, fmi_version=2)
        for fmu in order:
            c.get_fmu(fmu)
        for a, ac, b, bc in SSP_CONNECTIONS:
            c.add_link(_FMU_OF[a], ac, _FMU_OF[b], bc)
        for fmu, port in (("ReferenceSignal.fmu", "y_d"), ("PiezoStage.fmu", "y"),
                          ("PiezoStage.fmu", "y_meas"), ("AdaptiveCompoundController.fmu", "v"),
                          *(("AdaptiveCompoundController.fmu", name) for name in TIMING_OUTPUTS)):
            c.add_output(fmu, port, port)
        for comp, values in starts.items():
            for var, value in values.items():
                c.add_start_value(_FMU_OF[comp], var, _start_text(value))
        c.make_fmu(path.name, step_size=pset.step_size, sequential=sequential)
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(work / path.name), path)
    finally:
        quiet.setLevel(level)
        shutil.rmtree(work, ignore_errors=True)
    return path


def simulate_container(container_path, stop_time, step_size, *, sequential=False):
    """Run a closed-loop container with fmpy (fixed step h, outputs every h).

    Parameters
    ----------
    container_path : str or Path
    stop_time, step_size : float
    sequential : bool
        How the container was built: in sequential mode the plant applies over
        ``[t_k, t_(k+1))`` the ``v`` the container reports at ``t_(k+1)``.

    Returns
    -------
    ndarray
        ``time, y_d, y, y_meas, v`` and the controller's timing outputs (with ``v``'s
        timing) at ``t_0 .. t_(n-1)``.
    """
    from fmpy import simulate_fmu

    n = int(round(stop_time / step_size))
    res = simulate_fmu(str(container_path), stop_time=stop_time, step_size=step_size,
                       output_interval=step_size, output=list(IMPORTER_FIELDS[1:]))
    if res.shape[0] < n + 1 or not math.isclose(res["time"][n], stop_time, rel_tol=1e-9):
        raise RuntimeError(f"{container_path}: expected {n + 1} rows up to t = {stop_time}, "
                           f"got {res.shape[0]}")
    out = np.zeros(n, dtype=_DTYPE)
    out["time"] = np.arange(n) * step_size
    for f in ("y_d", "y", "y_meas"):
        out[f] = res[f][:n]
    out["v"] = res["v"][1:n + 1] if sequential else res["v"][:n]
    for name in IMPORTER_FIELDS[5:]:
        out[name] = res[name][1:n + 1] if sequential else res[name][:n]
    return out
