"""A subject one of whose trials has force plates that never carry force (a plate switched
off, an empty export): the subject is processed, the mass fitted on its other trial, and the
trial without a measured frame is reported as such, never with numbers it does not have,
nor counted as over Hicks' thresholds in a dataset's totals.

The walk, with a second copy of its walk trial, ``walk_zero``, whose grf.mot holds zeros in
every column but time.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from solver.dataset.summary import dataset_totals, trial_row
from solver.results import load_processed
from tests.cli_run import run_addb as _run
from tests.conftest import SHARED_DATA, writable_copy
from tests.trial_edits import zero_forces

pytestmark = pytest.mark.slow


def test_a_trial_whose_plates_never_carry_force_is_reported_without_numbers(tmp_path: Path) -> None:
    subject = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path / "walk")
    shutil.copytree(subject / "trials" / "walk", subject / "trials" / "walk_zero")
    zero_forces(subject / "trials" / "walk_zero" / "grf.mot")
    out = tmp_path / "out"
    code, printed, err = _run(["process", str(subject), "--out", str(out)])
    assert code == 0, err
    results = json.loads((out / "walk_zero" / "results.json").read_text())
    assert results["n_observed_frames"] == 0 and results["hicks_linear_ok"] is None
    row = next(line.split() for line in printed.splitlines() if line.startswith("walk_zero "))
    assert row[1] == "0/238" and row[3:] == ["-", "-", "-", "-"], row  # trial, frames, marker RMS, then no numbers
    assert "All-NaN" not in err and "nan" not in printed, err
    assert ("addb: warning: trial walk_zero: no frame with measured force enters the fit (all 238 frames left out, "
            "first for: measured vertical force differs from m(a+g)): it has no residuals or Hicks verdicts") in err, err  # fmt: skip
    code, info, err = _run(["info", str(out)])
    assert code == 0, err
    lines = info.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("  trial walk_zero:"))
    assert lines[k + 1] == "    no frame with measured force entered the fit: no residuals or Hicks verdicts", lines[k : k + 2]
    # a dataset's totals: the share of trials within Hicks' thresholds is over the trials that have a verdict
    rows = [trial_row(load_processed(out, name)) for name in ("walk", "walk_zero")]
    totals = dataset_totals([{"status": "ok", "trials": rows}])
    walk = rows[0]
    assert walk["hicks_linear_ok"] and walk["hicks_angular_ok"], walk  # so the walk alone is within both
    assert totals["hicks_linear_share"] == 1.0 and totals["hicks_angular_share"] == 1.0, totals
