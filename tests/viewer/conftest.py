"""Fixtures of the viewer tests: the demo subject processed once (kinematics stage, a few
seconds) and per-test copies of that output, so that each test has its own review
record and nothing is written into the package or the user's cache; the shared walk
processed once with dynamics."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.demo import DEMO_SUBJECT


@pytest.fixture(scope="session")
def demo_processed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo subject's kinematics output (``OUT/<trial>/trial.npz``), shared, read only."""
    from solver.pipeline import process_kinematics

    out = tmp_path_factory.mktemp("demo") / "out"
    process_kinematics(DEMO_SUBJECT, out)
    return out


@pytest.fixture(scope="session")
def walk_processed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shared walk (rajagopal2016_walk) processed with dynamics by ``process_subject``
    (its trials' proposals, residuals and Hicks verdicts), shared, read only: copy it."""
    from solver.pipeline import process_subject
    from tests.conftest import SHARED_DATA

    out = tmp_path_factory.mktemp("walk") / "out"
    process_subject(SHARED_DATA / "subjects" / "rajagopal2016_walk", out)
    return out


@pytest.fixture
def demo_out(demo_processed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private copy of the processed demo (its review record goes beside it)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    out = tmp_path / "out"
    shutil.copytree(demo_processed, out)
    return out


@pytest.fixture
def demo_paths(demo_out: Path) -> ReviewPaths:
    """Review folders of the demo with the private output copy."""
    return ReviewPaths.for_subject(DEMO_SUBJECT, demo_out)


@pytest.fixture
def make_app() -> Iterator[Callable[..., object]]:
    """Start ReviewApps on 127.0.0.1 with a free port; all are stopped afterwards."""
    from addb_viewer.app.server import ReviewApp

    apps: list[ReviewApp] = []

    def make(paths: ReviewPaths, **kw: object) -> ReviewApp:
        kw.setdefault("background", False)
        app = ReviewApp(paths, reviewer=str(kw.pop("reviewer", "tester")), host="127.0.0.1", port=0, **kw)
        apps.append(app)
        return app

    yield make
    for app in apps:
        app.stop()
