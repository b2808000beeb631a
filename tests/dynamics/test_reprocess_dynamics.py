"""Reprocess after a flag edit: the dynamics stage only, on the kinematics cached by the
last full run (``solver.pipeline.reprocess_dynamics``), gives what a full run with the same
flags gives; a stale or missing cache means a full run; the review app's Reprocess uses it.

All on the real walk (rajagopal2016_walk: a static trial and a walk with force plates).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from solver import pipeline
from solver.dynamics.fit import CONVERGED_WEIGHTS
from solver.pipeline import (
    CACHE_DIR,
    KINEMATICS_CACHE,
    process_subject,
    reprocess_dynamics,
)
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
BAND = pipeline.options_for_fit("band")
KEYS = ("marker_rms_m", "marker_max_m", "linear_residual_rms_N", "angular_residual_rms_Nm", "mass_kg", "unobserved_frames")
ARRAYS = ("q", "tau", "residual_force", "residual_moment", "unobserved", "com")


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(subject copy, output of a full run with the (default) band fit, without flags): a
    Reprocess of it is not warm-started, so it equals a full run bit for bit."""
    root = tmp_path_factory.mktemp("reprocess")
    subject = writable_copy(WALK, root / "rajagopal2016_walk")
    out = root / "out"
    process_subject(subject, out, options=BAND)
    return subject, out


def _copy_out(out: Path, dst: Path) -> Path:
    shutil.copytree(out, dst, symlinks=True)
    return dst


def _flags(out: Path) -> dict[str, np.ndarray]:
    """The walk's current unmeasured frames (the proposals) plus frames 100-120 flagged:
    mid-stance on the plates, measured in the unflagged run."""
    r = json.loads((out / "walk" / "results.json").read_text())
    mask = np.zeros(r["n_frames"], dtype=bool)
    mask[r["unobserved_frames"]] = True
    assert not mask[100:121].any()
    mask[100:121] = True
    return {"walk": mask}


def _no_kinematics(monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(*a: object, **k: object) -> None:
        raise AssertionError("the kinematics stage ran")

    monkeypatch.setattr(pipeline, "subject_kinematics", boom)
    monkeypatch.setattr(pipeline, "run_kinematics", boom)


def _counting_kinematics(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    calls: list[int] = []
    real = pipeline.subject_kinematics

    def counted(*a: object, **k: object) -> pipeline.SubjectKinematics:
        calls.append(1)
        return real(*a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, "subject_kinematics", counted)
    return calls


def _results(out: Path) -> dict:
    return json.loads((out / "walk" / "results.json").read_text())


def test_full_run_writes_the_kinematics_cache(base: tuple[Path, Path]) -> None:
    subject, out = base
    assert (out / CACHE_DIR / KINEMATICS_CACHE).is_file()
    sk, why = pipeline.load_kinematics_cache(out, pipeline.kinematics_cache_key(pipeline.extend_subject(pipeline.load_subject(subject))))
    assert sk is not None, why
    assert [t.name for t in sk.kinematics.trials] == ["static", "walk"]
    # the cache is not a trial
    assert sorted(p.parent.name for p in out.glob("*/trial.npz")) == ["static", "walk"]


def test_flag_edit_reruns_the_dynamics_only_and_equals_a_full_run(
    base: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    subject, out = base
    flags = _flags(out)
    reference = tmp_path / "full"
    process_subject(subject, reference, options=replace(BAND, trials=("walk",)), unmeasured_force=flags)

    fast = _copy_out(out, tmp_path / "fast")
    before_static = (fast / "static" / "trial.npz").stat().st_mtime_ns
    _no_kinematics(monkeypatch)
    messages: list[str] = []
    result = reprocess_dynamics(subject, fast, ("walk",), flags, lambda m, f: messages.append(m))
    assert any("kinematics reused from the cache" in m for m in messages), messages

    a, b = _results(fast), _results(reference)
    # the flags took effect: frames 100-120 are unobserved now
    assert set(range(100, 121)) <= set(a["unobserved_frames"])
    # no warm start: the cached kinematics are bit for bit the full run's, so the numbers are equal
    for key in KEYS:
        assert a[key] == b[key], key
    pa, pb = load_processed(fast, "walk"), load_processed(reference, "walk")
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(pa, name), getattr(pb, name), err_msg=name)
    assert result.dynamics is not None and result.dynamics.mass_kg == b["mass_kg"]
    # only the named trial was replaced; the summary says where the kinematics came from
    assert (fast / "static" / "trial.npz").stat().st_mtime_ns == before_static
    summary = json.loads((fast / "subject.json").read_text())
    assert summary["kinematics_from_cache"] is True
    assert a["stage_seconds"]["kinematics"] < 0.05  # nothing but reading the cache


def test_warm_start_skips_kinematics_and_keeps_mass_and_flags_exact(
    base: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The opt-in warm start of the band fit: mass and unobserved frames are a full run's exactly (they come
    from the centre-of-mass fit on the kinematics); the fitted motion lands elsewhere (the
    fit stops on its relative-decrease tolerance, so its end point depends on its start):
    measured 2 % on the marker RMS, which is what this bounds."""
    subject, out = base
    flags = _flags(out)
    reference = tmp_path / "full"
    process_subject(subject, reference, options=replace(BAND, trials=("walk",)), unmeasured_force=flags)
    warm = _copy_out(out, tmp_path / "warm")
    _no_kinematics(monkeypatch)
    reprocess_dynamics(subject, warm, ("walk",), flags, warm_start=True)
    a, b = _results(warm), _results(reference)
    assert a["mass_kg"] == b["mass_kg"]
    assert a["unobserved_frames"] == b["unobserved_frames"]
    assert abs(a["marker_rms_m"] - b["marker_rms_m"]) < 0.05 * b["marker_rms_m"]
    assert a["linear_residual_rms_BW"] < 0.03 and a["angular_residual_rms_BWh"] < 0.05


def test_stale_or_missing_cache_falls_back_to_a_full_run(
    base: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    subject0, out0 = base
    subject = writable_copy(subject0, tmp_path / "rajagopal2016_walk")
    out = _copy_out(out0, tmp_path / "out")
    flags = _flags(out)
    calls = _counting_kinematics(monkeypatch)

    # the copied subject lives elsewhere: the key names the folder, so the cache is stale
    marker_file = subject / "trials" / "walk" / "markers.trc"
    messages: list[str] = []
    reprocess_dynamics(subject, out, ("walk",), flags, lambda m, f: messages.append(m))
    assert len(calls) == 1
    assert any("stale" in m and "full run" in m for m in messages), messages

    # the fallback rewrote the cache: the next flag edit reuses it
    reprocess_dynamics(subject, out, ("walk",), flags)
    assert len(calls) == 1

    # touching an input file makes it stale, naming the file
    st = marker_file.stat()
    os.utime(marker_file, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    messages.clear()
    reprocess_dynamics(subject, out, ("walk",), flags, lambda m, f: messages.append(m))
    assert len(calls) == 2
    assert any("trials/walk/markers.trc" in m for m in messages), messages

    # a saved extension (addb_extensions.json) makes it stale too
    (subject / "addb_extensions.json").write_text(json.dumps({"schema": "addb.extensions", "version": 1, "extensions": []}))
    messages.clear()
    reprocess_dynamics(subject, out, ("walk",), flags, lambda m, f: messages.append(m))
    assert len(calls) == 3
    assert any("addb_extensions.json" in m for m in messages), messages

    # no cache at all
    shutil.rmtree(out / CACHE_DIR)
    messages.clear()
    reprocess_dynamics(subject, out, ("walk",), flags, lambda m, f: messages.append(m))
    assert len(calls) == 4
    assert any("no kinematics cache" in m for m in messages), messages
    assert (out / CACHE_DIR / KINEMATICS_CACHE).is_file()


def test_app_reprocess_job_reruns_the_dynamics_only(
    base: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The Reprocessor asks for a dynamics-only job; the job's child runs it without the
    kinematics stage (run in this process, so the monkeypatch holds)."""
    from addb_viewer.app import jobs, reprocess

    subject, out0 = base
    out = _copy_out(out0, tmp_path / "out")
    flags = _flags(out)

    specs: list[jobs.JobSpec] = []

    class Recorder:
        def __init__(self, spec: jobs.JobSpec, work: Path, **kw: object) -> None:
            specs.append(spec)
            self.running = False

        def start(self) -> None:
            pass

    monkeypatch.setattr(reprocess, "SolverJob", Recorder)
    widget = SimpleNamespace
    panel = widget(trial=widget(value="walk"), progress=widget(value=0, visible=False), cancel=widget(disabled=True),
                   reprocess=widget(disabled=False), job_status=widget(content=""), comparison=widget(content=""))  # fmt: skip
    app = SimpleNamespace(paths=SimpleNamespace(subject_dir=subject, out_dir=out, jobs_dir=tmp_path / "jobs"),
                          store=None, trial=None, trials=["static", "walk"], panel=panel,
                          background_run=lambda: None)  # fmt: skip
    reprocess.Reprocessor(app).reprocess("walk")  # type: ignore[arg-type]
    assert len(specs) == 1 and specs[0].dynamics_only and specs[0].trials == ("walk",)
    reprocess.Reprocessor(app).process_subject()  # type: ignore[arg-type]
    assert not specs[1].dynamics_only  # the first processing stays a full run

    # the child with that spec (and the reviewer's flags)
    work = tmp_path / "work"
    work.mkdir()
    np.savez(work / "unmeasured_force.npz", m0=flags["walk"])
    spec_file = work / "job.json"
    spec_file.write_text(json.dumps({"subject_dir": str(subject), "out_dir": str(out), "trials": ["walk"],
                                     "unmeasured_force_trials": ["walk"], "unmeasured_force": str(work / "unmeasured_force.npz"),
                                     "kind": "process", "dynamics_only": True}))  # fmt: skip
    _no_kinematics(monkeypatch)
    lines: list[str] = []
    monkeypatch.setattr(jobs, "_emit", lambda obj: lines.append(json.dumps(obj)))
    assert jobs._child(str(spec_file)) == 0, lines
    assert any("kinematics reused" in line for line in lines), lines
    assert set(range(100, 121)) <= set(_results(out)["unobserved_frames"])


@pytest.fixture(scope="module")
def converged_base(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(subject copy, output of a full run with ``addb process --fit converged`` (the default), no flags)."""
    root = tmp_path_factory.mktemp("reprocess_converged")
    subject = writable_copy(WALK, root / "rajagopal2016_walk")
    out = root / "out"
    process_subject(subject, out, options=pipeline.options_for_fit("converged"))
    return subject, out


def test_converged_fit_has_lower_residuals_and_marker_error_than_the_band_fit(
    base: tuple[Path, Path], converged_base: tuple[Path, Path]
) -> None:
    """The converged fit (exact banded Gauss-Newton steps, the masses solved with the
    coordinates) reaches a lower marker RMS *and* lower linear and angular residuals than
    the band fit on the same measured frames (measured with the alternation: 1.28 against
    1.31 cm, 2.9 against 3.6 N, 4.9 against 7.7 N·m; with the joint fit 1.27 cm, 2.2 N, 4.2 N·m; its joint
    torques: tests/dynamics/test_joint_torques_opensim.py); the run records its settings,
    weights included."""
    a, b = _results(converged_base[1]), _results(base[1])
    assert a["n_observed_frames"] == b["n_observed_frames"]
    assert a["marker_rms_m"] < b["marker_rms_m"]
    assert a["linear_residual_rms_N"] < 0.9 * b["linear_residual_rms_N"]
    assert a["angular_residual_rms_Nm"] < 0.8 * b["angular_residual_rms_Nm"]
    fit = json.loads((converged_base[1] / "subject.json").read_text())["dynamics_settings"]["fit"]
    assert fit["direction"] == "coefficients" and fit["mass_fit"] == "joint"
    assert {k: fit[k] for k in CONVERGED_WEIGHTS} == CONVERGED_WEIGHTS


def test_converged_fit_reprocess_is_warm_started_and_equals_a_full_run_to_its_tolerance(
    converged_base: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Reprocess after a flag edit (as the review app calls it: no options) reruns the
    dynamics only, with the fit the output was made with, warm-started from the previous
    solution because that fit runs to convergence; it lands on a full run's answer with
    the same flags to the fit's tolerance. Mass and unobserved frames are exact (the
    centre-of-mass fit on the cached kinematics); the coordinates are not unique (the arms'
    rotations are barely observed), so what is bounded is what the fit minimizes: marker RMS
    to 1 % and the residual RMS on measured frames to 1 N and 1 N·m (measured 0.03 %,
    0.7 N and 0.5 N·m with another flag set)."""
    subject, out = converged_base
    flags = _flags(out)
    reference = tmp_path / "full"
    process_subject(subject, reference, options=pipeline.options_for_fit("converged", ("walk",)), unmeasured_force=flags)
    warm = _copy_out(out, tmp_path / "warm")
    _no_kinematics(monkeypatch)
    starts: list[dict] = []
    real = pipeline.previous_solutions
    monkeypatch.setattr(pipeline, "previous_solutions", lambda *a: starts.append(real(*a)) or starts[-1])
    reprocess_dynamics(subject, warm, ("walk",), flags)
    assert len(starts) == 1 and "walk" in starts[0]  # warm-started from the previous walk
    summary = json.loads((warm / "subject.json").read_text())
    assert summary["kinematics_from_cache"] is True
    assert summary["dynamics_settings"]["fit"]["direction"] == "coefficients"
    a, b = _results(warm), _results(reference)
    assert set(range(100, 121)) <= set(a["unobserved_frames"])
    assert a["mass_kg"] == b["mass_kg"]
    assert a["unobserved_frames"] == b["unobserved_frames"]
    assert abs(a["marker_rms_m"] - b["marker_rms_m"]) < 0.01 * b["marker_rms_m"]
    assert abs(a["linear_residual_rms_N"] - b["linear_residual_rms_N"]) < 1.0
    assert abs(a["angular_residual_rms_Nm"] - b["angular_residual_rms_Nm"]) < 1.0


def test_the_command_offers_every_named_fit() -> None:
    """``addb process --fit`` and ``addb info --fit`` list their choices literally (the CLI
    does not import the pipeline at start-up); they must be :data:`solver.pipeline.FIT_CHOICES`."""
    from addb_viewer.cli import build_parser

    sub = next(a for a in build_parser()._subparsers._group_actions if a.choices)
    for command in ("process", "info"):
        fit = next(a for a in sub.choices[command]._actions if a.dest == "fit")
        assert tuple(fit.choices) == pipeline.FIT_CHOICES, command


def test_an_unknown_fit_name_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown dynamics fit 'fast'"):
        pipeline.options_for_fit("fast")


def test_the_review_record_in_the_subject_folder_does_not_invalidate_the_kinematics(
    base: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The review app keeps the record in the subject folder (annotations.json, its journal
    and lock): a flag edit rewrites those files, and the Reprocess that follows must still
    reuse the cached kinematics (the key once hashed every top-level file)."""
    from annotations import AnnotationStore

    subject, out0 = base
    out = _copy_out(out0, tmp_path / "out")
    key = pipeline.kinematics_cache_key(pipeline.extend_subject(pipeline.load_subject(subject)))
    with AnnotationStore.open(subject / "annotations.json", reviewer="tester") as store:
        store.set_reviewed("walk", True)
    written = sorted(p.name for p in subject.iterdir() if p.name.startswith("annotations."))
    assert "annotations.json" in written and len(written) >= 2, written
    assert pipeline.kinematics_cache_key(pipeline.extend_subject(pipeline.load_subject(subject))) == key
    _no_kinematics(monkeypatch)
    reprocess_dynamics(subject, out, ["walk"], _flags(out), options=BAND)
    assert set(range(100, 121)) <= set(_results(out)["unobserved_frames"])
