"""The diagnosis' documents name every registered cause where a reader looks for it: a row of
the table of causes in docs/diagnose/README.md, the row of ``addb diagnose`` in the README's
command table, and a module ``causes/<name>.py`` named in solver/diagnose/README.md's layout
(step 6 of "Adding a cause" there; a cause added without them fails here)."""

from __future__ import annotations

import re
from pathlib import Path

from solver.diagnose.causes.registry import NAMES

REPO = Path(__file__).resolve().parents[2]


def test_every_cause_has_a_row_in_the_method_table() -> None:
    rows = re.findall(r"^\| `(\w+)` \|", (REPO / "docs" / "diagnose" / "README.md").read_text(), flags=re.MULTILINE)
    assert sorted(rows) == sorted(NAMES)


def test_every_cause_is_named_in_the_command_row_and_the_code_map() -> None:
    readme = (REPO / "README.md").read_text()
    command_row = next(line for line in readme.splitlines() if line.startswith("| `addb diagnose "))
    code_map = (REPO / "solver" / "diagnose" / "README.md").read_text()
    assert [n for n in NAMES if f"`{n}`" not in command_row] == []
    assert [n for n in NAMES if f"`{n}.py`" not in code_map] == []
    assert all((REPO / "solver" / "diagnose" / "causes" / f"{n}.py").is_file() for n in NAMES)
