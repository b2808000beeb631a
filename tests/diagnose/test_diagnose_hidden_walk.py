"""Hidden-effect tests on the walk (:mod:`tests.diagnose.hidden`; the run's are in
``test_diagnose_hidden_run.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.diagnose.harness import Base, neutral_base
from tests.diagnose.hidden import assert_named_and_recovered, cases

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Base:
    """The walk's neutral base (its own findings applied)."""
    return neutral_base("walk", tmp_path_factory.mktemp("base") / "walk")


@pytest.mark.parametrize(("cause", "seed"), cases("walk"))
def test_hidden_cause_is_named_and_recovered(cause: str, seed: int, base: Base, tmp_path: Path) -> None:
    assert_named_and_recovered(cause, seed, base, tmp_path)
