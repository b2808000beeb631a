"""``addb info FILE.b3d``: the summary of results.b3d against the oracle, and a damaged file's error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from addb_viewer.cli import main
from solver.io.summary import summarize

SHARED = Path(__file__).resolve().parents[2].parent / "shared"
B3D = SHARED / "data" / "b3d" / "results.b3d"

pytestmark = pytest.mark.skipif(not B3D.exists(), reason="shared results.b3d not present")


def test_summary_matches_oracle() -> None:
    o = json.loads((SHARED / "oracles" / "b3d_results_oracle.json").read_text())
    s = summarize(B3D)
    assert s["kind"] == "b3d" and s["dofs"] == o["header"]["getNumDofs"]
    assert s["passes"] == [t.lower() for t in o["header"]["processingPassTypes"]]
    assert [t["name"] for t in s["trials"]] == [t["getTrialName"] for t in o["trials"]]
    assert [t["frames"] for t in s["trials"]] == [t["getTrialLength"] for t in o["trials"]]
    assert [t["rate_hz"] for t in s["trials"]] == [1 / t["getTrialTimestep"] for t in o["trials"]]
    assert [t["missing_grf_frames"] for t in s["trials"]] == [
        sum(r != "notMissingGRF" for r in t["getMissingGRF_names"]) for t in o["trials"]
    ]


def test_cli_info(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["info", str(B3D)]) == 0
    out = capsys.readouterr().out
    assert "walking2_segment_0" in out and "33 DOFs" in out and "100 Hz" in out
    bad = tmp_path / "cut.b3d"
    bad.write_bytes(B3D.read_bytes()[:1_000_000])
    assert main(["info", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "B3dFormatError" in err and "byte 0" in err and str(bad) in err
