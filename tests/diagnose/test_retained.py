"""The share of a landmark marker's shift that inverse kinematics leaves in that marker's
error (:func:`solver.diagnose.data.retained_displacement`) predicts what re-solving the
pose actually does, on real walking frames."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from solver.diagnose.data import retained_displacement
from solver.io.trc import read_trc
from solver.kinematics.ik import FrameSolver, IkSettings, initial_pose
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from tests.conftest import SHARED_DATA

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


def exact_pose(solver: FrameSolver, q0: np.ndarray, y: np.ndarray, anchor: np.ndarray) -> np.ndarray:
    """The frame's IK optimum (markers plus the solver's pull toward ``anchor``), solved
    to convergence by scipy (the solver itself stops at a relative cost decrease of 1e-5)."""
    lam = solver.settings.temporal_weight
    seen = np.isfinite(y).all(axis=1)
    free = solver.free

    def full(x: np.ndarray) -> np.ndarray:
        q = q0.copy()
        q[free] = x
        return solver.sk.cmap.complete(q)

    def fun(x: np.ndarray) -> np.ndarray:
        return np.concatenate([solver.residual(full(x), y, seen)[0], np.sqrt(lam) * (x - anchor[free])])

    def jac(x: np.ndarray) -> np.ndarray:
        return np.vstack([solver.residual(full(x), y, seen)[1], np.sqrt(lam) * np.eye(free.size)])

    return full(least_squares(fun, q0[free], jac=jac, xtol=1e-12, ftol=1e-12, gtol=1e-12).x)


@pytest.fixture(scope="module")
def solved() -> tuple[Skeleton, FrameSolver, list[str], np.ndarray, np.ndarray]:
    """Generic Rajagopal model, walk markers of three frames, their poses at the optimum."""
    sk = Skeleton(read_osim(WALK / "unscaled_generic.osim"))
    mk = read_trc(WALK / "trials" / "walk" / "markers.trc")
    names = [n for n in mk.names if n in sk.marker_names]
    obs = np.asarray(mk.positions)[[60, 120, 180]][:, [mk.names.index(n) for n in names]]
    solver = FrameSolver(sk, sk.marker_index(names), np.ones(len(names)), IkSettings())
    q = []
    for y in obs:
        q0 = solver.solve(initial_pose(solver, y), y, max_iterations=100)[0]
        q.append(exact_pose(solver, q0, y, q0))
        q[-1] = exact_pose(solver, q[-1], y, q[-1])  # the pull toward the pose itself vanishes
    return sk, solver, names, obs, np.array(q)


def test_retained_share_matches_a_re_solved_pose(solved) -> None:
    sk, solver, names, obs, q = solved
    landmarks = np.array([m.fixed for m in sk.osim.markers if m.name in names])
    assert landmarks.sum() >= 5
    seen = np.isfinite(obs).all(axis=2)
    kept = retained_displacement(sk, q, names, seen, landmarks)
    rng = np.random.default_rng(3)
    absorbed, misses = [], []
    for j in np.flatnonzero(landmarks):
        for t in range(obs.shape[0]):
            d = 0.003 * rng.standard_normal(3)
            y = obs[t].copy()
            y[j] -= d  # the model marker sits d further from its observation: error + d
            q_new = exact_pose(solver, q[t], y, q[t])
            before = sk.marker_positions(q[t], solver.markers[[j]])[0, 0] - obs[t, j]
            after = sk.marker_positions(q_new, solver.markers[[j]])[0, 0] - y[j]
            change = after - before
            misses.append(np.linalg.norm(change - kept[t, j] @ d) / np.linalg.norm(d))
            absorbed.append(np.linalg.norm(d - change) / np.linalg.norm(d))
    misses, absorbed = np.array(misses), np.array(absorbed)
    # linear prediction (Gauss-Newton Hessian, marker errors of an unscaled model): within
    # 20 % of the shift everywhere, and far closer than the identity (no pose change) is
    assert misses.max() < 0.2, misses.max()
    assert np.median(misses) < 0.25 * np.median(absorbed), (np.median(misses), np.median(absorbed))
    assert absorbed.max() > 0.4  # the pose does take up much of some shifts
    # the other markers keep the identity
    assert np.allclose(kept[:, ~landmarks], np.eye(3))
