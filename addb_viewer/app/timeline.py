"""The timeline of a trial: one strip per track across the whole trial, always visible
beside the 3D view, with the playhead and the selected range.

Tracks, top to bottom (:data:`TRACKS`): the reviewer's unmeasured-force flags per foot
(left, right; "both" and "no foot said" count for each), the solver's proposals (pending,
accepted, rejected), frames with measured force per foot (vertical ground reaction force
applied to that foot above 20 N on a frame the dynamics fit trusts), foot contact from
the kinematics per foot (the foot's lowest body origin at stance level and nearly still:
:func:`kinematic_contact`, the same thresholds as the dynamics stage's contact), and the
frames whose residual is over the Hicks thresholds.

The strip is drawn here as an RGB image (:func:`timeline_image`, numpy only, a few
milliseconds for thousands of frames); the page shows it with a frame slider (click to
seek), a range slider (drag its ends to select frames) and the buttons and hotkeys that
flag, unflag, accept or reject the selection (wired in :mod:`addb_viewer.app.server`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from addb_viewer.app.flags import FlagView
from addb_viewer.app.scene import foot_of_body, plate_feet
from solver.results import ProcessedTrial

BoolArray = NDArray[np.bool_]

#: Track name -> its colour where set (RGB).
TRACKS: dict[str, tuple[int, int, int]] = {
    "flag left": (40, 110, 255),
    "flag right": (240, 60, 60),
    "proposal": (255, 150, 0),
    "force left": (120, 160, 235),
    "force right": (235, 140, 140),
    "contact left": (70, 70, 160),
    "contact right": (160, 70, 70),
    "over Hicks": (190, 0, 190),
}
#: Colours of accepted and rejected proposals on the proposal track.
ACCEPTED = (0, 160, 80)
REJECTED = (150, 150, 150)
BACKGROUND = (245, 245, 245)
PLAYHEAD = (20, 20, 20)
SELECTION = (255, 230, 120)
#: Image size: width in pixels (frames are binned or repeated to fit), and per track.
WIDTH_PX = 640
ROW_PX = 11
GAP_PX = 3
#: Vertical force on a foot above which its force counts as measured, N.
FORCE_THRESHOLD_N = 20.0


@dataclass(frozen=True)
class TrackData:
    """Per-frame values of every track (all ``(T,)``).

    Attributes
    ----------
    masks
        Track name -> bool mask (the proposal track's mask is "any proposal").
    proposal_state
        ``(T,)`` int: 0 none, 1 pending, 2 accepted, 3 rejected.
    """

    masks: dict[str, BoolArray]
    proposal_state: NDArray[np.int8]


def kinematic_contact(trial: ProcessedTrial, *, height_m: float = 0.03, speed_m_s: float = 0.6) -> dict[str, BoolArray]:
    """Foot contact from the motion alone: per foot ("left", "right"), frames where the
    lowest origin of the foot's bodies (calcaneus, toes, talus) is within ``height_m`` of
    its stance level (its 5th percentile over the trial) and moves slower than
    ``speed_m_s``. ``(T,)`` masks; all False when the trial has no such bodies."""
    out = {}
    dt = float(np.median(np.diff(trial.time))) if trial.n_frames > 1 else 0.01
    for foot in ("left", "right"):
        idx = [i for i, b in enumerate(trial.body_names)
               if foot_of_body(b) == foot and b.lower().startswith(("calcn", "toes", "talus", "foot"))]  # fmt: skip
        if not idx:
            out[foot] = np.zeros(trial.n_frames, bool)
            continue
        pos = trial.body_position[:, idx, :]  # (T, k, 3)
        low = np.argmin(pos[:, :, 1], axis=1)
        lowest = pos[np.arange(trial.n_frames), low]  # (T, 3)
        height = lowest[:, 1]
        level = np.nanpercentile(height, 5) if np.isfinite(height).any() else 0.0
        speed = np.linalg.norm(np.gradient(pos.mean(axis=1), dt, axis=0), axis=1)
        out[foot] = (height <= level + height_m) & (speed <= speed_m_s)
    return out


def track_data(trial: ProcessedTrial, view: FlagView | None, hicks: BoolArray | None) -> TrackData:
    """The per-frame values of every track of ``trial`` (``view``: the review state,
    None when there is no review record; ``hicks``: frames over the Hicks thresholds)."""
    n = trial.n_frames
    none = np.zeros(n, bool)
    masks: dict[str, BoolArray] = {}
    masks["flag left"] = view.left | (view.flagged & ~view.left & ~view.right) if view is not None else none
    masks["flag right"] = view.right | (view.flagged & ~view.left & ~view.right) if view is not None else none
    state = np.zeros(n, np.int8)
    proposed = view.proposed if view is not None else np.asarray(trial.proposed, bool)
    state[proposed] = 1
    if view is not None:
        state[view.proposed & view.accepted] = 2
        state[view.rejected] = 3
    masks["proposal"] = state > 0
    feet = plate_feet(trial)
    measured = ~np.asarray(trial.unobserved, bool) if trial.has_dynamics else np.ones(n, bool)
    for foot in ("left", "right"):
        fy = np.zeros(n)
        for i, p in enumerate(trial.plates):
            on = feet[i] == foot
            fy[on] += np.nan_to_num(p.force[on, 1])
        masks[f"force {foot}"] = (fy > FORCE_THRESHOLD_N) & measured
    contact = kinematic_contact(trial)
    masks["contact left"], masks["contact right"] = contact["left"], contact["right"]
    masks["over Hicks"] = np.asarray(hicks, bool) if hicks is not None else none
    return TrackData(masks, state)


def frame_columns(n_frames: int, width: int = WIDTH_PX) -> NDArray[np.intp]:
    """``(width + 1,)`` the first frame of each pixel column (and the end): frames are
    binned (many per column) or repeated (one frame over several columns)."""
    return np.floor(np.linspace(0, n_frames, width + 1)).astype(np.intp)


def column_of(frame: int, n_frames: int, width: int = WIDTH_PX) -> int:
    """The pixel column that shows ``frame``."""
    return int(min(width - 1, max(0, np.floor((frame + 0.5) * width / max(n_frames, 1)))))


def _binned_any(mask: BoolArray, edges: NDArray[np.intp]) -> BoolArray:
    """Per column: any frame of its bin set (a column with no own frame takes the frame it
    repeats)."""
    n = mask.size
    csum = np.concatenate([[0], np.cumsum(mask.astype(np.int64))])
    start = np.minimum(edges[:-1], n - 1)
    stop = np.maximum(edges[1:], start + 1)
    return (csum[stop] - csum[start]) > 0


def timeline_image(data: TrackData, *, frame: int | None = None, selection: tuple[int, int] | None = None,
                   width: int = WIDTH_PX) -> NDArray[np.uint8]:  # fmt: skip
    """The timeline strip: ``(len(TRACKS) * (ROW_PX + GAP_PX), width, 3)`` uint8 RGB.

    Parameters
    ----------
    data
        From :func:`track_data`.
    frame
        The playhead's frame (a dark column), or None.
    selection
        Half-open frame range ``(start, stop)`` shaded on the gaps between tracks, or None.
    """
    n = data.proposal_state.size
    edges = frame_columns(n, width)
    rows = len(TRACKS)
    img = np.empty((rows * (ROW_PX + GAP_PX), width, 3), np.uint8)
    img[:] = 255
    if selection is not None:
        s, e = selection
        cols = _binned_any((np.arange(n) >= s) & (np.arange(n) < e), edges)
        img[:, cols] = SELECTION
    for r, (name, color) in enumerate(TRACKS.items()):
        top = r * (ROW_PX + GAP_PX) + GAP_PX
        band = img[top : top + ROW_PX]
        band[:] = BACKGROUND
        if name == "proposal":
            for value, c in ((1, color), (2, ACCEPTED), (3, REJECTED)):
                band[:, _binned_any(data.proposal_state == value, edges)] = c
        else:
            band[:, _binned_any(data.masks[name], edges)] = color
    if frame is not None and n:
        img[:, column_of(frame, n, width)] = PLAYHEAD
    return img


def legend_markdown() -> str:
    """The track names in their colours, top to bottom (the image carries no text)."""
    def chip(c: tuple[int, int, int]) -> str:
        return f"<span style='color:rgb{c}'>■</span>"

    parts = [f"{chip(c)} {name}" for name, c in TRACKS.items()]
    parts[2] += f" ({chip(ACCEPTED)} accepted, {chip(REJECTED)} rejected)"
    return "<small>" + " · ".join(parts) + "</small>"
