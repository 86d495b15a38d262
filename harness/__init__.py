"""Co-simulation harness for the piezo stage FMUs (docs/cosimulation.md, docs/model.md).

Public API
----------
Simulation (package :mod:`harness.masters`, whose registry says which master runs what)
    :func:`simulate_closed_loop` (FMUs through fmpy), :func:`simulate_open_loop`,
    :func:`simulate_closed_loop_native` (the same FMUs and loop in the native C master),
    :func:`simulate_closed_loop_core` / :func:`simulate_open_loop_core` (C core, no FMI).
Speed and scale
    ``python -m harness bench`` (:mod:`harness.bench`), Monte Carlo sweeps on Dask
    :func:`run_sweep` (``python -m harness sweep``, :mod:`harness.sweep`).
Scenarios
    :func:`load_scenarios`, :func:`load_scenario_file`, :func:`get_scenario`,
    :func:`list_scenarios`, :class:`Scenario`, :class:`Signal`.
Metrics
    :func:`compute_metrics`, :func:`rms_error`, :func:`relative_error`.
Identification (paper section 3; :mod:`harness.identify`)
    :func:`identify_pi`, :func:`identify_transfer_function`, :func:`identify_creep`,
    :func:`identify_coupled_model`, :class:`IdentificationRecord`,
    :class:`CoupledModelEstimate`, :func:`run_identification`; from measured
    records: :func:`read_record`, :func:`fit_coupled_model`, :class:`CoupledModel`,
    :func:`read_params`, :func:`export_fmus`.
Reports
    :func:`run_all` (the main job), :func:`run_scenario`, :func:`evaluate_tracking`,
    :func:`evaluate_validation` (package :mod:`harness.report`).

The layers and each module's job: docs/harness.md. scipy, matplotlib and dask are imported
on first use (the package imports with fmpy, cffi and numpy alone).
"""

import importlib

#: where each public name lives (the package imports its modules when a name is first used, so
#: that ``python -m harness.buildtime.ssp_file`` and ``python -m harness.buildtime.references``, the build's entry
#: points, do not import themselves twice, and ``import harness.scenarios`` stays light)
_HOMES = {
    "fmu": ("FMUError", "FMUInitializationError", "UnknownParameterError"),
    "masters.c_core": ("simulate_closed_loop_core", "simulate_open_loop_core"),
    "masters.fmpy": ("simulate_closed_loop", "simulate_open_loop"),
    "masters.native": ("simulate_closed_loop_native",),
    "identify": ("CoupledModel", "CoupledModelEstimate", "IdentificationInputError",
                 "IdentificationRecord", "fit_coupled_model", "identify_coupled_model",
                 "identify_creep", "identify_pi", "identify_transfer_function", "read_params",
                 "read_record", "run_identification"),
    "identify.export": ("export_fmus",),
    "sweep": ("run_sweep",),
    "loop.metrics": ("Metrics", "compute_metrics", "relative_error", "rms_error"),
    "report": ("evaluate_tracking", "evaluate_validation", "run_all", "run_scenario"),
    "scenarios": ("Scenario", "ScenarioError", "ScenarioFileError", "Signal",
                  "UnknownScenarioError", "get_scenario", "list_scenarios", "load_scenario_file",
                  "load_scenarios"),
}
_MODULE_OF = {name: module for module, names in _HOMES.items() for name in names}


def __getattr__(name):
    """A public name (imported from its module on first use), or a submodule."""
    module = _MODULE_OF.get(name)
    if module is not None:
        value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
        globals()[name] = value
        return value
    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


def __dir__():
    return sorted(set(globals()) | set(_MODULE_OF))


__all__ = [
    "simulate_closed_loop",
    "simulate_open_loop",
    "simulate_closed_loop_native",
    "run_sweep",
    "simulate_closed_loop_core",
    "simulate_open_loop_core",
    "load_scenarios",
    "load_scenario_file",
    "get_scenario",
    "list_scenarios",
    "Scenario",
    "Signal",
    "compute_metrics",
    "rms_error",
    "relative_error",
    "Metrics",
    "identify_pi",
    "identify_transfer_function",
    "identify_creep",
    "identify_coupled_model",
    "IdentificationRecord",
    "CoupledModelEstimate",
    "IdentificationInputError",
    "read_record",
    "fit_coupled_model",
    "CoupledModel",
    "read_params",
    "export_fmus",
    "run_identification",
    "run_all",
    "run_scenario",
    "evaluate_tracking",
    "evaluate_validation",
    "FMUError",
    "FMUInitializationError",
    "UnknownParameterError",
    "ScenarioError",
    "ScenarioFileError",
    "UnknownScenarioError",
]
