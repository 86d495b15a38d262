"""Where the harness looks for its built artefacts (harness/paths.py, the rules of its
module docstring): the environment variable, the package's own ``_data/``, the checkout's
build, then an installed distribution's ``_data/``; none there: the checkout's path, so
that the error names where the file was expected.

Reference: the docstring's order, checked on folders made here. And the cost: the installed
distributions are looked up (``importlib.metadata.packages_distributions``, which reads every
installed distribution's metadata, about 0.2 s) only when the earlier candidates are missing
and once per process; a sweep's workers ask for the runner's path at every chunk, and a
lookup per call once halved a 3 s sweep's rate (55 % of the compute bound instead of 93 %).
"""

from __future__ import annotations

import pytest

from harness import paths


@pytest.fixture
def tree(tmp_path, monkeypatch):
    """A checkout (``repo/``) whose package is ``repo/harness``, and an installed copy's
    ``_data`` elsewhere; the lookup of installed distributions counted."""
    repo, installed = tmp_path / "repo", tmp_path / "site" / "harness" / "_data"
    (repo / "harness").mkdir(parents=True)
    installed.mkdir(parents=True)
    calls = []

    def lookup():
        calls.append(1)
        return installed

    monkeypatch.delenv("PIEZO_FMU_DIR", raising=False)
    monkeypatch.setattr(paths, "REPO_ROOT", repo)
    monkeypatch.setattr(paths, "PACKAGE_DIR", repo / "harness")
    monkeypatch.setattr(paths, "IN_CHECKOUT", True)
    monkeypatch.setattr(paths, "_installed_data_dir", lookup)
    return repo, installed, calls


def test_the_order_is_env_package_checkout_installed(tree, monkeypatch, tmp_path):
    repo, installed, calls = tree
    assert paths.fmu_dir() == repo / "build" / "fmus"                   # nothing anywhere
    (installed / "fmus").mkdir()
    assert paths.fmu_dir() == installed / "fmus"
    (repo / "build" / "fmus").mkdir(parents=True)
    n = len(calls)
    assert paths.fmu_dir() == repo / "build" / "fmus"
    assert len(calls) == n, "the checkout's build exists: no lookup of installed distributions"
    (repo / "harness" / "_data" / "fmus").mkdir(parents=True)
    assert paths.fmu_dir() == repo / "harness" / "_data" / "fmus"
    assert len(calls) == n
    monkeypatch.setenv("PIEZO_FMU_DIR", str(tmp_path / "mine"))
    assert paths.fmu_dir() == tmp_path / "mine"


def test_outside_a_checkout_only_the_package_is_looked_at(tree, monkeypatch):
    repo, installed, calls = tree
    monkeypatch.setattr(paths, "IN_CHECKOUT", False)
    (installed / "fmus").mkdir()
    (repo / "build" / "fmus").mkdir(parents=True)
    assert paths.fmu_dir() == repo / "harness" / "_data" / "fmus"
    assert calls == []


def test_the_installed_lookup_is_made_once_per_process():
    paths._installed_data_dir.cache_clear()
    first = paths._installed_data_dir()
    for _ in range(5):
        assert paths._installed_data_dir() == first
    info = paths._installed_data_dir.cache_info()
    assert (info.misses, info.hits) == (1, 5)
