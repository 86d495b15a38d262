"""``python -m harness sweep``: Monte Carlo robustness sweeps of the closed loop on Dask.

N closed-loop runs per scenario, each with the plant's parameters drawn from
distributions the user gives (``--vary``), run by Dask: a local cluster of worker
processes by default (one per core), or an existing cluster with ``--scheduler ADDRESS``.
Each worker loads the FMUs once (the client ships the FMU files, so every worker runs
exactly the client's build) and reuses its instances from run to run through
``fmi2Reset`` (:class:`harness.masters.native.NativeLoop`).

A spread is ``KEY=SPEC``. SPEC is ``[uniform:|normal:]WIDTH[%]``: ``uniform`` (default)
draws from [-WIDTH, WIDTH], ``normal`` from N(0, WIDTH^2); with ``%`` the change is
relative (WIDTH in percent), without it absolute. KEY is

* ``pi.weights``: every PI weight (w0, w[1..m]) independently;
* ``tf.poles``: each pole of G independently (relative: in the pole's continuous-time
  frequency ln(p)/h, i.e. p -> p^(1 + delta), so a relative spread never makes a stable
  pole unstable; absolute: p -> p + delta; a complex pair moves together, absolute in
  its radius), at fixed DC gain and zero;
* ``tf.zero``: the zero of B = b1 z^-1 + b2 z^-2 (z0 = -b2/b1; relative as for the
  poles), at fixed DC gain;
* ``tf.gain``: the DC gain of G;
* ``creep.k_c``, ``creep.alpha``, or any other Real PiezoStage parameter by its name;
* ``sensor.seed`` (no SPEC): every run gets its own sensor-noise seed.

A sweep must move something: without a spread (or with only spreads of width 0) every run
would be the same run, and it is refused. Run i draws its parameters from a generator seeded
by (``--seed``, i), on the worker that runs it, so a sweep is reproducible whatever the
scheduling, and the same draws are applied to every scenario's own plant. A run that
diverges (the controller's monitor stops it, a value overflows, or its error exceeds the
reference: :mod:`harness.loop.checks`), clips its voltage persistently, or whose drawn
parameters the FMU refuses is counted and reported; it does not stop the sweep.

Speed: a task is a batch of runs in one C call of the native runner
(``piezo_runner_batch``: no Python between runs), its parameters drawn for the whole task
and its rows written in one go; the checks' rules decide on the batch's sums, and a run
that fails them is run again on its own for its status and message (:mod:`.worker`). A
task is about half a second of the runner's CPU time (fewer runs towards the end). The
summary prints the runs/s next to the compute bound measured in the same command
(:mod:`harness.bench.bound`: the runner's ns/sample x samples per run / cores).

Scale: each task's rows are appended to ``sweep_runs.journal.csv`` (and flushed) as it
completes; the client keeps 25 bytes per run, queues a few tasks per worker and makes each
task as it hands it out, so its memory grows by those 25 bytes per run only. A worker may be
lost at any moment: what every task needs is a task of its own that the scheduler computes
again (not scattered data, which it cannot), a task lost with its worker is run again, and a
run is recorded once; with no worker on the cluster the sweep waits ``--no-workers-timeout``
seconds for one, then stops with its runs in the journal. ``--resume`` continues an
interrupted sweep from its journal (``sweep_manifest.json`` says what the runs depend on; a
different sweep is refused): only the missing runs are computed.

Results (under ``--out``, default ``out/sweep``): the table of percentiles and worst case
of e_rms and e_r per scenario (printed, ``sweep_summary.csv``/``.md``), every run with its
drawn parameters (``sweep_runs.csv``, sorted by scenario and run), the worst run's parameter
set as a scenario file keyed by FMU variable names (``worst_<scenario>.toml``: rerun it with
``python -m harness run worst_<scenario> --scenario-file ...``), and histogram and CDF of
e_rms (``sweep_e_rms.png``).
"""

from .sweep_command import add_sweep_arguments, run_sweep_command
from .outputs import summary_rows, write_outputs
from .manifest import MANIFEST
from .dispatch import SweepIncompleteError, plant_start_values, run_sweep
from .spreads import Spread, draw_plant_parameters, parse_spread
from .store import JOURNAL, RUNS, STATUSES, SweepResult

__all__ = ["Spread", "parse_spread", "draw_plant_parameters", "run_sweep", "SweepResult",
           "add_sweep_arguments", "run_sweep_command", "STATUSES", "SweepIncompleteError",
           "plant_start_values", "summary_rows", "write_outputs", "JOURNAL", "RUNS", "MANIFEST"]
