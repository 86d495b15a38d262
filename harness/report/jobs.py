"""The jobs of the command line: the main job (:func:`run_all`) and one scenario (:func:`run_scenario`).

A job runs what :mod:`.conditions` and :mod:`.run` define, then writes what
:mod:`.tables`, :mod:`.figures` and :mod:`.document` produce:

* terminal: the headline table first (ours, paper, ratio), then every
  condition side by side, the user's scenarios, the validation table, the
  stage-use table (:mod:`.stage_use`), the stage's day (:mod:`.stage_day`), a sensor that stops
  answering (:mod:`.sensor_faults`, in the report), and what each condition is;
* files: ``tracking.csv``, ``validation.csv``, ``stage_use.csv``, ``stage_day.csv``, ``report.md``,
  ``report.html``, ``provenance.json`` and, unless disabled, the figures as
  PNG (150 dpi) and SVG.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import sys
import textwrap

from .. import masters
from ..fmu import CONTROLLER_MODEL, PLANT_MODEL, WINDOWS_PLATFORM
from ..progress import Progress
from ..scenarios import VALIDATION_SCENARIOS, get_scenario, load_scenarios, stage_use_scenarios
from . import document as doc_
from . import tables
from .conditions import (
    condition_label,
    default_conditions,
    describe_condition,
    user_condition,
)
from .figures import draw_main_figures, draw_scenario_figure, draw_stage_use_figures
from .provenance import collect_provenance
from .run import evaluate_tracking, evaluate_validation, parameter_defaults, validation_series
from .stage_use import (HOLD_STEP, LAWS, STAGE_USE_NOTES, format_stage_use_table, run_stage_use,
                        stage_use_table_rows, write_stage_use_csv)
from .sensor_faults import (RESET_NOTES, SENSOR_FAULT_NOTES, reset_figure, reset_rows, run_resets, run_sensor_faults,
                            sensor_fault_rows, sensor_faults_figure)
from .stage_day import (DAY_LAWS, REPORT_PARTS, STAGE_DAY_NOTES, day_estimates_figure, day_frames_figure,
                        run_stage_day, stage_day_table_rows, write_stage_day_csv)

__all__ = ["run_all", "run_scenario", "check_out_dir", "prepare_out_dir", "VALIDATION_NOTES",
           "REPORT_WIDTH"]

#: Terminal width the printed notes are wrapped to.
REPORT_WIDTH = 100

VALIDATION_NOTES = (
    "Model vs model: the paper's Tables 2/3 compare each model with measured stage data, which "
    "we do not have. Our rows compare the coupled model (the Table 1 creep row of each input) "
    "with the Hammerstein model (creep.enabled = false) on the same input: they measure what "
    "the creep block adds, not how accurate either model is.",
    "C − H: coupled minus Hammerstein output over the metric window; e_r is normalised by the "
    "coupled output. y span: min–max of the coupled model's displacement over the window.",
    "paper H / C: the paper's e_rms of the Hammerstein and of the coupled model against its "
    "measured data (Table 2; Table 3 for e_r), for reference only.",
)


def check_out_dir(out_dir):
    """Refuse an output folder that cannot be created, without creating anything.

    Raises
    ------
    NotADirectoryError
        ``out_dir`` (or a parent) is an existing file.
    PermissionError
        The folder (or the parent it would be created in) is not writable.
    """
    out = Path(out_dir)
    for p in [out, *out.parents]:
        if p.exists():
            if not p.is_dir():
                raise NotADirectoryError(f"cannot create the output folder {out}: {p} is a file")
            if not os.access(p, os.W_OK | os.X_OK):
                raise PermissionError(f"cannot create the output folder {out}: {p} is not "
                                      f"writable")
            break
    return out


def prepare_out_dir(out_dir):
    """Create the output folder (and its parents); refuse a path that is a file.

    Raises
    ------
    NotADirectoryError, PermissionError, OSError
        The folder cannot be created (see :func:`check_out_dir`).
    """
    out = check_out_dir(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return out


def _overrides_text(params):
    return ", ".join(f"{k} = {v!r}" for k, v in params.items()) or "none"


def _parameter_table(scenarios):
    """Scenarios grouped by identical overrides: which parameters each group ran."""
    groups = {}
    for sc in scenarios:
        key = (tuple(sc.plant.items()), tuple(sc.controller.items()), sc.kind)
        groups.setdefault(key, []).append(sc.name)
    rows = []
    for (plant, ctrl, kind), names in groups.items():
        rows.append([", ".join(names), _overrides_text(dict(plant)),
                     _overrides_text(dict(ctrl)) if kind == "tracking" else "(no controller)"])
    return ["scenarios", "plant overrides", "controller overrides"], rows


def _provenance_blocks(prov, scenarios, defaults_source):
    D = doc_
    rows = [["commit", prov.commit], ["date", prov.date], ["machine", prov.machine],
            ["command", f"`{prov.command}`"], ["backend", prov.backend]]
    if prov.fmi_version is not None:
        rows.append(["FMI version", f"{prov.fmi_version}.0"])
    rows += [[name, version] for name, version in prov.versions.items()]
    blocks = [D.Heading("Provenance"), D.Table(("item", "value"), tuple(map(tuple, rows)))]
    if prov.fmus:
        blocks.append(D.Table(
            ("FMU", "GUID", "version", "FMI", "platforms", "generated by", "sha256"),
            tuple((f.name, f.guid, f.version, f.fmi_version, ", ".join(f.platforms),
                   f.generation_tool + (f" ({f.generated})" if f.generated else ""),
                   f.sha256[:16] + "…")
                  for f in prov.fmus),
            caption="FMUs that ran (from their modelDescription.xml):"))
        windows = set(WINDOWS_PLATFORM.values())
        linux_only = [f.name for f in prov.fmus if not windows & set(f.platforms)]
        if linux_only:
            blocks.append(D.Paragraph(
                f"**Linux only:** {', '.join(linux_only)} have no Windows binaries (they were "
                f"built without MinGW-w64); FMUs for Windows users need a build with it."))
    if prov.core_library:
        blocks.append(D.Paragraph(f"C core library: `{prov.core_library['path']}`, sha256 "
                                  f"{prov.core_library['sha256'][:16]}… (no FMU ran)."))
    head, prows = _parameter_table(scenarios)
    blocks += [D.Heading("Parameters", 3),
               D.Paragraph(f"Each scenario's overrides, by FMU variable name. Every other "
                           f"parameter is {defaults_source}."),
               D.Table(tuple(head), tuple(map(tuple, prows)))]
    return blocks


def _wrap_notes(title, notes):
    lines = [title]
    for n in notes:
        lines += textwrap.wrap(n, REPORT_WIDTH, initial_indent="  - ",
                               subsequent_indent="    ")
    return "\n".join(lines)


def _effective(defaults, overrides):
    p = dict(defaults)
    p.update(overrides)
    return p


def run_all(out_dir="out", *, adaptation=None, preview=True, master="gauss-seidel",
            fmu_dir=None, plots=True, backend="fmpy", registry=None, extra_scenarios=(),
            stream=sys.stdout, progress=sys.stderr, command=None, progress_interval=2.0,
            fmi_version=2):
    """Run every tracking condition, the validation inputs and the stage-use scenarios (each
    with the controller's defaults and the paper's law, through PiezoStageClosedLoop at a
    variable communication step, whatever the backend); write the report.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    adaptation, preview, master
        Base options of the tracking conditions (see :func:`default_conditions`).
    fmu_dir : str or Path, optional
    plots : bool
        Draw the figures (PNG and SVG).
    backend : {"auto", "fmpy", "native", "core"}
    registry : dict, optional
        Scenario registry (built-in plus user files); default built-in.
    extra_scenarios : iterable of str
        Further scenarios (the user's) run with the base options and reported
        in their own table ("user") or as validation rows; never next to paper values.
    stream : file-like or None
        Where the tables are printed.
    progress : file-like or None
        Where one line per finished run (and for long runs, lines within) is written.
    command : str, optional
        The command line, for the provenance (default: ``sys.argv``).
    progress_interval : float
        Least wall time [s] between two progress lines within one run.
    fmi_version : {2, 3}
        Run the FMI 2.0 (default) or the FMI 3.0 editions of the FMUs.

    Returns
    -------
    dict
        ``{"tracking": {condition key: [TrackingResult]}, "validation": [ValidationResult],
        "conditions": [Condition], "stage_use": [StageUseRun], "provenance": Provenance,
        "figures": [FigureFile], "files": [Path]}``
    """
    out = prepare_out_dir(out_dir)
    registry = load_scenarios() if registry is None else registry
    conditions = default_conditions(adaptation, preview, master)
    extra = [get_scenario(n, registry) for n in extra_scenarios]
    extra_track = tuple(s.name for s in extra if s.kind == "tracking")
    validation_names = list(VALIDATION_SCENARIOS) + [s.name for s in extra
                                                     if s.kind == "validation"]
    if extra_track:
        conditions.append(user_condition(extra_track, adaptation, preview, master))
    # every scenario looked up once, here; the Scenario objects go down
    scenarios = {n: get_scenario(n, registry)
                 for n in [*(n for c in conditions for n in c.scenarios), *validation_names]}
    # provenance first: a missing FMU fails here, before minutes of runs
    masters.simulators(backend, fmi_version)    # an impossible backend/version pair fails now
    prov = collect_provenance(backend, fmu_dir, command=command, fmi_version=fmi_version)
    plant_def = parameter_defaults(PLANT_MODEL, backend, fmu_dir, fmi_version)
    ctrl_def = parameter_defaults(CONTROLLER_MODEL, backend, fmu_dir, fmi_version)

    stage_names = stage_use_scenarios()
    total = (sum(len(c.scenarios) for c in conditions) + len(validation_names)
             + len(LAWS) * len(stage_names) + len(DAY_LAWS) * len(REPORT_PARTS))
    prog = Progress(total, progress, progress_interval)
    tracking = {}
    for cond in conditions:
        res = []
        for name in cond.scenarios:
            what = f"{cond.key} / {name}"
            sc = scenarios[name]
            r = evaluate_tracking(sc, condition=cond.key, adaptation=cond.adaptation,
                                  preview=cond.preview, master=cond.master, fmu_dir=fmu_dir,
                                  backend=backend, fmi_version=fmi_version,
                                  keep_data=plots and cond.role != "check",
                                  progress=prog.within(what, sc.step_size))
            prog.done(f"{what}: e_rms {r.e_rms_um * 1e3:.4g} nm", r.elapsed_s)
            res.append(r)
        tracking[cond.key] = res
    validation = []
    for name in validation_names:
        sc = scenarios[name]
        r = evaluate_validation(sc, fmu_dir=fmu_dir, backend=backend,
                                fmi_version=fmi_version, keep_data=plots,
                                progress=prog.within(f"validation / {name}", sc.step_size))
        prog.done(f"validation / {name}: C − H e_rms {r.diff_e_rms_um:.4f} µm", r.elapsed_s)
        validation.append(r)
    stage = run_stage_use(stage_names, registry=registry, fmu_dir=fmu_dir, fmi_version=fmi_version,
                          keep_data=plots, progress=prog)
    day = run_stage_day(fmu_dir=fmu_dir, fmi_version=fmi_version, keep_data=plots, progress=prog)
    sensor_faults = run_sensor_faults()
    resets = run_resets()

    files = []
    all_tracking = [r for c in conditions for r in tracking[c.key]]
    files.append(tables.write_tracking_csv(all_tracking, out / "tracking.csv"))
    files.append(tables.write_validation_csv(validation, out / "validation.csv"))
    files.append(write_stage_use_csv(stage, out / "stage_use.csv"))
    files.append(write_stage_day_csv(day, out / "stage_day.csv"))

    figures = []
    if plots:
        first = all_tracking[0].spec
        nominal_g = _effective(ctrl_def, first.controller)
        plants = {r.scenario: _effective(plant_def, r.spec.plant) for r in all_tracking}
        limits = None
        if nominal_g.get("sat.enabled", True):
            limits = (nominal_g.get("sat.v_min", float("nan")),
                      nominal_g.get("sat.v_max", float("nan")))
        figures = draw_main_figures(out, tracking, conditions, validation, nominal_g=nominal_g,
                                    plants=plants, v_limits=limits)
        figures += draw_stage_use_figures(out, stage, nominal_g=_effective(ctrl_def, {}),
                                          plants={r.scenario: _effective(plant_def, r.spec.plant)
                                                  for r in stage})
        figures += [day_frames_figure(day, out), day_estimates_figure(day, out, _effective(ctrl_def, {})),
                    sensor_faults_figure(sensor_faults, out), reset_figure(resets, out)]
        for f in figures:
            files += f.files

    scenarios = [r.spec for r in all_tracking] + [r.spec for r in validation]
    seen, unique = set(), []
    for sc in scenarios:
        if sc.name not in seen:
            seen.add(sc.name)
            unique.append(sc)
    defaults_source = ("the start value in the modelDescription of the FMUs above"
                       if backend != "core" else "the C core's default")
    report = _main_document(conditions, tracking, validation, figures, prov, unique,
                            defaults_source, plots, registry, stage, fmi_version, day, sensor_faults, resets)
    (out / "report.md").write_text(doc_.render_markdown(report), encoding="utf-8")
    (out / "report.html").write_text(doc_.render_html(report), encoding="utf-8")
    (out / "provenance.json").write_text(json.dumps(prov.as_dict(), indent=2) + "\n",
                                         encoding="utf-8")
    files += [out / "report.md", out / "report.html", out / "provenance.json"]

    if stream is not None:
        stream.write(_terminal_text(conditions, tracking, validation, registry, stage) + "\n")
        stream.write(f"\nReport: {out / 'report.html'} and {out / 'report.md'} "
                     f"({len(files)} files in {out}/)\n")
        stream.flush()
    return {"tracking": tracking, "validation": validation, "conditions": conditions,
            "stage_use": stage, "stage_day": day, "sensor_faults": sensor_faults, "resets": resets,
            "provenance": prov,
            "figures": figures, "files": files}


def condition_notes(conditions, registry=None):
    """What each condition is, by key; a plant already described is not described again."""
    out, seen = {}, set()
    for c in conditions:
        lines = describe_condition(c, registry)
        if lines[0] in seen:
            lines = ["Plant: the same as above."] + lines[1:]
        seen.add(lines[0])
        out[c.key] = lines
    return out


def _headline_title(cond):
    return f"Headline ({cond.label}) vs the paper's Tables 4/5"


#: What the columns of the all-conditions table are.
CONDITIONS_TABLE_NOTE = ("headline: the benchmark; RLS off / no preview: the headline with that "
                         "part switched off; nominal model: plant = controller model, an "
                         "implementation check (round-off by construction with preview)")


#: the terminal's stage-use notes: what its compact table leaves out, then the report's notes
STAGE_USE_TERMINAL_NOTES = ("The terminal shows each run's worst move; report.md has every move, "
                            "est.a1 before the last one and the controller's warnings.",
                            *STAGE_USE_NOTES)


def _stage_use_intro(fmi_version):
    """What the stage-use section is, in one paragraph."""
    return (f"What a positioning stage mostly does, on the mismatch plant: hold, move, hold "
            f"again, scan triangle rasters and dwell between frames (harness/scenarios/"
            f"stage_use.toml). Each scenario runs with the controller's defaults (ours) and with "
            f"the paper's law, through PiezoStageClosedLoop (FMI {fmi_version}.0, fmpy) with its "
            f"input y_d, one sample per communication step while y_d moves and for 0.5 s after, "
            f"{HOLD_STEP * 1e3:g} ms steps while it holds (the rows of one-sample steps at those "
            f"points, bit for bit). The family of 50 stages: docs/stage_use.md.")


def _terminal_text(conditions, tracking, validation, registry, stage=()):
    head = next(c for c in conditions if c.role == "headline")
    builtin = [c for c in conditions if c.role != "user"]
    parts = [tables.format_tracking_table(tracking[head.key], _headline_title(head)),
             tables.format_conditions_table(builtin, tracking,
                                            "All conditions: e_rms [nm] per reference")
             + "\n" + "\n".join(textwrap.wrap(CONDITIONS_TABLE_NOTE, REPORT_WIDTH))]
    for c in conditions:
        if c.role == "user":
            parts.append(tables.format_tracking_table(
                tracking[c.key], f"User scenarios ({c.label.split(', ', 1)[1]}), no paper values"))
    paper_v = [r for r in validation if r.has_paper]
    user_v = [r for r in validation if not r.has_paper]
    parts.append(tables.format_validation_table(
        paper_v, "Validation: coupled vs Hammerstein model (model vs model, no measured data)"))
    if user_v:
        parts.append(tables.format_validation_table(
            user_v, "User validation inputs: coupled vs Hammerstein model"))
    if stage:
        parts.append(format_stage_use_table(stage, "Stage use: ours vs the paper's law on the "
                                                   "mismatch plant")
                     + "\n" + _wrap_notes("Stage-use notes:", STAGE_USE_TERMINAL_NOTES))
    described = condition_notes(conditions, registry)
    notes = [_wrap_notes(f"{c.label}:", described[c.key]) for c in conditions]
    parts.append("What each condition is\n" + "\n".join(notes))
    parts.append(_wrap_notes("Validation notes:", VALIDATION_NOTES))
    return "\n\n".join(parts)


def _figure_block(fig):
    return doc_.Figure(fig.png.name, fig.svg.name, fig.caption, alt=fig.name)


def _add_section(doc, figures, title, text, table, notes, wanted):
    """A study's section: its heading, text, table ``(head, rows)``, notes and the figures ``wanted``
    picks."""
    D = doc_
    head, rows = table
    doc.add(D.Heading(title), D.Paragraph(text), D.Table(tuple(head), tuple(map(tuple, rows))), D.Bullets(notes))
    for f in figures:
        if wanted(f):
            doc.add(_figure_block(f))


def _main_document(conditions, tracking, validation, figures, prov, scenarios, defaults_source,
                   plots, registry=None, stage=(), fmi_version=2, day=(), sensor_faults=(), resets=()):
    D = doc_
    figs = {f.name: f for f in figures}
    head = next(c for c in conditions if c.role == "headline")
    builtin = [c for c in conditions if c.role != "user"]
    doc = D.Document("Piezo stage co-simulation report")
    doc.add(D.Paragraph(f"Run on {prov.date} at commit `{prov.commit}`, backend "
                        f"{prov.backend}. Provenance, parameters and the files are at the end."))

    h_head, h_rows = tables.tracking_table_rows(tracking[head.key])
    doc.add(D.Heading("Headline: tracking error, ours vs the paper"),
            D.Paragraph(f"**{head.label}.** Tracking error over the metric window, e_rms (eq 36) "
                        f"and e_r (eq 37), next to the paper's Tables 4/5; ratio = ours / paper."),
            D.Table(tuple(h_head), tuple(map(tuple, h_rows))))
    if "headline" in figs:
        doc.add(_figure_block(figs["headline"]))
    doc.add(D.Bullets(tuple(describe_condition(head, registry)), "What this condition is:"))

    c_head, c_rows = tables.conditions_table_rows(builtin, tracking)
    doc.add(D.Heading("All tracking conditions"),
            D.Paragraph("e_rms [nm] of every condition per reference, the paper's Table 4 "
                        "first. Columns: " + CONDITIONS_TABLE_NOTE + "."),
            D.Table(tuple(c_head), tuple(map(tuple, c_rows))),
            D.Heading("What each condition is", 3))
    described = condition_notes(builtin, registry)
    for c in builtin:
        doc.add(D.Bullets(tuple(described[c.key]), f"**{c.label}** (`{c.key}`):"))

    for c in conditions:
        if c.role != "user":
            continue
        u_head, u_rows = tables.tracking_table_rows(tracking[c.key])
        doc.add(D.Heading("User scenarios"),
                D.Paragraph(f"**{c.label}.** Not the paper's experiments, so no paper values."),
                D.Table(tuple(u_head), tuple(map(tuple, u_rows))),
                D.Bullets(tuple(describe_condition(c, registry)), "What this condition is:"))
        if "user_tracking_error" in figs:
            doc.add(_figure_block(figs["user_tracking_error"]))

    doc.add(D.Heading("Tracking figures"))
    if not plots:
        doc.add(D.Paragraph("No figures: the run had plots switched off (`--no-plots`)."))
    for name in ("tracking_error", "tracking_period", "control_voltage", "rls_estimates"):
        if name in figs:
            doc.add(_figure_block(figs[name]))

    paper_v = [r for r in validation if r.has_paper]
    user_v = [r for r in validation if not r.has_paper]
    v_head, v_rows = tables.validation_table_rows(paper_v, markdown=True)
    doc.add(D.Heading("Model validation: coupled vs Hammerstein model (model vs model)"),
            D.Paragraph("The plant alone (open loop) on the six inputs of Tables 1-3, run twice: "
                        "with creep (coupled model) and without (Hammerstein model)."),
            D.Table(tuple(v_head), tuple(map(tuple, v_rows))),
            D.Bullets(VALIDATION_NOTES))
    if user_v:
        u_head, u_rows = tables.validation_table_rows(user_v, markdown=True)
        doc.add(D.Paragraph("**User validation inputs** (not the paper's, so no paper values):"),
                D.Table(tuple(u_head), tuple(map(tuple, u_rows))))
    for name in ("hysteresis", "creep"):
        if name in figs:
            doc.add(_figure_block(figs[name]))

    if stage:
        s_head, s_rows = stage_use_table_rows(stage)
        doc.add(D.Heading("Stage use"), D.Paragraph(_stage_use_intro(fmi_version)),
                D.Table(tuple(s_head), tuple(map(tuple, s_rows))), D.Bullets(STAGE_USE_NOTES))
        for f in figures:
            if f.name.startswith("stage_use_"):
                doc.add(_figure_block(f))

    if day:
        _add_section(doc, figures, "A stage's day", (
            "The fourth stage of the identification family (the one issue 43 found the robust update of "
            "issue 35 bursting on after a few raster frames), 1 nm sensor, through PiezoStageClosedLoop at "
            "10 ms communication steps while the reference holds: 60 raster frames with 0.5 s dwells, 60 s "
            "of a 1 Hz tone then a 10 µm step, and the fresh step. The whole family over a day of "
            "rasters, tones and a random hour: docs/stage_day.md (python -m harness stage-day)."),
            stage_day_table_rows(day), STAGE_DAY_NOTES, lambda f: f.name.startswith("stage_day_"))

    if sensor_faults:
        _add_section(doc, figures, "A sensor that stops answering", (
            "The report's stage with a sensor that sticks where it was (or 2 nm off), dies (reads 0) or "
            "sticks after a dropout, in a 5 µm hold and mid-ramp of a 10 Hz raster: how soon the supervision "
            "names it and how far the stage went. The whole family, sensors of 0 to 200 nm on 50 stages: "
            "docs/robustness.md (python -m harness supervision stuck)."),
            sensor_fault_rows(sensor_faults), SENSOR_FAULT_NOTES, lambda f: f.name == "sensor_faults")
    if resets:
        _add_section(doc, figures, "Leaving the safe state (sup.reset)", (
            "The report's stage with a 20 nm sensor in a 5 µm hold: a sensor that sticks or dies, a reference "
            "beyond the stage's reach and an amplifier inverted for good put the loop in its safe state; the "
            "fault reset sup.reset is raised while the cause persists and again after it is gone. The whole "
            "family, sensors of 5 to 200 nm on 50 stages: docs/robustness.md (python -m harness supervision "
            "reset)."), reset_rows(resets), RESET_NOTES, lambda f: f.name == "fault_reset")

    doc.add(*_provenance_blocks(prov, scenarios, defaults_source))
    names = ["tracking.csv", "validation.csv"] + (["stage_use.csv"] if stage else [])
    names += ["stage_day.csv"] if day else []
    names += [p.name for f in figures for p in f.files]
    names += ["report.md", "report.html", "provenance.json"]
    doc.add(D.Heading("Files"), D.Bullets(tuple(f"`{n}`" for n in names)))
    return doc


#: Above this size a time series file is announced on the progress stream.
LARGE_FILE_BYTES = 50e6


def run_scenario(name, out_dir="out", *, adaptation=None, preview=True, master="gauss-seidel",
                 fmu_dir=None, plots=True, registry=None, backend="fmpy", stream=sys.stdout,
                 progress=sys.stderr, timeseries="csv", progress_interval=2.0, fmi_version=2):
    """Run one scenario (tracking or validation), print its table, write its files.

    Files: ``<name>.csv`` (metrics, same columns as ``tracking.csv`` or
    ``validation.csv``), ``<name>_timeseries.csv`` (or ``.npz``; none with
    ``timeseries=None``) and, with plots, ``<name>.png`` and ``<name>.svg``.

    Parameters
    ----------
    timeseries : {"csv", "npz", None}
        Format of the time series file, or ``None`` for none.
    fmi_version : {2, 3}
        Run the FMI 2.0 (default) or the FMI 3.0 editions of the FMUs.

    Returns
    -------
    TrackingResult or ValidationResult

    Raises
    ------
    ValueError
        Closed-loop options given for a validation scenario, or an unknown format.
    """
    sc = get_scenario(name, registry)
    if timeseries not in (None, *tables.TIMESERIES_FORMATS):
        raise ValueError(f"timeseries must be one of {', '.join(tables.TIMESERIES_FORMATS)} "
                         f"or None, got {timeseries!r}")
    if sc.kind == "validation" and (adaptation is not None or not preview
                                    or master != "gauss-seidel"):
        raise ValueError(f"scenario '{sc.name}' is a validation scenario (the plant runs alone): "
                         f"adaptation, preview and master do not apply")
    masters.simulators(backend, fmi_version)    # an impossible backend/version pair fails now
    out = prepare_out_dir(out_dir)
    prog = Progress(1, progress, progress_interval)
    keep = plots or timeseries is not None
    if sc.kind == "tracking":
        label = condition_label("run", adaptation, preview, master)
        r = evaluate_tracking(sc, condition="run", adaptation=adaptation, preview=preview,
                              master=master, fmu_dir=fmu_dir, backend=backend,
                              fmi_version=fmi_version, keep_data=keep,
                              progress=prog.within(sc.name, sc.step_size))
        prog.done(f"{sc.name}: e_rms {r.e_rms_um * 1e3:.4g} nm", r.elapsed_s)
        tables.write_tracking_csv([r], out / f"{sc.name}.csv")
        series = r.data
        table = tables.format_tracking_table([r], f"Tracking: {sc.name} ({label})")
    else:
        r = evaluate_validation(sc, fmu_dir=fmu_dir, backend=backend,
                                fmi_version=fmi_version, keep_data=keep,
                                progress=prog.within(sc.name, sc.step_size))
        prog.done(f"{sc.name}: C − H e_rms {r.diff_e_rms_um:.4f} µm", r.elapsed_s)
        tables.write_validation_csv([r], out / f"{sc.name}.csv")
        series = validation_series(r) if keep else None
        table = tables.format_validation_table(
            [r], f"Validation: {sc.name}, coupled vs Hammerstein model (model vs model)")
    if timeseries is not None:
        size = tables.timeseries_size(series, timeseries)
        if size > LARGE_FILE_BYTES:
            hint = (" (--timeseries-format npz writes less than half, --no-timeseries nothing)"
                    if timeseries == "csv" else "")
            prog.note(f"writing {sc.name}_timeseries.{timeseries}, about {size / 1e6:.0f} MB"
                      f"{hint}")
        tables.write_timeseries(series, out / f"{sc.name}_timeseries", timeseries)
    if plots:
        if sc.kind == "tracking":
            nominal = _effective(parameter_defaults(CONTROLLER_MODEL, backend, fmu_dir,
                                                    fmi_version),
                                 sc.controller)
            plant = _effective(parameter_defaults(PLANT_MODEL, backend, fmu_dir, fmi_version),
                               sc.plant)
            draw_scenario_figure(r, out, nominal_g=nominal, plant=plant, label=label)
        else:
            draw_scenario_figure(r, out)
    if stream is not None:
        stream.write(table + "\n")
        stream.flush()
    return r
