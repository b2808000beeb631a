"""Default output folders never land inside a read-only subject folder, even for root.

addb decides "read-only" from the folder's mode bits as well as ``os.access``
(:func:`solver.io.subject.folder_is_writable`), because root may write anywhere. The tests
build their own read-only and writable copies of a real subject in ``tmp_path``, so they
do not depend on whether ``../shared`` happens to be mounted read-only on this machine.
"""

from __future__ import annotations

import shutil
import stat
from pathlib import Path

import pytest

from addb_viewer.locations import (
    ANNOTATIONS_NAME,
    OUTPUT_NAME,
    annotations_path,
    cache_root,
    default_output_dir,
    uses_subject_folder,
)
from solver.io.subject import folder_is_writable
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


def _read_only_copy(dst: Path) -> Path:
    """A copy of the walk subject whose folders are r-x and files r-- (as a lab's shared
    data); the caller restores write bits so that pytest can remove it."""
    shutil.copytree(WALK, dst)
    for p in [dst, *dst.rglob("*")]:
        p.chmod(0o444 if p.is_file() else 0o555)
    return dst


def _restore(folder: Path) -> None:
    for p in [folder, *folder.rglob("*")]:
        p.chmod(0o644 if p.is_file() else 0o755)


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache" / "addb"


def test_read_only_subject_folder_uses_the_cache(tmp_path: Path, cache: Path) -> None:
    subject = _read_only_copy(tmp_path / "rajagopal2016_walk")
    try:
        assert stat.S_IMODE(subject.stat().st_mode) == 0o555
        assert not folder_is_writable(subject)  # even for root, whom chmod does not stop
        assert not uses_subject_folder(subject)
        out = default_output_dir(subject)
        assert cache_root() == cache and out.parent == cache
        assert out.name.startswith("rajagopal2016_walk-")
        assert annotations_path(subject, out) == out.parent / f"{out.name}.annotations.json"
        assert not str(annotations_path(subject, out)).startswith(str(subject.resolve()))
    finally:
        _restore(subject)
    # the same folder with its write bits back: outputs go inside it again
    assert folder_is_writable(subject)
    assert default_output_dir(subject) == subject.resolve() / OUTPUT_NAME


def test_writable_copy_of_the_shared_subject_keeps_outputs_inside(
    tmp_path: Path, cache: Path
) -> None:
    subject = writable_copy(WALK, tmp_path / "rajagopal2016_walk")
    assert uses_subject_folder(subject)
    assert default_output_dir(subject) == subject.resolve() / OUTPUT_NAME
    assert annotations_path(subject, subject / OUTPUT_NAME) == subject.resolve() / ANNOTATIONS_NAME


def test_an_empty_read_only_folder_uses_the_cache(tmp_path: Path, cache: Path) -> None:
    subject = tmp_path / "subject"
    subject.mkdir()
    subject.chmod(0o555)  # r-x: root could still write, the mode says no
    try:
        assert default_output_dir(subject).parent == cache
    finally:
        subject.chmod(0o755)
    assert default_output_dir(subject) == subject.resolve() / OUTPUT_NAME
