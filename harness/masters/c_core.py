"""The core master: the closed loop of :func:`harness.masters.fmpy.simulate_closed_loop`, run
directly on the C core.

Same experiment, same result fields, no FMI layer: the plant and controller are
the cffi binding's :class:`harness.binding.core.Plant` and :class:`harness.binding.core.Controller`.
Comparing both runs sample by sample checks the FMI layer and the master.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..binding import core
from ..fmu import LoopFaultWarning
from ..loop import (
    CLOSED_LOOP_DTYPE,
    CLOSED_LOOP_FIELDS,
    OPEN_LOOP_DTYPE,
    REFERENCE_PREVIEW,
    as_structured,
    open_loop_grid,
    prepare_closed_loop,
    sample_range,
)

__all__ = ["simulate_closed_loop_core", "simulate_open_loop_core"]


def simulate_closed_loop_core(scenario, *, adaptation=None, preview=True, master="gauss-seidel",
                              plant_params=None, controller_params=None, fmu_dir=None,
                              duration=None, registry=None, step_order="plant-first",
                              progress=None):
    """Run a tracking scenario on the C core (no FMUs).

    Parameters
    ----------
    scenario, adaptation, preview, master, plant_params, controller_params, duration, registry, step_order, progress
        As :func:`harness.masters.fmpy.simulate_closed_loop` (the FMUs' semantics, emulated sample
        by sample; ``step_order`` changes nothing here, as it changes nothing there).
    fmu_dir : ignored
        Accepted so that both functions share one signature.

    Returns
    -------
    ndarray
        Structured array with the fields of :func:`harness.masters.fmpy.simulate_closed_loop`.

    Raises
    ------
    FileNotFoundError
        ``build/libpiezo_core.so`` is missing.
    KeyError
        Unknown parameter name.
    harness.binding.core.CoreParameterError
        A parameter value is out of range.
    """
    setup = prepare_closed_loop(scenario, adaptation=adaptation, preview=preview, master=master,
                                plant_params=plant_params, controller_params=controller_params,
                                duration=duration, registry=registry, step_order=step_order)
    plant = core.Plant(setup.plant_params)
    ctrl = core.Controller(setup.controller_params)
    n = setup.n
    samples = sample_range(n, setup.h, progress)
    rows = np.zeros((n, len(CLOSED_LOOP_FIELDS)))
    rows[:, 0] = setup.time
    rows[:, 1] = setup.y_d
    y_ref = setup.y_ref
    # the stamped preview as the FMU sees it: its time stamps (and t_meas) count from the
    # second sample on, when they have advanced by h; it is REFERENCE_PREVIEW samples ahead
    # of the measurement (every master here exchanges at communication points)
    y_preview = setup.y_preview if setup.y_preview is not None else [0.0] * n
    lead = REFERENCE_PREVIEW if setup.y_preview is not None else 0
    out = plant.output
    step_input, p_step = ctrl.step_input, plant.step

    def c_step(k, y_meas):
        return step_input(y_ref[k], y_meas, y_preview[k], lead if k > 0 else 0)[:8]

    k = 0
    try:
        published = ctrl.output[:8]      # the controller's outputs before its first step
        if not setup.feedthrough:
            # v computed from the inputs of t_k is published at t_(k+1) (FMU default)
            for k in samples:
                rows[k, 2] = out.y
                rows[k, 3] = out.y_meas
                rows[k, 4:] = published
                applied = published[0]
                published = c_step(k, out.y_meas)
                out = p_step(applied)
        elif setup.master == "gauss-seidel":
            # direct feedthrough read after the inputs are set: v(k) from the inputs of t_k
            for k in samples:
                c = c_step(k, out.y_meas)
                rows[k, 2] = out.y
                rows[k, 3] = out.y_meas
                rows[k, 4:] = c
                out = p_step(c[0])
        else:
            # direct feedthrough under a Jacobi master: the v read at t_k is a peek with the
            # inputs held from t_(k-1) (their stamps have not advanced since: no stamped
            # preview); the step then commits v from the inputs of t_k
            held = (0.0, 0.0)
            for k in samples:
                c = ctrl.peek(*held)[:8]
                rows[k, 2] = out.y
                rows[k, 3] = out.y_meas
                rows[k, 4:] = c
                held = (y_ref[k], out.y_meas)
                c_step(k, out.y_meas)
                out = p_step(c[0])
    except core.CoreDivergedError as exc:
        # say where, as the FMU masters do (the class and its attributes stay)
        exc.args = (f"{exc.args[0]} (at t = {k * setup.h:.6g} s, sample {k})",) + exc.args[1:]
        raise
    if ctrl.fault:          # sup.reaction = 1: the run went on in the safe state; say so as the FMUs do
        warnings.warn(LoopFaultWarning(f"core controller: {ctrl.safe_state_message()}"), stacklevel=2)
    return as_structured(rows, CLOSED_LOOP_DTYPE)


def simulate_open_loop_core(plant_params, v_signal, *, step_size=0.0005, fmu_dir=None,
                            progress=None):
    """Drive the core plant alone; same result as :func:`harness.masters.fmpy.simulate_open_loop`.

    Parameters
    ----------
    plant_params : dict or None
        Parameter overrides by FMU variable name.
    v_signal : array_like, shape (N,)
        Voltage ``v(k)`` [V].
    step_size : float
        Sample period h [s].
    fmu_dir : ignored
    progress : callable, optional
        As :func:`harness.masters.fmpy.simulate_open_loop`.

    Returns
    -------
    ndarray
        Fields ``time, v, u, x, y, y_meas``; ``u[k] = P[v](k)``.
    """
    v, time = open_loop_grid(v_signal, step_size)
    params = dict(plant_params or {})
    params.setdefault("h", float(step_size))
    plant = core.Plant(params)
    n = v.size
    rows = np.zeros((n, len(OPEN_LOOP_DTYPE.names)))
    rows[:, 0] = time
    rows[:, 1] = v
    out = plant.output
    vl = v.tolist()
    for k in sample_range(n, float(step_size), progress):
        vk = vl[k]
        rows[k, 3] = out.x
        rows[k, 4] = out.y
        rows[k, 5] = out.y_meas
        out = plant.step(vk)
        rows[k, 2] = out.u
    return as_structured(rows, OPEN_LOOP_DTYPE)
