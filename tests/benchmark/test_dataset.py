"""Dataset builder: frame selection, per-foot ground truth at the foot origin, skipped
trials, kinematic inputs, and splits by subject."""

from __future__ import annotations

import numpy as np
import pytest

from solver.benchmark.dataset import (
    MIN_TRIAL_FRAMES,
    BenchmarkError,
    BenchmarkTrial,
    Skipped,
    Split,
    benchmark_trial,
    build_dataset,
    leave_one_subject_out,
    load_dataset,
    split_subjects,
)
from solver.results import save_processed

from .conftest import processed_trial


def test_frames_with_unmeasured_force_are_excluded_with_a_margin() -> None:
    unobserved = np.zeros(40, dtype=bool)
    unobserved[5:9] = True
    b = benchmark_trial(processed_trial(40, unobserved=unobserved), inputs="processed", margin_frames=0)
    assert isinstance(b, BenchmarkTrial)
    assert b.frames.tolist() == [k for k in range(40) if not 5 <= k < 9]
    b = benchmark_trial(processed_trial(40, unobserved=unobserved), inputs="processed")  # default margin: 3 frames
    assert b.frames.tolist() == [k for k in range(40) if not 2 <= k < 12]


def test_frames_with_a_load_on_another_body_or_no_body_are_excluded() -> None:
    trial = processed_trial(40)
    body = trial.plates[0].body.copy()
    body[10:13] = trial.body_names.index("pelvis")  # a third contact body
    body[20:22] = -1  # a loaded plate applied to nobody
    b = benchmark_trial(processed_trial(40, plate_body={"r": body}), inputs="processed", margin_frames=0)
    assert isinstance(b, BenchmarkTrial)
    excluded = sorted(set(range(40)) - set(b.frames.tolist()))
    assert excluded == [10, 11, 12, 20, 21]


def test_short_trials_and_trials_without_dynamics_are_skipped() -> None:
    unobserved = np.ones(30, dtype=bool)
    unobserved[: MIN_TRIAL_FRAMES - 1] = False
    skipped = benchmark_trial(processed_trial(30, unobserved=unobserved), inputs="processed", margin_frames=0)
    assert isinstance(skipped, Skipped) and "fewer than 12" in skipped.reason
    unobserved[MIN_TRIAL_FRAMES - 1] = False
    kept = benchmark_trial(processed_trial(30, unobserved=unobserved), inputs="processed", margin_frames=0)
    assert isinstance(kept, BenchmarkTrial) and kept.frames.size == MIN_TRIAL_FRAMES
    t = processed_trial(20)
    from dataclasses import replace

    no_dyn = replace(t, residual_force=np.full_like(t.residual_force, np.nan))
    assert isinstance(benchmark_trial(no_dyn), Skipped)


def test_ground_truth_wrench_is_moved_to_the_foot_origin() -> None:
    offset = np.array([0.1, -0.05, 0.02])
    n = 30
    left = np.zeros(n, dtype=bool)
    left[:5] = True
    t = processed_trial(n, left=left, cop_offset=tuple(offset))
    b = benchmark_trial(t, inputs="processed")
    f = t.plates[0].force
    expected = np.cross(offset, f) + [0.0, 2.0, 0.0]  # (cop - origin) x F + free moment
    np.testing.assert_allclose(b.grf[:, 0], f)
    np.testing.assert_allclose(b.grm[:, 0], expected, atol=1e-9)
    assert b.contact[:5].all() and b.contact[5:, 0].all() and not b.contact[5:, 1].any()


def test_input_is_filtered_and_kinematic_input_recovers_the_motion() -> None:
    t = processed_trial(30)
    b = benchmark_trial(t)  # kinematic inputs: IK of the (exact) model markers
    assert b.inputs == "kinematic"
    np.testing.assert_allclose(b.q_unfiltered, t.q, atol=2e-3)
    assert b.cutoff_hz == 30.0 and not np.array_equal(b.q, b.q_unfiltered)
    with pytest.raises(BenchmarkError, match="inputs"):
        benchmark_trial(t, inputs="video")


def test_resampled_to_100_hz() -> None:
    """The same samples at 50 Hz put on the 100 Hz grid by linear interpolation: the even
    frames are the samples themselves and the odd ones the midpoints of their neighbours
    (coordinates, ground truth and torques), and the booleans come from a neighbour."""
    from dataclasses import replace

    t = processed_trial(40)
    slow = replace(t, time=t.time * 2.0)  # the same samples at 50 Hz
    b = benchmark_trial(slow, inputs="processed")
    assert isinstance(b, BenchmarkTrial)
    assert b.n_frames == 79 and np.allclose(np.diff(b.time), 0.01)
    samples_100 = benchmark_trial(t, inputs="processed")  # the same samples, not resampled
    assert isinstance(samples_100, BenchmarkTrial)
    for name in ("q_unfiltered", "grf", "grm", "tau", "com_acc"):
        ours, samples = getattr(b, name), getattr(samples_100, name)
        np.testing.assert_allclose(ours[::2], samples, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(ours[1::2], 0.5 * (samples[:-1] + samples[1:]), rtol=0, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(b.contact[::2], samples_100.contact)


def test_load_dataset_from_output_folders(tmp_path) -> None:
    for subject in ("a", "b"):
        t = processed_trial(20, subject=subject)
        save_processed(tmp_path / subject / t.trial / "trial.npz", t)
    ds = load_dataset([tmp_path / "a", tmp_path / "b"], inputs="processed")
    assert ds.subjects == ["a", "b"] and ds.n_frames == 40
    t = processed_trial(20, subject="a")
    save_processed(tmp_path / "a_again" / t.trial / "trial.npz", t)
    with pytest.raises(BenchmarkError, match="also in"):  # one subject processed into two folders
        load_dataset([tmp_path / "a", tmp_path / "a_again"], inputs="processed")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BenchmarkError, match="no processed trial"):
        load_dataset([tmp_path / "empty"])


def test_seeded_split_puts_no_subject_in_two_splits() -> None:
    names = [f"s{i:02d}" for i in range(20)]
    s = split_subjects(names, seed=3)
    assert len(s.test) == 4 and len(s.dev) == 2 and len(s.train) == 14
    assert sorted(s.train + s.dev + s.test) == names
    assert split_subjects(names, seed=3) == s and split_subjects(names, seed=4) != s
    three = split_subjects(["a", "b", "c"])
    assert (len(three.train), len(three.dev), len(three.test)) == (1, 1, 1)
    two = split_subjects(["a", "b"])
    assert (len(two.train), len(two.dev), len(two.test)) == (1, 0, 1)
    with pytest.raises(BenchmarkError, match="two splits"):
        Split(("a",), (), ("a",))


def test_leave_one_subject_out_tests_every_subject_once() -> None:
    folds = leave_one_subject_out(["c", "a", "b", "a"])
    assert [f.test for f in folds] == [("a",), ("b",), ("c",)]
    for f in folds:
        assert f.test[0] not in f.train and len(f.train) == 2


def test_dataset_of_subjects() -> None:
    ds = build_dataset([processed_trial(20, subject="a"), processed_trial(20, subject="b")], inputs="processed")
    assert ds.of_subjects(["b"]).subjects == ["b"]


def test_kinematic_input_starts_from_the_best_observed_frame() -> None:
    """A subject walking into the capture volume: the first 15 frames see half of the
    markers, and in a pose turned half a turn about the vertical (labels swapped, as a
    poorly reconstructed entry can look). The inverse kinematics starts from the frame that
    sees the most markers and runs outwards, so those frames do not carry a wrong pose into
    the well-observed ones (started from the first frame instead, it ends metres away)."""
    from dataclasses import replace

    from solver.benchmark.dataset import kinematic_coordinates

    t = processed_trial(40)
    half = t.observed.shape[1] // 2
    observed = np.array(t.observed)
    observed[:15] = np.nan
    entry = t.observed[:15, :half] - t.observed[:15, :half].mean(axis=1, keepdims=True)
    entry[..., [0, 2]] *= -1.0
    observed[:15, :half] = entry + t.observed[:15, :half].mean(axis=1, keepdims=True)
    q = kinematic_coordinates(replace(t, observed=observed))
    np.testing.assert_allclose(q[15:], t.q[15:], atol=2e-3)


def test_names_tell_two_labs_subjects_of_one_name_apart(tmp_path) -> None:
    """``names`` (a dataset tree's relative paths, ``addb benchmark OUT``) name the subjects in
    place of their recorded names: two labs' ``s01`` are two subjects, not a duplicate."""
    for lab in ("labA", "labB"):
        t = processed_trial(20, subject="s01")
        save_processed(tmp_path / lab / "s01" / t.trial / "trial.npz", t)
    folders = [tmp_path / "labA" / "s01", tmp_path / "labB" / "s01"]
    with pytest.raises(BenchmarkError, match="also in"):  # under their recorded names: one subject twice
        load_dataset(folders, inputs="processed")
    ds = load_dataset(folders, inputs="processed", names=["labA/s01", "labB/s01"])
    assert ds.subjects == ["labA/s01", "labB/s01"] and ds.n_frames == 40
    assert {t.subject for t in ds.trials} == {"labA/s01", "labB/s01"}


def test_one_folder_given_twice_under_two_names_is_refused(tmp_path) -> None:
    t = processed_trial(20, subject="s01")
    save_processed(tmp_path / "labA" / "s01" / t.trial / "trial.npz", t)
    folder = tmp_path / "labA" / "s01"
    with pytest.raises(BenchmarkError, match="given twice") as err:
        load_dataset([folder, folder], inputs="processed", names=["labA/s01", None])
    assert err.value.path == str(folder)
    # the same folder through another path (a symbolic link, a path with "..") is the same folder
    (tmp_path / "link").symlink_to(folder, target_is_directory=True)
    with pytest.raises(BenchmarkError, match="given twice"):
        load_dataset([tmp_path / "labA" / ".." / "labA" / "s01", tmp_path / "link"], inputs="processed")
    assert load_dataset([folder], inputs="processed", names=["labA/s01"]).subjects == ["labA/s01"]
