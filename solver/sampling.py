"""The frame spacing of a time column, one rule for the whole code base.

Recordings are sampled at a fixed rate, but their time columns carry round-off, and a
dropped or repeated frame leaves one odd step; the median step is the frame interval that
ignores both (the rule OpenSim's and AddBiomechanics' readers apply to TRC and MOT time
columns, which have no other rate for the frames a pipeline resamples).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def frame_interval(time: ArrayLike, default: float | None = None, what: str = "time column") -> float:
    """Median step of a time column, s.

    Parameters
    ----------
    time
        ``(T,)`` frame times, s, increasing.
    default
        Returned when ``time`` has fewer than two frames; without one that is an error.
    what
        What ``time`` is (a file, a trial), for the error message.

    Raises
    ------
    ValueError
        Fewer than two frames and no ``default``.
    """
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size < 2:
        if default is None:
            raise ValueError(f"{what}: {t.size} frame(s), at least two are needed for a frame rate")
        return float(default)
    return float(np.median(np.diff(t)))


def frame_rate(time: ArrayLike, default: float | None = None, what: str = "time column") -> float:
    """Frame rate of a time column ``time`` ``(T,)`` (frame times, s), Hz: one over
    :func:`frame_interval` (``default``, in Hz, when there are fewer than two frames).

    Raises
    ------
    ValueError
        Fewer than two frames and no ``default``.
    """
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size < 2 and default is not None:
        return float(default)
    return 1.0 / frame_interval(t, what=what)
