"""Command-line pieces of identification, export and parameter files.

:mod:`harness.cli` owns the parser and the dispatch; per subcommand it calls

* ``identify``: :func:`add_identify_arguments`, then :func:`check_identify_arguments`
  (a one-line error or None) and :func:`run_identify`;
* ``export``: :func:`add_export_arguments`, then :func:`run_export`;
* ``run`` and ``all``: :func:`add_param_file_arguments`, then
  :func:`apply_param_files` puts ``--plant-params`` / ``--controller-params`` into
  their scenarios.

::

    python -m harness identify --pi-data LOW.csv --tf-data MIXED.csv --creep-data A.csv [B.csv ...]
                               [--out params.json] [--sample-period S] [--operators M]
                               [--v-max V] [--delay N] [--holdout F] [--max-evaluations N]
    python -m harness identify --demo [--duration S] [--noise-free] [--seed N] [--out DIR]
    python -m harness identify --family N [--record-set standard|two|six] [--duration S]
                               [--noise-free] [--seed N]
    python -m harness identify --internal-channels [--noise-rms UM] [--seed N] [--free-w0]
                               [--displacement-only]
    python -m harness export --params FILE [--out DIR] [--fmu-dir DIR]
    python -m harness [all | run SCENARIO] --plant-params FILE --controller-params FILE

User errors raise ValueError (or FileNotFoundError), which the caller turns
into exit code 2 and one line; a fit that does not converge and a virtual
experiment that fails its own checks raise :class:`harness.loop.checks.RunCheckError`
(exit code 3).
"""

from __future__ import annotations

import math
import sys

from ..loop.checks import RunCheckError
from . import demo, from_files
from .export import export_fmus
from .family import validate_family
from .fit import (DEFAULT_HOLDOUT, DEFAULT_MAX_EVALUATIONS, IdentificationFitError,
                  UndeterminedModelError)
from .internal import run_identification
from .params import (CONTROLLER_MODEL, PLANT_MODEL, override_scenarios, parameter_types,
                     read_params, split_params)
from .result_tables import format_report

__all__ = ["add_identify_arguments", "check_identify_arguments", "run_identify",
           "add_export_arguments", "run_export", "add_param_file_arguments",
           "apply_param_files"]

_DATA = (("pi_data", "--pi-data"), ("tf_data", "--tf-data"), ("creep_data", "--creep-data"))
_FIT = (("sample_period", "--sample-period"), ("operators", "--operators"), ("v_max", "--v-max"),
        ("delay", "--delay"), ("holdout", "--holdout"), ("max_evaluations", "--max-evaluations"))
_DEMO = (("duration", "--duration"), ("noise_free", "--noise-free"))
_INTERNAL = (("noise_rms", "--noise-rms"), ("free_w0", "--free-w0"),
             ("displacement_only", "--displacement-only"))
_PARAM_FILES = (("plant_params", "--plant-params"), ("controller_params", "--controller-params"))


def add_identify_arguments(parser):
    """Add the options of ``identify`` (records, --demo, --internal-channels) to a parser."""
    g = parser.add_argument_group(
        "from measured records",
        "Records are CSV files with the columns time [s], v [V], y [um], sampled at h from rest. "
        "--out is the parameter file (a .json path) or a folder (params.json in it); the "
        "reports <stem>.report.md and .report.json go beside it.")
    g.add_argument("--pi-data", metavar="FILE",
                   help="step 1 (PI): a low-frequency record, e.g. v = 10 sin(2 pi t) + 10 V")
    g.add_argument("--tf-data", metavar="FILE",
                   help="step 2 (G): a mixed-frequency record, e.g. 5/40/80 Hz")
    g.add_argument("--creep-data", metavar="FILE", nargs="+", action="extend",
                   help="step 3 (creep): one or more records (a file may serve several steps)")
    g.add_argument("--sample-period", type=float, metavar="S",
                   help="the model's sample period h [s] (default 0.0005); records must be "
                        "sampled at it")
    g.add_argument("--operators", type=int, metavar="M", help="play operators (default 9)")
    g.add_argument("--v-max", type=float, metavar="V",
                   help="threshold scale [V] (default: max |v| of the --pi-data record)")
    g.add_argument("--delay", type=int, metavar="N",
                   help="extra input delay of G in samples, tf.delay (default 0; not fitted)")
    g.add_argument("--holdout", type=float, metavar="F",
                   help="fraction of each record held out at its end (default 0.25; 0: none)")
    g.add_argument("--max-evaluations", type=int, metavar="N",
                   help="most evaluations of each start of the search (default 500; the search "
                        "stops earlier, when it no longer improves on the records' noise floor)")
    d = parser.add_argument_group("the virtual experiment")
    d.add_argument("--demo", action="store_true",
                   help="records of the PiezoStage FMU with known parameters, identified like "
                        "user data")
    d.add_argument("--family", type=int, metavar="N",
                   help="validate the identification on N stages drawn at random from around "
                        "the paper's parameter ranges (recorded on the C core, identified from "
                        "v and y) and print the distribution of the errors and times")
    d.add_argument("--record-set", choices=("standard", "two", "six"),
                   help="--family: the records of each stage: standard (1 Hz, 5/40/80 Hz, "
                        "10 Hz), two (1 Hz, 5/40/80 Hz) or six (the paper's six validation "
                        "inputs); default standard")
    d.add_argument("--duration", type=float, metavar="S",
                   help="--demo, --family: length of each record [s] (default 10)")
    d.add_argument("--noise-free", action="store_true",
                   help="--demo, --family: no sensor noise or quantisation (default: 2 nm, "
                        "1 nm rms)")
    d.add_argument("--seed", type=int, metavar="N",
                   help="--demo, --internal-channels: base seed of the noise (default 1); "
                        "--family: seed of the stages (default 2026)")
    i = parser.add_argument_group("each step alone on the model's internal channels")
    i.add_argument("--internal-channels", action="store_true",
                   help="check each step alone on the PiezoStage model's internal outputs u and "
                        "x (a real stage gives only v and y)")
    i.add_argument("--noise-rms", type=float, metavar="UM",
                   help="white measurement noise [µm rms] on every recorded channel "
                        "(default 0; 0.001 = 1 nm)")
    i.add_argument("--free-w0", action="store_true",
                   help="fit w0 too (only w0 + w1 is identifiable, r_1 = 0); default: w0 fixed "
                        "at the plant's value")
    i.add_argument("--displacement-only", action="store_true",
                   help="fit every step to the measured displacement, as the paper's experiment "
                        "must (the blocks then bias each other)")


def add_export_arguments(parser):
    """Add the options of ``export`` to a parser."""
    parser.add_argument("--params", metavar="FILE", required=True,
                        help="parameter file (JSON of FMU variable names, e.g. from identify) to "
                             "put into PiezoStage.fmu and AdaptiveCompoundController.fmu as start "
                             "values")


def add_param_file_arguments(parser):
    """Add ``--plant-params`` / ``--controller-params`` (``run`` and ``all``) to a parser."""
    r = parser.add_argument_group("parameter files")
    r.add_argument("--plant-params", metavar="FILE",
                   help="parameter file applied to the PiezoStage of every scenario (names the "
                        "plant has)")
    r.add_argument("--controller-params", metavar="FILE",
                   help="parameter file applied to the controller of every scenario (names the "
                        "controller has)")


def _given(args, attr):
    return getattr(args, attr, None) not in (None, False, [])


def check_identify_arguments(args):
    """A one-line error about the combination of ``identify``'s options, or None."""
    data = [flag for attr, flag in _DATA if _given(args, attr)]
    family = getattr(args, "family", None) is not None
    modes = [m for m, on in (("records", bool(data)), ("--demo", args.demo),
                             ("--internal-channels", args.internal_channels),
                             ("--family", family)) if on]
    if len(modes) > 1:
        return f"identify takes one of: the records, --demo, --internal-channels, --family " \
               f"(got {' and '.join(modes)})"
    if not modes:
        return ("identify needs the records: --pi-data LOW.csv --tf-data MIXED.csv "
                "--creep-data A.csv [B.csv ...] (or --demo for the virtual experiment)")
    if data and len(data) < 3:
        missing = [flag for attr, flag in _DATA if not _given(args, attr)]
        return f"identify needs --pi-data, --tf-data and --creep-data (missing: {', '.join(missing)})"
    if not args.internal_channels:
        for attr, flag in _INTERNAL:
            if _given(args, attr):
                return f"{flag} is only used by 'identify --internal-channels'"
    if not family and _given(args, "record_set"):
        return "--record-set is only used by 'identify --family'"
    if family and args.family < 1:
        return f"--family must be >= 1 stage, got {args.family}"
    if family:
        for attr, flag in _FIT[:5]:
            if _given(args, attr):
                return f"{flag} is not used by 'identify --family' (the drawn stages fix it)"
    if not args.demo and not family:
        for attr, flag in _DEMO:
            if _given(args, attr):
                return f"{flag} is only used by 'identify --demo' and 'identify --family'"
        if data and _given(args, "seed"):
            return ("--seed is only used by 'identify --demo', 'identify --family' and "
                    "'identify --internal-channels'")
    if args.internal_channels:
        for attr, flag in _FIT:
            if _given(args, attr):
                return f"{flag} is not used by 'identify --internal-channels'"
    if args.demo:
        for attr, flag in _FIT[:4]:
            if _given(args, attr):
                return f"{flag} is not used by 'identify --demo' (the virtual stage fixes it)"
    checks = (
        ("sample_period", lambda x: math.isfinite(x) and x > 0, "a finite number > 0 (s)"),
        ("operators", lambda x: 1 <= x <= 16, "in 1..16"),
        ("v_max", lambda x: math.isfinite(x) and x > 0, "a finite number > 0 (V)"),
        ("delay", lambda x: 0 <= x <= 8, "in 0..8 samples"),
        ("holdout", lambda x: 0 <= x <= 0.9, "in [0, 0.9]"),
        ("max_evaluations", lambda x: x >= 1, ">= 1"),
        ("duration", lambda x: math.isfinite(x) and x > 0, "a finite number > 0 (s)"),
        ("noise_rms", lambda x: math.isfinite(x) and x >= 0, "a finite number >= 0 (µm)"),
        ("seed", lambda x: x >= 0, ">= 0"),
    )
    for attr, ok, valid in checks:
        value = getattr(args, attr, None)
        if value is not None and not ok(value):
            return f"--{attr.replace('_', '-')} must be {valid}, got {value:g}"
    return None


def run_identify(args, stream=sys.stdout, progress=sys.stderr):
    """Run ``identify`` (records, --demo or --internal-channels); return the exit code.

    Raises
    ------
    harness.loop.checks.RunCheckError
        The fit did not converge, or the virtual experiment failed its checks.
    """
    holdout = DEFAULT_HOLDOUT if args.holdout is None else args.holdout
    max_evaluations = getattr(args, "max_evaluations", None) or DEFAULT_MAX_EVALUATIONS
    say = _progress_lines(progress)
    try:
        if args.internal_channels:
            run_identification(args.out, backend=args.backend,
                               noise_rms_um=args.noise_rms or 0.0,
                               seed=1 if args.seed is None else args.seed,
                               fmu_dir=args.fmu_dir, fix_w0=not args.free_w0,
                               displacement_only=args.displacement_only)
            return 0
        if getattr(args, "family", None) is not None:
            return _identify_family(args, stream, say)
        if args.demo:
            result = demo.run_demo(args.out,
                                   duration=10.0 if args.duration is None else args.duration,
                                   noise=not args.noise_free,
                                   seed=1 if args.seed is None else args.seed,
                                   holdout=holdout, fmu_dir=args.fmu_dir, backend=args.backend,
                                   stream=stream, progress=progress,
                                   max_evaluations=max_evaluations)
            if result.failures:
                raise RunCheckError(f"the virtual experiment failed {len(result.failures)} of its "
                                    f"checks; first: {result.failures[0]}")
            return 0
        return _identify_records(args, holdout, max_evaluations, stream, say)
    except IdentificationFitError as exc:
        raise RunCheckError(str(exc)) from None


def _identify_family(args, stream, say):
    """``identify --family N``: the distribution of the errors over N drawn stages."""
    family = validate_family(args.family, seed=2026 if args.seed is None else args.seed,
                             record_set=args.record_set or "standard",
                             duration=10.0 if args.duration is None else args.duration,
                             noise=not args.noise_free, progress=say)
    if stream is not None:
        stream.write(family.format() + "\n")
        stream.flush()
    bad = [st for st in family.stages if st.undetermined]
    if bad:
        raise RunCheckError(f"stage {bad[0].index + 1} of the family: the identification left "
                            f"{', '.join(bad[0].undetermined)} undetermined")
    return 0


def _progress_lines(stream):
    """A callable that writes one progress line of the fit to ``stream`` (or nothing)."""
    if stream is None:
        return None

    def say(line):
        stream.write(f"identify: {line}\n")
        stream.flush()

    return say


def _identify_records(args, holdout, max_evaluations, stream, say):
    h = 0.0005 if args.sample_period is None else args.sample_period
    m = 9 if args.operators is None else args.operators
    result, records = from_files.identify_files(args.pi_data, args.tf_data, args.creep_data, h=h,
                                                m=m, v_max=args.v_max, delay=args.delay or 0,
                                                holdout=holdout, max_evaluations=max_evaluations,
                                                progress=say)
    header = [f"Identification from measured records (v and y only): step 1 {args.pi_data}, "
              f"step 2 {args.tf_data}, step 3 {', '.join(args.creep_data)}; h = {h:g} s, "
              f"m = {m}, v_max = {result.model.v_max:g} V; the last {holdout:.0%} of each "
              f"record held out; {result.elapsed_s:.1f} s."]
    files = from_files.write_outputs(result, args.out, records=records, header=header)
    if result.undetermined:
        first = result.undetermined[0]
        more = (f" (and {len(result.undetermined) - 1} more)" if len(result.undetermined) > 1
                else "")
        raise UndeterminedModelError(
            f"the records do not determine {first.text()}{more}; no parameter file written, "
            f"see {files[1]}")
    if stream is not None:
        stream.write(format_report(result, header=header) + "\n\n")
        stream.write(f"Wrote {files[0]} (parameters, for --plant-params, --controller-params and "
                     f"export) and its reports {files[1].name}, {files[2].name}\n")
        stream.flush()
    return 0


def run_export(args, stream=sys.stdout):
    """Run ``export``: the parameter file into the FMUs (harness.identify.export); return the exit code."""
    params = read_params(args.params)
    written = export_fmus(params, args.out, fmu_dir=args.fmu_dir, source=args.params)
    if stream is not None:
        for model, (path, given) in written.items():
            names = ", ".join(given) if given else "none"
            stream.write(f"{path}: {len(given)} start values from {args.params} ({names})\n")
        stream.flush()
    return 0


def apply_param_files(args, registry, progress=sys.stderr):
    """The registry with ``--plant-params`` / ``--controller-params`` applied to every scenario.

    Each FMU takes the names it has; a name of neither FMU is an error
    (:class:`harness.identify.params.ParameterFileError`).
    """
    files = [(attr, flag, getattr(args, attr, None)) for attr, flag in _PARAM_FILES]
    if not any(f for _, _, f in files):
        return registry
    types = {m: parameter_types(m, fmu_dir=args.fmu_dir, backend=args.backend)
             for m in (PLANT_MODEL, CONTROLLER_MODEL)}
    plant, controller = {}, {}
    for attr, flag, path in files:
        if not path:
            continue
        p, c = split_params(read_params(path), types[PLANT_MODEL], types[CONTROLLER_MODEL],
                            source=path)
        if attr == "plant_params":
            plant, target, model = p, p, PLANT_MODEL
        else:
            controller, target, model = c, c, CONTROLLER_MODEL
        if progress is not None:
            n = len(target)
            progress.write(f"{flag} {path}: {n} parameter{'' if n == 1 else 's'} applied to the "
                           f"{model} of every scenario\n")
    return override_scenarios(registry, plant, controller)
