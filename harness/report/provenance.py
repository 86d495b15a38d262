"""Where a report's numbers come from: commit, FMUs, package versions, date, machine.

:func:`collect_provenance` gathers everything a reader needs to reproduce a
report: the commit of the harness (and whether the tree had uncommitted
changes; for an installed package, the commit it was built from), each FMU's GUID,
version and checksum from its modelDescription, the versions of Python, fmpy and numpy, the date and the machine.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
import datetime as _dt
from importlib import metadata
import os
from pathlib import Path
import platform
import sys

from .. import _source, masters, paths
from ..binding import core
from ..fmu import fmu_path, fmu_platforms, model_description

__all__ = ["FMUInfo", "Provenance", "collect_provenance", "fmu_info", "commit_id"]


@dataclass(frozen=True)
class FMUInfo:
    """What identifies one FMU (or the core library) that a report ran."""

    name: str
    path: str
    guid: str
    version: str
    fmi_version: str
    generation_tool: str
    generated: str
    sha256: str
    platforms: tuple = ()


def fmu_info(path):
    """Read an FMU's identity from its modelDescription."""
    md = model_description(path)
    return FMUInfo(name=md.modelName, path=str(path), guid=md.guid or "",
                   version=getattr(md, "version", None) or "not set",
                   fmi_version=md.fmiVersion or "",
                   generation_tool=md.generationTool or "",
                   generated=md.generationDateAndTime or "",
                   sha256=paths.sha256_of(path), platforms=fmu_platforms(path))


@dataclass
class Provenance:
    """Everything that identifies a report's run.

    Attributes
    ----------
    commit : str
        Commit hash of the harness's repository, with `` with uncommitted changes`` when
        the tracked files differ from it (see :func:`commit_id`).
    backend : str
    fmi_version : int or None
        The FMI version of the FMUs that ran (None with the core backend, which runs no FMU).
    fmus : list of FMUInfo
        The FMUs that ran (empty with the core backend).
    core_library : dict
        Path and sha256 of the C core library (core backend only).
    versions : dict
        Python and package versions.
    date : str
        ISO 8601 with the time zone.
    machine : str
    command : str
    """

    commit: str
    backend: str
    fmi_version: object = 2
    fmus: list = field(default_factory=list)
    core_library: dict = field(default_factory=dict)
    versions: dict = field(default_factory=dict)
    date: str = ""
    machine: str = ""
    command: str = ""

    def as_dict(self):
        """A JSON-ready dict."""
        return asdict(self)


def commit_id():
    """The commit the harness comes from (:mod:`harness._source`).

    A source checkout: git's HEAD, with `` with uncommitted changes`` when the tracked files
    differ from it. An installed package: the commit recorded when it was built, with
    `` (recorded at build time, installed package)``. Otherwise ``unknown`` and why.
    """
    if paths.IN_CHECKOUT:
        here = _source.git_source(paths.REPO_ROOT)
        if here["commit"]:
            return _source.describe(here)
    built = _source.installed_source()
    if built is None:
        return "unknown (not a git checkout, and no build record)"
    if not built["commit"]:
        return "unknown (the installed package was not built from a git checkout)"
    return f"{_source.describe(built)} (recorded at build time, installed package)"


def _version(dist):
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def _cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_description():
    """Host name, OS, CPU model and count."""
    return (f"{platform.node() or 'unknown host'}: {platform.system()} {platform.release()} "
            f"{platform.machine()}, {_cpu_model()}, {os.cpu_count()} CPUs")


def collect_provenance(backend="fmpy", fmu_dir=None, models=None, command=None, fmi_version=2):
    """Gather the provenance of a run.

    Parameters
    ----------
    backend : {"auto", "fmpy", "native", "core"}
    fmu_dir : str or Path, optional
    models : sequence of str, optional
        The FMUs that ran (default: those of the backend's master, :attr:`harness.masters.Master.fmus`).
    command : str, optional
        The command line (default: ``sys.argv``).
    fmi_version : {2, 3}
        The edition of the FMUs that ran.

    Returns
    -------
    Provenance
    """
    models = masters.get(backend).fmus if models is None else tuple(models)
    prov = Provenance(commit=commit_id(), backend=backend,
                      fmi_version=None if backend == "core" else int(fmi_version))
    if backend != "core":
        prov.fmus = [fmu_info(fmu_path(m, fmu_dir, fmi_version)) for m in models]
    else:
        lib = core.library_path()
        prov.core_library = {"path": str(lib), "sha256": paths.sha256_of(lib) if lib.is_file() else ""}
    prov.versions = {"python": platform.python_version(), "fmpy": _version("fmpy"),
                     "numpy": _version("numpy"), "scipy": _version("scipy"),
                     "matplotlib": _version("matplotlib"), "cffi": _version("cffi")}
    prov.date = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
    prov.machine = machine_description()
    prov.command = command if command is not None else " ".join(sys.argv)
    return prov
