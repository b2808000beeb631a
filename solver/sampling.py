"""The frame spacing of a time column, one rule for the whole code base.

Recordings are sampled at a fixed rate, but their time columns carry round-off, and a
dropped or repeated frame leaves one odd step; the median step is the frame interval that
ignores both (the rule OpenSim's and AddBiomechanics' readers apply to TRC and MOT time
columns, which have no other rate for the frames a pipeline resamples).

A rate read from a time column is given as its nominal value (:func:`nominal_rate`):
``np.arange(T) * 0.01`` has a median step of 0.010000000000000009 s, which is 100 Hz, not
99.99999999999991 Hz, in results.json, a .b3d header or a filter's design.
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


def nominal_rate(rate: float) -> float:
    """A rate (Hz) measured from a time column, as the lab set it: the nearest whole number of
    Hz when ``rate`` is within one part in a million of it (100 Hz, not 99.99999999999991 Hz;
    2000 Hz, not 1999.9999999 Hz), otherwise ``rate`` unchanged (a 148.148 Hz camera keeps
    its rate). NaN, infinite or non-positive rates are returned as they are.
    """
    rate = float(rate)
    if not (np.isfinite(rate) and rate > 0):
        return rate
    nearest = round(rate)
    return float(nearest) if nearest > 0 and abs(rate - nearest) <= 1e-6 * nearest else rate


def nominal_interval(interval: float) -> float:
    """A frame interval (s) measured from a time column, as one over the :func:`nominal_rate`
    of its rate: 0.010000000000000009 s gives 0.01 s. Non-positive or non-finite intervals
    are returned as they are."""
    interval = float(interval)
    if not (np.isfinite(interval) and interval > 0):
        return interval
    return 1.0 / nominal_rate(1.0 / interval)


def frame_rate(time: ArrayLike, default: float | None = None, what: str = "time column") -> float:
    """Frame rate of a time column ``time`` ``(T,)`` (frame times, s), Hz: the
    :func:`nominal_rate` of one over :func:`frame_interval` (``default``, in Hz, when there
    are fewer than two frames).

    Raises
    ------
    ValueError
        Fewer than two frames and no ``default``.
    """
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size < 2 and default is not None:
        return float(default)
    return nominal_rate(1.0 / frame_interval(t, what=what))
