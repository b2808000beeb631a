"""A Reprocess of one trial refits the subject's body mass over every trial (with the
reviewer's flags). The solver's ``reprocess_dynamics`` writes only the trials it is given, so
the review app gives it every trial with dynamics: on the OpenCap subject, flags on walking1
move the fitted mass and DJ1 is rewritten with it; the page says so, and would name a trial
left with the old mass."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.app.reprocess import dynamics_trials, other_mass_trials
from tests.conftest import SHARED_DATA, writable_copy

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
    assert dynamics_trials(OPENCAP, out) == ["DJ1", "walking1"]  # what the review app's Reprocess writes
    shutil.rmtree(out)


def test_a_reprocess_rewrites_every_trial_with_dynamics(tmp_path: Path, make_app) -> None:
    from addb_viewer.app.paths import ReviewPaths
    from solver.pipeline import process_subject
    from tests.conftest import writable_copy

    subject = writable_copy(OPENCAP, tmp_path / "opencap")
    process_subject(subject, tmp_path / "out")
    old = json.loads((tmp_path / "out" / "subject.json").read_text())["fitted_mass_kg"]
    dj1_before = (tmp_path / "out" / "DJ1" / "DJ1_id.sto").read_bytes()
    app = make_app(ReviewPaths.for_subject(subject, tmp_path / "out"))
    app.load_trial("walking1")
    app.select(20, 59)
    app.selection_edit("Flag")
    app.edit("accept all", lambda ed, _k, _f: ed.accept())  # no pending proposal: no warning
    app.jobs.reprocess("walking1")
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    out = tmp_path / "out"
    table = app.panel.comparison.content
    new = json.loads((out / "subject.json").read_text())["fitted_mass_kg"]
    assert abs(new - old) > 0.05, (old, new)  # the flags moved the fitted mass ...
    for trial in ("walking1", "DJ1"):  # ... and every trial's dynamics were made with it
        assert json.loads((out / trial / "results.json").read_text())["mass_kg"] == pytest.approx(new, abs=1e-9)
    assert (out / "DJ1" / "DJ1_id.sto").read_bytes() != dj1_before
    assert other_mass_trials(out, "walking1", new) == []
    assert "Reprocess result" in table and "Rewritten too" in table and "DJ1" in table, table
    assert "The fitted body mass is now" not in table, table  # no trial left with the old mass


def test_a_trial_left_with_the_old_mass_is_named(tmp_path: Path, make_app) -> None:
    """A trial folder left in the output after its trial left the subject folder is not
    rewritten (the solver no longer has it): the table names it with its old mass."""
    from addb_viewer.app.paths import ReviewPaths
    from solver.pipeline import process_subject
    from tests.conftest import writable_copy

    subject = writable_copy(OPENCAP, tmp_path / "opencap")
    process_subject(subject, tmp_path / "out")
    old = json.loads((tmp_path / "out" / "subject.json").read_text())["fitted_mass_kg"]
    shutil.rmtree(subject / "trials" / "DJ1")
    app = make_app(ReviewPaths.for_subject(subject, tmp_path / "out"))
    app.load_trial("walking1")
    app.select(20, 59)
    app.selection_edit("Flag")
    app.edit("accept all", lambda ed, _k, _f: ed.accept())
    app.jobs.reprocess("walking1")
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    table = app.panel.comparison.content
    assert "Rewritten too" not in table, table
    assert "The fitted body mass is now" in table and f"DJ1 ({old:.2f} kg)" in table, table


def test_the_trial_shown_is_reloaded_when_another_is_reprocessed(tmp_path: Path, make_app) -> None:
    """Reprocess walking1 (its flags) while DJ1 is on screen: DJ1 is rewritten by the same run
    (the masses are fitted over both), so the page reloads it (it kept the old numbers)."""
    from addb_viewer.app.paths import ReviewPaths
    from solver.pipeline import process_subject
    from solver.results import load_processed

    subject = writable_copy(OPENCAP, tmp_path / "opencap")
    out = tmp_path / "out"
    process_subject(subject, out)
    app = make_app(ReviewPaths.for_subject(subject, out))
    app.load_trial("walking1")
    app.select(20, 59)
    app.selection_edit("Flag")
    app.edit("accept all", lambda ed, _k, _f: ed.accept())
    app.load_trial("DJ1", frame=120)
    old = app.trial.mass_kg
    app.jobs.reprocess("walking1")
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    disk = load_processed(out, "DJ1")
    assert abs(disk.mass_kg - old) > 0.05  # DJ1 was rewritten with the new mass ...
    assert app.trial.trial == "DJ1" and app.trial.mass_kg == disk.mass_kg  # ... and the page shows it
    assert app.playback.frame == 120 and "reloaded" in app.panel.job_status.content, app.panel.job_status.content
