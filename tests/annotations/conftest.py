"""Fixtures of the annotations tests: a subject folder, a deterministic clock, shared data."""

from __future__ import annotations

from pathlib import Path

import pytest
from annotation_support import StepClock


@pytest.fixture
def clock() -> StepClock:
    return StepClock()


@pytest.fixture
def subject(tmp_path: Path) -> Path:
    folder = tmp_path / "subject01"
    folder.mkdir()
    return folder
