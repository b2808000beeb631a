"""tests/benchmarks/probe_rule_replay.py: replayed with the rule as it is, each captured draw
and consistent trial names what the live diagnosis named, with the benchmark's own verdict
(its ``--json`` rows); a rule that asks the impossible names nothing; with the registration
confirmed on the marker-only motion (as addb diagnose does) a hidden mass redistribution has
its name and a hidden registration keeps its own."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from solver.diagnose.causes.registry import NAMES
from solver.diagnose.selection import ChoiceRule
from tests.scripts import load_script

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "tests" / "benchmarks" / "probe_rule_replay.py"


@pytest.fixture(scope="module")
def probe():
    return load_script(str(SCRIPT.relative_to(REPO)))


@pytest.fixture(scope="module")
def captured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three walk draws (a plate's shift, which the joint fit at mass_sigma 0.1 names as the
    plates' registration; a mass redistribution, which it named so until the registration had
    to be confirmed on the marker-only motion; a registration) and one consistent trial,
    captured."""
    out = tmp_path_factory.mktemp("replay") / "capture.pkl"
    subprocess.run(
        [sys.executable, str(SCRIPT), "capture", "--sigma", "0.1", "--out", str(out), "--", "--trials", "walk",
         "--causes", "plate_position_offset,segment_mass_distribution,plate_registration", "--first", "6", "--draws", "1", "--synthetic", "1"],
        cwd=REPO, check=True, capture_output=True,
    )
    return out


def test_the_rule_as_it_is_replays_the_live_choices(probe, captured: Path) -> None:
    records = probe.load([captured])
    assert [r.kind for r in records] == ["draw", "draw", "draw", "synthetic"]
    s = probe.score(records, ChoiceRule())
    assert s["unlike"] == 0 and s["misses"] == 0
    rows = json.loads(captured.with_suffix(".json").read_text())
    for row in rows["rows"]:
        named, within = s["verdicts"][row["cause"], row["trial"], row["seed"]]
        assert (named[0] if named else None) == row["chosen"]
        assert within == row["within_tolerance"]
    assert s["alarms"] == sum(t["chosen"] is not None for t in rows["synthetic"])
    same = probe.rule_of(probe.current_values())  # the search's start is the rule as it is
    assert replace(same, relative_gain_of={}) == replace(ChoiceRule(), relative_gain_of={})
    assert all(same.relative_gain_needed(c) == ChoiceRule().relative_gain_needed(c) for c in NAMES)


def test_a_rule_asking_the_impossible_names_nothing(probe, captured: Path) -> None:
    records = probe.load([captured])
    s = probe.score(records, probe.rule_of({"min_t": 1e9}))
    assert all(named is None for named, _ in s["verdicts"].values())
    assert s["alarms"] == 0 and sum(s["within"].values()) == 0


def test_the_registration_confirmed_on_the_marker_only_motion(probe, captured: Path) -> None:
    # addb diagnose confirms the registration on the marker-only motion
    # (solver.diagnose.selection.confirmed, since the probe's --confirm-registration 0 was
    # measured): the mass draw the joint fit named as the registration is named as what it is
    records = probe.load([captured])
    assert probe.confirmed(records, None) is records
    named = {r.hidden[0]: r for r in records if r.kind == "draw"}
    mass, registration = named["segment_mass_distribution"], named["plate_registration"]
    twin = {(e.cause, e.choice): e for e in mass.marker_only}
    assert twin["plate_registration", None].relative_gain < 0  # it makes the marker-only motion's cost worse
    assert all(e.cause != "plate_registration" for e in mass.fitted)  # so it is no candidate on the fitted one
    assert any(e.cause == "plate_registration" for e in registration.fitted)  # a hidden registration is
    verdicts = probe.score(records, ChoiceRule())["verdicts"]
    assert verdicts["segment_mass_distribution", mass.trial, mass.seed] == (("segment_mass_distribution", None), True)
    assert verdicts["plate_registration", registration.trial, registration.seed] == (("plate_registration", None), True)
    # the probe's own confirmation is then what the product does
    assert probe.score(probe.confirmed(records, 0.0), ChoiceRule())["verdicts"] == verdicts


def test_compare_names_the_live_column_and_lists_changed_draws(probe, tmp_path: Path) -> None:
    table = [REPO / "docs" / "diagnose" / f"results_draws_{part}.json" for part in ("0_9", "10_19")]
    same = probe.compare(table, table, "live, label")
    assert "| within tolerance, live, label |" in same and "joint fit" not in same
    assert "Draws whose verdict changed (0 of 180;" in same
    # one draw's verdict flipped in a copy: listed, and its row counts one fewer
    rows = json.loads(table[1].read_text())
    flipped = next(r for r in rows["rows"] if r["within_tolerance"])
    flipped["within_tolerance"] = False
    (tmp_path / "b.json").write_text(json.dumps(rows))
    text = probe.compare(table, [table[0], tmp_path / "b.json"], "live")
    assert "Draws whose verdict changed (1 of 180;" in text
    within = sum(r["within_tolerance"] for t in table for r in json.loads(t.read_text())["rows"] if r["cause"] == flipped["cause"])
    assert f"| {flipped['cause']} | 20 | {within} | {within - 1} |" in text
    assert f"{flipped['trial']} draw {flipped['seed']}" in text
