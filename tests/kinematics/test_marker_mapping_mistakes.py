"""Mistakes in a subject's marker mapping (``markers.yaml``) that leave markers out of the fit
are named on the command line: a mapping entry whose model marker the model does not carry
(a typo), and two columns of a trial that stand for one model marker (a lab marker mapped
onto a name the file also has). On the real walk, ``addb kinematics --trial static`` (the
scaling runs on every trial; a few seconds per run)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.cli_run import run_addb
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


def _kinematics(subject: Path, out: Path) -> tuple[int, str]:
    """``addb kinematics SUBJECT --out OUT --trial static`` in this process: (exit code, stderr)."""
    code, _, err = run_addb(["kinematics", str(subject), "--out", str(out), "--trial", "static"])
    return code, err


def test_a_mapping_to_a_marker_the_model_lacks_is_named(tmp_path: Path) -> None:
    """``R.ASIS: R_ASIS`` (the model calls it R.ASIS): the run goes on without R.ASIS and the
    warning names the entry and the file; an entry for a marker no trial has is not named
    (a lab-wide mapping lists markers of other subjects)."""
    subject = writable_copy(WALK, tmp_path / "walk")
    (subject / "markers.yaml").write_text("markers:\n  R.ASIS: R_ASIS\n  LASI: L.ASIS\n")
    code, err = _kinematics(subject, tmp_path / "out")
    assert code == 0, err
    assert "addb: warning: markers.yaml maps R.ASIS to R_ASIS, which is not a marker of the model: R.ASIS is left out of the fit" in err, err
    assert "LASI" not in err
    results = json.loads((tmp_path / "out" / "static" / "results.json").read_text())
    assert "R.ASIS" in results["markers_ignored"] and "R.ASIS" not in results["markers_used"]


def test_two_columns_for_one_model_marker_are_named(tmp_path: Path) -> None:
    """``R.ASIS: L.ASIS`` while the file also has L.ASIS: both columns stand for the model's
    L.ASIS; the fit takes the first (R.ASIS, as before) and the warning names the trial, both
    columns and the one left out."""
    subject = writable_copy(WALK, tmp_path / "walk")
    (subject / "markers.yaml").write_text("markers:\n  R.ASIS: L.ASIS\n")
    code, err = _kinematics(subject, tmp_path / "out")
    assert code == 0, err
    for trial in ("static", "walk"):  # scaling reads every trial
        assert (f"addb: warning: trial {trial}: the columns R.ASIS and L.ASIS both stand for the model marker L.ASIS "
                "(markers.yaml); the fit uses R.ASIS, the first, and leaves L.ASIS out") in err, err  # fmt: skip
