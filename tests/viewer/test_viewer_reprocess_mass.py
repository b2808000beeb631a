"""A Reprocess of one trial refits the subject's body mass over every trial (with the
reviewer's flags) but rewrites only that trial's files: the page names the other trials whose
results were made with the old mass (the OpenCap subject: DJ1 beside a reprocessed walking1)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.app.reprocess import other_mass_trials
from tests.conftest import SHARED_DATA

pytestmark = pytest.mark.slow

OPENCAP = SHARED_DATA / "subjects" / "opencap_uhlrich2023"


def test_the_trials_left_with_the_old_mass_are_named(tmp_path: Path) -> None:
    from solver.pipeline import process_subject, reprocess_dynamics
    from solver.results import load_processed

    out = tmp_path / "out"
    process_subject(OPENCAP, out)
    old = json.loads((out / "subject.json").read_text())["fitted_mass_kg"]
    assert other_mass_trials(out, "walking1", old) == []  # one mass everywhere after a full run
    before = (out / "DJ1" / "DJ1_id.sto").read_bytes()
    flags = np.zeros(load_processed(out, "walking1").n_frames, bool)
    flags[20:60] = True
    reprocess_dynamics(OPENCAP, out, ["walking1"], unmeasured_force={"walking1": flags})
    new = json.loads((out / "subject.json").read_text())["fitted_mass_kg"]
    assert abs(new - old) > 0.05  # the flags moved the subject's fitted mass
    assert (out / "DJ1" / "DJ1_id.sto").read_bytes() == before  # DJ1 was not rewritten
    assert other_mass_trials(out, "walking1", new) == [("DJ1", pytest.approx(old))]
    shutil.rmtree(out)


def test_the_reprocess_table_names_them(tmp_path: Path, make_app) -> None:
    from addb_viewer.app.paths import ReviewPaths
    from solver.pipeline import process_subject
    from tests.conftest import writable_copy

    subject = writable_copy(OPENCAP, tmp_path / "opencap")
    process_subject(subject, tmp_path / "out")
    app = make_app(ReviewPaths.for_subject(subject, tmp_path / "out"))
    app.load_trial("walking1")
    app.select(20, 59)
    app.selection_edit("Flag")
    app.edit("accept all", lambda ed, _k, _f: ed.accept())  # no pending proposal: no warning
    app.jobs.reprocess("walking1")
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    table = app.panel.comparison.content
    assert "Reprocess result" in table and "The fitted body mass is now" in table and "DJ1 (" in table, table
