"""MOT/STO tables, ground reaction forces and coordinates: shared files, odd headers,
broken copies, moment conventions, exact round trips, and OpenSim 4.6 reading our files."""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from solver.errors import MotFormatError
from solver.io.force_columns import classify, group_plates
from solver.io.mot import (
    default_rotational,
    is_force_table,
    read_coordinates,
    read_forces,
    read_table,
    write_coordinates,
    write_forces,
    write_table,
)
from solver.io.plate_moments import detect_reference
from solver.io.types import ForcePlate, ForceRecording, Table
from tests.conftest import OPENSIM_REASON, import_tool
from tests.conftest import SHARED_DATA as DATA
from tests.io.damage import damaged, expect_format_error

MOT_FILES = sorted([*DATA.rglob("*.mot"), *DATA.rglob("*.sto")])
G = 9.80665

#: plates per force file (names as in the columns), from reading the column headers
PLATES = {
    "rajagopal2016/grf_walk.mot": ("r", "l"),
    "rajagopal2016/grf_run.mot": ("R", "L"),
    "rajagopal2016_walk/trials/walk/grf.mot": ("r", "l"),
    "rajagopal2016_run/trials/run/grf.mot": ("R", "L"),
    "opencap_uhlrich2023/DJ1/grf.mot": ("R", "L", "3"),
    "opencap_uhlrich2023/trials/DJ1/grf.mot": ("R", "L", "3"),
    "opencap_uhlrich2023/walking1/grf.mot": ("R", "L"),
    "opencap_uhlrich2023/trials/walking1/grf.mot": ("R", "L"),
    "camargo2021_levelground/grf.mot": ("1", "2", "3", "4", "5", "6"),
    "initial_off_treadmill/grf.mot": ("R", "L"),
    "stairdown/grf.mot": ("0", "1"),
}
#: subject masses from the data README / addb_subject.json files, kg
MASS = {
    "rajagopal2016_walk": 85.0668,
    "grf_walk": 85.0668,
    "rajagopal2016_run": 72.84,
    "grf_run": 72.84,
    "opencap": 75.7,
}


def _plates_for(path: Path) -> tuple[str, ...] | None:
    rel = path.as_posix()
    for key, names in PLATES.items():
        if rel.endswith(key):
            return names
    return None


def _mass_for(path: Path) -> float | None:
    rel = path.as_posix()
    return next((m for k, m in MASS.items() if k in rel), None)


def _raw_rows(path: Path) -> list[list[str]]:
    """Data rows split on whitespace, independent of the reader (after the 'time' line)."""
    lines = path.read_text(encoding="latin-1").splitlines()
    start = next(i for i, line in enumerate(lines) if line.split()[:1] == ["time"])
    return [line.split() for line in lines[start + 1 :] if line.strip()]


def test_shared_data_has_mot_files() -> None:
    assert len(MOT_FILES) >= 40


@pytest.mark.parametrize("path", MOT_FILES, ids=lambda p: str(p.relative_to(DATA)))
def test_every_shared_mot_reads_and_is_classified(path: Path) -> None:
    table = read_table(path)
    rows = _raw_rows(path)
    assert table.data.shape == (len(rows), len(rows[0]) - 1)
    np.testing.assert_array_equal(table.time, [float(r[0]) for r in rows])
    assert table.data[-1, -1] == float(rows[-1][-1])
    expected_plates = _plates_for(path)
    assert is_force_table(table) == (expected_plates is not None)
    if expected_plates is None:  # coordinates: expert IK results
        assert table.header["inDegrees"] == "yes" and "pelvis_tx" in table.column_names
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # moment conversions: tested below
        forces = read_forces(path)
    assert tuple(p.name for p in forces.plates) == expected_plates
    vertical = sum(p.force[:, 1] for p in forces.plates)
    mass = _mass_for(path)
    if mass is None:  # mass unknown: a person's peak is 0.5-2.5 kN
        assert 500 < vertical.max() < 2500
    else:  # walking/running 1-3 BW, drop-jump landing up to 5 BW
        upper = 5.0 if "DJ1" in path.as_posix() else 3.0
        assert 1.0 < vertical.max() / (mass * G) < upper
    for plate in forces.plates:
        loaded = plate.force[:, 1] > 100
        if loaded.sum() > 10:
            # free moment at the CoP of a horizontal plate is vertical (after any conversion)
            horizontal = np.hypot(plate.free_moment[loaded, 0], plate.free_moment[loaded, 2])
            assert np.median(horizontal) < 1.0


def test_force_file_reads_whole(shared_data: Path) -> None:
    # a 2000 Hz force file (its read time: tests/benchmarks/bench_io.py)
    forces = read_forces(shared_data / "trials/rajagopal2016/grf_walk.mot")
    assert forces.n_frames == 4778 and forces.rate_hz == 2000.0


# ----------------------------------------------------------------------------- odd headers


def test_datacolumns_header_blank_line_and_unnumbered_plate(shared_data: Path) -> None:
    path = shared_data / "trials/stairdown/grf.mot"
    lines = path.read_text().splitlines()
    assert lines[4] == "endheader" and lines[5] == ""
    table = read_table(path)
    assert table.header["datarows"] == "4500" and table.header["range"].startswith("1.0")
    forces = read_forces(path)
    assert [p.name for p in forces.plates] == ["0", "1"]  # ground_force_* and 1_ground_force_*
    assert forces.rate_hz == 1000.0 and forces.time[0] == 0.001
    # the second plate's moment columns are 1_ground_torque_*
    groups = group_plates(table.column_names)
    assert groups[1].moment == ("1_ground_torque_x", "1_ground_torque_y", "1_ground_torque_z")


def test_trailing_tab_column_and_name_line(shared_data: Path) -> None:
    path = shared_data / "trials/opencap_uhlrich2023/walking1/grf.mot"
    names_line = path.read_text().splitlines()[5]
    assert names_line.endswith("ground_torque_z\t")
    table = read_table(path)
    assert len(table.column_names) == 18 and table.column_names[-1] == "L_ground_torque_z"
    assert table.header["name"].startswith("C:/MyDriveSym")


def test_tab_padded_header_and_padded_names(shared_data: Path) -> None:
    path = shared_data / "trials/rajagopal2016/grf_run.mot"
    assert path.read_text().splitlines()[4].startswith("endheader\t\t")
    table = read_table(path)
    assert table.header["name"] == "grf_run.mot"
    assert table.column_names[0] == "R_ground_force_vx"  # padding removed
    forces = read_forces(path)
    assert forces.rate_hz == 1000.0 and forces.time[0] == 0.23


def test_opensim4_header(shared_data: Path) -> None:
    table = read_table(shared_data / "trials/camargo2021_levelground/grf.mot")
    assert table.header["version"] == "3" and table.header["OpenSimVersion"] == "4.1"
    assert table.header["DataType"] == "double"
    assert "name" not in table.header


def test_free_text_header_lines(shared_data: Path) -> None:
    table = read_table(shared_data / "expert_comparison/Expert1/DJ1.mot")
    assert table.header["name"] == "Coordinates"
    assert "Units are S.I. units" in table.header["comment"]


# ----------------------------------------------------------------------------- coordinates


def test_coordinates_converted_by_motion_type(shared_data: Path) -> None:
    path = shared_data / "expert_comparison/Expert1/walking1.mot"
    raw = read_table(path)
    q = read_coordinates(path)
    assert q.header["inDegrees"] == "no" and q.header["inDegrees_file"] == "yes"
    np.testing.assert_allclose(
        q.column("hip_flexion_r"), np.deg2rad(raw.column("hip_flexion_r")), rtol=1e-15, atol=0
    )
    # translations and the coupled patella coordinate are not converted ...
    np.testing.assert_array_equal(q.column("pelvis_ty"), raw.column("pelvis_ty"))
    np.testing.assert_array_equal(q.column("knee_angle_r_beta"), raw.column("knee_angle_r_beta"))
    # ... and indeed OpenSim wrote knee_angle_r_beta in radians: it equals the knee angle
    np.testing.assert_allclose(q.column("knee_angle_r_beta"), q.column("knee_angle_r"), atol=1e-6)
    assert 0.9 < np.median(q.column("pelvis_ty")) < 1.0  # metres


def test_coordinates_with_explicit_rotational_set(shared_data: Path) -> None:
    path = shared_data / "expert_comparison/Expert1/walking1.mot"
    q = read_coordinates(path, rotational={"hip_flexion_r"})
    raw = read_table(path)
    np.testing.assert_array_equal(q.column("knee_angle_r"), raw.column("knee_angle_r"))
    assert np.max(np.abs(q.column("hip_flexion_r"))) < 1.0  # rad, was ~25 deg


def test_default_rotational_heuristic() -> None:
    names = [
        "pelvis_tilt",
        "pelvis_tx",
        "pelvis_ty",
        "pelvis_tz",
        "knee_angle_r_beta",
        "knee_translation_x",
        "ankle_angle_l",
    ]
    assert default_rotational(names) == {"pelvis_tilt", "ankle_angle_l"}


def test_missing_in_degrees_needs_a_decision(tmp_path: Path) -> None:
    path = tmp_path / "q.mot"
    path.write_text("Coordinates\nendheader\ntime\thip\n0\t10\n0.1\t20\n")
    with pytest.raises(MotFormatError, match="inDegrees"):
        read_coordinates(path)
    np.testing.assert_allclose(
        read_coordinates(path, in_degrees=True).column("hip"), np.deg2rad([10, 20])
    )


# ----------------------------------------------------------------------------- moments


def test_moments_about_plate_origins_are_converted_with_warnings(shared_data: Path) -> None:
    """Each of the six plates writes its moment about a point (plate 2: the lab origin), not
    the free moment at the CoP, and its warning names that point. Physics checks both the
    point and the conversion: on a horizontal plate the free moment at the CoP is vertical,
    so moving the written moment from the named point (as printed, to the mm) to the CoP,
    M - (cop - o) x F, must leave no horizontal moment, and so must the reader's result."""
    path = shared_data / "trials/camargo2021_levelground/grf.mot"
    with pytest.warns(UserWarning) as record:
        forces = read_forces(path)
    messages = [str(w.message) for w in record]
    assert len(messages) == 6
    assert "plate 2: the moment columns are moments about the lab origin" in messages[1]
    raw = read_forces(path, moment_reference="cop")  # as written, no warning
    for k, (message, plate, written) in enumerate(
        zip(messages, forces.plates, raw.plates, strict=True)
    ):
        assert f"plate {k + 1}: the moment columns are moments about the " in message
        named = re.search(r"about the point \(([^)]*)\) m", message)
        origin = np.array([float(v) for v in named.group(1).split(",")]) if named else np.zeros(3)
        loaded = written.force[:, 1] > 100
        as_written = written.free_moment[loaded]
        about_cop = as_written - np.cross(written.cop[loaded] - origin, written.force[loaded])
        converted = plate.free_moment[loaded]
        assert np.median(np.hypot(as_written[:, 0], as_written[:, 2])) > 20, k  # not a free moment
        assert np.median(np.hypot(about_cop[:, 0], about_cop[:, 2])) < 1.0, k  # the named point
        assert np.median(np.hypot(converted[:, 0], converted[:, 2])) < 0.5, k
        assert np.median(np.abs(converted[:, 1])) < 20, k  # free moments are small


def test_moments_about_lab_origin_treadmill(shared_data: Path) -> None:
    path = shared_data / "trials/initial_off_treadmill/grf.mot"
    with pytest.warns(UserWarning, match="about the lab origin"):
        forces = read_forces(path)
    raw = read_forces(path, moment_reference="cop")
    p, r = forces.plates[0], raw.plates[0]
    np.testing.assert_allclose(p.free_moment, r.free_moment - np.cross(r.cop, r.force))
    origin = read_forces(path, moment_reference="origin")
    np.testing.assert_array_equal(origin.plates[0].free_moment, p.free_moment)


def test_opensim_convention_files_are_not_touched(shared_data: Path) -> None:
    path = shared_data / "trials/rajagopal2016/grf_walk.mot"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        forces = read_forces(path)
    table = read_table(path)
    np.testing.assert_array_equal(
        forces.plates[0].free_moment[:, 1], table.column("ground_torque_r_y")
    )


@pytest.mark.parametrize("seed", range(4))
def test_detect_reference_recovers_a_known_point(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 200
    force = np.column_stack([rng.normal(0, 50, n), rng.uniform(200, 900, n), rng.normal(0, 50, n)])
    cop = np.column_stack([rng.uniform(0, 0.5, n), np.full(n, 0.01), rng.uniform(-0.3, 0.3, n)])
    tau = np.column_stack([np.zeros(n), rng.normal(0, 5, n), np.zeros(n)])
    point = rng.uniform(-3, 3, 3)
    moment = tau + np.cross(cop - point, force)
    ref = detect_reference(force, cop, moment)
    assert ref is not None and ref.kind == "point"
    np.testing.assert_allclose(ref.point, point, atol=1e-9)
    assert detect_reference(force, cop, tau).kind == "cop"
    assert detect_reference(force, cop, tau + np.cross(cop, force)).kind == "origin"


# ----------------------------------------------------------------------------- broken input


@pytest.fixture
def grf_lines(shared_data: Path) -> list[str]:
    """Lines of the rajagopal walk GRF file (header lines 1-6, names line 7, data from 8)."""
    return (shared_data / "trials/rajagopal2016/grf_walk.mot").read_text().splitlines()


def _damaged(tmp_path: Path, lines: list[str]) -> Path:
    return damaged(tmp_path, lines, ".mot")


def _expect(
    path: Path, line: int | None, *words: str, reader: Callable[[Path], object] = read_table
) -> MotFormatError:
    return expect_format_error(MotFormatError, reader, path, line, *words)


def test_truncated_file(tmp_path: Path, grf_lines: list[str]) -> None:
    _expect(_damaged(tmp_path, grf_lines[:1000]), 1000, "4778 rows", "993", "truncated")


def test_truncated_inside_a_row(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = [*grf_lines[:500], grf_lines[500][:30]]
    _expect(_damaged(tmp_path, lines), 501, "expected 19 values")


def test_a_repeated_time_is_named_in_seconds_as_the_file_writes_it(tmp_path: Path, grf_lines: list[str]) -> None:
    """A row written twice: the error names the line and the two times as plain numbers of
    seconds."""
    lines = list(grf_lines)
    lines.insert(100, lines[99])
    lines[2] = lines[2].replace("nRows=4778", "nRows=4779")
    t = lines[99].split("\t")[0]
    err = _expect(_damaged(tmp_path, lines), 101, "does not increase")
    assert f"time {float(t)!r} s does not increase (previous row: {float(t)!r} s)" in str(err), str(err)


def test_wrong_column_count(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = list(grf_lines)
    lines[99] = lines[99] + "\t0.0"
    _expect(_damaged(tmp_path, lines), 100, "expected 19 values", "found 20")


def test_text_in_a_number_field(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = list(grf_lines)
    cells = lines[299].split("\t")
    cells[4] = "1,5"  # column 5: time, vx, vy, vz, px
    lines[299] = "\t".join(cells)
    err = _expect(_damaged(tmp_path, lines), 300, "'1,5'", "ground_force_r_px")
    assert err.where == "ground_force_r_px"


def test_missing_endheader(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = [line for line in grf_lines if line != "endheader"]
    _expect(_damaged(tmp_path, lines), len(lines) + 1, "endheader")


def test_duplicate_columns(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = list(grf_lines)
    lines[6] = lines[6].replace("ground_force_l_vz", "ground_force_l_vy")
    err = _expect(_damaged(tmp_path, lines), 7, "'ground_force_l_vy'", "twice")
    assert err.where == "ground_force_l_vy"


def test_first_column_not_time(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = list(grf_lines)
    lines[6] = lines[6].replace("time", "t", 1)
    _expect(_damaged(tmp_path, lines), 7, "'time'")


def test_column_count_differs_from_header(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = [line.replace("nColumns=19", "nColumns=20") for line in grf_lines]
    err = _expect(_damaged(tmp_path, lines), None, "20 columns", "19")
    assert err.where == "header"


def test_incomplete_plate(tmp_path: Path, grf_lines: list[str]) -> None:
    lines = list(grf_lines)
    lines[6] = lines[6].replace("ground_force_l_vz", "other_column")
    err = _expect(_damaged(tmp_path, lines), None, "plate 'l'", reader=read_forces)
    assert err.where == "plate l"


def test_not_a_force_file(shared_data: Path) -> None:
    path = shared_data / "expert_comparison/Expert1/walking1.mot"
    _expect(path, None, "no ground reaction force columns", reader=read_forces)


def test_empty_and_header_only_files(tmp_path: Path) -> None:
    empty = tmp_path / "empty.mot"
    empty.write_text("\n\n")
    _expect(empty, 1, "empty")
    header_only = tmp_path / "header.mot"
    header_only.write_text("name\nendheader\n")
    _expect(header_only, 3, "ends after 'endheader'")


# ----------------------------------------------------------------------------- round trips


def _same_recording(a: ForceRecording, b: ForceRecording) -> None:
    assert a.rate_hz == b.rate_hz
    np.testing.assert_array_equal(a.time, b.time)
    assert [p.name for p in a.plates] == [p.name for p in b.plates]
    for p, q in zip(a.plates, b.plates, strict=True):
        for field in ("force", "cop", "free_moment"):
            np.testing.assert_array_equal(getattr(p, field), getattr(q, field))


def test_real_forces_round_trip_exactly(shared_data: Path, tmp_path: Path) -> None:
    for rel in ("trials/stairdown/grf.mot", "trials/opencap_uhlrich2023/DJ1/grf.mot"):
        forces = read_forces(shared_data / rel)
        path = tmp_path / "grf.mot"
        write_forces(path, forces)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # free moments stay free moments
            _same_recording(read_forces(path), forces)


@pytest.mark.parametrize("seed", range(5))
def test_random_forces_round_trip_exactly(tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 50
    time = np.cumsum(rng.uniform(0.5, 1.5, n)) * 1e-3
    plates = tuple(
        ForcePlate(
            name,
            rng.normal(size=(n, 3)) * 300,
            rng.normal(size=(n, 3)),
            rng.normal(size=(n, 3)) * 10,
        )
        for name in ("1", "r", "Left")
    )
    forces = ForceRecording(time, float(rng.uniform(100, 3000)), plates)
    path = tmp_path / "grf.mot"
    write_forces(path, forces)
    _same_recording(read_forces(path, moment_reference="cop"), forces)
    assert read_table(path).column_names[:3] == (
        "ground_force_1_vx",
        "ground_force_1_vy",
        "ground_force_1_vz",
    )


@pytest.mark.parametrize("seed", range(5))
def test_coordinates_in_degrees_round_trip_exactly(tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    names = ["pelvis_tilt", "pelvis_tx", "knee_angle_r", "knee_angle_r_beta", "tiny"]
    q = rng.normal(size=(60, 5)) * np.array([1.0, 2.0, 3.0, 1.0, 1e-9])
    q[0] = [0.0, -0.0, np.pi, -np.pi / 2, 5e-324]
    time = np.arange(60) / 120.0
    rotational = {"pelvis_tilt", "knee_angle_r", "tiny"}
    path = tmp_path / "q.mot"
    write_coordinates(path, names, q, time, rotational=rotational)
    back = read_coordinates(path, rotational)
    assert back.column_names == tuple(names)
    np.testing.assert_array_equal(back.data, q)
    assert np.array_equal(np.signbit(back.data), np.signbit(q))
    np.testing.assert_array_equal(back.time, time)
    raw = read_table(path)  # the file holds degrees for rotational columns only
    np.testing.assert_allclose(raw.column("knee_angle_r"), np.rad2deg(q[:, 2]), rtol=1e-14)
    np.testing.assert_array_equal(raw.column("pelvis_tx"), q[:, 1])


@pytest.mark.parametrize("kind", ["mot", "sto"])
def test_table_round_trip_exactly(tmp_path: Path, kind: str) -> None:
    rng = np.random.default_rng(7)
    table = Table(
        ("a_moment", "b_force"),
        rng.normal(size=(30, 2)) * 1e3,
        np.arange(30) * 0.01,
        {"inDegrees": "no", "Custom": "kept"},
    )
    path = tmp_path / f"t.{kind}"
    write_table(path, table, kind=kind)
    back = read_table(path)
    assert back.column_names == table.column_names
    np.testing.assert_array_equal(back.data, table.data)
    np.testing.assert_array_equal(back.time, table.time)
    assert back.header["Custom"] == "kept" and back.header["inDegrees"] == "no"
    assert back.header["nRows"] == "30" and back.header["nColumns"] == "3"


def test_writer_rejects_bad_names_and_time(tmp_path: Path) -> None:
    with pytest.raises(MotFormatError, match="repeated"):
        write_table(tmp_path / "x.mot", Table(("a", "a"), np.zeros((2, 2)), np.arange(2.0)))
    with pytest.raises(MotFormatError, match="time must increase"):
        write_table(tmp_path / "x.mot", Table(("a",), np.zeros((2, 1)), np.zeros(2)))


def test_force_columns_naming_schemes() -> None:
    assert classify("ground_force_r_vx") == ("r", "force", 0)
    assert classify("R_ground_force_py") == ("R", "cop", 1)
    assert classify("1_ground_force_vz") == ("1", "force", 2)
    assert classify("ground_force_1_mx") == ("1", "moment", 0)
    assert classify("ground_torque_l_y") == ("l", "moment", 1)
    assert classify("ground_force_vx") == ("0", "force", 0)
    assert classify("pelvis_tx") is None and classify("time") is None


# ----------------------------------------------------------------------------- OpenSim


@pytest.mark.opensim
def test_opensim_reads_written_forces_coordinates_and_sto(
    shared_data: Path, tmp_path: Path
) -> None:
    opensim = import_tool("opensim", reason=OPENSIM_REASON)
    forces = read_forces(shared_data / "trials/rajagopal2016/grf_walk.mot")
    grf = tmp_path / "grf.mot"
    write_forces(grf, forces)
    table = opensim.TimeSeriesTable(str(grf))
    assert (table.getNumRows(), table.getNumColumns()) == (4778, 18)
    col = table.getDependentColumn("ground_force_r_vy").to_numpy()
    np.testing.assert_array_equal(col, forces.plates[0].force[:, 1])
    storage = opensim.Storage(str(grf))
    assert storage.getSize() == 4778 and storage.getColumnLabels().getSize() == 19

    q = read_coordinates(shared_data / "expert_comparison/Expert1/walking1.mot")
    rot = default_rotational(q.column_names)
    coords = tmp_path / "q.mot"
    write_coordinates(coords, q.column_names, q.data, q.time, rotational=rot)
    table = opensim.TimeSeriesTable(str(coords))
    assert table.getTableMetaDataAsString("inDegrees") == "yes"
    hip = table.getDependentColumn("hip_flexion_r").to_numpy()
    np.testing.assert_allclose(hip, np.rad2deg(q.column("hip_flexion_r")), rtol=1e-13)
    storage = opensim.Storage(str(coords))
    assert storage.isInDegrees() and storage.getSize() == q.time.shape[0]

    sto = tmp_path / "t.sto"
    write_table(sto, q, kind="sto")
    table = opensim.TimeSeriesTable(str(sto))
    assert table.getNumRows() == q.time.shape[0]
    np.testing.assert_array_equal(
        table.getDependentColumn("pelvis_tx").to_numpy(), q.column("pelvis_tx")
    )


@pytest.mark.parametrize(
    ("name", "expected"),
    [("Coordinates", "Coordinates"), ("a=b", "a-b"), ("range of motion", "table range of motion")],
)
def test_table_name_line_reads_back(tmp_path: Path, name: str, expected: str) -> None:
    path = tmp_path / "named.mot"
    write_table(path, Table(("a",), np.zeros((2, 1)), np.arange(2.0), {"name": name}))
    back = read_table(path)
    assert back.header["name"] == expected
    assert back.column_names == ("a",)  # the name line never swallows the header
