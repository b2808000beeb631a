"""Where the review app's camera looks: framing the subject, the three anatomical views,
and following the pelvis during playback (no viser here; the server applies the poses).

Frames are OpenSim's ground frame: X forward (walking direction), Y up, Z to the right.
The sagittal view looks along -Z from the subject's right side, the frontal view along -X
from in front, the top view down along -Y with X up on the screen.

A trial is framed for the page's own canvas (:func:`framed_view`): the camera backs off
until the skeleton stays inside the canvas on every frame (below the dataset queue's
window when one floats over its top); when that would need more than
:data:`MAX_DISTANCE_M` (a long walk, a trial that walks towards the camera) the camera
follows the pelvis instead, framed so the skeleton of any one frame fits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatVec = NDArray[np.float64]

#: Distance of the camera from the point it looks at, m (a 1.8 m subject fills the view).
DISTANCE_M = 3.2
#: Camera height above the point it looks at in the side views, m.
ELEVATION_M = 0.4
VIEWS = ("Sagittal", "Frontal", "Top")
#: Farthest the framing backs off to keep a whole trial in view, m; beyond, it follows
#: (farther, a skeleton is too small to judge its markers: with the 75 deg field of view a
#: 1.8 m subject is 1.8 / (2 d tan 37.5 deg) of the canvas height, 120 px of 800 at 8 m).
MAX_DISTANCE_M = 6.0
#: Room kept around the body origins (the meshes reach past them), m.
BODY_MARGIN_M = 0.2
#: The top of the head above the pelvis origin, at least, m (no body origin marks it).
HEAD_ABOVE_PELVIS_M = 0.85
#: Frames sampled to frame a trial (every frame for shorter trials).
FRAMING_SAMPLES = 120
#: Gap kept between the skeleton and the edges of the canvas, px.
EDGE_PX = 8.0
#: Nearest depth a framed point may have in front of the camera, m.
NEAR_M = 0.3


@dataclass(frozen=True)
class CameraPose:
    """A camera pose: ``position`` and ``look_at`` (m, ground frame), ``up`` (unit vector)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]


def framing_point(pelvis: NDArray[np.float64]) -> NDArray[np.float64]:
    """The point a trial's camera looks at: the median of the pelvis origin over the
    frames where it is known, ``(T, 3)`` -> ``(3,)``; (0, 1, 0) when never known."""
    ok = np.isfinite(pelvis).all(axis=1)
    return np.median(pelvis[ok], axis=0) if ok.any() else np.array([0.0, 1.0, 0.0])


def view_pose(view: str, look: NDArray[np.float64], *, distance: float = DISTANCE_M) -> CameraPose:
    """The camera pose of ``view`` (one of :data:`VIEWS`) looking at ``look`` ``(3,)``, m,
    ground frame, from ``distance`` m.

    Raises
    ------
    ValueError
        An unknown view name.
    """
    look = np.asarray(look, dtype=float)
    if view == "Sagittal":
        offset, up = (0.0, ELEVATION_M, distance), (0.0, 1.0, 0.0)
    elif view == "Frontal":
        offset, up = (distance, ELEVATION_M, 0.0), (0.0, 1.0, 0.0)
    elif view == "Top":
        offset, up = (0.0, distance, 0.0), (1.0, 0.0, 0.0)
    else:
        raise ValueError(f"unknown view {view!r}; expected one of {', '.join(VIEWS)}")
    return CameraPose(tuple(look + offset), tuple(look), up)  # type: ignore[arg-type]


def followed(position: NDArray[np.float64], look_at: NDArray[np.float64], target: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A camera moved along with the pelvis: the same offset from ``target`` as it had
    from ``look_at`` (the reviewer's orbit and zoom are kept); returns (position, look_at)."""
    if not np.isfinite(target).all():
        return position, look_at
    return target + (np.asarray(position) - np.asarray(look_at)), np.asarray(target, dtype=float)


@dataclass(frozen=True)
class Canvas:
    """A page's 3D canvas: ``width`` and ``height`` in CSS px, the vertical field of view
    ``fov`` (rad), and ``top`` px at its top covered by a floating window (the dataset
    queue), where the skeleton is not put."""

    width: float
    height: float
    fov: float
    top: float = 0.0


#: The canvas assumed for a page that has not reported its own: a 1600 x 1000 window less
#: the app's docked panels (px), three.js' and viser's default field of view (75 deg).
DEFAULT_CANVAS = Canvas(width=715.0, height=1000.0, fov=float(np.radians(75.0)))


def _basis(pose: CameraPose) -> tuple[FloatVec, FloatVec, FloatVec]:
    """(forward, right, up) unit vectors of a camera pose (right = forward x up)."""
    fwd = np.asarray(pose.look_at, float) - np.asarray(pose.position, float)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(pose.up, float))
    right /= np.linalg.norm(right)
    return fwd, right, np.cross(right, fwd)


def project(points: NDArray[np.float64], pose: CameraPose, canvas: Canvas) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Pixel coordinates of ``points`` ``(N, 3)`` (m, ground frame) on ``canvas`` seen
    from ``pose`` (a pinhole camera with the canvas' vertical field of view, as three.js
    draws it): ``(N, 2)`` px from the canvas' top-left corner (x right, y down), and the
    depth of each point in front of the camera ``(N,)`` (m; not positive: behind it)."""
    fwd, right, up = _basis(pose)
    rel = np.asarray(points, float) - np.asarray(pose.position, float)
    depth = rel @ fwd
    f = 0.5 * canvas.height / np.tan(0.5 * canvas.fov)  # focal length, px
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.column_stack((0.5 * canvas.width + f * (rel @ right) / depth, 0.5 * canvas.height - f * (rel @ up) / depth))
    return px, depth


def body_points(body_position: NDArray[np.float64], frames: NDArray[np.intp] | None = None) -> NDArray[np.float64]:
    """Points the camera must keep in view to show the skeleton: for each frame (default:
    at most :data:`FRAMING_SAMPLES` spread over the trial), the eight corners of the box
    around its body origins ``body_position[k]`` ``(B, 3)`` (body 0 the pelvis) widened by
    :data:`BODY_MARGIN_M` and reaching :data:`HEAD_ABOVE_PELVIS_M` above the pelvis;
    frames with unknown bodies are skipped. ``(T, B, 3)`` -> ``(8 n, 3)`` m."""
    bp = np.asarray(body_position, float)
    if frames is None:
        frames = np.unique(np.linspace(0, len(bp) - 1, min(len(bp), FRAMING_SAMPLES)).round().astype(int))
    out = []
    for k in frames:
        b = bp[k][np.isfinite(bp[k]).all(axis=1)]
        if not len(b) or not np.isfinite(bp[k, 0]).all():
            continue
        lo, hi = b.min(axis=0) - BODY_MARGIN_M, b.max(axis=0) + BODY_MARGIN_M
        hi[1] = max(hi[1], bp[k, 0, 1] + HEAD_ABOVE_PELVIS_M)
        out.append([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return np.asarray(out, float).reshape(-1, 3)


def _fits(points: NDArray[np.float64], pose: CameraPose, canvas: Canvas) -> bool:
    px, depth = project(points, pose, canvas)
    return bool(
        (depth > NEAR_M).all()
        and (px[:, 0] >= EDGE_PX).all() and (px[:, 0] <= canvas.width - EDGE_PX).all()
        and (px[:, 1] >= canvas.top + EDGE_PX).all() and (px[:, 1] <= canvas.height - EDGE_PX).all()
    )  # fmt: skip


def _centred(view: str, points: NDArray[np.float64], canvas: Canvas, distance: float) -> CameraPose:
    """The ``view`` at ``distance`` from the points' box centre, moved across the screen so
    the points' projection is centred in the part of the canvas below ``canvas.top``."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pose = view_pose(view, 0.5 * (lo + hi), distance=distance)
    want = np.array([0.5 * canvas.width, 0.5 * (canvas.top + canvas.height)])
    for _ in range(8):  # the projection is not linear in the shift: corrections until centred
        px, depth = project(points, pose, canvas)
        if not (depth > NEAR_M).all():
            return pose
        shift_px = 0.5 * (px.min(axis=0) + px.max(axis=0)) - want
        if np.abs(shift_px).max() < 0.25:
            return pose
        _, right, up = _basis(pose)
        # metres per pixel at the depth of the points that bound each axis (the nearest
        # points of a path seen end-on move fastest across the screen)
        edge_depth = [0.5 * (depth[np.argmin(px[:, a])] + depth[np.argmax(px[:, a])]) for a in (0, 1)]
        m_per_px = np.asarray(edge_depth) * np.tan(0.5 * canvas.fov) * 2.0 / canvas.height
        move = m_per_px[0] * shift_px[0] * right - m_per_px[1] * shift_px[1] * up
        pose = CameraPose(tuple(np.asarray(pose.position) + move), tuple(np.asarray(pose.look_at) + move), pose.up)  # type: ignore[arg-type]
    return pose


def framed_view(view: str, body_position: NDArray[np.float64], canvas: Canvas, frame: int = 0) -> tuple[CameraPose, bool]:
    """The camera pose of ``view`` (one of :data:`VIEWS`) that keeps the skeleton inside
    ``canvas`` (below ``canvas.top``) on every frame of a trial, and whether it does.

    The camera looks from :data:`DISTANCE_M` or, where the trial's path does not fit, from
    farther (steps of 10 %, up to :data:`MAX_DISTANCE_M`), at the box of
    :func:`body_points`, moved across the screen so that box is centred in the free part of
    the canvas. When no distance up to the limit holds every frame, the pose frames frame
    ``frame`` alone and the second value is False: the caller follows the pelvis
    (:func:`followed`), which keeps that framing on every frame.

    Parameters
    ----------
    body_position
        ``(T, B, 3)`` body origins, m, ground frame (body 0 the pelvis).
    canvas
        The page's canvas (:class:`Canvas`).

    Raises
    ------
    ValueError
        An unknown view name.
    """
    points = body_points(body_position)
    if not len(points):
        return view_pose(view, framing_point(np.asarray(body_position)[:, 0, :])), True
    pose, fits = _backed_off(view, points, canvas, MAX_DISTANCE_M)
    if fits:
        return pose, True
    one = body_points(body_position, np.array([min(max(frame, 0), len(body_position) - 1)]))
    return _backed_off(view, one if len(one) else points, canvas, 4 * MAX_DISTANCE_M)[0], False


def _backed_off(view: str, points: NDArray[np.float64], canvas: Canvas, limit: float) -> tuple[CameraPose, bool]:
    """The nearest centred pose (:data:`DISTANCE_M`, then 10 % farther at each step, up to
    ``limit`` m) that keeps ``points`` inside ``canvas``, and True; else the farthest one
    tried, and False."""
    distance = DISTANCE_M
    pose = _centred(view, points, canvas, distance)
    while not _fits(points, pose, canvas):
        if distance * 1.1 > limit * 1.0001:
            return pose, False
        distance *= 1.1
        pose = _centred(view, points, canvas, distance)
    return pose, True
