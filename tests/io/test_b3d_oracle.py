"""Our .b3d reader against what nimblephysics 0.10.52.1 reads from results.b3d.

Oracle: ../shared/oracles/b3d_results_oracle.json (see README_b3d.md there). Float64
values are compared exactly (the JSON keeps full precision); per-frame header values
stored as float32 are compared as float32 widened to float64, also exactly. nimble's enum
names differ in case from ours for pass types (``KINEMATICS``), so those compare upper-cased.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from solver.io.b3d import B3dFile, dof_names, open_b3d
from tests.conftest import SHARED_DATA

SHARED = SHARED_DATA.parent
B3D = SHARED / "data" / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's
ORACLE_PATH = SHARED / "oracles" / "b3d_results_oracle.json"


@pytest.fixture(scope="module")
def oracle() -> dict:
    return json.loads(ORACLE_PATH.read_text())


@pytest.fixture(scope="module")
def b3d() -> B3dFile:
    return open_b3d(B3D)


def test_input_is_the_oracle_file(oracle: dict) -> None:
    assert hashlib.sha256(B3D.read_bytes()).hexdigest() == oracle["input"]["sha256"]


def test_header(b3d: B3dFile, oracle: dict) -> None:
    h, o = b3d.header, oracle["header"]
    raw = oracle["raw_protobuf_supplement"]
    assert h.version == raw["header"]["version"]
    assert h.n_dofs == o["getNumDofs"]
    assert h.n_joints == o["getNumJoints"]
    assert len(h.trials) == o["getNumTrials"]
    assert len(h.passes) == o["getNumProcessingPasses"]
    assert h.mass_kg == o["getMassKg"]
    assert h.height_m == o["getHeightM"]
    assert h.sex == o["getBiologicalSex"]
    assert h.age_years == o["getAgeYears"]
    assert list(h.ground_contact_bodies) == o["getGroundForceBodies"]
    assert list(h.tags) == o["getSubjectTags"]
    assert h.notes == o["getNotes"]
    assert h.href == o["getHref"]
    assert list(h.custom_value_names) == o["getCustomValues"]
    assert [p.type.upper() for p in h.passes] == o["processingPassTypes"]
    assert list(h.marker_names) == raw["header"]["marker_name"]
    text = b3d.model_text(0)
    ot = o["opensimFileText"][0]
    assert len(text) == ot["numChars"]
    assert hashlib.sha256(text.encode("utf-8")).hexdigest() == ot["sha256_utf8"]
    assert text.startswith(ot["first200"]) and text.endswith(ot["last100"])


def test_layout(b3d: B3dFile, oracle: dict) -> None:
    lay = oracle["raw_protobuf_supplement"]["layout"]
    assert b3d.data_start == lay["data_section_start"]
    assert b3d.sensor_frame_bytes == lay["raw_sensor_frame_size"]
    assert b3d.pass_frame_bytes == lay["processing_pass_frame_size"]
    assert b3d.data_end == b3d.file_bytes == lay["actual_file_size"]
    assert sum(t.n_frames for t in b3d.header.trials) == lay["frames_total"]


def test_trials(b3d: B3dFile, oracle: dict) -> None:
    for trial, o in zip(b3d.header.trials, oracle["trials"], strict=True):
        assert trial.name == o["getTrialName"]
        assert trial.n_frames == o["getTrialLength"]
        assert trial.timestep_s == o["getTrialTimestep"]
        assert trial.original_name == o["getTrialOriginalName"]
        assert trial.split_index == o["getTrialSplitIndex"]
        assert list(trial.tags) == o["getTrialTags"]
        assert len(trial.passes) == o["getTrialNumProcessingPasses"]
        assert trial.n_force_plates == o["getNumForcePlates"]
        assert list(trial.missing_grf) == o["getMissingGRF_names"]
        assert trial.force_plate_corners.shape == (0, 4, 3)  # nimble segfaults on this: no corners
        for tp, op in zip(trial.passes, o["passes"], strict=True):
            for ours, theirs in (
                (tp.marker_rms, "getTrialMarkerRMSs"),
                (tp.marker_max, "getTrialMarkerMaxs"),
                (tp.linear_residual, "getTrialLinearResidualNorms"),
                (tp.angular_residual, "getTrialAngularResidualNorms"),
                (tp.joints_max_velocity, "getTrialMaxJointVelocity"),
            ):
                np.testing.assert_array_equal(ours, np.array(op[theirs], dtype=np.float64), err_msg=theirs)
            np.testing.assert_array_equal(tp.dof_positions_observed, op["getDofPositionsObserved"])
            np.testing.assert_array_equal(tp.dof_velocities_finite_differenced, op["getDofVelocitiesFiniteDifferenced"])
            np.testing.assert_array_equal(tp.dof_accelerations_finite_differenced, op["getDofAccelerationsFiniteDifferenced"])
            assert tp.lowpass_cutoff_hz == op["getLowpassCutoffFrequency"]
            assert tp.lowpass_filter_order == op["getLowpassFilterOrder"]
            assert list(tp.force_plate_cutoffs) == op["getForceplateCutoffs"]


def _sampled() -> list[tuple[int, int, int]]:
    o = json.loads(ORACLE_PATH.read_text())
    return [(i, f["request"]["trial"], f["request"]["startFrame"]) for i, f in enumerate(o["frames"])]


@pytest.mark.parametrize(("index", "trial", "frame"), _sampled())
def test_sampled_frame(b3d: B3dFile, oracle: dict, index: int, trial: int, frame: int) -> None:
    o = oracle["frames"][index]
    fr = b3d.read_frame(trial, frame)
    assert fr.n_frames == 1 and fr.trial == o["trial"] and fr.start == o["t"]
    assert fr.missing_grf[0] == o["missingGRFReason"]
    # markers: nimble lists the observed ones (no NaN) in header order
    names = b3d.header.marker_names
    observed = [(names[j], fr.markers[0, j].tolist()) for j in range(len(names)) if not np.isnan(fr.markers[0, j]).any()]
    assert observed == [(n, xyz) for n, xyz in o["markerObservations"]]
    assert fr.plate_force[0].tolist() == o["rawForcePlateForces"]
    assert fr.plate_cop[0].tolist() == o["rawForcePlateCenterOfPressures"]
    assert fr.plate_moment[0].tolist() == o["rawForcePlateTorques"]
    assert fr.acc_obs.shape[1] == len(o["accObservations"]) and fr.gyro_obs.shape[1] == len(o["gyroObservations"])
    assert fr.emg.shape[1] == len(o["emgSignals"]) and fr.exo.shape[1] == len(o["exoTorques"])
    assert fr.custom.shape[1] == len(o["customValues"])
    info = b3d.header.trials[trial]
    for j, (ours, op) in enumerate(zip(fr.passes, o["processingPasses"], strict=True)):
        assert ours.type.upper() == op["type"]
        for field, key in (
            ("pos", "pos"), ("vel", "vel"), ("acc", "acc"), ("tau", "tau"),
            ("com_pos", "comPos"), ("com_vel", "comVel"), ("com_acc", "comAcc"),
        ):  # fmt: skip
            assert getattr(ours, field)[0].tolist() == op[key], field
        assert ours.ground_contact_wrench[0].ravel().tolist() == op["groundContactWrenches"]
        assert ours.ground_contact_force[0].ravel().tolist() == op["groundContactForce"]
        assert ours.ground_contact_cop[0].ravel().tolist() == op["groundContactCenterOfPressure"]
        assert ours.ground_contact_torque[0].ravel().tolist() == op["groundContactTorque"]
        # nimble fills these from the header's per-frame float32 arrays
        tp = info.passes[j]
        assert float(tp.marker_rms[frame]) == op["markerRMS"]
        assert float(tp.marker_max[frame]) == op["markerMax"]
        assert float(tp.linear_residual[frame]) == op["linearResidual"]
        assert float(tp.angular_residual[frame]) == op["angularResidual"]
        # stored empty in this file; nimble gives empty joint centres and histories
        assert ours.extra["world_frame_joint_centers"].shape[1] == len(op["jointCenters"])
        assert ours.extra["root_frame_root_pos_history"].shape[1] == len(op["rootPosHistoryInRootFrame"])


def test_every_frame(b3d: B3dFile, oracle: dict) -> None:
    for o in oracle["all_frames"]:
        fr = b3d.read_trial(o["trial"])
        assert fr.n_frames == o["numFramesRead"]
        assert [round(float(t / b3d.header.trials[o["trial"]].timestep_s)) for t in fr.time_s] == o["t"]
        assert fr.passes[0].pos.tolist() == o["pass0_pos"]
        assert (~np.isnan(fr.markers).any(axis=2)).sum(axis=1).tolist() == o["numMarkerObservations"]
        assert fr.plate_force.tolist() == o["rawForcePlateForces"]


def test_range_equals_single_frames(b3d: B3dFile) -> None:
    """A range read gives the same values as frame-by-frame reads (seek arithmetic)."""
    whole = b3d.read_frames(1, 10, 20)
    for i in range(10):
        one = b3d.read_frame(1, 10 + i)
        np.testing.assert_array_equal(one.passes[0].tau[0], whole.passes[0].tau[i])
        np.testing.assert_array_equal(one.markers[0], whole.markers[i])


def test_embedded_model_coordinates(b3d: B3dFile, oracle: dict, tmp_path: Path) -> None:
    """The embedded model parses with our .osim reader; its coordinates are nimble's DOFs."""
    from solver.model.osim import read_osim

    p = tmp_path / "model.osim"
    p.write_text(b3d.model_text(0))
    model = read_osim(p)
    assert list(dof_names(model)) == oracle["skeleton"]["dofNames"]
    assert len(model.coordinates) == b3d.header.n_dofs + 2  # two coupled knee coordinates
    assert set(oracle["skeleton"]["bodyNodeNames"]) <= set(model.body_names)
    names = {m.name for m in model.markers}
    assert names == {m[0] for m in oracle["skeleton"]["markersMap"]}


def test_frames_are_immutable(b3d: B3dFile) -> None:
    fr = b3d.read_frame(0, 0)
    with pytest.raises(ValueError):
        fr.passes[0].pos[0, 0] = 1.0
    with pytest.raises(IndexError):
        b3d.read_frames(0, 100, 200)
    with pytest.raises(KeyError):
        b3d.read_frame("nope", 0)


def test_vectorized_read_equals_frame_by_frame_parse(b3d: B3dFile, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ranges are read as column views when every frame shares frame 0's field layout;
    forcing the per-frame protobuf parse gives the same values."""
    import dataclasses

    from solver.io import b3d as reader

    fast = [b3d.read_trial(k) for k in range(2)] + [b3d.read_frames(1, 0, 0)]
    monkeypatch.setattr(reader, "_columns_fast", lambda region, fields: None)
    slow = [b3d.read_trial(k) for k in range(2)] + [b3d.read_frames(1, 0, 0)]
    for a, b in zip(fast, slow, strict=True):
        for f in dataclasses.fields(a):
            x, y = getattr(a, f.name), getattr(b, f.name)
            if f.name == "passes":
                for pa, pb in zip(x, y, strict=True):
                    for g in dataclasses.fields(pa):
                        u, v = getattr(pa, g.name), getattr(pb, g.name)
                        if g.name == "extra":
                            assert set(u) == set(v)
                            for key in u:
                                assert u[key].shape == v[key].shape, key
                                np.testing.assert_array_equal(u[key], v[key])
                        elif isinstance(u, np.ndarray):
                            assert u.shape == v.shape
                            np.testing.assert_array_equal(u, v)
                        else:
                            assert u == v
            elif isinstance(x, np.ndarray):
                assert x.shape == y.shape, f.name
                np.testing.assert_array_equal(x, y)
            else:
                assert x == y, f.name
