"""``python -m harness sweep``: its options and what it runs."""

from __future__ import annotations

import os
import sys

from .. import masters
from ..scenarios import load_scenarios
from .dispatch import NO_WORKERS_TIMEOUT, SweepIncompleteError, run_sweep
from .outputs import PROG, format_summary, write_outputs

__all__ = ["add_sweep_arguments", "run_sweep_command"]


def add_sweep_arguments(parser):
    """Add the options of ``sweep`` to an argparse parser."""
    parser.add_argument("scenarios", nargs="+", metavar="SCENARIO",
                        help="tracking scenario(s) to sweep (see: python -m harness list)")
    parser.add_argument("-n", "--runs", type=int, default=100, metavar="N",
                        help="runs per scenario (default 100)")
    parser.add_argument("--vary", action="append", default=[], metavar="KEY=SPEC",
                        help="a spread of plant parameters, repeatable: KEY is pi.weights, "
                             "tf.poles, tf.zero, tf.gain, creep.k_c, creep.alpha, any Real "
                             "PiezoStage parameter, or sensor.seed (no SPEC: a seed per run); "
                             "SPEC is [uniform:|normal:]WIDTH[%%] (%% relative, else absolute), "
                             "e.g. --vary pi.weights=10%% --vary creep.alpha=normal:0.005")
    parser.add_argument("--seed", type=int, default=1, help="seed of the draws (default 1)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="address of an existing Dask scheduler (default: start a local "
                             "cluster of worker processes)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="worker processes of the local cluster (default: one per core; "
                             "0: run in this process without Dask)")
    parser.add_argument("--chunk", type=int, metavar="N", help="runs per Dask task (default: auto)")
    parser.add_argument("--no-workers-timeout", type=float, default=NO_WORKERS_TIMEOUT, metavar="SECONDS",
                        help=f"how long a sweep on Dask waits with no worker on the cluster (all "
                             f"lost, or none yet) before it stops; the runs done stay in the "
                             f"journal for --resume (default {NO_WORKERS_TIMEOUT:.0f})")
    parser.add_argument("--backend", choices=masters.SWEEP_BACKENDS, default="native",
                        help="master of each run: native (default) or fmpy")
    parser.add_argument("--no-adaptation", action="store_true", help="switch the controller's RLS off")
    parser.add_argument("--no-preview", action="store_true", help="feed y_d(k) instead of y_d(k+d)")
    parser.add_argument("--jacobi", action="store_true", help="Jacobi master")
    parser.add_argument("--out", default=os.path.join("out", "sweep"), metavar="DIR",
                        help="output folder (default out/sweep)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the interrupted sweep in --out (the same scenarios, -n, "
                             "--seed, --vary and options): only its missing runs are computed")
    parser.add_argument("--no-plots", action="store_true", help="do not write the PNG")
    parser.add_argument("--fmu-dir", metavar="DIR", help="folder of the FMUs (default build/fmus)")
    parser.add_argument("--scenario-file", action="append", default=[], metavar="FILE",
                        help="TOML file of extra scenarios (repeatable)")
    return parser


def run_sweep_command(args, stream=None):
    """Run ``sweep`` with parsed arguments; print the table; return the exit code (0: the sweep
    ran, whatever its runs did; 1: runs are missing after every attempt)."""
    stream = stream or sys.stdout
    if args.runs < 1:
        raise ValueError(f"--runs must be at least 1, got {args.runs}")
    if args.workers is not None and args.workers < 0:
        raise ValueError(f"--workers must be >= 0, got {args.workers}")
    if args.chunk is not None and args.chunk < 1:
        raise ValueError(f"--chunk must be at least 1, got {args.chunk}")
    timeout = getattr(args, "no_workers_timeout", NO_WORKERS_TIMEOUT)
    if not timeout >= 0:
        raise ValueError(f"--no-workers-timeout must be >= 0, got {timeout}")
    registry = load_scenarios(args.scenario_file)
    try:
        result = run_sweep(args.scenarios, args.vary, args.runs, seed=args.seed, scheduler=args.scheduler,
                           workers=args.workers, chunk=args.chunk, backend=args.backend,
                           adaptation=False if args.no_adaptation else None,
                           preview=not args.no_preview,
                           master="jacobi" if args.jacobi else "gauss-seidel", fmu_dir=args.fmu_dir,
                           registry=registry, progress=sys.stderr, out=args.out,
                           resume=getattr(args, "resume", False), no_workers_timeout=timeout)
    except SweepIncompleteError as exc:
        sys.stderr.write(f"{PROG}: error: {exc}\n")
        return 1
    stream.write(format_summary(result))
    written = write_outputs(result, args.out, plots=not args.no_plots)
    stream.write("wrote " + ", ".join(str(p) for p in written) + "\n")
    return 0
