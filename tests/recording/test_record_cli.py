"""``addb record`` and ``addb export`` through ``addb_viewer.cli.main``."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from addb_viewer.cli import main
from addb_viewer.demo import DEMO_SUBJECT
from addb_viewer.locations import annotations_path
from annotations import AnnotationStore
from solver.io.mcap_file import open_recording
from solver.results import load_processed
from tests.recording.test_rerun_recording import Recording, per_frame_points


def test_help_lists_the_commands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert "record" in out and "export" in out


def test_record_writes_a_readable_rrd(
    tmp_path: Path, demo_out: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb record`` writes one recording of the processed walk: read back with rerun's
    reader, its observed markers are the trial's own (float32), frame by frame."""
    out_file = tmp_path / "walk.rrd"
    assert (
        main(
            [
                "record",
                str(DEMO_SUBJECT),
                "--trial",
                "walk",
                "-o",
                str(out_file),
                "--out",
                str(demo_out),
            ]
        )
        == 0
    )
    assert f"wrote {out_file}" in capsys.readouterr().out
    reader = RrdReader(out_file)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    trial = load_processed(demo_out, "walk")
    got = per_frame_points(Recording(out_file), "/world/markers/observed", trial)
    np.testing.assert_array_equal(got, trial.observed.astype(np.float32))


def test_export_mcap_round_trips(tmp_path: Path, demo_out: Path) -> None:
    out_file = tmp_path / "walk.mcap"
    argv = ["export", str(DEMO_SUBJECT), "--trial", "walk", "--format", "mcap", "-o", str(out_file)]
    assert main([*argv, "--out", str(demo_out)]) == 0
    trial = load_processed(demo_out, "walk")
    with open_recording(out_file) as rec:
        np.testing.assert_array_equal(rec.to_arrays()["observed"], trial.observed)


def test_export_format_from_suffix(tmp_path: Path, demo_out: Path) -> None:
    out_file = tmp_path / "walk.rrd"
    assert (
        main(
            [
                "export",
                str(DEMO_SUBJECT),
                "--trial",
                "walk",
                "-o",
                str(out_file),
                "--out",
                str(demo_out),
            ]
        )
        == 0
    )
    assert len(RrdReader(out_file).recordings()) == 1


def test_unknown_trial_is_a_clear_error(
    tmp_path: Path, demo_out: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "export",
        str(DEMO_SUBJECT),
        "--trial",
        "run",
        "-o",
        str(tmp_path / "x.mcap"),
        "--out",
        str(demo_out),
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "no processed trial 'run'" in err and "static, walk" in err
    assert not (tmp_path / "x.mcap").exists()


def test_missing_subject_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "record",
        str(tmp_path / "nope"),
        "--trial",
        "walk",
        "-o",
        str(tmp_path / "x.rrd"),
        "--out",
        str(tmp_path / "o"),
    ]
    assert main(argv) == 1
    assert "nope" in capsys.readouterr().err


def test_default_output_and_review_record(
    tmp_path: Path, demo_out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A writable subject without --out: processed into <subject>/addb_out (the processing
    is stubbed with a copy of the session's output), and its review record is recorded."""
    import solver.pipeline

    subject = tmp_path / "s01"
    shutil.copytree(DEMO_SUBJECT, subject)
    calls = []

    def fake_process(subject_dir: Path, out_dir: Path, **kw: object) -> None:
        calls.append((Path(subject_dir), Path(out_dir)))
        shutil.copytree(demo_out, out_dir)

    monkeypatch.setattr(solver.pipeline, "process_subject", fake_process)
    with AnnotationStore.open(
        annotations_path(subject, subject / "addb_out"), reviewer="ana"
    ) as store:
        store.set_unmeasured("walk", range(40, 55), foot="left")
    out_file = tmp_path / "walk.mcap"
    assert main(["export", str(subject), "--trial", "walk", "-o", str(out_file)]) == 0
    assert calls == [(subject, subject.resolve() / "addb_out")]
    with open_recording(out_file) as rec:
        state = rec.annotations()["state"]
    (run,) = state["unmeasured_force"]
    assert (run["start"], run["stop"], run["foot"], run["provenance"]["reviewer"]) == (
        40,
        55,
        "left",
        "ana",
    )
    # second call: already processed, not processed again
    assert main(["record", str(subject), "--trial", "walk", "-o", str(tmp_path / "walk.rrd")]) == 0
    assert len(calls) == 1


@pytest.mark.parametrize(("command", "fmt"), [("record", []), ("export", ["--format", "mcap"]), ("export", [])],
                         ids=["record", "export_mcap", "export_rrd"])
def test_an_output_folder_in_place_of_the_subject_folder_says_so(
    command: str, fmt: list[str], tmp_path: Path, demo_out: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``addb process SUBJ --out OUT`` then ``addb record OUT ...``: OUT is named as addb's
    output folder and the command to type is given (it read as a subject folder without
    _subject.json); nothing is processed or written. Given as --out too, OUT is read as before."""
    output = tmp_path / ("walk.mcap" if fmt else "walk.rrd")
    args = ["--trial", "walk", *fmt, "-o", str(output)]
    assert main([command, str(demo_out), *args]) == 1
    err = capsys.readouterr().err
    assert f"SubjectFolderError ({demo_out}): is an output folder of addb (it holds subject.json), not a subject folder" in err
    assert f"addb {command} SUBJECT_DIR {' '.join(args)} --out {demo_out}" in err
    assert "_subject.json is missing" not in err and "Traceback" not in err
    assert not output.exists() and not (demo_out / "addb_out").exists()
    # the subject folder holding the output (<subject>/addb_out) is named in the command
    subject = tmp_path / "s01"
    shutil.copytree(DEMO_SUBJECT, subject)
    shutil.copytree(demo_out, subject / "addb_out")
    assert main([command, str(subject / "addb_out"), *args]) == 1
    assert f"addb {command} {subject} {' '.join(args)} --out {subject / 'addb_out'}" in capsys.readouterr().err
    assert main([command, str(demo_out), *args, "--out", str(demo_out)]) == 0
    assert output.is_file()


@pytest.mark.parametrize(
    ("name", "fmt", "expected"),
    [
        ("walk.mp4", [], "cannot tell the format from -o {output} (a .mp4 file); name it .b3d, .mcap, .rrd or give --format"),
        ("walk.rrd", ["--format", "mcap"], "--format mcap, but -o {output} names a rrd file"),
        ("walk.mcap", ["--format", "b3d"], "--format b3d, but -o {output} names a mcap file"),
    ],
    ids=["unknown suffix", "mcap as .rrd", "b3d as .mcap"],
)
def test_an_output_name_that_does_not_tell_or_contradicts_the_format_is_refused(
    name: str, fmt: list[str], expected: str, tmp_path: Path, demo_out: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``-o walk.mp4`` wrote an MCAP file under that name, and ``--format mcap -o walk.rrd`` an
    MCAP file named .rrd that Rerun cannot open; both are refused before anything is written."""
    output = tmp_path / name
    with pytest.raises(SystemExit) as exc:
        main(["export", str(DEMO_SUBJECT), "--trial", "walk", *fmt, "-o", str(output), "--out", str(demo_out)])
    assert str(exc.value) == "addb export: " + expected.format(output=output) + ("" if "cannot" in expected else "; give one that agrees")
    assert not output.exists()
