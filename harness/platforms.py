"""The platforms the FMUs carry binaries for: the one table of them.

Each row says where the binary goes in each FMI version's ``binaries/``, which compiler makes
it (the host's, or a cross compiler named by its target triple), the CMake option that
switches it, the Debian packages of its toolchain and of what runs its binaries here, and the
oldest systems it loads on. Everything else reads this table:

* the build: CMakeLists.txt runs ``python -m harness.platforms cmake`` at configure time and
  builds each cross platform whose compiler is on PATH (an ExternalProject with
  cmake/toolchains/cross-gcc.cmake and the row's triple);
* the harness: :data:`WINDOWS_PLATFORM` (the note when the FMUs have no Windows binary);
* the tests: tests/test_fmu_platforms.py checks and runs each platform's binaries, and checks
  that the platform table of docs/fmus.md says what this table says;
* .ci/run installs every row's packages (``python3 -m harness.platforms packages``).

Only the standard library is imported: the build runs this module before anything is built.
"""

from __future__ import annotations

from dataclasses import dataclass
import sys

__all__ = ["Platform", "PLATFORMS", "GLIBC_BASELINE", "HOST", "CROSS", "WINDOWS_PLATFORM",
           "by_key", "folder", "main"]

#: the oldest glibc every shipped Linux binary loads on: no versioned symbol newer than this
#: (the build pins the few newer ones, cmake/glibc_baseline.h; a test reads every ELF file)
GLIBC_BASELINE = (2, 17)


@dataclass(frozen=True)
class Platform:
    """One platform of the FMUs' binaries.

    Attributes
    ----------
    key : str
        The FMI 3.0 platform tuple (``x86_64-linux``), which also names it in the build and
        the tests.
    fmi2 : str or None
        The FMI 2.0 ``binaries/`` folder (``linux64``, ``win64``, ``win32``), or None where
        FMI 2.0 names no folder for the platform (aarch64 Linux: FMI 3.0 editions only).
    system : str
        CMake's system name: ``Linux`` or ``Windows``.
    triple : str or None
        The cross compiler's target triple (the prefix of ``<triple>-gcc``); None: the host
        compiler (the build machine is this platform).
    option : str
        The CMake option that switches the platform: AUTO (when ``<triple>-gcc`` is on PATH),
        ON (required) or OFF.
    flags : tuple of str
        Compiler flags of the platform beyond the project's (CMakeLists.txt: -O2,
        -ffp-contract=off, warnings), for its FMU binaries.
    toolchain_packages : tuple of str
        Debian packages of the cross compiler.
    runner : str or None
        The program that runs the platform's binaries on an x86-64 Linux machine (the tests
        use it): ``wine64``, ``wine``, ``qemu-aarch64``; None: they run natively.
    runner_packages : tuple of str
        Debian packages of the runner (``wine32:i386`` needs ``dpkg --add-architecture i386``).
    oldest : str
        The oldest systems the binaries load on, and why.
    """

    key: str
    fmi2: str | None
    system: str
    triple: str | None
    option: str
    flags: tuple = ()
    toolchain_packages: tuple = ()
    runner: str | None = None
    runner_packages: tuple = ()
    oldest: str = ""

    @property
    def fmi3(self):
        """The FMI 3.0 ``binaries/`` folder: the platform tuple."""
        return self.key

    @property
    def suffix(self):
        """The binaries' file suffix."""
        return ".dll" if self.system == "Windows" else ".so"

    @property
    def cross(self):
        """True when a cross compiler builds it."""
        return self.triple is not None

    def folder(self, fmi_version):
        """The ``binaries/`` folder in FMI version 2 or 3 (None: not in that version)."""
        return self.fmi2 if int(fmi_version) == 2 else self.fmi3


_GLIBC = ".".join(map(str, GLIBC_BASELINE))

PLATFORMS = (
    Platform(
        key="x86_64-linux", fmi2="linux64", system="Linux", triple=None, option="",
        oldest=(f"x86-64 Linux with glibc >= {_GLIBC}: RHEL/CentOS 7, Ubuntu 14.04, Debian 8 "
                f"and every later one")),
    Platform(
        key="x86_64-windows", fmi2="win64", system="Windows", triple="x86_64-w64-mingw32",
        option="PIEZO_WIN64", toolchain_packages=("gcc-mingw-w64-x86-64",),
        runner="wine64", runner_packages=("wine64",),
        oldest="64-bit Windows XP/Vista and later: only KERNEL32 and msvcrt are imported"),
    Platform(
        # x87 arithmetic keeps 80-bit intermediates: SSE2 gives the doubles of the other
        # platforms. The Windows x86 ABI promises a 4-byte aligned stack only; the SSE code
        # must not assume 16.
        key="x86-windows", fmi2="win32", system="Windows", triple="i686-w64-mingw32",
        option="PIEZO_WIN32", flags=("-msse2", "-mfpmath=sse", "-mincoming-stack-boundary=2"),
        toolchain_packages=("gcc-mingw-w64-i686",),
        runner="wine", runner_packages=("wine32:i386",),
        oldest=("32-bit Windows XP and later on a CPU with SSE2 (Pentium 4, Athlon 64 and "
                "later): only KERNEL32 and msvcrt are imported")),
    Platform(
        key="aarch64-linux", fmi2=None, system="Linux", triple="aarch64-linux-gnu",
        option="PIEZO_AARCH64", toolchain_packages=("gcc-aarch64-linux-gnu", "libc6-dev-arm64-cross"),
        runner="qemu-aarch64", runner_packages=("qemu-user",),
        oldest=(f"64-bit ARM Linux with glibc >= {_GLIBC} (the first glibc for aarch64): "
                f"RHEL/CentOS 7 for ARM, Ubuntu 14.04, Debian 8 and every later one")),
)

#: the platform the build machine is (its host compiler makes these binaries)
HOST = PLATFORMS[0]
#: the platforms a cross compiler makes
CROSS = tuple(p for p in PLATFORMS if p.cross)
#: the folder of the 64-bit Windows binary in each FMI version's binaries/
WINDOWS_PLATFORM = {v: next(p for p in CROSS if p.key == "x86_64-windows").folder(v) for v in (2, 3)}


def by_key(key):
    """The platform of a key (``x86-windows``) or of an FMI 2.0 folder (``win32``)."""
    for p in PLATFORMS:
        if key in (p.key, p.fmi2):
            return p
    raise KeyError(f"unknown platform {key!r}: one of {', '.join(p.key for p in PLATFORMS)}")


def folder(key, fmi_version):
    """The ``binaries/`` folder of a platform in FMI version 2 or 3."""
    return by_key(key).folder(fmi_version)


def _cmake_rows():
    """One line per cross platform for CMakeLists.txt: key|fmi2 folder|system|triple|option|
    flags (space-separated)|packages (space-separated)."""
    for p in CROSS:
        yield "|".join([p.key, p.fmi2 or "", p.system, p.triple, p.option, " ".join(p.flags),
                        " ".join(p.toolchain_packages)])


def main(argv=None):
    """``cmake``: the cross platforms for CMakeLists.txt; ``packages``: every Debian package
    of the toolchains and runners (for .ci/run); ``baseline``: the glibc baseline."""
    argv = sys.argv[1:] if argv is None else argv
    what = argv[0] if argv else ""
    if what == "cmake":
        print("\n".join(_cmake_rows()))
    elif what == "packages":
        print(" ".join(pkg for p in CROSS for pkg in (*p.toolchain_packages, *p.runner_packages)))
    elif what == "baseline":
        print(_GLIBC)
    else:
        print("usage: python -m harness.platforms cmake|packages|baseline", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
