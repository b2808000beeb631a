"""Which bodies share scale factors, and the anthropometric prior on them.

Scale parameters are per *group* of bodies, three factors each (along the body axes):

* mirror pairs share one group (``femur_r`` and ``femur_l``), as the two sides of a
  person are the same size to within marker placement error;
* a body with no observed marker joins the group of a child that has markers (the
  talus follows the calcaneus), else of its parent (the patella follows the femur,
  the hand the radius), so no parameter is left without data.

The prior (see :func:`prior_residuals`) pulls every factor toward the subject's height
ratio (subject height / model height) and the three factors of a group toward each
other, with weights small enough that markers decide wherever they can.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solver.model.osim import OsimModel
from solver.model.skeleton import Skeleton

FloatArray = NDArray[np.float64]

#: Hip-joint-centre height over stature, used to estimate a model's standing height from
#: its pelvis height in the default pose (anthropometric tables give 0.50-0.53; 0.53
#: makes Rajagopal's generic model 1.70 m, the height of the subject it was built from).
PELVIS_HEIGHT_RATIO = 0.53


def _mirror_key(name: str) -> str:
    return re.sub(r"(_r|_l|_R|_L)$", "", name)


@dataclass(frozen=True)
class ScaleGroups:
    """Assignment of bodies to scale groups.

    Attributes
    ----------
    names
        ``(G,)`` group names (the mirror key, e.g. ``femur``).
    body_group
        Body name -> group index.
    """

    names: tuple[str, ...]
    body_group: dict[str, int]

    @property
    def n_params(self) -> int:
        """Number of scale parameters, 3 per group."""
        return 3 * len(self.names)

    def body_scales(self, params: FloatArray) -> dict[str, FloatArray]:
        """Body name -> (3,) factors from the ``(3G,)`` parameter vector."""
        p = np.asarray(params).reshape(-1, 3)
        return {b: p[g] for b, g in self.body_group.items()}


def make_groups(model: OsimModel, bodies_with_markers: Iterable[str], *, symmetric: bool = True) -> ScaleGroups:
    """Build the groups for ``model`` given which bodies carry observed markers.

    With ``symmetric`` False, left and right bodies get groups of their own.
    """
    key_of = _mirror_key if symmetric else (lambda name: name)
    with_markers = set(bodies_with_markers)
    parent = {j.child.body: j.parent.body for j in model.joints}
    children: dict[str, list[str]] = {}
    for j in model.joints:
        children.setdefault(j.parent.body, []).append(j.child.body)
    has_data = {b: key_of(b) in {key_of(x) for x in with_markers} for b in model.body_names}

    def anchor(body: str, seen: tuple[str, ...] = ()) -> str:
        if has_data[body] or body in seen:
            return body
        for c in children.get(body, []):
            if has_data.get(c):
                return c
        p = parent.get(body, "ground")
        if p != "ground":
            return anchor(p, seen + (body,))
        for c in children.get(body, []):
            return anchor(c, seen + (body,))
        return body

    keys: list[str] = []
    body_group: dict[str, int] = {}
    for b in model.body_names:
        key = key_of(anchor(b))
        if key not in keys:
            keys.append(key)
        body_group[b] = keys.index(key)
    return ScaleGroups(tuple(keys), body_group)


def model_height(skeleton: Skeleton) -> float:
    """Standing height of the model in its default pose, m (see :data:`PELVIS_HEIGHT_RATIO`).

    The pelvis origin's height above the lowest body origin of the feet, plus the distance
    from that origin to the sole (taken as the lowest model marker below it, if any),
    divided by the hip-height ratio.
    """
    q = skeleton.neutral()
    _, pos = skeleton.body_poses(q)
    up = -np.asarray(skeleton.osim.gravity) / np.linalg.norm(skeleton.osim.gravity)
    heights = pos[0] @ up
    pelvis = heights[skeleton.body_index(skeleton.root_body)]
    lowest = heights.min()
    if len(skeleton.marker_names):
        lowest = min(lowest, float((skeleton.marker_positions(q)[0] @ up).min()))
    return float((pelvis - lowest) / PELVIS_HEIGHT_RATIO)


#: Beyond this relative deviation from the height ratio a scale factor is implausible
#: (adult segment proportions vary by roughly ±15% around the population mean, and marker
#: protocols add some apparent deviation); a steep penalty takes over past it.
PLAUSIBLE_DEVIATION = 0.35
BOUND_WEIGHT = 1e3


def prior_residuals(
    params: FloatArray, target: float, weight: float, anisotropy_weight: float
) -> tuple[FloatArray, FloatArray]:
    """Residuals and Jacobian of the scale prior.

    r = sqrt(weight) (s - target) for every factor, sqrt(anisotropy_weight)
    (s_x - s_y, s_y - s_z, s_z - s_x) within each group, and a steep one-sided penalty
    sqrt(weight * BOUND_WEIGHT) * excess on the part of |s - target| beyond
    ``PLAUSIBLE_DEVIATION * target``.

    Returns
    -------
    r, J
        ``(k,)`` residuals and ``(k, 3G)`` Jacobian.
    """
    n = params.size
    g = n // 3
    r1 = np.sqrt(weight) * (params - target)
    j1 = np.sqrt(weight) * np.eye(n)
    d = np.array([[1, -1, 0], [0, 1, -1], [-1, 0, 1]], dtype=float)
    j2 = np.sqrt(anisotropy_weight) * np.kron(np.eye(g), d)
    dev = params - target
    limit = PLAUSIBLE_DEVIATION * target
    excess = np.sign(dev) * np.maximum(np.abs(dev) - limit, 0.0)
    k = np.sqrt(weight * BOUND_WEIGHT)
    r3 = k * excess
    j3 = k * np.diag((np.abs(dev) > limit).astype(float))
    return np.concatenate([r1, j2 @ params, r3]), np.vstack([j1, j2, j3])
