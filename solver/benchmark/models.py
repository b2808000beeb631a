"""What every part of the benchmark shares: its error type and the (cached) skeleton of a
trial's scaled model. Kept apart so that the readers of trials (output folders,
:mod:`solver.benchmark.dataset`; .b3d files, :mod:`solver.benchmark.b3d_trials`) import
it without importing each other."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from solver.errors import AddbError


class BenchmarkError(AddbError):
    """The benchmark cannot run: no usable trial, a subject in two splits, a missing model."""


@lru_cache(maxsize=16)
def skeleton_for(model_path: str) -> Any:
    """The :class:`~solver.model.skeleton.Skeleton` of a scaled model file (cached).

    Raises
    ------
    BenchmarkError
        The model file does not exist (the output folder was moved).
    """
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton

    if not Path(model_path).is_file():
        raise BenchmarkError("the trial's scaled model file is missing (was the output folder moved?)", path=model_path)
    return Skeleton(read_osim(model_path))
