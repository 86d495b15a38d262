"""The harness's layers (docs/harness.md): each module imports only its own layer or those below,
the jobs reach the masters through the registry package only, and the package is grouped by
job (few top-level modules, no module name twice).

Reference: the layer diagram of docs/harness.md (:data:`LAYERS` below, top to bottom) and
harness/masters/__init__.py's promise (its docstring): the jobs and studies ask the registry
(``MASTERS``, ``closed_loop`` ...) and the names it exports, never a master's module. Read from
the source (ast), so a later import that breaks either fails here naming the file and line.
The layout's limits are issue 45's (:data:`MAX_TOP_LEVEL_MODULES`).
"""

from __future__ import annotations

import ast

import pytest

from conftest import REPO

HARNESS = REPO / "harness"
#: docs/harness.md's layers, top to bottom: each harness module or package by its first name
#: below ``harness``; a name not listed is ground (the lowest layer)
LAYERS = (
    ("cli", "__main__"),
    ("report", "identify", "sweep", "bench", "studies"),
    ("masters", "buildtime"),
    ("loop", "binding", "fmu"),
)
#: issue 45: at most this many modules directly in harness/ besides __init__.py and __main__.py
MAX_TOP_LEVEL_MODULES = 10


def _resolve(path, node, repo):
    """The absolute module an ImportFrom in ``path`` names (its relative level resolved)."""
    package = list(path.relative_to(repo).with_suffix("").parts[:-1])
    if node.level:
        package = package[:len(package) - (node.level - 1)]
        return ".".join(package + ([node.module] if node.module else []))
    return node.module or ""


def master_module_imports(root=HARNESS):
    """["file:line module"] of every import of a master's module from outside harness/masters."""
    submodules = {p.stem for p in (root / "masters").glob("*.py") if p.stem != "__init__"}
    found = []
    for path in sorted(root.rglob("*.py")):
        if (root / "masters") in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                module = _resolve(path, node, root.parent)
                names = [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                module, names = "", [a.name for a in node.names]
            else:
                continue
            targets = [f"{module}.{n}" for n in names] if module == "harness.masters" else [module, *names]
            for target in targets:
                parts = target.split(".")
                if parts[:2] == ["harness", "masters"] and len(parts) > 2 and parts[2] in submodules:
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno} {target}")
    return found


def _layer(module):
    """0 for the top layer, len(LAYERS) for ground; None for the package itself."""
    parts = module.split(".")
    if len(parts) < 2:
        return None
    for i, names in enumerate(LAYERS):
        if parts[1] in names:
            return i
    return len(LAYERS)


def upward_imports(root=HARNESS):
    """["file:line module -> target"] of every import of a higher layer (outside a package's own)."""
    found = []
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        me = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                module = _resolve(path, node, root.parent)
                targets = [module] + [f"{module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            for target in targets:
                mine, theirs = _layer(me), _layer(target)
                if (target.startswith("harness.") and mine is not None and theirs is not None
                        and theirs < mine and target.split(".")[1] != me.split(".")[1]):
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno} {me} -> {target}")
    return sorted(set(found))


def test_no_module_imports_a_layer_above_its_own():
    """Every harness module imports only modules of its own layer or below (docs/harness.md)."""
    assert upward_imports() == []


def test_the_layer_check_sees_an_upward_import(tmp_path):
    """Reference: a scratch harness whose ground module imports a study and a master."""
    (tmp_path / "harness" / "studies").mkdir(parents=True)
    (tmp_path / "harness" / "studies" / "timing_table.py").write_text("from ..progress import X\n")
    (tmp_path / "harness" / "progress.py").write_text(
        "from .studies import timing_table\nfrom .masters import MASTERS\nX = 1\n")
    assert upward_imports(tmp_path / "harness") == [
        "harness/progress.py:1 harness.progress -> harness.studies",
        "harness/progress.py:1 harness.progress -> harness.studies.timing_table",
        "harness/progress.py:2 harness.progress -> harness.masters",
        "harness/progress.py:2 harness.progress -> harness.masters.MASTERS"]


def layout_problems(root=HARNESS):
    """["..."] of what breaks the package's grouping: more than :data:`MAX_TOP_LEVEL_MODULES`
    modules directly in ``root``, and each module name (a file's or a package's, ``__init__``
    and ``__main__`` aside) used more than once below it, with its places."""
    top = sorted(p.stem for p in root.glob("*.py") if p.stem not in ("__init__", "__main__"))
    found = []
    if len(top) > MAX_TOP_LEVEL_MODULES:
        found.append(f"{len(top)} top-level modules (at most {MAX_TOP_LEVEL_MODULES}): "
                     + ", ".join(top))
    places = {}
    for path in sorted(root.rglob("*.py")):
        if path.stem == "__init__" and path.parent != root:
            package = path.parent
            places.setdefault(package.name, []).append(f"{package.relative_to(root.parent)}/")
        elif path.stem not in ("__init__", "__main__"):
            places.setdefault(path.stem, []).append(str(path.relative_to(root.parent)))
    found += [f"{name}: {', '.join(where)}" for name, where in sorted(places.items())
              if len(where) > 1]
    return found


def test_the_package_is_grouped_by_job():
    """At most ten top-level modules in harness/, and no module name twice (issue 45)."""
    assert layout_problems() == []


def test_the_layout_check_sees_too_many_modules_and_a_name_twice(tmp_path):
    """Reference: a scratch harness with eleven top-level modules, a file name in two packages
    and a file named as a package; renamed, it passes."""
    root = tmp_path / "harness"
    for package in ("report", "sweep", "bench"):
        (root / package).mkdir(parents=True)
        (root / package / "__init__.py").write_text("")
    for name in ("__init__", "__main__", *(f"m{i:02d}" for i in range(11))):
        (root / f"{name}.py").write_text("")
    for path in ("report/run.py", "sweep/run.py", "bench/report.py", "bench/measure.py"):
        (root / path).write_text("")
    assert layout_problems(root) == [
        "11 top-level modules (at most 10): " + ", ".join(f"m{i:02d}" for i in range(11)),
        "report: harness/bench/report.py, harness/report/",
        "run: harness/report/run.py, harness/sweep/run.py"]
    (root / "m10.py").unlink()
    (root / "bench" / "report.py").rename(root / "bench" / "text_report.py")
    (root / "sweep" / "run.py").rename(root / "sweep" / "dispatch.py")
    assert layout_problems(root) == []


def test_no_job_imports_a_masters_module():
    """Every harness module outside harness/masters imports the masters' names from the package."""
    assert master_module_imports() == []


def test_the_check_sees_a_relative_and_an_absolute_import(tmp_path):
    """Reference: a scratch harness with both forms of a forbidden import (the check can fail)."""
    (tmp_path / "harness" / "masters").mkdir(parents=True)
    (tmp_path / "harness" / "masters" / "native.py").write_text("X = 1\n")
    (tmp_path / "harness" / "report").mkdir()
    (tmp_path / "harness" / "report" / "job.py").write_text(
        "from ..masters.native import X\nfrom ..masters import native\nfrom ..masters import X\n")
    (tmp_path / "harness" / "study.py").write_text("import harness.masters.native\n")
    found = master_module_imports(tmp_path / "harness")
    assert found == ["harness/report/job.py:1 harness.masters.native",
                     "harness/report/job.py:2 harness.masters.native",
                     "harness/study.py:1 harness.masters.native"]


def test_every_master_is_registered_and_every_exported_name_exists():
    """Reference: the modules of harness/masters: each master module but the shared instance
    layer is a registered master's, the wired master among them, and ``__all__`` names only
    what the package has."""
    from harness import masters
    for name in masters.__all__:
        assert hasattr(masters, name), name
    assert masters.get("wired").fmus == ("PiezoStage", "AdaptiveCompoundController", "ReferenceSignal")
    run = masters.closed_loop("wired", fmi_version=3)
    assert run.func is masters.simulate_wired and run.keywords == {"fmi_version": 3}
    modules = {p.stem for p in (HARNESS / "masters").glob("*.py")} - {"__init__", "instance"}
    module_of = {"auto": None, "fmpy": "fmpy", "native": "native", "core": "c_core",
                 "closed-loop-fmu": "closed_loop_fmu", "ssp-player": "ssp", "container": "container",
                 "wired": "wired"}
    assert set(masters.MASTERS) == set(module_of)
    assert {m for m in module_of.values() if m} == modules


@pytest.mark.parametrize("backend", ["wired"])
def test_a_master_beside_the_backends_is_not_a_command_line_choice(backend):
    """Reference: the registry's ``backend`` flag: the wired master is called by its function."""
    from harness import masters
    assert backend in masters.MASTERS and backend not in masters.BACKENDS


def signal_kind_branches(root=HARNESS):
    """["file:line"] of every comparison of a signal's kind with a string outside the scenarios."""
    found = []
    for path in sorted(root.rglob("*.py")):
        if (root / "scenarios") in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Compare):
                continue
            for side in (node.left, *node.comparators):
                if (isinstance(side, ast.Attribute) and side.attr == "kind"
                        and isinstance(side.value, (ast.Name, ast.Attribute))
                        and (getattr(side.value, "id", None) or getattr(side.value, "attr", "")) in
                        ("signal", "sig")):
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno}")
    return found


def test_no_job_or_master_branches_on_the_kind_of_a_signal():
    """Reference: harness.scenarios.SIGNAL_KINDS, where each kind says what it is (its
    ``internal`` among them): outside the scenarios nothing compares ``signal.kind``."""
    assert signal_kind_branches() == []


def test_the_signal_kind_check_sees_a_branch(tmp_path):
    """Reference: a scratch module that branches on ``sc.signal.kind`` and on ``sig.kind``."""
    (tmp_path / "harness").mkdir()
    (tmp_path / "harness" / "job.py").write_text(
        'def f(sc, sig):\n    if sc.signal.kind == "sines":\n        return 1\n'
        '    return sig.kind != "table"\n')
    assert signal_kind_branches(tmp_path / "harness") == ["harness/job.py:2", "harness/job.py:4"]
