"""The reference experiment an FMU carries (FMI-LS-REF), read from the .fmu itself (FMI 2.0
or FMI 3.0: an element of an FMI 3.0 array is named ``name[j]`` in the parameter file).

Used by the tests that re-run it: with fmpy (test_fmu_reference_results.py), with a C host
on every platform's binaries (test_fmu_platforms.py), and on a binary rebuilt from the
FMU's sources (test_fmu_build_description.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
import zipfile
from xml.etree import ElementTree as ET

import numpy as np

LS_REF = "extra/org.fmi-standard.fmi-ls-ref/"
SSV = "{http://ssp-standard.org/SSP1/SystemStructureParameterValues}"
LS = "{http://fmi-standard.org/fmi-ls-manifest}"


@dataclass
class Experiment:
    """One experiment of an FMU's ``experiments.exp`` with its files loaded."""

    name: str
    start: float
    stop: float
    step: float
    tolerance: float
    parameters: dict        # {name: typed value}
    stimuli: np.ndarray     # structured (time first) or None
    reference: np.ndarray   # structured (time first)
    variables: dict         # {name: fmpy ScalarVariable}

    @property
    def outputs(self):
        return list(self.reference.dtype.names[1:])

    @property
    def steps(self):
        return int(round((self.stop - self.start) / self.step))


def read_csv_bytes(data):
    """fmpy's CSV layout (quoted header, time first) from bytes, every column float64."""
    lines = data.decode("utf-8").splitlines()
    names = [n.strip('"') for n in lines[0].split(",")]
    rows = [tuple(float(x) for x in line.split(",")) for line in lines[1:] if line]
    return np.array(rows, dtype=[(n, "f8") for n in names])


#: the SSP 1.0 type of the values of each FMI 2.0 and FMI 3.0 variable type we use
SSP_TYPE = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer",
            "Boolean": "Boolean"}


def variable_of(variables, name):
    """(variable, element index from 0 or None) behind a parameter name; ``name[j]`` that is
    not a variable itself is element j of an FMI 3.0 array (structured naming)."""
    if name in variables:
        return variables[name], None
    base, index = name[:-1].split("[")
    assert variables[base].dimensions, name
    return variables[base], int(index) - 1


def start_values(variables, parameters):
    """{variable name: value} to set: scalars as given, each FMI 3.0 array touched by an element
    as the list of all its elements (the others at their start values)."""
    out = {}
    for name, value in parameters.items():
        var, index = variable_of(variables, name)
        if index is None:
            out[name] = value
        else:
            array = out.setdefault(var.name, [float(x) for x in str(var.start).split()])
            array[index] = value
    return out


def read_ssv_bytes(data, variables):
    """{name: value} of an SSV, typed by the ssv element (checked against the FMU's type)."""
    out = {}
    for p in ET.fromstring(data).iter(f"{SSV}Parameter"):
        (value,) = list(p)
        kind = value.tag[len(SSV):]
        name = p.get("name")
        var, _ = variable_of(variables, name)
        assert SSP_TYPE[var.type] == kind, (name, kind, var.type)
        text = value.get("value")
        out[name] = {"Real": float, "Integer": int, "Boolean": lambda s: s == "true"}[kind](text)
    return out


def manifest(fmu):
    """The parsed ``fmi-ls-manifest.xml`` root of an FMU."""
    with zipfile.ZipFile(fmu) as zf:
        return ET.fromstring(zf.read(LS_REF + "fmi-ls-manifest.xml"))


def zip_fmu(folder, fmu):
    """Zip every file below `folder` into `fmu` (names relative to the folder, in order);
    returns `fmu`."""
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(Path(folder).rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(folder).as_posix())
    return fmu


def simulate_experiment(fmu, exp, parameters=None):
    """fmpy's run of experiment `exp` on the FMU at `fmu` (its own, or another build's or
    edition's): its times, stimuli and outputs, with its parameters (or `parameters`) as start
    values, FMI 3.0 arrays whole (:func:`start_values`)."""
    import fmpy

    params = exp.parameters if parameters is None else parameters
    return fmpy.simulate_fmu(str(fmu), start_time=exp.start, stop_time=exp.stop,
                             output_interval=exp.step, input=exp.stimuli,
                             start_values=start_values(exp.variables, params), output=exp.outputs)


def load_experiment(fmu):
    """The (single) experiment of the FMU at `fmu`, following the manifest."""
    import fmpy

    md = fmpy.read_model_description(str(fmu))
    variables = {v.name: v for v in md.modelVariables}
    root = manifest(fmu)
    (exp_rel,) = [r.get("source") for r in root.iter("Related")
                  if r.get("role", "").startswith("experiment")]
    with zipfile.ZipFile(fmu) as zf:
        exp_root = ET.fromstring(zf.read(LS_REF + exp_rel))
        (exp,) = exp_root.iter("Experiment")

        def file(tag):
            el = exp.find(tag)
            return None if el is None else zf.read(LS_REF + el.get("source"))

        params = file("Parameters")
        stimuli = file("Stimuli")
        return Experiment(
            name=exp.get("name"), start=float(exp.get("startTime")),
            stop=float(exp.get("stopTime")), step=float(exp.get("stepSize")),
            tolerance=float(exp.get("tolerance")),
            parameters=read_ssv_bytes(params, variables) if params else {},
            stimuli=read_csv_bytes(stimuli) if stimuli else None,
            reference=read_csv_bytes(file("References")),
            variables=variables)


def worst_violation(result, experiment):
    """max over samples and outputs of |y - y_ref| / (tolerance (1 + |y_ref|)): <= 1 passes."""
    worst = 0.0
    for name in experiment.outputs:
        y = np.asarray(result[name], dtype=float)
        ref = experiment.reference[name]
        worst = max(worst, float(np.max(np.abs(y - ref) / (experiment.tolerance * (1 + np.abs(ref))))))
    return worst


def unzip(fmu, folder):
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
    return folder


__all__ = ["Experiment", "load_experiment", "manifest", "read_csv_bytes", "read_ssv_bytes",
           "start_values", "variable_of", "SSP_TYPE",
           "worst_violation", "unzip", "LS_REF"]
