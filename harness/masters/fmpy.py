"""The fmpy master: the PiezoStage and AdaptiveCompoundController FMUs run through fmpy, on their
FMI 2.0 editions (default) or their FMI 3.0 editions (``fmi_version=3``: the FMUs in the
``fmi3/`` folder beside the FMI 2.0 ones, run through fmpy's FMU3Slave).

Semantics: both FMUs step on the grid ``t_k = k h``.  PiezoStage has no
direct feedthrough: at ``t_k`` it reports ``y(k)``, ``y_meas(k)``, ``x(k)``
and ``u = u(k-1)``; the ``v`` set at ``t_k`` acts over ``[t_k, t_k + h)``.
The default controller has none either: a doStep from ``t_k`` samples
``y_ref``, ``y_meas(k)`` and the time stamps and publishes the control it computed
at ``t_(k+1)``, so the plant applies it over ``[t_(k+1), t_(k+2))`` and the
loop delay is d = 2, which the controller detects (``mv.delay = -1``).

Both masters also wire what the closed-loop SSP wires: the plant's ``t_meas`` to the
controller's ``t_meas``, and the stamped preview of ReferenceSignal (``y_preview =
y_d(k + 4)``, ``t_preview = (k + 4) h``; computed here) to the controller's ``y_preview``
and ``t_preview``.

Both masters exchange values at communication points only:

* ``"gauss-seidel"``: in ModelStructure order, per sample::

      plant.(y, y_meas)(k) -> controller.(y_ref, y_meas) -> controller.v
                           -> plant.v -> doStep of both (``step_order``)

* ``"jacobi"`` (textbook): read every output, then set every input, then
  step every FMU.

With the default controller both give the same samples (no output depends
on an input, so the order of reads and writes does not matter).  With
``mv.feedthrough = true`` (and ``mv.delay = 0``: d = 1) only the Gauss-Seidel
master is sound: it reads ``v`` after setting the controller's inputs; a
Jacobi master reads a ``v`` computed from the previous inputs, which the
controller then never commits (the FMU logs a warning).

Both editions compile the same model code; the FMI 3.0 edition has array variables where
the FMI 2.0 one has numbered scalars (``pi.w`` for ``pi.w[1]`` .. ``pi.w[16]``). Parameters
are given by the FMI 2.0 names in either case: ``pi.w[3]`` sets element 3 of the array
``pi.w`` (the array is read in initialization mode, the element replaced, the array set).
The two editions give the same samples bit for bit.

Each FMU file is extracted once per process (:func:`harness.fmu.load`); instances are
always terminated and freed, also when a run fails.
"""

from __future__ import annotations

import ctypes
import time

from fmpy.fmi2 import fmi2Boolean, fmi2Real
import numpy as np

from ..fmu import (
    CONTROLLER_MODEL,
    PLANT_MODEL,
    TIMING_OUTPUTS,
    FMUError,
    warn_safe_state,
    check_fmi_version,
    fmu_path,
    load,
)
from ..loop import (
    CLOSED_LOOP_DTYPE,
    CLOSED_LOOP_FIELDS,
    OPEN_LOOP_DTYPE,
    as_structured,
    open_loop_grid,
    prepare_closed_loop,
    sample_range,
)
from .instance import CTRL_OUTPUTS, Instance, ScalarFunctions, step_error, vr_array

__all__ = ["simulate_closed_loop", "simulate_open_loop", "simulate_setup"]

_PLANT_OUTPUTS = ("u", "x", "y", "y_meas")


# ---------------------------------------------------------------------------
# public runs
# ---------------------------------------------------------------------------

def simulate_closed_loop(scenario, *, adaptation=None, preview=True, master="gauss-seidel",
                         plant_params=None, controller_params=None, fmu_dir=None,
                         duration=None, registry=None, step_order="plant-first", progress=None,
                         fmi_version=2, timing=None):
    """Run a tracking scenario through both FMUs with fmpy.

    Parameters
    ----------
    scenario : str or Scenario
        A tracking scenario or its name (see :func:`harness.list_scenarios`).
    adaptation : bool, optional
        Force the controller's RLS on (True) or off (False); ``None`` keeps the
        scenario's / FMU's setting (on by default).
    preview : bool
        Feed the controller ``y_ref = y_d(k + lead)`` and the stamped preview (True,
        docs/model.md, controller) or ``y_ref = y_d(k)`` and no stamped preview (False;
        gives a lag error).
    master : {"gauss-seidel", "jacobi"}
        Co-simulation algorithm (see the module docstring); both run the same
        loop with the default controller.
    plant_params, controller_params : dict, optional
        Extra parameter overrides by FMU variable name (after the scenario's).
    fmu_dir : str or Path, optional
        Folder holding ``PiezoStage.fmu`` and ``AdaptiveCompoundController.fmu``
        (default ``build/fmus`` or ``$PIEZO_FMU_DIR``).
    timing : dict, optional
        When given, filled at the end of the run with the controller's timing outputs
        ``loop_delay``, ``loop_delay_time``, ``preview_lead``, ``meas_offset`` (what it
        detected; docs/cosimulation.md).
    duration : float, optional
        Override the scenario's duration [s].
    registry : dict, optional
        Scenario registry for name lookup (default: built-in scenarios).
    step_order : {"plant-first", "controller-first"}
        Order of the two doStep calls of the Gauss-Seidel master.
    progress : callable, optional
        Called as ``progress(done, n)`` after every simulated second and at the end.
    fmi_version : {2, 3}
        Run the FMI 2.0 editions (default) or the FMI 3.0 editions (``fmi3/`` in the FMU
        folder, fmpy's FMU3Slave); both give the same samples bit for bit.

    Returns
    -------
    ndarray
        Structured array, one row per sample k, fields ``time, y_d, y, y_meas,
        v, q, a1, a2, b1, b2, pred_error, saturated``: the values at ``t_k``
        (``v`` is the voltage the plant applies over ``[t_k, t_(k+1))``;
        ``q``, ``a1..b2``, ``pred_error``, ``saturated`` belong to that ``v``).

    Raises
    ------
    FileNotFoundError
        An FMU is missing (the message says how to build it).
    UnknownParameterError
        A parameter name is not a parameter of the FMU.
    FMUInitializationError
        The FMU refused a parameter value.
    LoopDivergedError
        The controller declared the loop unstable, or a value diverged
        (:class:`harness.fmu.LoopFaultError`: its supervision stopped a loop that cannot work).
    FMUError
        An FMI call failed during the run.
    """
    setup = prepare_closed_loop(scenario, adaptation=adaptation, preview=preview, master=master,
                                plant_params=plant_params, controller_params=controller_params,
                                duration=duration, registry=registry, step_order=step_order)
    return simulate_setup(setup, fmu_dir, progress=progress, fmi_version=check_fmi_version(fmi_version),
                     timing=timing)


def _read_timing(inst):
    """The controller's TIMING_OUTPUTS now, as a dict (ints and a float [s])."""
    f, info = inst.fmu, inst.info
    ints = [info.vr(n) for n in TIMING_OUTPUTS if n != "loop_delay_time"]
    values = f.getInt32(ints) if inst.fmi3 else f.getInteger(ints)
    get_real = f.getFloat64 if inst.fmi3 else f.getReal
    out = dict(zip([n for n in TIMING_OUTPUTS if n != "loop_delay_time"], (int(v) for v in values)))
    out["loop_delay_time"] = float(get_real([info.vr("loop_delay_time")])[0])
    return {n: out[n] for n in TIMING_OUTPUTS}


def simulate_setup(setup, fmu_dir=None, block=0, block_ns=None, progress=None, fmi_version=2,
                   timing=None):
    """Run a prepared closed loop (:func:`harness.loop.prepare_closed_loop`); the result of
    :func:`simulate_closed_loop`. ``block``, ``block_ns`` and ``progress`` are those of
    :func:`_run_closed_loop` (the benchmark's timings), ``timing`` that of
    :func:`simulate_closed_loop`."""
    p_info = load(fmu_path(PLANT_MODEL, fmu_dir, fmi_version), fmi_version)
    c_info = load(fmu_path(CONTROLLER_MODEL, fmu_dir, fmi_version), fmi_version)
    n, h = setup.n, setup.h
    rows = np.zeros((n, len(CLOSED_LOOP_FIELDS)))
    rows[:, 0] = setup.time
    rows[:, 1] = setup.y_d

    plant = ctrl = None
    try:
        plant = Instance(p_info, "plant")
        ctrl = Instance(c_info, "controller")
        stop = n * h
        plant.initialize(setup.plant_params, stop)
        ctrl.initialize(setup.controller_params, stop)
        _run_closed_loop(plant, ctrl, setup, rows, block, block_ns, progress)
        warn_safe_state(ctrl.log, CONTROLLER_MODEL)      # sup.reaction = 1: the run went on, say why
        if timing is not None:
            timing.update(_read_timing(ctrl))
    finally:
        if ctrl is not None:
            ctrl.close()
        if plant is not None:
            plant.close()
    return as_structured(rows, CLOSED_LOOP_DTYPE)



def _run_closed_loop(plant, ctrl, setup, rows, block=0, block_ns=None, progress=None):
    """Run the whole loop into ``rows`` (n x 12, the CLOSED_LOOP_FIELDS).

    Every value goes straight from the FMU into its place in memory: the plant
    writes ``y_meas, t_meas, y`` of sample k next to ``y_ref, y_preview, t_preview`` of
    sample k in an exchange array, whose first five entries are then exactly the
    controller's inputs; the
    controller writes ``v, q, a1..b2, pred_error`` into row k, and the plant
    takes its ``v`` from there. ``block``/``block_ns``: thread CPU time [ns]
    of every complete block of ``block`` samples is appended to the list.
    ``progress(done, n)`` is called after every simulated second (blocks of one
    second then, unless timed).
    """
    fp, fc = ScalarFunctions(plant), ScalarFunctions(ctrl)
    GET, SET, GET_BOOL, DO_STEP = fp.names
    pc, cc = fp.c, fc.c
    p_get, p_set, p_step = fp.get, fp.set, fp.step
    c_get, c_set, c_get_bool, c_step = fc.get, fc.set, fc.get_bool, fc.step
    pi, ci = plant.info, ctrl.info

    keep = []                       # ctypes arrays whose addresses are passed

    def addr(values):
        arr = vr_array(values)
        keep.append(arr)
        return ctypes.addressof(arr)

    vr_p_out = addr([pi.vr("y_meas"), pi.vr("t_meas"), pi.vr("y")])
    vr_p_in = addr([pi.vr("v")])
    vr_c_in = addr([ci.vr(name) for name in ("y_ref", "y_preview", "t_preview", "y_meas", "t_meas")])
    vr_c_out = addr([ci.vr(name) for name in CTRL_OUTPUTS])
    vr_c_sat = addr([ci.vr("saturated")])
    n_c = len(CTRL_OUTPUTS)

    n, h = setup.n, setup.h
    # y_ref, y_preview, t_preview, y_meas, t_meas, y of sample k; without preview the
    # stamped preview stays 0 (a time stamp that does not advance: not connected)
    exchange = np.zeros((n, 6))
    exchange[:, 0] = setup.y_ref
    if setup.y_preview is not None:
        exchange[:, 1] = setup.y_preview
        exchange[:, 2] = setup.t_preview
    # fmi2Boolean is an int, fmi3Boolean a C bool (one byte)
    saturated = np.zeros(n, dtype=np.uint8 if plant.fmi3 else np.dtype(fmi2Boolean))
    row_bytes, ex_bytes, sat_bytes = rows.strides[0], exchange.strides[0], saturated.strides[0]
    rows_v = rows.ctypes.data + 4 * rows.strides[1]          # &rows[0, 4]: v, q, a1..pred_error
    ex0 = exchange.ctypes.data
    sat0 = saturated.ctypes.data
    times = setup.time.tolist()
    jacobi = setup.master == "jacobi"
    controller_first = setup.step_order == "controller-first"
    if block_ns is not None and block > 0:
        block = int(block)
    elif progress is not None:
        block = max(1, int(round(1.0 / h)))          # one simulated second
    else:
        block = n

    k, stage, inst, status = 0, GET, plant, 0
    for k0 in range(0, n, block):
        t_block = time.thread_time_ns()
        for k in range(k0, min(k0 + block, n)):
            ex = ex0 + k * ex_bytes
            out = rows_v + k * row_bytes
            status = p_get(pc, vr_p_out, 3, ex + 24)                   # y_meas, t_meas, y
            if status > 1:
                inst, stage = plant, GET
                break
            if jacobi:
                # textbook Jacobi: every output first, then every input
                status = c_get(cc, vr_c_out, n_c, out)
                if status > 1:
                    inst, stage = ctrl, GET
                    break
                status = c_get_bool(cc, vr_c_sat, 1, sat0 + k * sat_bytes)
                if status > 1:
                    inst, stage = ctrl, GET_BOOL
                    break
                status = p_set(pc, vr_p_in, 1, out)                     # v
                if status > 1:
                    inst, stage = plant, SET
                    break
                status = c_set(cc, vr_c_in, 5, ex)                      # y_ref .. t_meas
                if status > 1:
                    inst, stage = ctrl, SET
                    break
            else:
                # Gauss-Seidel in ModelStructure order: plant -> controller -> plant
                status = c_set(cc, vr_c_in, 5, ex)
                if status > 1:
                    inst, stage = ctrl, SET
                    break
                status = c_get(cc, vr_c_out, n_c, out)
                if status > 1:
                    inst, stage = ctrl, GET
                    break
                status = c_get_bool(cc, vr_c_sat, 1, sat0 + k * sat_bytes)
                if status > 1:
                    inst, stage = ctrl, GET_BOOL
                    break
                status = p_set(pc, vr_p_in, 1, out)
                if status > 1:
                    inst, stage = plant, SET
                    break
            t = times[k]
            if controller_first:
                status = c_step(cc, t, h, 1)
                if status > 1:
                    inst, stage = ctrl, DO_STEP
                    break
                status = p_step(pc, t, h, 1)
                if status > 1:
                    inst, stage = plant, DO_STEP
                    break
            else:
                status = p_step(pc, t, h, 1)
                if status > 1:
                    inst, stage = plant, DO_STEP
                    break
                status = c_step(cc, t, h, 1)
                if status > 1:
                    inst, stage = ctrl, DO_STEP
                    break
        if status > 1:
            break
        if block_ns is not None and k0 + block <= n:
            block_ns.append(time.thread_time_ns() - t_block)
        if progress is not None:
            progress(min(k0 + block, n), n)
    del keep
    rows[:, 2] = exchange[:, 5]
    rows[:, 3] = exchange[:, 3]
    rows[:, -1] = saturated != 0
    if status > 1:
        raise step_error(inst, stage, k, h, FMUError(f"{stage} returned status {status}"))


def simulate_open_loop(plant_params, v_signal, *, step_size=0.0005, fmu_dir=None, progress=None,
                       fmi_version=2):
    """Drive the PiezoStage FMU alone with a voltage sequence.

    Parameters
    ----------
    plant_params : dict or None
        Parameter overrides by FMU variable name (e.g. ``{"creep.enabled": False}``).
    v_signal : array_like, shape (N,)
        Voltage ``v(k)`` [V] applied over ``[t_k, t_k + h)``.
    step_size : float
        Sample period h [s] (also set as the FMU's ``h`` unless overridden).
    fmu_dir : str or Path, optional
        Folder holding ``PiezoStage.fmu``.
    progress : callable, optional
        Called as ``progress(done, n)`` after every simulated second and at the end.
    fmi_version : {2, 3}
        The FMI 2.0 (default) or FMI 3.0 edition of PiezoStage.

    Returns
    -------
    ndarray
        Structured array of N rows, fields ``time, v, u, x, y, y_meas``.
        Row k holds ``v(k)``, the hysteresis output ``u(k) = P[v](k)`` of that
        voltage (which the FMU reports at ``t_{k+1}``), and ``x(k)``, ``y(k)``,
        ``y_meas(k)`` as reported at ``t_k``.

    Raises
    ------
    FileNotFoundError, UnknownParameterError, FMUInitializationError, FMUError
        As :func:`simulate_closed_loop`.
    """
    v, time = open_loop_grid(v_signal, step_size)
    params = dict(plant_params or {})
    params.setdefault("h", float(step_size))
    info = load(fmu_path(PLANT_MODEL, fmu_dir, fmi_version), check_fmi_version(fmi_version))
    n, h = v.size, float(step_size)
    rows = np.zeros((n, len(OPEN_LOOP_DTYPE.names)))
    rows[:, 0] = time
    rows[:, 1] = v
    plant = None
    try:
        plant = Instance(info, "plant")
        plant.initialize(params, n * h)
        fn = ScalarFunctions(plant)
        comp, get, set_, step = fn.c, fn.get, fn.set, fn.step
        vr_out = vr_array([info.vr(nm) for nm in _PLANT_OUTPUTS])
        vr_in = vr_array([info.vr("v")])
        out = (fmi2Real * 4)()
        vin = (fmi2Real * 1)()
        out_addr, vin_addr = ctypes.addressof(out), ctypes.addressof(vin)
        np_out = np.ctypeslib.as_array(out)
        vl = v.tolist()
        times = time.tolist()
        k, stage = 0, fn.names[0]

        def check(status):
            if status > 1:
                raise FMUError(f"{stage} returned status {status}")

        try:
            for k in sample_range(n, h, progress):
                stage = fn.names[0]
                check(get(comp, vr_out, 4, out_addr))        # u(k-1), x(k), y(k), y_meas(k)
                rows[k, 3:6] = np_out[1:4]
                if k:
                    rows[k - 1, 2] = out[0]
                vin[0] = vl[k]
                stage = fn.names[1]
                check(set_(comp, vr_in, 1, vin_addr))
                stage = fn.names[3]
                check(step(comp, times[k], h, 1))
            k, stage = n, fn.names[0]
            check(get(comp, vr_out, 4, out_addr))
            rows[n - 1, 2] = out[0]
        except Exception as exc:
            raise step_error(plant, stage, k, h, exc) from None
    finally:
        if plant is not None:
            plant.close()
    return as_structured(rows, OPEN_LOOP_DTYPE)

