"""Each page's camera in the review app: framing the shown trial for the page's own canvas,
the anatomical views, following the pelvis (the viser side of :mod:`~addb_viewer.app.camera`,
which computes the poses without viser).

Every page (a browser tab, a viser client) reports its canvas size with its camera; a
trial is framed for that size (:func:`~addb_viewer.app.camera.framed_view`), again when the
size changes (a window or docked panel resized), and a page whose canvas cannot hold the
whole trial follows the pelvis instead. Pages still to connect start from the pose framed
for :data:`~addb_viewer.app.camera.DEFAULT_CANVAS`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from addb_viewer.app.camera import (
    DEFAULT_CANVAS,
    CameraPose,
    Canvas,
    followed,
    framed_view,
    view_pose,
)


class PageCameras:
    """The cameras of every page of one viser server.

    Parameters
    ----------
    server
        The ``viser.ViserServer`` whose pages' cameras are set.

    Attributes
    ----------
    view
        The view the cameras were last put in (one of :data:`~addb_viewer.app.camera.VIEWS`).
    canvas_top_px
        Pixels at the top of every canvas covered by a floating window (the dataset queue's),
        where the skeleton is not put.
    following
        Client ids of the pages whose canvas cannot hold the whole trial (they follow the
        pelvis whatever "Follow pelvis" says).

    Trial arguments are the shown trial's ``body_position`` ``(T, B, 3)`` (body origins, m,
    ground frame, body 0 the pelvis) and the frame shown; None when no trial is shown.
    """

    def __init__(self, server: Any) -> None:
        self.server = server
        self.view = "Sagittal"
        self.canvas_top_px = 0.0
        self.following: set[int] = set()
        self._framed_for: dict[int, tuple[float, float]] = {}  # client id -> canvas size framed for
        self._follow_offset: dict[int, NDArray[np.float64]] = {}  # client id -> look point minus pelvis

    def canvas(self, client: Any | None) -> Canvas:
        """The 3D canvas of page ``client`` as it last reported it (:data:`DEFAULT_CANVAS`
        for new pages, and pages that have not reported a size), with the dataset queue's
        window kept free at its top."""
        w = h = 0
        fov = DEFAULT_CANVAS.fov
        if client is not None:
            try:
                w, h, fov = client.camera.image_width, client.camera.image_height, client.camera.fov
            except AssertionError:  # no camera message from the page yet
                w = h = 0
        if w <= 0 or h <= 0:
            w, h, fov = DEFAULT_CANVAS.width, DEFAULT_CANVAS.height, DEFAULT_CANVAS.fov
        return Canvas(float(w), float(h), float(fov), float(self.canvas_top_px))

    def show_view(self, view: str, body_position: NDArray[np.float64] | None, frame: int) -> CameraPose:
        """Put every page's camera (and new pages') in ``view`` (Sagittal, Frontal, Top),
        framing the trial for each page's own canvas (:func:`framed_view`: the whole trial
        when it fits, else frame ``frame``, and that page then follows the pelvis). Returns
        the pose of new pages.

        Raises
        ------
        ValueError
            An unknown view name.
        """
        if body_position is None:
            pose = view_pose(view, np.array([0.0, 1.0, 0.0]))
            self.view = view
            self._apply(None, pose, None)
            return pose
        pose, _ = framed_view(view, body_position, self.canvas(None), frame)
        self.view = view
        self._apply(None, pose, None)
        for client in self.server.get_clients().values():
            self.frame_page(client, body_position, frame)
        return pose

    def frame_page(self, client: Any, body_position: NDArray[np.float64], frame: int) -> None:
        """Frame the trial (``body_position`` ``(T, B, 3)`` body origins, m, ground frame, body
        0 the pelvis) in the current view on one page; when the trial does not fit its
        canvas the page follows the pelvis instead (until a framing fits again)."""
        canvas = self.canvas(client)
        pose, fits = framed_view(self.view, body_position, canvas, frame)
        self._framed_for[client.client_id] = (canvas.width, canvas.height)
        if fits:
            self.following.discard(client.client_id)
        else:
            self.following.add(client.client_id)
        self._apply(client, pose, body_position[frame, 0, :])

    def resized(self, camera: Any, body_position: NDArray[np.float64] | None, frame: int) -> None:
        """A page reported its camera: frame the trial (``body_position`` ``(T, B, 3)`` body
        origins, m, ground frame, or None without a trial) again for it when its canvas
        changed size since it was framed (the page opened, the window or a docked panel
        resized)."""
        size = (float(camera.image_width), float(camera.image_height))
        if body_position is None or self._framed_for.get(camera.client.client_id) == size:
            return
        self.frame_page(camera.client, body_position, frame)

    def follow(self, pelvis: NDArray[np.float64], pages: set[int] | None = None) -> None:
        """Move the cameras of ``pages`` (client ids; None: every page) with the pelvis
        origin ``pelvis`` ``(3,)`` (m), the orbit and zoom kept, and the pelvis where the
        framing put it on the screen."""
        for client in self.server.get_clients().values():
            if pages is not None and client.client_id not in pages:
                continue
            target = pelvis + self._follow_offset.get(client.client_id, 0.0)
            pos, look = followed(client.camera.position, client.camera.look_at, target)
            with client.atomic():
                client.camera.position = tuple(pos)
                client.camera.look_at = tuple(look)

    def forget(self, client_id: int) -> None:
        """Drop what is kept about a page that closed."""
        self._framed_for.pop(client_id, None)
        self._follow_offset.pop(client_id, None)
        self.following.discard(client_id)

    def _apply(self, client: Any | None, pose: CameraPose, pelvis: NDArray[np.float64] | None) -> None:
        """Set a page's camera (None: the camera of pages still to connect); following then
        keeps the pelvis ``pelvis`` (at the frame shown) where the pose puts it."""
        if client is None:
            cam = self.server.initial_camera
            cam.look_at, cam.position, cam.up = pose.look_at, pose.position, pose.up
            return
        with client.atomic():
            client.camera.up_direction = pose.up
            client.camera.position = pose.position
            client.camera.look_at = pose.look_at
        if pelvis is not None and np.isfinite(pelvis).all():
            self._follow_offset[client.client_id] = np.asarray(pose.look_at) - pelvis
