"""The model binding: the C core through cffi, and the names the FMUs give its parameters.

* :mod:`~harness.binding.core`: the cffi binding of ``libpiezo_core.so`` (no FMI);
* :mod:`~harness.binding.fmu_variables`: every FMU's variables and the core's parameter
  tables, generated from the FMUs' declarations by ``packaging/fmu_interface.py``;
* :mod:`~harness.binding.closed_loop`: PiezoStageClosedLoop's parameter names (the three
  FMUs' under its names).

Nothing is imported here, so ``from harness.binding import fmu_variables`` loads no library.
"""
