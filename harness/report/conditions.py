"""What runs in the main job: the tracking conditions, and what each one is.

Each condition runs the six references of the paper's Tables 4/5 with one set
of closed-loop options.  The sentences that describe a condition are built from
the options it actually ran with (adaptation, preview, master, loop delay), so
the report never describes a different experiment from the one it shows.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from ..loop import loop_delay
from ..scenarios import MISMATCH_SCENARIOS, TRACKING_SCENARIOS, get_scenario, reference_label

__all__ = [
    "Condition",
    "condition_label",
    "default_conditions",
    "user_condition",
    "describe_condition",
    "lag_error_rms",
    "reference_label",
    "MISMATCH_PLANT_TEXT",
]

#: The mismatched plant of harness/scenarios/mismatch.toml, in words.
MISMATCH_PLANT_TEXT = (
    "the plant differs from the controller's model: PI weights +10 %, creep row 10 Hz of "
    "Table 1 (k_c 1.0497, α −0.0085), G numerator ×1.05 with the fast pole moved to 0.45 "
    "(DC gain +17.5 %), and a sensor with 2 nm resolution and 1 nm rms noise (1.15 nm rms "
    "of measurement noise with the quantisation); the controller keeps the nominal model")
NOMINAL_PLANT_TEXT = "the plant equals the controller's model (the FMUs' default parameters)"

#: Short names of the conditions, relative to the headline.
_SHORT_LABELS = {"mismatch": "headline", "mismatch_no_adaptation": "RLS off",
                 "mismatch_no_preview": "no preview", "nominal": "nominal model",
                 "user": "user"}

#: Condition roles, in the order the report shows them.
ROLES = ("headline", "ablation", "check", "user")


@dataclass(frozen=True)
class Condition:
    """A tracking condition: which scenarios, with which closed-loop options.

    Attributes
    ----------
    key : str
        Short identifier used in file names and the CSV.
    label : str
        Human-readable title.
    scenarios : tuple of str
    adaptation : bool or None
        ``None`` keeps the scenario's setting (on by default), ``False`` switches RLS off.
    preview : bool
    master : str
    role : {"headline", "ablation", "check", "user"}
        ``headline``: the benchmark compared with the paper; ``ablation``: the
        headline with one part switched off; ``check``: the nominal model, an
        implementation check; ``user``: the user's scenarios.
    plant : {"nominal", "mismatch", "user"}
        Which plant the scenarios run.
    """

    key: str
    label: str
    scenarios: tuple
    adaptation: object = None
    preview: bool = True
    master: str = "gauss-seidel"
    role: str = "headline"
    plant: str = "mismatch"

    @property
    def adaptation_on(self):
        return self.adaptation is not False

    @property
    def short_label(self):
        """Column title of the all-conditions table: how it differs from the headline."""
        return _SHORT_LABELS.get(self.key, self.key)


def condition_label(base, adaptation, preview, master):
    """'mismatch, adaptation on, preview on[, Jacobi master]'."""
    parts = [base,
             "adaptation " + ("off" if adaptation is False else "on"),
             "preview " + ("on" if preview else "off")]
    if master == "jacobi":
        parts.append("Jacobi master")
    return ", ".join(parts)


def default_conditions(adaptation=None, preview=True, master="gauss-seidel"):
    """The tracking conditions of the main job, built on the base options.

    Parameters
    ----------
    adaptation : bool or None
        Base adaptation setting (``None``: on).
    preview : bool
        Base preview setting.
    master : str

    Returns
    -------
    list of Condition
        In report order: the headline (mismatch with the base options), the
        ablations (adaptation off, preview off), the nominal-model check.
        Duplicates (e.g. preview off when the base already has it off) are dropped.
    """
    conds = [
        Condition("mismatch", condition_label("mismatch", adaptation, preview, master),
                  MISMATCH_SCENARIOS, adaptation, preview, master, "headline", "mismatch"),
        Condition("mismatch_no_adaptation",
                  condition_label("mismatch", False, preview, master),
                  MISMATCH_SCENARIOS, False, preview, master, "ablation", "mismatch"),
        Condition("mismatch_no_preview", condition_label("mismatch", adaptation, False, master),
                  MISMATCH_SCENARIOS, adaptation, False, master, "ablation", "mismatch"),
        Condition("nominal", condition_label("nominal model", adaptation, preview, master),
                  TRACKING_SCENARIOS, adaptation, preview, master, "check", "nominal"),
    ]
    seen, out = set(), []
    for c in conds:
        sig = (c.scenarios, c.adaptation is False, c.preview, c.master)
        if sig not in seen:
            seen.add(sig)
            out.append(c)
    return out


def user_condition(names, adaptation=None, preview=True, master="gauss-seidel"):
    """The condition that runs the user's tracking scenarios with the base options."""
    return Condition("user", condition_label("user scenarios", adaptation, preview, master),
                     tuple(names), adaptation, preview, master, "user", "user")


def lag_error_rms(scenario):
    """Expected rms error [um] of a stage that follows a sine reference d samples late.

    For one tone ``A sin(2 pi f t)``, ``y_d(t) - y_d(t - d h)`` has amplitude
    ``2 A sin(pi f d h)`` (about ``2 pi f A d h``), so rms ``sqrt(2) A sin(pi f d h)``;
    tones of distinct frequencies add in quadrature over whole periods.
    ``nan`` for a table reference.
    """
    sig = scenario.signal
    if not sig.frequencies:
        return math.nan
    dh = loop_delay(scenario.controller, scenario.plant) * scenario.step_size
    return math.sqrt(sum(2.0 * (a * math.sin(math.pi * f * dh)) ** 2
                         for a, f in zip(sig.amplitudes, sig.frequencies)))


def describe_condition(cond, registry=None):
    """Sentences that say what a condition is and what its result means.

    Parameters
    ----------
    cond : Condition
    registry : dict, optional
        Scenario registry (for the loop delay and the lag error).

    Returns
    -------
    list of str
    """
    scenarios = [get_scenario(n, registry) for n in cond.scenarios]
    d_values = sorted({loop_delay(s.controller, s.plant) for s in scenarios})
    d_text = "/".join(str(d) for d in d_values)
    h_ms = "/".join(f"{v * 1e3:g}" for v in sorted({s.step_size for s in scenarios}))
    out = []
    if cond.plant == "mismatch":
        out.append("Plant: " + MISMATCH_PLANT_TEXT + ".")
    elif cond.plant == "nominal":
        out.append("Plant: " + NOMINAL_PLANT_TEXT + ".")
    else:
        out.append("Plant and controller: the overrides of each user scenario "
                   "(see Provenance).")
    out.append("Adaptation: " + ("on, RLS updates the controller's estimate of G while the reference "
                                 "moves (on every sample of these tones), with integral action "
                                 "(docs/model.md, adaptation)."
                                 if cond.adaptation_on else
                                 "off: the controller uses the nominal G throughout (the integral "
                                 "action stays on)."))
    if cond.preview:
        out.append(f"Reference: previewed, the controller gets y_d(k+d), d = {d_text} samples "
                   f"ahead (h = {h_ms} ms).")
    else:
        lags = [lag_error_rms(s) * 1e3 for s in scenarios]
        lag_text = ", ".join(f"{reference_label(s)} {v:.0f} nm"
                             for s, v in zip(scenarios, lags) if math.isfinite(v))
        out.append(f"Reference: not previewed, the controller gets y_d(k), so the stage follows "
                   f"d = {d_text} samples late. This lag error is expected, not a fault: "
                   f"√2·A·sin(π f d h) rms per tone" + (f" ({lag_text})." if lag_text else "."))
    if cond.master == "jacobi":
        out.append("Master: Jacobi (all outputs read, then all inputs set). The controller "
                   "has no direct feedthrough, so this gives the same samples as Gauss-Seidel.")
    else:
        out.append("Master: Gauss-Seidel (plant outputs → controller → plant input).")
    if cond.role == "check":
        if cond.preview:
            out.append("Expected: exact tracking by construction (plant = model, reference "
                       "previewed), an error at round-off level. This row checks the "
                       "implementation; it is not comparable with the paper's experiment.")
        else:
            out.append("Expected: the lag error above and nothing else (plant = model); this "
                       "row checks the implementation.")
    elif cond.role == "headline":
        out.append("This is the benchmark compared with the paper's Tables 4/5 (measured on a "
                   "real stage); ratio = ours / paper.")
    elif cond.role == "ablation":
        out.append("The headline with one part switched off, to show what that part contributes.")
    return out
