"""The closed loop as an SSP 1.0 file that every SSP player applies: written, and its bound
parameter set read back (fmpy's SSP player runs it: :mod:`harness.masters.ssp`).

An SSP is a zip with ``SystemStructure.ssd`` (the system: components,
connectors, connections, default experiment) and ``resources/`` (the FMUs
and parameter files, SSV).  :func:`write_closed_loop_ssp` writes::

    reference (ReferenceSignal.fmu)   y_ref     --> controller.y_ref
                                      y_preview --> controller.y_preview
                                      t_preview --> controller.t_preview
    plant (PiezoStage.fmu)            y_meas    --> controller.y_meas
                                      t_meas    --> controller.t_meas
    controller (AdaptiveCompoundController.fmu)  v --> plant.v

Parameter sets, each under one name (the scenario's):

- ``resources/<set>/<component>.ssv``: the set's values of one component under its own
  variable names. The first set is bound on each component (``ssd:ParameterBinding`` of the
  component), the others ship beside it. Component bindings are what every player reads:
  libcosim applies a component's first binding, Ecos groups the bindings by the name of their
  ``ssv:ParameterSet`` (``init(parameter_set="<set>")`` applies it to every component),
  OMSimulator applies every binding of a component. A system-level binding (which libcosim and
  Ecos ignore) is not written, and only one set is bound: SSP 1.0 applies every binding of a
  component, a later one winning, while libcosim applies the first, so two bound sets would
  make players disagree.
- ``resources/<set>.ssv``: the same values under ``<component>.<variable>``, not bound: the
  form fmpy's player takes from its caller (``simulate_ssp(..., parameter_set=read_ssv(ssp,
  "resources/<set>.ssv"))``); it applies no binding by itself.

The step: OpenModelica's ``oms:FixedStepMaster stepSize`` on the system (OMSimulator), the
Open Simulation Platform's ``osp:FixedStepAlgorithm baseStepSize`` in the default experiment
(libcosim: the SSP then loads without a step given) and ``osp:StepSizeHint`` on each component
(libcosim and Ecos step each FMU at h also when their base step is a fraction of it), and a
default experiment over the scenario's duration.

The loop needs a master with a fixed communication step h. The controller detects
the loop delay the master's schedule makes (d = 2 where values are exchanged at
communication points, as every SSP player, Jacobi master and container in parallel
mode does; d = 1 where the plant gets the controller's post-step output) and, from
the time stamps ``t_preview`` and ``t_meas``, aligns the stamped preview with it
(docs/cosimulation.md).

The build writes ``build/fmus/PiezoStageClosedLoop.ssp`` with
``python -m harness.buildtime.ssp_file --fmu-dir build/fmus --out build/fmus/PiezoStageClosedLoop.ssp``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import math
from pathlib import Path
import sys
from xml.sax.saxutils import quoteattr
import zipfile

from fmpy.ssp.ssd import read_ssd

from ..binding.fmu_variables import SIGNALS
from ..fmu import fmu_path
from ..loop import reference_parameters
from ..scenarios import get_scenario

__all__ = [
    "SSP_FILENAME",
    "SSP_SCENARIO",
    "SSP_COMPONENTS",
    "SspParameterSet",
    "parameter_set_for_scenario",
    "write_closed_loop_ssp",
    "component_values",
    "read_bound_parameter_set",
    "main",
]

SSP_FILENAME = "PiezoStageClosedLoop.ssp"
#: The scenario whose parameters the built SSP binds (the mismatch case of docs/model.md, 1/5/10 Hz).
SSP_SCENARIO = "mismatch_1_5_10hz"
#: component name -> (its FMU, the connectors the SSP shows: the wired ones and the controller's
#: outputs a tool plots)
_CONNECTORS = {
    "reference": ("ReferenceSignal", ("y_d", "y_ref", "y_preview", "t_preview")),
    "controller": ("AdaptiveCompoundController", ("y_ref", "y_meas", "y_preview", "t_preview", "t_meas", "v",
                                                  "q", "pred_error", "loop_delay", "loop_delay_time",
                                                  "preview_lead", "meas_offset")),
    "plant": ("PiezoStage", ("v", "y", "y_meas", "t_meas")),
}
#: component name -> (FMU file, connectors as (name, kind, SSP type, unit)), each connector as its
#: FMU declares it (harness/binding/fmu_variables.py, from fmu_src/<Model>/variables.toml)
SSP_COMPONENTS = {comp: (f"{model}.fmu", tuple((name, *SIGNALS[model][name]) for name in names))
                  for comp, (model, names) in _CONNECTORS.items()}
#: (start component, connector, end component, connector)
SSP_CONNECTIONS = (
    ("reference", "y_ref", "controller", "y_ref"),
    ("reference", "y_preview", "controller", "y_preview"),
    ("reference", "t_preview", "controller", "t_preview"),
    ("plant", "y_meas", "controller", "y_meas"),
    ("plant", "t_meas", "controller", "t_meas"),
    ("controller", "v", "plant", "v"),
)
_UNITS = {"um": '<ssc:BaseUnit m="1" factor="1e-06"/>',
          "V": '<ssc:BaseUnit kg="1" m="2" s="-3" A="-1"/>',
          "s": '<ssc:BaseUnit s="1"/>'}
_NS = ('xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
       'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
       'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
       'xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd" '
       'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"')
#: ZIP timestamp of every entry: the same inputs give the same bytes
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


@dataclass(frozen=True)
class SspParameterSet:
    """One SSV: parameter values by ``<component>.<variable>``.

    Attributes
    ----------
    name : str
        File stem in ``resources/`` (``<name>.ssv``).
    description : str
    values : dict
        ``{"plant.pi.w0": 0.36784, "reference.lead": 2, ...}``; bool, int or float.
    stop_time : float
        Duration of the scenario [s] (the SSP's default experiment).
    step_size : float
        h [s].
    """

    name: str
    description: str
    values: dict
    stop_time: float
    step_size: float


def parameter_set_for_scenario(name, registry=None):
    """The SSV of a sines tracking scenario: its plant and controller overrides and its
    reference as ReferenceSignal parameters; ``lead`` = 1 + ``mv.delay`` when the scenario
    sets ``mv.delay`` (the stamped preview needs no setting).

    Parameters
    ----------
    name : str
        A tracking scenario whose reference is a sum of at most 8 sines.
    registry : dict, optional

    Returns
    -------
    SspParameterSet

    Raises
    ------
    ValueError
        Not a tracking scenario, a table reference, or more than 8 tones.
    """
    sc = get_scenario(name, registry)
    try:
        reference = reference_parameters(sc)
    except ValueError as exc:
        raise ValueError(f"{exc}; an SSP carries its reference as ReferenceSignal parameters") from None
    values = {}
    for comp, params in (("plant", sc.plant), ("controller", sc.controller)):
        for key, value in params.items():
            values[f"{comp}.{key}"] = value
    values["plant.h"] = values["controller.h"] = values["reference.h"] = float(sc.step_size)
    values.update({f"reference.{key}": value for key, value in reference.items()})
    return SspParameterSet(sc.name, sc.description, values, float(sc.duration),
                           float(sc.step_size))


def _ssv_value(value):
    if isinstance(value, bool):
        return "Boolean", "true" if value else "false"
    if isinstance(value, int):
        return "Integer", str(value)
    if not math.isfinite(value):
        raise ValueError(f"parameter value {value!r} is not finite")
    return "Real", repr(float(value))


def component_values(pset):
    """A set's values by component, under the component's own variable names.

    Parameters
    ----------
    pset : SspParameterSet

    Returns
    -------
    dict
        ``{component: {variable: value}}`` for every component of :data:`SSP_COMPONENTS`
        (empty where the set has no value of it).

    Raises
    ------
    ValueError
        A name is not ``<component>.<variable>`` of a component of the loop.
    """
    out = {comp: {} for comp in SSP_COMPONENTS}
    for key, value in pset.values.items():
        comp, _, var = key.partition(".")
        if comp not in out or not var:
            raise ValueError(f"parameter {key!r} of set {pset.name!r}: not <component>.<variable> of "
                             f"a component of the loop ({', '.join(SSP_COMPONENTS)})")
        out[comp][var] = value
    return out


def _ssv_text(name, values):
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
             f'version="1.0" name={quoteattr(name)}>',
             '  <ssv:Parameters>']
    for key in sorted(values):
        kind, text = _ssv_value(values[key])
        lines.append(f'    <ssv:Parameter name={quoteattr(key)}><ssv:{kind} value="{text}"/></ssv:Parameter>')
    lines += ['  </ssv:Parameters>', '</ssv:ParameterSet>', '']
    return "\n".join(lines)


def _component_ssv(set_name, component):
    """Where a set's values of one component are in the SSP."""
    return f"resources/{set_name}/{component}.ssv"


def _ssd_text(bound, step_size, stop_time):
    c = []
    c.append('<?xml version="1.0" encoding="UTF-8"?>')
    c.append(f'<ssd:SystemStructureDescription {_NS} name="PiezoStageClosedLoop" version="1.0">')
    c.append('  <ssd:System name="PiezoStageClosedLoop" description='
             + quoteattr("Piezo stage closed loop: reference with stamped preview, adaptive "
                         "compound controller, stage. Fixed communication step h; the controller "
                         "detects the loop delay (1 to 3 samples) and aligns the preview.") + '>')
    c.append('    <ssd:Elements>')
    for name, (fmu, connectors) in SSP_COMPONENTS.items():
        c.append(f'      <ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" '
                 f'source="resources/{fmu}">')
        c.append('        <ssd:Connectors>')
        for cname, kind, typ, unit in connectors:
            unit_attr = f' unit="{unit}"' if unit else ""
            c.append(f'          <ssd:Connector name="{cname}" kind="{kind}"><ssc:{typ}{unit_attr}/>'
                     f'</ssd:Connector>')
        c.append('        </ssd:Connectors>')
        c.append('        <ssd:ParameterBindings>')
        c.append(f'          <ssd:ParameterBinding source="{_component_ssv(bound, name)}"/>')
        c.append('        </ssd:ParameterBindings>')
        c.append('        <ssd:Annotations>')
        c.append('          <ssc:Annotation type="com.opensimulationplatform">')
        c.append(f'            <osp:StepSizeHint value="{step_size!r}"/>')
        c.append('          </ssc:Annotation>')
        c.append('        </ssd:Annotations>')
        c.append('      </ssd:Component>')
    c.append('    </ssd:Elements>')
    c.append('    <ssd:Connections>')
    for a, ac, b, bc in SSP_CONNECTIONS:
        c.append(f'      <ssd:Connection startElement="{a}" startConnector="{ac}" '
                 f'endElement="{b}" endConnector="{bc}"/>')
    c.append('    </ssd:Connections>')
    c.append('    <ssd:Annotations>')
    c.append('      <ssc:Annotation type="org.openmodelica">')
    c.append('        <oms:Annotations>')
    c.append('          <oms:SimulationInformation>')
    c.append(f'            <oms:FixedStepMaster description="oms-ma" stepSize="{step_size!r}"/>')
    c.append('          </oms:SimulationInformation>')
    c.append('        </oms:Annotations>')
    c.append('      </ssc:Annotation>')
    c.append('    </ssd:Annotations>')
    c.append('  </ssd:System>')
    c.append('  <ssd:Units>')
    for unit, base in _UNITS.items():
        c.append(f'    <ssc:Unit name="{unit}">{base}</ssc:Unit>')
    c.append('  </ssd:Units>')
    c.append(f'  <ssd:DefaultExperiment startTime="0" stopTime="{stop_time!r}">')
    c.append('    <ssd:Annotations>')
    c.append('      <ssc:Annotation type="org.openmodelica">')
    c.append('        <oms:Annotations>')
    c.append(f'          <oms:SimulationInformation loggingInterval="{step_size!r}"/>')
    c.append('        </oms:Annotations>')
    c.append('      </ssc:Annotation>')
    c.append('      <ssc:Annotation type="com.opensimulationplatform">')
    c.append('        <osp:Algorithm>')
    c.append(f'          <osp:FixedStepAlgorithm baseStepSize="{step_size!r}"/>')
    c.append('        </osp:Algorithm>')
    c.append('      </ssc:Annotation>')
    c.append('    </ssd:Annotations>')
    c.append('  </ssd:DefaultExperiment>')
    c.append('</ssd:SystemStructureDescription>')
    return "\n".join(c) + "\n"


def _add(zf, name, data):
    info = zipfile.ZipInfo(name, date_time=_ZIP_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    zf.writestr(info, data)


def write_closed_loop_ssp(path, fmu_dir, parameter_sets=None):
    """Write the closed-loop SSP.

    Parameters
    ----------
    path : str or Path
        The ``.ssp`` to write.
    fmu_dir : str or Path
        Folder with PiezoStage.fmu, AdaptiveCompoundController.fmu and ReferenceSignal.fmu.
    parameter_sets : list of SspParameterSet, optional
        The first is bound on every component; the others ship beside it. Default:
        ``[parameter_set_for_scenario(SSP_SCENARIO)]``.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        An FMU is missing (the message says how to build it).
    ValueError
        Two sets share a name, or a name of a set is not ``<component>.<variable>``.
    """
    path = Path(path)
    sets = list(parameter_sets or [parameter_set_for_scenario(SSP_SCENARIO)])
    names = [pset.name for pset in sets]
    if len(set(names)) != len(names):
        raise ValueError(f"parameter sets {names}: each needs its own name (it names its files)")
    fmus = {fmu: fmu_path(Path(fmu).stem, fmu_dir).read_bytes() for fmu, _ in SSP_COMPONENTS.values()}
    bound = sets[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    with zipfile.ZipFile(tmp, "w") as zf:
        _add(zf, "SystemStructure.ssd", _ssd_text(bound.name, bound.step_size, bound.stop_time))
        for name in sorted(fmus):
            _add(zf, f"resources/{name}", fmus[name])
        for pset in sets:
            _add(zf, f"resources/{pset.name}.ssv", _ssv_text(pset.name, pset.values))
            for comp, values in component_values(pset).items():
                _add(zf, _component_ssv(pset.name, comp), _ssv_text(pset.name, values))
    tmp.replace(path)
    return path


def read_bound_parameter_set(ssp_path):
    """The parameter set bound on the SSP's components, under ``<component>.<variable>``: what an
    SSP player applies, in the form fmpy's player takes (``simulate_ssp(...,
    parameter_set=...)``).

    The values are Python ``float``, ``int`` and ``bool``: fmpy's player sets a Boolean to
    ``value != 0.0``, which the text ``"false"`` of an SSV read by ``read_ssv`` would pass as
    true.

    Returns
    -------
    fmpy.ssp.ssd.ParameterSet or None
        None when no component binds a set.

    Raises
    ------
    ValueError
        The components bind sets of different names, or a component binds more than one.
    """
    from fmpy.ssp.ssd import Parameter, ParameterSet

    ssd = read_ssd(str(ssp_path))
    names, parameters = set(), []
    for element in ssd.system.elements:
        sets = [ps for binding in element.parameterBindings for ps in binding.parameterValues]
        if len(sets) > 1:
            raise ValueError(f"{ssp_path}: component {element.name!r} binds {len(sets)} parameter sets; "
                             f"SSP players differ in which applies, bind one")
        for ps in sets:
            names.add(ps.name)
            for p in ps.parameters:
                value = {"Real": float, "Integer": int,
                         "Boolean": lambda text: text.strip().lower() in ("true", "1")}[p.type](p.value)
                parameters.append(Parameter(name=f"{element.name}.{p.name}", type=p.type, value=value))
    if len(names) > 1:
        raise ValueError(f"{ssp_path}: the components bind sets of different names {sorted(names)}")
    if not names:
        return None
    return ParameterSet(name=names.pop(), parameters=parameters)


def main(argv=None):
    """``python -m harness.buildtime.ssp_file --fmu-dir DIR --out FILE [--scenario NAME ...]``."""
    p = argparse.ArgumentParser(prog="python -m harness.buildtime.ssp_file",
                                description="Write the closed-loop SSP (the build does this).")
    p.add_argument("--fmu-dir", required=True, help="folder with the three FMUs")
    p.add_argument("--out", required=True, help="the .ssp to write")
    p.add_argument("--scenario", action="append", metavar="NAME",
                   help=f"tracking scenario(s) to include as parameter sets; the first is bound on "
                        f"every component (default {SSP_SCENARIO})")
    args = p.parse_args(argv)
    try:
        sets = [parameter_set_for_scenario(n) for n in (args.scenario or [SSP_SCENARIO])]
        out = write_closed_loop_ssp(args.out, args.fmu_dir, sets)
    except (ValueError, KeyError, FileNotFoundError) as exc:
        sys.stderr.write(f"python -m harness.buildtime.ssp_file: error: {exc}\n")
        return 2
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
