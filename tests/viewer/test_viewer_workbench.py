"""``addb view DATASET_DIR`` without a browser: a dataset of two shared subjects (no Geometry
folder) is processed in the background by the Dask dataset runner while the app is up;
the queue lists both subjects and their trials with their states; opening the second
subject shows it with a bone mesh for every body; "Next trial to review" moves through
the unreviewed trials and skips a trial once it is marked reviewed; the queue's window fits
the narrowest open page."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import viser

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.queue import (
    KINEMATICS_ONLY,
    NOT_PROCESSED,
    PROCESSED,
    REVIEWED,
    build_queue,
    dataset_subjects,
    next_to_review,
)
from addb_viewer.app.workbench import Workbench, queue_markdown
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow
B3D = SHARED_DATA / "b3d" / "results.b3d"
SUBJECTS = {"labA/walk": "rajagopal2016_walk", "labB/run": "rajagopal2016_run"}


@pytest.fixture
def dataset(tmp_path: Path) -> Path:
    for rel, name in SUBJECTS.items():
        writable_copy(SHARED_DATA / "subjects" / name, tmp_path / "ds" / rel)
        assert not (tmp_path / "ds" / rel / "Geometry").exists()
    return tmp_path / "ds"


def test_workbench_processes_in_the_background_and_opens_subjects_from_the_queue(
    dataset: Path, make_app, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _, out, subjects = dataset_subjects(dataset)
    assert all(r.processing == NOT_PROCESSED for r in build_queue(subjects))
    first = subjects[0]
    app = make_app(ReviewPaths.for_subject(first.subject_dir, first.out_dir), process_missing=False)
    assert app.trial is None and not app.jobs.running  # the app does not process it itself
    (dataset / "labC").mkdir()
    shutil.copyfile(B3D, dataset / "labC" / "s03.b3d")  # no subject folder: neither processed nor listed
    notes_seen: list[str] = []

    class Recorded(Workbench):  # every content the window's notes take
        def _draw_notes(self) -> None:
            super()._draw_notes()
            notes_seen.append(self.notes.content)

    bench = Recorded(app, dataset, workers=1)
    bench.current = (first.rel, None)
    assert bench.processing_done.wait(600), bench.run_status.content
    # the window named the file the queue leaves out, once (the run told the same), and while
    # the run went on what it told its user; once it ended, the file alone (its dashboard is gone)
    seen = [c for c in notes_seen if "Dask workers" in c]
    assert seen and all(c.count("labC/s03.b3d") == 1 for c in seen), notes_seen
    assert "1 Dask workers, scheduler tcp://127.0.0.1:" in seen[-1]
    assert bench.notes.content == (
        "Not in the queue: labC/s03.b3d, a .b3d file (no subject folder): `addb convert FILE.b3d --out "
        "SUBJECT_DIR` makes a subject folder of one, `addb view FOLDER` reviews a folder of them."
    )
    rows = bench.refresh()
    listed = {(r.subject.rel, r.trial): r.processing for r in rows}
    assert listed == {  # labC's .b3d file is no subject
        ("labA/walk", "walk"): PROCESSED, ("labA/walk", "static"): KINEMATICS_ONLY,
        ("labB/run", "run"): PROCESSED, ("labB/run", "static"): KINEMATICS_ONLY,
    }  # fmt: skip
    assert (out / "labB" / "run" / "manifest.json").is_file()
    # while a subject ran, the queue showed its progress as its worker reported it
    assert {rel for rel, _ in bench.progress_seen} == {"labA/walk", "labB/run"}
    # reported at most every 0.5 s (solver.dataset.task.PROGRESS_INTERVAL_S), but the last report
    # always: each subject in order from its first report to its end (1.0). It used to ask for a
    # report past 50 %, which a quiet host no longer reached before the subjects ended, the last
    # report being held back by the interval (2026-11-29: 0.02, 0.40, 0.4997 for the walk)
    for rel in ("labA/walk", "labB/run"):
        fractions = [f for r, f in bench.progress_seen if r == rel]
        assert len(fractions) >= 2 and fractions == sorted(fractions) and fractions[-1] == 1.0, bench.progress_seen
    assert all(0.0 <= f <= 1.0 for _, f in bench.progress_seen)
    # the subject on screen was waiting for its output: it is shown once processed
    assert app.trial is not None and app.paths.subject_dir == first.subject_dir
    text = queue_markdown(rows)
    assert "labA/walk / walk" in text and "labB/run / run" in text
    # open the second subject from the dropdown: every body drawn as a mesh
    label = "labB/run / run"
    bench.choice.value = label
    assert app.paths.subject_dir == (dataset / "labB" / "run").resolve()
    assert app.trial is not None and app.trial.trial == "run" and app.scene is not None
    bodies = [b for b, m in app.trial.body_meshes.items() if m]
    assert bodies and all(isinstance(app.scene.bodies[b], viser.MeshHandle) for b in bodies)
    assert not app.panel.error.visible, app.panel.error.content
    # next trial to review: another unreviewed trial; a reviewed one is skipped
    row = bench.open_next()
    assert row is not None and (row.subject.rel, row.trial) != ("labB/run", "run")
    at_open = list(bench.rows)  # the queue as the reviewer sees it when the trial opens
    app.edit("trial reviewed", lambda ed, _k, _f: ed.set_reviewed(True))
    done = next(r for r in bench.rows if (r.subject.rel, r.trial) == (row.subject.rel, row.trial))
    assert done.review == REVIEWED and done.reviewer == "tester"
    seen = {(row.subject.rel, row.trial)}
    for _ in range(3):
        below = next_to_review(at_open, after=bench.current)
        nxt = bench.open_next()
        assert nxt is not None and (nxt.subject.rel, nxt.trial) not in seen
        # marking the trial reviewed sent it to the end of the queue; Next goes to the row that
        # was below it when it opened, not back to the top
        assert (nxt.subject.rel, nxt.trial) == (below.subject.rel, below.trial)
        at_open = list(bench.rows)
        seen.add((nxt.subject.rel, nxt.trial))
        app.edit("trial reviewed", lambda ed, _k, _f: ed.set_reviewed(True))
    assert bench.open_next() is None and "Every processed trial is reviewed" in bench.run_status.content
    shutil.rmtree(out)


def test_stopping_the_app_cancels_the_background_run_and_leaves_no_half_output(
    dataset: Path, make_app, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import json
    import time

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _, out, subjects = dataset_subjects(dataset)
    app = make_app(ReviewPaths.for_subject(subjects[1].subject_dir, subjects[1].out_dir), process_missing=False)
    bench = Workbench(app, dataset, workers=1)
    deadline = time.monotonic() + 120
    while not bench.running and time.monotonic() < deadline:  # the run has queued its subjects
        time.sleep(0.1)
    assert bench.running
    t0 = time.monotonic()
    bench.stop()
    assert bench.processing_done.is_set() and time.monotonic() - t0 < 60
    summary = json.loads((out / "dataset_summary.json").read_text())
    statuses = {s["rel"]: s["status"] for s in summary["subjects"]}
    assert "cancelled" in statuses.values() and "failed" not in statuses.values()
    for s in summary["subjects"]:  # a cancelled subject's output folder was never put in place
        if s["status"] == "cancelled":
            assert not (out / s["rel"] / "manifest.json").exists()
    assert not list(out.rglob(".addb-work-*"))


def test_the_queue_window_fits_the_narrowest_open_page(dataset: Path, make_app, tmp_path: Path, monkeypatch) -> None:
    """One queue window for every page: two pages report 900 and 400 px wide canvases and the
    window is 380 px (the narrow canvas less its gaps), with the compact table; when the
    narrow page closes, it widens to the other page's canvas (620 px at most) and the full
    table comes back."""
    from viewer_support import ProtocolClient, wait_for
    from viser import _messages

    from addb_viewer.app.workbench import COMPACT_BELOW_PX, QUEUE_GAP_PX, QUEUE_WIDTH_PX

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _, _, subjects = dataset_subjects(dataset)
    first = subjects[0]
    app = make_app(ReviewPaths.for_subject(first.subject_dir, first.out_dir), process_missing=False)
    bench = Workbench(app, dataset, workers=0)

    def page(width: int) -> ProtocolClient:
        before = set(app.name_fields)
        client = ProtocolClient(app.port)  # reports a 480 px canvas as it connects
        wait_for(lambda: set(app.name_fields) - before, 20, "the page connected")
        client.send(_messages.ViewerCameraMessage(
            wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 1.0, 3.0), fov=1.0, near=0.01, far=100.0, image_height=700,
            image_width=width, look_at=(0.0, 1.0, 0.0), up_direction=(0.0, 1.0, 0.0)))  # fmt: skip
        return client

    wide, narrow = page(900), page(400)
    try:
        wait_for(lambda: bench.width == 400 - 2 * QUEUE_GAP_PX, 20, "the window fitted to the narrow page")
        assert bench.width < COMPACT_BELOW_PX and "| state |" not in bench.table.content
        narrow.close()
        wait_for(lambda: bench.width == QUEUE_WIDTH_PX, 20, "the window widened when the narrow page closed")
        assert "| state |" in bench.table.content
    finally:
        wide.close()
        narrow.close()


def test_a_subject_is_named_by_its_place_in_the_dataset(dataset: Path, make_app, tmp_path: Path, monkeypatch) -> None:
    """Messages about a subject (a run cancelled by Open) name it as the queue does
    (``labB/run``), not by its folder's name alone (``run``, also the trial's name)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _, _, subjects = dataset_subjects(dataset)
    app = make_app(ReviewPaths.for_subject(subjects[0].subject_dir, subjects[0].out_dir), process_missing=False)
    paths = ReviewPaths.for_subject(subjects[1].subject_dir, subjects[1].out_dir)
    assert app._subject_label(paths) == paths.subject_dir.name  # no dataset: the folder's name
    Workbench(app, dataset, workers=0)
    assert app._subject_label(paths) == subjects[1].rel and "/" in subjects[1].rel


def test_the_window_names_the_b3d_files_the_queue_leaves_out(dataset: Path, make_app, tmp_path: Path, monkeypatch) -> None:
    """A dataset folder holding a ``.b3d`` file beside its subject folders: the queue lists the
    subject folders only, and its window names the file and how to review it; a file added
    later is named once the dataset is read again (Process changed subjects), one removed is
    no longer named."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _, _, subjects = dataset_subjects(dataset)
    app = make_app(ReviewPaths.for_subject(subjects[0].subject_dir, subjects[0].out_dir), process_missing=False)
    bench = Workbench(app, dataset, workers=0)
    assert bench.notes.content == ""  # nothing left out
    shutil.copyfile(B3D, dataset / "s03.b3d")
    bench.rediscover()
    assert {r.subject.rel for r in bench.refresh()} == set(SUBJECTS)
    assert bench.notes.content.startswith("Not in the queue: s03.b3d, a .b3d file (no subject folder)")
    assert "`addb view FOLDER`" in bench.notes.content
    for k in range(4, 9):  # more files: three named, the others counted
        shutil.copyfile(B3D, dataset / f"s0{k}.b3d")
    bench.rediscover()
    assert bench.notes.content.startswith("Not in the queue: s03.b3d, s04.b3d, s05.b3d and 3 more, 6 .b3d files")
    for k in range(3, 9):
        (dataset / f"s0{k}.b3d").unlink()
    bench.rediscover()
    assert bench.notes.content == ""


def test_the_window_names_a_symbolic_link_loop_it_did_not_search(dataset: Path, make_app, tmp_path: Path, monkeypatch) -> None:
    """A link leading back to a folder above it (``labX/up -> ../..``) is not followed by the
    dataset search (a loop); the dataset run names it on its terminal, and the workbench's
    window names it too, beside the .b3d files, and drops it once the link is gone."""
    from addb_viewer.app.queue import open_dataset
    from solver.dataset.discover import loop_note, scan_dataset

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _, _, subjects = dataset_subjects(dataset)
    app = make_app(ReviewPaths.for_subject(subjects[0].subject_dir, subjects[0].out_dir), process_missing=False)
    bench = Workbench(app, dataset, workers=0)
    (dataset / "labX").mkdir()
    (dataset / "labX" / "up").symlink_to("../..", target_is_directory=True)
    shutil.copyfile(B3D, dataset / "s03.b3d")
    bench.rediscover()
    assert {r.subject.rel for r in bench.refresh()} == set(SUBJECTS)
    assert bench.notes.content.startswith("Not in the queue: s03.b3d")
    assert "Not searched: labX/up, a symbolic link leading back to a folder above (a loop)." in bench.notes.content
    run_notes = open_dataset(dataset).notes[1]
    assert run_notes[1] == loop_note(scan_dataset(dataset)) and "labX/up" in run_notes[1]
    bench._run_note(run_notes[1])  # the background run's message about the same link: shown once
    assert bench.notes.content.count("labX/up") == 1
    bench._run_notes = []  # that run ended
    (dataset / "labX" / "up").unlink()
    (dataset / "s03.b3d").unlink()
    bench.rediscover()
    assert bench.notes.content == ""


def test_the_workbench_searches_the_dataset_folder_once(dataset: Path, make_app, tmp_path: Path, monkeypatch) -> None:
    """Opening the workbench and reading the dataset again each searched the dataset folder
    twice (once for the subjects, once for the .b3d files the queue leaves out); one search
    now gives both, the same as the two calls apart."""
    import addb_viewer.app.queue as queue_module
    from addb_viewer.app.queue import open_dataset
    from solver.dataset.discover import b3d_note, scan_dataset

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    shutil.copyfile(B3D, dataset / "s03.b3d")
    opened = open_dataset(dataset)
    assert (opened.dataset_dir, opened.out_dir, opened.subjects) == dataset_subjects(dataset)
    note, run_notes = opened.notes
    assert note.startswith("Not in the queue: s03.b3d, a .b3d file") and run_notes == (b3d_note(scan_dataset(dataset)),)
    searches = []
    real = queue_module.scan_dataset
    monkeypatch.setattr(queue_module, "scan_dataset", lambda *a, **k: searches.append(a) or real(*a, **k))
    app = make_app(ReviewPaths.for_subject(opened.subjects[0].subject_dir, opened.subjects[0].out_dir), process_missing=False)
    bench = Workbench(app, dataset, workers=0)
    assert len(searches) == 1 and bench.notes.content.startswith("Not in the queue: s03.b3d")
    bench.rediscover()
    assert len(searches) == 2
