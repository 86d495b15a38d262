"""Where things are: the repository (``REPO_ROOT``), the command that builds it
(``BUILD_COMMAND``), and the built artefacts: the FMUs, the libraries and their headers;
and how a report names a file it used (``sha256_of``).

The artefacts are looked for in order:

1. an environment variable (``PIEZO_FMU_DIR``, ``PIEZO_CORE_LIB``, ``PIEZO_CORE_INCLUDE``);
2. the package's own ``_data/`` folder, which ``pip install .`` fills (``fmus/``,
   ``lib/libpiezo_core.so``, ``include/*.h``; see the ``install()`` rules in CMakeLists.txt);
3. a source checkout: ``<repo>/build/fmus``, ``<repo>/build/libpiezo_core.so``,
   ``<repo>/fmu_src/core`` (the build of ``cmake -S . -B build && cmake --build build``);
4. the ``_data/`` of an installed distribution of the package (``piezo-stage-fmus``), when this copy of the package is
   a source checkout without a build (``pip install . && python -m harness`` run from the
   repository's root imports the checkout's ``harness``).

The first candidate that exists wins; if none does, the checkout's path (or, outside a
checkout, the package's) is returned, so that the error message names where the file
was expected.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.metadata import PackageNotFoundError, distribution, packages_distributions
import hashlib
import os
from pathlib import Path

__all__ = ["PACKAGE_DIR", "REPO_ROOT", "IN_CHECKOUT", "BUILD_COMMAND", "INSTALL_COMMAND",
           "fmu_dir", "core_library", "core_include_dir", "runner_library", "runner_include_dir",
           "bench_library", "bench_include_dir", "where_to_get_it", "describe_fmu_dir",
           "sha256_of"]

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_DIR.parent
#: this package is the ``harness/`` folder of a source checkout (not an installed copy)
IN_CHECKOUT = (REPO_ROOT / "CMakeLists.txt").is_file() and (REPO_ROOT / "fmu_src").is_dir()
BUILD_COMMAND = "cmake -S . -B build && cmake --build build"
INSTALL_COMMAND = "pip install ."
CORE_LIBRARY_NAME = "libpiezo_core.so"


@lru_cache(maxsize=1)
def _installed_data_dir():
    """``_data/`` of an installed distribution of the ``harness`` package (named in
    pyproject.toml; found by the import package it provides), or None. Looked up once per
    process and only when the earlier candidates are missing: ``packages_distributions``
    reads every installed distribution's metadata (about 0.2 s with a few hundred), and a
    sweep's workers ask for the runner's path at every chunk."""
    for name in packages_distributions().get("harness", []):
        try:
            dist = distribution(name)
        except PackageNotFoundError:
            continue
        data = Path(dist.locate_file("harness/_data"))
        if data.is_dir():
            return data
    return None


def _first(env, relative, checkout):
    """The path of the module docstring's rules: env var, package, checkout, installed."""
    value = os.environ.get(env)
    if value:
        return Path(value)
    own = PACKAGE_DIR / "_data" / relative
    if own.exists():
        return own
    if not IN_CHECKOUT:
        return own
    if (REPO_ROOT / checkout).exists():
        return REPO_ROOT / checkout
    installed = _installed_data_dir()
    if installed is not None and installed != PACKAGE_DIR / "_data" and (installed / relative).exists():
        return installed / relative
    return REPO_ROOT / checkout


def fmu_dir() -> Path:
    """Folder of the FMUs (``$PIEZO_FMU_DIR`` overrides)."""
    return _first("PIEZO_FMU_DIR", "fmus", "build/fmus")


def core_library() -> Path:
    """The core shared library (``$PIEZO_CORE_LIB`` overrides)."""
    return _first("PIEZO_CORE_LIB", f"lib/{CORE_LIBRARY_NAME}", f"build/{CORE_LIBRARY_NAME}")


def core_include_dir() -> Path:
    """Folder of the core's C headers, which the cffi binding reads
    (``$PIEZO_CORE_INCLUDE`` overrides)."""
    return _first("PIEZO_CORE_INCLUDE", "include", "fmu_src/core")


def runner_library() -> Path:
    """The native closed-loop master's library (``$PIEZO_RUNNER_LIB`` overrides)."""
    return _first("PIEZO_RUNNER_LIB", "lib/libpiezo_runner.so", "build/libpiezo_runner.so")


def runner_include_dir() -> Path:
    """Folder of ``piezo_runner.h``, which the native master's cffi binding reads."""
    return _first("PIEZO_RUNNER_INCLUDE", "include", "fmu_src/runner")


def bench_library() -> Path:
    """The core's timing loops (``python -m harness bench``)."""
    return _first("PIEZO_BENCH_LIB", "lib/libpiezo_bench.so", "build/libpiezo_bench.so")


def bench_include_dir() -> Path:
    """Folder of ``piezo_bench.h``."""
    return _first("PIEZO_BENCH_INCLUDE", "include", "fmu_src/bench")


def where_to_get_it() -> str:
    """How to produce the missing artefacts, for error messages."""
    if IN_CHECKOUT:
        return f"build them in {REPO_ROOT} with: {BUILD_COMMAND}  (or {INSTALL_COMMAND})"
    return f"reinstall the package from its source folder with: {INSTALL_COMMAND}"


def describe_fmu_dir() -> str:
    """The folder the FMUs are taken from when none is given, and why, for help texts:
    ``$PIEZO_FMU_DIR``, the package's own ``_data/fmus`` (``pip install .``) or the
    checkout's ``build/fmus``."""
    value = os.environ.get("PIEZO_FMU_DIR")
    if value:
        return f"{value}, from $PIEZO_FMU_DIR"
    path = fmu_dir()
    if path.parent.name == "_data":
        return f"{path}, the FMUs installed with the package; $PIEZO_FMU_DIR overrides"
    return f"{path}, the checkout's build; $PIEZO_FMU_DIR overrides"


def sha256_of(path):
    """The SHA-256 of a file's bytes, as hex (how a report, a provenance record and an
    exported FMU name a record, an FMU or a library)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
