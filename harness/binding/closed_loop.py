"""PiezoStageClosedLoop's parameters: the three FMUs' parameters under the closed-loop FMU's names.

The closed-loop FMU (fmu_src/PiezoStageClosedLoop) carries every parameter of PiezoStage
and ReferenceSignal under its own name, and AdaptiveCompoundController's too, but for the
controller's nominal model: the names it shares with the stage (``pi.*``, ``tf.a1`` ..
``tf.b2``, ``creep.k_c``, ``creep.alpha``, ``creep.exact``) are ``controller.<name>``
there. One ``h`` serves all three. The controller's ``mv.hold_inputs`` is not a parameter
of it (the loop inside exchanges every sample).

:func:`closed_loop_parameters` maps parameters by the components' names to the closed-loop
FMU's; the master ``closed-loop-fmu`` (:mod:`harness.masters.closed_loop_fmu`), the reference
results (:mod:`harness.buildtime.references`) and ``export`` (:mod:`harness.identify.export`) use it.
"""

from __future__ import annotations

from . import core
from .fmu_variables import COMPOSED, PREFIXES

__all__ = ["CLOSED_LOOP_MODEL", "CONTROLLER_PREFIX", "NOMINAL_MODEL_NAMES", "NOT_PARAMETERS",
           "closed_loop_parameters", "component_parameters"]

CLOSED_LOOP_MODEL = "PiezoStageClosedLoop"
_CONTROLLER = "AdaptiveCompoundController"
#: the prefix of the controller's nominal model in the closed-loop FMU (its declaration's)
CONTROLLER_PREFIX = PREFIXES[CLOSED_LOOP_MODEL][_CONTROLLER]
#: the controller's names in the closed-loop FMU, as its declaration composes them
_IN_LOOP = {name: loop for loop, (model, name) in COMPOSED[CLOSED_LOOP_MODEL].items() if model == _CONTROLLER}
#: the controller's parameters that name its nominal model (``controller.<name>`` in the loop)
NOMINAL_MODEL_NAMES = frozenset(n for n, loop in _IN_LOOP.items() if loop == CONTROLLER_PREFIX + n)
#: the controller's parameters the closed-loop FMU does not have (``h``: the loop's one)
NOT_PARAMETERS = tuple(n for n in core.CONTROLLER_PARAMETER_NAMES if n not in _IN_LOOP and n != "h")


def closed_loop_parameters(plant=None, controller=None, reference=None):
    """The closed-loop FMU's parameters for parameters of the three FMUs by their own names.

    Parameters
    ----------
    plant, controller, reference : dict, optional
        PiezoStage's, AdaptiveCompoundController's and ReferenceSignal's parameters by their
        names (each may give ``h``; the values must agree).

    Returns
    -------
    dict
        By the closed-loop FMU's names: the plant's and the reference's as they are, the
        controller's nominal model as ``controller.<name>``, ``h`` once.

    Raises
    ------
    ValueError
        The components give different ``h``, or the controller sets ``mv.hold_inputs`` (the
        closed loop has no such parameter; false, its value here, is dropped).
    """
    out = {}
    hs = {}
    for name, value in (reference or {}).items():
        if name == "h":
            hs["reference"] = value
        else:
            out[name] = value
    for name, value in (plant or {}).items():
        if name == "h":
            hs["plant"] = value
        else:
            out[name] = value
    for name, value in (controller or {}).items():
        if name == "h":
            hs["controller"] = value
        elif name in NOT_PARAMETERS:
            if value:
                raise ValueError(f"{CLOSED_LOOP_MODEL} has no parameter {name}: its loop exchanges "
                                 f"every sample inside, whatever the communication step")
        elif name in NOMINAL_MODEL_NAMES:
            out[CONTROLLER_PREFIX + name] = value
        else:
            out[name] = value
    if len({float(h) for h in hs.values()}) > 1:
        raise ValueError(f"{CLOSED_LOOP_MODEL} has one sample period h for the stage, the controller "
                         f"and the reference; given {', '.join(f'{c} {h!r}' for c, h in hs.items())}")
    if hs:
        out["h"] = next(iter(hs.values()))
    return out


def component_parameters(params):
    """The inverse of :func:`closed_loop_parameters` for the stage and the controller:
    ``(plant, controller, rest)``, each by its FMU's names (``rest``: the reference's and the
    loop's own, ``use_internal_reference``, ``y_d_lead``); ``h`` goes to both."""
    plant_names = set(core.PLANT_PARAMETER_NAMES)
    controller_names = set(core.CONTROLLER_PARAMETER_NAMES)
    plant, controller, rest = {}, {}, {}
    for name, value in params.items():
        if name == "h":
            plant[name] = controller[name] = value
        elif name.startswith(CONTROLLER_PREFIX) and name[len(CONTROLLER_PREFIX):] in NOMINAL_MODEL_NAMES:
            controller[name[len(CONTROLLER_PREFIX):]] = value
        elif name in plant_names:
            plant[name] = value
        elif name in controller_names:
            controller[name] = value
        else:
            rest[name] = value
    return plant, controller, rest
