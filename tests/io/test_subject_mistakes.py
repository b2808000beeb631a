"""Mistakes a user makes in a subject folder get a clear error or warning, not a numpy
traceback or a silently wrong result: a hand-edited ``addb_extensions.json``, an empty
``footBodyNames`` or one naming no body of the model, a mass or height in the wrong unit,
forces that no frame can use, a wrong ``massKg``, a marker file in the wrong unit, force
plates without a centre of pressure under load.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from solver.corrections import CORRECTIONS, FIELD_KINDS, extend_subject, read_extensions
from solver.errors import DynamicsError, SubjectFolderError
from solver.io.subject import load_subject
from solver.pipeline import process_kinematics, process_subject
from tests.conftest import SHARED_DATA, writable_copy
from tests.trial_edits import keep_first_marker_frames

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture
def walk(tmp_path: Path) -> Path:
    return writable_copy(WALK, tmp_path / "walk")


def _set(subject: Path, **values: object) -> None:
    path = subject / "_subject.json"
    data = json.loads(path.read_text())
    data.update(values)
    path.write_text(json.dumps(data))


def _extensions(subject: Path, *entries: dict) -> None:
    (subject / "addb_extensions.json").write_text(json.dumps({"schema": "addb.extensions", "version": 1, "extensions": list(entries)}))


# ----------------------------------------------------------------------------- addb_extensions.json


@pytest.mark.parametrize(
    "entry, field",
    [
        ({"cause": "body_mass"}, "mass_change_kg"),
        ({"cause": "body_mass", "mass_change_kg": "abc"}, "mass_change_kg"),
        ({"cause": "force_time_offset", "trial": "walk"}, "delay_s"),
        ({"cause": "unmeasured_force", "trial": "walk", "n_frames": "x"}, "n_frames"),
        ({"cause": "unmeasured_force", "trial": "walk", "n_frames": 10, "frames": [[5, 20]]}, "frames"),
        ({"cause": "unmeasured_force", "trial": "walk", "n_frames": 10, "frames": [[5, 2]]}, "frames"),
        ({"cause": "plate_force_gain", "trial": "walk", "plate": "r", "gain": 0}, "gain"),
        ({"cause": "plate_position_offset", "trial": "walk", "plate": "r", "shift_m": [0.1, 0.0]}, "shift_m"),
        ({"cause": "plate_registration", "trial": "walk", "shift_m": [0.0, 0.0, 0.0]}, "centre_m"),
        ({"cause": "marker_offset", "trial": "walk", "marker": "R.ASIS", "time_s": [0.0, 1.0], "lab_shift_m": [[0, 0, 0]]}, "lab_shift_m"),
        ({"cause": "segment_mass_distribution", "mass_change_kg": {"legs": "two"}}, "mass_change_kg"),
    ],
    ids=lambda v: v if isinstance(v, str) else v["cause"],
)
def test_an_extension_with_a_missing_or_malformed_field_names_it(walk: Path, entry: dict, field: str) -> None:
    good = {"cause": "body_mass", "trial": None, "mass_change_kg": 1.0}
    _extensions(walk, good, entry)
    with pytest.raises(SubjectFolderError, match=f"extension 2 \\({entry['cause']}\\)") as err:
        read_extensions(walk)
    assert err.value.where == f"extensions[1].{field}"
    assert "addb_extensions.json" in str(err.value)


def test_every_cause_says_which_fields_it_reads_and_their_kinds_exist() -> None:
    for cause, c in CORRECTIONS.items():
        assert set(c.fields) | set(c.optional), cause
        assert set(c.fields.values()) | set(c.optional.values()) <= set(FIELD_KINDS), cause


def test_entries_as_the_diagnosis_writes_them_are_read(walk: Path) -> None:
    entries = [
        {"cause": "force_time_offset", "trial": "walk", "delay_s": 0.038},
        {"cause": "plate_force_offset", "trial": "walk", "plate": "l", "offset_N": [20.1, 39.8, -17.5], "centre_m": [0.35, 0.0, 0.2]},
        {"cause": "plate_registration", "trial": "walk", "shift_m": [0.013, 0.0, 0.0], "rotation_rad": 0.01, "centre_m": [0.89, 0.0, -0.34]},
        {"cause": "unmeasured_force", "trial": "walk", "n_frames": 238, "frames": [[0, 47], [196, 238]], "times_s": [[0.0, 0.46], [1.96, 2.37]]},
        {"cause": "body_mass", "trial": None, "mass_change_kg": -4.9},
    ]
    _extensions(walk, *entries)
    assert read_extensions(walk) == entries
    assert extend_subject(load_subject(walk)).mass_kg == pytest.approx(load_subject(walk).mass_kg - 4.9)


def test_a_body_mass_extension_that_leaves_no_mass_is_refused(walk: Path) -> None:
    _extensions(walk, {"cause": "body_mass", "trial": None, "mass_change_kg": -100.0})
    with pytest.raises(SubjectFolderError, match=r"to -14.9332 kg; expected a positive mass"):
        extend_subject(load_subject(walk))


# ----------------------------------------------------------------------------- _subject.json


@pytest.mark.parametrize(
    "values, words",
    [
        ({"footBodyNames": []}, "footBodyNames=[]; expected a list of one or more body names"),
        ({"heightM": "182.9"}, "heightM='182.9' is more than 3 m; expected the value in m (not cm or mm)"),
        ({"massKg": 85066.8}, "massKg=85066.8 is more than 500 kg; expected the value in kg (not g or lb)"),
    ],
    ids=["no_feet", "height_in_cm", "mass_in_g"],
)
def test_subject_values_in_the_wrong_form_are_refused_with_the_key(walk: Path, values: dict, words: str) -> None:
    _set(walk, **values)
    with pytest.raises(SubjectFolderError, match=words.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(").replace(")", r"\)")) as err:
        load_subject(walk)
    assert err.value.where == next(iter(values)) and "_subject.json" in str(err.value)


# ----------------------------------------------------------------------------- forces and mass


def _scale_forces(subject: Path, factor: float) -> None:
    """Multiply every force column of the walk's grf.mot (the ``*_v*`` columns) by ``factor``."""
    path = subject / "trials" / "walk" / "grf.mot"
    lines = path.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 1
    names = lines[head].split("\t")
    cols = [j for j, n in enumerate(names) if "_v" in n]
    out = lines[: head + 1]
    for line in lines[head + 1 :]:
        v = line.split("\t")
        for j in cols:
            v[j] = repr(float(v[j]) * factor)
        out.append("\t".join(v))
    path.write_text("\n".join(out) + "\n")


def test_forces_in_kilonewtons_name_the_trial_the_mass_and_what_the_plates_weigh(walk: Path, tmp_path: Path) -> None:
    _scale_forces(walk, 1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning on the way (e.g. "Mean of empty slice")
        with pytest.raises(DynamicsError, match="no frame of walk is left with measured force to fit the mass") as err:
            process_subject(walk, tmp_path / "out")
    text = str(err.value)
    assert "massKg is 85.0668 kg" in text and "no plate ever carries more than 20 N upward" in text
    assert "measured vertical force differs from m(a+g) by N BW" in text


def test_a_wrong_mass_is_warned_about_with_the_fitted_one(walk: Path, tmp_path: Path) -> None:
    _set(walk, massKg=60.0)
    with pytest.warns(UserWarning, match=r"the fitted mass (\d+\.\d) kg is \+\d+ % from the subject's massKg \(60 kg\)") as rec:
        result = process_subject(walk, tmp_path / "out")
    fitted = float(next(w for w in rec if "fitted mass" in str(w.message)).message.args[0].split()[3])
    assert fitted == pytest.approx(result.dynamics.mass_kg, abs=0.05) and fitted > 60.0 * 1.15


def test_the_shared_subjects_are_not_warned_about(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        process_subject(WALK, tmp_path / "out")


def test_an_unknown_foot_body_is_refused_before_the_kinematics(walk: Path, tmp_path: Path) -> None:
    """A footBodyNames entry that is not a body of the model (a typo, another model's name) is
    refused before the kinematics stage runs, listing the model's bodies (it was found after
    the whole kinematics, naming the body only); without force plates it is not read."""
    _set(walk, footBodyNames=["calcn_r", "foot_l"])
    said: list[str] = []
    with pytest.raises(DynamicsError) as err:
        process_subject(walk, tmp_path / "out", progress=lambda message, fraction: said.append(message))
    message = str(err.value)
    assert "foot body 'foot_l' (footBodyNames in _subject.json) not in the model; its bodies: pelvis, femur_r, " in message, message
    assert "calcn_l" in message and "'calcn_r'" not in message, message
    assert said == [], said  # no stage began
    assert not (tmp_path / "out").exists()
    (walk / "trials" / "walk" / "grf.mot").unlink()  # no force plates: the feet are not read
    process_subject(walk, tmp_path / "no_forces")
    assert (tmp_path / "no_forces" / "walk" / "walk_ik.mot").is_file()


def test_foot_bodies_that_do_not_stand_on_the_plates_are_warned_about(walk: Path, tmp_path: Path) -> None:
    """footBodyNames naming the pelvis took the plates' force by horizontal distance and came
    out within the Hicks thresholds with no word; it is named with its height above the centre
    of pressure (a foot named beside it, the left toes, stands on the plate and is not)."""
    _set(walk, footBodyNames=["pelvis", "toes_l"])
    with pytest.warns(UserWarning, match=r"bodies named as feet stand high above the centre of pressure") as rec:
        process_subject(walk, tmp_path / "out")
    (message,) = [str(w.message) for w in rec if "bodies named as feet" in str(w.message)]
    named = message.split("take (", 1)[1].split(", median", 1)[0]
    assert named.startswith("pelvis ") and int(named.split()[1]) >= 30 and "toes_l" not in named, message
    assert message.startswith("trial walk: ") and "footBodyNames in _subject.json" in message


def test_a_plate_without_centre_of_pressure_under_load_is_warned_about(walk: Path, tmp_path: Path) -> None:
    path = walk / "trials" / "walk" / "grf.mot"
    lines = path.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 1
    names = lines[head].split("\t")
    px = names.index("ground_force_r_px")  # the right plate's centre of pressure, x
    out = lines[: head + 1]
    for line in lines[head + 1 :]:
        v = line.split("\t")
        v[px] = "nan"
        out.append("\t".join(v))
    path.write_text("\n".join(out) + "\n")
    with pytest.warns(UserWarning, match=r"trial walk, plate \S+: \d+ samples carry more than 0.2 body weights of vertical force with no centre of pressure"):
        process_subject(walk, tmp_path / "out")


def _set_trc_units(path: Path, unit: str) -> None:
    """Write ``unit`` in the Units field of a TRC's header (its values unchanged)."""
    lines = path.read_text().splitlines()
    values = lines[2].split("\t")
    [k] = [i for i, v in enumerate(values) if v.strip() == "mm"]
    values[k] = values[k].replace("mm", unit)
    lines[2] = "\t".join(values)
    path.write_text("\n".join(lines) + "\n")


def test_markers_in_the_wrong_unit_are_warned_about(walk: Path, tmp_path: Path) -> None:
    _set_trc_units(walk / "trials" / "walk" / "markers.trc", "m")  # the values stay in mm: a thousand times too far apart
    with pytest.warns(UserWarning, match=r"trial walk: marker RMS error \d+\.\d cm .* check the marker file's Units line"):
        process_kinematics(walk, tmp_path / "out")
    assert np.isfinite(json.loads((tmp_path / "out" / "walk" / "results.json").read_text())["marker_rms_m"])


def test_markers_ten_times_too_large_name_the_marker_files_not_the_model(walk: Path, tmp_path: Path) -> None:
    from solver.errors import KinematicsError

    for trial in ("static", "walk"):
        _set_trc_units(walk / "trials" / trial / "markers.trc", "cm")  # mm values read as cm: ten times too large
    with pytest.raises(KinematicsError, match="the scale fit drove a body's size to zero or below") as err:
        process_kinematics(walk, tmp_path / "out")
    assert "markers.trc" in str(err.value) and "Units line" in str(err.value)
    assert not (tmp_path / "out").exists()


def _rename_markers(path: Path, keep: int) -> list[str]:
    """Prefix ``LAB_`` to every marker name of a TRC after the first ``keep`` (a lab's own
    names the model does not carry); returns the renamed names."""
    lines = path.read_text().splitlines()
    cells = lines[3].split("\t")
    named = [i for i, c in enumerate(cells) if i >= 2 and c.strip()]
    for i in named[keep:]:
        cells[i] = "LAB_" + cells[i]
    lines[3] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return [cells[i] for i in named[keep:]]


def test_a_marker_set_that_misses_most_of_the_model_is_warned_about(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """OpenCap's walking1 with all but 10 of its 51 markers renamed: a small marker RMS error
    over the 10 the model carries, and a warning (console too) that names the trial, the 10
    of 49 and the ignored markers; DJ1 (45 of 49 matched, 6 ignored) is not warned about."""
    from addb_viewer.cli import main as cli

    subject = writable_copy(SHARED_DATA / "subjects" / "opencap_uhlrich2023", tmp_path / "oc")
    renamed = _rename_markers(subject / "trials" / "walking1" / "markers.trc", keep=10)
    with pytest.warns(UserWarning, match=r"trial walking1: only 10 of the model's 49 markers are matched") as rec:
        process_kinematics(subject, tmp_path / "out")
    [message] = [str(w.message) for w in rec if "markers are matched" in str(w.message)]  # one, and none for DJ1
    results = json.loads((tmp_path / "out" / "walking1" / "results.json").read_text())
    ignored = results["markers_ignored"]
    assert sorted(ignored) == sorted(renamed) and len(ignored) == 41
    assert f"41 of the trial's markers are not in the model and are ignored: {', '.join(ignored[:8])} and 33 more" in message
    assert "and 34 more are left without data" in message  # 39 model markers left: 5 named
    assert cli(["kinematics", str(subject), "--out", str(tmp_path / "cli")]) == 0
    assert "addb: warning: trial walking1: only 10 of the model's 49 markers are matched" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023"])
def test_the_shared_marker_sets_are_not_warned_about(name: str, tmp_path: Path) -> None:
    """The walk's model carries 107 markers and its trials match 41 (the static trial
    ignores 23 more): fewer than half of the model's alone is no warning (MIN_MATCHED_SHARE)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        process_kinematics(SHARED_DATA / "subjects" / name, tmp_path / "out")


def test_a_trial_too_short_for_the_dynamics_says_how_short(walk: Path, tmp_path: Path) -> None:
    """The walk's markers cut to their first six frames (0.05 s, inside the forces' 2.39 s):
    the trial is written with its kinematics, and its DynamicsError says how long the two
    overlap and what the dynamics needs, not that they do not overlap."""
    keep_first_marker_frames(walk / "trials" / "walk" / "markers.trc", 6)
    with pytest.raises(DynamicsError) as err:
        process_subject(walk, tmp_path / "out")
    text = str(err.value)
    assert "overlap" in text and "do not overlap" not in text, text
    assert "markers (0.000-0.050 s) and forces (0.000-2.389 s) overlap by 0.050 s (6 frames at 100 Hz); the dynamics needs at least 10" in text, text
