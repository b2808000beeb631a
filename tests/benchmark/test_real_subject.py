"""``addb benchmark`` on real subject folders (processed on the fly into their ``addb_out``)."""

from __future__ import annotations

import json
import shutil

import pytest

from addb_viewer.cli import main as cli
from solver.benchmark.mlp import torch_available
from tests.conftest import SHARED_DATA, TORCH_REASON, needs_tool, writable_copy

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


@needs_tool("torch", torch_available(), TORCH_REASON)
def test_hybrid_beats_the_motion_only_analytical_baseline_on_another_subject(tmp_path) -> None:
    """Two real subjects, leave-one-subject-out: the contact split (and force filter) learned
    on one subject's walk (and drop jump) scores the other's frames with a lower GRF error
    than the analytical baseline with its kinematic contact rule, the motion-only way to
    split the total force."""
    subjects = []
    for name in ("rajagopal2016_walk", "opencap_uhlrich2023"):
        subjects.append(tmp_path / name)
        writable_copy(SHARED_DATA / "subjects" / name, subjects[-1], ignore=shutil.ignore_patterns("addb_out*"))
    out = tmp_path / "report"
    args = ["benchmark", *map(str, subjects), "--method", "analytical", "--method", "hybrid", "--contact", "kinematic"]
    assert cli([*args, "-o", str(out)]) == 0
    report = json.loads((out / "benchmark.json").read_text())
    kinematic, hybrid = report["rows"]
    assert kinematic["method"] == "analytical (kinematic contact)" and hybrid["method"].startswith("hybrid")
    assert hybrid["frames"] == kinematic["frames"] > 300
    # the total force's filter, chosen on the other subject, also improves the CoM acceleration
    assert hybrid["com_acc"] < kinematic["com_acc"]
    assert hybrid["grf"] < 0.7 * kinematic["grf"]
    for trial in ("rajagopal2016_walk/walk", "opencap_uhlrich2023/walking1"):
        assert hybrid["per_trial"][trial]["grf"] < kinematic["per_trial"][trial]["grf"]
