"""Where the review app's camera looks: framing the subject, the three anatomical views,
and following the pelvis during playback (no viser here; the server applies the poses).

Frames are OpenSim's ground frame: X forward (walking direction), Y up, Z to the right.
The sagittal view looks along -Z from the subject's right side, the frontal view along -X
from in front, the top view down along -Y with X up on the screen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

#: Distance of the camera from the point it looks at, m (a 1.8 m subject fills the view).
DISTANCE_M = 3.2
#: Camera height above the point it looks at in the side views, m.
ELEVATION_M = 0.4
VIEWS = ("Sagittal", "Frontal", "Top")


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
    """The camera pose of ``view`` (one of :data:`VIEWS`) looking at ``look``.

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
