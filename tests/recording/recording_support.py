"""Helpers shared by the recording tests."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from solver.results import ProcessedTrial

#: The rerun CLI shipped in the rerun-sdk wheel, beside the running interpreter.
RERUN = Path(sys.executable).parent / "rerun"

#: A review state as ``review_state(TrialReview)`` gives it.
REVIEW = {
    "trial": "walk",
    "reviewed": False,
    "unmeasured_force": [
        {
            "start": 40,
            "stop": 55,
            "kind": "unmeasured_force",
            "foot": "left",
            "provenance": {
                "reviewer": "ana",
                "timestamp": "2026-11-21T10:00:00.000Z",
                "source": "manual",
            },
        }
    ],
    "excluded": [],
    "activities": [],
    "notes": [],
}


def with_dynamics(trial: ProcessedTrial, seed: int = 7) -> ProcessedTrial:
    """A copy of ``trial`` with finite synthetic dynamics, flags, missing markers, plate
    corners and body assignment, so that every branch of the writers runs."""
    rng = np.random.default_rng(seed)
    t, n = trial.n_frames, len(trial.coordinate_names)
    observed = trial.observed.copy()
    observed[5:9, 3] = np.nan  # a marker gap
    observed[20, :] = np.nan  # a frame with no marker at all
    unobserved = np.zeros(t, dtype=bool)
    unobserved[40:55] = True
    proposed = np.zeros(t, dtype=bool)
    proposed[40:60] = True
    reasons = tuple(
        "zero vertical force" if 40 <= k < 50 else "CoP outside foot" if 50 <= k < 60 else ""
        for k in range(t)
    )
    plates = []
    for i, p in enumerate(trial.plates):
        body = np.where(np.isfinite(p.cop).all(axis=1), 5 + 6 * i, -1)
        corners = np.array([[0.0, 0.0, 0.0], [0.6, 0.0, 0.0], [0.6, 0.0, 0.4], [0.0, 0.0, 0.4]]) + [
            0.7 * i,
            0,
            0,
        ]
        plates.append(dataclasses.replace(p, body=body, corners=corners))
    return dataclasses.replace(
        trial,
        observed=observed,
        qd=rng.normal(size=(t, n)),
        qdd=rng.normal(size=(t, n)),
        com_acc=rng.normal(size=(t, 3)),
        residual_force=rng.normal(scale=20.0, size=(t, 3)),
        residual_moment=rng.normal(scale=5.0, size=(t, 3)),
        tau=rng.normal(scale=50.0, size=(t, n)),
        unobserved=unobserved,
        proposed=proposed,
        proposal_reasons=reasons,
        plates=tuple(plates),
        settings={
            "dynamics": {"filter_hz": 30.0, "residual_weight": 0.1},
            "kinematics": {"max_iters": 200},
        },
        mass_kg=81.25,
    )


def without_dynamics(trial: ProcessedTrial) -> ProcessedTrial:
    """A copy of ``trial`` whose dynamics fields are NaN and flags cleared, as the
    pipeline writes a trial without force plates or before the dynamics stage."""
    t, n = trial.n_frames, len(trial.coordinate_names)
    nan3 = np.full((t, 3), np.nan)
    return dataclasses.replace(
        trial,
        qd=np.full((t, n), np.nan),
        qdd=np.full((t, n), np.nan),
        com_acc=nan3,
        residual_force=nan3,
        residual_moment=nan3.copy(),
        tau=np.full((t, n), np.nan),
        unobserved=np.zeros(t, dtype=bool),
        proposed=np.zeros(t, dtype=bool),
        proposal_reasons=("",) * t,
    )
