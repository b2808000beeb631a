"""Opening another subject (the dataset queue's "Open") while a solver run works on the shown
one: the run is cancelled and the page says so, with the subject it belonged to; what the
page showed of the old subject (the last edit's message, the Foot choice) does not stay."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from addb_viewer.app.panel import NO_EDITS
from addb_viewer.app.paths import ReviewPaths
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow


def test_open_cancels_the_running_reprocess_and_says_so(walk_processed: Path, make_app, tmp_path: Path) -> None:
    subjects = {}
    for name in ("first", "second"):
        subject = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path / name)
        subjects[name] = ReviewPaths.for_subject(subject, shutil.copytree(walk_processed, tmp_path / f"{name}_out"))
    app = make_app(subjects["first"])
    app.panel.foot.value = "left"
    app.edit("flag", lambda ed, _k, _f: ed.flag_range(10, 12, "left"))
    assert "✓ saved" in app.panel.saved.content
    before = (tmp_path / "first_out" / "walk" / "results.json").read_bytes()
    app.jobs.pending_warning.key = (("walk", int(app.view.pending.sum())),)  # the pending-proposal warning was seen (trial, frames) per trial
    app.jobs.pending_warning.at = -1e9  # long ago
    app.jobs.reprocess("walk")
    assert app.jobs.running
    app.open_subject(subjects["second"], "walk")
    status = app.panel.job_status.content
    assert "cancelled" in status and status.startswith("first ·") and "you opened second" in status, status
    assert not app.jobs.running and app.jobs.last_result.status == "cancelled"
    assert (tmp_path / "first_out" / "walk" / "results.json").read_bytes() == before  # the previous result kept
    assert app.panel.saved.content == NO_EDITS and app.panel.foot.value == "both"
    assert app.trial is not None and app.paths.subject_dir == subjects["second"].subject_dir
    app.open_subject(subjects["first"], "walk")  # nothing running: no message
    assert app.panel.job_status.content == ""
