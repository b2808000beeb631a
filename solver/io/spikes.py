"""Single-frame spikes of a marker, and markers far from all the others: values no body
point can take.

A lab's exporter writes a value such as 9999999 or 1e37 for a marker it lost, and a
mis-reconstructed frame puts a marker far away for one frame. Read as a position, one such
value drags the scale fit and the inverse kinematics by metres, and the residual forces
with them. A run of such values over several frames is no spike (:func:`marker_spikes`
needs the neighbouring frames near), but it lies kilometres from the frame's other markers
(:func:`far_markers`). The readers keep what the file holds (a TRC written and read again
is the same to the bit); where a trial is loaded for the pipeline
(:func:`solver.io.subject.load_trial`) and in ``addb info``, :func:`without_spikes` reads
each as a missing marker and says so.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from numpy.typing import NDArray

from solver.io.types import MarkerTrajectories

#: A marker farther than this (m) from its positions in both neighbouring frames, which lie
#: closer together than half that distance, is a spike (:func:`marker_spikes`).
SPIKE_M = 1.0


def marker_spikes(positions: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Find the single-frame spikes of every marker.

    A spike is a position more than :data:`SPIKE_M` from the marker's positions in both
    neighbouring frames while those two lie within half that distance of each other: the
    marker left and came back within one frame each way (60 m/s at 30 Hz), which no point
    of a body does. Smooth motion never is one, not even a marker file read in the wrong
    unit (its neighbours lie about twice a frame's step apart); a frame beside a gap, and
    the first and last frames, are never judged.

    Parameters
    ----------
    positions
        ``(T, M, 3)`` marker positions, m, NaN where missing.

    Returns
    -------
    frames, markers, distance
        ``(S,)`` each, for the S spikes in frame order: the frame index, the marker index,
        and the distance to the nearer neighbour's position, m.
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[0] < 3:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty, np.zeros(0)
    prev, here, nxt = p[:-2], p[1:-1], p[2:]
    with np.errstate(invalid="ignore", over="ignore"):
        near = np.minimum(np.linalg.norm(here - prev, axis=2), np.linalg.norm(here - nxt, axis=2))
        apart = np.linalg.norm(nxt - prev, axis=2)
        spike = (near > SPIKE_M) & (apart < 0.5 * near)  # NaN compares False
    frames, markers = np.nonzero(spike)
    return frames + 1, markers, near[frames, markers]


#: A marker farther than this (m) from the median of its frame's markers, and farther than
#: :data:`FAR_SPREAD` times their median distance from it, is far from the others
#: (:func:`far_markers`).
FAR_MARKER_M = 100.0
#: How many times the frame's own spread (the median distance of its markers from their
#: median) a far marker lies beyond: markers read in the wrong unit (all of them 1000 times
#: apart) are not far from each other, and the unit warning names them.
FAR_SPREAD = 20.0


def far_markers(positions: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Find the markers far from the frame's other markers (input audit 2026-12-02, finding 11:
    R.Shoulder written as 9999999 mm on six rows, 10 km away, made the scale fit blame the
    file's Units line).

    A marker is far when its distance from the median of the frame's markers (per axis)
    exceeds both :data:`FAR_MARKER_M` and :data:`FAR_SPREAD` times the median of those
    distances: no point on a person or in a lab is 100 m from the others. A frame whose
    coordinates all lie within 25 m of the origin has none (no two of its markers are 100 m
    apart), which is every frame of a lab file, so the usual cost is one comparison.

    Takes and returns what :func:`marker_spikes` does (``positions`` ``(T, M, 3)``, m, NaN
    where missing; ``(frames, markers, distance)``, ``(F,)`` each in frame order), the
    distance being the marker's from the frame's median, m.
    """
    p = np.asarray(positions, dtype=float)
    empty = np.zeros(0, dtype=np.intp)
    with np.errstate(invalid="ignore"):
        if p.ndim != 3 or not (np.abs(p) > FAR_MARKER_M / 4.0).any():  # 2 sqrt(3) x 25 m < 100 m
            return empty, empty, np.zeros(0)
    rows = np.flatnonzero(np.isfinite(p).all(axis=2).sum(axis=1) >= 3)  # a median of three or more
    if not rows.size:
        return empty, empty, np.zeros(0)
    q = p[rows]
    centre = np.nanmedian(q, axis=1)  # (R, 3)
    with np.errstate(invalid="ignore", over="ignore"):
        distance = np.linalg.norm(q - centre[:, None, :], axis=2)  # (R, M)
        spread = np.nanmedian(distance, axis=1)
        far = (distance > FAR_MARKER_M) & (distance > FAR_SPREAD * spread[:, None])  # NaN compares False
    r, markers = np.nonzero(far)
    return rows[r], markers, distance[r, markers]


def without_spikes(markers: MarkerTrajectories) -> MarkerTrajectories:
    """``markers`` with each marker far from the frame's others (:func:`far_markers`) and
    each single-frame spike (:func:`marker_spikes`) read as missing (NaN), with a
    :class:`UserWarning` for each far marker (the file, its frames, 0-based, and times, its
    distance) and one for the spikes (the file, the first spike's frame, time and marker, and
    the count); ``markers`` itself when there is none.

    Parameters
    ----------
    markers
        A trial's marker trajectories (``positions`` ``(T, M, 3)``, m).

    Returns
    -------
    MarkerTrajectories
        The same names, times and rate; positions ``(T, M, 3)``, m, NaN at the spikes.
    """
    where = markers.source or "markers"
    positions = markers.positions
    frames, which, distance = marker_spikes(positions)
    if frames.size:
        positions = positions.copy()
        positions[frames, which] = np.nan
        f, m = int(frames[0]), int(which[0])
        warnings.warn(
            f"{where}, frame {f} ({float(markers.time[f]):.3f} s): marker {markers.names[m]} is {float(distance[0]):.3g} m "
            f"from where it is in the frames before and after; {frames.size} such single-frame spike"
            f"{'s' * (frames.size > 1)} read as missing (a value written for a lost marker, or a bad reconstruction)",
            UserWarning,
            stacklevel=2,
        )
    far, far_which, far_distance = far_markers(positions)  # runs of such values: no spike, far from the others
    if far.size:
        positions = positions.copy() if positions is markers.positions else positions
        positions[far, far_which] = np.nan
        for m in np.unique(far_which).tolist():
            mine = np.flatnonzero(far_which == m)
            first, last = int(far[mine[0]]), int(far[mine[-1]])
            warnings.warn(
                f"{where}, frames {first}-{last} ({float(markers.time[first]):.3f}-{float(markers.time[last]):.3f} s): "
                f"marker {markers.names[m]} is {float(far_distance[mine[0]]) / 1000.0:.3g} km from the frame's other "
                f"markers on {mine.size} frame{'s' * (mine.size > 1)}, read as missing (a value written for a lost marker?)",
                UserWarning,
                stacklevel=2,
            )
    return markers if positions is markers.positions else dataclasses.replace(markers, positions=positions)
