"""The native closed-loop master (``fmu_src/runner/``, ``build/libpiezo_runner.so``) through cffi.

A small C co-simulation master loads the binaries of both FMUs through the FMI 2.0
API and runs the loop of :func:`harness.masters.fmpy.simulate_closed_loop` at native speed:
the same schedule (Gauss-Seidel in ModelStructure order, either doStep order, or
textbook Jacobi), the same ``y_ref`` and stamped preview (computed here), the same time
stamps (the plant's ``t_meas`` to the controller), the same result, bit for bit. The FMUs
are the same files the fmpy master runs (extracted once per process by
:func:`harness.fmu.load`).

FMU errors never end the process: a failing call stops the run and comes back with
the FMU's log messages as the exceptions of the fmpy master
(:class:`harness.fmu.LoopFaultError` when the controller's supervision stopped the loop,
:class:`harness.fmu.LoopDivergedError` when its monitor did or a value diverged,
:class:`harness.fmu.FMUError` otherwise,
:class:`harness.fmu.FMUInitializationError` for refused parameters). A completed
step with ``fmi2Warning`` (the controller's first clipped voltage) goes on.

:class:`NativeLoop` holds one plant and one controller instance and reuses them for
run after run through ``fmi2Reset`` (a sweep's worker keeps one per process);
:func:`simulate_closed_loop_native` is the drop-in function (``auto`` in
:mod:`harness.masters` picks it for long runs when the runner is built).
"""

from __future__ import annotations

import os
from pathlib import Path
import threading

from cffi import FFI
from fmpy import platform, sharedLibraryExtension
import numpy as np

from ..binding.core import header_cdef
from ..fmu import (CONTROLLER_MODEL, PLANT_MODEL, FMUError, FMUInitializationError,
                   fmu_path, load, loop_error_class, typed_parameters, warn_safe_state)
from ..loop import CLOSED_LOOP_DTYPE, CLOSED_LOOP_FIELDS, as_structured, prepare_closed_loop
from ..paths import runner_include_dir, runner_library, where_to_get_it

__all__ = [
    "NativeLoop",
    "missing_runner_message",
    "native_available",
    "native_loop",
    "runner_library_path",
    "simulate_closed_loop_native",
]

PLANT, CONTROLLER = 0, 1
_HEADER_NAME = "piezo_runner.h"
_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
_CALLS = {1: "fmi2GetReal", 2: "fmi2SetReal", 3: "fmi2GetBoolean", 4: "fmi2DoStep",
          5: "fmi2SetInteger", 6: "fmi2SetBoolean", 7: "fmi2SetupExperiment",
          8: "initialization", 9: "initialization", 10: "fmi2Terminate", 11: "fmi2Reset"}
_CTRL_REALS = ("v", "q", "est.a1", "est.a2", "est.b1", "est.b2", "pred_error")

_FFI = None
_LIB = None
_LOCK = threading.Lock()


def runner_library_path():
    """Path of the runner library: ``$PIEZO_RUNNER_LIB``, the installed package's, or
    ``<repo>/build/libpiezo_runner.so`` (see :mod:`harness.paths`)."""
    return runner_library()


def native_available():
    """True when the runner library is built."""
    return runner_library_path().is_file()


def missing_runner_message():
    """What to say when the runner library is not built: where it was looked for, how to
    build it (a checkout) or reinstall it (an installed package), and the way around it."""
    return (f"native runner library not found: {runner_library_path()}; {where_to_get_it()} "
            f"(or set PIEZO_RUNNER_LIB), or use the fmpy backend")


def _binding():
    """(ffi, lib) of the runner, loaded once per process."""
    global _FFI, _LIB
    if _LIB is None:
        with _LOCK:
            if _LIB is None:
                path = runner_library_path()
                if not path.is_file():
                    raise FileNotFoundError(missing_runner_message())
                ffi = FFI()
                ffi.cdef(header_cdef(runner_include_dir(), (_HEADER_NAME,)))
                _LIB = ffi.dlopen(str(path))
                _FFI = ffi
    return _FFI, _LIB


class NativeLoop:
    """One PiezoStage and one AdaptiveCompoundController instance in the native runner.

    Parameters
    ----------
    fmu_dir : str or Path, optional
        Folder of the FMUs (default :func:`harness.fmu.default_fmu_dir`).

    Raises
    ------
    FileNotFoundError
        An FMU or the runner library is missing (the message says how to build it).
    harness.fmu.FMUInitializationError
        A binary could not be loaded or instantiated (with the FMU's messages).

    Notes
    -----
    Each :meth:`run` resets both instances (``fmi2Reset``) unless they are fresh, sets
    the parameters, initializes, runs and terminates them. Not thread-safe: use one
    loop per thread (:func:`native_loop` does).
    """

    _count = 0

    def __init__(self, fmu_dir=None):
        ffi, lib = _binding()
        self._ffi, self._lib = ffi, lib
        self.plant_info = load(fmu_path(PLANT_MODEL, fmu_dir))
        self.controller_info = load(fmu_path(CONTROLLER_MODEL, fmu_dir))
        NativeLoop._count += 1
        keep = []

        def fmu(info, role):
            library = Path(info.unzipdir, "binaries", platform, info.model + sharedLibraryExtension)
            if not library.is_file():
                raise FileNotFoundError(f"{info.path.name} has no binary for {platform}: {library}")
            f = ffi.new("piezo_runner_fmu *")
            for field, text in (("library", str(library)), ("guid", info.md.guid),
                                ("resource_uri", Path(info.unzipdir, "resources").as_uri()),
                                ("instance_name", f"native-{role}-{os.getpid():07d}-{NativeLoop._count:06d}")):
                c = ffi.new("char[]", text.encode())
                keep.append(c)
                setattr(f, field, c)
            return f

        pi, ci = self.plant_info, self.controller_info
        refs = ffi.new("piezo_runner_refs *")
        refs.plant_y, refs.plant_y_meas, refs.plant_v = pi.vr("y"), pi.vr("y_meas"), pi.vr("v")
        refs.plant_t_meas = pi.vr("t_meas")
        refs.ctrl_y_ref, refs.ctrl_y_meas = ci.vr("y_ref"), ci.vr("y_meas")
        refs.ctrl_y_preview, refs.ctrl_t_preview = ci.vr("y_preview"), ci.vr("t_preview")
        refs.ctrl_t_meas = ci.vr("t_meas")
        for i, name in enumerate(_CTRL_REALS):
            refs.ctrl_reals[i] = ci.vr(name)
        refs.ctrl_saturated = ci.vr("saturated")
        error = ffi.new("char[4096]")
        runner = lib.piezo_runner_new(fmu(pi, "plant"), fmu(ci, "controller"), refs, error, 4096)
        if runner == ffi.NULL:
            raise FMUInitializationError(f"native runner: {ffi.string(error).decode(errors='replace')}")
        self._runner = ffi.gc(runner, lib.piezo_runner_free)
        self._fresh = True
        self._result = ffi.new("piezo_runner_result *")
        #: thread CPU time [ns] of each block of the last run (when timed)
        self.last_block_ns = None

    # -- logs -------------------------------------------------------------------------
    def log(self, role=None):
        """The FMUs' messages of the last run as ``"[Status] text"`` (one role or both)."""
        lib, ffi, r = self._lib, self._ffi, self._runner
        lines = []
        for i in range(lib.piezo_runner_log_count(r)):
            if role is None or lib.piezo_runner_log_role(r, i) == role:
                st = lib.piezo_runner_log_status(r, i)
                label = _STATUS[st] if 0 <= st < len(_STATUS) else str(st)
                lines.append(f"[{label}] {ffi.string(lib.piezo_runner_log_text(r, i)).decode(errors='replace')}")
        return lines

    def instance_bytes(self, role):
        """Bytes the instance (``PLANT`` 0 or ``CONTROLLER`` 1) allocated in fmi2Instantiate."""
        return int(self._lib.piezo_runner_instance_bytes(self._runner, role))

    def _model(self, role):
        return (self.plant_info if role == PLANT else self.controller_info).model

    def _message(self, role, what, status):
        lines = self.log(role)
        errors = [line for line in lines if line.startswith("[Error]")]
        detail = "; ".join((errors or lines)[-5:]) or f"status {_STATUS[status] if 0 <= status < 6 else status}"
        return f"{self._model(role)}: {what} failed: {detail}"

    # -- one run ----------------------------------------------------------------------
    def _set(self, role, info, params):
        ffi, lib, r = self._ffi, self._lib, self._runner
        reals, ints, bools = typed_parameters(info, params)
        for (vrs, values), fn, ctype in ((reals, lib.piezo_runner_set_real, "double[]"),
                                         (ints, lib.piezo_runner_set_integer, "int[]"),
                                         (bools, lib.piezo_runner_set_boolean, "int[]")):
            if not vrs:
                continue
            if ctype == "int[]":
                values = [int(v) for v in values]            # Booleans as 0/1
            st = fn(r, role, ffi.new("int[]", vrs), ffi.new(ctype, values), len(vrs))
            if st > 1:
                raise FMUInitializationError(self._message(role, "setting parameters", st))

    def _start(self, setup):
        lib, r = self._lib, self._runner
        if not self._fresh:
            lib.piezo_runner_reset(r)
        self._fresh = False
        lib.piezo_runner_clear_log(r)
        self._set(PLANT, self.plant_info, setup.plant_params)
        self._set(CONTROLLER, self.controller_info, setup.controller_params)
        res = self._result
        if lib.piezo_runner_initialize(r, 0.0, setup.n * setup.h, res) > 1:
            raise FMUInitializationError(
                self._message(res.failed_role, _CALLS.get(res.failed_call, "initialization"), res.status))

    def _run(self, setup, rows_ptr, stride, block, first=0, count=None, last=True):
        """Samples [first, first + count) of the run (all by default); ``last``: the run ends
        with them (the safe state's warning, fmi2Terminate)."""
        ffi, lib, r, res = self._ffi, self._lib, self._runner, self._result
        n, h = setup.n - first if count is None else count, setup.h
        y_ref = np.ascontiguousarray(setup.y_ref[first:first + n], dtype=np.float64)
        stamped = setup.y_preview is not None
        y_preview = np.ascontiguousarray(setup.y_preview[first:first + n] if stamped else [], dtype=np.float64)
        t_preview = np.ascontiguousarray(setup.t_preview[first:first + n] if stamped else [], dtype=np.float64)
        master = 1 if setup.master == "jacobi" else 0
        order = 1 if setup.step_order == "controller-first" else 0
        block_ns = np.zeros(n // block if block > 0 else 0)
        timing = ffi.from_buffer("double[]", block_ns) if block_ns.size else ffi.NULL
        st = lib.piezo_runner_run(r, n, h, master, order, ffi.from_buffer("double[]", y_ref),
                                  ffi.from_buffer("double[]", y_preview) if stamped else ffi.NULL,
                                  ffi.from_buffer("double[]", t_preview) if stamped else ffi.NULL,
                                  rows_ptr, stride, block if block_ns.size else 0, timing, res)
        self.last_block_ns = block_ns if block_ns.size else None
        if st > 1:
            k, role = first + res.samples, res.failed_role
            what = f"{_CALLS.get(res.failed_call, 'fmi2 call')} at t = {k * h:.6g} s (sample {k})"
            message = self._message(role, what, st)
            error = loop_error_class(self.log(role))(message)
            error.sample = k
            raise error
        if last:
            warn_safe_state(self.log(CONTROLLER), self.controller_info.model)   # sup.reaction = 1: say why
            lib.piezo_runner_terminate(r)

    def run(self, setup, *, block=0):
        """Run one closed loop.

        Parameters
        ----------
        setup : harness.loop.ClosedLoopSetup
            From :func:`harness.loop.prepare_closed_loop`.
        block : int
            When > 0, the thread CPU time of every complete block of ``block`` samples
            is kept in :attr:`last_block_ns` (for the benchmark).

        Returns
        -------
        ndarray
            The structured result of :func:`harness.masters.fmpy.simulate_closed_loop`.
        """
        n = setup.n
        rows = np.zeros((n, len(CLOSED_LOOP_FIELDS)))
        rows[:, 0] = setup.time
        rows[:, 1] = setup.y_d
        self._start(setup)
        ptr = self._ffi.from_buffer("double[]", rows) + 2
        self._run(setup, ptr, rows.shape[1], block)
        return as_structured(rows, CLOSED_LOOP_DTYPE)

    def run_chunks(self, setup, sink, *, chunk=1 << 16):
        """Run one closed loop as :meth:`run` does, handing its rows over in chunks instead of
        keeping them: ``sink(first, rows)`` for samples ``[first, first + len(rows))`` (the
        structured rows of :meth:`run`, the same bits). A long run (an hour is 7.2 million
        samples) then needs the memory of one chunk.

        Raises
        ------
        harness.fmu.FMUError
            As :meth:`run`; its ``sample`` attribute is the sample that failed (the chunks
            before it were handed over).
        """
        n = setup.n
        self._start(setup)
        for first in range(0, n, chunk):
            m = min(chunk, n - first)
            rows = np.zeros((m, len(CLOSED_LOOP_FIELDS)))
            rows[:, 0] = setup.time[first:first + m]
            rows[:, 1] = setup.y_d[first:first + m]
            ptr = self._ffi.from_buffer("double[]", rows) + 2
            self._run(setup, ptr, rows.shape[1], 0, first, m, last=first + m == n)
            sink(first, as_structured(rows, CLOSED_LOOP_DTYPE))

    def run_minimal(self, setup, *, block=0):
        """Run the loop with the minimal exchange (``y_meas`` and ``v`` only) and record
        nothing: the cost of the fmi2 calls themselves. Returns :attr:`last_block_ns`."""
        self._start(setup)
        self._run(setup, self._ffi.NULL, 0, block)
        return self.last_block_ns

    # -- many runs ----------------------------------------------------------------------
    def _table(self, info, params, per_run=None, runs=1):
        """A ``piezo_runner_params`` of ``params`` (name -> value, the order set), with the
        columns of ``per_run`` (name -> one value per run) varying from run to run; and the
        arrays it points into (keep them alive with it)."""
        ffi = self._ffi
        table = ffi.new("piezo_runner_params *")
        keep = [table]
        typed = typed_parameters(info, params)
        columns = {info.vr(name): values for name, values in (per_run or {}).items()}
        for (vrs, values), kind, dtype in zip(typed, ("real", "int", "bool"), (np.float64, np.intc, np.intc)):
            rows = np.tile(np.asarray(values, dtype=dtype), (runs if per_run else 1, 1))
            for j, vr in enumerate(vrs):
                if vr in columns:
                    rows[:, j] = np.asarray(columns.pop(vr), dtype=dtype)
            refs = np.asarray(vrs, dtype=np.intc)
            keep += [rows, refs]
            setattr(table, f"n_{kind}", len(vrs))
            ctype = "double[]" if dtype is np.float64 else "int[]"
            setattr(table, f"{kind}_refs", ffi.from_buffer("int[]", refs) if len(vrs) else ffi.NULL)
            setattr(table, f"{kind}s", ffi.from_buffer(ctype, rows) if len(vrs) else ffi.NULL)
        if columns:
            raise ValueError(f"{info.model}: varied parameters missing from the parameter set "
                             f"(value references {sorted(columns)})")
        table.per_run = 1 if per_run else 0
        return table, keep

    def run_batch(self, setup, per_run, window):
        """Run the closed loop of ``setup`` once per set of plant parameters, all in one C
        call (``piezo_runner_batch``): the runs of :meth:`run`, bit for bit, summarised by
        what the harness's checks and metrics read.

        Parameters
        ----------
        setup : harness.loop.ClosedLoopSetup
            The experiment. Its ``plant_params`` give the parameters set in every run (in
            their order), and the values of those not in ``per_run``; its
            ``controller_params`` are set in every run.
        per_run : dict
            Plant parameter name -> one value per run (1-D arrays of one length).
        window : (int, int)
            The metric window in samples, ``[start, stop)``.

        Returns
        -------
        dict of ndarray
            Per run: ``status`` (the worst FMI status; above 1 the run stopped at
            ``failed_call`` after ``samples`` samples), ``finite`` (y, y_meas and v finite
            in every sample), ``sum_error2`` and ``sum_y2`` (the sums of (y_d - y)^2 and
            y^2 over the window, as ``np.sum`` takes them), ``saturated`` (clipped samples
            in the window) and ``seconds`` (wall clock).

        Raises
        ------
        TypeError, harness.fmu.UnknownParameterError
            A parameter the FMU does not have, or a value of the wrong type.
        """
        ffi, lib = self._ffi, self._lib
        runs = len(next(iter(per_run.values()))) if per_run else 1
        if any(len(v) != runs for v in per_run.values()):
            raise ValueError("run_batch: the per-run columns differ in length")
        start, stop = (int(w) for w in window)
        if not 0 <= start <= stop <= setup.n:
            raise ValueError(f"run_batch: window {window!r} is not within the {setup.n} samples")
        plant, keep_p = self._table(self.plant_info, setup.plant_params, per_run, runs)
        controller, keep_c = self._table(self.controller_info, setup.controller_params)
        stamped = setup.y_preview is not None
        arrays = {"y_ref": np.ascontiguousarray(setup.y_ref, dtype=np.float64),
                  "y_d": np.ascontiguousarray(setup.y_d, dtype=np.float64),
                  "y_preview": np.ascontiguousarray(setup.y_preview if stamped else [], dtype=np.float64),
                  "t_preview": np.ascontiguousarray(setup.t_preview if stamped else [], dtype=np.float64)}
        x = ffi.new("piezo_runner_experiment *")
        x.n, x.h = setup.n, setup.h
        x.master = 1 if setup.master == "jacobi" else 0
        x.step_order = 1 if setup.step_order == "controller-first" else 0
        for name in ("y_ref", "y_d"):
            setattr(x, name, ffi.from_buffer("double[]", arrays[name]))
        for name in ("y_preview", "t_preview"):
            setattr(x, name, ffi.from_buffer("double[]", arrays[name]) if stamped else ffi.NULL)
        x.window_start, x.window_stop = start, stop
        out = {"status": np.zeros(runs, np.intc), "failed_call": np.zeros(runs, np.intc),
               "samples": np.zeros(runs, np.uintp), "finite": np.zeros(runs, np.intc),
               "sum_error2": np.zeros(runs), "sum_y2": np.zeros(runs),
               "saturated": np.zeros(runs, np.uintp), "seconds": np.zeros(runs)}
        o = ffi.new("piezo_runner_outcomes *")
        for name, arr in out.items():
            ctype = {np.dtype(np.intc): "int[]", np.dtype(np.uintp): "size_t[]"}.get(arr.dtype, "double[]")
            setattr(o, name, ffi.from_buffer(ctype, arr))
        done = lib.piezo_runner_batch(self._runner, x, plant, controller, runs, 1 if self._fresh else 0, o)
        if done != runs:
            raise ValueError("piezo_runner_batch refused its arguments (more than 64 parameters of a type?) "
                             "or found no memory for a run")
        self._fresh = False
        out["finite"] = out["finite"].astype(bool)
        return out

    def close(self):
        """Free both instances and unload the binaries (also done when collected)."""
        if getattr(self, "_runner", None) is not None:
            self._ffi.release(self._runner)      # runs piezo_runner_free now
            self._runner = None


def live_bytes():
    """Bytes all FMU instances of the native runners hold (their allocateMemory calls)."""
    return int(_binding()[1].piezo_runner_live_bytes())


_PER_THREAD = threading.local()


def native_loop(fmu_dir=None):
    """This thread's :class:`NativeLoop` for the FMUs in ``fmu_dir``, created on first use and
    kept (the binaries are loaded and instantiated once per thread and FMU set)."""
    key = []
    for model in (PLANT_MODEL, CONTROLLER_MODEL):
        path = fmu_path(model, fmu_dir)
        st = path.stat()
        key.append((str(path.resolve()), st.st_mtime_ns, st.st_size))
    key = tuple(key)
    loops = getattr(_PER_THREAD, "loops", None)
    if loops is None:
        loops = _PER_THREAD.loops = {}
    loop = loops.get(key)
    if loop is None:
        loop = loops[key] = NativeLoop(fmu_dir)
    return loop


#: why the native master refuses the FMI 3.0 editions (one line, for the command line too)
FMI3_REFUSAL = ("the native master (--backend native) runs the FMI 2.0 editions only; for the "
                "FMI 3.0 editions use --backend fmpy or auto (auto runs them with fmpy)")


class NativeFMIVersionError(ValueError):
    """The native master was asked to run the FMI 3.0 editions."""


def simulate_closed_loop_native(scenario, *, adaptation=None, preview=True, master="gauss-seidel",
                                plant_params=None, controller_params=None, fmu_dir=None,
                                duration=None, registry=None, step_order="plant-first",
                                progress=None, fmi_version=2):
    """Run a tracking scenario through both FMUs with the native master.

    Parameters, Returns and Raises are those of :func:`harness.masters.fmpy.simulate_closed_loop`
    (and the result equals it bit for bit); a missing runner library raises
    FileNotFoundError with the build command. The run is one C call (about 1000x real
    time), so ``progress(n, n)`` is called once, at its end. The native master calls the
    fmi2 functions: ``fmi_version=3`` raises :class:`NativeFMIVersionError`.
    """
    if fmi_version != 2:
        raise NativeFMIVersionError(FMI3_REFUSAL)
    setup = prepare_closed_loop(scenario, adaptation=adaptation, preview=preview, master=master,
                                plant_params=plant_params, controller_params=controller_params,
                                duration=duration, registry=registry, step_order=step_order)
    data = native_loop(fmu_dir).run(setup)
    if progress is not None:
        progress(setup.n, setup.n)
    return data
