"""Where a run's and a build's source is recorded (harness/_source.py, the report's commit):
the commit and whether the tracked files had uncommitted changes, asked of git in a checkout
and read from the build's record in an installed package. Reference: git itself, run on a
small repository made here (rev-parse HEAD; an edited tracked file is a change, a new
untracked one is not)."""

import json
import subprocess

import pytest

from harness import _source, paths
from harness.report import provenance


def _git(repo, *args):
    return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.fixture
def repo(tmp_path):
    r = tmp_path / "repo"
    r.mkdir()
    _git(r, "init", "-q")
    (r / "a.txt").write_text("one\n")
    _git(r, "add", "a.txt")
    _git(r, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "first")
    return r


def test_git_source_names_the_commit_and_uncommitted_changes(repo, tmp_path):
    head = _git(repo, "rev-parse", "HEAD")
    assert _source.git_source(repo) == {"commit": head, "dirty": False}
    (repo / "untracked.txt").write_text("new\n")             # not a change of the source
    assert _source.git_source(repo) == {"commit": head, "dirty": False}
    (repo / "a.txt").write_text("two\n")
    assert _source.git_source(repo) == {"commit": head, "dirty": True}
    assert _source.describe(_source.git_source(repo)) == f"{head} with uncommitted changes"
    assert _source.git_source(tmp_path / "not_a_repo") == {"commit": None, "dirty": False}


def test_the_record_is_rewritten_only_when_it_changes(repo, tmp_path):
    """The build's record: same source, same file (its time stamp too, so nothing that
    depends on it is rebuilt); a change of the tree, a new record."""
    out = tmp_path / "build" / "source.json"
    record = _source.write_source(repo, out)
    assert json.loads(out.read_text()) == record and _source.read_source(out) == record
    mtime = out.stat().st_mtime_ns
    _source.write_source(repo, out)
    assert out.stat().st_mtime_ns == mtime
    (repo / "a.txt").write_text("two\n")
    assert _source.write_source(repo, out)["dirty"] is True
    assert _source.read_source(out)["dirty"] is True
    assert _source.read_source(tmp_path / "absent.json") is None


@pytest.mark.parametrize("record,expected", [
    ({"commit": "ab" * 20, "dirty": False},
     f"{'ab' * 20} (recorded at build time, installed package)"),
    ({"commit": "ab" * 20, "dirty": True},
     f"{'ab' * 20} with uncommitted changes (recorded at build time, installed package)"),
    ({"commit": None, "dirty": False},
     "unknown (the installed package was not built from a git checkout)"),
    (None, "unknown (not a git checkout, and no build record)"),
])
def test_an_installed_package_reports_the_commit_it_was_built_from(monkeypatch, record, expected):
    """Outside a checkout (an installed package) the report's commit is the build's record."""
    monkeypatch.setattr(paths, "IN_CHECKOUT", False)
    monkeypatch.setattr(_source, "installed_source", lambda: record)
    assert provenance.commit_id() == expected


def test_a_checkout_reports_git_now():
    head = _git(paths.REPO_ROOT, "rev-parse", "HEAD")
    dirty = bool(_git(paths.REPO_ROOT, "status", "--porcelain", "--untracked-files=no"))
    assert provenance.commit_id() == head + (" with uncommitted changes" if dirty else "")
