"""FMU access: where the FMUs are, loading one, its model description, its parameters by
name and type, and the error family every master raises.

* :func:`fmu_path`: a model's FMU file in a folder (FMI 2.0, or the FMI 3.0 edition in the
  ``fmi3/`` folder beside it), with a message that says what a missing one means;
* :func:`load`: the FMU read and extracted once per process (cache keyed by path, mtime and
  size), checked to be the FMI version asked for and this project's model;
* :func:`sort_parameters` / :func:`typed_parameters`: parameters by FMU variable name, checked
  and split by type (FMI 3.0 array elements by their FMI 2.0 names, ``pi.w[3]``);
* :func:`model_description`, :func:`parameter_starts`, :func:`parameter_types`,
  :func:`fmu_platforms`, :func:`missing_windows_binaries`: what an FMU file declares and holds.

Every master (:mod:`harness.masters`) and every job reads FMUs through this module.
"""

from __future__ import annotations

import atexit
import difflib
import os
from pathlib import Path
import shutil
import tempfile
import zipfile

import fmpy
import numpy as np

from . import paths

__all__ = [
    "PLANT_MODEL", "CONTROLLER_MODEL", "REFERENCE_MODEL", "FMI_VERSIONS", "TIMING_OUTPUTS",
    "WINDOWS_PLATFORM", "REAL_TYPES", "INTEGER_TYPES",
    "FMUError", "FMUInitializationError", "FMUFileError", "LoopDivergedError", "LoopFaultError",
    "LOOP_FAILURES", "loop_error_class", "LoopFaultWarning", "SAFE_STATE_WORDS", "warn_safe_state",
    "UnknownParameterError",
    "default_fmu_dir", "check_fmi_version", "fmu_path", "LoadedFMU", "load", "array_size",
    "sort_parameters", "typed_parameters", "model_description", "starts_of", "parameter_starts",
    "parameter_types", "fmu_platforms", "missing_windows_binaries",
]

PLANT_MODEL = "PiezoStage"
CONTROLLER_MODEL = "AdaptiveCompoundController"
REFERENCE_MODEL = "ReferenceSignal"

#: the FMI versions the FMUs come in (the FMI 3.0 editions in the ``fmi3/`` subfolder)
FMI_VERSIONS = (2, 3)

#: the controller's outputs that say what it detected (Integer, except loop_delay_time)
TIMING_OUTPUTS = ("loop_delay", "loop_delay_time", "preview_lead", "meas_offset")
#: the folder of the Windows binary in each FMI version's binaries/ (harness/platforms.py)
from .platforms import WINDOWS_PLATFORM  # noqa: E402


class FMUError(RuntimeError):
    """An FMI call failed; the message carries the FMU's log messages."""


class LoopDivergedError(FMUError):
    """The closed loop diverged: the controller's monitor found it unstable, or a computed
    value was not finite; the message carries the FMU's explanation."""


class LoopFaultError(LoopDivergedError):
    """The controller's supervision stopped a loop that cannot work (a measurement that does not
    answer v, answers inverted or far off the model, later than the controller handles; v held
    at a limit); the message names the signal at fault and the evidence."""


#: how the controller's Error messages begin when it stops the loop itself, and the error each means
#: (fmu_src/fmi/fmu_controller.c, fmu_controller_failure: the words of AdaptiveCompoundController
#: and PiezoStageClosedLoop alike)
LOOP_FAILURES = (("supervision stopped the loop", LoopFaultError),
                 ("the closed loop is unstable", LoopDivergedError),
                 ("diverged", LoopDivergedError))


#: how the controller's Warning begins when a verdict put the loop in its safe state (sup.reaction = 1,
#: fmu_src/fmi/fmu_controller.c, fmu_controller_warning); the verdict's message follows "Why: "
SAFE_STATE_WORDS = "sup.reaction = safe:"


class LoopFaultWarning(UserWarning):
    """A run with ``sup.reaction`` = 1 (safe) went on after a supervision verdict: the controller
    ramped v to 0 V and held the loop in its safe state (``sup.fault``, ``sup.fault_time``); the
    message is the controller's Warning, the verdict's words included."""


def warn_safe_state(log_lines, where=""):
    """Issue a :class:`LoopFaultWarning` for the controller's safe-state Warning among an FMU's log
    lines (``"[Warning] ..."``), if there is one; return its text ("" if none)."""
    import warnings
    said = [line for line in log_lines if line.startswith("[Warning]") and SAFE_STATE_WORDS in line]
    if not said:
        return ""
    text = said[0][len("[Warning] "):]
    warnings.warn(LoopFaultWarning(f"{where}: {text}" if where else text), stacklevel=3)
    return text


def loop_error_class(log_lines):
    """The exception a failed run raises, from the FMU's log lines: :class:`LoopFaultError` or
    :class:`LoopDivergedError` when the controller stopped the loop itself
    (:data:`LOOP_FAILURES`), :class:`FMUError` otherwise."""
    errors = [line for line in log_lines if "[Error]" in line]
    for words, cls in LOOP_FAILURES:
        if any(words in line for line in errors):
            return cls
    return FMUError


class FMUInitializationError(FMUError, ValueError):
    """The FMU refused its parameters (instantiation or initialization failed)."""


class FMUFileError(FMUError, ValueError):
    """The file is not the FMU expected there: not an FMU at all, the other FMI version, or
    another model under this model's file name (a user error, like a missing FMU)."""


class UnknownParameterError(KeyError):
    """A parameter name is not a parameter of the FMU; the message lists the valid names."""

    def __str__(self):  # KeyError would quote the message
        return self.args[0]


def default_fmu_dir():
    """Folder of the FMUs: ``$PIEZO_FMU_DIR``, the copies ``pip install .`` put inside the
    package, or ``<repo>/build/fmus`` (see :mod:`harness.paths`)."""
    return paths.fmu_dir()


def check_fmi_version(fmi_version):
    """``fmi_version`` if it is one of :data:`FMI_VERSIONS`, else ValueError."""
    if fmi_version not in FMI_VERSIONS:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    return fmi_version


def fmu_path(model, fmu_dir=None, fmi_version=2):
    """Path of a model's FMU, checked to exist.

    Parameters
    ----------
    model : str
        ``"PiezoStage"``, ``"AdaptiveCompoundController"`` or ``"ReferenceSignal"``.
    fmu_dir : str or Path, optional
        Defaults to :func:`default_fmu_dir`.
    fmi_version : {2, 3}
        2: ``<fmu_dir>/<model>.fmu``; 3: the FMI 3.0 edition ``<fmu_dir>/fmi3/<model>.fmu``
        (or ``<fmu_dir>/<model>.fmu`` when ``fmu_dir`` is itself a folder of FMI 3.0
        editions without an ``fmi3/`` subfolder).

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        With the command that builds the FMUs.
    """
    check_fmi_version(fmi_version)
    chosen = fmu_dir is not None or bool(os.environ.get("PIEZO_FMU_DIR"))
    folder = Path(fmu_dir if fmu_dir is not None else default_fmu_dir())
    path = folder / f"{model}.fmu"
    if fmi_version == 3:
        nested = folder / "fmi3" / f"{model}.fmu"
        path = nested if nested.is_file() or not path.is_file() else path
    if not path.is_file():
        if chosen:
            why = _folder_contents(folder, model, fmi_version, from_env=fmu_dir is None)
            raise FileNotFoundError(f"FMU not found: {path}; {why}")
        raise FileNotFoundError(f"FMU not found: {path}; {paths.where_to_get_it()} "
                                f"(or set PIEZO_FMU_DIR to the folder of the FMUs)")
    return path


def _folder_contents(folder, model, fmi_version, from_env):
    """What a user-chosen FMU folder lacks and what it holds, for the message of a missing FMU."""
    need = (f"the harness runs {PLANT_MODEL}.fmu and {CONTROLLER_MODEL}.fmu from it"
            if model in (PLANT_MODEL, CONTROLLER_MODEL) else f"the harness runs {model}.fmu from it")
    if fmi_version == 3:
        need += ", or from its fmi3/ subfolder, in their FMI 3.0 editions"
    name = f"{folder} ($PIEZO_FMU_DIR)" if from_env else str(folder)
    if not folder.exists():
        return f"the folder {name} does not exist ({need})"
    if not folder.is_dir():
        return f"{name} is a file, not a folder ({need})"
    present = sorted(p.name for p in folder.glob("*.fmu"))
    if fmi_version == 3:
        present += sorted(f"fmi3/{p.name}" for p in (folder / "fmi3").glob("*.fmu"))
    held = f"it holds {', '.join(present)}" if present else "it holds no .fmu file at all"
    return f"the folder {name} has no {model}.fmu, {held} ({need})"


# ---------------------------------------------------------------------------
# loading: each FMU file read and extracted once per process
# ---------------------------------------------------------------------------

class LoadedFMU:
    """An extracted FMU: model description, unzip folder, variables by name.

    ``elements`` maps the FMI 2.0 name of every element of an FMI 3.0 array variable
    (``pi.w[3]``) to ``(array variable, index from 0)``.
    """

    __slots__ = ("path", "md", "unzipdir", "variables", "model", "fmi_version", "elements")

    def __init__(self, path, md, unzipdir):
        self.path = path
        self.md = md
        self.unzipdir = unzipdir
        self.variables = {v.name: v for v in md.modelVariables}
        self.model = md.coSimulation.modelIdentifier
        self.fmi_version = 3 if md.fmiVersion.startswith("3") else 2
        self.elements = {}
        for v in md.modelVariables:
            for i in range(array_size(v) or 0):
                self.elements[f"{v.name}[{i + 1}]"] = (v, i)

    def vr(self, name):
        try:
            return self.variables[name].valueReference
        except KeyError:
            other = (f": it is not this project's {self.path.stem} (its model is {self.model})"
                     if self.model != self.path.stem else "")
            raise FMUFileError(f"{self.path} has no variable '{name}'{other}") from None

    def parameter_names(self):
        """The parameters by their FMI 2.0 names (array elements one by one)."""
        names = []
        for name, v in self.variables.items():
            if v.causality != "parameter":
                continue
            size = array_size(v)
            names += [name] if size is None else [f"{name}[{i + 1}]" for i in range(size)]
        return names


def array_size(var):
    """The number of elements of an FMI 3.0 array variable, None for a scalar."""
    dims = getattr(var, "dimensions", None) or []
    if not dims:
        return None
    size = 1
    for d in dims:
        size *= int(d.start)
    return size


_EXTRACTED = {}
_TEMP_DIRS = []


def _cleanup():
    for d in _TEMP_DIRS:
        shutil.rmtree(d, ignore_errors=True)


atexit.register(_cleanup)


def load(path, fmi_version=2):
    """The FMU at ``path`` read and extracted (once per process, path and file content), checked
    to be an FMI ``fmi_version``.0 Co-Simulation FMU.

    Raises
    ------
    FMUFileError
        Not an FMU, or an FMU of the other FMI version.
    """
    st = path.stat()
    # the path as given too: messages name the file the caller asked for, also when another
    # path (a link) led to the same file earlier in the process
    key = (str(path), str(path.resolve()), st.st_mtime_ns, st.st_size)
    info = _EXTRACTED.get(key)
    if info is None:
        try:
            md = fmpy.read_model_description(str(path))
        except Exception as exc:    # fmpy raises BadZipFile, KeyError, lxml errors, ...
            raise FMUFileError(f"{path} is not an FMU (its model description cannot be read: "
                               f"{type(exc).__name__}: {exc})") from None
        if md.fmiVersion != f"{fmi_version}.0" or md.coSimulation is None:
            raise _wrong_edition(path, md.fmiVersion, fmi_version)
        unzipdir = tempfile.mkdtemp(prefix=f"harness_{path.stem}_")
        _TEMP_DIRS.append(unzipdir)
        fmpy.extract(str(path), unzipdir=unzipdir)
        info = LoadedFMU(path, md, unzipdir)
        _EXTRACTED[key] = info
    if info.fmi_version != fmi_version:
        raise _wrong_edition(path, info.md.fmiVersion, fmi_version)
    return info


def _wrong_edition(path, found, fmi_version):
    """The error for an FMU of the other FMI version (or without Co-Simulation)."""
    if fmi_version == 3:
        hint = " (the FMI 3.0 editions are in the fmi3/ folder beside the FMI 2.0 FMUs)"
    elif str(found).startswith("3"):
        hint = " (an FMI 3.0 edition: run it with --fmi 3)"
    else:
        hint = ""
    return FMUFileError(f"{path} is not an FMI {fmi_version}.0 Co-Simulation FMU (it is FMI "
                        f"{found}){hint}")


# ---------------------------------------------------------------------------
# parameters by name, checked and typed
# ---------------------------------------------------------------------------

REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")


def sort_parameters(info, params):
    """Parameters by FMI 2.0 variable name as ``(reals, ints, bools, arrays)``: each of the first
    three ``([vr], [value])``, ``arrays`` ``{array variable: {index from 0: value}}`` for the
    elements of FMI 3.0 array variables.

    Raises
    ------
    UnknownParameterError
        A name is not a parameter of the FMU (the message lists the close ones and all).
    TypeError
        A value does not fit the variable's type.
    """
    reals, ints, bools, arrays = ([], []), ([], []), ([], []), {}
    for name, value in params.items():
        var, index = info.variables.get(name), None
        if var is None and name in info.elements:
            var, index = info.elements[name]
        if var is None or var.causality != "parameter" or (index is None and array_size(var)):
            valid = info.parameter_names()
            close = difflib.get_close_matches(name, valid, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise UnknownParameterError(
                f"'{name}' is not a parameter of {info.model}{hint}; "
                f"parameters: {', '.join(valid)}")
        if var.type in REAL_TYPES:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
                raise TypeError(f"{info.model} parameter {name} is Real, got {value!r}")
            typed, target = float(value), reals
        elif var.type in INTEGER_TYPES:
            if isinstance(value, (bool, np.bool_)) or not float(value).is_integer():
                raise TypeError(f"{info.model} parameter {name} is Integer, got {value!r}")
            typed, target = int(value), ints
        elif var.type == "Boolean":
            if not (isinstance(value, (bool, np.bool_)) or value in (0, 1)):
                raise TypeError(f"{info.model} parameter {name} is Boolean, got {value!r}")
            typed, target = bool(value), bools
        else:
            raise TypeError(f"{info.model} parameter {name} has unsupported type {var.type}")
        if index is not None:
            arrays.setdefault(var, {})[index] = typed
        else:
            target[0].append(var.valueReference)
            target[1].append(typed)
    return reals, ints, bools, arrays


def typed_parameters(info, params):
    """Parameters of an FMI 2.0 FMU by variable name as ``(reals, ints, bools)``, each
    ``([vr], [value])`` (see :func:`sort_parameters`)."""
    reals, ints, bools, arrays = sort_parameters(info, params)
    if arrays:
        raise TypeError(f"{info.model}: array elements need the FMI 3.0 path")
    return reals, ints, bools


# ---------------------------------------------------------------------------
# what an FMU file declares and holds (read without extracting it)
# ---------------------------------------------------------------------------

_MD_CACHE = {}


def model_description(path):
    """fmpy's model description of an FMU file (cached by path, mtime and size)."""
    path = Path(path)
    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _MD_CACHE:
        _MD_CACHE[key] = fmpy.read_model_description(str(path))
    return _MD_CACHE[key]


def _start_value(var):
    """A parameter's ``start`` as Python values: one, or a list for an FMI 3.0 array; None
    for a type that is not Real, Integer or Boolean."""
    if var.type in ("Real", "Float64"):
        convert = float
    elif var.type in ("Integer", "Int32"):
        convert = int
    elif var.type == "Boolean":
        def convert(text):
            return text.lower() in ("true", "1")
    else:
        return None
    if getattr(var, "dimensions", None):          # an FMI 3.0 array: one start per element
        return [convert(text) for text in str(var.start).split()]
    return convert(str(var.start))


def starts_of(md):
    """The start value of every Real/Integer/Boolean parameter in a model description, by FMU
    variable name; the elements of an FMI 3.0 array variable by their FMI 2.0 names
    (``pi.w[1]`` ..), so both editions give the same dictionary."""
    out = {}
    for v in md.modelVariables:
        if v.causality != "parameter" or v.start is None:
            continue
        value = _start_value(v)
        if isinstance(value, list):
            out.update({f"{v.name}[{i + 1}]": x for i, x in enumerate(value)})
        elif value is not None:
            out[v.name] = value
    return out


def parameter_starts(model, fmu_dir=None, fmi_version=2):
    """:func:`starts_of` the model description of a model's FMU (read, not extracted).

    Raises
    ------
    FileNotFoundError
        The FMU is missing (see :func:`fmu_path`).
    """
    return starts_of(model_description(fmu_path(model, fmu_dir, fmi_version)))


def parameter_types(model, fmu_dir=None):
    """The type of every parameter of a model's FMI 2.0 FMU, by name: ``"Real"``,
    ``"Integer"`` or ``"Boolean"``."""
    md = model_description(fmu_path(model, fmu_dir))
    return {v.name: v.type for v in md.modelVariables if v.causality == "parameter"}


def fmu_platforms(path):
    """The platform folders of an FMU's ``binaries/`` (``linux64``, ``win64``, ...), sorted."""
    with zipfile.ZipFile(path) as zf:
        return tuple(sorted({n.split("/")[1] for n in zf.namelist()
                             if n.startswith("binaries/") and n.count("/") >= 2
                             and not n.endswith("/")}))


def missing_windows_binaries(fmu_dir=None, fmi_version=2):
    """A one-line note when the FMUs of `fmu_dir` have no Windows binary, else None.

    The build cross-compiles ``binaries/win64`` (FMI 3.0: ``x86_64-windows``) only when
    MinGW-w64 is installed; ``pip install .`` hides CMake's output, so the user learns it
    here. Only the plant FMU is looked at: one build makes all of them.
    """
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
        fix = (f"then rebuild ({paths.BUILD_COMMAND})" if paths.IN_CHECKOUT
               else f"then reinstall the package from its source folder ({paths.INSTALL_COMMAND})")
        fix = f"; for FMUs that also run on Windows install MinGW-w64 (Debian: gcc-mingw-w64-x86-64), {fix}"
    else:
        fix = ""
    return (f"the FMUs in {folder} have no Windows binaries (binaries/{windows}): MinGW-w64 was "
            f"not found when they were built, so they run on Linux only{fix}")
