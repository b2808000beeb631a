"""Pending proposals before a Reprocess: once a trial has a flag (or is marked reviewed) the
reviewer's flags replace the solver's proposals (addb_viewer.review_masks), so a proposal
neither accepted nor rejected would be fitted as a measured frame. On the walk processed
with dynamics (84 proposed frames), the flags panel says how many, the first Reprocess
press warns and starts nothing, the second runs; once every proposal is decided (accepted
or rejected) Reprocess runs at once and the warning is gone; an unflagged trial keeps the
solver's own proposals and is never warned about."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.app import reprocess
from addb_viewer.app.flags import pending_replaced
from addb_viewer.app.paths import ReviewPaths
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> list:
    """The solver jobs the app starts (recorded, not run)."""
    specs: list = []

    class Recorder:
        def __init__(self, spec, work, **kw) -> None:
            specs.append(spec)
            self.running = False

        def start(self) -> None:
            pass

        def cancel(self, *args, **kw) -> None:
            pass

        def wait(self, *args, **kw) -> bool:
            return True

    monkeypatch.setattr(reprocess, "SolverJob", Recorder)
    return specs


def test_reprocess_warns_once_about_pending_proposals_it_would_fit_as_measured(
    walk_processed: Path, tmp_path: Path, make_app, started: list
) -> None:
    subject = writable_copy(WALK, tmp_path / "walk")
    out = tmp_path / "out"
    shutil.copytree(walk_processed, out)
    app = make_app(ReviewPaths.for_subject(subject, out))
    n_proposed = int(app.view.proposed.sum())
    assert n_proposed > 0 and int(app.view.pending.sum()) == n_proposed
    # nothing flagged: the solver keeps its proposals, no warning, Reprocess runs at once
    assert pending_replaced(app.view) == 0 and "fitted as measured" not in app.panel.proposal_info.content
    app.jobs.reprocess()
    assert len(started) == 1
    # one flag outside the proposals: every proposal is now pending and would be measured
    frame = int(np.flatnonzero(~app.view.proposed)[0])
    app.seek(frame)
    app.edit("flag", lambda ed, k, foot: ed.toggle(k, foot))
    assert pending_replaced(app.view) == n_proposed
    assert f"{n_proposed} pending proposed frames will be fitted as measured" in app.panel.proposal_info.content
    app.jobs.reprocess()
    assert len(started) == 1 and f"{n_proposed} proposed frames of walk are still pending" in app.panel.job_status.content
    app.jobs.reprocess()  # at once (a double click): still only the warning
    assert len(started) == 1
    app.jobs.pending_warning.at -= reprocess.CONFIRM_AFTER_S  # the warning read: a second press later
    app.jobs.reprocess()  # pressed again: the reviewer means it
    assert len(started) == 2 and started[-1].unmeasured_force["walk"].sum() == 1
    # decided (every proposal accepted): no warning any more, Reprocess runs at once
    app.edit("accept all", lambda ed, k, foot: ed.accept())
    assert pending_replaced(app.view) == 0 and "fitted as measured" not in app.panel.proposal_info.content
    app.jobs.reprocess()
    assert len(started) == 3 and started[-1].unmeasured_force["walk"].sum() == n_proposed + 1


def test_trial_reviewed_warns_once_about_pending_proposals_and_flags_say_what_they_replace(
    walk_processed: Path, tmp_path: Path, make_app
) -> None:
    """Ticking "Trial reviewed" makes the flags replace the solver's proposals as a flag
    does: with pending proposals the first tick leaves the box unticked and says why, a
    double click changes nothing, a second tick later marks the trial; a flag edit that
    leaves pending proposals fitted as measured says so beside its "saved" line."""
    subject = writable_copy(WALK, tmp_path / "walk")
    out = tmp_path / "out"
    shutil.copytree(walk_processed, out)
    app = make_app(ReviewPaths.for_subject(subject, out))
    p = app.panel
    n_proposed = int(app.view.pending.sum())
    assert n_proposed > 0
    app.set_reviewed(True)
    assert not app.view.reviewed and not p.reviewed.value
    assert f"not marked reviewed: {n_proposed} proposed frames of walk are still pending" in p.saved.content
    app.set_reviewed(True)  # at once: a double click
    assert not app.view.reviewed
    app.review_warning.at -= reprocess.CONFIRM_AFTER_S  # the warning read: ticked again later
    app.set_reviewed(True)
    assert app.view.reviewed and p.reviewed.value and "✓ saved: trial reviewed" in p.saved.content
    assert f"{n_proposed} pending proposed frames are now fitted as measured" in p.saved.content
    app.set_reviewed(False)  # unticking never asks
    assert not app.view.reviewed and "fitted as measured" not in p.saved.content
    # a flag outside the proposals: the saved line says what it did to the pending ones
    frame = int(np.flatnonzero(~app.view.proposed)[0])
    app.seek(frame)
    app.toggle_flag()
    assert f"{n_proposed} pending proposed frames are now fitted as measured" in p.saved.content
    # the proposals decided: ticking marks at once, without a warning
    app.edit("accept all", lambda ed, k, foot: ed.accept())
    assert "fitted as measured" not in p.saved.content
    app.set_reviewed(True)
    assert app.view.reviewed and "not marked reviewed" not in p.saved.content


def test_a_review_record_outside_the_subject_folder_is_named(walk_processed: Path, tmp_path: Path, make_app, capsys) -> None:
    """A read-only subject folder (a copy of shared data) keeps its review record beside the
    output folder: the Flags folder and the terminal name it (a reviewer looked for
    ``<subject>/annotations.json``, as the README says); a writable one is not named."""
    import os
    import stat

    subject = writable_copy(WALK, tmp_path / "walk")
    out = tmp_path / "out"
    shutil.copytree(walk_processed, out)
    app = make_app(ReviewPaths.for_subject(subject, out))
    assert app.paths.annotations == subject / "annotations.json" and "review record is" not in app.panel.proposal_info.content
    app.stop()
    ro = writable_copy(WALK, tmp_path / "ro")
    os.chmod(ro, stat.S_IRUSR | stat.S_IXUSR)
    try:  # read-only by its mode bits (addb_viewer.locations.folder_is_writable), for root too
        app = make_app(ReviewPaths.for_subject(ro, out))
        record = str(tmp_path / "out.annotations.json")
        assert f"The review record is {record}" in app.panel.proposal_info.content, app.panel.proposal_info.content
        assert f"The review record is {record}" in capsys.readouterr().err
    finally:
        os.chmod(ro, stat.S_IRWXU)


def test_reprocess_of_another_trial_warns_about_the_pending_proposals_it_would_refit(
    walk_processed: Path, tmp_path: Path, make_app, started: list
) -> None:
    """A Reprocess rewrites every trial with dynamics (the masses are fitted over all of
    them), so the pending proposals of a trial that is not on screen are fitted as measured
    too: a Reprocess pressed on the static trial, with the walk flagged and its proposals
    pending, warns first and names the walk; the same holds for "Apply the named cause"."""
    subject = writable_copy(WALK, tmp_path / "walk")
    out = tmp_path / "out"
    shutil.copytree(walk_processed, out)
    app = make_app(ReviewPaths.for_subject(subject, out))
    assert app.trial.trial == "walk" and reprocess.written_trials(subject, out, "static") == ("static", "walk")
    n_proposed = int(app.view.proposed.sum())
    frame = int(np.flatnonzero(~app.view.proposed)[0])
    app.seek(frame)
    app.edit("flag", lambda ed, k, foot: ed.toggle(k, foot))
    assert pending_replaced(app.view) == n_proposed > 0
    app.load_trial("static")
    assert app.trial.trial == "static" and not app.trial.has_dynamics
    app.jobs.reprocess()
    status = app.panel.job_status.content
    assert not started and f"{n_proposed} proposed frames of walk are still pending" in status
    assert "A Reprocess of static fits walk again too" in status
    # the correction of a diagnosis is not saved either while the walk's proposals are pending
    (out / "static" / "diagnosis.json").write_text('{"extension": {"cause": "force_delay", "parameters": {}}}', encoding="utf-8")
    assert app.jobs.apply_diagnosis() is None and f"{n_proposed} proposed frames of walk are still pending" in app.panel.job_status.content
    assert not (subject / "addb_extensions.json").exists()
    app.jobs.pending_warning.at -= reprocess.CONFIRM_AFTER_S  # the warning read: pressed again later
    app.jobs.reprocess()  # the reviewer means it (the apply above warned but did not reset the warning)
    assert len(started) == 1 and started[0].trials == ("static", "walk") and started[0].unmeasured_force["walk"].sum() == 1
    # a damaged trial.npz of the other trial (a Reprocess is how it is mended) is read as no
    # view, so no pending count: not an error that would stop the Reprocess
    npz = out / "walk" / "trial.npz"
    good = npz.read_bytes()
    npz.write_bytes(good[:3000])  # truncated: zipfile.BadZipFile from np.load
    assert reprocess.output_view(app.store, out, "walk") is None
    npz.write_bytes(good)
    # once the walk's proposals are decided, the static trial's Reprocess runs at once
    app.load_trial("walk")
    app.edit("accept all", lambda ed, k, foot: ed.accept())
    app.load_trial("static")
    app.jobs.reprocess()
    assert len(started) == 2 and started[-1].unmeasured_force["walk"].sum() == n_proposed + 1
