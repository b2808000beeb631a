"""Hidden-effect tests on the run (:mod:`tests.diagnose.hidden`; the walk's are in
``test_diagnose_hidden_walk.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.diagnose.harness import Base, neutral_base
from tests.diagnose.hidden import assert_named_and_recovered, cases

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Base:
    """The run's neutral base (its own findings applied)."""
    return neutral_base("run", tmp_path_factory.mktemp("base") / "run")


@pytest.mark.parametrize(("cause", "seed"), cases("run"))
def test_hidden_cause_is_named_and_recovered(cause: str, seed: int, base: Base, tmp_path: Path) -> None:
    assert_named_and_recovered(cause, seed, base, tmp_path)
