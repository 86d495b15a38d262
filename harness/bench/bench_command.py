"""``python -m harness bench``: its options and what it runs."""

from __future__ import annotations

import sys

from ..paths import describe_fmu_dir
from ..scenarios import load_scenarios
from .measure import BLOCK, CHECKPOINTS, measure
from .text_report import format_figures

__all__ = ["add_bench_arguments", "run_bench"]


def add_bench_arguments(parser):
    """Add the options of ``bench`` to an argparse parser."""
    parser.add_argument("--scenario", default="mismatch_1_5_10hz",
                        help="tracking scenario whose parameters and reference are run "
                             "(default mismatch_1_5_10hz)")
    parser.add_argument("--samples", type=int, default=CHECKPOINTS[-1], metavar="N",
                        help="length of the timed runs; checkpoints beyond it are skipped "
                             "(default 1000000)")
    parser.add_argument("--repeat", type=int, default=5, metavar="R",
                        help="repetitions of the C loops (default 5)")
    parser.add_argument("--fmpy-repeat", type=int, default=3, metavar="R",
                        help="repetitions of the fmpy loop (default 3)")
    parser.add_argument("--no-fmpy", action="store_true", help="skip the fmpy loop")
    parser.add_argument("--fmu-dir", metavar="DIR",
                        help=f"folder of the FMUs (default: {describe_fmu_dir()})")
    parser.add_argument("--scenario-file", action="append", default=[], metavar="FILE",
                        help="TOML file of extra scenarios (repeatable)")
    return parser


def run_bench(args, stream=None):
    """Run ``bench`` with parsed arguments; print the figures; return the exit code."""
    stream = stream or sys.stdout
    if args.samples < 2 * BLOCK:
        raise ValueError(f"--samples must be at least {2 * BLOCK}, got {args.samples}")
    if args.repeat < 1 or args.fmpy_repeat < 1:
        raise ValueError("--repeat and --fmpy-repeat must be at least 1")
    registry = load_scenarios(args.scenario_file)
    figures = measure(args.scenario, n_max=args.samples, repeat=args.repeat,
                      fmpy_repeat=0 if args.no_fmpy else args.fmpy_repeat,
                      fmu_dir=args.fmu_dir, registry=registry, progress=sys.stderr)
    stream.write(format_figures(figures))
    return 0
