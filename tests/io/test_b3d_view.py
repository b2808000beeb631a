"""``addb view FILE.b3d``: the file is converted once into a cached subject folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addb_viewer.commands.view import b3d_subject
from solver.io.subject import load_subject

B3D = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "b3d" / "results.b3d"

pytestmark = pytest.mark.skipif(not B3D.exists(), reason="shared results.b3d not present")


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
