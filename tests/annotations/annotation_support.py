"""Helpers shared by the annotations tests (imported by name; not a test module)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

from tests.conftest import SHARED_DATA

UHLRICH = SHARED_DATA / "trials" / "opencap_uhlrich2023"
WORKER = Path(__file__).with_name("annotation_worker.py")


class StepClock:
    """A clock that advances 1 ms per call from 2026-01-01T00:00:00Z (distinct timestamps)."""

    def __init__(self) -> None:
        self.now = datetime(2026, 1, 1, tzinfo=UTC)

    def __call__(self) -> datetime:
        self.now += timedelta(milliseconds=1)
        return self.now
