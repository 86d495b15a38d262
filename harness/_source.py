"""Which source a build or a run comes from: the git commit and whether the tracked files
differed from it ("uncommitted changes").

The build records it once (``packaging/assemble_fmu.py source``, run by CMake at every
build) in ``source.json``: the FMUs carry it in their ``generationTool`` and ``pip install .``
installs the file as ``harness/_data/source.json``, so that an installed package, which has
no git checkout, still names the commit it was built from. A run from a checkout asks git
directly (:func:`git_source`); an installed copy reads the record (:func:`installed_source`).

Standard library only: the build runs it before anything else is importable.
"""

from __future__ import annotations

import json
from pathlib import Path
import subprocess

__all__ = ["git_source", "read_source", "installed_source", "describe", "write_source", "SOURCE_FILE"]

#: the record's name, in the build folder and in the installed package's ``_data/``
SOURCE_FILE = "source.json"


def _git(repo, *args):
    try:
        proc = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True,
                              timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return proc.stdout.strip() if proc.returncode == 0 else None


def git_source(repo):
    """The commit of the git checkout at `repo` and whether its tracked files differ from it.

    Returns
    -------
    dict
        ``{"commit": "<40 hex digits>" or None, "dirty": bool}``; ``commit`` is None outside
        a git checkout (or without git), and ``dirty`` is then False.
    """
    head = _git(repo, "rev-parse", "--verify", "HEAD")
    if not head:
        return {"commit": None, "dirty": False}
    status = _git(repo, "status", "--porcelain", "--untracked-files=no")
    return {"commit": head, "dirty": bool(status)}


def read_source(path):
    """The record written by the build at `path`, or None if there is none (or unreadable)."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or "commit" not in data:
        return None
    return {"commit": data["commit"] or None, "dirty": bool(data.get("dirty", False))}


def installed_source():
    """The record of an installed package (``harness/_data/source.json``), or None."""
    return read_source(Path(__file__).resolve().parent / "_data" / SOURCE_FILE)


def describe(source):
    """One line: ``<commit>``, ``<commit> with uncommitted changes``, or ``unknown``."""
    if not source or not source.get("commit"):
        return "unknown"
    return source["commit"] + (" with uncommitted changes" if source.get("dirty") else "")


def write_source(repo, out):
    """Write the record of `repo` to `out` (JSON), only when it changed; return the record."""
    record = git_source(repo)
    text = json.dumps(record, sort_keys=True) + "\n"
    out = Path(out)
    if not out.is_file() or out.read_text(encoding="utf-8") != text:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    return record
