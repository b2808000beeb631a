"""What README.md promises about the subject folder, the command table and the conventions,
where no other test checks it: what ``addb kinematics`` writes and prints, the units of the
motion file, ``--trial`` without ``--model``, ``markers.yaml``, ``disableDynamics``, an unknown
``--trial`` on each command line, and ``addb info`` without a path.

On the real walk (rajagopal2016_walk: trials static and walk), kinematics only (a few seconds
per run); every run writes below ``tmp_path``.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from tests.cli_run import run_addb as _run
from tests.conftest import SHARED_DATA, writable_copy
from tests.opensim_tables import read_table_by_hand

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
SCALED = "rajagopal2016_walk_scaled.osim"
TRIALS = ("static", "walk")


def _results(out: Path, trial: str) -> dict:
    return json.loads((out / trial / "results.json").read_text())


def _model_markers(osim: Path) -> set[str]:
    return {m.get("name") for m in ET.parse(osim).getroot().iter("Marker")}


@pytest.fixture(scope="module")
def full_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """``addb kinematics WALK --out OUT``: (OUT, what it printed on stdout)."""
    out = tmp_path_factory.mktemp("kinematics") / "out"
    code, printed, err = _run(["kinematics", str(WALK), "--out", str(out)])
    assert code == 0, err
    return out, printed


def test_kinematics_writes_the_scaled_model_and_each_trials_motion_and_results_static_included(full_run: tuple[Path, str]) -> None:
    """README, `addb kinematics`: "scale the model and solve inverse kinematics (all trials,
    static included); writes OUT/<subject>_scaled.osim, OUT/<trial>/<trial>_ik.mot,
    results.json, and prints a per-trial summary". The summary's figures are results.json's
    (marker RMS in m there, in cm on the console: SI inside, other units only in what is
    shown or written)."""
    out, printed = full_run
    assert {p.name for p in out.iterdir()} == {SCALED, "subject.json", *TRIALS}
    rows = {line.split()[0]: line.split() for line in printed.splitlines()[2:] if line.split() and line.split()[0] in TRIALS}
    assert sorted(rows) == sorted(TRIALS), printed
    for trial in TRIALS:
        assert (out / trial / f"{trial}_ik.mot").is_file(), trial
        r = _results(out, trial)
        header, names, values = read_table_by_hand(out / trial / f"{trial}_ik.mot")
        assert names[0] == "time" and int(header["nRows"]) == values.shape[0] == r["n_frames"]
        assert rows[trial] == [trial, str(r["n_frames"]), f"{r['marker_rms_m'] * 100:.2f}", f"{r['marker_max_m'] * 100:.2f}", r["worst_marker"]]
        assert 0.005 < r["marker_rms_m"] < 0.03, (trial, r["marker_rms_m"])  # metres: a lab's cm-level fit, not mm or cm figures
    assert printed.rstrip().endswith(f"wrote {out}")
    # the scaled model is an OpenSim model carrying the fitted marker set
    assert ET.parse(out / SCALED).getroot().tag == "OpenSimDocument" and len(_model_markers(out / SCALED)) > 60


def test_ik_mot_holds_degrees_and_metres_of_the_radian_coordinates_in_coordinate_set_order(full_run: tuple[Path, str]) -> None:
    """README, Conventions: "SI units inside the program (m, s, kg, N, N·m, rad); mm and
    degrees exist only in files", "coordinates q (T, n) in OpenSim CoordinateSet order",
    "OpenSim's lab frame: Y up". The walk's _ik.mot (inDegrees=yes) holds each rotational
    coordinate of the processed trial's q in degrees, the others (translations in m, the
    knees' coupled coordinates) as they are, in the order of the scaled model's coordinates;
    the pelvis stands about a metre above the floor along Y."""
    from solver.results import load_processed

    out, _ = full_run
    trial = load_processed(out, "walk")
    header, names, values = read_table_by_hand(out / "walk" / "walk_ik.mot")
    assert header["inDegrees"] == "yes"
    coordinates = [(c.get("name"), c.findtext("motion_type")) for c in ET.parse(out / SCALED).getroot().iter("Coordinate")]
    assert names == ["time", *(n for n, _ in coordinates)]
    assert list(trial.coordinate_names) == [n for n, _ in coordinates] and trial.q.shape == (trial.n_frames, len(coordinates)) == (238, 39)
    np.testing.assert_allclose(values[:, 0], trial.time, rtol=0, atol=1e-12)
    rotational = np.array([kind == "rotational" for _, kind in coordinates])
    assert rotational.sum() >= 30 and {kind for _, kind in coordinates} >= {"rotational", "translational"}
    expected = np.where(rotational, np.degrees(trial.q), trial.q)
    np.testing.assert_allclose(values[:, 1:], expected, rtol=1e-12, atol=1e-12)
    assert np.abs(trial.q[:, rotational]).max() < 2 * np.pi  # radians inside: no angle of a whole turn
    pelvis_ty = trial.q[:, trial.coordinate_names.index("pelvis_ty")]
    assert 0.8 < np.median(pelvis_ty) < 1.2, np.median(pelvis_ty)  # Y up, in metres


def test_kinematics_trial_option_writes_only_that_trial_and_scales_on_all(full_run: tuple[Path, str], tmp_path: Path) -> None:
    """README table, `addb kinematics ... [--trial NAME ...]` (its --help: "write only this
    trial; all trials are used for scaling"): with --trial walk and no --model, only the walk
    is written and printed, and the scaled model and the walk's motion are those of the run
    over every trial, byte for byte (the static trial still takes part in the scaling)."""
    full, _ = full_run
    out = tmp_path / "out"
    code, printed, err = _run(["kinematics", str(WALK), "--out", str(out), "--trial", "walk"])
    assert code == 0, err
    assert {p.name for p in out.iterdir()} == {SCALED, "subject.json", "walk"}
    assert (out / SCALED).read_bytes() == (full / SCALED).read_bytes()
    assert (out / "walk" / "walk_ik.mot").read_bytes() == (full / "walk" / "walk_ik.mot").read_bytes()
    assert [line.split()[0] for line in printed.splitlines()[2:-1]] == ["walk"], printed


def _rename_markers(trc: Path, names: dict[str, str]) -> None:
    """Rename markers in a TRC's name line (the fourth), values unchanged."""
    lines = trc.read_text().split("\n")
    cells = lines[3].split("\t")
    assert set(names) <= set(cells), trc
    lines[3] = "\t".join(names.get(c, c) for c in cells)
    trc.write_text("\n".join(lines))


def test_markers_yaml_maps_a_labs_marker_names_onto_the_models(full_run: tuple[Path, str], tmp_path: Path) -> None:
    """README, subject folder: "markers.yaml optional: lab marker name -> model marker name
    ({markers: {LASI: L.ASIS}, ...})" and "Markers are matched by name (or through
    markers.yaml)". The walk with its two ASIS markers renamed to names the model does not
    carry, and a markers.yaml that maps them back, gives the original run's outputs byte for
    byte, with no marker left unmatched."""
    full, _ = full_run
    subject = writable_copy(WALK, tmp_path / WALK.name)  # same folder name: same scaled model name
    lab = {"L.ASIS": "lab_left_asis", "R.ASIS": "lab_right_asis"}
    assert not set(lab.values()) & _model_markers(subject / "unscaled_generic.osim")  # only the mapping can match them
    for trial in TRIALS:
        _rename_markers(subject / "trials" / trial / "markers.trc", lab)
    (subject / "markers.yaml").write_text("markers: {lab_left_asis: L.ASIS, lab_right_asis: R.ASIS}\n")
    out = tmp_path / "out"
    code, _, err = _run(["kinematics", str(subject), "--out", str(out)])
    assert code == 0, err
    assert (out / SCALED).read_bytes() == (full / SCALED).read_bytes()
    for trial in TRIALS:
        assert (out / trial / f"{trial}_ik.mot").read_bytes() == (full / trial / f"{trial}_ik.mot").read_bytes(), trial
        mine, theirs = _results(out, trial), _results(full, trial)
        assert mine["markers_used"] == theirs["markers_used"] and mine["markers_ignored"] == theirs["markers_ignored"], trial
        assert not set(lab.values()) & set(mine["markers_ignored"]), trial
    assert {"L.ASIS", "R.ASIS"} <= set(_results(out, "walk")["markers_used"])


def test_disable_dynamics_makes_process_write_kinematics_only(full_run: tuple[Path, str], tmp_path: Path) -> None:
    """README, subject folder: `"disableDynamics": true` in _subject.json "skips the
    dynamics". `addb process` of the walk (which has force plates) then writes what `addb
    kinematics` writes: the same scaled model and motion, no joint torques, force or loads
    files, no residuals in results.json, and exits 0."""
    full, _ = full_run
    subject = writable_copy(WALK, tmp_path / WALK.name)
    meta = json.loads((subject / "_subject.json").read_text())
    meta["disableDynamics"] = True
    (subject / "_subject.json").write_text(json.dumps(meta, indent=2))
    out = tmp_path / "out"
    code, _, err = _run(["process", str(subject), "--out", str(out)])
    assert code == 0, err
    assert (out / SCALED).read_bytes() == (full / SCALED).read_bytes()
    assert sorted(p.name for p in (out / "walk").iterdir()) == ["results.json", "trial.npz", "walk_ik.mot"]  # no _id.sto, _grf.mot, _external_loads.xml
    assert (out / "walk" / "walk_ik.mot").read_bytes() == (full / "walk" / "walk_ik.mot").read_bytes()
    results = _results(out, "walk")
    assert not [k for k in results if "residual" in k or k.startswith("hicks")], results.keys()
    assert results["marker_rms_m"] == _results(full, "walk")["marker_rms_m"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["kinematics", "--out", "{out}"], "addb kinematics: KinematicsError: unknown trial(s) wlk; the subject has static, walk"),
        (["process", "--out", "{out}"], "addb process: KinematicsError: unknown trial(s) wlk; the subject has static, walk"),
        (["record", "-o", "{file}.rrd", "--out", "{out}"], "addb record: SubjectFolderError ({subject}): no trial 'wlk'; the subject's trials are static, walk"),
        (["export", "-o", "{file}.mcap", "--out", "{out}"], "addb export: SubjectFolderError ({subject}): no trial 'wlk'; the subject's trials are static, walk"),
    ],
    ids=["kinematics", "process", "record", "export"],
)
def test_an_unknown_trial_is_refused_on_the_command_line_naming_the_subjects_trials(
    argv: list[str], message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """README table, `addb process`: "a --trial name the subject does not have fails at once,
    naming its trials, before any stage runs; so do addb kinematics, record and export". On
    the command line: exit code 1, the message on stderr (no traceback), nothing written, and
    no stage run (each is replaced by one that fails the test)."""
    from solver import pipeline

    def stage_ran(*args: object, **kwargs: object) -> None:
        raise AssertionError("a stage ran before the trial names were checked")

    monkeypatch.setattr(pipeline, "subject_kinematics", stage_ran)
    monkeypatch.setattr(pipeline, "load_kinematics_cache", stage_ran)
    fill = {"out": str(tmp_path / "out"), "file": str(tmp_path / "trial"), "subject": str(WALK)}
    code, printed, err = _run([argv[0], str(WALK), "--trial", "wlk", *(a.format(**fill) for a in argv[1:])])
    assert code == 1 and printed == ""
    assert message.format(**fill) in err, err
    assert "Traceback" not in err and "a stage ran" not in err
    assert list(tmp_path.iterdir()) == []


def test_info_without_a_path_summarizes_the_demo_subject() -> None:
    """README table, `addb info [PATH]`: "a subject folder (default: the demo subject)". `addb
    info` alone prints what `addb info <the bundled demo folder>` prints, a subject summary
    of its trials."""
    from addb_viewer.demo import DEMO_SUBJECT

    code, alone, err = _run(["info"])
    assert code == 0, err
    code, named, err = _run(["info", str(DEMO_SUBJECT)])
    assert code == 0, err
    assert alone == named
    assert alone.startswith(f"{DEMO_SUBJECT}: subject\n")
    trials = sorted(p.name for p in (DEMO_SUBJECT / "trials").iterdir() if p.is_dir())
    assert trials and all(f"  trial {t}:" in alone for t in trials), alone


def test_a_c3d_trial_with_grf_mot_takes_its_forces_from_grf_mot(tmp_path: Path) -> None:
    """README, subject folder: "markers.trc or markers.c3d (a C3D trial without grf.mot takes
    its forces from the C3D's force platforms)"; grf.mot, when there, is the trial's forces.
    The opensim-core walking2.c3d beside a grf.mot of its own plates at half the force: the
    trial's forces are the file's, not the C3D's."""
    from solver.io.c3d import read_c3d
    from solver.io.mot import read_forces, write_forces
    from solver.io.subject import load_subject, load_trial

    subject = writable_copy(WALK, tmp_path / "s01")
    folder = subject / "trials" / "walking2"
    folder.mkdir()
    shutil.copy(SHARED_DATA / "trials" / "opensim_c3d" / "walking2.c3d", folder / "markers.c3d")
    from_c3d = load_trial(load_subject(subject).trial("walking2")).forces
    assert from_c3d is not None and len(from_c3d.plates) == 2
    _, c3d_forces = read_c3d(folder / "markers.c3d")
    half = dataclasses.replace(c3d_forces, plates=tuple(dataclasses.replace(p, force=p.force / 2) for p in c3d_forces.plates))
    write_forces(folder / "grf.mot", half)
    files = load_subject(subject).trial("walking2")
    assert files.forces_path == folder / "grf.mot"
    forces = load_trial(files).forces
    expected = read_forces(folder / "grf.mot")
    assert len(forces.plates) == len(expected.plates) == 2
    for mine, written, full in zip(forces.plates, expected.plates, from_c3d.plates, strict=True):
        np.testing.assert_array_equal(mine.force, written.force)
        peak = np.nanmax(np.abs(full.force))
        assert np.nanmax(np.abs(mine.force)) == pytest.approx(peak / 2, rel=1e-6)
