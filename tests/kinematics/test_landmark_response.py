"""The scale fit's response to a misplaced landmark marker (solver.kinematics.fit.landmark_scale_response).

A marker recorded off its landmark in one trial pulls the body scales, which move the scaled
landmark toward it; the diagnosis corrects a misplacement estimate by that response. Here
the response is checked against the kinematics stage run again with the marker moved."""

from __future__ import annotations

import numpy as np
import pytest

from solver.io.types import MarkerTrajectories
from solver.kinematics.stage import run_kinematics
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from tests.kinematics.test_kinematics import WALK, walk_result


def _landmark(result, generic, marker: str) -> np.ndarray:
    """The scaled generic location of ``marker`` (its fitted offset not included), m, body frame."""
    m = next(m for m in generic.markers if m.name == marker)
    return np.asarray(m.location) * np.asarray(result.body_scales[m.body])


@pytest.mark.parametrize(
    ("marker", "shift_cm"),
    [("S2", (-1.5, -0.5, 0.8)), ("R.Elbow", (0.3, -2.0, 0.3)), ("L.Knee", (0.5, 1.5, 0.0))],
)
def test_the_landmark_moves_as_the_response_predicts_when_one_trial_misplaces_a_marker(marker: str, shift_cm: tuple) -> None:
    base, trials = walk_result()
    generic = read_osim(WALK / "unscaled_generic.osim")
    shift = np.asarray(shift_cm) / 100.0
    # move the marker in the walk trial (not the static one) by R(t) shift, R its body's
    # orientation in the first solution
    sk = Skeleton(base.model)
    walk = base.trial("walk")
    body = next(m.body for m in generic.markers if m.name == marker)
    rot = sk.body_poses(walk.q)[0][:, sk.body_index(body)]  # (T, 3, 3)
    mk = dict(trials)["walk"]
    pos = np.array(mk.positions)
    j = mk.names.index(marker)
    pos[:, j] += np.einsum("tij,j->ti", rot, shift)
    moved = [("walk", MarkerTrajectories(mk.names, pos, mk.time, mk.rate_hz, mk.source)), ("static", dict(trials)["static"])]
    again = run_kinematics(generic, moved, height_m=1.829)
    actual = _landmark(again, generic, marker) - _landmark(base, generic, marker)
    predicted = np.asarray(base.landmark_scale_response["walk"][marker]) @ shift
    # the response is linear, the fit is not: within 15 % of the landmark's move or 0.3 mm
    assert np.linalg.norm(predicted) > 0.1 * np.linalg.norm(shift)  # the scales do take part of it
    assert np.linalg.norm(actual - predicted) < max(0.15 * np.linalg.norm(actual), 3e-4), (actual, predicted)
    assert set(base.landmark_scale_response) == {"walk", "static"}
