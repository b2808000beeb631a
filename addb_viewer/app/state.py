"""The playback controller: current frame, play/pause, speed, loop and in/out points.

Plain Python (no viser), so it is tested without a server. Playback follows the wall
clock: while playing, the frame is ``anchor_frame + (now - anchor_time) * rate * speed``,
so a slow scene update skips frames instead of slowing the replay down. Every method
that changes the timing takes ``now`` (seconds, e.g. ``time.monotonic()``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

SPEED_MIN = 0.1
"""Slowest playback speed (times real time)."""
SPEED_MAX = 2.0
"""Fastest playback speed (times real time)."""


@dataclass
class Playback:
    """Playback state of one trial.

    Attributes
    ----------
    n_frames
        Number of frames T (>= 1).
    rate_hz
        Frame rate, Hz (> 0).
    frame
        Current frame, ``0 <= frame < n_frames``.
    playing
        Whether the clock advances the frame.
    speed
        Playback speed, times real time, in ``[SPEED_MIN, SPEED_MAX]``.
    loop
        At the end, start again from frame 0 (else stop on the last frame).
    in_point, out_point
        Marked frames of a range selection (inclusive), or None.
    """

    n_frames: int
    rate_hz: float
    frame: int = 0
    playing: bool = False
    speed: float = 1.0
    loop: bool = True
    in_point: int | None = None
    out_point: int | None = None
    _anchor_frame: int = field(default=0, repr=False)
    _anchor_time: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        if self.n_frames < 1:
            raise ValueError(f"a trial needs at least one frame, got {self.n_frames}")
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"frame rate must be finite and > 0, got {self.rate_hz}")
        self.frame = self.clamp(self.frame)
        self.speed = min(max(float(self.speed), SPEED_MIN), SPEED_MAX)

    # ------------------------------------------------------------------ frames
    def clamp(self, frame: int) -> int:
        """``frame`` limited to ``[0, n_frames - 1]``."""
        return int(min(max(int(frame), 0), self.n_frames - 1))

    def time_of(self, frame: int) -> float:
        """Time of ``frame`` from the trial start, s."""
        return frame / self.rate_hz

    def seek(self, frame: int, now: float) -> int:
        """Go to ``frame`` (clamped); playback, if on, continues from there."""
        self.frame = self.clamp(frame)
        self._anchor(now)
        return self.frame

    def step(self, delta: int, now: float) -> int:
        """Pause and move ``delta`` frames (wrapping around when :attr:`loop` is on)."""
        self.playing = False
        target = self.frame + int(delta)
        if self.loop:
            target %= self.n_frames
        return self.seek(target, now)

    # ------------------------------------------------------------------ clock
    def play(self, now: float) -> None:
        """Start playing from the current frame (from 0 when at the end without loop)."""
        if not self.loop and self.frame >= self.n_frames - 1:
            self.frame = 0
        self.playing = True
        self._anchor(now)

    def pause(self, now: float) -> None:
        """Stop at the current frame."""
        self.tick(now)
        self.playing = False

    def toggle(self, now: float) -> bool:
        """Play if paused, pause if playing; returns the new :attr:`playing`."""
        if self.playing:
            self.pause(now)
        else:
            self.play(now)
        return self.playing

    def set_speed(self, speed: float, now: float) -> float:
        """Change the speed (clamped to ``[SPEED_MIN, SPEED_MAX]``) without a jump."""
        self.tick(now)
        s = float(speed)
        self.speed = min(max(s if math.isfinite(s) else 1.0, SPEED_MIN), SPEED_MAX)
        self._anchor(now)
        return self.speed

    def tick(self, now: float) -> int:
        """Advance the frame to wall-clock time ``now`` if playing; return the frame."""
        if not self.playing:
            return self.frame
        elapsed = max(now - self._anchor_time, 0.0)
        target = self._anchor_frame + math.floor(elapsed * self.rate_hz * self.speed + 1e-9)
        if target >= self.n_frames:
            if self.loop:
                target %= self.n_frames
                self.frame = target
                self._anchor(now)
                return self.frame
            self.frame = self.n_frames - 1
            self.playing = False
            return self.frame
        self.frame = target
        return self.frame

    def _anchor(self, now: float) -> None:
        self._anchor_frame = self.frame
        self._anchor_time = now

    # ------------------------------------------------------------------ in / out points
    def mark_in(self, frame: int | None = None) -> int:
        """Set the in point (default: the current frame): the start of the selected range.

        While only the out point is set, the two make a range in either order. While both
        are set, the range's start moves there; past the range's end it starts a new range
        there (the out point is cleared), rather than stretching the old range to it. The
        points are kept in order (:attr:`in_point` <= :attr:`out_point`), so a range marked
        end first (I at 140, O at 100) is the range 100-140 for the marks after it."""
        new = self.clamp(self.frame if frame is None else frame)
        if self.in_point is not None and self.out_point is not None and new > self.out_point:
            self.out_point = None
        self.in_point = new
        self._order_points()
        return new

    def mark_out(self, frame: int | None = None) -> int:
        """Set the out point (default: the current frame); as :meth:`mark_in`, mirrored: with
        both points set, the range's end moves there, and a point before the range's start
        starts a new range there."""
        new = self.clamp(self.frame if frame is None else frame)
        if self.in_point is not None and self.out_point is not None and new < self.in_point:
            self.in_point = None
        self.out_point = new
        self._order_points()
        return new

    def _order_points(self) -> None:
        if self.in_point is not None and self.out_point is not None and self.in_point > self.out_point:
            self.in_point, self.out_point = self.out_point, self.in_point

    def clear_marks(self) -> None:
        """Forget the in and out points."""
        self.in_point = self.out_point = None

    def selection(self) -> tuple[int, int] | None:
        """The marked frames as a half-open range ``(start, stop)``, in either order of
        marking; a single marked point selects that frame; None when nothing is marked."""
        pts = [p for p in (self.in_point, self.out_point) if p is not None]
        if not pts:
            return None
        return min(pts), max(pts) + 1


def next_run_start(mask: NDArray[np.bool_], frame: int, *, wrap: bool = True) -> int | None:
    """First frame after ``frame`` that starts a run of ``True`` in ``mask``.

    Starting inside a run skips to the next run, so repeated calls visit every run once.

    Parameters
    ----------
    mask
        ``(T,)`` booleans.
    frame
        Current frame.
    wrap
        Continue from frame 0 when no run starts after ``frame``.

    Returns
    -------
    int or None
        The frame, or None when ``mask`` has no run to go to.
    """
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return None
    starts = np.flatnonzero(m & ~np.concatenate(([False], m[:-1])))
    later = starts[starts > frame]
    if later.size:
        return int(later[0])
    if wrap:
        return int(starts[0])
    return None


def run_at(mask: NDArray[np.bool_], frame: int) -> tuple[int, int] | None:
    """The half-open run ``(start, stop)`` of ``True`` in ``mask`` containing ``frame``."""
    m = np.asarray(mask, dtype=bool)
    if not (0 <= frame < m.size) or not m[frame]:
        return None
    off = np.flatnonzero(~m[: frame + 1])
    start = int(off[-1]) + 1 if off.size else 0
    off = np.flatnonzero(~m[frame:])
    stop = frame + int(off[0]) if off.size else m.size
    return start, stop
