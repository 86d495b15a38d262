"""Where a report's numbers come from: commit, FMUs, package versions, date, machine.

:func:`collect_provenance` gathers everything a reader needs to reproduce a
report: the commit of the harness (and whether the tree had uncommitted
changes; for an installed package, the commit it was built from), each FMU's GUID, version and checksum from its modelDescription, the
versions of Python, fmpy and numpy, the date and the machine.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
import datetime as _dt
import hashlib
from importlib import metadata
import os
from pathlib import Path
import platform
import sys
import zipfile

from .._common import REPO_ROOT

__all__ = ["FMUInfo", "Provenance", "collect_provenance", "model_description", "fmu_info",
           "fmu_platforms", "missing_windows_binaries"]

_MD_CACHE = {}


def model_description(path):
    """fmpy's model description of an FMU file (cached by path, mtime and size)."""
    import fmpy

    path = Path(path)
    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _MD_CACHE:
        _MD_CACHE[key] = fmpy.read_model_description(str(path))
    return _MD_CACHE[key]


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


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


#: the folder of the Windows binary in each FMI version's binaries/
WINDOWS_PLATFORM = {2: "win64", 3: "x86_64-windows"}


def fmu_platforms(path):
    """The platform folders of an FMU's ``binaries/`` (``linux64``, ``win64``, ...), sorted."""
    with zipfile.ZipFile(path) as zf:
        return tuple(sorted({n.split("/")[1] for n in zf.namelist()
                             if n.startswith("binaries/") and n.count("/") >= 2
                             and not n.endswith("/")}))


def fmu_info(path):
    """Read an FMU's identity from its modelDescription."""
    md = model_description(path)
    return FMUInfo(name=md.modelName, path=str(path), guid=md.guid or "",
                   version=getattr(md, "version", None) or "not set",
                   fmi_version=md.fmiVersion or "",
                   generation_tool=md.generationTool or "",
                   generated=md.generationDateAndTime or "",
                   sha256=_sha256(path), platforms=fmu_platforms(path))


def missing_windows_binaries(fmu_dir=None, fmi_version=2):
    """A one-line note when the FMUs of `fmu_dir` have no Windows binary, else None.

    The build cross-compiles ``binaries/win64`` (FMI 3.0: ``x86_64-windows``) only when
    MinGW-w64 is installed; ``pip install .`` hides CMake's output, so the user learns it
    here. Only the plant FMU is looked at: one build makes all of them.
    """
    from .. import _paths
    from ..cosim import PLANT_MODEL, fmu_path

    try:
        path = fmu_path(PLANT_MODEL, fmu_dir, fmi_version)
        platforms = fmu_platforms(path)
    except (OSError, zipfile.BadZipFile):
        return None                         # the run itself says what is wrong
    windows = WINDOWS_PLATFORM[int(fmi_version)]
    if set(platforms) & set(WINDOWS_PLATFORM.values()):
        return None                         # (the other edition's: the run refuses it)
    folder = path.parent
    if fmu_dir is None and not os.environ.get("PIEZO_FMU_DIR"):
        fix = (f"then rebuild ({_paths.BUILD_COMMAND})" if _paths.IN_CHECKOUT
               else f"then reinstall the package from its source folder ({_paths.INSTALL_COMMAND})")
        fix = f"; for FMUs that also run on Windows install MinGW-w64 (Debian: gcc-mingw-w64-x86-64), {fix}"
    else:
        fix = ""
    return (f"the FMUs in {folder} have no Windows binaries (binaries/{windows}): MinGW-w64 was "
            f"not found when they were built, so they run on Linux only{fix}")


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
    from .. import _paths, _source

    if _paths.IN_CHECKOUT:
        here = _source.git_source(REPO_ROOT)
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
        The FMUs that ran (default: PiezoStage and AdaptiveCompoundController).
    command : str, optional
        The command line (default: ``sys.argv``).
    fmi_version : {2, 3}
        The edition of the FMUs that ran.

    Returns
    -------
    Provenance
    """
    from ..cosim import CONTROLLER_MODEL, PLANT_MODEL, fmu_path

    models = (PLANT_MODEL, CONTROLLER_MODEL) if models is None else tuple(models)
    prov = Provenance(commit=commit_id(), backend=backend,
                      fmi_version=None if backend == "core" else int(fmi_version))
    if backend != "core":
        prov.fmus = [fmu_info(fmu_path(m, fmu_dir, fmi_version)) for m in models]
    else:
        from .. import core
        lib = core.library_path()
        prov.core_library = {"path": str(lib), "sha256": _sha256(lib) if lib.is_file() else ""}
    prov.versions = {"python": platform.python_version(), "fmpy": _version("fmpy"),
                     "numpy": _version("numpy"), "scipy": _version("scipy"),
                     "matplotlib": _version("matplotlib"), "cffi": _version("cffi")}
    prov.date = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
    prov.machine = machine_description()
    prov.command = command if command is not None else " ".join(sys.argv)
    return prov
