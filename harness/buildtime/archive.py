"""FMU archives written reproducibly: one home for the zip layout of every FMU we write.

The build (``packaging/assemble_fmu.py``) and ``python -m harness export`` both write
FMUs through :func:`write_fmu_zip`: entries in sorted order, a folder entry for every
folder, every time stamp the same date, Unix permissions 0755 for folders and shared
libraries and 0644 for every other file, deflate at level 9. The same entries and date
give the same bytes.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath
import zipfile

__all__ = ["BINARY_SUFFIXES", "FOLDER_MODE", "FILE_MODE", "BINARY_MODE", "write_fmu_zip"]

#: Files that are shared libraries (made executable in the archive).
BINARY_SUFFIXES = {".so", ".dll", ".dylib"}
FOLDER_MODE, FILE_MODE, BINARY_MODE = 0o40755, 0o100644, 0o100755


def _with_folders(names):
    """Every file name and every folder above it (``a/b/`` for ``a/b/c``)."""
    out = set()
    for name in names:
        parts = PurePosixPath(name).parts
        out.add(name)
        for i in range(1, len(parts)):
            out.add("/".join(parts[:i]) + "/")
    return sorted(out)


def write_fmu_zip(files, out, date_time):
    """Write ``files`` (archive name -> bytes) as an FMU archive at ``out``.

    Parameters
    ----------
    files : dict
        POSIX path inside the archive -> content (bytes).
    out : str or Path
        The archive; written through a temporary file beside it and renamed.
    date_time : tuple
        ``(year, month, day, hour, minute, second)`` of every entry (1980 or later).

    Returns
    -------
    list of str
        The entry names, folders included, in archive order.
    """
    out = Path(out)
    names = _with_folders(files)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    try:
        with zipfile.ZipFile(tmp, "w") as zf:
            for name in names:
                info = zipfile.ZipInfo(name, date_time=tuple(date_time))
                info.create_system = 3                       # Unix permissions below
                if name.endswith("/"):
                    info.external_attr = (FOLDER_MODE << 16) | 0x10
                    zf.writestr(info, b"")
                    continue
                binary = PurePosixPath(name).suffix in BINARY_SUFFIXES
                info.external_attr = (BINARY_MODE if binary else FILE_MODE) << 16
                info.compress_type = zipfile.ZIP_DEFLATED
                zf.writestr(info, files[name], compresslevel=9)
        tmp.replace(out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return names
