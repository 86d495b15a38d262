"""The spreads of a sweep (``--vary KEY=SPEC``) and the plant parameter sets they draw.

Run i draws from its own generator, seeded by (seed, i): its parameters depend neither on
the number of runs nor on where or when they are drawn.
"""

from __future__ import annotations

from dataclasses import dataclass
import cmath
import math
import re

import numpy as np

from .seeding import pcg64_states

__all__ = ["Spread", "parse_spread", "apply_spreads", "run_deltas", "draw_plant_parameters",
           "draw_columns", "varied_keys", "varies_something"]

_GROUPS = ("pi.weights", "tf.poles", "tf.zero", "tf.gain")
_N_DELTAS = {"pi.weights": 17, "tf.poles": 2}
_SPEC = re.compile(r"^(?:(uniform|normal):)?\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(%?)$")


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


def apply_spreads(base, spreads, deltas):
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
        p.update(_moved_coefficients(base, structural))
    return p


def _moved_coefficients(base, structural):
    """G's coefficients ``tf.a1, tf.a2, tf.b1, tf.b2`` of ``base`` with its poles, zero and
    DC gain moved by ``structural`` ({group key: (spread, deltas)})."""
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
    return {"tf.a1": a1, "tf.a2": a2, "tf.b1": b1, "tf.b2": -b1 * zero}


def draw_columns(base, spreads, seed, indices):
    """The parameters the spreads move, for many runs at once.

    Each run still draws from its own generator, the one :func:`run_deltas` builds, here
    one PCG64 given each run's state in turn (:func:`harness.sweep.seeding.pcg64_states`);
    the moves are then made on whole columns, with the operations of :func:`apply_spreads`
    in its order, so every value is the one ``apply_spreads(base, spreads,
    run_deltas(spreads, seed, i))`` gives, bit for bit (G's coefficients, moved through
    complex roots, are computed run by run by the same function).

    Parameters
    ----------
    base : dict
        The complete plant parameter set the spreads move.
    spreads : sequence of Spread
    seed : int
    indices : sequence of int
        The runs.

    Returns
    -------
    dict
        FMU name -> 1-D array with one value per run (int64 for ``sensor.seed``, float64
        otherwise), for every parameter a spread moves.
    """
    indices = [int(i) for i in indices]
    m = len(indices)
    draws = [np.empty(m, np.int64) if s.distribution == "seed" else np.empty((m, _N_DELTAS.get(s.key, 1)))
             for s in spreads]
    bits = np.random.PCG64()
    rng = np.random.Generator(bits)
    for j, state in enumerate(pcg64_states(seed, indices)):
        bits.state = state
        for column, d in zip(draws, _draws_from(rng, spreads)):
            column[j] = d
    cols = {}

    def moved(name, delta, relative):
        value = cols.get(name, base[name])
        return value * (1.0 + delta) if relative else value + delta

    structural = {}
    for s, d in zip(spreads, draws):
        if s.key == "sensor.seed":
            cols["sensor.seed"] = d
        elif s.key == "pi.weights":
            cols["pi.w0"] = moved("pi.w0", d[:, 0], s.relative)
            for j in range(1, int(base["pi.m"]) + 1):
                cols[f"pi.w[{j}]"] = moved(f"pi.w[{j}]", d[:, j], s.relative)
        elif s.key in _GROUPS:
            structural[s.key] = (s, d)
        else:
            cols[s.key] = moved(s.key, d[:, 0], s.relative)
    if structural:
        per_run = [_moved_coefficients(base, {k: (s, d[j]) for k, (s, d) in structural.items()})
                   for j in range(m)]
        for name in ("tf.a1", "tf.a2", "tf.b1", "tf.b2"):
            cols[name] = np.array([c[name] for c in per_run], dtype=float)
    return {k: np.asarray(v, dtype=np.int64 if k == "sensor.seed" else float) for k, v in cols.items()}


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
    return [apply_spreads(base, spreads, run_deltas(spreads, seed, i)) for i in range(n)]


def run_deltas(spreads, seed, i):
    """Run i's {key: deltas}, from its own generator seeded by (seed, i): its parameters do
    not depend on the number of runs (a longer sweep extends a shorter one), nor on which
    worker draws them, nor when."""
    return {s.key: d for s, d in zip(spreads, _run_draws(spreads, seed, i))}


def _run_draws(spreads, seed, i):
    """Run i's deltas, one per spread in order: a seed (int) or an array of deltas."""
    return _draws_from(np.random.default_rng([int(seed), int(i)]), spreads)


def _draws_from(rng, spreads):
    """A run's deltas from its generator, one per spread in order."""
    return [int(rng.integers(0, 2**31 - 1)) if s.distribution == "seed"
            else _draw(rng, s, _N_DELTAS.get(s.key, 1)) for s in spreads]


def varied_keys(spreads, base):
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

