"""Reviewer flows of ``addb view DATASET_DIR`` found by an exploration of the workbench, each
on a dataset of the shared walk (``labA/walk``) and a copy whose marker file has a garbage
frame (``labA/broken``), processed once by ``addb process`` and copied for each test:

* another trial of the subject on screen opened from the queue keeps its review record
  open, so Undo still reaches the edits made before (it answered "Nothing to do");
* a subject whose background run finishes while one of its trials is on screen is reloaded
  (the page showed the old residuals beside a queue row with the new ones);
* a failed subject opened from the queue empties the previous trial's controls and says its
  error in full (the table cuts it at 80 characters, losing the file and line);
* a trial picked in the Playback folder's Trial list becomes the queue's current row;
* "Process changed subjects" processes a failed subject again once its file is mended (the
  background run at the start skips a subject that failed on the same inputs), lists a
  subject folder added since the app started (it was processed but never shown), and says
  so when the subject on screen fails (the page went on showing its earlier output silently);
* Undo whose last edit is on another trial than the one shown undoes nothing and names that
  trial (it removed frames the reviewer could not see, saying only "saved: undo");
* "Every processed trial is reviewed." goes once a trial needs review again;
* rejected proposals of a trial with no flag, not marked reviewed, are said to be still left
  out of the fit (the solver keeps its own choice until then)."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from viewer_support import wait_for

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.queue import dataset_subjects
from addb_viewer.app.workbench import Workbench
from addb_viewer.cli import main as cli
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow
BAD_LINE = 106  # the marker file's line of frame 100 (6 header lines)


@pytest.fixture(scope="module")
def processed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The dataset and its output tree (``addb_out``), processed once."""
    root = tmp_path_factory.mktemp("flows")
    ds = root / "ds"
    writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", ds / "labA" / "walk")
    broken = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", ds / "labA" / "broken")
    trc = broken / "trials" / "walk" / "markers.trc"
    lines = trc.read_text(encoding="utf-8").splitlines(keepends=True)
    assert lines[BAD_LINE - 1].startswith("100\t")
    lines[BAD_LINE - 1] = "100\t0.99000\tgarbage here\n"
    trc.write_text("".join(lines), encoding="utf-8")
    assert cli(["process", str(ds), "--out", str(ds / "addb_out"), "--workers", "1"]) == 1  # the broken subject fails
    return ds


@pytest.fixture
def dataset(processed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return Path(shutil.copytree(processed, tmp_path / "ds"))


def _bench(dataset: Path, make_app, workers: int = 0) -> tuple[object, Workbench]:
    _, _, subjects = dataset_subjects(dataset)
    walk = next(s for s in subjects if s.rel == "labA/walk")
    app = make_app(ReviewPaths.for_subject(walk.subject_dir, walk.out_dir), process_missing=False)
    app.load_trial("walk")
    bench = Workbench(app, dataset, workers=workers)
    bench.current = ("labA/walk", "walk")
    return app, bench


def _flagged(app) -> list[int]:
    return np.flatnonzero(app.store.mask("walk", app.trial.n_frames if app.trial.trial == "walk" else 238)).tolist()


def test_opening_another_trial_of_the_subject_keeps_the_undo_history(dataset: Path, make_app) -> None:
    app, bench = _bench(dataset, make_app)
    proposed = set(np.flatnonzero(app.trial.proposed).tolist())
    app.select(100, 109)
    app.selection_edit("Flag")
    assert set(range(100, 110)) <= set(_flagged(app))
    bench.open("labA/walk", "static")
    assert app.trial.trial == "static"
    bench.open("labA/walk", "walk")
    app.history("Undo")
    assert not set(range(100, 110)) & (set(_flagged(app)) - proposed), app.panel.saved.content


def test_a_trial_on_screen_is_reloaded_when_its_background_run_ends(dataset: Path, make_app) -> None:
    """Flags edited before the workbench starts change the subject's review: the background
    run processes it again, and the trial on screen shows the new result, at the frame it
    showed and with its in and out points."""
    _, _, subjects = dataset_subjects(dataset)
    walk = next(s for s in subjects if s.rel == "labA/walk")
    app = make_app(ReviewPaths.for_subject(walk.subject_dir, walk.out_dir), process_missing=False)
    app.load_trial("walk")
    before = app.trial
    app.edit("accept all", lambda ed, _k, _f: ed.accept())
    app.select(100, 129)
    app.selection_edit("Flag")
    assert "fitted with other flags" in app.panel.proposal_info.content  # not processed with them yet
    app.select(10, 20)  # the reviewer's in and out points survive the reload
    app.seek(57)  # and so does the frame shown
    app.panel.comparison.content = "Reprocess result: walk (an earlier run's table)"
    bench = Workbench(app, dataset, workers=1)
    bench.current = ("labA/walk", "walk")
    assert bench.processing_done.wait(600), bench.run_status.content
    after = load_processed(walk.out_dir, "walk")
    assert "fitted with other flags" not in app.panel.proposal_info.content, app.panel.proposal_info.content
    assert after.unobserved[100:130].all() and not before.unobserved[100:130].all()  # processed again
    assert app.trial.trial == "walk" and np.array_equal(app.trial.unobserved, after.unobserved)
    assert "reloaded" in app.panel.job_status.content, app.panel.job_status.content
    assert app.panel.comparison.content == ""  # the earlier table no longer describes the output
    assert app.playback.selection() == (10, 21)
    assert app.playback.frame == 57
    # the timeline's "left out" track shows the flagged frames the fit left out (not proposals)
    assert app.tracks.masks["left out"][100:130].all() and not app.tracks.masks["proposal"][100:130].any()
    assert np.array_equal(app.tracks.masks["left out"], after.unobserved)
    assert "without a foot" in app.panel.proposal_info.content  # the accepted proposals
    app.seek(110)  # a flagged frame the fit left out: the status line says so
    assert "left out of the fit" in app.panel.status.content, app.panel.status.content


def test_a_failed_subject_empties_the_trial_controls_and_says_its_error(dataset: Path, make_app) -> None:
    app, bench = _bench(dataset, make_app)
    app.select(100, 109)
    app.selection_edit("Flag")
    bench.open("labA/broken")
    assert app.trial is None
    status = app.panel.status.content
    assert "failed" in status and f"markers.trc:{BAD_LINE}" in status, status
    p = app.panel
    assert p.timeline.content == "" and p.reviewed.disabled and not p.reviewed.value and p.frame.disabled
    assert "flagged" not in p.proposal_info.content, p.proposal_info.content
    bench.open("labA/walk", "walk")  # and back: the controls work again
    assert app.trial.trial == "walk" and not p.reviewed.disabled and not p.frame.disabled and p.timeline.content



def test_a_run_waiting_for_the_background_plan_is_dropped_when_another_subject_opens(
    dataset: Path, make_app, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Reprocess pressed while the page's background run has not said what it processes
    waits for that; opening another subject in the queue drops it, as it cancels a run going
    (the page says so, naming both subjects), and nothing starts when the plan comes."""
    from addb_viewer.app import reprocess
    from solver.dataset.lock import output_tree_lock

    monkeypatch.setattr(reprocess, "SolverJob", _HeldJob)
    monkeypatch.setattr(reprocess, "PLAN_POLL_S", 0.02)
    app, bench = _bench(dataset, make_app)
    app.edit("accept all", lambda ed, _k, _f: ed.accept())  # no pending proposal to confirm
    with output_tree_lock(dataset / "addb_out"):  # the page's own background run holds the tree
        bench.processing_done.clear()
        app.jobs.reprocess("walk")
        assert app.jobs.running and app.jobs.job is None, app.panel.job_status.content
        bench.open("labA/broken")
        assert not app.jobs.running and app.jobs.job is None
        status = app.panel.job_status.content
        assert status == "labA/walk · Reprocessing walk: cancelled before it started. (you opened labA/broken)", status
        with bench._lock:
            bench._planned = True  # the plan comes: the dropped run stays dropped
        time.sleep(0.2)
        assert app.jobs.job is None and not app.jobs.running
        bench.processing_done.set()

def test_a_trial_picked_in_the_trial_list_becomes_the_queue_row(dataset: Path, make_app) -> None:
    app, bench = _bench(dataset, make_app)
    app._trial_picked("static")
    assert bench.current == ("labA/walk", "static")
    assert bench.choice.value == "labA/walk / static", bench.choice.value


def test_rejections_alone_are_said_to_leave_the_solver_its_choice(dataset: Path, make_app) -> None:
    app, _ = _bench(dataset, make_app)
    n = int(app.trial.proposed.sum())
    assert n > 0
    app.edit("reject all", lambda ed, _k, _f: ed.reject())
    assert f"{n} rejected proposed frames are still left out of the fit" in app.panel.proposal_info.content
    app.edit("reviewed", lambda ed, _k, _f: ed.set_reviewed(True))
    assert "still left out" not in app.panel.proposal_info.content


def test_undo_of_an_edit_on_another_trial_names_it(dataset: Path, make_app) -> None:
    app, _ = _bench(dataset, make_app)
    app.load_trial("static")
    app.select(10, 19)
    app.selection_edit("Flag")
    assert "on static" in app.panel.saved.content  # the saved line names the trial
    app.load_trial("walk")
    app.history("Undo")
    assert "not undone" in app.panel.saved.content and "trial static" in app.panel.saved.content
    static = app.store.mask("static", 10_000)
    assert static[10:20].all()  # still flagged
    app.load_trial("static")
    app.history("Undo")
    assert not app.store.mask("static", 10_000)[10:20].any()


def test_a_mended_subject_is_processed_again_from_the_page(dataset: Path, make_app) -> None:
    from addb_viewer.app.queue import FAILED, KINEMATICS_ONLY, PROCESSED

    _, bench = _bench(dataset, make_app, workers=1)
    assert bench.processing_done.wait(600), bench.run_status.content

    def state() -> str:
        return next(r.processing for r in bench.refresh() if r.subject.rel == "labA/broken" and r.trial in (None, "walk"))

    assert state() == FAILED  # the same inputs failed before: not run again
    shutil.copy(SHARED_DATA / "subjects" / "rajagopal2016_walk" / "trials" / "walk" / "markers.trc",
                dataset / "labA" / "broken" / "trials" / "walk" / "markers.trc")  # fmt: skip
    # a subject folder added while the app runs, and the subject on screen broken on disk
    writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", dataset / "labB" / "added")
    trc = dataset / "labA" / "walk" / "trials" / "walk" / "markers.trc"
    lines = trc.read_text(encoding="utf-8").splitlines(keepends=True)
    lines[BAD_LINE - 1] = "100\t0.99000\tgarbage here\n"
    trc.write_text("".join(lines), encoding="utf-8")
    assert bench.process_again()
    assert not bench.process_again() and "running already" in bench.run_status.content
    assert bench.processing_done.wait(600), bench.run_status.content
    assert state() == PROCESSED, bench.run_status.content
    # the line counts what the run did (a run with nothing to do read as the one before), the
    # failed subject apart from the two processed (it said "3 subject(s) processed ...; 1 failed")
    assert "2 subject(s) processed, 0 up to date; 1 failed." in bench.run_status.content, bench.run_status.content
    added = [r for r in bench.rows if r.subject.rel == "labB/added"]
    assert {r.trial: r.processing for r in added} == {"static": KINEMATICS_ONLY, "walk": PROCESSED}, added
    assert "labB/added / walk" in bench.labels  # Open lists it
    # the page still shows the walk's earlier output, and says that its subject failed
    app = bench.app
    assert app.trial is not None and app.trial.trial == "walk" and app.panel.error.visible
    error = app.panel.error.content
    assert "labA/walk failed when processed again in the background" in error and f"markers.trc:{BAD_LINE}" in error, error
    bench.workers = 0
    assert not bench.process_again() and "--workers 0" in bench.run_status.content


def test_all_reviewed_is_taken_back_when_a_trial_needs_review_again(dataset: Path, make_app) -> None:
    from addb_viewer.app.workbench import ALL_REVIEWED

    app, bench = _bench(dataset, make_app)
    for trial in ("walk", "static"):
        app.load_trial(trial)
        app.edit("reviewed", lambda ed, _k, _f: ed.set_reviewed(True))
    assert bench.open_next() is None and bench.run_status.content == ALL_REVIEWED
    app.edit("not reviewed", lambda ed, _k, _f: ed.set_reviewed(False))  # static again
    bench.refresh()
    assert bench.run_status.content == ""


def test_a_reprocess_keeps_the_dataset_manifest_current(dataset: Path, make_app) -> None:
    """After a Reprocess with the reviewer's flags the subject's manifest records those flags
    and the new figures, so the next dataset run (and Process changed subjects) skips it:
    it processed again a subject just fitted with the same flags. Once an input changed, a
    Reprocess leaves the manifest alone (the dataset run must process the subject)."""
    from addb_viewer.app.dataset_manifest import mark_reprocessed
    from addb_viewer.review_masks import review_digest
    from solver.dataset.manifest import current_manifest, manifest_key, read_manifest

    app, _ = _bench(dataset, make_app)
    subject, out = app.paths.subject_dir, app.paths.out_dir
    settings = read_manifest(out)["key"]["settings"]
    app.edit("accept all", lambda ed, _k, _f: ed.accept())
    app.select(100, 129)
    app.selection_edit("Flag")
    digest = review_digest(str(subject), str(out))
    assert current_manifest(out, manifest_key(subject, settings, digest)) is None  # flags changed: a run would redo it
    app.jobs.reprocess()
    assert app.jobs.finished.wait(300) and app.jobs.last_result.status == "done", app.panel.job_status.content
    # the output records the review record whose flags the run took
    assert json.loads((out / "subject.json").read_text())["review_record"] == str(app.paths.annotations.resolve())
    stored = current_manifest(out, manifest_key(subject, settings, digest))
    assert stored is not None, read_manifest(out)["key"]["annotations"]
    row = next(r for r in stored["trials"] if r["trial"] == "walk")
    results = json.loads((out / "walk" / "results.json").read_text())
    assert row["measured_frames"] == results["n_observed_frames"] and row["measured_frames"] < 238 - 30
    # an input changed since the dataset run: left for the dataset run to process
    (subject / "_subject.json").write_text((subject / "_subject.json").read_text() + "\n")
    before = (out / "manifest.json").read_bytes()
    assert not mark_reprocessed(subject, out, digest)
    assert (out / "manifest.json").read_bytes() == before


class _HeldJob:
    """A solver job that runs until the test ends it (no child process): the page's run
    state while it goes is what the test looks at."""

    def __init__(self, spec: object, work: object, *, on_progress: object, on_done) -> None:
        self.on_done, self.running = on_done, False

    def start(self) -> None:
        self.running = True

    def end(self) -> None:
        from addb_viewer.app.jobs import JobResult

        self.running = False
        self.on_done(JobResult("cancelled", None, 0.0))

    def cancel(self) -> None:  # the app's stop
        if self.running:
            self.end()

    def wait(self, timeout: float | None = None) -> None:
        pass

    def cleanup(self) -> None:
        pass


def _tree_free(tree: Path) -> bool:
    from solver.dataset.lock import output_tree_lock
    from solver.errors import DatasetError

    try:
        with output_tree_lock(tree):
            return True
    except DatasetError:
        return False


_STARTED_SPECS: list = []  # the specs _SpecJob was made with (the test empties it first)


class _SpecJob(_HeldJob):
    """A held job that keeps the spec it was made with, in :data:`_STARTED_SPECS`."""

    def __init__(self, spec: object, work: object, *, on_progress: object, on_done) -> None:
        super().__init__(spec, work, on_progress=on_progress, on_done=on_done)
        _STARTED_SPECS.append(spec)


def test_a_run_waiting_for_the_background_plan_takes_the_flags_as_they_are_when_it_starts(
    dataset: Path, make_app, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Reprocess pressed while the page's background run has not said what it processes
    waits for that; frames flagged meanwhile (the page stays open for review) enter the run
    that starts (it took the flags of the moment it was pressed)."""
    from addb_viewer.app import reprocess
    from solver.dataset.lock import output_tree_lock

    monkeypatch.setattr(reprocess, "SolverJob", _SpecJob)
    _STARTED_SPECS.clear()
    monkeypatch.setattr(reprocess, "PLAN_POLL_S", 0.02)
    app, bench = _bench(dataset, make_app)
    app.edit("accept all", lambda ed, _k, _f: ed.accept())  # no pending proposal to confirm
    tree = dataset / "addb_out"
    with output_tree_lock(tree):  # the page's own background run holds the tree
        bench.processing_done.clear()
        assert app.background_run() == "starting"
        app.jobs.reprocess("walk")
        assert app.jobs.running and app.jobs.job is None, app.panel.job_status.content
        before = set(_flagged(app))
        lo = next(k for k in range(238 - 7) if not before & set(range(k, k + 7)))  # 7 frames not flagged yet
        app.edit("flag", lambda ed, _k, _f: ed.flag_range(lo, lo + 7, "left"))  # flagged while it waits (end exclusive)
        with bench._lock:
            bench._planned = True  # the plan leaves this subject out: the run goes
        wait_for(lambda: app.jobs.job is not None, timeout=10.0, what="the waiting run to start")
        (spec,) = _STARTED_SPECS
        taken = np.flatnonzero(spec.unmeasured_force["walk"]).tolist()
        assert set(range(lo, lo + 7)) <= set(taken) and set(taken) == set(_flagged(app)), (lo, taken, _flagged(app))
        app.jobs.job.end()
    bench.processing_done.set()


def test_a_solver_run_from_the_page_holds_the_output_tree(dataset: Path, make_app, monkeypatch: pytest.MonkeyPatch) -> None:
    """A Reprocess (or diagnosis) from the page writes the subject's folder in the dataset's
    output tree: it holds the tree's lock as ``addb process SUBJECT --out OUT/labA/s01`` does
    (it wrote while another addb run could be writing the tree). Refused, with the holder
    named and nothing started, while another run holds the tree; held while it goes (a
    dataset run started meanwhile is refused, and so is "Process changed subjects"); freed
    when it ends. Under the workbench's own background run (whose lock this process holds)
    it starts unless that run processes the subject, and holds the tree until it ends even if
    that run ends first; pressed before that run has said what it processes, it waits for that
    (Cancel drops it), then starts or is refused."""
    from addb_viewer.app import reprocess
    from solver.dataset.lock import output_tree_lock

    monkeypatch.setattr(reprocess, "SolverJob", _HeldJob)
    app, bench = _bench(dataset, make_app)
    tree = dataset / "addb_out"
    app.edit("accept all", lambda ed, _k, _f: ed.accept())  # no pending proposal to confirm
    with output_tree_lock(tree):  # another run (its lock file names this process)
        app.jobs.reprocess("walk")
    status = app.panel.job_status.content
    assert app.jobs.job is None and "Reprocessing walk: not started" in status, status
    assert "another addb run is writing this output tree (process " in status, status
    assert not app.panel.reprocess.disabled and not app.panel.progress.visible and not app.panel.cancel.visible

    app.jobs.reprocess("walk")
    job = app.jobs.job
    assert job is not None and job.running and not _tree_free(tree)
    bench.workers = 1  # "Process changed subjects" would process the subject this run writes
    assert not bench.process_again() and "in progress" in bench.run_status.content, bench.run_status.content
    job.end()
    assert _tree_free(tree) and not app.jobs.running

    # the workbench's own background run holds the tree in this process; pressed before it
    # has said what it processes, a run waits for that (it was refused), then goes or not
    monkeypatch.setattr(reprocess, "PLAN_POLL_S", 0.02)
    with output_tree_lock(tree):
        bench.processing_done.clear()
        assert app.background_run() == "starting"
        app.jobs.reprocess("walk")
        waiting = app.panel.job_status.content
        assert app.jobs.running and app.jobs.job is job and "waiting until the background processing says" in waiting, waiting
        assert app.panel.reprocess.disabled and app.panel.cancel.visible
        app.jobs.cancel(wait=True)  # Cancel drops it
        assert not app.jobs.running and app.jobs.job is job and not app.panel.reprocess.disabled
        assert app.panel.job_status.content == "Reprocessing walk: cancelled before it started."
        app.jobs.reprocess("walk")
        with bench._lock:
            bench._planned, bench.running["labA/walk"] = True, "queued"  # the plan processes this subject
        wait_for(lambda: not app.jobs.running, timeout=10.0, what="the waiting run to be refused")
        assert app.jobs.job is job and "Reprocessing walk: not started" in app.panel.job_status.content
        assert "has this subject queued" in app.panel.job_status.content and not app.panel.reprocess.disabled
        with bench._lock:
            bench._planned = False
            bench.running.clear()
        app.jobs.reprocess("walk")
        assert app.jobs.running and app.jobs.job is job
        with bench._lock:
            bench._planned = True  # the plan leaves this subject out: the run goes
        wait_for(lambda: app.jobs.job is not job, timeout=10.0, what="the waiting run to start")
        assert app.jobs.job.running and app.jobs.running
        app.jobs.job.end()
        job = app.jobs.job
        bench.running["labA/walk"] = "queued"
        assert app.background_run() == "queued"
        app.jobs.diagnose("walk")
        assert "Diagnosing walk: not started" in app.panel.job_status.content and "has this subject queued" in app.panel.job_status.content
        assert not app.panel.reprocess.disabled  # the page can try again
        bench.running.clear()  # the run goes on with other subjects: the Reprocess joins its hold
        app.jobs.reprocess("walk")
        assert app.jobs.job is not job and app.jobs.running, app.panel.job_status.content
    bench.processing_done.set()  # the background run ended first: the Reprocess still holds the tree
    assert app.jobs.job.running and not _tree_free(tree)
    app.jobs.job.end()
    assert _tree_free(tree)
