"""Every repository file the documents name exists: a file renamed or removed fails here
until the README, docs/ and the benchmark record say where it went."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: A path into the repository's folders with a file extension (``solver/diagnose/judged_fit.py``,
#: ``docs/diagnose/RESULTS.md``); names with a placeholder (``<trial>``, ``*``) are not paths.
PATH = re.compile(r"(?<![\w/.<-])((?:solver|addb_viewer|annotations|tests|scripts|docs|examples)/[\w./-]*\.(?:py|md|json|sh|toml|png|txt))\b")


def documents() -> list[Path]:
    """The README, every page of docs/, the benchmark record and the packages' READMEs."""
    found = [REPO / "README.md", REPO / "tests" / "benchmarks" / "RESULTS.md", *sorted((REPO / "docs").rglob("*.md"))]
    for package in ("solver", "addb_viewer", "annotations"):
        found += sorted((REPO / package).rglob("README.md"))
    return found


def named_paths(text: str) -> set[str]:
    """The repository paths with an extension that ``text`` names."""
    return {m.group(1) for m in PATH.finditer(text)}


def test_every_file_the_documents_name_exists() -> None:
    missing = {}
    for doc in documents():
        absent = sorted(p for p in named_paths(doc.read_text()) if not (REPO / p).exists())
        if absent:
            missing[str(doc.relative_to(REPO))] = absent
    assert not missing, f"files named in the documents that are not in the repository: {missing}"


def test_the_documents_name_files_and_a_wrong_name_is_caught() -> None:
    """The check above reads what it should: the README names the pipeline's module and the
    diagnosis' judged-fit page, and a misspelt name is found missing."""
    readme = named_paths((REPO / "README.md").read_text())
    assert {"solver/pipeline.py", "docs/diagnose/JUDGED_FIT.md", "scripts/regenerate_figures.py"} <= readme
    assert named_paths("see solver/pipelines.py and `OUT/<trial>/trial.npz`") == {"solver/pipelines.py"}
    assert not (REPO / "solver/pipelines.py").exists()
