"""The timeline of a trial: one strip per track across the whole trial, always visible
beside the 3D view, with the playhead and the selected range.

Tracks, top to bottom (:data:`TRACKS`): the reviewer's unmeasured-force flags per foot
(left, right; "both" and "no foot said" count for each), the solver's proposals (pending,
accepted, rejected), the frames the last fit left out as without measured force (whatever
chose them: the solver's proposals, the reviewer's flags, a saved ``unmeasured_force``
correction), frames with measured force per foot (vertical ground reaction force
applied to that foot above 20 N on a frame the dynamics fit trusts), foot contact from
the kinematics per foot (the foot's lowest body origin at stance level and nearly still relative to the ground
under it: :func:`kinematic_contact`), and the
frames whose residual is over the Hicks thresholds.

The strip is drawn here as HTML with inline styles (:func:`timeline_html`: one positioned
block per run of frames, so hovering a run shows its frames and, for a proposal, its state
and reason; a few milliseconds for thousands of frames); the page shows it with a frame
slider (click to seek), a range slider (drag its ends to select frames) and the buttons
and hotkeys that flag, unflag, accept or reject the selection (wired in
:mod:`addb_viewer.app.server`).
"""

from __future__ import annotations

import html
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from addb_viewer.app.flags import FlagView
from addb_viewer.app.scene import foot_of_body, plate_feet
from solver.masks import true_runs
from solver.results import ProcessedTrial
from solver.sampling import frame_interval

BoolArray = NDArray[np.bool_]

#: Track name -> its colour where set (RGB).
TRACKS: dict[str, tuple[int, int, int]] = {
    "flag left": (40, 110, 255),
    "flag right": (240, 60, 60),
    "proposal": (255, 150, 0),
    "left out": (90, 90, 90),
    "force left": (120, 160, 235),
    "force right": (235, 140, 140),
    "contact left": (70, 70, 160),
    "contact right": (160, 70, 70),
    "over Hicks": (190, 0, 190),
}
#: Colours of accepted and rejected proposals on the proposal track.
ACCEPTED = (0, 160, 80)
REJECTED = (150, 150, 150)
BACKGROUND = (235, 235, 235)
PLAYHEAD = (20, 20, 20)
SELECTION = (255, 230, 120)
#: Strip layout: height of a track and the gap between tracks, width of the label column, px.
ROW_PX = 11
GAP_PX = 3
LABEL_PX = 78
#: Room kept right of the strip, px: the docked panel's scrollbar floats over its right edge
#: (it hid the last frames' runs and the playhead at the last frame).
RIGHT_PX = 12
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
        ``(T,)`` int: 0 none, 1 pending, 2 accepted (or flagged by hand:
        :attr:`~addb_viewer.app.flags.FlagView.agreed`), 3 rejected.
    """

    masks: dict[str, BoolArray]
    proposal_state: NDArray[np.int8]


def kinematic_contact(
    trial: ProcessedTrial, loaded: dict[str, BoolArray] | None = None, *, height_m: float = 0.03, speed_m_s: float = 1.0
) -> dict[str, BoolArray]:
    """Foot contact from the motion: per foot ("left", "right"), frames where the lowest
    origin of the foot's bodies (calcaneus, toes, talus) is within ``height_m`` of its
    stance level (its 5th percentile over the trial) and moves slower than ``speed_m_s``
    relative to the ground under it. On a treadmill the ground moves: where the foot is
    ``loaded`` (its measured force), its median velocity is the belt's, and it is taken
    off when faster than ``speed_m_s`` (the dynamics stage's rule, :mod:`solver.dynamics.contact`).
    The speed limit is looser than that stage's 0.6 m/s because the body origins roll with
    the foot where its lowest point stays put (on the shared walk and run, 1 m/s finds
    contact on 58-91 % of the frames with measured force, 0.6 m/s on 28-82 %).
    ``(T,)`` masks; all False when the trial has no such bodies."""
    out = {}
    dt = frame_interval(trial.time, default=0.01)
    for foot in ("left", "right"):
        idx = [i for i, b in enumerate(trial.body_names)
               if foot_of_body(b) == foot and b.lower().startswith(("calcn", "toes", "talus", "foot"))]  # fmt: skip
        if not idx:
            out[foot] = np.zeros(trial.n_frames, bool)
            continue
        pos = trial.body_position[:, idx, :]  # (T, k, 3)
        low = np.argmin(pos[:, :, 1], axis=1)
        height = pos[np.arange(trial.n_frames), low, 1]
        level = np.nanpercentile(height, 5) if np.isfinite(height).any() else 0.0
        velocity = np.gradient(pos.mean(axis=1), dt, axis=0)
        on = None if loaded is None else loaded.get(foot)
        ground = np.zeros(3)
        if on is not None and on.any():
            belt = np.nanmedian(velocity[on], axis=0)
            ground = belt if np.linalg.norm(belt) > speed_m_s else ground
        speed = np.linalg.norm(velocity - ground, axis=1)
        out[foot] = (height <= level + height_m) & (speed <= speed_m_s)
    return out


def track_data(trial: ProcessedTrial, view: FlagView | None, hicks: BoolArray | None) -> TrackData:
    """The per-frame values of every track of ``trial`` (``view``: the review state,
    None when there is no review record; ``hicks``: ``(T,)`` frames over the Hicks
    thresholds, or None)."""
    n = trial.n_frames
    none = np.zeros(n, bool)
    masks: dict[str, BoolArray] = {}
    masks["flag left"] = view.left | (view.flagged & ~view.left & ~view.right) if view is not None else none
    masks["flag right"] = view.right | (view.flagged & ~view.left & ~view.right) if view is not None else none
    state = np.zeros(n, np.int8)
    proposed = view.proposed if view is not None else np.asarray(trial.proposed, bool)
    state[proposed] = 1
    if view is not None:
        state[view.agreed] = 2
        state[view.rejected] = 3
    masks["proposal"] = state > 0
    masks["left out"] = np.asarray(trial.unobserved, bool) if trial.has_dynamics else none
    feet = plate_feet(trial)
    measured = ~np.asarray(trial.unobserved, bool) if trial.has_dynamics else np.ones(n, bool)
    for foot in ("left", "right"):
        fy = np.zeros(n)
        for i, p in enumerate(trial.plates):
            on = feet[i] == foot
            fy[on] += np.nan_to_num(p.force[on, 1])
        masks[f"force {foot}"] = (fy > FORCE_THRESHOLD_N) & measured
    contact = kinematic_contact(trial, {f: masks[f"force {f}"] for f in ("left", "right")})
    masks["contact left"], masks["contact right"] = contact["left"], contact["right"]
    masks["over Hicks"] = np.asarray(hicks, bool) if hicks is not None else none
    return TrackData(masks, state)


def _pct(x: float) -> str:
    return f"{100.0 * x:.3f}%"


def track_runs(data: TrackData, reasons: tuple[str, ...] = ()) -> list[tuple[str, int, int, tuple[int, int, int], str]]:
    """Every coloured run of the strip: ``(track, start, stop, colour, tooltip)`` with
    half-open frame ranges; the proposals' tooltips give their state and reason."""
    out = []
    for name, color in TRACKS.items():
        if name == "proposal":
            for value, state, c in ((1, "pending", color), (2, "accepted", ACCEPTED), (3, "rejected", REJECTED)):
                for s, e in true_runs(data.proposal_state == value):
                    reason = reasons[s] if s < len(reasons) and reasons[s] else "no reason given"
                    out.append((name, s, e, c, f"proposal ({state}), {frames_text(s, e)}: {reason}"))
            continue
        for s, e in true_runs(data.masks[name]):
            out.append((name, s, e, color, f"{name}, {frames_text(s, e)}"))
    return out


def frames_text(start: int, stop: int) -> str:
    """Frames ``[start, stop)`` as a tooltip names them: "frames 20–40", or "frame 6"."""
    return f"frame {start}" if stop - start == 1 else f"frames {start}–{stop - 1}"


def timeline_html(data: TrackData, *, reasons: tuple[str, ...] = (), frame: int | None = None,
                  selection: tuple[int, int] | None = None) -> str:  # fmt: skip
    """The timeline strip as HTML (inline styles only, no script): a label column and,
    per track, coloured runs placed by frame; hovering a run shows its frames (and, for a
    proposal, its state and reason); the selection is shaded and the playhead is a dark
    line.

    Parameters
    ----------
    data
        From :func:`track_data`.
    reasons
        ``(T,)`` the reason of each proposed frame (the trial's ``proposal_reasons``).
    frame
        The playhead's frame, or None.
    selection
        Half-open frame range ``(start, stop)`` to shade, or None.
    """
    n = max(int(data.proposal_state.size), 1)
    row = ROW_PX + GAP_PX
    height = len(TRACKS) * row + GAP_PX
    parts = [
        (f"<div style='display:flex;font-size:10px;line-height:{ROW_PX}px;font-family:sans-serif;padding-right:{RIGHT_PX}px'>"
         f"<div style='width:{LABEL_PX}px;flex-shrink:0;padding-top:{GAP_PX}px'>")
    ]
    parts += [f"<div style='height:{ROW_PX}px;margin-bottom:{GAP_PX}px;color:#444'>{name}</div>" for name in TRACKS]
    parts.append(f"</div><div class='addb-timeline' style='position:relative;flex-grow:1;height:{height}px'>")
    if selection is not None:
        s, e = selection
        parts.append(f"<div class='sel' title='selected: {frames_text(s, e)}' style='position:absolute;left:{_pct(s / n)};"
                     f"width:{_pct((e - s) / n)};top:0;bottom:0;background:rgb{SELECTION}'></div>")  # fmt: skip
    for r, name in enumerate(TRACKS):
        parts.append(f"<div style='position:absolute;left:0;right:0;top:{GAP_PX + r * row}px;height:{ROW_PX}px;"
                     f"background:rgba{(*BACKGROUND, 0.8)}'></div>")  # fmt: skip
    for name, s, e, color, tip in track_runs(data, reasons):
        r = list(TRACKS).index(name)
        parts.append(f"<div class='run' data-track='{name}' title='{html.escape(tip, quote=True)}' "
                     f"style='position:absolute;left:{_pct(s / n)};width:max({_pct((e - s) / n)},1px);"
                     f"top:{GAP_PX + r * row}px;height:{ROW_PX}px;background:rgb{color}'></div>")  # fmt: skip
    if frame is not None:
        parts.append(f"<div class='playhead' title='frame {frame}' style='position:absolute;left:{_pct((frame + 0.5) / n)};"
                     f"width:2px;margin-left:-1px;top:0;bottom:0;background:rgb{PLAYHEAD}'></div>")  # fmt: skip
    parts.append("</div></div>")
    return "".join(parts)


def legend_markdown() -> str:
    """The proposal track's colours (the other tracks are named beside their strip)."""
    def chip(c: tuple[int, int, int]) -> str:
        return f"<span style='color:rgb{c}'>■</span>"

    return (f"<small>proposal: {chip(TRACKS['proposal'])} pending, {chip(ACCEPTED)} accepted or flagged, "
            f"{chip(REJECTED)} rejected; hover a run for its frames and reason</small>")  # fmt: skip
