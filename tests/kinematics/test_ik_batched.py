"""The keyframe option of the trajectory solve (``IkSettings.keyframe_stride``): the batched
solver repeats the per-frame solver exactly, and keyframes every 4 frames reach the
frame-by-frame solve's marker errors on real walking with a motion no rougher."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from solver.io.trc import read_trc
from solver.kinematics.ik import FrameSolver, IkSettings, initial_pose, solve_trajectory
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from tests.conftest import SHARED_DATA

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@cache
def walk() -> tuple[FrameSolver, np.ndarray, np.ndarray]:
    """Generic Rajagopal model, the walk's markers, a solver with keyframes every 4 frames,
    and the frame-by-frame solve (the default, ``keyframe_stride=1``)."""
    sk = Skeleton(read_osim(WALK / "unscaled_generic.osim"))
    mk = read_trc(WALK / "trials" / "walk" / "markers.trc")
    names = [n for n in mk.names if n in sk.marker_names]
    obs = np.asarray(mk.positions)[:, [mk.names.index(n) for n in names]]
    solver = FrameSolver(sk, sk.marker_index(names), np.ones(len(names)), IkSettings(keyframe_stride=4))
    one = FrameSolver(sk, solver.markers, np.ones(len(names)), IkSettings())
    assert one.settings.keyframe_stride == 1
    q = solve_trajectory(one, obs, initial_pose(one, obs[0]))
    return solver, obs, q


def roughness(q: np.ndarray) -> float:
    """Mean absolute second difference of the coordinates over time (rad or m)."""
    return float(np.mean(np.abs(np.diff(q, 2, axis=0))))


def frame_costs(solver: FrameSolver, q: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """``(T,)`` sum of squared marker errors per frame, m²."""
    e = solver.sk.marker_positions(q, solver.markers) - obs
    return np.nansum(np.sum(e**2, axis=2), axis=1)


def test_solve_many_repeats_solve_frame_by_frame() -> None:
    solver, obs, q = walk()
    frames = np.arange(10, 230, 5)
    start = q[frames - 3]  # three frames (30 ms) away from the answer
    q_many, cost_many = solver.solve_many(start, obs[frames], start)
    single = [solver.solve(s, obs[f], s) for s, f in zip(start, frames)]
    np.testing.assert_allclose(q_many, np.array([s[0] for s in single]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(cost_many, [s[1] for s in single], rtol=1e-9)
    assert np.abs(q_many - start).max() > 1e-2  # the starts were not already the answers


def test_keyframe_scheme_reaches_the_frame_by_frame_marker_errors_no_rougher() -> None:
    solver, obs, q_one = walk()
    q = solve_trajectory(solver, obs, q_one[0])
    assert solver.settings.keyframe_stride > 1
    assert roughness(q) <= roughness(q_one)
    c_one, c = frame_costs(solver, q_one, obs), frame_costs(solver, q, obs)
    n_seen = np.isfinite(obs).all(axis=2).sum(axis=1)
    rms_one, rms = (np.sqrt(x.sum() / n_seen.sum()) for x in (c_one, c))
    assert rms <= rms_one + 1e-5  # m: 0.001 cm
    assert np.all(c <= 1.01 * c_one)  # no frame 1 % worse


def test_frames_without_markers_hold_the_last_solved_pose() -> None:
    solver, obs, q_one = walk()
    gappy = obs[:60].copy()
    gappy[:3] = np.nan  # before the first seen frame: the start pose
    gappy[20:27] = np.nan  # a gap: the pose of frame 19
    gappy[59] = np.nan  # at the end: the pose of frame 58
    q = solve_trajectory(solver, gappy, q_one[3])
    np.testing.assert_array_equal(q[:3], np.repeat(q_one[3][None], 3, axis=0))
    np.testing.assert_array_equal(q[20:27], np.repeat(q[19][None], 7, axis=0))
    np.testing.assert_array_equal(q[59], q[58])
    assert np.abs(q[28] - q[19]).max() > 1e-3  # solving resumed after the gap


def test_stride_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="keyframe_stride must be at least 1, got 0"):
        IkSettings(keyframe_stride=0)
