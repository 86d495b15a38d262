"""Co-simulation harness for the piezo stage FMUs (docs/cosimulation.md, docs/model.md).

Public API
----------
Simulation
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

Heavy dependencies (fmpy, cffi, matplotlib) are imported on first use.
"""

from .cosim import (
    FMUError,
    FMUInitializationError,
    UnknownParameterError,
    simulate_closed_loop,
    simulate_open_loop,
)
from .core_loop import simulate_closed_loop_core, simulate_open_loop_core
from .identify import (
    CoupledModel,
    CoupledModelEstimate,
    IdentificationInputError,
    IdentificationRecord,
    fit_coupled_model,
    identify_coupled_model,
    identify_creep,
    identify_pi,
    identify_transfer_function,
    read_params,
    read_record,
    run_identification,
)
from .identify.export import export_fmus
from .native import simulate_closed_loop_native
from .sweep import run_sweep
from .metrics import Metrics, compute_metrics, relative_error, rms_error
from .report import (
    evaluate_tracking,
    evaluate_validation,
    run_all,
    run_scenario,
)
from .scenarios import (
    Scenario,
    ScenarioError,
    ScenarioFileError,
    Signal,
    UnknownScenarioError,
    get_scenario,
    list_scenarios,
    load_scenario_file,
    load_scenarios,
)

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
