"""The example subjects of ``scripts/make_example_subject.py`` beyond the Camargo circuit:
their stated body masses follow from the force plates as the script says, and the stair
descent (whose head marker has gaps exported as zeros) processes to a good fit."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from solver.dynamics.preprocess import true_runs
from solver.io.c3d import read_c3d
from solver.io.mot import read_forces
from solver.io.types import ForceRecording
from solver.pipeline import process_subject
from tests.conftest import SHARED_DATA

REPO = Path(__file__).resolve().parents[2]
TRIALS = SHARED_DATA / "trials"
G = 9.80665


def _stated_mass(example: str) -> float:
    sys.path.insert(0, str(REPO / "scripts"))
    try:
        from make_example_subject import EXAMPLES
    finally:
        sys.path.pop(0)
    return float(EXAMPLES[example]["subject"]["massKg"])


def _midstance_mass(forces: ForceRecording, *, zero_unloaded: bool) -> float:
    """Mean vertical force / g from the first plate contact's mid-stance to the last one's:
    every foot is on a plate in between (the script's estimate)."""
    total = np.zeros(forces.n_frames)
    mids = []
    for plate in forces.plates:
        fy = plate.force[:, 1]
        on = fy > 20.0
        total += fy - (np.median(fy[~on]) if zero_unloaded else 0.0)
        mids += [forces.time[a:b].mean() for a, b in true_runs(on) if b - a > 50]
    sel = (forces.time >= min(mids)) & (forces.time <= max(mids))
    return float(total[sel].mean() / G)


def test_stair_descent_mass_is_the_stride_mean_of_the_vertical_force() -> None:
    forces = read_forces(TRIALS / "stairdown" / "grf.mot")
    assert _midstance_mass(forces, zero_unloaded=False) == pytest.approx(_stated_mass("stairdown"), abs=0.5)


@pytest.mark.parametrize("trial", ["walking2", "walking5"])
def test_c3d_walk_mass_is_the_step_mean_of_the_zeroed_vertical_force(trial: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _, forces = read_c3d(TRIALS / "opensim_c3d" / f"{trial}.c3d")
    assert _midstance_mass(forces, zero_unloaded=True) == pytest.approx(_stated_mass("opensim_c3d_walking"), abs=0.5)


@pytest.mark.slow
def test_stair_descent_processes_to_a_good_fit(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "scripts/make_example_subject.py", "stairdown", str(tmp_path / "stairs")], check=True, cwd=REPO)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        res = process_subject(tmp_path / "stairs", tmp_path / "out")
    td = res.dynamics.trial("stairdown")
    assert td.metrics["marker_rms_m"] < 0.01  # with the zero gaps read as markers: 10 cm
    assert td.metrics["hicks_linear_ok"] and td.metrics["hicks_angular_ok"]
    assert abs(res.dynamics.mass_kg - _stated_mass("stairdown")) < 2.0
