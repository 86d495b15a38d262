"""Parameterised FMUs: the built FMUs with a parameter file's values as start values.

:func:`export_fmus` writes ``PiezoStage.fmu``, ``AdaptiveCompoundController.fmu`` and
``PiezoStageClosedLoop.fmu`` into a folder: the stage, its controller with the stage as its
nominal model, and both in one closed loop (the stage's parameters under their names and the
controller's nominal model as ``controller.<name>``, :mod:`harness.binding.closed_loop`).  Each is the
built FMU (same binaries, sources and GUID: the binary checks the GUID it is instantiated with)
with

* ``modelDescription.xml``: the ``start`` attribute of each given parameter
  replaced (nothing else in the file changes);
* ``resources/start_values``: every parameter with its start value, one
  ``name = value`` per line, which the binary reads at ``fmi2Instantiate``
  and applies over its compiled defaults (an FMU must itself use the start
  values it declares: importers need not set them);
* ``extra/org.fmi-standard.fmi-ls-ref/``: reference results computed anew on the
  C core from the FMU's own start values (:data:`harness.buildtime.references.EXPORT_EXPERIMENTS`),
  so that the FMU's regression experiment tests the model it now carries;
* ``documentation/index.html`` with the variables table of the new model
  description (the identified start values) and a section saying where they came
  from, and ``documentation/fmi-ls-ref.html`` for the new experiment;
* ``extra/piezo_fmus.identification/``: ``provenance.json`` (the parameter file,
  the identification report and the measured records, each with its SHA-256, the
  FMU it was made from, the start values changed) and copies of the
  identification reports when they sit beside the parameter file.

The archive is written as the build writes its FMUs (:mod:`harness.buildtime.archive`:
the same permissions and the built FMU's date), so exporting the same parameters
twice gives the same bytes.

Values are written as the shortest decimal text that reads back to the same
double, so the FMU runs exactly the parameters of the file.  Before writing,
each value is checked against the variable's type and declared range, and the
complete parameter set of each FMU is initialised once in the C core (the
FMUs' own validation; the closed loop's, which adds rules of its own, in its FMU);
afterwards each FMU is checked with :func:`fmpy.validation.validate_fmu`.
"""

from __future__ import annotations

import json
import math
import html
import os
from pathlib import Path
import re
import tempfile
import zipfile

import fmpy
from fmpy.validation import validate_fmu

from ..binding import core
from ..binding.closed_loop import CLOSED_LOOP_MODEL, closed_loop_parameters
from ..buildtime import documentation as fmu_documentation, references as fmu_references
from ..fmu import FMUInitializationError, fmu_path, load, parameter_types
from ..buildtime.archive import write_fmu_zip
from ..paths import sha256_of
from .from_files import output_paths
from .params import CONTROLLER_MODEL, PLANT_MODEL, split_params

__all__ = ["ExportError", "START_VALUES_PATH", "PROVENANCE_DIR", "export_fmus",
           "format_start_value"]

#: Where the start values sit inside an FMU (read by fmu_start_values.c).
START_VALUES_PATH = "resources/start_values"
#: Where an exported FMU says where its start values came from.
PROVENANCE_DIR = "extra/piezo_fmus.identification"
LS_REF_DIR = "extra/org.fmi-standard.fmi-ls-ref"



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


def _check_in_core(model, params, source, path=None):
    """Initialise the complete parameter set in the C core (the FMUs' own checks); the closed
    loop's in its FMU at ``path``, whose rules are more than its blocks'."""
    if model == CLOSED_LOOP_MODEL:
        from ..masters import Instance      # the closed loop's own rules live in its FMU
        inst = None
        try:
            inst = Instance(load(path), "export")
            inst.initialize(params, 0.0)
        except FMUInitializationError as exc:
            text = str(exc).split("failed: ", 1)[-1]
            raise ExportError(f"{source}: {model} refuses these start values: {text}") from None
        finally:
            if inst is not None:
                inst.close()
        return
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
    md = fmpy.read_model_description(str(src))
    model = md.coSimulation.modelIdentifier
    variables = _parameters(md)
    kinds = {n: v.type for n, v in variables.items()}
    complete = {n: _parse_start(v.start, v.type) for n, v in variables.items()}
    for name, value in given.items():
        _check_range(name, value, variables[name], model, source)
    complete.update(given)
    _check_in_core(model, complete, source, src)
    return md, kinds, complete


def _identification_files(source):
    """The identification reports beside a parameter file (``<stem>.report.json``, ``.md``)."""
    if source is None or not Path(source).is_file():
        return {}
    _, md, js = output_paths(source)
    return {p.name: p for p in (js, md) if p.is_file()}


def _provenance(model, src, version, given, originals, source, reports):
    """``provenance.json`` of an exported FMU: where its start values came from."""
    doc = {"fmu": f"{model}.fmu", "exported_by": "python -m harness export",
           "made_from": {"file": Path(src).name, "version": version, "sha256": sha256_of(src)},
           "parameter_file": None, "identification_report": None, "records": [],
           "start_values_changed": {n: {"built": originals[n], "exported": v}
                                    for n, v in given.items() if originals[n] != v}}
    if source is not None and Path(source).is_file():
        doc["parameter_file"] = {"file": Path(source).name, "sha256": sha256_of(source)}
    report = next((p for n, p in reports.items() if n.endswith(".json")), None)
    if report is not None:
        doc["identification_report"] = {"file": report.name, "sha256": sha256_of(report)}
        try:
            records = json.loads(report.read_text(encoding="utf-8")).get("records", {})
        except (OSError, ValueError):
            records = {}
        doc["records"] = [dict({"label": label}, **info) for label, info in records.items()]
    return json.dumps(doc, indent=1, sort_keys=False) + "\n"


def _documentation_section(model, given, originals, provenance, reports):
    """The HTML section of an exported FMU's documentation: its start values' origin."""
    doc = json.loads(provenance)
    e = lambda t: html.escape(str(t), quote=True)      # noqa: E731
    rows = "".join(f"<tr><td><code>{e(n)}</code></td><td class=\"num\">{e(c['built'])}</td>"
                   f"<td class=\"num\">{e(c['exported'])}</td></tr>"
                   for n, c in doc["start_values_changed"].items())
    files = []
    if doc["parameter_file"]:
        files.append(f"parameter file <code>{e(doc['parameter_file']['file'])}</code> (SHA-256 "
                     f"<code>{e(doc['parameter_file']['sha256'])}</code>)")
    if doc["identification_report"]:
        files.append(f"identification report <code>{e(doc['identification_report']['file'])}"
                     f"</code> (SHA-256 <code>{e(doc['identification_report']['sha256'])}"
                     f"</code>), copied into <code>{PROVENANCE_DIR}/</code>")
    for r in doc["records"]:
        files.append(f"record <code>{e(r.get('path', r['label']))}</code>, "
                     f"{e(r.get('samples', '?'))} samples (SHA-256 "
                     f"<code>{e(r.get('sha256', 'not recorded'))}</code>)")
    listing = "".join(f"<li>{f}</li>" for f in files) or "<li>none recorded</li>"
    return f"""<h2 id="identified">Start values of an identified stage</h2>
<p>This {e(model)}.fmu was written by <code>python -m harness export</code> from
<code>{e(doc['made_from']['file'])}</code>: the same binaries and sources, with the start values
below in place of the built defaults (the variables table shows the new ones; the binary reads
them from <code>{START_VALUES_PATH}</code>, so an importer that sets nothing runs them). Its
regression experiment was recomputed from these values. Where they came from (also in
<code>{PROVENANCE_DIR}/provenance.json</code>):</p>
<ul>{listing}</ul>
<table><tr><th>parameter</th><th>built default</th><th>this FMU</th></tr>{rows}</table>
"""


def _write(src, dst, md, kinds, given, complete, source, plant_complete, reports):
    """Write ``dst``: ``src`` with ``given`` as start values, its references and documentation
    regenerated and its provenance added (through a temporary file)."""
    model = md.coSimulation.modelIdentifier
    with zipfile.ZipFile(src) as zin:
        files = {i.filename: zin.read(i.filename) for i in zin.infolist()
                 if not i.filename.endswith("/")}
        date = zin.getinfo("modelDescription.xml").date_time
    originals = {n: _parse_start(v.start, v.type) for n, v in _parameters(md).items()}
    xml = files["modelDescription.xml"].decode("utf-8")
    new_xml = _rewrite_starts(xml, given, kinds)
    files["modelDescription.xml"] = new_xml.encode("utf-8")
    files[START_VALUES_PATH] = _start_values_text(model, complete, kinds, source).encode("utf-8")
    with tempfile.TemporaryDirectory(prefix="piezo_export_") as tmp:
        ls_ref = Path(tmp) / "ls_ref"
        names = fmu_references.write_reference_results(
            model, new_xml, ls_ref, start_values=complete, plant_start_values=plant_complete)
        for name in list(files):
            if name.startswith(LS_REF_DIR + "/"):
                del files[name]
        for name in names:
            files[f"{LS_REF_DIR}/{name}"] = (ls_ref / name).read_bytes()
        provenance = _provenance(model, src, md.version, given, originals, source, reports)
        section = _documentation_section(model, given, originals, provenance, reports)
        files["documentation/index.html"] = fmu_documentation.exported_index_html(
            files["documentation/index.html"].decode("utf-8"), new_xml, section).encode("utf-8")
        files["documentation/fmi-ls-ref.html"] = fmu_documentation.ls_ref_html(
            new_xml, ls_ref).encode("utf-8")
    files[f"{PROVENANCE_DIR}/provenance.json"] = provenance.encode("utf-8")
    for name, path in reports.items():
        files[f"{PROVENANCE_DIR}/{name}"] = path.read_bytes()
    fd, tmp = tempfile.mkstemp(prefix=f".{model}.", suffix=".fmu", dir=dst.parent)
    os.close(fd)
    try:
        write_fmu_zip(files, tmp, date)
        _verify(tmp, md, complete, kinds)
        Path(tmp).replace(dst)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _verify(path, original, complete, kinds):
    """The written FMU: valid, same GUID, every parameter's start value as intended."""
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
    """Write PiezoStage.fmu, AdaptiveCompoundController.fmu and PiezoStageClosedLoop.fmu with
    ``params`` as start values.

    Parameters
    ----------
    params : dict
        FMU variable name -> value; each FMU takes the names it has (see
        :func:`harness.identify.params.split_params`); the closed loop takes both FMUs' (its
        stage the plant's, its controller the controller's: the identified stage is its
        controller's nominal model too).
    out_dir : str or Path
        Folder to write into (created); existing FMUs there are replaced.
    fmu_dir : str or Path, optional
        Folder of the built FMUs (default ``build/fmus``).
    source : str
        Where the parameters come from: the parameter file (its SHA-256 and the
        identification reports beside it go into the FMUs' provenance) or a name
        for messages.

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
    sources = {m: fmu_path(m, fmu_dir) for m in (PLANT_MODEL, CONTROLLER_MODEL, CLOSED_LOOP_MODEL)}
    kinds = {m: parameter_types(m, fmu_dir) for m in (PLANT_MODEL, CONTROLLER_MODEL)}
    plant, controller = split_params(params, kinds[PLANT_MODEL], kinds[CONTROLLER_MODEL],
                                     source=source)
    try:
        loop = closed_loop_parameters(plant=plant, controller=controller)
    except ValueError as exc:
        raise ExportError(f"{source}: {exc}") from None
    out = Path(out_dir)
    jobs = []
    for model, given in ((PLANT_MODEL, plant), (CONTROLLER_MODEL, controller), (CLOSED_LOOP_MODEL, loop)):
        dst = out / f"{model}.fmu"
        if dst.resolve() == sources[model].resolve():
            raise ExportError(f"{dst} is the FMU being parameterised; choose another --out folder")
        jobs.append((model, dst, given, _prepare(sources[model], given, source)))
    # every FMU checked before any is written
    plant_complete = jobs[0][3][2]
    reports = _identification_files(source)
    out.mkdir(parents=True, exist_ok=True)
    result = {}
    for model, dst, given, (md, kinds, complete) in jobs:
        _write(sources[model], dst, md, kinds, given, complete, source, plant_complete, reports)
        result[model] = (dst, given)
    return result
