"""The unmeasured-force mask in the solver: its frames, the one resampling rule, the one
join rule and the one "mask to runs" helper.

The mask
    ``unmeasured_force``: trial name -> ``(T,)`` bool, ``True`` on the frames whose external
    force was not (fully) measured, which the dynamic fit must not trust. It is given at
    the trial's **processed frames**: the frames of ``OUT/<trial>/trial.npz``, i.e.
    ``DynamicsOptions.rate_hz`` (100 Hz) from the first instant both the markers and the
    force plates cover (:func:`solver.dynamics.stage.trial_frames`). Those are the frames
    the review app shows and the review record stores, so a reviewer's flags reach the
    solver without any resampling. A mask of another length is refused (DynamicsError
    naming the trial and both lengths).

Masks made on other frames
    An AddBiomechanics ``review.json`` and the ``unmeasured_force`` extensions that
    ``addb diagnose --apply`` saves hold one entry per **marker** frame; they are put on
    the processed frames (and the diagnosis' frames back on marker frames) by
    :func:`resample_mask` only.

Resampling rule (:func:`resample_mask`)
    Frame ``k`` at time ``t_k`` stands for the interval ``[t_k - dt/2, t_k + dt/2)`` (``dt``
    its grid's median spacing). A target frame is flagged when its interval overlaps the
    interval of a flagged source frame by more than a thousandth of a frame. This is the
    conservative rule: every instant a source flag covers stays covered, so no
    unmeasured instant re-enters the fit when the rates differ (nearest-frame sampling,
    the previous rule, drops a flagged 200 Hz frame whose nearest 100 Hz frame is not
    flagged). On one grid it is the identity. The cost is at most one extra frame at each
    end of a run when the rates differ (a 100 -> 200 -> 100 Hz round trip widens a run
    by one 100 Hz frame at each end).

Join rule (:func:`join_masks`)
    The union, trial by trial, of masks on the **same** frames. Masks of one trial with
    different lengths are refused (naming the trial and both lengths): they were made on
    different frames (a mask at marker frames joined to one at processed frames, or a
    recording replaced after the flags were saved), and padding or cutting would move
    flags onto other instants. Resample first, then join.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import DynamicsError
from solver.sampling import frame_interval

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: Overlap (in frames of the finer grid) below which two frame intervals only touch.
_TOUCH = 1e-3


def true_runs(mask: Sequence[bool] | NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Half-open ``(start, stop)`` of every run of consecutive ``True`` values, in order.

    Parameters
    ----------
    mask
        ``(T,)`` booleans (or 0/1 values).

    Returns
    -------
    list of (int, int)
        Sorted, disjoint, non-adjacent runs: ``mask[start:stop]`` is all True, and the
        frames before ``start`` and at ``stop`` (when they exist) are False.

    Raises
    ------
    ValueError
        ``mask`` is not one-dimensional.
    """
    arr = np.asarray(mask)
    if arr.ndim != 1:
        raise ValueError(f"a frame mask must have shape (T,), got shape {arr.shape}")
    padded = np.zeros(arr.size + 2, dtype=np.int8)
    padded[1:-1] = arr.astype(bool)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))


def _spacing(time: FloatArray, other: FloatArray) -> float:
    return frame_interval(time, default=frame_interval(other, default=1.0))


def resample_mask(mask: Sequence[bool] | BoolArray, src_time: FloatArray, time: FloatArray) -> BoolArray:
    """A frame mask on other frame times, by the overlap rule (see the module docstring).

    Parameters
    ----------
    mask
        ``(S,)`` bool on the frames ``src_time``.
    src_time
        ``(S,)`` increasing frame times of ``mask``, s (a uniform grid).
    time
        ``(T,)`` increasing target frame times, s (a uniform grid; any start and rate).
        A grid's spacing is its median frame interval; a grid of one frame takes the
        other grid's.

    Returns
    -------
    numpy.ndarray
        ``(T,)`` bool: target frame ``j`` is True when ``[time[j] - dt/2, time[j] + dt/2)``
        overlaps a flagged ``[src_time[i] - ds/2, src_time[i] + ds/2)`` by more than a
        thousandth of the smaller spacing. ``time == src_time`` returns ``mask`` itself.

    Raises
    ------
    ValueError
        ``mask`` and ``src_time`` differ in length, or a mask is not one-dimensional.
    """
    src = np.asarray(mask, dtype=bool)
    src_time = np.asarray(src_time, dtype=float)
    time = np.asarray(time, dtype=float)
    if src.ndim != 1 or src.shape != src_time.shape:
        raise ValueError(f"a mask of shape {src.shape} on {src_time.size} frame times")
    if src_time.shape == time.shape and np.array_equal(src_time, time):
        return src.copy()
    ds, dt = _spacing(src_time, time), _spacing(time, src_time)
    tol = _TOUCH * min(ds, dt)
    out = np.zeros(time.size, dtype=bool)
    for a, b in true_runs(src):
        lo = src_time[a] - ds / 2  # the flagged instants: [lo, hi)
        hi = src_time[b - 1] + ds / 2
        # overlap of [t - dt/2, t + dt/2) with [lo, hi) is > tol
        j0 = int(np.searchsorted(time, lo - dt / 2 + tol, side="right"))
        j1 = int(np.searchsorted(time, hi + dt / 2 - tol, side="left"))
        out[j0:j1] = True
    return out


def join_masks(
    masks: Mapping[str, BoolArray] | None,
    extra: Mapping[str, BoolArray] | None,
    *,
    path: str | Path | None = None,
) -> dict[str, BoolArray] | None:
    """The union, trial by trial, of two sets of masks on the same frames.

    Parameters
    ----------
    masks, extra
        Trial name -> ``(T,)`` bool; None or empty for none.
    path
        The file the masks come from, named in the error.

    Returns
    -------
    dict or None
        Every trial of either; ``masks`` itself (None included) when ``extra`` is empty.

    Raises
    ------
    DynamicsError
        Two masks of one trial differ in length (naming the trial and both lengths).
    """
    if not extra:
        return None if masks is None else dict(masks)
    out = {name: np.asarray(m, dtype=bool) for name, m in (masks or {}).items()}
    for name, e in extra.items():
        e = np.asarray(e, dtype=bool)
        old = out.get(name)
        if old is None:
            out[name] = e.copy()
            continue
        if old.shape != e.shape:
            raise DynamicsError(
                f"two unmeasured-force masks of one trial differ in length ({old.size} and {e.size} "
                "frames): they were made on different frames; resample one onto the other's frames first",
                path=path,
                where=f"trial {name}",
            )
        out[name] = old | e
    return out
