"""docs/audits/2026-12-02-dataset.md, finding 3: a subject that fails because the output
storage fails (disk full, quota, I/O error) is no fault of its data. It used to be recorded
like a data failure, keyed to its inputs, so every later run reported it "failed
(unchanged)" and only ``--force`` (every subject again) redid it. Now its failure is
recorded as a transient ``StorageError`` and the next run processes it again."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.manifest import current_manifest, read_manifest, transient_failure
from solver.dataset.task import STARTED_NAME, storage_error
from solver.errors import AddbError
from tests.dataset.dataset_tree import build_tree, no_work_folders

WALK = "labA/walk"


def test_a_storage_error_is_found_behind_the_error_the_pipeline_raised() -> None:
    """A full disk is a storage error, also when another error was raised from it or while
    handling it; a missing file or a data error is not."""
    full = OSError(errno.ENOSPC, "No space left on device", "/out/s01/trial.npz")
    try:
        try:
            raise full
        except OSError as exc:
            raise AddbError("cannot write the trial") from exc
    except AddbError as wrapped:
        assert storage_error(wrapped) is full
    assert storage_error(OSError(errno.EDQUOT, "Disk quota exceeded")) is not None
    assert storage_error(OSError(errno.ENOENT, "No such file or directory")) is None
    assert storage_error(ValueError("bad marker")) is None


@pytest.mark.slow
def test_a_full_disk_is_recorded_as_transient_and_the_next_run_processes_the_subject_again(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:  # fmt: skip
    """The walk is processed (a real run, one worker), then processed again by its task with
    the same key while the disk is full as its output is renamed into place (as in the
    audit's tmpfs of 12 MB). The failure is a transient StorageError naming the file;
    ``addb info`` says the subject will be processed again and why, and the next run (the
    disk no longer full) processes it: it is not reported "failed (unchanged)"."""
    from solver.dataset import task

    tree = build_tree(tmp_path / "in", {WALK: "rajagopal2016_walk"})
    out = tmp_path / "out"
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 0
    key = read_manifest(out / WALK)["key"]

    def full_disk(src: Path, dst: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(dst))

    with monkeypatch.context() as patch:
        patch.setattr(task, "_replace_dir", full_disk)
        job = task.SubjectJob(WALK, str(tree / WALK), str(out / WALK), key, attempt="addb-subject-test-1")
        outcome = task.run_subject(job)
    error = outcome["error"]
    assert outcome["status"] == "failed" and error["type"] == "StorageError" and error["transient"] is True, outcome
    assert "storage error (ENOSPC: No space left on device)" in error["message"], error
    assert "the next run processes this subject again" in error["message"] and error["path"] == str(out / WALK)
    stored = read_manifest(out / WALK)
    assert stored["key"] == key and transient_failure(stored)
    assert current_manifest(out / WALK, key) is None  # not up to date: a resume does not skip it
    assert not list((out / "labA").glob(f".addb-work-*/{STARTED_NAME}"))  # the attempt's work folder is gone

    capsys.readouterr()
    assert cli(["info", str(tree), "--out", str(out)]) == 0
    info = capsys.readouterr().out
    assert f"{WALK}: its last run failed on a storage error, not on its data: storage error (ENOSPC" in info, info

    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "failed (unchanged)" not in printed, printed
    assert "\n1 subjects: 1 processed, 0 up to date, 0 failed in " in printed, printed
    again = read_manifest(out / WALK)
    assert again["status"] == "ok" and again["key"] == key
    (row,) = json.loads((out / "dataset_summary.json").read_text())["subjects"]
    assert row["rel"] == WALK and row["status"] == "ok" and row["attempts"] == 1 and "unchanged" not in row, row
    assert not no_work_folders(out), no_work_folders(out)
