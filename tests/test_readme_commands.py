"""The README's command-line table tells the command line as it is: every ``addb`` subcommand
has a row, and every option of its parser is written in the usage cell of one of its rows
(long or short form), so an option added to a parser without its line in the README fails
the suite; so does a choice of an option the table lists otherwise."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from addb_viewer.cli import build_parser

REPO = Path(__file__).resolve().parents[1]


def usage_cells(readme: str) -> dict[str, str]:
    """Subcommand -> the usage cells of its rows in the table under ``## Command line``,
    joined (a cell is split from the next at a ``|`` that is not escaped as ``\\|``)."""
    table = readme.split("\n## Command line", 1)[1].split("\n## ", 1)[0]
    out: dict[str, str] = {}
    for line in table.splitlines():
        cells = re.split(r"(?<!\\)\|", line)
        if len(cells) < 3:
            continue
        found = re.match(r"\s*`addb (\w+)", cells[1])
        if found:
            out[found.group(1)] = " ".join(f"{out.get(found.group(1), '')} {cells[1]}".split())
    return out


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def _named(option: str, usage: str) -> bool:
    return re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", usage) is not None


def test_the_usage_reader_splits_at_unescaped_bars_only() -> None:
    readme = "x\n## Command line\n\n| command | what |\n| --- | --- |\n| `addb x A\\|B [--y N]` | does x |\n| `addb x --z` | more |\n\n## Next\n"
    assert usage_cells(readme) == {"x": "`addb x A\\|B [--y N]` `addb x --z`"}


def test_every_subcommand_and_option_is_in_the_readme_table() -> None:
    usage = usage_cells((REPO / "README.md").read_text())
    missing = []
    for name, sub in _subcommands().items():
        if name not in usage:
            missing.append(name)
            continue
        for action in sub._actions:
            options = action.option_strings
            if options and "-h" not in options and not any(_named(s, usage[name]) for s in options):
                missing.append(f"{name} {'/'.join(options)}")
    assert missing == []


def written_choices(option: str, usage: str) -> set[str]:
    """The values written after ``option`` in a usage cell (``--fit rounds\\|band`` gives
    {"rounds", "band"}), over every occurrence."""
    out: set[str] = set()
    for found in re.finditer(rf"(?<![\w-]){re.escape(option)}[ =]([\w.-]+(?:\\\|[\w.-]+)*)", usage):
        out |= set(found.group(1).split("\\|"))
    return out


def test_the_choice_reader_joins_the_rows() -> None:
    usage = "`addb x [--format mcap\\|rrd] -o F` `addb x --format b3d` [--fit N]"
    assert written_choices("--format", usage) == {"mcap", "rrd", "b3d"}
    assert written_choices("--fit", usage) == {"N"}


def test_every_choice_of_an_option_is_in_the_readme_table() -> None:
    """An option with fixed choices lists exactly its parser's choices in the table (over its
    rows), so a choice added, renamed or dropped in the parser fails the suite."""
    usage = usage_cells((REPO / "README.md").read_text())
    wrong = {}
    for name, sub in _subcommands().items():
        for action in sub._actions:
            if not action.choices or not action.option_strings:
                continue
            written = set().union(*(written_choices(s, usage.get(name, "")) for s in action.option_strings))
            if written != {str(c) for c in action.choices}:
                wrong[f"{name} {'/'.join(action.option_strings)}"] = (sorted(written), sorted(map(str, action.choices)))
    assert wrong == {}
