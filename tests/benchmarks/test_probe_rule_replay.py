"""tests/benchmarks/probe_rule_replay.py: replayed with the rule as it is, each captured draw
and consistent trial names what the live diagnosis named, with the benchmark's own verdict
(its ``--json`` rows); a rule that asks the impossible names nothing."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from solver.diagnose.causes.registry import NAMES
from solver.diagnose.selection import ChoiceRule

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "tests" / "benchmarks" / "probe_rule_replay.py"


@pytest.fixture(scope="module")
def probe():
    spec = importlib.util.spec_from_file_location("probe_rule_replay", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["probe_rule_replay"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def captured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two walk draws (a plate's shift, which the joint fit at mass_sigma 0.1 names as the
    plates' registration, and a registration) and one consistent trial, captured."""
    out = tmp_path_factory.mktemp("replay") / "capture.pkl"
    subprocess.run(
        [sys.executable, str(SCRIPT), "capture", "--sigma", "0.1", "--out", str(out), "--", "--trials", "walk",
         "--causes", "plate_position_offset,plate_registration", "--first", "6", "--draws", "1", "--synthetic", "1"],
        cwd=REPO, check=True, capture_output=True,
    )
    return out


def test_the_rule_as_it_is_replays_the_live_choices(probe, captured: Path) -> None:
    records = probe.load([captured])
    assert [r.kind for r in records] == ["draw", "draw", "synthetic"]
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
