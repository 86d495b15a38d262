"""Command line: ``python -m harness [all|run|list|identify|export|bench|sweep|STUDY] [options]`` (or
``piezo-harness``).

* ``all`` (the default when no subcommand is given): every tracking condition
  and the validation inputs; the headline table next to the paper's, a report
  (report.md, report.html) with figures and provenance under ``--out``.
* ``run SCENARIO``: one scenario; its metrics, time series and figure.
* ``list``: the known scenarios (with ``--scenario-file``, also the user's).
* ``identify``: identify the coupled model from measured records (``--pi-data``,
  ``--tf-data``, ``--creep-data``), or ``--demo`` (the virtual experiment), or
  ``--internal-channels`` (each step alone on the model's internal outputs).
* ``export --params FILE``: PiezoStage.fmu and AdaptiveCompoundController.fmu with
  the file's values as start values.
* ``bench``: speed and memory figures (:mod:`harness.bench`).
* ``sweep SCENARIO... --vary KEY=SPEC``: Monte Carlo robustness sweeps on Dask
  (:mod:`harness.sweep`).
* the studies, each with its own options (:data:`STUDIES`): ``timing``, ``supervision``,
  ``stage-use``, ``stage-day``: they measure a documented family and write its page's table.

``--backend`` of ``all`` and ``run``: ``auto`` (default) runs long closed loops
(``harness.masters.LONG_RUN_SAMPLES``) on the native C master and the rest with
fmpy; ``fmpy``, ``native`` (closed loops; the plant alone still runs in fmpy) and
``core`` (the C core without FMI) force one. ``--fmi 3`` runs the FMI 3.0 editions of
the FMUs (with fmpy; ``auto`` then means fmpy, ``native`` and ``core`` refuse it).

Each subcommand lives in one place: a function that declares its parser and
options (``_add_<name>_parser``, built from the shared option groups it
needs) followed by its handler (``_cmd_<name>``).  Adding a subcommand is
those two functions and one entry in :data:`SUBCOMMANDS`.  An option a
subcommand does not take is refused like any unknown option, in one line.

Exit codes, each with a one-line message on stderr that names the program:

* 0: done;
* 1: an FMI call failed for another reason (a fault);
* 2: a user error (bad command line, unknown scenario, missing FMU, an FMU of the other
  FMI version or not an FMU of this project, malformed scenario file or CSV, bad parameter,
  output folder that cannot be written);
* 3: a run failed its own checks: it diverged (the controller's monitor stopped
  it, a value overflowed, or its error exceeds the reference) or the controller
  clipped the voltage persistently (see :mod:`harness.loop.checks`).
"""

from __future__ import annotations

import argparse
import os
import sys

from . import masters, report
from .paths import describe_fmu_dir
from .bench import add_bench_arguments, run_bench
from .fmu import FMUError, UnknownParameterError, missing_windows_binaries
from .identify.identify_command import (add_export_arguments, add_identify_arguments,
                                        add_param_file_arguments, apply_param_files,
                                        check_identify_arguments, run_export, run_identify)
from .loop.checks import EXIT_RUN_FAILED, RunCheckError
from .scenarios import ScenarioError, format_scenario_list, get_scenario, load_scenarios
from .sweep import add_sweep_arguments, run_sweep_command

__all__ = ["build_parser", "main", "SUBCOMMANDS", "UsageError"]

#: How the program is named when run as a module.
MODULE_PROG = "python -m harness"
EXIT_OK, EXIT_FAULT, EXIT_USER = 0, 1, 2


class UsageError(Exception):
    """A command-line mistake: reported in one line with exit code 2."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage dump) and name the help."""

    def error(self, message):
        raise UsageError(f"{message} (see: {self.prog} --help)")


# ---------------------------------------------------------------------------
# option groups shared by several subcommands (each subcommand picks its own)
# ---------------------------------------------------------------------------

def _output_option(p, what):
    p.add_argument("--out", default="out", metavar="DIR",
                   help=f"output folder for {what} (default: out/, created if missing)")


def _fmu_dir_option(p, what):
    p.add_argument("--fmu-dir", metavar="DIR", help=f"{what} (default: {describe_fmu_dir()})")


def _backend_options(p, closed_loop=False):
    if closed_loop:
        p.add_argument("--backend", choices=masters.BACKENDS, default="auto",
                       help="auto (default): the native C master for long closed loops, fmpy "
                            "otherwise; fmpy or native: that master for the FMUs; closed-loop-fmu: "
                            "the loop inside one FMU, PiezoStageClosedLoop, through fmpy; core: the C "
                            "core through cffi, no FMI")
        p.add_argument("--master", dest="backend", choices=masters.BACKENDS, default=argparse.SUPPRESS,
                       help="the same as --backend")
    else:
        p.add_argument("--backend", choices=masters.OPEN_LOOP_BACKENDS, default="fmpy",
                       help="fmpy: run the FMUs (default); core: the C core through cffi, no FMI")
    _fmu_dir_option(p, "folder of PiezoStage.fmu and AdaptiveCompoundController.fmu")
    if closed_loop:
        p.add_argument("--fmi", type=int, choices=(2, 3), default=2, metavar="{2,3}",
                       help="run the FMUs' FMI 2.0 editions (default) or their FMI 3.0 editions "
                            "(the fmi3/ folder beside them, run with fmpy: --backend auto or "
                            "fmpy); both give the same samples")


def _scenario_file_option(p):
    p.add_argument("--scenario-file", action="append", default=[], metavar="FILE",
                   help="TOML file of extra scenarios (repeatable; format: harness/scenarios/__init__.py)")


def _loop_options(p, applies_to):
    g = p.add_argument_group(f"closed-loop options ({applies_to})")
    g.add_argument("--no-adaptation", action="store_true", help="switch the controller's RLS off")
    g.add_argument("--no-preview", action="store_true",
                   help="give the controller y_d(k) instead of y_d(k+d) (expect a lag error)")
    g.add_argument("--jacobi", action="store_true",
                   help="Jacobi master (outputs read before inputs are set); with the default "
                        "controller it gives the same samples as Gauss-Seidel")


def _plots_option(p):
    p.add_argument("--no-plots", action="store_true", help="draw no figures (PNG/SVG)")


def _out_dir(args):
    """Check --out now (creating nothing), so a path that cannot be a folder fails before
    any run."""
    try:
        return report.check_out_dir(args.out)
    except OSError as exc:
        raise UsageError(f"--out: {exc}") from None


def _fmi_version(args):
    """The --fmi version, checked against --backend before any run."""
    master = masters.get(args.backend)
    if args.fmi != 2 and args.fmi not in master.fmi_versions:
        raise UsageError(f"--fmi {args.fmi} does not apply to --backend {args.backend} "
                         f"({master.fmi_note}); use --backend fmpy or auto")
    return args.fmi


def _warn_if_linux_only(args, fmi_version=2):
    """One warning line on stderr when the FMUs to be run have no Windows binaries (a build
    without MinGW-w64; pip hides CMake's note of it)."""
    note = missing_windows_binaries(args.fmu_dir, fmi_version)
    if note:
        sys.stderr.write(f"{args.prog}: warning: {note}\n")
        sys.stderr.flush()


def _loop_settings(args):
    return (False if args.no_adaptation else None, not args.no_preview,
            "jacobi" if args.jacobi else "gauss-seidel")


# ---------------------------------------------------------------------------
# each subcommand in one place: its parser function, then its handler
# ---------------------------------------------------------------------------

def _add_all_parser(sub):
    p = sub.add_parser(
        "all", help="run everything: the paper's scenarios, the report (default)",
        description="Run every tracking condition on the paper's six references and the six "
                    "validation inputs; print the headline table next to the paper's Tables "
                    "4/5 and write report.md, report.html, provenance.json, the CSV tables and "
                    "the figures (PNG and SVG) to --out.")
    _output_option(p, "the report")
    _backend_options(p, closed_loop=True)
    _scenario_file_option(p)
    _plots_option(p)
    _loop_options(p, "the base of every tracking condition")
    add_param_file_arguments(p)
    p.set_defaults(handler=_cmd_all)
    return p


def _cmd_all(args, command):
    registry = load_scenarios(args.scenario_file)
    builtin = load_scenarios()
    extra = [n for n in registry if n not in builtin]
    adaptation, preview, master = _loop_settings(args)
    _out_dir(args)
    registry = apply_param_files(args, registry, progress=sys.stderr)
    fmi_version = _fmi_version(args)
    if args.backend != "core":
        _warn_if_linux_only(args, fmi_version)
    # the streams as they are now, not as the library's defaults bound them at its import (a caller
    # that imported it with redirected streams, a test's capture, may have closed those since)
    report.run_all(args.out, adaptation=adaptation, preview=preview, master=master,
                   fmu_dir=args.fmu_dir, plots=not args.no_plots, backend=args.backend,
                   registry=registry, extra_scenarios=extra, command=command,
                   fmi_version=fmi_version, stream=sys.stdout, progress=sys.stderr)
    return EXIT_OK


def _add_run_parser(sub):
    p = sub.add_parser(
        "run", help="run one scenario",
        description="Run one scenario (see: list); print its table and write <SCENARIO>.csv, "
                    "its time series and its figure to --out.")
    p.add_argument("scenario", metavar="SCENARIO", help="scenario name (see: list)")
    _output_option(p, "the files")
    _backend_options(p, closed_loop=True)
    _scenario_file_option(p)
    _plots_option(p)
    g = p.add_argument_group("time series")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--no-timeseries", action="store_true",
                   help="write no time series file (long runs)")
    x.add_argument("--timeseries-format", choices=("csv", "npz"), default="csv",
                   help="csv (default) or npz: NumPy arrays, less than half the CSV's size, "
                        "read back with numpy.load(FILE)['y']")
    _loop_options(p, "tracking scenarios only")
    add_param_file_arguments(p)
    p.set_defaults(handler=_cmd_run)
    return p


def _cmd_run(args, command):
    registry = load_scenarios(args.scenario_file)
    sc = get_scenario(args.scenario, registry)
    if sc.kind != "tracking":
        given = [f for f, on in (("--no-adaptation", args.no_adaptation),
                                 ("--no-preview", args.no_preview),
                                 ("--jacobi", args.jacobi)) if on]
        if given:
            raise UsageError(f"{given[0]} does not apply to '{sc.name}', a {sc.kind} scenario "
                             f"(the plant runs alone: no controller, no reference)")
    adaptation, preview, master = _loop_settings(args)
    fmi_version = _fmi_version(args)
    _out_dir(args)
    registry = apply_param_files(args, registry, progress=sys.stderr)
    if args.backend != "core":
        _warn_if_linux_only(args, fmi_version)
    report.run_scenario(sc.name, args.out, adaptation=adaptation, preview=preview, master=master,
                        fmu_dir=args.fmu_dir, plots=not args.no_plots, registry=registry,
                        backend=args.backend, fmi_version=fmi_version,
                        timeseries=None if args.no_timeseries else args.timeseries_format,
                        stream=sys.stdout, progress=sys.stderr)
    return EXIT_OK


def _add_list_parser(sub):
    p = sub.add_parser("list", help="list the known scenarios",
                       description="List the built-in scenarios and those of --scenario-file.")
    _scenario_file_option(p)
    p.set_defaults(handler=_cmd_list)
    return p


def _cmd_list(args, command):
    text = format_scenario_list(load_scenarios(args.scenario_file))
    if text:
        print(text)
    return EXIT_OK


def _add_identify_parser(sub):
    p = sub.add_parser(
        "identify", help="identify the coupled model (paper section 3) from measured records",
        description="Identify the coupled model from measured records of voltage and "
                    "displacement (the PI weights solved for each value of the poles, the zero "
                    "and the creep order, which are searched from several starts; the paper's "
                    "stepwise recipe is one start), and say which parameter the records do not "
                    "determine; or --demo: a virtual experiment on the PiezoStage FMU with known "
                    "parameters; or --family N: the method checked on N stages drawn from the "
                    "paper's ranges; or --internal-channels: each of the paper's steps alone on "
                    "the model's internal outputs u and x. Writes a parameter file keyed by FMU "
                    "variable names, for export, --plant-params and --controller-params "
                    "(docs/identification.md).")
    p.add_argument("--out", default="out", metavar="PATH",
                   help="the parameter file (a .json path) or a folder (default: out/)")
    _backend_options(p)
    add_identify_arguments(p)
    p.set_defaults(handler=_cmd_identify)
    return p


def _cmd_identify(args, command):
    problem = check_identify_arguments(args)
    if problem:
        raise UsageError(problem)
    if not str(args.out).endswith(".json"):
        _out_dir(args)
    return run_identify(args, stream=sys.stdout, progress=sys.stderr)


def _add_export_parser(sub):
    p = sub.add_parser(
        "export", help="parameterised FMUs from a parameter file",
        description="Write PiezoStage.fmu and AdaptiveCompoundController.fmu with the values of "
                    "a parameter file as their start values (the built binaries reused, the "
                    "modelDescription rewritten, the GUID kept); each FMU takes the names it has. "
                    "Each FMU's regression experiment (FMI-LS-REF) and documentation are "
                    "recomputed for those values, and extra/piezo_fmus.identification/ records "
                    "where they came from (the parameter file, the identification report and the "
                    "measured records beside it, with their SHA-256).")
    _output_option(p, "the two FMUs")
    _fmu_dir_option(p, "folder of the built FMUs")
    add_export_arguments(p)
    p.set_defaults(handler=_cmd_export)
    return p


def _cmd_export(args, command):
    _out_dir(args)
    _warn_if_linux_only(args)
    return run_export(args)


def _add_bench_parser(sub):
    p = sub.add_parser(
        "bench", help="speed and memory figures",
        description="Speed and memory of the core, the FMI layer and the masters: ns/sample at "
                    "2e3, 2e4, 1.2e5 and 1e6 samples into a run (medians of repeated runs, thread "
                    "CPU time), memory per instance, exact creep mode's O(k) cost, ratios and "
                    "real-time factors.")
    add_bench_arguments(p)
    p.set_defaults(handler=_cmd_bench)
    return p


def _cmd_bench(args, command):
    return run_bench(args)


def _add_sweep_parser(sub):
    p = sub.add_parser(
        "sweep", help="Monte Carlo robustness sweeps on Dask",
        description="Monte Carlo robustness sweep: N closed-loop runs per scenario with the "
                    "plant's parameters drawn from the given spreads, on a local Dask cluster or "
                    "an existing one (--scheduler); percentiles and worst case of e_rms and e_r, "
                    "the worst parameter set as a scenario file, histogram and CDF of e_rms. "
                    "Runs that diverge are results of the sweep, counted, not failures.")
    add_sweep_arguments(p)
    p.set_defaults(handler=_cmd_sweep)
    return p


def _cmd_sweep(args, command):
    _out_dir(args)
    return run_sweep_command(args)


#: The subcommands, in --help order: each adds its parser and sets its handler.
#: The studies: each measures a documented family and writes its page's table; each keeps its own
#: options (``python -m harness STUDY --help``), so its arguments go to its module's ``main``
#: untouched. Name: (module under harness, what it measures).
STUDIES = {
    "timing": ("studies.timing_table", "what the FMUs detect under each master (docs/cosimulation.md)"),
    "supervision": ("studies.supervision_table", "the controller's supervision: fault tables, families, "
                                         "stuck and noisy sensors, sup.reset (docs/robustness.md)"),
    "stage-use": ("studies.stage_use_table", "issue 35's stage-use targets on the family of stages "
                                     "(docs/stage_use.md)"),
    "stage-day": ("studies.stage_day_table", "issue 43's targets over a stage's day on the stage family "
                               "(docs/stage_day.md)"),
}


def _add_study_parsers(sub):
    # listed in --help; main() hands their arguments to the study before this parser sees them
    for name, (_, text) in STUDIES.items():
        sub.add_parser(name, help=f"study: {text}", add_help=False)


def _run_study(name, argv, prog):
    """The study's own command line: its module's main(argv, prog), imported when used."""
    import importlib
    module = importlib.import_module(f"{__package__}.{STUDIES[name][0]}")
    code = module.main(argv, prog=f"{prog} {name}")
    return EXIT_OK if code is None else code


SUBCOMMANDS = (_add_all_parser, _add_run_parser, _add_list_parser, _add_identify_parser,
               _add_export_parser, _add_bench_parser, _add_sweep_parser, _add_study_parsers)


def build_parser(prog=MODULE_PROG):
    """Return the argument parser of the command line."""
    p = _Parser(
        prog=prog,
        description="Co-simulate the PiezoStage and AdaptiveCompoundController FMUs and compare "
                    "with the paper's Tables 2-5. Without a subcommand: all.",
        epilog="Each subcommand has its own options: %(prog)s SUBCOMMAND --help. Exit codes: "
               "0 done, 1 FMI fault, 2 user error, 3 a run diverged or saturated (a loop the "
               "controller's supervision stopped counts as diverged).")
    sub = p.add_subparsers(title="subcommands", dest="command", metavar="SUBCOMMAND",
                           parser_class=_Parser)
    for add in SUBCOMMANDS:
        add(sub)
    return p


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------

def _program_name():
    """'piezo-harness' from the console script, 'python -m harness' otherwise."""
    name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    if not name or name in ("__main__.py", "-c", "-m") or name.endswith(".py"):
        return MODULE_PROG
    return name


def _one_line(exc):
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    return " ".join(text.split())


def _subcommand_names(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return set(action.choices)
    return set()


def _options_with_value(parser):
    """Every option string (of every subcommand) that takes a value."""
    out = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sp in action.choices.values():
                out |= _options_with_value(sp)
        elif action.option_strings and action.nargs != 0:
            out.update(action.option_strings)
    return out


def _with_default_command(argv, parser):
    """No subcommand means ``all``: ``--backend core`` is ``all --backend core``.

    Options given before a subcommand (``--out DIR run X``) are refused with a
    hint: each subcommand takes its own options after its name.
    """
    if argv and not argv[0].startswith("-"):
        return list(argv)
    if argv and argv[0] in ("-h", "--help"):
        return list(argv)
    takes_value = _options_with_value(parser)
    names = _subcommand_names(parser)
    for i, tok in enumerate(argv):
        if tok in names and (i == 0 or argv[i - 1] not in takes_value):
            raise UsageError(f"options go after the subcommand: {parser.prog} {tok} ... "
                             f"{' '.join(argv[:i])}")
    return ["all", *argv]


def main(argv=None, prog=None):
    """Run the command line; return the exit code.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default: ``sys.argv[1:]``).
    prog : str, optional
        Program name in messages (default: the console script's name, or
        ``python -m harness``).
    """
    prog = prog or _program_name()
    argv = list(sys.argv[1:] if argv is None else argv)

    def fail(message, code=EXIT_USER):
        sys.stderr.write(f"{prog}: error: {message}\n")
        sys.stderr.flush()
        return code

    for stream in (sys.stdout, sys.stderr):      # µ and − on a terminal that cannot show them
        try:
            stream.reconfigure(errors="replace")
        except (AttributeError, ValueError):
            pass
    if argv and argv[0] in STUDIES:
        try:
            return _run_study(argv[0], argv[1:], prog)
        except SystemExit as exc:                # the study's --help or its argparse's refusal
            return exc.code if isinstance(exc.code, int) else EXIT_OK
    parser = build_parser(prog)
    try:
        argv = _with_default_command(argv, parser)
        args, extra = parser.parse_known_args(argv)
        if extra:
            raise UsageError(f"'{args.command}' does not take {' '.join(extra)} "
                             f"(see: {prog} {args.command} --help)")
    except UsageError as exc:
        return fail(str(exc))
    except SystemExit as exc:                    # --help
        return exc.code if isinstance(exc.code, int) else EXIT_OK

    command = " ".join([prog, *argv])
    args.prog = prog
    try:
        return args.handler(args, command)
    except UsageError as exc:
        return fail(str(exc))
    except RunCheckError as exc:
        return fail(_one_line(exc), EXIT_RUN_FAILED)
    except (ScenarioError, UnknownParameterError) as exc:
        return fail(_one_line(exc))
    except FMUError as exc:
        return fail(_one_line(exc), EXIT_USER if isinstance(exc, ValueError) else EXIT_FAULT)
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError,
            FileExistsError) as exc:
        return fail(_one_line(exc))
    except OSError as exc:
        return fail(_one_line(exc), EXIT_FAULT)
    except (ValueError, TypeError, KeyError) as exc:
        return fail(_one_line(exc))
    except KeyboardInterrupt:
        return fail("interrupted", 130)
