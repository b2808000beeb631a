"""A trial that starts with the subject walking into the capture volume.

opensim-core's C3D walking5 (``scripts/make_example_subject.py opensim_c3d_walking``)
sees one marker on its first observed frame and 40 later. Before 2026-11-25 ``addb
process`` posed that first frame from its one marker and solved forwards from it: a solve
that saw few markers turned the pelvis by a full turn, the constant-velocity guess
carried one turn a frame into every later frame (pelvis_rotation at -5400 rad by the
end, the markers none the wiser: 0.65 cm RMS), and the dynamics stage got a motion it
could not use (24 cm marker RMS after the fit, 4 of 441 frames with measured force kept,
an angular residual of 88 N·m). The trial is now solved from its best-observed frame, and
every solution is kept the whole number of turns nearest the frame before it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from tests.conftest import SHARED_DATA

REPO = Path(__file__).resolve().parents[2]
TURN = 2 * np.pi


@pytest.mark.parametrize("model", ["Rajagopal2016.osim", "../subjects/opencap_uhlrich2023/unscaled_generic.osim"])
def test_a_full_turn_of_a_full_turn_coordinate_moves_no_marker(model: str) -> None:
    sk = Skeleton(read_osim(SHARED_DATA / "models" / model))
    rng = np.random.default_rng(0)
    q = sk.cmap.complete(sk.neutral() + rng.uniform(-0.3, 0.3, sk.n) * sk.is_independent)
    p0 = sk.marker_positions(q)
    turning = np.flatnonzero(sk.full_turn)
    assert {"pelvis_tilt", "pelvis_list", "pelvis_rotation"} <= {sk.coordinate_names[c] for c in turning}
    for c in turning:
        qt = q.copy()
        qt[c] += TURN
        np.testing.assert_allclose(sk.marker_positions(sk.cmap.complete(qt)), p0, rtol=0, atol=1e-12)
    # the other rotational coordinates move something with their turn (the knee's
    # translations are splines of its angle; a coupler's input moves its dependent too)
    others = np.flatnonzero(sk.is_rotational & sk.is_independent & ~sk.full_turn & ~sk.locked)
    assert others.size > 0
    for c in others:
        qt = q.copy()
        qt[c] += TURN
        moved = np.linalg.norm(sk.marker_positions(sk.cmap.complete(qt)) - p0, axis=1).max()
        assert moved > 1e-3, sk.coordinate_names[c]


@pytest.fixture(scope="module")
def walking5(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``addb process`` of the example (walking2 and walking5, scaled on both, as the
    dataset benchmark has it): the subject folder and the output folder."""
    root = tmp_path_factory.mktemp("walking5")
    subject = root / "c3d"
    subprocess.run([sys.executable, "scripts/make_example_subject.py", "opensim_c3d_walking", str(subject)], check=True, cwd=REPO, capture_output=True)
    out = root / "out"
    subprocess.run([str(Path(sys.executable).parent / "addb"), "process", str(subject), "--out", str(out)], check=True, capture_output=True)
    return subject, out


def test_walking5_kinematics_turn_no_coordinate_between_frames(walking5: tuple[Path, Path]) -> None:
    # the kinematics the dynamics stage started from (the output's cache holds the trial at
    # its marker rate); the solved frames only: frames before any marker is seen hold a pose
    from solver.io.subject import load_subject
    from solver.pipeline import kinematics_cache_key, load_kinematics_cache

    subject, out = walking5
    cached, reason = load_kinematics_cache(out, kinematics_cache_key(load_subject(subject)))
    assert cached is not None, reason
    kin = next(t for t in cached.kinematics.trials if t.name == "walking5")
    seen = np.isfinite(kin.observed).all(axis=2).any(axis=1)
    q = kin.q[seen]
    assert q.shape[0] > 1000
    # one turn a frame before; 0.29 rad is the largest step now, on a frame seeing 4 markers
    assert np.abs(np.diff(q, axis=0)).max() < 0.5
    err = np.linalg.norm(kin.modeled - kin.observed, axis=2)
    assert np.nanmax(err) < 0.05  # 15 cm before
    assert np.sqrt(np.nanmean(err**2)) < 0.0062  # 0.65 cm before


def test_walking5_dynamics_keep_its_measured_frames(walking5: tuple[Path, Path]) -> None:
    r = json.loads((walking5[1] / "walking5" / "results.json").read_text())
    assert r["n_observed_frames"] >= 70  # 4 before: the contact check rejected a spinning body
    assert r["marker_rms_m"] < 0.007  # 24 cm before
    assert r["linear_residual_rms_N"] < 2.0  # 9.7 N before
    assert r["angular_residual_rms_Nm"] < 5.0  # 88 N·m before
