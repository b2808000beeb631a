"""The dynamics fit the diagnosis judges on, rebuilt when a trial was processed with another.

The diagnosis' choice rule (its 10 % relative gain, the folds, the plausible sizes, the
neutral bases of its benchmark: docs/diagnose/RESULTS.md) was calibrated on the dynamics
fit with ``direction="band"``, a fixed number of rounds and its weights
(:class:`solver.dynamics.fit.FitSettings`'s defaults, ``addb process --fit band``). The
fit that runs to convergence (:func:`solver.dynamics.fit.converged_fit`, the pipeline's
default) moves the motion further toward the measured forces: a hidden force error then
shows far less in the residual forces and more in the marker errors, and 10 of the 58
hidden-cause tests of tests/diagnose failed when the diagnosis judged that motion with its
thresholds (measured 2026-11-24 with the converged fit's first weights;
docs/diagnose/RESULTS.md, "The fit it judges on").

So the diagnosis judges every trial on the band fit: when the trial's output was made with
another fit, the dynamics stage is run again with ``FitSettings()`` (the recorded
``derivative`` kept) into a scratch folder, from the output's
cached kinematics (:func:`solver.pipeline.reprocess_dynamics`, which equals a full run
with the same flags bit for bit), and the diagnosis reads that folder. The user's output
is not touched.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from solver.dynamics.fit import FitSettings

if TYPE_CHECKING:
    from solver.dynamics.stage import DynamicsOptions

Progress = Callable[[str, float], None]

def judged_fit(recorded: FitSettings) -> FitSettings:
    """The fit the diagnosis judges a trial processed with ``recorded`` on: the one its
    thresholds were calibrated on, :class:`~solver.dynamics.fit.FitSettings`' defaults
    (``direction="band"``, its weights, rounds stopping on their number only), with the
    recorded ``derivative`` (which also sets the inverse dynamics' derivatives)."""
    return FitSettings(derivative=recorded.derivative)


def is_judged_fit(recorded: FitSettings) -> bool:
    """True when an output made with ``recorded`` can be judged as it is."""
    return recorded == judged_fit(recorded)


@contextmanager
def judged_output(
    subject_dir: str | Path,
    out_dir: str | Path,
    trial: str,
    unmeasured_force: Mapping[str, np.ndarray] | None = None,
    progress: Progress | None = None,
    *,
    recorded: DynamicsOptions | None = None,
) -> Iterator[Path]:
    """The output folder to diagnose ``trial`` in: ``out_dir`` itself when it was made with
    the judged fit, else a scratch folder with the trial processed again with it (removed
    on exit).

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        The subject's processed output (its ``subject.json`` records the fit).
    trial
        The trial to write in the scratch folder.
    unmeasured_force
        Trial name -> ``(T,)`` reviewer's flags at the processed frames, as the output was
        processed with (every trial's: the body mass factors are fitted over all of them).
    progress
        Called with (message, fraction).
    recorded
        The dynamics options ``out_dir`` was made with, when the caller has read them
        already (default: :func:`solver.pipeline.recorded_dynamics_options`).

    Raises
    ------
    SubjectFolderError, FileFormatError, KinematicsError, DynamicsError
        As :func:`solver.pipeline.reprocess_dynamics`.
    """
    from solver.pipeline import (
        CACHE_DIR,
        ProcessOptions,
        recorded_dynamics_options,
        reprocess_dynamics,
    )

    if recorded is None:
        recorded = recorded_dynamics_options(out_dir)
    if is_judged_fit(recorded.fit):
        yield Path(out_dir)
        return
    with tempfile.TemporaryDirectory(prefix="addb_judged_fit_") as tmp:
        base = Path(tmp) / "out"
        cache = Path(out_dir) / CACHE_DIR
        if cache.is_dir():
            shutil.copytree(cache, base / CACHE_DIR)
        options = ProcessOptions(dynamics=replace(recorded, fit=judged_fit(recorded.fit)))
        say = progress or (lambda m, f: None)
        reprocess_dynamics(
            subject_dir, base, [trial], dict(unmeasured_force or {}) or None,
            lambda m, f: say(f"the diagnosis' fit (band): {m}", f), options=options, warm_start=False,
        )  # fmt: skip
        yield base
