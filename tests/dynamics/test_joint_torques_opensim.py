"""The walk's joint torques against OpenSim's inverse dynamics of the same trial
(``../shared/oracles/opensim_id_walk.sto``; :mod:`tests.dynamics.opensim_torques`).

The default (converged, joint mass) fit's leg torques differ from OpenSim's by 0.175 N·m/kg
RMS and the band fit's by 0.173 (OpenSim filters at 6 Hz and uses its own IK and scaled
model, so they are not expected to agree exactly). The alternation (``--fit rounds``) run
to convergence with the band fit's weights (accelerations 500 rad/s², residuals 2 N and
2 N·m) lets the motion's accelerations take up the residual instead (the swinging leg and
the trunk), and the torques are 0.72 N·m/kg from OpenSim's: that setting is a strict
expected failure, the reason
:data:`solver.dynamics.fit.CONVERGED_WEIGHTS` exists (tests/benchmarks/RESULTS.md, blocks
``joint-torques`` and ``converged-weights``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from solver.dynamics.fit import alternating_fit
from solver.dynamics.stage import DynamicsOptions
from solver.io.subject import load_subject
from solver.pipeline import ProcessOptions, options_for_fit, process_subject
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy
from tests.dynamics.opensim_torques import BAND_WEIGHTS, compare_with_opensim_id

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
#: RMS difference of the leg joint torques from OpenSim's ID, N·m/kg.
TOLERANCE = 0.2


@pytest.mark.parametrize(
    "fit",
    [
        "default",
        "band",
        pytest.param("alternation with the band fit's weights", marks=pytest.mark.xfail(strict=True, reason=(
            "run to its minimum with accelerations at 500 rad/s² against residuals at 2 N, the motion takes up the "
            "residual with leg and trunk accelerations and the leg joint torques leave OpenSim's ID by more than the "
            "tolerance (the joint fit with these weights: block joint-torques of tests/benchmarks/RESULTS.md)"))),
    ],
)  # fmt: skip
def test_leg_joint_torques_are_near_opensims_inverse_dynamics(fit: str, tmp_path: Path) -> None:
    subject = writable_copy(WALK, tmp_path / "rajagopal2016_walk")
    if fit in ("default", "band"):
        options = options_for_fit(fit, ("walk",))
    else:
        options = ProcessOptions(trials=("walk",), dynamics=DynamicsOptions(fit=alternating_fit(**BAND_WEIGHTS)))
    process_subject(subject, tmp_path / "out", options=options)
    result = compare_with_opensim_id(load_processed(tmp_path / "out", "walk"), load_subject(subject).mass_kg)
    assert result.frames > 100
    assert result.rms_difference < TOLERANCE, result.per_coordinate
