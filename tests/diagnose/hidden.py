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
Causes whose detection is not yet reliable are marked ``xfail`` with their measured
detection rate, so the gap stays visible.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.diagnose.effects import TOLERANCE, check
from tests.diagnose.harness import Base, draw, hidden_run, neutral_base

#: Causes named reliably: their first benchmark draws are tested (even indices on the walk,
#: odd ones on the run; see :func:`tests.diagnose.harness.draw`).
RELIABLE = {
    "unmeasured_force": (0, 1, 2, 3),
    "force_time_offset": (0, 1, 2, 3, 4),  # 4: a -10 ms delay on the walk, whose correction moves the shared span by a frame
    "body_mass": (0, 1, 2, 4),
    "plate_force_offset": (0, 1, 2, 3, 4),
    "plate_force_gain": (0, 2, 3, 4),  # 3: the run's belt R at 0.968
    "marker_offset": (0, 1, 2),  # walk only (the run's model has no landmark markers)
    "segment_mass_distribution": (2, 5),  # a walk and a run draw (the run's base applies its own +2.8 kg to the legs)
    "plate_position_offset": (0, 1, 3, 4),  # walk 1.5 and 1.2 cm, run 3.3 and 2.3 cm
}
#: On the treadmill run, whose two plates are the belts under one foot each, a gain of one
#: plate competes with a body-mass change (both scale the load of every other stance): 4 of
#: the 10 run draws are named (docs/diagnose/RESULTS.md: 2 of 6 on belt L, 2 of 4 on belt R,
#: whose other 2 name a mass change), so the first run draw (belt L at 0.946) is an
#: expected failure.
RUN_GAP = {
    "plate_force_gain": "on the treadmill run a one-belt gain competes with a body-mass change (4 of 10 run draws named; this one, belt L at 0.946, names nothing)",
}
#: Causes not yet named reliably (detection rates in docs/diagnose/RESULTS.md), or whose first
#: draw is a known miss: that draw is run as an expected failure, so that the gap stays
#: visible and an improvement shows.
UNRELIABLE = {
    "segment_mass_distribution": "the walk's base keeps its own +2.9 kg to the legs (not named: 3 of 5 folds improve), so a hidden move out of the legs (draw 0: 5.8 kg) leaves about 2 kg, in 3 of 5 folds (docs/diagnose/RESULTS.md)",
}


def cases(key: str) -> list:
    """The hidden-effect cases of trial ``key``: ``pytest.param(cause, seed)`` each, the
    expected failures marked."""
    out = []

    def add(cause: str, index: int, why: str | None = None) -> None:
        k, seed = draw(cause, index)
        if k == key:
            marks = () if why is None else (pytest.mark.xfail(reason=why, strict=False),)
            out.append(pytest.param(cause, seed, marks=marks, id=f"{cause}-{k}-{seed}"))

    for cause, indices in RELIABLE.items():
        for index in indices:
            add(cause, index)
    for cause, why in RUN_GAP.items():
        add(cause, 1, why)
    for cause, why in UNRELIABLE.items():
        add(cause, 0, why)
    return out


def assert_named_and_recovered(cause: str, seed: int, base: Base, tmp_path: Path) -> None:
    """Hide ``cause`` (seed ``seed``) in a copy of ``base``, run ``addb diagnose`` and check
    the choice, the parameter (:data:`tests.diagnose.effects.TOLERANCE`) and the held-out
    gain."""
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


def trial_tests(key: str) -> tuple[object, object]:
    """The module-scoped fixture ``base`` (trial ``key``'s neutral base) and the test of
    every case of that trial, for a test module to bind at its top level."""

    @pytest.fixture(scope="module", name="base")
    def base_fixture(tmp_path_factory: pytest.TempPathFactory) -> Base:
        return neutral_base(key, tmp_path_factory.mktemp("base") / key)

    @pytest.mark.slow
    @pytest.mark.parametrize(("cause", "seed"), cases(key))
    def test_hidden_cause_is_named_and_recovered(cause: str, seed: int, base: Base, tmp_path: Path) -> None:
        assert_named_and_recovered(cause, seed, base, tmp_path)

    return base_fixture, test_hidden_cause_is_named_and_recovered

