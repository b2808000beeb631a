"""Single-frame spikes of a marker: a value no body point can take between two frames.

A lab's exporter writes a value such as 9999999 or 1e37 for a marker it lost, and a
mis-reconstructed frame puts a marker far away for one frame. Read as a position, one such
value drags the scale fit and the inverse kinematics by metres, and the residual forces
with them. The readers keep what the file holds (a
TRC written and read again is the same to the bit); where a trial is loaded for the
pipeline (:func:`solver.io.subject.load_trial`) and in ``addb info``, :func:`without_spikes`
reads each spike as a missing marker and says so.
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


def without_spikes(markers: MarkerTrajectories) -> MarkerTrajectories:
    """``markers`` with each single-frame spike (:func:`marker_spikes`) read as missing
    (NaN), and a :class:`UserWarning` naming the file, the first spike's frame (0-based), time and
    marker, and the count; ``markers`` itself when there is none.

    Parameters
    ----------
    markers
        A trial's marker trajectories (``positions`` ``(T, M, 3)``, m).

    Returns
    -------
    MarkerTrajectories
        The same names, times and rate; positions ``(T, M, 3)``, m, NaN at the spikes.
    """
    frames, which, distance = marker_spikes(markers.positions)
    if not frames.size:
        return markers
    positions = markers.positions.copy()
    positions[frames, which] = np.nan
    f, m = int(frames[0]), int(which[0])
    where = markers.source or "markers"
    warnings.warn(
        f"{where}, frame {f} ({float(markers.time[f]):.3f} s): marker {markers.names[m]} is {float(distance[0]):.3g} m "
        f"from where it is in the frames before and after; {frames.size} such single-frame spike"
        f"{'s' * (frames.size > 1)} read as missing (a value written for a lost marker, or a bad reconstruction)",
        UserWarning,
        stacklevel=2,
    )
    return dataclasses.replace(markers, positions=positions)
