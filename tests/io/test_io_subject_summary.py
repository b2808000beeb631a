"""Subject folders, ``summarize``/``format_summary`` on every kind of shared file, and the
``addb info`` command on good, missing and broken input."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from solver.errors import FileFormatError, SubjectFolderError, TrcFormatError
from solver.io.subject import load_subject, load_trial
from solver.io.summary import format_summary, summarize
from tests.conftest import OPENSIM_REASON, import_tool, writable_copy
from tests.conftest import SHARED_DATA as DATA
from tests.opensim_tables import trc_times_by_hand

SUBJECTS = sorted(p for p in (DATA / "subjects").iterdir() if p.is_dir())
#: name -> (mass kg, height m, {trial: has forces}) from the data README and JSON files
EXPECTED = {
    "opencap_uhlrich2023": (75.7, 1.85, {"DJ1": True, "walking1": True}),
    "rajagopal2016_run": (72.84, 1.80, {"run": True, "static": False}),
    "rajagopal2016_walk": (85.0668, 1.829, {"static": False, "walk": True}),
}
G = 9.80665


def test_three_subjects_are_shared() -> None:
    assert [p.name for p in SUBJECTS] == sorted(EXPECTED)


@pytest.mark.parametrize("folder", SUBJECTS, ids=lambda p: p.name)
def test_subject_folders_load(folder: Path) -> None:
    subject = load_subject(folder)
    mass, height, trials = EXPECTED[folder.name]
    assert subject.name == folder.name and subject.path == folder
    assert subject.mass_kg == mass and subject.height_m == height
    assert subject.foot_body_names == ("calcn_r", "calcn_l")
    assert subject.disable_dynamics is False
    assert subject.model_path == folder / "unscaled_generic.osim"
    assert {t.name: t.forces_path is not None for t in subject.trials} == trials
    assert subject.raw["massKg"] == str(mass) or float(subject.raw["massKg"]) == mass
    for files in subject.trials:
        trial = load_trial(files)
        assert trial.name == files.name
        assert trial.markers.n_frames > 100
        if trial.forces is None:
            assert not trials[files.name]
            continue
        # force and marker recordings cover the same trial
        assert trial.forces.time[0] <= trial.markers.time[0] + 0.01
        assert trial.forces.time[-1] >= trial.markers.time[-1] - 0.01
        peak_bw = sum(p.force[:, 1] for p in trial.forces.plates).max() / (mass * G)
        assert 1.0 < peak_bw < (5.0 if files.name == "DJ1" else 3.0)


def _copy_subject(tmp_path: Path, name: str = "rajagopal2016_walk") -> Path:
    dest = tmp_path / name
    shutil.copytree(DATA / "subjects" / name, dest)
    return dest


def test_missing_mass_names_the_file_and_key(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    json_path = folder / "_subject.json"
    raw = json.loads(json_path.read_text())
    del raw["massKg"]
    json_path.write_text(json.dumps(raw))
    with pytest.raises(SubjectFolderError) as info:
        load_subject(folder)
    assert info.value.path == str(json_path) and info.value.where == "massKg"
    assert "massKg" in str(info.value) and "_subject.json" in str(info.value)


@pytest.mark.parametrize("value", ["heavy", -3, 0, True])
def test_bad_mass(tmp_path: Path, value: object) -> None:
    folder = _copy_subject(tmp_path)
    raw = json.loads((folder / "_subject.json").read_text())
    raw["massKg"] = value
    (folder / "_subject.json").write_text(json.dumps(raw))
    with pytest.raises(SubjectFolderError, match="not a positive number"):
        load_subject(folder)


def test_numeric_mass_and_height_are_accepted(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    raw = json.loads((folder / "_subject.json").read_text())
    raw.update(massKg=70, heightM=1.7, disableDynamics="true", footBodyNames=["toes_r"])
    (folder / "_subject.json").write_text(json.dumps(raw))
    subject = load_subject(folder)
    assert (subject.mass_kg, subject.height_m) == (70.0, 1.7)
    assert subject.disable_dynamics is True and subject.foot_body_names == ("toes_r",)


def test_invalid_json_reports_the_line(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    (folder / "_subject.json").write_text('{\n  "massKg": "70",\n  "heightM" 1.8\n}')
    with pytest.raises(SubjectFolderError, match="not valid JSON") as info:
        load_subject(folder)
    assert info.value.line == 3


def test_missing_model_and_markers(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    (folder / "unscaled_generic.osim").unlink()
    with pytest.raises(SubjectFolderError, match=r"unscaled_generic\.osim is missing"):
        load_subject(folder)
    folder = _copy_subject(tmp_path / "b")
    (folder / "trials/walk/markers.trc").unlink()
    with pytest.raises(SubjectFolderError, match=r"no markers\.trc or markers\.c3d") as info:
        load_subject(folder)
    assert info.value.path == str(folder / "trials/walk")


def test_missing_json_and_trials(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    shutil.rmtree(folder / "trials")
    with pytest.raises(SubjectFolderError, match="trials folder is missing"):
        load_subject(folder)
    (folder / "_subject.json").unlink()
    with pytest.raises(SubjectFolderError, match=r"_subject\.json is missing"):
        load_subject(folder)


def test_c3d_trial_takes_forces_from_the_c3d(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    trial_dir = folder / "trials" / "treadmill"
    trial_dir.mkdir()
    shutil.copy(DATA / "trials/opensim_c3d/walking2.c3d", trial_dir / "markers.c3d")
    subject = load_subject(folder)
    files = subject.trial("treadmill")
    assert files.markers_path.suffix == ".c3d" and files.forces_path is None
    trial = load_trial(files)
    assert trial.forces is not None and len(trial.forces.plates) == 2
    assert trial.forces.n_frames == trial.markers.n_frames == 1249


def test_broken_trial_file_names_the_file_and_line(tmp_path: Path) -> None:
    folder = _copy_subject(tmp_path)
    trc = folder / "trials/walk/markers.trc"
    lines = trc.read_text().splitlines()
    trc.write_text("\n".join(lines[:-20]) + "\n")
    files = load_subject(folder).trial("walk")
    with pytest.raises(TrcFormatError, match="truncated") as info:
        load_trial(files)
    assert info.value.path == str(trc)


# ----------------------------------------------------------------------------- summaries

SUMMARY_FILES = sorted(
    p
    for pattern in ("*.trc", "*.mot", "*.sto", "*.c3d", "*.osim", "*.xml", "*review*.json")
    for p in DATA.rglob(pattern)
)


def _read_by_hand(path: Path) -> dict[str, object]:
    """What a summary must report, read from the file without addb's readers: a TRC's header
    counts; a MOT/STO's data rows after its 'time' line; a C3D's counts by ezc3d; a review
    file's entries; an XML document's first element (an ExternalLoads: its forces). The
    .osim counts are checked against OpenSim below."""
    text = path.read_text(encoding="latin-1") if path.suffix != ".c3d" else ""
    if path.suffix == ".trc":
        lines = text.splitlines()
        header = dict(zip(lines[1].split(), lines[2].split(), strict=True))
        return {"kind": "trc", "frames": int(header["NumFrames"]),
                "markers": int(header["NumMarkers"]), "rate_hz": float(header["DataRate"])}  # fmt: skip
    if path.suffix in (".mot", ".sto"):
        lines = text.splitlines()
        start = next(i for i, line in enumerate(lines) if line.split()[:1] == ["time"])
        return {"frames": sum(1 for line in lines[start + 1 :] if line.strip())}
    if path.suffix == ".c3d":
        c3d = ezc3d.c3d(str(path))
        points = c3d["header"]["points"]
        return {"kind": "c3d", "frames": points["last_frame"] - points["first_frame"] + 1,
                "markers": points["size"], "rate_hz": float(points["frame_rate"])}  # fmt: skip
    if path.suffix == ".json":
        entries = json.loads(text)["missing_grf_data"]
        return {"kind": "review", "review_frames": len(entries), "missing_grf_frames": sum(entries)}
    if path.suffix == ".xml":
        body = re.sub(r"<!--.*?-->", "", text, flags=re.DOTALL)
        element = re.search(r"<OpenSimDocument[^>]*>\s*<(\w+)", body).group(1)
        if element == "ExternalLoads":
            return {"kind": "external_loads", "n_forces": text.count("<ExternalForce ")}
        return {"kind": "opensim_xml", "element": element}
    return {"kind": "osim"}


@pytest.mark.parametrize("path", SUMMARY_FILES, ids=lambda p: str(p.relative_to(DATA)))
def test_every_shared_file_is_summarized(path: Path) -> None:
    d = summarize(path)
    json.dumps(d)  # JSON-serializable for the UI
    text = format_summary(d)
    assert text.startswith(str(path)) and len(text.splitlines()) >= 2
    expected = _read_by_hand(path)
    if "n_forces" in expected:
        assert len(d["forces"]) == expected.pop("n_forces")
    assert {k: d[k] for k in expected} == expected
    if path.suffix in (".trc", ".c3d"):
        assert d["duration_s"] == pytest.approx((d["frames"] - 1) / d["rate_hz"], rel=1e-6)
    if path.suffix == ".osim":  # the exact counts: test_osim_counts_agree_with_opensim
        assert 14 <= d["bodies"] <= 22 and 25 <= d["coordinates"] <= 39 and d["markers"] > 30
    if path.name.startswith("grf") and path.suffix == ".mot":
        assert d["kind"] == "forces" and len(d["plates"]) >= 2


@pytest.mark.parametrize("path", sorted([*DATA.rglob("_subject.json"), *DATA.rglob("addb_subject.json")]),
                         ids=lambda p: str(p.relative_to(DATA)))  # fmt: skip
def test_a_subject_json_is_summarized_with_its_values(path: Path) -> None:
    """Every subject JSON of the shared data: its mass and height as written, and its feet."""
    raw = json.loads(path.read_text())
    lines = format_summary(summarize(path)).splitlines()
    assert lines[1] == f"  mass {raw['massKg']} kg, height {raw['heightM']} m", lines
    assert lines[2] == f"  feet: {', '.join(raw['footBodyNames'])}", lines


def test_osim_counts_match_opensim_conventions(shared_data: Path) -> None:
    # 3.x layout: ground is a Body there but not counted
    d30 = summarize(shared_data / "subjects/rajagopal2016_walk/unscaled_generic.osim")
    d40 = summarize(shared_data / "models/Rajagopal2016.osim")
    assert (d30["version"], d40["version"]) == ("30000", "40000")
    assert d30["bodies"] == d40["bodies"] == 22
    assert d30["coordinates"] == d40["coordinates"] == 39


@pytest.mark.opensim
@pytest.mark.parametrize(
    "path", sorted(DATA.rglob("*.osim")), ids=lambda p: str(p.relative_to(DATA))
)
def test_osim_counts_agree_with_opensim(path: Path) -> None:
    """Every shared model (3.x and 4.x layouts, with and without arms): OpenSim's counts."""
    opensim = import_tool("opensim", reason=OPENSIM_REASON)
    # OpenSim logs into opensim.log in the folder it is reading a model from (it changes
    # into it while loading): no file log, and no warnings about the meshes it cannot find
    opensim.Logger.removeFileSink()
    opensim.Logger.setLevelString("error")
    model = opensim.Model(str(path))
    d = summarize(path)
    assert d["bodies"] == model.getBodySet().getSize()
    assert d["coordinates"] == model.getCoordinateSet().getSize()
    assert d["markers"] == model.getMarkerSet().getSize()
    # the details (addb info MODEL): total mass, each coordinate's range, default and flags
    # in OpenSim's units (rotational in degrees here), the couplers and the markers' bodies
    state = model.initSystem()
    assert d["mass_kg"] == pytest.approx(model.getTotalMass(state), rel=1e-12)
    coordinates = model.getCoordinateSet()
    assert [c["name"] for c in d["coordinate_list"]] == [coordinates.get(i).getName() for i in range(coordinates.getSize())]
    for c in d["coordinate_list"]:
        osim = coordinates.get(c["name"])
        k = 180.0 / math.pi if c["unit"] == "deg" else 1.0
        assert (c["unit"] == "deg") == (osim.getMotionType() == opensim.Coordinate.Rotational), c
        expected = [osim.getRangeMin() * k, osim.getRangeMax() * k, osim.getDefaultValue() * k]
        assert [float(v) for v in (*c["range"], c["default"])] == pytest.approx(expected, rel=1e-3, abs=1e-9), c
        assert (c["locked"], c["clamped"]) == (osim.getDefaultLocked(), osim.getDefaultClamped()), c
    couplers = {}
    for i in range(model.getConstraintSet().getSize()):
        coupler = opensim.CoordinateCouplerConstraint.safeDownCast(model.getConstraintSet().get(i))
        if coupler is not None and coupler.get_isEnforced():
            couplers[coupler.getDependentCoordinateName()] = coupler.getIndependentCoordinateNames().get(0)
    assert {c["name"]: c["coupled_to"] for c in d["coordinate_list"] if c["coupled_to"]} == couplers
    markers = model.getMarkerSet()
    by_body: dict[str, list[str]] = {}
    for i in range(markers.getSize()):
        by_body.setdefault(markers.get(i).getParentFrame().findBaseFrame().getName(), []).append(markers.get(i).getName())
    assert d["markers_by_body"] == by_body


def test_subject_summary_in_body_weights(shared_data: Path) -> None:
    """The peak is the largest sum of the two plates' vertical force columns, read from the
    file's text (not through the reader), and in body weights of the subject's 85.0668 kg."""
    folder = shared_data / "subjects/rajagopal2016_walk"
    d = summarize(folder)
    trials = {t["name"]: t for t in d["trials"]}
    assert trials["static"]["kinematics_only"] is True
    walk = trials["walk"]
    lines = (folder / "trials/walk/grf.mot").read_text().splitlines()
    header = lines.index("endheader") + 1
    names = lines[header].split("\t")
    rows = np.array(
        [[float(v) for v in line.split("\t")] for line in lines[header + 1 :] if line.strip()]
    )
    peak = (
        rows[:, names.index("ground_force_r_vy")] + rows[:, names.index("ground_force_l_vy")]
    ).max()
    assert walk["peak_vertical_force_n"] == pytest.approx(peak, rel=1e-12)
    assert walk["peak_vertical_force_bw"] == pytest.approx(peak / (85.0668 * G), rel=1e-12)
    assert 1.0 < walk["peak_vertical_force_bw"] < 1.5  # walking
    text = format_summary(d)
    assert "BW" in text and "kinematics only" in text and "85.07 kg" in text


def _raw_gaps(path: Path) -> dict[str, object]:
    """Gaps counted from a TRC's text, independent of the reader: a marker is missing on a
    row where one of its cells is empty or "nan"; its longest run of such rows; the first
    marker (file order) with the longest run."""
    lines = path.read_text().splitlines()
    names = [n for n in lines[3].split("\t")[2:] if n.strip()]
    rows = [line.split("\t") for line in lines[5:] if line.strip()[:1].isdigit()]
    longest, worst, n_with, n_missing = 0, None, 0, 0
    for j, name in enumerate(names):
        run = best = 0
        for row in rows:
            cells = row[2 + 3 * j : 5 + 3 * j]
            if any(c.strip().lower() in ("", "nan") for c in cells):
                run, n_missing = run + 1, n_missing + 1
                best = max(best, run)
            else:
                run = 0
        n_with += best > 0
        if best > longest:
            longest, worst = best, name
    return {
        "markers_with_gaps": n_with,
        "longest_gap_frames": longest,
        "longest_gap_marker": worst,
        "missing_fraction": n_missing / (len(rows) * len(names)),
    }


def test_gaps_are_counted(shared_data: Path) -> None:
    path = shared_data / "trials/camargo2021_levelground/markers.trc"
    gaps = summarize(path)["gaps"]
    expected = _raw_gaps(path)
    assert expected["markers_with_gaps"] > 0 and expected["longest_gap_frames"] > 1
    for key in ("markers_with_gaps", "longest_gap_frames", "longest_gap_marker"):
        assert gaps[key] == expected[key], key
    assert gaps["missing_fraction"] == pytest.approx(expected["missing_fraction"], rel=1e-12)
    none = summarize(shared_data / "trials/rajagopal2016/motion_capture_walk.trc")["gaps"]
    assert none["markers_with_gaps"] == 0 and none["longest_gap_frames"] == 0


def test_moment_conversion_notes(shared_data: Path) -> None:
    d = summarize(shared_data / "trials/camargo2021_levelground/grf.mot")
    assert len(d["notes"]) == 6 and "note:" in format_summary(d)


def test_summary_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        summarize(tmp_path / "missing.trc")
    other = tmp_path / "notes.txt"
    other.write_text("x")
    with pytest.raises(FileFormatError, match="unknown file type"):
        summarize(other)
    folder = tmp_path / "not_a_subject"
    folder.mkdir()
    with pytest.raises(SubjectFolderError, match=r"_subject\.json is missing"):
        summarize(folder)


def _addb_info(path: Path) -> subprocess.CompletedProcess[str]:
    code = "import sys; from addb_viewer.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, "info", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


def test_cli_info_ok(shared_data: Path) -> None:
    result = _addb_info(shared_data / "subjects/opencap_uhlrich2023")
    assert result.returncode == 0, result.stderr
    assert "trial DJ1" in result.stdout and "BW" in result.stdout


@pytest.mark.parametrize("damage", ["missing", "truncated", "binary"])
def test_cli_info_bad_input_is_one_line(shared_data: Path, tmp_path: Path, damage: str) -> None:
    path = tmp_path / "markers.trc"
    if damage == "truncated":
        text = (shared_data / "trials/rajagopal2016/motion_capture_walk.trc").read_text()
        path.write_text(text[: len(text) // 2])
    elif damage == "binary":
        path.write_bytes(bytes(range(256)) * 4)
    result = _addb_info(path)
    assert result.returncode == 1
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("addb info:") and str(path) in lines[0]


def test_markers_have_no_nan_where_the_file_has_numbers(shared_data: Path) -> None:
    trial = load_trial(load_subject(shared_data / "subjects/opencap_uhlrich2023").trial("DJ1"))
    assert not np.isnan(trial.markers.positions).any()


def test_trial_ranges_that_addb_does_not_apply_are_a_note_of_the_summary(tmp_path: Path) -> None:
    """README, The subject folder: ``trialRanges`` is not applied. ``addb info`` says so for
    the walk, whose entry [0.45, 2.0] s would cut the trial, with the frames it would leave
    out counted from the TRC's Time column; a range that holds every frame, a trial the key
    does not name and a subject without the key give no note; a malformed entry is named."""
    walk = DATA / "subjects" / "rajagopal2016_walk"
    times = trc_times_by_hand(walk / "trials" / "walk" / "markers.trc")
    outside = int(np.count_nonzero((times < 0.45) | (times > 2.0)))
    assert 0 < outside < len(times) == 238
    d = summarize(walk)
    note = (
        f"{walk / '_subject.json'}: trialRanges gives trial walk [0.45, 2.0] s; addb does not apply trialRanges and "
        f"processes the whole trial ({times[0]:.2f}-{times[-1]:.2f} s), the {outside} of its 238 marker frames "
        "outside the range included (cut the trial's files to leave them out)"
    )
    assert d["notes"] == [note]
    assert f"  note: {note}" in format_summary(d).splitlines()

    copy = writable_copy(walk, tmp_path / "walk")
    raw = json.loads((walk / "_subject.json").read_text())
    for ranges, expected in (
        ({"walk": [times[0], times[-1]]}, None),  # every frame inside
        ({"static": [0.5, 1.0]}, "static"),  # the other trial
        ({"walk": ["0.45", 2.0]}, "['0.45', 2.0], not [start, end] in seconds"),
        (None, None),
    ):
        raw.pop("trialRanges", None)
        if ranges is not None:
            raw["trialRanges"] = ranges
        (copy / "_subject.json").write_text(json.dumps(raw))
        notes = summarize(copy).get("notes", [])
        if expected is None:
            assert notes == [], ranges
        else:
            assert len(notes) == 1 and expected in notes[0], (ranges, notes)
