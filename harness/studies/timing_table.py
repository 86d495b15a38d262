"""What the FMUs detect under each master: the table of docs/cosimulation.md, measured.

Every master that installs here runs the mismatch case's six scenarios with every FMU at its
defaults, with the plant as specified and with one more sample of input delay
(``tf.delay = 1``). For each master and plant the table gives what the controller reports at
the end (``loop_delay``, ``preview_lead``, ``meas_offset``), when it chose its delay (the
latest ``loop_delay_time`` of the six runs) and the e_rms of each scenario over [1, 3) s::

    python -m harness timing                  # the table, in Markdown
    python -m harness timing --seeds 1 2 3 4  # the family: e_rms and choice times over seeds

The masters (their schedules: docs/cosimulation.md, section 2), each asked of the registry
:mod:`harness.masters`: our Gauss-Seidel in both doStep orders and our Jacobi (``fmpy``),
fmpy's SSP player (``ssp-player``) and fmu-manipulation-toolbox's container
(``container``) in parallel mode and in sequential mode with each of the 6 orders of its FMU
list.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
from dataclasses import dataclass, field

from .. import masters
from ..loop import EXCHANGE_LOOP_DELAY
from ..loop.metrics import compute_metrics
from ..masters import CONTAINER_ORDER
from ..scenarios import MISMATCH_SCENARIOS, get_scenario, reference_label

__all__ = ["MASTERS", "MasterRun", "run_master", "measure", "markdown_table", "family_summary", "main"]

_ABBREV = {"ReferenceSignal.fmu": "reference", "AdaptiveCompoundController.fmu": "controller",
           "PiezoStage.fmu": "plant"}


def _orders():
    """The orders of the container's FMU list."""
    return list(itertools.permutations(CONTAINER_ORDER))


def _master_names():
    names = ["harness Gauss-Seidel, plant first", "harness Gauss-Seidel, controller first",
             "harness Jacobi", "fmpy SSP player", "container, parallel"]
    for order in _orders():
        names.append("container, sequential: " + ", ".join(_ABBREV[f] for f in order))
    return names


#: the masters of the table, in its order
MASTERS = tuple(_master_names())


@dataclass
class MasterRun:
    """One scenario under one master: the e_rms [um] and what the controller reported."""

    master: str
    scenario: str
    tf_delay: int
    seed: int | None
    e_rms: float
    loop_delay: int
    loop_delay_time: float
    preview_lead: int
    meas_offset: int
    extra: dict = field(default_factory=dict)


def run_master(master, scenario, tf_delay=0, seed=None, workdir=None):
    """Run one scenario under one master, every FMU at its defaults.

    Parameters
    ----------
    master : str
        One of :data:`MASTERS`.
    scenario : str
        A tracking scenario with a sines reference.
    tf_delay : int
        The plant's ``tf.delay``.
    seed : int, optional
        The plant's ``sensor.seed`` (default: the scenario's).
    workdir : str or Path, optional
        Where the containers are written (default: a temporary folder).

    Returns
    -------
    MasterRun
    """
    if master not in MASTERS:
        raise ValueError(f"unknown master {master!r}; masters: {', '.join(MASTERS)}")
    sc = get_scenario(scenario)
    plant = {"tf.delay": int(tf_delay)}
    if seed is not None:
        plant["sensor.seed"] = int(seed)
    if master.startswith("harness"):
        timing = {}
        kwargs = {"master": "jacobi"} if "Jacobi" in master else \
            {"step_order": "controller-first" if "controller first" in master else "plant-first"}
        run = masters.closed_loop("fmpy")(sc.name, plant_params=plant, timing=timing, **kwargs)
    else:
        if master == "fmpy SSP player":
            run = masters.closed_loop("ssp-player")(sc.name, plant_params=plant)
        else:
            sequential = "sequential" in master
            order = CONTAINER_ORDER
            if sequential:
                names = master.split(": ")[1].split(", ")
                inverse = {v: k for k, v in _ABBREV.items()}
                order = tuple(inverse[n] for n in names)
            run = masters.closed_loop("container")(sc.name, sequential=sequential, order=order,
                                                   plant_params=plant, workdir=workdir)
        timing = {f: run[f][-1] for f in ("loop_delay", "loop_delay_time", "preview_lead", "meas_offset")}
    e = compute_metrics(run["time"], run["y_d"], run["y"], sc.metric_window, sc.step_size).e_rms
    return MasterRun(master, sc.name, int(tf_delay), seed, float(e), int(timing["loop_delay"]),
                     float(timing["loop_delay_time"]), int(timing["preview_lead"]),
                     int(timing["meas_offset"]))


def measure(masters=MASTERS, scenarios=None, tf_delays=(0, 1), seeds=(None,), progress=None):
    """Every master x tf.delay x seed x scenario, as a list of :class:`MasterRun`."""
    scenarios = list(scenarios or MISMATCH_SCENARIOS)
    runs = []
    for master, tf_delay, seed in itertools.product(masters, tf_delays, seeds):
        for name in scenarios:
            runs.append(run_master(master, name, tf_delay, seed))
        if progress is not None:
            progress(f"{master}, tf.delay {tf_delay}, seed {seed}")
    return runs


def markdown_table(runs):
    """The table of docs/cosimulation.md: one row per master and tf.delay."""
    scenarios = list(dict.fromkeys(r.scenario for r in runs))
    head = (["master", "tf.delay", "d chosen", "at [ms]", "preview lead", "meas offset"]
            + [f"{reference_label(get_scenario(s))} [nm]" for s in scenarios])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    keys = list(dict.fromkeys((r.master, r.tf_delay) for r in runs))
    for master, tf_delay in keys:
        group = [r for r in runs if (r.master, r.tf_delay) == (master, tf_delay)]
        by_scenario = {r.scenario: r for r in group}

        def same(attr):
            values = sorted({getattr(r, attr) for r in group})
            return "/".join(str(v) for v in values)

        cells = [master, str(tf_delay), same("loop_delay"),
                 f"{max(r.loop_delay_time for r in group) * 1e3:.1f}", same("preview_lead"),
                 same("meas_offset")]
        cells += [f"{by_scenario[s].e_rms * 1e3:.2f}" for s in scenarios]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def family_summary(runs):
    """Median and worst e_rms [nm] and choice time [ms] per scenario over every master,
    tf.delay and seed, and whether every run chose the schedule's delay (a Markdown table)."""
    scenarios = list(dict.fromkeys(r.scenario for r in runs))
    lines = ["| scenario | runs | e_rms median [nm] | e_rms worst [nm] | chosen at, median [ms] | "
             "chosen at, worst [ms] |", "|---|---|---|---|---|---|"]
    for s in scenarios:
        group = [r for r in runs if r.scenario == s]
        e = [r.e_rms * 1e3 for r in group]
        t = [r.loop_delay_time * 1e3 for r in group]
        lines.append(f"| {reference_label(get_scenario(s))} | {len(group)} | {statistics.median(e):.2f} | {max(e):.2f} | "
                     f"{statistics.median(t):.1f} | {max(t):.1f} |")
    return "\n".join(lines)


def main(argv=None, prog=None):
    """``python -m harness timing [--seeds N ...] [--master NAME ...] [--scenario NAME ...]``."""
    p = argparse.ArgumentParser(prog=prog or "python -m harness timing",
                                description="What the FMUs detect under each master (docs/cosimulation.md).")
    p.add_argument("--seeds", type=int, nargs="*", default=None,
                   help="sensor seeds: print the family's distribution instead of the table")
    p.add_argument("--master", action="append", choices=MASTERS, help="only these masters")
    p.add_argument("--scenario", action="append", help="only these scenarios")
    args = p.parse_args(argv)
    masters = args.master or MASTERS
    seeds = tuple(args.seeds) if args.seeds else (None,)
    # the containers' runtime writes notes to the standard output: send them to stderr
    # while measuring, so that stdout is the table alone
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        runs = measure(masters, args.scenario, seeds=seeds,
                       progress=lambda text: print(f"  done: {text}", file=sys.stderr, flush=True))
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
    wrong = [r for r in runs if r.loop_delay != _expected_delay(r)]
    if args.seeds:
        print(family_summary(runs))
    else:
        print(markdown_table(runs))
    if wrong:
        print(f"{len(wrong)} runs chose another delay than their schedule's: "
              + "; ".join(f"{r.master} tf.delay {r.tf_delay} {r.scenario}: {r.loop_delay}" for r in wrong))
        return 1
    return 0


def _expected_delay(run):
    """The loop delay of a master's schedule (docs/cosimulation.md, section 2)."""
    # a post-step link (the container's sequential mode) makes the loop one sample shorter
    return EXCHANGE_LOOP_DELAY - (1 if "sequential" in run.master else 0) + run.tf_delay


if __name__ == "__main__":
    sys.exit(main())
