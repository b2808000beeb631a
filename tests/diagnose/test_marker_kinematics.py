"""The diagnosis' marker-only motion (:func:`solver.diagnose.data.marker_kinematics`)
starts its inverse kinematics at the best-observed frame.

On opensim-core's C3D walking5, started from the first frame (the subject entering the
capture volume, 3 of 40 markers seen), it carried a wrong pose into the whole trial:
residual forces of 10^6 N on frames that see every marker, and a plate offset estimated
at 18 kN (2026-11-22)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.diagnose.data import marker_kinematics
from solver.model.osim import read_osim
from tests.benchmark.conftest import processed_trial


def test_marker_only_motion_starts_from_the_best_observed_frame() -> None:
    # the first 15 frames see half of the markers, in a pose turned half a turn about the
    # vertical (as a poorly reconstructed entry into the volume can look)
    t = processed_trial(40)
    half = t.observed.shape[1] // 2
    observed = np.array(t.observed)
    observed[:15] = np.nan
    centre = t.observed[:15, :half].mean(axis=1, keepdims=True)
    entry = t.observed[:15, :half] - centre
    entry[..., [0, 2]] *= -1.0
    observed[:15, :half] = entry + centre
    ik = marker_kinematics(replace(t, observed=observed), read_osim(t.model_path))
    # the 30 Hz low-pass spreads the entry's jump over ten frames (started from the first
    # frame instead, a coordinate winds up by 150 rad over the trial)
    np.testing.assert_allclose(ik.q[25:], t.q[25:], atol=3e-3)
    assert not ik.unobserved.any()


def test_the_marker_only_motion_takes_the_generic_mass_distribution_back() -> None:
    # the dynamics stage multiplies each body's mass and inertia by a fitted factor (then all
    # by one, to the fitted total); undoing that gives the scaled model at that total exactly
    from solver.diagnose.data import generic_mass_distribution
    from solver.dynamics.stage import _with_mass
    from solver.model.scaling import scale_model
    from tests.conftest import SHARED_DATA

    generic = read_osim(SHARED_DATA / "models" / "Rajagopal2016.osim")
    rng = np.random.default_rng(3)
    scales = {b.name: rng.uniform(0.85, 1.2, 3) for b in generic.bodies}
    scaled = scale_model(generic, scales, mass=72.0)
    factors = {b.name: float(rng.uniform(0.7, 1.3)) for b in generic.bodies}
    fitted = _with_mass(scaled, 70.5, factors)
    assert abs(fitted.bodies[1].mass / scaled.bodies[1].mass - 70.5 / 72.0) > 0.01  # the factors moved mass
    back = generic_mass_distribution(fitted, generic)
    expected = scale_model(generic, scales, mass=70.5)
    for got, want in zip(back.bodies, expected.bodies):
        assert got.name == want.name
        np.testing.assert_allclose(got.mass, want.mass, rtol=1e-12)
        np.testing.assert_allclose(np.array(got.inertia), np.array(want.inertia), rtol=1e-10, atol=1e-15)
        assert got.com == want.com
    assert back.joints == fitted.joints and back.markers == fitted.markers
