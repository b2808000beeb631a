"""Which foot each plate's wrench acts on, and which frames have unmeasured external force.

Assignment (per plate, per frame): a loaded plate's centre of pressure is compared, in the
horizontal plane, with each foot's sole segment (from the foot body's origin to a point
beyond its toes' origin); the wrench goes to the nearest foot within ``max_distance``.
Any number of plates works, a foot may stand on two plates at once, and a plate whose
centre of pressure is close to both feet is flagged as ambiguous (two feet on one plate).

Unmeasured force (proposals, each with its reason):

* a foot is kinematically in contact (its lowest point at ground level and nearly still)
  while no plate assigns it any force: it stands on uninstrumented ground;
* the measured vertical force differs from what the centre-of-mass motion requires,
  m (a_com,y + g), by more than ``force_mismatch_bw`` body weights.

The reviewer's annotations, when given, replace these proposals.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solver.dynamics.preprocess import true_runs
from solver.model.skeleton import Skeleton
from solver.results import PlateData

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ContactSettings:
    """Thresholds of contact assignment and detection.

    Attributes
    ----------
    loaded_bw
        A plate is loaded when its force exceeds this fraction of body weight.
    max_distance
        Largest horizontal distance (m) from a centre of pressure to a foot's sole segment
        for the foot to receive that plate's force.
    ambiguous_distance
        When both feet are closer than this (m) to a loaded plate's CoP, the frame is
        flagged as ambiguous (two feet on one plate).
    contact_height
        A foot is in contact when its lowest point is within this height (m) of the level
        it has when standing on a plate.
    contact_speed
        ... and moves slower than this (m/s) relative to the surface it stands on (on a
        treadmill, the belt: the median velocity of its lowest point while loaded).
    force_mismatch_bw
        Vertical force mismatch (in body weights) that marks a frame as unmeasured ...
    mismatch_seconds
        ... when it lasts at least this long (impact transients, which the filtered
        kinematics cannot follow, last a few frames and stay measured).
    toe_extension
        The sole segment runs from the foot origin to its toes' origin plus this fraction of
        that distance (reaching the tip of the toes).
    """

    loaded_bw: float = 0.02
    max_distance: float = 0.25
    ambiguous_distance: float = 0.08
    contact_height: float = 0.03
    contact_speed: float = 0.6
    force_mismatch_bw: float = 0.3
    mismatch_seconds: float = 0.0
    toe_extension: float = 0.5


@dataclass(frozen=True)
class ContactResult:
    """Assignment and proposals of one trial.

    Attributes
    ----------
    plate_foot
        ``(P, T)`` index into ``feet`` of the foot each plate's force is applied to, -1 when
        the plate is unloaded or no foot is near.
    feet
        Foot body names.
    foot_in_contact
        ``(F, T)`` kinematic contact of each foot.
    foot_loaded
        ``(F, T)`` whether some plate assigns force to each foot.
    ambiguous
        ``(T,)`` frames where a loaded plate is close to two feet.
    proposed
        ``(T,)`` frames proposed as unmeasured.
    reasons
        ``(T,)`` why ("" when not proposed).
    stance_height
        ``(F,)`` median height (m) of each foot's lowest point above the centre of pressure
        of the plate whose force is applied to it, on those frames; NaN for a foot never loaded. A few
        centimetres for a foot; far more when ``feet`` name other bodies
        (warned about by :func:`solver.dynamics.stage._warn_raised_feet`).
    """

    plate_foot: NDArray[np.int64]
    feet: tuple[str, ...]
    foot_in_contact: NDArray[np.bool_]
    foot_loaded: NDArray[np.bool_]
    ambiguous: NDArray[np.bool_]
    proposed: NDArray[np.bool_]
    reasons: tuple[str, ...]
    stance_height: FloatArray


def _foot_points(sk: Skeleton, q: FloatArray, foot: str, ext: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Heel point, toe tip point and lowest point of a foot, each ``(T, 3)``."""
    rot, pos = sk.body_poses(q)
    b = sk.body_index(foot)
    children = [j.child.body for j in sk.osim.joints if j.parent.body == foot]
    heel = pos[:, b]
    if children:
        toes = pos[:, sk.body_index(children[0])]
        tip = toes + ext * (toes - heel)
    else:
        tip = heel + rot[:, b] @ np.array([0.2, 0.0, 0.0])
    on_foot = [i for i, mb in enumerate(sk.marker_bodies) if mb == foot or mb in children]
    candidates = [heel, tip]
    if on_foot:
        mk = sk.marker_positions(q, np.array(on_foot))
        candidates += [mk[:, k] for k in range(mk.shape[1])]
    pts = np.stack(candidates, axis=1)  # (T, K, 3)
    lowest = pts[np.arange(pts.shape[0]), np.argmin(pts[:, :, 1], axis=1)]
    return heel, tip, lowest


def _segment_distance(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Horizontal (x-z) distance from points p to segments a-b, all ``(T, 3)``."""
    p2, a2, b2 = p[:, [0, 2]], a[:, [0, 2]], b[:, [0, 2]]
    ab = b2 - a2
    t = np.clip(np.sum((p2 - a2) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p2 - (a2 + t[:, None] * ab), axis=1)


def _long_runs(mask: NDArray[np.bool_], min_len: int) -> NDArray[np.bool_]:
    """``mask`` keeping only runs of at least ``min_len`` consecutive True frames."""
    out = np.zeros_like(mask)
    for start, stop in true_runs(mask):
        if stop - start >= min_len:
            out[start:stop] = True
    return out


#: Reason of a frame proposed because the plates' vertical force does not match the
#: motion (followed by " by X BW", the mismatch on that frame).
MISMATCH_REASON = "measured vertical force differs from m(a+g)"


def reason_kind(reason: str) -> str:
    """A proposal reason without its per-frame figure (the " by X BW" of a force mismatch)."""
    return MISMATCH_REASON if reason.startswith(MISMATCH_REASON) else reason


def _ground_velocity(velocity: FloatArray, loaded: BoolArray, contact_speed: float) -> FloatArray:
    """``(3,)`` velocity of the surface a foot stands on, m/s: zero over ground; on a
    treadmill the belt's, i.e. the median velocity of the foot's lowest point on the frames
    its plate carries it, when that exceeds ``contact_speed`` (a foot standing still on
    the ground moves slower)."""
    if not loaded.any():
        return np.zeros(3)
    belt = np.median(velocity[loaded], axis=0)
    return belt if np.linalg.norm(belt) > contact_speed else np.zeros(3)


def assign_contacts(
    sk: Skeleton,
    q: FloatArray,
    plates: Sequence[PlateData],
    feet: Sequence[str],
    mass_kg: float,
    dt: float,
    com_acc: FloatArray | None = None,
    settings: ContactSettings | None = None,
) -> ContactResult:
    """Assign plate wrenches to feet and propose frames with unmeasured force.

    Parameters
    ----------
    sk
        The scaled model.
    q
        ``(T, n)`` coordinates on the trial's frames.
    plates
        Plate wrenches on the same frames.
    feet
        Names of the foot bodies (``footBodyNames``).
    mass_kg
        Body mass, kg (for thresholds in body weights).
    dt
        Frame interval, s.
    com_acc
        ``(T, 3)`` centre-of-mass acceleration, m/s² (None skips the force-mismatch test).
    settings
        Thresholds.
    """
    st = settings or ContactSettings()
    t = q.shape[0]
    g = float(np.linalg.norm(sk.osim.gravity))
    bw = mass_kg * g
    pts = [_foot_points(sk, q, f, st.toe_extension) for f in feet]
    plate_foot = np.full((len(plates), t), -1, dtype=np.int64)
    ambiguous = np.zeros(t, dtype=bool)
    for i, p in enumerate(plates):
        loaded = np.nan_to_num(p.force[:, 1]) > st.loaded_bw * bw
        cop = np.nan_to_num(p.cop)
        dist = np.stack([_segment_distance(cop, heel, tip) for heel, tip, _ in pts], axis=0)  # (F, T)
        nearest = np.argmin(dist, axis=0)
        near = dist[nearest, np.arange(t)] <= st.max_distance
        plate_foot[i] = np.where(loaded & near, nearest, -1)
        if len(feet) > 1:
            ambiguous |= loaded & (np.sort(dist, axis=0)[1] <= st.ambiguous_distance)
    foot_loaded = np.stack([(plate_foot == k).any(axis=0) for k in range(len(feet))], axis=0)

    # kinematic contact: lowest point at the level the foot has when it stands on a plate
    levels = np.concatenate([p.cop[np.nan_to_num(p.force[:, 1]) > st.loaded_bw * bw, 1] for p in plates] or [np.zeros(1)])
    levels = levels[np.isfinite(levels)]
    ground = float(np.median(levels)) if levels.size else np.nan  # no plate ever loaded: no kinematic contact
    contact = np.zeros((len(feet), t), dtype=bool)
    stance_height = np.full(len(feet), np.nan)
    for k, (_, _, lowest) in enumerate(pts):
        height = lowest[:, 1] - ground
        # above the surface of the plate that loads it (plates of a staircase lie at other levels)
        above = [lowest[on, 1] - p.cop[on, 1] for i, p in enumerate(plates) if (on := plate_foot[i] == k).any()]
        above_all = np.concatenate(above) if above else np.zeros(0)
        if np.isfinite(above_all).any():
            stance_height[k] = np.nanmedian(above_all)
        stance_level = np.median(height[foot_loaded[k]]) if foot_loaded[k].any() else np.percentile(height, 5)
        velocity = np.gradient(lowest, dt, axis=0)
        speed = np.linalg.norm(velocity - _ground_velocity(velocity, foot_loaded[k], st.contact_speed), axis=1)
        contact[k] = (height <= stance_level + st.contact_height) & (speed <= st.contact_speed)

    reasons = [""] * t
    proposed = np.zeros(t, dtype=bool)
    for k, foot in enumerate(feet):
        off = contact[k] & ~foot_loaded[k]
        for j in np.flatnonzero(off):
            reasons[j] = f"{foot} in contact with no plate force"
        proposed |= off
    if com_acc is not None and np.isfinite(com_acc).all():
        measured = sum((np.nan_to_num(p.force[:, 1]) for p in plates), np.zeros(t))
        required = mass_kg * (com_acc[:, 1] + g)
        mismatch = np.abs(measured - required) / bw
        bad = _long_runs(mismatch > st.force_mismatch_bw, int(np.ceil(st.mismatch_seconds / dt)))
        for j in np.flatnonzero(bad & ~proposed):
            reasons[j] = f"{MISMATCH_REASON} by {mismatch[j]:.2f} BW"
        proposed |= bad
    return ContactResult(
        plate_foot=plate_foot,
        feet=tuple(feet),
        foot_in_contact=contact,
        foot_loaded=foot_loaded,
        ambiguous=ambiguous,
        proposed=proposed,
        reasons=tuple(reasons),
        stance_height=stance_height,
    )
