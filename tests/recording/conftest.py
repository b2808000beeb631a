"""Fixtures of the recording tests: the demo trial processed once per session, a copy
with synthetic finite dynamics, and a Rerun CLI environment without analytics."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from addb_viewer.demo import DEMO_SUBJECT
from solver.results import ProcessedTrial, load_processed
from tests.recording.recording_support import RERUN, with_dynamics, without_dynamics


@pytest.fixture(scope="session")
def demo_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled demo subject through the kinematics stage (a few seconds; the full
    pipeline with dynamics takes minutes, and the writers only need a ProcessedTrial)."""
    from solver.pipeline import process_kinematics

    out = tmp_path_factory.mktemp("demo") / "out"
    process_kinematics(DEMO_SUBJECT, out)
    return out


@pytest.fixture(scope="session")
def demo_trial(demo_out: Path) -> ProcessedTrial:
    """The demo walk with NaN dynamics (as a kinematics-only trial is written)."""
    return without_dynamics(load_processed(demo_out, "walk"))


@pytest.fixture(scope="session")
def dynamic_trial(demo_trial: ProcessedTrial) -> ProcessedTrial:
    return with_dynamics(demo_trial)


@pytest.fixture(params=["kinematics_only", "with_dynamics"])
def any_trial(
    request: pytest.FixtureRequest, demo_trial: ProcessedTrial, dynamic_trial: ProcessedTrial
) -> ProcessedTrial:
    """Both the pipeline's current output (NaN dynamics) and the synthetic finite copy."""
    return demo_trial if request.param == "kinematics_only" else dynamic_trial


@pytest.fixture(scope="session")
def rerun_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Environment for the ``rerun`` CLI with its own config folder and analytics off."""
    home = tmp_path_factory.mktemp("rerun-config")
    env = {**os.environ, "XDG_CONFIG_HOME": str(home), "XDG_DATA_HOME": str(home)}
    subprocess.run(
        [str(RERUN), "analytics", "disable"], env=env, capture_output=True, timeout=60, check=True
    )
    return env
