"""Where ``addb process DATASET_DIR --out OUT`` may write, and what it says about what it
found, on a dataset of symbolic links to the shared subjects (``labA/walk``, ``labA/run``,
``labB/walk``; a subject that OUT would lie in is a writable copy instead).

* OUT inside the dataset folder holding subject folders of it (``--out DATASET/labA``) is
  refused, naming them: the search leaves OUT out, and the run skipped them silently. OUT
  inside a subject folder is refused too (its outputs would become the subject's inputs).
* OUT that is the output folder of one subject (``addb process SUBJECT_DIR --out OUT``) is
  refused: the dataset tree and its summary were written among that subject's files.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.discover import scan_dataset, subjects_below
from tests.conftest import writable_copy
from tests.dataset.dataset_tree import SUBJECTS

LINKED = {"labA/walk": "rajagopal2016_walk", "labA/run": "rajagopal2016_run", "labB/walk": "rajagopal2016_walk"}


def _files(folder: Path) -> list[str]:
    """Every entry below ``folder``, symbolic links not followed (what a refused run must leave)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture
def dataset(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    root = tmp_path / "ds"
    for rel, name in LINKED.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).symlink_to(SUBJECTS / name, target_is_directory=True)
    return root


def test_an_output_tree_holding_subjects_of_the_dataset_is_refused_naming_them(dataset: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = _files(dataset)
    out = dataset / "labA"
    assert cli(["process", str(dataset), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert f"DatasetError ({out.resolve()}): the output tree lies inside the dataset folder" in err, err
    assert "holds 2 of its subject folder(s) (labA/run, labA/walk)" in err and "Traceback" not in err
    assert _files(dataset) == before  # nothing written, no subject processed
    # the search met labA and left it out; the subjects it holds are named from the dataset
    scan = scan_dataset(dataset, exclude=(out,))
    assert [s.rel for s in scan.subjects] == ["labB/walk"] and scan.excluded == (out,)
    assert [s.rel for s in subjects_below(dataset, out)] == ["labA/run", "labA/walk"]


def test_an_output_tree_in_or_at_a_subject_folder_is_refused(dataset: Path, capsys: pytest.CaptureFixture[str]) -> None:
    copy = writable_copy(SUBJECTS / "rajagopal2016_walk", dataset / "labB" / "copy")
    before = _files(dataset)
    for out, said in ((copy, "holds 1 of its subject folder(s) (labB/copy)"),
                      (copy / "results", "lies inside the subject folder labB/copy of the dataset")):  # fmt: skip
        assert cli(["process", str(dataset), "--out", str(out), "--workers", "1"]) == 1
        err = capsys.readouterr().err
        assert f"DatasetError ({out.resolve()}): the output tree" in err and said in err, err
        assert _files(dataset) == before


def _states(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file below ``folder``: relative path -> (size, modification time in ns)."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*") if p.is_file()}


@pytest.mark.slow
def test_the_output_folder_of_one_subject_is_refused_as_an_output_tree(dataset: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    one = tmp_path / "walk_out"
    assert cli(["process", str(SUBJECTS / "rajagopal2016_walk"), "--out", str(one)]) == 0
    before = _states(one)
    capsys.readouterr()
    assert cli(["process", str(dataset), "--out", str(one), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert f"DatasetError ({one.resolve()}): is the output folder of one subject (it holds subject.json" in err, err
    assert "expected a new folder, an empty one, or an earlier dataset output tree" in err and "Traceback" not in err
    assert _states(one) == before  # no labA/, no dataset_summary.json
