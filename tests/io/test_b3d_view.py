"""``addb view FILE.b3d``: the file is converted once into a cached subject folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addb_viewer.commands.view import b3d_subject
from solver.io.subject import load_subject
from tests.conftest import SHARED_DATA

B3D = SHARED_DATA / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's


def test_b3d_subject_is_cached(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    folder = b3d_subject(B3D)
    assert folder.is_relative_to(tmp_path / "cache" / "addb" / "b3d")
    subject = load_subject(folder)
    assert [t.name for t in subject.trials] == ["walking1_segment_0", "walking2_segment_0"]
    assert (folder / "annotations.json").is_file()
    stamp = (folder / "_subject.json").stat().st_mtime_ns
    assert b3d_subject(B3D) == folder
    assert (folder / "_subject.json").stat().st_mtime_ns == stamp  # not converted again


def test_a_folder_of_b3d_files_opens_as_a_dataset(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """s01 is results.b3d with frames 3-8 of its second trial labelled notOverForcePlate
    (results.b3d itself labels no frame), s02 the file as published: each subject's review
    record holds exactly its own file's labels."""
    import dataclasses
    import shutil

    from addb_viewer.app.queue import NOT_PROCESSED, build_queue, dataset_subjects, is_dataset
    from addb_viewer.commands.view import b3d_dataset, is_b3d_folder
    from annotations import AnnotationStore
    from solver.io.b3d import open_b3d
    from solver.io.b3d_writer import write_b3d

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    folder = tmp_path / "published"
    folder.mkdir()
    f = open_b3d(B3D)
    trials = list(f.header.trials)
    labels = {t.name: [r != "notMissingGRF" for r in t.missing_grf] for t in trials}
    assert not any(any(v) for v in labels.values())
    reasons = list(trials[1].missing_grf)
    reasons[3:9] = ["notOverForcePlate"] * 6
    trials[1] = dataclasses.replace(trials[1], missing_grf=tuple(reasons))
    header = dataclasses.replace(f.header, trials=tuple(trials))
    write_b3d(folder / "s01.b3d", header, [f.read_trial(k) for k in range(len(trials))])
    shutil.copyfile(B3D, folder / "s02.b3d")
    expected = {"s01": {**labels, trials[1].name: [r != "notMissingGRF" for r in reasons]}, "s02": labels}
    assert is_b3d_folder(folder) and not is_b3d_folder(tmp_path / "cache")
    root = b3d_dataset(folder)
    assert is_dataset(root) and b3d_dataset(folder) == root  # converted once, then reused
    _, out, subjects = dataset_subjects(root)
    assert [s.rel for s in subjects] == ["s01", "s02"] and out == root / "addb_out"
    rows = build_queue(subjects)
    assert {(r.subject.rel, r.processing) for r in rows} == {("s01", NOT_PROCESSED), ("s02", NOT_PROCESSED)}
    # each subject keeps its file's missing-GRF labels as its review record
    for s in subjects:
        with AnnotationStore.open(s.subject_dir / "annotations.json", reviewer="test") as store:
            for t in trials:
                mask = store.mask(t.name, t.n_frames, kind="unmeasured_force")
                np.testing.assert_array_equal(mask, expected[s.rel][t.name], err_msg=f"{s.rel} {t.name}")


def _review_of(folder: Path, trial: str) -> tuple[list, list]:
    from annotations import AnnotationStore

    with AnnotationStore.open(folder / "annotations.json", reviewer="checker") as store:
        flags = [(r.start, r.stop, r.provenance.source, r.provenance.reviewer) for r in store.flag_runs(trial)]
        notes = [(n.start, n.stop, n.text) for n in store.notes(trial)]
    return flags, notes


def test_a_changed_file_converts_again_with_its_review(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:  # fmt: skip
    """``addb view FILE.b3d`` reviewed (alice flags frames and writes a note), then the file
    touched (a copy made again, a download): the new conversion's review record holds
    alice's flags and note. When the earlier conversion's trials had other frame counts the
    record is not carried over, and the command names where the earlier review is."""
    import json
    import os
    import shutil

    from annotations import AnnotationStore

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    path = tmp_path / "s01.b3d"
    shutil.copyfile(B3D, path)
    first = b3d_subject(path)
    trial = "walking1_segment_0"
    with AnnotationStore.open(first / "annotations.json", reviewer="alice") as store:
        store.set_unmeasured(trial, range(10, 20), foot="left")
        store.add_note(trial, "alice: checked", start=10, stop=20)
    reviewed = _review_of(first, trial)
    assert reviewed == ([(10, 20, "manual", "alice")], [(10, 20, "alice: checked")])
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**10))
    second = b3d_subject(path)
    assert second != first
    assert _review_of(second, trial) == reviewed
    assert f"carried over the review of the earlier conversion ({first / 'annotations.json'})" in capsys.readouterr().out

    source = json.loads((second / "b3d_source.json").read_text())
    source["trials"][trial]["frames"] += 1  # as if that version of the file had another frame count
    (second / "b3d_source.json").write_text(json.dumps(source))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 2 * 10**10))
    third = b3d_subject(path)
    assert _review_of(third, trial) == ([], [])
    printed = capsys.readouterr().out
    assert f"not carried over: the review of the earlier conversion {second / 'annotations.json'}" in printed, printed
