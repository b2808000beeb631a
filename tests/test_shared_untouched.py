"""The suite leaves ../shared as it found it (tests/conftest.py: the controlling process
lists every file's size and modification time at the start and the end; a difference
fails the run and names the files), checked on a repository and a shared folder of its own."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from tests.conftest import changed_files, file_states

CONFTEST = Path(__file__).resolve().parent / "conftest.py"


def test_changed_files_names_what_was_added_removed_or_modified(tmp_path: Path) -> None:
    (tmp_path / "a.txt").write_text("a")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.txt").write_text("b")
    (tmp_path / "c.txt").write_text("c")
    before = file_states(tmp_path)
    assert set(before) == {"a.txt", "sub/b.txt", "c.txt"}
    assert changed_files(before, file_states(tmp_path)) == []
    (tmp_path / "sub" / "b.txt").write_text("bb")  # modified
    (tmp_path / "c.txt").unlink()  # removed
    (tmp_path / "sub" / "new.json").write_text("{}")  # added, as a review record would be
    assert changed_files(before, file_states(tmp_path)) == ["c.txt", "sub/b.txt", "sub/new.json"]


def _run(tmp_path: Path, body: str) -> subprocess.CompletedProcess[str]:
    """pytest on one test ``body`` in ``tmp_path/repo`` with this conftest, beside
    ``tmp_path/shared/data`` holding one file."""
    repo, data = tmp_path / "repo", tmp_path / "shared" / "data"
    shutil.rmtree(tmp_path, ignore_errors=True)
    (repo / "tests").mkdir(parents=True)
    data.mkdir(parents=True)
    (data / "walk.trc").write_text("markers\n")
    shutil.copy(CONFTEST, repo / "tests" / "conftest.py")
    (repo / "tests" / "test_one.py").write_text(
        "from pathlib import Path\n\nDATA = Path(__file__).resolve().parents[2] / 'shared' / 'data'\n\n\n"
        f"def test_one():\n    {body}\n"
    )
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist", "tests"],
        cwd=repo, capture_output=True, text=True, check=False, timeout=120,
    )


def test_a_test_that_writes_into_shared_fails_the_run(tmp_path: Path) -> None:
    reads = _run(tmp_path / "reads", "assert (DATA / 'walk.trc').read_text() == 'markers\\n'")
    assert reads.returncode == 0, reads.stdout + reads.stderr
    writes = _run(tmp_path / "writes", "(DATA / 'annotations.json').write_text('{}')")
    assert writes.returncode == 1, writes.stdout + writes.stderr
    assert "1 passed" in writes.stdout  # the test itself passed: the run fails on the data
    assert "error: the tests changed files of" in writes.stderr and "data/annotations.json" in writes.stderr
