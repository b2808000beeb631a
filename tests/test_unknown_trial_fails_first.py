"""A trial name the subject does not have (``--trial`` with a typo) fails before any stage
runs, so it costs no processing, names the subject's trials, and writes nothing.

On the real walk (rajagopal2016_walk: trials static and walk). Each stage is replaced by one
that fails the test if it runs.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.recording.jobs import record_subject_trial
from solver import pipeline
from solver.errors import KinematicsError, SubjectFolderError
from solver.pipeline import ProcessOptions, process_kinematics, process_subject, reprocess_dynamics
from tests.conftest import SHARED_DATA

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


def _stage_ran(*args: object, **kwargs: object) -> None:
    raise AssertionError("a stage ran before the trial names were checked")


@pytest.mark.parametrize(
    "run",
    [
        lambda out: process_subject(WALK, out, options=ProcessOptions(trials=("walk", "wlk"))),
        lambda out: process_kinematics(WALK, out, options=ProcessOptions(trials=("walk", "wlk"))),
        lambda out: reprocess_dynamics(WALK, out, ("walk", "wlk")),
    ],
    ids=["process_subject", "process_kinematics", "reprocess_dynamics"],
)
def test_an_unknown_trial_fails_before_any_stage(run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(pipeline, "subject_kinematics", _stage_ran)
    monkeypatch.setattr(pipeline, "load_kinematics_cache", _stage_ran)
    with pytest.raises(KinematicsError, match=r"unknown trial\(s\) wlk; the subject has static, walk"):
        run(tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_recording_of_an_unknown_trial_fails_before_processing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``addb record`` / ``addb export`` of an unprocessed subject: the trial is checked
    before the subject is processed."""
    monkeypatch.setattr(pipeline, "process_subject", _stage_ran)
    with pytest.raises(SubjectFolderError, match=r"no trial 'wlk'; the subject's trials are static, walk"):
        record_subject_trial(WALK, "wlk", tmp_path / "walk.rrd", out_dir=tmp_path / "out")
    assert not (tmp_path / "out").exists() and not (tmp_path / "walk.rrd").exists()


def test_a_subject_names_its_trials_when_asked_for_one_it_lacks() -> None:
    """``Subject.trial`` (what ``addb diagnose``, ``addb record`` and the review app's
    masks ask) raises the folder error that names the subject's trials, not a KeyError."""
    from solver.io.subject import load_subject

    subject = load_subject(WALK)
    assert subject.trial("walk").name == "walk"
    with pytest.raises(SubjectFolderError, match=r"no trial 'wlk'; the subject's trials are static, walk") as err:
        subject.trial("wlk")
    assert not isinstance(err.value, KeyError) and err.value.path == str(WALK)
