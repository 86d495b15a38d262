"""Run the experiments and report them next to the paper's Tables 2-5.

One module per job:

* :mod:`.conditions`: what the main job runs (the tracking conditions) and
  what each condition is, in words built from its options;
* :mod:`.run`: running one scenario (:func:`evaluate_tracking`,
  :func:`evaluate_validation`) and its result;
* :mod:`.tables`: the tables (terminal, Markdown) and the CSV/NPZ files;
* :mod:`.figures`: the figures, one per question, PNG and SVG;
* :mod:`.document`: report.md and report.html from one list of blocks;
* :mod:`.provenance`: commit, FMU GUIDs and versions, package versions, date, machine;
* :mod:`.jobs`: the command line's jobs, :func:`run_all` and :func:`run_scenario`.

Progress lines (:mod:`harness.progress`) and plain tables (:mod:`harness.text_tables`)
are shared with the other jobs; the identification is :mod:`harness.identify`.
"""

from .conditions import Condition, default_conditions, describe_condition
from .figures import FigureFile
from .jobs import VALIDATION_NOTES, check_out_dir, prepare_out_dir, run_all, run_scenario
from .provenance import Provenance, collect_provenance
from .run import TrackingResult, ValidationResult, evaluate_tracking, evaluate_validation
from .tables import (
    format_conditions_table,
    format_tracking_table,
    format_validation_table,
    write_timeseries,
    write_timeseries_csv,
    write_timeseries_npz,
    write_tracking_csv,
    write_validation_csv,
)

__all__ = [
    "Condition",
    "TrackingResult",
    "ValidationResult",
    "FigureFile",
    "Provenance",
    "default_conditions",
    "describe_condition",
    "evaluate_tracking",
    "evaluate_validation",
    "format_tracking_table",
    "format_conditions_table",
    "format_validation_table",
    "write_tracking_csv",
    "write_validation_csv",
    "write_timeseries",
    "write_timeseries_csv",
    "write_timeseries_npz",
    "collect_provenance",
    "check_out_dir",
    "prepare_out_dir",
    "run_all",
    "run_scenario",
    "VALIDATION_NOTES",
]
