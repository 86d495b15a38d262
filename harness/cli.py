"""Command line: ``python -m harness [all|run SCENARIO|list|identify] [options]``.

* ``python -m harness`` (or ``all``): every tracking condition and the
  validation inputs, tables next to the paper's, CSV/Markdown/PNG under ``--out``.
* ``python -m harness run SCENARIO``: one scenario.
* ``python -m harness list``: the known scenarios (with ``--scenario-file``, also the user's).
* ``python -m harness identify``: the paper's three-step identification on records of the
  PiezoStage model (``--noise-rms UM`` adds measurement noise), every parameter next to
  the value the plant ran; ``identification.csv`` / ``.md`` under ``--out``.
* ``python -m harness bench``: speed and memory figures (:mod:`harness.bench`).
* ``python -m harness sweep SCENARIO... --vary KEY=SPEC``: Monte Carlo robustness sweeps
  on Dask (:mod:`harness.sweep`).

``--backend``: ``auto`` (default) runs long closed loops (``harness.native.LONG_RUN_SAMPLES``)
on the native master and the rest with fmpy; ``fmpy``, ``native`` (closed loops; the plant
alone still runs in fmpy) and ``core`` (the C core without FMI) force one.

Exit codes, each with a one-line message on stderr:

* 0: done;
* 1: an FMI call failed for another reason (a fault);
* 2: a user error (unknown scenario, missing FMU, malformed scenario file or CSV,
  bad parameter);
* 3: a run failed its own checks: it diverged (the controller's monitor stopped
  it, a value overflowed, or its error exceeds the reference) or the controller
  clipped the voltage persistently (see :mod:`harness.checks`).
"""

from __future__ import annotations

import argparse
import math
import sys

__all__ = ["build_parser", "main"]

PROG = "python -m harness"
COMMANDS = ("all", "run", "list", "identify")
# options of 'identify' only: (attribute, flag)
_IDENTIFY_OPTIONS = (("noise_rms", "--noise-rms"), ("seed", "--seed"), ("free_w0", "--free-w0"),
                     ("displacement_only", "--displacement-only"))


def build_parser():
    """Return the argument parser of the command line."""
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Co-simulate the PiezoStage and AdaptiveCompoundController FMUs and "
                    "compare with the paper's Tables 2-5.",
    )
    p.add_argument("command", nargs="?", default="all", metavar="{all,run,list,identify,bench,sweep}",
                   help="all (default): run everything; run SCENARIO: one scenario; "
                        "list: known scenarios; identify: the paper's parameter identification; "
                        "bench: speed and memory figures; sweep: Monte Carlo robustness sweeps "
                        "(python -m harness bench --help, python -m harness sweep --help)")
    p.add_argument("scenario", nargs="?", help="scenario name for 'run'")
    p.add_argument("--out", default="out", metavar="DIR", help="output folder (default: out/)")
    p.add_argument("--no-adaptation", action="store_true", help="switch the controller's RLS off")
    p.add_argument("--no-preview", action="store_true",
                   help="feed y_d(k) instead of y_d(k+d) (expect a lag error)")
    p.add_argument("--jacobi", action="store_true",
                   help="Jacobi master (one more sample of loop delay; mv.delay raised by 1)")
    p.add_argument("--fmu-dir", metavar="DIR",
                   help="folder of PiezoStage.fmu and AdaptiveCompoundController.fmu "
                        "(default: build/fmus)")
    p.add_argument("--scenario-file", action="append", default=[], metavar="FILE",
                   help="TOML file of extra scenarios (repeatable)")
    p.add_argument("--no-plots", action="store_true", help="do not write PNG figures")
    p.add_argument("--backend", choices=("auto", "fmpy", "native", "core"), default="auto",
                   help="auto (default): the native master for long closed loops, else fmpy; "
                        "fmpy or native: that master for the FMUs; core: the C core via cffi")
    g = p.add_argument_group("identify")
    g.add_argument("--noise-rms", type=float, metavar="UM",
                   help="white measurement noise [um rms] on every recorded channel "
                        "(default 0; 0.001 = 1 nm)")
    g.add_argument("--seed", type=int, metavar="N", help="base seed of the noise (default 1)")
    g.add_argument("--free-w0", action="store_true",
                   help="fit w0 too (only w0 + w1 is identifiable, r_1 = 0); default: w0 fixed "
                        "at the plant's value")
    g.add_argument("--displacement-only", action="store_true",
                   help="fit every step to the measured displacement, as the paper's experiment "
                        "must (the blocks then bias each other)")
    return p


def _fail(message, code=2):
    sys.stderr.write(f"{PROG}: error: {message}\n")
    return code


def main(argv=None):
    """Run the command line; return the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in _TOOLS:
        return _run_tool(argv[0], argv[1:])
    parser = build_parser()
    args = parser.parse_intermixed_args(argv)
    if args.command not in COMMANDS:
        return _fail(f"unknown command '{args.command}'; "
                     f"use one of: all, run SCENARIO, list, identify, bench, sweep")
    if args.command == "run" and not args.scenario:
        return _fail("'run' needs a scenario name (see: python -m harness list)")
    if args.command != "run" and args.scenario:
        return _fail(f"unexpected argument '{args.scenario}' for '{args.command}'")
    if args.command != "identify":
        for attr, flag in _IDENTIFY_OPTIONS:
            if getattr(args, attr) not in (None, False):
                return _fail(f"{flag} is only used by 'identify'")
    else:
        if args.noise_rms is not None and not (math.isfinite(args.noise_rms)
                                               and args.noise_rms >= 0):
            return _fail(f"--noise-rms must be a finite number >= 0 (um), got {args.noise_rms:g}")
        if args.seed is not None and args.seed < 0:
            return _fail(f"--seed must be >= 0, got {args.seed}")

    from .checks import EXIT_RUN_FAILED, RunCheckError
    from .scenarios import ScenarioError, load_scenarios
    from .cosim import FMUError, UnknownParameterError

    adaptation = False if args.no_adaptation else None
    preview = not args.no_preview
    master = "jacobi" if args.jacobi else "gauss-seidel"
    try:
        registry = load_scenarios(args.scenario_file)
        if args.command == "list":
            _list(registry)
            return 0
        from . import report
        if args.command == "identify":
            if args.backend == "native":
                return _fail("identify runs the plant alone: use --backend fmpy or core")
            report.run_identification(args.out, backend="fmpy" if args.backend == "auto" else args.backend,
                                      noise_rms_um=args.noise_rms or 0.0,
                                      seed=1 if args.seed is None else args.seed,
                                      fmu_dir=args.fmu_dir, fix_w0=not args.free_w0,
                                      displacement_only=args.displacement_only)
            return 0
        if args.command == "run":
            report.run_scenario(args.scenario, args.out, adaptation=adaptation, preview=preview,
                                master=master, fmu_dir=args.fmu_dir, plots=not args.no_plots,
                                registry=registry, backend=args.backend)
        else:
            builtin = load_scenarios()
            extra = [n for n in registry if n not in builtin or registry[n] is not builtin[n]]
            report.run_all(args.out, adaptation=adaptation, preview=preview, master=master,
                           fmu_dir=args.fmu_dir, plots=not args.no_plots, backend=args.backend,
                           registry=registry, extra_scenarios=extra)
        return 0
    except RunCheckError as exc:
        return _fail(_one_line(exc), EXIT_RUN_FAILED)
    except (ScenarioError, UnknownParameterError, FileNotFoundError) as exc:
        return _fail(_one_line(exc))
    except FMUError as exc:
        return _fail(_one_line(exc), 2 if isinstance(exc, ValueError) else 1)
    except (ValueError, TypeError, KeyError) as exc:
        return _fail(_one_line(exc))
    except KeyboardInterrupt:
        return _fail("interrupted", 130)


def _one_line(exc):
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    return " ".join(text.split())


def _list(registry):
    kinds = {"tracking": "Tracking (closed loop, reference y_d in um)",
             "validation": "Validation (plant alone, input v in V)"}
    for kind, title in kinds.items():
        names = [n for n, s in registry.items() if s.kind == kind]
        if not names:
            continue
        print(title)
        width = max(len(n) for n in names)
        for n in names:
            print(f"  {n:<{width}}  {registry[n].description}")


# --- bench and sweep (issue 11): per command, one function adds its options, one runs it ---
_TOOLS = ("bench", "sweep")


def add_bench_parser(parser):
    """Options of ``bench`` (see :mod:`harness.bench`)."""
    from .bench import add_bench_arguments

    parser.description = ("Speed and memory of the core, the FMI layer and the masters: "
                          "ns/sample at 2e3, 2e4, 1.2e5 and 1e6 samples into a run (medians "
                          "of repeated runs, thread CPU time), memory per instance, exact "
                          "creep mode's O(k) cost, ratios and real-time factors.")
    return add_bench_arguments(parser)


def run_bench_command(args):
    """Run ``bench``; return the exit code."""
    from .bench import run_bench

    return run_bench(args)


def add_sweep_parser(parser):
    """Options of ``sweep`` (see :mod:`harness.sweep`)."""
    from .sweep import add_sweep_arguments

    parser.description = ("Monte Carlo robustness sweep: N closed-loop runs per scenario with "
                          "the plant's parameters drawn from the given spreads, on a local Dask "
                          "cluster or an existing one (--scheduler); percentiles and worst case "
                          "of e_rms and e_r, the worst parameter set as a scenario file, "
                          "histogram and CDF of e_rms.")
    return add_sweep_arguments(parser)


def run_sweep_command(args):
    """Run ``sweep``; return the exit code (diverged runs are results, not failures)."""
    from .sweep import run_sweep_command as run

    return run(args)


def _run_tool(name, argv):
    add, run = {"bench": (add_bench_parser, run_bench_command),
                "sweep": (add_sweep_parser, run_sweep_command)}[name]
    parser = argparse.ArgumentParser(prog=f"{PROG} {name}")
    add(parser)
    args = parser.parse_args(argv)
    from .cosim import FMUError
    from .scenarios import ScenarioError

    def fail(message, code=2):
        sys.stderr.write(f"{PROG} {name}: error: {message}\n")
        return code

    try:
        return run(args)
    except (ScenarioError, FileNotFoundError, ValueError, TypeError, KeyError) as exc:
        return fail(_one_line(exc))
    except FMUError as exc:
        return fail(_one_line(exc), 1)
    except KeyboardInterrupt:
        return fail("interrupted", 130)
