"""Both recordings of the demo walk processed by the whole pipeline (real dynamics:
residuals, torques, proposals with reasons, plates assigned to the feet)."""

from __future__ import annotations

from itertools import groupby
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.demo import DEMO_SUBJECT
from addb_viewer.recording.mcap_writer import write_mcap
from addb_viewer.recording.rerun_writer import write_rerun
from solver.io.mcap_file import load_processed_mcap
from solver.results import ProcessedTrial, load_processed
from tests.recording.test_rerun_recording import Recording, per_frame_points

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def full_trial(tmp_path_factory: pytest.TempPathFactory) -> ProcessedTrial:
    from solver.pipeline import process_subject

    out = tmp_path_factory.mktemp("full") / "out"
    process_subject(DEMO_SUBJECT, out)
    trial = load_processed(out, "walk")
    assert trial.has_dynamics
    return trial


def test_mcap_round_trip_of_real_dynamics(tmp_path: Path, full_trial: ProcessedTrial) -> None:
    back = load_processed_mcap(write_mcap(full_trial, tmp_path / "walk.mcap"))
    for name in (
        "observed",
        "body_wxyz",
        "residual_force",
        "residual_moment",
        "tau",
        "com_acc",
        "unobserved",
        "proposed",
    ):
        np.testing.assert_array_equal(getattr(back, name), getattr(full_trial, name), err_msg=name)
    assert (
        back.proposal_reasons == full_trial.proposal_reasons
        and back.settings == full_trial.settings
    )
    for p, q in zip(back.plates, full_trial.plates, strict=True):
        np.testing.assert_array_equal(p.force, q.force)
        np.testing.assert_array_equal(p.body, q.body)


def test_rerun_recording_of_real_dynamics(tmp_path: Path, full_trial: ProcessedTrial) -> None:
    """Markers and residual force bit for bit; the solver's reasons logged once per run of
    proposed frames with one reason, at the run's first frame, with that reason's text."""
    rec = Recording(write_rerun(full_trial, tmp_path / "walk.rrd"))
    got = per_frame_points(rec, "/world/markers/observed", full_trial)
    np.testing.assert_array_equal(got, full_trial.observed.astype(np.float32))
    frames, values = rec.column("/residuals/force", "Scalars:scalars")
    ok = np.isfinite(full_trial.residual_force).all(axis=1)
    np.testing.assert_array_equal(frames, np.flatnonzero(ok))
    np.testing.assert_array_equal(np.array(values), full_trial.residual_force[ok])
    frames, text = rec.column("/flags/reasons", "TextLog:text")
    runs = []  # (first frame, reason) of each run of proposed frames sharing a reason
    k = 0
    for (proposed, reason), run in groupby(
        zip(full_trial.proposed.tolist(), full_trial.proposal_reasons, strict=True)
    ):
        if proposed and reason:
            runs.append((k, reason))
        k += len(list(run))
    assert runs  # the real walk has proposals with reasons
    assert list(zip(frames.tolist(), [t[0] for t in text], strict=True)) == runs
