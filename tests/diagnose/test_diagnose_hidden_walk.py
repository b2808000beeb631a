"""Hidden-effect tests on the walk (:mod:`tests.diagnose.hidden`; one module per trial so that
the test workers run the trials side by side)."""

from pathlib import Path

import numpy as np
import pytest

from tests.diagnose.harness import Base, draw
from tests.diagnose.hidden import assert_named_and_recovered, trial_tests

base, test_hidden_cause_is_named_and_recovered, test_shift_of_one_plate_or_of_every_plate = trial_tests("walk")


@pytest.mark.parametrize("index", [8, 11], ids=["R.Elbow", "S2"])
def test_a_misplacement_the_scale_fit_took_up_in_part_is_recovered(index: int, base: Base, tmp_path: Path) -> None:
    # benchmark draws 8 (R.Elbow, 2.0 cm, mostly along the humerus) and 11 (S2, 2.1 cm, mostly
    # forward): the scale fit moves the landmark about 0.35 and 0.6 cm toward the marker
    # (lengthening the humerus, deepening the pelvis); without that part added back
    # (solver.kinematics.fit.landmark_scale_response) the estimates were 0.54 and 0.70 cm off
    _, seed = draw("marker_offset", index)
    report = assert_named_and_recovered("marker_offset", seed, base, tmp_path)
    assert np.linalg.norm(report["chosen_parameters"]["landmark_shift_m"]) > 0.002


@pytest.mark.parametrize(
    "index",
    [
        6,
        14,
        18,
        pytest.param(19, marks=pytest.mark.xfail(strict=True, reason=(
            "on the converged fit (2026-11-26) the offset is named and recovered, but the refit with it does not "
            "lower the held-out marker RMS"
        ))),
    ],
    ids=["L.MT5", "R.Toe", "R.Ankle", "R.Heel"],
)  # fmt: skip
def test_a_foot_marker_misplacement_is_named_on_folds_mixing_the_phases(index: int, base: Base, tmp_path: Path) -> None:
    # benchmark draws 6, 14, 18 and 19 (foot markers, 1.2-2.5 cm): the walk's foot markers
    # carry an error that repeats with every stride; with the blocks dealt to the folds in
    # turn each fold held one phase of it, and these four were missed (none named, or the
    # neighbouring R.Ankle for 14 and 19; docs/diagnose/RESULTS.md at 186d110). The marker
    # offsets' folds mix the phases (MarkerOffset.folds_mix_phases) since ae27b29
    _, seed = draw("marker_offset", index)
    report = assert_named_and_recovered("marker_offset", seed, base, tmp_path)
    chosen = next(c for c in report["candidates"] if c["cause"] == "marker_offset")
    assert chosen["folds_improved"] >= 0.8


def test_a_mass_redistribution_the_registration_took_is_named(base: Base, tmp_path: Path) -> None:
    # benchmark draw 12 (the legs 5.5 kg lighter; draw 2 is among the hidden-cause cases):
    # on the fitted motion the plates' registration removes 12 % of its channels' cost and
    # was named, while on the marker-only motion it adds 1.6 %; the registration is named
    # from the fitted motion only when that motion confirms it
    # (PlateRegistration.confirmed_on_marker_motion), and the reason says so
    _, seed = draw("segment_mass_distribution", 12)
    report = assert_named_and_recovered("segment_mass_distribution", seed, base, tmp_path)
    assert any(c["cause"] == "plate_registration" for c in report["candidates"])  # still ranked
    assert "plate_registration removes" in report["reason"] and "does not confirm it" in report["reason"]
