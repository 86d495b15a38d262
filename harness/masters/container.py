"""The closed loop in an FMU container of fmu-manipulation-toolbox (an optional package:
``pip install fmu-manipulation-toolbox``, in the ``test`` extra).

* In **parallel** mode the container sets all inputs, steps all FMUs, gets all outputs (it
  reads the outputs after initialization first): our loop, sample for sample.
* In **sequential** mode it sets one FMU's inputs, steps it and gets its outputs before the
  next FMU: each FMU receives the post-step outputs of the FMUs before it (true
  Gauss-Seidel). Whatever the order, one link of the loop is post-step, so the loop has one
  sample less delay: d = 1, which the controller detects; configured for it (``mv.delay =
  0``; ``lead = 0`` with the reference before the controller), it runs the d = 1 loop of a
  ModelStructure-ordered Gauss-Seidel master with ``mv.feedthrough``, sample for sample.

The functions return a structured array of :data:`harness.loop.IMPORTER_FIELDS`, one row per
sample time ``t_k`` for which the container reports values (``v`` is the voltage the plant
applies over ``[t_k, t_(k+1))``).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
import shutil
import tempfile
import warnings

from fmpy import simulate_fmu
import numpy as np

from ..fmu import TIMING_OUTPUTS, default_fmu_dir, warn_safe_state
from ..loop import IMPORTER_DTYPE, IMPORTER_FIELDS
from ..scenarios import get_scenario
from ..buildtime.ssp_file import SSP_CONNECTIONS, parameter_set_for_scenario

__all__ = ["CONTAINER_ORDER", "ContainerTerminateWarning", "MissingImporterError", "build_closed_loop_container",
           "simulate_container", "simulate_closed_loop_container"]

#: FMU files of the loop, in the topological order of its links (reference -> controller -> plant)
CONTAINER_ORDER = ("ReferenceSignal.fmu", "AdaptiveCompoundController.fmu", "PiezoStage.fmu")
_FMU_OF = {"reference": "ReferenceSignal.fmu", "controller": "AdaptiveCompoundController.fmu",
           "plant": "PiezoStage.fmu"}


class MissingImporterError(ImportError):
    """An optional importer package is not installed; the message says how to get it."""


class ContainerTerminateWarning(UserWarning):
    """The container refused to terminate after a complete run (see :func:`simulate_container`)."""


def _container_class():
    """fmu-manipulation-toolbox's FMUContainer (MissingImporterError when not installed)."""
    try:     # optional: fmu-manipulation-toolbox is in the test extra only
        from fmu_manipulation_toolbox.container import FMUContainer
    except ImportError as exc:    # pragma: no cover - the test extra installs it
        raise MissingImporterError(
            "fmu-manipulation-toolbox is needed for container FMUs: "
            "pip install fmu-manipulation-toolbox") from exc
    return FMUContainer


def _start_text(value):
    """A start value as the container's text (``true``, ``3``, ``0.25``)."""
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
        src = Path(fmu_dir) if fmu_dir is not None else default_fmu_dir()
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
    
    Warns
    -----
    ContainerTerminateWarning
        The container returned an error from terminate after the last step, as it does
        when an FMU in it ends with a Warning (a clipped or poorly predicted run): the samples
        are complete and returned.
    """
    n = int(round(stop_time / step_size))
    res = _simulate_keeping_results(container_path, stop_time, step_size)
    if res.shape[0] < n + 1 or not math.isclose(res["time"][n], stop_time, rel_tol=1e-9):
        raise RuntimeError(f"{container_path}: expected {n + 1} rows up to t = {stop_time}, "
                           f"got {res.shape[0]}")
    out = np.zeros(n, dtype=IMPORTER_DTYPE)
    out["time"] = np.arange(n) * step_size
    for f in ("y_d", "y", "y_meas"):
        out[f] = res[f][:n]
    out["v"] = res["v"][1:n + 1] if sequential else res["v"][:n]
    for name in IMPORTER_FIELDS[5:]:
        out[name] = res[name][1:n + 1] if sequential else res[name][:n]
    return out


def _simulate_keeping_results(container_path, stop_time, step_size):
    """``fmpy.simulate_fmu`` on the container, terminating it here rather than in fmpy.

    The container (fmu-manipulation-toolbox 2.0) returns Error from terminate when an FMU in
    it returns anything but OK there, a Warning included; our controller and plant return a
    Warning from terminate with their run's summary (samples clipped, ``|pred_error|`` above
    its bound). fmpy would raise and lose the run; here the samples are kept and the
    container's terminate status becomes a :class:`ContainerTerminateWarning` quoting what
    the container and its FMUs logged.
    """
    from fmpy import extract, instantiate_fmu, read_model_description
    from fmpy.fmi1 import FMICallException

    log = []

    def logger(_env, _name, status, _category, message):
        log.append((int(status), message.decode(errors="replace") if isinstance(message, bytes)
                    else str(message)))

    unzipdir = extract(str(container_path))
    try:
        md = read_model_description(unzipdir)
        fmu = instantiate_fmu(unzipdir, md, "CoSimulation", logger=logger)
        try:
            res = simulate_fmu(unzipdir, model_description=md, fmu_instance=fmu, stop_time=stop_time,
                               step_size=step_size, output_interval=step_size,
                               output=list(IMPORTER_FIELDS[1:]), terminate=False)
            warn_safe_state([f"[Warning] {text}" for status, text in log if status == 1],
                            str(container_path))          # sup.reaction = 1: the run went on, say why
            try:
                fmu.terminate()
            except FMICallException as exc:
                said = " | ".join(text for _status, text in log
                                  if "Terminate:" in text or "failed to terminate" in text)
                warnings.warn(ContainerTerminateWarning(
                    f"{container_path}: the container's terminate returned status {exc.status} "
                    f"(it counts an FMU's Warning at terminate as a failure), the run's samples are "
                    f"complete; logged at terminate: {said or 'nothing'}"), stacklevel=3)
        finally:
            fmu.freeInstance()
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    return res


def simulate_closed_loop_container(scenario, *, sequential=False, order=CONTAINER_ORDER,
                                   plant_params=None, controller_params=None,
                                   reference_params=None, fmu_dir=None, registry=None,
                                   workdir=None):
    """The closed loop of a scenario in a container built for the run and removed after it:
    :func:`build_closed_loop_container`, then :func:`simulate_container` over the scenario's
    duration.

    Parameters
    ----------
    scenario : str
        A tracking scenario with a sines reference.
    sequential, order, plant_params, controller_params, reference_params, fmu_dir, registry
        As :func:`build_closed_loop_container`.
    workdir : str or Path, optional
        Where the container is built (default: the system's temporary folder).

    Returns
    -------
    ndarray
        As :func:`simulate_container`.
    """
    sc = get_scenario(scenario, registry)
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        path = build_closed_loop_container(sc.name, Path(tmp) / "loop.fmu", sequential=sequential,
                                           order=order, plant_params=plant_params,
                                           controller_params=controller_params,
                                           reference_params=reference_params, fmu_dir=fmu_dir,
                                           registry=registry)
        return simulate_container(path, sc.duration, sc.step_size, sequential=sequential)
