"""The runs of a sweep, streamed to disk: the journal (one CSV row per run, appended as
each task completes, a task's rows in one write), what is kept in memory (25 bytes per run)
and the result that reads its rows back."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
import io
import math
import os
from pathlib import Path

import numpy as np

from .spreads import apply_spreads, run_deltas

__all__ = ["STATUSES", "JOURNAL", "RUNS", "STATUS_CODE", "RunStore", "ParameterSets",
           "RunRows", "SweepResult", "TaskRows", "csv_line", "task_rows"]

#: outcomes of a run (their codes are their places: a new one goes at the end); "stopped": the
#: controller's supervision stopped a loop that cannot work (harness.fmu.LoopFaultError), apart
#: from "diverged", a loop the divergence monitor or a non-finite value ended
STATUSES = ("ok", "diverged", "saturated", "invalid", "stopped")
JOURNAL = "sweep_runs.journal.csv"
RUNS = "sweep_runs.csv"
STATUS_CODE = {s: i for i, s in enumerate(STATUSES)}
MISSING = -1


def csv_line(cells):
    """One CSV row as UTF-8 bytes, ending in a newline."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(cells)
    return buf.getvalue().encode("utf-8")


def _cell(text):
    """One text field as :func:`csv_line` writes it among others (quoted when it must be)."""
    return csv_line([text]).decode("utf-8")[:-1] if text else ""


@dataclass(frozen=True)
class TaskRows:
    """A task's runs, as the journal records them: what is kept in memory of each run and
    its journal row (``data``, every row ending in a newline; row j ends at ``ends[j]``).

    Attributes
    ----------
    indices : ndarray of int64
    codes : ndarray of int8
        ``STATUS_CODE`` of each run's status.
    e_rms, e_r : ndarray of float64
    data : bytes
    ends : ndarray of int64
    """

    indices: np.ndarray
    codes: np.ndarray
    e_rms: np.ndarray
    e_r: np.ndarray
    data: bytes
    ends: np.ndarray

    def __len__(self):
        return int(self.indices.size)


def task_rows(name, indices, statuses, e_rms, e_r, seconds, columns, reasons):
    """The journal rows of some runs of scenario ``name``, in the columns of
    :attr:`RunStore.header`, written as :func:`csv_line` writes them (the numbers as their
    shortest exact text, ``seconds`` to 0.1 ms), all in one go.

    Parameters
    ----------
    name : str
    indices : sequence of int
    statuses : sequence of str
        One of :data:`STATUSES` per run.
    e_rms, e_r, seconds : sequence of float
    columns : sequence of sequences
        The varied parameters' values: one sequence per column, one value per run (Python
        floats and ints, as their text is written).
    reasons : sequence of str
        One line each (a row holds no newline), empty for a run that is ok.

    Returns
    -------
    TaskRows
    """
    indices = [int(i) for i in indices]
    e_rms = [float(e) for e in e_rms]
    e_r = [float(e) for e in e_r]
    head = _cell(name)
    values = zip(*columns) if columns else ((),) * len(indices)
    lines = [",".join([head, str(i), st, repr(e), repr(r), f"{s:.4f}", *map(repr, vals), _cell(why)])
             for i, st, e, r, s, vals, why in zip(indices, statuses, e_rms, e_r, seconds, values, reasons)]
    data = ("\n".join(lines) + "\n").encode("utf-8") if lines else b""
    ends = np.flatnonzero(np.frombuffer(data, np.uint8) == ord("\n")).astype(np.int64) + 1
    if ends.size != len(lines):
        raise ValueError("a journal row holds a newline")
    return TaskRows(np.asarray(indices, dtype=np.int64),
                    np.asarray([STATUS_CODE[s] for s in statuses], dtype=np.int8),
                    np.asarray(e_rms, dtype=float), np.asarray(e_r, dtype=float), data, ends)


class RunStore:
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
        self.status = {k: np.full(self.n, MISSING, np.int8) for k in self.names}
        self.e_rms = {k: np.full(self.n, math.nan) for k in self.names}
        self.e_r = {k: np.full(self.n, math.nan) for k in self.names}
        self.offset = {k: np.full(self.n, -1, np.int64) for k in self.names}
        self._out = None
        self._pos = 0

    def done(self, name=None):
        names = self.names if name is None else [name]
        return int(sum(np.count_nonzero(self.status[k] != MISSING) for k in names))

    def missing(self, name):
        return np.flatnonzero(self.status[name] == MISSING)

    def missing_blocks(self, name, block=1 << 16):
        """The missing runs of ``name`` in order, as arrays of at most ``block`` indices
        (nothing the size of all the runs is made)."""
        codes = self.status[name]
        for start in range(0, self.n, block):
            found = np.flatnonzero(codes[start:start + block] == MISSING)
            if found.size:
                yield found + start

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
                i, code = int(row[1]), STATUS_CODE[row[2]]
                e_rms, e_r = float(row[3]), float(row[4])
            except (ValueError, KeyError):
                continue
            if 0 <= i < self.n and self.status[row[0]][i] == MISSING:
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
            self._out.write(csv_line(self.header))
        self._out.flush()
        self._pos = self._out.tell()

    def add(self, name, rows):
        """Record rows ``(index, status, e_rms, e_r, reason, seconds, [values])`` (see
        :meth:`add_rows`). Returns the ``(index, status)`` of the rows that were new."""
        rows = list(rows)
        if not rows:
            return []
        index, status, e_rms, e_r, reason, seconds, values = zip(*rows)
        task = task_rows(name, index, status, e_rms, e_r, seconds, list(zip(*values)), reason)
        new = self.add_rows(name, task)
        return [(i, s) for i, s, keep in zip(index, status, new) if keep]

    def add_rows(self, name, task):
        """Record a task's runs (:class:`TaskRows`) and append their rows to the journal in
        one write (flushed). A run already recorded, or given twice, is recorded once.
        Returns whether each run was new (bool array)."""
        idx = task.indices
        new = self.status[name][idx] == MISSING
        if idx.size:
            first = np.zeros(idx.size, bool)
            first[np.unique(idx, return_index=True)[1]] = True
            new &= first
        starts = np.concatenate(([0], task.ends[:-1])).astype(np.int64)
        if new.all():
            chunk, lengths = task.data, task.ends - starts
        else:
            chunk = b"".join(task.data[a:b] for a, b, keep in zip(starts, task.ends, new) if keep)
            lengths = (task.ends - starts)[new]
        if chunk:
            offsets = self._pos + np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
            self._out.write(chunk)
            self._out.flush()
            self._pos += len(chunk)
            kept = idx[new]
            self.status[name][kept] = task.codes[new]
            self.e_rms[name][kept] = task.e_rms[new]
            self.e_r[name][kept] = task.e_r[new]
            self.offset[name][kept] = offsets
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
            dst.write(csv_line(self.header))
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


class ParameterSets:
    """Run i's parameter set, drawn again when asked for (nothing is kept per run)."""

    def __init__(self, base, spreads, seed, n):
        self.base, self.spreads, self.seed, self.n = base, spreads, seed, n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        if not -self.n <= i < self.n:
            raise IndexError(i)
        return apply_spreads(self.base, self.spreads, run_deltas(self.spreads, self.seed, i % self.n))


class RunRows:
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
    store : RunStore
    compute_seconds : float
        Wall-clock seconds from the first task handed out to the last one collected (nan
        when nothing was computed).
    bound : harness.bench.bound.Bound, str or None
        The native runner's cost measured in this call, and the cores; why it could not be
        measured (str); None with fmpy, or when nothing was computed.
    load : tuple or None
        The load average (1, 5, 15 min) when the call started.
    cpu_seconds : dict
        CPU seconds while computing: ``tasks`` (the tasks' processes, summed over the tasks)
        and ``client`` (this process besides the tasks); and ``tasks_wall``, the tasks'
        wall-clock seconds summed (more than their CPU when other processes had the cores).
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
    compute_seconds: float = math.nan
    bound: object = None
    load: tuple = None
    cpu_seconds: dict = field(default_factory=dict)

    def counts(self, name):
        codes = self.store.status[name]
        return {s: int(np.count_nonzero(codes == STATUS_CODE[s])) for s in STATUSES}

    def errors(self, name, field="e_rms"):
        values = self.store.e_rms[name] if field == "e_rms" else self.store.e_r[name]
        return values[self.store.status[name] == STATUS_CODE["ok"]]

    def worst(self, name):
        """Index of the ok run with the largest e_rms, or None."""
        ok = self.store.status[name] == STATUS_CODE["ok"]
        if not ok.any():
            return None
        return int(np.argmax(np.where(ok, self.store.e_rms[name], -np.inf)))

