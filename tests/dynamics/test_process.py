"""``addb process`` end to end on the real subjects: outputs, residual quality, OpenSim
reproduction, the Camargo circuit with steps off the plates, and bad input."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main as cli
from solver.errors import DynamicsError, SubjectFolderError
from solver.io.mot import read_table
from solver.pipeline import process_subject
from solver.results import load_processed
from tests.conftest import OPENSIM_REASON, SHARED_DATA, import_tool, writable_copy

REPO = Path(__file__).resolve().parents[2]
SUBJECTS = SHARED_DATA / "subjects"
OPENSIM_WALK = {"linear_BW": 0.090, "angular_BWh": 0.032}  # shared/oracles/README.md

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def walk_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("walk") / "out"
    assert cli(["process", str(SUBJECTS / "rajagopal2016_walk"), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def opencap_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("opencap") / "out"
    process_subject(SUBJECTS / "opencap_uhlrich2023", out)
    return out


def _results(out: Path, trial: str) -> dict:
    return json.loads((out / trial / "results.json").read_text())


def test_walk_writes_every_output_with_the_required_keys(walk_out: Path) -> None:
    assert (walk_out / "rajagopal2016_walk_scaled.osim").is_file()
    for f in ("walk_ik.mot", "walk_id.sto", "walk_grf.mot", "walk_external_loads.xml", "results.json", "trial.npz"):
        assert (walk_out / "walk" / f).is_file(), f
    r = _results(walk_out, "walk")
    for key in ("n_frames", "rate_hz", "mass_kg", "marker_rms_m", "marker_max_m", "linear_residual_rms_N",
                "angular_residual_rms_Nm", "linear_residual_rms_BW", "angular_residual_rms_BWh", "unobserved_frames", "stage_seconds"):
        assert key in r, key
    assert r["rate_hz"] == 100.0 and r["n_frames"] == 238
    assert abs(r["mass_kg"] - 85.07) < 2.0  # fitted mass near the stated one
    id_table = read_table(walk_out / "walk" / "walk_id.sto")
    assert "pelvis_tx_force" in id_table.column_names and "knee_angle_r_moment" in id_table.column_names
    # the static trial has no force plates: kinematics only
    assert "linear_residual_rms_N" not in _results(walk_out, "static")
    assert _results(walk_out, "static")["rate_hz"] == 100.0  # the nominal rate (solver.sampling), not 99.99999999999991


def test_walk_residuals_beat_opensim_and_meet_hicks(walk_out: Path) -> None:
    r = _results(walk_out, "walk")
    assert r["linear_residual_rms_BW"] < OPENSIM_WALK["linear_BW"]
    assert r["angular_residual_rms_BWh"] < OPENSIM_WALK["angular_BWh"]
    assert r["hicks_linear_ok"] and r["hicks_angular_ok"]
    assert r["linear_residual_rms_BW"] < 0.03 and r["angular_residual_rms_BWh"] < 0.05
    # at least as many frames with measured force as AddBiomechanics kept (114), marker RMS below its 1.47 cm
    assert r["n_observed_frames"] >= 114
    assert r["marker_rms_m"] < 0.0147


def test_walk_unobserved_frames_are_where_a_foot_is_on_the_floor(walk_out: Path) -> None:
    trial = load_processed(walk_out, "walk")
    unobserved = np.flatnonzero(trial.unobserved)
    # the subject starts and ends the trial standing on uninstrumented floor
    assert trial.unobserved[0] and trial.unobserved[-1]
    assert not trial.unobserved[100:150].any()
    assert all(trial.proposal_reasons[k] for k in unobserved)
    # each plate's force goes to one foot, and to the foot that is over it: the file's "r"
    # and "l" columns are the right and left foot's forces (tests/dynamics/test_contact.py)
    feet = {"r": trial.body_names.index("calcn_r"), "l": trial.body_names.index("calcn_l")}
    assert sorted(p.name for p in trial.plates) == sorted(feet)
    for plate in trial.plates:
        loaded = plate.force[:, 1] > 50
        assert loaded.sum() > 50, plate.name
        np.testing.assert_array_equal(plate.body[loaded], feet[plate.name], err_msg=plate.name)


@pytest.mark.opensim
def test_opensim_inverse_dynamics_reproduces_our_id_sto(walk_out: Path, tmp_path: Path) -> None:
    osim = import_tool("opensim", reason=OPENSIM_REASON)
    osim.Logger.setLevelString("error")
    mine = read_table(walk_out / "walk" / "walk_id.sto")
    tool = osim.InverseDynamicsTool()
    tool.setModelFileName(str(walk_out / "rajagopal2016_walk_scaled.osim"))
    tool.setCoordinatesFileName(str(walk_out / "walk" / "walk_ik.mot"))
    tool.setExternalLoadsFileName(str(walk_out / "walk" / "walk_external_loads.xml"))
    tool.setLowpassCutoffFrequency(-1)
    tool.setStartTime(float(mine.time[0]))
    tool.setEndTime(float(mine.time[-1]))
    tool.setResultsDir(str(tmp_path))
    tool.setOutputGenForceFileName("opensim_id.sto")
    excluded = osim.ArrayStr()
    excluded.append("Muscles")
    tool.setExcludedForces(excluded)
    tool.run()
    theirs = read_table(tmp_path / "opensim_id.sto")
    common = [c for c in mine.column_names if c in theirs.column_names]
    assert len(common) >= 37  # every independent coordinate
    diff = {c: float(np.abs(mine.column(c) - theirs.column(c)).max()) for c in common}
    worst = max(diff, key=diff.get)
    # the README's claim: OpenSim reproduces our generalized forces to 0.1 N·m (the
    # quintic spline's derivatives are the operator its InverseDynamicsTool applies)
    assert diff[worst] < 0.1, (worst, diff[worst])


def test_opencap_subject_processes_and_meets_the_targets(opencap_out: Path) -> None:
    for trial in ("DJ1", "walking1"):
        r = _results(opencap_out, trial)
        assert r["hicks_linear_ok"] and r["hicks_angular_ok"], trial
        assert r["linear_residual_rms_BW"] < 0.03 and r["angular_residual_rms_BWh"] < 0.05, trial


def test_opencap_walking_proposals_agree_with_the_addbiomechanics_review(opencap_out: Path) -> None:
    """The expert-reviewed AddBiomechanics file flags frames 0-23 of walking1 (a foot on the
    floor before the plates); our automatic proposals must find that span."""
    review = np.array(json.loads((SHARED_DATA / "trials" / "opencap_uhlrich2023" / "walking1" / "addb_review_segment_1.json").read_text())["missing_grf_data"])
    trial = load_processed(opencap_out, "walking1")
    ours = trial.unobserved[: review.size]  # both at 100 Hz from the first marker frame
    agreement = float(np.mean(ours == review))
    assert agreement > 0.9, agreement
    assert ours[np.flatnonzero(review)].mean() > 0.8


def test_reviewer_flags_override_proposals(tmp_path: Path) -> None:
    """Flags given to process_subject replace the automatic proposals (frame for frame)."""
    from solver.io.subject import load_subject, load_trial

    subject = load_subject(SUBJECTS / "rajagopal2016_walk")
    n = load_trial(next(t for t in subject.trials if t.name == "walk")).markers.n_frames
    flags = np.zeros(n, dtype=bool)
    flags[:50] = True
    flags[200:] = True
    res = process_subject(SUBJECTS / "rajagopal2016_walk", tmp_path / "out", unmeasured_force={"walk": flags})
    td = res.dynamics.trial("walk")
    np.testing.assert_array_equal(td.unobserved, flags[: td.unobserved.size])
    assert {r for r in td.reasons if r} == {"flagged by the reviewer"}


def test_camargo_steps_off_the_plates_are_proposed_and_fit(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "scripts/make_example_subject.py", "camargo2021_levelground", str(tmp_path / "camargo")], check=True, cwd=REPO)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the file's moments are about plate origins (converted, warned)
        res = process_subject(tmp_path / "camargo", tmp_path / "out")
    td = res.dynamics.trial("levelground")
    assert 0.1 < td.unobserved.mean() < 0.9  # several steps are on uninstrumented ground
    assert any("in contact with no plate force" in r for r in td.reasons)
    assert td.metrics["hicks_linear_ok"]


# ----------------------------------------------------------------------------- bad input


def _copy_subject(tmp_path: Path) -> Path:
    return writable_copy(SUBJECTS / "rajagopal2016_walk", tmp_path / "subject")


def _damage_grf(subject: Path, fn) -> None:
    path = subject / "trials" / "walk" / "grf.mot"
    lines = path.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 2
    lines[head:] = [fn(i, line) for i, line in enumerate(lines[head:])]
    path.write_text("\n".join(lines) + "\n")


def _kinematics_kept(subject: Path, out: Path, tmp_path: Path, match: str) -> None:
    """The trial the dynamics stage could not take is written as a kinematics-only trial:
    the motion file and marker errors of the kinematics stage alone (byte for byte those of
    ``process_kinematics``), with the error in its results.json."""
    from solver.pipeline import process_kinematics

    results = json.loads((out / "walk" / "results.json").read_text())
    error = results["dynamics_error"]
    assert error["type"] == "DynamicsError" and error["where"] == "trial walk" and match in error["message"]
    assert "linear_residual_rms_N" not in results and not load_processed(out, "walk").has_dynamics
    assert sorted(p.name for p in (out / "walk").iterdir()) == ["results.json", "trial.npz", "walk_ik.mot"]
    process_kinematics(subject, tmp_path / "kinematics")
    assert (out / "walk" / "walk_ik.mot").read_bytes() == (tmp_path / "kinematics" / "walk" / "walk_ik.mot").read_bytes()
    alone = json.loads((tmp_path / "kinematics" / "walk" / "results.json").read_text())
    for key in ("n_frames", "marker_rms_m", "marker_max_m", "marker_rms_by_marker_m", "markers_used", "markers_ignored"):
        assert results[key] == alone[key], key
    assert "dynamics_error" not in json.loads((out / "static" / "results.json").read_text())


@pytest.mark.parametrize(
    "damage, match",
    [
        (lambda i, line: line.replace(line.split("\t")[2], "nan", 1) if i == 1500 else line, "NaN"),
        (lambda i, line: "\t".join([line.split("\t")[0], line.split("\t")[1], "250000", *line.split("\t")[3:]]) if i == 1500 else line, "body weights"),
    ],
    ids=["nan_force", "absurd_force"],
)
def test_bad_forces_name_the_trial_and_keep_its_kinematics(tmp_path: Path, damage, match: str) -> None:
    subject = _copy_subject(tmp_path)
    _damage_grf(subject, damage)
    out = tmp_path / "out"
    with pytest.raises(DynamicsError, match=match) as err:
        process_subject(subject, out)
    assert "trial walk" in str(err.value)  # the stage's error as it is (a dataset run lists it so)
    _kinematics_kept(subject, out, tmp_path, match)
    assert not list(tmp_path.glob(".out.tmp-*"))


def test_forces_that_do_not_overlap_the_markers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from solver.pipeline import reprocess_dynamics

    subject = _copy_subject(tmp_path)
    _damage_grf(subject, lambda i, line: "\t".join([f"{float(line.split(chr(9))[0]) + 100.0:.6f}", *line.split("\t")[1:]]))
    out = tmp_path / "out"
    assert cli(["process", str(subject), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "addb process: DynamicsError (trial walk): markers (" in err and "do not overlap in time" in err
    assert f"the trial's kinematics were written without dynamics ({out / 'walk'}: motion and marker errors" in err
    _kinematics_kept(subject, out, tmp_path, "do not overlap in time")
    # a Reprocess (the review app's, after a flag edit) raises before it writes, as before
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(DynamicsError, match="do not overlap in time"):
        reprocess_dynamics(subject, out, ["walk"])
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_the_other_trials_dynamics_are_fitted_without_the_one_that_failed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """OpenCap with NaN in walking1's forces: DJ1's dynamics are fitted (on DJ1 alone, as
    for a subject without walking1), walking1 keeps its kinematics, the error says both, and
    ``addb diagnose`` of walking1 names the error instead of diagnosing nothing."""
    subject = writable_copy(SUBJECTS / "opencap_uhlrich2023", tmp_path / "oc")
    path = subject / "trials" / "walking1" / "grf.mot"
    lines = path.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 2
    cells = lines[head + 100].split("\t")
    cells[2] = "nan"
    lines[head + 100] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    with pytest.raises(DynamicsError, match="force is NaN") as err:
        process_subject(subject, out)
    assert "trial walking1" in str(err.value)
    assert "dynamics_error" in json.loads((out / "walking1" / "results.json").read_text())
    dj1 = json.loads((out / "DJ1" / "results.json").read_text())
    assert "dynamics_error" not in dj1 and np.isfinite(dj1["linear_residual_rms_N"])
    # DJ1's dynamics are the stage's on the same kinematics with walking1 given no forces
    from solver import single_threaded_blas
    from solver.dynamics.stage import run_dynamics
    from solver.io.subject import load_subject
    from solver.pipeline import subject_kinematics

    info = load_subject(subject)
    with single_threaded_blas():  # as the pipeline runs both stages: two BLAS threads sum in another order
        sk = subject_kinematics(info)
        trials = [(t.name, t.markers, t.forces if t.name == "DJ1" else None) for t in sk.trials]
        dyn = run_dynamics(sk.kinematics, trials, mass_kg=info.mass_kg, foot_bodies=info.foot_body_names, height_m=info.height_m)
    assert dj1["mass_kg"] == dyn.mass_kg  # the residuals to rounding
    assert dj1["linear_residual_rms_N"] == pytest.approx(dyn.trial("DJ1").metrics["linear_residual_rms_N"], rel=1e-9)
    capsys.readouterr()
    assert cli(["diagnose", str(subject), "--trial", "walking1", "--out", str(out)]) == 1
    assert "trial 'walking1' was processed without dynamics: plate" in capsys.readouterr().err


def test_missing_mass_names_the_file_and_key(tmp_path: Path) -> None:
    subject = _copy_subject(tmp_path)
    data = json.loads((subject / "_subject.json").read_text())
    del data["massKg"]
    (subject / "_subject.json").write_text(json.dumps(data))
    with pytest.raises(SubjectFolderError, match="massKg") as err:
        process_subject(subject, tmp_path / "out")
    assert "_subject.json" in str(err.value)
    assert cli(["process", str(subject), "--out", str(tmp_path / "out")]) == 1


def test_reprocessing_one_trial_keeps_the_others(walk_out: Path, tmp_path: Path) -> None:
    from solver.pipeline import ProcessOptions

    out = tmp_path / "out"
    shutil.copytree(walk_out, out)
    static_before = (out / "static" / "results.json").read_bytes()
    (out / "walk" / "stale.txt").write_text("from the previous run")
    process_subject(SUBJECTS / "rajagopal2016_walk", out, options=ProcessOptions(trials=("walk",)))
    assert (out / "static" / "results.json").read_bytes() == static_before  # untouched
    assert not (out / "walk" / "stale.txt").exists()  # the trial folder was replaced whole
    r = _results(out, "walk")
    assert r["hicks_linear_threshold_N"] == pytest.approx(0.05 * r["mass_kg"] * 9.80665)
    assert not list(tmp_path.glob(".out.*"))


def test_the_review_apps_table_gives_the_residuals_of_results_json(walk_out: Path) -> None:
    """The Reprocess table's residual figures are over the frames with measured force, as
    results.json's: over every frame they counted the force no plate measured on the frames
    left out of the fit (hundreds of newtons on the walk) and every such frame as over a
    Hicks threshold. The page's over-Hicks frames (its timeline track, status line and jump)
    are the same measured frames."""
    from addb_viewer.app.summary import hicks_exceeded, hicks_thresholds, trial_summary

    trial = load_processed(walk_out, "walk")
    r = _results(walk_out, "walk")
    s = trial_summary(trial)
    assert s["residual_force_rms_n"] == pytest.approx(r["linear_residual_rms_N"], rel=1e-9)
    assert s["residual_moment_rms_nm"] == pytest.approx(r["angular_residual_rms_Nm"], rel=1e-9)
    assert s["measured_frames"] == r["n_observed_frames"]
    over = hicks_exceeded(trial)
    assert s["hicks_frames"] == int(over.sum()) and not over[trial.unobserved].any()
    th = hicks_thresholds(trial)
    left_out_over = (np.linalg.norm(trial.residual_force, axis=1) > th.force_n) & trial.unobserved
    assert left_out_over.sum() > 10  # the frames a count over every frame would take
