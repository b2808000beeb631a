"""Diagnosis from the page: the button runs ``addb diagnose`` of the shown trial in the
background job runner and shows its report; "Apply" saves the named cause's correction
(as ``addb diagnose --apply``) and reprocesses the trial, with the before/after table."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from addb_viewer.app.paths import ReviewPaths
from solver.corrections import read_extensions
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def walk_processed(tmp_path_factory: pytest.TempPathFactory):
    from solver.pipeline import process_subject

    base = tmp_path_factory.mktemp("diag")
    subject = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", base / "walk")
    process_subject(subject, base / "out")
    return subject, base / "out"


def test_diagnose_button_writes_and_shows_the_report_and_apply_reprocesses(walk_processed, make_app, tmp_path) -> None:
    subject0, out0 = walk_processed
    subject = shutil.copytree(subject0, tmp_path / "walk")
    out = shutil.copytree(out0, tmp_path / "out")
    app = make_app(ReviewPaths.for_subject(subject, out))
    assert app.trial.trial == "walk" and "Not diagnosed yet" in app.panel.diagnosis.content
    app.jobs.diagnose()
    assert app.jobs.finished.wait(600), app.panel.job_status.content
    assert app.jobs.last_result.status == "done", app.jobs.last_result.message
    report = json.loads((out / "walk" / "diagnosis.json").read_text())
    assert report["trial"] == "walk" and report["candidates"]
    shown = app.panel.diagnosis.content
    assert "Not diagnosed yet" not in shown
    # the panel states the report's verdict and its reason (not one of either)
    verdict = f"**Chosen cause: `{report['chosen']}`**" if report["chosen"] else "**No cause stands out.**"
    assert verdict in shown and report["reason"] and report["reason"] in shown, shown
    # the candidates are a list that wraps in the panel (a code block ran far off its right edge)
    first = report["candidates"][0]["cause"].replace("_", "\\_")
    assert f"- {first} score" in shown and "```" not in shown, shown
    # processed with the default fit, judged on the alternation: the page says its figures differ
    judged = report["settings"]["judged_fit"]
    assert judged["rebuilt"] and f"Judged on the `{judged['fit']}` dynamics fit" in shown, shown
    # Apply: a correction the diagnosis names (here written into its report: +3 kg of body mass)
    report["extension"] = {"cause": "body_mass", "trial": None, "mass_change_kg": 3.0}
    (out / "walk" / "diagnosis.json").write_text(json.dumps(report))
    stated = json.loads((out / "subject.json").read_text())["mass_kg"]
    entry = app.jobs.apply_diagnosis()
    assert entry == report["extension"]
    saved = read_extensions(subject)
    assert [e["cause"] for e in saved] == ["body_mass"] and saved[0]["mass_change_kg"] == 3.0
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    assert "Reprocess result" in app.panel.comparison.content
    # the report behind the correction is kept (the solver rewrote the trial's folder without
    # it) and said to be made on the results before the Reprocess
    assert json.loads((out / "walk" / "diagnosis.json").read_text())["extension"] == report["extension"]
    assert "Made on earlier results" in app.panel.diagnosis.content and verdict in app.panel.diagnosis.content
    # the reprocess used the corrected stated mass (the fitted mass comes from the forces alone:
    # with the same frames left out it does not move; until the masks had one owner it moved
    # only because the app's Reprocess dropped the solver's proposals of a trial nobody flagged)
    assert json.loads((out / "subject.json").read_text())["mass_kg"] == pytest.approx(stated + 3.0, abs=1e-9)


def test_apply_without_a_named_cause_changes_nothing(walk_processed, make_app, tmp_path, monkeypatch) -> None:
    subject0, out0 = walk_processed
    subject = shutil.copytree(subject0, tmp_path / "walk")
    out = shutil.copytree(out0, tmp_path / "out")
    app = make_app(ReviewPaths.for_subject(subject, out))
    assert app.jobs.apply_diagnosis() is None and "Run the diagnosis first" in app.panel.job_status.content
    (out / "walk" / "diagnosis.json").write_text(json.dumps({"extension": None}))
    assert app.jobs.apply_diagnosis() is None and "named no cause" in app.panel.job_status.content
    assert not (subject / "addb_extensions.json").exists()
    # a subject folder the app cannot write: the refusal is said beside the button too (the
    # page's error box is at the top of the panel, scrolled out of view)
    import solver.corrections
    from solver.errors import SubjectFolderError

    def refuse(folder, entry):
        raise SubjectFolderError("the subject folder is read-only; copy the subject", path=Path(folder))

    monkeypatch.setattr(solver.corrections, "save_extension", refuse)
    (out / "walk" / "diagnosis.json").write_text(json.dumps({"extension": {"cause": "body_mass", "mass_change_kg": 3.0}}))
    with pytest.raises(SubjectFolderError):
        app.jobs.apply_diagnosis()
    assert "Not applied" in app.panel.job_status.content and "read-only" in app.panel.job_status.content
    assert not app.jobs.running


def test_apply_saves_a_correction_once(walk_processed, make_app, tmp_path) -> None:
    """A second press while the first one's run goes on, a press with pending proposals the
    Reprocess would only warn about, and a press for a correction already saved save
    nothing (every later processing would apply a duplicate twice)."""
    subject0, out0 = walk_processed
    subject = shutil.copytree(subject0, tmp_path / "walk")
    out = shutil.copytree(out0, tmp_path / "out")
    app = make_app(ReviewPaths.for_subject(subject, out))
    report = {"extension": {"cause": "body_mass", "trial": None, "mass_change_kg": 3.0}}
    (out / "walk" / "diagnosis.json").write_text(json.dumps(report))
    assert app.jobs.apply_diagnosis() == report["extension"]
    assert app.jobs.apply_diagnosis() is None and "not saved" in app.panel.job_status.content  # the run goes on
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    assert len(read_extensions(subject)) == 1
    (out / "walk" / "diagnosis.json").write_text(json.dumps(report))  # the Reprocess replaced the trial's folder
    assert app.jobs.apply_diagnosis() is None  # already saved: reprocessed with it, not saved again
    assert app.jobs.finished.wait(600) and app.jobs.last_result.status == "done", app.jobs.last_result
    assert len(read_extensions(subject)) == 1
    # flags with pending proposals: the Reprocess would only warn, so nothing is saved
    app.select(100, 109)
    app.selection_edit("Flag")
    report = {"extension": {"cause": "body_mass", "trial": None, "mass_change_kg": 1.0}}
    (out / "walk" / "diagnosis.json").write_text(json.dumps(report))
    assert app.jobs.apply_diagnosis() is None and "still pending" in app.panel.job_status.content
    assert len(read_extensions(subject)) == 1


def test_apply_is_disabled_where_the_correction_cannot_be_saved(walk_processed, make_app, demo_paths, tmp_path) -> None:
    """The correction goes into the subject folder: for a read-only folder and for the
    bundled demo (package data) the button is disabled, its hint says why, and a press
    from Python (or a page that raced the update) saves nothing and says so beside it."""
    import os
    import stat

    from addb_viewer.app.panel import APPLY_HINT

    subject0, out0 = walk_processed
    out = shutil.copytree(out0, tmp_path / "walk_out")
    (out / "walk" / "diagnosis.json").write_text(json.dumps({"extension": {"cause": "body_mass", "mass_change_kg": 3.0}}))
    writable = shutil.copytree(subject0, tmp_path / "walk")
    app = make_app(ReviewPaths.for_subject(writable, out))
    assert not app.panel.apply_diagnosis.disabled and app.panel.apply_diagnosis.hint == APPLY_HINT
    app.stop()
    ro = shutil.copytree(subject0, tmp_path / "ro")
    os.chmod(ro, stat.S_IRUSR | stat.S_IXUSR)
    try:  # read-only by its mode bits, for root too
        app = make_app(ReviewPaths.for_subject(ro, out))
        p = app.panel
        assert p.apply_diagnosis.disabled and "the subject folder is read-only" in p.apply_diagnosis.hint
        assert app.jobs.apply_diagnosis() is None and not app.jobs.running
        assert "Not applied" in p.job_status.content and "read-only" in p.job_status.content
        assert not (ro / "addb_extensions.json").exists()
        # the dataset queue's Open of a writable subject enables it again
        app.open_subject(ReviewPaths.for_subject(writable, out))
        assert not p.apply_diagnosis.disabled and p.apply_diagnosis.hint == APPLY_HINT
        app.stop()
    finally:
        os.chmod(ro, stat.S_IRWXU)
    demo = make_app(demo_paths)
    assert demo.panel.apply_diagnosis.disabled and "bundled demo is package data" in demo.panel.apply_diagnosis.hint
    assert demo.jobs.apply_diagnosis("walk") is None and "Not applied" in demo.panel.job_status.content
    assert not (demo_paths.subject_dir / "addb_extensions.json").exists()


def test_a_trial_without_dynamics_is_not_offered_a_diagnosis(walk_processed, tmp_path) -> None:
    """The static trial has no force plates: its Diagnosis folder says there is nothing to
    diagnose, not "press Diagnose this trial" (the explorer's report: the button then answered
    "nothing to diagnose" beside the same invitation); a trial whose dynamics failed says why."""
    from addb_viewer.app.diagnosis import diagnosis_markdown

    subject, out0 = walk_processed
    out = shutil.copytree(out0, tmp_path / "out")
    assert "n_observed_frames" not in json.loads((out / "static" / "results.json").read_text())
    assert diagnosis_markdown(out, subject, "static") == "static has no dynamics (no force plates): nothing to diagnose."
    assert "Not diagnosed yet" in diagnosis_markdown(out, subject, "walk")
    failed = json.loads((out / "static" / "results.json").read_text())
    failed["dynamics_error"] = {"type": "ForcePlateError", "message": "grf.mot: plate 2 <has> no force"}
    (out / "static" / "results.json").write_text(json.dumps(failed))
    shown = diagnosis_markdown(out, subject, "static")
    assert shown == "static has no dynamics (its dynamics failed: grf.mot: plate 2 &lt;has&gt; no force): nothing to diagnose."
