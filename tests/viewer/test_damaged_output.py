"""A dataset whose output was damaged after the run (docs/audits/2026-12-02-viewer.md,
findings 1-3): a trial's trial.npz deleted, or its results.json cut short. The queue says
"output lost" with the file (not "processed" with the manifest's stale figures); "Open" on
a trial without trial.npz names it and the missing file (no other trial shown in its
place); a damaged results.json leaves the subject's other trials openable and names the
file once, with one remedy."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.queue import (
    KINEMATICS_ONLY,
    OUTPUT_LOST,
    PROCESSED,
    build_queue,
    dataset_subjects,
    next_to_review,
)
from addb_viewer.app.workbench import Workbench, queue_markdown
from solver.dataset.manifest import MANIFEST_NAME
from solver.dataset.summary import subject_rows
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow
WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture(scope="module")
def processed_dataset(walk_processed: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dataset of two copies of the walk (``lab/cut``, ``lab/gone``) with their output and
    the dataset run's manifest in ``<dataset>/addb_out``, shared by the module: copy it."""
    root = tmp_path_factory.mktemp("damaged") / "ds"
    rows = subject_rows(walk_processed)
    for name in ("cut", "gone"):
        writable_copy(WALK, root / "lab" / name)
        out = root / "addb_out" / "lab" / name
        shutil.copytree(walk_processed, out)
        (out / MANIFEST_NAME).write_text(json.dumps({"key": {}, "status": "ok", "trials": rows}))
    return root


@pytest.fixture
def damaged(processed_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private copy of the dataset, as in the audit's repro: ``lab/cut``'s walk/results.json
    cut to its first 200 bytes, ``lab/gone``'s walk/trial.npz deleted."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    root = shutil.copytree(processed_dataset, tmp_path / "ds")
    res = root / "addb_out" / "lab" / "cut" / "walk" / "results.json"
    res.write_bytes(res.read_bytes()[:200])
    (root / "addb_out" / "lab" / "gone" / "walk" / "trial.npz").unlink()
    return root


def _paths(dataset: Path, rel: str) -> ReviewPaths:
    _, _, subjects = dataset_subjects(dataset)
    subject = next(s for s in subjects if s.rel == rel)
    return ReviewPaths.for_subject(subject.subject_dir, subject.out_dir)


def test_the_queue_shows_a_trial_with_damaged_or_missing_output_as_output_lost(damaged: Path) -> None:
    """Finding 1: with a manifest, the walk trials whose results.json is damaged or whose
    trial.npz is gone are "output lost", the detail naming the file and what is wrong, with
    none of the manifest's figures; they are not offered for review. The intact static
    trials stay processed."""
    _, out, subjects = dataset_subjects(damaged)
    rows = build_queue(subjects)
    by = {(r.subject.rel, r.trial): r for r in rows}
    assert set(by) == {("lab/cut", "walk"), ("lab/cut", "static"), ("lab/gone", "walk"), ("lab/gone", "static")}
    cut, gone = by[("lab/cut", "walk")], by[("lab/gone", "walk")]
    for row in (cut, gone):
        assert row.processing == OUTPUT_LOST, row
        assert row.frames == 0 and row.measured_frames == 0 and row.pending is None
        assert row.marker_rms_m is None and row.hicks_linear_ok is None and row.hicks_angular_ok is None
        assert not row.needs_review
    assert str(out / "lab" / "cut" / "walk" / "results.json") in cut.detail and "not valid JSON" in cut.detail
    assert str(out / "lab" / "gone" / "walk" / "trial.npz") in gone.detail and "missing" in gone.detail
    assert all(by[(rel, "static")].processing in (PROCESSED, KINEMATICS_ONLY) for rel in ("lab/cut", "lab/gone"))
    table = queue_markdown(rows)
    lines = [line for line in table.splitlines() if "/ walk" in line]
    assert len(lines) == 2 and all("output lost" in line and "| processed" not in line for line in lines), table
    assert all(r.trial == "static" for r in rows if r.needs_review)
    assert next_to_review(rows).trial == "static"


def test_the_queue_names_a_lost_output_without_a_manifest_too(damaged: Path) -> None:
    """Without the dataset run's manifest the queue reads the trial folders: the damaged
    results.json is named, not silently left out of the queue."""
    _, _, subjects = dataset_subjects(damaged)
    for s in subjects:
        (s.out_dir / MANIFEST_NAME).unlink()
    by = {(r.subject.rel, r.trial): r for r in build_queue(subjects)}
    assert by[("lab/cut", "walk")].processing == OUTPUT_LOST and "results.json" in by[("lab/cut", "walk")].detail
    assert by[("lab/cut", "static")].processing in (PROCESSED, KINEMATICS_ONLY)


def test_open_on_a_trial_without_trial_npz_names_it_and_shows_no_other_trial(damaged: Path, make_app) -> None:
    """Finding 2: the queue's Open on lab/gone's walk (its trial.npz deleted) shows no trial
    (it used to show the static trial without a word) and the error names the trial and the
    missing file."""
    paths = _paths(damaged, "lab/gone")
    app = make_app(paths, process_missing=False)
    assert app.trial is not None and app.trial.trial == "static"  # the only trial with output
    bench = Workbench(app, damaged, workers=0)
    bench.open("lab/gone", "walk")
    assert app.trial is None, "another trial was shown in place of the one asked for"
    error = app.panel.error.content
    assert app.panel.error.visible and "'walk'" in error and "lab/gone" in error
    assert str(paths.out_dir / "walk" / "trial.npz") in error and "missing" in error
    assert "walk" in app.panel.status.content and "cannot be opened" in app.panel.status.content
    # the subject's other trial still opens
    bench.open("lab/gone", "static")
    assert app.trial is not None and app.trial.trial == "static" and not app.panel.error.visible


def test_a_damaged_results_json_leaves_the_other_trials_openable(damaged: Path, make_app) -> None:
    """Finding 3: lab/cut's walk (the preferred trial) has a damaged results.json: the subject
    opens with its static trial, and the page names the damaged file once, what is wrong
    and one remedy, with no class names."""
    paths = _paths(damaged, "lab/cut")
    app = make_app(paths, process_missing=False)
    assert app.trial is not None and app.trial.trial == "static"
    error = app.panel.error.content
    assert app.panel.error.visible and "'walk'" in error and "showing 'static'" in error, error
    res = str(paths.out_dir / "walk" / "results.json")
    assert error.count(res) == 1 and "not valid JSON" in error, error
    assert "trial.npz" not in error, error  # the intact file is not blamed
    assert "Error" not in error.replace("not valid", ""), error  # no TrialLoadError, ProcessedTrialError
    assert error.count("process the subject again") == 1 and "Reprocess" not in error, error
    assert "walk" in app.panel.trial.options  # still listed: picking it says the same
    # the queue's Open on the damaged trial of the subject shown: no trial (not static) and the file named
    bench = Workbench(app, damaged, workers=0)
    bench.open("lab/cut", "walk")
    assert app.trial is None and res in app.panel.error.content and "'walk'" in app.panel.error.content
    bench.open("lab/cut", "static")
    assert app.trial is not None and app.trial.trial == "static" and not app.panel.error.visible
    # opening the subject from the queue does the same
    other = _paths(damaged, "lab/gone")
    app.open_subject(other)
    app.open_subject(paths)
    assert app.trial is not None and app.trial.trial == "static" and res in app.panel.error.content
    # asking for the damaged trial itself: no trial shown, the file named
    app.open_subject(paths, "walk")
    assert app.trial is None and res in app.panel.error.content and "not valid JSON" in app.panel.error.content
