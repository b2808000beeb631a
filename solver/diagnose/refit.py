"""Refit a processed trial with an extension: the dynamics stage again, from its own motion.

The refit runs :func:`solver.dynamics.stage.run_dynamics` on the trial alone, starting
from the processed coordinates (instead of inverse kinematics) with the processed
(scaled, mass-fitted) model, on the extension-corrected raw forces and markers, and with
fewer Gauss-Newton rounds than the pipeline (it starts near the optimum). It gives the
metrics "after" the extension, in the pipeline's own terms (results.json keys), and a
:class:`~solver.results.ProcessedTrial` the diagnosis can look at again. The diagnosis
runs it twice, with and without the extension (:func:`solver.diagnose.core.refit_result`):
starting from the processed motion, the refit lowers the residual by itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.dynamics.fit import FitSettings
from solver.dynamics.stage import (
    DynamicsOptions,
    DynamicsResult,
    TrialDynamics,
    run_dynamics,
    trial_frames,
)
from solver.io.types import ForceRecording, MarkerTrajectories
from solver.kinematics.result import KinematicsResult, TrialKinematics
from solver.masks import resample_mask
from solver.model.mass_groups import redistribute  # noqa: F401 (re-exported)
from solver.model.osim import OsimModel
from solver.model.skeleton import Skeleton
from solver.results import ProcessedTrial

BoolArray = NDArray[np.bool_]

#: Rounds and iterations of the refit's dynamics fit (the pipeline's: 4 and 12).
REFIT_ROUNDS = 3
REFIT_ITERATIONS = 12


@dataclass(frozen=True)
class Refit:
    """Result of :func:`refit_trial`.

    Attributes
    ----------
    trial
        The refitted trial (dynamics fields, model path of the original).
    metrics
        Its results.json-style metrics (:func:`solver.dynamics.metrics.residual_metrics`).
    model
        The refitted (mass-fitted) model.
    seconds
        Wall time, s.
    """

    trial: ProcessedTrial
    metrics: dict[str, Any]
    model: OsimModel
    seconds: float


def refit_trial(
    trial: ProcessedTrial,
    model: OsimModel,
    forces: ForceRecording,
    *,
    mass_kg: float,
    feet: tuple[str, ...],
    unmeasured: BoolArray | None,
    known_unmeasured: BoolArray | None = None,
    observed: np.ndarray | None = None,
    settings: Mapping[str, Any] | None = None,
    proposal_q: NDArray[np.float64] | None = None,
) -> Refit:
    """Run the dynamics stage again on one processed trial.

    Parameters
    ----------
    trial
        The processed trial (its coordinates start the fit).
    model
        The model to fit with (the processed model, possibly with changed body masses).
    forces
        The raw force recording with the extension's corrections.
    mass_kg
        Stated mass for the stage's thresholds.
    feet
        Foot bodies.
    unmeasured
        ``(T,)`` frames with unmeasured force on the trial's frames that replace the stage's
        own proposals (a reviewer's flags), or None to keep the proposals.
    known_unmeasured
        ``(T,)`` frames with unmeasured force that join the proposals (saved extensions,
        the ``unmeasured_force`` extension), or None.
    observed
        ``(T, M, 3)`` observed markers to fit (default: the trial's).
    settings
        The trial's processing settings (cut-off, filter order, fit weights).
    proposal_q
        ``(T, n)`` coordinates on the trial's frames on which feet are assigned and
        unmeasured frames proposed (default: the processed ones; see
        :func:`solver.dynamics.stage.run_dynamics`).
    """
    import time

    t0 = time.perf_counter()
    st = dict(settings or trial.settings or {})
    fit = dict(st.get("fit", {}) or {})
    fit_fields = {k: v for k, v in fit.items() if k in FitSettings.__dataclass_fields__}
    fit_fields.update(rounds=REFIT_ROUNDS, iterations=REFIT_ITERATIONS)
    opts = DynamicsOptions(
        rate_hz=float(st.get("rate_hz", trial.rate_hz)),
        cutoff_hz=float(st.get("cutoff_hz", 30.0)),
        filter_order=int(st.get("filter_order", 3)),
        alpha=float(st.get("alpha", 1e-6)),
        fit=FitSettings(**fit_fields),
    )
    obs = trial.observed if observed is None else observed
    sk = Skeleton(model)
    kin = KinematicsResult(
        model=model,
        body_scales={},
        marker_offsets={},
        trials=(TrialKinematics(trial.trial, trial.time, trial.coordinate_names, trial.q, trial.marker_names, obs, sk.marker_positions(trial.q, sk.marker_index(list(trial.marker_names)))),),
    )
    markers = MarkerTrajectories(trial.marker_names, obs, trial.time, trial.rate_hz)
    if unmeasured is not None:  # onto the refit's frames (other ones when a correction shifts the forces in time)
        frames = trial_frames(markers, forces, opts.rate_hz, trial.trial)
        unmeasured = resample_mask(unmeasured, trial.time, frames)
    dyn = run_dynamics(
        kin,
        [(trial.trial, markers, forces)],
        mass_kg=mass_kg,
        foot_bodies=feet,
        height_m=trial.height_m,
        unmeasured_force=None if unmeasured is None else {trial.trial: np.asarray(unmeasured, dtype=bool)},
        known_unmeasured=None if known_unmeasured is None else {trial.trial: np.asarray(known_unmeasured, dtype=bool)},
        options=opts,
        proposal_q=None if proposal_q is None else {trial.trial: proposal_q},
    )
    if dyn is None:  # pragma: no cover - the trial had forces when it was processed
        raise ValueError(f"trial {trial.trial} has no force data to refit")
    td = dyn.trial(trial.trial)
    after = processed_from_dynamics(trial, td, dyn)
    return Refit(after, dict(td.metrics, mass_kg=dyn.mass_kg), dyn.model, time.perf_counter() - t0)


def processed_from_dynamics(template: ProcessedTrial, td: TrialDynamics, dyn: DynamicsResult) -> ProcessedTrial:
    """A :class:`ProcessedTrial` from a dynamics result, other fields from ``template``."""
    from solver.model.rotations import rotations_to_wxyz

    sk = Skeleton(dyn.model)
    rot, pos = sk.body_poses(td.q)
    return replace(
        template,
        time=td.time,
        q=td.q,
        qd=td.qd,
        qdd=td.qdd,
        observed=td.observed_markers,
        modeled=sk.marker_positions(td.q, sk.marker_index(list(td.marker_names))),
        body_position=pos,
        body_wxyz=rotations_to_wxyz(rot),
        plates=td.plates,
        mass_kg=dyn.mass_kg,
        com=td.com,
        com_acc=td.com_acc,
        residual_force=td.residual_force,
        residual_moment=td.residual_moment,
        tau=td.tau,
        unobserved=td.unobserved,
        proposed=td.contact.proposed,
        proposal_reasons=tuple(td.contact.reasons),
        metrics=dict(td.metrics),
    )
