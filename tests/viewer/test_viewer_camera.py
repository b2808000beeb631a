"""The camera frames the subject when a trial loads; sagittal, frontal and top views; the
pelvis followed with the reviewer's orbit kept (poses checked against the trial's pelvis)."""

from __future__ import annotations

import numpy as np
import pytest

from addb_viewer.app.camera import DISTANCE_M, followed, framing_point, view_pose


def test_views_look_at_the_point_from_the_anatomical_directions() -> None:
    look = np.array([1.0, 0.9, -0.2])
    for view, axis in (("Sagittal", 2), ("Frontal", 0), ("Top", 1)):
        pose = view_pose(view, look)
        d = np.asarray(pose.position) - look
        assert np.allclose(pose.look_at, look)
        assert np.argmax(np.abs(d)) == axis and d[axis] == pytest.approx(DISTANCE_M)
        assert abs(np.dot(d / np.linalg.norm(d), pose.up)) < 0.2  # up is never the view axis
    with pytest.raises(ValueError, match="Sagittal, Frontal, Top"):
        view_pose("Oblique", look)


def test_framing_ignores_unknown_frames_and_following_keeps_the_offset() -> None:
    pelvis = np.array([[0.0, 1.0, 0.0], [np.nan, np.nan, np.nan], [2.0, 1.0, 0.0], [4.0, 1.0, 0.0]])
    assert np.allclose(framing_point(pelvis), [2.0, 1.0, 0.0])
    assert np.allclose(framing_point(np.full((3, 3), np.nan)), [0.0, 1.0, 0.0])
    pos, look = followed(np.array([1.0, 2.0, 5.0]), np.array([0.0, 1.0, 0.0]), np.array([3.0, 1.1, 0.2]))
    assert np.allclose(look, [3.0, 1.1, 0.2]) and np.allclose(pos - look, [1.0, 1.0, 5.0])
    same = followed(np.ones(3), np.zeros(3), np.full(3, np.nan))
    assert np.allclose(same[0], 1.0) and np.allclose(same[1], 0.0)


def test_app_frames_the_loaded_trial_and_switches_views(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    assert app.trial is not None
    cam = app.server.initial_camera
    assert np.allclose(cam.look_at, framing_point(app.trial.body_position[:, 0, :]))
    app.seek(100)
    pose = app.camera_view("Frontal")
    pelvis = app.trial.body_position[100, 0, :]
    assert np.allclose(pose.look_at, pelvis) and np.allclose(cam.look_at, pelvis)
    assert np.allclose(np.asarray(cam.position) - pelvis, [DISTANCE_M, 0.4, 0.0])
