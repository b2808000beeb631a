"""Better than an expert: on every trial of shared/data/expert_comparison our automatic
scaling + IK leaves a lower marker RMS than the expert's hand-scaled model and IK, both
evaluated with our forward kinematics on the same markers and frames. The full table is in
docs/kinematics/EXPERT_COMPARISON.md (tests/benchmarks/bench_expert_comparison.py)."""

from __future__ import annotations

import pytest

from tests.benchmarks.bench_expert_comparison import ROOT, expert_rms

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("expert", ["Expert1", "Expert2"])
def test_ours_is_lower_than_the_experts_on_every_trial(expert: str) -> None:
    rows = expert_rms(ROOT / expert)
    assert len(rows) >= (25 if expert == "Expert1" else 4)
    worse = [(r["trial"], round(r["ours_rms_cm"], 2), round(r["expert_rms_cm"], 2)) for r in rows if r["ours_rms_cm"] >= r["expert_rms_cm"]]
    assert not worse, worse
