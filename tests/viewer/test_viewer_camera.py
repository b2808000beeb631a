"""The camera frames the subject when a trial loads; sagittal, frontal and top views; the
pelvis followed with the reviewer's orbit kept (poses checked against the trial's pelvis);
the framing keeps every frame's skeleton inside a narrow canvas below the queue's window
(projected through the same pinhole camera three.js draws), a trial too long to frame is
followed with its skeleton in view, and each page is framed for the canvas it reports (again
when that changes size, not when the reviewer orbits)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from viewer_support import ProtocolClient, wait_for
from viser import _messages

from addb_viewer.app.camera import (
    DEFAULT_CANVAS,
    DISTANCE_M,
    EDGE_PX,
    MAX_DISTANCE_M,
    CameraPose,
    Canvas,
    body_points,
    followed,
    framed_view,
    framing_point,
    project,
    view_pose,
)


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


def _stretched(body_position: np.ndarray, factor: float) -> np.ndarray:
    """The trial's bodies with the pelvis path stretched ``factor`` times along X (a longer
    walk, each skeleton unchanged)."""
    pelvis_x = body_position[:, :1, 0]
    out = body_position.copy()
    out[..., 0] += (factor - 1.0) * (pelvis_x - pelvis_x[0])
    return out


def test_the_framing_keeps_every_frame_of_the_walk_inside_a_narrow_canvas(demo_paths, make_app) -> None:
    """A 1366 x 800 window leaves the 3D canvas about 480 px wide, and the dataset queue covers
    its top 310 px: every frame's skeleton box (all frames, not only the sampled ones the
    framing uses) projects inside the rest, with the gap kept, from the sagittal, frontal
    and top views; at the default canvas the camera stays nearer."""
    bp = make_app(demo_paths).trial.body_position
    every = body_points(bp, np.arange(len(bp)))
    narrow = Canvas(480.0, 800.0, np.radians(75.0), top=310.0)
    for view in ("Sagittal", "Frontal", "Top"):
        pose, fits = framed_view(view, bp, narrow)
        px, depth = project(every, pose, narrow)
        assert fits and (depth > 0).all()
        assert px[:, 0].min() >= EDGE_PX - 1e-6 and px[:, 0].max() <= narrow.width - EDGE_PX + 1e-6, view
        assert px[:, 1].min() >= narrow.top + EDGE_PX - 1e-6 and px[:, 1].max() <= narrow.height - EDGE_PX + 1e-6, view
        # the frames it samples centred in the free part of the canvas (to a pixel)
        px, _ = project(body_points(bp), pose, narrow)
        assert abs(0.5 * (px[:, 0].min() + px[:, 0].max()) - narrow.width / 2) < 1.0, view
        assert abs(0.5 * (px[:, 1].min() + px[:, 1].max()) - (narrow.top + narrow.height) / 2) < 1.0, view
    pose, _ = framed_view("Sagittal", bp, narrow)
    far = np.linalg.norm(np.subtract(pose.position, pose.look_at))
    pose, _ = framed_view("Sagittal", bp, DEFAULT_CANVAS)
    assert DISTANCE_M <= np.linalg.norm(np.subtract(pose.position, pose.look_at)) < far


def test_a_walk_too_long_to_frame_is_followed_with_its_skeleton_in_view(demo_paths, make_app) -> None:
    """The walk stretched eight times (24 m) does not fit even from MAX_DISTANCE_M: the pose
    frames the current frame, and following the pelvis from there keeps every frame's
    skeleton inside the canvas."""
    bp = _stretched(make_app(demo_paths).trial.body_position, 8.0)
    canvas = Canvas(715.0, 1000.0, np.radians(75.0), top=310.0)
    pose, fits = framed_view("Sagittal", bp, canvas, frame=100)
    assert not fits
    assert np.linalg.norm(np.subtract(pose.position, pose.look_at)) <= MAX_DISTANCE_M
    offset = np.asarray(pose.look_at) - bp[100, 0]
    position, look = np.asarray(pose.position), np.asarray(pose.look_at)
    for k in range(len(bp)):
        position, look = followed(position, look, bp[k, 0] + offset)
        px, depth = project(body_points(bp, np.array([k])), CameraPose(tuple(position), tuple(look), pose.up), canvas)
        assert (depth > 0).all() and (px[:, 0] >= 0).all() and (px[:, 0] <= canvas.width).all(), k
        assert (px[:, 1] >= canvas.top).all() and (px[:, 1] <= canvas.height).all(), k


def test_app_frames_the_loaded_trial_and_switches_views(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    assert app.trial is not None
    cam = app.server.initial_camera
    pose, fits = framed_view("Sagittal", app.trial.body_position, DEFAULT_CANVAS)
    assert fits and np.allclose(cam.look_at, pose.look_at) and np.allclose(cam.position, pose.position)
    app.seek(100)
    pose = app.camera_view("Frontal")
    assert np.allclose(cam.look_at, pose.look_at) and np.allclose(cam.position, pose.position)
    d = np.asarray(cam.position) - np.asarray(cam.look_at)
    assert np.argmax(np.abs(d)) == 0 and d[0] >= DISTANCE_M  # from in front, along +X
    assert not app.panel.follow.value


def _pose_of(client) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(client.camera.position), np.asarray(client.camera.look_at)


def test_each_page_is_framed_for_its_own_canvas_and_again_when_it_changes_size(demo_paths, make_app) -> None:
    """A page (a protocol client reporting a 480 x 360 canvas, fov 1 rad) is framed for that
    canvas when it connects; when it reports another size (200 x 600) it is framed again for
    it; a camera report of the same size (the reviewer orbiting) leaves the camera where the
    reviewer put it."""
    app = make_app(demo_paths)
    bp = app.trial.body_position

    def framed(width: float, height: float, fov: float) -> CameraPose:
        return framed_view("Sagittal", bp, Canvas(width, height, fov, app.cameras.canvas_top_px))[0]

    def report(page: ProtocolClient, width: int, height: int, position: tuple[float, float, float]) -> None:
        page.send(_messages.ViewerCameraMessage(
            wxyz=(1.0, 0.0, 0.0, 0.0), position=position, fov=1.0, near=0.01, far=100.0, image_height=height,
            image_width=width, look_at=(0.0, 1.0, 0.0), up_direction=(0.0, 1.0, 0.0)))  # fmt: skip

    page = ProtocolClient(app.port)
    try:
        client = wait_for(lambda: next(iter(app.server.get_clients().values()), None), what="the page connected")
        small = framed(480, 360, 1.0)
        wait_for(lambda: np.allclose(_pose_of(client)[0], small.position), 20, "framed for 480 x 360")
        assert np.allclose(_pose_of(client)[1], small.look_at)
        report(page, 200, 600, (0.0, 1.0, 3.0))
        narrow = framed(200, 600, 1.0)
        wait_for(lambda: np.allclose(_pose_of(client)[0], narrow.position), 20, "framed again for 200 x 600")
        # another pose than the first (so the wait above did not pass by chance)
        assert np.linalg.norm(np.subtract(narrow.position, small.position)) > 0.1
        orbit = (5.0, 2.0, 4.0)
        report(page, 200, 600, orbit)
        wait_for(lambda: np.allclose(_pose_of(client)[0], orbit), 20, "the reviewer's orbit")
        time.sleep(1.0)  # a re-framing would have replaced it by now
        assert np.allclose(_pose_of(client)[0], orbit)
    finally:
        page.close()


def test_a_page_whose_canvas_cannot_hold_the_trial_follows_it_alone(demo_paths, make_app) -> None:
    """The walk stretched eight times: a page follows the pelvis (its camera keeps the
    framing's offset from the pelvis as frames change) while "Follow pelvis" stays unticked;
    a second page at the same size does too, and once the trial fits again (the stretch
    undone, the view chosen again) neither follows any more."""
    app = make_app(demo_paths)
    original = app.trial.body_position.copy()
    app.trial.body_position[:] = _stretched(original, 8.0)
    pages = [ProtocolClient(app.port), ProtocolClient(app.port)]
    try:
        clients = wait_for(lambda: len(app.server.get_clients()) == 2 and list(app.server.get_clients().values()), what="two pages")
        wait_for(lambda: len(app.cameras.following) == 2, 20, "both pages following")
        assert not app.panel.follow.value
        bp = app.trial.body_position
        app.seek(50)
        offset = {c.client_id: _pose_of(c)[1] - bp[50, 0] for c in clients}
        app.seek(180)
        for c in clients:
            assert np.allclose(_pose_of(c)[1] - bp[180, 0], offset[c.client_id])
            assert np.linalg.norm(bp[180, 0] - bp[50, 0]) > 5.0  # the pelvis moved far: the camera went with it
        app.trial.body_position[:] = original
        app.camera_view("Sagittal")
        assert not app.cameras.following
        look = {c.client_id: _pose_of(c)[1] for c in clients}
        app.seek(20)
        assert all(np.allclose(_pose_of(c)[1], look[c.client_id]) for c in clients)  # framed, not following
    finally:
        for page in pages:
            page.close()
