"""The app's solver jobs in a pre-started ("warm") child (addb_viewer.app.jobs.prestart_solver):
the job runs in the spare process, its outputs equal a fresh child's bit for bit, a dead
spare is replaced by a fresh child, and a warm job can be cancelled.

On the real walk (rajagopal2016_walk), a Reprocess of the walk (dynamics only) with frames
100-120 flagged.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.app import jobs
from solver.pipeline import process_subject
from tests.conftest import SHARED_DATA, writable_copy

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture(scope="module")
def processed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict[str, np.ndarray]]:
    """(subject copy, output of a full run, the walk's flags: proposals + frames 100-120)."""
    root = tmp_path_factory.mktemp("warm")
    subject = writable_copy(WALK, root / "rajagopal2016_walk")
    out = root / "out"
    process_subject(subject, out)
    r = json.loads((out / "walk" / "results.json").read_text())
    mask = np.zeros(r["n_frames"], dtype=bool)
    mask[r["unobserved_frames"]] = True
    mask[100:121] = True
    return subject, out, {"walk": mask}


def _run(subject: Path, out: Path, flags: dict, work: Path, monkeypatch, *, warm: bool) -> tuple[jobs.JobResult, int]:
    """One dynamics-only Reprocess job; (its result, the pid of the process that ran it)."""
    monkeypatch.setenv("ADDB_WARM_SOLVER", "1" if warm else "0")
    spare_pid = None
    if warm:
        jobs.prestart_solver(work.parent)
        assert jobs.wait_for_spare(120)
        spare_pid = jobs._spare.proc.pid  # type: ignore[union-attr]
    job = jobs.SolverJob(jobs.JobSpec(subject, out, ("walk",), flags, dynamics_only=True), work,
                         on_progress=lambda m, f: None, on_done=lambda r: None)  # fmt: skip
    job.start()
    assert job._proc is not None
    pid = job._proc.pid
    assert (pid == spare_pid) if warm else (spare_pid is None)
    result = job.wait(300)
    assert result is not None
    return result, pid


def _arrays(out: Path) -> dict[str, np.ndarray]:
    with np.load(out / "walk" / "trial.npz") as z:
        return {k: z[k] for k in z.files if k != "header"}


def test_warm_child_runs_the_job_and_gives_a_fresh_childs_numbers(processed, tmp_path: Path, monkeypatch) -> None:
    subject, out0, flags = processed
    # each job reprocesses its own copy of the output, so that both start from the same one
    # (a fit that warm-starts would otherwise start the second job from the first's result)
    out = shutil.copytree(out0, tmp_path / "cold_out", symlinks=True)
    cold, _ = _run(subject, out, flags, tmp_path / "jobs" / "cold", monkeypatch, warm=False)
    assert cold.status == "done", cold.message
    ref = _arrays(out)
    ref_results = json.loads((out / "walk" / "results.json").read_text())
    out = shutil.copytree(out0, tmp_path / "warm_out", symlinks=True)
    warm, _ = _run(subject, out, flags, tmp_path / "jobs" / "warm", monkeypatch, warm=True)
    assert warm.status == "done", warm.message
    assert (tmp_path / "jobs" / "warm" / "child.log").is_file()  # the spare wrote its log beside the spec
    got = _arrays(out)
    assert got.keys() == ref.keys()
    for k in ref:
        assert np.array_equal(got[k], ref[k], equal_nan=ref[k].dtype.kind == "f"), k
    res = json.loads((out / "walk" / "results.json").read_text())
    for k in ("marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm", "mass_kg", "unobserved_frames"):
        assert res[k] == ref_results[k], k
    assert set(range(100, 121)) <= set(res["unobserved_frames"])


def test_a_dead_spare_is_replaced_by_a_fresh_child(processed, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("ADDB_WARM_SOLVER", "1")  # on even where a conftest turns spares off
    subject, out, flags = processed
    jobs.prestart_solver(tmp_path)
    assert jobs.wait_for_spare(120)
    dead = jobs._spare
    assert dead is not None
    dead.proc.kill()
    dead.proc.wait()
    job = jobs.SolverJob(jobs.JobSpec(subject, out, ("walk",), flags, dynamics_only=True), tmp_path / "job",
                         on_progress=lambda m, f: None, on_done=lambda r: None)  # fmt: skip
    job.start()
    assert job._proc is not None and job._proc.pid != dead.proc.pid
    result = job.wait(300)
    assert result is not None and result.status == "done", result and result.message


def test_a_spare_that_dies_as_the_job_starts_is_replaced(processed, tmp_path: Path, monkeypatch) -> None:
    """The spare passed its checks but its pipe is broken when the spec is written."""
    monkeypatch.setenv("ADDB_WARM_SOLVER", "1")
    subject, out, flags = processed
    jobs.prestart_solver(tmp_path)
    assert jobs.wait_for_spare(120)
    dead = jobs._spare
    assert dead is not None
    dead.proc.kill()
    dead.proc.wait()
    jobs._spare = None
    monkeypatch.setattr(jobs, "_take_spare", lambda: dead.proc)
    job = jobs.SolverJob(jobs.JobSpec(subject, out, ("walk",), flags, dynamics_only=True), tmp_path / "job",
                         on_progress=lambda m, f: None, on_done=lambda r: None)  # fmt: skip
    job.start()
    assert job._proc is not None and job._proc.pid != dead.proc.pid
    result = job.wait(300)
    assert result is not None and result.status == "done", result and result.message


def test_a_warm_job_can_be_cancelled(processed, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("ADDB_WARM_SOLVER", "1")
    subject, out, flags = processed
    before = (out / "walk" / "results.json").read_bytes()
    messages: list[str] = []
    jobs.prestart_solver(tmp_path)
    assert jobs.wait_for_spare(120)
    job = jobs.SolverJob(jobs.JobSpec(subject, out, None, flags), tmp_path / "job",  # a full run: long enough
                         on_progress=lambda m, f: messages.append(m), on_done=lambda r: None)  # fmt: skip
    job.start()
    deadline = 60.0
    while not messages and deadline > 0:  # the child is working
        job._finished.wait(0.05)
        deadline -= 0.05
    job.cancel()
    result = job.wait(30)
    assert result is not None and result.status == "cancelled"
    assert (out / "walk" / "results.json").read_bytes() == before  # the previous result is kept
