"""``python -m harness sweep``: Monte Carlo robustness sweeps of the closed loop on Dask.

N closed-loop runs per scenario, each with the plant's parameters drawn from
distributions the user gives (``--vary``), run by Dask: a local cluster of worker
processes by default (one per core), or an existing cluster with ``--scheduler ADDRESS``.
Each worker loads the FMUs once (the client ships the FMU files, so every worker runs
exactly the client's build) and reuses its instances from run to run through
``fmi2Reset`` (:class:`harness.native.NativeLoop`).

A spread is ``KEY=SPEC``. SPEC is ``[uniform:|normal:]WIDTH[%]``: ``uniform`` (default)
draws from [-WIDTH, WIDTH], ``normal`` from N(0, WIDTH^2); with ``%`` the change is
relative (WIDTH in percent), without it absolute. KEY is

* ``pi.weights``: every PI weight (w0, w[1..m]) independently;
* ``tf.poles``: each pole of G independently (relative: in the pole's continuous-time
  frequency ln(p)/h, i.e. p -> p^(1 + delta), so a relative spread never makes a stable
  pole unstable; absolute: p -> p + delta; a complex pair moves together, absolute in
  its radius), at fixed DC gain and zero;
* ``tf.zero``: the zero of B = b1 z^-1 + b2 z^-2 (z0 = -b2/b1; relative as for the
  poles), at fixed DC gain;
* ``tf.gain``: the DC gain of G;
* ``creep.k_c``, ``creep.alpha``, or any other Real PiezoStage parameter by its name;
* ``sensor.seed`` (no SPEC): every run gets its own sensor-noise seed.

A sweep must move something: without a spread (or with only spreads of width 0) every run
would be the same run, and it is refused. Run i draws its parameters from a generator seeded
by (``--seed``, i), on the worker that runs it, so a sweep is reproducible whatever the
scheduling, and the same draws are applied to every scenario's own plant. A run that
diverges (the controller's monitor stops it, a value overflows, or its error exceeds the
reference: :mod:`harness.checks`), clips its voltage persistently, or whose drawn
parameters the FMU refuses is counted and reported; it does not stop the sweep.

Scale: each task's rows are appended to ``sweep_runs.journal.csv`` (and flushed) as it
completes; the client keeps 25 bytes per run and queues a few tasks per worker, so its
memory does not grow with the number of runs. A task lost with its worker is run again and
a run is recorded once. ``--resume`` continues an interrupted sweep from its journal
(``sweep_manifest.json`` says what the runs depend on; a different sweep is refused): only
the missing runs are computed.

Results (under ``--out``, default ``out/sweep``): the table of percentiles and worst case
of e_rms and e_r per scenario (printed, ``sweep_summary.csv``/``.md``), every run with its
drawn parameters (``sweep_runs.csv``, sorted by scenario and run), the worst run's parameter
set as a scenario file keyed by FMU variable names (``worst_<scenario>.toml``: rerun it with
``python -m harness run worst_<scenario> --scenario-file ...``), and histogram and CDF of
e_rms (``sweep_e_rms.png``).
"""

from __future__ import annotations

import atexit
import cmath
import csv
from dataclasses import dataclass, field, fields
import hashlib
import math
import os
from pathlib import Path
import re
import shutil
import sys
import tempfile
import time

import numpy as np

__all__ = ["Spread", "parse_spread", "draw_plant_parameters", "run_sweep", "SweepResult",
           "add_sweep_arguments", "run_sweep_command", "STATUSES"]

PROG = "python -m harness sweep"
#: outcomes of a run
STATUSES = ("ok", "diverged", "saturated", "invalid")
_GROUPS = ("pi.weights", "tf.poles", "tf.zero", "tf.gain")
_N_DELTAS = {"pi.weights": 17, "tf.poles": 2}
_SPEC = re.compile(r"^(?:(uniform|normal):)?\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(%?)$")


# ---------------------------------------------------------------------------
# spreads and draws
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Spread:
    """One ``--vary`` spread.

    Attributes
    ----------
    key : str
        ``pi.weights``, ``tf.poles``, ``tf.zero``, ``tf.gain``, ``sensor.seed`` or a Real
        PiezoStage parameter name.
    distribution : {"uniform", "normal", "seed"}
    width : float
        Half-width (uniform) or standard deviation (normal), a fraction when relative.
    relative : bool
    """

    key: str
    distribution: str
    width: float = 0.0
    relative: bool = True

    def describe(self):
        if self.distribution == "seed":
            return f"{self.key}: a new seed per run"
        w = f"{self.width * 100:g} %" if self.relative else f"{self.width:g}"
        kind = "relative" if self.relative else "absolute"
        form = "+-" if self.distribution == "uniform" else "sigma "
        return f"{self.key}: {self.distribution}, {kind} {form}{w}"


def parse_spread(text, real_parameters=None):
    """Parse ``KEY=SPEC`` (see the module docstring) into a :class:`Spread`.

    Parameters
    ----------
    text : str
    real_parameters : collection of str, optional
        The Real PiezoStage parameter names a KEY may also be.

    Raises
    ------
    ValueError
        With the accepted forms.
    """
    key, sep, spec = str(text).partition("=")
    key, spec = key.strip(), spec.strip()
    if key == "sensor.seed":
        if sep and spec not in ("", "random"):
            raise ValueError(f"--vary sensor.seed takes no width (got {text!r})")
        return Spread("sensor.seed", "seed")
    known = set(_GROUPS) | set(real_parameters or ())
    if key not in known:
        names = ", ".join(list(_GROUPS) + ["sensor.seed", "creep.k_c", "creep.alpha"])
        raise ValueError(f"--vary {text!r}: unknown key {key!r}; use one of {names} or a Real "
                         f"PiezoStage parameter name")
    m = _SPEC.match(spec) if sep else None
    if not m:
        raise ValueError(f"--vary {text!r}: expected {key}=[uniform:|normal:]WIDTH[%], "
                         f"e.g. {key}=10% (relative) or {key}=normal:0.001 (absolute)")
    width = float(m.group(2))
    if not (math.isfinite(width) and width >= 0):
        raise ValueError(f"--vary {text!r}: the width must be a finite number >= 0")
    relative = m.group(3) == "%"
    return Spread(key, m.group(1) or "uniform", width / 100 if relative else width, relative)


def _draw(rng, spread, size):
    if spread.distribution == "uniform":
        return rng.uniform(-spread.width, spread.width, size)
    return rng.normal(0.0, spread.width, size)


def _move(value, delta, relative):
    return float(value * (1.0 + delta) if relative else value + delta)


def _move_root(root, delta, relative):
    """A pole or zero moved by delta: relative in ln(root) (p -> p^(1 + delta)), absolute in
    the value (real) or the radius (complex)."""
    if relative:
        if root == 0:
            return root
        if isinstance(root, complex):
            return cmath.exp((1.0 + delta) * cmath.log(root))
        return math.copysign(abs(root) ** (1.0 + delta), root)
    if isinstance(root, complex):
        return cmath.rect(abs(root) + delta, cmath.phase(root))
    return root + delta


def _apply(base, spreads, deltas):
    """The plant parameter set ``base`` (complete, by FMU name) moved by one run's deltas."""
    p = dict(base)
    structural = {}
    for s in spreads:
        d = deltas[s.key]
        if s.key == "sensor.seed":
            p["sensor.seed"] = int(d)
        elif s.key == "pi.weights":
            m = int(p["pi.m"])
            p["pi.w0"] = _move(p["pi.w0"], d[0], s.relative)
            for j in range(1, m + 1):
                p[f"pi.w[{j}]"] = _move(p[f"pi.w[{j}]"], d[j], s.relative)
        elif s.key in _GROUPS:
            structural[s.key] = (s, d)
        else:
            p[s.key] = _move(p[s.key], float(d[0]), s.relative)
    if structural:
        a1, a2, b1, b2 = (float(base[k]) for k in ("tf.a1", "tf.a2", "tf.b1", "tf.b2"))
        gain = (b1 + b2) / (1.0 + a1 + a2)
        zero = -b2 / b1
        disc = complex(a1 * a1 - 4.0 * a2)
        roots = [(-a1 + cmath.sqrt(disc)) / 2.0, (-a1 - cmath.sqrt(disc)) / 2.0]
        if "tf.poles" in structural:
            s, d = structural["tf.poles"]
            if a1 * a1 - 4.0 * a2 >= 0:                 # two real poles, moved independently
                roots = [_move_root(r.real, float(d[i]), s.relative) for i, r in enumerate(roots)]
            else:                                        # a complex pair moves together
                r = _move_root(roots[0], float(d[0]), s.relative)
                roots = [r, r.conjugate()]
        if "tf.zero" in structural:
            s, d = structural["tf.zero"]
            zero = _move_root(zero, float(d[0]), s.relative)
        if "tf.gain" in structural:
            s, d = structural["tf.gain"]
            gain = _move(gain, float(d[0]), s.relative)
        r1, r2 = (complex(r) for r in roots)
        a1, a2 = -(r1 + r2).real, (r1 * r2).real
        # DC gain (b1 + b2) / A(1) with b2 = -b1 z0: b1 = gain A(1) / (1 - z0)
        b1 = gain * (1.0 + a1 + a2) / (1.0 - zero) if zero != 1.0 else math.nan
        p.update({"tf.a1": a1, "tf.a2": a2, "tf.b1": b1, "tf.b2": -b1 * zero})
    return p


def draw_plant_parameters(base, spreads, n, seed=1):
    """Draw n plant parameter sets.

    Parameters
    ----------
    base : dict
        The complete plant parameter set (FMU name -> value) the spreads move.
    spreads : sequence of Spread
    n : int
    seed : int
        Seed of NumPy's default generator.

    Returns
    -------
    list of dict
        One complete parameter set per run.
    """
    return [_apply(base, spreads, _run_deltas(spreads, seed, i)) for i in range(n)]


def _run_deltas(spreads, seed, i):
    """Run i's {key: deltas}, from its own generator seeded by (seed, i): its parameters do
    not depend on the number of runs (a longer sweep extends a shorter one), nor on which
    worker draws them, nor when."""
    rng = np.random.default_rng([int(seed), int(i)])
    d = {}
    for s in spreads:
        if s.distribution == "seed":
            d[s.key] = int(rng.integers(0, 2**31 - 1))
        else:
            d[s.key] = _draw(rng, s, _N_DELTAS.get(s.key, 1))
    return d


def _varied_keys(spreads, base):
    """The FMU parameter names the spreads move in ``base`` (the columns of the runs table):
    every PI weight that a spread can move (w0, and w[1..m] unless a relative spread meets a
    zero weight), the four coefficients of G for a pole, zero or gain spread, the named
    parameter otherwise."""
    keys = set()
    for s in spreads:
        if s.key == "pi.weights":
            keys.add("pi.w0")
            keys.update(f"pi.w[{j}]" for j in range(1, int(base["pi.m"]) + 1)
                        if not s.relative or base[f"pi.w[{j}]"] != 0)
        elif s.key in _GROUPS:
            keys.update(("tf.a1", "tf.a2", "tf.b1", "tf.b2"))
        else:
            keys.add(s.key)
    return keys


def varies_something(spreads):
    """True when at least one spread moves a parameter (a seed per run, or a width > 0)."""
    return any(s.distribution == "seed" or s.width > 0 for s in spreads)


def plant_start_values(fmu_dir=None):
    """The PiezoStage parameters' start values from its model description (name -> value)."""
    from .cosim import PLANT_MODEL, _load, fmu_path

    info = _load(fmu_path(PLANT_MODEL, fmu_dir))
    out = {}
    for name, var in info.variables.items():
        if var.causality != "parameter":
            continue
        if var.type == "Real":
            out[name] = float(var.start)
        elif var.type == "Integer":
            out[name] = int(var.start)
        elif var.type == "Boolean":
            out[name] = str(var.start).lower() in ("true", "1")
    return out


# ---------------------------------------------------------------------------
# the worker side
# ---------------------------------------------------------------------------
_WORKER_DIRS = {}


def _worker_cleanup():
    for d in _WORKER_DIRS.values():
        shutil.rmtree(d, ignore_errors=True)


atexit.register(_worker_cleanup)


def _fmu_dir_for(package):
    """A folder holding the shipped FMU files on this worker (written once per content)."""
    digest, files = package
    d = _WORKER_DIRS.get(digest)
    if d is None:
        d = tempfile.mkdtemp(prefix="harness_sweep_")
        for name, data in files.items():
            Path(d, name).write_bytes(data)
        _WORKER_DIRS[digest] = d
    return d


def _scenario_fields(sc):
    """A picklable description of a Scenario (its mappings are read-only proxies)."""
    out = {f.name: getattr(sc, f.name) for f in fields(sc)}
    for k in ("plant", "controller", "paper"):
        out[k] = dict(out[k])
    return out


def _scenario(fields_):
    from types import MappingProxyType

    from .scenarios import Scenario

    f = dict(fields_)
    for k in ("plant", "controller", "paper"):
        f[k] = MappingProxyType(dict(f[k]))
    return Scenario(**f)


def _one_run(scenario, params, options, fmu_dir):
    """Run one closed loop; return (status, e_rms [um], e_r, reason)."""
    from ._common import prepare_closed_loop
    from .checks import RunCheckError, RunSaturatedError, check_tracking_run
    from .cosim import FMUError, FMUInitializationError, LoopDivergedError, UnknownParameterError, _simulate
    from .metrics import compute_metrics
    from .native import native_loop

    try:
        setup = prepare_closed_loop(scenario, plant_params=params, adaptation=options["adaptation"],
                                    preview=options["preview"], master=options["master"])
        if options["backend"] == "native":
            data = native_loop(fmu_dir).run(setup)
        else:
            data = _simulate(setup, fmu_dir)
        check_tracking_run(data, scenario)
    except LoopDivergedError as exc:
        return "diverged", math.nan, math.nan, _first_line(exc)
    except RunSaturatedError as exc:
        return "saturated", math.nan, math.nan, _first_line(exc)
    except RunCheckError as exc:
        return "diverged", math.nan, math.nan, _first_line(exc)
    except (FMUInitializationError, UnknownParameterError, TypeError, ValueError) as exc:
        return "invalid", math.nan, math.nan, _first_line(exc)
    except FMUError as exc:
        return "diverged", math.nan, math.nan, _first_line(exc)
    m = compute_metrics(data["time"], data["y_d"], data["y"], scenario.metric_window,
                        scenario.step_size)
    return "ok", m.e_rms, m.e_r, ""


def _first_line(exc):
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    return " ".join(text.split())[:400]


def _peak_rss():
    """This process's peak resident set size in bytes (None where the OS does not say)."""
    try:
        import resource
    except ImportError:                                     # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


def run_chunk(package, scenario_fields, base, spreads, seed, indices, varied, options):
    """Worker task: some runs of one scenario, each drawing its own parameters.

    Parameters
    ----------
    package : (str, dict)
        Content digest and ``{file name: bytes}`` of both FMUs.
    scenario_fields : dict
        From :func:`_scenario_fields`.
    base : dict
        The scenario's complete plant parameter set, before the spreads.
    spreads : list of Spread
    seed : int
    indices : list of int
        The runs (run i draws from the generator seeded by (seed, i)).
    varied : list of str
        Parameter names whose drawn values are returned with each run.
    options : dict
        ``backend``, ``adaptation``, ``preview``, ``master``.

    Returns
    -------
    (list of tuple, int or None)
        ``(index, status, e_rms_um, e_r, reason, seconds, [values of varied])`` per run,
        and this worker's peak RSS in bytes.
    """
    fmu_dir = _fmu_dir_for(package)
    scenario = _scenario(scenario_fields)
    out = []
    for index in indices:
        params = _apply(base, spreads, _run_deltas(spreads, seed, index))
        t0 = time.perf_counter()
        status, e_rms, e_r, reason = _one_run(scenario, params, options, fmu_dir)
        out.append((int(index), status, e_rms, e_r, reason, time.perf_counter() - t0,
                    [params[k] for k in varied]))
    return out, _peak_rss()


# ---------------------------------------------------------------------------
# the client side: runs streamed to disk
# ---------------------------------------------------------------------------
MANIFEST = "sweep_manifest.json"
JOURNAL = "sweep_runs.journal.csv"
RUNS = "sweep_runs.csv"
_STATUS_CODE = {s: i for i, s in enumerate(STATUSES)}
_MISSING = -1


class SweepIncompleteError(RuntimeError):
    """Runs are missing after the sweep (their tasks failed on every attempt)."""


def _csv_line(cells):
    import io

    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(cells)
    return buf.getvalue().encode("utf-8")


class _Store:
    """The runs of a sweep: on disk, one CSV row per run in the journal, appended (and
    flushed) as each task completes; in memory, 25 bytes per run (status, e_rms, e_r and
    where its row is), whatever the number of runs. Each run is recorded once: a row for
    a run already recorded is not written again.

    Parameters
    ----------
    folder : Path
    names : list of str
        The scenarios.
    n : int
        Runs per scenario.
    columns : list of str
        The varied parameter names (columns between ``seconds`` and ``reason``).
    """

    def __init__(self, folder, names, n, columns):
        self.folder, self.names, self.n, self.columns = Path(folder), list(names), int(n), list(columns)
        self.path = self.folder / JOURNAL
        self.header = ["scenario", "run", "status", "e_rms_um", "e_r", "seconds", *self.columns, "reason"]
        self.status = {k: np.full(self.n, _MISSING, np.int8) for k in self.names}
        self.e_rms = {k: np.full(self.n, math.nan) for k in self.names}
        self.e_r = {k: np.full(self.n, math.nan) for k in self.names}
        self.offset = {k: np.full(self.n, -1, np.int64) for k in self.names}
        self._out = None
        self._pos = 0

    def done(self, name=None):
        names = self.names if name is None else [name]
        return int(sum(np.count_nonzero(self.status[k] != _MISSING) for k in names))

    def missing(self, name):
        return np.flatnonzero(self.status[name] == _MISSING)

    def load(self):
        """Read the journal of an interrupted sweep: every complete row of a known run is
        recorded (the first, if a run appears twice); a last line cut off by the
        interruption is dropped from the file. Returns the number of runs recorded."""
        if not self.path.exists():
            return 0
        with open(self.path, "r+b") as f:
            data = f.read()
            end = data.rfind(b"\n") + 1
            if end < len(data):
                f.truncate(end)                     # a row cut off mid-write
        pos = 0
        for raw in data[:end].splitlines(keepends=True):
            here, pos = pos, pos + len(raw)
            try:
                row = next(csv.reader([raw.decode("utf-8")]))
            except (UnicodeDecodeError, csv.Error, StopIteration):
                continue
            if len(row) != len(self.header) or row[0] not in self.status:
                continue                            # the header, or not a row of this sweep
            try:
                i, code = int(row[1]), _STATUS_CODE[row[2]]
                e_rms, e_r = float(row[3]), float(row[4])
            except (ValueError, KeyError):
                continue
            if 0 <= i < self.n and self.status[row[0]][i] == _MISSING:
                self._record(row[0], i, code, e_rms, e_r, here)
        return self.done()

    def _record(self, name, i, code, e_rms, e_r, offset):
        self.status[name][i] = code
        self.e_rms[name][i] = e_rms
        self.e_r[name][i] = e_r
        self.offset[name][i] = offset

    def open(self, fresh):
        """Start appending (``fresh``: a new journal with its header)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self._out = open(self.path, "wb" if fresh else "ab")
        if fresh:
            self._out.write(_csv_line(self.header))
        self._out.flush()
        self._pos = self._out.tell()

    def add(self, name, rows):
        """Record a task's rows and append them to the journal (flushed). Returns the rows
        that were new."""
        new = []
        chunk = bytearray()
        for index, status, e_rms, e_r, reason, seconds, values in rows:
            if self.status[name][index] != _MISSING:
                continue
            line = _csv_line([name, index, status, repr(float(e_rms)), repr(float(e_r)),
                              f"{seconds:.4f}", *[repr(v) for v in values], reason])
            self._record(name, index, _STATUS_CODE[status], e_rms, e_r, self._pos + len(chunk))
            chunk += line
            new.append((index, status))
        if chunk:
            self._out.write(chunk)
            self._out.flush()
            self._pos += len(chunk)
        return new

    def close(self):
        if self._out is not None:
            self._out.close()
            self._out = None

    def row(self, name, i):
        """The recorded row of run i as strings (None if the run is missing)."""
        off = int(self.offset[name][i])
        if off < 0:
            return None
        with open(self.path, "rb") as f:
            f.seek(off)
            return next(csv.reader([f.readline().decode("utf-8")]))

    def write_sorted(self, path):
        """Write every recorded row, by scenario and run, to ``path`` (CSV with the header),
        reading the journal row by row."""
        tmp = Path(str(path) + ".tmp")
        with open(self.path, "rb") as src, open(tmp, "wb") as dst:
            dst.write(_csv_line(self.header))
            for name in self.names:
                for off in self.offset[name]:
                    if off >= 0:
                        src.seek(int(off))
                        dst.write(src.readline())
        os.replace(tmp, path)
        return Path(path)

    def adopt(self, path):
        """Read the rows from ``path`` (written by :meth:`write_sorted`) from now on, so that
        the journal can go."""
        pos = 0
        with open(path, "rb") as f:
            f.readline()                                # the header
            pos = f.tell()
            for name in self.names:
                for i in np.flatnonzero(self.offset[name] >= 0):
                    self.offset[name][i] = pos
                    pos += len(f.readline())
        self.path = Path(path)


class _Parameters:
    """Run i's parameter set, drawn again when asked for (nothing is kept per run)."""

    def __init__(self, base, spreads, seed, n):
        self.base, self.spreads, self.seed, self.n = base, spreads, seed, n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        if not -self.n <= i < self.n:
            raise IndexError(i)
        return _apply(self.base, self.spreads, _run_deltas(self.spreads, self.seed, i % self.n))


class _Runs:
    """Run i's ``(status, e_rms_um, e_r, reason, seconds)``, read from the sweep's store
    (status ``missing`` for a run that was never recorded)."""

    def __init__(self, store, name):
        self.store, self.name = store, name

    def __len__(self):
        return self.store.n

    def __getitem__(self, i):
        if not -self.store.n <= i < self.store.n:
            raise IndexError(i)
        i %= self.store.n
        row = self.store.row(self.name, i)
        if row is None:
            return ("missing", math.nan, math.nan, "", math.nan)
        return (row[2], float(row[3]), float(row[4]), row[-1], float(row[5]))


@dataclass
class SweepResult:
    """Everything a sweep produced.

    The runs themselves are on disk (``store``); in memory are 25 bytes per run.

    Attributes
    ----------
    scenarios : list of str
    spreads : list of Spread
    parameters : dict
        Per scenario name, the parameter set of every run (``parameters[name][i]``, drawn
        again on access).
    runs : dict
        Per scenario name, ``runs[name][i]`` = ``(status, e_rms_um, e_r, reason, seconds)``.
    elapsed : float
        Wall-clock seconds of this call (cluster start included).
    workers : str
        Where it ran.
    options : dict
    computed : int
        Runs computed by this call (the others came from the journal with ``resume``).
    peak_rss : dict
        Peak resident set sizes in bytes: ``client`` (this process, where a local cluster's
        scheduler also runs) and ``worker`` (the largest of the workers; None without Dask).
    store : _Store
    """

    scenarios: list
    spreads: list
    parameters: dict
    runs: dict
    elapsed: float
    workers: str
    options: dict
    computed: int = 0
    peak_rss: dict = field(default_factory=dict)
    store: object = None

    def counts(self, name):
        codes = self.store.status[name]
        return {s: int(np.count_nonzero(codes == _STATUS_CODE[s])) for s in STATUSES}

    def errors(self, name, field="e_rms"):
        values = self.store.e_rms[name] if field == "e_rms" else self.store.e_r[name]
        return values[self.store.status[name] == _STATUS_CODE["ok"]]

    def worst(self, name):
        """Index of the ok run with the largest e_rms, or None."""
        ok = self.store.status[name] == _STATUS_CODE["ok"]
        if not ok.any():
            return None
        return int(np.argmax(np.where(ok, self.store.e_rms[name], -np.inf)))


def _chunks_of(indices, size):
    for i in range(0, len(indices), size):
        yield [int(j) for j in indices[i:i + size]]


def _fmu_package(fmu_dir):
    from .cosim import CONTROLLER_MODEL, PLANT_MODEL, fmu_path

    files = {}
    digest = hashlib.sha256()
    for model in (PLANT_MODEL, CONTROLLER_MODEL):
        path = fmu_path(model, fmu_dir)
        data = path.read_bytes()
        files[path.name] = data
        digest.update(data)
    return digest.hexdigest(), files


class _Progress:
    """Progress of the runs on stderr, with the rate and the time left: a rewritten line on
    a terminal, else a line per 10 % of the runs (and at least every 30 s)."""

    def __init__(self, total, done, stream):
        self.total, self.stream = total, stream
        self.done = self.start = done
        self.bad = 0
        self.t0 = self.last = time.perf_counter()
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.next_mark = (math.floor(10 * done / total) + 1) / 10 if total else 1.0

    def update(self, new):
        self.done += len(new)
        self.bad += sum(1 for _, status in new if status != "ok")
        now = time.perf_counter()
        frac = self.done / self.total
        elapsed = now - self.t0
        rate = (self.done - self.start) / elapsed if elapsed > 0 else 0.0
        eta = f", ETA {(self.total - self.done) / rate:.0f} s" if rate > 0 and self.done < self.total else ""
        text = (f"sweep: {self.done}/{self.total} runs ({frac:.0%}), {self.bad} not ok, "
                f"{elapsed:.1f} s, {rate:.0f} runs/s{eta}")
        if self.tty:
            self.stream.write("\r" + text + ("\n" if self.done == self.total else ""))
            self.stream.flush()
        elif frac >= self.next_mark or self.done == self.total or now - self.last >= 30.0:
            self.stream.write(text + "\n")
            self.stream.flush()
            self.last = now
            while self.next_mark <= frac:
                self.next_mark += 0.1

    def say(self, text):
        self.stream.write(("\n" if self.tty and self.done < self.total else "") + text + "\n")
        self.stream.flush()


def _digest(obj):
    import json

    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=repr).encode()).hexdigest()[:16]


def _identity(scs, spreads, n_runs, seed, options, package_digest, bases):
    """What makes a sweep's runs what they are: a sweep is resumed only into the same."""
    return {
        "format": 1,
        "scenarios": [sc.name for sc in scs],
        "scenario_definitions": {sc.name: _digest(_scenario_fields(sc)) for sc in scs},
        "runs": int(n_runs),
        "seed": int(seed),
        "spreads": [[s.key, s.distribution, s.width, s.relative] for s in spreads],
        "options": {k: options[k] for k in sorted(options)},
        "fmus": package_digest,
        "base_parameters": {name: _digest(base) for name, base in bases.items()},
    }


def _read_manifest(folder):
    import json

    try:
        return json.loads((Path(folder) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None


def _write_manifest(folder, identity, complete):
    import json

    path = Path(folder) / MANIFEST
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"identity": identity, "complete": bool(complete)}, indent=1) + "\n")
    os.replace(tmp, path)


def _identity_difference(old, new):
    names = {"scenarios": "the scenarios", "scenario_definitions": "a scenario's definition",
             "runs": "the number of runs", "seed": "the seed", "spreads": "the spreads",
             "options": "the options", "fmus": "the FMUs", "base_parameters": "the plant parameters",
             "format": "the file format"}
    diff = [names.get(k, k) for k in new if old.get(k) != new[k]]
    if "seed" in [k for k in new if old.get(k) != new[k]]:
        diff[diff.index("the seed")] = f"the seed ({old.get('seed')}, now {new['seed']})"
    if "runs" in [k for k in new if old.get(k) != new[k]]:
        diff[diff.index("the number of runs")] = f"the number of runs ({old.get('runs')}, now {new['runs']})"
    return ", ".join(diff)


def _prepare_folder(folder, identity, resume, progress):
    """Check the output folder against ``resume`` and return whether the journal is new."""
    manifest = _read_manifest(folder)
    journal, final = folder / JOURNAL, folder / RUNS
    unfinished = manifest is not None and not manifest.get("complete") and journal.exists()
    if not resume:
        if unfinished:
            raise ValueError(f"{folder} holds an unfinished sweep: add --resume to continue it "
                             f"(same scenarios, -n, --seed and --vary), or give another --out")
        return True
    if manifest is None or not (unfinished or (manifest.get("complete") and final.exists())):
        if progress is not None:
            progress.write(f"sweep: --resume: no sweep to continue in {folder}; starting one\n")
        return True
    if manifest.get("identity") != identity:
        raise ValueError(f"--resume: {folder} holds a sweep with other settings "
                         f"({_identity_difference(manifest.get('identity', {}), identity)}): "
                         f"give the same scenarios, -n, --seed, --vary and options, or another --out")
    if not unfinished:                              # complete: its runs table is the journal
        shutil.copyfile(final, journal)
    return False


def run_sweep(scenarios, spreads, n_runs, *, seed=1, scheduler=None, workers=None, chunk=None,
              backend="native", adaptation=None, preview=True, master="gauss-seidel",
              fmu_dir=None, registry=None, progress=None, out=None, resume=False):
    """Run a Monte Carlo sweep, streaming every run to disk as its task completes.

    Parameters
    ----------
    scenarios : sequence of str
        Tracking scenarios.
    spreads : sequence of Spread or str
        The distributions (``KEY=SPEC`` strings are parsed); at least one must move a
        parameter.
    n_runs : int
        Runs per scenario.
    seed : int
        Seed of the draws.
    scheduler : str, optional
        Address of an existing Dask scheduler (e.g. ``tcp://10.0.0.5:8786``); else a local
        cluster of ``workers`` processes is started (and stopped) for the sweep.
    workers : int, optional
        Local worker processes (default: the number of cores); 0 runs everything in this
        process without Dask.
    chunk : int, optional
        Runs per task (default: about four tasks per worker and scenario, at most 50).
    backend : {"native", "fmpy"}
    adaptation, preview, master
        As :func:`harness.cosim.simulate_closed_loop`.
    fmu_dir, registry
        FMU folder and scenario registry.
    progress : file, optional
        Where the progress goes (e.g. ``sys.stderr``).
    out : path, optional
        Folder of the journal (``sweep_runs.journal.csv``, one row per run as it completes)
        and the manifest (``sweep_manifest.json``); default: a temporary folder.
    resume : bool
        Continue the unfinished sweep in ``out`` (the same scenarios, runs, seed, spreads,
        options and FMUs): only its missing runs are computed.

    Returns
    -------
    SweepResult

    Raises
    ------
    ValueError
        Bad arguments, nothing varied, or ``out`` holding another (or an unfinished) sweep.
    SweepIncompleteError
        Runs whose task failed on every attempt (the others are in the journal: resume).
    """
    from ._common import normalize_master
    from .native import native_available
    from .scenarios import get_scenario

    t_start = time.perf_counter()
    if n_runs < 1:
        raise ValueError(f"the number of runs must be at least 1, got {n_runs}")
    if backend not in ("native", "fmpy"):
        raise ValueError(f"backend must be 'native' or 'fmpy', got {backend!r}")
    if backend == "native" and not native_available():
        from .native import runner_library_path
        raise FileNotFoundError(f"native runner library not found: {runner_library_path()}; build "
                                f"it (cmake --build build) or use --backend fmpy")
    master = normalize_master(master)
    base_all = plant_start_values(fmu_dir)
    reals = [k for k, v in base_all.items() if isinstance(v, float)]
    spreads = [s if isinstance(s, Spread) else parse_spread(s, reals) for s in spreads]
    keys = [s.key for s in spreads]
    if len(set(keys)) != len(keys):
        raise ValueError(f"a key is varied twice: {', '.join(keys)}")
    scs = [get_scenario(name, registry) for name in scenarios]
    for sc in scs:
        if sc.kind != "tracking":
            raise ValueError(f"scenario '{sc.name}' is a {sc.kind} scenario; a sweep needs tracking "
                             f"scenarios")
    if not varies_something(spreads):
        what = "no spread is given" if not spreads else "every spread has width 0"
        raise ValueError(f"nothing varies ({what}): all {n_runs} runs would be the same run; add "
                         f"--vary KEY=SPEC, e.g. --vary pi.weights=10% --vary sensor.seed")
    bases = {}
    for sc in scs:
        base = {**base_all, **dict(sc.plant)}
        base.setdefault("h", sc.step_size)
        bases[sc.name] = base
    varied = sorted(set().union(*(_varied_keys(spreads, b) for b in bases.values())))
    options = {"backend": backend, "adaptation": adaptation, "preview": bool(preview),
               "master": master}
    package = _fmu_package(fmu_dir)
    identity = _identity(scs, spreads, n_runs, seed, options, package[0], bases)
    names = [sc.name for sc in scs]
    total = n_runs * len(scs)

    if out is None:
        folder = Path(tempfile.mkdtemp(prefix="harness_sweep_runs_"))
        _WORKER_DIRS[str(folder)] = str(folder)          # removed at exit
    else:
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
    fresh = _prepare_folder(folder, identity, resume, progress)
    store = _Store(folder, names, n_runs, varied)
    if not fresh:
        store.load()
    _write_manifest(folder, identity, complete=False)
    store.open(fresh)
    done_before = store.done()
    if progress is not None and done_before:
        progress.write(f"sweep: resuming {folder}: {done_before} of {total} runs done, "
                       f"{total - done_before} to compute\n")
    prog = _Progress(total, done_before, progress) if progress is not None else None
    fields_ = {sc.name: _scenario_fields(sc) for sc in scs}
    worker_rss = []
    failures = []

    def collect(name, result):
        rows, rss = result
        if rss is not None:
            worker_rss.append(rss)
        new = store.add(name, rows)
        if prog:
            prog.update(new)

    n_workers = (os.cpu_count() or 1) if workers is None else int(workers)
    size = chunk or max(1, min(50, math.ceil(n_runs / (4 * max(n_workers, 1)))))
    try:
        if scheduler is None and n_workers == 0:
            where = "this process (no Dask)"
            for sc in scs:
                for part in _chunks_of(store.missing(sc.name), size):
                    rows, _ = run_chunk(package, fields_[sc.name], bases[sc.name], spreads, seed, part,
                                        varied, options)
                    collect(sc.name, (rows, None))
        else:
            where = _run_on_dask(scheduler, n_workers, package, scs, store, size, collect, failures,
                                 (fields_, bases, spreads, seed, varied, options), prog)
    except KeyboardInterrupt:
        store.close()
        if progress is not None:
            progress.write(f"\nsweep: interrupted: {store.done()} of {total} runs are in {store.path}; "
                           f"the same command with --resume computes the rest\n")
            progress.flush()
        raise
    store.close()
    missing = total - store.done()
    if missing:
        why = f" (last error: {failures[-1]})" if failures else ""
        raise SweepIncompleteError(f"{missing} of {total} runs are missing: their tasks failed on every "
                                   f"attempt{why}; the others are in {store.path}: rerun with --resume")
    peak = {"client": _peak_rss(), "worker": max(worker_rss) if worker_rss else None}
    return SweepResult(names, spreads,
                       {sc.name: _Parameters(bases[sc.name], spreads, seed, n_runs) for sc in scs},
                       {name: _Runs(store, name) for name in names},
                       time.perf_counter() - t_start, where, options, computed=total - done_before,
                       peak_rss=peak, store=store)


_ATTEMPTS = 4          # a task whose worker is lost is run again; after this many failures its runs are missing


def _run_on_dask(scheduler, n_workers, package, scs, store, size, collect, failures, task, prog):
    """Run the missing runs on Dask; return where. At most a few tasks per worker are
    queued at a time (memory does not grow with the number of runs). A task lost with its
    worker is rescheduled by Dask; a task that fails anyway is submitted again."""
    from collections import deque

    from dask.distributed import Client, LocalCluster, as_completed

    fields_, bases, spreads, seed, varied, options = task
    cluster = None
    if scheduler is None:
        import logging
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
        client = Client(cluster)
        where = f"a local Dask cluster of {n_workers} worker process{'es' if n_workers > 1 else ''}"
    else:
        client = Client(scheduler, timeout=30)
        info = client.scheduler_info()
        nw = len(info.get("workers", {}))
        where = f"the Dask cluster at {scheduler} ({nw} worker{'s' if nw != 1 else ''})"
        n_workers = max(nw, 1)
    try:
        shipped = client.scatter(package, broadcast=True)
        pending = deque((sc.name, part, 1) for sc in scs for part in _chunks_of(store.missing(sc.name), size))
        inflight = {}
        queue = as_completed()
        limit = max(8, 4 * n_workers)

        def submit():
            name, part, attempt = pending.popleft()
            fut = client.submit(run_chunk, shipped, fields_[name], bases[name], spreads, seed, part,
                                varied, options, pure=False)
            inflight[fut] = (name, part, attempt)
            queue.add(fut)

        while pending and len(inflight) < limit:
            submit()
        for fut in queue:
            name, part, attempt = inflight.pop(fut)
            try:
                result = fut.result()
            except Exception as exc:                # noqa: BLE001 - any failure of a task is retried
                failures.append(_first_line(exc) or type(exc).__name__)
                if attempt < _ATTEMPTS:
                    pending.appendleft((name, part, attempt + 1))
                    if prog is not None:
                        prog.say(f"sweep: a task of {len(part)} runs failed ({failures[-1]}); "
                                 f"running it again (attempt {attempt + 1} of {_ATTEMPTS})")
            else:
                collect(name, result)
            fut.release()
            while pending and len(inflight) < limit:
                submit()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return where


# ---------------------------------------------------------------------------
# tables, files, plots
# ---------------------------------------------------------------------------
PERCENTILES = (5, 50, 95, 99)


def summary_rows(result):
    """One dict per scenario: counts, percentiles and worst of e_rms [nm] and e_r [%]."""
    rows = []
    for name in result.scenarios:
        c = result.counts(name)
        row = {"scenario": name, "runs": len(result.runs[name]), **c}
        for field, scale, unit in (("e_rms", 1e3, "nm"), ("e_r", 100.0, "%")):
            vals = result.errors(name, field) * scale
            for p in PERCENTILES:
                row[f"{field}_p{p}_{unit}"] = float(np.percentile(vals, p)) if vals.size else math.nan
            row[f"{field}_worst_{unit}"] = float(vals.max()) if vals.size else math.nan
        rows.append(row)
    return rows


def _mb(n):
    return "?" if n is None else f"{n / 1e6:.0f} MB"


def format_summary(result):
    """The printed table."""
    n = len(next(iter(result.runs.values())))
    head = (f"{PROG}: {n} runs per scenario on {result.workers}, backend {result.options['backend']}, "
            f"{sum(len(v) for v in result.runs.values())} runs in {result.elapsed:.1f} s")
    lines = [head, "spreads: " + ("; ".join(s.describe() for s in result.spreads) or "none")]
    cols = ["runs", "ok", "div", "sat", "inv"] + [f"p{p}" for p in PERCENTILES] + ["worst"]
    width = max(12, *(len(s) for s in result.scenarios))
    lines.append(f"{'':<{width}}  {'':>26}  {'e_rms [nm]':^38}  {'e_r [%]':^38}")
    lines.append(f"{'scenario':<{width}}  " + " ".join(f"{c:>5}" for c in cols[:5]) + "  "
                 + " ".join(f"{c:>7}" for c in cols[5:]) + "  "
                 + " ".join(f"{c:>7}" for c in cols[5:]))
    for row in summary_rows(result):
        counts = [row["runs"], row["ok"], row["diverged"], row["saturated"], row["invalid"]]
        e = [row[f"e_rms_p{p}_nm"] for p in PERCENTILES] + [row["e_rms_worst_nm"]]
        r = [row[f"e_r_p{p}_%"] for p in PERCENTILES] + [row["e_r_worst_%"]]
        lines.append(f"{row['scenario']:<{width}}  " + " ".join(f"{c:>5}" for c in counts) + "  "
                     + " ".join(f"{x:>7.3g}" for x in e) + "  " + " ".join(f"{x:>7.3g}" for x in r))
    lines.append("div: diverged (monitor, overflow or error above the reference), sat: clipped "
                 "persistently, inv: parameters refused by the FMU; percentiles over the ok runs")
    rate = result.computed / result.elapsed if result.elapsed > 0 else math.nan
    resumed = sum(len(v) for v in result.runs.values()) - result.computed
    peak = result.peak_rss or {}
    lines.append(f"this call: {result.computed} runs computed" + (f" ({resumed} from the journal)" if resumed else "")
                 + f", {rate:.0f} runs/s including the start; peak RSS {_mb(peak.get('client'))} in this "
                 f"process" + (f", {_mb(peak.get('worker'))} in the largest worker"
                               if peak.get("worker") is not None else ""))
    return "\n".join(lines) + "\n"


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    v = float(v)
    if math.isnan(v):
        return "nan"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    text = repr(v)
    return text if any(ch in text for ch in ".en") else text + ".0"


def write_parameter_file(path, scenario, params, title, options=None):
    """Write ``params`` as a scenario file: a parameter set ``<stem>`` keyed by FMU variable
    names and a scenario ``<stem>`` that extends ``scenario`` with it."""
    path = Path(path)
    name = path.stem
    lines = [f"# {title}", "# Rerun: python -m harness run " + name + " --scenario-file " + path.name, "",
             f"[parameter_sets.{name}]"]
    lines += [f'"{k}" = {_toml_value(v)}' for k, v in params.items()]
    lines += ["", "[[scenario]]", f'name = "{name}"', f'extends = "{scenario}"',
              f'plant_set = "{name}"', f'description = "{title}"']
    if options and options.get("adaptation") is False:
        lines.append('controller = { "rls.enabled" = false }')
    path.write_text("\n".join(lines) + "\n")
    return path


def write_outputs(result, out_dir, plots=True):
    """Write the CSV/Markdown tables, the runs, the worst parameter files and the plot."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    rows = summary_rows(result)
    with open(out / "sweep_summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written.append(out / "sweep_summary.csv")
    md = ["| scenario | runs | ok | diverged | saturated | invalid | "
          + " | ".join(f"e_rms p{p} [nm]" for p in PERCENTILES) + " | e_rms worst [nm] | "
          + " | ".join(f"e_r p{p} [%]" for p in PERCENTILES) + " | e_r worst [%] |",
          "|" + "---|" * (6 + 2 * (len(PERCENTILES) + 1))]
    for r in rows:
        vals = [r["scenario"], r["runs"], r["ok"], r["diverged"], r["saturated"], r["invalid"]]
        vals += [f"{r[f'e_rms_p{p}_nm']:.3g}" for p in PERCENTILES] + [f"{r['e_rms_worst_nm']:.3g}"]
        vals += [f"{r[f'e_r_p{p}_%']:.3g}" for p in PERCENTILES] + [f"{r['e_r_worst_%']:.3g}"]
        md.append("| " + " | ".join(str(v) for v in vals) + " |")
    (out / "sweep_summary.md").write_text(
        format_summary(result).splitlines()[0] + "\n\n" + "\n".join(md) + "\n")
    written.append(out / "sweep_summary.md")

    written.append(result.store.write_sorted(out / RUNS))

    for name in result.scenarios:
        i = result.worst(name)
        if i is not None:
            e = float(result.store.e_rms[name][i])
            title = (f"worst run of the sweep of {name}: run {i}, e_rms = {e * 1e3:.6g} nm "
                     f"(master {result.options['master']}, preview {result.options['preview']})")
            written.append(write_parameter_file(out / f"worst_{name}.toml", name,
                                                result.parameters[name][i], title, result.options))
        codes = result.store.status[name]
        bad = np.flatnonzero((codes == _STATUS_CODE["diverged"]) | (codes == _STATUS_CODE["saturated"]))
        if bad.size:
            j = int(bad[0])
            title = f"first {STATUSES[codes[j]]} run of the sweep of {name}: run {j}"
            written.append(write_parameter_file(out / f"failed_{name}.toml", name,
                                                result.parameters[name][j], title, result.options))
    if plots:
        written.append(plot_errors(result, out / "sweep_e_rms.png"))
    if out.resolve() == result.store.folder.resolve() and result.store.path.name == JOURNAL:
        # the sorted table is written: the sweep is complete, its journal is no longer needed
        manifest = _read_manifest(out)
        if manifest is not None:
            _write_manifest(out, manifest["identity"], complete=True)
        journal = result.store.path
        result.store.adopt(out / RUNS)
        journal.unlink(missing_ok=True)
    return written


def plot_errors(result, path):
    """Histogram and empirical CDF of e_rms [nm] per scenario (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_h, ax_c) = plt.subplots(1, 2, figsize=(11, 4.2))
    all_vals = np.concatenate([result.errors(n) * 1e3 for n in result.scenarios] or [np.zeros(0)])
    positive = all_vals[all_vals > 0]
    log = positive.size > 1 and positive.max() / positive.min() > 30
    if positive.size:
        lo, hi = positive.min(), positive.max()
        bins = (np.geomspace(lo, hi * 1.0001, 40) if log else np.linspace(lo, hi * 1.0001 + 1e-12, 40))
    else:
        bins = 10
    for name in result.scenarios:
        vals = np.sort(result.errors(name) * 1e3)
        c = result.counts(name)
        not_ok = len(result.runs[name]) - c["ok"]
        label = f"{name} ({c['ok']} ok" + (f", {not_ok} not ok)" if not_ok else ")")
        if vals.size:
            ax_h.hist(vals, bins=bins, histtype="step", linewidth=1.5, label=label)
            ax_c.step(vals, np.arange(1, vals.size + 1) / len(result.runs[name]), where="post",
                      label=label)
    for ax in (ax_h, ax_c):
        if log:
            from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
            ax.set_xscale("log")
            ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("e_rms [nm]")
        ax.grid(True, which="major", alpha=0.3)
    ax_h.set_ylabel("runs")
    ax_h.set_title("histogram of e_rms")
    ax_c.set_ylabel("fraction of all runs with e_rms <= x")
    ax_c.set_ylim(0, 1.02)
    ax_c.set_title("empirical CDF (not-ok runs count as above every x)")
    ax_h.legend(fontsize=8)
    import textwrap

    spreads = "; ".join(s.describe() for s in result.spreads) or "no spread"
    title = (f"Monte Carlo sweep, {len(next(iter(result.runs.values())))} runs per scenario "
             f"(backend {result.options['backend']}): {spreads}")
    fig.suptitle(textwrap.fill(title, 150), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------
def add_sweep_arguments(parser):
    """Add the options of ``sweep`` to an argparse parser."""
    parser.add_argument("scenarios", nargs="+", metavar="SCENARIO",
                        help="tracking scenario(s) to sweep (see: python -m harness list)")
    parser.add_argument("-n", "--runs", type=int, default=100, metavar="N",
                        help="runs per scenario (default 100)")
    parser.add_argument("--vary", action="append", default=[], metavar="KEY=SPEC",
                        help="a spread of plant parameters, repeatable: KEY is pi.weights, "
                             "tf.poles, tf.zero, tf.gain, creep.k_c, creep.alpha, any Real "
                             "PiezoStage parameter, or sensor.seed (no SPEC: a seed per run); "
                             "SPEC is [uniform:|normal:]WIDTH[%%] (%% relative, else absolute), "
                             "e.g. --vary pi.weights=10%% --vary creep.alpha=normal:0.005")
    parser.add_argument("--seed", type=int, default=1, help="seed of the draws (default 1)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="address of an existing Dask scheduler (default: start a local "
                             "cluster of worker processes)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="worker processes of the local cluster (default: one per core; "
                             "0: run in this process without Dask)")
    parser.add_argument("--chunk", type=int, metavar="N", help="runs per Dask task (default: auto)")
    parser.add_argument("--backend", choices=("native", "fmpy"), default="native",
                        help="master of each run: native (default) or fmpy")
    parser.add_argument("--no-adaptation", action="store_true", help="switch the controller's RLS off")
    parser.add_argument("--no-preview", action="store_true", help="feed y_d(k) instead of y_d(k+d)")
    parser.add_argument("--jacobi", action="store_true", help="Jacobi master")
    parser.add_argument("--out", default=os.path.join("out", "sweep"), metavar="DIR",
                        help="output folder (default out/sweep)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the interrupted sweep in --out (the same scenarios, -n, "
                             "--seed, --vary and options): only its missing runs are computed")
    parser.add_argument("--no-plots", action="store_true", help="do not write the PNG")
    parser.add_argument("--fmu-dir", metavar="DIR", help="folder of the FMUs (default build/fmus)")
    parser.add_argument("--scenario-file", action="append", default=[], metavar="FILE",
                        help="TOML file of extra scenarios (repeatable)")
    return parser


def run_sweep_command(args, stream=None):
    """Run ``sweep`` with parsed arguments; print the table; return the exit code (0: the sweep
    ran, whatever its runs did; 1: runs are missing after every attempt)."""
    from .scenarios import load_scenarios

    stream = stream or sys.stdout
    if args.runs < 1:
        raise ValueError(f"--runs must be at least 1, got {args.runs}")
    if args.workers is not None and args.workers < 0:
        raise ValueError(f"--workers must be >= 0, got {args.workers}")
    if args.chunk is not None and args.chunk < 1:
        raise ValueError(f"--chunk must be at least 1, got {args.chunk}")
    registry = load_scenarios(args.scenario_file)
    try:
        result = run_sweep(args.scenarios, args.vary, args.runs, seed=args.seed, scheduler=args.scheduler,
                           workers=args.workers, chunk=args.chunk, backend=args.backend,
                           adaptation=False if args.no_adaptation else None,
                           preview=not args.no_preview,
                           master="jacobi" if args.jacobi else "gauss-seidel", fmu_dir=args.fmu_dir,
                           registry=registry, progress=sys.stderr, out=args.out,
                           resume=getattr(args, "resume", False))
    except SweepIncompleteError as exc:
        sys.stderr.write(f"{PROG}: error: {exc}\n")
        return 1
    stream.write(format_summary(result))
    written = write_outputs(result, args.out, plots=not args.no_plots)
    stream.write("wrote " + ", ".join(str(p) for p in written) + "\n")
    return 0
