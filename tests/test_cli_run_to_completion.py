"""The ``addb`` console process of a command that runs to completion gets
:func:`addb_viewer.cli.run_to_completion` (glibc's malloc thresholds, deferred full garbage
collections, no collection at exit); ``addb view``, which serves until stopped, and
``main`` called from Python keep the interpreter's defaults. What it saves a whole ``addb
process`` is measured in tests/benchmarks/RESULTS.md (block ``startup``)."""

from __future__ import annotations

import gc
import json
import subprocess
import sys

from addb_viewer import cli
from tests.conftest import SHARED_DATA

MODEL = SHARED_DATA / "subjects" / "rajagopal2016_walk" / "unscaled_generic.osim"

# Runs ``main()`` as the console script does (no argv: sys.argv is the command line), with
# the view command's server replaced by a stub, and prints what the process was left with.
# The atexit function registered first runs last, after run_to_completion's gc.freeze.
_CONSOLE = """
import atexit, gc, json, sys
seen = {}
atexit.register(lambda: print(json.dumps(seen | {"frozen_at_exit": gc.get_freeze_count()})))
import addb_viewer.commands.view as view
view.run = lambda args: 0
from addb_viewer.cli import main
sys.argv = ["addb", *sys.argv[1:]]
code = main()
seen.update(code=code, threshold=list(gc.get_threshold()))
"""


def _console(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _CONSOLE, *args], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_command_that_runs_to_completion_defers_full_collections_and_freezes_at_exit() -> None:
    seen = _console("info", str(MODEL))
    assert seen["code"] == 0
    assert seen["threshold"][2] == cli.FULL_COLLECTION_THRESHOLD != gc.get_threshold()[2]
    assert seen["frozen_at_exit"] > 10_000  # every object the imports made, left out of the last collection


def test_the_review_server_keeps_the_interpreter_defaults() -> None:
    seen = _console("view", str(MODEL))
    assert seen["code"] == 0
    assert seen["threshold"] == list(gc.get_threshold())
    assert seen["frozen_at_exit"] == 0


def test_the_malloc_settings_apply_on_this_machine() -> None:
    """glibc's mallopt accepts both thresholds (Linux, as CI); elsewhere they are skipped."""
    code = "import json; from addb_viewer.cli import run_to_completion; print(json.dumps(run_to_completion()))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) is True


def test_main_called_from_python_leaves_the_interpreter_alone() -> None:
    before = gc.get_threshold()
    assert cli.main(["info", str(MODEL)]) == 0
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0


def test_a_reader_that_leaves_the_pipe_gets_no_traceback() -> None:
    """``addb info MODEL | head -1``: when the reader of stdout has gone before the summary is
    printed, the command exits 141 (128 + SIGPIPE, as a shell reports it) with nothing on
    stderr, not a BrokenPipeError traceback."""
    proc = subprocess.Popen([sys.executable, "-m", "addb_viewer.cli", "info", str(MODEL)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    proc.stdout.close()  # before the child has imported anything: its print meets a closed pipe
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 141 and err == "", err
