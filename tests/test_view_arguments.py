"""``addb view``'s argument checks that refuse on the terminal, before the server starts:
an output folder its processing would refuse, and a file that is not a .b3d file.

The review app is replaced by a stub that fails the test if it is made: a check that let the
argument through would otherwise start a server that runs until stopped.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import addb_viewer.app.server
from addb_viewer.cli import main
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture(autouse=True)
def no_server(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kw: object) -> None:
        raise AssertionError("addb view started the review app")

    monkeypatch.setattr(addb_viewer.app.server, "ReviewApp", refuse)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("where", ["the subject folder", "a folder above it"])
def test_an_output_folder_that_is_or_holds_the_subject_is_refused_before_the_server_starts(
    where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was refused only in the page, when the app processed the subject; the same reason
    is now on the terminal, with exit code 1, and nothing is written."""
    subject = writable_copy(WALK, tmp_path / "lab" / "s01")
    out = subject if where == "the subject folder" else subject.parent
    before = _tree(out)
    assert main(["view", str(subject), "--out", str(out), "--port", "0"]) == 1
    err = capsys.readouterr().err
    what = "is" if out == subject else "holds"
    assert f"addb view: OutputFolderError ({out}): the output folder {what} the input folder {subject}" in err
    assert f"--out {subject.parent / 's01_out'}" in err and "Traceback" not in err
    assert _tree(out) == before


def test_an_output_folder_inside_the_subject_folder_is_let_through(tmp_path: Path) -> None:
    """``<subject>/addb_out`` is where addb view writes by default: the app is made (the stub)."""
    subject = writable_copy(WALK, tmp_path / "s01")
    with pytest.raises(AssertionError, match="started the review app"):
        main(["view", str(subject), "--out", str(subject / "addb_out"), "--port", "0"])


@pytest.mark.parametrize("name", ["trials/walk/markers.trc", "unscaled_generic.osim", "_subject.json"])
def test_a_file_other_than_a_b3d_file_is_named_as_a_file(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    """It read as "no such subject folder", as if the file did not exist."""
    path = WALK / name
    assert main(["view", str(path), "--port", "0"]) == 1
    err = capsys.readouterr().err
    assert f"addb view: SubjectFolderError ({path}): is a file; addb view expects a subject folder (with _subject.json), " in err
    assert "a .b3d file or a folder of .b3d files" in err
    assert "no such" not in err and "Traceback" not in err


def test_a_missing_path_is_still_no_such_subject_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["view", str(tmp_path / "nope"), "--port", "0"]) == 1
    assert f"no such subject folder: {tmp_path / 'nope'}" in capsys.readouterr().err


@pytest.mark.parametrize("beside", [True, False], ids=["with a subject folder", "alone"])
def test_a_folder_of_b3d_files_is_a_dataset_when_it_also_holds_subject_folders(
    beside: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A folder holding a .b3d file and a subject folder was taken as a folder of .b3d files:
    the file was converted and reviewed alone and the subject folder left out, where ``addb
    process`` and ``addb info`` take the same folder as a dataset folder. It now opens as that
    dataset (the workbench queues the subject folder and names the .b3d file it leaves out);
    a folder of .b3d files alone still opens the converted files."""
    from addb_viewer.commands import view

    folder = tmp_path / "lab"
    folder.mkdir()
    (folder / "s02.b3d").write_bytes(b"not read: the dispatch only looks at names")
    if beside:
        writable_copy(WALK, folder / "s01")
    opened: list[Path] = []
    monkeypatch.setattr(view, "open_dataset", lambda args, dataset: (opened.append(dataset), (None, None))[1])
    monkeypatch.setattr(view, "_serve", lambda app, args: 0)
    converted = tmp_path / "converted"  # what b3d_dataset makes: a tree of subject folders
    writable_copy(WALK, converted / "s02")
    monkeypatch.setattr(view, "b3d_dataset", lambda f: converted)
    assert main(["view", str(folder), "--port", "0"]) == 0
    assert opened == [folder if beside else converted]
