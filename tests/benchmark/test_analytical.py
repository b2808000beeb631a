"""The analytical baseline on synthetic trials whose motion and forces are known."""

from __future__ import annotations

import numpy as np
import pytest

from solver.benchmark.analytical import analytical_baseline, kinematic_contact
from solver.benchmark.dataset import GRAVITY, benchmark_trial, skeleton_for
from solver.benchmark.evaluate import score_trial
from solver.benchmark.metrics import summarize

from .conftest import motion, processed_trial


def test_grf_is_mass_times_com_acceleration_minus_gravity_on_a_translating_body() -> None:
    """Pelvis accelerating at (0.5, 0, -0.2) m/s², no joint motion: a_com is that exactly
    (a quadratic path: its second differences are exact), and the force is
    m (a - g) for that known a, not for the baseline's own estimate of it."""
    accel = np.array([0.5, 0.0, -0.2])
    q = motion(40, accel=tuple(accel), swing=0.0)
    trial = benchmark_trial(processed_trial(q=q), inputs="processed", cutoff_hz=60.0)
    pred = analytical_baseline(trial)
    np.testing.assert_allclose(pred.com_acc, np.tile(accel, (40, 1)), atol=1e-6)
    expected = np.tile(trial.mass_kg * (accel - GRAVITY), (40, 1))
    np.testing.assert_allclose(pred.grf[:, 0], expected, atol=1e-6)  # single support: all on the right foot
    np.testing.assert_allclose(pred.grf[:, 1], 0.0)
    np.testing.assert_allclose(pred.grm, 0.0)


def test_grf_equals_m_times_a_com_minus_g_with_joint_motion() -> None:
    """With joints moving, the total force equals m (a_com - g) for the centre of mass
    differentiated twice (to the central-difference truncation error)."""
    trial = benchmark_trial(processed_trial(120), inputs="processed", cutoff_hz=60.0)
    pred = analytical_baseline(trial)
    k = trial.frames[2:-2]
    total = pred.grf.sum(axis=1)
    expected = trial.mass_kg * (trial.com_acc - GRAVITY)  # synthetic truth: CoM by central differences
    assert np.abs(total[k] - expected[k]).max() < 0.05 * trial.mass_kg  # < 0.05 N/kg
    assert summarize(score_trial(trial, pred))["grf"] < 0.05


def test_double_support_splits_the_force_evenly() -> None:
    n = 30
    right = np.ones(n, dtype=bool)
    left = np.zeros(n, dtype=bool)
    left[10:20] = True
    trial = benchmark_trial(processed_trial(n, right=right, left=left), inputs="processed")
    pred = analytical_baseline(trial)
    np.testing.assert_allclose(pred.grf[10:20, 0], pred.grf[10:20, 1])
    np.testing.assert_allclose(pred.grf[:10, 1], 0.0)
    np.testing.assert_allclose(pred.grf.sum(axis=1), trial.mass_kg * (pred.com_acc - GRAVITY), atol=1e-9)


def test_no_force_in_flight() -> None:
    n = 30
    right = np.ones(n, dtype=bool)
    right[12:18] = False
    trial = benchmark_trial(processed_trial(n, right=right), inputs="processed")
    pred = analytical_baseline(trial)
    np.testing.assert_allclose(pred.grf[12:18], 0.0)


def test_torques_match_inverse_dynamics_with_the_true_force_in_single_support() -> None:
    """The synthetic truth applies the same total force at a CoP offset from the foot origin
    with a free moment; the baseline applies it at the origin with no moment: torques of
    the joints above the foot still agree closely, and the GRM error is the true moment."""
    trial = benchmark_trial(processed_trial(60), inputs="processed", cutoff_hz=60.0)
    pred = analytical_baseline(trial)
    errors = summarize(score_trial(trial, pred))
    true_moment = np.linalg.norm(trial.grm[trial.frames], axis=-1).mean(axis=1) / trial.mass_kg
    assert errors["grm"] == pytest.approx(true_moment.mean(), rel=1e-9)
    assert errors["torque"] < 0.2  # N·m/kg: the moment arm of the CoP offset, at the ankle and above


def test_kinematic_contact_uses_foot_height() -> None:
    trial = benchmark_trial(processed_trial(30), inputs="processed")
    on = kinematic_contact(trial, trial.q)
    assert on.shape == (30, 2) and on.all()  # both feet on the floor in the neutral pose
    pred = analytical_baseline(trial, contact="kinematic")
    np.testing.assert_allclose(pred.grf[:, 0], pred.grf[:, 1])
    with pytest.raises(ValueError, match="contact"):
        analytical_baseline(trial, contact="guess")


def test_kinematic_contact_follows_the_step_the_foot_stands_on() -> None:
    """Standing still, then (from frame 40) standing 0.3 m higher, as on a stair: the floor
    of each foot is its own lowest point nearby, so both feet stay in contact on the upper
    step, and a foot lifted 0.2 m above it is not."""
    trial = benchmark_trial(processed_trial(q=motion(100, accel=(0.0, 0.0, 0.0), swing=0.0)), inputs="processed", cutoff_hz=60.0)
    sk = skeleton_for(trial.model_path)
    q = np.array(trial.q)
    q[40:, sk.coordinate_index("pelvis_ty")] += 0.3
    on = kinematic_contact(trial, q)
    assert on[:15].all() and on[65:].all()  # a quarter window away from the step
    lifted = q.copy()
    lifted[70:80, sk.coordinate_index("pelvis_ty")] += 0.2  # both feet 0.2 m up
    assert not kinematic_contact(trial, lifted)[70:80].any()
