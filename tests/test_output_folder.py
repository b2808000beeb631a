"""An output folder is replaced whole, so addb refuses one that holds what it did not write.

`addb process SUBJECT --out SUBJECT` once deleted the subject's own files, and `--out` naming
a folder of notes replaced it with the outputs. Every refusal happens before any stage runs
and leaves every file where it was. Outputs are as readable as the umask makes a new file.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.runner import process_dataset
from solver.errors import DatasetError, OutputFolderError
from solver.outputs import check_output_folder
from solver.pipeline import process_kinematics, process_subject
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


def _tree(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` (relative path -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def subject(tmp_path: Path) -> Path:
    return writable_copy(WALK, tmp_path / "lab" / "s01")


@pytest.mark.parametrize("where", ["the subject folder", "a folder above it"])
@pytest.mark.parametrize("run", [process_subject, process_kinematics], ids=["process", "kinematics"])
def test_an_output_folder_that_is_or_holds_the_subject_is_refused_before_any_stage(subject: Path, where: str, run) -> None:
    out = subject if where == "the subject folder" else subject.parent.parent
    before = _tree(out)
    with pytest.raises(OutputFolderError, match="input folder") as err:
        run(subject, out)
    assert str(out) in str(err.value)
    assert _tree(out) == before
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]  # no staging folder was made


def test_a_folder_of_other_files_is_refused_and_kept(subject: Path, tmp_path: Path) -> None:
    out = tmp_path / "results"
    (out / "other").mkdir(parents=True)
    (out / "notes.txt").write_text("my notes")
    with pytest.raises(OutputFolderError, match=r"holds 2 entries \(notes.txt, other\) and is not an output of addb"):
        process_subject(subject, out)
    assert (out / "notes.txt").read_text() == "my notes" and (out / "other").is_dir()
    # the command line says the same, with the folder, and exits 1
    assert cli(["process", str(subject), "--out", str(out)]) == 1
    assert (out / "notes.txt").read_text() == "my notes"


def test_a_file_is_refused(subject: Path, tmp_path: Path) -> None:
    out = tmp_path / "afile"
    out.write_text("not a folder")
    with pytest.raises(OutputFolderError, match="exists and is not a folder"):
        process_kinematics(subject, out)
    assert out.read_text() == "not a folder"


def test_an_earlier_output_an_empty_folder_and_a_folder_inside_the_subject_are_written(subject: Path, tmp_path: Path) -> None:
    first = tmp_path / "out"
    process_kinematics(subject, first)
    (first / "stale.txt").write_text("from before")  # an earlier output: replaced whole
    check_output_folder(first, (subject,))
    process_kinematics(subject, first)
    assert (first / "subject.json").is_file() and not (first / "stale.txt").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    check_output_folder(empty, (subject,))
    check_output_folder(subject / "addb_out", (subject,))  # where `addb view` writes by default


def test_a_dataset_cannot_be_its_own_output_tree_and_a_foreign_subject_folder_fails_alone(subject: Path) -> None:
    dataset = subject.parent.parent  # lab/s01 below it
    before = _tree(dataset)
    for out in (dataset, dataset.parent):
        with pytest.raises(DatasetError, match="dataset folder"):
            process_dataset(dataset, out)
    assert _tree(dataset) == before
    # the subject's output folder holds someone else's files: that subject fails, named, and
    # its folder stays (no worker starts: no subject is left to run)
    out = dataset.parent / "out"
    (out / "lab" / "s01").mkdir(parents=True)
    (out / "lab" / "s01" / "notes.txt").write_text("keep")
    run = process_dataset(dataset, out)
    [failed] = run.failed
    assert failed["rel"] == "lab/s01" and failed["error"]["type"] == "OutputFolderError"
    assert "notes.txt" in failed["error"]["message"]
    assert (out / "lab" / "s01" / "notes.txt").read_text() == "keep"


def test_outputs_are_as_readable_as_the_umask_allows(subject: Path, tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        out = tmp_path / "out"
        process_kinematics(subject, out)
    finally:
        os.umask(old)
    mode = lambda p: stat.S_IMODE(p.stat().st_mode)
    assert mode(out) == 0o755  # not mkdtemp's 0700
    assert mode(out / "s01_scaled.osim") == 0o644  # not mkstemp's 0600
    assert mode(out / "walk" / "walk_ik.mot") == 0o644


def test_a_folder_where_a_file_is_written_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "model_dir"
    folder.mkdir()
    assert cli(["kinematics", str(WALK), "--out", str(tmp_path / "out"), "--model", str(folder)]) == 1
    err = capsys.readouterr().err
    assert f"cannot use {folder}: Is a directory" in err and "Traceback" not in err


@pytest.mark.parametrize("argv", [["record", "--trial", "walk"], ["export", "--trial", "walk", "--format", "mcap"], ["export", "--format", "b3d"]],
                         ids=["record", "export_mcap", "export_b3d"])
def test_a_recording_or_b3d_named_by_a_folder_is_refused_before_processing(argv: list[str], subject: Path, tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "recordings"
    folder.mkdir()
    out = tmp_path / "out"
    assert cli([argv[0], str(subject), *argv[1:], "-o", str(folder), "--out", str(out)] if argv[0] != "export" or "b3d" not in argv
               else [argv[0], str(subject), *argv[1:], "-o", str(folder)]) == 1
    err = capsys.readouterr().err
    assert f"OutputFolderError ({folder}): is a folder; expected the name of the" in err and "Traceback" not in err
    assert not out.exists() and list(folder.iterdir()) == []  # nothing processed, nothing written


@pytest.mark.parametrize("given", ["subject output", "trial output"])
@pytest.mark.parametrize(
    "argv",
    [["kinematics", "--out", "{other}"], ["process", "--out", "{other}"], ["diagnose", "--trial", "walk"], ["view", "--port", "0"]],
    ids=["kinematics", "process", "diagnose", "view"],
)
def test_an_output_folder_given_as_the_subject_is_named_as_one(
    argv: list[str], given: str, subject: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A user gives ``addb_out``, or a trial's output folder ``addb_out/walk``, where the
    subject folder goes. kinematics and diagnose said "_subject.json is missing", process "no
    subject folder below this folder" (it took the folder for a dataset), and view started a
    page that showed that error (for ``addb_out``); each now says what output the folder is and
    names the subject folder and the folder to give as --out, and writes nothing."""
    import addb_viewer.app.server

    out = subject / "addb_out"
    assert cli(["kinematics", str(subject), "--out", str(out)]) == 0
    folder = out if given == "subject output" else out / "walk"
    expected = {
        "subject output": f"({out}): is an output folder of addb (it holds subject.json), not a subject folder; expected the "
        f"subject folder (the one with _subject.json): here probably {subject}, with this folder given as --out",
        "trial output": f"({folder}): is the output folder of one trial (it holds results.json), not a subject folder; expected "
        f"the subject folder (the one with _subject.json): here probably {subject}, with {out} given as --out",
    }[given]
    before = _tree(subject)
    monkeypatch.setattr(addb_viewer.app.server, "ReviewApp", lambda *a, **k: pytest.fail("addb view started the review app"))
    capsys.readouterr()
    assert cli([argv[0], str(folder), *(a.format(other=tmp_path / "other") for a in argv[1:])]) == 1
    err = capsys.readouterr().err
    assert expected in err, err
    assert "Traceback" not in err and _tree(subject) == before and not (tmp_path / "other").exists()


@pytest.mark.parametrize(
    "argv",
    [["kinematics", "--out", "{out}"], ["diagnose", "--trial", "walk"], ["record", "--trial", "walk", "-o", "{out}.rrd"],
     ["export", "--trial", "walk", "-o", "{out}.mcap"]],
    ids=["kinematics", "diagnose", "record", "export"],
)
def test_a_dataset_folder_given_as_the_subject_is_named_as_one(argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A user gives the dataset folder where one subject folder goes: the commands said
    "_subject.json is missing"; each now names the subject folders below it (a link back to
    the folder above is not followed) and what to give instead, and writes nothing."""
    dataset = tmp_path / "dataset"
    for rel in ("labA/s01", "labB/2024/s07"):
        writable_copy(WALK, dataset / rel)
    (dataset / "labA" / "up").symlink_to("../..", target_is_directory=True)
    before = _tree(dataset)
    out = tmp_path / "written"
    assert cli([argv[0], str(dataset), *(a.format(out=out) for a in argv[1:])]) == 1
    err = capsys.readouterr().err
    assert (
        f"SubjectFolderError ({dataset}): is a dataset folder, not a subject folder (_subject.json is in the folders "
        "below it: labA/s01, labB/2024/s07); give one subject folder, or process them all with addb process DATASET_DIR --out OUT"
    ) in err, err
    assert "Traceback" not in err and _tree(dataset) == before and not list(tmp_path.glob("written*"))


@pytest.mark.parametrize(
    "argv",
    [["kinematics", "--out", "{out}"], ["process", "--out", "{out}"], ["diagnose", "--trial", "walk"],
     ["record", "--trial", "walk", "-o", "{out}.rrd"], ["export", "--trial", "walk", "-o", "{out}.mcap"], ["view", "--port", "0"]],
    ids=["kinematics", "process", "diagnose", "record", "export", "view"],
)  # fmt: skip
def test_a_folder_inside_a_dataset_output_tree_given_as_the_subject_is_named_as_one(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A lab's folder of a dataset run's output tree (``OUT/labA``: no ``_subject.json``, no
    output marker) given where a subject folder goes: the commands said "_subject.json is
    missing" (``addb view`` started a page showing it, ``addb process`` "no subject folder below
    this folder"); each now names the output tree and what to give instead, and writes nothing."""
    import addb_viewer.app.server

    dataset, out_tree = tmp_path / "dataset", tmp_path / "tree"
    writable_copy(WALK, dataset / "labA" / "s01")
    for rel in ("labA/s01", "labB/s02"):  # both fail alone (another's file in the folder): no cluster starts
        (out_tree / rel).mkdir(parents=True)
        (out_tree / rel / "notes.txt").write_text("keep")
    writable_copy(WALK, dataset / "labB" / "s02")
    process_dataset(dataset, out_tree)
    lab = out_tree / "labA"
    before = _tree(out_tree)
    monkeypatch.setattr(addb_viewer.app.server, "ReviewApp", lambda *a, **k: pytest.fail("addb view started the review app"))
    capsys.readouterr()
    written = tmp_path / "written"
    assert cli([argv[0], str(lab), *(a.format(out=written) for a in argv[1:])]) == 1
    err = capsys.readouterr().err
    assert (
        f"Error ({lab}): is a folder inside the dataset output tree {out_tree}, not a subject folder; expected a subject "
        f"folder of the dataset (addb info {out_tree} names the dataset folder), or addb view {out_tree} to review its subjects"
    ) in err, err
    assert "Traceback" not in err and _tree(out_tree) == before and not list(tmp_path.glob("written*"))


@pytest.mark.parametrize("command", ["process", "kinematics", "convert"])
@pytest.mark.parametrize("where", ["a file", "under a file"])
def test_an_out_that_is_or_lies_under_a_file_is_refused_by_the_parser(
    command: str, where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before, ``addb process SUBJECT --out FILE/out`` computed the whole subject, then
    failed on writing ("cannot use FILE: File exists")."""
    a_file = tmp_path / "notes.txt"
    a_file.write_text("keep")
    out = a_file if where == "a file" else a_file / "deeper" / "out"
    subject = str(WALK) if command != "convert" else str(SHARED_DATA / "b3d" / "results.b3d")
    with pytest.raises(SystemExit) as exit_:
        cli([command, subject, "--out", str(out)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    expected = f"{out} is a file; expected a folder" if where == "a file" else f"{out} lies under {a_file}, which is a file"
    assert f"addb {command}: error: argument --out: {expected}" in err, err
    assert a_file.read_text() == "keep"
