"""Numbers and sizes given on the command line are checked by the parser, before anything
runs: ``addb process DATASET --workers -1`` started a Dask cluster of no worker and waited
for ever, ``--memory-limit lots`` ended in a traceback from Dask's size parser once the run
had started, and ``--retries``, ``addb view --workers`` and ``addb benchmark --epochs``
took negative numbers."""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.cli import main
from tests.conftest import SHARED_DATA

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["process", "DATASET", "--out", "OUT", "--workers", "-1"], "argument --workers: expected a whole number of at least 1, got '-1'"),
        (["process", "DATASET", "--out", "OUT", "--workers", "0"], "argument --workers: expected a whole number of at least 1, got '0'"),
        (["process", "DATASET", "--out", "OUT", "--workers", "two"], "argument --workers: expected a whole number, got 'two'"),
        (["process", "DATASET", "--out", "OUT", "--retries", "-3"], "argument --retries: expected a whole number of at least 0, got '-3'"),
        (["process", "DATASET", "--out", "OUT", "--memory-limit", "lots"], "argument --memory-limit: expected a size such as 4GB or 500MiB, or auto, got 'lots'"),
        (["process", "DATASET", "--out", "OUT", "--memory-limit", "0"], "argument --memory-limit: expected a size above zero, got '0'"),
        (["view", "DATASET", "--workers", "-2"], "argument --workers: expected a whole number of at least 0, got '-2'"),
        (["benchmark", "DATASET", "--epochs", "0"], "argument --epochs: expected a whole number of at least 1, got '0'"),
    ],
)
def test_a_bad_number_is_refused_by_the_parser(argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dataset = tmp_path / "ds"
    argv = [{"DATASET": str(dataset), "OUT": str(tmp_path / "out")}.get(a, a) for a in argv]
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert f"addb {argv[0]}: error: {message}" in err, err
    assert not (tmp_path / "out").exists() and not dataset.exists()


@pytest.mark.parametrize("size", ["auto", "2GB", "500MiB", "2e9"])
def test_sizes_dask_reads_are_kept_as_given(size: str) -> None:
    from addb_viewer.commands import memory_size

    assert memory_size(size) == ("auto" if size == "auto" else size)
