"""The parts of a dataset run that need no cluster: finding subject folders, the manifest
key that decides what a rerun skips, and the report page."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from solver.dataset.discover import find_subjects, loop_note, scan_dataset
from solver.dataset.manifest import (
    FINAL_STATUSES,
    current_manifest,
    finished_manifest,
    input_files,
    lost_trials,
    manifest_key,
    subject_status,
)
from solver.dataset.report import render_report
from solver.dataset.summary import dataset_totals
from solver.errors import DatasetError
from tests.conftest import writable_copy
from tests.dataset.dataset_tree import SUBJECTS


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    root = tmp_path / "data"
    writable_copy(SUBJECTS / "rajagopal2016_walk", root / "labA" / "s01")
    writable_copy(SUBJECTS / "rajagopal2016_walk", root / "labB" / "deeper" / "s02")
    (root / "labA" / "s01" / "addb_out" / "copy").mkdir(parents=True)  # an output folder is no subject
    (root / "labA" / "s01" / "addb_out" / "copy" / "_subject.json").write_text("{}")
    (root / ".hidden" / "s03").mkdir(parents=True)
    (root / ".hidden" / "s03" / "_subject.json").write_text("{}")
    return root


def test_subjects_are_found_at_any_depth_and_the_output_tree_mirrors_them(tree: Path, tmp_path: Path) -> None:
    out_inside = tree / "out"
    writable_copy(SUBJECTS / "rajagopal2016_walk", out_inside / "labA" / "s01")  # an earlier run's output
    found = find_subjects(tree, exclude=(out_inside,))
    assert [s.rel for s in found] == ["labA/s01", "labB/deeper/s02"]
    assert found[1].out_dir(tmp_path / "OUT") == (tmp_path / "OUT" / "labB" / "deeper" / "s02").resolve()
    assert found[0].path == (tree / "labA" / "s01").resolve()


def test_links_back_to_a_folder_above_are_not_followed_and_are_named(tree: Path, tmp_path: Path) -> None:
    """A link to a folder above it (``labA/up -> ../..``, here the folder holding the dataset,
    and one inside a subject's trials) was followed: the search found the dataset again
    inside itself until the path grew too long (a hundred-odd "subjects" from one), and the
    manifest hashed the subject's files as often. Both are left out and named; a link to a
    folder beside it (a lab's subject linked in) is still followed."""
    (tree / "labA" / "up").symlink_to("../..", target_is_directory=True)
    (tree / "labA" / "s01" / "trials" / "loop").symlink_to("..", target_is_directory=True)
    (tree / "labC").mkdir()
    (tree / "labC" / "linked").symlink_to(tree / "labB" / "deeper" / "s02", target_is_directory=True)
    scan = scan_dataset(tree)
    assert [s.rel for s in scan.subjects] == ["labA/s01", "labB/deeper/s02", "labC/linked"]
    assert scan.loops == ("labA/up",)
    assert loop_note(scan) == "did not follow a symbolic link leading back to a folder above it (a loop): labA/up"
    files = input_files(tree / "labA" / "s01")
    assert not [f for f in files if "loop" in f] and "trials/walk/markers.trc" in files
    assert loop_note(scan_dataset(tree / "labB")) is None


def test_the_dataset_search_and_the_note_on_a_dataset_folder_enter_the_same_folders(tree: Path) -> None:
    """``load_subject`` of a dataset folder names the subject folders below it
    (:func:`solver.io.subject.dataset_folder_note`) with its own walk; it skipped hidden and
    ``addb_out`` folders but not ``__pycache__`` or ``node_modules``, which the dataset search
    skips, so it named "subjects" a dataset run would not process. Both walks now enter the
    folders of one rule (:func:`solver.files.folders_to_search`)."""
    from solver.files import folders_to_search
    from solver.io.subject import dataset_folder_note

    for skipped in ("__pycache__", "node_modules"):
        (tree / "labB" / skipped / "p9").mkdir(parents=True)
        (tree / "labB" / skipped / "p9" / "_subject.json").write_text("{}")
    (tree / "labA" / "up").symlink_to("..", target_is_directory=True)
    assert [s.rel for s in scan_dataset(tree).subjects] == ["labA/s01", "labB/deeper/s02"]
    note = dataset_folder_note(tree)
    assert "below it: labA/s01, labB/deeper/s02)" in note and "p9" not in note and "up" not in note, note
    names = ["up", "s01", ".git", "addb_out", "__pycache__", "node_modules", "copy"]
    assert folders_to_search(tree / "labA", names) == (["copy", "s01"], ["up"])


def test_a_folder_without_subjects_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no subject folder") as info:
        find_subjects(tmp_path)
    assert info.value.path == str(tmp_path.resolve())


def test_manifest_key_follows_the_inputs_and_only_them(tree: Path) -> None:
    subject = tree / "labA" / "s01"
    key = manifest_key(subject, {"a": 1})
    assert set(key["inputs"]) == {"_subject.json", "unscaled_generic.osim", "trials/static/markers.trc",
                                  "trials/walk/markers.trc", "trials/walk/grf.mot"}  # fmt: skip
    # the same files elsewhere give the same key; meshes, outputs and the review record are no inputs
    assert manifest_key(tree / "labB" / "deeper" / "s02", {"a": 1}) == key
    (subject / "Geometry").mkdir()
    (subject / "Geometry" / "femur.vtp").write_text("mesh")
    (subject / "annotations.json").write_text("{}")
    assert manifest_key(subject, {"a": 1}) == key
    # the review's digest, settings and content changes change the key
    assert manifest_key(subject, {"a": 1}, "digest") != key
    assert manifest_key(subject, {"a": 2}) != key
    trc = subject / "trials" / "walk" / "markers.trc"
    trc.write_bytes(trc.read_bytes() + b"\n")
    assert manifest_key(subject, {"a": 1})["inputs"]["trials/walk/markers.trc"] != key["inputs"]["trials/walk/markers.trc"]
    assert len(input_files(subject)) == 5


def test_key_changes_name_what_changed_between_two_keys(tree: Path) -> None:
    """The phrases ``addb info DATASET_DIR`` prints for a subject a new run processes again,
    from the keys of the subject's files before and after real edits."""
    from solver.dataset.manifest import key_changes, run_settings

    subject = tree / "labA" / "s01"
    before = manifest_key(subject, run_settings({}))
    assert key_changes(before, manifest_key(subject, run_settings({}))) == []
    trc = subject / "trials" / "walk" / "markers.trc"
    trc.write_bytes(trc.read_bytes() + b"\n")
    (subject / "trials" / "walk" / "grf.mot").unlink()
    (subject / "notes.txt").write_text("session notes")
    now = manifest_key(subject, run_settings({"fit": "alternation"}), "digest")
    assert key_changes(before, now) == [
        "the settings changed (fit: default then, alternation now)", "trials/walk/markers.trc changed", "notes.txt added", "trials/walk/grf.mot removed",
        "the review's flags changed",
    ]  # fmt: skip
    assert key_changes({**before, "code": "0" * 64}, before) == ["addb's code changed"]
    many = {**before, "inputs": {f"trials/t{k}/markers.trc": "0" for k in range(5)}}
    assert key_changes(before, many)[0] == "trials/t0/markers.trc, trials/t1/markers.trc, trials/t2/markers.trc and 2 more files added"


def test_a_subject_whose_key_cannot_be_made_is_named_with_what_cannot_be_read(tree: Path) -> None:
    """The one key test of a run and of ``addb info DATASET_DIR`` (``subject_key_now``): a
    review record its reader refuses, or an input file that cannot be opened (a link to
    nowhere), raise ``KeyUnreadable`` naming which, with the error's class for the subject's
    failure record; otherwise the key is the manifest key with the reader's digest."""
    from solver.dataset.manifest import KeyUnreadable, subject_key_now

    subject = tree / "labA" / "s01"

    def damaged(subject_dir: str, out_dir: str) -> str:
        raise ValueError(f"{out_dir}/annotations.json: line 3: expected an object")

    assert subject_key_now(subject, tree / "out", {"a": 1}, lambda s, o: "digest") == manifest_key(subject, {"a": 1}, "digest")
    assert subject_key_now(subject, tree / "out", {"a": 1}, None) == manifest_key(subject, {"a": 1})
    with pytest.raises(KeyUnreadable) as caught:
        subject_key_now(subject, tree / "out", {}, damaged)
    assert str(caught.value) == f"cannot read the review record: {tree / 'out'}/annotations.json: line 3: expected an object"
    assert caught.value.error_type == "ValueError"
    (subject / "trials" / "walk" / "extra.trc").symlink_to(tree / "nowhere.trc")
    with pytest.raises(KeyUnreadable) as caught:
        subject_key_now(subject, tree / "out", {}, None)
    assert str(caught.value).startswith("cannot read the subject's files: ") and "extra.trc" in str(caught.value)
    assert caught.value.error_type == "OSError"


def test_manifest_key_follows_the_solver_code(tmp_path: Path) -> None:
    # the version number stays 0.1.0 across commits: the key carries a digest of the source of
    # the solver modules processing runs, so a rerun after an update of them processes the
    # subjects again (tests/test_provenance.py: and only after an update of them)
    import shutil

    import solver
    from solver.provenance import code_digest

    package = Path(solver.__file__).parent
    assert manifest_key(tmp_path, {})["code"] == code_digest(package) == code_digest()
    copy = tmp_path / "solver"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert code_digest(copy) == code_digest()
    (copy / "notes.txt").write_text("not source")  # only Python source counts
    assert code_digest(copy) == code_digest()
    masks = copy / "masks.py"
    masks.write_text(masks.read_text() + "\n# edited\n")
    assert code_digest(copy) != code_digest()


def test_a_stored_manifest_counts_only_with_an_equal_key_and_a_final_status(tmp_path: Path) -> None:
    key = {"schema": 1, "inputs": {"a": "0"}}
    (tmp_path / "manifest.json").write_text(json.dumps({"key": key, "status": "ok"}))
    assert current_manifest(tmp_path, key)["status"] == "ok"
    assert current_manifest(tmp_path, {**key, "inputs": {"a": "1"}}) is None
    (tmp_path / "manifest.json").write_text(json.dumps({"key": key, "status": "running"}))
    assert current_manifest(tmp_path, key) is None
    (tmp_path / "manifest.json").write_text('{"key": ')  # cut short by a crash: not current
    assert current_manifest(tmp_path, key) is None
    assert finished_manifest(tmp_path) is None
    for status in FINAL_STATUSES:  # what addb info compares with, whatever the key
        (tmp_path / "manifest.json").write_text(json.dumps({"key": key, "status": status}))
        assert finished_manifest(tmp_path)["status"] == status


def test_a_manifest_whose_trial_output_is_gone_is_not_current(tmp_path: Path) -> None:
    """Output deleted or emptied after the run is not counted as finished: a new run processes
    the subject again (docs/audits/2026-12-02-dataset.md, finding 7)."""
    key = {"schema": 1, "inputs": {"a": "0"}}
    rows = [{"trial": "walk"}, {"trial": "static"}]
    (tmp_path / "manifest.json").write_text(json.dumps({"key": key, "status": "ok", "trials": rows}))
    for trial in ("walk", "static"):
        (tmp_path / trial).mkdir()
        for f in ("trial.npz", "results.json"):
            (tmp_path / trial / f).write_bytes(b"x")
    assert current_manifest(tmp_path, key)["status"] == "ok" and lost_trials(tmp_path, finished_manifest(tmp_path)) == []
    (tmp_path / "walk" / "trial.npz").write_bytes(b"")  # emptied
    assert current_manifest(tmp_path, key) is None and lost_trials(tmp_path, finished_manifest(tmp_path)) == ["walk"]
    shutil.rmtree(tmp_path / "static")  # deleted
    assert lost_trials(tmp_path, finished_manifest(tmp_path)) == ["walk", "static"]
    (tmp_path / "manifest.json").write_text(json.dumps({"key": key, "status": "failed", "trials": []}))
    assert current_manifest(tmp_path, key)["status"] == "failed"  # a failure record lists no output


def test_a_subjects_status_follows_its_trials_in_one_place() -> None:
    # the worker (task.py) and the review app's Reprocess (dataset_manifest.py) both record it
    # in the manifest; each computed it itself before
    import inspect

    from addb_viewer.app import dataset_manifest
    from solver.dataset import task

    static = {"trial": "static", "status": "kinematics_only"}
    assert subject_status([static, {"trial": "walk", "status": "ok"}]) == "ok"
    assert subject_status([static]) == "kinematics_only"
    for module in (task, dataset_manifest):
        source = inspect.getsource(module)
        assert "subject_status(rows)" in source and 'r["status"] == "ok"' not in source, module.__name__


def test_report_escapes_names_and_lists_failures_with_file_and_line() -> None:
    subjects = [
        {"rel": "lab<A>/s&1", "status": "failed", "trials": [],
         "error": {"type": "TrcFormatError", "message": "bad row", "path": "/d/markers.trc", "line": 7}},
        {"rel": "labA/s2", "status": "kinematics_only", "trials": [
            {"trial": "static", "status": "kinematics_only", "frames": 100, "rate_hz": 100.0, "duration_s": 1.0,
             "measured_frames": 0, "measured_s": 0.0, "marker_rms_m": 0.01, "contact_frames": None,
             "clinical_frames": 0, "residual_force_hist_BW": None, "residual_moment_hist_BWh": None,
             "hicks_linear_ok": None, "hicks_angular_ok": None}]},
    ]  # fmt: skip
    totals = dataset_totals(subjects)
    assert totals["subjects"] == {"failed": 1, "kinematics_only": 1} and totals["frames"] == 100
    assert totals["hours_with_measured_force"] == 0.0 and totals["clinical_grade_share"] is None
    page = render_report({"dataset": "/d", "out": "/o", "addb_version": "x", "finished": "now", "seconds": 1.0,
                          "totals": totals, "subjects": subjects})  # fmt: skip
    assert "lab&lt;A&gt;/s&amp;1" in page and "lab<A>" not in page
    assert "/d/markers.trc:7" in page and "Failures (1)" in page and "<svg" in page
    # two sources (first folders): a row each, the source's name escaped too
    assert '<td class="l">lab&lt;A&gt;</td><td>1 failed</td><td>0 (0)</td>' in page
    assert '<td class="l">labA</td><td>1 kinematics_only</td><td>1 (0)</td><td>100 (0)</td>' in page
    one = [dict(s, rel=s["rel"].replace("lab<A>", "labA")) for s in subjects]  # one source: no table
    assert "By source" not in render_report({"dataset": "/d", "out": "/o", "addb_version": "x", "finished": "now",
                                             "seconds": 1.0, "totals": dataset_totals(one), "subjects": one})  # fmt: skip


def test_a_worker_killed_between_the_two_renames_loses_no_finished_output(tmp_path: Path) -> None:
    """_replace_dir moves the old output aside, then the new one in; a kill between the two
    leaves only the moved-aside copy, which the next run puts back."""
    import tempfile

    from solver.dataset.task import WORK_PREFIX, remove_stale_work

    out = tmp_path / "out"
    out.mkdir()
    aside = Path(tempfile.mkdtemp(prefix=f"{WORK_PREFIX}old-s-01-", dir=out))
    (aside / "previous").mkdir()
    (aside / "previous" / "manifest.json").write_text('{"key": {}}')
    fresh = Path(tempfile.mkdtemp(prefix=f"{WORK_PREFIX}s-02-", dir=out))
    (fresh / "half.txt").write_text("unfinished")
    assert remove_stale_work(out) == 2
    assert (out / "s-01" / "manifest.json").read_text() == '{"key": {}}'
    assert sorted(p.name for p in out.iterdir()) == ["s-01"]


def test_a_failure_after_the_subjects_log_was_closed_is_recorded_with_the_whole_log(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    """A subject that fails in its last steps (its output renamed into place: here a full
    disk) is recorded as failing with that error, its process.log holding every line, not as
    "I/O operation on closed file" without a record (docs/audits/2026-12-02-dataset.md,
    finding 6)."""
    import errno

    from solver.dataset import task
    from solver.dataset.manifest import read_manifest

    subject = writable_copy(SUBJECTS / "rajagopal2016_walk", tmp_path / "s01")
    final = tmp_path / "out" / "s01"

    def full_disk(src: Path, dst: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(dst))

    monkeypatch.setattr(task, "_replace_dir", full_disk)
    outcome = task.run_subject(task.SubjectJob("s01", str(subject), str(final), {"inputs": "test"}))
    assert outcome["status"] == "failed" and "No space left on device" in outcome["error"]["message"], outcome
    log = (final / task.LOG_NAME).read_text(encoding="utf-8")
    assert "done: ok" in log and "failed: [Errno 28] No space left on device" in log, log
    assert "closed file" not in log, log
    assert read_manifest(final)["status"] == "failed"
    assert sorted(p.name for p in final.parent.iterdir()) == ["s01"]  # no work folder left


def test_a_second_run_on_one_output_tree_is_refused_while_the_first_holds_it(tree: Path, tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Two runs on one OUT each removed the other's work folders at start, failing its running
    subjects (and a failure with unchanged inputs is not run again). The second now stops
    before anything is written, naming the first; a holder that dies leaves no stale lock."""
    import os
    import signal
    import subprocess
    import sys

    from addb_viewer.cli import main as cli
    from solver.dataset.lock import LOCK_NAME, output_tree_lock

    out = tmp_path / "out"
    out.mkdir()
    with output_tree_lock(out):
        assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
        err = capsys.readouterr().err
        assert f"DatasetError ({out}): another addb run is writing this output tree (process {os.getpid()} on " in err, err
        assert "wait for it to end (or stop it), or give another --out" in err and "Traceback" not in err
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]  # no subject, no summary
    # a holder killed without a word: the system releases its lock
    script = (
        "import sys, time; from solver.dataset.lock import output_tree_lock\n"
        "with output_tree_lock(sys.argv[1]):\n    print('held', flush=True); time.sleep(60)"
    )
    holder = subprocess.Popen(
        [sys.executable, "-c", script, str(out)], stdout=subprocess.PIPE, text=True, cwd=Path(__file__).resolve().parents[2]
    )
    assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
    with pytest.raises(DatasetError, match="another addb run is writing this output tree"), output_tree_lock(out):
        pass
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait(timeout=30)
    with output_tree_lock(out):
        assert f"process {os.getpid()} on " in (out / LOCK_NAME).read_text()


def test_a_writer_that_joins_this_process_hold_keeps_the_tree_until_it_ends(tmp_path: Path) -> None:
    """The review app's Reprocess under its own background dataset run wrote on without a
    lock of its own: when the dataset run ended first, the tree was freed while the Reprocess
    still wrote. A writer that joins the process's hold (``join_tree_hold``) now keeps the
    ``flock`` until it ends, whichever ends first; outside a hold it joins nothing."""
    import subprocess
    import sys

    from solver.dataset.lock import join_tree_hold, output_tree_lock

    out = tmp_path / "OUT"
    out.mkdir()

    def free() -> bool:  # asked from another process, as a dataset run in another terminal would
        script = ("import sys\nfrom solver.dataset.lock import output_tree_lock\nfrom solver.errors import DatasetError\n"
                  "try:\n    with output_tree_lock(sys.argv[1]): print('free')\nexcept DatasetError: print('held')")
        answer = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True, text=True, check=True,
                                cwd=Path(__file__).resolve().parents[2])  # fmt: skip
        return {"free": True, "held": False}[answer.stdout.strip()]

    with join_tree_hold(out) as joined:
        assert joined is False and free()
    with join_tree_hold(None) as joined:
        assert joined is False
    first = output_tree_lock(out)
    first.__enter__()
    with join_tree_hold(out) as joined:
        assert joined is True
        first.__exit__(None, None, None)  # the dataset run ends first
        assert not free()
        with pytest.raises(DatasetError, match="another addb run is writing this output tree"), output_tree_lock(out):
            pass  # nor does a new holder of this process get it
    assert free()
    with output_tree_lock(out), join_tree_hold(out) as joined:  # the joined writer ends first
        assert joined is True
    assert free()


def test_a_hold_that_cannot_write_its_holder_frees_the_tree_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A hold whose holder line could not be written (a full disk) kept its lock file open,
    and so the tree locked, for as long as the error's traceback lived (here: the
    ``pytest.raises`` record). It is now closed before the error leaves, so the tree is free."""
    import socket

    from solver.dataset.lock import LOCK_NAME, output_tree_lock

    out = tmp_path / "OUT"
    out.mkdir()

    def no_space() -> str:
        raise OSError(28, "No space left on device")

    with monkeypatch.context() as patch:
        patch.setattr(socket, "gethostname", no_space)  # fails while the holder's line is written
        with pytest.raises(OSError, match="No space left") as failed, output_tree_lock(out):
            pass
    assert failed.value.errno == 28  # the record (and its traceback) still lives here
    with output_tree_lock(out):  # raised DatasetError ("another addb run ...") before
        assert "process " in (out / LOCK_NAME).read_text()


@pytest.mark.parametrize("command", ["process", "kinematics"])
def test_a_one_subject_run_into_a_dataset_output_tree_holds_the_tree(command: str, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """``addb process labA/s01 --out OUT/labA/s01`` replaced the subject's folder of a dataset
    run's output tree without the tree's lock, so it could write while a dataset run worked on
    the tree. It now holds the lock: refused, writing nothing, while a run holds it; and while
    it holds it, a dataset run is refused. Outside an output tree it holds nothing."""
    import os

    from addb_viewer.cli import main as cli
    from solver.dataset.lock import LOCK_NAME, output_tree_lock, subject_output_lock
    from solver.outputs import SUMMARY_NAME

    out = tmp_path / "OUT"
    out.mkdir()
    (out / SUMMARY_NAME).write_text("{}")  # what marks an output tree
    folder = out / "labA" / "s01"
    with output_tree_lock(out):
        assert cli([command, str(SUBJECTS / "rajagopal2016_walk"), "--out", str(folder)]) == 1
        err = capsys.readouterr().err
        assert f"DatasetError ({out}): another addb run is writing this output tree (process {os.getpid()} on " in err, err
        assert "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == sorted([LOCK_NAME, SUMMARY_NAME])  # nothing written
    with subject_output_lock(folder) as held:
        assert held == out.resolve()
        with pytest.raises(DatasetError, match="another addb run is writing this output tree"), output_tree_lock(out):
            pass
    with subject_output_lock(tmp_path / "elsewhere" / "s01") as held:
        assert held is None


def _holding(tree_dir: Path) -> subprocess.Popen[str]:
    """Another process holding the output tree ``tree_dir`` (as a running dataset run does)."""

    script = (
        "import sys, time; from solver.dataset.lock import output_tree_lock\n"
        "with output_tree_lock(sys.argv[1]):\n    print('held', flush=True); time.sleep(120)"
    )
    holder = subprocess.Popen([sys.executable, "-c", script, str(tree_dir)], stdout=subprocess.PIPE, text=True,
                              cwd=Path(__file__).resolve().parents[2])  # fmt: skip
    assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
    return holder


def test_a_one_subject_run_into_a_tree_a_first_run_is_writing_is_refused(tree: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Dataset audit 2026-12-02, finding 4: while the first run into a new OUT runs (no
    dataset_summary.json yet, only its lock file), ``addb process SUBJECT --out OUT/s01`` is
    refused naming the tree (it replaced the run's finished output and manifest)."""
    from addb_viewer.cli import main as cli

    out = tmp_path / "out"
    out.mkdir()
    holder = _holding(out)
    try:
        assert cli(["process", str(tree / "labA" / "s01"), "--out", str(out / "labA" / "s01")]) == 1
        err = capsys.readouterr().err
        assert f"DatasetError ({out}): another addb run is writing this output tree (process {holder.pid} on " in err, err
        assert not (out / "labA").exists()
    finally:
        holder.kill()
        holder.wait(timeout=30)


def test_a_run_inside_another_runs_tree_is_refused_and_a_run_around_one_leaves_its_work(tree: Path, tmp_path: Path) -> None:
    """Dataset audit 2026-12-02, finding 5: a dataset run whose OUT lies inside a tree another
    run is writing is refused before anything is written; and a run whose OUT holds another
    run's tree below it leaves that tree's work folders alone (its start removed them, failing
    the other run's subjects), while its own stale work folders go."""
    from solver.dataset.runner import process_dataset
    from solver.dataset.task import WORK_PREFIX, remove_stale_work

    outer = tmp_path / "T"
    outer.mkdir()
    holder = _holding(outer)
    try:
        with pytest.raises(DatasetError, match="another addb run is writing this output tree") as err:
            process_dataset(tree, outer / "sub")
        assert err.value.path == str(outer) and not any((outer / "sub").iterdir())
    finally:
        holder.kill()
        holder.wait(timeout=30)
    inner = outer / "sub"
    holder = _holding(inner)
    try:
        theirs = inner / "labA" / f"{WORK_PREFIX}s01-abc"
        mine = outer / "labB" / f"{WORK_PREFIX}s02-def"
        theirs.mkdir(parents=True)
        mine.mkdir(parents=True)
        assert remove_stale_work(outer) == 1
        assert theirs.is_dir() and not mine.exists()
    finally:
        holder.kill()
        holder.wait(timeout=30)
