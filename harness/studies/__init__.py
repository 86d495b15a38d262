"""The studies: each measures a documented family and writes its page's table, run as
``python -m harness <study>`` (:data:`harness.cli.STUDIES`).

* :mod:`.timing_table`: what the FMUs detect under each master (docs/cosimulation.md);
* :mod:`.supervision_table`: the controller's supervision, its fault tables and families
  (docs/robustness.md);
* :mod:`.stage_use_table`: the stage-use targets on the family of stages (docs/stage_use.md);
* :mod:`.stage_day_table`: a stage's day on the stage family (docs/stage_day.md).

Each module's ``main(argv, prog)`` parses its own options; they run the loop through the
masters' registry (:mod:`harness.masters`) and the scenarios (:mod:`harness.scenarios`).
"""
