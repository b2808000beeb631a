"""Scoring predictions on benchmark frames, and running a method over a split.

A *method* maps a :class:`~solver.benchmark.dataset.BenchmarkTrial` to a
:class:`~solver.benchmark.analytical.Prediction` on all its frames; only the trial's
benchmark frames are scored (:mod:`solver.benchmark.metrics`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from solver.benchmark.analytical import Prediction
from solver.benchmark.dataset import BenchmarkTrial, torque_columns
from solver.benchmark.metrics import (
    FrameErrors,
    com_acc_errors,
    grf_errors,
    grm_errors,
    summarize,
    torque_errors,
)

Method = Callable[[BenchmarkTrial], Prediction]


def score_trial(trial: BenchmarkTrial, pred: Prediction) -> FrameErrors:
    """Per-frame errors of ``pred`` on the benchmark frames of ``trial``."""
    k = trial.frames
    cols = torque_columns(trial)
    m = trial.mass_kg
    return FrameErrors(
        com_acc=com_acc_errors(pred.com_acc[k], trial.com_acc[k]),
        grm=grm_errors(pred.grm[k], trial.grm[k], m),
        grf=grf_errors(pred.grf[k], trial.grf[k], m),
        torque=torque_errors(pred.tau[k][:, cols], trial.tau[k][:, cols], m),
    )


@dataclass(frozen=True)
class MethodResult:
    """A method's errors on a set of trials.

    Attributes
    ----------
    method
        Row label of the table.
    metrics
        Mean errors over all scored frames (:func:`~solver.benchmark.metrics.summarize`).
    per_trial
        ``"subject/trial"`` -> mean errors on that trial's frames.
    n_frames
        Number of scored frames.
    seconds
        Wall time of the method (training included), s.
    notes
        Free-form details (training time, folds, ...).
    """

    method: str
    metrics: dict[str, float]
    per_trial: dict[str, dict[str, float]]
    n_frames: int
    seconds: float
    notes: dict[str, object]


def evaluate(method: Method, trials: Iterable[BenchmarkTrial]) -> tuple[FrameErrors, dict[str, dict[str, float]]]:
    """Run ``method`` on each trial and score it: pooled per-frame errors and per-trial means."""
    parts = []
    per_trial = {}
    for trial in trials:
        errors = score_trial(trial, method(trial))
        parts.append(errors)
        per_trial[f"{trial.subject}/{trial.trial}"] = summarize(errors)
    return FrameErrors.concatenate(parts), per_trial


def contact_phases(trials: Iterable[BenchmarkTrial]) -> dict[str, float]:
    """Share of the benchmark frames in flight (no foot in contact), single support and
    double support, from the ground-truth contact."""
    counts = np.zeros(3)
    for t in trials:
        n = t.contact[t.frames].sum(axis=1)
        counts += np.bincount(np.minimum(n, 2), minlength=3)[:3]
    total = counts.sum()
    shares = counts / total if total else np.full(3, np.nan)
    return {"flight": float(shares[0]), "single_support": float(shares[1]), "double_support": float(shares[2])}
