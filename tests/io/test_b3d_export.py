"""``addb export DIR --format b3d``: a processed subject (results.b3d converted and processed
by addb, dynamics pass included) written as .b3d holds exactly addb's values, and
write -> read -> write -> read is exact on every field. Also the dataset-tree form and the
reviewer flags as ``manualReview``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main
from solver.io.b3d import dof_names, open_b3d
from solver.io.b3d_writer import write_b3d
from solver.model.osim import read_osim
from solver.results import load_processed, processed_trials
from tests.conftest import SHARED_DATA
from tests.io.test_b3d_roundtrip import assert_same

B3D = SHARED_DATA / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def processed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("b3d_export")
    assert main(["convert", str(B3D), "--out", str(root / "subject")]) == 0
    assert main(["process", str(root / "subject"), "--out", str(root / "out")]) == 0
    return root / "out"


def test_export_holds_addb_values(processed: Path, tmp_path: Path) -> None:
    out_file = tmp_path / "ours.b3d"
    assert main(["export", str(processed), "--format", "b3d", "-o", str(out_file)]) == 0
    f = open_b3d(out_file)
    h = f.header
    assert [p.type for p in h.passes] == ["kinematics", "dynamics"]
    scaled = next(processed.glob("*_scaled.osim"))
    assert f.model_text(1) == scaled.read_text()
    from solver.model.osim import read_osim

    dofs = dof_names(read_osim(scaled))
    assert h.n_dofs == len(dofs)
    assert [t.name for t in h.trials] == processed_trials(processed)
    for k, info in enumerate(h.trials):
        ours = load_processed(processed, info.name)
        assert h.mass_kg == ours.mass_kg
        fr = f.read_trial(k)
        cols = [ours.coordinate_names.index(n) for n in dofs]
        dyn = fr.passes[1]
        np.testing.assert_array_equal(dyn.pos, ours.q[:, cols])
        np.testing.assert_array_equal(dyn.vel, ours.qd[:, cols])
        np.testing.assert_array_equal(dyn.acc, ours.qdd[:, cols])
        np.testing.assert_array_equal(dyn.tau, ours.tau[:, cols])
        np.testing.assert_array_equal(dyn.com_pos, ours.com)
        np.testing.assert_array_equal(dyn.com_acc, ours.com_acc)
        np.testing.assert_array_equal(fr.passes[0].pos, dyn.pos)
        assert not fr.passes[0].tau.any()
        for j, m in enumerate(ours.marker_names):
            np.testing.assert_array_equal(fr.markers[:, h.marker_names.index(m)], ours.observed[:, j])
        for p, plate in enumerate(ours.plates):
            np.testing.assert_array_equal(fr.plate_force[:, p], np.nan_to_num(plate.force))
            np.testing.assert_array_equal(fr.plate_moment[:, p], np.nan_to_num(plate.free_moment))
        # per-frame summaries, stored as float32
        tp = info.passes[1]
        np.testing.assert_array_equal(tp.linear_residual, np.linalg.norm(ours.residual_force, axis=1).astype(np.float32))
        np.testing.assert_array_equal(tp.angular_residual, np.linalg.norm(ours.residual_moment, axis=1).astype(np.float32))
        np.testing.assert_array_equal(tp.marker_rms, ours.marker_rms_per_frame.astype(np.float32))
        # contact: the sum of the body wrenches is the sum of the plate wrenches addb applied
        total_plate = sum(np.nan_to_num(p.force) * (p.body >= 0)[:, None] for p in ours.plates)
        np.testing.assert_allclose(dyn.ground_contact_force.sum(axis=1), total_plate, atol=1e-9)
        np.testing.assert_allclose(
            dyn.ground_contact_wrench[:, :, :3],
            np.cross(dyn.ground_contact_cop, dyn.ground_contact_force) + dyn.ground_contact_torque,
            atol=1e-9,
        )
        # missing GRF exactly on the frames addb left out of the dynamic fit
        missing = np.array([r != "notMissingGRF" for r in info.missing_grf])
        np.testing.assert_array_equal(missing, ours.unobserved)
        assert set(info.missing_grf) <= {"notMissingGRF", "notOverForcePlate", "forceDiscrepancy", "unmeasuredExternalForceDetected"}


def test_write_read_write_is_exact(processed: Path, tmp_path: Path) -> None:
    first = tmp_path / "first.b3d"
    assert main(["export", str(processed), "--format", "b3d", "-o", str(first)]) == 0
    a = open_b3d(first)
    frames = [a.read_trial(k) for k in range(len(a.header.trials))]
    second = tmp_path / "second.b3d"
    write_b3d(second, a.header, frames)
    b = open_b3d(second)
    assert_same(a.header, b.header, "header")
    for k, fr in enumerate(frames):
        assert_same(fr, b.read_trial(k), f"trial {k}")
    assert first.read_bytes() == second.read_bytes()


def test_reviewer_flags_become_manual_review(processed: Path, tmp_path: Path) -> None:
    from annotations import AnnotationStore

    out = tmp_path / "out"
    shutil.copytree(processed, out)
    trial = processed_trials(out)[0]
    n = load_processed(out, trial).n_frames
    with AnnotationStore.open(tmp_path / "out.annotations.json", reviewer="tester") as store:
        store.set_trial_info(trial, n_frames=n, rate_hz=100.0)
        store.set_unmeasured(trial, range(60, 64), source="manual")
    target = tmp_path / "flagged.b3d"
    assert main(["export", str(out), "--format", "b3d", "-o", str(target)]) == 0
    reasons = open_b3d(target).header.trials[0].missing_grf
    assert reasons[60:64] == ("manualReview",) * 4
    assert "manualReview" not in reasons[:60] + reasons[64:]


def test_dataset_tree_one_file_per_subject(processed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A dataset output tree: one file per subject its summary lists with processed trials, in
    the tree's layout; a failed subject is named as left out (it was left out silently); a
    folder inside the tree (``OUT/lab_a``) stands for the subjects below it, laid out below it
    (it was refused: "_subject.json is missing")."""
    tree = tmp_path / "tree"
    (tree / "lab_a").mkdir(parents=True)
    shutil.copytree(processed, tree / "lab_a" / "s01")
    shutil.copytree(processed, tree / "s02")
    (tree / "lab_a" / "s03").mkdir()  # failed: no processed trial
    # a processed output inside a hidden cache (the diagnosis' judged fit) is not a subject
    shutil.copytree(processed, tree / "s02" / ".addb_cache" / "judged_fit" / "walk" / "out")
    listed = [{"rel": "lab_a/s01", "status": "ok"}, {"rel": "lab_a/s03", "status": "failed"}, {"rel": "s02", "status": "ok"}]
    (tree / "dataset_summary.json").write_text(json.dumps({"dataset": str(tmp_path / "dataset"), "subjects": listed}))
    dest = tmp_path / "b3d_out"
    capsys.readouterr()
    assert main(["export", str(tree), "--format", "b3d", "-o", str(dest)]) == 0
    assert f"addb export: {tree}: left out a subject without processed trials (lab_a/s03)" in capsys.readouterr().err
    written = sorted(str(p.relative_to(dest)) for p in dest.rglob("*.b3d"))
    assert written == ["lab_a/s01.b3d", "s02.b3d"]
    for p in dest.rglob("*.b3d"):
        assert len(open_b3d(p).header.trials) == 2
    lab = tmp_path / "lab_out"
    assert main(["export", str(tree / "lab_a"), "--format", "b3d", "-o", str(lab)]) == 0
    assert sorted(str(p.relative_to(lab)) for p in lab.rglob("*.b3d")) == ["s01.b3d"]
    assert (lab / "s01.b3d").read_bytes() == (dest / "lab_a" / "s01.b3d").read_bytes()


def test_a_dataset_tree_exports_as_b3d_without_format(processed: Path, tmp_path: Path) -> None:
    """A dataset output tree (the only format it exports to is .b3d) given with ``-o FOLDER``
    and no ``--format``: the same files as with ``--format b3d``."""
    tree = tmp_path / "tree"
    shutil.copytree(processed, tree / "lab_a" / "s01")
    (tree / "dataset_summary.json").write_text(json.dumps({"dataset": str(tmp_path / "dataset"),
                                                           "subjects": [{"rel": "lab_a/s01", "status": "ok"}]}))  # fmt: skip
    assert main(["export", str(tree), "--format", "b3d", "-o", str(tmp_path / "given")]) == 0
    assert main(["export", str(tree), "-o", str(tmp_path / "inferred")]) == 0
    assert (tmp_path / "inferred" / "lab_a" / "s01.b3d").read_bytes() == (tmp_path / "given" / "lab_a" / "s01.b3d").read_bytes()


def test_benchmark_reads_b3d_like_our_output(processed: Path, tmp_path: Path) -> None:
    """The benchmark on the exported .b3d (its dynamics pass as ground truth) scores the
    same frames with the same ground truth as on addb's output folder."""
    from solver.benchmark.dataset import load_dataset, torque_columns

    exported = tmp_path / "subject.b3d"
    assert main(["export", str(processed), "--format", "b3d", "-o", str(exported)]) == 0
    ours = load_dataset([processed], inputs="processed")
    theirs = load_dataset([exported], inputs="processed")
    assert [t.trial for t in theirs.trials] == [t.trial for t in ours.trials]
    assert theirs.n_frames == ours.n_frames > 100
    for a, b in zip(ours.trials, theirs.trials, strict=True):
        np.testing.assert_array_equal(a.frames, b.frames)
        np.testing.assert_array_equal(a.contact, b.contact)
        np.testing.assert_array_equal(a.com_acc, b.com_acc)
        np.testing.assert_allclose(a.grf, b.grf, atol=1e-9)
        np.testing.assert_allclose(a.grm, b.grm, atol=1e-6)
        cols = torque_columns(a)
        np.testing.assert_array_equal(a.tau[:, cols], b.tau[:, cols])
        np.testing.assert_allclose(a.q, b.q, atol=1e-12)
    # the CLI takes the file as a subject, and scores it as the output folder
    for name, arg in (("b3d", exported), ("out", processed)):
        assert main(["benchmark", str(arg), "--inputs", "processed", "-o", str(tmp_path / name)]) == 0
    rows = [json.loads((tmp_path / name / "benchmark.json").read_text())["rows"][0] for name in ("b3d", "out")]
    assert rows[0]["frames"] == rows[1]["frames"]
    for metric in ("com_acc", "grf", "grm", "torque"):
        assert rows[0][metric] == pytest.approx(rows[1][metric], rel=1e-6), metric


def test_benchmark_needs_a_dynamics_pass(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """results.b3d has only a kinematics pass: no ground truth, a clear error."""
    assert main(["benchmark", str(B3D), "-o", str(tmp_path / "bench")]) == 1
    err = capsys.readouterr().err
    assert "no dynamics pass" in err and str(B3D) in err


def test_a_trial_without_force_data_exports_no_measured_frame(tmp_path: Path) -> None:
    """The walk's static trial has no force plates. Its frames were exported as
    ``notMissingGRF``: a reader took the standing subject for airborne (zero measured force),
    and ``addb benchmark`` of the file scored its 287 frames as flight (435 frames, 66 % flight,
    against the output folder's 148 frames of the walk alone). Every frame of a trial without
    dynamics is now ``notOverForcePlate``, and the file scores the frames the folder scores."""
    from solver.benchmark.dataset import load_dataset
    from tests.conftest import SHARED_DATA

    out = tmp_path / "out"
    assert main(["process", str(SHARED_DATA / "subjects" / "rajagopal2016_walk"), "--out", str(out)]) == 0
    exported = tmp_path / "walk.b3d"
    assert main(["export", str(out), "--format", "b3d", "-o", str(exported)]) == 0
    trials = {t.name: t for t in open_b3d(exported).header.trials}
    assert trials["static"].n_force_plates == 0 and not load_processed(out, "static").has_dynamics
    assert set(trials["static"].missing_grf) == {"notOverForcePlate"} and len(trials["static"].missing_grf) == trials["static"].n_frames
    walk = load_processed(out, "walk")
    np.testing.assert_array_equal([r != "notMissingGRF" for r in trials["walk"].missing_grf], walk.unobserved)
    # the header's mass is the scaled model's (the fitted one the walk's torques used), not the
    # static trial's given mass (trials[0], by name: the header said 85.07 kg, the model 84.95)
    f = open_b3d(exported)
    static = load_processed(out, "static")
    assert f.header.mass_kg == walk.mass_kg != static.mass_kg
    # the static trial has no fitted velocities: the central differences of its coordinates,
    # finite in both passes and in the header's per-frame maximum (they were NaN)
    k = f.header.trial_index("static")
    frames, info = f.read_trial(k), f.header.trials[k]
    cols = [static.coordinate_names.index(n) for n in dof_names(read_osim(next(out.glob("*_scaled.osim"))))]
    velocity = np.gradient(static.q[:, cols], static.time, axis=0)
    for kept in frames.passes:
        np.testing.assert_array_equal(kept.vel, velocity)
        np.testing.assert_array_equal(kept.acc, np.gradient(velocity, static.time, axis=0))
    assert all(np.isfinite(tp.joints_max_velocity).all() for tp in info.passes)
    # the time step of 100 Hz, not the median step of the time column (0.010000000000000009 s)
    assert {t.timestep_s for t in f.header.trials} == {0.01} and {t.rate_hz for t in f.header.trials} == {100.0}
    ours, theirs = load_dataset([out]), load_dataset([exported])
    assert [t.trial for t in theirs.trials] == [t.trial for t in ours.trials] == ["walk"]
    assert theirs.n_frames == ours.n_frames > 100


@pytest.fixture(scope="module")
def reviewed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """results.b3d converted, frames 60-63 of walking2_segment_0 flagged by a reviewer, and
    processed with ``--annotations SUBJ/annotations.json`` into a folder not named addb_out
    (the workflow ``addb convert`` prints): audit 2026-12-02-b3d findings 3 and 4."""
    from annotations import AnnotationStore

    root = tmp_path_factory.mktemp("b3d_reviewed")
    subject = root / "subj"
    assert main(["convert", str(B3D), "--out", str(subject)]) == 0
    with AnnotationStore.open(subject / "annotations.json", reviewer="tester") as store:
        store.set_unmeasured("walking2_segment_0", range(60, 64), source="manual")
    assert main(["process", str(subject), "--out", str(root / "out"), "--annotations", str(subject / "annotations.json")]) == 0
    return root / "out"


def test_an_output_folder_finds_its_subject_and_review_record(reviewed: Path, tmp_path: Path) -> None:
    """``addb export OUT`` of a folder processed with ``--annotations``: the reviewer's flags are
    ``manualReview`` (they were ``unmeasuredExternalForceDetected``) and the subject's tags,
    sex and age are kept (they were ``()``, ``unknown``, -1), found from the subject folder the
    output folder records, not from its name."""
    target = tmp_path / "x.b3d"
    assert main(["export", str(reviewed), "--format", "b3d", "-o", str(target)]) == 0
    h = open_b3d(target).header
    reasons = h.trials[h.trial_index("walking2_segment_0")].missing_grf
    assert reasons[60:64] == ("manualReview",) * 4
    assert "manualReview" not in reasons[:60] + reasons[64:]
    assert "manualReview" not in h.trials[h.trial_index("walking1_segment_0")].missing_grf
    source = open_b3d(B3D).header
    assert (h.tags, h.sex, h.age_years) == (source.tags, source.sex, source.age_years) == (("healthy",), "male", 18)


def test_the_inputs_subject_json_records_are_taken(reviewed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``subject_dir`` and ``review_record`` in the output folder's subject.json (relative to
    the folder, or absolute) name the inputs; a recorded null review record means none; a
    recorded path that is gone is named and left out; a value that is no path is refused
    naming subject.json."""
    from addb_viewer.commands.export import recorded_inputs
    from solver.outputs import REVIEW_RECORD_KEY, SUBJECT_DIR_KEY

    subject = reviewed.parent / "subj"
    out = tmp_path / "moved" / "out"
    shutil.copytree(reviewed, out, ignore=shutil.ignore_patterns(".addb_cache"))  # no cache: nothing else names the subject
    shutil.copy(subject / "annotations.json", tmp_path / "record.json")
    summary = json.loads((out / "subject.json").read_text())
    # the run recorded its inputs (addb process --annotations)
    assert (summary[SUBJECT_DIR_KEY], summary[REVIEW_RECORD_KEY]) == (str(subject.resolve()), str((subject / "annotations.json").resolve()))
    assert recorded_inputs(out) == (subject.resolve(), (subject / "annotations.json").resolve())
    del summary[SUBJECT_DIR_KEY], summary[REVIEW_RECORD_KEY]  # an output folder of an older addb, without its cache
    (out / "subject.json").write_text(json.dumps(summary))
    assert recorded_inputs(out) == (None, None)

    def record(**keys: object) -> None:
        (out / "subject.json").write_text(json.dumps({**summary, **keys}))

    record(**{SUBJECT_DIR_KEY: str(subject), REVIEW_RECORD_KEY: "../../record.json"})
    assert recorded_inputs(out) == (subject, out / "../../record.json")
    target = tmp_path / "x.b3d"
    assert main(["export", str(out), "--format", "b3d", "-o", str(target)]) == 0
    h = open_b3d(target).header
    assert h.trials[h.trial_index("walking2_segment_0")].missing_grf[60:64] == ("manualReview",) * 4 and h.tags == ("healthy",)
    record(**{SUBJECT_DIR_KEY: str(subject), REVIEW_RECORD_KEY: None})  # processed without flags: none, not the subject's
    assert recorded_inputs(out) == (subject, None)
    record(**{SUBJECT_DIR_KEY: str(tmp_path / "gone"), REVIEW_RECORD_KEY: None})
    capsys.readouterr()
    assert recorded_inputs(out) == (None, None)
    assert str(tmp_path / "gone") in capsys.readouterr().err
    from solver.errors import FileFormatError

    record(**{SUBJECT_DIR_KEY: 3})
    with pytest.raises(FileFormatError, match="subject_dir") as err:
        recorded_inputs(out)
    assert str(out / "subject.json") in str(err.value)
