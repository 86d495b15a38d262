"""Measured records in: a user's CSV files of voltage and displacement.

One file per experiment, comma-separated, with a header row naming at least
the columns

* ``time`` [s]: sample times, strictly increasing and uniform, period ``h``;
* ``v`` [V]: the voltage applied at that time (held until the next sample);
* ``y`` [um]: the displacement measured at that time.

Extra columns are ignored, blank lines and lines starting with ``#`` are
skipped.  The experiment is assumed to start from rest (stage at ``y = 0``
with ``v = 0`` before the first row), as the model's records do.

Every problem is reported as one line naming the file (and the line and
column where there is one) by an exception that subclasses
:class:`RecordError`, itself a :class:`ValueError`:

===========================  ==============================================
:class:`RecordFileError`     unreadable or empty file, bad header, ragged row
:class:`MissingColumnError`  a required column is missing or misnamed
:class:`NonNumericError`     a value is not a number
:class:`NonFiniteError`      a value is NaN or infinite
:class:`TimeGridError`       time not increasing, or not uniformly sampled
:class:`SamplePeriodError`   the sample period is not the model's ``h``
:class:`ShortRecordError`    too few samples or voltage reversals
:class:`ConstantVoltageError`  the voltage never moves
===========================  ==============================================
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
import difflib
import math
from pathlib import Path
import re

import numpy as np

__all__ = [
    "REQUIRED_COLUMNS",
    "MIN_RECORD_SAMPLES",
    "TIME_TOLERANCE",
    "RecordError",
    "RecordFileError",
    "MissingColumnError",
    "NonNumericError",
    "NonFiniteError",
    "TimeGridError",
    "SamplePeriodError",
    "ShortRecordError",
    "ConstantVoltageError",
    "MeasuredRecord",
    "count_reversals",
    "read_record",
    "write_record",
]

#: Columns a record file must have, with their units.
REQUIRED_COLUMNS = {"time": "s", "v": "V", "y": "um"}
#: Fewest samples a record may hold (0.1 s at 2 kHz).
MIN_RECORD_SAMPLES = 200
#: Largest allowed distance of a sample time from the uniform grid, as a fraction of h.
TIME_TOLERANCE = 0.01
# A decimal number as a CSV cell holds it (float() also takes "1_000" and " 1 "), and the
# spellings of NaN and infinity, refused with their own message.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NON_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
#: A reversal of the voltage counts once it has moved back by this fraction of its range.
REVERSAL_DEADBAND = 0.01


class RecordError(ValueError):
    """A measured record cannot be used; the message is one line naming the file."""


class RecordFileError(RecordError):
    """The file cannot be read, is empty, has no usable header or a ragged row."""


class MissingColumnError(RecordError):
    """A required column (``time``, ``v`` or ``y``) is missing or misnamed."""


class NonNumericError(RecordError):
    """A value in a required column is not a number."""


class NonFiniteError(RecordError):
    """A value in a required column is NaN or infinite."""


class TimeGridError(RecordError):
    """The time column does not increase, or is not uniformly sampled."""


class SamplePeriodError(RecordError):
    """The sample period of the record is not the model's ``h``."""


class ShortRecordError(RecordError):
    """Too few samples, or too few reversals of the voltage."""


class ConstantVoltageError(RecordError):
    """The voltage never moves: the record carries no information about the stage."""


@dataclass(frozen=True, eq=False)
class MeasuredRecord:
    """One experiment read from a CSV file.

    Attributes
    ----------
    label : str
        Name of the experiment (the file name without its extension).
    path : Path
        The file it was read from.
    h : float
        Sample period [s] (the model's, checked against the time column).
    time : ndarray
        Sample times [s] as given.
    v : ndarray
        Voltage [V].
    y : ndarray
        Measured displacement [um].
    """

    label: str
    path: Path
    h: float
    time: np.ndarray
    v: np.ndarray
    y: np.ndarray

    @property
    def n_samples(self):
        return int(self.v.size)


def count_reversals(v, deadband=REVERSAL_DEADBAND):
    """Number of times ``v`` changes direction by more than ``deadband`` of its range.

    A sine of P periods has about 2P reversals; a step or a ramp has none.

    Parameters
    ----------
    v : array_like, shape (N,)
    deadband : float
        Fraction of ``max(v) - min(v)`` the signal must move back from its
        last extreme before a reversal counts (ignores noise wiggles).

    Returns
    -------
    int
    """
    v = np.asarray(v, dtype=float).ravel()
    if v.size < 3:
        return 0
    band = deadband * float(v.max() - v.min())
    if not band > 0:
        return 0
    count, direction, extreme = 0, 0, float(v[0])
    for x in v.tolist():
        if direction == 0:                      # leaving the start value
            if x > extreme + band or x < extreme - band:
                direction, extreme = (1 if x > extreme else -1), x
        elif direction > 0:
            if x > extreme:
                extreme = x
            elif x < extreme - band:
                count, direction, extreme = count + 1, -1, x
        else:
            if x < extreme:
                extreme = x
            elif x > extreme + band:
                count, direction, extreme = count + 1, 1, x
    return count


def _fmt(x):
    """Shortest text that reads back as x (0.0005, not 0.00050000000000000001)."""
    return repr(float(x))


def unreadable_file_message(path, exc, what):
    """One line saying why a text file could not be read (records here, parameter files in
    :mod:`harness.identify.params`).

    Parameters
    ----------
    path : str or Path
        The file.
    exc : OSError or UnicodeDecodeError
        What opening, reading or decoding it raised.
    what : str
        What a folder given instead is not, e.g. ``"a CSV file"``.

    Returns
    -------
    str
        ``"<path>: no such file"``, ``"<path>: is a folder, not <what>"``,
        ``"<path>: not a text file (<reason>)"`` or ``"<path>: cannot be read (<reason>)"``.
    """
    if isinstance(exc, FileNotFoundError):
        return f"{path}: no such file"
    if isinstance(exc, IsADirectoryError):
        return f"{path}: is a folder, not {what}"
    if isinstance(exc, UnicodeDecodeError):
        return f"{path}: not a text file ({exc.reason})"
    return f"{path}: cannot be read ({exc.strerror or exc})"


def _read_rows(path):
    """(header, [(line number, fields)]) of the file, blank and '#' lines skipped."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = [(i, row) for i, row in enumerate(csv.reader(fh), start=1)
                    if row and any(f.strip() for f in row) and not row[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordFileError(unreadable_file_message(path, exc, "a CSV file")) from None
    except csv.Error as exc:
        raise RecordFileError(f"{path}: not a valid CSV file ({exc})") from None
    if not rows:
        raise RecordFileError(f"{path}: the file is empty (expected a header: time,v,y)")
    return rows[0], rows[1:]


def _guess_column(name, candidates):
    """The header entry that looks like a misspelt ``name`` (Time, y_um, y [um], tme), or None."""
    for c in candidates:
        low = c.lower()
        if low == name or (low.startswith(name) and not low[len(name):len(name) + 1].isalnum()):
            return c
    close = difflib.get_close_matches(name, candidates, n=1, cutoff=0.75)
    return close[0] if close else None


def _column_index(path, header_line, header):
    names = [f.strip() for f in header]
    index = {}
    for name in REQUIRED_COLUMNS:
        hits = [i for i, n in enumerate(names) if n == name]
        if len(hits) > 1:
            raise RecordFileError(f"{path}: line {header_line}: column '{name}' appears "
                                  f"{len(hits)} times in the header")
        if hits:
            index[name] = hits[0]
    missing = [n for n in REQUIRED_COLUMNS if n not in index]
    if missing:
        name = missing[0]
        found = ", ".join(names) if names else "none"
        if len(names) == 1 and any(sep in names[0] for sep in ";\t"):
            hint = "; the file does not look comma-separated"
        else:
            guess = _guess_column(name, [n for n in names if n not in REQUIRED_COLUMNS])
            hint = f" (is '{guess}' meant to be '{name}'?)" if guess else ""
        units = ", ".join(f"{n} [{u}]" for n, u in REQUIRED_COLUMNS.items())
        raise MissingColumnError(f"{path}: missing column '{name}'{hint}; the header has: "
                                 f"{found}; a record needs the columns {units}")
    return index, len(names)


def read_record(path, *, h=0.0005, label=None, min_reversals=0):
    """Read and validate one measured record (a CSV file of time, v and y).

    Parameters
    ----------
    path : str or Path
    h : float
        The model's sample period [s]; the record must be sampled at it.
    label : str, optional
        Name of the experiment (default: the file name without extension).
    min_reversals : int
        Fewest reversals of the voltage the record must hold
        (:func:`count_reversals`; e.g. 4 = two periods of a periodic input).

    Returns
    -------
    MeasuredRecord

    Raises
    ------
    RecordError
        One of its subclasses, with a one-line message naming the file and,
        where there is one, the line and column.
    """
    path = Path(path)
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"h must be a finite number > 0, got {h!r}")
    (header_line, header), rows = _read_rows(path)
    index, width = _column_index(path, header_line, header)
    values = {name: np.empty(len(rows)) for name in REQUIRED_COLUMNS}
    for r, (line, fields) in enumerate(rows):
        if len(fields) != width:
            raise RecordFileError(f"{path}: line {line} has {len(fields)} fields, "
                                  f"the header has {width}")
        for name, col in index.items():
            text = fields[col].strip()
            if _NUMBER.fullmatch(text):
                x = float(text)
            elif _NON_FINITE.fullmatch(text):
                x = math.nan
            else:
                shown = text if len(text) <= 40 else text[:37] + "..."
                raise NonNumericError(f"{path}: line {line}, column '{name}': "
                                      f"'{shown}' is not a number")
            if not math.isfinite(x):          # nan, inf, or an overflow such as 1e999
                raise NonFiniteError(f"{path}: line {line}, column '{name}': {text} is not "
                                     f"finite (every value must be a finite number)")
            values[name][r] = x
    lines = [line for line, _ in rows]
    t, v, y = values["time"], values["v"], values["y"]
    n = t.size

    if n < 2:
        raise ShortRecordError(f"{path}: {n} sample{'s' if n != 1 else ''}; a record needs at "
                               f"least {MIN_RECORD_SAMPLES}")
    dt = np.diff(t)
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        k = int(bad[0]) + 1
        raise TimeGridError(f"{path}: line {lines[k]}: time does not increase "
                            f"(t = {_fmt(t[k])} s after {_fmt(t[k - 1])} s)")
    period = float(t[-1] - t[0]) / (n - 1)
    grid = t[0] + np.arange(n) * period
    off = np.abs(t - grid)
    k = int(np.argmax(off))
    if off[k] > TIME_TOLERANCE * period:
        raise TimeGridError(f"{path}: line {lines[k]}: time is not uniformly sampled: "
                            f"t = {_fmt(t[k])} s, the uniform grid of the record has "
                            f"{grid[k]:.9g} s (mean period {period:.9g} s; tolerance "
                            f"{TIME_TOLERANCE:.0%} of it)")
    if abs(period - h) > 1e-6 * h:
        unit = (" (is time in ms? the column is in s)" if abs(period / 1000 - h) <= 1e-6 * h
                else "")
        raise SamplePeriodError(
            f"{path}: sample period {period:.9g} s ({1 / period:.6g} Hz) is not the model's "
            f"h = {_fmt(h)} s ({1 / h:.6g} Hz){unit}; record at {1 / h:.6g} Hz, or identify a "
            f"model sampled at {period:.6g} s (--sample-period {period:.6g})")
    if n < MIN_RECORD_SAMPLES:
        raise ShortRecordError(f"{path}: {n} samples ({n * h:.6g} s); a record needs at least "
                               f"{MIN_RECORD_SAMPLES} ({MIN_RECORD_SAMPLES * h:.6g} s)")
    if float(v.max()) == float(v.min()):
        raise ConstantVoltageError(f"{path}: the voltage never moves (v = {_fmt(v[0])} V on "
                                   f"every line); a record needs a varying voltage")
    if min_reversals > 0:
        reversals = count_reversals(v)
        if reversals < min_reversals:
            raise ShortRecordError(
                f"{path}: the voltage reverses direction {reversals} time"
                f"{'s' if reversals != 1 else ''}; this step needs at least {min_reversals} "
                f"(about {min_reversals / 2:g} periods of a periodic input)")
    return MeasuredRecord(label if label is not None else path.stem, path, h, t, v, y)


def write_record(path, time, v, y, extra=None):
    """Write a record as CSV (``time,v,y`` and optional extra columns), full precision.

    Every value is written as the shortest text that reads back to the same
    double, so :func:`read_record` returns exactly what was written.

    Parameters
    ----------
    path : str or Path
    time, v, y : array_like, shape (N,)
    extra : dict of str to array_like, optional
        Further columns (ignored by :func:`read_record`).

    Returns
    -------
    Path
    """
    cols = {"time": time, "v": v, "y": y}
    cols.update(extra or {})
    arrays = [np.asarray(c, dtype=float).ravel() for c in cols.values()]
    n = arrays[0].size
    if any(a.size != n for a in arrays):
        raise ValueError("every column must have the same length: "
                         + ", ".join(f"{k} {a.size}" for k, a in zip(cols, arrays)))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lists = [a.tolist() for a in arrays]
    with open(path, "w", newline="") as fh:
        fh.write(",".join(cols) + "\n")
        fh.writelines(",".join(map(repr, row)) + "\n" for row in zip(*lists))
    return path


