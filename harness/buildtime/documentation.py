"""The documentation inside an FMU, generated at build time.

``documentation/index.html`` = the hand-written part of the model
(``packaging/documentation/<id>.html``: what it models, the equations with units)
+ parts generated from the model description, so that they cannot drift from it:
the identity table, the table of every variable (causality, variability, type, unit,
default, range, description), how to connect the loop (from ``harness/buildtime/ssp_file.py``, the
same connections the build's SSP uses), how to build from the sources, the reference
results, the paper and the licence.

``documentation/fmi-ls-ref.html``: what the reference results (FMI-LS-REF) hold, how
they were computed and how to compare with them, read from the experiments file.
"""

from __future__ import annotations

import html
from pathlib import Path
import re
from xml.etree import ElementTree as ET

from ..platforms import PLATFORMS
from .ssp_file import SSP_COMPONENTS, SSP_CONNECTIONS


PROJECT = "piezo_fmus"
CITATION = ('"Coupling Modeling and Adaptive Control for Piezoelectric-Actuated Positioning '
            'Stage", research article, Modelling and Simulation in Engineering (Hindawi), 2022, '
            'article ID 2534439')
CITATION_URL = "https://www.hindawi.com/journals/mse/2022/2534439/"
LICENSE_NAME = "BSD-3-Clause"

STYLE = """
body { font-family: sans-serif; max-width: 72em; margin: 2em auto; padding: 0 1em; line-height: 1.45; }
table { border-collapse: collapse; margin: 0.8em 0; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; vertical-align: top; text-align: left; }
th { background: #eee; }
td.num { text-align: right; white-space: nowrap; }
code, pre { background: #f4f4f4; }
pre { padding: 0.6em; overflow-x: auto; }
h1 img { float: right; width: 96px; }
"""


MINUS_INFINITY = "\u2212\u221e"
INFINITY = "\u221e"


def _e(text):
    return html.escape(str(text), quote=True)


def _type_element(var):
    (typ,) = [c for c in var if c.tag in ("Real", "Integer", "Boolean", "String", "Enumeration")]
    return typ


def _is_fmi3(root):
    return root.get("fmiVersion", "").startswith("3")


def _fmi(root, name):
    """The function ``fmi2<name>`` or ``fmi3<name>`` of the model description's FMI version."""
    return ("fmi3" if _is_fmi3(root) else "fmi2") + name


#: FMI 3.0 variable elements (the types of the variables table)
FMI3_TYPE_TAGS = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
                  "Int64", "UInt64", "Boolean", "String", "Binary", "Enumeration", "Clock")


def _variables(root):
    """(variable element, element holding the type attributes, type name, array size or None)
    for every variable: FMI 2.0 ScalarVariable and its type child, FMI 3.0 typed elements
    (an array's size from its Dimension)."""
    if not _is_fmi3(root):
        for var in root.iter("ScalarVariable"):
            typ = _type_element(var)
            yield var, typ, typ.tag, None
        return
    for var in root.find("ModelVariables"):
        if var.tag not in FMI3_TYPE_TAGS:
            continue
        dims = var.findall("Dimension")
        size = None
        if dims:
            size = 1
            for d in dims:
                size *= int(d.get("start"))
        yield var, var, var.tag, size


def _fmt_number(text):
    return text.replace("-", "\u2212") if text else text


def variable_rows(root):
    """One dict per variable (FMI 2.0 ScalarVariable, FMI 3.0 variable, an array as one row
    with type ``Float64[n]`` and its start values): name, causality, variability, type, unit
    (its display unit when the model description defines one), start, range, description."""
    display = {}
    for unit in root.iter("Unit"):
        names = [d.get("name") for d in unit.iter("DisplayUnit")]
        if names:
            display[unit.get("name")] = names[0]
    rows = []
    for var, typ, type_name, size in _variables(root):
        lo, hi = typ.get("min"), typ.get("max")
        if type_name == "Boolean":
            rng = "false, true"
        elif lo is None and hi is None:
            rng = ""
        else:
            low = f"[{_fmt_number(lo)}" if lo is not None else f"({MINUS_INFINITY}"
            high = f"{_fmt_number(hi)}]" if hi is not None else f"{INFINITY})"
            rng = f"{low}, {high}"
        unit = typ.get("displayUnit") or display.get(typ.get("unit"), typ.get("unit") or "")
        rows.append({"name": var.get("name"), "causality": var.get("causality", "local"),
                     "variability": var.get("variability", "continuous"),
                     "type": type_name if size is None else f"{type_name}[{size}]",
                     "unit": unit, "start": _fmt_number(typ.get("start") or ""),
                     "range": rng, "description": var.get("description", "")})
    return rows


def _variables_table(root):
    head = ("Name", "Causality", "Variability", "Type", "Unit", "Default", "Range", "Description")
    out = ['<table class="variables">', "<tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>"]
    for r in variable_rows(root):
        out.append(
            f'<tr><td><code>{_e(r["name"])}</code></td><td>{_e(r["causality"])}</td>'
            f'<td>{_e(r["variability"])}</td><td>{_e(r["type"])}</td><td>{_e(r["unit"])}</td>'
            f'<td class="num">{_e(r["start"])}</td><td class="num">{_e(r["range"])}</td>'
            f'<td>{_e(r["description"])}</td></tr>')
    out.append("</table>")
    return "\n".join(out)


def _identity_table(root, platforms):
    cs = root.find("CoSimulation")
    exp = root.find("DefaultExperiment")
    items = [
        ("Model", root.get("modelName")),
        ("FMI version", f"{root.get('fmiVersion')}, Co-Simulation"),
        ("Model identifier", cs.get("modelIdentifier")),
        ("GUID", root.get("guid")),
        ("Instantiation token", root.get("instantiationToken")),
        ("Version", root.get("version")),
        ("Generated", f"{root.get('generationDateAndTime')} by {root.get('generationTool')}"),
        ("Author", root.get("author")),
        ("Copyright", root.get("copyright")),
        ("Licence", root.get("license")),
        ("Binaries", ", ".join(f"binaries/{p}" for p in platforms) + ", and C sources in sources/"),
    ]
    if exp is not None:
        items.append(("Default experiment", f"{exp.get('startTime')} s to {exp.get('stopTime')} s, "
                                            f"step {exp.get('stepSize')} s"))
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in items if v)
    return f"<table>{rows}</table>"


def _system_model_section(do_step):
    """PiezoStageClosedLoop's section instead of the wiring: the loop is inside."""
    return f"""
<h2 id="loop">Using it in a system model</h2>
<p>The loop of the three FMUs PiezoStage, AdaptiveCompoundController and ReferenceSignal is
inside: nothing to wire. Drop it into a master with any communication step (fixed, such as
1 ms or 10 ms, or variable): every <code>{do_step}</code> computes the samples of
<code>h</code> whose instants it passes. Read <code>y</code> (the true displacement),
<code>y_meas</code> (the sensor), <code>v</code> and <code>error</code>; give the desired
displacement either as the internal reference's parameters (the default) or through the input
<code>y_d</code> with <code>use_internal_reference</code> = false, ahead of time by
<code>y_d_lead</code> samples if the master knows it. With the defaults and a step of
<code>h</code> = 0.5 ms it gives the samples of the three FMUs wired as in the project's
closed-loop SSP (<code>PiezoStageClosedLoop.ssp</code>), bit for bit.</p>
"""


def _connection_section(model_identifier, do_step="fmi2DoStep"):
    """The HTML section on wiring the closed loop, this model's connections in bold (the
    closed-loop FMU: how it goes into a system model instead)."""
    if model_identifier not in {fmu[:-4] for fmu, _ in SSP_COMPONENTS.values()}:
        return _system_model_section(do_step)
    fmu_of = {comp: fmu for comp, (fmu, _) in SSP_COMPONENTS.items()}
    units = {(comp, name): unit for comp, (_, conns) in SSP_COMPONENTS.items()
             for name, _, _, unit in conns}
    rows = []
    for a, ac, b, bc in SSP_CONNECTIONS:
        mine = model_identifier in (fmu_of[a][:-4], fmu_of[b][:-4])
        style = ' style="font-weight: bold"' if mine else ""
        rows.append(f"<tr{style}><td>{_e(fmu_of[a][:-4])}.<code>{_e(ac)}</code></td>"
                    f"<td>{_e(fmu_of[b][:-4])}.<code>{_e(bc)}</code></td>"
                    f"<td>{_e(units[(a, ac)])}</td></tr>")
    return f"""
<h2 id="loop">Connecting the closed loop</h2>
<p>The three FMUs of this project form the tracking loop of the paper: ReferenceSignal
feeds the controller the desired displacement with preview, AdaptiveCompoundController
computes the voltage, PiezoStage moves. The connections (rows of this FMU in bold):</p>
<table><tr><th>from (output)</th><th>to (input)</th><th>unit</th></tr>
{''.join(rows)}</table>
<ul>
<li>Step all three FMUs with the same fixed communication step <code>h</code> = 0.5 ms
(the <code>h</code> parameter of each). The controller computes one control per
measurement: it refuses a longer step at the first <code>{do_step}</code>, naming it and
<code>h</code>.</li>
<li>Wire every pair of equal names, as in the table, the time stamps included
(<code>t_meas</code>, <code>t_preview</code>). With the defaults the controller then finds
its own timing under any master: it detects the loop delay (2 samples where values are
exchanged at communication points, 1 where a master hands an FMU another's
<em>post-step</em> output, one more for a plant with an input delay) within a few
milliseconds, with a start-up law that is stable for each, and aligns the stamped preview
with it. Its outputs <code>loop_delay</code>, <code>loop_delay_time</code>,
<code>preview_lead</code> and <code>meas_offset</code> say what it found.</li>
<li>Wired with <code>y_ref</code> and <code>y_meas</code> alone, the controller still
detects its delay and takes <code>y_ref</code> as the reference d samples ahead
(ReferenceSignal's <code>lead</code>, 2 by default). <code>mv.delay</code> = 0..8 sets
d = 1 + <code>mv.delay</code> instead of detecting it.</li>
<li>In Simulink (FMU import block), Dymola or any SSP tool: three FMU blocks with the
sample time <code>h</code>, wired as in the table. The project's repository ships the
same loop as an SSP 1.0 file (<code>PiezoStageClosedLoop.ssp</code>) with the mismatch
benchmark's parameters bound.</li>
</ul>
"""


def _arrays_note(root):
    """FMI 3.0: how the array variables are addressed (nothing for FMI 2.0)."""
    if not _is_fmi3(root):
        return ""
    arrays = [(var.get("name"), var.get("valueReference"), size)
              for var, _, _, size in _variables(root) if size is not None]
    if not arrays:
        return ""
    items = "".join(f"<li><code>{_e(name)}</code>: value reference {_e(vr)}, {size} values</li>"
                    for name, vr, size in arrays)
    return f"""
<h2 id="arrays">Array variables</h2>
<p>This FMI 3.0 edition has array variables where the FMI 2.0 edition has numbered
scalars (<code>name[1]</code> .. <code>name[n]</code>). An array is read and set whole: one
value reference, n values in element order (<code>nValues</code> counts the values). Element
j is the FMI 2.0 edition's <code>name[j]</code>; the array's value reference is that of
<code>name[1]</code>, every scalar keeps its FMI 2.0 value reference, and the references of
the other elements are not used.</p>
<ul>{items}</ul>
"""


def _source_section(fmi_version, model_identifier, c_files, defines):
    files = " ".join(f"sources/{f}" for f in c_files)
    fmi2 = fmi_version.startswith("2")
    linux, windows = ("linux64", "win64") if fmi2 else ("x86_64-linux", "x86_64-windows")
    major = "2" if fmi2 else "3"
    platform_types = "TypesPlatform" if fmi2 else "PlatformTypes"
    note = (" (FMI 2.0.4 source-code FMU; the same files are listed in the "
            "<code>&lt;SourceFiles&gt;</code> element of the model description)") if fmi2 else ""
    defs = "".join(f"<li><code>{_e(d)}</code> (MinGW only)</li>" for d in defines)
    # the flags a platform's shipped binary is built with beyond the common ones (harness/platforms.py)
    extra = "".join(f" For <code>binaries/{_e(p.folder(major))}</code> add <code>{_e(' '.join(p.flags))}</code>, "
                    f"as its shipped binary is built." for p in PLATFORMS if p.flags and p.folder(major))
    optional = f"<p>Optional definitions:</p><ul>{defs}</ul>" if defs else ""
    return f"""
<h2 id="sources">Building from the sources</h2>
<p><code>sources/</code> holds every C file and header the binaries are built from, flat,
and <code>sources/buildDescription.xml</code> lists the files to compile, the include
folder and the definitions{note}. Only the FMI {major}.0 headers
(<code>fmi{major}Functions.h</code>, <code>fmi{major}FunctionTypes.h</code>,
<code>fmi{major}{platform_types}.h</code>) come from the importer. With GCC or Clang:</p>
<pre>cc -shared -fPIC -std=c99 -O2 -ffp-contract=off -I sources -I FMI{major}_HEADERS \\
   {_e(files)} \\
   -lm -o binaries/{linux}/{_e(model_identifier)}.so</pre>
<p>For Windows with MinGW-w64, add <code>-D__USE_MINGW_ANSI_STDIO=1 -static-libgcc</code>
and write <code>binaries/{windows}/{_e(model_identifier)}.dll</code> (the shipped win64
binary is built this way).{extra} The code is plain C99 with no dependency other than the C
library and its math functions. <code>-ffp-contract=off</code> keeps every multiply and add
as written (no fused multiply-add), as in the shipped binaries; <code>-ffast-math</code>
would change the results.</p>
{optional}
"""


def index_html(model_description, fragment, platforms, c_files, defines, reference_files):
    """The text of ``documentation/index.html``."""
    root = ET.fromstring(model_description.encode("utf-8"))
    model = root.get("modelName")
    ident = root.find("CoSimulation").get("modelIdentifier")
    if _is_fmi3(root):
        # the hand-written part names the FMI 2.0 functions; this edition has the fmi3 ones
        fragment = fragment.replace("fmi2DoStep", "fmi3DoStep")
    refs = ""
    if reference_files:
        refs = ("<h2 id=\"references\">Reference results</h2>\n<p>The FMU carries a regression "
                "experiment in <code>extra/org.fmi-standard.fmi-ls-ref/</code> (FMI-LS-REF): see "
                "<a href=\"fmi-ls-ref.html\">fmi-ls-ref.html</a>.</p>")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{_e(model)}</title>
<style>{STYLE}</style>
</head>
<body>
<h1><img src="../model.png" alt="">{_e(model)}</h1>
<p>{_e(root.get("description", ""))}</p>
{_identity_table(root, platforms)}
{fragment.strip()}
<h2 id="variables">Variables</h2>
<p>Generated from this FMU's <code>modelDescription.xml</code>. Units: displacement in
µm (<code>um</code>), voltage in V, time in s. Parameters are set before
<code>{_fmi(root, "ExitInitializationMode")}</code>; an invalid value is refused there with a log
message that names the parameter and its valid range. The ranges are the model
description's <code>min</code> and <code>max</code>, which FMI {"3.0" if _is_fmi3(root) else "2.0"} makes inclusive; where a
bound is exclusive (a quantity that must be positive, for example) or depends on another
parameter, the description says so.</p>
{_variables_table(root)}
{_connection_section(ident, _fmi(root, "DoStep"))}
{_arrays_note(root)}
{_source_section(root.get("fmiVersion"), ident, c_files, defines)}
{refs}
<h2 id="paper">Source</h2>
<p>The model, the controller and their default parameters follow {_e(CITATION)},
<a href="{CITATION_URL}">{CITATION_URL}</a>. Where the paper's printed equations contain
typos, the FMU implements the corrected form; the project's documentation (docs/model.md in
its repository) gives each correction and its reason.</p>
<h2 id="license">Licence</h2>
<p>{_e(root.get("copyright", ""))}. Distributed under the {LICENSE_NAME} licence: see
<a href="licenses/license.txt">licenses/license.txt</a>.</p>
</body>
</html>
"""


def exported_index_html(index, model_description, section):
    """``documentation/index.html`` of an exported FMU from the built FMU's ``index``.

    The variables table is generated again from the exported ``model_description`` (its
    start values are the identified ones), and ``section`` (HTML: where the start values
    came from) is put before it; the rest of the built page is kept.
    """
    root = ET.fromstring(model_description.encode("utf-8"))
    table = re.compile(r'<table class="variables">.*?</table>', re.DOTALL)
    if len(table.findall(index)) != 1 or index.count('<h2 id="variables">') != 1:
        raise ValueError("the built documentation has no single variables table to replace")
    index = table.sub(lambda m: _variables_table(root), index)
    old = re.compile(r'<h2 id="identified">.*?(?=<h2 id="variables">)', re.DOTALL)
    index = old.sub("", index)          # an exported FMU exported again: one section
    return index.replace('<h2 id="variables">', section + '<h2 id="variables">', 1)


def ls_ref_html(model_description, ls_ref_dir):
    """The text of ``documentation/fmi-ls-ref.html`` from the experiments file."""
    root = ET.fromstring(model_description.encode("utf-8"))
    model = root.get("modelName")
    ident = root.find("CoSimulation").get("modelIdentifier")
    exp_root = ET.parse(Path(ls_ref_dir) / "experiments.exp").getroot()
    items = []
    for exp in exp_root.iter("Experiment"):
        files = "".join(f"<li>{tag}: <code>{_e(el.get('source'))}</code></li>"
                        for tag in ("Parameters", "Stimuli", "References")
                        for el in exp.findall(tag))
        items.append(f"<h2>{_e(exp.get('name'))}</h2><p>{_e(exp.get('description'))}</p>"
                     f"<p>From {exp.get('startTime')} s to {exp.get('stopTime')} s, "
                     f"communication step {exp.get('stepSize')} s, tolerance "
                     f"{exp.get('tolerance')}.</p><ul>{files}</ul>")
    return f"""<!DOCTYPE html>
<html lang="en">
<head><meta charset="utf-8"><title>{_e(model)}: reference results</title>
<style>{STYLE}</style></head>
<body>
<h1>{_e(model)}: reference results (FMI-LS-REF)</h1>
<p><code>extra/org.fmi-standard.fmi-ls-ref/fmi-ls-manifest.xml</code> lists the files of the
FMI Layered Standard for References (version 1.0.0-alpha.1); the experiment is in
<code>experiments.exp</code>. The reference outputs were computed by the project's C core
(the same code as in <code>sources/</code>) called directly, not through this FMU, on
64-bit Linux. CSV files: a quoted header, <code>time</code> first, one row per sample
<code>t_k = k h</code>, numbers written so that they read back exactly.</p>
<h2>How to use them</h2>
<ol>
<li>Instantiate the FMU, set the parameters of the SSV file (names are FMU variable names{
"; <code>name[j]</code> is element j of the array variable <code>name</code>" if _is_fmi3(root) else ""}),
start at the experiment's start time.</li>
<li>At every communication point <code>t_k</code>: set the inputs to the row of
<code>t_k</code> in the stimuli file, then call <code>{_fmi(root, "DoStep")}(t_k, h)</code>.</li>
<li>Record the outputs at every <code>t_k</code> (row 0: after initialization) and
compare: the result passes when at every sample
<code>|y − y_ref| ≤ tolerance · (1 + |y_ref|)</code>. On the platform the reference was made
on the outputs are equal bit for bit; other platforms and compilers differ in the last
digits of the C library's functions.</li>
</ol>
<p>With fmpy:</p>
<pre>import fmpy
from fmpy.util import read_csv
ref = read_csv("{ident}_ref.csv")
result = fmpy.simulate_fmu("{ident}.fmu", stop_time=0.5, output_interval=0.0005,
                           input=..., start_values=..., output=list(ref.dtype.names[1:]))</pre>
{''.join(items)}
</body>
</html>
"""
