"""Checks of the arguments of the store's public methods (explicit errors, never ``assert``)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from annotations.errors import AnnotationError
from annotations.model import FEET, FLAG_KINDS, SOURCES

MAX_FRAME = 50_000_000
"""Largest accepted frame index + 1 (about 5.8 days at 100 Hz): catches unit mistakes."""

FramesLike = int | range | Iterable[int] | NDArray[np.integer]


def check_kind(kind: str) -> str:
    """The flag kind, if it is one of ``FLAG_KINDS``; raises ``AnnotationError`` otherwise."""
    if kind not in FLAG_KINDS:
        raise AnnotationError(f"unknown flag kind {kind!r}; expected one of {FLAG_KINDS}")
    return kind


def check_foot(foot: str | None) -> str | None:
    """The foot, if ``None`` or one of ``FEET``; raises ``AnnotationError`` otherwise."""
    if foot is not None and foot not in FEET:
        raise AnnotationError(f"unknown foot {foot!r}; expected one of {FEET} or None")
    return foot


def check_source(source: str) -> str:
    """The provenance source, if one of ``SOURCES``; raises ``AnnotationError`` otherwise."""
    if source not in SOURCES:
        raise AnnotationError(f"unknown source {source!r}; expected one of {SOURCES}")
    return source


def check_trial(trial: str) -> None:
    """Raise unless ``trial`` is a non-empty name without control characters."""
    if (
        not isinstance(trial, str)
        or not trial
        or len(trial) > 200
        or any(ord(c) < 32 for c in trial)
    ):
        raise AnnotationError(f"trial must be a non-empty name, got {trial!r}")


def count(value: Any, name: str) -> int:
    """``value`` as an int, if it is a non-negative integer (not a bool).

    Raises
    ------
    AnnotationError
        Naming ``name``, if ``value`` is a bool, not an integer, or negative.
    """
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise AnnotationError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)


def span(start: Any, stop: Any) -> tuple[int, int]:
    """A half-open frame range ``(start, stop)`` with ``0 <= start < stop``.

    Raises
    ------
    AnnotationError
        If ``start`` or ``stop`` is not a non-negative integer, or ``stop <= start``.
    """
    s, e = count(start, "start"), count(stop, "stop")
    if e <= s:
        raise AnnotationError(f"empty or reversed frame range [{s}, {e})")
    return s, e


def frames_list(frames: FramesLike) -> list[int]:
    """Frame indices from an int, a range or an iterable of ints (not booleans).

    Raises
    ------
    AnnotationError
        If ``frames`` is a bool or a boolean mask, not integers, empty, a range with a step
        other than 1 or ending past ``MAX_FRAME``, or holds a negative index.
    """
    if isinstance(frames, bool | np.bool_):
        raise AnnotationError("frames must be frame indices, got a boolean")
    if isinstance(frames, int | np.integer):
        out = [int(frames)]
    elif isinstance(frames, range):
        if frames.step != 1:
            raise AnnotationError("a frame range must have step 1")
        if frames.stop > MAX_FRAME:
            raise AnnotationError(f"frame range {frames} is beyond {MAX_FRAME} frames")
        out = list(frames)
    else:
        arr = np.asarray(list(frames) if not isinstance(frames, np.ndarray) else frames)
        if arr.dtype == np.bool_:
            raise AnnotationError("frames is a boolean mask; use set_mask() for masks")
        if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
            raise AnnotationError(
                f"frames must be integer frame indices, got {arr.dtype} {arr.shape}"
            )
        out = sorted(set(arr.tolist()))
    if not out:
        raise AnnotationError("no frames given")
    if min(out) < 0:
        raise AnnotationError(f"frame indices must be >= 0, got {min(out)}")
    return out
