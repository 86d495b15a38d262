"""The closed-loop-FMU master: the closed loop of :func:`harness.masters.fmpy.simulate_closed_loop`
run by one FMU, PiezoStageClosedLoop (the stage, the controller and the reference inside,
fmu_src/PiezoStageClosedLoop), through fmpy, on its FMI 2.0 or FMI 3.0 edition.

The scenario's parameters go to the FMU under its names (:func:`harness.binding.closed_loop.
closed_loop_parameters`: the controller's nominal model as ``controller.<name>``). A sines
reference is the FMU's internal one (ReferenceSignal's parameters: the same ``y_ref`` =
y_d(k + lead) and stamped preview y_d(k + 4) the other masters give the controller, from the
second sample on); without preview, ``lead`` = ``preview`` = 0 (y_d(k), no stamped preview).
A table reference goes through the input ``y_d``, given ``lead`` samples ahead with
``y_d_lead`` = ``lead``: the controller gets the same y_d(k + lead), and the same loop where the
loop delay d equals that lead (the default, d = 2), and with d > lead the controller of the
other masters takes y_d(k + d) from their stamped preview from the second sample on, which this
one has not: such runs differ.

:func:`simulate_closed_loop_fmu` steps one sample per doStep and reads every output at every
sample, so the rows are
those of the other masters, bit for bit (the tests compare them): ``y_d`` is the scenario's (as
theirs), the rest are the FMU's outputs at ``t_k``. With ``mv.feedthrough`` the FMU applies v(k)
in sample k as a Gauss-Seidel master does, and publishes it at ``t_(k+1)``: row k takes the
controller's outputs from there. A Jacobi master with ``mv.feedthrough`` (a stale v, which the
fmpy master shows) is no loop this FMU runs, and is refused.

:func:`simulate_closed_loop_fmu_steps` runs a table or profile reference with a variable
communication step, as a system simulation uses the FMU: one sample per doStep while y_d moves
and for a settle time after, long steps while it holds (:func:`communication_points`). The FMU
computes every sample inside a long step with the input y_d it was given at the step's start,
so a step that spans only samples of one y_d gives the samples of one-sample steps; the rows
are those of :func:`simulate_closed_loop_fmu` at the communication points, bit for bit (the
tests compare them), with the controller's ``est.adapting`` and ``est.noise`` besides.
"""

from __future__ import annotations

import ctypes

import numpy as np

from ..binding.closed_loop import CLOSED_LOOP_MODEL, closed_loop_parameters
from ..fmu import TIMING_OUTPUTS, FMUError, check_fmi_version, fmu_path, load, warn_safe_state
from ..loop import (CLOSED_LOOP_DTYPE, CLOSED_LOOP_FIELDS, REFERENCE_LEAD, REFERENCE_PREVIEW,
                    as_structured, prepare_closed_loop, reference_lead, reference_parameters)
from .instance import CTRL_OUTPUTS, Instance, ScalarFunctions, step_error, vr_array

__all__ = ["simulate_closed_loop_fmu", "simulate_closed_loop_fmu_steps", "closed_loop_fmu_parameters",
           "communication_points", "STEPS_FIELDS"]

#: the FMU's outputs of row k, in CLOSED_LOOP_FIELDS order from y (y_d is the scenario's)
_OUTPUTS = ("y", "y_meas") + CTRL_OUTPUTS
_N_PLANT = 2        # y, y_meas: of t_k also with mv.feedthrough


def closed_loop_fmu_parameters(setup, preview=True):
    """The closed-loop FMU's parameters of a prepared closed loop (:func:`harness.loop.
    prepare_closed_loop`): the plant's and the controller's, and the reference's (sines) or
    the input's lead (table)."""
    sc = setup.scenario
    lead = reference_lead(setup.controller_params) or REFERENCE_LEAD
    if sc.signal.internal:
        reference = reference_parameters(sc)
        reference.update({"lead": lead, "preview": REFERENCE_PREVIEW} if preview
                         else {"lead": 0, "preview": 0})
        own = {}
    else:
        reference = {}
        own = {"use_internal_reference": False, "y_d_lead": lead if preview else 0}
    params = closed_loop_parameters(plant=setup.plant_params, controller=setup.controller_params,
                                    reference=reference)
    params.update(own)
    return params


def simulate_closed_loop_fmu(scenario, *, adaptation=None, preview=True, master="gauss-seidel",
                             plant_params=None, controller_params=None, fmu_dir=None,
                             duration=None, registry=None, step_order="plant-first", progress=None,
                             fmi_version=2, timing=None):
    """Run a tracking scenario through PiezoStageClosedLoop with fmpy.

    Parameters
    ----------
    scenario, adaptation, preview, master, plant_params, controller_params, fmu_dir, duration, registry, step_order, progress, fmi_version, timing
        As :func:`harness.masters.fmpy.simulate_closed_loop` (``step_order`` changes nothing:
        the FMU runs its loop inside; ``timing``'s ``meas_offset`` is 0, the loop's own).

    Returns
    -------
    ndarray
        The fields of :func:`harness.masters.fmpy.simulate_closed_loop`, the same values.

    Raises
    ------
    ValueError
        A Jacobi master with ``mv.feedthrough`` (see the module docstring).
    FileNotFoundError, UnknownParameterError, FMUInitializationError, LoopDivergedError, FMUError
        As :func:`harness.masters.fmpy.simulate_closed_loop`.
    """
    setup = prepare_closed_loop(scenario, adaptation=adaptation, preview=preview, master=master,
                                plant_params=plant_params, controller_params=controller_params,
                                duration=duration, registry=registry, step_order=step_order)
    if setup.feedthrough and setup.master == "jacobi":
        raise ValueError(f"{CLOSED_LOOP_MODEL} runs its loop inside, as a Gauss-Seidel master does with "
                         f"mv.feedthrough = true; a Jacobi master's stale v is no loop it runs: use "
                         f"master='gauss-seidel'")
    fmi_version = check_fmi_version(fmi_version)
    info = load(fmu_path(CLOSED_LOOP_MODEL, fmu_dir, fmi_version), fmi_version)
    n, h = setup.n, setup.h
    rows = np.zeros((n, len(CLOSED_LOOP_FIELDS)))
    rows[:, 0] = setup.time
    rows[:, 1] = setup.y_d
    inst = None
    try:
        inst = Instance(info, "closed-loop")
        inst.initialize(closed_loop_fmu_parameters(setup, preview), (n + 1) * h)
        _run(inst, setup, rows, progress)
        warn_safe_state(inst.log, CLOSED_LOOP_MODEL)     # sup.reaction = 1: the run went on, say why
        if timing is not None:
            timing.update(_read_timing(inst))
    finally:
        if inst is not None:
            inst.close()
    return as_structured(rows, CLOSED_LOOP_DTYPE)


def _read_timing(inst):
    f, info = inst.fmu, inst.info
    names = ("loop_delay", "preview_lead")
    ints = (f.getInt32 if inst.fmi3 else f.getInteger)([info.vr(x) for x in names])
    get_real = f.getFloat64 if inst.fmi3 else f.getReal
    out = dict(zip(names, (int(v) for v in ints)), meas_offset=0,
               loop_delay_time=float(get_real([info.vr("loop_delay_time")])[0]))
    return {name: out[name] for name in TIMING_OUTPUTS}


class _Exchange:
    """What a run's loop exchanges with the FMU at each step, set up once: the instance's scalar
    functions (:class:`~harness.masters.instance.ScalarFunctions`), the buffers of the reals and
    booleans it reads and of the input y_d it sets, and the addresses of those buffers and of
    their value references (the loop passes addresses, the fastest call)."""

    def __init__(self, inst, reals, bools):
        self.fn = ScalarFunctions(inst)
        info = inst.info
        self.n_out, self.n_bool = len(reals), len(bools)
        self.vr_out = vr_array([info.vr(x) for x in reals])
        self.vr_bool = vr_array([info.vr(x) for x in bools])
        self.vr_y_d = vr_array([info.vr("y_d")])
        self.out = (ctypes.c_double * self.n_out)()
        self.bools = ((ctypes.c_uint8 if inst.fmi3 else ctypes.c_int) * self.n_bool)()
        self.y_d_in = (ctypes.c_double * 1)()
        self.np_out = np.ctypeslib.as_array(self.out)
        #: a_out, a_bool, a_y, a_vr_out, a_vr_bool, a_vr_y
        self.addresses = tuple(ctypes.addressof(x) for x in (self.out, self.bools, self.y_d_in,
                                                              self.vr_out, self.vr_bool, self.vr_y_d))


def _run(inst, setup, rows, progress):
    """Row k: the outputs at t_k (with mv.feedthrough the controller's at t_(k+1)); one sample a step.
    The y_d input of a table reference is set before each step."""
    ex = _Exchange(inst, _OUTPUTS, ("saturated",))
    fn = ex.fn
    GET, SET, GET_BOOL, DO_STEP = fn.names
    c, get, set_, get_bool, step = fn.c, fn.get, fn.set, fn.get_bool, fn.step
    n, h = setup.n, setup.h
    n_out, sat, y_d_in, np_out = ex.n_out, ex.bools, ex.y_d_in, ex.np_out
    a_out, a_sat, a_y, a_vr_out, a_vr_sat, a_vr_y = ex.addresses
    external = not setup.scenario.signal.internal
    y_ref = setup.y_ref
    lag = 1 if setup.feedthrough else 0          # the controller's outputs of row k are at t_(k+lag)
    second = max(1, int(round(1.0 / h)))
    total = n + lag                              # outputs read at t_0 .. t_(total-1)
    failed, stage, k = False, GET, 0
    for k in range(total):
        stage = GET
        failed = get(c, a_vr_out, n_out, a_out) > 1
        if not failed:
            stage = GET_BOOL
            failed = get_bool(c, a_vr_sat, 1, a_sat) > 1
        if failed:
            break
        if k < n:
            rows[k, 2:2 + _N_PLANT] = np_out[:_N_PLANT]
        if k >= lag:
            rows[k - lag, 2 + _N_PLANT:-1] = np_out[_N_PLANT:]
            rows[k - lag, -1] = float(sat[0] != 0)
        if k == total - 1:
            break
        if external:
            y_d_in[0] = y_ref[min(k, n - 1)]
            stage = SET
            failed = set_(c, a_vr_y, 1, a_y) > 1
            if failed:
                break
        stage = DO_STEP
        failed = step(c, k * h, h, 1) > 1
        if failed:
            break
        if progress is not None and (k + 1) % second == 0:
            progress(min(k + 1, n), n)
    if failed:
        raise step_error(inst, stage, k, h, FMUError(f"{stage} returned an error"))
    if progress is not None:
        progress(n, n)


#: the fields of :func:`simulate_closed_loop_fmu_steps`: the closed loop's and the controller's
#: robust adaptation (est.adapting as 0/1, est.noise [um])
STEPS_FIELDS = CLOSED_LOOP_FIELDS + ("adapting", "noise")
_STEPS_DTYPE = np.dtype([(f, "f8") for f in STEPS_FIELDS])
_STEPS_REALS = _OUTPUTS + ("est.noise",)
_STEPS_BOOLS = ("saturated", "est.adapting")


def communication_points(y_d, y_ref, h, lead, hold_step=0.01, settle=0.5):
    """The communication points of a variable-step run, as sample indices.

    One sample per step from ``lead + 1`` samples before y_d moves until ``settle`` after it
    stops (and over the first ``settle``, where the controller detects its loop delay); steps
    of up to ``hold_step`` where it holds. A long step never spans two values of ``y_ref``,
    the input the FMU is given at the step's start and holds over the step.

    Parameters
    ----------
    y_d, y_ref : array_like
        The desired displacement of each sample, and the input y_d(k + lead) given at it.
    h : float
        The sample period [s].
    lead : int
        ``y_d_lead``: how many samples ahead the input is.
    hold_step, settle : float
        [s].

    Returns
    -------
    ndarray of int
        Increasing, from 0 to ``n - 1``.
    """
    y_d, y_ref = np.asarray(y_d, dtype=float), np.asarray(y_ref, dtype=float)
    n = y_d.size
    tail, big = int(round(settle / h)), max(1, int(round(hold_step / h)))
    busy = np.zeros(n + 1, dtype=bool)
    busy[:min(n, tail)] = True
    for j in np.flatnonzero(y_d[1:] != y_d[:-1]) + 1:        # y_d(j) differs from y_d(j - 1)
        busy[max(0, j - lead - 1):min(n, j + tail)] = True
    # the next sample where the input changes, or the loop is busy, from each sample on
    stop_at = busy[:n] | np.concatenate([[True], y_ref[1:] != y_ref[:-1]])
    nxt = np.full(n + 1, n - 1)
    idx = np.flatnonzero(stop_at)
    pos = np.searchsorted(idx, np.arange(n), side="right")
    has = pos < idx.size
    nxt[:n][has] = idx[pos[has]]
    points, k = [0], 0
    while k < n - 1:
        k = k + 1 if busy[k] else int(min(k + big, nxt[k], n - 1))
        points.append(k)
    return np.asarray(points, dtype=np.int64)


def simulate_closed_loop_fmu_steps(scenario, *, hold_step=0.01, settle=0.5, adaptation=None,
                                   plant_params=None, controller_params=None, fmu_dir=None,
                                   duration=None, registry=None, fmi_version=2, log=None):
    """Run a tracking scenario with a table or profile reference through PiezoStageClosedLoop at
    a variable communication step (see :func:`communication_points`).

    Parameters
    ----------
    scenario, adaptation, plant_params, controller_params, fmu_dir, duration, registry, fmi_version
        As :func:`simulate_closed_loop_fmu` (with preview; the master's order does not apply).
    hold_step, settle : float
        [s]: the longest step while y_d holds, and how long after a motion the steps stay one
        sample long.
    log : list, optional
        Extended with the FMU's messages (``"[Warning] ..."``) at the end of the run.

    Returns
    -------
    ndarray
        Structured array of :data:`STEPS_FIELDS`, one row per communication point: the rows of
        :func:`simulate_closed_loop_fmu` there, and ``adapting`` (est.adapting, 0 or 1) and
        ``noise`` (est.noise [um]).

    Raises
    ------
    ValueError
        A sines reference (the FMU's own ReferenceSignal: any step gives its samples; use
        :func:`simulate_closed_loop_fmu`), or a controller with ``mv.feedthrough``.
    FileNotFoundError, UnknownParameterError, FMUInitializationError, LoopDivergedError, FMUError
        As :func:`simulate_closed_loop_fmu`.
    """
    setup = prepare_closed_loop(scenario, adaptation=adaptation, plant_params=plant_params,
                                controller_params=controller_params, duration=duration,
                                registry=registry)
    if setup.scenario.signal.internal:
        raise ValueError(f"scenario '{setup.scenario.name}' has a sines reference: "
                         f"simulate_closed_loop_fmu_steps runs the input y_d (a table or a profile)")
    if setup.feedthrough:
        raise ValueError("simulate_closed_loop_fmu_steps runs the default controller (mv.feedthrough "
                         "= false): with feedthrough v depends on the input held over a step")
    fmi_version = check_fmi_version(fmi_version)
    info = load(fmu_path(CLOSED_LOOP_MODEL, fmu_dir, fmi_version), fmi_version)
    lead = reference_lead(setup.controller_params) or REFERENCE_LEAD
    points = communication_points(setup.y_d, setup.y_ref, setup.h, lead, hold_step, settle)
    rows = np.zeros((points.size, len(STEPS_FIELDS)))
    rows[:, 0] = setup.time[points]
    rows[:, 1] = setup.y_d[points]
    inst = None
    try:
        inst = Instance(info, "closed-loop-steps")
        inst.initialize(closed_loop_fmu_parameters(setup), (setup.n + 1) * setup.h)
        _run_steps(inst, setup, points, rows)
        if log is not None:
            log.extend(inst.log)
    finally:
        if inst is not None:
            inst.close()
    return as_structured(rows, _STEPS_DTYPE)


def _run_steps(inst, setup, points, rows):
    """Row i: the outputs at communication point ``points[i]``; the input y_d set before each step."""
    ex = _Exchange(inst, _STEPS_REALS, _STEPS_BOOLS)
    fn = ex.fn
    GET, SET, GET_BOOL, DO_STEP = fn.names
    c, get, set_, get_bool, step = fn.c, fn.get, fn.set, fn.get_bool, fn.step
    h, y_ref = setup.h, setup.y_ref
    n_out, n_bool, bools, y_d_in, np_out = ex.n_out, ex.n_bool, ex.bools, ex.y_d_in, ex.np_out
    a_out, a_bool, a_y, a_vr_out, a_vr_bool, a_vr_y = ex.addresses
    n_fields = len(CLOSED_LOOP_FIELDS)
    last = points.size - 1
    failed, stage, k = False, GET, 0
    for i, k in enumerate(points.tolist()):
        stage = GET
        failed = get(c, a_vr_out, n_out, a_out) > 1
        if not failed:
            stage = GET_BOOL
            failed = get_bool(c, a_vr_bool, n_bool, a_bool) > 1
        if failed:
            break
        rows[i, 2:n_fields - 1] = np_out[:n_out - 1]
        rows[i, n_fields - 1] = float(bools[0] != 0)
        rows[i, n_fields] = float(bools[1] != 0)
        rows[i, n_fields + 1] = np_out[n_out - 1]
        if i == last:
            break
        y_d_in[0] = y_ref[k]
        stage = SET
        failed = set_(c, a_vr_y, 1, a_y) > 1
        if failed:
            break
        stage = DO_STEP
        failed = step(c, k * h, (points[i + 1] - k) * h, 1) > 1
        if failed:
            break
    if failed:
        raise step_error(inst, stage, k, h, FMUError(f"{stage} returned an error"))
