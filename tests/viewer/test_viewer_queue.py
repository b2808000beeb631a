"""The review queue of a dataset (no browser): processing and review states, pending
proposals, the order a reviewer works in, and the "next trial to review"; a damaged review
record named as such."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.app.queue import (
    FAILED,
    IN_REVIEW,
    KINEMATICS_ONLY,
    NOT_PROCESSED,
    PROCESSED,
    PROCESSING,
    RECORD_UNREADABLE,
    REVIEWED,
    UNREVIEWED,
    build_queue,
    dataset_subjects,
    is_dataset,
    next_to_review,
)
from addb_viewer.app.workbench import queue_markdown
from addb_viewer.locations import annotations_path
from annotations import AnnotationStore
from solver.dataset.manifest import MANIFEST_NAME
from solver.dataset.summary import subject_rows
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture
def walk_output(walk_processed: Path) -> Path:
    return walk_processed


@pytest.fixture
def dataset(tmp_path: Path, walk_output: Path) -> Path:
    """Five copies of the walk: fresh, reviewed by alice, in review by bob (two proposed
    frames flagged), failed, not processed; outputs in <dataset>/addb_out."""
    root = tmp_path / "ds"
    rows = subject_rows(walk_output)
    for name in ("fresh", "done", "busy", "broken", "waiting"):
        writable_copy(WALK, root / "lab" / name)
    out = root / "addb_out" / "lab"
    for name in ("fresh", "done", "busy"):
        shutil.copytree(walk_output, out / name)
        (out / name / MANIFEST_NAME).write_text(json.dumps({"key": {}, "status": "ok", "trials": rows}))
    (out / "broken").mkdir(parents=True)
    (out / "broken" / MANIFEST_NAME).write_text(json.dumps({"key": {}, "status": "failed", "trials": [], "error": {
        "type": "TrcFormatError", "message": "bad row", "path": "/x/markers.trc", "line": 121}}))  # fmt: skip
    with AnnotationStore.open(annotations_path(root / "lab" / "done", out / "done"), reviewer="alice") as s:
        s.set_reviewed("walk")
    walk = next(r for r in rows if r["trial"] == "walk")
    first = walk["proposed_ranges"][0][0]
    with AnnotationStore.open(annotations_path(root / "lab" / "busy", out / "busy"), reviewer="bob") as s:
        s.set_unmeasured("walk", [first, first + 1])
    return root


def test_queue_states_reviewers_and_pending_proposals(dataset: Path, walk_output: Path) -> None:
    assert is_dataset(dataset) and not is_dataset(dataset / "lab" / "fresh")
    _, out, subjects = dataset_subjects(dataset)
    assert out == (dataset / "addb_out").resolve() and [s.rel for s in subjects] == [
        "lab/broken", "lab/busy", "lab/done", "lab/fresh", "lab/waiting"]  # fmt: skip
    rows = build_queue(subjects, running={"lab/waiting": "kinematics 40 %"})
    by = {(r.subject.rel, r.trial): r for r in rows}
    proposed = int(sum(b - a for a, b in next(
        r for r in subject_rows(walk_output) if r["trial"] == "walk")["proposed_ranges"]))  # fmt: skip
    assert proposed > 2
    assert by[("lab/fresh", "walk")].pending == proposed and by[("lab/fresh", "walk")].review == UNREVIEWED
    assert by[("lab/busy", "walk")].pending == proposed - 2
    assert (by[("lab/busy", "walk")].review, by[("lab/busy", "walk")].reviewer) == (IN_REVIEW, "bob")
    assert (by[("lab/done", "walk")].review, by[("lab/done", "walk")].reviewer) == (REVIEWED, "alice")
    assert by[("lab/done", "static")].processing == KINEMATICS_ONLY
    assert by[("lab/fresh", "walk")].processing == PROCESSED and by[("lab/fresh", "walk")].measured_frames > 0
    assert by[("lab/broken", None)].processing == FAILED and "markers.trc:121" in by[("lab/broken", None)].detail
    assert by[("lab/waiting", None)].processing == PROCESSING
    results = json.loads((walk_output / "walk" / "results.json").read_text())
    assert by[("lab/fresh", "walk")].marker_rms_m == pytest.approx(results["marker_rms_m"], abs=1e-15)
    # order: trials with pending proposals first (most pending first), failed, running, reviewed last
    order = [(r.subject.rel, r.trial) for r in rows]
    assert order[:2] == [("lab/fresh", "walk"), ("lab/busy", "walk")]
    assert order.index(("lab/broken", None)) < order.index(("lab/waiting", None)) < order.index(("lab/done", "walk"))
    assert next_to_review(rows).trial == "walk" and next_to_review(rows).subject.rel == "lab/fresh"
    assert next_to_review(rows, after=("lab/fresh", "walk")).subject.rel == "lab/busy"
    # the summary line: subject states with the subjects, the review count with the trials
    # (it read "5 subjects, 6 trials: 1 reviewed, 1 processing, 1 failed")
    n_trials = sum(r.trial is not None for r in rows)
    head = queue_markdown(rows).splitlines()[0]
    assert head == f"**5 subjects (1 processing, 1 failed), {n_trials} trials: 1 reviewed**", head
    # an edit after the trial was marked reviewed is named beside the mark (the mark stays)
    with AnnotationStore.open(annotations_path(dataset / "lab" / "done", out / "lab" / "done"), reviewer="carol") as s:
        s.set_unmeasured("walk", [5])
    done = next(r for r in build_queue(subjects) if (r.subject.rel, r.trial) == ("lab/done", "walk"))
    assert (done.review, done.reviewer) == (REVIEWED, "alice, edited since by carol")
    assert "reviewed (alice, edited since by carol)" in queue_markdown([done])
    with AnnotationStore.open(annotations_path(dataset / "lab" / "done", out / "lab" / "done"), reviewer="dave") as s:
        s.set_unmeasured("walk", [6])  # everyone else who edited since, in order (carol was dropped)
    with AnnotationStore.open(annotations_path(dataset / "lab" / "done", out / "lab" / "done"), reviewer="alice") as s:
        s.set_unmeasured("walk", [7])  # the one who marked it is not listed
    done = next(r for r in build_queue(subjects) if (r.subject.rel, r.trial) == ("lab/done", "walk"))
    assert done.reviewer == "alice, edited since by carol, dave"
    # a trial in review names everyone who edited it, the last editor first (it named bob only
    # once erin had edited after him, and a team could not tell that bob was on it too)
    with AnnotationStore.open(annotations_path(dataset / "lab" / "busy", out / "lab" / "busy"), reviewer="erin") as s:
        s.set_unmeasured("walk", [3])
    busy = next(r for r in build_queue(subjects) if (r.subject.rel, r.trial) == ("lab/busy", "walk"))
    assert (busy.review, busy.reviewer) == (IN_REVIEW, "erin, bob")
    # a subject processed again keeps its trials, review states and figures, marked as
    # processing (they collapsed into one row: Open lost the trial on screen, the reviewed
    # count dropped); the summary counts it once
    again = build_queue(subjects, running={"lab/done": "40 %: inverse kinematics"})
    done_rows = {r.trial: r for r in again if r.subject.rel == "lab/done"}
    assert set(done_rows) == {"walk", "static"} and all(r.processing == PROCESSING for r in done_rows.values())
    assert done_rows["walk"].review == REVIEWED and done_rows["walk"].marker_rms_m == by[("lab/done", "walk")].marker_rms_m
    assert "processing: 40 %: inverse kinematics" in queue_markdown(again)
    assert queue_markdown(again).splitlines()[0].startswith("**5 subjects (1 processing, 1 failed)")
    # without a process running, the waiting subject is simply not processed
    assert next(r for r in build_queue(subjects) if r.subject.rel == "lab/waiting").processing == NOT_PROCESSED


def test_a_dataset_output_tree_opens_the_same_queue(dataset: Path) -> None:
    root, out, subjects = dataset_subjects(dataset)
    summary = {"dataset": str(root), "subjects": [{"rel": s.rel} for s in subjects]}
    (out / "dataset_summary.json").write_text(json.dumps(summary))
    root2, out2, subjects2 = dataset_subjects(out)
    assert (root2, out2) == (root, out) and subjects2 == subjects
    assert [r.attention for r in build_queue(subjects2)] == [r.attention for r in build_queue(subjects)]


def test_next_to_review_goes_round_every_unreviewed_row(tmp_path: Path) -> None:
    """Pressing R again and again visits every row that needs review, in queue order, and
    starts from the first when the trial on screen is not known yet (rel, None)."""
    from types import SimpleNamespace

    def row(rel: str, trial: str, needs: bool) -> SimpleNamespace:
        return SimpleNamespace(subject=SimpleNamespace(rel=rel), trial=trial, needs_review=needs)

    rows = [row("a", "t1", True), row("b", "t1", True), row("c", "t1", False), row("d", "t1", True)]
    seen, after = [], None
    for _ in range(4):
        nxt = next_to_review(rows, after=after)
        after = (nxt.subject.rel, nxt.trial)
        seen.append(nxt.subject.rel)
    assert seen == ["a", "b", "d", "a"]  # c is reviewed; after d the queue starts again
    assert next_to_review(rows, after=("b", None)).subject.rel == "a"
    assert next_to_review([row("a", "t1", True)], after=("a", "t1")) is None  # never the row on screen


def test_next_to_review_reads_after_in_the_order_the_reviewer_saw() -> None:
    """The reviewer opens the top row and accepts its proposals: it sinks below rows that
    still need review. Next goes to the row that was below it when it was opened, not past
    the rows it overtook on its way down (the explorer's report: R skipped three trials)."""
    from types import SimpleNamespace

    def row(rel: str, needs: bool) -> SimpleNamespace:
        return SimpleNamespace(subject=SimpleNamespace(rel=rel), trial="t", needs_review=needs)

    seen = [("a", "t"), ("b", "t"), ("c", "t"), ("d", "t")]  # a on screen, at the top
    now = [row("b", True), row("c", True), row("a", True), row("d", True), row("e", True)]  # a sank, e is new
    assert next_to_review(now, after=("a", "t")).subject.rel == "d"  # queue order alone: past b and c
    assert next_to_review(now, after=("a", "t"), order=seen).subject.rel == "b"
    visits, after = [], ("a", "t")
    for _ in range(5):
        nxt = next_to_review(now, after=after, order=seen)
        after = (nxt.subject.rel, nxt.trial)
        visits.append(nxt.subject.rel)
    assert visits == ["b", "c", "d", "e", "a"]  # every row, the new one after the seen ones


def test_a_reprocess_after_the_dataset_run_shows_its_figures_in_the_queue(dataset: Path) -> None:
    """The review app's Reprocess rewrites a trial's results.json, not the dataset run's
    manifest: the queue takes that trial's figures from the newer results.json, and its
    pending proposals from the trial.npz written with it."""
    import os

    _, out, subjects = dataset_subjects(dataset)
    res = out / "lab" / "fresh" / "walk" / "results.json"
    m = json.loads(res.read_text())
    before = {(r.subject.rel, r.trial): r for r in build_queue(subjects)}[("lab/fresh", "walk")]
    assert before.marker_rms_m == pytest.approx(m["marker_rms_m"])
    m.update(marker_rms_m=0.0131, n_observed_frames=m["n_observed_frames"] - 14, hicks_linear_ok=False)
    res.write_text(json.dumps(m))
    manifest = out / "lab" / "fresh" / MANIFEST_NAME
    os.utime(res, ns=(manifest.stat().st_mtime_ns + 10**9,) * 2)  # written after the run
    after = {(r.subject.rel, r.trial): r for r in build_queue(subjects)}[("lab/fresh", "walk")]
    assert after.marker_rms_m == 0.0131 and after.measured_frames == before.measured_frames - 14
    assert after.hicks_linear_ok is False and after.pending == before.pending  # trial.npz unchanged
    # the Reprocess's fit proposes more frames (its trial.npz, written with results.json)
    npz = res.parent / "trial.npz"
    with np.load(npz) as z:
        arrays = dict(z)
    unmeasured = np.flatnonzero(~arrays["proposed"])[:9]
    arrays["proposed"][unmeasured] = True
    np.savez(npz, **arrays)
    os.utime(npz, ns=(manifest.stat().st_mtime_ns + 10**9,) * 2)
    again = {(r.subject.rel, r.trial): r for r in build_queue(subjects)}[("lab/fresh", "walk")]
    assert again.pending == before.pending + 9 and again.frames == before.frames
    os.utime(res, ns=(manifest.stat().st_mtime_ns - 10**9,) * 2)  # older than the manifest: the manifest counts
    assert {(r.subject.rel, r.trial): r for r in build_queue(subjects)}[("lab/fresh", "walk")].marker_rms_m == before.marker_rms_m


def test_a_damaged_review_record_is_named_in_the_queue_not_shown_unreviewed(dataset: Path) -> None:
    """bob's record of lab/busy cut short on disk (a full disk, a bad copy): its trials say
    "record unreadable" (not "unreviewed", which would send a second reviewer over work
    already done), with no pending count (the flags are unknown), and they come first."""
    _, out, subjects = dataset_subjects(dataset)
    record = annotations_path(dataset / "lab" / "busy", out / "lab" / "busy")
    text = record.read_text()
    record.write_text(text[: len(text) // 2])
    rows = build_queue(subjects)
    busy = [r for r in rows if r.subject.rel == "lab/busy"]
    assert {r.trial for r in busy} == {"walk", "static"}
    assert all(r.review == RECORD_UNREADABLE and r.pending is None for r in busy)
    assert [(r.subject.rel, r.trial) for r in rows[:2]] == [("lab/busy", "static"), ("lab/busy", "walk")]
    assert "record unreadable" in queue_markdown(rows) and "record unreadable" in queue_markdown(rows, compact=True)
    # the other subjects' states are unchanged
    by = {(r.subject.rel, r.trial): r for r in rows}
    assert by[("lab/done", "walk")].review == REVIEWED and by[("lab/fresh", "walk")].review == UNREVIEWED


def test_next_to_review_reaches_a_row_sorted_above_the_one_shown_before_going_round_again() -> None:
    """As the workbench calls it (the order taken again at each open, the rows opened kept):
    a subject processed while the reviewer goes round takes a place above the trial shown;
    R reaches it before opening any trial a second time (the explorer's report: R opened
    DJ1, walking1, walk, the statics, then DJ1 again, never the run processed meanwhile)."""
    from types import SimpleNamespace

    def row(rel: str) -> SimpleNamespace:
        return SimpleNamespace(subject=SimpleNamespace(rel=rel), trial="t", needs_review=True)

    queues = [
        ["dj1", "walking1", "walk", "static"],  # the run not processed yet
        ["dj1", "run", "walking1", "walk", "static"],  # processed: sorted second
    ]
    visited: set = set()
    opened, after, order = [], None, None
    for press in range(6):
        rows = [row(r) for r in queues[min(press, 1)]]
        nxt = next_to_review(rows, after=after, order=order, visited=visited)
        key = (nxt.subject.rel, nxt.trial)
        if key in visited:
            visited.clear()
        visited.add(key)
        opened.append(nxt.subject.rel)
        after, order = key, [(r.subject.rel, r.trial) for r in rows]
    assert opened == ["dj1", "walking1", "walk", "static", "run", "walking1"]  # then round again, after the run
