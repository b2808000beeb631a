"""``plate_registration`` (every plate misregistered alike against the motion-capture frame):
its correction undoes a hidden misregistration exactly on real recordings, and its linear
model predicts the change of the plates' total wrench that a misregistration makes on the
processed walk (the exact rigid motion of every plate's readings, filtered as the
diagnosis does). Its hidden-effect draws run with the other causes' (:mod:`tests.diagnose.hidden`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.corrections import correct_forces, register_plates, turn_about_vertical
from solver.io.mot import read_forces
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import copy_subject, hide_registration, plates_centre

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
RUN = SHARED_DATA / "subjects" / "rajagopal2016_run"


@pytest.mark.parametrize(("subject", "trial"), [(WALK, "walk"), (RUN, "run")])
def test_correction_undoes_a_hidden_registration(subject: Path, trial: str, tmp_path: Path) -> None:
    original = read_forces(subject / "trials" / trial / "grf.mot")
    copy = copy_subject(subject, tmp_path / "subject", (trial,))
    shift, rotation = np.array([0.021, 0.0, -0.013]), float(np.radians(-1.7))
    centre = hide_registration(copy, trial, shift, rotation)
    hidden = read_forces(copy / "trials" / trial / "grf.mot")
    loaded = [np.nan_to_num(np.asarray(p.force)[:, 1]) > 50.0 for p in original.plates]
    # the hidden readings moved: centres of pressure by about the shift, forces turned
    for h, o, on in zip(hidden.plates, original.plates, loaded):
        moved = np.asarray(h.cop)[on] - np.asarray(o.cop)[on]
        assert np.median(np.linalg.norm(moved, axis=1)) > 0.01
        np.testing.assert_allclose(np.asarray(h.force)[on], np.asarray(o.force)[on] @ turn_about_vertical(rotation).T, atol=1e-3)
    entry = {"cause": "plate_registration", "trial": trial, "shift_m": shift.tolist(), "rotation_rad": rotation, "centre_m": centre.tolist()}
    corrected = correct_forces(hidden, entry)
    for a, b, on in zip(corrected.plates, original.plates, loaded):
        np.testing.assert_allclose(np.asarray(a.force), np.asarray(b.force), atol=1e-3)  # the file's digits
        np.testing.assert_allclose(np.asarray(a.cop)[on], np.asarray(b.cop)[on], atol=1e-5)
        np.testing.assert_allclose(np.asarray(a.free_moment), np.asarray(b.free_moment), atol=1e-3)
    # without a rotation the entry may leave it out
    back = correct_forces(register_plates(original, shift, 0.0, centre), {k: v for k, v in entry.items() if k != "rotation_rad"})
    for a, b in zip(back.plates, original.plates):
        np.testing.assert_allclose(np.nan_to_num(a.cop), np.nan_to_num(b.cop), atol=1e-12)


@pytest.mark.slow
def test_linear_model_predicts_the_change_of_the_plates_wrench(tmp_path: Path) -> None:
    """The columns of :func:`solver.diagnose.causes.plate_registration.columns` times
    (sx, sz, φ) against the exact change of the total plate wrench (force N, moment about the
    pelvis N·m) for a 2.5 cm shift and a 2 degree turn, on the processed walk: within 3 % of
    its RMS (the model is first order in the angle), and the translation part exactly."""
    from addb_viewer.cli import main as cli
    from solver.diagnose.causes.plate_registration import columns
    from solver.diagnose.data import prepare
    from solver.io.subject import load_subject, load_trial
    from solver.results import load_processed

    keep = tuple(t.name for t in (WALK / "trials").iterdir() if t.name == "walk" or not (t / "grf.mot").exists())
    subject = copy_subject(WALK, tmp_path / "walk", keep)
    assert cli(["process", str(subject), "--out", str(subject / "addb_out")]) == 0
    processed = load_processed(subject / "addb_out", "walk")
    info = load_subject(subject)
    forces = load_trial(info.trial("walk")).forces
    kw = {"stated_mass": info.mass_kg, "flagged": np.zeros(processed.n_frames, dtype=bool)}
    before = prepare(processed, forces, **kw)
    wrench, _, loaded, pivot, radius, centroids = columns(before)
    np.testing.assert_allclose(pivot, plates_centre(subject, "walk"), atol=1e-12)
    assert 0.3 < radius < 1.0 and loaded.mean() > 0.5 and set(centroids) == {"r", "l"}
    for theta, tol in (([0.02, -0.015, 0.0], 1e-9), ([0.02, -0.015, np.radians(2.0)], 0.03)):
        after = prepare(processed, register_plates(forces, np.array([theta[0], 0.0, theta[1]]), theta[2], pivot), **kw)
        actual = after.external()[1] - before.external()[1]
        err = actual - wrench @ np.array(theta)
        rms = np.sqrt(np.mean(np.sum(actual**2, axis=1)))
        assert rms > 5.0
        assert np.sqrt(np.mean(np.sum(err**2, axis=1))) <= tol * rms
