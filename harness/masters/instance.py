"""One FMU instance through fmpy, and its C functions called directly: what the fmpy-based
masters share (:mod:`harness.masters.fmpy`, :mod:`harness.masters.wired`,
:mod:`harness.masters.closed_loop_fmu`) and what :mod:`harness.identify.export` initialises a
closed-loop FMU with.

:class:`Instance` wraps an fmpy FMU2Slave or FMU3Slave (by the FMU's version) with its log and
its life cycle (always terminated and freed); :class:`ScalarFunctions` gives a hot loop the
instance's bare C functions for scalar values, called the FMI 2.0 way in either edition;
:func:`raw_function` one of them; :func:`vr_array` a ctypes array of value references;
:func:`step_error` the exception of a failed call in a run (:func:`harness.fmu.loop_error_class`
of what the FMU logged). :data:`CTRL_OUTPUTS` are the controller's Real outputs the masters read
at every sample, in the order of the record's fields from ``v``.
"""

from __future__ import annotations

import ctypes

from fmpy import calloc, fmi2, free
from fmpy.fmi1 import printLogMessage
from fmpy.fmi2 import FMU2Slave, fmi2ValueReference
from fmpy.fmi3 import FMU3Slave

from ..fmu import REAL_TYPES, FMUInitializationError, array_size, loop_error_class, sort_parameters

__all__ = ["CTRL_OUTPUTS", "Instance", "ScalarFunctions", "raw_function", "vr_array", "step_error"]

#: the controller's Real outputs every master reads at every sample (v, then its companions)
CTRL_OUTPUTS = ("v", "q", "est.a1", "est.a2", "est.b1", "est.b2", "pred_error")

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
        printLogMessage(component, instance_name, status, category, message)


def _callbacks():
    """A fresh callback structure whose (formatted) log messages reach :func:`_log_message`.

    fmpy's native proxy formats the variadic message and forwards it to one
    process-wide logger, the one of the structure it was last installed on;
    installing it on a fresh structure per instance makes sure our instances
    log to us even if other code in the process installed its own logger.
    """
    global _LOGGER
    if _LOGGER is None:
        _LOGGER = fmi2.fmi2CallbackLoggerTYPE(_log_message)
    cb = fmi2.fmi2CallbackFunctions()
    cb.logger = _LOGGER
    cb.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(free)
    try:
        from fmpy.logging import addLoggerProxy     # optional: not in every fmpy version
        addLoggerProxy(ctypes.byref(cb))
    except Exception:  # pragma: no cover - the raw format string is logged then
        pass
    return cb


# ---------------------------------------------------------------------------
# one FMU instance
# ---------------------------------------------------------------------------


def _fmi3_logger(sink):
    """An fmpy logMessage callback appending ``[Status] text`` to the list ``sink``."""
    labels = ("OK", "Warning", "Discard", "Error", "Fatal")

    def log_message(env, status, category, message):
        text = message.decode("utf-8", "replace") if message else ""
        label = labels[status] if 0 <= status < len(labels) else str(status)
        if len(sink) < 200:
            sink.append(f"[{label}] {text}")
    return log_message


class Instance:
    """Thin lifetime wrapper of an fmpy FMU2Slave or FMU3Slave (by the FMU's version)."""

    def __init__(self, info, role):
        _COUNTER[0] += 1
        self.info = info
        self.fmi3 = info.fmi_version == 3
        self.name = f"harness-{role}-{_COUNTER[0]}"
        self.log = _LOGS.setdefault(self.name, [])
        self.fmu = None
        self.instantiated = False
        self.initialized = False
        if self.fmi3:
            self.fmu = FMU3Slave(guid=info.md.guid, unzipDirectory=info.unzipdir,
                                 modelIdentifier=info.model, instanceName=self.name)
        else:
            self.fmu = FMU2Slave(guid=info.md.guid, unzipDirectory=info.unzipdir,
                                 modelIdentifier=info.model, instanceName=self.name)
        try:
            if self.fmi3:
                self.fmu.instantiate(loggingOn=False, logMessage=_fmi3_logger(self.log))
            else:
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
        """Set parameters by name, typed from the model description (FMI 3.0: array elements
        by their FMI 2.0 names, in initialization mode, where the array can be read)."""
        reals, ints, bools, arrays = sort_parameters(self.info, params)
        f = self.fmu
        try:
            if self.fmi3:
                for var, elements in arrays.items():
                    size = array_size(var)
                    get = f.getFloat64 if var.type in REAL_TYPES else f.getInt32
                    put = f.setFloat64 if var.type in REAL_TYPES else f.setInt32
                    values = list(get([var.valueReference], nValues=size))
                    for index, value in elements.items():
                        values[index] = value
                    put([var.valueReference], values)
                if reals[0]:
                    f.setFloat64(*reals)
                if ints[0]:
                    f.setInt32(*ints)
                if bools[0]:
                    f.setBoolean(*bools)
            else:
                if reals[0]:
                    f.setReal(*reals)
                if ints[0]:
                    f.setInteger(*ints)
                if bools[0]:
                    f.setBoolean(*bools)
        except Exception as exc:
            raise FMUInitializationError(self._message("setting parameters", exc)) from None

    def initialize(self, params, stop_time):
        if self.fmi3:
            try:
                self.fmu.enterInitializationMode(startTime=0.0, stopTime=stop_time)
            except Exception as exc:
                raise FMUInitializationError(self._message("fmi3EnterInitializationMode", exc)) from None
            self.set_parameters(params)
            try:
                self.fmu.exitInitializationMode()
            except Exception as exc:
                raise FMUInitializationError(self._message("initialization", exc)) from None
            self.initialized = True
            return
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


def vr_array(values):
    """A ctypes array of value references."""
    return (fmi2ValueReference * len(values))(*values)


def step_error(inst, what, k, h, exc):
    message = inst._message(f"{what} at t = {k * h:.6g} s (sample {k})", exc)
    return loop_error_class(inst.log)(message)

def raw_function(fmu, name, *argtypes):
    """The FMU's C function ``name`` as a bare ctypes prototype returning the status.

    fmpy's ``FMU2Slave.fmi2*`` methods wrap every call in Python (argument
    conversion, call logging, a status check that raises); the hot loop calls
    the C functions directly, passes raw addresses into its result arrays and
    checks the status itself.
    """
    address = ctypes.cast(getattr(fmu.dll, name), ctypes.c_void_p).value
    return ctypes.CFUNCTYPE(ctypes.c_int, *argtypes)(address)


class ScalarFunctions:
    """One instance's C functions for scalar values, called the FMI 2.0 way
    (``get(c, vr, n, address)``, ``step(c, t, h, flag)``, status returned) for either edition:
    for FMI 3.0 they pass ``nValues = n`` and the doStep's out-arguments. ``names`` are the FMI
    functions behind get, set, get_bool and step (for messages); ``c`` is the instance."""

    def __init__(self, inst):
        vp, sz, dbl = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_double
        fmu = inst.fmu
        self.c = fmu.component
        if not inst.fmi3:
            self.names = ("fmi2GetReal", "fmi2SetReal", "fmi2GetBoolean", "fmi2DoStep")
            self.get, self.set, self.get_bool = (raw_function(fmu, name, vp, vp, sz, vp)
                                                 for name in self.names[:3])
            self.step = raw_function(fmu, "fmi2DoStep", vp, dbl, dbl, ctypes.c_int)
            return
        self.names = ("fmi3GetFloat64", "fmi3SetFloat64", "fmi3GetBoolean", "fmi3DoStep")
        flag = ctypes.c_bool
        self._out = [flag(), flag(), flag(), dbl()]         # doStep's out-arguments, kept alive
        out = [ctypes.addressof(x) for x in self._out]

        def values(name):
            raw = raw_function(fmu, name, vp, vp, sz, vp, sz)
            return lambda c, vr, n, addr: raw(c, vr, n, addr, n)

        raw_step = raw_function(fmu, "fmi3DoStep", vp, dbl, dbl, flag, vp, vp, vp, vp)
        self.get, self.set, self.get_bool = (values(name) for name in self.names[:3])
        self.step = lambda c, t, h, no_set: raw_step(c, t, h, bool(no_set), *out)
