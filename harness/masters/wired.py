"""The wired master: the three FMUs connected as a user wires them in a tool, under any
schedule, with a fault on any connection.

The loop is the closed-loop SSP's (:data:`harness.buildtime.ssp_file.SSP_CONNECTIONS`): ReferenceSignal's
``y_ref``, ``y_preview``, ``t_preview`` and PiezoStage's ``y_meas``, ``t_meas`` to the
controller's inputs of the same names, the controller's ``v`` to PiezoStage's.

Schedules (docs/cosimulation.md, section 2):

* ``"exchange"``: at ``t_k`` every output is read, every input set, every FMU stepped (a
  Jacobi master, fmpy's SSP player after its first step, the container in parallel mode);
  the loop delay is d = 2.
* ``"player"``: the same, with every input 0 at the first step (fmpy's SSP player).
* a permutation of ``("reference", "controller", "plant")``: true Gauss-Seidel, each FMU in
  turn gets the latest outputs of the others (post-step where they stepped before it),
  steps and publishes (the container in sequential mode); d = 1.

A :class:`Fault` changes what one input receives: nothing (``"open"``: the input keeps its
start value, as an unconnected input does), a constant, the first value it received
(``"stuck"``), the value times a factor (``"scale"``: -1 for an inverted sign, 1e-3 for mm
fed to a µm input), another output (``"source"``: ``y_meas`` fed from the reference's
``y_ref``), +value and -value in turn whatever the loop does (``"alternate"``: a
measurement no stage gives), the value it received at the fault's start from then on
(``"freeze"``: a sensor that freezes where it is), the value once every ``every`` samples and the connection's
otherwise (``"dropout"``: a sensor that drops a reading now and then), or the connection's
value plus ``value`` times the time since the fault began (``"drift"``: an offset that
creeps, ``value`` per second), from a given time on. :func:`simulate_wired` runs the loop until the end or
until an FMU's doStep fails, and returns what happened: the samples, the status, the first
Error message and every Warning (:class:`WiredRun`).

A scenario with a table or profile reference has no ReferenceSignal to run: the reference
is then played by the master itself with ReferenceSignal's outputs and timing (``y_d(k)``,
``y_ref = y_d(k + lead)``, the stamped preview ``y_d(k + 4)`` at ``(k + 4) h``, k the steps it
took), stepped in its place in the schedule, so a true Gauss-Seidel order runs a stage-use
profile too (docs/stage_use.md).

This master exists to show what the FMUs do when they are wired wrongly (the fault table of
docs/robustness.md, ``tests/test_supervision_family.py``) and in a true Gauss-Seidel order;
the harness's own masters (:mod:`harness.masters.fmpy`, :mod:`harness.masters.native`) run
the loop fast.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field
import itertools
import math

import numpy as np

from ..fmu import CONTROLLER_MODEL, PLANT_MODEL, REFERENCE_MODEL, check_fmi_version, fmu_path, load
from ..loop import REFERENCE_LEAD, REFERENCE_PREVIEW, reference_lead
from ..scenarios import get_scenario
from ..buildtime.ssp_file import SSP_CONNECTIONS, parameter_set_for_scenario
from .instance import Instance, ScalarFunctions, raw_function, vr_array

__all__ = ["COMPONENTS", "SCHEDULES", "FAULT_KINDS", "WIRED_FIELDS", "Fault", "WiredRun",
           "simulate_wired", "schedule_name"]

#: the components of the loop and their FMUs (the SSP's names)
COMPONENTS = {"reference": REFERENCE_MODEL, "controller": CONTROLLER_MODEL, "plant": PLANT_MODEL}
#: every schedule: the two exchanging ones, then the six sequential orders
SCHEDULES = ("exchange", "player") + tuple(itertools.permutations(("reference", "controller", "plant")))
FAULT_KINDS = ("open", "constant", "stuck", "scale", "source", "alternate", "freeze", "dropout", "drift")

# the Real outputs read from each component after each step (what the connections and the
# record need); the controller's Integer and Boolean outputs are read separately
_REAL_OUTPUTS = {
    "reference": ("y_d", "y_ref", "y_preview", "t_preview"),
    "plant": ("y", "y_meas", "t_meas"),
    "controller": ("v", "q", "pred_error"),
}
_INT_OUTPUTS = ("loop_delay",)
#: the fields of the record, one row per sample t_k (the values at t_k; v is the voltage the
#: plant applies over [t_k, t_(k+1)), y_meas_in what the controller's y_meas input received)
WIRED_FIELDS = ("time", "y_d", "y", "y_meas", "v", "q", "pred_error", "saturated", "loop_delay",
                "y_meas_in")
_WIRED_DTYPE = np.dtype([(f, "f8") for f in WIRED_FIELDS])


@dataclass(frozen=True)
class Fault:
    """What one input of the loop receives instead of its connection's value.

    Attributes
    ----------
    connector : str
        The input, by its name on the controller or the plant (``"y_meas"``, ``"v"``,
        ``"t_meas"``, ...): the end of one of :data:`harness.buildtime.ssp_file.SSP_CONNECTIONS`.
    kind : str
        One of :data:`FAULT_KINDS`.
    value : float or str
        The constant (``"constant"``), the factor (``"scale"``), the amplitude
        (``"alternate"``), the value of a dropped reading (``"dropout"``), the rate per second
        (``"drift"``) or the output ``"component.variable"`` it is fed from (``"source"``).
    start : float
        The time [s] from which the fault acts (before it the connection is sound).
    every : int
        ``"dropout"``: one sample in ``every`` (from the first at ``start``) gets ``value``.
    """

    connector: str
    kind: str
    value: object = 0.0
    start: float = 0.0
    every: int = 100

    def __post_init__(self):
        ends = [end for _, _, _, end in SSP_CONNECTIONS]
        if self.connector not in ends:
            raise ValueError(f"fault on {self.connector!r}: not an input of the loop; inputs: "
                             f"{', '.join(ends)}")
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind {self.kind!r}: one of {', '.join(FAULT_KINDS)}")
        if self.kind == "source":
            comp, _, var = str(self.value).partition(".")
            if comp not in _REAL_OUTPUTS or var not in _REAL_OUTPUTS[comp]:
                raise ValueError(f"fault source {self.value!r}: one of "
                                 + ", ".join(f"{c}.{v}" for c, vs in _REAL_OUTPUTS.items() for v in vs))
        elif self.kind in ("constant", "scale", "alternate", "dropout", "drift") \
                and not math.isfinite(float(self.value)):
            raise ValueError(f"fault value {self.value!r}: a finite number")
        if self.kind == "dropout" and not (isinstance(self.every, int) and self.every >= 1):
            raise ValueError(f"fault every {self.every!r}: a whole number of samples >= 1")


@dataclass
class WiredRun:
    """What a wired run did.

    Attributes
    ----------
    samples : ndarray
        Structured array of :data:`WIRED_FIELDS`, one row per sample reached.
    error_time : float or None
        The time [s] of the step that returned an Error (None: the run reached its end).
    error : str
        The first Error message of the FMU that failed ("" if none).
    warnings : dict
        ``{component: [message, ...]}``: every Warning each FMU logged, in order.
    fault : int
        The controller's ``sup.fault`` where the run ended (0: none; with ``sup.reaction`` = 1,
        the code of the verdict that holds the loop in its safe state).
    fault_time : float
        Its ``sup.fault_time`` [s].
    """

    samples: np.ndarray
    error_time: float = None
    error: str = ""
    warnings: dict = field(default_factory=dict)
    fault: int = 0
    fault_time: float = 0.0


def schedule_name(schedule):
    """A schedule as text: ``"exchange"``, ``"player"`` or ``"plant, controller, reference"``."""
    return schedule if isinstance(schedule, str) else ", ".join(schedule)


def _check_schedule(schedule):
    if isinstance(schedule, str):
        if schedule in ("exchange", "player"):
            return schedule
    elif tuple(schedule) in SCHEDULES:
        return tuple(schedule)
    raise ValueError(f"schedule {schedule!r}: 'exchange', 'player' or an order of "
                     f"reference, controller and plant")


def simulate_wired(scenario, schedule="exchange", faults=(), *, duration=None, plant_params=None,
                   controller_params=None, reference_params=None, fmu_dir=None, fmi_version=2,
                   registry=None):
    """Run the three FMUs of a sines tracking scenario, wired by hand, under ``schedule``.

    Parameters
    ----------
    scenario : str
        A tracking scenario with a sines reference (its parameters as the closed-loop SSP
        binds them: :func:`harness.buildtime.ssp_file.parameter_set_for_scenario`).
    schedule : str or tuple of str
        One of :data:`SCHEDULES` (see the module docstring).
    faults : sequence of Fault
        At most one per input.
    duration : float, optional
        Override the scenario's duration [s].
    plant_params, controller_params, reference_params : dict, optional
        Overrides on top of the scenario's, by FMU variable name.
    fmu_dir : str or Path, optional
    fmi_version : {2, 3}
    registry : dict, optional

    Returns
    -------
    WiredRun
    """
    schedule = _check_schedule(schedule)
    fault_of = {}
    for f in faults:
        if f.connector in fault_of:
            raise ValueError(f"two faults on {f.connector!r}")
        fault_of[f.connector] = f
    fmi_version = check_fmi_version(fmi_version)
    sc = get_scenario(scenario, registry)
    table = sc.kind == "tracking" and not sc.signal.internal
    params = {comp: {} for comp in COMPONENTS}
    if table:
        if reference_params:
            raise ValueError(f"scenario '{sc.name}' has a {sc.signal.kind} reference, which the "
                             f"master plays itself: reference_params do not apply")
        h = float(sc.step_size)
        params["plant"].update(sc.plant)
        params["controller"].update(sc.controller)
        params["plant"]["h"] = params["controller"]["h"] = h
        stop = float(sc.duration)
    else:
        pset = parameter_set_for_scenario(sc, registry)
        for key, value in pset.values.items():
            comp, name = key.split(".", 1)
            params[comp][name] = value
        h = float(pset.step_size)
        stop = float(pset.stop_time)
    for comp, over in (("plant", plant_params), ("controller", controller_params),
                       ("reference", reference_params)):
        params[comp].update(over or {})
    stop = stop if duration is None else float(duration)
    n = int(round(stop / h))
    if n < 1 or abs(n * h - stop) > 1e-9 * max(1.0, stop):
        raise ValueError(f"duration {stop!r} s is not a whole number of steps of {h:g} s")

    inst = {}
    try:
        for comp, model in COMPONENTS.items():
            if table and comp == "reference":
                lead = reference_lead(params["controller"]) or REFERENCE_LEAD
                inst[comp] = _TableReference(sc.signal, n, h, lead)
                continue
            info = load(fmu_path(model, fmu_dir, fmi_version), fmi_version)
            inst[comp] = Instance(info, comp)
        for comp in COMPONENTS:
            inst[comp].initialize(params[comp], n * h)
        return _run(inst, schedule, fault_of, n, h)
    finally:
        for i in inst.values():
            i.close()


class _TableReference:
    """ReferenceSignal played by the master for a table or profile reference: after k steps its
    outputs are ``y_d(k)``, ``y_ref = y_d(k + lead)``, ``y_preview = y_d(k + preview)`` and
    ``t_preview = (k + preview) h`` (the FMU's own, with its default ``preview``)."""

    fmi3 = False

    def __init__(self, signal, n, h, lead):
        ahead = max(lead, REFERENCE_PREVIEW) + 2
        self.y_d = signal.evaluate(np.arange(n + ahead, dtype=float) * h).tolist()
        self.h, self.lead, self.k = h, lead, 0
        self.log = []

    def initialize(self, params, stop_time):
        self.k = 0

    def outputs(self, arr):
        """Write y_d, y_ref, y_preview, t_preview (the order of _REAL_OUTPUTS) into ``arr``."""
        k, y = self.k, self.y_d
        arr[0], arr[1], arr[2] = y[k], y[k + self.lead], y[k + REFERENCE_PREVIEW]
        arr[3] = (k + REFERENCE_PREVIEW) * self.h

    def close(self):
        pass


def _run(inst, schedule, fault_of, n, h):
    table = isinstance(inst["reference"], _TableReference)
    fn = {comp: ScalarFunctions(i) for comp, i in inst.items() if not isinstance(i, _TableReference)}
    keep = []

    def reals(values):
        arr = (ctypes.c_double * len(values))(*values)
        keep.append(arr)
        return arr

    # every Real output in one slot of `val`, by (component, variable)
    slot, vr_out, out_arr = {}, {}, {}
    for comp, names in _REAL_OUTPUTS.items():
        out_arr[comp] = reals([0.0] * len(names))
        if comp in fn:
            vr_out[comp] = vr_array([inst[comp].info.vr(x) for x in names])
            keep.append(vr_out[comp])
        for i, x in enumerate(names):
            slot[(comp, x)] = (comp, i)
    # each component's inputs, in the order of SSP_CONNECTIONS
    ins = {comp: [(a, ac, bc) for a, ac, b, bc in SSP_CONNECTIONS if b == comp] for comp in inst}
    vr_in, in_arr = {}, {}
    for comp, conns in ins.items():
        if conns:
            vr_in[comp] = vr_array([inst[comp].info.vr(bc) for _, _, bc in conns])
            in_arr[comp] = reals([0.0] * len(conns))
            keep.append(vr_in[comp])
    ctrl = inst["controller"]
    vr_int = vr_array([ctrl.info.vr(x) for x in _INT_OUTPUTS])
    vr_sat = vr_array([ctrl.info.vr("saturated")])
    int_out = (ctypes.c_int32 * len(_INT_OUTPUTS))()
    sat_out = (ctypes.c_uint8 * 1)() if ctrl.fmi3 else (ctypes.c_int * 1)()
    vr_sat_addr, sat_addr = ctypes.addressof(vr_sat), ctypes.addressof(sat_out)
    vr_int_addr, int_addr = ctypes.addressof(vr_int), ctypes.addressof(int_out)
    get_int_raw = _int_getter(ctrl)
    first, turns, frozen = {}, {}, {}
    rows = np.zeros((n, len(WIRED_FIELDS)))
    failed = None

    def read(comp):
        arr = out_arr[comp]
        if table and comp == "reference":
            inst[comp].outputs(arr)
            return
        f = fn[comp]
        st = f.get(f.c, ctypes.addressof(vr_out[comp]), len(arr), ctypes.addressof(arr))
        if st > 1:
            raise _Failed(comp, f.names[0])

    def value(comp, var):
        c, i = slot[(comp, var)]
        return out_arr[c][i]

    # per component: (input index, source slot, fault) and the set call's arguments
    plan = {}
    for comp, conns in ins.items():
        if conns:
            fc = fn[comp]
            plan[comp] = ([(i, slot[(a, ac)], bc, fault_of.get(bc)) for i, (a, ac, bc) in enumerate(conns)],
                          fc, ctypes.addressof(vr_in[comp]), ctypes.addressof(in_arr[comp]), len(conns))

    def write(comp, t, zero=False):
        if comp not in plan:
            return
        links, fc, vr_addr, arr_addr, n_in = plan[comp]
        arr = in_arr[comp]
        opened = []
        for i, (c_src, j), bc, f in links:
            x = 0.0 if zero else out_arr[c_src][j]
            if f is not None and t >= f.start - 0.5 * h:
                if f.kind == "open":
                    opened.append(i)        # never set: keeps what it had (its start value)
                    continue
                if f.kind == "constant":
                    x = float(f.value)
                elif f.kind == "stuck":
                    x = first.setdefault(bc, x)
                elif f.kind == "scale":
                    x = x * float(f.value)
                elif f.kind == "alternate":
                    turns[bc] = turns.get(bc, 0) + 1
                    x = float(f.value) if turns[bc] % 2 else -float(f.value)
                elif f.kind == "freeze":
                    x = frozen.setdefault(bc, x)
                elif f.kind == "dropout":
                    turns[bc] = turns.get(bc, 0) + 1
                    x = float(f.value) if turns[bc] % f.every == 1 % f.every else x
                elif f.kind == "drift":
                    x = x + float(f.value) * (t - f.start)
                else:
                    x = value(*str(f.value).split(".", 1))
            else:
                first.setdefault(bc, x)
            arr[i] = x
            if bc == "y_meas":
                rows[k, 9] = x
        if not opened:
            st = fc.set(fc.c, vr_addr, n_in, arr_addr)
            if st > 1:
                raise _Failed(comp, fc.names[1])
            return
        for i, _, bc, _ in links:
            if i in opened:
                continue
            one = reals([arr[i]])
            vr = vr_array([inst[comp].info.vr(bc)])
            keep.append(vr)
            st = fc.set(fc.c, ctypes.addressof(vr), 1, ctypes.addressof(one))
            if st > 1:
                raise _Failed(comp, fc.names[1])

    def step(comp, t):
        if table and comp == "reference":
            inst[comp].k += 1
            return
        f = fn[comp]
        st = f.step(f.c, t, h, 1)
        if st > 1:
            raise _Failed(comp, f.names[3])

    def record(k):
        rows[k, 0] = k * h
        rows[k, 1] = value("reference", "y_d")
        rows[k, 2] = value("plant", "y")
        rows[k, 3] = value("plant", "y_meas")
        rows[k, 4] = value("controller", "v")
        rows[k, 5] = value("controller", "q")
        rows[k, 6] = value("controller", "pred_error")
        fc = fn["controller"]
        fc.get_bool(fc.c, vr_sat_addr, 1, sat_addr)
        get_int_raw(fc.c, vr_int_addr, 1, int_addr)
        rows[k, 7] = float(sat_out[0] != 0)
        rows[k, 8] = float(int_out[0])

    k = 0
    try:
        for comp in COMPONENTS:
            read(comp)
        for k in range(n):
            t = k * h
            record(k)
            if isinstance(schedule, str):
                for comp in COMPONENTS:
                    write(comp, t, zero=schedule == "player" and k == 0)
                for comp in COMPONENTS:
                    step(comp, t)
                for comp in COMPONENTS:
                    read(comp)
            else:
                for comp in schedule:
                    write(comp, t)
                    step(comp, t)
                    read(comp)
        k = n
    except _Failed as exc:
        failed = exc
    del keep
    samples = rows[:k].copy().view(_WIRED_DTYPE).reshape(k)
    run = WiredRun(samples)
    if failed is None:
        fc = fn["controller"]
        vr_code, vr_when = vr_array([ctrl.info.vr("sup.fault")]), vr_array([ctrl.info.vr("sup.fault_time")])
        code, when = (ctypes.c_int32 * 1)(), (ctypes.c_double * 1)()
        if get_int_raw(fc.c, ctypes.addressof(vr_code), 1, ctypes.addressof(code)) <= 1 \
                and fc.get(fc.c, ctypes.addressof(vr_when), 1, ctypes.addressof(when)) <= 1:
            run.fault, run.fault_time = int(code[0]), float(when[0])
    for comp, i in inst.items():
        run.warnings[comp] = [line[len("[Warning] "):] for line in i.log if line.startswith("[Warning]")]
    if failed is not None:
        run.error_time = k * h
        log = inst[failed.component].log
        errors = [line[len("[Error] "):] for line in log if line.startswith("[Error]")]
        run.error = errors[0] if errors else f"{failed.call} returned an error"
    return run


def _int_getter(inst):
    """The instance's Integer (FMI 3.0: Int32) getter as a bare C function, called the FMI 2.0
    way: ``get(c, vr, n, address)``."""
    vp, sz = ctypes.c_void_p, ctypes.c_size_t
    if not inst.fmi3:
        return raw_function(inst.fmu, "fmi2GetInteger", vp, vp, sz, vp)
    raw = raw_function(inst.fmu, "fmi3GetInt32", vp, vp, sz, vp, sz)
    return lambda c, vr, n, addr: raw(c, vr, n, addr, n)


class _Failed(Exception):
    def __init__(self, component, call):
        super().__init__(f"{component}: {call}")
        self.component, self.call = component, call
