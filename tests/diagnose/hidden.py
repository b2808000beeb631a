"""Hidden-effect tests: a cause hidden in a real trial's raw files is named by the public
``addb diagnose``, its parameter is recovered, and the extension gains on held-out frames.

Each real trial is first made a *neutral base* (its own findings applied until none stands
out, :func:`tests.diagnose.harness.neutral_base`); the effect is then hidden in a copy
with a seeded random magnitude in the issue's ranges (:mod:`tests.diagnose.effects`), and
the parameter is compared with the base's own estimate of the same cause.

Causes whose detection is not yet reliable (see ``docs/diagnose/RESULTS.md``) are marked
``xfail`` with their measured detection rate, so the gap stays visible.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.diagnose.effects import TOLERANCE, check
from tests.diagnose.harness import Base, draw, hidden_run, neutral_base

pytestmark = pytest.mark.slow

#: Causes named reliably: their first benchmark draws are tested (even indices on the walk,
#: odd ones on the run; see :func:`tests.diagnose.harness.draw`).
RELIABLE = {
    "unmeasured_force": (0, 1, 2, 3),
    "force_time_offset": (0, 1, 2, 3, 4),  # 4: a -10 ms delay on the walk, whose correction moves the shared span by a frame
    "body_mass": (0, 1, 2, 4),
    "plate_force_offset": (0, 1, 2, 3, 4),
    "plate_force_gain": (0, 2, 4),
    "marker_offset": (0, 1, 2),  # walk only (the run's model has no landmark markers)
    "segment_mass_distribution": (2, 5),  # a walk and a run draw (the run's base applies its own +2.8 kg to the legs)
}
#: On the treadmill run, whose two plates are the belts under one foot each, a gain of one
#: plate competes with a body-mass change (both scale the load of every other stance) and
#: usually neither stands out: the run draw of this cause is an expected failure.
RUN_GAP = {
    "plate_force_gain": "on the treadmill run a one-plate gain competes with a body-mass change; usually neither stands out",
}
#: Causes not yet named reliably (detection rates in docs/diagnose/RESULTS.md), or whose first
#: draw is a known miss: that draw is run as an expected failure, so that the gap stays
#: visible and an improvement shows.
UNRELIABLE = {
    "plate_position_offset": "walk 6 of 10 benchmark draws named (2 within 0.5 cm; the sideways part of a shift is uncertain to 0.9 cm there), run 3 of 10 (3 within): shifts under 2.5 cm rarely stand out from the run's own residual (2026-11-23)",
    "segment_mass_distribution": "the walk's base keeps its own +2.9 kg to the legs (not named: 3 of 5 folds improve), so a hidden move out of the legs (draw 0: 5.8 kg) leaves about 2 kg, in 3 of 5 folds (docs/diagnose/RESULTS.md)",
}


def _cases() -> list:
    out = []
    for cause, indices in RELIABLE.items():
        for index in indices:
            key, seed = draw(cause, index)
            out.append(pytest.param(cause, key, seed, id=f"{cause}-{key}-{seed}"))
    for cause, why in RUN_GAP.items():
        key, seed = draw(cause, 1)
        out.append(pytest.param(cause, key, seed, marks=pytest.mark.xfail(reason=why, strict=False), id=f"{cause}-{key}-{seed}"))
    for cause, why in UNRELIABLE.items():
        key, seed = draw(cause, 0)
        out.append(pytest.param(cause, key, seed, marks=pytest.mark.xfail(reason=why, strict=False), id=f"{cause}-{key}-{seed}"))
    return out


@pytest.fixture(scope="module")
def bases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Base]:
    """Neutral bases of the walk and the run, built on first use."""
    root = tmp_path_factory.mktemp("bases")
    cache: dict[str, Base] = {}

    class Lazy(dict):
        def __missing__(self, key: str) -> Base:
            cache[key] = neutral_base(key, root / key)
            self[key] = cache[key]
            return cache[key]

    return Lazy()


@pytest.mark.parametrize(("cause", "key", "seed"), _cases())
def test_hidden_cause_is_named_and_recovered(cause: str, key: str, seed: int, bases: dict[str, Base], tmp_path: Path) -> None:
    base = bases[key]
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
