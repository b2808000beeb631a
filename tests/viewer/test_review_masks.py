"""The review record -> the solver's unmeasured-force masks (addb_viewer.review_masks): the
app's Reprocess, ``addb process`` (one subject and a dataset) and ``addb diagnose`` give the
solver the same masks for one record of a real subject (the Camargo circuit: 200 Hz markers,
100 Hz processed frames); which trials enter; a record at the marker rate and an
AddBiomechanics review.json resampled onto the processed frames by the one rule; and
review.json import/export through the one reader (solver.io.review) and the one writer
(annotations.addb), byte for byte on the shared files."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from addb_viewer.review_masks import (
    import_addb_review,
    masks_from_file,
    subject_masks,
    unmeasured_force,
)
from annotations import AnnotationError, AnnotationStore, export_addb_review, write_addb_review
from solver.errors import FileFormatError, SubjectFolderError
from solver.io.review import read_review
from solver.masks import true_runs
from tests.conftest import SHARED_DATA, writable_copy

REPO = Path(__file__).resolve().parents[2]
UHLRICH = SHARED_DATA / "trials" / "opencap_uhlrich2023"
REVIEW_FILES = sorted(UHLRICH.glob("*/addb_review_segment_*.json"))
pytestmark = pytest.mark.filterwarnings("ignore:.*the moment columns are moments about:UserWarning")  # Camargo's plates
N_MARKERS, N_FRAMES = 3067, 1534  # the Camargo circuit: 200 Hz markers from 5 ms, 100 Hz processed frames


@pytest.fixture(scope="module")
def camargo_files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("camargo") / "camargo"
    subprocess.run([sys.executable, "scripts/make_example_subject.py", "camargo2021_levelground", str(folder)], check=True, cwd=REPO)
    return folder


@pytest.fixture
def camargo(camargo_files: Path, tmp_path: Path) -> Path:
    """A private copy of the Camargo subject folder (its record goes inside it)."""
    return writable_copy(camargo_files, tmp_path / "camargo")


class _Captured(Exception):
    """Raised by the stand-in solver once it has the masks the command gave it."""


def _capture(monkeypatch: pytest.MonkeyPatch, seen: dict) -> None:
    """Replace the solver's entry points by ones that keep their ``unmeasured_force``."""
    import solver.diagnose.core
    import solver.pipeline

    def process_subject(*args, unmeasured_force=None, **kw):
        seen["process"] = unmeasured_force
        raise _Captured

    def diagnose_trial(*args, unmeasured_force=None, **kw):
        seen["diagnose_trial"] = unmeasured_force
        raise _Captured

    monkeypatch.setattr(solver.pipeline, "process_subject", process_subject)
    monkeypatch.setattr(solver.diagnose.core, "diagnose_trial", diagnose_trial)


def _app_masks(store: AnnotationStore, subject: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict:
    """What the review app's Reprocess gives the solver (Reprocessor._masks)."""
    from addb_viewer.app.reprocess import Reprocessor

    monkeypatch.setenv("ADDB_WARM_SOLVER", "0")
    errors: list = []
    app = SimpleNamespace(store=store, paths=SimpleNamespace(subject_dir=subject, out_dir=tmp_path / "out", jobs_dir=tmp_path / "jobs"),
                          show_error=lambda context, exc: errors.append((context, exc)))  # fmt: skip
    masks = Reprocessor(app)._masks()  # type: ignore[arg-type]
    assert errors == []
    return masks


def test_app_process_and_diagnose_give_the_solver_the_same_masks(camargo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One record of the Camargo circuit, as the app writes it (the processed trial's 1534
    frames at 100 Hz): the app's Reprocess, ``addb process SUBJECT --annotations``, ``addb
    process DATASET`` (the runner's mask loader) and ``addb diagnose`` (its processing
    and its diagnosis) all give the solver exactly the reviewer's frames."""
    from addb_viewer.cli import main as cli

    record = camargo / "annotations.json"  # where addb view keeps a writable subject's record
    with AnnotationStore.open(record, reviewer="ana") as store:
        store.set_trial_info("levelground", n_frames=N_FRAMES, rate_hz=100.0)
        store.set_unmeasured("levelground", range(100, 140), foot="left")
        store.set_unmeasured("levelground", range(700, 705))
        app = _app_masks(store, camargo, tmp_path, monkeypatch)
    expected = np.zeros(N_FRAMES, dtype=bool)
    expected[100:140] = expected[700:705] = True

    seen: dict = {}
    _capture(monkeypatch, seen)
    with pytest.raises(_Captured):
        cli(["process", str(camargo), "--out", str(tmp_path / "p"), "--annotations", str(record)])
    process = seen.pop("process")
    dataset = subject_masks(str(camargo), str(tmp_path / "d"))
    with pytest.raises(_Captured):
        cli(["diagnose", str(camargo), "--trial", "levelground", "--out", str(tmp_path / "g")])  # not processed: processes first
    diagnose_process = seen.pop("process")
    (tmp_path / "g2" / "levelground").mkdir(parents=True)
    (tmp_path / "g2" / "levelground" / "trial.npz").write_bytes(b"")  # processed already: diagnoses at once
    with pytest.raises(_Captured):
        cli(["diagnose", str(camargo), "--trial", "levelground", "--out", str(tmp_path / "g2"), "--annotations", str(record)])
    diagnose = seen.pop("diagnose_trial")

    for name, masks in {"app": app, "process": process, "dataset": dataset, "diagnose (processing)": diagnose_process}.items():
        assert sorted(masks) == ["levelground"], name
        np.testing.assert_array_equal(masks["levelground"], expected, err_msg=name)
    np.testing.assert_array_equal(diagnose, expected)


def test_an_annotations_path_with_no_record_is_refused_and_nothing_created(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """``addb process``/``addb diagnose --annotations`` with a mistyped path: exit 1 naming the
    path before anything runs, no record created there (the store would create one) and no
    output; the subject's own record is not read in its place. A folder holding a record is
    taken as that record."""
    from addb_viewer.cli import main as cli

    walk = SHARED_DATA / "subjects" / "rajagopal2016_walk"
    seen: dict = {}
    _capture(monkeypatch, seen)  # the solver never runs: it would raise _Captured
    for argv in (["process", str(walk), "--out", str(tmp_path / "out")],
                 ["diagnose", str(walk), "--trial", "walk", "--out", str(tmp_path / "out")]):  # fmt: skip
        for typo in (tmp_path / "typo.json", tmp_path / "typo", tmp_path):
            assert cli([*argv, "--annotations", str(typo)]) == 1, (argv[0], typo)
            err = capsys.readouterr().err
            assert f"addb {argv[0]}: AnnotationFileError ({typo})" in err and "nothing was created" in err
            assert "no such file or folder" in err if typo != tmp_path else "a folder without annotations.json" in err
            assert sorted(p.name for p in tmp_path.iterdir()) == [], (argv[0], typo)
    assert seen == {}
    subject = writable_copy(walk, tmp_path / "walk")
    with AnnotationStore.open(subject, reviewer="ana") as store:
        store.set_unmeasured("walk", range(10, 20))
    with pytest.raises(_Captured):
        cli(["process", str(subject), "--out", str(tmp_path / "p"), "--annotations", str(subject)])
    assert seen.pop("process")["walk"][10:20].all()


def test_a_record_of_another_subject_is_refused_and_unknown_trials_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:  # fmt: skip
    """``addb process``/``addb diagnose SUBJECT --annotations RECORD`` with the record of
    another subject (the walk's flags given for the run): exit 1 before the solver runs,
    naming the record, its trials and the subject's. A record that names the subject's
    trials and one more (a trial folder since removed) is taken, with a warning naming the
    trial whose flags are not used."""
    from addb_viewer.cli import main as cli

    run = SHARED_DATA / "subjects" / "rajagopal2016_run"
    record = tmp_path / "walk_review.json"
    with AnnotationStore.open(record, reviewer="ana") as store:
        store.set_unmeasured("walk", range(10, 20))
    seen: dict = {}
    _capture(monkeypatch, seen)
    for argv in (["process", str(run), "--out", str(tmp_path / "out")],
                 ["diagnose", str(run), "--trial", "run", "--out", str(tmp_path / "out")]):  # fmt: skip
        assert cli([*argv, "--annotations", str(record)]) == 1, argv[0]
        err = capsys.readouterr().err
        assert f"addb {argv[0]}: SubjectFolderError ({record})" in err, err
        assert "names the trial walk and none of this subject's (run, static)" in err, err
        assert not (tmp_path / "out").exists()
    assert seen == {}

    with AnnotationStore.open(record, reviewer="ana") as store:
        store.set_unmeasured("run", range(30, 40))
    with pytest.raises(_Captured):
        cli(["process", str(run), "--out", str(tmp_path / "p"), "--annotations", str(record)])
    assert sorted(seen.pop("process")) == ["run"]
    # the command line shows warnings as one line each on stderr
    err = capsys.readouterr().err
    assert "addb: warning: walk_review.json names trials that rajagopal2016_run does not have (walk); their flags are not used" in err, err


def test_review_work_on_a_trial_the_subject_no_longer_has_is_named(tmp_path: Path) -> None:
    """The walk reviewed (frames 10-19 flagged), then its trial folder renamed ``walk_01``:
    the dataset run's mask loader takes no flag and warns, naming the record and the trial;
    a trial the record only knows the frames of (opened, not reviewed) is not named."""
    walk = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path / "walk")
    with AnnotationStore.open(walk, reviewer="ana") as store:
        store.set_unmeasured("walk", range(10, 20))
        store.set_trial_info("static", n_frames=287, rate_hz=100.0)
    (walk / "trials" / "static").rename(walk / "trials" / "static_01")
    (walk / "trials" / "walk").rename(walk / "trials" / "walk_01")
    with pytest.warns(UserWarning) as caught:
        assert subject_masks(str(walk), str(tmp_path / "out")) is None
    assert [str(w.message) for w in caught] == [
        "annotations.json holds review work on a trial this subject no longer has (walk): its flags are not used"
    ]


def test_a_record_at_the_marker_rate_is_resampled_by_the_overlap_rule(camargo: Path) -> None:
    """A record on the marker frames (an older ``addb convert``'s, here 200 Hz): marker
    frames 1000-1099 ([5.0025, 5.5025) s) become processed frames 500-550 (frame 550 overlaps
    by 2.5 ms), as an AddBiomechanics review.json of the same frames does."""
    flags = np.zeros(N_MARKERS, dtype=bool)
    flags[1000:1100] = True
    with AnnotationStore.open(camargo, reviewer="addb convert") as store:
        store.set_trial_info("levelground", n_frames=N_MARKERS, rate_hz=200.0)
        store.set_mask("levelground", flags, source="imported")
        masks = unmeasured_force(store, camargo)
    assert masks["levelground"].size == N_FRAMES and true_runs(masks["levelground"]) == [(500, 551)]
    review = camargo / "review.json"
    write_addb_review(review, flags)
    from_file = masks_from_file(review, camargo, reviewer="test")
    np.testing.assert_array_equal(from_file["levelground"], masks["levelground"])


def test_a_converted_b3d_at_another_rate_is_recorded_on_the_processed_frames(camargo: Path) -> None:
    """``addb convert`` (and ``addb view FILE.b3d``) store a .b3d's missing-GRF labels on the
    processed frames the review app shows and edits: labels on marker frames 1000-1099 of a
    200 Hz file become processed frames 500-550 at 100 Hz, the frames the solver takes from a
    record on the marker frames (test above), with their note on the same frames. Stored on
    the file's frames (until 2026-11-24), the app read them, and wrote new flags, as if they
    were processed frames: 10-11 s instead of 5-5.5 s."""
    from addb_viewer.commands.convert import write_review_record
    from solver.io.b3d_convert import ConvertedSubject, ConvertedTrial

    reasons = ["notMissingGRF"] * N_MARKERS
    reasons[1000:1100] = ["notOverForcePlate"] * 100
    converted = ConvertedSubject(camargo, camargo / "source.b3d", (ConvertedTrial("levelground", "levelground", N_MARKERS, 200.0, tuple(reasons)),))
    record = write_review_record(converted, reviewer="addb convert")
    with AnnotationStore.open(record, reviewer="test") as store:
        review = store.review("levelground")
        assert (review.n_frames, review.rate_hz) == (N_FRAMES, pytest.approx(100.0))
        assert true_runs(store.mask("levelground")) == [(500, 551)]
        assert store.flag("levelground", 500).provenance.source == "imported"
        assert [(n.start, n.stop, n.text) for n in store.notes("levelground")] == [(500, 551, "AddBiomechanics: missing GRF (notOverForcePlate)")]
        masks = unmeasured_force(store, camargo)
    # the solver's mask is the record's own (no second resampling: the record is at the processed rate)
    assert true_runs(masks["levelground"]) == [(500, 551)]


def test_which_trials_enter_and_flags_made_on_other_frames(tmp_path: Path) -> None:
    """Flagged or marked-reviewed trials enter (their flags replace the proposals); a trial
    only opened keeps the proposals; a trial without force plates has no dynamics; a record
    of another length at the processed rate is refused naming the trial and both counts."""
    walk = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path / "walk")
    with AnnotationStore.open(walk, reviewer="ana") as store:
        store.set_trial_info("walk", n_frames=238, rate_hz=100.0)
        store.set_trial_info("static", n_frames=287, rate_hz=100.0)
        store.set_unmeasured("static", range(3, 9))
        assert unmeasured_force(store, walk) == {}  # walk only opened; static has no plates
        store.set_reviewed("walk")
        masks = unmeasured_force(store, walk)
        assert sorted(masks) == ["walk"] and masks["walk"].shape == (238,) and not masks["walk"].any()
        store.set_unmeasured("walk", [10, 11])
        assert np.flatnonzero(unmeasured_force(store, walk)["walk"]).tolist() == [10, 11]
        store.set_trial_info("walk", n_frames=240, rate_hz=100.0)
        with pytest.raises(AnnotationError, match="240 frames for this trial but it has 238 processed frames") as info:
            unmeasured_force(store, walk)
        assert "walk" in str(info.value)


def test_a_review_json_needs_a_one_trial_subject_and_all_its_frames(camargo: Path, tmp_path: Path) -> None:
    two = SHARED_DATA / "subjects" / "rajagopal2016_walk"
    review = tmp_path / "review.json"
    write_addb_review(review, np.zeros(238, bool))
    with pytest.raises(SubjectFolderError, match="covers one trial; this subject has 2"):
        masks_from_file(review, two, reviewer="test")
    write_addb_review(review, np.zeros(N_MARKERS - 1, bool))
    with pytest.raises(FileFormatError, match=f"{N_MARKERS - 1} entries for a trial or segment of {N_MARKERS} marker frames"):
        masks_from_file(review, camargo, reviewer="test")


# ----------------------------------------------------------------------------- review.json <-> record


def test_the_shared_review_files_are_there() -> None:
    assert [p.parent.name for p in REVIEW_FILES] == ["DJ1", "walking1"]


@pytest.mark.parametrize("review", REVIEW_FILES, ids=lambda p: p.parent.name)
@pytest.mark.parametrize("start_frame", [0, 109])
def test_import_then_export_is_byte_exact(tmp_path: Path, review: Path, start_frame: int) -> None:
    original = review.read_bytes()
    n = len(read_review(review))
    trial = review.parent.name
    store = AnnotationStore.open(tmp_path, reviewer="ana")
    store.set_unmeasured(trial, range(start_frame + n, start_frame + n + 5))  # outside: not exported
    import_addb_review(store, trial, review, start_frame=start_frame, n_frames=n)
    out = tmp_path / "review.json"
    export_addb_review(store, trial, out, start_frame=start_frame, n_frames=n)
    assert out.read_bytes() == original
    store.close()
    reopened = AnnotationStore.open(tmp_path, reviewer="bob")  # and from what was saved on disk
    export_addb_review(reopened, trial, tmp_path / "again.json", start_frame=start_frame, n_frames=n)
    assert (tmp_path / "again.json").read_bytes() == original
    reopened.close()


def test_walking1_flags_are_imported_as_unmeasured_force(tmp_path: Path) -> None:
    review = UHLRICH / "walking1" / "addb_review_segment_1.json"
    with AnnotationStore.open(tmp_path, reviewer="ana") as store:
        edit = import_addb_review(store, "walking1", review)
        assert edit.changed == 24
        assert store.ranges("walking1") == [(0, 24)]  # foot off the plates at the start
        flag = store.flag("walking1", 0)
        assert flag.foot is None and flag.provenance.source == "imported" and flag.provenance.reviewer == "ana"
        np.testing.assert_array_equal(store.mask("walking1", 136), read_review(review))


def test_import_keeps_agreeing_manual_flags_clears_the_others_and_undoes(tmp_path: Path) -> None:
    review = UHLRICH / "walking1" / "addb_review_segment_1.json"
    with AnnotationStore.open(tmp_path, reviewer="ana") as store:
        store.set_unmeasured("walking1", 5, foot="left")  # agrees with the file: kept as is
        store.set_unmeasured("walking1", 50, foot="right")  # file says false: cleared
        before = store.snapshot()
        import_addb_review(store, "walking1", review)
        assert store.flag("walking1", 5).foot == "left" and store.flag("walking1", 50) is None
        assert store.ranges("walking1") == [(0, 24)]
        store.undo()  # one edit, one undo step
        assert store.snapshot() == before


def test_a_review_json_for_one_trial_of_several_is_taken_with_trial(tmp_path: Path) -> None:
    """``addb process SUBJECT --trial walk --annotations review.json``: the one trial named."""
    from solver.io.subject import load_subject, load_trial

    walk = SHARED_DATA / "subjects" / "rajagopal2016_walk"  # static and walk
    n = load_trial(load_subject(walk).trial("walk")).markers.n_frames
    flags = np.zeros(n, bool)
    flags[:30] = True
    review = tmp_path / "review.json"
    write_addb_review(review, flags)
    masks = masks_from_file(review, walk, reviewer="test", trials=("walk",))
    assert list(masks) == ["walk"] and masks["walk"][:25].all() and not masks["walk"][40:].any()
    with pytest.raises(SubjectFolderError, match="name it with --trial"):
        masks_from_file(review, walk, reviewer="test", trials=("walk", "static"))
    with pytest.raises(SubjectFolderError, match="no trial 'run'"):
        masks_from_file(review, walk, reviewer="test", trials=("run",))
