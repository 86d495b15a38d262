"""The compute bound of a sweep: how many runs per second the native runner alone would
run on the cores the sweep has (``python -m harness sweep`` measures it in its own command,
``bench`` shows it for runs of a few lengths).

The runner's cost per sample is measured as ``python -m harness bench`` measures it (the
native runner recording every output, thread CPU time in blocks of
:data:`harness.bench.measure.BLOCK` samples, the median of the blocks), on each swept
scenario's own experiment with its nominal plant. The bound is then the cores divided by
the CPU time of the runs: ``cores / sum over the runs of (ns/sample x samples)``. Whatever
a sweep spends besides (drawing the parameters, setting up each run, the checks and metrics,
the rows, Dask) keeps it below the bound.
"""

from __future__ import annotations

from dataclasses import dataclass
import statistics

import numpy as np

from ..masters import NativeLoop
from .measure import BLOCK

__all__ = ["Bound", "INSTANCES", "RUN_SECONDS", "TIMED_SAMPLES", "measure_runner"]

#: samples timed per scenario (at least; whole runs)
TIMED_SAMPLES = 150_000
#: fresh instance pairs they are spread over
INSTANCES = 3
#: the run lengths [s] whose bound ``bench`` shows (those of docs/speed.md's sweep table)
RUN_SECONDS = (0.5, 3.0, 30.0)


@dataclass(frozen=True)
class Bound:
    """The native runner's cost per scenario, and the cores it is divided among.

    Attributes
    ----------
    ns_per_sample : dict
        Scenario name -> the runner's median ns per sample.
    samples : dict
        Scenario name -> samples per run.
    cores : int
        Runs computed at once (the local cluster's workers, at most the machine's cores; the
        worker threads of a cluster given by address; 1 in this process).
    """

    ns_per_sample: dict
    samples: dict
    cores: int

    def seconds_per_run(self, counts):
        """The runner's mean CPU seconds per run, over ``counts`` (scenario name -> runs)."""
        total = sum(counts.values())
        ns = sum(c * self.ns_per_sample[k] * self.samples[k] for k, c in counts.items())
        return ns * 1e-9 / total if total else float("nan")

    def runs_per_second(self, counts):
        """The bound for ``counts`` (scenario name -> runs): runs per second on the cores."""
        return self.cores / self.seconds_per_run(counts)


def measure_runner(setups, fmu_dir=None, samples=TIMED_SAMPLES, instances=INSTANCES):
    """The native runner's median ns/sample on each experiment.

    Parameters
    ----------
    setups : dict
        Scenario name -> :class:`harness.loop.ClosedLoopSetup`.
    fmu_dir : path, optional
    samples : int
        Samples to time per experiment (whole runs, at least one per instance).
    instances : int
        Fresh instance pairs the samples are spread over: the cost moves by a few percent
        from one pair to the next (where their memory lies), and the median over the pairs'
        blocks does not bet on one of them.

    Returns
    -------
    dict
        Scenario name -> ns/sample.
    """
    per_block = {name: [] for name in setups}
    for _ in range(instances):
        loop = NativeLoop(fmu_dir)
        try:
            for name, setup in setups.items():
                block = min(BLOCK, setup.n)
                for _ in range(max(1, -(-samples // (instances * setup.n)))):
                    loop.run(setup, block=block)
                    per_block[name].extend((np.asarray(loop.last_block_ns) / block).tolist())
        finally:
            loop.close()
    return {name: statistics.median(values) for name, values in per_block.items()}
