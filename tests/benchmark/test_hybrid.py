"""The hybrid method (analytical total force, network contact split): its training targets,
the choice of its force filter, the invariance its mirrored training copies rely on, and how
a prediction is assembled."""

from __future__ import annotations

import dataclasses

import numpy as np

from solver.benchmark.analytical import analytical_baseline, kinematic_contact, torques_from_feet
from solver.benchmark.dataset import benchmark_input, benchmark_trial, build_dataset, skeleton_for
from solver.benchmark.hybrid import (
    CUTOFFS_HZ,
    FEATURES_PER_FOOT,
    contact_features,
    select_cutoff,
    split_targets,
    toe_body,
    total_force,
    train_contact_split,
)
from solver.benchmark.mlp import MlpOptions, torch_available
from solver.benchmark.run import run_benchmark
from tests.conftest import TORCH_REASON, needs_tool

from .conftest import MODEL, motion, processed_trial

needs_torch = needs_tool("torch", torch_available(), TORCH_REASON)


def test_targets_are_the_measured_vertical_shares_or_airborne() -> None:
    n = 40
    right = np.ones(n, dtype=bool)
    left = np.zeros(n, dtype=bool)
    left[10:20] = True
    right[25:32] = False  # flight: no plate loaded
    trial = benchmark_trial(processed_trial(n, right=right, left=left), inputs="processed", margin_frames=0)
    frames = np.arange(n)
    y = split_targets(trial, frames)
    np.testing.assert_allclose(y[:10, :3], np.tile([1.0, 0.0, 0.0], (10, 1)), atol=1e-12)
    np.testing.assert_allclose(y[10:20, :3], np.tile([0.5, 0.5, 0.0], (10, 1)), atol=1e-12)
    np.testing.assert_allclose(y[25:32, :3], np.tile([0.0, 0.0, 1.0], (7, 1)), atol=1e-12)
    np.testing.assert_allclose(y[:, :3].sum(axis=1), 1.0)
    # the pelvis does not accelerate vertically: about one body weight on every frame, the
    # flight frames included (there the analytical force, not the zero measured one, counts)
    np.testing.assert_allclose(y[:, 3], 1.0, atol=0.05)
    analytical = np.abs(total_force(trial)[0][:, 1]) / (trial.mass_kg * 9.80665)
    np.testing.assert_allclose(y[25:32, 3], analytical[25:32])


def test_the_total_force_filter_is_chosen_against_the_measured_force() -> None:
    """On the clean synthetic motion no extra filter is chosen (30 Hz: every lower cut-off
    flattens its accelerations). With a 20 Hz pelvis vibration of 1 mm (16 m/s² of
    acceleration) in the input, which the plates, computed from the clean motion, do not
    see, the chosen cut-off removes it, and the input as it is is far worse."""
    q = motion(120)
    clean = benchmark_trial(processed_trial(q=q), inputs="processed")
    assert select_cutoff([clean])[0] == 30.0
    noisy_q = q.copy()
    sk = skeleton_for(str(MODEL))
    noisy_q[:, sk.coordinate_index("pelvis_ty")] += 0.001 * np.sin(2 * np.pi * 20.0 * np.arange(120) / 100.0)
    noisy = dataclasses.replace(clean, q_unfiltered=noisy_q, q=benchmark_input(noisy_q, cutoff_hz=clean.cutoff_hz))
    cutoff, errors = select_cutoff([noisy])
    assert cutoff <= 12.0 and set(errors) == set(CUTOFFS_HZ)
    assert errors[30.0] > 10 * errors[cutoff]
    np.testing.assert_array_equal(total_force(noisy, 30.0)[1], noisy.q)  # 30 Hz: q̃ as it is
    assert select_cutoff([noisy], [30.0])[0] == 30.0


def test_contact_features_do_not_depend_on_the_lab_heading() -> None:
    """The mirrored training copies and the pooling of labs rely on the features being
    the same when the lab's horizontal axes point elsewhere: turn the whole motion by 70°
    about the vertical and compare."""
    sk = skeleton_for(str(MODEL))
    q = motion(60, accel=(0.4, 0.1, -0.3), swing=0.5)
    theta = np.deg2rad(70.0)
    turned = q.copy()
    i_rot, i_x, i_z = (sk.coordinate_index(c) for c in ("pelvis_rotation", "pelvis_tx", "pelvis_tz"))
    turned[:, i_rot] += theta
    c, s = np.cos(theta), np.sin(theta)
    turned[:, i_x] = c * q[:, i_x] + s * q[:, i_z]
    turned[:, i_z] = -s * q[:, i_x] + c * q[:, i_z]
    r_y = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    _, pos = sk.body_poses(q)
    _, pos_turned = sk.body_poses(turned)
    np.testing.assert_allclose(pos_turned, pos @ r_y.T, atol=1e-9)  # the turn is a rotation about +y
    trial = benchmark_trial(processed_trial(q=q), inputs="processed")
    f = contact_features(trial, q)
    assert f.shape == (60, FEATURES_PER_FOOT, 2)
    np.testing.assert_allclose(contact_features(trial, turned), f, atol=1e-9)
    np.testing.assert_array_equal(f[:, -1], kinematic_contact(trial, q))
    assert (f[:, :2] >= 0).all() and (f[:, :2].min(axis=0) == 0).all()  # heights above their lowest point
    assert toe_body(trial, "calcn_r") == "toes_r" and toe_body(trial, "toes_r") == "toes_r"


@needs_torch
def test_prediction_is_the_analytical_force_split_by_the_network() -> None:
    trials = build_dataset(
        [
            processed_trial(40, subject="a"),
            processed_trial(40, subject="b", q=motion(40, accel=(0.2, 0.0, 0.1), swing=0.2)),
        ],
        inputs="processed",
    ).trials
    model = train_contact_split(trials[:1], trials[1:], options=MlpOptions(epochs=2, hidden=8))
    assert len(model.history) == 2 and np.isfinite(model.history[-1]["dev_loss"])
    assert model.n_train == 2 * len(trials[0].frames)  # every frame also mirrored
    test = trials[1]
    pred = model.predict(test)
    shares = model.shares(test)
    np.testing.assert_allclose(shares.sum(axis=1), 1.0, atol=1e-6)
    total, q, qd, qdd = total_force(test, model.cutoff_hz)
    assert model.cutoff_hz in CUTOFFS_HZ and set(model.cutoff_errors) == set(CUTOFFS_HZ)
    gate = kinematic_contact(test, test.q)
    for k in range(2):
        np.testing.assert_allclose(pred.grf[:, k], (shares[:, k] * gate[:, k])[:, None] * total, atol=1e-9)
    np.testing.assert_allclose(pred.grm, 0.0)
    # the CoM acceleration is the analytical baseline's on the same (re-filtered) coordinates
    np.testing.assert_allclose(pred.com_acc, analytical_baseline(test, q=q).com_acc, atol=1e-12)
    np.testing.assert_allclose(pred.tau, torques_from_feet(test, q, qd, qdd, pred.grf, pred.grm), atol=1e-9)


@needs_torch
def test_hybrid_row_is_scored_on_the_same_frames_by_subject() -> None:
    dataset = build_dataset(
        [processed_trial(40, subject="a"), processed_trial(40, subject="b", q=motion(40, swing=0.2))], inputs="processed"
    )
    result = run_benchmark(dataset, methods=("analytical", "hybrid"), mlp_options=MlpOptions(epochs=1, hidden=8))
    assert [r.method for r in result.rows] == ["analytical (measured contact)", "hybrid (analytical force, MLP contact split)"]
    assert result.rows[0].n_frames == result.rows[1].n_frames == dataset.n_frames
    for fold in result.rows[1].notes["folds"]:
        assert not set(fold["test"]) & set(fold["train"])
