"""``addb convert``: results.b3d -> a subject folder (markers, forces, model, review record);
end to end, the converted subject processed by ``addb process`` and compared with
AddBiomechanics' own pass (marked slow)."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main
from solver.io.b3d import dof_names, open_b3d
from solver.io.b3d_writer import write_b3d
from solver.io.mot import read_forces
from solver.io.subject import load_subject
from solver.io.trc import read_trc
from tests.conftest import SHARED_DATA

B3D = SHARED_DATA / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's


def test_converted_subject_holds_the_file_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "subject"
    assert main(["convert", str(B3D), "--out", str(out)]) == 0
    f = open_b3d(B3D)
    subject = load_subject(out)
    assert subject.mass_kg == f.header.mass_kg and subject.height_m == f.header.height_m
    assert subject.foot_body_names == f.header.ground_contact_bodies
    assert (out / "unscaled_generic.osim").read_text() == f.model_text(0)
    assert [t.name for t in subject.trials] == sorted(t.name for t in f.header.trials)
    for k, info in enumerate(f.header.trials):
        fr = f.read_trial(k)
        markers = read_trc(out / "trials" / info.name / "markers.trc")
        assert markers.n_frames == info.n_frames and markers.rate_hz == info.rate_hz
        for j, name in enumerate(markers.names):
            src = fr.markers[:, f.header.marker_names.index(name)]
            absent = np.isnan(src).any(axis=1) | (src == 0).all(axis=1)
            np.testing.assert_array_equal(markers.positions[~absent, j], src[~absent])
            assert np.isnan(markers.positions[absent, j]).all()
        assert "" not in markers.names
        forces = read_forces(out / "trials" / info.name / "grf.mot")
        assert len(forces.plates) == info.n_force_plates
        for p, plate in enumerate(forces.plates):
            np.testing.assert_array_equal(plate.force, fr.plate_force[:, p])
            np.testing.assert_array_equal(plate.cop, fr.plate_cop[:, p])
            np.testing.assert_array_equal(plate.free_moment, fr.plate_moment[:, p])
    # a second convert into the same folder needs --force, and says so in plain words
    capsys.readouterr()
    assert main(["convert", str(B3D), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"addb convert: SubjectFolderError ({out}): exists and already holds a subject (_subject.json); add --force to write" in err
    assert "pass overwrite" not in err
    assert main(["convert", str(B3D), "--out", str(out), "--force"]) == 0


def test_missing_grf_labels_become_the_review_record(tmp_path: Path) -> None:
    from annotations import AnnotationStore

    f = open_b3d(B3D)
    info = f.header.trials[1]
    reasons = list(info.missing_grf)
    reasons[3:9] = ["notOverForcePlate"] * 6
    reasons[50:52] = ["manualReview"] * 2
    trials = list(f.header.trials)
    trials[1] = dataclasses.replace(info, missing_grf=tuple(reasons))
    header = dataclasses.replace(f.header, trials=tuple(trials))
    labelled = tmp_path / "labelled.b3d"
    write_b3d(labelled, header, [f.read_trial(k) for k in range(len(trials))])
    out = tmp_path / "subject"
    assert main(["convert", str(labelled), "--out", str(out)]) == 0
    with AnnotationStore.open(out / "annotations.json", reviewer="test") as store:
        mask = store.mask(info.name, info.n_frames, kind="unmeasured_force")
        np.testing.assert_array_equal(mask, [r != "notMissingGRF" for r in reasons])
        assert store.flag(info.name, 4).provenance.source == "imported"
        notes = sorted((n.start, n.stop, n.text) for n in store.notes(info.name))
        assert notes == [
            (3, 9, "AddBiomechanics: missing GRF (notOverForcePlate)"),
            (50, 52, "AddBiomechanics: missing GRF (manualReview)"),
        ]
        assert not store.mask(f.header.trials[0].name, f.header.trials[0].n_frames, kind="unmeasured_force").any()


def test_our_fk_of_the_file_coordinates_gives_the_file_com(tmp_path: Path) -> None:
    """Why the comparison's AddBiomechanics marker error is fair: our forward kinematics of
    the file's coordinates with the embedded model gives the file's centre of mass (nimble
    leaves the two 0.06 kg patella bodies out, hence the 1 mm tolerance)."""
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton

    f = open_b3d(B3D)
    p = tmp_path / "m.osim"
    p.write_text(f.model_text(0))
    model = read_osim(p)
    skel = Skeleton(model)
    cols = [skel.coordinate_index(n) for n in dof_names(model)]
    for k, info in enumerate(f.header.trials):
        fr = f.read_trial(k)
        q = np.zeros((info.n_frames, skel.n))
        q[:, cols] = fr.passes[0].pos
        com = skel.center_of_mass(skel.cmap.complete(q))
        # the file's comPos is 0 on frame 0 (README_b3d.md)
        np.testing.assert_allclose(com[1:], fr.passes[0].com_pos[1:], atol=1e-3)


@pytest.mark.slow
def test_convert_process_compare(tmp_path: Path) -> None:
    """results.b3d converted and processed: our marker RMS is below AddBiomechanics' pass,
    our residuals are within the Hicks thresholds on the frames with measured force."""
    from solver.io.b3d_compare import compare_with_b3d

    subject, out = tmp_path / "subject", tmp_path / "out"
    assert main(["convert", str(B3D), "--out", str(subject)]) == 0
    assert main(["process", str(subject), "--out", str(out)]) == 0
    rows = compare_with_b3d(B3D, out)
    assert len(rows) == 2
    for r in rows:
        assert r["addb_marker_rms_m"] < r["b3d_marker_rms_m"]
        assert r["addb_observed_frames"] > 0.8 * r["measured_frames"]
        assert r["linear_residual_rms_N"] <= r["hicks_linear_threshold_N"]
        assert r["angular_residual_rms_Nm"] <= r["hicks_angular_threshold_Nm"]
    (tmp_path / "rows.json").write_text(json.dumps(rows))


def test_force_removes_the_trials_of_the_earlier_conversion_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``addb convert --force`` of a file with fewer trials: the trial folders the earlier
    conversion wrote and this file does not have go (``addb process`` would otherwise solve
    them with the new subject); a trial folder of the user's own, and one of the earlier
    conversion's with another file in it, stay, and the command says which."""
    f = open_b3d(B3D)
    first, second = (t.name for t in f.header.trials)
    one = tmp_path / "one_trial.b3d"
    write_b3d(one, dataclasses.replace(f.header, trials=f.header.trials[:1]), [f.read_trial(0)])
    out = tmp_path / "subject"
    assert main(["convert", str(B3D), "--out", str(out)]) == 0
    mine = out / "trials" / "mine"
    mine.mkdir()
    (mine / "markers.trc").write_bytes((out / "trials" / first / "markers.trc").read_bytes())
    (out / "trials" / second / "notes.txt").write_text("the reviewer's own file\n")
    capsys.readouterr()
    assert main(["convert", str(one), "--out", str(out), "--force"]) == 0
    printed = capsys.readouterr().out
    assert "kept trial folders of the earlier conversion that this file does not have, as they hold other files" in printed
    assert printed.rstrip().count(second) == 1 and "removed" not in printed
    assert sorted(p.name for p in (out / "trials").iterdir()) == sorted([first, second, "mine"])
    (out / "trials" / second / "notes.txt").unlink()
    assert main(["convert", str(B3D), "--out", str(out), "--force"]) == 0
    capsys.readouterr()
    assert main(["convert", str(one), "--out", str(out), "--force"]) == 0
    printed = capsys.readouterr().out
    assert f"removed the trial folders of the earlier conversion that this file does not have: {second}" in printed
    assert sorted(p.name for p in (out / "trials").iterdir()) == sorted([first, "mine"])
    assert [t.name for t in load_subject(out).trials] == sorted([first, "mine"])
    assert np.array_equal(read_trc(mine / "markers.trc").positions, read_trc(out / "trials" / first / "markers.trc").positions, equal_nan=True)


def test_a_pass_the_file_does_not_have_is_named_with_the_passes_it_has(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """results.b3d has one processing pass: ``--pass 7`` fails before anything is written,
    naming the pass it has (the message read "1 processing passes")."""
    assert len(open_b3d(B3D).header.passes) == 1
    assert main(["convert", str(B3D), "--out", str(tmp_path / "s"), "--pass", "7"]) == 1
    err = capsys.readouterr().err
    assert f"SubjectFolderError ({B3D}): the file has one processing pass (pass 0), no pass 7 to take the model from" in err, err
    assert not (tmp_path / "s").exists()


def test_a_file_without_a_subject_mass_is_refused_before_anything_is_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A .b3d whose header has no mass (proto3 reads an absent one as 0): the conversion fails
    naming the .b3d and the missing mass, and leaves no folder (it wrote a subject folder
    that ``addb process`` then refused, naming that folder's own ``_subject.json``)."""
    f = open_b3d(B3D)
    no_mass = tmp_path / "no_mass.b3d"
    write_b3d(no_mass, dataclasses.replace(f.header, mass_kg=0.0), [f.read_trial(k) for k in range(len(f.header.trials))])
    assert main(["convert", str(no_mass), "--out", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert f"SubjectFolderError ({no_mass}): the file's header gives no subject mass (mass_kg 0.0)" in err, err
    assert not (tmp_path / "s").exists()



def _header_with(tmp_path: Path, name: str, **changes: object) -> Path:
    """results.b3d rewritten with its header's fields ``changes`` (dataclasses.replace)."""
    f = open_b3d(B3D)
    out = tmp_path / f"{name}.b3d"
    write_b3d(out, dataclasses.replace(f.header, **changes), [f.read_trial(k) for k in range(len(f.header.trials))])
    return out


@pytest.mark.parametrize(
    ("case", "changes", "message"),
    [
        ("mass in grams", {"mass_kg": 68000.0}, r", header\): mass_kg 68000 is more than 500 kg"),
        ("height in cm", {"height_m": 172.0}, r", header\): height_m 172 is more than 3 m"),
        ("a marker twice", "marker", r", header\): marker names (\S+) appear more than once in marker_name"),
        ("a 1 ns time step", "timestep", r", trial 'walking2_segment_0'\): trial_timestep 1e-09 s \(1e\+09 Hz\); expected"),
        ("truncated model text", "model", r", pass 0\): the model text of pass 0 is not well-formed XML"),
    ],
)
def test_a_header_convert_would_write_wrong_is_refused_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, changes: object, message: str
) -> None:
    """Input audit 2026-12-02, findings 10 and 14: header values that ``_subject.json``, the
    TRC reader or the dynamics would refuse in the written folder (naming its own files, the
    folder left half written) are refused first, naming the .b3d and the field, trial or
    pass, and no folder is written."""
    f = open_b3d(B3D)
    if changes == "marker":
        names = list(f.header.marker_names)
        names[1] = names[0]
        changes = {"marker_names": tuple(names)}
    elif changes == "timestep":
        trials = list(f.header.trials)
        k = f.header.trial_index("walking2_segment_0")
        trials[k] = dataclasses.replace(trials[k], timestep_s=1e-9)
        changes = {"trials": tuple(trials)}
    elif changes == "model":
        passes = list(f.header.passes)
        passes[0] = dataclasses.replace(passes[0], model_osim_text=passes[0].model_osim_text[: len(passes[0].model_osim_text) // 2])
        changes = {"passes": tuple(passes)}
    bad = _header_with(tmp_path, case.replace(" ", "_"), **changes)
    assert main(["convert", str(bad), "--out", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert f"SubjectFolderError ({bad}, " in err and "nothing was written" in err, err
    assert re.search(message, err), err
    assert not (tmp_path / "s").exists()


def test_a_file_without_a_height_converts_without_one(tmp_path: Path) -> None:
    """Input audit 2026-12-02, finding 10: a header height of 0 (proto3's absent value, what
    addb export writes for a subject without one) is left out of ``_subject.json`` (it was
    written as 0, which ``addb process`` refused); the subject loads with no height."""
    no_height = _header_with(tmp_path, "no_height", height_m=0.0)
    assert main(["convert", str(no_height), "--out", str(tmp_path / "s")]) == 0
    assert "heightM" not in json.loads((tmp_path / "s" / "_subject.json").read_text())
    subject = load_subject(tmp_path / "s")
    assert subject.height_m is None and subject.mass_kg == open_b3d(B3D).header.mass_kg


@pytest.mark.slow
def test_a_trial_renamed_by_the_conversion_is_compared_under_its_folder_name(tmp_path: Path) -> None:
    """Trial names with spaces become folder names with underscores; the conversion's
    ``b3d_source.json`` maps them back (:func:`converted_trial_folders`), and the comparison
    with the file given that map finds every trial (``scripts/b3d_compare.py`` passed none
    and stopped with FileNotFoundError on the first)."""
    from solver.io.b3d_compare import compare_with_b3d
    from solver.io.b3d_convert import converted_trial_folders

    f = open_b3d(B3D)
    spaced = tmp_path / "spaced.b3d"
    trials = tuple(dataclasses.replace(t, name=t.name.replace("_segment_", " segment ")) for t in f.header.trials)
    write_b3d(spaced, dataclasses.replace(f.header, trials=trials), [f.read_trial(k) for k in range(len(trials))])
    subject, out = tmp_path / "subject", tmp_path / "out"
    assert main(["convert", str(spaced), "--out", str(subject)]) == 0
    names = converted_trial_folders(subject)
    assert names == {t.name: t.name.replace(" ", "_") for t in trials} and all(" " in n for n in names)
    assert main(["process", str(subject), "--out", str(out)]) == 0
    with pytest.raises(FileNotFoundError):
        compare_with_b3d(spaced, out)
    rows = compare_with_b3d(spaced, out, trial_names=names)
    assert [r["trial"] for r in rows] == [t.name for t in trials]
    assert all(r["addb_marker_rms_m"] < r["b3d_marker_rms_m"] for r in rows)


def _with_labels(f, k: int, runs: dict[tuple[int, int], str], path: Path) -> Path:
    """``f`` written to ``path`` with trial ``k``'s missing-GRF labels set to ``runs``
    ((start, stop) -> reason; every other frame ``notMissingGRF``)."""
    info = f.header.trials[k]
    reasons = ["notMissingGRF"] * info.n_frames
    for (start, stop), reason in runs.items():
        reasons[start:stop] = [reason] * (stop - start)
    trials = list(f.header.trials)
    trials[k] = dataclasses.replace(info, missing_grf=tuple(reasons))
    write_b3d(path, dataclasses.replace(f.header, trials=tuple(trials)), [f.read_trial(j) for j in range(len(trials))])
    return path


def test_force_replaces_the_earlier_import_and_keeps_the_reviewers_flags_and_notes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A converted subject reviewed (alice flags frames on both trials, one range over a
    label of the file, and writes a note), then converted again with ``--force`` from a file
    whose labels moved: the record's imported flags and notes are exactly the new file's,
    alice's flags (foot, author) and note stay, and the command says it kept them. Converted
    once more from a file without the labelled trial: that trial's import goes with its
    folder, alice's flags on it stay."""
    from annotations import AnnotationStore

    f = open_b3d(B3D)
    first, second = (t.name for t in f.header.trials)
    old = _with_labels(f, 1, {(3, 9): "notOverForcePlate", (50, 52): "manualReview"}, tmp_path / "old.b3d")
    new = _with_labels(f, 1, {(20, 25): "notOverForcePlate"}, tmp_path / "new.b3d")
    out = tmp_path / "subject"
    assert main(["convert", str(old), "--out", str(out)]) == 0
    with AnnotationStore.open(out / "annotations.json", reviewer="alice") as store:
        store.set_unmeasured(second, range(60, 70), foot="left")
        store.set_unmeasured(second, range(4, 7), foot="right")  # over the file's label at 3-8
        store.set_unmeasured(first, range(10, 20))
        store.add_note(second, "alice: the left foot is off the plate", start=60, stop=70)
    capsys.readouterr()
    assert main(["convert", str(new), "--out", str(out), "--force"]) == 0
    printed = capsys.readouterr().out
    with AnnotationStore.open(out / "annotations.json", reviewer="checker") as store:
        runs = [(r.start, r.stop, r.foot, r.provenance.source, r.provenance.reviewer) for r in store.flag_runs(second)]
        assert runs == [
            (4, 7, "right", "manual", "alice"),
            (20, 25, None, "imported", "addb convert"),
            (60, 70, "left", "manual", "alice"),
        ]
        assert [(r.start, r.stop) for r in store.flag_runs(first)] == [(10, 20)]
        notes = sorted((n.start, n.stop, n.text, n.provenance.source) for n in store.notes(second))
        assert notes == [
            (20, 25, "AddBiomechanics: missing GRF (notOverForcePlate)", "imported"),
            (60, 70, "alice: the left foot is off the plate", "manual"),
        ]
    kept = ", ".join(f"{name} {n}" for name, n in sorted({first: 10, second: 13}.items()))  # in the order of the names
    assert f"kept the reviewers' own flags and notes in the review record (flagged frames: {kept})" in printed
    one = tmp_path / "one_trial.b3d"
    write_b3d(one, dataclasses.replace(f.header, trials=f.header.trials[:1]), [f.read_trial(0)])
    assert main(["convert", str(one), "--out", str(out), "--force"]) == 0
    with AnnotationStore.open(out / "annotations.json", reviewer="checker") as store:
        assert [(r.start, r.stop, r.provenance.source) for r in store.flag_runs(second)] == [(4, 7, "manual"), (60, 70, "manual")]
        assert [n.provenance.source for n in store.notes(second)] == ["manual"]
