"""Playback controller (addb_viewer.app.state): wall-clock playback, stepping, loop,
speed limits, in/out points, jumps to runs of a mask. No server."""

from __future__ import annotations

import numpy as np
import pytest

from addb_viewer.app.state import SPEED_MAX, SPEED_MIN, Playback, next_run_start, run_at


def test_playback_follows_the_wall_clock_and_speed() -> None:
    pb = Playback(n_frames=500, rate_hz=100.0)
    pb.play(now=10.0)
    assert pb.tick(10.5) == 50  # 0.5 s at 100 Hz
    pb.set_speed(0.5, now=10.5)
    assert pb.tick(11.5) == 100  # one more second at half speed
    pb.pause(now=11.5)
    assert pb.tick(20.0) == 100 and not pb.playing


def test_speed_is_limited_to_the_documented_range() -> None:
    pb = Playback(n_frames=10, rate_hz=100.0)
    assert pb.set_speed(10.0, now=0.0) == SPEED_MAX
    assert pb.set_speed(0.0, now=0.0) == SPEED_MIN
    assert pb.set_speed(float("nan"), now=0.0) == 1.0


def test_loop_wraps_and_no_loop_stops_on_the_last_frame() -> None:
    pb = Playback(n_frames=100, rate_hz=100.0, loop=True)
    pb.play(now=0.0)
    assert pb.tick(1.25) == 25 and pb.playing
    pb = Playback(n_frames=100, rate_hz=100.0, loop=False)
    pb.play(now=0.0)
    assert pb.tick(5.0) == 99 and not pb.playing
    pb.play(now=6.0)  # playing again from the end restarts
    assert pb.frame == 0 and pb.playing


def test_step_pauses_clamps_or_wraps() -> None:
    pb = Playback(n_frames=10, rate_hz=50.0, loop=False)
    pb.play(now=0.0)
    assert pb.step(1, now=0.0) == 1 and not pb.playing
    assert pb.step(-5, now=0.0) == 0
    pb.loop = True
    assert pb.step(-1, now=0.0) == 9
    assert pb.seek(1000, now=0.0) == 9 and pb.seek(-3, now=0.0) == 0


def test_seek_while_playing_continues_from_the_new_frame() -> None:
    pb = Playback(n_frames=1000, rate_hz=100.0)
    pb.play(now=0.0)
    pb.seek(500, now=2.0)
    assert pb.tick(2.1) == 510


def test_in_out_points_give_a_half_open_range_in_either_order() -> None:
    pb = Playback(n_frames=100, rate_hz=100.0)
    assert pb.selection() is None
    pb.seek(40, now=0.0)
    pb.mark_in()
    assert pb.selection() == (40, 41)
    pb.mark_out(12)
    assert pb.selection() == (12, 41)
    pb.clear_marks()
    assert pb.selection() is None


def test_a_mark_past_the_other_end_of_a_range_starts_a_new_range() -> None:
    """In at 10, out at 20, then in at 300 selects frame 300 (a new range), not 20-300; the
    explorer's report: one more key then flagged 281 frames."""
    pb = Playback(n_frames=500, rate_hz=100.0)
    pb.mark_in(10)
    pb.mark_out(20)
    pb.mark_in(15)
    assert pb.selection() == (15, 21)  # inside the range: the in point moves
    pb.mark_in(300)
    assert pb.selection() == (300, 301)
    pb.mark_out(320)
    assert pb.selection() == (300, 321)
    pb.mark_out(5)  # mirrored
    assert pb.selection() == (5, 6)
    pb.clear_marks()
    pb.mark_out(30)
    pb.mark_in(50)  # only the other point set: either order
    assert pb.selection() == (30, 51)


def test_a_range_marked_end_first_is_moved_by_the_marks_after_it() -> None:
    """I at 140 then O at 100 select 100-140; a point inside that range then moves its start
    (I) or its end (O), and one before its start (I) stretches it: the explorer's report,
    where O at 130 collapsed the range to frame 130 and I at 90 gave 90-100 (the points were
    kept as marked, in at 140 and out at 100)."""
    pb = Playback(n_frames=300, rate_hz=100.0)
    pb.mark_in(140)
    pb.mark_out(100)
    assert pb.selection() == (100, 141)
    pb.mark_out(130)
    assert pb.selection() == (100, 131)
    pb.clear_marks()
    pb.mark_in(140)
    pb.mark_out(100)
    pb.mark_in(110)
    assert pb.selection() == (110, 141)
    pb.clear_marks()
    pb.mark_in(140)
    pb.mark_out(100)
    pb.mark_in(90)
    assert pb.selection() == (90, 141)
    pb.mark_in(200)  # past the range's end: a new range
    assert pb.selection() == (200, 201)


def test_bad_trial_sizes_are_refused() -> None:
    with pytest.raises(ValueError, match="at least one frame"):
        Playback(n_frames=0, rate_hz=100.0)
    with pytest.raises(ValueError, match="frame rate"):
        Playback(n_frames=5, rate_hz=0.0)


def test_next_run_start_visits_each_run_and_wraps() -> None:
    m = np.zeros(20, bool)
    m[3:6] = m[10:12] = True
    assert next_run_start(m, 0) == 3
    assert next_run_start(m, 4) == 10  # inside a run: go to the next one
    assert next_run_start(m, 11) == 3  # wraps
    assert next_run_start(m, 11, wrap=False) is None
    assert next_run_start(np.zeros(5, bool), 0) is None


def test_run_at() -> None:
    m = np.array([0, 1, 1, 1, 0, 1], bool)
    assert run_at(m, 2) == (1, 4)
    assert run_at(m, 5) == (5, 6)
    assert run_at(m, 0) is None and run_at(m, 9) is None
