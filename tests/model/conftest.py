"""Fixtures of the model tests: paths to the shared data and oracles, cached skeletons."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from tests.conftest import SHARED_DATA

SHARED = SHARED_DATA.parent
ORACLES = SHARED / "oracles"
MODELS = SHARED / "data" / "models"
ORACLE_MODELS = {
    "unscaled": MODELS / "Rajagopal2016.osim",
    "scaled_walk": ORACLES / "opensim_scaled_walk.osim",
}


@cache
def skeleton(path: str) -> Skeleton:
    """Parsed and converted model, cached across tests (read-only use)."""
    return Skeleton(read_osim(path))


@pytest.fixture(scope="session")
def oracle() -> dict[str, np.ndarray]:
    """The OpenSim 4.6 oracle arrays (see shared/oracles/*.json)."""
    with np.load(ORACLES / "opensim_rajagopal2016_oracle.npz") as data:
        return {k: data[k] for k in data.files}
