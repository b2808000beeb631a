"""Bad input that got no clear error before the input audit of 2026-12-02
(docs/audits/2026-12-02-inputs.md): each test states the error a user gets now, naming the
file and the line, element or parameter."""

from __future__ import annotations

import struct
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from solver.errors import C3dFormatError, TrcFormatError
from solver.io.c3d import read_c3d
from solver.io.c3d_layout import check_c3d
from solver.io.trc import read_trc
from tests.conftest import SHARED_DATA

WALK_C3D = SHARED_DATA / "trials" / "opensim_c3d" / "walking2.c3d"
RUN_TRC = SHARED_DATA / "subjects" / "rajagopal2016_run" / "trials" / "run" / "markers.trc"
MODEL = SHARED_DATA / "models" / "Rajagopal2016.osim"
REPO = Path(__file__).resolve().parents[2]


def _c3d_with_float(path: Path, group: str, name: str, value: float, header_rate: float | None = None) -> Path:
    """walking2.c3d with the first value of parameter ``group:name`` set to ``value`` (and
    the header's frame rate, bytes 20-23, to ``header_rate``), written to ``path``."""
    param = check_c3d(WALK_C3D).get(group, name)
    data = bytearray(WALK_C3D.read_bytes())
    at = param.offset + 2 + len(name) + 2 + 2 + len(param.dims)  # the record's first value
    data[at : at + 4] = struct.pack("<f", value)
    if header_rate is not None:
        data[20:24] = struct.pack("<f", header_rate)
    path.write_bytes(bytes(data))
    return path


def _refused_c3d(bad: Path, match: str) -> None:
    """``read_c3d(bad)`` raises a C3dFormatError matching ``match`` that names ``bad``."""
    with warnings.catch_warnings(), pytest.raises(C3dFormatError, match=match) as err:
        warnings.simplefilter("ignore")
        read_c3d(bad)
    assert err.value.path == str(bad)


def test_a_joint_whose_child_is_ground_is_refused(tmp_path: Path) -> None:
    """A joint whose child frame is ground: an OsimModelError naming the joint, in a fresh
    interpreter (the reader hangs today; the test gives it 20 s)."""
    text = MODEL.read_text()
    old = "<socket_child_frame>pelvis_offset</socket_child_frame>"
    assert old in text
    model = tmp_path / "child_ground.osim"
    model.write_text(text.replace(old, "<socket_child_frame>ground_offset</socket_child_frame>", 1))
    code = ("import sys\nfrom solver.errors import OsimModelError\nfrom solver.model.osim import read_osim\n"
            "try:\n    read_osim(sys.argv[1])\nexcept OsimModelError as err:\n    print(err)\n")
    done = subprocess.run([sys.executable, "-c", code, str(model)], cwd=REPO, capture_output=True, text=True, timeout=20, check=False)
    assert done.returncode == 0 and "ground_pelvis" in done.stdout and str(model) in done.stdout, done.stderr[-2000:]


def test_a_c3d_frame_rate_of_zero_is_refused(tmp_path: Path) -> None:
    """POINT:RATE and the header's rate 0: a C3dFormatError naming the file and the rate."""
    _refused_c3d(_c3d_with_float(tmp_path / "rate0.c3d", "POINT", "RATE", 0.0, header_rate=0.0), "RATE")


def test_an_analog_rate_that_disagrees_with_the_header_is_refused(tmp_path: Path) -> None:
    """ANALOG:RATE 1000 Hz where the header says 8 samples per frame at 250 Hz (2000 Hz): a
    C3dFormatError naming the file and ANALOG:RATE, not 168,895 N peak forces."""
    _refused_c3d(_c3d_with_float(tmp_path / "analog_rate.c3d", "ANALOG", "RATE", 1000.0), "ANALOG:RATE")


def test_a_row_missing_a_value_in_a_file_whose_rows_end_with_a_tab_is_refused(tmp_path: Path) -> None:
    """The run's TRC (rows end with a tab) with one value removed from line 11: a
    TrcFormatError naming the file and line 11, not 41 markers shifted by one axis."""
    lines = RUN_TRC.read_text().split("\n")
    assert lines[10].endswith("\t")
    cells = lines[10].split("\t")
    del cells[5]  # marker 2's X
    lines[10] = "\t".join(cells)
    bad = tmp_path / "markers.trc"
    bad.write_text("\n".join(lines))
    with pytest.raises(TrcFormatError, match="found 127 cells") as err:
        read_trc(bad)
    assert err.value.line == 11 and err.value.path == str(bad)


WALK_MOT = SHARED_DATA / "subjects" / "rajagopal2016_walk" / "trials" / "walk" / "grf.mot"
WALK_TRC = SHARED_DATA / "subjects" / "rajagopal2016_walk" / "trials" / "walk" / "markers.trc"
WALK_MODEL = SHARED_DATA / "subjects" / "rajagopal2016_walk" / "unscaled_generic.osim"


def test_two_columns_for_one_plate_axis_are_refused(tmp_path: Path) -> None:
    """Audit finding 7: the left plate's columns renamed in the ``r_ground_force_`` scheme
    (so both plates read as plate r): a MotFormatError naming both columns, not a plate
    silently dropped."""
    from solver.errors import MotFormatError
    from solver.io.mot import read_forces

    lines = WALK_MOT.read_text().split("\n")
    names = next(i for i, line in enumerate(lines) if line.startswith("time"))
    lines[names] = (lines[names].replace("ground_force_l_v", "r_ground_force_v").replace("ground_force_l_p", "r_ground_force_p")
                    .replace("ground_torque_l_", "r_ground_torque_"))
    bad = tmp_path / "grf.mot"
    bad.write_text("\n".join(lines))
    with pytest.raises(MotFormatError, match="columns ground_force_r_vx and r_ground_force_vx both give plate 'r'") as err:
        read_forces(bad)
    assert err.value.path == str(bad)


def test_a_nan_free_moment_is_named_with_its_plate_and_time(tmp_path: Path) -> None:
    """Audit finding 8: a NaN in a plate's moment column stops the dynamics with the file, the
    plate and the time (it said "cannot filter a signal with missing (NaN) samples")."""
    from solver.dynamics.stage import DynamicsOptions, _filtered_plates
    from solver.errors import DynamicsError
    from solver.io.mot import read_forces

    forces = read_forces(WALK_MOT)
    moment = forces.plates[0].free_moment.copy()
    moment[100, 1] = float("nan")
    import dataclasses

    broken = dataclasses.replace(forces, plates=(dataclasses.replace(forces.plates[0], free_moment=moment), *forces.plates[1:]))
    with pytest.raises(DynamicsError, match=rf"plate {forces.plates[0].name}: the free moment is .* at {forces.time[100]:.3f} s \(sample 101") as err:
        _filtered_plates(broken, forces.time[::10], DynamicsOptions(), 700.0, "walk")
    assert err.value.path == str(WALK_MOT)


def test_a_marker_mapping_that_is_not_utf8_is_named(tmp_path: Path) -> None:
    """Audit finding 9: a Latin-1 markers.yaml gives a KinematicsError naming it, not a
    UnicodeDecodeError traceback."""
    from solver.errors import KinematicsError
    from solver.kinematics.observations import read_marker_settings

    bad = tmp_path / "markers.yaml"
    bad.write_bytes(b"R.Shoulder: RACR  # \xe9paule droite\n")
    with pytest.raises(KinematicsError, match="not UTF-8") as err:
        read_marker_settings(bad)
    assert err.value.path == str(bad)


def test_chained_or_doubled_couplers_are_refused(tmp_path: Path) -> None:
    """Audit finding 2: a coupler driven by another coupler's dependent coordinate, and a
    coordinate two couplers drive, give an OsimModelError naming the couplers (a bare
    ValueError from the coupling map, or silently the second coupler)."""
    from solver.errors import OsimModelError
    from solver.model.osim import read_osim

    text = WALK_MODEL.read_text()
    chained = tmp_path / "chained.osim"
    chained.write_text(text.replace("<independent_coordinate_names>knee_angle_l</independent_coordinate_names>",
                                    "<independent_coordinate_names>knee_angle_r_beta</independent_coordinate_names>", 1))
    with pytest.raises(OsimModelError, match="driven by 'knee_angle_r_beta', which coupler .* drives; chained couplers"):
        read_osim(chained)
    doubled = tmp_path / "doubled.osim"
    doubled.write_text(text.replace("<dependent_coordinate_name>knee_angle_l_beta</dependent_coordinate_name>",
                                    "<dependent_coordinate_name>knee_angle_r_beta</dependent_coordinate_name>", 1))
    with pytest.raises(OsimModelError, match="'knee_angle_r_beta' is the dependent coordinate of two couplers"):
        read_osim(doubled)


def test_an_inertia_with_a_negative_principal_moment_is_refused(tmp_path: Path) -> None:
    """Audit finding 3: a negative inertia gives an OsimModelError naming the body and its
    line (pinocchio's "The 3d inertia should be positive" traceback, or, off the diagonal,
    accepted silently)."""
    from solver.errors import OsimModelError
    from solver.model.osim import read_osim

    text = WALK_MODEL.read_text()
    body = text.index('<Body name="pelvis">')
    pelvis = text[body:].replace("<inertia_xy>0</inertia_xy>", "<inertia_xy>0.5</inertia_xy>", 1)
    bad = tmp_path / "bad_pelvis.osim"
    bad.write_text(text[:body] + pelvis)
    with pytest.raises(OsimModelError, match="negative principal moment") as err:
        read_osim(bad)
    assert err.value.where == "<Body name='pelvis'>" and err.value.line is not None


def test_a_b3d_with_empty_sensor_frames_opens(tmp_path: Path) -> None:
    """.b3d audit finding 5: a trial with no marker, plate or IMU value has empty sensor frames
    (raw_sensor_frame_size 0); our writer writes such a file and the reader opens it (it
    refused "raw_sensor_frame_size is 0, expected > 0")."""
    import numpy as np

    from solver.io.b3d import B3dFrames, B3dHeader, B3dTrial, open_b3d
    from solver.io.b3d_writer import write_b3d

    trial = B3dTrial(name="a", original_name="a", split_index=0, timestep_s=0.01, n_frames=2, tags=(),
                     missing_grf=("notMissingGRF",) * 2, n_force_plates=0, force_plate_corners=np.zeros((0, 4, 3)),
                     marker_names_guessed=False, passes=())
    header = B3dHeader(version=4, n_dofs=0, mass_kg=70.0, height_m=1.7, sex="male", age_years=30, tags=(), notes="",
                       href="", ground_contact_bodies=(), marker_names=(), passes=(), trials=(trial,))
    empty = np.zeros((2, 0, 3))
    path = tmp_path / "empty_sensor.b3d"
    write_b3d(path, header, [B3dFrames(trial=0, start=0, time_s=np.arange(2) * 0.01, missing_grf=trial.missing_grf,
                                       markers=empty, plate_force=empty, plate_cop=empty, plate_moment=empty, passes=())])
    frames = open_b3d(path).read_trial(0)
    assert frames.markers.shape == (2, 0, 3) and frames.n_frames == 2


def test_an_unknown_missing_grf_reason_is_read_and_written_back(tmp_path: Path) -> None:
    """.b3d audit finding 6: a missing-GRF reason number this reader does not know (a newer
    writer's) is read as ``unknownReason<number>`` (not measured) and written back as the
    same number; the file was unreadable."""
    from solver.io import b3d_schema as schema
    from solver.io.b3d import open_b3d
    from solver.io.b3d_writer import write_b3d

    msg = schema.Header(version=4, num_dofs=0)
    msg.marker_name.append("m")
    sensor = schema.SensorFrame()
    sensor.marker_obs.extend([1.0, 2.0, 3.0])
    blob = sensor.SerializeToString()
    msg.raw_sensor_frame_size = len(blob)
    msg.trial_header.add(name="a", trial_length=2, trial_timestep=0.01).missing_grf_reason.extend([0, 11])
    raw = msg.SerializeToString()
    path = tmp_path / "reason11.b3d"
    path.write_bytes(struct.pack("<q", len(raw)) + raw + blob * 2)
    f = open_b3d(path)
    assert f.header.trials[0].missing_grf == ("notMissingGRF", "unknownReason11")
    again = tmp_path / "again.b3d"
    write_b3d(again, f.header, [f.read_trial(0)])
    assert open_b3d(again).header.trials[0].missing_grf == ("notMissingGRF", "unknownReason11")


def test_a_lost_marker_filled_with_a_sentinel_is_read_as_missing(tmp_path: Path) -> None:
    """Audit finding 11: R.Shoulder written as 9999999 mm on six rows (a lost-marker fill, no
    single-frame spike) is read by the TRC reader as the file holds it, and as missing where
    the trial is loaded, with a warning naming the file, the marker and the frames (the scale
    fit blamed the Units line and heightM); every other sample is as before."""
    import numpy as np

    from solver.io.spikes import without_spikes

    lines = WALK_TRC.read_text().split("\n")
    for r in range(50, 56):  # lines 51-56: data rows 45-50, frames 44-49
        cells = lines[r].split("\t")
        cells[2:5] = ["9999999"] * 3
        lines[r] = "\t".join(cells)
    bad = tmp_path / "markers.trc"
    bad.write_text("\n".join(lines))
    raw = read_trc(bad)
    shoulder = raw.names.index("R.Shoulder")
    assert (raw.positions[44:50, shoulder] == 9999.999).all()  # the reader keeps what the file holds
    with pytest.warns(UserWarning, match=rf"{bad}, frames 44-49 \(0.440-0.490 s\): marker R.Shoulder is 17.3 km from the frame's other markers on 6 frames"):
        read = without_spikes(raw)
    good = read_trc(WALK_TRC)
    lost = np.zeros(good.positions.shape[:2], dtype=bool)
    lost[44:50, shoulder] = True
    assert np.isnan(read.positions[lost]).all()
    np.testing.assert_array_equal(read.positions[~lost], good.positions[~lost])


def test_a_data_rate_that_disagrees_with_the_time_column_does_not_set_the_filter(tmp_path: Path) -> None:
    """Audit finding 13: ``DataRate=1000`` in a force file whose time column steps 0.5 ms: the
    reader warns, naming the file (and keeps the header's value: a force file written and read
    again is the same), and the dynamics filters the forces at the time column's 2000 Hz: the
    same forces as from the file without the wrong DataRate (the cutoff had doubled)."""
    import numpy as np

    from solver.dynamics.stage import DynamicsOptions, _filtered_plates
    from solver.io.mot import read_forces

    lines = WALK_MOT.read_text().split("\n")
    lines.insert(lines.index("endheader"), "DataRate=1000")
    bad = tmp_path / "grf.mot"
    bad.write_text("\n".join(lines))
    with pytest.warns(UserWarning, match=rf"{bad}: DataRate says 1000 Hz but the time column steps 0.0005 s \(2000 Hz\)"):
        wrong = read_forces(bad)
    right = read_forces(WALK_MOT)
    assert wrong.rate_hz == 1000.0 and right.rate_hz == 2000.0
    frames = right.time[::20]
    for a, b in zip(_filtered_plates(wrong, frames, DynamicsOptions(), 700.0, "walk"),
                    _filtered_plates(right, frames, DynamicsOptions(), 700.0, "walk"), strict=True):  # fmt: skip
        np.testing.assert_array_equal(a.force, b.force)
    lines[lines.index("DataRate=1000")] = "DataRate=2000"
    bad.write_text("\n".join(lines))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_forces(bad).rate_hz == 2000.0


def test_a_lab_marker_mapped_twice_is_refused(tmp_path: Path) -> None:
    """Audit finding 15: a markers.yaml giving R.Shoulder twice is refused, naming the file,
    the line and both names (the last entry won silently); the same in JSON."""
    from solver.errors import KinematicsError
    from solver.kinematics.observations import read_marker_settings

    bad = tmp_path / "markers.yaml"
    bad.write_text("R.Shoulder: RACR\nR.Shoulder: LACR\n")
    with pytest.raises(KinematicsError, match=r"line 2: 'R.Shoulder' is mapped twice \('RACR' on an earlier line, then 'LACR'\)") as err:
        read_marker_settings(bad)
    assert err.value.path == str(bad)
    nested = tmp_path / "nested.yaml"
    nested.write_text("markers:\n  R.Shoulder: RACR\n  L.Shoulder: LACR\nattach_unmatched: true\n")
    assert read_marker_settings(nested).mapping == {"R.Shoulder": "RACR", "L.Shoulder": "LACR"}
    doubled = tmp_path / "markers.json"
    doubled.write_text('{"R.Shoulder": "RACR", "R.Shoulder": "LACR"}')
    with pytest.raises(KinematicsError, match=r"'R.Shoulder' is mapped twice \('RACR' and 'LACR'\)"):
        read_marker_settings(doubled)


def test_a_one_frame_marker_file_is_named_as_such(tmp_path: Path) -> None:
    """Audit finding 16: a TRC of one frame stops the dynamics with "the markers have 1
    frame", naming the file (it said the markers and forces "do not overlap in time")."""
    from solver.dynamics.stage import trial_frames
    from solver.errors import DynamicsError
    from solver.io.mot import read_forces

    lines = WALK_TRC.read_text().split("\n")
    lines[2] = lines[2].replace("238", "1", 1)  # NumFrames
    one = tmp_path / "markers.trc"
    one.write_text("\n".join(lines[:7]) + "\n")
    markers = read_trc(one)
    assert markers.time.size == 1
    with pytest.raises(DynamicsError, match="the markers have 1 frame; the dynamics needs at least 10") as err:
        trial_frames(markers, read_forces(WALK_MOT), 100.0, "walk")
    assert err.value.path == str(one)


def test_an_absurd_force_is_printed_briefly_with_its_time(tmp_path: Path) -> None:
    """Audit finding 17: a force of 1e308 N is printed as 1e+308 N with its time and sample
    (it was printed with its 309 digits and no time)."""
    import dataclasses

    from solver.dynamics.stage import DynamicsOptions, _filtered_plates
    from solver.errors import DynamicsError
    from solver.io.mot import read_forces

    forces = read_forces(WALK_MOT)
    force = forces.plates[0].force.copy()
    force[3000, 1] = 1e308
    broken = dataclasses.replace(forces, plates=(dataclasses.replace(forces.plates[0], force=force), *forces.plates[1:]))
    with pytest.raises(DynamicsError, match=rf"force of 1e\+308 N at {forces.time[3000]:.3f} s \(sample 3001\) is 1\.\d+e\+305 body weights") as err:
        _filtered_plates(broken, forces.time[::10], DynamicsOptions(), 700.0, "walk")
    assert err.value.path == str(WALK_MOT) and len(str(err.value)) < 400
