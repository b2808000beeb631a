"""Contact assignment on the real walk: plates to feet, a foot on two plates, two feet on one
plate (ambiguous), and the proposals of unmeasured force."""

from __future__ import annotations

from functools import cache

import numpy as np

from solver.dynamics.contact import assign_contacts
from solver.io.subject import load_subject
from solver.model.skeleton import Skeleton
from solver.pipeline import plates_on_frames, subject_kinematics
from solver.results import PlateData
from tests.conftest import SHARED_DATA

FEET = ("calcn_r", "calcn_l")


@cache
def walk():
    sk = subject_kinematics(load_subject(SHARED_DATA / "subjects" / "rajagopal2016_walk"))
    trial = sk.kinematics.trial("walk")
    raw = next(t for t in sk.trials if t.name == "walk")
    return Skeleton(sk.kinematics.model), trial, plates_on_frames(raw.forces, trial.time)


def test_each_plate_goes_to_the_foot_standing_on_it() -> None:
    skel, trial, plates = walk()
    res = assign_contacts(skel, trial.q, plates, FEET, 85.07, 0.01)
    names = {p.name: i for i, p in enumerate(plates)}
    loaded_r = plates[names["r"]].force[:, 1] > 50
    loaded_l = plates[names["l"]].force[:, 1] > 50
    # the file's "r" and "l" columns are the right and left foot's forces
    assert (res.plate_foot[names["r"], loaded_r] == 0).mean() > 0.97
    assert (res.plate_foot[names["l"], loaded_l] == 1).mean() > 0.97
    assert not res.ambiguous.any()


def test_a_foot_on_two_plates_receives_both() -> None:
    """Split the right foot's plate into a heel plate and a forefoot plate (each half the
    force, CoPs 6 cm behind and ahead): both go to the right foot."""
    skel, trial, plates = walk()
    r = next(p for p in plates if p.name == "r")
    rot, _ = skel.body_poses(trial.q)
    forward = rot[:, skel.body_index("calcn_r"), :, 0]  # the foot's x axis
    forward[:, 1] = 0.0
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    heel = PlateData("heel", r.force / 2, r.cop - 0.06 * forward, r.free_moment / 2)
    fore = PlateData("fore", r.force / 2, r.cop + 0.06 * forward, r.free_moment / 2)
    res = assign_contacts(skel, trial.q, [heel, fore], FEET, 85.07, 0.01)
    loaded = r.force[:, 1] > 50
    assert (res.plate_foot[0, loaded] == 0).mean() > 0.95
    assert (res.plate_foot[1, loaded] == 0).mean() > 0.95
    assert res.foot_loaded[0, loaded].all()


def test_two_feet_on_one_plate_is_flagged_ambiguous() -> None:
    """One loaded plate whose CoP sits midway between the two feet: ambiguous exactly when
    both feet are within ``ambiguous_distance`` of it (the swing foot passing the stance foot)."""
    from solver.dynamics.contact import ContactSettings, _foot_points, _segment_distance

    skel, trial, _ = walk()
    st = ContactSettings()
    pts = [_foot_points(skel, trial.q, f, st.toe_extension) for f in FEET]
    mids = [0.5 * (heel + tip) for heel, tip, _ in pts]
    cop = 0.5 * (mids[0] + mids[1])
    cop[:, 1] = 0.0
    force = np.zeros_like(cop)
    force[:, 1] = 700.0
    res = assign_contacts(skel, trial.q, [PlateData("shared", force, cop, np.zeros_like(force))], FEET, 85.07, 0.01)
    dist = np.stack([_segment_distance(cop, heel, tip) for heel, tip, _ in pts])
    both_near = (dist <= st.ambiguous_distance).all(axis=0)
    assert both_near.any() and (~both_near).any()
    np.testing.assert_array_equal(res.ambiguous, both_near)


def test_a_foot_on_the_floor_without_plate_force_is_proposed() -> None:
    skel, trial, plates = walk()
    g = np.linalg.norm(skel.osim.gravity)
    com_acc = np.gradient(np.gradient(skel.center_of_mass(trial.q), 0.01, axis=0), 0.01, axis=0)
    res = assign_contacts(skel, trial.q, plates, FEET, 85.07, 0.01, com_acc)
    left = 1
    off = res.foot_in_contact[left] & ~res.foot_loaded[left]
    assert off[:20].all()  # the trial starts with the left foot on the floor
    assert res.proposed[off].all()
    assert all("calcn_l in contact with no plate force" == res.reasons[k] for k in np.flatnonzero(off))
    assert g > 9.8


def test_a_foot_on_a_treadmill_belt_is_in_contact() -> None:
    """On the treadmill run the stance foot moves backward with the belt (about 4 m/s): its
    kinematic contact is judged relative to the belt, so loaded frames are in contact, and
    no unloaded foot is called in contact (no false proposal of unmeasured force)."""
    sk = subject_kinematics(load_subject(SHARED_DATA / "subjects" / "rajagopal2016_run"))
    trial = sk.kinematics.trial("run")
    raw = next(t for t in sk.trials if t.name == "run")
    skel = Skeleton(sk.kinematics.model)
    res = assign_contacts(skel, trial.q, plates_on_frames(raw.forces, trial.time), FEET, 72.84, 0.01)
    for k in range(2):
        loaded = res.foot_loaded[k]
        assert loaded.sum() > 100
        assert res.foot_in_contact[k, loaded].mean() > 0.3
        assert not (res.foot_in_contact[k] & ~loaded).any()


def test_a_foot_stands_on_its_plate_and_a_pelvis_named_as_a_foot_far_above_it() -> None:
    """``stance_height``: each foot's lowest point above the centre of pressure of the plate
    that loads it, a few millimetres for the walk's heels; a pelvis and a torso named as feet
    take force by horizontal distance, half a metre and a metre above it."""
    skel, trial, plates = walk()
    feet = assign_contacts(skel, trial.q, plates, FEET, 85.07, 0.01).stance_height
    assert feet.shape == (2,) and np.all(np.abs(feet) < 0.02), feet
    wrong = assign_contacts(skel, trial.q, plates, ("pelvis", "torso"), 85.07, 0.01).stance_height
    assert wrong[0] > 0.4 and wrong[1] > 0.9, wrong


def test_a_plate_force_far_from_m_a_plus_g_is_proposed_with_its_mismatch() -> None:
    """Halve the right plate's vertical force over about 0.2 s of its stance (the foot stays
    loaded, so no "no plate force" reason): exactly those frames whose total vertical force
    then differs from m(a_com,y + g) by more than ``force_mismatch_bw`` are proposed, each
    with the reason "measured vertical force differs from m(a+g) by X BW" and X the
    mismatch on that frame; the frames outside the window keep their proposals."""
    from solver.dynamics.contact import MISMATCH_REASON, ContactSettings
    from solver.masks import true_runs

    skel, trial, plates = walk()
    mass, dt = 85.07, 0.01
    g = float(np.linalg.norm(skel.osim.gravity))
    com_acc = np.gradient(np.gradient(skel.center_of_mass(trial.q), dt, axis=0), dt, axis=0)
    before = assign_contacts(skel, trial.q, plates, FEET, mass, dt, com_acc)
    r = next(i for i, p in enumerate(plates) if p.name == "r")
    # the longest run of frames with the right foot's force above 0.8 body weight
    start, stop = max(true_runs(plates[r].force[:, 1] > 0.8 * mass * g), key=lambda run: run[1] - run[0])
    window = np.arange(start, stop)
    assert len(window) >= 18
    force = plates[r].force.copy()
    force[window, 1] *= 0.5
    changed = [p if i != r else type(p)(p.name, force, p.cop, p.free_moment) for i, p in enumerate(plates)]
    after = assign_contacts(skel, trial.q, changed, FEET, mass, dt, com_acc)

    measured = sum(np.nan_to_num(p.force[:, 1]) for p in changed)
    mismatch = np.abs(measured - mass * (com_acc[:, 1] + g)) / (mass * g)
    expected = mismatch[window] > ContactSettings().force_mismatch_bw
    assert expected.sum() >= 15  # the halving is visible on most of the window
    np.testing.assert_array_equal(after.proposed[window], before.proposed[window] | expected)
    for j in window[expected & ~before.proposed[window]]:
        assert after.reasons[j] == f"{MISMATCH_REASON} by {mismatch[j]:.2f} BW"
        assert after.foot_loaded[0, j]  # still loaded: the force, not the contact, is wrong
    outside = np.setdiff1d(np.arange(len(trial.q)), window)
    np.testing.assert_array_equal(after.proposed[outside], before.proposed[outside])
