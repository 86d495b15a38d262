"""cffi (ABI mode) binding of the pure C core ``libpiezo_core.so``.

The C declarations are read from the headers in ``fmu_src/core/`` at import
time (comments, ``#include`` lines and include guards dropped, integer
``#define`` constants kept), so the binding cannot drift from the headers.
The shared library itself is loaded lazily, once per process. Both are found by
:mod:`harness.paths`: ``$PIEZO_CORE_LIB`` / ``$PIEZO_CORE_INCLUDE``, else the copies
``pip install .`` put inside the package, else ``<repo>/build/libpiezo_core.so`` and
``<repo>/fmu_src/core`` of a source checkout.

Parameters are addressed by their FMU variable names (docs/fmus.md),
e.g. ``{"creep.alpha": -0.0085, "pi.w[2]": 0.03}``; defaults come from the core
(``piezo_plant_default_params`` / ``piezo_controller_default_params``).

Main classes: :class:`Plant` and :class:`Controller`. Thin wrappers around the
individual operators (:func:`pi_model`, :func:`transfer_function`,
:func:`gl_operator`, :func:`gl_weights`, :func:`diophantine`) exist so that
tests can drive the C maths directly.
"""
from __future__ import annotations

import math
import numbers
import re
import threading
from collections import namedtuple
from pathlib import Path

import numpy as np
from cffi import FFI

from .. import paths
from .fmu_variables import PARAMETERS

__all__ = [
    "CoreParameterError", "CoreInputError", "CoreDivergedError", "CoreUnstableError",
    "CoreFaultError", "Plant",
    "Controller",
    "PlantOutput", "ControllerOutput", "PIModel", "PIInverse",
    "TransferFunction", "GLOperator", "pi_model", "transfer_function",
    "gl_operator", "gl_weights", "diophantine", "default_plant_params",
    "default_controller_params", "PLANT_PARAMETER_NAMES",
    "CONTROLLER_PARAMETER_NAMES", "ffi", "lib", "library_path", "plant_params_struct",
    "controller_params_struct",
]

# The headers are read at import (PIEZO_CORE_INCLUDE overrides their directory).
CORE_DIR = paths.core_include_dir()
HEADER_ORDER = ("piezo_status.h", "piezo_hysteresis.h", "piezo_tf.h",
                "piezo_creep.h", "piezo_plant.h", "piezo_supervisor.h", "piezo_controller.h",
                "piezo_reference.h")

PIEZO_OK = 0
PIEZO_ERR_NULL = 1
PIEZO_ERR_PARAM = 2
PIEZO_ERR_NONFINITE = 3
PIEZO_ERR_CAPACITY = 4
PIEZO_ERR_DIVERGED = 5
PIEZO_ERR_UNSTABLE = 6
PIEZO_ERR_FAULT = 7


# --------------------------------------------------------------------------
# cdef from the headers
# --------------------------------------------------------------------------
_INT_DEFINE = re.compile(r"#\s*define\s+([A-Za-z_]\w*)\s+(-?\d+)\s*")
_GUARD = re.compile(r"#\s*(ifndef|define)\s+([A-Za-z_]\w*_H)\s*|#\s*endif\s*")
_INCLUDE = re.compile(r"#\s*include\s*[<\"][^>\"]+[>\"]\s*")


def header_cdef(core_dir: Path = CORE_DIR, names=HEADER_ORDER) -> str:
    """Return the cffi ``cdef`` source built from the core headers.

    Parameters
    ----------
    core_dir : Path
        Directory holding the headers.
    names : sequence of str
        The headers, in dependency order (default ``HEADER_ORDER``).

    Returns
    -------
    str
        The concatenated declarations, comment- and preprocessor-free except
        for integer ``#define`` constants.

    Raises
    ------
    RuntimeError
        If a header contains a preprocessor line other than an include, an
        include guard or an integer ``#define`` (cffi could not use it).
    """
    chunks = []
    for name in names:
        text = (core_dir / name).read_text()
        text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
        text = re.sub(r"//[^\n]*", "", text)
        lines = []
        for line in text.splitlines():
            s = line.strip()
            if not s.startswith("#"):
                lines.append(line)
                continue
            if _INCLUDE.fullmatch(s) or _GUARD.fullmatch(s):
                continue
            m = _INT_DEFINE.fullmatch(s)
            if m:
                lines.append(f"#define {m.group(1)} {m.group(2)}")
                continue
            raise RuntimeError(f"{name}: preprocessor line not supported by the binding: {s!r}")
        chunks.append(f"/* {name} */\n" + "\n".join(lines))
    return "\n".join(chunks)


ffi = FFI()
ffi.cdef(header_cdef())

_LIB = None
_LIB_LOCK = threading.Lock()


def library_path() -> Path:
    """Path of the shared library: ``$PIEZO_CORE_LIB``, the installed copy, or
    ``<repo>/build/libpiezo_core.so`` (see :mod:`harness.paths`)."""
    return paths.core_library()


def lib():
    """Return the loaded core library (loaded on first use, once per process).

    Raises
    ------
    FileNotFoundError
        If the library does not exist; the message gives the build command.
    """
    global _LIB
    if _LIB is None:
        with _LIB_LOCK:
            if _LIB is None:
                path = library_path()
                if not path.is_file():
                    raise FileNotFoundError(
                        f"piezo core library not found: {path}; {paths.where_to_get_it()} "
                        f"(or set PIEZO_CORE_LIB to the library path)")
                _LIB = ffi.dlopen(str(path))
    return _LIB


# --------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------
def _fmt(value: float) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.15g}"


class CoreParameterError(ValueError):
    """A parameter was refused by the core.

    Attributes
    ----------
    parameter : str
        FMU variable name of the offending parameter (from ``piezo_diag``).
    valid_range : str
        The valid range as reported by the core, e.g. ``"[-1, 1]"``.
    value : float
        The offending value.
    """

    def __init__(self, parameter: str, valid_range: str, value: float):
        self.parameter = parameter
        self.valid_range = valid_range
        self.value = value
        super().__init__(f"{parameter} = {_fmt(value)} is out of range: valid range {valid_range}")


class CoreInputError(ValueError):
    """A non-finite input was refused by the core; its state is unchanged."""


class CoreDivergedError(FloatingPointError):
    """The inputs were finite but a computed value was not (overflow: the model or the
    loop diverged); the step was refused and the state is unchanged."""


class CoreUnstableError(CoreDivergedError):
    """The controller's monitor found the loop unstable: ``|pred_error|`` stayed above
    ``monitor.pred_error_max`` for ``monitor.divergence_samples`` consecutive samples, or in a
    quarter of a window that long; the step was refused and the state is unchanged."""


class CoreFaultError(CoreDivergedError):
    """The controller's supervision found a loop that cannot work (a measurement that does
    not answer v, answers inverted or far off the model, ...); the step was refused and the
    loop's state is unchanged. The message is the supervision's (the FMU's own words).

    Attributes
    ----------
    fault : str
        The verdict's short name (``piezo_supervisor_fault_name``), e.g. ``"no response"``.
    """

    def __init__(self, message: str, fault: str):
        super().__init__(message)
        self.fault = fault


def _str(p) -> str:
    return "<unknown>" if p == ffi.NULL else ffi.string(p).decode()


def _raise_init(status: int, what: str, diag) -> None:
    if status == PIEZO_OK:
        return
    if status == PIEZO_ERR_PARAM:
        raise CoreParameterError(_str(diag.parameter), _str(diag.valid_range), float(diag.value))
    raise RuntimeError(f"{what} failed with piezo_status {status}")


def _raise_step(status: int, what: str, inputs: dict) -> None:
    if status == PIEZO_OK:
        return
    if status == PIEZO_ERR_NONFINITE:
        desc = ", ".join(f"{k} = {v!r}" for k, v in inputs.items())
        raise CoreInputError(f"{what}: non-finite input refused ({desc}); state unchanged")
    if status == PIEZO_ERR_DIVERGED:
        desc = ", ".join(f"{k} = {v!r}" for k, v in inputs.items())
        raise CoreDivergedError(f"{what}: diverged: a computed value is not finite although the "
                                f"inputs are ({desc}); step refused, state unchanged")
    if status == PIEZO_ERR_PARAM:
        desc = ", ".join(f"{k} = {v!r}" for k, v in inputs.items())
        raise ValueError(f"{what}: an input is out of its range ({desc}); state unchanged")
    # the controller's refusals (PIEZO_ERR_UNSTABLE, _FAULT) are raised before, with its own words
    # (Controller._raise_fault)
    raise RuntimeError(f"{what} failed with piezo_status {status}")


# --------------------------------------------------------------------------
# parameter tables (FMU name -> struct field path, kind), generated from the FMUs'
# declarations (fmu_src/<Model>/variables.toml) into fmu_variables.py
# --------------------------------------------------------------------------
_PLANT_TABLE = PARAMETERS["PiezoStage"]
_CONTROLLER_TABLE = PARAMETERS["AdaptiveCompoundController"]

PLANT_PARAMETER_NAMES = tuple(_PLANT_TABLE)
CONTROLLER_PARAMETER_NAMES = tuple(_CONTROLLER_TABLE)


def _coerce(name: str, kind: str, value):
    if kind == "float":
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise TypeError(f"{name} must be a real number, got {value!r}")
        return float(value)
    if kind == "bool":
        if isinstance(value, (bool, np.bool_)) or (isinstance(value, numbers.Integral) and value in (0, 1)):
            return 1 if value else 0
        raise TypeError(f"{name} must be a Boolean, got {value!r}")
    # int
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer():
        return int(value)
    raise TypeError(f"{name} must be an integer, got {value!r}")


def _get_path(obj, path):
    for p in path:
        obj = obj[p] if isinstance(p, int) else getattr(obj, p)
    return obj


def _set_path(obj, path, value):
    for p in path[:-1]:
        obj = obj[p] if isinstance(p, int) else getattr(obj, p)
    last = path[-1]
    if isinstance(last, int):
        obj[last] = value
    else:
        setattr(obj, last, value)


def _apply(table: dict, struct, params: dict | None, kind_name: str) -> None:
    for name, value in (params or {}).items():
        if name not in table:
            raise KeyError(f"unknown {kind_name} parameter {name!r}; valid names: {', '.join(table)}")
        path, kind = table[name]
        _set_path(struct, path, _coerce(name, kind, value))


def _to_dict(table: dict, struct) -> dict:
    out = {}
    for name, (path, kind) in table.items():
        v = _get_path(struct, path)
        out[name] = bool(v) if kind == "bool" else (int(v) if kind == "int" else float(v))
    return out


def plant_params_struct(params: dict | None):
    """A ``piezo_plant_params`` (cffi, owned by Python): the core's defaults with ``params``
    (FMU variable names) applied."""
    p = ffi.new("piezo_plant_params *")
    lib().piezo_plant_default_params(p)
    _apply(_PLANT_TABLE, p, params, "plant")
    return p


def controller_params_struct(params: dict | None):
    """A ``piezo_controller_params`` (cffi, owned by Python): the core's defaults with
    ``params`` (FMU variable names) applied."""
    p = ffi.new("piezo_controller_params *")
    lib().piezo_controller_default_params(p)
    _apply(_CONTROLLER_TABLE, p, params, "controller")
    return p


def default_plant_params() -> dict:
    """Return the core's plant defaults as a dict keyed by FMU variable name."""
    return _to_dict(_PLANT_TABLE, plant_params_struct(None))


def default_controller_params() -> dict:
    """Return the core's controller defaults as a dict keyed by FMU variable name."""
    return _to_dict(_CONTROLLER_TABLE, controller_params_struct(None))


# --------------------------------------------------------------------------
# exact-mode history buffer
# --------------------------------------------------------------------------
# Doubles of exact-mode history per sample (piezo_creep.h: x(j) and w_j). Only used to
# pre-size a buffer for a whole run; correctness relies on *_history_needed alone.
_HISTORY_PER_SAMPLE = 2


class _History:
    """Growing float64 buffer handed to the exact-mode G-L steps.

    Grown by doubling (at least to the requested size) before a step whose
    ``*_history_needed`` exceeds the capacity; the old contents are copied.
    """

    __slots__ = ("array", "ptr")

    def __init__(self):
        self.array = np.zeros(0)
        self.ptr = ffi.NULL

    @property
    def capacity(self) -> int:
        return self.array.shape[0]

    def ensure(self, needed: int) -> None:
        cap = self.array.shape[0]
        if needed <= cap:
            return
        new = np.zeros(max(int(needed), 2 * cap, 1024))
        new[:cap] = self.array          # keep x(0..k-1): the exact sum reads them
        self.array = new
        self.ptr = ffi.from_buffer("double[]", new)


# --------------------------------------------------------------------------
# what the blocks share
# --------------------------------------------------------------------------
class _Block:
    """A core block (``piezo_<name>``): its struct initialized from a parameter struct, the
    parameters by FMU name, the sample index, reset, and the exact-mode history it owns."""

    _NAME = ""          # the core's name of the block: piezo_<name>, piezo_<name>_init ...
    _TABLE = {}         # its parameter table (FMU name -> field path, kind)

    def __init__(self, params_struct):
        self._lib = lib()
        self._params = params_struct
        self._raw = ffi.new(f"piezo_{self._NAME} *")
        diag = ffi.new("piezo_diag *")
        init = f"piezo_{self._NAME}_init"
        _raise_init(getattr(self._lib, init)(self._raw, self._params, diag), init, diag)
        self._hist = _History()

    @property
    def params(self) -> dict:
        """The parameter set in use, keyed by FMU variable name."""
        return _to_dict(self._TABLE, self._params)

    @property
    def raw(self):
        """The underlying ``piezo_<name> *`` cdata (read-only use, for tests)."""
        return self._raw

    @property
    def k(self) -> int:
        """The core's sample index: the plant's current sample, the controller's next one."""
        return int(self._raw.k)

    def reset(self) -> None:
        """Return to k = 0 (the plant at rest with its noise reseeded; the controller with its
        nominal model and initial covariance)."""
        getattr(self._lib, f"piezo_{self._NAME}_reset")(self._raw)


# --------------------------------------------------------------------------
# Plant
# --------------------------------------------------------------------------
PlantOutput = namedtuple("PlantOutput", "u x y y_meas")
PlantOutput.__doc__ = """Plant outputs at one sample: u (PI output of the last applied voltage),
x (Hammerstein output), y (true displacement), y_meas (sensor reading), all in um."""

PLANT_DTYPE = np.dtype([("time", "f8"), ("v", "f8"), ("u", "f8"), ("x", "f8"),
                        ("y", "f8"), ("y_meas", "f8")])


class Plant(_Block):
    """The coupled piezo stage model ``v -PI-> u -G-> x -creep-> y`` plus the sensor.

    Parameters
    ----------
    params : dict or None
        Overrides of the core defaults, keyed by FMU variable name
        (see ``PLANT_PARAMETER_NAMES``).

    Raises
    ------
    KeyError
        Unknown parameter name.
    CoreParameterError
        A parameter is out of range (the core's ``piezo_diag``).

    Notes
    -----
    At sample k the outputs u(k-1), x(k), y(k), y_meas(k) are known before
    v(k) is applied (no feedthrough). In exact creep mode the binding owns a
    growing history buffer of the creep input.
    """

    _NAME = "plant"
    _TABLE = _PLANT_TABLE

    def __init__(self, params: dict | None = None):
        super().__init__(plant_params_struct(params))
        self._p = self._raw
        self._h = float(self._params.h)

    @property
    def h(self) -> float:
        """Sample period [s]."""
        return self._h

    @property
    def output(self) -> PlantOutput:
        """Outputs at the current sample k."""
        o = self._p.out
        return PlantOutput(o.u, o.x, o.y, o.y_meas)

    def step(self, v: float) -> PlantOutput:
        """Apply v(k) [V] and advance to k+1.

        Parameters
        ----------
        v : float
            Voltage of the current sample.

        Returns
        -------
        PlantOutput
            The outputs at the new sample k+1.

        Raises
        ------
        CoreInputError
            If v is NaN or infinite (the state is left unchanged).
        """
        v = float(v)
        self._hist.ensure(self._lib.piezo_plant_history_needed(self._p))
        st = self._lib.piezo_plant_step(self._p, v, self._hist.ptr, self._hist.capacity, ffi.NULL)
        _raise_step(st, "piezo_plant_step", {"v": v})
        return self.output

    def simulate(self, v) -> np.ndarray:
        """Apply a voltage sequence from the current state.

        Parameters
        ----------
        v : array_like, shape (N,)
            Voltages v[0..N-1] applied at samples k0..k0+N-1 (k0 = ``self.k``).

        Returns
        -------
        numpy.ndarray
            Structured array of N rows with fields ``time, v, u, x, y, y_meas``;
            row i holds the outputs at sample k0+i (before v[i] is applied),
            v[i], and time = (k0+i) h.

        Raises
        ------
        CoreInputError
            At the first non-finite v (the plant stays at that sample).
        """
        v = np.ascontiguousarray(v, dtype=float).ravel()
        n = v.shape[0]
        k0 = self.k
        res = np.zeros(n, dtype=PLANT_DTYPE)
        res["time"] = np.arange(k0, k0 + n, dtype=float) * self._h
        res["v"] = v
        hist = self._hist
        needed = self._lib.piezo_plant_history_needed
        if needed(self._p):
            hist.ensure(needed(self._p) + _HISTORY_PER_SAMPLE * n)   # one allocation for the run
        ptr, cap = hist.ptr, hist.capacity
        step, p, o, null = self._lib.piezo_plant_step, self._p, self._p.out, ffi.NULL
        u = res["u"]; x = res["x"]; y = res["y"]; ym = res["y_meas"]
        vl = v.tolist()
        for i in range(n):
            u[i] = o.u; x[i] = o.x; y[i] = o.y; ym[i] = o.y_meas
            st = step(p, vl[i], ptr, cap, null)
            if st == PIEZO_ERR_CAPACITY:         # refused, state unchanged: grow and retry
                hist.ensure(needed(p))
                ptr, cap = hist.ptr, hist.capacity
                st = step(p, vl[i], ptr, cap, null)
            if st:
                _raise_step(st, f"piezo_plant_step (row {i})", {"v": vl[i]})
        return res


# --------------------------------------------------------------------------
# Controller
# --------------------------------------------------------------------------
ControllerOutput = namedtuple("ControllerOutput",
                              "v q a1 a2 b1 b2 pred_error saturated delay preview adapting noise fallback")
ControllerOutput.__doc__ = """Controller result of one sample: v [V], q [um], the estimates
a1, a2, b1, b2 used for q, the RLS one-step prediction error [um], saturated (bool), the loop
delay d of the law (int, 0 while it is being detected), preview (bool: the law used a stamped
preview rather than y_ref), adapting (bool: the estimates were updated; the FMUs' est.adapting)
the measured noise of y_meas [um] (est.noise) and why the law fell back to the nominal model at
this sample (0 none, 1 a jump of the reference, 2 a prediction over the window, 3 one prediction
beyond the monitor's bound: a loop that rings; the FMUs count them in est.fallbacks)."""


def _ctrl_out(o) -> ControllerOutput:
    t = o.theta
    return ControllerOutput(o.v, o.q, t[0], t[1], t[2], t[3], o.pred_error, bool(o.saturated),
                            int(o.delay), bool(o.preview), bool(o.adapting), o.noise,
                            int(o.fallback))


class Controller(_Block):
    """Adaptive compound controller (RLS + MV law + inverse creep + inverse PI).

    Parameters
    ----------
    params : dict or None
        Overrides of the core defaults, keyed by FMU variable name
        (see ``CONTROLLER_PARAMETER_NAMES``).

    Raises
    ------
    KeyError
        Unknown parameter name.
    CoreParameterError
        A parameter is out of range.
    """

    _NAME = "controller"
    _TABLE = _CONTROLLER_TABLE

    def __init__(self, params: dict | None = None):
        super().__init__(controller_params_struct(params))
        self._c = self._raw
        self._out = ffi.new("piezo_controller_output *")
        self._in = ffi.new("piezo_controller_input *")

    @property
    def output(self) -> ControllerOutput:
        """The last committed sample (zeros and the nominal estimates before the first)."""
        return _ctrl_out(self._c.out)

    def _call(self, fn, name, y_ref, y_meas) -> ControllerOutput:
        y_ref = float(y_ref)
        y_meas = float(y_meas)
        self._hist.ensure(self._lib.piezo_controller_history_needed(self._c))
        st = fn(self._c, y_ref, y_meas, self._hist.ptr, self._hist.capacity, self._out)
        self._raise_fault(st, name)
        _raise_step(st, name, {"y_ref": y_ref, "y_meas": y_meas})
        return _ctrl_out(self._out)

    def explain(self, status: int) -> str:
        """Why the controller refused a sample with ``status``, in its own words
        (``piezo_controller_explain``, the FMU's message): the supervision's verdict and
        evidence, the monitor's counts, or the divergence; "" for another status."""
        size = 2048
        buf = ffi.new("char[]", size)
        self._lib.piezo_controller_explain(self._c, int(status), buf, size)
        return ffi.string(buf).decode()

    @property
    def fault(self) -> int:
        """The fault code the loop is held in its safe state for (``sup.reaction`` = 1), 0 while
        it runs (docs/robustness.md, the fault codes)."""
        return int(self._c.fault)

    @property
    def fault_sample(self) -> int | None:
        """The sample whose verdict put the loop in its safe state (None while it runs)."""
        return int(self._c.k_fault) if self._c.fault else None

    def safe_state_message(self, t0: float = 0.0) -> str:
        """The safe state's Warning, as the FMUs log it (``piezo_controller_explain_safe_state``),
        times counted from ``t0``; "" while the loop runs."""
        size = 2048
        buf = ffi.new("char[]", size)
        ctx = ffi.new("piezo_sup_context *")
        ctx.t0, ctx.h = float(t0), float(self._c.sup.h)
        self._lib.piezo_controller_explain_safe_state(self._c, ctx, buf, size)
        return ffi.string(buf).decode()

    def fault_reset(self, y_ref: float, y_meas: float, t0: float = 0.0) -> tuple[bool, str]:
        """Raise ``sup.reset`` before the current sample, as the FMUs do on its rising edge.

        In the safe state, and once the cause the safe state can see is gone
        (``piezo_controller_reset_refusal``), the loop restarts from its nominal model at the
        current sample, from the stage at rest at ``y_meas``, with v ramping from 0 V
        (``piezo_controller_restart``); else nothing changes.

        Parameters
        ----------
        y_ref, y_meas : float
            The inputs of the sample the loop would restart at [um].
        t0 : float
            The time of sample 0, for the message's times [s].

        Returns
        -------
        (bool, str)
            Whether the loop restarted, and the message the FMUs log (an event when accepted,
            a Warning when refused).
        """
        inp = ffi.new("piezo_controller_input *")
        inp.y_ref, inp.y_meas = float(y_ref), float(y_meas)
        refusal = int(self._lib.piezo_controller_reset_refusal(self._c, inp))
        k = int(self._c.k)
        if refusal == 0:
            self._lib.piezo_controller_restart(self._c, inp.y_meas)
        ctx = ffi.new("piezo_sup_context *")
        ctx.t0, ctx.h = float(t0), float(self._c.sup.h)
        buf = ffi.new("char[]", 2048)
        self._lib.piezo_controller_explain_reset(self._c, refusal, inp, k, ctx, buf, 2048)
        return refusal == 0, ffi.string(buf).decode()

    def _raise_fault(self, status, name):
        """Raise the loop's refusals (supervision, monitor, divergence) with the core's words."""
        if status == PIEZO_ERR_FAULT:
            fault = _str(self._lib.piezo_supervisor_fault_name(self._c.verdict.fault))
            raise CoreFaultError(f"{name}: {self.explain(status)}", fault)
        if status == PIEZO_ERR_UNSTABLE:
            raise CoreUnstableError(f"{name}: {self.explain(status)}; step refused, state unchanged")
        if status == PIEZO_ERR_DIVERGED:
            raise CoreDivergedError(f"{name}: {self.explain(status)}; step refused, state unchanged")

    def peek(self, y_ref: float, y_meas: float) -> ControllerOutput:
        """Control of the current sample without committing anything.

        Parameters
        ----------
        y_ref : float
            Reference d samples ahead, y_d(k+d) [um].
        y_meas : float
            Measured displacement y_meas(k) [um].

        Returns
        -------
        ControllerOutput
        """
        return self._call(self._lib.piezo_controller_peek, "piezo_controller_peek", y_ref, y_meas)

    def step(self, y_ref: float, y_meas: float) -> ControllerOutput:
        """Compute and commit the control of the current sample (k -> k+1).

        Parameters
        ----------
        y_ref : float
            Reference d samples ahead, y_d(k+d) [um].
        y_meas : float
            Measured displacement y_meas(k) [um].

        Returns
        -------
        ControllerOutput

        Raises
        ------
        CoreInputError
            If an input is NaN or infinite (the state is left unchanged).
        CoreUnstableError
            The monitor found the loop unstable (nothing committed).
        CoreFaultError
            The supervision found a loop that cannot work (nothing of the loop committed).
        """
        return self._call(self._lib.piezo_controller_step, "piezo_controller_step", y_ref, y_meas)

    def step_input(self, y_ref: float, y_meas: float, y_preview: float = 0.0,
                   preview_lead: int = 0) -> ControllerOutput:
        """:meth:`step` with a stamped preview (``piezo_controller_step_input``).

        Parameters
        ----------
        y_ref, y_meas : float
            As :meth:`step`; ``y_ref`` is used when no stamped preview covers ``k + d``.
        y_preview : float
            ``y_d`` at the measurement's sample plus ``preview_lead`` [um].
        preview_lead : int
            1 .. ``PIEZO_PREVIEW_RING - 1``; 0: no stamped preview this sample.

        Returns
        -------
        ControllerOutput
        """
        inp = self._in
        inp.y_ref, inp.y_meas = float(y_ref), float(y_meas)
        inp.y_preview, inp.preview_lead = float(y_preview), int(preview_lead)
        self._hist.ensure(self._lib.piezo_controller_history_needed(self._c))
        st = self._lib.piezo_controller_step_input(self._c, inp, self._hist.ptr, self._hist.capacity,
                                                   self._out)
        self._raise_fault(st, "piezo_controller_step_input")
        _raise_step(st, "piezo_controller_step_input",
                    {"y_ref": inp.y_ref, "y_meas": inp.y_meas, "y_preview": inp.y_preview,
                     "preview_lead": inp.preview_lead})
        return _ctrl_out(self._out)


# --------------------------------------------------------------------------
# thin operator wrappers (for tests)
# --------------------------------------------------------------------------
class PIInverse:
    """Inverse PI model (``piezo_pi_inverse``); ``raw`` exposes the struct."""

    def __init__(self, raw):
        self.raw = raw

    def step(self, u: float) -> float:
        """Return v = P^-1[u](k) and advance."""
        v = ffi.new("double *")
        _raise_step(lib().piezo_pi_inverse_step(self.raw, float(u), v), "piezo_pi_inverse_step", {"u": u})
        return v[0]


class PIModel:
    """Forward PI model (``piezo_pi``); ``raw`` exposes the struct.

    Parameters
    ----------
    params : dict or None
        ``pi.*`` overrides of the core's plant defaults.
    """

    def __init__(self, params: dict | None = None):
        p = ffi.new("piezo_plant_params *")
        lib().piezo_plant_default_params(p)
        _apply({k: v for k, v in _PLANT_TABLE.items() if k.startswith("pi.")}, p, params, "PI")
        self.raw = ffi.new("piezo_pi *")
        diag = ffi.new("piezo_diag *")
        _raise_init(lib().piezo_pi_init(self.raw, ffi.addressof(p, "pi"), diag), "piezo_pi_init", diag)

    @property
    def z(self) -> np.ndarray:
        """Copy of the play states z_1..z_m."""
        return np.array([self.raw.z[i] for i in range(self.raw.m)])

    def reset(self) -> None:
        """Zero the play states."""
        lib().piezo_pi_reset(self.raw)

    def step(self, v: float) -> float:
        """Return u = P[v](k) and advance."""
        u = ffi.new("double *")
        _raise_step(lib().piezo_pi_step(self.raw, float(v), u), "piezo_pi_step", {"v": v})
        return u[0]

    def inverse(self) -> PIInverse:
        """Inverse model with initial states consistent with the current play states (eq 28)."""
        inv = ffi.new("piezo_pi_inverse *")
        st = lib().piezo_pi_inverse_init(inv, self.raw)
        if st != PIEZO_OK:
            raise RuntimeError(f"piezo_pi_inverse_init failed with piezo_status {st}")
        return PIInverse(inv)


def pi_model(params: dict | None = None) -> PIModel:
    """Forward PI model from ``pi.*`` parameters (core defaults otherwise)."""
    return PIModel(params)


class TransferFunction:
    """G(z) with extra delay (``piezo_tf``): ``step(u(k))`` returns x(k+1)."""

    def __init__(self, params: dict | None = None):
        p = ffi.new("piezo_plant_params *")
        lib().piezo_plant_default_params(p)
        table = {k: v for k, v in _PLANT_TABLE.items() if k.startswith("tf.")}
        _apply(table, p, params, "transfer-function")
        self.raw = ffi.new("piezo_tf *")
        diag = ffi.new("piezo_diag *")
        _raise_init(lib().piezo_tf_init(self.raw, ffi.addressof(p, "tf"), diag), "piezo_tf_init", diag)

    def reset(self) -> None:
        lib().piezo_tf_reset(self.raw)

    def step(self, u: float) -> float:
        """Consume u(k), return x(k+1)."""
        x = ffi.new("double *")
        _raise_step(lib().piezo_tf_step(self.raw, float(u), x), "piezo_tf_step", {"u": u})
        return x[0]


def transfer_function(params: dict | None = None) -> TransferFunction:
    """G(z) from ``tf.*`` parameters (core defaults otherwise)."""
    return TransferFunction(params)


class GLOperator:
    """Grunwald-Letnikov operator (``piezo_gl``): ``step(x(k))`` returns y(k)."""

    def __init__(self, alpha: float, gain: float = 1.0, exact: bool = False):
        self.raw = ffi.new("piezo_gl *")
        diag = ffi.new("piezo_diag *")
        _raise_init(lib().piezo_gl_init(self.raw, float(alpha), float(gain), 1 if exact else 0, diag),
                    "piezo_gl_init", diag)
        self._hist = _History()
        self._y = ffi.new("double *")

    @property
    def k(self) -> int:
        return int(self.raw.k)

    def reset(self) -> None:
        lib().piezo_gl_reset(self.raw)

    def step(self, x: float) -> float:
        """Consume x(k), return y(k)."""
        L = lib()
        self._hist.ensure(L.piezo_gl_history_needed(self.raw))
        st = L.piezo_gl_step(self.raw, float(x), self._hist.ptr, self._hist.capacity, self._y)
        _raise_step(st, "piezo_gl_step", {"x": x})
        return self._y[0]

    def run(self, x) -> np.ndarray:
        """Apply a whole sequence (a loop over :meth:`step`, for speed)."""
        xl = np.asarray(x, dtype=float).ravel().tolist()
        L = lib()
        hist, needed = self._hist, L.piezo_gl_history_needed
        if needed(self.raw):
            hist.ensure(needed(self.raw) + _HISTORY_PER_SAMPLE * len(xl))
        stepf, raw, ptr, cap, y = L.piezo_gl_step, self.raw, hist.ptr, hist.capacity, self._y
        out = np.empty(len(xl))
        for i, xi in enumerate(xl):
            st = stepf(raw, xi, ptr, cap, y)
            if st == PIEZO_ERR_CAPACITY:         # refused, state unchanged: grow and retry
                hist.ensure(needed(raw))
                ptr, cap = hist.ptr, hist.capacity
                st = stepf(raw, xi, ptr, cap, y)
            if st:
                _raise_step(st, "piezo_gl_step", {"x": xi})
            out[i] = y[0]
        return out


def gl_operator(alpha: float, gain: float = 1.0, exact: bool = False) -> GLOperator:
    """G-L operator of order alpha with output gain; exact (full memory) or SOE."""
    return GLOperator(alpha, gain, exact)


def gl_weights(alpha: float, n: int) -> np.ndarray:
    """The first n G-L weights w_0..w_{n-1} from the core's recursion (eq 14)."""
    w = np.zeros(int(n))
    if n > 0:
        lib().piezo_gl_weights(float(alpha), ffi.from_buffer("double[]", w), int(n))
    return w


def diophantine(a1: float, a2: float, d: int):
    """Solve 1 = A E + z^-d Gd with A = 1 + a1 z^-1 + a2 z^-2.

    Returns
    -------
    (e, g) : tuple of ndarray
        e[0..d-1] and g[0..1].
    """
    e = np.zeros(max(int(d), 0) + 16)   # slack: a bad d must not write out of bounds
    g = np.zeros(2)
    st = lib().piezo_diophantine(float(a1), float(a2), int(d),
                                 ffi.from_buffer("double[]", e), ffi.from_buffer("double[]", g))
    if st != PIEZO_OK:
        raise ValueError(f"piezo_diophantine(a1={a1}, a2={a2}, d={d}) failed with piezo_status {st}")
    return e[:int(d)], g
