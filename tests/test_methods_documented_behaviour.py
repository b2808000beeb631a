"""What README.md's method sections state and no other test checks: the processed frames
("The unmeasured-force mask: one path"), the OpenSim-compatible inverse dynamics ("How the
model conversion works"), the scale groups, their ±35 % band and the exact (affine) marker
Jacobian ("How scaling and inverse kinematics work"), the 30 Hz filter of plates and
coordinates, the coupled and bounded coordinates of the fit and which frames count as
measured ("How the dynamics work"), and the spline derivatives, the kept body scales and
``_id.sto`` against ``trial.npz`` ("Where the layout and methods depart from the design
sketch").

On the real walk (rajagopal2016_walk), processed once per module (a few seconds), plus one
kinematics-and-unfitted-dynamics run of the walk with its force file cut short, and the
OpenSim 4.6 oracle; every run writes below ``tmp_path``. Reference values are computed here
from the raw files with scipy, by hand, or taken from ../shared/oracles.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from solver.constants import GRAVITY
from solver.dynamics.stage import DynamicsOptions, TrialDynamics, run_dynamics
from solver.pipeline import ProcessOptions, ProcessResult, process_subject
from solver.results import ProcessedTrial, load_processed
from tests.conftest import SHARED_DATA, writable_copy
from tests.opensim_tables import read_table_by_hand, trc_times_by_hand

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
ORACLES = SHARED_DATA.parent / "oracles"
RATE_HZ = 100.0  # README: "common 100 Hz frames"
CUTOFF_HZ = 30.0  # README: "low-passed at 30 Hz (3rd order, zero phase)"
ORDER = 3
#: The coordinates whose generalized force the walker knee's velocity term cannot reach:
#: neither ancestors nor descendants of a knee (the trunk and the arms).
FAR_FROM_THE_KNEES = ("lumbar", "arm_", "elbow_", "pro_sup", "wrist_")


def _grid(start: float, stop: float) -> np.ndarray:
    """100 Hz frames from ``start`` up to ``stop`` (inclusive when on the grid)."""
    return start + np.arange(int(np.floor((stop - start) * RATE_HZ + 1e-9)) + 1) / RATE_HZ


def _lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float = CUTOFF_HZ) -> np.ndarray:
    """scipy's zero-phase Butterworth (forward and backward) of the README's order."""
    from scipy.signal import butter, sosfiltfilt

    return sosfiltfilt(butter(ORDER, cutoff_hz / (0.5 * rate_hz), output="sos"), x, axis=0)


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> tuple[ProcessResult, Path, ProcessedTrial, dict]:
    """The walk processed with the defaults: (what process_subject returned, OUT, the walk's
    trial.npz, its results.json)."""
    out = tmp_path_factory.mktemp("walk") / "out"
    res = process_subject(WALK, out)
    return res, out, load_processed(out, "walk"), json.loads((out / "walk" / "results.json").read_text())


@pytest.fixture(scope="module")
def unfitted(walk: tuple[ProcessResult, Path, ProcessedTrial, dict]) -> TrialDynamics:
    """The walk's dynamics stage without the dynamics fit (``fit_motion=False``): its
    coordinates are the ones the fit starts from (the filtered inverse kinematics, root
    translations shifted onto the centre-of-mass path)."""
    res = walk[0]
    sk = res.kinematics
    dyn = run_dynamics(
        sk.kinematics,
        [(t.name, t.markers, t.forces) for t in sk.trials],
        mass_kg=sk.subject.mass_kg,
        foot_bodies=sk.subject.foot_body_names,
        height_m=sk.subject.height_m,
        options=DynamicsOptions(fit_motion=False),
    )
    assert dyn is not None
    return dyn.trial("walk")


# ------------------------------------------------------------------ the processed frames


def test_processed_frames_are_100_hz_over_the_span_markers_and_plates_share(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict], tmp_path: Path
) -> None:
    """README, "The unmeasured-force mask: one path": the processed frames, those of
    ``OUT/<trial>/trial.npz``, are "100 Hz over the span the markers and the plates share".
    On the walk the markers (0-2.37 s) end before the plates (0-2.3885 s); on a copy whose
    force file is cut to 0.3025-2.0 s the frames start with the plates, off the marker grid,
    and end with them."""
    _, _, trial, results = walk
    markers = trc_times_by_hand(WALK / "trials" / "walk" / "markers.trc")
    _, _, grf = read_table_by_hand(WALK / "trials" / "walk" / "grf.mot")
    expected = _grid(max(markers[0], grf[0, 0]), min(markers[-1], grf[-1, 0]))
    np.testing.assert_allclose(trial.time, expected, rtol=0, atol=1e-9)
    assert results["n_frames"] == expected.size and results["rate_hz"] == RATE_HZ

    subject = writable_copy(WALK, tmp_path / "walk")
    path = subject / "trials" / "walk" / "grf.mot"
    lines = path.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    body = [line for line in lines[end + 2 :] if line.strip() and 0.3025 - 1e-9 <= float(line.split()[0]) <= 2.0 + 1e-9]
    header = [f"nRows={len(body)}" if line.startswith("nRows=") else line for line in lines[: end + 2]]
    path.write_text("\n".join(header + body) + "\n")
    process_subject(subject, tmp_path / "out", options=ProcessOptions(dynamics=DynamicsOptions(fit_motion=False), trials=("walk",)))
    cut = load_processed(tmp_path / "out", "walk")
    np.testing.assert_allclose(cut.time, _grid(0.3025, 2.0), rtol=0, atol=1e-9)
    assert cut.time.size == 170 and cut.unobserved.shape == (170,)  # 0.3025 + k/100 s up to 1.9925 s


# ------------------------------------------------------------------ filtering


def test_plate_forces_are_lowpassed_at_30_hz_third_order_zero_phase_then_put_on_the_frames(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README, "How the dynamics work": "coordinates and plate wrenches low-passed at 30 Hz
    (3rd order, zero phase)" on "common 100 Hz frames". Each plate's force in trial.npz is
    the raw grf.mot force (2000 Hz) filtered so by scipy, then interpolated onto the frames;
    a filter at 25 or 35 Hz, or none, is told apart by more than 0.1 N."""
    trial = walk[2]
    _, names, raw = read_table_by_hand(WALK / "trials" / "walk" / "grf.mot")
    time = raw[:, 0]
    rate = 1.0 / float(np.median(np.diff(time)))
    assert rate == pytest.approx(2000.0)
    assert sorted(p.name for p in trial.plates) == ["l", "r"]
    for plate in trial.plates:
        force = raw[:, [names.index(f"ground_force_{plate.name}_v{a}") for a in "xyz"]]

        def on_frames(x: np.ndarray) -> np.ndarray:
            return np.column_stack([np.interp(trial.time, time, x[:, k]) for k in range(3)])

        assert np.abs(on_frames(_lowpass(force, rate)) - plate.force).max() < 1e-6, plate.name
        for other in (on_frames(_lowpass(force, rate, 25.0)), on_frames(_lowpass(force, rate, 35.0)), on_frames(force)):
            assert np.abs(other - plate.force).max() > 0.1, plate.name


def test_coordinates_enter_the_fit_lowpassed_at_30_hz_third_order_zero_phase(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict], unfitted: TrialDynamics
) -> None:
    """README, "How the dynamics work": the coordinates are "low-passed at 30 Hz (3rd order,
    zero phase)" before the fit. Without the fit, every coordinate but the root translations
    (shifted onto the fitted centre-of-mass path) is the inverse kinematics filtered so by
    scipy (the marker frames are the processed frames here); compared away from the ends,
    where the filters pad the signal differently. 25 Hz, 35 Hz or no filter differ."""
    res = walk[0]
    kin = res.kinematics.kinematics.trial("walk")
    np.testing.assert_allclose(kin.time, unfitted.time, rtol=0, atol=1e-9)
    from solver.model.skeleton import Skeleton

    sk = Skeleton(res.kinematics.kinematics.model)
    shifted = {c for c in sk.root_transform_axes() if sk.motion_types[c] == "translational"}
    cols = [c for c in range(sk.n) if c not in shifted]
    inner = slice(20, -20)
    start = unfitted.q[inner][:, cols]
    assert np.abs(_lowpass(kin.q, RATE_HZ)[inner][:, cols] - start).max() < 1e-8
    for other in (_lowpass(kin.q, RATE_HZ, 25.0), _lowpass(kin.q, RATE_HZ, 35.0), kin.q):
        assert np.abs(other[inner][:, cols] - start).max() > 1e-4


# ------------------------------------------------------------------ the fitted coordinates


def test_fitted_coordinates_follow_their_coupler_keep_locks_and_stop_at_bounds(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict], unfitted: TrialDynamics
) -> None:
    """README: "Every expanded joint value is a function of one OpenSim coordinate (after
    coordinate coupler constraints) ... generalized forces are projected back with the
    coupling Jacobian"; the fit holds "the coordinates a step would carry past their bounds"
    there. In trial.npz the patella coordinate knee_angle_<s>_beta is the coupler's linear
    function of knee_angle_<s> (read from the model file) and carries no generalized force
    (nor in _id.sto); in _ik.mot it follows OpenSim's file convention (a coupled coordinate
    in radians, the knee angle in degrees); locked coordinates stay at their default; and no
    clamped joint coordinate ends past both its range and the filtered motion the fit
    started from (which may overshoot a range slightly and is never pulled back)."""
    res, out, trial, _ = walk
    from solver.model.skeleton import Skeleton

    sk = Skeleton(res.dynamics.model)
    assert list(sk.coordinate_names) == list(trial.coordinate_names)
    couplers = ET.parse(WALK / "unscaled_generic.osim").getroot().iter("CoordinateCouplerConstraint")
    _, ik_names, ik = read_table_by_hand(out / "walk" / "walk_ik.mot")
    _, sto_names, sto = read_table_by_hand(out / "walk" / "walk_id.sto")
    checked = 0
    for c in couplers:
        dep, ind = c.findtext("dependent_coordinate_name").strip(), c.findtext("independent_coordinate_names").strip()
        slope, intercept = (float(v) for v in c.find(".//LinearFunction/coefficients").text.split())
        d, i = sk.coordinate_index(dep), sk.coordinate_index(ind)
        np.testing.assert_allclose(trial.q[:, d], slope * trial.q[:, i] + intercept, rtol=0, atol=1e-12)
        assert np.all(trial.tau[:, d] == 0.0) and np.all(sto[:, sto_names.index(f"{dep}_moment")] == 0.0)
        assert np.abs(trial.tau[:, i]).max() > 1.0  # the knee's torque is all on the independent one
        np.testing.assert_allclose(ik[:, ik_names.index(dep)], np.radians(ik[:, ik_names.index(ind)]) * slope + intercept, atol=1e-9)
        checked += 1
    assert checked == 2
    locked = np.flatnonzero(sk.locked)
    assert locked.size >= 4
    np.testing.assert_array_equal(trial.q[:, locked], np.broadcast_to(sk.defaults[locked], (trial.n_frames, locked.size)))
    root = set(sk.root_transform_axes())
    start = unfitted.q
    for c in (c for c in np.flatnonzero(sk.clamped) if c not in root):
        lo, hi = min(sk.ranges[c, 0], start[:, c].min()), max(sk.ranges[c, 1], start[:, c].max())
        assert lo - 1e-12 <= trial.q[:, c].min() and trial.q[:, c].max() <= hi + 1e-12, sk.coordinate_names[c]


def test_velocities_and_accelerations_are_the_natural_quintic_spline_derivatives(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README: "Velocities and accelerations are derivatives of the natural quintic spline
    through the filtered coordinates, not central differences". trial.npz's qd and qdd equal
    the first and second derivatives of scipy's quintic interpolating spline through its q
    with third and fourth derivatives zero at both ends; central differences are far off."""
    from scipy.interpolate import make_interp_spline

    trial = walk[2]
    zero = np.zeros(trial.q.shape[1])
    spline = make_interp_spline(trial.time, trial.q, k=5, bc_type=([(3, zero), (4, zero)], [(3, zero), (4, zero)]))
    np.testing.assert_allclose(trial.qd, spline(trial.time, 1), rtol=0, atol=1e-9 * np.abs(trial.qd).max())
    np.testing.assert_allclose(trial.qdd, spline(trial.time, 2), rtol=0, atol=1e-9 * np.abs(trial.qdd).max())
    dt = 1.0 / RATE_HZ
    central = (trial.q[2:] - 2 * trial.q[1:-1] + trial.q[:-2]) / dt**2
    assert np.abs(central - trial.qdd[1:-1]).max() > 1.0  # rad/s²


# ------------------------------------------------------------------ masses, scales, files


def test_the_dynamics_fit_keeps_the_kinematics_body_scales_and_refits_only_the_masses(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README: "the dynamics fit keeps the kinematics stage's body scales (it fits
    coordinates and masses)". The model after the dynamics stage, and the written
    ``<subject>_scaled.osim``, put every body and marker where the kinematics' scaled model
    does (at the walk's poses); its masses sum to the fitted mass of results.json, and
    their distribution differs from the kinematics model's (the mass factors)."""
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton

    res, out, trial, results = walk
    kin_model, dyn_model = res.kinematics.kinematics.model, res.dynamics.model
    written = read_osim(out / "rajagopal2016_walk_scaled.osim")
    q = trial.q[::20]
    ref = Skeleton(kin_model)
    _, pos = ref.body_poses(q)
    markers = ref.marker_positions(q)
    for model, tol in ((dyn_model, 1e-12), (written, 1e-9)):
        sk = Skeleton(model)
        np.testing.assert_allclose(sk.body_poses(q)[1], pos, rtol=0, atol=tol)
        assert list(sk.marker_names) == list(ref.marker_names)
        np.testing.assert_allclose(sk.marker_positions(q), markers, rtol=0, atol=tol)
        assert sk.total_mass == pytest.approx(results["mass_kg"], rel=1e-9)
    kin_mass = np.array([b.mass for b in kin_model.bodies])
    dyn_mass = np.array([b.mass for b in dyn_model.bodies])
    ratio = dyn_mass / kin_mass
    assert ratio.max() - ratio.min() > 1e-3  # not one uniform factor: the body masses were fitted
    np.testing.assert_allclose([b.mass for b in written.bodies], dyn_mass, rtol=1e-9)


def test_id_sto_is_in_opensims_convention_and_trial_npz_holds_the_exact_torques(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README: "``<trial>_id.sto`` is written in OpenSim's convention (Simbody's walker-knee
    velocity term); the exact values are in ``trial.npz`` (``results.json`` reports the
    difference)". Its columns (``<coordinate>_moment``, ``_force`` for translations) hold
    the stage's OpenSim-convention forces; the largest difference from trial.npz's is
    results.json's ``opensim_convention_max_diff``, above round-off; the coordinates the
    knees' velocity term cannot reach (trunk, arms) do not differ at all."""
    res, out, trial, results = walk
    _, names, sto = read_table_by_hand(out / "walk" / "walk_id.sto")
    kinds = {c.name: ("force" if c.motion_type == "translational" else "moment") for c in res.dynamics.model.coordinates}
    assert names[1:] == [f"{n}_{kinds[n]}" for n in trial.coordinate_names]
    np.testing.assert_allclose(sto[:, 0], trial.time, rtol=0, atol=1e-9)
    values = sto[:, 1:]
    np.testing.assert_allclose(values, res.dynamics.trial("walk").tau_opensim, rtol=1e-12, atol=1e-9)
    diff = np.abs(values - trial.tau)
    assert diff.max() == pytest.approx(results["opensim_convention_max_diff"], rel=1e-9, abs=1e-9)
    assert diff.max() > 1e-3
    far = [k for k, n in enumerate(trial.coordinate_names) if n.startswith(FAR_FROM_THE_KNEES)]
    near = [trial.coordinate_names.index(n) for n in ("knee_angle_r", "knee_angle_l", "hip_flexion_r", "pelvis_tx")]
    assert len(far) >= 10
    assert diff[:, far].max() < 1e-9 and diff[:, near].max(axis=0).min() > 1e-3


@pytest.mark.parametrize("tag", ["unscaled", "scaled_walk"])
def test_opensim_compatible_inverse_dynamics_reproduces_the_oracle_to_1e_12(tag: str) -> None:
    """README, "How the model conversion works": "``inverse_dynamics(...,
    opensim_compatible=True)`` reproduces OpenSim's numbers to 1e-12. The differences are
    below 0.07 N·m on the oracle states." On the OpenSim 4.6 oracle (10 states, all
    coordinates, constraints not applied as in the oracle): OpenSim-compatible within 1e-12
    N·m (N) of OpenSim; the exact default within 0.07 of it but not within round-off, and
    only on the legs and the root (the walker knees, their ancestors and descendants)."""
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton

    path = SHARED_DATA / "models" / "Rajagopal2016.osim" if tag == "unscaled" else ORACLES / "opensim_scaled_walk.osim"
    sk = Skeleton(read_osim(path))
    with np.load(ORACLES / "opensim_rajagopal2016_oracle.npz") as oracle:
        q, qd, qdd, ref = (oracle[f"{tag}__id_{k}"] for k in ("q", "qdot", "qddot", "tau"))
        assert list(oracle[f"{tag}__coord_names"]) == list(sk.coordinate_names)
    compatible = sk.inverse_dynamics(q, qd, qdd, constrained=False, opensim_compatible=True).tau
    exact = sk.inverse_dynamics(q, qd, qdd, constrained=False).tau
    assert np.abs(compatible - ref).max() <= 1e-12
    gap = np.abs(exact - compatible)
    assert 1e-3 < gap.max() < 0.07
    far = [k for k, n in enumerate(sk.coordinate_names) if n.startswith(FAR_FROM_THE_KNEES)]
    assert gap[:, far].max() < 1e-12


def test_residual_metrics_count_only_the_frames_with_measured_force(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README: the fit weighs "the root residual wrench (measured frames; a weak version on
    unmeasured frames)"; trial.npz's ``unobserved`` are "frames left out of the fit";
    "finally inverse dynamics (joint torques, root residuals) and Hicks metrics". results.json's
    residual RMS (N, N·m, body weights of the fitted mass, BW·height) are those of
    trial.npz's residuals over the frames not unobserved, which it counts and lists; over
    all frames (the unmeasured force included) they would be several times larger. The
    Hicks thresholds are 0.05 BW and 0.1 BW·height."""
    _, _, trial, r = walk
    measured = ~trial.unobserved
    assert 0 < measured.sum() < trial.n_frames
    assert r["n_observed_frames"] == int(measured.sum())
    assert r["unobserved_frames"] == np.flatnonzero(trial.unobserved).tolist()
    force = np.linalg.norm(trial.residual_force, axis=1)
    moment = np.linalg.norm(trial.residual_moment, axis=1)
    lin, ang = float(np.sqrt(np.mean(force[measured] ** 2))), float(np.sqrt(np.mean(moment[measured] ** 2)))
    assert r["linear_residual_rms_N"] == pytest.approx(lin, rel=1e-12)
    assert r["angular_residual_rms_Nm"] == pytest.approx(ang, rel=1e-12)
    bw = r["mass_kg"] * GRAVITY
    assert r["linear_residual_rms_BW"] == pytest.approx(lin / bw, rel=1e-12)
    assert r["angular_residual_rms_BWh"] == pytest.approx(ang / (bw * trial.height_m), rel=1e-12)
    assert r["hicks_linear_threshold_N"] == pytest.approx(0.05 * bw, rel=1e-12)
    assert r["hicks_angular_threshold_Nm"] == pytest.approx(0.1 * bw * trial.height_m, rel=1e-12)
    assert float(np.sqrt(np.mean(force**2))) > 3 * lin


# ------------------------------------------------------------------ scaling


def test_left_and_right_share_scales_unmarked_bodies_follow_a_neighbour_within_35_percent(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README, "How scaling and inverse kinematics work": "the scale factors of body groups
    (left and right share; a body without markers follows a neighbour)", and "A prior keeps
    factors near the height ratio ... every factor within ±35%". On the walk: every _r body
    has exactly its _l twin's three factors; every body without a fitted marker has exactly
    the factors of its parent or of one of its children; every factor lies within 35 % of
    subject height / model height."""
    from solver.kinematics.scale_groups import model_height
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton

    res, _, _, results = walk
    kin = res.kinematics.kinematics
    scales = {b: np.asarray(s) for b, s in kin.body_scales.items()}
    generic = read_osim(WALK / "unscaled_generic.osim")
    assert set(scales) == set(generic.body_names)
    pairs = [(b, b[:-2] + "_l") for b in scales if b.endswith("_r")]
    assert len(pairs) >= 9
    for right, left in pairs:
        np.testing.assert_array_equal(scales[right], scales[left], err_msg=right)
    used = set(results["markers_used"])
    marked = {m.body for m in generic.markers if m.name in used}
    parent = {j.child.body: j.parent.body for j in generic.joints}
    children: dict[str, list[str]] = {}
    for child, par in parent.items():
        children.setdefault(par, []).append(child)
    unmarked = [b for b in generic.body_names if b not in marked]
    assert {"talus_r", "patella_r"} <= set(unmarked)
    for body in unmarked:
        neighbours = [n for n in [parent.get(body), *children.get(body, [])] if n in scales]
        assert any(np.array_equal(scales[body], scales[n]) for n in neighbours), body
    ratio = res.kinematics.subject.height_m / model_height(Skeleton(generic))
    every = np.concatenate(list(scales.values()))
    assert np.all(np.abs(every - ratio) <= 0.35 * ratio), (ratio, every.min(), every.max())


def test_marker_positions_are_affine_in_the_scale_factors_with_the_exact_jacobian(
    walk: tuple[ProcessResult, Path, ProcessedTrial, dict],
) -> None:
    """README: "marker positions are affine in scales and offsets at fixed poses, so their
    Jacobian is exact". At five of the walk's inverse-kinematics poses, the markers of the
    generic model rebuilt at the fitted scales s and at s changed by up to ±15 % per factor
    differ by exactly J(s) (s' - s) (the scale fit's Jacobian, to 1e-9 m), and J(s') = J(s)."""
    from solver.kinematics.scale_groups import make_groups
    from solver.kinematics.scale_jacobian import ScaleJacobian
    from solver.model.osim import read_osim
    from solver.model.scaling import scale_model
    from solver.model.skeleton import Skeleton

    res, _, _, results = walk
    kin = res.kinematics.kinematics
    generic = read_osim(WALK / "unscaled_generic.osim")
    used = set(results["markers_used"])
    groups = make_groups(generic, {m.body for m in generic.markers if m.name in used})
    s0 = np.concatenate([kin.body_scales[next(b for b, g in groups.body_group.items() if g == k)] for k in range(len(groups.names))])
    for body, g in groups.body_group.items():  # the fitted factors are the groups' factors
        np.testing.assert_array_equal(kin.body_scales[body], s0[3 * g : 3 * g + 3])
    s1 = s0 * (1.0 + np.random.default_rng(7).uniform(-0.15, 0.15, s0.size))
    q = kin.trial("walk").q[::50]
    jac = ScaleJacobian(generic, groups)
    body = np.array([generic.body_names.index(m.body) for m in generic.markers])
    local = np.array([m.location for m in generic.markers])

    def markers_and_jacobian(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sk = Skeleton(scale_model(generic, groups.body_scales(s)))
        assert list(sk.marker_names) == [m.name for m in generic.markers]
        rot, _ = sk.body_poses(q)
        return sk.marker_positions(q), jac.markers(rot, sk.cmap.complete(q), body, local)

    p0, j0 = markers_and_jacobian(s0)
    p1, j1 = markers_and_jacobian(s1)
    assert np.abs(p1 - p0).max() > 0.05  # the change moves markers by centimetres
    np.testing.assert_allclose(p1, p0 + j0 @ (s1 - s0), rtol=0, atol=1e-9)
    np.testing.assert_allclose(j1, j0, rtol=0, atol=1e-12)
