"""tests/benchmarks/probe_cop_symmetry.py on the shared walk: a hidden shift of one belt moves
that foot's mean centre of pressure by the shift turned into the foot's frame and leaves the
other foot's alone; a hidden registration moves both; undoing a candidate that is the hidden
effect gives back the recording's own means; the tie-break keeps a choice that is already the
candidate of the smallest asymmetry."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from solver.results import load_processed
from tests.conftest import SHARED_DATA
from tests.scripts import load_script

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def probe():
    return load_script("tests/benchmarks/probe_cop_symmetry.py")


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory):
    """The walk processed (its motion), its force recording and the probe's foot frames."""
    from addb_viewer.cli import main as cli
    from solver.io.mot import read_forces

    out = tmp_path_factory.mktemp("cop") / "walk"
    subject = SHARED_DATA / "subjects" / "rajagopal2016_walk"
    with contextlib.redirect_stdout(io.StringIO()):
        assert cli(["process", str(subject), "--out", str(out)]) == 0
    processed = load_processed(out, "walk")
    recording = read_forces(subject / "trials" / "walk" / "grf.mot")
    return processed, recording


def test_a_belt_shift_moves_one_foot_and_a_registration_both(probe, walk) -> None:
    processed, recording = walk
    feet = probe.FootFrames(processed, recording, 9.80665 * processed.mass_kg)
    before = feet.means(recording)
    shift = np.array([0.02, 0.0, -0.01])
    moved = feet.means(probe.shifted(recording, "r", shift))
    np.testing.assert_allclose(moved["l"], before["l"], atol=1e-12)  # the other foot's alone
    _, rot, _ = feet.frames["r"]
    local = np.einsum("tji,j->ti", rot, shift).mean(axis=0)  # the shift in the right foot's frame
    np.testing.assert_allclose(moved["r"] - before["r"], local[[0, 2]], atol=1e-12)
    assert abs(np.linalg.norm(moved["r"] - before["r"]) - np.linalg.norm(shift)) < 0.002  # the foot lies nearly flat
    truth = {"shift_m": [0.015, 0.0, 0.01], "rotation_rad": float(np.radians(1.0)), "centre_m": [0.9, 0.0, -0.25]}
    registered = feet.means(probe.hidden_recording(recording, "plate_registration", None, truth))
    assert np.linalg.norm(registered["r"] - before["r"]) > 0.01 and np.linalg.norm(registered["l"] - before["l"]) > 0.01


def test_undoing_the_hidden_effect_gives_the_recording_back(probe, walk) -> None:
    processed, recording = walk
    feet = probe.FootFrames(processed, recording, 9.80665 * processed.mass_kg)
    own = feet.asymmetry(recording)
    truth = {"shift_m": [-0.01, 0.0, 0.022], "rotation_rad": float(np.radians(-1.5)), "centre_m": [0.9, 0.0, -0.25]}
    for cause, plate in (("plate_position_offset", "r"), ("plate_registration", None)):
        hidden = probe.hidden_recording(recording, cause, plate, truth)
        params = {"plate": plate, **truth} if plate else truth
        back = probe.undone(hidden, {"cause": cause, "parameters": params})
        assert feet.asymmetry(hidden) != pytest.approx(own, abs=1e-3)
        assert feet.asymmetry(back) == pytest.approx(own, abs=1e-12)


def test_the_tie_break_keeps_a_choice_of_the_smallest_asymmetry(probe) -> None:
    row = {"cause": "plate_position_offset", "choice": "r", "truth": {}, "chosen": "plate_position_offset",
           "chosen_choice": "r", "within_tolerance": True}  # fmt: skip
    scored = {("plate_position_offset", "r"): 0.01, ("plate_registration", None): 0.02}
    assert probe.tie_break(row, {}, {}, scored, {}) == (None, True)
    # the other candidate smaller, and not the hidden cause: named instead, so not within tolerance
    scored[("plate_registration", None)] = 0.005
    assert probe.tie_break(row, {}, {}, scored, {}) == (("plate_registration", None), False)
    # a cause outside the two: the diagnosis' choice stands
    assert probe.tie_break({**row, "chosen": "body_mass", "within_tolerance": False}, {}, {}, scored, {}) == (None, False)
