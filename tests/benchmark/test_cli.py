"""``addb benchmark`` on processed output folders of synthetic subjects."""

from __future__ import annotations

import json

import numpy as np
import pytest

from addb_viewer.cli import main as cli
from solver.results import load_processed, save_processed
from tests.conftest import TORCH_REASON, import_tool

from .conftest import motion, processed_trial


@pytest.fixture(scope="module")
def out_dirs(tmp_path_factory: pytest.TempPathFactory) -> list:
    base = tmp_path_factory.mktemp("bench")
    dirs = []
    for i, name in enumerate(("s1", "s2")):
        t = processed_trial(30, subject=name, q=motion(30, accel=(0.3 * i, 0.0, 0.0)))
        save_processed(base / name / t.trial / "trial.npz", t)
        dirs.append(base / name)
    return dirs


def _true_grm_error(out_dir) -> np.ndarray:
    """Per frame, the GRM error of a prediction of no moment, N·m/kg, by hand from the saved
    plates: |(CoP - foot origin) x F + free moment| of each foot, mean over the two feet."""
    t = load_processed(out_dir, "walk")
    per_foot = []
    for plate, foot in zip(t.plates, ("calcn_r", "calcn_l"), strict=True):
        arm = np.nan_to_num(plate.cop - t.body_position[:, t.body_names.index(foot)])
        per_foot.append(np.linalg.norm(np.cross(arm, plate.force) + plate.free_moment, axis=1))
    return np.mean(per_foot, axis=0) / t.mass_kg


def test_benchmark_prints_and_writes_the_table(out_dirs, tmp_path, capsys) -> None:
    """The command's table and files; the rows carry the benchmark's numbers: the analytical
    baseline predicts no ground moment, so its GRM error (both contact rules) is the true
    moment, computed here from the plates."""
    out = tmp_path / "report"
    argv = ["benchmark", *map(str, out_dirs), "--contact", "measured", "--contact", "kinematic", "-o", str(out), "--filtering"]
    assert cli(argv) == 0
    text = capsys.readouterr().out
    assert "analytical (measured contact)" in text and "GRF error (N/kg)" in text
    assert "benchmark frames: 60" in text and "activities (annotations): none annotated" in text
    report = json.loads((out / "benchmark.json").read_text())
    assert report["command"].startswith("addb benchmark ") and "--filtering" in report["command"]
    assert [r["method"] for r in report["rows"]] == ["analytical (measured contact)", "analytical (kinematic contact)"]
    assert (out / "benchmark.md").is_file() and (out / "filtering_study.md").is_file()
    true_grm = np.concatenate([_true_grm_error(d) for d in out_dirs]).mean()
    for row in report["rows"]:
        assert row["frames"] == 60 and row["grm"] == pytest.approx(true_grm, rel=1e-9), row["method"]


def test_benchmark_rejects_a_folder_that_is_not_a_subject(tmp_path, capsys) -> None:
    assert cli(["benchmark", str(tmp_path)]) == 1
    assert "neither a processed output folder nor a subject folder" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["mlp", "hybrid"])
def test_trained_methods_need_training_subjects(out_dirs, tmp_path, capsys, method) -> None:
    import_tool("torch", reason=TORCH_REASON)
    assert cli(["benchmark", str(out_dirs[0]), "--method", method, "-o", str(tmp_path)]) == 1
    assert "no training subject" in capsys.readouterr().err


def test_activity_durations_come_from_the_review_record(out_dirs, tmp_path) -> None:
    from addb_viewer.commands.benchmark import activity_seconds
    from annotations import AnnotationStore

    subject = tmp_path / "subject"
    subject.mkdir()
    assert activity_seconds([(out_dirs[0], subject)]) is None  # no review record yet
    with AnnotationStore.open(subject, reviewer="test") as store:
        store.set_trial_info("walk", n_frames=30, rate_hz=100.0)
        store.add_activity("walk", 0, 20, "overground_walking")
        store.add_activity("walk", 20, 30, "overground_running")
    secs = activity_seconds([(out_dirs[0], subject), (out_dirs[1], None)])
    assert secs == {"overground_walking": 0.2, "overground_running": 0.1}


def test_an_output_without_dynamics_names_its_skipped_trials(tmp_path, capsys) -> None:
    """``addb kinematics`` output of the walk (no dynamics on any trial): the error said "see
    the skipped trials" without showing them, and called the walk's reason "no force plates"
    although it has them. It now lists each skipped trial with its reason."""
    from tests.conftest import SHARED_DATA

    out = tmp_path / "walk_kin"
    assert cli(["kinematics", str(SHARED_DATA / "subjects" / "rajagopal2016_walk"), "--out", str(out)]) == 0
    capsys.readouterr()
    assert cli(["benchmark", str(out), "-o", str(tmp_path / "report")]) == 1
    err = capsys.readouterr().err
    reason = "no dynamics (no force plates, or processed for kinematics only)"
    assert f"no trial with force data to score; skipped trials: rajagopal2016_walk/static: {reason}; rajagopal2016_walk/walk: {reason}" in err, err
    assert not (tmp_path / "report").exists()
