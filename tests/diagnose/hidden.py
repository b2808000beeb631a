"""Hidden-effect tests: a cause hidden in a real trial's raw files is named by the public
``addb diagnose``, its parameter is recovered, and the extension gains on held-out frames.

Each real trial is first made a *neutral base* (its own findings applied until none stands
out, :func:`tests.diagnose.harness.neutral_base`); the effect is then hidden in a copy
with a seeded random magnitude in the issue's ranges (:mod:`tests.diagnose.effects`), and
the parameter is compared with the base's own estimate of the same cause.

The cases are the benchmark's first draws (``tests/benchmarks/bench_diagnose.py``), so
their outcome is in ``docs/diagnose/RESULTS.md`` too. They run from one test file per
trial (``test_diagnose_hidden_walk.py``, ``test_diagnose_hidden_run.py``), so that the
two trials' bases and draws run side by side on the test workers (one file per worker).
Every cause runs a contiguous range of draws (:data:`DRAWS`); the known misses among them
are strict expected failures with their reason (:data:`KNOWN_MISSES`), so the gap stays
visible and nothing is silently left out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.diagnose.effects import (
    TOLERANCE,
    Hidden,
    check,
    copy_subject,
    hide_registration,
    loaded_plates,
)
from tests.diagnose.harness import Base, diagnose_json, draw, hidden_run, neutral_base

#: Every cause runs its first :data:`DRAWS` benchmark draws, a contiguous range (draw k on
#: the walk for even k and on the run for odd k; every ``marker_offset`` draw on the walk, the
#: run's model having no landmark markers; :func:`tests.diagnose.harness.draw`). No draw is
#: left out: a known miss is an expected failure (``strict``: a miss that starts passing
#: fails, so the list stays true) with what the diagnosis does instead. Rates over 20 draws
#: per cause stay the benchmark's (docs/diagnose/RESULTS.md).
DRAWS = 6
#: (cause, draw index) -> what the diagnosis does instead (measured on 2026-11-26 with
#: ``pytest tests/diagnose/test_diagnose_hidden_*.py``, the diagnosis judging the pipeline's
#: default converged fit: 48 of the 54 draws named and recovered). On the band fit it was
#: calibrated on until 2026-11-26 the misses were other draws: the run's body mass of draw 5,
#: the walk's plate shift of draw 2 and its mass redistribution of draw 4 (the refit's
#: held-out residual did not go down) are named and recovered on the converged fit. The walk's
#: mass redistribution of draw 2, named the plates' registration until the registration had
#: to be confirmed on the marker-only motion (2026-11-27), is named and recovered since.
KNOWN_MISSES: dict[tuple[str, int], str] = {
    ("plate_position_offset", 4): "walk: the fitted motion keeps 0.4 cm of a 1.2 cm shift (under the 0.5 cm worth naming) and the marker-only motion's estimate is 1.7 standard errors from none: a 1.8 kg mass redistribution that removes 0 % of its channels' cost is named",
    ("marker_offset", 3): "walk: the offset improves only 60 % of the held-out folds: no cause named",
    ("marker_offset", 5): "walk, R.Elbow: named, but the elbow and wrist joints take up most of the shift (estimate outside 0.5 cm)",
    ("segment_mass_distribution", 0): "walk: the base keeps its own +2.9 kg to the legs, so a hidden move out of the legs (5.8 kg) leaves about 2 kg, in 3 of 5 folds: no cause named",
    ("plate_registration", 3): "run: the fitted motion keeps 0.1 cm of a 1.2 cm shift and 1 degree turn; on the marker-only motion the registration removes 5 % of its channels' cost (needs 10 %): no cause named",
}


def cases(key: str) -> list:
    """The hidden-effect cases of trial ``key``: ``pytest.param(cause, seed)`` each, the
    known misses marked as strict expected failures."""
    from tests.diagnose.effects import CAUSES

    out = []
    for cause in CAUSES:
        for index in range(DRAWS):
            k, seed = draw(cause, index)
            if k != key:
                continue
            why = KNOWN_MISSES.get((cause, index))
            marks = () if why is None else (pytest.mark.xfail(reason=why, strict=True),)
            out.append(pytest.param(cause, seed, marks=marks, id=f"{cause}-{k}-{seed}"))
    return out


def assert_named_and_recovered(cause: str, seed: int, base: Base, tmp_path: Path) -> dict:
    """Hide ``cause`` (seed ``seed``) in a copy of ``base``, run ``addb diagnose`` and check
    the choice, the parameter (:data:`tests.diagnose.effects.TOLERANCE`) and the held-out
    gain; returns the report."""
    hidden, report = hidden_run(base, cause, seed, tmp_path / "subject")
    result = check(hidden, report, base.report)
    assert report["chosen"] == cause, report["reason"]
    assert result["detected"], f"chose {report['chosen_parameters']} instead of {hidden.choice}"
    assert result["error"] <= TOLERANCE[cause], (hidden.truth, report["chosen_parameters"])
    chosen = next(c for c in report["candidates"] if c["cause"] == cause)
    assert chosen["gain"] > 0 and chosen["held_out_gain"] > 0  # cross-validated: on held-out frames
    before, after = report["held_out"]["before"], report["held_out"]["after"]
    # the residual on held-out frames goes down with the extension (markers for a marker offset)
    if cause == "marker_offset":
        assert after["marker_rms_m"] < before["marker_rms_m"]
    else:
        assert after["linear_residual_rms_N"] ** 2 + after["angular_residual_rms_Nm"] ** 2 < (
            before["linear_residual_rms_N"] ** 2 + before["angular_residual_rms_Nm"] ** 2
        )
    return report


#: The shift of :func:`assert_one_or_every_plate`, m (ground frame, in the floor plane).
SHIFT = (0.018, 0.0, -0.017)


def assert_one_or_every_plate(which: str, base: Base, tmp_path: Path) -> None:
    """The same 2.5 cm shift of the centre of pressure hidden in one plate's readings (the
    plate loaded on most samples) is named ``plate_position_offset`` on that plate, and in
    every plate's readings ``plate_registration``; each recovered relative to the base's
    own estimate (:data:`tests.diagnose.effects.TOLERANCE`)."""
    from solver.io.mot import read_forces

    subject = copy_subject(base.subject, tmp_path / "subject")
    rec = {p.name: p for p in read_forces(subject / "trials" / base.trial / "grf.mot").plates}
    busiest = max(loaded_plates(subject, base.trial), key=lambda n: int(np.sum(np.nan_to_num(rec[n].force[:, 1]) > 50.0)))
    shift = np.array(SHIFT)
    if which == "one":
        hide_registration(subject, base.trial, shift, 0.0, (busiest,))
        hidden = Hidden("plate_position_offset", busiest, {"shift_m": shift.tolist()})
    else:
        centre = hide_registration(subject, base.trial, shift, 0.0)
        hidden = Hidden("plate_registration", None, {"shift_m": shift.tolist(), "rotation_rad": 0.0, "centre_m": centre.tolist()})
    report = diagnose_json(subject, base.trial)
    result = check(hidden, report, base.report)
    assert report["chosen"] == hidden.cause, report["reason"]
    assert result["detected"], f"chose {report['chosen_parameters']} instead of {busiest}"
    assert result["error"] <= TOLERANCE[hidden.cause], (hidden.truth, report["chosen_parameters"])


def trial_tests(key: str) -> tuple[object, object, object]:
    """The module-scoped fixture ``base`` (trial ``key``'s neutral base), the test of every
    case of that trial and the test of a shift of one plate or of every plate, for a test
    module to bind at its top level."""

    @pytest.fixture(scope="module", name="base")
    def base_fixture(tmp_path_factory: pytest.TempPathFactory) -> Base:
        return neutral_base(key, tmp_path_factory.mktemp("base") / key)

    @pytest.mark.slow
    @pytest.mark.parametrize(("cause", "seed"), cases(key))
    def test_hidden_cause_is_named_and_recovered(cause: str, seed: int, base: Base, tmp_path: Path) -> None:
        assert_named_and_recovered(cause, seed, base, tmp_path)

    @pytest.mark.slow
    @pytest.mark.parametrize("which", ["one", "every"])
    def test_shift_of_one_plate_or_of_every_plate(which: str, base: Base, tmp_path: Path) -> None:
        assert_one_or_every_plate(which, base, tmp_path)

    return base_fixture, test_hidden_cause_is_named_and_recovered, test_shift_of_one_plate_or_of_every_plate

