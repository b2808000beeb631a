"""The README's results table quotes its blocks: every number of its "ours" column is printed
in the blocks its last column names, so a block made again with other numbers fails here
until the README says what the block now says."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.scripts import load_script

REPO = Path(__file__).resolve().parents[1]
#: A number as the blocks print it: 12.1x, 0.003 BW, 1.24 cm, 4724 (no sign: "4-7" is a range).
NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?![\w.]*\d)")


@pytest.fixture(scope="module")
def figures():
    return load_script("scripts/regenerate_figures.py")


def results_rows() -> list[tuple[str, str, list[str]]]:
    """``(measure, ours, block names)`` of each row of the README's "## Results" table."""
    text = (REPO / "README.md").read_text()
    section = text[text.index("## Results\n") : text.index("\n## ", text.index("## Results\n") + 1)]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip()[1:-1])]
        if not line.startswith("| ") or len(cells) != 4 or cells[0] in ("measure", "---"):
            continue
        rows.append((cells[0], cells[1], re.findall(r"`([\w.-]+)`", cells[3])))
    return rows


def block_text(figures, name: str) -> str:
    """What block ``name`` prints: its block in its document, or the documents its command
    writes itself (a figure with ``writes``)."""
    fig = next((f for f in figures.FIGURES if f.name == name), None)
    assert fig is not None, f"the README's results cite block {name!r}, which the registry does not have"
    if fig.writes:
        return "\n".join((REPO / w).read_text() for w in fig.writes if w.endswith(".md"))
    block = figures._block(fig)[1]
    assert block is not None, f"block {name!r} is not in {fig.doc}"
    return block


def numbers(text: str) -> set[str]:
    """The numbers of ``text``, without the backticked names and paths (block names, files)
    and the references to the notes under the table ("note 2")."""
    return set(NUMBER.findall(re.sub(r"`[^`\n]*`|\bnote \d+", " ", text)))


def test_the_results_table_has_its_rows_and_every_row_cites_a_block() -> None:
    rows = results_rows()
    assert len(rows) >= 15
    assert all(blocks for _, _, blocks in rows), [m for m, _, b in rows if not b]


def test_every_number_of_the_ours_column_is_printed_by_its_blocks(figures) -> None:
    missing = {}
    for measure, ours, blocks in results_rows():
        printed = set().union(*(numbers(block_text(figures, b)) for b in blocks))
        absent = sorted(numbers(ours) - printed)
        if absent:
            missing[f"{measure} ({', '.join(blocks)})"] = absent
    assert not missing, f"numbers in the README's results that their blocks do not print: {missing}"


def test_a_number_the_blocks_do_not_print_is_caught(figures) -> None:
    """The check above can fail: the walk's speed-up against OpenSim's IK tool changed in its
    last digit to a number block ``kinematics`` does not print is caught."""
    _, ours, _ = next(r for r in results_rows() if r[2] == ["kinematics"] and "faster than OpenSim's IK tool" in r[1])
    speedup = re.search(r"(\d+\.\d)x faster", ours).group(1)
    printed = numbers(block_text(figures, "kinematics"))
    assert speedup in printed
    other = next(f"{float(speedup) + d:.1f}" for d in (0.1, 0.2, 0.3, -0.1, -0.2) if f"{float(speedup) + d:.1f}" not in printed)
    assert numbers(ours.replace(f"{speedup}x", f"{other}x")) - printed == {other}
