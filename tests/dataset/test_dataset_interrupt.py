"""Ctrl-C during ``addb process DATASET_DIR``: the terminal sends SIGINT to every process of
the command (the CLI, the Dask nanny and worker processes). The run used to end in pages of
tracebacks from each process; a subject given up at the interrupt could be recorded as
failed (its worker could no longer reach the scheduler), and a failure with the same inputs
is not run again. Now the command says what finished and what did not, its summary lists
the unfinished subjects as cancelled, nothing is recorded as failed, and the same command
processes only what was left.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from tests.dataset.dataset_tree import build_tree

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
#: Processed one after the other on one worker, in this order (the walk takes about 1 s,
#: the run about 2.5 s): the interrupt comes once the walk is done, while the run runs.
TREE = {"labA/a_walk": "rajagopal2016_walk", "labA/b_run": "rajagopal2016_run"}


#: ``python -m addb_viewer.cli ARGS`` with Python's own Ctrl-C handler, whatever the
#: disposition inherited (:func:`_process`).
_AS_FROM_A_TERMINAL = (
    "import signal, sys\n"
    "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
    "sys.argv[0] = 'addb'\n"
    "from addb_viewer.cli import main\n"
    "sys.exit(main())"
)


def _process(root: Path, out: Path, interrupt_after: str | None, terminate: bool = False) -> tuple[int, str]:
    """``addb process root --out out --workers 1`` in its own process group; with
    ``interrupt_after``, SIGINT to the whole group once a line of its output holds that text
    (with ``terminate``, SIGTERM to the command's own process alone, as ``timeout`` sends it).

    The command starts with SIGINT's default disposition, as from a terminal: a test run
    started in the background of a non-interactive shell (``bash .ci/run &``) ignores SIGINT,
    and a command that inherits that rightly ignores Ctrl-C too (the run then ended as if
    never interrupted, exit code 0)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cmd = [sys.executable, "-c", _AS_FROM_A_TERMINAL, "process", str(root), "--out", str(out), "--workers", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True)
    lines: list[str] = []
    assert proc.stdout is not None
    timer = threading.Timer(300, proc.kill)  # a hung run fails the test instead of hanging it
    timer.start()
    try:
        for line in proc.stdout:
            lines.append(line)
            if interrupt_after is not None and interrupt_after in line:
                if terminate:
                    os.kill(proc.pid, signal.SIGTERM)
                else:
                    os.killpg(proc.pid, signal.SIGINT)
                interrupt_after = None
        return proc.wait(), "".join(lines)
    finally:
        timer.cancel()


def test_ctrl_c_keeps_finished_subjects_and_the_same_command_resumes(tmp_path: Path) -> None:
    root = build_tree(tmp_path / "ds", TREE)
    out = tmp_path / "out"
    code, text = _process(root, out, interrupt_after="1 processed, 0 failed")
    assert code == 130, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    assert (
        f"addb process: interrupted: 1 of 2 subjects to process finished and are kept in {out.resolve()}; "
        "dataset_summary.json lists labA/b_run as cancelled. Run the same command again for them"
    ) in text, text
    assert text.rstrip().endswith("addb process: interrupted"), text
    summary = json.loads((out / "dataset_summary.json").read_text())
    assert [(s["rel"], s["status"]) for s in summary["subjects"]] == [("labA/a_walk", "ok"), ("labA/b_run", "cancelled")]
    assert not (out / "labA" / "b_run").exists()  # given up without a trace: no output, no failure record
    assert not [p.name for p in (out / "labA").iterdir() if p.name.startswith(".")]  # no work folder left
    code, text = _process(root, out, interrupt_after=None)
    assert code == 0, text
    assert "1 subjects: " not in text and "2 subjects: 1 processed, 1 up to date, 0 failed" in text, text


def test_sigterm_stops_the_run_as_ctrl_c_does(tmp_path: Path) -> None:
    """SIGTERM (``timeout``, SLURM, ``kill``) to the command: the finished subject is kept,
    the summary is written with the other listed as cancelled, no work folder is left, exit
    code 143 (docs/audits/2026-12-02-dataset.md, finding 9: it used to leave no summary)."""
    root = build_tree(tmp_path / "ds", TREE)
    out = tmp_path / "out"
    code, text = _process(root, out, interrupt_after="1 processed, 0 failed", terminate=True)
    assert code == 143, text
    assert "Traceback" not in text and text.rstrip().endswith("addb process: terminated (SIGTERM)"), text
    summary = json.loads((out / "dataset_summary.json").read_text())
    assert [(s["rel"], s["status"]) for s in summary["subjects"]] == [("labA/a_walk", "ok"), ("labA/b_run", "cancelled")]
    assert not [p.name for p in (out / "labA").iterdir() if p.name.startswith(".")]  # no work folder left


def _sigint_ignored() -> bool:
    return signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_a_worker_started_again_after_a_death_ignores_sigint_too() -> None:
    """The local cluster's workers start with SIGINT ignored, inherited from the command; one
    that its nanny starts again after a death (the retry of a subject whose worker died)
    inherited the command's handler instead, and printed its traceback at the next Ctrl-C."""
    import time

    from solver.dataset.runner import DatasetOptions, _local_cluster, local_client

    cluster = _local_cluster(DatasetOptions(workers=1))
    try:
        client = local_client(cluster)
        (first,) = client.run(os.getpid).values()
        assert list(client.run(_sigint_ignored).values()) == [True]
        os.kill(first, signal.SIGKILL)
        deadline = time.monotonic() + 60
        pids: list[int] = []
        while time.monotonic() < deadline:
            try:
                pids = list(client.run(os.getpid).values())
            except Exception:  # noqa: BLE001 - the dead worker is still listed
                pids = []
            if pids and first not in pids:
                break
            time.sleep(0.2)
        assert pids and first not in pids, "the nanny did not start the worker again"
        assert list(client.run(_sigint_ignored).values()) == [True]
        client.close()
    finally:
        cluster.close()
