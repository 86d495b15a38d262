"""The loop run in libcosim (libcosimpy) and Ecos (ecospy), as their users run it
(tests/test_engines.py). Each function returns ``{field: array}`` of the samples at
``t_1 .. t_n`` (both engines report after a step): ``y_d`` (the reference's, or the closed-loop
FMU's ``reference``), ``y``, ``y_meas``, ``v`` and the controller's ``loop_delay``, and, under
``params``, the parameter values the engine's FMUs hold after initialization (read back, not
the ones given).

How each engine steps (read in its source, open-simulation-platform/libcosim
src/cosim/algorithm/fixed_step_algorithm.cpp and Ecos-platform/ecos src/ecos/simulation.cpp,
src/ecos/algorithm/fixed_step_algorithm.cpp): at initialization every FMU's outputs are
passed to the connected inputs (libcosim iterates once per FMU, Ecos once per instance), then
at every step every FMU steps from t_k with the inputs of t_k, and the outputs are passed to
the inputs afterwards: values exchanged at communication points, the loop delay d = 2, the
schedule of the harness's exchange master (:mod:`harness.masters.wired`, ``"exchange"``).
"""
import os
from pathlib import Path

import numpy as np

from harness.buildtime.ssp_file import SSP_COMPONENTS, SSP_CONNECTIONS

#: what is recorded: (field, component of the three-FMU loop, its variable)
RECORD = (("y_d", "reference", "y_d"), ("y", "plant", "y"), ("y_meas", "plant", "y_meas"),
          ("v", "controller", "v"))
#: the same of PiezoStageClosedLoop (one component)
RECORD_CLOSED_LOOP = (("y_d", "reference"), ("y", "y"), ("y_meas", "y_meas"), ("v", "v"))


def _ns(seconds):
    return int(round(seconds * 1e9))


# ---------------------------------------------------------------------------
# libcosim
# ---------------------------------------------------------------------------

def _libcosim_variables(ex, index):
    return {v.name.decode(): (v.reference, v.type) for v in ex.slave_variables(index)}


def _libcosim_set(ex, index, variables, values):
    from libcosimpy.CosimEnums import CosimVariableType as T
    for name, value in values.items():
        vr, typ = variables[name]
        if typ == T.REAL.value:
            ok = ex.real_initial_value(index, vr, float(value))
        elif typ == T.INTEGER.value:
            ok = ex.integer_initial_value(index, vr, int(value))
        else:
            ok = ex.boolean_initial_value(index, vr, bool(value))
        if not ok:
            raise RuntimeError(f"libcosim refused the initial value {name} = {value!r}")


def _libcosim_run(ex, n, record, read_back):
    """Step n times, recording after each step; read_back: {(index, name): (vr, type)}."""
    from libcosimpy.CosimObserver import CosimObserver
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    out = {field: np.zeros(n) for field, _, _ in record}
    out["loop_delay"] = np.zeros(n, dtype=int)
    delay_at = record[-1][1]
    for k in range(n):
        if not ex.step(1):
            raise RuntimeError(f"libcosim's step {k + 1} failed")
        for field, index, vr in record[:-1]:
            out[field][k] = obs.last_real_values(index, [vr])[0]
        out["loop_delay"][k] = obs.last_integer_values(delay_at[0], [delay_at[1]])[0]
    params = {}
    for (index, name), (vr, typ) in read_back.items():
        getter = obs.last_real_values if typ == 0 else obs.last_integer_values
        params[(index, name)] = getter(index, [vr])[0]
    return out, params


def libcosim_loop(fmus, params, n, h):
    """The three FMUs added one by one and connected as the SSP connects them, each parameter
    an initial value; a fixed-step execution of step h."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimSlave import CosimLocalSlave
    ex = CosimExecution.from_step_size(_ns(h))
    slaves = {comp: CosimLocalSlave(fmu_path=str(fmus[comp]), instance_name=comp) for comp in SSP_COMPONENTS}
    index = {comp: ex.add_local_slave(slave) for comp, slave in slaves.items()}
    variables = {comp: _libcosim_variables(ex, i) for comp, i in index.items()}
    for comp, values in params.items():
        _libcosim_set(ex, index[comp], variables[comp], values)
    for a, ac, b, bc in SSP_CONNECTIONS:
        ex.connect_real_variables(index[a], variables[a][ac][0], index[b], variables[b][bc][0])
    return _libcosim_record(ex, index, variables, n, params)


def libcosim_ssp(path, n, step=None):
    """The SSP loaded by libcosim, with the step it reads from the SSP (``step`` None) or the
    one given."""
    from libcosimpy.CosimExecution import CosimExecution
    ex = (CosimExecution.from_ssp_file(str(path)) if step is None
          else CosimExecution.from_ssp_file(str(path), step_size=_ns(step)))
    index = {info.name.decode(): info.index for info in ex.slave_infos()}
    variables = {comp: _libcosim_variables(ex, i) for comp, i in index.items()}
    return _libcosim_record(ex, index, variables, n, None)


def _libcosim_record(ex, index, variables, n, params):
    record = [(field, index[comp], variables[comp][var][0]) for field, comp, var in RECORD]
    record.append(("loop_delay", (index["controller"], variables["controller"]["loop_delay"][0]), None))
    read_back = {(comp, name): variables[comp][name] for comp in variables
                 for name in variables[comp] if variables[comp][name][1] in (0, 1)}
    out, values = _libcosim_run(ex, n, record, {(index[c], nm): v for (c, nm), v in read_back.items()})
    out["params"] = {f"{c}.{nm}": values[(index[c], nm)] for c, nm in read_back}
    return out


def libcosim_closed_loop_fmu(path, params, n, h):
    """PiezoStageClosedLoop alone in a fixed-step execution of step h."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimSlave import CosimLocalSlave
    ex = CosimExecution.from_step_size(_ns(h))
    slave = CosimLocalSlave(fmu_path=str(path), instance_name="loop")
    i = ex.add_local_slave(slave)
    variables = _libcosim_variables(ex, i)
    _libcosim_set(ex, i, variables, params)
    record = [(field, i, variables[var][0]) for field, var in RECORD_CLOSED_LOOP]
    record.append(("loop_delay", (i, variables["loop_delay"][0]), None))
    out, _ = _libcosim_run(ex, n, record, {})
    return out


# ---------------------------------------------------------------------------
# Ecos
# ---------------------------------------------------------------------------

def ecos_binary(name):
    """The path of one of ecospy's programs (``proxyfmu``, ``ecos``)."""
    import ecospy
    return Path(ecospy.__file__).parent / "binaries" / name


def _ecos_run(sim, n, record, parameter_set, read_back):
    sim.init(parameter_set=parameter_set)
    params = {name: getter(ident) for name, (getter, ident) in read_back(sim).items()}
    out = {field: np.zeros(n) for field, _ in record}
    out["loop_delay"] = np.zeros(n, dtype=int)
    delay = record[-1][1]
    for k in range(n):
        sim.step()
        for field, ident in record[:-1]:
            out[field][k] = sim.get_real(ident)
        out["loop_delay"][k] = sim.get_integer(delay)
    sim.terminate()
    out["params"] = params
    return out


def _ecos_record():
    record = [(field, f"{comp}::{var}") for field, comp, var in RECORD]
    record.append(("loop_delay", "controller::loop_delay"))
    return record


def _ecos_read_back(names):
    def read(sim):
        return {name: (sim.get_integer if isinstance(value, (bool, int)) else sim.get_real,
                       "::".join(name.split(".", 1)))
                for name, value in names.items() if not isinstance(value, bool)}
    return read


def ecos_loop(fmus, params, n, h, proxy=False):
    """The three FMUs added one by one (``proxy``: each in its own process, through
    ``proxyfmu://``), connected as the SSP connects them, the parameters one parameter set
    applied at ``init``."""
    from ecospy import EcosSimulation, EcosSimulationStructure
    with EcosSimulationStructure() as ss:
        for comp in SSP_COMPONENTS:
            uri = f"proxyfmu://localhost?file={fmus[comp]}" if proxy else str(fmus[comp])
            ss.add_model(comp, uri)
        for a, ac, b, bc in SSP_CONNECTIONS:
            ss.make_real_connection(f"{a}::{ac}", f"{b}::{bc}")
        flat = {f"{comp}::{name}": value for comp, values in params.items() for name, value in values.items()}
        if flat:
            ss.add_parameter_set("run", flat)
        with EcosSimulation(structure=ss, step_size=h) as sim:
            names = {f"{comp}.{name}": value for comp, values in params.items() for name, value in values.items()}
            return _ecos_run(sim, n, _ecos_record(), "run" if flat else None, _ecos_read_back(names))


def ecos_ssp(path, n, h, parameter_set=None, names=()):
    """The SSP loaded by Ecos (its API takes the step), ``init(parameter_set=...)``; ``names``:
    the ``<component>.<variable>`` to read back after initialization."""
    from ecospy import EcosSimulation
    with EcosSimulation(step_size=h, ssp_path=str(path)) as sim:
        return _ecos_run(sim, n, _ecos_record(), parameter_set, _ecos_read_back(dict(names)))


def ecos_closed_loop_fmu(path, params, n, h):
    """PiezoStageClosedLoop alone."""
    from ecospy import EcosSimulation, EcosSimulationStructure
    with EcosSimulationStructure() as ss:
        ss.add_model("loop", str(path))
        flat = {f"loop::{name}": value for name, value in params.items()}
        if flat:
            ss.add_parameter_set("run", flat)
        with EcosSimulation(structure=ss, step_size=h) as sim:
            record = [(field, f"loop::{var}") for field, var in RECORD_CLOSED_LOOP]
            record.append(("loop_delay", "loop::loop_delay"))
            return _ecos_run(sim, n, record, "run" if flat else None, lambda s: {})


def ecos_proxy_ready():
    """None, or why ecospy's proxyfmu cannot run here (its wheel ships it without the run bit)."""
    path = ecos_binary("proxyfmu")
    if not path.is_file():
        return f"{path} is missing"
    if not os.access(path, os.X_OK):
        return f"{path} lacks the run bit (ecospy's wheel ships it so): chmod +x it, as .ci/run does"
    return None
