"""``python -m harness bench``: speed and memory of the core, the FMI layer and the masters.

Figures are printed, never asserted (the machine is shared and noisy). Every loop runs a
closed-loop scenario (default ``mismatch_1_5_10hz``: the mismatched plant with its sensor
noise, adaptation on) up to ``--samples`` samples (default 1e6, 500 s) and times blocks of
250 samples with the thread's CPU clock, so preemption by other processes does not count.
The cost "at N samples into a run" is the median over the blocks of the last 10000 samples
before N (the last N/2 for N < 20000) and over the repetitions.

Loops, all on the same trajectory (the core closed loop records y_meas and v, which drive
the plant and the controller timed alone):

* plant core, controller core, core closed loop: ``build/libpiezo_bench.so`` (C, no FMI);
* fmi2 API loop: the native runner with the minimal exchange (y_meas and v only,
  nothing recorded): what the fmi2 calls of both FMUs cost;
* native runner: the native master recording every output (``--backend native``);
* fmpy loop: the fmpy master (``--backend fmpy``).

Also: memory per instance (core structs; bytes each FMU allocates in fmi2Instantiate),
exact creep mode's O(k) cost and history, the end-to-end time of one 3 s run per
master, a sweep's compute bound for runs of 0.5, 3 and 30 s (:mod:`.bound`: the native
runner's ns/sample x samples a run / cores; ``sweep`` measures its own), and the machine.
"""

from .bench_command import add_bench_arguments, run_bench
from .measure import CHECKPOINTS, measure
from .text_report import format_figures

__all__ = ["CHECKPOINTS", "add_bench_arguments", "run_bench", "measure", "format_figures"]
