"""Conversions between frame masks (what the solver takes) and frame ranges (what is stored).

A mask is a boolean ``(T,)`` array, one entry per frame at the trial's frame rate,
``True`` where the flag is set. A range list is a sorted list of disjoint, non-adjacent,
half-open ``(start, stop)`` pairs of 0-based frame indices.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from annotations.errors import AnnotationError

BoolArray = NDArray[np.bool_]


def mask_to_ranges(mask: Sequence[bool] | NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Half-open ranges of the ``True`` runs of a mask.

    Parameters
    ----------
    mask
        ``(T,)`` booleans, one per frame.

    Returns
    -------
    list of (int, int)
        ``[(start, stop), ...]`` sorted, disjoint and non-adjacent, so that
        ``ranges_to_mask(mask_to_ranges(m), len(m))`` equals ``m``.

    Raises
    ------
    AnnotationError
        If ``mask`` is not one-dimensional or not boolean.
    """
    arr = np.asarray(mask)
    if arr.ndim != 1:
        raise AnnotationError(f"a frame mask must have shape (T,), got shape {arr.shape}")
    if arr.size and arr.dtype != np.bool_:
        raise AnnotationError(f"a frame mask must be boolean, got dtype {arr.dtype}")
    padded = np.zeros(arr.size + 2, dtype=np.int8)
    padded[1:-1] = arr
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(edges[0::2], edges[1::2], strict=True)]


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


def resample_mask(
    mask: Sequence[bool] | NDArray[np.bool_],
    *,
    from_hz: float,
    to_hz: float,
    n_frames: int | None = None,
) -> BoolArray:
    """A mask at another frame rate, conservatively: a frame is flagged if it overlaps
    any flagged frame.

    Frame ``i`` at rate ``f`` stands for the time interval ``[(i - 0.5) / f, (i + 0.5) / f)``
    (both trials start at time 0). Output frame ``j`` is ``True`` when its interval
    overlaps the interval of a ``True`` input frame by a positive amount, so no flagged
    instant is lost (the right choice for unmeasured force: better to leave one frame
    too many out of the dynamic fit). With ``from_hz == to_hz`` the mask is unchanged.

    Parameters
    ----------
    mask
        ``(T_in,)`` booleans at ``from_hz``.
    from_hz, to_hz
        Input and output frame rates, Hz (> 0).
    n_frames
        Output length; default ``round(T_in * to_hz / from_hz)``.

    Returns
    -------
    numpy.ndarray
        ``(n_frames,)`` bool at ``to_hz``.
    """
    if not (math.isfinite(from_hz) and from_hz > 0 and math.isfinite(to_hz) and to_hz > 0):
        raise AnnotationError(f"frame rates must be finite and > 0, got {from_hz}, {to_hz} Hz")
    src = np.asarray(mask)
    ratio = Fraction(to_hz) / Fraction(from_hz)
    n_out = round(src.size * ratio) if n_frames is None else _check_count(n_frames, "n_frames")
    out = np.zeros(n_out, dtype=bool)
    for start, stop in mask_to_ranges(src):
        # overlap <=> j > (start - 1/2) r - 1/2  and  j < (stop - 1/2) r + 1/2
        lo = (Fraction(2 * start - 1) * ratio - 1) / 2
        hi = (Fraction(2 * stop - 1) * ratio + 1) / 2
        j0 = math.floor(lo) + 1
        j1 = math.ceil(hi)
        out[max(j0, 0) : max(min(j1, n_out), 0)] = True
    return out


def _check_count(value: int, name: str) -> int:
    if isinstance(value, bool) or int(value) != value or value < 0:
        raise AnnotationError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)
