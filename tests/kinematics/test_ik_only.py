"""``addb kinematics --model SCALED.osim``: inverse kinematics alone with a model already
scaled (OpenSim's InverseKinematicsTool's job). On the model an earlier full run scaled and
wrote, it gives that run's coordinates and marker errors, reads only the trials asked for,
and names bad input. Without --model, ``--trial`` solves only the trials asked for after the
scaling, which every trial enters."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main as cli
from solver.errors import KinematicsError, MarkerMismatchError
from solver.io.mot import read_coordinates
from solver.pipeline import ProcessOptions, process_kinematics
from tests.conftest import SHARED_DATA

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
SCALED = "rajagopal2016_walk_scaled.osim"


def _coordinates(folder: Path, trial: str) -> tuple[tuple[str, ...], np.ndarray]:
    """Column names and ``(T, K)`` values of a trial's _ik.mot, as written (no unit change)."""
    table = read_coordinates(folder / trial / f"{trial}_ik.mot", rotational=[])
    return table.column_names, table.data


@pytest.fixture(scope="module")
def full_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("full") / "out"
    process_kinematics(WALK, out)
    return out


def test_ik_alone_on_the_written_scaled_model_gives_the_full_runs_motion(full_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "ik"
    assert cli(["kinematics", str(WALK), "--out", str(out), "--model", str(full_run / SCALED), "--trial", "walk"]) == 0
    # only the trial asked for: the static trial, which only scaling needs, is not solved
    assert sorted(p.name for p in out.iterdir()) == sorted([SCALED, "subject.json", "walk"])
    assert (out / SCALED).read_bytes() == (full_run / SCALED).read_bytes()
    full = json.loads((full_run / "walk" / "results.json").read_text())
    mine = json.loads((out / "walk" / "results.json").read_text())
    assert mine["n_frames"] == full["n_frames"] == 238
    assert mine["markers_used"] == full["markers_used"]
    assert abs(mine["marker_rms_m"] - full["marker_rms_m"]) < 1e-6, (mine["marker_rms_m"], full["marker_rms_m"])
    assert mine["stage_seconds"]["scaling"] == 0.0 < full["stage_seconds"]["scaling"]
    names_a, a = _coordinates(full_run, "walk")
    names_b, b = _coordinates(out, "walk")
    assert names_a == names_b and a.shape == b.shape == (238, 39)
    assert np.abs(a - b).max() < 1e-6, np.abs(a - b).max()
    summary = json.loads((out / "subject.json").read_text())
    assert summary["scaled_model"] == str((full_run / SCALED).resolve())
    assert summary["body_scales"] == {} and summary["marker_offsets_m"] == {}


def test_ik_alone_names_an_unknown_trial(full_run: Path, tmp_path: Path) -> None:
    with pytest.raises(KinematicsError, match="unknown trial.*wlk.*static, walk"):
        process_kinematics(WALK, tmp_path / "out", options=ProcessOptions(trials=("wlk",)), scaled_model=full_run / SCALED)
    assert not (tmp_path / "out").exists()


def test_ik_alone_with_a_model_of_other_markers_names_the_trial(full_run: Path, tmp_path: Path) -> None:
    text = (full_run / SCALED).read_text()
    assert text.count('<Marker name="') > 60
    other = tmp_path / "renamed_markers.osim"  # the same model, no marker name in common with the trial
    other.write_text(text.replace('<Marker name="', '<Marker name="x_'))
    with pytest.raises(MarkerMismatchError, match="walk"):
        process_kinematics(WALK, tmp_path / "out", options=ProcessOptions(trials=("walk",)), scaled_model=other)
    assert not (tmp_path / "out").exists()


def test_scaling_with_one_trial_asked_for_solves_that_trials_motion_only(full_run: Path, tmp_path: Path) -> None:
    """``addb kinematics --trial walk`` (scaling, no --model): every trial enters the scale
    fit, so the scaled model is the full run's, byte for byte; only the walk's inverse
    kinematics runs after it (the static trial's was solved and thrown away), and its motion
    is the full run's."""
    said: list[str] = []
    out = tmp_path / "walk_only"
    process_kinematics(WALK, out, options=ProcessOptions(trials=("walk",)), progress=lambda m, f: said.append(m))
    assert "inverse kinematics: walk" in said and "inverse kinematics: static" not in said, said
    assert (out / SCALED).read_bytes() == (full_run / SCALED).read_bytes()
    assert sorted(p.name for p in out.iterdir()) == sorted([SCALED, "subject.json", "walk"])
    names_a, a = _coordinates(full_run, "walk")
    names_b, b = _coordinates(out, "walk")
    assert names_a == names_b and np.array_equal(a, b)
    full = json.loads((full_run / "walk" / "results.json").read_text())
    mine = json.loads((out / "walk" / "results.json").read_text())
    assert mine["marker_rms_m"] == full["marker_rms_m"] and mine["markers_used"] == full["markers_used"]
