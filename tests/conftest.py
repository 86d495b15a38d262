"""Shared pytest fixtures.

Blocks are owned by different parts of the project; keep each block separate.
"""
import os

# The tests' linear algebra is small; multi-threaded BLAS only spins when the
# machine is shared (seen: the suite's CPU time went from 40 s to 10 min).
# Set before numpy is first imported; subprocesses inherit it.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# =============================================================================
# FMU fixtures (FMI layer: tests/test_fmu_*.py)
#
# Builds the FMUs with CMake into build/ when they are missing or older than
# any of their sources, extracts each once per session, and offers `Fmu`, a
# thin driver over fmpy's FMU2Slave that captures the FMU's log messages and
# keeps time on the integer grid t0 + k h like an honest master.
# =============================================================================
import ctypes
import pathlib
import shutil
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
# the checkout's harness is the one tested, however pytest was started (the test files import
# it without putting the checkout on sys.path themselves)
if str(REPO) not in sys.path[:1]:
    sys.path.insert(0, str(REPO))
BUILD_DIR = REPO / "build"
FMU_DIR = BUILD_DIR / "fmus"
FMU3_DIR = FMU_DIR / "fmi3"


def state_format():
    """The serialized FMU state's integer constants (BLOB_HEADER, BLOB_OFF_*, ...) as declared
    once, in fmu_src/fmi/fmu_state_format.h, which the glue and the C tests compile."""
    import re
    text = (REPO / "fmu_src" / "fmi" / "fmu_state_format.h").read_text()
    return {name: int(value) for name, value in re.findall(r"^#define (BLOB_\w+) (\d+)u$", text, re.M)}


def _cmake_list(path, name):
    """The words of ``set(NAME ...)`` in a CMake file (the list's one home)."""
    import re
    m = re.search(rf"^set\({name} ([^)]*)\)", path.read_text(), re.M)
    return tuple(m.group(1).split())


#: the FMUs the build makes (CMakeLists.txt FMU_IDS)
FMU_NAMES = _cmake_list(REPO / "CMakeLists.txt", "FMU_IDS")
#: the three FMUs of the loop, in the argument order of the C hosts that wire them
#: (fmu_regressions, fmu_supervision: tests/c/CMakeLists.txt PIEZO_LOOP_IDS)
LOOP_FMUS = _cmake_list(REPO / "tests" / "c" / "CMakeLists.txt", "PIEZO_LOOP_IDS")
#: a scenario whose sweeps have every kind of run: ok, stopped, clipped, refused (the file says why)
NEAR_LIMITS = REPO / "tests" / "scenarios" / "near_limits.toml"
NEAR_LIMITS_NAME = "near_limits_20hz"
_FMU_SOURCE_SUFFIXES = {".c", ".h", ".xml", ".map", ".txt", ".cmake", ".py", ".html", ".png"}


def _fmu_sources():
    yield REPO / "CMakeLists.txt"
    yield REPO / "LICENSE"
    yield REPO / "pyproject.toml"                           # the FMUs' version
    # the SSP, the reference results and the FMU documentation are written by Python
    yield from (REPO / "harness").glob("*.py")
    yield from (REPO / "harness" / "scenarios").glob("*.toml")
    for sub in ("fmu_src", "modelDescription", "cmake", "packaging"):
        for path in (REPO / sub).rglob("*"):
            if path.is_file() and path.suffix in _FMU_SOURCE_SUFFIXES:
                yield path


def _commit_date_changed():
    """The FMUs carry the commit date and the source (commit, uncommitted changes): a new
    commit, or a tree that became clean or dirty, re-stamps them (build/piezo_commit_date.txt
    and build/source.json hold those of the last build; packaging/assemble_fmu.py
    commit_epoch and harness/_source.py git_source compute them)."""
    stamp = BUILD_DIR / "piezo_commit_date.txt"
    if not stamp.is_file():
        return True
    sys.path.insert(0, str(REPO / "packaging"))
    try:
        from assemble_fmu import commit_epoch
    finally:
        sys.path.pop(0)
    from harness._source import git_source, read_source
    return (stamp.read_text().split()[0] != str(commit_epoch(REPO))
            or read_source(BUILD_DIR / "source.json") != git_source(REPO))


def _fmus_stale():
    fmus = ([FMU_DIR / f"{name}.fmu" for name in FMU_NAMES] + [BUILD_DIR / "libpiezo_core.so"]
            + [FMU3_DIR / f"{name}.fmu" for name in FMU_NAMES]        # the FMI 3.0 editions
            + [FMU_DIR / "PiezoStageClosedLoop.ssp"]
            + [BUILD_DIR / "libpiezo_runner.so", BUILD_DIR / "libpiezo_bench.so"])   # native master, bench
    if not all(f.exists() for f in fmus):
        return True
    oldest = min(f.stat().st_mtime for f in fmus)
    return (any(src.stat().st_mtime > oldest for src in _fmu_sources())
            or _commit_date_changed())


def build_fmus():
    """Build (if needed) and return {modelIdentifier: path of the .fmu}."""
    if _fmus_stale():
        if shutil.which("cmake") is None:
            raise RuntimeError("cmake is needed to build the FMUs and the core library")
        subprocess.run(["cmake", "-S", str(REPO), "-B", str(BUILD_DIR), f"-DPIEZO_PYTHON={sys.executable}"],
                       check=True, stdout=subprocess.DEVNULL)
        subprocess.run(["cmake", "--build", str(BUILD_DIR), "-j", "4"], check=True, stdout=subprocess.DEVNULL)
    return {name: FMU_DIR / f"{name}.fmu" for name in FMU_NAMES}


def pytest_sessionstart(session):
    """Every test needs the build (core library for cffi, FMUs for fmpy): make it
    once, before collection, so no test can silently skip for a missing artifact."""
    build_fmus()


@pytest.fixture(scope="session")
def fmu_paths():
    return build_fmus()


@pytest.fixture(scope="session")
def fmu3_paths(fmu_paths):
    """{modelIdentifier: path of the FMI 3.0 edition's .fmu} (built with the FMI 2.0 ones)."""
    return {name: FMU3_DIR / f"{name}.fmu" for name in FMU_NAMES}


class FmuPackage:
    """An extracted FMU: its model description and where it was unzipped."""

    def __init__(self, path):
        import fmpy
        self.path = pathlib.Path(path)
        self.unzipdir = fmpy.extract(str(path))
        self.md = fmpy.read_model_description(str(path))
        self.variables = {v.name: v for v in self.md.modelVariables}

    def instantiate(self, **kwargs):
        return Fmu(self, **kwargs)


@pytest.fixture(scope="session")
def _fmu_packages(fmu_paths):
    packages = {name: FmuPackage(path) for name, path in fmu_paths.items()}
    yield packages
    for package in packages.values():
        shutil.rmtree(package.unzipdir, ignore_errors=True)


def _package_fixture(model):
    """A session fixture: the extracted FmuPackage of ``model``."""
    @pytest.fixture(scope="session")
    def package(_fmu_packages):
        return _fmu_packages[model]
    package.__doc__ = f"The extracted {model}.fmu (FmuPackage)."
    return package


piezo_stage = _package_fixture("PiezoStage")
controller = _package_fixture("AdaptiveCompoundController")
reference_signal = _package_fixture("ReferenceSignal")
closed_loop = _package_fixture("PiezoStageClosedLoop")


# fmpy's native logger proxy (which formats the variadic message) keeps ONE
# Python logger per process, so every instance shares one dispatcher that
# routes by componentEnvironment.
_FMU_BY_ID = {}
_fmu_ids = iter(range(1, 1 << 30))


def _dispatch_log(env, instance_name, status, category, message):
    fmu = _FMU_BY_ID.get(env or 0)
    record = (status, category.decode(errors="replace"), message.decode(errors="replace"))
    if fmu is not None:
        fmu.messages.append(record)
    else:
        print(f"[{instance_name.decode(errors='replace')}] {record}")


_dispatch_logger = None


def _shared_logger():
    global _dispatch_logger
    if _dispatch_logger is None:
        from fmpy.fmi2 import fmi2CallbackLoggerTYPE
        _dispatch_logger = fmi2CallbackLoggerTYPE(_dispatch_log)
    return _dispatch_logger


class Fmu:
    """One instance of an FMU, driven through fmpy.fmi2.FMU2Slave."""

    def __init__(self, package, logging_on=False, instance_name="instance"):
        from fmpy.fmi2 import (FMU2Slave, fmi2CallbackFunctions, fmi2CallbackAllocateMemoryTYPE,
                               fmi2CallbackFreeMemoryTYPE)
        from fmpy import calloc, free
        from fmpy.logging import addLoggerProxy

        self.package = package
        self.messages = []          # (status, category, text)
        self.id = next(_fmu_ids)
        _FMU_BY_ID[self.id] = self
        md = package.md
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=package.unzipdir,
                               modelIdentifier=md.coSimulation.modelIdentifier,
                               instanceName=instance_name)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = _shared_logger()
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        callbacks.componentEnvironment = self.id
        addLoggerProxy(ctypes.byref(callbacks))     # formats the variadic message in C
        self.callbacks = callbacks
        self.slave.instantiate(callbacks=callbacks, loggingOn=logging_on)
        self.t0 = 0.0
        self.h = None
        self.k = 0
        self._freed = False

    # -- messages -------------------------------------------------------------
    def errors(self):
        return [text for status, _, text in self.messages if status >= 3]

    def last_error(self):
        errors = self.errors()
        return errors[-1] if errors else ""

    def clear_messages(self):
        self.messages.clear()

    # -- variables --------------------------------------------------------------
    def _var(self, name):
        return self.package.variables[name]

    def set(self, values):
        for name, value in values.items():
            var = self._var(name)
            vr = [var.valueReference]
            if var.type == "Real":
                self.slave.setReal(vr, [float(value)])
            elif var.type == "Integer":
                self.slave.setInteger(vr, [int(value)])
            elif var.type == "Boolean":
                self.slave.setBoolean(vr, [bool(value)])
            else:
                raise TypeError(var.type)

    def get(self, name):
        var = self._var(name)
        vr = [var.valueReference]
        if var.type == "Real":
            return self.slave.getReal(vr)[0]
        if var.type == "Integer":
            return self.slave.getInteger(vr)[0]
        if var.type == "Boolean":
            return bool(self.slave.getBoolean(vr)[0])
        raise TypeError(var.type)

    def get_reals(self, names):
        return self.slave.getReal([self._var(n).valueReference for n in names])

    # -- life cycle ---------------------------------------------------------------
    def setup(self, start_time=0.0, params=None):
        self.slave.setupExperiment(startTime=start_time)
        self.t0 = start_time
        if params:
            self.set(params)
        self.slave.enterInitializationMode()

    def initialize(self, params=None, start_time=0.0):
        self.setup(start_time, params)
        self.slave.exitInitializationMode()
        self.h = self.get("h")
        self.k = 0

    @property
    def time(self):
        return self.t0 + self.k * self.h

    def step(self, n=1):
        self.slave.doStep(self.time, n * self.h)
        self.k += n

    def free(self):
        if not self._freed:
            self._freed = True
            self.slave.freeInstance()
            _FMU_BY_ID.pop(self.id, None)


@pytest.fixture
def make_fmu():
    """Factory: make_fmu(package, logging_on=False) -> Fmu; frees them all at teardown."""
    created = []

    def factory(package, **kwargs):
        fmu = package.instantiate(**kwargs)
        created.append(fmu)
        return fmu

    yield factory
    for fmu in created:
        fmu.free()


def assert_refused(call, fmu, *fragments):
    """Call ``call()`` (an FMI call on ``fmu``) and require the refusal the FMUs give bad input:
    fmpy's FMICallException with status fmi2Error, and an Error message logged by this call
    (the messages are cleared first, so an earlier one cannot stand in) that contains every
    fragment. Returns the message."""
    from fmpy.fmi1 import FMICallException
    fmu.clear_messages()
    with pytest.raises(FMICallException) as info:
        call()
    assert info.value.status == 3, info.value        # fmi2Error
    message = fmu.last_error()
    assert message, "refused without an Error message"
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


def assert_nonfinite_refusals_change_nothing(make, signal, refuse_at, error):
    """Two blocks from ``make()`` stepped through ``signal``; before each sample in ``refuse_at``
    the second is handed NaN, +Inf and -Inf, each refused with ``error``: the two outputs must be
    bitwise equal (a refusal changes nothing)."""
    import numpy as np
    a, b = make(), make()
    out_a, out_b = [], []
    for k, x in enumerate(signal):
        if k in refuse_at:
            for bad in (np.nan, np.inf, -np.inf):
                with pytest.raises(error):
                    b.step(bad)
        out_a.append(a.step(x))
        out_b.append(b.step(x))
    assert out_a == out_b


def assert_state_continues_bitwise(make_fmu, package, params, run, n_before, n_after, carried):
    """An FMU state taken after ``n_before`` samples of ``run(fmu, n, k0=...)`` (``params`` set
    at initialization) continues bitwise: the next ``n_after`` samples equal the uninterrupted
    run's when the state is set back, when its serialized blob is deserialized into the same
    instance, and when the blob is deserialized into a fresh instance never initialized, where
    ``carried(fresh)`` first checks what the state brought (its parameters)."""
    import numpy as np
    fmu = make_fmu(package)
    fmu.initialize(params)
    run(fmu, n_before)
    state = fmu.slave.getFMUstate()
    blob = fmu.slave.serializeFMUstate(state)
    reference = run(fmu, n_after, k0=n_before)

    # set the state back: same continuation
    fmu.slave.setFMUstate(state)
    fmu.k = n_before
    assert np.array_equal(run(fmu, n_after, k0=n_before), reference)
    fmu.slave.freeFMUstate(state)

    # deserialize in the same instance
    state2 = fmu.slave.deSerializeFMUstate(blob)
    fmu.slave.setFMUstate(state2)
    fmu.k = n_before
    assert np.array_equal(run(fmu, n_after, k0=n_before), reference)
    fmu.slave.freeFMUstate(state2)

    # deserialize into a fresh instance that was never initialized
    fresh = make_fmu(package)
    state3 = fresh.slave.deSerializeFMUstate(blob)
    fresh.slave.setFMUstate(state3)
    fresh.slave.freeFMUstate(state3)
    fresh.h, fresh.k = fmu.h, n_before
    carried(fresh)
    assert np.array_equal(run(fresh, n_after, k0=n_before), reference)


def assert_reset_to_start_values(fmu, fresh, terminate_first, outputs):
    """fmi2Reset of ``fmu`` (after fmi2Terminate when ``terminate_first``), then it and ``fresh``
    (a new instance of the same FMU) set up at t = 0: every parameter and input of ``fmu`` has
    its XML start value again, and its ``outputs`` equal ``fresh``'s."""
    if terminate_first:
        fmu.slave.terminate()
    fmu.slave.reset()
    fmu.setup()
    fresh.setup()
    for name, var in fmu.package.variables.items():
        if var.causality in ("parameter", "input"):
            assert fmu.get(name) == start_value(var), name
    assert fmu.get_reals(outputs) == fresh.get_reals(outputs)


def reset_after_a_non_default_run(make_fmu, package, non_default, run, inputs, terminate_first, outputs):
    """The reset tests' common start: ``non_default`` must set every parameter of ``package``
    away from its XML start value; an instance initialized with them and run 200 samples
    (``run(fmu, n)``), then its ``inputs`` set, must hold them all; then
    assert_reset_to_start_values of it against a fresh instance. Returns (the reset instance,
    the fresh one), both in InitializationMode."""
    variables = package.variables
    params = {n for n, var in variables.items() if var.causality == "parameter"}
    assert set(non_default) == params       # a new parameter must be added here
    assert all(non_default[n] != start_value(variables[n]) for n in params)

    fmu = make_fmu(package)
    fmu.initialize(non_default)
    run(fmu, 200)
    fmu.set(inputs)
    assert {n: fmu.get(n) for n in params} == non_default     # the run really used them
    fresh = make_fmu(package)
    assert_reset_to_start_values(fmu, fresh, terminate_first, outputs)
    return fmu, fresh


def start_value(var):
    """The XML start value of a model variable (as fmpy reads it), as a Python value."""
    return {"Real": float, "Integer": int}.get(var.type, lambda s: s in ("true", True))(var.start)

# ============================ end of FMU fixtures ============================


# =============================================================================
# Optional tools: the cross compilers of the platforms (harness/platforms.py) and what
# runs their binaries here (wine64, wine, qemu-aarch64)
#
# Without them the build makes FMUs with fewer platforms, and the tests that need them skip
# with the reason. .ci/run installs all of them and sets PIEZO_REQUIRE_PLATFORMS=1: there
# such a skip is a failure, so CI still proves every platform's binaries.
# PIEZO_REQUIRE_WIN64=1 (before there were other platforms) requires the x86_64-windows ones.
# =============================================================================

from harness.platforms import CROSS as CROSS_PLATFORMS, HOST as HOST_PLATFORM  # noqa: E402
from harness.platforms import by_key as platform_by_key  # noqa: E402

#: set by .ci/run: a missing cross compiler or runner, or FMUs built without it, fail the test
REQUIRE_PLATFORMS = os.environ.get("PIEZO_REQUIRE_PLATFORMS", "") == "1"
REQUIRE_WIN64 = os.environ.get("PIEZO_REQUIRE_WIN64", "") == "1"
#: where Debian puts wine64 and wine (not on PATH)
WINE_DIRS = ("/usr/lib/wine",)
WINE64_DIRS = WINE_DIRS
WIN64_HINT = ("install MinGW-w64 and wine64 (Debian: gcc-mingw-w64-x86-64 wine64, as .ci/run "
              "does) and rebuild")


def platform_hint(platform):
    """How to get what a platform's tests need, for skip messages."""
    if platform.key == "x86_64-windows":
        return WIN64_HINT
    return (f"install {platform.triple}-gcc and {platform.runner} (Debian: "
            f"{' '.join(platform.toolchain_packages + platform.runner_packages)}, as .ci/run "
            f"does) and rebuild")


def _required(platform):
    return REQUIRE_PLATFORMS or (REQUIRE_WIN64 and platform.key == "x86_64-windows")


def need_platform(platform, reason):
    """Skip the calling test because `reason` (what the platform's tests miss); with
    PIEZO_REQUIRE_PLATFORMS=1 (or PIEZO_REQUIRE_WIN64=1 for x86_64-windows) fail it instead,
    with the same reason."""
    platform = platform_by_key(platform) if isinstance(platform, str) else platform
    text = f"{reason}: {platform_hint(platform)}"
    if _required(platform):
        variable = "PIEZO_REQUIRE_PLATFORMS" if REQUIRE_PLATFORMS else "PIEZO_REQUIRE_WIN64"
        pytest.fail(f"{text} ({variable}=1 makes this a failure, not a skip)", pytrace=False)
    pytest.skip(text)


def need_win64(reason):
    """need_platform for 64-bit Windows."""
    need_platform("x86_64-windows", reason)


def error_lines(stderr):
    """The lines of a command's stderr without the platform note that every run of FMUs built
    without MinGW-w64 prints first ("warning: the FMUs in ... have no Windows binaries",
    harness.fmu.missing_windows_binaries): a test of a message sees the same lines on a
    machine with or without MinGW-w64."""
    return [line for line in stderr.strip().splitlines()
            if not (": warning: the FMUs in " in line and " have no Windows binaries " in line)]


def cross_tool(platform, name):
    """Path of the platform's tool <triple>-<name> (gcc, objdump) on PATH, or skip (see
    need_platform)."""
    platform = platform_by_key(platform) if isinstance(platform, str) else platform
    tool = f"{platform.triple}-{name}"
    path = shutil.which(tool)
    if not path:
        need_platform(platform, f"{tool} not found on PATH")
    return path


def mingw_tool(name):
    """Path of the MinGW-w64 tool x86_64-w64-mingw32-<name> on PATH, or skip."""
    return cross_tool("x86_64-windows", name)


def platform_runner(platform):
    """Path of the program that runs the platform's binaries here (PATH, then Debian's
    /usr/lib/wine for wine64 and wine), or skip (see need_platform)."""
    platform = platform_by_key(platform) if isinstance(platform, str) else platform
    path = (shutil.which(platform.runner)
            or shutil.which(platform.runner, path=os.pathsep.join(WINE_DIRS)))
    if not path:
        need_platform(platform, f"{platform.runner} not found (on PATH or in /usr/lib/wine)")
    return path


def wine64():
    """Path of wine64, or skip (see need_platform)."""
    return platform_runner("x86_64-windows")


def fmu_platforms(path):
    """The platform folders under binaries/ of an FMU file."""
    import zipfile
    with zipfile.ZipFile(path) as zf:
        return sorted({n.split("/")[1] for n in zf.namelist()
                       if n.startswith("binaries/") and n.count("/") >= 2 and not n.endswith("/")})


def need_platform_binaries(path, platform, fmi_version):
    """Skip (see need_platform) unless the FMU at `path` has the platform's binaries/ folder:
    the build cross-compiles them only when the platform's compiler is installed."""
    platform = platform_by_key(platform) if isinstance(platform, str) else platform
    folder = platform.folder(fmi_version)
    if folder not in fmu_platforms(path):
        need_platform(platform, f"{pathlib.Path(path).name} has no binaries/{folder}/ "
                                f"({platform.triple}-gcc was not found when it was built)")


def need_windows_binaries(path, folder="win64"):
    """Skip (see need_platform) unless the FMU at `path` has binaries/<folder>/ (a Windows
    folder of either FMI version)."""
    platform = platform_by_key(folder)
    need_platform_binaries(path, platform, 2 if folder == platform.fmi2 else 3)


def built_cross_platforms():
    """The keys of the cross platforms whose binaries the build in build/ makes, by the build's
    rule (CMakeLists.txt) read back from its cache: the platform's option ON, or AUTO with
    ``<triple>-gcc`` found when it was configured (``PIEZO_CC_<key>`` not NOTFOUND)."""
    import re
    cache = (BUILD_DIR / "CMakeCache.txt").read_text()

    def value(name):
        found = re.search(rf"^{re.escape(name)}:\w+=(.*)$", cache, re.M)
        return found.group(1) if found else ""

    keys = set()
    for platform in CROSS_PLATFORMS:
        option, compiler = value(platform.option) or "AUTO", value(f"PIEZO_CC_{platform.key}")
        if option == "ON" or (option == "AUTO" and compiler and not compiler.endswith("-NOTFOUND")):
            keys.add(platform.key)
    return keys


def expected_binaries(name, fmi_version):
    """The binaries/ files an FMU of this build should hold: the host's, and those of every
    cross platform the build makes (built_cross_platforms) that has a folder in that FMI
    version. Reference: the platform table and the build's configuration, not the archive."""
    built = built_cross_platforms()
    files = []
    for platform in (HOST_PLATFORM, *CROSS_PLATFORMS):
        folder = platform.folder(fmi_version)
        if folder and (platform is HOST_PLATFORM or platform.key in built):
            files.append(f"binaries/{folder}/{name}{platform.suffix}")
    return sorted(files)

# ======================== end of optional tools =========================


# =============================================================================
# Helpers the test files share (tests/README.md: how to write a test here)
# =============================================================================

def mismatch_plant():
    """The mismatch plant of docs/model.md (harness/scenarios/mismatch.toml, its one home):
    the plant parameters of the mismatch scenarios."""
    from harness.scenarios import get_scenario
    return dict(get_scenario("mismatch_5hz").plant)


def run_harness(*args, cwd=REPO, check=False, timeout=900):
    """``python -m harness ARGS`` of this checkout in a subprocess (figures without a display);
    the CompletedProcess (text). ``check``: the run must exit 0 (its stderr is the message)."""
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-m", "harness", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


#: valgrind's memcheck as the C hosts run under it: every error, and every byte left at exit
#: (definitely, indirectly or possibly lost, or still reachable), makes the exit code 3
MEMCHECK_OPTIONS = ("--leak-check=full", "--show-leak-kinds=all", "--errors-for-leak-kinds=all",
                    "--error-exitcode=3")


def memcheck_prefix(what):
    """The command prefix that runs a C host under valgrind's memcheck (MEMCHECK_OPTIONS); [] when
    valgrind is missing outside CI, with a note naming ``what`` ran without it (printed and a
    warning in pytest's summary). Under CI (the environment variable CI set, as .ci/run is run)
    valgrind is required: the test fails."""
    import warnings
    valgrind = shutil.which("valgrind")
    if valgrind:
        return [valgrind, *MEMCHECK_OPTIONS]
    if os.environ.get("CI"):
        pytest.fail("valgrind is required under CI (CI is set): apt-get install valgrind (.ci/run "
                    "does this)", pytrace=False)
    note = (f"NOTE: valgrind is not installed: {what} ran WITHOUT memcheck, so memory errors and "
            "leaks were NOT checked (install valgrind; it is required under CI)")
    print(note, file=sys.stderr)
    warnings.warn(note)
    return []


def memcheck_clean(stderr):
    """valgrind's verdict in a run's stderr: no error, and no byte in use at exit (hence none
    lost)."""
    import re
    errors = re.search(r"ERROR SUMMARY: (\d+) errors", stderr)
    in_use = re.search(r"in use at exit: ([\d,]+) bytes", stderr)
    return (errors is not None and int(errors.group(1)) == 0
            and in_use is not None and int(in_use.group(1).replace(",", "")) == 0)

# ========================= end of shared helpers ==========================


# =============================================================================
# Optional engines: libcosim (libcosimpy) and Ecos (ecospy), the extra "engines"
#
# Without them the tests that run the loop in them skip with the reason. .ci/run installs
# them (and Debian's libtbb12, which Ecos's library needs) and sets PIEZO_REQUIRE_ENGINES=1:
# there such a skip is a failure, as PIEZO_REQUIRE_PLATFORMS does for the platforms.
# =============================================================================

REQUIRE_ENGINES = os.environ.get("PIEZO_REQUIRE_ENGINES", "") == "1"
ENGINE_HINT = {
    "libcosim": "pip install libcosimpy (or '.[engines]', as .ci/run does)",
    "Ecos": "pip install ecospy and apt-get install libtbb12 (or '.[engines]', as .ci/run does)",
}


def need_engine(engine, reason):
    """Skip the calling test because `reason` (what running it in `engine` misses); with
    PIEZO_REQUIRE_ENGINES=1 fail it instead, with the same reason."""
    text = f"{engine}: {reason}: {ENGINE_HINT[engine]}"
    if REQUIRE_ENGINES:
        pytest.fail(f"{text} (PIEZO_REQUIRE_ENGINES=1 makes this a failure, not a skip)", pytrace=False)
    pytest.skip(text)

# ======================== end of optional engines =========================
