"""A dataset subject one of whose trials the dynamics stage cannot take (its markers overlap
its forces by six frames) keeps what ``addb process SUBJECT_DIR`` keeps: the other trials
with their dynamics, that trial's kinematics with its error in its results.json, and a
warning naming the trial; the subject is processed, not failed, and the run exits 0.

On a one-subject tree (the walk, plus ``walk_short``: the walk's first six marker frames,
its forces whole), one local worker.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_run import run_addb
from tests.conftest import SHARED_DATA, writable_copy
from tests.trial_edits import add_short_walk

pytestmark = pytest.mark.slow
REL = "labA/s01"


def test_a_trial_the_dynamics_cannot_take_leaves_the_subject_processed(tmp_path: Path) -> None:
    subject = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path / "dataset" / REL)
    add_short_walk(subject)
    out = tmp_path / "out"
    code, _, err = run_addb(["process", str(tmp_path / "dataset"), "--out", str(out), "--workers", "1"])
    assert code == 0, err
    summary = json.loads((out / "dataset_summary.json").read_text())
    (row,) = summary["subjects"]
    assert row["status"] == "ok", row.get("error")
    trials = {t["trial"]: t for t in row["trials"]}
    assert trials["walk"]["status"] == "ok" and trials["walk"]["measured_frames"] > 100
    assert trials["walk_short"]["status"] == "kinematics_only" and trials["static"]["status"] == "kinematics_only"
    kept = json.loads((out / REL / "walk_short" / "results.json").read_text())
    assert kept["dynamics_error"]["type"] == "DynamicsError" and "walk_short" in kept["dynamics_error"]["where"]
    assert any("walk_short" in w and "kinematics were kept" in w for w in row["warnings"]), row["warnings"]
