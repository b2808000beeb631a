"""The whole-motion profile's linear map predicts what a small change of the motion does to
the root wrench and the markers, on the real processed walk (an exact inverse dynamics and
marker positions recomputed after the change)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main as cli
from solver.diagnose.core import build_context
from solver.diagnose.data import prepare
from solver.diagnose.motion_profile import MotionProfile, _wrench_about_ground
from solver.io.subject import load_subject, load_trial
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from solver.results import load_processed
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import copy_subject

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture(scope="module")
def profile(tmp_path_factory: pytest.TempPathFactory) -> MotionProfile:
    """The whole-motion profile of the processed walk (its static trial kept for scaling)."""
    keep = tuple(t.name for t in (WALK / "trials").iterdir() if t.name == "walk" or not (t / "grf.mot").exists())
    subject = copy_subject(WALK, tmp_path_factory.mktemp("motion") / "walk", keep)
    assert cli(["process", str(subject), "--out", str(subject / "addb_out")]) == 0
    processed = load_processed(subject / "addb_out", "walk")
    info = load_subject(Path(subject))
    raw = load_trial(info.trial("walk"))
    data = prepare(
        processed, raw.forces, stated_mass=info.mass_kg, flagged=np.zeros(processed.n_frames, dtype=bool),
        generic_model=read_osim(info.model_path), feet=info.foot_body_names,
    )
    ctx, _ = build_context(data)
    return MotionProfile(data, ctx.evaluated, ctx.sigmas)


def test_linear_rows_predict_a_small_change_of_the_motion(profile: MotionProfile) -> None:
    data = profile.data
    trial = data.trial
    sk = Skeleton(read_osim(trial.model_path))
    free = np.flatnonzero(sk.is_independent & ~sk.locked)
    t_n, h = data.n_frames, data.dt
    # a smooth step of every free coordinate: 2 mrad (2 mm) waves of different periods
    phase = np.arange(t_n)[:, None] * h * 2 * np.pi / (0.6 + 0.05 * np.arange(free.size))[None, :]
    step = 2e-3 * np.sin(phase + np.arange(free.size))
    dq = np.zeros_like(trial.q)
    dq[:, free] = step
    q1 = sk.cmap.complete(trial.q + dq)
    d1 = np.zeros_like(dq)
    d2 = np.zeros_like(dq)
    d1[1:-1] = (dq[2:] - dq[:-2]) / (2 * h)
    d2[1:-1] = (dq[2:] - 2 * dq[1:-1] + dq[:-2]) / h**2
    w0, pelvis = _wrench_about_ground(sk, trial.q, trial.qd, trial.qdd)
    w1, _ = _wrench_about_ground(sk, q1, trial.qd + d1, trial.qdd + d2)
    change = w1 - w0
    change[:, 3:] -= np.cross(pelvis, change[:, :3])  # about the processed pelvis origin
    predicted = profile.per_frame(profile.a @ step.ravel())
    sig = np.array([profile.sigmas.force] * 3 + [profile.sigmas.moment] * 3)
    ev = profile.evaluated
    actual = change[ev] / sig
    pred = predicted[ev, :6]
    assert np.abs(actual).max() > 3  # the step matters: over 6 N or N·m somewhere
    assert np.linalg.norm(pred - actual) < 0.01 * np.linalg.norm(actual)
    # markers: model positions after the step against the Jacobian's prediction
    idx = sk.marker_index(list(data.markers.names))
    moved = (sk.marker_positions(q1, idx) - sk.marker_positions(trial.q, idx)) / profile.sigmas.marker
    m = len(data.markers.names)
    seen = data.markers.seen
    pred_m = predicted[:, 6 : 6 + 3 * m].reshape(t_n, m, 3)
    assert np.linalg.norm(pred_m[seen] - moved[seen]) < 0.01 * np.linalg.norm(moved[seen])
    # rows of markers not seen are zero (no row exists there)
    assert not np.any(pred_m[~seen])
