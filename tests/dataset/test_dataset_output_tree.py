"""Where ``addb process DATASET_DIR --out OUT`` may write, and what it says about what it
found, on a dataset of symbolic links to the shared subjects (``labA/walk``, ``labA/run``,
``labB/walk``; a subject that OUT would lie in is a writable copy instead).

* OUT inside the dataset folder holding subject folders of it (``--out DATASET/labA``) is
  refused, naming them: the search leaves OUT out, and the run skipped them silently. OUT
  inside a subject folder is refused too (its outputs would become the subject's inputs).
* OUT that is the output folder of one subject (``addb process SUBJECT_DIR --out OUT``) is
  refused: the dataset tree and its summary were written among that subject's files.
* A .b3d file in a folder of its own is no subject folder: the run says it is not processed
  and how to make it one (``addb convert``), also when it finds no subject at all (it said
  only "no subject folder").
* The progress and the last line count the subjects processed, up to date and failed apart:
  a run with one subject up to date said "2/2 subjects, 907 frames processed" and "2 subjects".
  An earlier output tree inside the dataset folder is no refusal (it holds no subject folder).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.discover import scan_dataset, subjects_below
from solver.dataset.runner import process_dataset
from tests.conftest import SHARED_DATA, writable_copy
from tests.dataset.dataset_tree import BROKEN, SUBJECTS, build_tree

B3D = SHARED_DATA / "b3d" / "results.b3d"
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


def test_b3d_files_outside_subject_folders_are_named_with_what_is_expected(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    root = tmp_path / "published"
    (root / "labC" / "p1").mkdir(parents=True)
    (root / "labC" / "p1" / "results.b3d").symlink_to(B3D)
    assert cli(["process", str(root), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert f"DatasetError ({root.resolve()}): no subject folder (a folder holding _subject.json) below this folder; " in err
    assert "a .b3d file (labC/p1/results.b3d), which a dataset run does not process" in err, err
    assert "addb convert FILE.b3d --out SUBJECT_DIR" in err and not (tmp_path / "out").exists()
    # the advice holds: converted in its folder, the file's folder is a subject folder, and
    # a .b3d file inside a subject folder is an input of it, not named
    writable_copy(root / "labC", tmp_path / "copy" / "labC", symlinks=False)
    folder = tmp_path / "copy" / "labC" / "p1"
    assert cli(["convert", str(folder / "results.b3d"), "--out", str(folder)]) == 0
    scan = scan_dataset(tmp_path / "copy")
    assert [s.rel for s in scan.subjects] == ["labC/p1"] and scan.b3d_files == ()


def test_a_b3d_file_in_a_dataset_of_subject_folders_is_named_as_not_processed(dataset: Path, tmp_path: Path) -> None:
    (dataset / "labC" / "p1").mkdir(parents=True)
    (dataset / "labC" / "p1" / "results.b3d").symlink_to(B3D)
    out = tmp_path / "out"
    for rel in LINKED:  # each subject's output folder holds a file of someone else's: they fail alone, no cluster starts
        (out / rel).mkdir(parents=True)
        (out / rel / "notes.txt").write_text("keep")
    said: list[str] = []
    run = process_dataset(dataset, out, log=said.append)
    assert [s["rel"] for s in run.failed] == sorted(LINKED)
    [note] = [m for m in said if ".b3d" in m]
    assert note.startswith("the dataset folder holds a .b3d file (labC/p1/results.b3d), which a dataset run does not process")
    assert "addb convert FILE.b3d --out SUBJECT_DIR" in note


def test_an_output_tree_given_as_the_dataset_is_named_as_one(dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``addb process OUT`` of a dataset run's output tree said "no subject folder below this
    folder"; it now says what the folder is and names the dataset folder its summary records."""
    out = tmp_path / "out"
    for rel in LINKED:  # every subject fails alone (someone else's file in its folder): no cluster starts
        (out / rel).mkdir(parents=True)
        (out / rel / "notes.txt").write_text("keep")
    process_dataset(dataset, out)
    assert (out / "dataset_summary.json").is_file()
    assert cli(["process", str(out), "--out", str(tmp_path / "out2")]) == 1
    err = capsys.readouterr().err
    assert (
        f"addb process: DatasetError ({out}): is the output tree of a dataset run (it holds dataset_summary.json), not a "
        f"dataset folder; expected the folder of subject folders: here probably {dataset.resolve()}, with this folder given as --out"
    ) in err, err
    assert not (tmp_path / "out2").exists()


@pytest.mark.slow
def test_a_run_counts_subjects_processed_up_to_date_and_failed_apart(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    root = tmp_path / "ds"
    (root / "labA").mkdir(parents=True)
    (root / "labA" / "walk").symlink_to(SUBJECTS / "rajagopal2016_walk", target_is_directory=True)
    out = root / "results"  # inside the dataset folder: left out of the search, and no refusal once it is an output tree
    assert cli(["process", str(root), "--out", str(out), "--workers", "1"]) == 0
    (root / "labA" / "run").symlink_to(SUBJECTS / "rajagopal2016_run", target_is_directory=True)
    build_tree(root, {}, broken=True)
    capsys.readouterr()
    assert cli(["process", str(root), "--out", str(out), "--workers", "1"]) == 1  # the broken subject fails
    printed = capsys.readouterr()
    summary = json.loads((out / "dataset_summary.json").read_text())
    assert {s["rel"]: s["status"] for s in summary["subjects"]} == {"labA/run": "ok", "labA/walk": "skipped", BROKEN: "failed"}
    frames = sum(r["frames"] for s in summary["subjects"] if s["rel"] == "labA/run" for r in s["trials"])
    assert "s 1 up to date, 0 failed, 2 to process" in printed.err, printed.err
    assert f"s 1 processed, 1 failed, 1 up to date ({frames} frames processed)" in printed.err, printed.err
    assert "3 subjects: 1 processed, 1 up to date, 1 failed in " in printed.out, printed.out
    # nothing changed: nothing runs, and the broken subject is still counted failed
    assert cli(["process", str(root), "--out", str(out), "--workers", "1"]) == 1
    printed = capsys.readouterr()
    assert "s 2 up to date, 1 failed, 0 to process" in printed.err, printed.err
    assert "3 subjects: 0 processed, 2 up to date, 1 failed in " in printed.out, printed.out


def test_a_damaged_summary_is_named_by_every_reader(dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``dataset_summary.json`` is read by ``addb info``, ``addb benchmark``, the workbench's
    queue and the check of ``addb process OUT``; one reader
    (:func:`solver.outputs.read_summary`) serves them all. Cut short or rewritten by
    hand, it is named with its line (the workbench gave a traceback from the JSON parser) and
    the tree is still named as an output tree."""
    from addb_viewer.app.queue import open_dataset
    from solver.errors import FileFormatError
    from solver.outputs import read_summary

    out = tmp_path / "out"
    for rel in LINKED:  # every subject fails alone: no cluster starts
        (out / rel).mkdir(parents=True)
        (out / rel / "notes.txt").write_text("keep")
    process_dataset(dataset, out)
    summary = out / "dataset_summary.json"
    whole = summary.read_text()
    assert read_summary(out)["dataset"] == str(dataset.resolve())
    summary.write_text(whole[: len(whole) // 2])  # cut short
    lines = whole[: len(whole) // 2].count("\n") + 1
    with pytest.raises(FileFormatError, match="not valid JSON") as err:
        read_summary(out)
    assert err.value.path == str(summary) and err.value.line == lines
    with pytest.raises(FileFormatError, match="not valid JSON"):
        open_dataset(out)
    for command in (["info", str(out)], ["benchmark", str(out)]):
        assert cli(command) == 1
        printed = capsys.readouterr().err
        assert f"FileFormatError ({summary}:{lines}): not valid JSON" in printed and "Traceback" not in printed, printed
    assert cli(["process", str(out), "--out", str(tmp_path / "out2")]) == 1
    assert "is the output tree of a dataset run (it holds dataset_summary.json)" in capsys.readouterr().err
    summary.write_text(json.dumps({"dataset": str(dataset), "subjects": [{"status": "failed"}]}))  # no relative paths
    with pytest.raises(FileFormatError, match="expected a dataset summary of addb"):
        open_dataset(out)
    assert cli(["benchmark", str(out)]) == 1
    assert "expected a dataset summary of addb" in capsys.readouterr().err


def test_a_folder_inside_an_output_tree_is_told_from_the_outputs_in_it(tmp_path: Path) -> None:
    """The one test behind ``addb info OUT/labA``, ``addb benchmark``/``export`` of it and the
    subject reader's note (:func:`solver.outputs.tree_part`), on a tree laid out by hand: a
    folder of subject outputs is a part of the tree, named by its path below it; the tree
    itself, a subject's output folder (its manifest, or trial outputs in it), a trial's output
    folder and a folder outside any tree are not. A part's subjects are those whose path is
    below it, not those whose path only starts with its name (``labAB`` is not in ``labA``)."""
    from solver.outputs import (
        MANIFEST_NAME,
        SUMMARY_NAME,
        TRIAL_RESULTS,
        summary_subjects,
        tree_part,
    )

    out = tmp_path / "OUT"
    rels = ["labA/s01", "labA/2024/s02", "labAB/s03", "s04"]
    for rel in rels:
        (out / rel / "walk").mkdir(parents=True)
        (out / rel / MANIFEST_NAME).write_text("{}")
        (out / rel / "walk" / TRIAL_RESULTS).write_text("{}")
    (out / "s04" / MANIFEST_NAME).unlink()
    (out / "s04" / "walk" / "trial.npz").write_bytes(b"")  # a subject's folder without its records: trial outputs in it
    summary = {"dataset": str(tmp_path / "data"), "subjects": [{"rel": r, "status": "ok", "trials": []} for r in rels]}
    (out / SUMMARY_NAME).write_text(json.dumps(summary))
    (tmp_path / "elsewhere").mkdir()

    assert tree_part(out / "labA") == (out.resolve(), "labA")
    assert tree_part(out / "labA" / "2024") == (out.resolve(), "labA/2024")
    not_parts = [out, out / "labA" / "s01", out / "s04", out / "labA" / "s01" / "walk", tmp_path / "elsewhere",
                 out / "labA" / "missing", out / SUMMARY_NAME]  # fmt: skip
    assert [tree_part(p) for p in not_parts] == [None] * len(not_parts)
    assert [s["rel"] for s in summary_subjects(summary, "labA")] == ["labA/s01", "labA/2024/s02"]
    assert [s["rel"] for s in summary_subjects(summary, "labA/2024")] == ["labA/2024/s02"]
    assert [s["rel"] for s in summary_subjects(summary)] == rels


@pytest.mark.slow
def test_an_output_tree_without_a_processed_subject_is_refused_alike_by_benchmark_and_export(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb benchmark OUT`` and ``addb export OUT --format b3d`` of a run whose every subject
    failed each refused in its own words (one of them without saying why there is none); both
    now say the same (:meth:`solver.dataset.discover.TreeSubjects.require_processed`), for the
    tree and for a folder of it, and write nothing."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    root = build_tree(tmp_path / "ds", {}, broken=True)
    out = tmp_path / "OUT"
    assert cli(["process", str(root), "--out", str(out), "--workers", "1"]) == 1  # its one subject fails
    before = _files(tmp_path)
    for folder in (out, out / BROKEN.split("/")[0]):
        capsys.readouterr()
        assert cli(["benchmark", str(folder), "-o", str(tmp_path / "bench")]) == 1
        bench = capsys.readouterr().err
        assert cli(["export", str(folder), "--format", "b3d", "-o", str(tmp_path / "b3d")]) == 1
        export = capsys.readouterr().err
        said = (f"({folder}): a dataset output tree (or a folder of one) without a processed subject (every subject "
                "failed or was cancelled, or none is below it)")  # fmt: skip
        assert said in bench and said in export and "Traceback" not in bench + export, (bench, export)
    assert _files(tmp_path) == before
