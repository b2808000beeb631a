"""Fixtures shared by every test folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

#: The read-only real lab data beside the repository: ``<repo>/../shared/data``.
SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``: measured TRC/MOT/C3D/.osim files and subject folders."""
    return SHARED_DATA


def writable_copy(src: Path, dst: Path, **copytree_kw: object) -> Path:
    """Copy ``src`` to ``dst`` and make the copy writable (files 0o644, folders 0o755).

    ``shutil.copytree`` keeps the mode bits of the read-only shared data, and addb treats
    a folder without write bits as read-only (outputs then go to the user's cache).
    """
    shutil.copytree(src, dst, **copytree_kw)
    dst.chmod(0o755)
    for p in dst.rglob("*"):
        p.chmod(0o644 if p.is_file() else 0o755)
    return dst
