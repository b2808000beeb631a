"""Bad .osim input gives an OsimModelError naming the file, the line and the element."""

from __future__ import annotations

from pathlib import Path

import pytest

from solver.errors import OsimModelError
from solver.model.osim import read_osim
from tests.conftest import import_tool
from tests.model.conftest import MODELS

SOURCE = (MODELS / "Rajagopal2016.osim").read_text()


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "broken.osim"
    p.write_text(text)
    return p


def test_unsupported_joint_type(tmp_path: Path) -> None:
    text = SOURCE.replace('<PinJoint name="ankle_r">', '<EllipsoidJoint name="ankle_r">', 1)
    text = text.replace("</PinJoint>", "</EllipsoidJoint>", 1)
    p = _write(tmp_path, text)
    with pytest.raises(OsimModelError, match=r"EllipsoidJoint is not supported") as err:
        read_osim(p)
    assert str(p) in str(err.value) and "ankle_r" in str(err.value)


def test_unsupported_function(tmp_path: Path) -> None:
    start = SOURCE.index('<SimmSpline name="function">')
    end = SOURCE.index("</SimmSpline>", start) + len("</SimmSpline>")
    text = SOURCE[:start] + '<Sine name="function"><amplitude>1</amplitude></Sine>' + SOURCE[end:]
    with pytest.raises(OsimModelError, match="function type Sine is not supported"):
        read_osim(_write(tmp_path, text))


def test_not_xml(tmp_path: Path) -> None:
    with pytest.raises(OsimModelError, match="not well-formed") as err:
        read_osim(_write(tmp_path, SOURCE[: len(SOURCE) // 2]))
    assert err.value.line is not None


def test_text_in_a_number_field(tmp_path: Path) -> None:
    text = SOURCE.replace("<mass>11.776999999999999</mass>", "<mass>eleven</mass>", 1)
    assert text != SOURCE
    with pytest.raises(OsimModelError, match=r"<mass> must hold numbers.*eleven") as err:
        read_osim(_write(tmp_path, text))
    assert "pelvis" in str(err.value)
    assert err.value.line == text[: text.index('<Body name="pelvis">')].count("\n") + 1


def test_marker_on_unknown_body(tmp_path: Path) -> None:
    text = SOURCE.replace("<socket_parent_frame>/bodyset/torso</socket_parent_frame>", "<socket_parent_frame>/bodyset/tail</socket_parent_frame>", 1)
    with pytest.raises(OsimModelError, match="neither a body nor an offset frame"):
        read_osim(_write(tmp_path, text))


def test_coupler_with_unknown_coordinate(tmp_path: Path) -> None:
    text = SOURCE.replace("<dependent_coordinate_name>knee_angle_r_beta</dependent_coordinate_name>",
                          "<dependent_coordinate_name>knee_beta</dependent_coordinate_name>", 1)
    with pytest.raises(OsimModelError, match="unknown coordinate 'knee_beta'"):
        read_osim(_write(tmp_path, text))


def test_missing_file_raises_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_osim(tmp_path / "nope.osim")


def test_two_markers_of_one_name_are_refused(tmp_path: Path) -> None:
    start = SOURCE.index('<Marker name="')
    end = SOURCE.index("</Marker>", start) + len("</Marker>")
    text = SOURCE[:end] + SOURCE[start:end] + SOURCE[end:]  # the first marker twice
    name = SOURCE[start:].split('"')[1]
    with pytest.raises(OsimModelError, match=f"two marker components are named '{name}'") as err:
        read_osim(_write(tmp_path, text))
    assert "MarkerSet" in str(err.value)


def test_two_bodies_of_one_name_are_named_as_such(tmp_path: Path) -> None:
    text = SOURCE.replace('<Body name="tibia_r">', '<Body name="femur_r">', 1)
    assert text != SOURCE
    with pytest.raises(OsimModelError, match="two body components are named 'femur_r'"):
        read_osim(_write(tmp_path, text))


def test_a_model_without_mass_is_refused(tmp_path: Path) -> None:
    import re

    text = re.sub(r"<mass>[^<]*</mass>", "<mass>0</mass>", SOURCE)
    with pytest.raises(OsimModelError, match="every body has zero mass"):
        read_osim(_write(tmp_path, text))


def test_a_coordinate_range_with_min_above_max_is_refused(tmp_path: Path) -> None:
    """OpenSim 4.6 refuses the model ("Maximum coordinate range less than minimum"); addb
    read it as the range turned round, with nothing said. Min equal to max stays valid."""
    start = SOURCE.index('<Coordinate name="knee_angle_r"')
    lo = SOURCE.index("<range>", start)
    hi = SOURCE.index("</range>", lo) + len("</range>")
    text = SOURCE[:lo] + "<range>2.0944 0</range>" + SOURCE[hi:]
    with pytest.raises(OsimModelError, match=r"<range> 2.0944 0: the minimum is above the maximum") as err:
        read_osim(_write(tmp_path, text))
    assert "knee_angle_r" in str(err.value) and "broken.osim" in str(err.value)
    line = text[:start].count("\n") + 1  # where <Coordinate name="knee_angle_r"> starts
    assert err.value.line == line and f"broken.osim:{line}," in str(err.value)
    opensim = import_tool("opensim")  # the oracle refuses the same file
    with pytest.raises(Exception, match="Maximum coordinate range less than minimum"):
        opensim.Model(str(tmp_path / "broken.osim")).initSystem()
    model = read_osim(_write(tmp_path, SOURCE[:lo] + "<range>0.5 0.5</range>" + SOURCE[hi:]))
    (knee,) = [c for c in model.coordinates if c.name == "knee_angle_r"]
    assert knee.range == (0.5, 0.5)
