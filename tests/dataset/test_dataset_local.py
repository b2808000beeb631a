"""``addb process DATASET_DIR`` on a real two-worker LocalCluster: the three shared subjects
nested under two lab folders, a broken subject and a kinematics-only one. The good
subjects' results equal a serial one-subject run's; the broken one is listed with its
file and line and makes the exit code 1; the summary and the report name every subject;
a second run skips everything; editing one input file reprocesses that subject only."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.manifest import MANIFEST_NAME, read_manifest
from solver.dataset.summary import CONTACT_CLASSES
from solver.results import load_processed, processed_trials
from tests.dataset.dataset_tree import (
    BROKEN,
    BROKEN_LINE,
    COMPARED,
    FULL_TREE,
    KINEMATICS_ONLY,
    SUBJECTS,
    assert_same_results,
    build_tree,
    no_work_folders,
    results,
)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_tree(tmp_path_factory.mktemp("dataset") / "in", FULL_TREE, broken=True, kinematics_only=True)


@pytest.fixture(scope="module")
def first_run(tree: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, dict]:
    out = tmp_path_factory.mktemp("dataset_out") / "out"
    code = cli(["process", str(tree), "--out", str(out), "--workers", "2"])
    return out, code, json.loads((out / "dataset_summary.json").read_text())


@pytest.fixture(scope="module")
def serial(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One-subject runs of the three shared subjects (the command as it was before)."""
    base = tmp_path_factory.mktemp("serial")
    outs = {}
    for rel, name in FULL_TREE.items():
        outs[rel] = base / name
        assert cli(["process", str(SUBJECTS / name), "--out", str(outs[rel])]) == 0
    return outs


def test_good_subjects_equal_a_serial_one_subject_run(first_run, serial) -> None:
    out, _, _ = first_run
    compared = sum(assert_same_results(out / rel, serial[rel]) for rel in FULL_TREE)
    # walk, run, DJ1 and walking1 with dynamics (every metric), the two statics (3 kinematic ones)
    assert compared == 4 * len(COMPARED) + 2 * 3
    for rel in FULL_TREE:  # the one-subject layout, plus the manifest and the log
        mine = {p.relative_to(out / rel).as_posix() for p in (out / rel).rglob("*")}
        theirs = {p.relative_to(serial[rel]).as_posix() for p in serial[rel].rglob("*")}
        assert mine - theirs == {MANIFEST_NAME, "process.log"}, rel
        assert theirs <= mine
        # written in a work folder and renamed into place: each trial finds its scaled model
        # in the subject's output folder (the review app, the diagnosis and the benchmark load it)
        for trial in processed_trials(out / rel):
            model = Path(load_processed(out / rel, trial).model_path)
            assert model.is_file() and model.parent == out / rel, (rel, trial, model)


def test_broken_subject_is_listed_with_file_and_line_and_fails_the_run(first_run) -> None:
    out, code, summary = first_run
    assert code == 1
    entry = next(s for s in summary["subjects"] if s["rel"] == BROKEN)
    assert entry["status"] == "failed" and entry["error"]["type"] == "TrcFormatError"
    assert entry["error"]["path"].endswith(f"{BROKEN}/trials/walk/markers.trc")
    assert entry["error"]["line"] == BROKEN_LINE
    log = (out / BROKEN / "process.log").read_text()
    assert f"markers.trc:{BROKEN_LINE}" in log and "Traceback" in log
    others = [s for s in summary["subjects"] if s["rel"] != BROKEN]
    assert all(s["status"] in ("ok", "kinematics_only") for s in others)


def test_summary_and_report_name_every_subject_in_the_papers_terms(first_run) -> None:
    out, _, summary = first_run
    rels = sorted([*FULL_TREE, BROKEN, KINEMATICS_ONLY])
    assert sorted(s["rel"] for s in summary["subjects"]) == rels
    kin = next(s for s in summary["subjects"] if s["rel"] == KINEMATICS_ONLY)
    assert kin["status"] == "kinematics_only" and all(r["measured_frames"] == 0 for r in kin["trials"])
    t = summary["totals"]
    assert t["subjects"] == {"ok": 3, "failed": 1, "kinematics_only": 1}
    # totals add up from the per-trial results.json files of the output tree
    frames = sum(r["n_frames"] for rel in [*FULL_TREE, KINEMATICS_ONLY] for r in results(out / rel).values())
    measured = sum(r.get("n_observed_frames", 0) for rel in FULL_TREE for r in results(out / rel).values())
    assert t["frames"] == frames and t["measured_frames"] == measured
    rate = 100.0  # every trial here is solved at 100 Hz
    assert t["hours"] == pytest.approx(frames / rate / 3600, rel=1e-6)
    assert t["hours_with_measured_force"] == pytest.approx(measured / rate / 3600, rel=1e-6)
    assert sum(t["contact_share"][c] for c in CONTACT_CLASSES) == pytest.approx(1.0)
    assert t["contact_share"]["flight"] > 0.0  # the run has flight phases
    assert sum(t["residual_force_hist_BW"]) == measured == sum(t["residual_moment_hist_BWh"])
    html = (out / "dataset_report.html").read_text()
    assert all(rel in html for rel in rels) and "<svg" in html and f"markers.trc:{BROKEN_LINE}" in html
    assert not no_work_folders(out)


def test_second_run_skips_everything_and_an_edited_input_reprocesses_one_subject(first_run, tree) -> None:
    out, _, _ = first_run
    before = {rel: read_manifest(out / rel) for rel in [*FULL_TREE, KINEMATICS_ONLY]}
    t0 = time.perf_counter()
    code = cli(["process", str(tree), "--out", str(out), "--workers", "2"])
    seconds = time.perf_counter() - t0
    summary = json.loads((out / "dataset_summary.json").read_text())
    status = {s["rel"]: s["status"] for s in summary["subjects"]}
    assert code == 1  # the broken subject is still broken (reported, not run again)
    assert status == {**dict.fromkeys([*FULL_TREE, KINEMATICS_ONLY], "skipped"), BROKEN: "failed"}
    assert next(s for s in summary["subjects"] if s["rel"] == BROKEN)["unchanged"] is True
    assert seconds < 10.0, seconds
    assert summary["totals"]["frames"] > 0  # skipped subjects still count in the totals
    # edit one input file of the kinematics-only subject: only that subject runs again
    meta = tree / KINEMATICS_ONLY / "_subject.json"
    meta.write_text(meta.read_text() + "\n")
    cli(["process", str(tree), "--out", str(out), "--workers", "2"])
    summary = json.loads((out / "dataset_summary.json").read_text())
    status = {s["rel"]: s["status"] for s in summary["subjects"]}
    assert status[KINEMATICS_ONLY] == "kinematics_only"
    assert all(status[rel] == "skipped" for rel in FULL_TREE)
    for rel in FULL_TREE:
        assert read_manifest(out / rel) == before[rel]
    assert read_manifest(out / KINEMATICS_ONLY)["key"] != before[KINEMATICS_ONLY]["key"]


def test_a_reviewers_flags_reprocess_their_subject_and_replace_its_proposals(first_run, tree) -> None:
    """Flags saved by a reviewer (still in the record's journal) change the manifest key of
    that subject only, and the rerun leaves out exactly the flagged frames."""
    from annotations import AnnotationStore

    out, _, _ = first_run
    walk = "labA/rajagopal2016_walk"
    before = json.loads((out / walk / "walk" / "results.json").read_text())
    with AnnotationStore.open(tree / walk, reviewer="tester") as store:
        store.set_unmeasured("walk", range(100, 110))
    cli(["process", str(tree), "--out", str(out), "--workers", "2"])
    summary = json.loads((out / "dataset_summary.json").read_text())
    status = {s["rel"]: s["status"] for s in summary["subjects"]}
    assert status[walk] == "ok" and status["labA/rajagopal2016_run"] == "skipped"
    after = json.loads((out / walk / "walk" / "results.json").read_text())
    assert after["unobserved_frames"] == list(range(100, 110)) != before["unobserved_frames"]
    assert after["n_observed_frames"] == after["n_frames"] - 10
    assert read_manifest(out / walk)["key"]["annotations"] is not None


def _worker_environment() -> dict[str, str | None]:
    import os

    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")}


def test_local_workers_keep_glibcs_adaptive_mmap_threshold() -> None:
    """Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_`` in its workers, which turns off glibc's
    adaptive mmap threshold (each subject took 23-39 % longer in such a worker,
    solver/dataset/runner.py); the local cluster's workers start without it and keep Dask's
    one-thread setting for the numeric libraries."""
    from distributed import Client

    from solver.dataset.runner import DatasetOptions, _local_cluster

    with _local_cluster(DatasetOptions(workers=1)) as cluster, Client(cluster) as client:
        (env,) = client.run(_worker_environment).values()
    assert env == {"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1"}


def test_info_summarizes_the_output_tree_and_each_subjects_output_folder(first_run, capsys: pytest.CaptureFixture[str]) -> None:
    """``addb info OUT`` said "_subject.json is missing" of the output tree, and "is an output
    folder of addb ... with this folder given as --out" of a subject's output folder (info has
    no --out). The tree now reads as its summary's totals, each subject's folder as its trials'
    metrics (from their results.json), a failed subject as its error."""
    out = first_run[0]
    capsys.readouterr()
    assert cli(["info", str(out)]) == 0
    text = capsys.readouterr().out
    t = json.loads((out / "dataset_summary.json").read_text())["totals"]  # the module's last run's
    assert f"{out}: dataset output\n" in text
    (subjects,) = [line for line in text.splitlines() if line.startswith("  subjects: ")]
    assert subjects.endswith(f" ({t['n_subjects']} in all)") and t["n_subjects"] == 5
    assert all(f"{n} {status}" in subjects for status, n in t["subjects"].items()) and "failed" in subjects
    assert f"frames (with measured force): {t['frames']} ({t['measured_frames']})" in text
    assert f"report: {out / 'dataset_report.html'}" in text
    for rel in [*FULL_TREE, KINEMATICS_ONLY]:
        assert cli(["info", str(out / rel)]) == 0
        text = capsys.readouterr().out
        assert "dataset run: " in text and "Traceback" not in text
        trials = results(out / rel)
        assert text.count("\n  trial ") == len(trials) > 0, text
        for name, r in trials.items():
            head = f"  trial {name}: {r['n_frames']} frames"
            if "n_observed_frames" in r:
                head += f" ({r['n_observed_frames']} with measured force)"
            assert f"{head}, marker RMS {r['marker_rms_m'] * 100:.2f} cm" in text, (rel, name, text)
            if "n_observed_frames" in r:
                assert f"residual force {r['linear_residual_rms_N']:.1f} N RMS ({r['linear_residual_rms_BW']:.3f} BW)" in text
            else:
                assert f"{head}, marker RMS {r['marker_rms_m'] * 100:.2f} cm (kinematics only)" in text
    # one trial's results.json reads as its line of the folder's summary
    rel = next(iter(FULL_TREE))
    name = next(n for n, r in results(out / rel).items() if "n_observed_frames" in r)
    assert cli(["info", str(out / rel)]) == 0
    lines = capsys.readouterr().out.splitlines()
    at = lines.index(next(x for x in lines if x.startswith(f"  trial {name}: ")))
    assert cli(["info", str(out / rel / name / "results.json")]) == 0
    assert capsys.readouterr().out.splitlines()[1:] == lines[at:at + 2]
    assert cli(["info", str(out / BROKEN)]) == 0
    text = capsys.readouterr().out
    assert "dataset run: failed (TrcFormatError: " in text and "no processed trial" in text
    # a trial's output folder reads as its results.json; a lab's folder as its subjects' totals
    # (both said "_subject.json is missing")
    assert cli(["info", str(out / rel / name)]) == 0
    assert capsys.readouterr().out.splitlines()[1:] == lines[at:at + 2]
    assert cli(["info", str(out / "labB")]) == 0
    text = capsys.readouterr().out
    below = sorted(r for r in [*FULL_TREE, BROKEN, KINEMATICS_ONLY] if r.startswith("labB/"))
    assert text.startswith(f"{out / 'labB'}: part of the dataset output tree {out}\n  {len(below)} of the run's 5 subjects: ")
    rows = [r for rel_ in below if rel_ != BROKEN for r in results(out / rel_).values()]
    measured = sum(r.get("n_observed_frames", 0) for r in rows)
    assert f"  frames (with measured force): {sum(r['n_frames'] for r in rows)} ({measured})" in text, text
    assert "1 failed" in text and f"addb info {out} summarizes the whole run" in text
    # the whole tree's "by source" lines (the paper's per-dataset table) equal each source's folder
    assert cli(["info", str(out)]) == 0
    whole = capsys.readouterr().out
    for lab in ("labA", "labB"):
        assert cli(["info", str(out / lab)]) == 0
        part = dict(line.strip().split(": ", 1) for line in capsys.readouterr().out.splitlines()[2:-1])
        (line,) = [x for x in whole.splitlines() if x.startswith(f"    {lab}: ")]
        subjects, trials, frames, hours, hours_measured, clinical, rms = line.split(": ", 1)[1].split("; ")
        assert subjects + f" ({len([r for r in [*FULL_TREE, BROKEN, KINEMATICS_ONLY] if r.startswith(lab)])} in all)" == part["subjects"]
        assert (trials, frames, hours, hours_measured) == (part["trials (with dynamics)"], part["frames (with measured force)"],
                                                           part["hours"], part["hours with measured force"])  # fmt: skip
        assert clinical == part["clinical-grade frames (both Hicks thresholds met)"] and rms == part["marker RMS per trial, mean / median (cm)"].split(" / ")[1]
    page = (out / "dataset_report.html").read_text()
    assert "By source (the first folder of each subject" in page and page.count('<td class="l">labA</td>') == 1


def test_a_subjects_output_folder_given_as_its_subject_names_its_subject_folder(first_run, tree: Path, capsys) -> None:
    """``addb diagnose OUT/labA/s01`` (a dataset run's output, where the subject folder goes)
    said "expected the subject folder ..., with this folder given as --out" without naming it;
    the output tree's summary records the dataset folder, so the message names the subject
    folder, and record/export's suggested command has it filled in."""
    out = first_run[0]
    rel = next(iter(FULL_TREE))
    capsys.readouterr()
    assert cli(["diagnose", str(out / rel), "--trial", "walk"]) == 1
    assert f"(the one with _subject.json): here probably {(tree / rel).resolve()}, with this folder given as --out" in capsys.readouterr().err
    assert cli(["record", str(out / rel), "--trial", "walk", "-o", str(out.parent / "walk.rrd")]) == 1
    err = capsys.readouterr().err
    assert f"given as --out: addb record {(tree / rel).resolve()} --trial walk -o {out.parent / 'walk.rrd'} --out {out / rel}" in err, err
    assert not (out.parent / "walk.rrd").exists()


def test_info_of_the_dataset_folder_lists_its_subjects_and_its_output_tree(
    first_run, tree: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb info DATASET_DIR`` was refused ("is a dataset folder ..."). It now lists every
    subject the dataset search finds as ``addb info SUBJECT_DIR`` reads it (mass, height,
    trials, frames), the broken one with its file and line, the totals in the paper's terms,
    and the state of an output tree: each subject by what its folder holds (a subject skipped
    as up to date counts by the output it kept), and a subject added since the run."""
    import shutil

    from solver.dataset.inventory import dataset_inventory, inventory_text
    from solver.io.summary import summarize

    out = first_run[0]
    capsys.readouterr()
    assert cli(["info", str(tree)]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"{tree}: dataset folder\n")
    frames = seconds = 0.0
    for rel in [*FULL_TREE, KINEMATICS_ONLY]:
        one = summarize(tree / rel)  # what addb info SUBJECT_DIR reads
        n = sum(t["frames"] for t in one["trials"])
        frames += n
        seconds += sum(t["frames"] / t["rate_hz"] for t in one["trials"])
        line = f"  {rel}: {one['mass_kg']:.4g} kg, {one['height_m']:.4g} m; {len(one['trials'])} trials ("
        assert line in text and f"{n:,} frames" in text.split(line)[1].split("\n")[0], (rel, text)
    assert f"  {KINEMATICS_ONLY}: " in text and "(dynamics disabled)" in text.split(f"  {KINEMATICS_ONLY}: ")[1].split("\n")[0]
    assert f"  {BROKEN}: cannot be read: TrcFormatError ({tree / BROKEN / 'trials' / 'walk' / 'markers.trc'}:{BROKEN_LINE})" in text
    assert "  5 subjects, 1 of them unreadable; " in text and f", {int(frames):,} frames, {seconds / 3600:.4f} hours (" in text
    assert f"output tree: none at {tree / 'addb_out'}; addb process DATASET_DIR --out OUT (or addb view DATASET_DIR)" in text
    assert "and addb info DATASET_DIR --out OUT names the subjects a new run processes again)" in text
    # with the module's output tree, and a subject added since its run
    added = tree / "labC" / "new"
    added.mkdir(parents=True)
    try:
        (added / "_subject.json").write_text('{"massKg": 70}')
        seen: list[tuple[str, float]] = []
        d = dataset_inventory(tree, out, progress=lambda m, f: seen.append((m, f)))
        assert [m for m, _ in seen] == [f"reading {s['rel']}" for s in d["subjects"]] + ["read 6 subjects"]
        assert [f for _, f in seen] == [k / 6 for k in range(6)] + [1.0]
        assert d["totals"]["subjects"] == 6 and d["totals"]["unreadable"] == 2 and d["totals"]["frames"] == int(frames)
        assert d["output"]["counts"] == {"processed": 3, "kinematics only": 1, "failed": 1, "cancelled": 0}
        assert d["output"]["new"] == ["labC/new"]
        text = inventory_text(d)
        assert f"  output tree: {out} (a run finished " in text and ": 3 processed, 1 kinematics only, 1 failed; addb info" in text
        assert "    not in that run: labC/new (added since; a new run processes it)" in text
    finally:
        shutil.rmtree(tree / "labC")


def _info(capsys: pytest.CaptureFixture[str], tree: Path, out: Path, *options: str) -> str:
    """What ``addb info DATASET_DIR --out OUT [options]`` prints (it must exit 0)."""
    capsys.readouterr()
    assert cli(["info", str(tree), "--out", str(out), *options]) == 0
    return capsys.readouterr().out


def _statuses(out: Path) -> dict[str, str]:
    """Each subject's status in the last dataset run's summary of ``out``."""
    return {s["rel"]: s["status"] for s in json.loads((out / "dataset_summary.json").read_text())["subjects"]}


def test_info_of_the_dataset_folder_names_the_subjects_a_new_run_processes_again(
    first_run, tree: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb info DATASET_DIR --out OUT`` could not say which subjects changed since the run
    (a dataset builder learnt it only by running). It compares each subject's files now with
    its manifest: after a run every subject is up to date (the broken one too: the same
    inputs are not run again); after an edit of one subject's ``_subject.json`` and a file
    added to another, it names those two and what changed, and a run then processes exactly
    those two again; a subject whose output a one-subject run replaced is named as such."""
    out = first_run[0]
    everyone = [*FULL_TREE, BROKEN, KINEMATICS_ONLY]

    def info(*options: str) -> str:
        return _info(capsys, tree, out, *options)

    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1  # current (earlier tests may edit)
    text = info()
    assert f"    up to date: {len(everyone)} subjects (a new run skips them)" in text and "changed since" not in text, text
    # a run with another fit processes every subject again (the run above used the default)
    text = info("--fit", "band")
    assert f"    changed since that run: {len(everyone)} subjects (a new run processes them again)\n" in text, text
    assert text.count(": the settings changed (fit: default then, band now)\n") == len(everyone), text
    edited, added = list(FULL_TREE)[:2]
    subject_json = tree / edited / "_subject.json"
    original = subject_json.read_bytes()
    try:
        subject_json.write_bytes(original + b"\n")
        (tree / added / "notes.txt").write_text("session notes")
        text = info()
        assert "    changed since that run: 2 subjects (a new run processes them again)\n" in text, text
        lines = sorted([f"      {edited}: _subject.json changed\n", f"      {added}: notes.txt added\n"])  # the search's order
        assert "".join(lines) in text, text
        assert f"    up to date: {len(everyone) - 2} subjects (a new run skips them)" in text
        assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
        status = _statuses(out)
        assert {rel for rel, st in status.items() if st != "skipped"} == {edited, added, BROKEN}, status
        assert status[BROKEN] == "failed" and status[edited] == status[added] == "ok"
    finally:
        subject_json.write_bytes(original)
        (tree / added / "notes.txt").unlink(missing_ok=True)
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1  # as the module's tree was
    assert f"    up to date: {len(everyone)} subjects" in info()
    # a kinematics run into the tree writes no manifest: the next run processes the subject again
    assert cli(["kinematics", str(tree / edited), "--out", str(out / edited)]) == 0
    text = info()
    assert "    changed since that run: 1 subject (a new run processes it again)\n" in text, text
    assert (f"      {edited}: its output holds no record of the inputs it was made from (written by addb kinematics, "
            "or by a one-subject addb process with --trial, or with a review file not the subject's own)\n") in text, text
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
    assert f"    up to date: {len(everyone)} subjects" in info()
    part = out / edited.split("/")[0]  # a folder of the tree: addb info prints its totals
    for other, option in ((tree / edited, ["--out", str(out)]), (out, ["--out", str(out)]), (part, ["--fit", "band"])):
        assert cli(["info", str(other), *option]) == 1  # --out and --fit belong to a dataset folder
        message = f"DatasetError ({other}): is not a dataset folder; {option[0]} of addb info applies only to a dataset folder"
        assert message in capsys.readouterr().err
    assert cli(["info", str(tree / edited), "--out", str(out), "--fit", "band"]) == 1
    assert "is not a dataset folder; --out and --fit of addb info apply only to a dataset folder" in capsys.readouterr().err


def test_a_whole_one_subject_run_into_the_tree_leaves_the_manifest_a_dataset_run_would(
    first_run, tree: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb process labA/s01 --out OUT/labA/s01`` left no manifest, so the next dataset run
    processed the subject again though nothing had changed. A whole run now writes the
    manifest a dataset run writes: the same key (files, code, settings, no review flags) and
    the same summary rows, so ``addb info`` calls it up to date and the dataset run skips it.
    Its ``--fit`` is in the key (another fit is "the settings changed"); so is the absence of
    the reviewer's flags it did not apply (a subject with flags is processed again); given
    the subject's own review record (``--annotations``, the record the dataset run reads),
    its key holds that record's flags as the dataset run's does, and the dataset run skips
    it. A ``--trial`` run, which merges into the folder, and a run with another review file
    remove the manifest: the dataset run processes the subject again."""
    from annotations import AnnotationStore

    out = first_run[0]
    rel = "labB/opencap_uhlrich2023"  # no review record
    everyone = [*FULL_TREE, BROKEN, KINEMATICS_ONLY]

    def info(*options: str) -> str:
        return _info(capsys, tree, out, *options)

    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1  # current (earlier tests may edit)
    by_dataset = read_manifest(out / rel)
    assert cli(["process", str(tree / rel), "--out", str(out / rel)]) == 0
    mine = read_manifest(out / rel)
    assert mine is not None and mine["one_subject_run"] is True and "one_subject_run" not in by_dataset
    assert mine["key"] == by_dataset["key"] and mine["rel"] == rel and mine["status"] == by_dataset["status"] == "ok"
    assert mine["fitted_mass_kg"] == pytest.approx(by_dataset["fitted_mass_kg"], rel=1e-9)
    assert [r["trial"] for r in mine["trials"]] == [r["trial"] for r in by_dataset["trials"]]
    for a, b in zip(mine["trials"], by_dataset["trials"], strict=True):
        for name in ("frames", "measured_frames", "marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm"):
            assert (a[name] is None and b[name] is None) or a[name] == pytest.approx(b[name], rel=1e-9, abs=1e-12), (a["trial"], name)
    assert f"    up to date: {len(everyone)} subjects (a new run skips them)" in info()
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
    assert _statuses(out)[rel] == "skipped", _statuses(out)
    # its fit is in the key
    assert cli(["process", str(tree / rel), "--out", str(out / rel), "--fit", "band"]) == 0
    assert read_manifest(out / rel)["key"]["settings"] == {"addb_process": "default", "fit": "band"}
    assert f"      {rel}: the settings changed (fit: band then, default now)\n" in info()
    text = info("--fit", "band")
    assert "    changed since that run: 4 subjects (a new run processes them again)\n" in text, text
    assert f"      {rel}: the settings changed" not in text, text
    # some trials: the folder's manifest no longer describes it
    assert cli(["process", str(tree / rel), "--out", str(out / rel), "--trial", "walking1"]) == 0
    assert read_manifest(out / rel) is None
    assert f"      {rel}: its output holds no record of the inputs it was made from" in info()
    # a subject with the reviewer's flags: the one-subject run did not apply them
    walk = "labA/rajagopal2016_walk"
    with AnnotationStore.open(tree / walk, reviewer="tester") as store:
        store.set_unmeasured("walk", range(100, 110))  # as the test of the flags left it (or runs alone)
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
    assert _statuses(out)[rel] == "ok" and "one_subject_run" not in read_manifest(out / rel)
    with_flags = read_manifest(out / walk)["key"]
    assert with_flags["annotations"] is not None
    assert cli(["process", str(tree / walk), "--out", str(out / walk)]) == 0
    assert read_manifest(out / walk)["key"]["annotations"] is None
    text = info()
    assert f"    changed since that run: 1 subject (a new run processes it again)\n      {walk}: the review's flags changed\n" in text, text
    # with the subject's own record, the one the dataset run reads: the same key as the dataset run's
    assert cli(["process", str(tree / walk), "--out", str(out / walk), "--annotations", str(tree / walk)]) == 0
    mine = read_manifest(out / walk)
    assert mine["key"] == with_flags and mine["one_subject_run"] is True
    assert f"    up to date: {len(everyone)} subjects" in info()
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1
    assert _statuses(out)[walk] == "skipped", _statuses(out)
    # with another review file (a copy of that record): not what a dataset run applies
    copy = tmp_path / "flags.json"
    shutil.copyfile(tree / walk / "annotations.json", copy)
    assert cli(["process", str(tree / walk), "--out", str(out / walk), "--annotations", str(copy)]) == 0
    assert read_manifest(out / walk) is None
    assert f"      {walk}: its output holds no record of the inputs it was made from" in info()
    assert cli(["process", str(tree), "--out", str(out), "--workers", "1"]) == 1  # as the module's tree was
    assert _statuses(out)[walk] == "ok"
    assert f"    up to date: {len(everyone)} subjects" in info()


def test_benchmark_of_the_output_tree_scores_each_processed_subject_under_its_path(
    first_run, tree: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb benchmark OUT`` of a dataset run's tree said "neither a processed output folder nor
    a subject folder". It now reads every subject the summary lists with processed trials,
    named by its path in the tree (two labs' ``s01`` are two subjects), and leaves out the
    failed one, saying so: the same per-trial errors as its subject folders given one by one
    (the module's earlier tests may have reprocessed some)."""
    out = first_run[0]
    capsys.readouterr()
    assert cli(["benchmark", str(out), "-o", str(tmp_path / "tree")]) == 0
    assert f"left out a subject without processed trials ({BROKEN})" in capsys.readouterr().err
    whole = json.loads((tmp_path / "tree" / "benchmark.json").read_text())
    assert cli(["benchmark", *(str(out / rel) for rel in FULL_TREE), "-o", str(tmp_path / "one")]) == 0
    one = json.loads((tmp_path / "one" / "benchmark.json").read_text())
    assert sorted(whole["test_subjects"]) == sorted(FULL_TREE) and sorted(one["test_subjects"]) == sorted(FULL_TREE.values())
    renamed = {f"{rel}/{key.split('/', 1)[1]}": e for rel, name in FULL_TREE.items()
               for key, e in one["rows"][0]["per_trial"].items() if key.startswith(f"{name}/")}  # fmt: skip
    assert whole["rows"][0]["per_trial"] == renamed and len(renamed) >= 3
    assert whole["rows"][0]["frames"] == one["rows"][0]["frames"]
    # a lab's folder inside the tree stands for the subjects below it (it was refused)
    capsys.readouterr()
    assert cli(["benchmark", str(out / "labA"), "-o", str(tmp_path / "labA")]) == 0
    lab = json.loads((tmp_path / "labA" / "benchmark.json").read_text())
    assert sorted(lab["test_subjects"]) == sorted(r for r in FULL_TREE if r.startswith("labA/"))
    assert lab["rows"][0]["per_trial"] == {k: e for k, e in renamed.items() if k.startswith("labA/")}
    # the dataset folder itself is named as such, with the command that makes its output tree
    capsys.readouterr()
    assert cli(["benchmark", str(tree), "-o", str(tmp_path / "x")]) == 1
    err = capsys.readouterr().err
    assert f"SubjectFolderError ({tree}): is a dataset folder (5 subject folders)" in err
    assert "addb process DATASET_DIR --out OUT and give the output tree OUT" in err and not (tmp_path / "x").exists()
