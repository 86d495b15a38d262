"""The experiment every master runs, whichever runs it (:mod:`harness.masters`).

A scenario and the options of a closed-loop run become a :class:`ClosedLoopSetup`: the
samples, the reference the controller receives, the parameters of both FMUs, the loop
delay d the controller runs and the lead of its reference. Here too: the fields of the
results, and the loop delay and the reference's lead, each computed in one place.
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
import math

import numpy as np

from ..scenarios import Scenario, get_scenario

#: the schedules of our own masters (``master=`` of :func:`prepare_closed_loop`)
SCHEDULES = ("gauss-seidel", "jacobi")
#: doStep orders of the Gauss-Seidel master (the exchange happens before both steps)
STEP_ORDERS = ("plant-first", "controller-first")

#: Start value of the controller's ``mv.delay`` (the XML start; a test checks
#: it against the FMU and the core): -1, the controller detects its loop delay.
DEFAULT_MV_DELAY = -1
#: The loop delay of a master that exchanges values at communication points (every master
#: here): the plant's one sample plus the controller's publishing at the end of its step.
EXCHANGE_LOOP_DELAY = 2
#: Start values of ReferenceSignal's ``lead`` (of ``y_ref``) and ``preview`` (of the stamped
#: preview ``y_preview``, ``t_preview``); a test checks them against the FMU.
REFERENCE_LEAD = 2
REFERENCE_PREVIEW = 4


def loop_delay(controller_params, plant_params=None):
    """The loop delay d the controller runs under the masters here.

    Parameters
    ----------
    controller_params, plant_params : dict
        Parameter overrides by FMU variable name.

    Returns
    -------
    int
        ``1 + mv.delay`` when ``mv.delay`` is set (0 .. 8); with ``mv.delay = -1`` (the
        default) the delay the controller detects in a master that exchanges values at
        communication points: 2, one less with ``mv.feedthrough``, plus the plant's
        ``tf.delay``.
    """
    c = controller_params or {}
    mv_delay = int(c.get("mv.delay", DEFAULT_MV_DELAY))
    if mv_delay >= 0:
        return 1 + mv_delay
    d = EXCHANGE_LOOP_DELAY - (1 if c.get("mv.feedthrough", False) else 0)
    return d + int((plant_params or {}).get("tf.delay", 0))


def reference_lead(controller_params):
    """ReferenceSignal's ``lead`` that goes with the controller: ``1 + mv.delay`` when
    ``mv.delay`` is set (0 .. 8), else None: the FMU's own default (``REFERENCE_LEAD``), whose
    preview the detecting controller aligns by its time stamps."""
    mv_delay = int((controller_params or {}).get("mv.delay", DEFAULT_MV_DELAY))
    return 1 + mv_delay if mv_delay >= 0 else None


#: the tones ReferenceSignal has
REFERENCE_TONES = 8


def reference_parameters(scenario):
    """ReferenceSignal's parameters for a tracking scenario's sines reference: ``offset`` and all
    eight tones (the unused ones 0, so the set is the whole reference, whatever the FMU's
    defaults), and ``lead`` = 1 + ``mv.delay`` when the scenario sets ``mv.delay``.

    Raises
    ------
    ValueError
        Not a tracking scenario, a table reference, or more than 8 tones.
    """
    sig = scenario.signal
    if scenario.kind != "tracking" or not sig.internal:
        raise ValueError(f"scenario '{scenario.name}' is not a tracking scenario with a sines "
                         f"reference, which ReferenceSignal's parameters would carry")
    if len(sig.amplitudes) > REFERENCE_TONES:
        raise ValueError(f"scenario '{scenario.name}' has {len(sig.amplitudes)} tones; "
                         f"ReferenceSignal has {REFERENCE_TONES}")
    values = {"offset": float(sig.offset)}
    tones = list(zip(sig.amplitudes, sig.frequencies, sig.phases))
    tones += [(0.0, 0.0, 0.0)] * (REFERENCE_TONES - len(tones))
    for i, (a, f, p) in enumerate(tones, start=1):
        values[f"amplitude[{i}]"] = float(a)
        values[f"frequency[{i}]"] = float(f)
        values[f"phase[{i}]"] = float(p)
    lead = reference_lead(scenario.controller)
    if lead is not None:
        values["lead"] = lead
    return values


#: the fields of a closed-loop result (every master's but other tools'), and of an open loop's
CLOSED_LOOP_FIELDS = ("time", "y_d", "y", "y_meas", "v", "q", "a1", "a2", "b1", "b2", "pred_error",
                      "saturated")
CLOSED_LOOP_DTYPE = np.dtype([(f, "f8") for f in CLOSED_LOOP_FIELDS])
OPEN_LOOP_FIELDS = ("time", "v", "u", "x", "y", "y_meas")
OPEN_LOOP_DTYPE = np.dtype([(f, "f8") for f in OPEN_LOOP_FIELDS])
#: the result of other tools' masters (:mod:`harness.masters.ssp`, :mod:`harness.masters.container`):
#: the closed loop's first fields and the controller's timing outputs
IMPORTER_FIELDS = ("time", "y_d", "y", "y_meas", "v", "loop_delay", "loop_delay_time", "preview_lead",
                   "meas_offset")
IMPORTER_DTYPE = np.dtype([(f, "f8") for f in IMPORTER_FIELDS])


def as_structured(rows, dtype):
    """View a C-contiguous (n, n_fields) float64 array as a structured array of n rows."""
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    return rows.view(dtype).reshape(rows.shape[0])


def normalize_master(master):
    """Return the canonical master name or raise ValueError."""
    key = str(master).lower().replace("_", "-")
    if key in ("gs", "gauss-seidel", "gaussseidel", "seidel"):
        return "gauss-seidel"
    if key == "jacobi":
        return "jacobi"
    raise ValueError(f"master must be one of {SCHEDULES}, got {master!r}")


def normalize_step_order(order):
    """Return the canonical doStep order or raise ValueError."""
    key = str(order).lower().replace("_", "-")
    if key in STEP_ORDERS:
        return key
    raise ValueError(f"step_order must be one of {STEP_ORDERS}, got {order!r}")


@dataclass(frozen=True)
class ClosedLoopSetup:
    """Everything a closed-loop run needs, resolved from a scenario and options.

    Attributes
    ----------
    scenario : Scenario
    n : int
        Number of samples (rows).
    h : float
        Sample period [s].
    time : ndarray
        ``k h`` for ``k = 0 .. n-1``.
    y_d : ndarray
        Desired displacement on the grid, ``y_d(k)``.
    y_ref : list of float
        Controller input per sample: ``y_d(k + lead)`` with preview (``lead`` = ``1 +
        mv.delay`` when set, else ReferenceSignal's default ``REFERENCE_LEAD``), ``y_d(k)``
        without.
    y_preview : list of float or None
        The stamped preview ``y_d(k + REFERENCE_PREVIEW)`` (with preview), else None.
    t_preview : list of float or None
        Its time stamps ``(k + REFERENCE_PREVIEW) h``, else None.
    d : int
        The loop delay the controller runs (:func:`loop_delay`).
    feedthrough : bool
        The controller's ``mv.feedthrough``: v depends directly on the inputs.
    master : str
        ``"gauss-seidel"`` or ``"jacobi"``.
    step_order : str
        ``"plant-first"`` or ``"controller-first"`` (the order of the doStep calls).
    plant_params, controller_params : dict
        Effective parameter overrides by FMU variable name.
    """

    scenario: Scenario
    n: int
    h: float
    time: np.ndarray
    y_d: np.ndarray
    y_ref: list
    y_preview: list
    t_preview: list
    d: int
    feedthrough: bool
    master: str
    step_order: str
    plant_params: dict
    controller_params: dict


def prepare_closed_loop(scenario, *, adaptation=None, preview=True, master="gauss-seidel",
                        plant_params=None, controller_params=None, duration=None,
                        registry=None, step_order="plant-first"):
    """Resolve the scenario and options of a closed-loop run (see ``simulate_closed_loop``)."""
    sc = get_scenario(scenario, registry)
    if sc.kind != "tracking":
        raise ValueError(f"scenario '{sc.name}' is a {sc.kind} scenario; "
                         f"a closed-loop run needs a tracking scenario")
    master = normalize_master(master)
    step_order = normalize_step_order(step_order)
    h = float(sc.step_size)
    if duration is None:
        n = sc.n_samples
    else:
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be a positive number, got {duration!r}")
        n = int(round(float(duration) / h))
        if n < 1 or abs(n * h - duration) > 1e-9 * max(1.0, duration):
            raise ValueError(f"duration {duration!r} s is not a whole number of steps of {h:g} s")

    p = dict(sc.plant)
    p.update(plant_params or {})
    p.setdefault("h", h)
    c = dict(sc.controller)
    c.update(controller_params or {})
    c.setdefault("h", h)
    if adaptation is not None:
        c["rls.enabled"] = bool(adaptation)
    # Every master here exchanges values at communication points: the controller
    # detects d = 2 (+ tf.delay), or runs the d = 1 + mv.delay it is given. Like
    # ReferenceSignal, the setup gives y_ref = y_d(k + lead) and the stamped
    # preview y_d(k + REFERENCE_PREVIEW) at (k + REFERENCE_PREVIEW) h.
    d = loop_delay(c, p)
    lead = reference_lead(c) or REFERENCE_LEAD
    feedthrough = bool(c.get("mv.feedthrough", False))

    time = np.arange(n, dtype=float) * h
    ahead = max(lead, REFERENCE_PREVIEW)
    ext = np.arange(n + ahead, dtype=float) * h
    y_d_ext = sc.signal.evaluate(ext)
    y_d = y_d_ext[:n].copy()
    y_ref = (y_d_ext[lead:lead + n] if preview else y_d).tolist()
    y_preview = t_preview = None
    if preview:
        y_preview = y_d_ext[REFERENCE_PREVIEW:REFERENCE_PREVIEW + n].tolist()
        t_preview = ext[REFERENCE_PREVIEW:REFERENCE_PREVIEW + n].tolist()
    return ClosedLoopSetup(sc, n, h, time, y_d, y_ref, y_preview, t_preview, d, feedthrough, master,
                           step_order, p, c)


def sample_blocks(n, h, progress=None):
    """Split the samples ``0 .. n-1`` into blocks of one simulated second.

    Yields one ``range`` per block; after each block, calls ``progress(done, n)``
    (``done`` samples simulated so far), so a long run can report itself without a
    check in the per-sample loop.
    """
    size = max(1, int(round(1.0 / h)))
    for start in range(0, n, size):
        stop = min(n, start + size)
        yield range(start, stop)
        if progress is not None:
            progress(stop, n)


def sample_range(n, h, progress=None):
    """``range(n)``, reporting ``progress(done, n)`` after every simulated second (if given)."""
    if progress is None:
        return range(n)
    return itertools.chain.from_iterable(sample_blocks(n, h, progress))


def open_loop_grid(v_signal, step_size):
    """Validate an open-loop voltage sequence; return (v ndarray, time ndarray)."""
    v = np.asarray(v_signal, dtype=float)
    if v.ndim != 1 or v.size == 0:
        raise ValueError(f"v_signal must be a non-empty 1-D sequence, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        k = int(np.flatnonzero(~np.isfinite(v))[0])
        raise ValueError(f"v_signal[{k}] = {v[k]!r} is not finite")
    if not (math.isfinite(step_size) and step_size > 0):
        raise ValueError(f"step_size must be a positive number, got {step_size!r}")
    return v, np.arange(v.size, dtype=float) * float(step_size)
