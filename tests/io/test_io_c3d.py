"""C3D reading: markers and plates in the OpenSim frame, physical checks on the two walking
trials, agreement with ezc3d's own CoP, the axis rotation, and damaged files."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from solver.errors import C3dFormatError
from solver.io.c3d import read_c3d, rotation_to_opensim
from solver.io.types import ForceRecording, MarkerTrajectories
from tests.conftest import SHARED_DATA as DATA

C3D_FILES = sorted(DATA.rglob("*.c3d"))
FOOT = ("CAL", "MT1", "MT2", "MAL")
Loaded = tuple[Path, MarkerTrajectories, ForceRecording]


@pytest.fixture(scope="module", params=C3D_FILES, ids=lambda p: p.name)
def trial(request: pytest.FixtureRequest) -> Loaded:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the plates report the reaction on the body: no flip
        markers, forces = read_c3d(request.param)
    return request.param, markers, forces


def test_two_c3d_files_are_shared() -> None:
    assert [p.name for p in C3D_FILES] == ["walking2.c3d", "walking5.c3d"]


def test_markers_in_metres_above_the_floor(trial: Loaded) -> None:
    """Every marker value is ezc3d's raw point (lab mm, Z up) mapped by hand to OpenSim's
    frame, (x, y, z) -> (x, z, -y) / 1000 (both files: X_SCREEN=+X, Y_SCREEN=+Z), in the
    file's label order, NaN exactly where ezc3d has no point; then the physical checks."""
    path, markers, _ = trial
    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    axes = (point["X_SCREEN"]["value"], point["Y_SCREEN"]["value"], point["UNITS"]["value"])
    assert axes == (["+X"], ["+Z"], ["mm"])
    assert list(markers.names) == [s.strip() for s in point["LABELS"]["value"]]
    raw = np.asarray(c3d["data"]["points"][:3]).transpose(2, 1, 0)  # (T, M, 3), lab mm
    expected = np.stack([raw[..., 0], raw[..., 2], -raw[..., 1]], axis=-1) / 1000.0
    np.testing.assert_allclose(markers.positions, expected, rtol=0, atol=1e-12)  # NaN where NaN
    assert markers.rate_hz == 250.0
    first = c3d["header"]["points"]["first_frame"]
    np.testing.assert_allclose(markers.time, (first + np.arange(raw.shape[0])) * 0.004)
    y = markers.positions[:, :, 1]
    assert np.nanmin(y) > -0.01  # Y up: nothing below the floor
    assert 0.85 < np.nanmedian(markers.marker("RASI")[:, 1]) < 1.15  # pelvis ~1 m
    assert 1.3 < np.nanmedian(markers.marker("C7")[:, 1]) < 1.7
    assert np.isnan(markers.positions).any()  # gaps of the Vicon export are kept as NaN


def test_two_plates_with_corners_on_the_floor(trial: Loaded) -> None:
    _, markers, forces = trial
    assert forces is not None and [p.name for p in forces.plates] == ["1", "2"]
    np.testing.assert_array_equal(forces.time, markers.time)
    for plate in forces.plates:
        assert plate.corners.shape == (4, 3)
        np.testing.assert_allclose(plate.corners[:, 1], 0.0, atol=1e-9)  # floor level, Y up
        extent = np.ptp(plate.corners, axis=0)
        assert 0.4 < extent[0] < 0.7 and 0.4 < extent[2] < 1.3  # plate sizes in metres


def test_stance_force_is_upward_about_body_weight(trial: Loaded) -> None:
    _, _, forces = trial
    peaks = []
    for plate in forces.plates:
        vertical = plate.force[:, 1]
        stance = vertical > 100
        assert stance.sum() > 80  # one stance of ~0.5 s at 250 Hz
        assert np.median(vertical[stance]) > 300  # upward, not a sign-flipped plate
        peaks.append(vertical.max())
    # walking peaks are 1.0-1.3 BW of an adult: 600-1400 N, and similar for both feet
    assert all(600 < p < 1400 for p in peaks)
    assert max(peaks) / min(peaks) < 1.3


def test_cop_inside_the_plate_during_stance(trial: Loaded) -> None:
    _, _, forces = trial
    for plate in forces.plates:
        stance = plate.force[:, 1] > 0.2 * plate.force[:, 1].max()
        lo, hi = plate.corners.min(axis=0), plate.corners.max(axis=0)
        cop = plate.cop[stance]
        # 3 cm margin: heel strike on the plate edge puts the CoP just outside
        margin = 0.03
        assert np.all(cop[:, [0, 2]] > lo[[0, 2]] - margin)
        assert np.all(cop[:, [0, 2]] < hi[[0, 2]] + margin)
        np.testing.assert_allclose(cop[:, 1], 0.0, atol=1e-9)  # on the plate surface
        # the free moment at the CoP is about the plate normal (vertical) only
        np.testing.assert_allclose(plate.free_moment[stance][:, [0, 2]], 0.0, atol=1e-9)
        assert np.abs(plate.free_moment[stance][:, 1]).max() < 15.0  # N*m


def test_cop_is_under_a_foot(trial: Loaded) -> None:
    """Markers and plates are in the same frame: a wrong axis map would put feet elsewhere."""
    _, markers, forces = trial
    foot = [n for n in markers.names if any(k in n for k in FOOT)]
    idx = [markers.index(n) for n in foot]
    for plate in forces.plates:
        stance = np.flatnonzero(plate.force[:, 1] > 300)
        feet = markers.positions[stance][:, idx, :]
        horizontal = np.hypot(
            feet[:, :, 0] - plate.cop[stance, None, 0], feet[:, :, 2] - plate.cop[stance, None, 2]
        )
        assert np.nanmax(np.nanmin(horizontal, axis=1)) < 0.12


def test_matches_ezc3d_cop_and_free_moment(trial: Loaded) -> None:
    path, _, forces = trial
    c3d = ezc3d.c3d(str(path), extract_forceplat_data=True)
    rot = rotation_to_opensim(c3d["parameters"])
    for plate, raw in zip(forces.plates, c3d["data"]["platform"], strict=True):
        n = raw["force"].shape[1] // forces.n_frames
        frame = int(np.argmax(plate.force[:, 1]))
        sl = slice(frame * n, (frame + 1) * n)
        cop = rot @ raw["center_of_pressure"][:, sl].mean(axis=1) / 1000.0
        tz = rot @ raw["Tz"][:, sl].mean(axis=1) / 1000.0
        # averaging the wrench vs averaging ezc3d's per-sample CoP: equal within 0.1 mm
        np.testing.assert_allclose(plate.cop[frame], cop, atol=1e-4)
        np.testing.assert_allclose(plate.free_moment[frame], tz, atol=1e-2)
        # signed: the plates report the reaction on the body, so no component is negated
        force = rot @ raw["force"][:, sl].mean(axis=1)
        np.testing.assert_allclose(plate.force[frame], force, rtol=1e-12)


# ----------------------------------------------------------------------------- axes


def _params(x_screen: str | None = None, y_screen: str | None = None) -> dict:
    point = {}
    if x_screen:
        point["X_SCREEN"] = {"value": [x_screen]}
    if y_screen:
        point["Y_SCREEN"] = {"value": [y_screen]}
    return {"POINT": point}


def test_default_z_up_map() -> None:
    rot = rotation_to_opensim(_params())
    np.testing.assert_array_equal(rot @ [1.0, 2.0, 3.0], [1.0, 3.0, -2.0])  # (x, z, -y)


@pytest.mark.parametrize("up", ["+x", "-x", "+y", "-y", "+z", "-z", "Z", "y"])
def test_every_up_axis_gives_a_proper_rotation(up: str) -> None:
    rot = rotation_to_opensim(_params(), up_axis=up)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    axis = np.zeros(3)
    axis["xyz".index(up[-1].lower())] = -1.0 if up.startswith("-") else 1.0
    np.testing.assert_allclose(rot @ axis, [0.0, 1.0, 0.0])  # the lab's up becomes +Y


@pytest.mark.parametrize(
    ("x_screen", "y_screen"),
    [(a, b) for a, b in itertools.permutations(["+X", "-Y", "+Z", "-X", "+Y", "-Z"], 2)
     if a[-1] != b[-1]],
)  # fmt: skip
def test_screen_axes_give_proper_rotations(x_screen: str, y_screen: str) -> None:
    rot = rotation_to_opensim(_params(x_screen, y_screen))
    assert np.linalg.det(rot) == pytest.approx(1.0)
    right = np.zeros(3)
    right["XYZ".index(x_screen[-1])] = -1.0 if x_screen[0] == "-" else 1.0
    np.testing.assert_allclose(rot @ right, [1.0, 0.0, 0.0])


def test_invalid_up_axis() -> None:
    with pytest.raises(C3dFormatError, match="axis 'w'"):
        rotation_to_opensim(_params(), up_axis="w")


# ----------------------------------------------------------------------------- damaged


def test_truncated_c3d_is_reported(tmp_path: Path) -> None:
    source = C3D_FILES[0]
    path = tmp_path / "cut.c3d"
    path.write_bytes(source.read_bytes()[:20000])
    with pytest.raises(C3dFormatError) as info:
        read_c3d(path)
    assert "truncated" in info.value.message and "1249 frames" in info.value.message
    assert info.value.path == str(path) and info.value.where == "frame 13"


def test_not_a_c3d_file(tmp_path: Path) -> None:
    path = tmp_path / "text.c3d"
    path.write_text("this is a text file\n")
    with pytest.raises(C3dFormatError, match="ezc3d cannot read") as info:
        read_c3d(path)
    assert info.value.path == str(path)


def test_missing_c3d(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_c3d(tmp_path / "none.c3d")


def test_plates_reporting_the_force_on_the_plate_are_negated_with_a_warning(
    tmp_path: Path,
) -> None:
    source = C3D_FILES[1]
    c3d = ezc3d.c3d(str(source))
    c3d["data"]["analogs"] = -c3d["data"]["analogs"]  # action on the plate instead of reaction
    flipped = tmp_path / "flipped.c3d"
    c3d.write(str(flipped))
    _, reference = read_c3d(source)
    with pytest.warns(UserWarning, match="reports the force applied to the plate") as record:
        _, forces = read_c3d(flipped)
    assert len(record) == 2
    for a, b in zip(reference.plates, forces.plates, strict=True):
        np.testing.assert_array_equal(a.force, b.force)
        np.testing.assert_array_equal(a.cop, b.cop)
        np.testing.assert_array_equal(a.free_moment, b.free_moment)
