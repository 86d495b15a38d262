"""docs/cosimulation.md, section 4: its table of what the FMUs detect under each master is the
output of python -m harness timing, not typed.

Reference: the script itself (harness.studies.timing_table.run_master), rerun here for the masters
that are quick to run (ours and fmpy's SSP player, 48 runs) and for one sequential order of
the container: every cell of their rows must equal the documented one as printed (two
decimals of nm, the stamps and the choice time exactly). tests/test_masters.py checks the
other orders' delays and stamps against the schedules."""

import pytest

from harness.studies import timing_table
from harness.scenarios import MISMATCH_SCENARIOS
from conftest import REPO

DOC = REPO / "docs" / "cosimulation.md"


def documented_rows():
    """{(master, tf.delay): cells} of the table in docs/cosimulation.md, section 4."""
    text = DOC.read_text()
    section = text[text.index("## 4. What the FMUs detect under each master"):text.index("## 5.")]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| ") and cells[0] in timing_table.MASTERS:
            rows[(cells[0], int(cells[1]))] = cells
    return rows


def test_every_master_has_its_two_rows():
    rows = documented_rows()
    assert set(rows) == {(m, t) for m in timing_table.MASTERS for t in (0, 1)}


QUICK = ["harness Gauss-Seidel, plant first", "harness Jacobi", "fmpy SSP player",
         "container, sequential: plant, controller, reference"]


@pytest.mark.parametrize("tf_delay", [0, 1])
@pytest.mark.parametrize("master", QUICK)
def test_documented_rows_are_the_scripts_output(master, tf_delay):
    runs = [timing_table.run_master(master, name, tf_delay) for name in MISMATCH_SCENARIOS]
    table = timing_table.markdown_table(runs).splitlines()
    assert len(table) == 3
    cells = [c.strip() for c in table[2].strip().strip("|").split("|")]
    assert cells == documented_rows()[(master, tf_delay)]
