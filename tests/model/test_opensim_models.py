"""Every model in shared/data converts exactly: kinematics and dynamics against OpenSim 4.6
computed at test time (test extra ``opensim``; skipped when it is absent, failed under CI=true).

Covers the 4.x and 3.x layouts, SimmSpline and PolynomialFunction knees, Weld,
Pin and Universal joints, models with and without arms.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import OPENSIM, OPENSIM_REASON, require_tool
from tests.model.conftest import SHARED, skeleton

ALL_MODELS = sorted(
    {p.resolve() for p in (SHARED / "data").rglob("*.osim")} | {(SHARED / "oracles" / "opensim_scaled_walk.osim").resolve()}
)


@pytest.fixture(scope="module", params=ALL_MODELS, ids=lambda p: f"{p.parent.name}/{p.name}")
def pair(request: pytest.FixtureRequest) -> tuple:
    require_tool("opensim", OPENSIM, OPENSIM_REASON)
    from tests.model import opensim_ref as ref

    path = str(request.param)
    return skeleton(path), ref.OpenSimModel(path)


@pytest.mark.opensim
def test_kinematics_match(pair: tuple) -> None:
    from tests.model.opensim_ref import random_states

    sk, om = pair
    assert list(sk.coordinate_names) == om.names
    q = sk.cmap.complete(random_states(sk.ranges, 4, seed=1))
    for k in range(q.shape[0]):
        om.set_state(q[k])
        names, pos = om.markers()
        np.testing.assert_allclose(sk.marker_positions(q[k], sk.marker_index(names))[0], pos, atol=1e-5)
        bnames, bpos = om.bodies()
        _, ours = sk.body_poses(q[k])
        np.testing.assert_allclose(ours[0, [sk.body_index(b) for b in bnames]], bpos, atol=1e-5)
        np.testing.assert_allclose(sk.center_of_mass(q[k])[0], om.com(), atol=1e-5)


@pytest.mark.opensim
def test_inverse_dynamics_match(pair: tuple) -> None:
    from tests.model.opensim_ref import random_states

    sk, om = pair
    rng = np.random.default_rng(2)
    q = sk.cmap.complete(random_states(sk.ranges, 3, seed=3))
    qd = rng.uniform(-2, 2, q.shape)
    qdd = rng.uniform(-10, 10, q.shape)
    ours = sk.inverse_dynamics(q, qd, qdd, constrained=False, opensim_compatible=True).tau
    for k in range(q.shape[0]):
        theirs = om.inverse_dynamics(q[k], qd[k], qdd[k])
        assert np.all(np.abs(ours[k] - theirs) <= np.maximum(1e-3, 1e-5 * np.abs(theirs)))


def test_models_cover_the_feature_list() -> None:
    """The parametrization above really exercises the joint and function types we claim."""
    text = "".join(Path(p).read_text(errors="ignore") for p in ALL_MODELS)
    for token in ("<WeldJoint", "<UniversalJoint", "<PinJoint", "<PolynomialFunction", "<SimmSpline",
                  "<MultiplierFunction", "<CoordinateCouplerConstraint", 'Version="30000"'):
        assert token in text
