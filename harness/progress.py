"""Progress lines on stderr: one per finished run, and within a long run.

A finished run prints ``[i/N] what: 1.23 s (total 4.5 s)``.  Within a run the
simulators call back after every simulated second; a line
``[i/N] what: 12 of 600 s simulated (3.1 s)`` is printed when at least
``interval`` seconds of wall time passed since the last line, so a 3 s run
stays silent and a 600 s run reports itself every few seconds.
"""

from __future__ import annotations

import time as _time

__all__ = ["Progress"]


class Progress:
    """Counts finished runs and reports them (and long runs) on a stream.

    Parameters
    ----------
    total : int
        Number of runs.
    stream : file-like or None
        Where the lines go; ``None`` is silent.
    interval : float
        Least wall time [s] between two lines within a run.
    """

    def __init__(self, total, stream, interval=2.0):
        self.total, self.stream, self.interval = total, stream, float(interval)
        self.i = 0
        self.start = _time.perf_counter()

    def _prefix(self):
        width = len(str(self.total))
        return f"[{self.i + 1:>{width}}/{self.total}]"

    def _write(self, line):
        if self.stream is not None:
            self.stream.write(line + "\n")
            self.stream.flush()

    def within(self, what, h):
        """A ``progress(done, n)`` callback for one simulation of the next run.

        Parameters
        ----------
        what : str
            How the simulation is named.
        h : float
            Sample period [s], to print simulated seconds.

        Returns
        -------
        callable or None
            ``report(done, n, part=None)``; ``part`` names one of several simulations
            of a run (e.g. "coupled model").  ``None`` when the stream is ``None``.
        """
        if self.stream is None:
            return None
        t0 = _time.perf_counter()
        last = [t0]

        def report(done, n, part=None):
            now = _time.perf_counter()
            if done >= n or now - last[0] < self.interval:
                return
            last[0] = now
            which = f" ({part})" if part else ""
            self._write(f"{self._prefix()} {what}{which}: {done * h:.0f} of {n * h:.6g} s "
                        f"simulated ({now - t0:.1f} s)")

        return report

    def note(self, line):
        """A free line (e.g. 'writing about 260 MB of time series')."""
        self._write(f"  {line}")

    def done(self, what, elapsed):
        """One run finished."""
        self.i += 1
        width = len(str(self.total))
        self._write(f"[{self.i:>{width}}/{self.total}] {what}: {elapsed:.2f} s "
                    f"(total {_time.perf_counter() - self.start:.1f} s)")
