"""Scenario definitions: built-in (paper Tables 1-5, docs/model.md, scenarios; stage use,
docs/stage_use.md) and user files.

A scenario file is TOML (read with :mod:`tomllib`).  It may define named
parameter sets and any number of scenarios::

    [parameter_sets.my_plant]          # optional, reusable override sets
    "creep.alpha" = -0.0085

    [[scenario]]
    name = "my_case"                   # required, [A-Za-z0-9_.-]+, not a known name
    kind = "tracking"                  # "tracking" (closed loop, y_d in um)
                                       # or "validation" (plant alone, v in V)
    description = "free text"          # optional
    extends = "track_5hz"              # optional: start from a known scenario
    duration = 3.0                     # [s], default 3.0
    step_size = 0.0005                 # [s], default 0.0005; must equal the FMUs' h
    metric_window = [1.0, 3.0]         # [s], half-open, default [0, duration)
    plant_set = "my_plant"             # optional, a parameter set's name
    controller_set = "..."             # optional (tracking only)
    plant = { "pi.w0" = 0.35 }         # optional overrides by FMU variable name
    controller = { "rls.forgetting" = 0.99 }   # tracking only

    # the signal: "reference" (y_d, tracking) or "input" (v, validation)
    reference = { type = "sines", amplitudes = [10.0], frequencies = [5.0],
                  phases = [0.0], offset = 0.0 }       # phases in rad
    # or
    reference = { type = "csv", file = "ref.csv" }     # path relative to the TOML file
    # or a stage-use profile (tracking only; docs/stage_use.md)
    reference = { type = "profile", start = 0.0, segments = [
        { hold = 0.2 },                                   # hold the position 0.2 s
        { move = 10.0 },                                  # a step of +10 um
        { move = 30.0, shape = "scurve", time = 0.05 },   # +30 um along an S-curve, 50 ms
        { to = 5.0, shape = "ramp", time = 0.1 },         # to 5 um along a ramp, 100 ms
        { scan = "triangle", frequency = 10.0, amplitude = 10.0, time = 2.0 },
        { scan = "sine", frequency = 1.0, amplitude = 10.0, time = 60.0 },
        { hold = 10.0 },
    ] }

A profile starts at ``start`` [um] (default 0) at t = 0 and runs its segments
in order, each from where the one before left the stage:

* ``hold = T``: the position, for T seconds;
* ``move = D`` (by D um) or ``to = P`` (to P um), ``shape = "step"`` (the
  default: the position jumps at the segment's first sample, no ``time``),
  ``"ramp"`` or ``"scurve"`` over ``time`` seconds: ``p + D c((t - t0)/time)``
  with c(s) = s (ramp) or the cycloid s - sin(2 pi s)/(2 pi) (S-curve: zero
  velocity and acceleration at both ends), reaching p + D at the next
  segment's first sample;
* ``scan = "triangle"`` or ``"sine"``, from the current position p over
  ``time`` seconds: p + A tri(f (t - t0)), tri rising from 0 to 1 in half a
  period and back (a raster line out and back, A < 0 scans downwards), or
  p + A sin(2 pi f (t - t0)); the next segment starts where it ends (p after
  whole periods).

Every time is a whole number of samples of ``step_size``, so each segment
begins on a sample; ``duration`` defaults to the profile's length (a longer
one holds the last position). The moves, the holds and the scans, and so the
windows of the stage-use metrics (where a move ends and a hold begins:
:mod:`harness.loop.profiles`), come from the profile itself. Segments are counted
from 1 in messages (``reference.segments[2].time``).

Rules a file is checked against (each broken rule is one error naming the
file, the scenario and the field):

* a name names one scenario: a user scenario may not reuse a built-in name
  or one defined by an earlier file (use ``extends`` to start from it);
* ``step_size`` is the sample period of the run and must equal the FMUs'
  ``h`` (0.0005 s unless the scenario sets ``"h"`` in ``plant`` and
  ``controller``): the harness exchanges values once per sample;
* every sine frequency must lie below the Nyquist frequency
  ``1 / (2 step_size)``, and so must a profile's scans;
* a profile's segments have exactly one of ``hold``, ``move``, ``to``,
  ``scan`` and only the keys that go with it; a step takes no ``time``, a
  ramp, an S-curve and a scan need one; its times are whole numbers of
  samples; a profile is a tracking reference; ``duration`` may not cut it;
* a validation scenario runs the plant alone, so it takes no controller
  overrides;
* paper values (``paper = {...}``: ``e_rms_um``/``e_r`` for tracking,
  ``hammerstein_*``/``coupled_*`` for validation) belong to the built-in
  scenarios of the paper's tables; a user file may not set them, and a user
  scenario that ``extends`` a built-in one does not inherit them.

The CSV holds two columns, time [s] and value, with an optional header line,
``time,y_d`` for a tracking reference [um] and ``time,v`` for a validation
input [V] (a unit may follow, e.g. ``time [s],y_d [um]``); time must be
strictly increasing and cover the run; values are linearly interpolated onto
the sample grid (held constant after the last row, which only matters for the
reference preview).

Override precedence: the base scenario (``extends``), then the named set,
then the scenario's own ``plant``/``controller`` tables.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field, replace
import math
from pathlib import Path
import re
import tomllib
from types import MappingProxyType
from typing import Mapping

import numpy as np

__all__ = [
    "Signal",
    "Scenario",
    "ScenarioError",
    "ScenarioFileError",
    "UnknownScenarioError",
    "DEFAULT_STEP_SIZE",
    "BUILTIN_FILES",
    "TRACKING_SCENARIOS",
    "MISMATCH_SCENARIOS",
    "VALIDATION_SCENARIOS",
    "Segment",
    "MOVE_SHAPES",
    "SCAN_SHAPES",
    "STAGE_USE_FILE",
    "PAPER_LAW_SET",
    "load_scenario_file",
    "load_scenarios",
    "parameter_set",
    "profile_signal",
    "stage_use_scenarios",
    "get_scenario",
    "list_scenarios",
    "format_scenario_list",
    "reference_label",
    "read_signal_csv",
]

DEFAULT_STEP_SIZE = 0.0005
DEFAULT_DURATION = 3.0
SCENARIO_DIR = Path(__file__).resolve().parent
BUILTIN_FILES = ("tracking.toml", "validation.toml", "mismatch.toml", "stage_use.toml")
#: the built-in file of the stage-use scenarios (docs/stage_use.md), and its parameter set of
#: the paper's adaptation law
STAGE_USE_FILE = "stage_use.toml"
PAPER_LAW_SET = "paper_law"

TRACKING_SCENARIOS = (
    "track_1hz",
    "track_5hz",
    "track_10hz",
    "track_20hz",
    "track_1_5_10hz",
    "track_1_10_20hz",
)
MISMATCH_SCENARIOS = tuple(n.replace("track_", "mismatch_") for n in TRACKING_SCENARIOS)
VALIDATION_SCENARIOS = (
    "validate_1hz",
    "validate_10hz",
    "validate_20hz",
    "validate_50hz",
    "validate_100hz",
    "validate_5_40_80hz",
)

_KINDS = ("tracking", "validation")
_SIGNAL_KEY = {"tracking": "reference", "validation": "input"}
_NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")
_PARAM_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?(\.[A-Za-z_][A-Za-z0-9_]*(\[[0-9]+\])?)*$")
_SCENARIO_KEYS = {
    "name", "kind", "description", "extends", "duration", "step_size", "metric_window",
    "plant_set", "controller_set", "plant", "controller", "paper", "reference", "input",
}
_PAPER_KEYS = {
    "e_rms_um", "e_r",
    "hammerstein_e_rms_um", "coupled_e_rms_um", "hammerstein_e_r", "coupled_e_r",
}


class ScenarioError(Exception):
    """Base class of the scenario errors."""


class ScenarioFileError(ScenarioError, ValueError):
    """A scenario file or reference CSV is malformed.

    The message names the file, the scenario and field (when known) and
    what is wrong.
    """

    def __init__(self, path, message, scenario=None, field=None):
        self.path = None if path is None else str(path)
        self.scenario = scenario
        self.field = field
        where = [] if self.path is None else [self.path]
        if scenario is not None:
            where.append(f"scenario '{scenario}'")
        if field is not None:
            where.append(f"field '{field}'")
        super().__init__((": ".join(where) + ": " if where else "") + message)


class UnknownScenarioError(ScenarioError, KeyError):
    """The requested scenario name is not known; the message lists the known names."""

    def __init__(self, name, known):
        self.name = name
        self.known = tuple(known)
        super().__init__(f"unknown scenario '{name}'; known scenarios: {', '.join(self.known)}")

    def __str__(self):  # KeyError would quote the message
        return self.args[0]


#: the shapes of a profile's moves and scans (see the module docstring)
MOVE_SHAPES = ("step", "ramp", "scurve")
SCAN_SHAPES = ("triangle", "sine")


@dataclass(frozen=True)
class Segment:
    """One segment of a profile reference, placed on the sample grid.

    Attributes
    ----------
    kind : {"hold", "move", "scan"}
    shape : str
        A move's ``"step"``, ``"ramp"`` or ``"scurve"``, a scan's ``"triangle"`` or ``"sine"``;
        ``""`` for a hold.
    first : int
        The sample at which the segment begins (``t = first h``).
    samples : int
        Its length in samples (0 for a step: the position jumps at ``first``).
    start, end : float
        The position [um] where it begins and where it leaves the next segment.
    frequency, amplitude : float
        A scan's [Hz] and [um] (0 otherwise).
    """

    kind: str
    shape: str
    first: int
    samples: int
    start: float
    end: float
    frequency: float = 0.0
    amplitude: float = 0.0

    @property
    def stop(self):
        """The sample after its last one (``first + samples``)."""
        return self.first + self.samples

    def values(self, x, h):
        """The positions at sample times ``x`` (in samples, ``first <= x < stop``; ``h`` the
        sample period [s])."""
        u = np.asarray(x, dtype=float) - self.first
        if self.kind == "hold":
            return np.full(u.shape, self.start)
        if self.kind == "move":
            s = u / self.samples
            c = s if self.shape == "ramp" else s - np.sin(2.0 * np.pi * s) / (2.0 * np.pi)
            return self.start + (self.end - self.start) * c
        # scans from their own start position, time (u h) from the segment's start
        phase = self.frequency * u * h
        if self.shape == "sine":
            return self.start + self.amplitude * np.sin(2.0 * np.pi * phase)
        return self.start + self.amplitude * (1.0 - np.abs(1.0 - 2.0 * (phase - np.floor(phase))))


@dataclass(frozen=True)
class Signal:
    """A scenario's signal: desired displacement ``y_d`` [um] or input voltage ``v`` [V].

    Attributes
    ----------
    kind : {"sines", "table", "profile"}
        Sum of sines plus offset, a table interpolated linearly, or a stage-use profile
        (holds, moves and scans, on the sample grid).
    amplitudes, frequencies, phases : tuple of float
        Sine parameters (frequencies in Hz, phases in rad); empty for a table.
    offset : float
        Constant added to the sines; a profile's start position.
    table_time, table_value : tuple of float
        Table rows (``kind == "table"``).
    source : str
        Where the signal came from (CSV path for a table).
    segments : tuple of Segment
        A profile's segments, in order (``kind == "profile"``).
    step : float
        A profile's sample period [s] (the scenario's ``step_size``).
    """

    kind: str
    amplitudes: tuple = ()
    frequencies: tuple = ()
    phases: tuple = ()
    offset: float = 0.0
    table_time: tuple = ()
    table_value: tuple = ()
    source: str = ""
    segments: tuple = ()
    step: float = 0.0

    @property
    def samples(self):
        """A profile's length in samples (the sum of its segments')."""
        return self.segments[-1].stop if self.segments else 0

    def evaluate(self, time):
        """Evaluate the signal at the given times.

        Parameters
        ----------
        time : array_like
            Times [s].

        Returns
        -------
        ndarray of float
        """
        return SIGNAL_KINDS[self.kind].evaluate(self, np.asarray(time, dtype=float))

    def describe(self):
        """Return a short human-readable description."""
        return SIGNAL_KINDS[self.kind].describe(self)

    @property
    def internal(self):
        """ReferenceSignal plays it (its parameters carry it): the FMUs' internal reference,
        the SSP's and the closed-loop FMU's; otherwise a master feeds it as the input y_d."""
        return SIGNAL_KINDS[self.kind].internal


def _evaluate_sines(sig, t):
    out = np.full(t.shape, float(sig.offset))
    for a, f, p in zip(sig.amplitudes, sig.frequencies, sig.phases):
        out += a * np.sin(2.0 * np.pi * f * t + p)
    return out


def _evaluate_table(sig, t):
    return np.interp(t, np.asarray(sig.table_time), np.asarray(sig.table_value))


def _evaluate_profile(sig, t):
    # in samples, a time on the grid snapped to its integer k (k h / h may miss k by an ulp)
    x = t / sig.step
    near = np.rint(x)
    x = np.where(np.abs(x - near) < 1e-6, near, x)
    out = np.full(x.shape, float(sig.segments[-1].end))
    out[x < 0] = sig.offset
    if x.ndim == 1 and x.size > 1 and np.all(x[1:] >= x[:-1]):
        # times in order (a run's grid): each segment is one slice, found by bisection, so an
        # hour of a thousand segments costs as much as one (the same values as the masks)
        for seg in sig.segments:
            lo, hi = np.searchsorted(x, seg.first, "left"), np.searchsorted(x, seg.stop, "left")
            if hi > lo:
                out[lo:hi] = seg.values(x[lo:hi], sig.step)
        return out
    for seg in sig.segments:
        inside = (x >= seg.first) & (x < seg.stop)
        if inside.any():
            out[inside] = seg.values(x[inside], sig.step)
    return out


def _describe_sines(sig):
    terms = " + ".join(f"{a:g} sin(2 pi {f:g} t{'' if p == 0 else f' + {p:g}'})"
                       for a, f, p in zip(sig.amplitudes, sig.frequencies, sig.phases))
    return terms + (f" + {sig.offset:g}" if sig.offset else "")


def _describe_table(sig):
    return f"table {sig.source} ({len(sig.table_time)} rows)"


def _describe_profile(sig):
    return "profile: " + ", ".join(_segment_text(s, sig.step) for s in sig.segments)


def _segment_text(seg, h):
    """'hold 0.2 s', 'step +10 um', 'scurve +30 um in 0.05 s', 'triangle 10 Hz 10 um for 2 s'."""
    secs = f"{seg.samples * h:g} s"
    if seg.kind == "hold":
        return f"hold {secs}"
    if seg.kind == "move":
        size = f"{seg.end - seg.start:+g} um"
        return f"step {size}" if seg.shape == "step" else f"{seg.shape} {size} in {secs}"
    return f"{seg.shape} {seg.frequency:g} Hz {seg.amplitude:g} um for {secs}"


@dataclass(frozen=True)
class Scenario:
    """One simulation scenario.

    Attributes
    ----------
    name : str
    kind : {"tracking", "validation"}
        Tracking runs the closed loop with ``signal`` as ``y_d`` [um];
        validation runs the plant alone with ``signal`` as ``v`` [V].
    description : str
    signal : Signal
    duration : float
        Run length [s]; the run has ``n_samples = round(duration / step_size)`` rows.
    step_size : float
        Sample period h [s].
    metric_window : tuple of float
        Half-open window ``[start, stop)`` [s] of the metrics.
    plant, controller : Mapping[str, bool | int | float]
        Parameter overrides by FMU variable name.
    paper : Mapping[str, float]
        Paper values (``e_rms_um``/``e_r`` for tracking; ``hammerstein_*`` and
        ``coupled_*`` for validation); ``e_r`` as a fraction.
    source : str
        File the scenario was read from.
    """

    name: str
    kind: str
    description: str
    signal: Signal
    duration: float = DEFAULT_DURATION
    step_size: float = DEFAULT_STEP_SIZE
    metric_window: tuple = (0.0, DEFAULT_DURATION)
    plant: Mapping = field(default_factory=lambda: MappingProxyType({}))
    controller: Mapping = field(default_factory=lambda: MappingProxyType({}))
    paper: Mapping = field(default_factory=lambda: MappingProxyType({}))
    source: str = ""

    @property
    def n_samples(self):
        """Number of samples (rows) of a run."""
        return int(round(self.duration / self.step_size))

    def time_grid(self, n=None):
        """Sample times ``k h`` for ``k = 0 .. n-1`` (integer counter, no accumulation)."""
        n = self.n_samples if n is None else int(n)
        return np.arange(n, dtype=float) * self.step_size

    def with_overrides(self, plant=None, controller=None, **changes):
        """Return a copy with extra parameter overrides (and other field changes)."""
        p = dict(self.plant)
        p.update(plant or {})
        c = dict(self.controller)
        c.update(controller or {})
        return replace(self, plant=MappingProxyType(p), controller=MappingProxyType(c), **changes)


# ---------------------------------------------------------------------------
# CSV reference tables
# ---------------------------------------------------------------------------

def read_signal_csv(path, value_name="value"):
    """Read a two-column CSV (time, value) with an optional header.

    Parameters
    ----------
    path : str or Path
    value_name : str
        Name used in messages (``y_d`` or ``v``).

    Returns
    -------
    time, value : ndarray

    Raises
    ------
    ScenarioFileError
        Missing/unreadable file, wrong number of columns, non-numeric or
        non-finite entry, fewer than two rows, or time not strictly increasing.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ScenarioFileError(path, f"cannot read the CSV file ({exc.strerror or exc})") from None
    times, values = [], []
    rows = list(csv.reader(text.splitlines()))
    first_data = True
    for lineno, row in enumerate(rows, start=1):
        cells = [c.strip() for c in row]
        if not cells or all(c == "" for c in cells) or cells[0].startswith("#"):
            continue
        if len(cells) != 2:
            raise ScenarioFileError(
                path, f"line {lineno}: expected 2 columns (time,{value_name}), found {len(cells)}")
        try:
            t, y = float(cells[0]), float(cells[1])
        except ValueError:
            if first_data and not times:
                _check_csv_header(cells, path, lineno, value_name)
                first_data = False
                continue
            bad = cells[0] if not _is_float(cells[0]) else cells[1]
            raise ScenarioFileError(path, f"line {lineno}: '{bad}' is not a number") from None
        first_data = False
        if not (math.isfinite(t) and math.isfinite(y)):
            raise ScenarioFileError(path, f"line {lineno}: non-finite value")
        if times and not t > times[-1]:
            raise ScenarioFileError(
                path, f"line {lineno}: time {t:g} is not greater than the previous {times[-1]:g} "
                      f"(time must be strictly increasing)")
        times.append(t)
        values.append(y)
    if len(times) < 2:
        raise ScenarioFileError(path, f"needs at least 2 data rows (time,{value_name}), found {len(times)}")
    return np.asarray(times), np.asarray(values)


#: Accepted header names of the time column, after lower-casing and dropping a unit.
_TIME_HEADERS = ("time", "t")
#: What each signal's value column is, for the header check's message.
_VALUE_MEANING = {"y_d": "the desired displacement y_d [um] of a tracking reference",
                  "v": "the input voltage v [V] of a validation input"}
_UNIT_RE = re.compile(r"\s*(\[[^\]]*\]|\([^)]*\))$|_(s|um|µm|v)$", re.IGNORECASE)


def _header_name(cell):
    """A header cell without its unit: 'time [s]', 'time_s', 'y_d (um)' -> 'time', 'time', 'y_d'."""
    return _UNIT_RE.sub("", cell.strip()).strip().lower()


def _check_csv_header(cells, path, lineno, value_name):
    """Refuse a header that does not say ``time,<value_name>`` (e.g. a voltage file as a reference)."""
    if _is_float(cells[0]):      # a data row with a bad value, not a header
        raise ScenarioFileError(path, f"line {lineno}: '{cells[1]}' is not a number")
    time_name, value = _header_name(cells[0]), _header_name(cells[1])
    expected = f"time,{value_name}"
    if time_name not in _TIME_HEADERS:
        raise ScenarioFileError(
            path, f"line {lineno}: header's first column must be 'time', found '{cells[0]}' "
                  f"(expected header '{expected}')")
    if value_name in _VALUE_MEANING and value != value_name.lower():
        raise ScenarioFileError(
            path, f"line {lineno}: header's second column is '{cells[1]}', expected "
                  f"'{value_name}': this file must hold {_VALUE_MEANING[value_name]}")


def _is_float(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------
# TOML parsing
# ---------------------------------------------------------------------------

def _check_params(table, path, scenario, fieldname):
    if not isinstance(table, dict):
        raise ScenarioFileError(path, "must be a table of FMU variable name = value",
                                scenario, fieldname)
    out = {}
    for key, value in table.items():
        if isinstance(value, dict):
            raise ScenarioFileError(
                path, f"'{key}' is a table; quote dotted names, e.g. \"{key}.x\" = 1.0",
                scenario, fieldname)
        if not _PARAM_RE.match(key):
            raise ScenarioFileError(path, f"'{key}' is not a valid FMU variable name",
                                    scenario, fieldname)
        if isinstance(value, bool):
            out[key] = value
        elif isinstance(value, int):
            out[key] = value
        elif isinstance(value, float):
            if not math.isfinite(value):
                raise ScenarioFileError(path, f"'{key}' must be finite, got {value}",
                                        scenario, fieldname)
            out[key] = value
        else:
            raise ScenarioFileError(
                path, f"'{key}' must be a number or a boolean, got {type(value).__name__} {value!r}",
                scenario, fieldname)
    return out


def _number(value, path, scenario, fieldname, positive=False, nonneg=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioFileError(path, f"must be a finite number, got {value!r}", scenario, fieldname)
    if positive and not value > 0:
        raise ScenarioFileError(path, f"must be > 0, got {value!r}", scenario, fieldname)
    if nonneg and value < 0:
        raise ScenarioFileError(path, f"must be >= 0, got {value!r}", scenario, fieldname)
    return float(value)


def _number_list(value, path, scenario, fieldname, nonneg=False):
    if not isinstance(value, list) or not value:
        raise ScenarioFileError(path, f"must be a non-empty list of numbers, got {value!r}",
                                scenario, fieldname)
    return tuple(_number(v, path, scenario, fieldname, nonneg=nonneg) for v in value)


def _parse_signal(spec, path, scenario, fieldname, value_name):
    types = ", ".join(f'"{k.file_type}"' for k in SIGNAL_KINDS.values())
    if not isinstance(spec, dict):
        raise ScenarioFileError(path, f"must be a table with a 'type' key ({types})", scenario,
                                fieldname)
    kind = next((k for k in SIGNAL_KINDS.values() if k.file_type == spec.get("type")), None)
    if kind is None:
        raise ScenarioFileError(path, f"'type' must be one of {types}, got {spec.get('type')!r}",
                                scenario, fieldname)
    if kind.tracking_only and value_name != "y_d":
        others = " or ".join(f'"{k.file_type}"' for k in SIGNAL_KINDS.values() if not k.tracking_only)
        raise ScenarioFileError(path, f"a {kind.file_type} is a tracking reference (y_d in um); a "
                                      f"validation input takes {others}", scenario, f"{fieldname}.type")
    return kind.parse(spec, path, scenario, fieldname, value_name)


def _parse_sines(spec, path, scenario, fieldname, value_name):
    allowed = {"type", "amplitudes", "frequencies", "phases", "offset"}
    _reject_unknown(spec, allowed, path, scenario, fieldname)
    for key in ("amplitudes", "frequencies"):
        if key not in spec:
            raise ScenarioFileError(path, "missing (required for type = \"sines\")",
                                    scenario, f"{fieldname}.{key}")
    amps = _number_list(spec["amplitudes"], path, scenario, f"{fieldname}.amplitudes")
    freqs = _number_list(spec["frequencies"], path, scenario, f"{fieldname}.frequencies",
                         nonneg=True)
    phases = (_number_list(spec["phases"], path, scenario, f"{fieldname}.phases")
              if "phases" in spec else (0.0,) * len(amps))
    if not len(amps) == len(freqs) == len(phases):
        raise ScenarioFileError(
            path, f"amplitudes, frequencies and phases must have the same length "
                  f"(got {len(amps)}, {len(freqs)}, {len(phases)})", scenario, fieldname)
    offset = _number(spec.get("offset", 0.0), path, scenario, f"{fieldname}.offset")
    return Signal("sines", amps, freqs, phases, offset, source=str(path))


def _parse_csv(spec, path, scenario, fieldname, value_name):
    _reject_unknown(spec, {"type", "file"}, path, scenario, fieldname)
    file = spec.get("file")
    if not isinstance(file, str) or not file:
        raise ScenarioFileError(path, "missing or not a string (path of the CSV file)",
                                scenario, f"{fieldname}.file")
    csv_path = Path(file)
    if not csv_path.is_absolute() and path is not None:
        csv_path = Path(path).resolve().parent / csv_path
    try:
        t, y = read_signal_csv(csv_path, value_name)
    except ScenarioFileError as exc:    # name the scenario that wants the CSV, too
        raise ScenarioFileError(path, str(exc), scenario, f"{fieldname}.file") from None
    return Signal("table", table_time=tuple(t.tolist()), table_value=tuple(y.tolist()),
                  source=str(csv_path))


#: what one segment of a profile may hold, by the key that names its kind
_SEGMENT_KEYS = {"hold": {"hold"}, "move": {"move", "shape", "time"}, "to": {"to", "shape", "time"},
                 "scan": {"scan", "frequency", "amplitude", "time"}}


@dataclass(frozen=True)
class _ProfileSpec:
    """A profile as written (times in s), placed on the grid once the step is known."""

    kind = "profile"        # its SignalKind (not a field)

    start: float
    items: tuple        # (field, kind, shape, seconds, change or target, absolute, f, a)
    source: str


def _parse_profile(spec, path, scenario, fieldname):
    """The profile's table checked key by key (times are placed on the grid later, by
    :func:`_place_profile`, when the scenario's step is known)."""
    _reject_unknown(spec, {"type", "start", "segments"}, path, scenario, fieldname)
    start = _number(spec.get("start", 0.0), path, scenario, f"{fieldname}.start")
    segs = spec.get("segments")
    if not isinstance(segs, list) or not segs:
        raise ScenarioFileError(path, f"must be a non-empty list of segments ({{hold = ...}}, "
                                      f"{{move = ...}}, {{to = ...}}, {{scan = ...}}), got {segs!r}",
                                scenario, f"{fieldname}.segments")
    items = []
    for i, seg in enumerate(segs, start=1):
        where = f"{fieldname}.segments[{i}]"
        if not isinstance(seg, dict):
            raise ScenarioFileError(path, f"must be a table, got {seg!r}", scenario, where)
        kinds = [k for k in _SEGMENT_KEYS if k in seg]
        if len(kinds) != 1:
            raise ScenarioFileError(
                path, f"must have exactly one of 'hold', 'move', 'to', 'scan' (has "
                      f"{', '.join(repr(k) for k in kinds) or 'none'})", scenario, where)
        key = kinds[0]
        _reject_unknown(seg, _SEGMENT_KEYS[key], path, scenario, where)
        if key == "hold":
            secs = _number(seg["hold"], path, scenario, f"{where}.hold", positive=True)
            items.append((where, "hold", "", secs, 0.0, False, 0.0, 0.0))
        elif key in ("move", "to"):
            value = _number(seg[key], path, scenario, f"{where}.{key}")
            shape = seg.get("shape", "step")
            if shape not in MOVE_SHAPES:
                raise ScenarioFileError(path, f"must be one of {', '.join(map(repr, MOVE_SHAPES))}, "
                                              f"got {shape!r}", scenario, f"{where}.shape")
            if shape == "step":
                if "time" in seg:
                    raise ScenarioFileError(path, "a step takes no time (it jumps at the segment's "
                                                  "first sample); use shape = \"ramp\" or \"scurve\"",
                                            scenario, f"{where}.time")
                secs = 0.0
            elif "time" not in seg:
                raise ScenarioFileError(path, f"missing (required for shape = \"{shape}\")",
                                        scenario, f"{where}.time")
            else:
                secs = _number(seg["time"], path, scenario, f"{where}.time", positive=True)
            items.append((where, "move", shape, secs, value, key == "to", 0.0, 0.0))
        else:
            shape = seg["scan"]
            if shape not in SCAN_SHAPES:
                raise ScenarioFileError(path, f"must be one of {', '.join(map(repr, SCAN_SHAPES))}, "
                                              f"got {shape!r}", scenario, f"{where}.scan")
            for k in ("frequency", "amplitude", "time"):
                if k not in seg:
                    raise ScenarioFileError(path, "missing (required for a scan)", scenario, f"{where}.{k}")
            f = _number(seg["frequency"], path, scenario, f"{where}.frequency", positive=True)
            a = _number(seg["amplitude"], path, scenario, f"{where}.amplitude")
            secs = _number(seg["time"], path, scenario, f"{where}.time", positive=True)
            items.append((where, "scan", shape, secs, 0.0, False, f, a))
    return _ProfileSpec(start, tuple(items), "" if path is None else str(path))


def _place_profile(spec, step, path, scenario):
    """The profile's segments on the grid of ``step``: every time a whole number of samples,
    every scan below the Nyquist frequency; a Signal of kind "profile"."""
    nyquist = 0.5 / step
    first, position, out = 0, spec.start, []
    for where, kind, shape, secs, value, absolute, f, a in spec.items:
        m = int(round(secs / step))
        if abs(m * step - secs) > 1e-9 * max(1.0, secs) or (secs > 0 and m < 1):
            name = {"hold": "hold"}.get(kind, "time")
            raise ScenarioFileError(path, f"{secs:g} s is not a whole number of samples of step_size "
                                          f"{step:g} s", scenario, f"{where}.{name}")
        if kind == "hold":
            end = position
        elif kind == "move":
            end = value if absolute else position + value
        else:
            if f >= nyquist:
                raise ScenarioFileError(
                    path, f"{f:g} Hz is at or above the Nyquist frequency {nyquist:g} Hz of step_size "
                          f"{step:g} s", scenario, f"{where}.frequency")
            seg = Segment(kind, shape, first, m, position, position, f, a)
            end = float(seg.values([first + m], step)[0])
        out.append(Segment(kind, shape, first, m, position, end, f, a))
        first, position = first + m, end
    if first == 0:
        raise ScenarioFileError(path, "the profile lasts no time (give it a hold, a timed move or a "
                                      "scan)", scenario, "reference.segments")
    return Signal("profile", offset=spec.start, source=spec.source, segments=tuple(out), step=step)


def profile_signal(segments, start=0.0, step=DEFAULT_STEP_SIZE):
    """A profile reference from its segments, as a scenario file writes them.

    Parameters
    ----------
    segments : list of dict
        ``{"hold": 0.2}``, ``{"move": 10.0, "shape": "scurve", "time": 0.05}``, ``{"to": 5.0}``,
        ``{"scan": "triangle", "frequency": 10.0, "amplitude": 10.0, "time": 2.0}``, ...
    start : float
        The start position [um].
    step : float
        The sample period [s].

    Returns
    -------
    Signal

    Raises
    ------
    ScenarioFileError
        As for a file (without a file's name).
    """
    spec = _parse_profile({"type": "profile", "start": start, "segments": list(segments)}, None,
                          None, "reference")
    return _place_profile(spec, float(step), None, None)


def _regrid_profile(signal, step, path, scenario):
    """An inherited profile on another step (``extends`` with a new ``step_size``)."""
    items = []
    for i, seg in enumerate(signal.segments, start=1):
        where = f"reference.segments[{i}]"
        secs = seg.samples * signal.step
        if seg.kind == "move":
            items.append((where, "move", seg.shape, secs, seg.end, True, 0.0, 0.0))
        else:
            items.append((where, seg.kind, seg.shape, secs, 0.0, False, seg.frequency, seg.amplitude))
    return _place_profile(_ProfileSpec(signal.offset, tuple(items), signal.source), step, path, scenario)


def _reject_unknown(table, allowed, path, scenario, fieldname):
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ScenarioFileError(
            path, f"unknown key(s) {', '.join(repr(u) for u in unknown)}; allowed: "
                  f"{', '.join(sorted(allowed))}", scenario, fieldname)


def _parse_scenario(entry, index, path, known, sets, builtin=False):
    label = f"#{index + 1}"
    if not isinstance(entry, dict):
        raise ScenarioFileError(path, "each [[scenario]] must be a table", label)
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ScenarioFileError(path, f"missing or invalid (letters, digits, _ . -), got {name!r}",
                                label, "name")
    _reject_unknown(entry, _SCENARIO_KEYS, path, name, None)

    base = None
    if "extends" in entry:
        base_name = entry["extends"]
        if base_name not in known:
            raise ScenarioFileError(
                path, f"'{base_name}' is not a known scenario (known: {', '.join(known)})",
                name, "extends")
        base = known[base_name]

    kind = entry.get("kind", base.kind if base else None)
    if kind is None:
        raise ScenarioFileError(path, "missing; must be \"tracking\" or \"validation\"",
                                name, "kind")
    if kind not in _KINDS:
        raise ScenarioFileError(path, f"must be \"tracking\" or \"validation\", got {kind!r}",
                                name, "kind")
    description = entry.get("description", base.description if base else "")
    if not isinstance(description, str):
        raise ScenarioFileError(path, "must be a string", name, "description")

    sig_key = _SIGNAL_KEY[kind]
    wrong_key = _SIGNAL_KEY["validation" if kind == "tracking" else "tracking"]
    if wrong_key in entry:
        raise ScenarioFileError(
            path, f"a {kind} scenario takes '{sig_key}', not '{wrong_key}'", name, wrong_key)
    if sig_key in entry:
        signal = _parse_signal(entry[sig_key], path, name, sig_key,
                               "y_d" if kind == "tracking" else "v")
    elif base is not None and base.kind == kind:
        signal = base.signal
    else:
        raise ScenarioFileError(path, "missing (the scenario's signal)", name, sig_key)

    step = _number(entry.get("step_size", base.step_size if base else DEFAULT_STEP_SIZE),
                   path, name, "step_size", positive=True)
    signal_kind = SIGNAL_KINDS[signal.kind]
    signal = signal_kind.place(signal, step, path, name)
    own = signal_kind.length(signal) if sig_key in entry else None
    if own is not None:
        default_duration = round(own * step, 9)     # the signal's own length (a profile's)
    else:
        default_duration = base.duration if base else DEFAULT_DURATION
    duration = _number(entry.get("duration", default_duration), path, name, "duration", positive=True)
    n = round(duration / step)
    if n < 1 or abs(n * step - duration) > 1e-9 * max(1.0, duration):
        raise ScenarioFileError(
            path, f"duration {duration:g} s is not a whole number of steps of {step:g} s",
            name, "duration")
    if "metric_window" in entry:
        win = entry["metric_window"]
        if not isinstance(win, list) or len(win) != 2:
            raise ScenarioFileError(path, f"must be [start, stop] in s, got {win!r}",
                                    name, "metric_window")
        window = tuple(_number(w, path, name, "metric_window") for w in win)
    elif base is not None:
        window = (base.metric_window[0], min(base.metric_window[1], duration))
        if not window[0] < window[1]:
            raise ScenarioFileError(
                path, f"the window [{base.metric_window[0]:g}, {base.metric_window[1]:g}] s "
                      f"inherited from '{base.name}' is empty for duration {duration:g} s; "
                      f"set metric_window", name, "metric_window")
    else:
        window = (0.0, duration)
    if not (0.0 <= window[0] < window[1] <= duration + 1e-12):
        raise ScenarioFileError(
            path, f"must satisfy 0 <= start < stop <= duration ({duration:g} s), got "
                  f"[{window[0]:g}, {window[1]:g}]", name, "metric_window")

    if kind == "validation":
        given = [k for k in ("controller", "controller_set") if k in entry]
        if given:
            raise ScenarioFileError(
                path, "a validation scenario runs the plant alone: controller overrides do not "
                      "apply (remove them, or make it a tracking scenario)", name, given[0])
        if base is not None and base.controller:
            raise ScenarioFileError(
                path, f"'{base.name}' has controller overrides, which do not apply to a "
                      f"validation scenario (the plant runs alone)", name, "extends")
    params = {}
    for which in ("plant", "controller"):
        merged = dict(getattr(base, which)) if base else {}
        set_key = f"{which}_set"
        if set_key in entry:
            set_name = entry[set_key]
            if set_name not in sets:
                raise ScenarioFileError(
                    path, f"'{set_name}' is not a known parameter set (known: "
                          f"{', '.join(sorted(sets)) or 'none'})", name, set_key)
            merged.update(sets[set_name])
        if which in entry:
            merged.update(_check_params(entry[which], path, name, which))
        params[which] = MappingProxyType(merged)

    _check_sample_period(step, params, kind, path, name, "step_size" in entry)

    # Paper values belong to the paper's own (built-in) scenarios: a user scenario
    # that extends one is a different experiment and must not be shown next to them.
    paper = dict(base.paper) if base is not None and builtin else {}
    if "paper" in entry and not builtin:
        raise ScenarioFileError(
            path, "paper values belong to the built-in scenarios of the paper's tables; a user "
                  "scenario is reported without them (remove this table)", name, "paper")
    if "paper" in entry:
        table = entry["paper"]
        if not isinstance(table, dict):
            raise ScenarioFileError(path, "must be a table", name, "paper")
        _reject_unknown(table, _PAPER_KEYS, path, name, "paper")
        for key, value in table.items():
            paper[key] = _number(value, path, name, f"paper.{key}", nonneg=True)

    signal_kind.check(signal, step, duration, path, name, sig_key)

    return Scenario(
        name=name, kind=kind, description=description, signal=signal, duration=duration,
        step_size=step, metric_window=window, plant=params["plant"],
        controller=params["controller"], paper=MappingProxyType(paper), source=str(path),
    )


#: Relative tolerance of the sample-period check (h is written with a few digits).
_H_RTOL = 1e-9


def _check_sample_period(step, params, kind, path, name, step_given):
    """``step_size`` must be the FMUs' sample period h: the harness exchanges values once per
    sample, so any other step would silently resample the reference and hold the inputs."""
    models = [("plant", "PiezoStage")]
    if kind == "tracking":
        models.append(("controller", "AdaptiveCompoundController"))
    for which, model in models:
        h = params[which].get("h", DEFAULT_STEP_SIZE)
        if isinstance(h, bool) or abs(float(h) - step) > _H_RTOL * step:
            where = (f"its {which} override \"h\" = {h!r}" if "h" in params[which]
                     else f"h = {DEFAULT_STEP_SIZE:g} s, the {model} default")
            hint = (f"set step_size = {float(h):g}" if not isinstance(h, bool) else "fix \"h\"")
            raise ScenarioFileError(
                path, f"step_size {step:g} s differs from the sample period of {model} "
                      f"({where}); the run steps once per sample: {hint}, or set \"h\" in plant "
                      f"and controller to change the sample period",
                name, "step_size" if step_given else which)


def _check_nyquist(signal, step, duration, path, name, fieldname):
    """Every tone must lie below the Nyquist frequency of the sample grid."""
    nyquist = 0.5 / step
    for f, a in zip(signal.frequencies, signal.amplitudes):
        if a != 0 and f >= nyquist:
            raise ScenarioFileError(
                path, f"{f:g} Hz is at or above the Nyquist frequency {nyquist:g} Hz of "
                      f"step_size {step:g} s: its samples alias to a different tone",
                name, f"{fieldname}.frequencies")


def _check_table_covers(signal, step, duration, path, name, fieldname):
    """The table must cover every sample time of the run."""
    t0, t1 = signal.table_time[0], signal.table_time[-1]
    last = (round(duration / step) - 1) * step
    if t0 > 1e-12 or t1 < last - 1e-9:
        raise ScenarioFileError(
            path, f"the table {signal.source} covers [{t0:g}, {t1:g}] s but the run needs "
                  f"[0, {last:g}] s", name, fieldname)


def _check_profile_length(signal, step, duration, path, name, fieldname):
    """The run must not cut the profile (a longer one holds its last position)."""
    if round(duration / step) < signal.samples:
        raise ScenarioFileError(
            path, f"duration {duration:g} s would cut the profile, which lasts "
                  f"{signal.samples * step:g} s (leave duration out: it defaults to the profile's "
                  f"length; a longer one holds the last position)", name, "duration")


def _place_profile_on(signal, step, path, name):
    """A profile as written placed on the step's grid, or a placed one moved to another grid."""
    if isinstance(signal, _ProfileSpec):
        return _place_profile(signal, step, path, name)
    return _regrid_profile(signal, step, path, name) if signal.step != step else signal


def _placed_as_it_is(signal, step, path, name):
    """A :class:`SignalKind`'s ``place`` unless it has its own: the signal serves any grid as it is."""
    return signal


def _no_length_of_its_own(signal):
    """A :class:`SignalKind`'s ``length`` unless it has its own: None (the scenario's duration)."""
    return None


@dataclass(frozen=True)
class SignalKind:
    """One kind of signal, everything about it in one place (:data:`SIGNAL_KINDS`).

    Attributes
    ----------
    name : str
        :attr:`Signal.kind`.
    file_type : str
        Its ``type`` in a scenario file.
    internal : bool
        ReferenceSignal plays it (:attr:`Signal.internal`).
    tracking_only : bool
        Only a tracking reference (``y_d``) may be of this kind.
    parse : callable
        ``parse(spec, path, scenario, fieldname, value_name)``: the Signal (or a profile as
        written, which ``place`` puts on the grid) of a scenario file's table.
    evaluate, describe : callable
        ``evaluate(signal, t)``, ``describe(signal)``: :meth:`Signal.evaluate`, :meth:`Signal.describe`.
    check : callable
        ``check(signal, step, duration, path, scenario, fieldname)``: refuse a run it cannot
        serve (ScenarioFileError).
    place : callable
        ``place(signal, step, path, scenario)``: the signal on the scenario's sample grid.
    length : callable
        ``length(signal)``: its own length in samples (the default duration), or None.
    """

    name: str
    file_type: str
    internal: bool
    tracking_only: bool
    parse: object
    evaluate: object
    describe: object
    check: object
    place: object = _placed_as_it_is
    length: object = _no_length_of_its_own


#: every kind of signal a scenario may have, by :attr:`Signal.kind`: a new kind is one entry
SIGNAL_KINDS = {k.name: k for k in (
    SignalKind("sines", "sines", internal=True, tracking_only=False, parse=_parse_sines,
               evaluate=_evaluate_sines, describe=_describe_sines, check=_check_nyquist),
    SignalKind("table", "csv", internal=False, tracking_only=False, parse=_parse_csv,
               evaluate=_evaluate_table, describe=_describe_table, check=_check_table_covers),
    SignalKind("profile", "profile", internal=False, tracking_only=True,
               parse=lambda spec, path, scenario, fieldname, value_name:
                   _parse_profile(spec, path, scenario, fieldname),
               evaluate=_evaluate_profile, describe=_describe_profile, check=_check_profile_length,
               place=_place_profile_on, length=lambda signal: signal.samples),
)}


def load_scenario_file(path, known=None, parameter_sets=None, builtin=False):
    """Parse one scenario TOML file.

    Parameters
    ----------
    path : str or Path
    known : dict, optional
        Scenarios already known (for ``extends``); not modified.
    parameter_sets : dict, optional
        Parameter sets already known (for ``plant_set``/``controller_set``);
        updated in place with the file's ``[parameter_sets.*]``.
    builtin : bool
        The file is one of the built-in scenario files: it may set paper
        values, and ``extends`` inherits them.

    Returns
    -------
    dict of str to Scenario
        The file's scenarios, in file order.

    Raises
    ------
    ScenarioFileError
        Unreadable file, TOML syntax error, an invalid field, or a name that
        is already known.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ScenarioFileError(path, f"cannot read the scenario file ({exc.strerror or exc})") from None
    try:
        doc = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ScenarioFileError(path, f"not UTF-8 text ({exc.reason})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioFileError(path, f"TOML syntax error: {exc}") from None
    unknown = sorted(set(doc) - {"scenario", "parameter_sets"})
    if unknown:
        raise ScenarioFileError(
            path, f"unknown top-level key(s) {', '.join(repr(u) for u in unknown)}; "
                  f"expected [[scenario]] entries and optional [parameter_sets.NAME]")
    sets = parameter_sets if parameter_sets is not None else {}
    psets = doc.get("parameter_sets", {})
    if not isinstance(psets, dict):
        raise ScenarioFileError(path, "must be a table of tables", None, "parameter_sets")
    for set_name, table in psets.items():
        sets[set_name] = _check_params(table, path, None, f"parameter_sets.{set_name}")
    entries = doc.get("scenario", [])
    if not isinstance(entries, list):
        raise ScenarioFileError(path, "use [[scenario]] (an array of tables)", None, "scenario")
    if not entries and not psets:
        raise ScenarioFileError(path, "defines no [[scenario]]")
    known_now = dict(known or {})
    out = {}
    for i, entry in enumerate(entries):
        sc = _parse_scenario(entry, i, path, known_now, sets, builtin)
        if sc.name in out:
            raise ScenarioFileError(path, f"duplicate scenario name '{sc.name}'", sc.name, "name")
        if sc.name in (known or {}):
            other = known[sc.name]
            owner = ("a built-in scenario" if Path(other.source).parent == SCENARIO_DIR
                     else f"a scenario of {other.source}")
            raise ScenarioFileError(
                path, f"'{sc.name}' is already the name of {owner}; choose another name "
                      f"(extends = \"{sc.name}\" starts from it)", sc.name, "name")
        out[sc.name] = sc
        known_now[sc.name] = sc
    return out


_BUILTIN_CACHE = {}


def load_scenarios(files=(), include_builtin=True):
    """Load the built-in scenarios and, optionally, user files.

    Parameters
    ----------
    files : iterable of str or Path
        User scenario files, read in order (later files may ``extends``
        scenarios of earlier ones; no file may reuse a known name).
    include_builtin : bool
        Start from the built-in scenarios of ``harness/scenarios/``.

    Returns
    -------
    dict of str to Scenario
        Insertion-ordered registry.
    """
    registry = {}
    sets = {}
    if include_builtin:
        if not _BUILTIN_CACHE:
            b_reg, b_sets = {}, {}
            for fname in BUILTIN_FILES:
                b_reg.update(load_scenario_file(SCENARIO_DIR / fname, b_reg, b_sets,
                                                builtin=True))
            _BUILTIN_CACHE["registry"] = b_reg
            _BUILTIN_CACHE["sets"] = b_sets
        registry.update(_BUILTIN_CACHE["registry"])
        sets.update(_BUILTIN_CACHE["sets"])
    for f in files:
        registry.update(load_scenario_file(f, registry, sets))
    return registry


def parameter_set(name):
    """A built-in parameter set by name (a copy), e.g. :data:`PAPER_LAW_SET`.

    Raises
    ------
    KeyError
        No built-in set has that name (the message lists them).
    """
    load_scenarios()
    sets = _BUILTIN_CACHE["sets"]
    if name not in sets:
        raise KeyError(f"no built-in parameter set '{name}'; known: {', '.join(sorted(sets))}")
    return dict(sets[name])


def stage_use_scenarios(registry=None):
    """Names of the built-in stage-use scenarios (:data:`STAGE_USE_FILE`), in file order."""
    registry = load_scenarios() if registry is None else registry
    path = SCENARIO_DIR / STAGE_USE_FILE
    return [n for n, s in registry.items() if Path(s.source) == path]


def list_scenarios(registry=None, kind=None):
    """Names of the known scenarios.

    Parameters
    ----------
    registry : dict, optional
        Defaults to the built-in scenarios.
    kind : {"tracking", "validation"}, optional
        Filter by kind.

    Returns
    -------
    list of str
    """
    registry = load_scenarios() if registry is None else registry
    return [n for n, s in registry.items() if kind is None or s.kind == kind]


def reference_label(scenario):
    """'1 Hz', '1/5/10 Hz' for a sine reference; the scenario name otherwise."""
    sig = scenario.signal
    if sig.frequencies:
        return "/".join(f"{f:g}" for f in sig.frequencies) + " Hz"
    return scenario.name


def format_scenario_list(registry):
    """The scenarios of a registry by kind, one line each with its description (and the
    file it came from, for a user's scenario): what ``python -m harness list`` prints."""
    kinds = {"tracking": "Tracking (closed loop, reference y_d in µm)",
             "validation": "Validation (plant alone, input v in V)"}
    lines = []
    for kind, title in kinds.items():
        names = [n for n, s in registry.items() if s.kind == kind]
        if not names:
            continue
        lines.append(title)
        width = max(len(n) for n in names)
        for n in names:
            sc = registry[n]
            user = "" if Path(sc.source).parent == SCENARIO_DIR else f" [{sc.source}]"
            lines.append(f"  {n:<{width}}  {sc.description}{user}")
    return "\n".join(lines)


def get_scenario(name, registry=None):
    """Look a scenario up by name.

    Parameters
    ----------
    name : str or Scenario
        A scenario object is returned unchanged.
    registry : dict, optional
        Defaults to the built-in scenarios.

    Returns
    -------
    Scenario

    Raises
    ------
    UnknownScenarioError
        (a :class:`KeyError`) listing the known names.
    """
    if isinstance(name, Scenario):
        return name
    registry = load_scenarios() if registry is None else registry
    try:
        return registry[name]
    except KeyError:
        raise UnknownScenarioError(name, registry) from None
