"""The walk's joint torques against OpenSim's inverse dynamics of the same trial
(``../shared/oracles/opensim_id_walk.sto``; :mod:`tests.dynamics.opensim_torques`).

The default (band) fit's leg torques differ from OpenSim's by 0.17 N·m/kg RMS (measured
2026-11-24; OpenSim filters at 6 Hz and uses its own IK and scaled model, so they are not
expected to agree exactly). The converged fit reaches far lower residuals by letting the
motion's accelerations take them up (the swinging leg and the trunk), and its torques are
0.72 N·m/kg from OpenSim's: it fails, and is a strict expected failure until it is mended
(tests/benchmarks/RESULTS.md, "The converged fit").
"""

from __future__ import annotations

from pathlib import Path

import pytest

from solver.io.subject import load_subject
from solver.pipeline import options_for_fit, process_subject
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy
from tests.dynamics.opensim_torques import compare_with_opensim_id

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
#: RMS difference of the leg joint torques from OpenSim's ID, N·m/kg.
TOLERANCE = 0.25


@pytest.mark.parametrize(
    "fit",
    [
        "default",
        pytest.param("converged", marks=pytest.mark.xfail(strict=True, reason=(
            "the converged fit's motion takes up the residual with leg and trunk accelerations: "
            "0.72 N·m/kg from OpenSim's ID (hip rotation accelerations of 660 rad/s² RMS over 0.4 s)"))),
    ],
)  # fmt: skip
def test_leg_joint_torques_are_near_opensims_inverse_dynamics(fit: str, tmp_path: Path) -> None:
    subject = writable_copy(WALK, tmp_path / "rajagopal2016_walk")
    process_subject(subject, tmp_path / "out", options=options_for_fit(fit, ("walk",)))
    result = compare_with_opensim_id(load_processed(tmp_path / "out", "walk"), load_subject(subject).mass_kg)
    assert result.frames > 100
    assert result.rms_difference < TOLERANCE, result.per_coordinate
