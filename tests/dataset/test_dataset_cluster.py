"""``addb process DATASET_DIR --scheduler tcp://...`` on a real multi-process cluster: a
``dask scheduler`` and two ``dask worker`` processes started here on 127.0.0.1. The results
equal a serial one-subject run's; then a worker running a subject is killed with SIGKILL
on the first attempt: with the default ``--retries`` (1) the subject is retried on another
worker process and completes, and nothing half-written is left in the output tree; with
``--retries 0`` that subject alone fails, named as a worker death."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.manifest import read_manifest
from tests.dataset.dataset_tree import (
    KINEMATICS_ONLY,
    SUBJECTS,
    assert_same_results,
    build_tree,
    no_work_folders,
)

pytestmark = pytest.mark.slow
REPO = Path(__file__).resolve().parents[2]
WALK = "labA/rajagopal2016_walk"


def _dask_command(tool: str) -> list[str]:
    exe = Path(sys.executable).parent / "dask"
    assert exe.exists(), f"the dask command line is not installed beside {sys.executable}"
    return [str(exe), tool]


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory):
    """``dask scheduler`` + two ``dask worker`` processes (one thread each) on 127.0.0.1.

    The scheduler gives up on a task at its first worker death (allowed-failures 0), so
    the retry seen by the test is addb's own, not the scheduler's."""
    work = tmp_path_factory.mktemp("cluster")
    env = dict(os.environ, PYTHONPATH=str(REPO), DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="0")
    sched_file = work / "scheduler.json"
    logs = [open(work / name, "w") for name in ("scheduler.log", "worker0.log", "worker1.log")]  # noqa: SIM115 (closed below)
    procs = [subprocess.Popen(
        [*_dask_command("scheduler"), "--host", "127.0.0.1", "--port", "0", "--dashboard-address", ":0",
         "--scheduler-file", str(sched_file)],
        env=env, cwd=work, stdout=subprocess.DEVNULL, stderr=logs[0],
    )]  # fmt: skip
    deadline = time.monotonic() + 60
    while not sched_file.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert sched_file.exists(), (work / "scheduler.log").read_text()
    address = json.loads(sched_file.read_text())["address"]
    for k in range(2):
        procs.append(subprocess.Popen(
            [*_dask_command("worker"), address, "--nthreads", "1", "--nworkers", "1", "--name", f"w{k}",
             "--host", "127.0.0.1", "--dashboard-address", ":0"],
            env=env, cwd=work, stdout=subprocess.DEVNULL, stderr=logs[k + 1],
        ))  # fmt: skip
    from distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(2, timeout=120)
    yield address, work
    for p in procs:
        p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
    for f in logs:
        f.close()


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_tree(tmp_path_factory.mktemp("tree") / "in", {WALK: "rajagopal2016_walk"}, kinematics_only=True)


@pytest.fixture(scope="module")
def serial_walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("serial") / "walk"
    assert cli(["process", str(SUBJECTS / "rajagopal2016_walk"), "--out", str(out)]) == 0
    return out


def test_scheduler_run_equals_a_serial_run(scheduler, tree, serial_walk, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    address, _ = scheduler
    out = tmp_path / "out"
    assert cli(["process", str(tree), "--out", str(out), "--scheduler", address]) == 0
    # workers started with Dask's defaults carry MALLOC_TRIM_THRESHOLD_: the user is told
    assert "2 of 2 Dask workers run with MALLOC_TRIM_THRESHOLD_ set" in capsys.readouterr().err
    summary = json.loads((out / "dataset_summary.json").read_text())
    assert {s["rel"]: s["status"] for s in summary["subjects"]} == {WALK: "ok", KINEMATICS_ONLY: "kinematics_only"}
    assert summary["scheduler"] == address
    assert assert_same_results(out / WALK, serial_walk) == 9 + 3


def _run_killing_the_walks_first_worker(address: str, tree: Path, out: Path, marker: Path, *options: str,
                                        rel: str = WALK) -> int:
    """``addb process TREE --out OUT --scheduler ADDRESS OPTIONS`` with the worker that runs
    the first attempt of subject ``rel`` (default the walk; "": the first subject to start)
    killed once that subject has started (SIGKILL, its pid in ``marker``); returns the exit
    code once the nanny has started that worker again."""
    from distributed import Client

    from tests.dataset.kill_plugin import KillOnFirstAttempt

    with Client(address, timeout="30s") as client:
        client.register_plugin(KillOnFirstAttempt(rel, str(marker), str(out)))
        try:
            code = cli(["process", str(tree), "--out", str(out), "--scheduler", address, *options])
        finally:
            client.unregister_worker_plugin(KillOnFirstAttempt.name)
        client.wait_for_workers(2, timeout=120)  # the nanny restarted the killed worker
    assert marker.exists(), "the plugin never killed a worker"
    return code


def test_killed_worker_is_retried_elsewhere_and_nothing_is_half_written(scheduler, tree, serial_walk, tmp_path: Path) -> None:
    address, _ = scheduler
    marker, out = tmp_path / "killed.pid", tmp_path / "out"
    code = _run_killing_the_walks_first_worker(address, tree, out, marker)  # the default --retries
    killed_pid = int(marker.read_text())
    assert code == 0
    summary = json.loads((out / "dataset_summary.json").read_text())
    walk = next(s for s in summary["subjects"] if s["rel"] == WALK)
    assert walk["status"] == "ok" and walk["attempts"] == 2
    assert walk["worker_pid"] != killed_pid  # another worker process finished it
    assert read_manifest(out / WALK)["worker_pid"] == walk["worker_pid"]
    assert assert_same_results(out / WALK, serial_walk) == 9 + 3
    assert not no_work_folders(out), no_work_folders(out)
    assert not [p for p in out.rglob("*.tmp*")]
    shutil.rmtree(out)


def test_with_no_retries_a_killed_worker_fails_its_subject_alone(scheduler, tree, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The same death with ``--retries 0``: the walk is recorded once as failed (a worker
    death, one attempt), the other subject is processed, exit code 1; the retry of the test
    above is therefore the default ``--retries`` at work, not the scheduler's."""
    address, _ = scheduler
    marker, out = tmp_path / "killed.pid", tmp_path / "out"
    code = _run_killing_the_walks_first_worker(address, tree, out, marker, "--retries", "0")
    assert code == 1
    summary = json.loads((out / "dataset_summary.json").read_text())
    rows = {s["rel"]: s for s in summary["subjects"]}
    assert {rel: s["status"] for rel, s in rows.items()} == {WALK: "failed", KINEMATICS_ONLY: "kinematics_only"}
    assert rows[WALK]["attempts"] == 1 and rows[WALK]["error"]["type"] == "WorkerDied"
    assert "died 1 time(s)" in rows[WALK]["error"]["message"]
    assert "retrying" not in capsys.readouterr().err
    assert not (out / WALK / "manifest.json").exists()
    assert not no_work_folders(out), no_work_folders(out)
    assert not [p for p in out.rglob("*.tmp*")]


def test_a_worker_death_charges_only_the_subject_that_was_running_on_it(scheduler, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """docs/audits/2026-12-02-dataset.md, finding 1: four walks on the two one-thread workers
    (each worker is given two at once: every subject is its own task group, which the
    scheduler does not hold back), and the worker of the first subject to start is killed
    while it runs, with ``--retries 0``. Only that subject fails, as a worker death of one
    attempt; the subject that was only queued on the dead worker is submitted again without
    counting an attempt and is processed (it used to fail as ``WorkerDied`` too)."""
    address, _ = scheduler
    walks = {f"labA/walk{k}": "rajagopal2016_walk" for k in range(4)}
    tree = build_tree(tmp_path / "in", walks)
    marker, out = tmp_path / "killed.pid", tmp_path / "out"
    capsys.readouterr()
    code = _run_killing_the_walks_first_worker(address, tree, out, marker, "--retries", "0", rel="")
    err = capsys.readouterr().err
    rows = {s["rel"]: s for s in json.loads((out / "dataset_summary.json").read_text())["subjects"]}
    failed = sorted(rel for rel, s in rows.items() if s["status"] != "ok")
    assert len(failed) == 1, {rel: (s["status"], s.get("error")) for rel, s in rows.items()}
    assert code == 1
    died = rows[failed[0]]
    assert died["error"]["type"] == "WorkerDied" and died["attempts"] == 1, died
    assert "died 1 time(s)" in died["error"]["message"]
    assert all(s["attempts"] == 1 for rel, s in rows.items() if rel != failed[0]), rows
    requeued = [line for line in err.splitlines() if "submitted again (no attempt counted)" in line]
    assert requeued and all("before the subject started there" in line for line in requeued), err
    assert not no_work_folders(out), no_work_folders(out)
