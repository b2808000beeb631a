"""Fixtures shared by every test folder."""

from __future__ import annotations

from pathlib import Path

import pytest

#: The read-only real lab data beside the repository: ``<repo>/../shared/data``.
SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``: measured TRC/MOT/C3D/.osim files and subject folders."""
    return SHARED_DATA
