"""Frame ranges, the review record's form of its flags: frame indices -> ranges -> a mask.

A range list is a sorted list of disjoint, non-adjacent, half-open ``(start, stop)`` pairs
of 0-based frame indices; a mask is a boolean ``(T,)`` array, one entry per frame of the
trial as the record stores it (``n_frames``, ``rate_hz``), ``True`` where the flag is set.
The store keeps flags per frame, so it forms ranges from frame indices
(:func:`frames_to_ranges`). Runs of a boolean mask outside the store, resampling masks to
other frames and joining masks belong to :mod:`solver.masks` (the package imports nothing
of the solver; the app converts the record into the solver's masks,
:mod:`addb_viewer.review_masks`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from annotations.errors import AnnotationError

BoolArray = NDArray[np.bool_]


def ranges_to_mask(ranges: Iterable[tuple[int, int]], n_frames: int) -> BoolArray:
    """Boolean mask with ``True`` on the frames of the given half-open ranges.

    Parameters
    ----------
    ranges
        ``(start, stop)`` pairs with ``0 <= start <= stop <= n_frames``; they may
        overlap or be empty.
    n_frames
        Length ``T`` of the mask.

    Returns
    -------
    numpy.ndarray
        ``(T,)`` bool.

    Raises
    ------
    AnnotationError
        If a range is reversed or outside ``[0, n_frames]``.
    """
    n = _check_count(n_frames, "n_frames")
    out = np.zeros(n, dtype=bool)
    for start, stop in ranges:
        s, e = int(start), int(stop)
        if not 0 <= s <= e <= n:
            raise AnnotationError(
                f"range ({start}, {stop}) is not within [0, {n}] with start <= stop"
            )
        out[s:e] = True
    return out


def frames_to_ranges(frames: Iterable[int]) -> list[tuple[int, int]]:
    """Half-open ranges covering a set of frame indices (duplicates allowed, any order).

    Parameters
    ----------
    frames
        Non-negative frame indices.

    Returns
    -------
    list of (int, int)
        Sorted, disjoint, non-adjacent ranges.

    Raises
    ------
    AnnotationError
        If a frame index is negative.
    """
    arr = np.unique(np.fromiter((int(f) for f in frames), dtype=np.int64))
    if arr.size == 0:
        return []
    if arr[0] < 0:
        raise AnnotationError(f"frame indices must be >= 0, got {int(arr[0])}")
    breaks = np.flatnonzero(np.diff(arr) != 1)
    starts = np.concatenate(([arr[0]], arr[breaks + 1]))
    stops = np.concatenate((arr[breaks] + 1, [arr[-1] + 1]))
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def _check_count(value: int, name: str) -> int:
    if isinstance(value, bool) or int(value) != value or value < 0:
        raise AnnotationError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)
