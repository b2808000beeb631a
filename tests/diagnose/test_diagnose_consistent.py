"""No false alarm: on a trial consistent by construction (a processed real walk's motion,
forces computed from it, realistic marker and force noise), ``addb diagnose`` names no cause."""

from __future__ import annotations

from pathlib import Path

import pytest

from solver.results import load_processed
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import copy_subject
from tests.diagnose.harness import diagnose_json
from tests.diagnose.synthetic import consistent_subject

pytestmark = pytest.mark.slow

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.fixture(scope="module")
def processed_walk(tmp_path_factory: pytest.TempPathFactory):
    from solver.pipeline import options_for_fit, process_subject

    subject = copy_subject(WALK, tmp_path_factory.mktemp("real") / "walk")
    # the default (converged) fit's motion, as the benchmark's bases (tests/diagnose/harness.py, _process)
    process_subject(subject, subject / "addb_out", options=options_for_fit("converged"))
    return load_processed(subject / "addb_out", "walk")


@pytest.mark.parametrize("seed", [0, 1])
def test_consistent_trial_names_no_cause(processed_walk, seed: int, tmp_path: Path) -> None:
    subject = consistent_subject(processed_walk, WALK, tmp_path / "synthetic", seed=seed)
    report = diagnose_json(subject, "walk")
    assert report["chosen"] is None, report["reason"]
    assert "No cause stands out" in report["reason"]
    # and the force causes' estimates are near their neutral values
    by = {c["cause"]: c["parameters"] for c in report["candidates"]}
    assert abs(by["body_mass"]["mass_change_kg"]) < 2.0
    assert abs(by["force_time_offset"]["delay_s"]) < 0.01
