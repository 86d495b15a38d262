"""Parameterised FMUs: the built FMUs with a parameter file's values as start values.

:func:`export_fmus` writes ``PiezoStage.fmu`` and ``AdaptiveCompoundController.fmu``
into a folder.  Each is the built FMU (same binaries, sources and GUID: the
binary checks the GUID it is instantiated with) with

* ``modelDescription.xml``: the ``start`` attribute of each given parameter
  replaced (nothing else in the file changes);
* ``resources/start_values``: every parameter with its start value, one
  ``name = value`` per line, which the binary reads at ``fmi2Instantiate``
  and applies over its compiled defaults (an FMU must itself use the start
  values it declares: importers need not set them).

Values are written as the shortest decimal text that reads back to the same
double, so the FMU runs exactly the parameters of the file.  Before writing,
each value is checked against the variable's type and declared range, and the
complete parameter set of each FMU is initialised once in the C core (the
FMUs' own validation); afterwards each FMU is checked with
:func:`fmpy.validation.validate_fmu`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
import re
import tempfile
import zipfile

from .params import CONTROLLER_MODEL, PLANT_MODEL, split_params

__all__ = ["ExportError", "START_VALUES_PATH", "export_fmus", "format_start_value"]

#: Where the start values sit inside an FMU (read by fmu_start_values.c).
START_VALUES_PATH = "resources/start_values"


class ExportError(ValueError):
    """The parameters cannot be put into the FMUs (out of range, or the FMU is not as expected)."""


def format_start_value(value, kind):
    """The XML / start_values text of a value: Real repr, Integer decimal, Boolean true/false."""
    if kind == "Boolean":
        return "true" if value else "false"
    if kind == "Integer":
        return str(int(value))
    return repr(float(value))


def _parse_start(text, kind):
    if kind == "Boolean":
        return text in ("true", "1")
    if kind == "Integer":
        return int(text)
    return float(text)


def _parameters(md):
    """{name: variable} of the parameters in a model description."""
    return {v.name: v for v in md.modelVariables if v.causality == "parameter"}


def _check_range(name, value, var, model, source):
    if var.type != "Real" and var.type != "Integer":
        return
    lo = None if var.min is None else float(var.min)
    hi = None if var.max is None else float(var.max)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        rng = f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
        raise ExportError(f"{source}: {name} = {value!r} is outside {model}'s declared range "
                          f"{rng}")


def _check_in_core(model, params, source):
    """Initialise the complete parameter set in the C core (the FMUs' own checks)."""
    from .. import core

    try:
        if model == PLANT_MODEL:
            core.Plant(params)
        else:
            core.Controller(params)
    except (core.CoreParameterError, ValueError, KeyError) as exc:
        text = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        raise ExportError(f"{source}: {model} refuses these start values: {text}") from None


def _rewrite_starts(xml, values, kinds):
    """``xml`` with the start attribute of each named variable replaced; every name must hit once."""
    for name, value in values.items():
        block = re.compile(r'(<ScalarVariable\b[^>]*?\bname="' + re.escape(name)
                           + r'"[^>]*>)(.*?)(</ScalarVariable>)', re.DOTALL)
        hits = block.findall(xml)
        if len(hits) != 1:
            raise ExportError(f"the model description has {len(hits)} variables named {name}")
        text = format_start_value(value, kinds[name])

        def swap(m, text=text, name=name):
            body, n = re.subn(r'(<(?:Real|Integer|Boolean)\b[^>]*?\bstart=")[^"]*(")',
                              lambda t: t.group(1) + text + t.group(2), m.group(2), count=1)
            if n != 1:
                raise ExportError(f"the model description gives {name} no start value")
            return m.group(1) + body + m.group(3)

        xml = block.sub(swap, xml, count=1)
    return xml


def _start_values_text(model, params, kinds, source):
    lines = [f"# {model}: start values of every parameter, the same as modelDescription.xml.",
             f"# Read by the FMU binary at fmi2Instantiate (written by python -m harness export "
             f"from {Path(source).name})."]
    lines += [f"{name} = {format_start_value(v, kinds[name])}" for name, v in params.items()]
    return "\n".join(lines) + "\n"


def _prepare(src, given, source):
    """Check ``given`` against ``src``'s model description and the model; nothing is written.

    Returns (model description, parameter types, complete parameter set).
    """
    import fmpy

    md = fmpy.read_model_description(str(src))
    model = md.coSimulation.modelIdentifier
    variables = _parameters(md)
    kinds = {n: v.type for n, v in variables.items()}
    complete = {n: _parse_start(v.start, v.type) for n, v in variables.items()}
    for name, value in given.items():
        _check_range(name, value, variables[name], model, source)
    complete.update(given)
    _check_in_core(model, complete, source)
    return md, kinds, complete


def _write(src, dst, md, kinds, given, complete, source):
    """Write ``dst``: ``src`` with ``given`` as start values, through a temporary file."""
    model = md.coSimulation.modelIdentifier
    with zipfile.ZipFile(src) as zin:
        xml = zin.read("modelDescription.xml").decode("utf-8")
        new_xml = _rewrite_starts(xml, given, kinds)
        fd, tmp = tempfile.mkstemp(prefix=f".{model}.", suffix=".fmu", dir=dst.parent)
        os.close(fd)
        try:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zout:
                for info in zin.infolist():
                    if info.filename in ("modelDescription.xml", START_VALUES_PATH):
                        continue
                    zout.writestr(info, zin.read(info.filename))
                zout.writestr("modelDescription.xml", new_xml)
                zout.writestr(START_VALUES_PATH,
                              _start_values_text(model, complete, kinds, source))
            _verify(tmp, md, complete, kinds)
            os.replace(tmp, dst)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def _verify(path, original, complete, kinds):
    """The written FMU: valid, same GUID, every parameter's start value as intended."""
    import fmpy
    from fmpy.validation import validate_fmu

    problems = validate_fmu(str(path))
    if problems:
        raise ExportError(f"the written FMU does not validate: {'; '.join(problems)}")
    md = fmpy.read_model_description(str(path))
    if md.guid != original.guid:
        raise ExportError(f"the GUID changed ({original.guid} -> {md.guid})")
    for v in md.modelVariables:
        if v.causality == "parameter":
            got = _parse_start(v.start, v.type)
            want = complete[v.name]
            if got != want and not (isinstance(got, float) and math.isnan(got)):
                raise ExportError(f"{v.name}: start {v.start} written, {want!r} intended")


def export_fmus(params, out_dir, *, fmu_dir=None, source="parameters"):
    """Write PiezoStage.fmu and AdaptiveCompoundController.fmu with ``params`` as start values.

    Parameters
    ----------
    params : dict
        FMU variable name -> value; each FMU takes the names it has (see
        :func:`harness.identify.params.split_params`).
    out_dir : str or Path
        Folder to write into (created); existing FMUs there are replaced.
    fmu_dir : str or Path, optional
        Folder of the built FMUs (default ``build/fmus``).
    source : str
        Where the parameters come from, for messages and the start_values header.

    Returns
    -------
    dict
        ``{model: (path, parameters given to it)}``.

    Raises
    ------
    FileNotFoundError
        A built FMU is missing (the message says how to build it).
    harness.identify.params.ParameterFileError
        A name is a parameter of neither FMU, or a value has the wrong type.
    ExportError
        A value is out of range (declared in the model description, or
        refused by the model), or the written FMU fails its checks.
    """
    import fmpy

    from ..cosim import fmu_path

    sources = {m: fmu_path(m, fmu_dir) for m in (PLANT_MODEL, CONTROLLER_MODEL)}
    kinds = {m: {v.name: v.type for v in fmpy.read_model_description(str(p)).modelVariables
                 if v.causality == "parameter"} for m, p in sources.items()}
    plant, controller = split_params(params, kinds[PLANT_MODEL], kinds[CONTROLLER_MODEL],
                                     source=source)
    out = Path(out_dir)
    jobs = []
    for model, given in ((PLANT_MODEL, plant), (CONTROLLER_MODEL, controller)):
        dst = out / f"{model}.fmu"
        if dst.resolve() == sources[model].resolve():
            raise ExportError(f"{dst} is the FMU being parameterised; choose another --out folder")
        jobs.append((model, dst, given, _prepare(sources[model], given, source)))
    # both FMUs checked before either is written
    out.mkdir(parents=True, exist_ok=True)
    result = {}
    for model, dst, given, (md, kinds, complete) in jobs:
        _write(sources[model], dst, md, kinds, given, complete, source)
        result[model] = (dst, given)
    return result
