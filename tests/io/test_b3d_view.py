"""``addb view FILE.b3d``: the file is converted once into a cached subject folder."""

from __future__ import annotations

from pathlib import Path

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
