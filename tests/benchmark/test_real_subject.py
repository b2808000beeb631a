"""``addb benchmark`` on a real subject folder (processed on the fly into its ``addb_out``)."""

from __future__ import annotations

import json
import shutil

import pytest

from addb_viewer.cli import main as cli
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow


def test_walk_subject_is_processed_and_scored(tmp_path, capsys) -> None:
    # a writable copy: the shared folder must stay untouched (and root may write anywhere)
    subject = tmp_path / "rajagopal2016_walk"
    writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", subject, ignore=shutil.ignore_patterns("addb_out*"))
    out = tmp_path / "report"
    assert cli(["benchmark", str(subject), "--contact", "measured", "--contact", "kinematic", "-o", str(out)]) == 0
    assert (subject / "addb_out" / "walk" / "trial.npz").is_file()
    report = json.loads((out / "benchmark.json").read_text())
    summary = report["dataset"]
    assert summary["trials"] == ["rajagopal2016_walk/walk"]
    assert any("static" in s for s in summary["skipped"])  # no force plates
    assert 100 <= summary["frames"] <= 154  # measured frames (154) less the margins
    measured, kinematic = report["rows"]
    # walking, inputs by IK of the markers: errors of the order seen in the recorded benchmark
    assert measured["com_acc"] < 2.0 and measured["grf"] < 2.0 and measured["torque"] < 0.4
    assert kinematic["grf"] >= measured["grf"]  # the measured contact is the better split
    assert "walk" in capsys.readouterr().out
