"""A trial whose recordings the dynamics stage could not take is written with its kinematics
and its error in its results.json (``dynamics_error``); the reviewer is told so where they
meet it: its row in the dataset queue, and the page's status line when it is open.

The walk, plus ``walk_short`` (the walk's first six marker frames, its forces whole),
processed by ``addb process SUBJECT_DIR`` into the subject's own output folder.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.queue import KINEMATICS_ONLY, QueueSubject, build_queue
from tests.cli_run import run_addb
from tests.conftest import SHARED_DATA, writable_copy
from tests.trial_edits import add_short_walk

pytestmark = pytest.mark.slow
MESSAGE = "markers (0.000-0.050 s) and forces (0.000-2.389 s)"  # the start of the trial's dynamics error


@pytest.fixture(scope="module")
def processed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(subject folder, its output folder) with walk_short kept as kinematics."""
    subject = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path_factory.mktemp("s") / "walk")
    add_short_walk(subject)
    out = subject / "addb_out"
    code, _, err = run_addb(["process", str(subject), "--out", str(out)])
    assert code == 1 and "walk_short" in err and (out / "walk_short" / "results.json").is_file(), err
    return subject, out




def test_the_queue_row_says_the_trials_dynamics_failed(processed: tuple[Path, Path]) -> None:
    subject, out = processed
    rows = {r.trial: r for r in build_queue((QueueSubject("labA/walk", subject, out),))}
    assert rows["walk"].detail == "" and rows["static"].detail == ""
    short = rows["walk_short"]
    assert short.processing == KINEMATICS_ONLY and short.detail.startswith(f"dynamics failed: {MESSAGE}"), short.detail


def test_the_open_trial_says_its_dynamics_failed_not_that_a_reprocess_brings_them(processed: tuple[Path, Path], make_app) -> None:
    subject, out = processed
    app = make_app(ReviewPaths.for_subject(subject, out), process_missing=False)
    app.load_trial("walk_short")
    status = app.panel.status.content
    assert f"its dynamics failed: {MESSAGE}" in status and "Reprocess" not in status, status
