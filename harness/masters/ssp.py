"""The closed loop in fmpy's SSP player: the closed-loop SSP (:mod:`harness.buildtime.ssp_file`) written for a
scenario and run by ``fmpy.ssp.simulation.simulate_ssp``.

The player steps every component, then copies outputs to inputs: a Jacobi master, whose
loop delay is d = 2 as ours. It starts every connector at 0 instead of reading the outputs
after initialization, so the controller's first sample sees ``y_ref = 0`` (not ``y_d(2h)``)
and ``y_meas = 0``; from there on it runs our loop (``tests/test_masters.py``). It does not
apply the SSP's parameter bindings by itself: :func:`simulate_closed_loop_ssp` gives it the
bound parameter set.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
import re
import shutil
import tempfile
import zipfile

from fmpy.ssp.simulation import simulate_ssp
import numpy as np

from ..fmu import default_fmu_dir
from ..loop import IMPORTER_DTYPE, IMPORTER_FIELDS
from ..buildtime.ssp_file import parameter_set_for_scenario, read_bound_parameter_set, write_closed_loop_ssp

__all__ = ["simulate_closed_loop_ssp", "simulate_ssp_scenario"]


def simulate_closed_loop_ssp(ssp_path, stop_time=None, step_size=None):
    """Run an SSP with fmpy's SSP player, applying its bound parameter set.

    fmpy's player (``fmpy.ssp.simulation.simulate_ssp``) steps every component, then
    copies outputs to inputs (a Jacobi master), starting from connector values of 0.

    Parameters
    ----------
    ssp_path : str or Path
    stop_time, step_size : float, optional
        Default: the SSP's default experiment and the OMSimulator step annotation.

    Returns
    -------
    ndarray
        fmpy's structured result: ``time`` and one field per connector
        (``reference.y_d``, ``plant.y``, ``controller.v``, ...); the row of time
        ``t_k`` holds the values after the step from ``t_k``.
    """
    with zipfile.ZipFile(ssp_path) as zf:
        ssd = zf.read("SystemStructure.ssd").decode("utf-8")
    if stop_time is None:
        stop_time = float(re.search(r'<ssd:DefaultExperiment[^>]*stopTime="([^"]+)"', ssd).group(1))
    if step_size is None:
        step_size = float(re.search(r'<oms:FixedStepMaster[^>]*stepSize="([^"]+)"', ssd).group(1))
    return simulate_ssp(str(ssp_path), stop_time=stop_time, step_size=step_size,
                        parameter_set=read_bound_parameter_set(ssp_path))


def simulate_ssp_scenario(scenario, *, fmu_dir=None, registry=None, workdir=None, plant_params=None,
                          controller_params=None, reference_params=None):
    """Write the closed-loop SSP of a scenario and run it with fmpy's SSP player.

    Parameters
    ----------
    scenario : str
        A tracking scenario with a sines reference (see :mod:`harness.buildtime.ssp_file`).
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
        folder = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
        path = write_closed_loop_ssp(Path(workdir) / f"{pset.name}.ssp", folder, [pset])
        res = simulate_closed_loop_ssp(path, stop_time=pset.stop_time, step_size=pset.step_size)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    h = pset.step_size
    n = int(round(pset.stop_time / h))
    res = res[:n]          # the player may step once more when its float time falls short of stop
    out = np.zeros(n, dtype=IMPORTER_DTYPE)
    out["time"] = (np.arange(n) + 1) * h
    out["y_d"] = res["reference.y_d"]
    out["y"] = res["plant.y"]
    out["y_meas"] = res["plant.y_meas"]
    out["v"] = res["controller.v"]       # published at t_(k+1): applied over [t_(k+1), t_(k+2))
    for name in IMPORTER_FIELDS[5:]:
        out[name] = res[f"controller.{name}"]
    return out
