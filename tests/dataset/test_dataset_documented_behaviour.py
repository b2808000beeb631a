"""README, "Processing a dataset": the promises a dataset builder relies on that no other test
checks, on one small real tree run once (one worker): the Rajagopal walk with a reviewer's
flags (``labA``), the OpenCap subject, a copy of the walk whose two TRC headers contradict
their Time columns (two warnings), and the broken walk of :mod:`tests.dataset.dataset_tree`.

* a reviewed subject's output is what ``addb process SUBJECT --out ... --annotations
  SUBJECT/annotations.json`` writes, and a one-subject run without ``--annotations`` does
  not use the flags;
* each trial row of ``dataset_summary.json`` is the subject's own ``results.json``;
* a manifest keys on the SHA-256 of each input file, addb's version and code digest, the
  settings and the flags used; ``process.log`` tells the subject's progress;
* the end of the run: the first warning of each subject (the others counted), the table of
  failures with file and line, the counts and the dataset's totals;
* ``--force`` processes every subject again, the unchanged failed one too;
* the local cluster: one thread per worker, the memory divided among the workers.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
from html import escape as html_escape
from pathlib import Path
from typing import Any

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.manifest import MANIFEST_NAME, read_manifest
from tests.conftest import writable_copy
from tests.dataset.dataset_tree import (
    BROKEN,
    BROKEN_LINE,
    SUBJECTS,
    assert_same_results,
    build_tree,
    results,
)

pytestmark = pytest.mark.slow

WALK = "labA/rajagopal2016_walk"  # reviewed: walk frames 100-109 flagged as unmeasured
OPENCAP = "labB/opencap_uhlrich2023"  # no review record
WARNED = "labB/warned_walk"  # the walk, both TRC headers saying 120 Hz
GOOD = (WALK, OPENCAP, WARNED)
FLAGGED = list(range(100, 110))


def _rate_warning(trc: Path) -> str:
    """The reader's warning of a TRC whose DataRate says 120 Hz over a Time column at 100 Hz."""
    return f"{trc}: DataRate says 120 Hz but the Time column steps 0.01 s (100 Hz); rate_hz keeps the header's value"


def _say_120_hz(trc: Path) -> None:
    lines = trc.read_text().splitlines(keepends=True)
    assert lines[2].split()[:2] == ["100.0", "100.0"], lines[2]  # DataRate, CameraRate
    lines[2] = lines[2].replace("100.0", "120.0", 2)
    trc.write_text("".join(lines))


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The tree, its output tree, and what ``addb process TREE --out OUT --workers 1`` said."""
    from annotations import AnnotationStore

    base = tmp_path_factory.mktemp("documented")
    tree = build_tree(base / "in", {WALK: "rajagopal2016_walk", OPENCAP: "opencap_uhlrich2023"}, broken=True)
    warned = writable_copy(SUBJECTS / "rajagopal2016_walk", tree / WARNED)
    for trial in ("static", "walk"):
        _say_120_hz(warned / "trials" / trial / "markers.trc")
    with AnnotationStore.open(tree / WALK, reviewer="tester") as store:
        store.set_unmeasured("walk", range(100, 110))
    out = base / "out"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = cli(["process", str(tree), "--out", str(out), "--workers", "1"])
    summary = json.loads((out / "dataset_summary.json").read_text())
    return {"tree": tree, "out": out, "code": code, "stdout": stdout.getvalue(), "stderr": stderr.getvalue(),
            "summary": summary, "subjects": {s["rel"]: s for s in summary["subjects"]}}  # fmt: skip


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*")}


def test_a_reviewed_subject_is_written_as_a_one_subject_run_with_its_annotations_writes_it(run, tmp_path: Path) -> None:
    """README: ``DATASET_DIR/labA/s01`` is written to ``OUT/labA/s01/`` exactly as ``addb process
    DATASET_DIR/labA/s01 --out OUT/labA/s01 --annotations DATASET_DIR/labA/s01/annotations.json``
    would write it (plus manifest.json and process.log); a one-subject run uses flags only from
    ``--annotations``, so without it a reviewed subject's flags are not used."""
    subject, mine = run["tree"] / WALK, run["out"] / WALK
    record = subject / "annotations.json"
    assert record.is_file()
    theirs = tmp_path / "with"
    assert cli(["process", str(subject), "--out", str(theirs), "--annotations", str(record)]) == 0
    assert assert_same_results(mine, theirs) == 9 + 3  # walk (every metric), static (kinematic ones)
    assert results(mine)["walk"]["unobserved_frames"] == results(theirs)["walk"]["unobserved_frames"] == FLAGGED
    assert _files(mine) - _files(theirs) == {MANIFEST_NAME, "process.log"} and _files(theirs) <= _files(mine)
    plain = tmp_path / "plain"
    assert cli(["process", str(subject), "--out", str(plain)]) == 0
    unobserved = results(plain)["walk"]["unobserved_frames"]
    assert unobserved != FLAGGED and not set(FLAGGED) <= set(unobserved), unobserved


def test_each_trial_row_of_the_summary_is_the_subjects_own_results(run) -> None:
    """README, Summary: per subject and trial the status, frames, frames with measured force,
    duration, marker RMS, residuals in N, N·m, BW and BW·h, Hicks verdicts, fitted mass and
    stage times; checked against each trial's results.json in the subject's output folder."""
    same = ("marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm", "linear_residual_rms_BW",
            "angular_residual_rms_BWh", "hicks_linear_ok", "hicks_angular_ok", "mass_kg", "stage_seconds")  # fmt: skip
    checked = 0
    for rel in GOOD:
        entry = run["subjects"][rel]
        assert entry["status"] == "ok", rel
        rows = {r["trial"]: r for r in entry["trials"]}
        own = results(run["out"] / rel)
        assert sorted(rows) == sorted(own) and len(own) == 2, (rel, sorted(rows))
        for trial, r in own.items():
            row = rows[trial]
            dynamics = "n_observed_frames" in r
            assert row["status"] == ("ok" if dynamics else "kinematics_only"), (rel, trial)
            assert row["frames"] == r["n_frames"] and row["measured_frames"] == r.get("n_observed_frames", 0), (rel, trial)
            assert row["duration_s"] == pytest.approx(r["n_frames"] / r["rate_hz"], rel=1e-12), (rel, trial)
            for name in same:
                assert row[name] == r.get(name), (rel, trial, name)
            if dynamics:
                assert row["linear_residual_rms_BW"] is not None and row["hicks_linear_ok"] in (True, False)
                assert entry["fitted_mass_kg"] == pytest.approx(r["mass_kg"], rel=1e-12), rel
            checked += 1
    assert checked == 6


def test_a_manifest_keys_on_the_sha256_of_each_input_file_the_code_the_settings_and_the_flags_used(run) -> None:
    """README, Resume: a rerun skips a subject whose manifest still matches: SHA-256 of every
    input file, the addb version and a digest of the solver's source code, the settings, and
    the review record whose flags were used (``<subject>/annotations.json``)."""
    from addb_viewer.review_masks import review_digest
    from solver.provenance import addb_version, code_digest

    for rel, name in ((WALK, "rajagopal2016_walk"), (OPENCAP, "opencap_uhlrich2023")):
        key = read_manifest(run["out"] / rel)["key"]
        # the subject's files as published (the review record the reviewer added is no input)
        files = sorted(p for p in (SUBJECTS / name).rglob("*") if p.is_file())
        expected = {p.relative_to(SUBJECTS / name).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in files}
        assert key["inputs"] == expected and len(expected) >= 5, rel
        assert key["addb_version"] == addb_version() and key["code"] == code_digest(), rel
        assert key["settings"] == {"addb_process": "default"}, rel
    flags = read_manifest(run["out"] / WALK)["key"]["annotations"]
    assert flags is not None and flags == review_digest(str(run["tree"] / WALK), str(run["out"] / WALK))
    assert read_manifest(run["out"] / OPENCAP)["key"]["annotations"] is None


def test_process_log_tells_the_subjects_progress_and_the_flags_it_used(run) -> None:
    """README, Output tree: ``process.log`` holds the subject's progress (and its warnings, and
    the error with its traceback when it failed): where it went, the reviewer's flags it used,
    and how it ended with its frames."""
    tree, out = run["tree"], run["out"]
    for rel in GOOD:
        log = (out / rel / "process.log").read_text()
        frames = sum(r["frames"] for r in run["subjects"][rel]["trials"])
        assert f"subject {rel}: {(tree / rel).resolve()} -> {(out / rel).resolve()} (pid " in log.splitlines()[0], (rel, log)
        assert f"done: ok, {frames} frames in " in log, (rel, log)
        assert ("reviewer flags used for walk" in log) is (rel == WALK), (rel, log)
        assert "Traceback" not in log, rel


def test_a_subject_with_several_warnings_is_named_by_its_first_at_the_end_and_all_in_the_summary(run) -> None:
    """README, Output tree: the subjects that warned are named at the end of the run (the first
    warning of each) and in the report's Warnings section (all of each subject's, also in
    ``dataset_summary.json``); here two, one per TRC file of the subject."""
    warned = run["tree"] / WARNED
    expected = {_rate_warning(warned / "trials" / t / "markers.trc") for t in ("static", "walk")}
    warnings = run["subjects"][WARNED]["warnings"]
    assert len(warnings) == 2 and set(warnings) == expected, warnings
    assert f"\n  {WARNED}: {warnings[0]} (and 1 more)\n" in run["stderr"], run["stderr"]
    assert warnings[1] not in run["stderr"]
    assert read_manifest(run["out"] / WARNED)["warnings"] == warnings
    named = [rel for rel, s in run["subjects"].items() if s.get("warnings")]
    assert f"\n{len(named)} subject(s) with warnings (each in full in {run['out']}/SUBJECT/process.log):\n" in run["stderr"]
    assert run["subjects"][OPENCAP]["warnings"] == []
    html = (run["out"] / "dataset_report.html").read_text()
    cell = "<br>".join(html_escape(m) for m in warnings)  # the subject's row lists them all
    assert f'<h2>Warnings ({len(named)} subject' in html
    assert f'<td class="l">{WARNED}</td><td class="l">{cell}</td>' in html


def test_the_run_ends_with_a_table_of_failures_naming_file_and_line_and_exit_code_1(run) -> None:
    """README, Failures: a subject whose data fails is recorded once (file, line, as the readers
    say it) and the batch goes on; the command ends with a table of failures and exit code 1."""
    assert run["code"] == 1
    entry = run["subjects"][BROKEN]
    error = entry["error"]
    assert entry["status"] == "failed" and entry["attempts"] == 1  # a data failure is not retried
    path = run["tree"] / BROKEN / "trials" / "walk" / "markers.trc"
    assert Path(error["path"]).resolve() == path.resolve() and error["line"] == BROKEN_LINE, error
    line = f"  {BROKEN}: TrcFormatError: {error['message']} ({error['path']}:{BROKEN_LINE})\n"
    assert f"\n1 subject(s) failed:\n{line}" in run["stderr"], run["stderr"]
    assert all(run["subjects"][rel]["status"] == "ok" and run["subjects"][rel]["attempts"] == 1 for rel in GOOD)


def test_the_last_line_counts_the_subjects_apart_and_gives_the_datasets_totals(run) -> None:
    """README, Counts: the progress line and the last line count the subjects processed now, up
    to date and failed apart; the frames are those of the subjects processed now, then the
    dataset's totals (trials, frames, hours, hours with measured force, as in the summary)."""
    t = run["summary"]["totals"]
    own = [r for rel in GOOD for r in results(run["out"] / rel).values()]
    assert t["trials"] == len(own) == 6 and t["frames"] == sum(r["n_frames"] for r in own)
    assert f"3 processed, 1 failed, 0 up to date ({t['frames']} frames processed)" in run["stderr"], run["stderr"]
    (last,) = [x for x in run["stdout"].splitlines() if x.startswith("4 subjects: ")]
    assert last.startswith("4 subjects: 3 processed, 0 up to date, 1 failed in "), last
    assert last.endswith(f" s; the dataset: 6 trials, {t['frames']} frames ({t['hours']:.4f} h, "
                         f"{t['hours_with_measured_force']:.4f} h with measured force)"), last  # fmt: skip
    assert t["hours"] == pytest.approx(sum(r["n_frames"] / r["rate_hz"] for r in own) / 3600, rel=1e-9)


def _table_status(stdout: str, rel: str) -> str:
    """The status column of ``rel``'s row in the run's table."""
    (row,) = [x for x in stdout.splitlines() if x.startswith(f"{rel}  ")]
    return row[len(rel):].strip().split("  ")[0]


def test_force_processes_every_subject_again_the_unchanged_failed_one_too(run, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """README, Resume: a rerun skips a subject whose manifest still matches; a subject whose
    unchanged data failed is reported again without running; ``--force`` reprocesses
    everything (on a copy of the module's output tree)."""
    out = tmp_path / "out"
    shutil.copytree(run["out"], out, symlinks=True)
    tree = run["tree"]
    before = {rel: read_manifest(out / rel) for rel in [*GOOD, BROKEN]}
    capsys.readouterr()
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
    printed = capsys.readouterr()
    summary = {s["rel"]: s for s in json.loads((out / "dataset_summary.json").read_text())["subjects"]}
    assert {rel: s["status"] for rel, s in summary.items()} == {**dict.fromkeys(GOOD, "skipped"), BROKEN: "failed"}
    assert all(_table_status(printed.out, rel) == "skipped (ok)" for rel in GOOD), printed.out
    assert _table_status(printed.out, BROKEN) == "failed (unchanged)", printed.out
    assert "\n4 subjects: 0 processed, 3 up to date, 1 failed in " in printed.out, printed.out
    assert all(read_manifest(out / rel) == before[rel] for rel in before)
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1", "--force"]) == 1
    printed = capsys.readouterr()
    summary = {s["rel"]: s for s in json.loads((out / "dataset_summary.json").read_text())["subjects"]}
    assert {rel: s["status"] for rel, s in summary.items()} == {**dict.fromkeys(GOOD, "ok"), BROKEN: "failed"}
    assert "unchanged" not in summary[BROKEN] and all(s["attempts"] == 1 for s in summary.values())  # all ran now
    assert "\n4 subjects: 3 processed, 0 up to date, 1 failed in " in printed.out, printed.out
    assert all(_table_status(printed.out, rel) == "ok" for rel in GOOD) and _table_status(printed.out, BROKEN) == "failed"
    for rel in [*GOOD, BROKEN]:  # each manifest written again, with the same key
        now = read_manifest(out / rel)
        assert now["key"] == before[rel]["key"] and now["seconds"] != before[rel]["seconds"], rel
    assert results(out / WALK)["walk"]["unobserved_frames"] == FLAGGED  # still with the reviewer's flags


def _workers(options: Any) -> list[dict[str, Any]]:
    """What the scheduler of :func:`solver.dataset.runner._local_cluster` knows of each worker."""
    from distributed import Client

    from solver.dataset.runner import _local_cluster

    with _local_cluster(options) as cluster, Client(cluster) as client:
        return list(client.scheduler_info()["workers"].values())


def test_the_local_cluster_has_a_worker_per_core_with_one_thread_and_its_share_of_the_memory() -> None:
    """README, Cores: the local cluster has ``--workers`` processes (default: the cores) with
    one thread each and a memory limit each (``--memory-limit``, default the RAM divided among
    them)."""
    from distributed.system import MEMORY_LIMIT

    from solver.dataset.runner import DatasetOptions

    cores = os.cpu_count() or 1
    workers = _workers(DatasetOptions())
    assert [w["nthreads"] for w in workers] == [1] * cores, workers
    assert all(w["memory_limit"] == pytest.approx(MEMORY_LIMIT / cores, rel=1e-9) for w in workers), (MEMORY_LIMIT, workers)
    (worker,) = _workers(DatasetOptions(workers=1, memory_limit="1GB"))
    assert worker["nthreads"] == 1 and worker["memory_limit"] == 10**9


def test_the_default_memory_limit_divides_the_ram_among_the_workers_asked_for() -> None:
    """README, Cores: a memory limit each (``--memory-limit``, default the RAM divided among
    them), with a ``--workers`` other than the cores (``addb process --help``: "default: RAM /
    workers")."""
    from distributed.system import MEMORY_LIMIT

    from solver.dataset.runner import DatasetOptions

    n = 1 if (os.cpu_count() or 1) > 1 else 2
    workers = _workers(DatasetOptions(workers=n))
    assert len(workers) == n
    assert all(w["memory_limit"] == pytest.approx(MEMORY_LIMIT / n, rel=1e-9) for w in workers), (MEMORY_LIMIT, workers)


def test_the_local_cluster_never_pauses_a_worker_at_its_memory_threshold() -> None:
    """Dataset audit 2026-12-02, finding 2: a worker paused at 80 % of its memory limit runs
    nothing more, and one that stayed below the kill threshold (95 %) hung the run without a
    word. The local cluster's workers do not pause (Dask's ``distributed.worker.memory.pause``
    off in each worker process); they still are killed at their limit (terminate 0.95)."""
    from distributed import Client

    from solver.dataset.runner import DatasetOptions, _local_cluster

    with _local_cluster(DatasetOptions(workers=1, memory_limit="1GB")) as cluster, Client(cluster) as client:
        fractions = client.run(lambda dask_worker: (dask_worker.memory_manager.memory_pause_fraction,
                                                    dask_worker.memory_manager.memory_limit))  # fmt: skip
    ((pause, limit),) = fractions.values()
    assert pause is False and limit == 10**9, fractions
