"""Identification of the coupled model (paper section 3), by job.

* :mod:`~harness.identify.data`: a user's CSV records (time, v, y) in, validated;
* :mod:`~harness.identify.model`: the blocks evaluated forward (PI, G, creep);
* :mod:`~harness.identify.steps`: the paper's three steps, each on its own;
* :mod:`~harness.identify.fit`: the coupled model from measured v and y (stepwise as a
  start, a search, a joint refinement, the check that every parameter is determined),
  under a documented normalisation;
* :mod:`~harness.identify.varpro`: the search by variable projection (the PI weights
  solved, poles, zero and creep order searched from several starts);
* :mod:`~harness.identify.family`: the method validated on stages drawn from the paper's
  ranges;
* :mod:`~harness.identify.params`: parameter files (JSON of FMU variable names);
* :mod:`~harness.identify.export`: parameterised FMUs;
* :mod:`~harness.identify.from_files`, :mod:`~harness.identify.result_tables`: files in, reports out;
* :mod:`~harness.identify.demo`: the virtual experiment;
* :mod:`~harness.identify.internal`: each step alone on the model's internal outputs
  (``identify --internal-channels``);
* :mod:`~harness.identify.identify_command`: the command-line pieces.

Heavy modules (fmpy, scipy) are imported on first use.
"""

from .data import MeasuredRecord, RecordError, read_record, write_record
from .fit import (
    CoupledModel,
    IdentificationFitError,
    IdentificationResult,
    fit_coupled_model,
)
from .model import *  # noqa: F401,F403
from .model import __all__ as _model_all
from .internal import (
    IdentificationRow,
    IdentificationRun,
    format_identification_table,
    generate_identification_records,
    run_identification,
    write_identification_csv,
)
from .params import ParameterFileError, read_params, write_params
from .steps import *  # noqa: F401,F403
from .steps import __all__ as _steps_all

__all__ = list(_model_all) + list(_steps_all) + [
    "MeasuredRecord", "RecordError", "read_record", "write_record",
    "CoupledModel", "IdentificationFitError", "IdentificationResult", "fit_coupled_model",
    "ParameterFileError", "read_params", "write_params",
    "IdentificationRow", "IdentificationRun", "format_identification_table",
    "generate_identification_records", "run_identification", "write_identification_csv",
]
