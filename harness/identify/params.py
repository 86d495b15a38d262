"""Parameter files: one flat JSON object of FMU variable names and values.

::

    {"pi.m": 9, "pi.v_max": 20.0, "pi.w0": 0.4317, "pi.w[1]": 0.0, ..., "tf.a1": -1.442,
     "tf.delay": 0, "creep.k_c": 1.0, "creep.alpha": -0.0085, "h": 0.0005}

Names are the FMUs' parameter names.  One file serves both FMUs: each takes
the names it has (``tf.delay`` and ``sensor.*`` are PiezoStage's only,
``mv.*``, ``rls.*`` and ``sat.*`` AdaptiveCompoundController's); a name that
neither FMU has is an error.  Values are JSON numbers (finite) or booleans.

:func:`write_params` / :func:`read_params` write and read such a file,
:func:`split_params` assigns the names to the FMUs and checks the types, and
:func:`override_scenarios` applies them to every scenario of a registry (what
``--plant-params`` and ``--controller-params`` of the command line do).
"""

from __future__ import annotations

import difflib
import json
import math
from pathlib import Path

from ..binding import core
from ..fmu import parameter_types as fmu_parameter_types
from .data import unreadable_file_message

__all__ = [
    "PLANT_MODEL",
    "CONTROLLER_MODEL",
    "ParameterFileError",
    "write_params",
    "read_params",
    "parameter_types",
    "split_params",
    "override_scenarios",
]

PLANT_MODEL = "PiezoStage"
CONTROLLER_MODEL = "AdaptiveCompoundController"


class ParameterFileError(ValueError):
    """A parameter file or value is unusable; the message is one line naming the file."""


def _value_text(value):
    return json.dumps(value)


def write_params(path, params):
    """Write parameters as a JSON object (one name per line, values at full precision).

    Parameters
    ----------
    path : str or Path
    params : dict
        FMU variable name -> int, float or bool.

    Returns
    -------
    Path
    """
    clean = {}
    for name, value in params.items():
        if isinstance(value, bool):
            clean[str(name)] = value
        elif isinstance(value, int):
            clean[str(name)] = int(value)
        else:
            x = float(value)
            if not math.isfinite(x):
                raise ParameterFileError(f"{path}: {name} = {x!r} is not finite")
            clean[str(name)] = x
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"  {json.dumps(k)}: {_value_text(v)}" for k, v in clean.items()]
    path.write_text("{\n" + ",\n".join(lines) + "\n}\n")
    return path


def _reject_constant(name):
    raise ValueError(f"{name} is not a valid value (every number must be finite)")


def _no_duplicates(pairs):
    seen = {}
    for key, value in pairs:
        if key in seen:
            raise ValueError(f"{key!r} appears twice")
        seen[key] = value
    return seen


def read_params(path):
    """Read a parameter file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
        Name -> int, float or bool, in file order.

    Raises
    ------
    ParameterFileError
        Unreadable file, not a JSON object, a repeated name, or a value
        that is not a finite number or a boolean.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterFileError(unreadable_file_message(path, exc, "a parameter file")) from None
    try:
        data = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as exc:
        raise ParameterFileError(f"{path}: not valid JSON: {exc.msg} at line {exc.lineno}, "
                                 f"column {exc.colno}") from None
    except ValueError as exc:
        raise ParameterFileError(f"{path}: {exc}") from None
    if not isinstance(data, dict):
        raise ParameterFileError(f"{path}: expected a JSON object of parameter names and values, "
                                 f"got a {type(data).__name__}")
    for name, value in data.items():
        if isinstance(value, bool):
            continue
        if not isinstance(value, (int, float)):
            raise ParameterFileError(f"{path}: {name} = {json.dumps(value)} is not a number or "
                                     f"a boolean")
    return data


def parameter_types(model, *, fmu_dir=None, backend="fmpy"):
    """The parameters of one FMU and their types.

    Parameters
    ----------
    model : {"PiezoStage", "AdaptiveCompoundController"}
    fmu_dir : str or Path, optional
        Folder of the FMUs (backend ``"fmpy"``; default ``build/fmus``).
    backend : {"fmpy", "core"}
        Read the FMU's model description, or the C core binding's parameter
        tables (the same names).

    Returns
    -------
    dict
        Name -> ``"Real"``, ``"Integer"`` or ``"Boolean"``.
    """
    if backend == "core":
        defaults = (core.default_plant_params() if model == PLANT_MODEL
                    else core.default_controller_params())
        return {n: ("Boolean" if isinstance(v, bool) else "Integer" if isinstance(v, int)
                    else "Real") for n, v in defaults.items()}
    return fmu_parameter_types(model, fmu_dir)


def _check_type(name, value, kind, model, source):
    if kind == "Boolean":
        if isinstance(value, bool):
            return value
        raise ParameterFileError(f"{source}: {name} = {json.dumps(value)}: {model}'s {name} is "
                                 f"a Boolean (true or false)")
    if isinstance(value, bool):
        raise ParameterFileError(f"{source}: {name} = {json.dumps(value)}: {model}'s {name} is "
                                 f"{'an Integer' if kind == 'Integer' else 'a Real'}, not a boolean")
    if kind == "Integer":
        if isinstance(value, int) or float(value).is_integer():
            return int(value)
        raise ParameterFileError(f"{source}: {name} = {json.dumps(value)}: {model}'s {name} is "
                                 f"an Integer")
    return float(value)


def split_params(params, plant_types, controller_types, *, source="parameters"):
    """Assign each parameter to the FMUs that have it, checking its type.

    Parameters
    ----------
    params : dict
        Name -> value (e.g. from :func:`read_params`).
    plant_types, controller_types : dict
        Parameter name -> type of each FMU (:func:`parameter_types`).
    source : str
        Where the parameters come from (the file), for messages.

    Returns
    -------
    plant, controller : dict
        The parameters each FMU has, typed (int, float or bool).

    Raises
    ------
    ParameterFileError
        A name is a parameter of neither FMU (the message suggests close
        names), or a value does not fit the variable's type.
    """
    plant, controller = {}, {}
    for name, value in params.items():
        if name not in plant_types and name not in controller_types:
            known = sorted(set(plant_types) | set(controller_types))
            close = difflib.get_close_matches(name, known, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ParameterFileError(f"{source}: '{name}' is a parameter of neither "
                                     f"{PLANT_MODEL} nor {CONTROLLER_MODEL}{hint}")
        if name in plant_types:
            plant[name] = _check_type(name, value, plant_types[name], PLANT_MODEL, source)
        if name in controller_types:
            controller[name] = _check_type(name, value, controller_types[name],
                                           CONTROLLER_MODEL, source)
    return plant, controller


def override_scenarios(registry, plant_params=None, controller_params=None):
    """A copy of a scenario registry with parameters applied over every scenario's own.

    Parameters
    ----------
    registry : dict of str to Scenario
    plant_params, controller_params : dict, optional
        Applied after each scenario's plant and controller overrides (the
        file wins), e.g. an identified stage model.

    Returns
    -------
    dict of str to Scenario
    """
    plant = dict(plant_params or {})
    ctrl = dict(controller_params or {})
    if not plant and not ctrl:
        return dict(registry)
    return {name: sc.with_overrides(plant=plant, controller=ctrl) for name, sc in registry.items()}
