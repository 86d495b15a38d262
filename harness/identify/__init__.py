"""Identification of the coupled model (paper section 3), by job.

* :mod:`~harness.identify.model`: the blocks evaluated forward (PI, G, creep);
* :mod:`~harness.identify.steps`: the paper's three steps, each on its own;
"""

from .model import *  # noqa: F401,F403
from .model import __all__ as _model_all
from .steps import *  # noqa: F401,F403
from .steps import __all__ as _steps_all

__all__ = list(_model_all) + list(_steps_all)
