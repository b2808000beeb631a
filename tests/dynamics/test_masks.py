"""The unmeasured-force mask's rules (solver.masks): the one runs helper, the one resampling
rule (overlap: conservative, the identity on one grid; on the real frame times of the walk's
forces and the Camargo circuit's 200 Hz markers), the one join rule, and the dynamics stage
refusing a mask made on other frames."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from solver.dynamics.stage import DynamicsOptions, trial_frames
from solver.errors import DynamicsError
from solver.io.subject import load_subject, load_trial
from solver.masks import join_masks, resample_mask, true_runs
from tests.conftest import SHARED_DATA

SUBJECTS = SHARED_DATA / "subjects"
masks = st.lists(st.booleans(), max_size=300).map(lambda xs: np.array(xs, dtype=bool))


def _walk_times() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(marker times, force times, processed frame times) of the walk."""
    subject = load_subject(SUBJECTS / "rajagopal2016_walk")
    trial = load_trial(subject.trial("walk"))
    return trial.markers.time, trial.forces.time, trial_frames(trial.markers, trial.forces, DynamicsOptions().rate_hz, "walk")


def _camargo_times() -> tuple[np.ndarray, np.ndarray]:
    """(200 Hz marker times, 100 Hz processed frame times) of the Camargo circuit's files."""
    from solver.io.mot import read_forces
    from solver.io.trc import read_trc

    folder = SHARED_DATA / "trials" / "camargo2021_levelground"
    markers = read_trc(folder / "markers.trc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # moments about plate origins (converted, warned)
        forces = read_forces(folder / "grf.mot")
    return markers.time, trial_frames(markers, forces, DynamicsOptions().rate_hz, "levelground")


# ----------------------------------------------------------------------------- runs


@given(masks)
def test_true_runs_are_the_masks_runs(mask: np.ndarray) -> None:
    runs = true_runs(mask)
    rebuilt = np.zeros(mask.size, dtype=bool)
    for a, b in runs:
        rebuilt[a:b] = True
    np.testing.assert_array_equal(rebuilt, mask)
    for (s0, e0), (s1, e1) in itertools.pairwise(runs):  # sorted, disjoint, non-adjacent
        assert s0 < e0 < s1 < e1
    with pytest.raises(ValueError, match="shape"):
        true_runs(np.zeros((3, 2), dtype=bool))


# ----------------------------------------------------------------------------- resampling


@given(
    masks.filter(lambda m: m.size >= 2),
    st.sampled_from([50.0, 100.0, 120.0, 200.0, 250.0, 2000.0]),
    st.sampled_from([50.0, 100.0, 120.0, 200.0, 250.0, 2000.0]),
    st.floats(-0.02, 0.02),
)
@settings(max_examples=150, deadline=None)
def test_resampling_is_conservative_and_no_wider(mask: np.ndarray, f_in: float, f_out: float, shift: float) -> None:
    """Every flagged instant stays flagged; an unflagged target frame overlaps no flagged
    source frame (by more than a touch): exactly the overlap rule, on grids of any offset."""
    src = 0.3 + np.arange(mask.size) / f_in
    n_out = int(np.floor((mask.size / f_in) * f_out))
    assume(n_out >= 2)  # a grid's spacing needs two frames
    dst = 0.3 + shift + np.arange(n_out) / f_out
    out = resample_mask(mask, src, dst)
    assert out.dtype == np.bool_ and out.shape == dst.shape
    touch = 1e-3 / max(f_in, f_out)  # a thousandth of the finer frame: intervals that only touch
    for j in range(n_out):
        lo, hi = dst[j] - 0.5 / f_out, dst[j] + 0.5 / f_out
        most = max((min(hi, src[i] + 0.5 / f_in) - max(lo, src[i] - 0.5 / f_in) for i in np.flatnonzero(mask)), default=-1.0)
        if most > 1.01 * touch:
            assert out[j], (j, most)
        if most < 0.99 * touch:
            assert not out[j], (j, most)


@given(masks)
def test_resampling_on_one_grid_is_the_identity(mask: np.ndarray) -> None:
    t = 0.23 + np.arange(mask.size) / 100.0
    np.testing.assert_array_equal(resample_mask(mask, t, t), mask)
    # the same grid computed another way (float noise) too
    np.testing.assert_array_equal(resample_mask(mask, t, 0.23 + np.arange(mask.size) * 0.01), mask)


def test_resampling_example_100_to_200_hz_and_back() -> None:
    t100, t200 = np.arange(5) / 100, np.arange(10) / 200
    # 100 Hz frames 1..2 cover [5, 25) ms; 200 Hz frame j covers [(j - .5), (j + .5)) * 5 ms,
    # so frames 1..5 overlap it (frame 5, [22.5, 27.5) ms, by 2.5 ms)
    np.testing.assert_array_equal(resample_mask(np.array([0, 1, 1, 0, 0], bool), t100, t200), [0, 1, 1, 1, 1, 1, 0, 0, 0, 0])
    # and back: 200 Hz frames 2..4 ([7.5, 22.5) ms) -> 100 Hz frames 1..2
    np.testing.assert_array_equal(resample_mask(np.array([0, 0, 1, 1, 1, 0, 0, 0], bool), t200[:8], t100[:4]), [0, 1, 1, 0])


def test_walk_processed_frames_to_force_frames_and_back_is_a_superset() -> None:
    """Processed frames 100-120 of the walk (100 Hz, [0.995, 1.205) s) on the plates' 2000 Hz
    frames are 1990-2410 (k/2000 s overlapping that span); back on the processed frames they
    are 99-121: the flagged span plus one frame at each end, never less."""
    _, force_time, time = _walk_times()
    assert time[0] == 0.0 and force_time[0] == 0.0 and np.isclose(np.median(np.diff(force_time)), 1 / 2000)
    flags = np.zeros(time.size, dtype=bool)
    flags[100:121] = True
    on_forces = resample_mask(flags, time, force_time)
    assert true_runs(on_forces) == [(1990, 2411)]
    back = resample_mask(on_forces, force_time, time)
    assert true_runs(back) == [(99, 122)]
    assert (back | flags).tolist() == back.tolist()


def test_camargo_marker_frames_to_processed_frames_and_back_is_a_superset() -> None:
    """The Camargo circuit: markers at 200 Hz from 5 ms, processed frames at 100 Hz from 5 ms.
    Marker frames 1000-1099 ([5.0025, 5.5025) s) -> processed frames 500-550 (frame 550,
    [5.500, 5.510) s, overlaps by 2.5 ms; nearest-frame sampling, the old rule, gave 500-549
    and let that instant into the fit); marker frames 2001-2050 -> processed 1000-1025; back
    on the marker frames: 999-1101 and 1999-2051."""
    marker_time, time = _camargo_times()
    assert marker_time.size == 3067 and time.size == 1534 and time[0] == marker_time[0] == 0.005
    flags = np.zeros(marker_time.size, dtype=bool)
    flags[1000:1100] = flags[2001:2051] = True
    on_frames = resample_mask(flags, marker_time, time)
    assert true_runs(on_frames) == [(500, 551), (1000, 1026)]
    back = resample_mask(on_frames, time, marker_time)
    assert true_runs(back) == [(999, 1102), (1999, 2052)]
    assert not (flags & ~back).any()


# ----------------------------------------------------------------------------- joining


def test_join_is_the_union_of_masks_on_the_same_frames() -> None:
    a = {"walk": np.eye(1, 10, 0, dtype=bool)[0], "run": np.zeros(4, bool)}
    b = {"walk": np.eye(1, 10, 7, dtype=bool)[0], "stairs": np.ones(3, bool)}
    out = join_masks(a, b)
    assert out is not None and sorted(out) == ["run", "stairs", "walk"]
    assert np.flatnonzero(out["walk"]).tolist() == [0, 7]
    assert not a["walk"][7]  # the inputs are not changed
    assert join_masks(None, {}) is None and join_masks(a, None) == a and join_masks(None, b)["stairs"].all()


def test_join_refuses_masks_of_one_trial_on_other_frames(tmp_path: Path) -> None:
    with pytest.raises(DynamicsError, match=r"differ in length \(238 and 476 frames\)") as info:
        join_masks({"walk": np.zeros(238, bool)}, {"walk": np.zeros(476, bool)}, path=tmp_path / "addb_extensions.json")
    assert "trial walk" in str(info.value) and "addb_extensions.json" in str(info.value)


@pytest.mark.slow
def test_the_dynamics_stage_refuses_a_mask_made_on_other_frames(tmp_path: Path) -> None:
    """A mask at the walk's marker frames of another recording (one frame short) is not
    quietly padded: the stage names the trial and both frame counts."""
    from solver.pipeline import process_subject

    _, _, time = _walk_times()
    with pytest.raises(DynamicsError, match=rf"mask has {time.size - 1} frames but the trial has {time.size} processed") as info:
        process_subject(SUBJECTS / "rajagopal2016_walk", tmp_path / "out", unmeasured_force={"walk": np.zeros(time.size - 1, bool)})
    assert "trial walk" in str(info.value)
    assert not (tmp_path / "out").exists()
