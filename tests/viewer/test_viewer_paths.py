"""Paths of the review app (addb_viewer.app.paths): paths from the page cannot leave their
folder (.., absolute paths, symbolic links), default folders for the demo and a subject."""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.app.paths import ReviewPaths, UnsafePathError, confine, safe_name
from addb_viewer.demo import DEMO_SUBJECT


def test_confine_accepts_paths_inside(tmp_path: Path) -> None:
    assert confine(tmp_path, "a/b.rrd") == tmp_path.resolve() / "a" / "b.rrd"
    assert confine(tmp_path, tmp_path / "x") == tmp_path.resolve() / "x"
    assert confine(tmp_path, "a/../b") == tmp_path.resolve() / "b"


@pytest.mark.parametrize("bad", ["../x", "a/../../x", "/etc/passwd", "", "   ", "a\x00b"])
def test_confine_refuses_paths_outside(tmp_path: Path, bad: str) -> None:
    with pytest.raises(UnsafePathError):
        confine(tmp_path / "root", bad)


def test_confine_follows_symbolic_links(tmp_path: Path) -> None:
    root = tmp_path / "root"
    root.mkdir()
    (root / "out").symlink_to(tmp_path)
    with pytest.raises(UnsafePathError, match="outside"):
        confine(root, "out/secret.txt")


@pytest.mark.parametrize("bad", ["..", ".", "a/b", "a\\b", "", "x\n"])
def test_safe_name_refuses_anything_but_one_component(bad: str) -> None:
    with pytest.raises(UnsafePathError):
        safe_name(bad)
    assert safe_name("walk_01") == "walk_01"


def test_demo_writes_into_the_user_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    p = ReviewPaths.for_subject(DEMO_SUBJECT)
    for folder in (p.out_dir, p.annotations, p.recordings_dir, p.jobs_dir):
        assert folder.is_relative_to(tmp_path / "cache" / "addb")
    assert not p.annotations.is_relative_to(p.out_dir)  # the solver replaces out_dir


def test_writable_subject_keeps_everything_inside(tmp_path: Path) -> None:
    subject = tmp_path / "s01"
    subject.mkdir()
    p = ReviewPaths.for_subject(subject)
    assert p.out_dir == subject.resolve() / "addb_out"
    assert p.annotations == subject.resolve() / "annotations.json"
    assert p.recording_file("walk") == subject.resolve() / "addb_recordings" / "walk.rrd"
    assert p.trial_dir("walk") == p.out_dir / "walk"
    for bad in ("../walk", "/tmp/x", "a/b"):
        with pytest.raises(UnsafePathError):
            p.recording_file(bad)
        with pytest.raises(UnsafePathError):
            p.trial_dir(bad)
