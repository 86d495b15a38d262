"""What a stage-use profile asks of the loop: where its moves end and its holds begin, and the
errors there.

A profile reference (``type = "profile"``, :mod:`harness.scenarios`) is a sequence of holds,
moves and scans on the sample grid. From it alone this module derives the windows the
stage-use metrics read (docs/stage_use.md):

* **a move's window**: from the move's first sample to ``settle`` after its last (a step's
  last sample is its first): the worst ``|y_d - y|`` there is the move's error;
* **a hold's window**: from ``settle`` after the motion before it ended (the run's start counts
  as one) to the next motion's first sample (or the run's end): the worst ``|y - y_d|`` there;
* **a scan frame after a dwell**: a scan segment that follows another one with only holds
  between them: its worst error, and the worst error over the last second of the frame before.

Every function takes the rows a run recorded by their sample index ``k`` (``time / h``), so a
run that recorded only its communication points (the closed-loop FMU at a long step during
holds) is read the same way, over the samples it has.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SETTLE", "SCAN_TAIL", "MoveError", "HoldError", "ScanError", "motions", "move_windows",
           "hold_windows", "scan_pairs", "move_errors", "hold_errors",
           "scan_errors", "sample_index"]

#: [s] how long after a move ends its window lasts, and after which a hold's window begins
SETTLE = 0.5
#: [s] the steady part of a scan frame that the frame after a dwell is compared with
SCAN_TAIL = 1.0


@dataclass(frozen=True)
class MoveError:
    """The worst ``|y_d - y|`` [um] over one move's window ``[first, stop)`` (samples)."""

    segment: int
    first: int
    stop: int
    worst: float


@dataclass(frozen=True)
class HoldError:
    """The worst ``|y - y_d|`` [um] over one hold's window ``[first, stop)`` (samples), which
    holds the position ``position`` [um]."""

    first: int
    stop: int
    position: float
    worst: float


@dataclass(frozen=True)
class ScanError:
    """A scan frame after a dwell: its worst error [um] over ``[first, stop)`` and the worst
    error over the last ``SCAN_TAIL`` of the frame before (``steady``)."""

    segment: int
    first: int
    stop: int
    worst: float
    steady: float

    @property
    def ratio(self):
        """``worst / steady``."""
        return self.worst / self.steady


def _samples(seconds, h):
    return int(round(seconds / h))


def motions(signal):
    """The profile's motions: ``(segment index, Segment)`` of every move and scan that changes
    the position (a move of size 0 is a hold)."""
    return [(i, s) for i, s in enumerate(signal.segments)
            if s.kind == "scan" or (s.kind == "move" and s.end != s.start)]


def move_windows(signal, n, h, settle=SETTLE):
    """``(segment index, first, stop)`` of every move's window: from its first sample to
    ``settle`` after its last, within the run's ``n`` samples."""
    tail = _samples(settle, h)
    return [(i, s.first, min(n, s.stop + tail)) for i, s in motions(signal)
            if s.kind == "move" and s.first < n]


def hold_windows(signal, n, h, settle=SETTLE):
    """``(first, stop, position)`` of every hold's window: from ``settle`` after the motion
    before it (or the run's start) to the next motion's first sample (or the run's end ``n``);
    windows that this leaves empty are left out."""
    tail = _samples(settle, h)
    out, after = [], 0           # after: where the motion before ended
    for _, s in motions(signal) + [(None, None)]:
        first = after + tail
        stop = n if s is None else min(n, s.first)
        if stop > first:
            out.append((first, stop, float(signal.evaluate([first * signal.step])[0])))
        if s is None:
            break
        after = s.stop
    return out


def scan_pairs(signal, n, h, tail=SCAN_TAIL):
    """``(segment index, (first, stop) of the frame, (first, stop) of the last ``tail`` of the
    frame before)`` for every scan that follows another scan with only holds between them."""
    out, prev = [], None
    for i, s in enumerate(signal.segments):
        if s.kind == "scan":
            if prev is not None and prev.stop < s.first and s.stop <= n:
                start = max(prev.first, prev.stop - _samples(tail, h))
                out.append((i, (s.first, s.stop), (start, prev.stop)))
            prev = s
        elif s.kind == "move" and s.end != s.start:
            prev = None
    return out


def sample_index(time, h):
    """The sample index ``k`` of rows recorded at ``time = k h``."""
    return np.rint(np.asarray(time, dtype=float) / h).astype(np.int64)


def _worst(k, err, first, stop):
    sel = (k >= first) & (k < stop)
    return float(np.max(err[sel])) if sel.any() else float("nan")


def move_errors(signal, time, y_d, y, h, settle=SETTLE):
    """A :class:`MoveError` per move of the profile, from a run's rows (``time``, ``y_d``,
    ``y``), whichever samples it recorded."""
    k = sample_index(time, h)
    err = np.abs(np.asarray(y_d) - np.asarray(y))
    n = int(k[-1]) + 1
    return [MoveError(i, a, b, _worst(k, err, a, b)) for i, a, b in move_windows(signal, n, h, settle)]


def hold_errors(signal, time, y_d, y, h, settle=SETTLE):
    """A :class:`HoldError` per hold window of the profile, from a run's rows."""
    k = sample_index(time, h)
    err = np.abs(np.asarray(y) - np.asarray(y_d))
    n = int(k[-1]) + 1
    return [HoldError(a, b, p, _worst(k, err, a, b)) for a, b, p in hold_windows(signal, n, h, settle)]


def scan_errors(signal, time, y_d, y, h, tail=SCAN_TAIL):
    """A :class:`ScanError` per scan frame after a dwell, from a run's rows."""
    k = sample_index(time, h)
    err = np.abs(np.asarray(y_d) - np.asarray(y))
    n = int(k[-1]) + 1
    return [ScanError(i, a, b, _worst(k, err, a, b), _worst(k, err, *before))
            for i, (a, b), before in scan_pairs(signal, n, h, tail)]
