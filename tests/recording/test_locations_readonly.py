"""Default output folders never land inside a read-only subject folder, even for root."""

from __future__ import annotations

from pathlib import Path

from addb_viewer.locations import cache_root, default_output_dir
from tests.conftest import SHARED_DATA


def test_read_only_subject_folder_uses_the_cache(tmp_path: Path) -> None:
    subject = tmp_path / "subject"
    subject.mkdir()
    subject.chmod(0o555)  # r-x: root could still write, the mode says no
    try:
        out = default_output_dir(subject)
        assert out.parent == cache_root()
        assert default_output_dir(SHARED_DATA / "subjects" / "rajagopal2016_walk").parent == cache_root()
    finally:
        subject.chmod(0o755)
    assert default_output_dir(subject) == subject.resolve() / "addb_out"
