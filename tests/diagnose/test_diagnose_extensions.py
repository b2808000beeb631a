"""Saved extensions: each correction undoes its hidden effect exactly on real recordings,
unmeasured frames join the masks, and a damaged file is refused with its name."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.corrections import (
    append_extension,
    correct_forces,
    correct_markers,
    extend_subject,
    extension_masks,
    read_extensions,
)
from solver.diagnose.data import plate_centre
from solver.errors import SubjectFolderError
from solver.io.mot import read_forces
from solver.io.subject import load_subject
from solver.masks import join_masks
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import (
    copy_subject,
    hide_body_mass,
    hide_plate_gain,
    hide_plate_offset,
    hide_plate_shift,
    hide_time_offset,
)

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture
def walk(tmp_path: Path) -> Path:
    return copy_subject(WALK, tmp_path / "walk")


def _plates(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    rec = read_forces(path)
    return {p.name: (np.asarray(p.force), np.asarray(p.cop), np.asarray(p.free_moment)) for p in rec.plates}


@pytest.mark.parametrize(
    ("hide", "entry"),
    [
        (hide_time_offset, lambda h: {"cause": "force_time_offset", "trial": "walk", **h.truth}),
        (hide_plate_gain, lambda h: {"cause": "plate_force_gain", "trial": "walk", "plate": h.choice, **h.truth}),
        (hide_plate_shift, lambda h: {"cause": "plate_position_offset", "trial": "walk", "plate": h.choice, **h.truth}),
    ],
)
def test_force_corrections_undo_the_hidden_effect(walk: Path, hide, entry) -> None:
    original = read_forces(WALK / "trials" / "walk" / "grf.mot")
    hidden = hide(walk, "walk", np.random.default_rng(7))
    corrected = correct_forces(read_forces(walk / "trials" / "walk" / "grf.mot"), entry(hidden))
    np.testing.assert_allclose(corrected.time, original.time, atol=1e-6)
    for a, b in zip(corrected.plates, original.plates):
        np.testing.assert_allclose(np.nan_to_num(a.force), np.nan_to_num(b.force), atol=1e-3)
        np.testing.assert_allclose(np.nan_to_num(a.cop), np.nan_to_num(b.cop), atol=1e-5)
        np.testing.assert_allclose(np.nan_to_num(a.free_moment), np.nan_to_num(b.free_moment), atol=1e-3)


def test_plate_offset_correction_restores_the_loaded_force(walk: Path) -> None:
    original = _plates(WALK / "trials" / "walk" / "grf.mot")
    hidden = hide_plate_offset(walk, "walk", np.random.default_rng(3))
    bw = 9.80665 * load_subject(WALK).mass_kg
    plate = next(p for p in read_forces(WALK / "trials" / "walk" / "grf.mot").plates if p.name == hidden.choice)
    centre = plate_centre(plate, bw).tolist()
    drifted = {p.name: p for p in read_forces(walk / "trials" / "walk" / "grf.mot").plates}[hidden.choice]
    force, cop, free = original[hidden.choice]
    loaded = np.nan_to_num(force[:, 1]) > 0.1 * bw
    # the drift moved the exported centre of pressure (its force acts at the plate's centre)
    assert np.max(np.linalg.norm(np.asarray(drifted.cop)[loaded] - cop[loaded], axis=1)) > 0.005
    entry = {"cause": "plate_force_offset", "trial": "walk", "plate": hidden.choice, **hidden.truth, "centre_m": centre}
    corrected = correct_forces(read_forces(walk / "trials" / "walk" / "grf.mot"), entry)
    got = {p.name: p for p in corrected.plates}[hidden.choice]
    np.testing.assert_allclose(np.nan_to_num(got.force), np.nan_to_num(force), atol=1e-3)
    # where the plate bears load, the centre of pressure and free moment come back too (to the
    # precision of the file's digits)
    np.testing.assert_allclose(np.asarray(got.cop)[loaded], cop[loaded], atol=2e-4)
    np.testing.assert_allclose(np.asarray(got.free_moment)[loaded], free[loaded], atol=0.05)
    # an entry saved before the centre was recorded subtracts the force at the recorded CoP
    old = correct_forces(read_forces(walk / "trials" / "walk" / "grf.mot"), {k: v for k, v in entry.items() if k != "centre_m"})
    old_plate = {p.name: p for p in old.plates}[hidden.choice]
    np.testing.assert_allclose(np.nan_to_num(old_plate.force), np.nan_to_num(force), atol=1e-3)
    np.testing.assert_array_equal(np.asarray(old_plate.cop), np.asarray(drifted.cop))


def test_marker_correction_subtracts_the_lab_shift(walk: Path) -> None:
    from solver.io.trc import read_trc

    mk = read_trc(walk / "trials" / "walk" / "markers.trc")
    shift = np.tile([0.01, -0.02, 0.005], (mk.time.size, 1))
    entry = {"cause": "marker_offset", "trial": "walk", "marker": mk.names[3], "time_s": mk.time.tolist(), "lab_shift_m": shift.tolist()}
    out = correct_markers(mk, entry)
    np.testing.assert_allclose(out.positions[:, 3], mk.positions[:, 3] - shift)
    np.testing.assert_array_equal(np.delete(out.positions, 3, axis=1), np.delete(mk.positions, 3, axis=1))


def test_mass_and_masks_of_saved_extensions(walk: Path) -> None:
    hidden = hide_body_mass(walk, "walk", np.random.default_rng(5))
    stated = load_subject(walk).mass_kg
    append_extension(walk, {"cause": "body_mass", "trial": None, **hidden.truth})
    append_extension(walk, {"cause": "unmeasured_force", "trial": "walk", "n_frames": 10, "frames": [[2, 4]]})
    append_extension(walk, {"cause": "unmeasured_force", "trial": "walk", "n_frames": 10, "frames": [[7, 8]]})
    assert [e["cause"] for e in read_extensions(walk)] == ["body_mass", "unmeasured_force", "unmeasured_force"]
    assert extend_subject(load_subject(walk)).mass_kg == pytest.approx(stated + hidden.truth["mass_change_kg"])
    masks = extension_masks(load_subject(walk))
    np.testing.assert_array_equal(np.flatnonzero(masks["walk"]), [2, 3, 7])
    reviewer = {"walk": np.eye(1, 10, 0, dtype=bool)[0]}
    np.testing.assert_array_equal(np.flatnonzero(join_masks(reviewer, masks)["walk"]), [0, 2, 3, 7])


def test_damaged_extensions_file_is_named(walk: Path) -> None:
    (walk / "addb_extensions.json").write_text('{"schema": "addb.extensions", "version": 1, "extensions": [')
    with pytest.raises(SubjectFolderError, match="addb_extensions.json"):
        read_extensions(walk)
    (walk / "addb_extensions.json").write_text('{"schema": "something else", "version": 1, "extensions": []}')
    with pytest.raises(SubjectFolderError, match="addb.extensions version 1"):
        read_extensions(walk)


def test_extension_naming_an_unknown_plate_is_refused(walk: Path) -> None:
    rec = read_forces(walk / "trials" / "walk" / "grf.mot")
    with pytest.raises(SubjectFolderError, match="plate 'nope'"):
        correct_forces(rec, {"cause": "plate_force_gain", "plate": "nope", "gain": 1.1})


def test_saving_into_a_read_only_subject_is_refused(walk: Path) -> None:
    """A subject folder marked read-only (the shared data) gets no extension file, and the
    error names the folder, even for root, whom ``os.access`` lets write anywhere."""
    from solver.corrections import FILE_NAME, save_extension

    walk.chmod(0o555)
    try:
        with pytest.raises(SubjectFolderError, match="read-only") as err:
            save_extension(walk, {"cause": "body_mass", "trial": "walk", "mass_change_kg": 3.0})
        assert str(walk) in str(err.value)
        assert not (walk / FILE_NAME).exists()
    finally:
        walk.chmod(0o755)


def test_marker_offset_entry_moves_the_recordings_by_the_shift_beyond_the_fitted_offset() -> None:
    """``--apply`` and the refit move a marker's recordings by the shift its error shows
    beyond the offset the kinematics stage gave the model marker (the whole misplacement
    counts that offset twice), in the lab frame at each frame."""
    from types import SimpleNamespace

    from solver.diagnose.core import extension_entry
    from solver.diagnose.selection import Evaluation

    angle = np.linspace(0.0, 1.0, 5)
    rot = np.zeros((5, 2, 3, 3))
    rot[:, :, 0, 0] = np.cos(angle)[:, None]
    rot[:, :, 0, 2] = np.sin(angle)[:, None]
    rot[:, :, 1, 1] = 1.0
    rot[:, :, 2, 0] = -np.sin(angle)[:, None]
    rot[:, :, 2, 2] = np.cos(angle)[:, None]
    data = SimpleNamespace(
        markers=SimpleNamespace(names=["A", "B"], rotation=rot), time=np.arange(5) * 0.01, trial=SimpleNamespace(trial="walk")
    )
    residual, fitted = np.array([0.01, -0.02, 0.005]), np.array([0.003, 0.004, 0.0])
    params = {"value": (fitted + residual).tolist(), "marker": "B", "body": "femur_l", "shift_m": (fitted + residual).tolist(),
              "residual_shift_m": residual.tolist(), "fitted_offset_m": fitted.tolist()}
    ev = Evaluation("marker_offset", "B", params, None, 3, 1.0, 1.0, np.ones(5), 1.0)
    entry = extension_entry(ev, data, data.time)
    np.testing.assert_allclose(entry["shift_m"], residual)
    np.testing.assert_allclose(entry["misplacement_m"], fitted + residual)
    np.testing.assert_allclose(entry["lab_shift_m"], np.einsum("tij,j->ti", rot[:, 1], residual), atol=1e-6)
