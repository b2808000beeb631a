"""Attach markers the model does not carry to the body they move with.

Once a rough pose is known (the fit frames after a first scale fit), each unmatched
lab marker is expressed in every body's frame at every fit frame where it is seen. A
marker glued to a segment keeps a constant position in that segment's frame, so the body
whose frame shows the smallest spread of positions (RMS distance to their mean) is the
one it is attached to, and the mean is its body-fixed location. Markers whose best spread
is still large (not rigidly attached to any body, e.g. a marker on loose clothing) are
left out and reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solver.model.skeleton import Skeleton

FloatArray = NDArray[np.float64]

#: A marker whose position varies more than this in its best body's frame (RMS, m) is
#: not considered attached to any body.
MAX_SPREAD_M = 0.02


@dataclass(frozen=True)
class Placement:
    """Where an unmatched marker was attached.

    Attributes
    ----------
    name
        Lab marker name (becomes the model marker name).
    body
        Body it is attached to.
    location
        ``(3,)`` position in the (scaled) body frame, m.
    spread
        RMS distance of the per-frame body-frame positions to ``location``, m.
    """

    name: str
    body: str
    location: tuple[float, float, float]
    spread: float


def place_markers(
    skeleton: Skeleton, q: FloatArray, obs: FloatArray, names: list[str], *, min_frames: int = 3
) -> tuple[list[Placement], list[str]]:
    """Find the body and body-fixed location of unmatched markers.

    Parameters
    ----------
    skeleton
        The scaled model.
    q
        ``(F, n)`` coordinates of frames with a good pose.
    obs
        ``(F, K, 3)`` observed positions of the unmatched markers, NaN where missing.
    names
        ``(K,)`` their names.
    min_frames
        Markers seen in fewer frames are not placed.

    Returns
    -------
    placed, rejected
        Placements, and names that could not be attached.
    """
    rot, pos = skeleton.body_poses(q)  # (F, B, 3, 3), (F, B, 3)
    placed, rejected = [], []
    for k, name in enumerate(names):
        seen = np.isfinite(obs[:, k]).all(axis=1)
        if seen.sum() < min_frames:
            rejected.append(name)
            continue
        y = obs[seen, k]  # (f, 3)
        local = np.einsum("fbji,fbj->fbi", rot[seen], y[:, None, :] - pos[seen])  # R^T (y - p)
        mean = local.mean(axis=0)  # (B, 3)
        spread = np.sqrt(np.mean(np.sum((local - mean) ** 2, axis=2), axis=0))  # (B,)
        b = int(np.argmin(spread))
        if spread[b] > MAX_SPREAD_M:
            rejected.append(name)
            continue
        placed.append(Placement(name, skeleton.body_names[b], tuple(float(v) for v in mean[b]), float(spread[b])))
    return placed, rejected
