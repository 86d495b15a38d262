"""FMI 2.0 co-simulation master for the PiezoStage and AdaptiveCompoundController FMUs (fmpy).

Semantics: both FMUs step on the grid ``t_k = k h``.  PiezoStage has no
direct feedthrough: at ``t_k`` it reports ``y(k)``, ``y_meas(k)``, ``x(k)``
and ``u = u(k-1)``; the ``v`` set at ``t_k`` acts over ``[t_k, t_k + h)``.
The default controller has none either: a doStep from ``t_k`` samples
``y_ref = y_d(k+d)`` and ``y_meas(k)`` and publishes the control it computed
at ``t_(k+1)``, so the plant applies it over ``[t_(k+1), t_(k+2))`` and the
loop delay is d = 2 (``mv.delay = 1``).

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

Each FMU file is extracted once per process (cache keyed by path, mtime and
size); instances are always terminated and freed, also when a run fails.
"""

from __future__ import annotations

import atexit
import ctypes
import difflib
from pathlib import Path
import shutil
import tempfile

import numpy as np

from ._common import (
    CLOSED_LOOP_DTYPE,
    CLOSED_LOOP_FIELDS,
    OPEN_LOOP_DTYPE,
    as_structured,
    open_loop_grid,
    prepare_closed_loop,
    sample_range,
)

__all__ = [
    "PLANT_MODEL",
    "CONTROLLER_MODEL",
    "REFERENCE_MODEL",
    "FMUError",
    "FMUInitializationError",
    "LoopDivergedError",
    "UnknownParameterError",
    "default_fmu_dir",
    "fmu_path",
    "simulate_closed_loop",
    "simulate_open_loop",
]

PLANT_MODEL = "PiezoStage"
CONTROLLER_MODEL = "AdaptiveCompoundController"
REFERENCE_MODEL = "ReferenceSignal"

_PLANT_OUTPUTS = ("u", "x", "y", "y_meas")
_CTRL_OUTPUTS = ("v", "q", "est.a1", "est.a2", "est.b1", "est.b2", "pred_error")


class FMUError(RuntimeError):
    """An FMI call failed; the message carries the FMU's log messages."""


class LoopDivergedError(FMUError):
    """The closed loop diverged: the controller's monitor found it unstable, or a computed
    value was not finite; the message carries the FMU's explanation."""


class FMUInitializationError(FMUError, ValueError):
    """The FMU refused its parameters (instantiation or initialization failed)."""


class UnknownParameterError(KeyError):
    """A parameter name is not a parameter of the FMU; the message lists the valid names."""

    def __str__(self):  # KeyError would quote the message
        return self.args[0]


def default_fmu_dir():
    """Folder of the FMUs: ``$PIEZO_FMU_DIR``, the copies ``pip install .`` put inside the
    package, or ``<repo>/build/fmus`` (see :mod:`harness._paths`)."""
    from . import _paths
    return _paths.fmu_dir()


def fmu_path(model, fmu_dir=None):
    """Path of a model's FMU, checked to exist.

    Parameters
    ----------
    model : str
        ``"PiezoStage"``, ``"AdaptiveCompoundController"`` or ``"ReferenceSignal"``.
    fmu_dir : str or Path, optional
        Defaults to :func:`default_fmu_dir`.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        With the command that builds the FMUs.
    """
    path = Path(fmu_dir if fmu_dir is not None else default_fmu_dir()) / f"{model}.fmu"
    if not path.is_file():
        from . import _paths
        raise FileNotFoundError(f"FMU not found: {path}; {_paths.where_to_get_it()} "
                                f"(or set PIEZO_FMU_DIR to the folder of the FMUs)")
    return path


# ---------------------------------------------------------------------------
# extraction cache
# ---------------------------------------------------------------------------

class _FMUInfo:
    """An extracted FMU: model description, unzip folder, variables by name."""

    __slots__ = ("path", "md", "unzipdir", "variables", "model")

    def __init__(self, path, md, unzipdir):
        self.path = path
        self.md = md
        self.unzipdir = unzipdir
        self.variables = {v.name: v for v in md.modelVariables}
        self.model = md.coSimulation.modelIdentifier

    def vr(self, name):
        try:
            return self.variables[name].valueReference
        except KeyError:
            raise FMUError(f"{self.path.name} has no variable '{name}'") from None


_EXTRACTED = {}
_TEMP_DIRS = []


def _cleanup():
    for d in _TEMP_DIRS:
        shutil.rmtree(d, ignore_errors=True)


atexit.register(_cleanup)


def _load(path):
    import fmpy

    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    info = _EXTRACTED.get(key)
    if info is None:
        md = fmpy.read_model_description(str(path))
        if md.fmiVersion != "2.0" or md.coSimulation is None:
            raise FMUError(f"{path} is not an FMI 2.0 Co-Simulation FMU")
        unzipdir = tempfile.mkdtemp(prefix=f"harness_{path.stem}_")
        _TEMP_DIRS.append(unzipdir)
        fmpy.extract(str(path), unzipdir=unzipdir)
        info = _FMUInfo(path, md, unzipdir)
        _EXTRACTED[key] = info
    return info


# ---------------------------------------------------------------------------
# logging: route the FMU's messages of our instances into per-instance lists
# ---------------------------------------------------------------------------

_LOGGER = None
_LOGS = {}          # instance name -> list of messages
_COUNTER = [0]


def _log_message(component, instance_name, status, category, message):
    name = instance_name.decode("utf-8", "replace") if instance_name else ""
    text = message.decode("utf-8", "replace") if message else ""
    sink = _LOGS.get(name)
    if sink is not None:
        labels = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
        label = labels[status] if 0 <= status < len(labels) else str(status)
        if len(sink) < 200:
            sink.append(f"[{label}] {text}")
    else:  # somebody else's FMU in this process: behave like fmpy's default
        from fmpy.fmi1 import printLogMessage
        printLogMessage(component, instance_name, status, category, message)


def _callbacks():
    """A fresh callback structure whose (formatted) log messages reach :func:`_log_message`.

    fmpy's native proxy formats the variadic message and forwards it to one
    process-wide logger, the one of the structure it was last installed on;
    installing it on a fresh structure per instance makes sure our instances
    log to us even if other code in the process installed its own logger.
    """
    global _LOGGER
    from fmpy import calloc, free
    from fmpy import fmi2

    if _LOGGER is None:
        _LOGGER = fmi2.fmi2CallbackLoggerTYPE(_log_message)
    cb = fmi2.fmi2CallbackFunctions()
    cb.logger = _LOGGER
    cb.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(free)
    try:
        from fmpy.logging import addLoggerProxy
        addLoggerProxy(ctypes.byref(cb))
    except Exception:  # pragma: no cover - the raw format string is logged then
        pass
    return cb


# ---------------------------------------------------------------------------
# one FMU instance
# ---------------------------------------------------------------------------

def _typed_parameters(info, params):
    """Parameters by FMU variable name as ``(reals, ints, bools)``, each ``([vr], [value])``.

    Raises
    ------
    UnknownParameterError
        A name is not a parameter of the FMU (the message lists the close ones and all).
    TypeError
        A value does not fit the variable's type.
    """
    reals, ints, bools = ([], []), ([], []), ([], [])
    for name, value in params.items():
        var = info.variables.get(name)
        if var is None or var.causality != "parameter":
            valid = [n for n, v in info.variables.items() if v.causality == "parameter"]
            close = difflib.get_close_matches(name, valid, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise UnknownParameterError(
                f"'{name}' is not a parameter of {info.model}{hint}; "
                f"parameters: {', '.join(valid)}")
        if var.type == "Real":
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
                raise TypeError(f"{info.model} parameter {name} is Real, got {value!r}")
            reals[0].append(var.valueReference)
            reals[1].append(float(value))
        elif var.type == "Integer":
            if isinstance(value, (bool, np.bool_)) or not float(value).is_integer():
                raise TypeError(f"{info.model} parameter {name} is Integer, got {value!r}")
            ints[0].append(var.valueReference)
            ints[1].append(int(value))
        elif var.type == "Boolean":
            if not (isinstance(value, (bool, np.bool_)) or value in (0, 1)):
                raise TypeError(f"{info.model} parameter {name} is Boolean, got {value!r}")
            bools[0].append(var.valueReference)
            bools[1].append(bool(value))
        else:
            raise TypeError(f"{info.model} parameter {name} has unsupported type {var.type}")
    return reals, ints, bools


class _Instance:
    """Thin lifetime wrapper of an fmpy FMU2Slave."""

    def __init__(self, info, role):
        from fmpy.fmi2 import FMU2Slave

        _COUNTER[0] += 1
        self.info = info
        self.name = f"harness-{role}-{_COUNTER[0]}"
        self.log = _LOGS.setdefault(self.name, [])
        self.fmu = None
        self.instantiated = False
        self.initialized = False
        self.fmu = FMU2Slave(guid=info.md.guid, unzipDirectory=info.unzipdir,
                             modelIdentifier=info.model, instanceName=self.name)
        try:
            self.callbacks = _callbacks()   # kept alive with the instance
            self.fmu.instantiate(callbacks=self.callbacks, loggingOn=False)
        except Exception as exc:
            self._release_library()
            raise FMUInitializationError(self._message(f"instantiating {info.path.name}", exc)) from None
        self.instantiated = True

    def _message(self, what, exc):
        errors = [line for line in self.log if line.startswith("[Error]")]
        detail = "; ".join((errors or self.log)[-5:]) or str(exc)
        return f"{self.info.model}: {what} failed: {detail}"

    def set_parameters(self, params):
        """Set parameters by name, typed from the model description."""
        reals, ints, bools = _typed_parameters(self.info, params)
        try:
            if reals[0]:
                self.fmu.setReal(*reals)
            if ints[0]:
                self.fmu.setInteger(*ints)
            if bools[0]:
                self.fmu.setBoolean(*bools)
        except Exception as exc:
            raise FMUInitializationError(self._message("setting parameters", exc)) from None

    def initialize(self, params, stop_time):
        try:
            self.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
        except Exception as exc:
            raise FMUInitializationError(self._message("fmi2SetupExperiment", exc)) from None
        self.set_parameters(params)
        try:
            self.fmu.enterInitializationMode()
            self.fmu.exitInitializationMode()
        except Exception as exc:
            raise FMUInitializationError(self._message("initialization", exc)) from None
        self.initialized = True

    def _release_library(self):
        try:
            self.fmu.freeLibrary()
        except Exception:
            pass

    def close(self):
        """Terminate (if initialized) and free; never raises."""
        if self.fmu is None:
            return
        try:
            if self.initialized:
                try:
                    self.fmu.terminate()
                except Exception:
                    pass
            if self.instantiated:
                try:
                    self.fmu.freeInstance()   # also unloads the library
                except Exception:
                    self._release_library()
        finally:
            self.fmu = None
            _LOGS.pop(self.name, None)


def _vr_array(values):
    from fmpy.fmi2 import fmi2ValueReference

    return (fmi2ValueReference * len(values))(*values)


def _step_error(inst, what, k, h, exc):
    message = inst._message(f"{what} at t = {k * h:.6g} s (sample {k})", exc)
    diverged = any("[Error]" in line and ("diverged" in line or "unstable" in line)
                   for line in inst.log)
    return (LoopDivergedError if diverged else FMUError)(message)


# ---------------------------------------------------------------------------
# public runs
# ---------------------------------------------------------------------------

def simulate_closed_loop(scenario, *, adaptation=None, preview=True, master="gauss-seidel",
                         plant_params=None, controller_params=None, fmu_dir=None,
                         duration=None, registry=None, step_order="plant-first", progress=None):
    """Run a tracking scenario through both FMUs with fmpy.

    Parameters
    ----------
    scenario : str or Scenario
        A tracking scenario or its name (see :func:`harness.list_scenarios`).
    adaptation : bool, optional
        Force the controller's RLS on (True) or off (False); ``None`` keeps the
        scenario's / FMU's setting (on by default).
    preview : bool
        Feed the controller ``y_ref = y_d(k + d)`` (True, docs/model.md, controller)
        or ``y_d(k)`` (False; gives a lag error).
    master : {"gauss-seidel", "jacobi"}
        Co-simulation algorithm (see the module docstring); both run the same
        loop with the default controller.
    plant_params, controller_params : dict, optional
        Extra parameter overrides by FMU variable name (after the scenario's).
    fmu_dir : str or Path, optional
        Folder holding ``PiezoStage.fmu`` and ``AdaptiveCompoundController.fmu``
        (default ``build/fmus`` or ``$PIEZO_FMU_DIR``).
    duration : float, optional
        Override the scenario's duration [s].
    registry : dict, optional
        Scenario registry for name lookup (default: built-in scenarios).
    step_order : {"plant-first", "controller-first"}
        Order of the two doStep calls of the Gauss-Seidel master.
    progress : callable, optional
        Called as ``progress(done, n)`` after every simulated second and at the end.

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
        The controller declared the loop unstable, or a value diverged.
    FMUError
        An FMI call failed during the run.
    """
    setup = prepare_closed_loop(scenario, adaptation=adaptation, preview=preview, master=master,
                                plant_params=plant_params, controller_params=controller_params,
                                duration=duration, registry=registry, step_order=step_order)
    return _simulate(setup, fmu_dir, progress=progress)


def _simulate(setup, fmu_dir=None, block=0, block_ns=None, progress=None):
    """Run a prepared closed loop (see :func:`_run_closed_loop` for the timing and progress
    arguments)."""
    p_info = _load(fmu_path(PLANT_MODEL, fmu_dir))
    c_info = _load(fmu_path(CONTROLLER_MODEL, fmu_dir))
    n, h = setup.n, setup.h
    rows = np.zeros((n, len(CLOSED_LOOP_FIELDS)))
    rows[:, 0] = setup.time
    rows[:, 1] = setup.y_d

    plant = ctrl = None
    try:
        plant = _Instance(p_info, "plant")
        ctrl = _Instance(c_info, "controller")
        stop = n * h
        plant.initialize(setup.plant_params, stop)
        ctrl.initialize(setup.controller_params, stop)
        _run_closed_loop(plant, ctrl, setup, rows, block, block_ns, progress)
    finally:
        if ctrl is not None:
            ctrl.close()
        if plant is not None:
            plant.close()
    return as_structured(rows, CLOSED_LOOP_DTYPE)


def _raw_function(fmu, name, *argtypes):
    """The FMU's C function ``name`` as a bare ctypes prototype returning the status.

    fmpy's ``FMU2Slave.fmi2*`` methods wrap every call in Python (argument
    conversion, call logging, a status check that raises); the hot loop calls
    the C functions directly, passes raw addresses into its result arrays and
    checks the status itself.
    """
    address = ctypes.cast(getattr(fmu.dll, name), ctypes.c_void_p).value
    return ctypes.CFUNCTYPE(ctypes.c_int, *argtypes)(address)


class _LoopFunctions:
    """The fmi2 functions of the closed loop for one plant and one controller instance."""

    def __init__(self, plant, ctrl):
        vp, sz, dbl, i32 = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_double, ctypes.c_int
        pf, cf = plant.fmu, ctrl.fmu
        self.pc, self.cc = pf.component, cf.component
        self.p_get = _raw_function(pf, "fmi2GetReal", vp, vp, sz, vp)
        self.p_set = _raw_function(pf, "fmi2SetReal", vp, vp, sz, vp)
        self.p_step = _raw_function(pf, "fmi2DoStep", vp, dbl, dbl, i32)
        self.c_get = _raw_function(cf, "fmi2GetReal", vp, vp, sz, vp)
        self.c_set = _raw_function(cf, "fmi2SetReal", vp, vp, sz, vp)
        self.c_get_bool = _raw_function(cf, "fmi2GetBoolean", vp, vp, sz, vp)
        self.c_step = _raw_function(cf, "fmi2DoStep", vp, dbl, dbl, i32)


def _run_closed_loop(plant, ctrl, setup, rows, block=0, block_ns=None, progress=None):
    """Run the whole loop into ``rows`` (n x 12, the CLOSED_LOOP_FIELDS).

    Every value goes straight from the FMU into its place in memory: the plant
    writes ``y_meas, y`` of sample k next to ``y_ref(k)`` in an exchange array,
    whose first two entries are then exactly the controller's inputs; the
    controller writes ``v, q, a1..b2, pred_error`` into row k, and the plant
    takes its ``v`` from there. ``block``/``block_ns``: thread CPU time [ns]
    of every complete block of ``block`` samples is appended to the list.
    ``progress(done, n)`` is called after every simulated second (blocks of one
    second then, unless timed).
    """
    import time

    from fmpy.fmi2 import fmi2Boolean

    fn = _LoopFunctions(plant, ctrl)
    pc, cc = fn.pc, fn.cc
    p_get, p_set, p_step = fn.p_get, fn.p_set, fn.p_step
    c_get, c_set, c_get_bool, c_step = fn.c_get, fn.c_set, fn.c_get_bool, fn.c_step
    pi, ci = plant.info, ctrl.info

    keep = []                       # ctypes arrays whose addresses are passed

    def addr(values):
        arr = _vr_array(values)
        keep.append(arr)
        return ctypes.addressof(arr)

    vr_p_out = addr([pi.vr("y_meas"), pi.vr("y")])
    vr_p_in = addr([pi.vr("v")])
    vr_c_in = addr([ci.vr("y_ref"), ci.vr("y_meas")])
    vr_c_out = addr([ci.vr(name) for name in _CTRL_OUTPUTS])
    vr_c_sat = addr([ci.vr("saturated")])
    n_c = len(_CTRL_OUTPUTS)

    n, h = setup.n, setup.h
    exchange = np.zeros((n, 3))          # y_ref(k), y_meas(k), y(k)
    exchange[:, 0] = setup.y_ref
    saturated = np.zeros(n, dtype=np.dtype(fmi2Boolean))
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

    k, stage, inst, status = 0, "fmi2GetReal", plant, 0
    for k0 in range(0, n, block):
        t_block = time.thread_time_ns()
        for k in range(k0, min(k0 + block, n)):
            ex = ex0 + k * ex_bytes
            out = rows_v + k * row_bytes
            status = p_get(pc, vr_p_out, 2, ex + 8)                    # y_meas(k), y(k)
            if status > 1:
                inst, stage = plant, "fmi2GetReal"
                break
            if jacobi:
                # textbook Jacobi: every output first, then every input
                status = c_get(cc, vr_c_out, n_c, out)
                if status > 1:
                    inst, stage = ctrl, "fmi2GetReal"
                    break
                status = c_get_bool(cc, vr_c_sat, 1, sat0 + k * sat_bytes)
                if status > 1:
                    inst, stage = ctrl, "fmi2GetBoolean"
                    break
                status = p_set(pc, vr_p_in, 1, out)                     # v
                if status > 1:
                    inst, stage = plant, "fmi2SetReal"
                    break
                status = c_set(cc, vr_c_in, 2, ex)                      # y_ref(k), y_meas(k)
                if status > 1:
                    inst, stage = ctrl, "fmi2SetReal"
                    break
            else:
                # Gauss-Seidel in ModelStructure order: plant -> controller -> plant
                status = c_set(cc, vr_c_in, 2, ex)
                if status > 1:
                    inst, stage = ctrl, "fmi2SetReal"
                    break
                status = c_get(cc, vr_c_out, n_c, out)
                if status > 1:
                    inst, stage = ctrl, "fmi2GetReal"
                    break
                status = c_get_bool(cc, vr_c_sat, 1, sat0 + k * sat_bytes)
                if status > 1:
                    inst, stage = ctrl, "fmi2GetBoolean"
                    break
                status = p_set(pc, vr_p_in, 1, out)
                if status > 1:
                    inst, stage = plant, "fmi2SetReal"
                    break
            t = times[k]
            if controller_first:
                status = c_step(cc, t, h, 1)
                if status > 1:
                    inst, stage = ctrl, "fmi2DoStep"
                    break
                status = p_step(pc, t, h, 1)
                if status > 1:
                    inst, stage = plant, "fmi2DoStep"
                    break
            else:
                status = p_step(pc, t, h, 1)
                if status > 1:
                    inst, stage = plant, "fmi2DoStep"
                    break
                status = c_step(cc, t, h, 1)
                if status > 1:
                    inst, stage = ctrl, "fmi2DoStep"
                    break
        if status > 1:
            break
        if block_ns is not None and k0 + block <= n:
            block_ns.append(time.thread_time_ns() - t_block)
        if progress is not None:
            progress(min(k0 + block, n), n)
    del keep
    rows[:, 2] = exchange[:, 2]
    rows[:, 3] = exchange[:, 1]
    rows[:, -1] = saturated != 0
    if status > 1:
        raise _step_error(inst, stage, k, h, FMUError(f"{stage} returned status {status}"))


def simulate_open_loop(plant_params, v_signal, *, step_size=0.0005, fmu_dir=None, progress=None):
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
    from fmpy.fmi2 import fmi2Real

    v, time = open_loop_grid(v_signal, step_size)
    params = dict(plant_params or {})
    params.setdefault("h", float(step_size))
    info = _load(fmu_path(PLANT_MODEL, fmu_dir))
    n, h = v.size, float(step_size)
    rows = np.zeros((n, len(OPEN_LOOP_DTYPE.names)))
    rows[:, 0] = time
    rows[:, 1] = v
    plant = None
    try:
        plant = _Instance(info, "plant")
        plant.initialize(params, n * h)
        f, comp = plant.fmu, plant.fmu.component
        get, set_, step = f.fmi2GetReal, f.fmi2SetReal, f.fmi2DoStep
        vr_out = _vr_array([info.vr(nm) for nm in _PLANT_OUTPUTS])
        vr_in = _vr_array([info.vr("v")])
        out = (fmi2Real * 4)()
        vin = (fmi2Real * 1)()
        np_out = np.ctypeslib.as_array(out)
        vl = v.tolist()
        times = time.tolist()
        k, stage = 0, "fmi2GetReal"
        try:
            for k in sample_range(n, h, progress):
                stage = "fmi2GetReal"
                get(comp, vr_out, 4, out)        # u(k-1), x(k), y(k), y_meas(k)
                rows[k, 3:6] = np_out[1:4]
                if k:
                    rows[k - 1, 2] = out[0]
                vin[0] = vl[k]
                stage = "fmi2SetReal"
                set_(comp, vr_in, 1, vin)
                stage = "fmi2DoStep"
                step(comp, times[k], h, 1)
            k, stage = n, "fmi2GetReal"
            get(comp, vr_out, 4, out)
            rows[n - 1, 2] = out[0]
        except Exception as exc:
            raise _step_error(plant, stage, k, h, exc) from None
    finally:
        if plant is not None:
            plant.close()
    return as_structured(rows, OPEN_LOOP_DTYPE)
