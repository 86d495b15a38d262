"""The repository stands on its own: no tracked file points to a document outside it, the
licence is stated the same way everywhere, every relative link of the documentation
resolves inside the repository, and the README starts with what a newcomer needs.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tomllib
from xml.etree import ElementTree as ET
from conftest import REPO

LICENSE_ID = "BSD-3-Clause"
#: what no tracked file may name: the folder and the file of the design notes that do not
#: ship with the repository (spelled in two pieces, so that this file does not find itself)
FORBIDDEN = ("shared" + "/", "DES" + "IGN")


def _tracked():
    git = shutil.which("git")
    assert git and (REPO / ".git").exists(), "the repository checks need git and a checkout"
    out = subprocess.run([git, "-C", str(REPO), "ls-files"], capture_output=True, text=True,
                         check=True).stdout
    return [REPO / line for line in out.splitlines()]


def test_no_tracked_file_refers_to_the_design_notes_outside_the_repository():
    """Reference: git grep, as the issue states it; .ci/ may name the pattern it checks."""
    done = subprocess.run(["git", "-C", str(REPO), "grep", "-n", "-E", "|".join(FORBIDDEN), "--",
                           ".", ":!.ci"], capture_output=True, text=True)
    assert done.returncode == 1 and done.stdout == "", done.stdout


def test_the_licence_is_bsd_3_clause_everywhere():
    text = (REPO / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License") and "Neither the name of the copyright holder" in text
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert project["license"] == LICENSE_ID and project["license-files"] == ["LICENSE"]
    for md in sorted((REPO / "modelDescription").glob("*.xml")):
        assert ET.parse(md).getroot().get("license").startswith(LICENSE_ID), md.name
    for doc in (REPO / "README.md", REPO / "docs" / "index.md", REPO / "docs" / "fmus.md"):
        assert LICENSE_ID in doc.read_text(), doc.name


_LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_documentation_links_resolve_inside_the_repository():
    pages = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
    assert {p.name for p in pages} >= {"README.md", "index.md", "model.md", "fmus.md"}
    anchors = {}
    for page in pages:
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)       # code, not links
        text = re.sub(r"^    .*$|`[^`]*`", "", text, flags=re.M)
        for target in _LINK.findall(text):
            if re.match(r"[a-z]+:", target):                       # https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            path = (page.parent / file).resolve() if file else page
            assert REPO in path.parents or path == REPO, f"{page.name}: {target} leaves the repository"
            assert path.exists(), f"{page.name}: broken link {target}"
            if anchor and path.suffix == ".md":
                if path not in anchors:
                    anchors[path] = {_slug(h) for h in re.findall(r"^#+ (.+)$", path.read_text(), re.M)}
                assert anchor in anchors[path], f"{page.name}: no section #{anchor} in {path.name}"


def _slug(heading):
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def test_readme_starts_with_prerequisites_and_the_two_commands():
    lines = (REPO / "README.md").read_text().splitlines()
    assert lines[0].startswith("Prerequisites: Python >= 3.11")
    head = "\n".join(lines[:3])
    assert "C compiler" in head and "CMake" in head
    block = lines[lines.index("```sh") + 1: lines.index("```")]
    assert block == ["pip install . && python -m harness",
                     "pip install '.[test]' && python -m pytest -q"]
    assert "## For someone receiving the FMUs" in lines


#: the longest C file of fmu_src/ (issue 45: each file one job; the sample's code apart from
#: its setup, checks and messages)
C_FILE_MAX_LINES = 1200


def test_no_c_file_of_the_fmus_is_over_1200_lines():
    """Reference: the line count of every tracked .c file under fmu_src/ (wc -l)."""
    sizes = {p.relative_to(REPO).as_posix(): len(p.read_text().splitlines())
             for p in _tracked() if p.suffix == ".c" and p.parts[len(REPO.parts)] == "fmu_src"}
    assert "fmu_src/core/piezo_controller.c" in sizes and len(sizes) >= 20, sorted(sizes)
    over = {name: n for name, n in sizes.items() if n > C_FILE_MAX_LINES}
    assert not over, over
