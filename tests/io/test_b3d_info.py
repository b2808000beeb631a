"""``addb info FILE.b3d``: the summary of results.b3d against the oracle, and a damaged file's error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from addb_viewer.cli import main
from solver.io.summary import summarize
from tests.conftest import SHARED_DATA

SHARED = SHARED_DATA.parent
B3D = SHARED / "data" / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's


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


def test_each_trial_is_named_once(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """A trial's line named it and then, in parentheses, the trial it was split from, which the
    name already says ("walking2_segment_0 (walking2 part 0)"; "walk (walk part 0)" for a file
    of addb export): read as each trial listed twice. The source stays when the name does not say it."""
    import dataclasses

    from solver.io.b3d import open_b3d
    from solver.io.b3d_writer import write_b3d

    assert main(["info", str(B3D)]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in ("walking1", "walking2"):
        [line] = [s for s in lines if name in s]
        assert line.count(name) == 1 and line.startswith(f"    {name}_segment_0: ")
    f = open_b3d(B3D)
    first, second = f.header.trials
    trials = (dataclasses.replace(first, name="overground"), dataclasses.replace(second, name="walking1", split_index=0))
    renamed = tmp_path / "renamed.b3d"
    write_b3d(renamed, dataclasses.replace(f.header, trials=trials), [f.read_trial(k) for k in range(2)])
    assert main(["info", str(renamed)]) == 0
    out = capsys.readouterr().out
    assert "    overground (from walking2 part 0): 132 frames" in out
    assert "    walking1: 131 frames" in out and out.count("walking1") == 1


def test_unknown_age_and_a_folder_of_b3d_files(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The format's unknown age (-1, as ``addb export`` writes for a subject without one) read
    "age -1"; a folder of .b3d files failed as a subject folder without ``_subject.json``, and a
    dataset folder the same way. The folder of files is listed, the dataset folder listed as one
    (its subjects: here two without a model, each named with its error)."""
    import dataclasses
    import shutil

    from solver.io.b3d import open_b3d
    from solver.io.b3d_writer import write_b3d

    f = open_b3d(B3D)
    header = dataclasses.replace(f.header, age_years=-1, tags=("healthy", "walking"))
    folder = tmp_path / "published"
    folder.mkdir()
    write_b3d(folder / "s01.b3d", header, [f.read_trial(k) for k in range(len(header.trials))])
    shutil.copy(B3D, folder / "s02.b3d")
    assert main(["info", str(folder / "s01.b3d")]) == 0
    out = capsys.readouterr().out
    assert ", age unknown, 68 kg, 1.7 m, tags: healthy, walking" in out and "age -1" not in out
    assert main(["info", str(B3D)]) == 0
    assert f", age {f.header.age_years}, 68 kg" in capsys.readouterr().out
    s = summarize(folder)
    assert s["kind"] == "b3d_folder" and [e["name"] for e in s["files"]] == ["s01.b3d", "s02.b3d"]
    assert [e["frames"] for e in s["files"]] == [sum(t.n_frames for t in f.header.trials)] * 2
    assert main(["info", str(folder)]) == 0
    out = capsys.readouterr().out
    assert f"  2 .b3d files, {2 * s['files'][0]['frames']} frames" in out
    assert "    s02.b3d: 2 trials, 263 frames; 68 kg, 1.7 m; passes kinematics" in out
    dataset = tmp_path / "dataset"
    for rel in ("labA/s1", "labB/s2"):
        (dataset / rel).mkdir(parents=True)
        (dataset / rel / "_subject.json").write_text('{"massKg": 70, "heightM": 1.7}')
    assert main(["info", str(dataset)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{dataset}: dataset folder\n  2 subjects, 2 of them unreadable; 0 trials")
    for rel in ("labA/s1", "labB/s2"):
        assert f"  {rel}: cannot be read: SubjectFolderError ({dataset / rel / 'unscaled_generic.osim'}): the model" in out


def test_a_damaged_file_in_a_folder_and_a_mixed_folder(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """A folder with one cut .b3d file listed the others' headers only up to that file's error;
    now the damaged file is a line naming its error and the others are listed. A folder holding
    both .b3d files and subject folders was listed as a folder of .b3d files; it is a dataset
    folder, listed as one with the .b3d files it leaves out."""
    import shutil

    folder = tmp_path / "published"
    folder.mkdir()
    shutil.copy(B3D, folder / "a_good.b3d")
    (folder / "b_cut.b3d").write_bytes(B3D.read_bytes()[:300])
    s = summarize(folder)
    good, cut = s["files"]
    assert good["name"] == "a_good.b3d" and good["frames"] == s["frames"] > 0
    assert cut["name"] == "b_cut.b3d" and "b_cut.b3d" in cut["error"]
    assert main(["info", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "    a_good.b3d: 2 trials, 263 frames" in out
    assert f"    b_cut.b3d: cannot be read: {cut['error']}" in out
    # the subject folders below: a dataset folder, whose output folder is not searched
    for rel in ("s1", "addb_out/s1"):
        (folder / rel).mkdir(parents=True)
        (folder / rel / "_subject.json").write_text('{"massKg": 70, "heightM": 1.7}')
    assert main(["info", str(folder)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{folder}: dataset folder\n  1 subject, 1 of them unreadable;") and "\n  s1: cannot be read" in out
    assert "addb_out/s1" not in out  # the default output folder is not searched
    assert "  left out: the dataset folder holds 2 .b3d files (a_good.b3d, b_cut.b3d), which a dataset run does not process" in out
