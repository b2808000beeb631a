"""``addb diagnose`` end to end on the real walk: the JSON object, the real finding of the
unmodified trial, ``--apply`` feeding the next processing, the review app's panel, and
clear errors for bad input."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main as cli
from solver.corrections import read_extensions
from solver.diagnose.causes.registry import NAMES as CAUSES
from solver.results import load_processed
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import copy_subject, hide_body_mass
from tests.diagnose.harness import diagnose_json
from tests.trial_edits import zero_forces

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """A writable copy of the walk subject, processed and diagnosed once."""
    subject = copy_subject(WALK, tmp_path_factory.mktemp("cli") / "walk")
    return subject, diagnose_json(subject, "walk")


def test_json_object_has_the_issue_keys(walk: tuple[Path, dict]) -> None:
    subject, report = walk
    for key in ("marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm"):
        assert np.isfinite(report["baseline"][key])
    # processed with the pipeline's default (joint) fit: judged on the alternation, run again for it
    assert report["settings"]["judged_fit"] == {"fit": "rounds", "processed_fit": "converged", "rebuilt": True}
    assert sorted(c["cause"] for c in report["candidates"]) == sorted(CAUSES)
    # the causes whose rows carry the markers' errors are cross-validated on folds mixing the phases
    assert report["settings"]["folds"] == 5
    assert sorted(report["settings"]["folds_mixing_phases"]) == ["marker_offset", "segment_mass_distribution"]
    for c in report["candidates"]:
        assert set(c) >= {"cause", "parameters", "uncertainty", "score", "gain"}
    scores = [c["score"] for c in report["candidates"]]
    assert scores == sorted(scores, reverse=True)
    assert report["chosen"] in CAUSES
    assert set(report["after"]) >= {"marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm", "hicks_linear_ok"}
    # the saved file (what the review app reads) is the printed object, value for value
    saved = json.loads((subject / "addb_out" / "walk" / "diagnosis.json").read_text())
    assert _without_times(saved) == _without_times(report)


def _without_times(x: object) -> object:
    if isinstance(x, dict):
        return {k: _without_times(v) for k, v in x.items() if k not in ("seconds", "stage_seconds", "judged_fit")}
    if isinstance(x, list):
        return [_without_times(v) for v in x]
    return x


@pytest.fixture(scope="module")
def band(walk: tuple[Path, dict]) -> Path:
    """The walk processed with ``--fit band`` into a folder of its own (before any test
    diagnoses it there)."""
    subject, _ = walk
    out = subject.parent / "band"
    assert cli(["process", str(subject), "--out", str(out), "--fit", "band"]) == 0
    return out


def test_every_output_is_judged_on_the_alternation_and_left_untouched(walk: tuple[Path, dict], band: Path) -> None:
    """The diagnosis judges on the fit its rule was calibrated on, the alternation of
    ``--fit rounds`` (solver/diagnose/judged_fit.py): an output made with it is judged as it
    is, and on the default (joint fit) output and one made with ``--fit band`` it runs again
    in a scratch folder, so the three reports are equal, value for value; the user's output
    keeps its files (only diagnosis.json and the judged fit's cache entry,
    ``.addb_cache/judged_fit/walk``, are added by the first diagnosis)."""
    subject, report = walk
    out = subject / "addb_out"
    assert (out / ".addb_cache" / "judged_fit" / "walk" / "key.json").is_file()  # the fixture's diagnosis ran the alternation
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != "diagnosis.json"}
    again = diagnose_json(subject, "walk")
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != "diagnosis.json"}
    assert after == before
    assert _without_times(again) == _without_times(report)
    rounds = subject.parent / "rounds"
    assert cli(["process", str(subject), "--out", str(rounds), "--fit", "rounds"]) == 0
    on_rounds = diagnose_json(subject, "walk", "--out", str(rounds))
    assert on_rounds["settings"]["judged_fit"] == {"fit": "rounds", "processed_fit": "rounds", "rebuilt": False}
    assert not (rounds / ".addb_cache" / "judged_fit").exists()  # judged as processed: nothing run again
    assert _without_times(on_rounds) == _without_times(report)
    band_files = {p.relative_to(band): p.read_bytes() for p in band.rglob("*") if p.is_file() and p.name != "diagnosis.json"}
    on_band = diagnose_json(subject, "walk", "--out", str(band))
    assert on_band["settings"]["judged_fit"] == {"fit": "rounds", "processed_fit": "band", "rebuilt": True}
    assert _without_times(on_band) == _without_times(report)
    kept = {p.relative_to(band): p.read_bytes() for p in band.rglob("*") if p.is_file() and p.name != "diagnosis.json" and ".addb_cache" not in p.parts}
    assert kept == {k: v for k, v in band_files.items() if ".addb_cache" not in k.parts}
    judged = json.loads((rounds / "walk" / "results.json").read_text())
    default = json.loads((out / "walk" / "results.json").read_text())
    results = json.loads((band / "walk" / "results.json").read_text())
    for key in ("marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm"):
        assert report["baseline"][key] == judged[key]
        assert default[key] <= judged[key], key  # the joint fit: at or below the alternation it replaced
    assert default["linear_residual_rms_N"] < 0.9 * results["linear_residual_rms_N"]


def test_a_second_diagnosis_reads_the_judged_fit_from_its_cache(walk: tuple[Path, dict], band: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The judged fit's run is kept in ``OUT/.addb_cache/judged_fit/<trial>`` with its key:
    a second diagnosis of unchanged inputs runs no dynamics and reports the same values; a
    flag edit changes the key, runs the fit again with the flags and replaces the entry."""
    from solver import pipeline
    from solver.diagnose.core import DiagnoseOptions, diagnose_trial

    subject, _ = walk
    out = band
    report = diagnose_json(subject, "walk", "--out", str(out))
    entry = out / ".addb_cache" / "judged_fit" / "walk"
    key = json.loads((entry / "key.json").read_text())
    assert key["trial"] == "walk" and key["flags"] == {}
    calls: list[object] = []
    real = pipeline.reprocess_dynamics

    def counting(*args: object, **kwargs: object) -> object:
        calls.append(args)
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, "reprocess_dynamics", counting)
    again = diagnose_json(subject, "walk", "--out", str(out))
    assert calls == []
    assert _without_times(again) == _without_times(report)
    n = load_processed(out, "walk").n_frames
    flags = np.zeros(n, dtype=bool)
    flags[100:121] = True
    diagnose_trial(subject, "walk", out, unmeasured_force=flags, options=DiagnoseOptions(refit=False))
    assert len(calls) == 1
    flagged = json.loads((entry / "key.json").read_text())
    assert flagged["flags"]["walk"][0] == n and flagged["kinematics"] == key["kinematics"]
    judged = json.loads((entry / "out" / "walk" / "results.json").read_text())
    assert set(range(100, 121)) <= set(judged["unobserved_frames"])
    assert not (entry / "out" / ".addb_cache").exists()  # the kinematics cache stays in OUT only


def test_a_cache_entry_replaced_during_a_diagnosis_takes_no_files_from_it(walk: tuple[Path, dict], band: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A diagnosis reads the judged fit's cache entry from its own copy: another diagnosis
    that replaces (or removes) the entry meanwhile leaves the folder being read whole."""
    import shutil

    from solver import pipeline
    from solver.diagnose.judged_fit import judged_output

    subject, _ = walk
    out = band
    entry = out / ".addb_cache" / "judged_fit" / "walk"
    with judged_output(subject, out, "walk"):  # the entry for these flags (none), run if missing
        pass
    cached = load_processed(entry / "out", "walk")
    monkeypatch.setattr(pipeline, "reprocess_dynamics", lambda *a, **k: pytest.fail("the cache entry was not read"))
    with judged_output(subject, out, "walk") as folder:
        assert entry not in folder.parents
        shutil.rmtree(entry)  # what a concurrent replacement does to the old entry's folder
        read = load_processed(folder, "walk")
    np.testing.assert_array_equal(read.q, cached.q)
    np.testing.assert_array_equal(read.tau, cached.tau)


def test_unmodified_walk_names_its_steps_off_the_plates(walk: tuple[Path, dict]) -> None:
    """The walk has no reviewer flags: its real steps off the plates are the finding, and
    they are the frames the pipeline's contact analysis proposed on its own."""
    subject, report = walk
    assert report["chosen"] == "unmeasured_force", report["reason"]
    processed = load_processed(subject / "addb_out", "walk")
    found = np.zeros(processed.n_frames, dtype=bool)
    for a, b in report["chosen_parameters"]["frames"]:
        found[a:b] = True
    proposed = processed.proposed
    assert proposed.any()
    assert (found & proposed).sum() >= 0.8 * proposed.sum()
    assert (found & ~proposed).sum() <= 0.2 * found.sum()
    held = report["held_out"]
    assert held["after"]["linear_residual_rms_N"] < 0.5 * held["before"]["linear_residual_rms_N"]
    # the "before" marker RMS is that of the body translated to balance the missing force
    # (centimetres): the report says so beside the figures, in the text and the review app
    from addb_viewer.app.diagnosis import diagnosis_markdown

    assert held["before"]["marker_rms_m"] > 2 * held["after"]["marker_rms_m"]
    assert "moves the body off its markers" in held["note"]
    assert "moves the body off its markers" in diagnosis_markdown(subject / "addb_out", subject, "walk")


def test_review_panel_lists_the_markers_standing_out(walk: tuple[Path, dict]) -> None:
    """The walk's landmark markers carry real offsets beyond what the kinematics fit places
    (docs/diagnose/FINDINGS.md); besides the chosen cause the report lists them, and the
    review app's Diagnosis folder shows each of them with its estimate."""
    from addb_viewer.app.diagnosis import diagnosis_markdown

    subject, report = walk
    others = report["also_standing_out"]
    assert len(others) >= 3  # the shoulders, the elbows, the clavicles...
    assert all(e["cause"] == "marker_offset" for e in others)
    text = diagnosis_markdown(subject / "addb_out", subject, "walk")
    block = text.split("Other markers that stand out", 1)[1].split("\n\n")[1]  # the list after the heading
    listed = [line.replace("\\_", "_") for line in block.splitlines() if line.startswith("- ")]
    assert len(listed) == len(others), block
    for line, e in zip(listed, others):
        assert f"marker {e['parameters']['marker']} on {e['parameters']['body']}" in line


def test_refit_keeps_the_frames_the_solver_left_out(tmp_path: Path) -> None:
    """With no reviewer flags, the refit runs as the next ``addb process`` would: the
    solver's own unmeasured-force proposals stand (OpenCap's walk steps off its plates),
    so the refit fits about the frames the processing did. Replacing the proposals by the
    (empty) reviewer flags had brought every step off the plates back into the fit."""
    subject = copy_subject(SHARED_DATA / "subjects" / "opencap_uhlrich2023", tmp_path / "opencap")
    report = diagnose_json(subject, "walking1")
    results = json.loads((subject / "addb_out" / "walking1" / "results.json").read_text())
    assert report["chosen"] not in (None, "unmeasured_force")  # the extension leaves the flags alone
    left_out = results["n_frames"] - results["n_observed_frames"]
    assert left_out >= 10  # the solver left steps out
    assert abs(report["after"]["n_observed_frames"] - results["n_observed_frames"]) <= 0.25 * left_out
    # the reference refit (no extension) continues the processing on its frames exactly
    assert report["before_refit"]["n_observed_frames"] == results["n_observed_frames"]


def test_apply_feeds_the_next_processing_and_the_review_app(tmp_path: Path) -> None:
    """A hidden mass error is named, --apply saves it, the next processing uses it: the
    diagnosis of the reprocessed subject no longer names it, and the review app shows both."""
    subject = copy_subject(WALK, tmp_path / "walk")
    hidden = hide_body_mass(subject, "walk", np.random.default_rng(21))
    # the unmeasured frames of the walk first (a real finding; otherwise it is named first)
    assert diagnose_json(subject, "walk", "--apply")["chosen"] == "unmeasured_force"
    cli(["process", str(subject), "--out", str(subject / "addb_out")])
    report = diagnose_json(subject, "walk", "--apply")
    assert report["chosen"] == "body_mass", report["reason"]
    assert report["chosen_parameters"]["mass_change_kg"] == pytest.approx(hidden.truth["mass_change_kg"], abs=1.5)
    assert [e["cause"] for e in read_extensions(subject)] == ["unmeasured_force", "body_mass"]
    cli(["process", str(subject), "--out", str(subject / "addb_out")])
    after = diagnose_json(subject, "walk")
    assert after["chosen"] != "body_mass"
    mass = next(c for c in after["candidates"] if c["cause"] == "body_mass")
    assert abs(mass["parameters"]["mass_change_kg"]) < 1.0

    from addb_viewer.app.paths import ReviewPaths
    from addb_viewer.app.server import ReviewApp

    app = ReviewApp(ReviewPaths.for_subject(subject, subject / "addb_out"), reviewer="t", port=0, background=False)
    try:
        text = app.panel.diagnosis.content
        assert (f"`{after['chosen']}`" in text) if after["chosen"] else ("No cause stands out" in text)
        assert "`body_mass` (every trial)" in text and "`unmeasured_force` (this trial)" in text
    finally:
        app.stop()


def _run(*argv: str) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = cli(["diagnose", *argv])
    return code, err.getvalue()


def test_bad_input_gives_clear_errors(walk: tuple[Path, dict]) -> None:
    subject, _ = walk
    code, err = _run(str(subject), "--trial", "nope")
    assert code == 1 and "no trial 'nope'" in err and "walk" in err
    code, err = _run(str(subject), "--trial", "static")
    assert code == 1 and "no force plates" in err
    (subject / "addb_extensions.json").write_text("{not json")
    try:
        code, err = _run(str(subject), "--trial", "walk")
        assert code == 1 and "addb_extensions.json" in err
    finally:
        (subject / "addb_extensions.json").unlink()


def test_a_trial_without_a_measured_frame_has_nothing_to_diagnose(tmp_path: Path) -> None:
    """A trial whose plates never carry force is processed without residuals; its diagnosis
    says so, naming the trial and its results.json, and writes no diagnosis (it failed in
    the judged fit's rerun with the mass fit's message, after testing every cause)."""
    subject = copy_subject(WALK, tmp_path / "walk")
    shutil.copytree(subject / "trials" / "walk", subject / "trials" / "walk_zero")
    zero_forces(subject / "trials" / "walk_zero" / "grf.mot")
    out = tmp_path / "out"
    code, err = _run(str(subject), "--trial", "walk_zero", "--out", str(out))
    assert code == 1, err
    results = json.loads((out / "walk_zero" / "results.json").read_text())
    assert results["n_observed_frames"] == 0, results  # processed first, without measured frames
    errors = [line for line in err.splitlines() if line.startswith("addb diagnose:")]
    assert len(errors) == 1 and errors[0].startswith(f"addb diagnose: DiagnosisError ({out / 'walk_zero' / 'results.json'})"), err
    assert "trial 'walk_zero' has no frame with measured force in its fit (all 238 frames left out" in errors[0], errors
    assert errors[0].endswith("nothing to diagnose"), errors
    assert "testing candidate causes" not in err, err  # refused before the diagnosis, not after it
    assert not (out / "walk_zero" / "diagnosis.json").exists()


def test_apply_on_a_read_only_subject_is_refused_before_the_diagnosis(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--apply writes into the subject folder: a read-only one is refused at once (naming it),
    not after the processing and the diagnosis; without --apply the same folder is diagnosed."""
    import solver.pipeline

    def never(*args, **kw):
        raise AssertionError("the subject was processed before --apply was refused")

    monkeypatch.setattr(solver.pipeline, "process_subject", never)
    subject = copy_subject(WALK, tmp_path / "walk", trials=("walk",))
    subject.chmod(0o555)
    try:
        code, err = _run(str(subject), "--trial", "walk", "--out", str(tmp_path / "out"), "--apply")
        assert code == 1
        assert f"SubjectFolderError ({subject})" in err and "addb_extensions.json" in err and "read-only" in err
        assert not (tmp_path / "out").exists() and not (subject / "addb_extensions.json").exists()
        with pytest.raises(AssertionError, match="processed before"):  # without --apply it goes on to process
            _run(str(subject), "--trial", "walk", "--out", str(tmp_path / "out"))
    finally:
        subject.chmod(0o755)


def test_a_warning_about_the_data_is_shown_once_however_many_fits_repeat_it(tmp_path: Path) -> None:
    """A wrong massKg: the processing, the judged fit and both refits each warn that the
    fitted mass is far from it (the refits with their own fitted masses, from another
    place); the command shows the warning once."""
    subject = copy_subject(WALK, tmp_path / "walk")
    data = json.loads((subject / "_subject.json").read_text())
    (subject / "_subject.json").write_text(json.dumps({**data, "massKg": 65.0}))
    code, err = _run(str(subject), "--trial", "walk", "--out", str(tmp_path / "out"))
    assert code == 0
    lines = [x for x in err.splitlines() if "addb: warning:" in x]
    assert len(lines) == 1 and "the fitted mass 85.0 kg is +31 % from the subject's massKg (65 kg)" in lines[0], lines


def test_the_scale_response_changes_the_misplacement_reported_not_what_is_named(walk, monkeypatch) -> None:
    # the marker estimate adds back what the scale fit took up (m = (I - L)^-1 (offset +
    # residual shift)); its t value stays that of the residual shift: when it divided by the
    # larger error of the whole m, OpenCap DJ1's neutral base named other causes (2026-11-25)
    from solver.diagnose import core
    from solver.diagnose.core import DiagnoseOptions, diagnose_trial
    from solver.diagnose.selection import ChoiceRule, contends, significance

    subject, _ = walk
    with_l = diagnose_trial(subject, "walk", subject / "addb_out", options=DiagnoseOptions(refit=False))
    monkeypatch.setattr(core, "load_scale_response", lambda out_dir, trial: {})
    without = diagnose_trial(subject, "walk", subject / "addb_out", options=DiagnoseOptions(refit=False))
    rule = ChoiceRule()
    markers = {e.choice: e for e in with_l.evaluations if e.cause == "marker_offset"}
    plain = {e.choice: e for e in without.evaluations if e.cause == "marker_offset"}
    assert markers.keys() == plain.keys() and len(markers) >= 10
    moved = 0
    for name, ev in markers.items():
        assert significance(ev) == pytest.approx(significance(plain[name]), rel=1e-9), name
        assert contends(ev, rule) == contends(plain[name], rule), name
        np.testing.assert_allclose(ev.parameters["residual_shift_m"], plain[name].parameters["residual_shift_m"], rtol=1e-9, atol=1e-12)
        gap = np.linalg.norm(np.subtract(ev.parameters["shift_m"], plain[name].parameters["shift_m"]))
        np.testing.assert_allclose(gap, np.linalg.norm(ev.parameters["landmark_shift_m"]), rtol=1e-6, atol=1e-9)
        moved += gap > 0.002
    assert moved >= 3  # several of the walk's landmarks lose more than 2 mm to the scales
    chosen = [None if d.chosen is None else (d.chosen.cause, d.chosen.choice) for d in (with_l, without)]
    assert chosen[0] == chosen[1]
