"""Former home of the identification code, kept so that existing imports work.

Everything now lives in :mod:`harness.identify` (``model``: the blocks;
``steps``: the paper's three steps; ``fit``: fit from measured ``v`` and ``y``;
``data``: user CSV records; ``params`` and ``export``: parameter files and
parameterised FMUs; ``demo``: the virtual experiment).
"""

from .identify.model import *  # noqa: F401,F403
from .identify.model import __all__ as _model_all
from .identify.steps import *  # noqa: F401,F403
from .identify.steps import __all__ as _steps_all

__all__ = list(_model_all) + list(_steps_all)
