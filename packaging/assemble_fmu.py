"""Assemble an FMU from its parts, reproducibly (called by the build, cmake/PiezoFmu.cmake).

``python packaging/assemble_fmu.py commit-date --repo DIR --out FILE [--source-out FILE]``
    Writes the date the FMUs are stamped with (seconds since 1970, UTC): the
    ``SOURCE_DATE_EPOCH`` environment variable, else the date of the checked-out commit,
    else the newest modification time of the model descriptions and C sources. With
    ``--source-out``, also the source they are built from: the commit and whether the
    tracked files had uncommitted changes (``harness/_source.py``). Each file is rewritten
    only when it changes.

``python packaging/assemble_fmu.py assemble --id ID --fmi-version 2.0 ...``
    Lays out the FMU in ``--stage`` and zips it to ``--out``:

    * ``modelDescription.xml``: the source XML with ``version``, ``generationTool`` (the
      project, its version and the commit, from ``--source-file``) and
      ``generationDateAndTime`` (the commit date) set;
    * ``model.png``: the icon;
    * ``binaries/<platform>/<id>.<so|dll>``: one per ``--binary PLATFORM=FILE``;
    * ``sources/``: the C files and headers, flat, and ``buildDescription.xml`` (the
      FMI 3.0 build description, which FMI 2.0.4 adopts for source-code FMUs);
    * ``documentation/index.html`` (generated from the model description and the
      hand-written part, see ``harness/buildtime/documentation.py``), ``documentation/fmi-ls-ref.html``
      and ``documentation/licenses/license.txt``;
    * ``extra/org.fmi-standard.fmi-ls-ref/``: the reference results (``--extra-dir``).

    The zip is reproducible: entries in sorted order, every time stamp the commit date,
    fixed permissions, fixed compression level; the same inputs give the same bytes.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
if str(REPO) not in sys.path:          # harness: buildtime.documentation, buildtime.archive, _source
    sys.path.insert(0, str(REPO))

TOOL = "piezo_fmus"
LS_REF_DIR = "extra/org.fmi-standard.fmi-ls-ref"
#: the oldest date a zip entry can carry
ZIP_EPOCH = int(_dt.datetime(1980, 1, 1, tzinfo=_dt.timezone.utc).timestamp())


# ---------------------------------------------------------------------------
# the date
# ---------------------------------------------------------------------------

def commit_epoch(repo):
    """Seconds since 1970 of the build's date (see the module docstring)."""
    env = os.environ.get("SOURCE_DATE_EPOCH")
    if env:
        return int(env)
    try:
        out = subprocess.run(["git", "-C", str(repo), "log", "-1", "--format=%ct"],
                             capture_output=True, text=True, check=True).stdout.strip()
        if out:
            return int(out)
    except (OSError, subprocess.CalledProcessError, ValueError):
        pass
    repo = Path(repo)
    files = [p for sub in ("modelDescription", "fmu_src") for p in (repo / sub).rglob("*")
             if p.is_file()]
    return int(max(p.stat().st_mtime for p in files))


def iso_date(epoch):
    """xs:dateTime in UTC, e.g. ``2026-11-23T20:51:37Z``."""
    return _dt.datetime.fromtimestamp(epoch, _dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


# ---------------------------------------------------------------------------
# modelDescription.xml
# ---------------------------------------------------------------------------

_ROOT_TAG = re.compile(r"<fmiModelDescription\b[^>]*>", re.S)


def _set_attribute(tag, name, value):
    pattern = re.compile(rf'(\s){re.escape(name)}="[^"]*"')
    if pattern.search(tag):
        return pattern.sub(lambda m: f'{m.group(1)}{name}="{value}"', tag, count=1)
    # a new attribute goes on its own line, after the last one
    indent = " " * (len("<fmiModelDescription") + 1)
    return re.sub(r"\s*(/?>)$", lambda m: f'\n{indent}{name}="{value}"{m.group(1)}', tag, count=1)


def generation_tool(version, source=None):
    """``generationTool``: the project, its version and the source it was built from, e.g.
    ``piezo_fmus 1.0.0, commit 0123...cdef`` (``... with uncommitted changes`` when the
    tracked files differed from the commit; no commit outside a git checkout)."""
    from harness._source import describe

    if not source or not source.get("commit"):
        return f"{TOOL} {version}, not built from a git checkout"
    return f"{TOOL} {version}, commit {describe(source)}"


def stamp_model_description(text, version, epoch, source=None):
    """The model description with ``version``, ``generationTool`` (see
    :func:`generation_tool`) and ``generationDateAndTime`` set; the rest of the text
    unchanged."""
    match = _ROOT_TAG.search(text)
    if not match:
        raise ValueError("no <fmiModelDescription> element")
    tag = match.group(0)
    for name, value in (("version", version), ("generationTool", generation_tool(version, source)),
                        ("generationDateAndTime", iso_date(epoch))):
        tag = _set_attribute(tag, name, value)
    return text[:match.start()] + tag + text[match.end():]


# ---------------------------------------------------------------------------
# sources/buildDescription.xml
# ---------------------------------------------------------------------------

def build_description(fmi_version, model_identifier, sources, defines, language="C99"):
    """The build description of a flat ``sources/`` folder (FMI 3.0 schema, 2.4.10).

    Parameters
    ----------
    fmi_version : str
        ``"2.0"`` or ``"3.0"``: the FMI version of the FMU (the file's format is FMI 3.0's).
    model_identifier : str
    sources : list of str
        File names of the C files to compile, relative to ``sources/``.
    defines : list of str
        ``NAME`` or ``NAME=value``; each is written as an optional preprocessor definition
        that a build for MinGW needs (see ``DEFINE_DESCRIPTIONS``).
    """
    if fmi_version.startswith("2"):
        comment = ['<!-- How to compile this FMU from sources/: FMI 2.0.4 adopts the build description of',
                   '     FMI 3.0 (section 2.4.10), hence fmiVersion="3.0". The importer supplies the FMI 2.0',
                   '     headers (fmi2Functions.h, fmi2FunctionTypes.h, fmi2TypesPlatform.h). -->']
    else:
        comment = ['<!-- How to compile this FMU from sources/; the importer supplies the FMI 3.0 headers. -->']
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', *comment,
             '<fmiBuildDescription fmiVersion="3.0">',
             f'  <BuildConfiguration modelIdentifier="{model_identifier}"'
             ' description="Any C99 compiler; link the C math library where it is separate (-lm)">',
             f'    <SourceFileSet language="{language}">']
    for name in sources:
        lines.append(f'      <SourceFile name="{name}"/>')
    for define in defines:
        name, _, value = define.partition("=")
        description = DEFINE_DESCRIPTIONS.get(name, "")
        value_attr = f' value="{value}"' if value else ""
        lines.append(f'      <PreprocessorDefinition name="{name}"{value_attr} optional="true"'
                     f' description="{description}"/>')
    lines.append('      <IncludeDirectory name="."/>')
    lines += ['    </SourceFileSet>',
              '    <Library name="m" external="true" description="C math library (libm on Unix;'
              ' part of the C run-time on Windows)"/>',
              '  </BuildConfiguration>',
              '</fmiBuildDescription>', '']
    return "\n".join(lines)


DEFINE_DESCRIPTIONS = {
    "__USE_MINGW_ANSI_STDIO": "MinGW only: the C99 printf of MinGW, so that log messages print "
                              "size_t values (%zu) correctly; the win64 binary is built with it",
}


# ---------------------------------------------------------------------------
# the zip
# ---------------------------------------------------------------------------

def write_zip(stage, out, epoch):
    """Zip the folder `stage` to `out` reproducibly (harness.buildtime.archive); return the entry names."""
    from harness.buildtime.archive import write_fmu_zip

    stage = Path(stage)
    date = _dt.datetime.fromtimestamp(max(epoch, ZIP_EPOCH), _dt.timezone.utc).timetuple()[:6]
    files = {p.relative_to(stage).as_posix(): p.read_bytes()
             for p in stage.rglob("*") if p.is_file()}
    return write_fmu_zip(files, out, date)


# ---------------------------------------------------------------------------
# assemble
# ---------------------------------------------------------------------------

def _copy(src, dst):
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)


def assemble(args):
    from harness.buildtime import documentation as fmu_documentation

    epoch = int(Path(args.date_file).read_text().split()[0]) if args.date_file else \
        commit_epoch(Path.cwd())
    stage = Path(args.stage)
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)

    from harness._source import git_source, read_source

    source = read_source(args.source_file) if args.source_file else git_source(Path.cwd())
    xml = stamp_model_description(Path(args.model_description).read_text(encoding="utf-8"),
                                  args.version, epoch, source)
    (stage / "modelDescription.xml").write_text(xml, encoding="utf-8", newline="\n")
    _copy(args.icon, stage / "model.png")

    platforms = []
    for item in args.binary:
        folder, _, file = item.partition("=")
        file = Path(file)
        if file.suffix not in (".so", ".dll", ".dylib"):
            raise ValueError(f"--binary {item}: not a shared library")
        _copy(file, stage / "binaries" / folder / f"{args.id}{file.suffix}")
        platforms.append(folder)

    sources = stage / "sources"
    names = {}
    for file in [*args.sources, *args.headers]:
        name = Path(file).name
        if name in names and Path(names[name]).read_bytes() != Path(file).read_bytes():
            raise ValueError(f"two different sources are named {name}: {names[name]}, {file}")
        names[name] = file
        _copy(file, sources / name)
    c_files = [Path(f).name for f in args.sources]
    (sources / "buildDescription.xml").write_text(
        build_description(args.fmi_version, args.id, c_files, args.define or []), encoding="utf-8", newline="\n")

    extra = []
    if args.extra_dir:
        for file in sorted(Path(args.extra_dir).iterdir()):
            if file.is_file():
                _copy(file, stage / LS_REF_DIR / file.name)
                extra.append(file.name)

    doc = stage / "documentation"
    _copy(args.license, doc / "licenses" / "license.txt")
    (doc / "index.html").write_text(
        fmu_documentation.index_html(
            model_description=xml, fragment=Path(args.documentation).read_text(encoding="utf-8"),
            platforms=platforms, c_files=c_files, defines=args.define or [],
            reference_files=extra),
        encoding="utf-8", newline="\n")
    if extra:
        (doc / "fmi-ls-ref.html").write_text(
            fmu_documentation.ls_ref_html(model_description=xml, ls_ref_dir=stage / LS_REF_DIR),
            encoding="utf-8", newline="\n")

    entries = write_zip(stage, args.out, epoch)
    print(f"{args.out}: {sum(not e.endswith('/') for e in entries)} files "
          f"({', '.join(platforms)}, dated {iso_date(epoch)})")


def write_commit_date(args):
    text = f"{commit_epoch(args.repo)}\n"
    out = Path(args.out)
    if not out.is_file() or out.read_text() != text:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    if args.source_out:
        from harness._source import write_source

        write_source(args.repo, args.source_out)


def main(argv=None):
    p = argparse.ArgumentParser(prog="assemble_fmu.py", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("commit-date", help="write the build date (seconds since 1970)")
    d.add_argument("--repo", required=True)
    d.add_argument("--out", required=True)
    d.add_argument("--source-out", help="also write the source record (commit, uncommitted changes)")
    a = sub.add_parser("assemble", help="lay out and zip one FMU")
    a.add_argument("--id", required=True)
    a.add_argument("--fmi-version", required=True, choices=("2.0", "3.0"))
    a.add_argument("--model-description", required=True)
    a.add_argument("--version", required=True)
    a.add_argument("--date-file")
    a.add_argument("--source-file", help="the source record of commit-date --source-out "
                                         "(default: ask git in the current folder)")
    a.add_argument("--binary", action="append", default=[], metavar="PLATFORM=FILE")
    a.add_argument("--sources", nargs="+", required=True)
    a.add_argument("--headers", nargs="*", default=[])
    a.add_argument("--define", action="append", metavar="NAME[=VALUE]")
    a.add_argument("--icon", required=True)
    a.add_argument("--documentation", required=True)
    a.add_argument("--license", required=True)
    a.add_argument("--extra-dir")
    a.add_argument("--stage", required=True)
    a.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if args.command == "commit-date":
        write_commit_date(args)
    else:
        assemble(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
