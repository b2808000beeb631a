"""ExternalLoads XML (read, write, OpenSim 4.6 loads ours, plate mapping) and review files
(the one reader, solver.io.review, against the one writer, annotations.addb)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from annotations.addb import write_addb_review
from solver.errors import FileFormatError, XmlFormatError
from solver.io.external_loads import (
    ExternalForce,
    ExternalLoads,
    plates_by_force,
    read_external_loads,
    write_external_loads,
)
from solver.io.mot import read_forces, read_table
from solver.io.review import read_review
from tests.conftest import OPENSIM_REASON, import_tool
from tests.conftest import SHARED_DATA as DATA

LOADS = sorted(DATA.rglob("grf_*.xml"))
REVIEWS = sorted(DATA.rglob("*review*.json"))


def test_external_loads_files_are_shared() -> None:
    assert [p.name for p in LOADS] == ["grf_run.xml", "grf_walk.xml"]


@pytest.mark.parametrize("path", LOADS, ids=lambda p: p.name)
def test_read_external_loads(path: Path) -> None:
    loads = read_external_loads(path)
    assert loads.name == path.stem
    assert [f.applied_to_body for f in loads.forces] == ["calcn_r", "calcn_l"]
    assert all(f.force_expressed_in_body == "ground" for f in loads.forces)
    assert loads.datafile == f"../ExpData/{path.stem}.mot"
    right = loads.forces[0]
    side = "r" if "walk" in path.name else "R"
    prefix = f"ground_force_{side}_" if side == "r" else f"{side}_ground_force_"
    assert right.force_identifier == prefix + "v"
    assert right.point_identifier == prefix + "p"
    torque = "ground_torque_r_" if side == "r" else "R_ground_torque_"
    assert right.torque_identifier == torque


@pytest.mark.parametrize("path", LOADS, ids=lambda p: p.name)
def test_identifiers_map_to_the_plates_of_the_data_file(path: Path) -> None:
    loads = read_external_loads(path)
    data = path.with_suffix(".mot")  # the datafile path in the XML points elsewhere
    mapping = plates_by_force(loads, read_table(data).column_names)
    names = [p.name for p in read_forces(data).plates]
    assert list(mapping.values()) == names  # right -> r/R, left -> l/L
    assert mapping[loads.forces[0].name].lower() == "r"


@pytest.mark.parametrize("path", LOADS, ids=lambda p: p.name)
def test_external_loads_round_trip(path: Path, tmp_path: Path) -> None:
    loads = read_external_loads(path)
    out = tmp_path / "loads.xml"
    write_external_loads(out, loads)
    back = read_external_loads(out)
    assert (back.name, back.forces, back.datafile) == (loads.name, loads.forces, loads.datafile)


@pytest.mark.opensim
def test_opensim_loads_written_external_loads(tmp_path: Path) -> None:
    opensim = import_tool("opensim", reason=OPENSIM_REASON)
    loads = ExternalLoads(
        "plates",
        (
            ExternalForce("right", "calcn_r", force_identifier="ground_force_1_v",
                          point_identifier="ground_force_1_p",
                          torque_identifier="ground_torque_1_"),
            ExternalForce("left", "calcn_l", force_identifier="ground_force_2_v",
                          point_identifier="ground_force_2_p"),
        ),
        datafile="grf.mot",
    )  # fmt: skip
    out = tmp_path / "loads.xml"
    write_external_loads(out, loads)
    osim = opensim.ExternalLoads(str(out), True)
    assert osim.getSize() == 2 and osim.getDataFileName() == "grf.mot"
    assert osim.get(0).getName() == "right"
    assert osim.get(0).get_applied_to_body() == "calcn_r"
    assert osim.get(0).get_force_identifier() == "ground_force_1_v"
    assert osim.get(0).get_torque_identifier() == "ground_torque_1_"
    assert osim.get(1).get_point_identifier() == "ground_force_2_p"


def test_not_external_loads(shared_data: Path) -> None:
    path = shared_data / "trials/rajagopal2016/id_setup_walk.xml"
    with pytest.raises(XmlFormatError, match="expected an <ExternalLoads>") as info:
        read_external_loads(path)
    assert info.value.path == str(path) and info.value.where == "OpenSimDocument"


def test_malformed_xml_reports_the_line(shared_data: Path, tmp_path: Path) -> None:
    lines = (shared_data / "trials/rajagopal2016/grf_walk.xml").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if "</force_identifier>" in line)
    lines[k] = lines[k].replace("</force_identifier>", "")  # unclosed element
    bad = tmp_path / "bad.xml"
    bad.write_text("\n".join(lines))
    with pytest.raises(XmlFormatError, match="not well-formed") as info:
        read_external_loads(bad)
    # the parser notices at the parent's closing tag, a few lines below
    assert info.value.line is not None and k + 1 <= info.value.line <= k + 6


def test_external_force_without_body(shared_data: Path, tmp_path: Path) -> None:
    text = (shared_data / "trials/rajagopal2016/grf_walk.xml").read_text()
    bad = tmp_path / "nobody.xml"
    bad.write_text(text.replace("<applied_to_body>calcn_l</applied_to_body>", ""))
    with pytest.raises(XmlFormatError, match="applied_to_body") as info:
        read_external_loads(bad)
    assert info.value.where == "ExternalForce Left_GRF"


def test_identifier_without_plate(shared_data: Path) -> None:
    loads = read_external_loads(shared_data / "trials/rajagopal2016/grf_walk.xml")
    columns = read_table(shared_data / "trials/rajagopal2016/grf_run.mot").column_names
    with pytest.raises(XmlFormatError, match="'ground_force_r_v' matches no plate"):
        plates_by_force(loads, columns)


# ----------------------------------------------------------------------------- review files


def test_review_files_are_shared() -> None:
    assert len(REVIEWS) == 2


@pytest.mark.parametrize("path", REVIEWS, ids=lambda p: p.parent.name)
def test_review_round_trip_is_byte_identical(path: Path, tmp_path: Path) -> None:
    mask = read_review(path)
    assert mask.dtype == bool and mask.ndim == 1
    assert mask.shape[0] == path.read_text().count("true") + path.read_text().count("false")
    out = tmp_path / path.name
    write_addb_review(out, mask)
    assert out.read_bytes() == path.read_bytes()


def test_walking_review_flags_the_first_frames(shared_data: Path) -> None:
    mask = read_review(
        shared_data / "trials/opencap_uhlrich2023/walking1/addb_review_segment_1.json"
    )
    assert mask[:24].all() and not mask[24:].any()


def test_random_review_round_trip(tmp_path: Path) -> None:
    mask = np.random.default_rng(3).random(500) < 0.3
    path = tmp_path / "review.json"
    write_addb_review(path, mask)
    np.testing.assert_array_equal(read_review(path), mask)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ('{"missing_grf_data": [true, 1]}', "missing_grf_data[1]"),
        ('{"other": []}', "'missing_grf_data'"),
        ('{"missing_grf_data": "yes"}', "list of true/false"),
        ('{"missing_grf_data": [true,\n', "not valid JSON"),
    ],
)
def test_broken_review_files(tmp_path: Path, text: str, words: str) -> None:
    path = tmp_path / "review.json"
    path.write_text(text)
    with pytest.raises(FileFormatError) as info:
        read_review(path)
    assert words in str(info.value) and info.value.path == str(path)


def test_review_length_is_checked_against_the_trial(tmp_path: Path) -> None:
    """``n_frames``: extra trailing entries (old AddBiomechanics UI) are dropped with a
    warning, fewer entries than the trial's frames are an error naming the file."""
    path = tmp_path / "review.json"
    write_addb_review(path, np.array([True, False, False, True]))
    with pytest.warns(UserWarning, match="1 extra trailing entries dropped"):
        np.testing.assert_array_equal(read_review(path, n_frames=3), [True, False, False])
    np.testing.assert_array_equal(read_review(path, n_frames=4), [True, False, False, True])
    with pytest.raises(FileFormatError, match="4 entries for a trial or segment of 5 marker frames") as info:
        read_review(path, n_frames=5)
    assert info.value.path == str(path)
