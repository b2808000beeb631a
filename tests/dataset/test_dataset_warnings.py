"""A dataset run names the subjects whose processing warned: their warnings were only in each
subject's ``process.log``, so a header that contradicts its own data went unseen in a batch.

The warning here is a real one of the readers: the walk's TRC header says 120 Hz while its
Time column steps 0.01 s (:func:`solver.io.trc.read_trc`)."""

from __future__ import annotations

import json
from html import escape as html_escape
from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.manifest import read_manifest
from tests.conftest import writable_copy
from tests.dataset.dataset_tree import SUBJECTS

pytestmark = pytest.mark.slow


def test_a_subjects_warnings_reach_the_summary_the_manifest_and_the_terminal(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tree = tmp_path / "in"
    walk = writable_copy(SUBJECTS / "rajagopal2016_walk", tree / "labA" / "walk")
    writable_copy(SUBJECTS / "rajagopal2016_walk", tree / "labA" / "quiet")
    trc = walk / "trials" / "walk" / "markers.trc"
    lines = trc.read_text().splitlines(keepends=True)
    assert lines[2].split()[:2] == ["100.0", "100.0"]  # DataRate, CameraRate
    lines[2] = lines[2].replace("100.0", "120.0", 2)
    trc.write_text("".join(lines))
    message = f"{trc}: DataRate says 120 Hz but the Time column steps 0.01 s (100 Hz); rate_hz keeps the header's value"
    out = tmp_path / "out"
    for run in ("first", "second (both up to date)"):
        assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 0, run
        err = capsys.readouterr().err
        assert f"\n1 subject(s) with warnings (each in full in {out}/SUBJECT/process.log):\n  labA/walk: {message}\n" in err, run
        assert "labA/quiet:" not in err, run
        subjects = {s["rel"]: s for s in json.loads((out / "dataset_summary.json").read_text())["subjects"]}
        assert subjects["labA/walk"]["warnings"] == [message] and subjects["labA/quiet"]["warnings"] == [], run
    assert read_manifest(out / "labA" / "walk")["warnings"] == [message]
    html = (out / "dataset_report.html").read_text()
    assert "<h2>Warnings (1 subject)</h2>" in html and f'<td class="l">labA/walk</td><td class="l">{html_escape(message)}</td>' in html
    assert f"warning: {message}" in (out / "labA" / "walk" / "process.log").read_text()
    # a whole one-subject run into the tree (its manifest stands for a dataset run's): the
    # warning is still printed, and kept in the manifest, so the next dataset run, which skips
    # the subject, still names it
    assert cli(["process", str(walk), "--out", str(out / "labA" / "walk")]) == 0
    err = capsys.readouterr().err
    assert err.count(f"addb: warning: {message}\n") == 1, err  # as the console script prints warnings, once
    manifest = read_manifest(out / "labA" / "walk")
    assert manifest["one_subject_run"] is True and manifest["warnings"] == [message]
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 0
    assert f"\n1 subject(s) with warnings (each in full in {out}/SUBJECT/process.log):\n  labA/walk: {message}\n" in capsys.readouterr().err
    subjects = {s["rel"]: s for s in json.loads((out / "dataset_summary.json").read_text())["subjects"]}
    assert subjects["labA/walk"]["status"] == "skipped" and subjects["labA/walk"]["warnings"] == [message]


def test_a_failed_subject_keeps_the_warnings_raised_before_it_failed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A subject whose markers warn (the same DataRate) and whose force file is cut in the
    middle of a row fails; the warning raised before the failure is in its record beside the
    error, and the terminal names it among the warnings as well as the failures."""
    tree = tmp_path / "in"
    broken = writable_copy(SUBJECTS / "rajagopal2016_walk", tree / "labB" / "broken")
    trc = broken / "trials" / "walk" / "markers.trc"
    lines = trc.read_text().splitlines(keepends=True)
    lines[2] = lines[2].replace("100.0", "120.0", 2)
    trc.write_text("".join(lines))
    mot = broken / "trials" / "walk" / "grf.mot"
    rows = mot.read_text().splitlines()
    cut = len(rows) // 2
    mot.write_text("\n".join(rows[:cut]) + "\n" + rows[cut][:20] + "\n")
    message = f"{trc}: DataRate says 120 Hz but the Time column steps 0.01 s (100 Hz); rate_hz keeps the header's value"
    out = tmp_path / "out"
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert f"\n1 subject(s) with warnings (each in full in {out}/SUBJECT/process.log):\n  labB/broken: {message}\n" in err
    assert "\n1 subject(s) failed:\n  labB/broken: " in err and "grf.mot" in err
    [entry] = json.loads((out / "dataset_summary.json").read_text())["subjects"]
    assert entry["status"] == "failed" and entry["warnings"] == [message] and entry["error"]["path"].endswith("grf.mot")
    assert read_manifest(out / "labB" / "broken")["warnings"] == [message]
