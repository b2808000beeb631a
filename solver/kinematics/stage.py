"""The kinematics stage: scale the model and solve inverse kinematics for every trial.

Steps (each timed in :attr:`KinematicsResult.seconds`):

1. match each trial's markers to the model (name mapping); unmatched markers are listed;
2. pick fit frames from every trial (evenly spaced among the best-observed frames);
3. start from the generic model scaled uniformly to the subject's height, register the
   root rigidly and solve IK on the fit frames;
4. fit body scales, marker offsets and fit-frame coordinates jointly (:mod:`.fit`);
5. optionally attach unmatched markers to bodies (:mod:`.autoplace`) and refit;
6. solve every frame of every trial with the fitted model, warm-started along time (:mod:`.ik`).

:func:`run_ik` is step 6 alone, with a model that is already scaled (OpenSim's
InverseKinematicsTool's job).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from solver.errors import KinematicsError
from solver.io.types import MarkerTrajectories
from solver.kinematics.autoplace import place_markers
from solver.kinematics.fit import (
    FitResult,
    FitSettings,
    ScaleFitProblem,
    fit_model,
    landmark_scale_response,
)
from solver.kinematics.ik import (
    FrameSolver,
    IkSettings,
    initial_pose,
    solve_trajectory,
    solve_trajectory_from,
)
from solver.kinematics.observations import MarkerMatch, match_markers, observations
from solver.kinematics.result import KinematicsResult, TrialKinematics
from solver.kinematics.scale_groups import make_groups, model_height
from solver.model.osim import Marker, OsimModel
from solver.model.scaling import scale_model
from solver.model.skeleton import Skeleton

FloatArray = NDArray[np.float64]
Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class KinematicsOptions:
    """Options of the kinematics stage.

    Attributes
    ----------
    frames_per_trial
        Least number of frames taken from each trial into the scale fit.
    max_fit_frames
        Frames of the scale fit, shared equally between the trials (at least
        ``frames_per_trial`` each).
    marker_weights
        Model marker name -> weight (default 1).
    attach_unmatched
        Attach trial markers the model lacks to the best-fitting body (see autoplace).
    symmetric_scales
        Left and right bodies share scale factors.
    fit
        Weights of the joint fit.
    ik
        Settings of the per-frame solver.
    """

    frames_per_trial: int = 2
    max_fit_frames: int = 48
    marker_weights: Mapping[str, float] = field(default_factory=dict)
    attach_unmatched: bool = False
    symmetric_scales: bool = True
    fit: FitSettings = field(default_factory=FitSettings)
    ik: IkSettings = field(default_factory=IkSettings)


def _pick_frames(obs: FloatArray, k: int) -> NDArray[np.intp]:
    """Up to ``k`` evenly spaced frames among those seeing at least 90% of the best count."""
    count = np.isfinite(obs).all(axis=2).sum(axis=1)
    good = np.flatnonzero(count >= 0.9 * count.max())
    if good.size <= k:
        return good
    return good[np.linspace(0, good.size - 1, k).round().astype(int)]


def _initial_fit_poses(solver: FrameSolver, fit_y: FloatArray, trial_of: list[int]) -> FloatArray:
    """Poses of the fit frames with the height-scaled model.

    The first fit frame of each trial is posed from scratch (:func:`initial_pose`); the
    next ones of the same trial start from the previous solution, falling back to a
    fresh start when that ends with more than twice the first frame's error.
    """
    q_init = np.empty((fit_y.shape[0], solver.sk.n))
    ref_cost = np.inf
    for f in range(fit_y.shape[0]):
        n_seen = max(int(np.isfinite(fit_y[f]).all(axis=1).sum()), 1)
        if f == 0 or trial_of[f] != trial_of[f - 1]:
            q, cost = solver.solve(initial_pose(solver, fit_y[f]), fit_y[f], max_iterations=60)
            ref_cost = cost / n_seen
        else:
            q, cost = solver.solve(q_init[f - 1], fit_y[f], max_iterations=60)
            if cost / n_seen > 2.0 * ref_cost:
                q2, cost2 = solver.solve(initial_pose(solver, fit_y[f]), fit_y[f], max_iterations=60)
                if cost2 < cost:
                    q, cost = q2, cost2
        q_init[f] = q
    return q_init


#: Marker RMS error (m) over which a trial's fit is warned about: far past any lab's
#: marker error (the shared trials fit at 0.7-1.3 cm), it means the markers and the model
#: disagree in units or identity (a TRC's Units line, ``heightM`` in the wrong unit, a
#: marker set mapped to the wrong landmarks).
GROSS_RMS_M = 0.10


def _scale_fit(problem: ScaleFitProblem, q0: FloatArray, scales0: FloatArray, trials: Sequence[tuple[str, MarkerTrajectories]]) -> FitResult:
    """:func:`fit_model`, with a scale the fit drives to zero or below (markers and model
    apart by far more than any subject's size: a unit error) reported as such.

    Raises
    ------
    KinematicsError
        The fit asked for a non-positive scale factor, naming the marker files.
    """
    from solver.errors import ScaleFactorError

    try:
        return fit_model(problem, q0, scales0)
    except ScaleFactorError as exc:
        files = ", ".join(str(m.source) for _, m in trials if m.source) or "the marker files"
        raise KinematicsError(
            f"the scale fit drove a body's size to zero or below ({exc.message}): the markers and the model are far "
            f"apart in size; check the Units line of {files} (mm or m) and heightM"
        ) from None


def _warn_gross_errors(results: Sequence[TrialKinematics]) -> None:
    """Warn (UserWarning) about each trial whose marker RMS error exceeds :data:`GROSS_RMS_M`."""
    import warnings

    for trial in results:
        if trial.marker_rms > GROSS_RMS_M:
            warnings.warn(
                f"trial {trial.name}: marker RMS error {100 * trial.marker_rms:.1f} cm after scaling and inverse "
                "kinematics; the markers and the model disagree: check the marker file's Units line (mm or m), "
                "heightM, and that the marker names match the model's",
                UserWarning,
                stacklevel=3,
            )


def run_kinematics(
    generic: OsimModel,
    trials: Sequence[tuple[str, MarkerTrajectories]],
    *,
    height_m: float | None = None,
    mapping: Mapping[str, str] | None = None,
    options: KinematicsOptions | None = None,
    progress: Progress | None = None,
    ik_trials: Collection[str] | None = None,
) -> KinematicsResult:
    """Scale ``generic`` to the subject and solve IK for every trial (or those of ``ik_trials``).

    Parameters
    ----------
    generic
        The unscaled model.
    trials
        ``(name, markers)`` of every trial of the subject (static trials included).
    height_m
        Subject height, m; None uses the model's own height (scale prior at 1).
    mapping
        Lab marker name -> model marker name.
    options
        Stage options.
    progress
        Called with (message, fraction done) as the stage advances.
    ik_trials
        Names of the trials whose motion is wanted: the scale fit uses every trial, the
        final IK runs on these only (None: every trial).

    Returns
    -------
    KinematicsResult
        Its ``trials`` are those of ``ik_trials``, in the order of ``trials``.

    Raises
    ------
    KinematicsError, MarkerMismatchError
        No trials, a trial with zero frames, no marker in common with the model, or every
        matched marker missing; the message names the trial.
    """
    opts = options or KinematicsOptions()
    say = progress or (lambda msg, frac: None)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    model_marker_names = [m.name for m in generic.markers]
    matches, columns = _match_trials(generic, trials, mapping)
    union = sorted({n for m in matches for n in m.model_markers}, key=model_marker_names.index)
    unmatched = sorted({n for m in matches for n in m.unmatched}) if opts.attach_unmatched else []

    # fit frames; trial_of[f] says which trial fit frame f is from
    per_trial = max(opts.frames_per_trial, opts.max_fit_frames // len(trials))
    picked = []
    for k, ((_, markers), match) in enumerate(zip(trials, matches)):
        frames = _pick_frames(markers.positions[:, list(match.trial_columns)], per_trial)
        picked += [(k, int(f)) for f in frames]
    trial_of = [k for k, _ in picked]

    def gather(names: list[str]) -> FloatArray:
        out = np.full((len(picked), len(names), 3), np.nan)
        for i, (k, f) in enumerate(picked):
            for j, n in enumerate(names):
                c = columns[k].get(n)
                if c is not None:
                    out[i, j] = trials[k][1].positions[f, c]
        return out

    fit_y = gather(union)
    keep = np.isfinite(fit_y).all(axis=2).any(axis=0)
    union = [n for n, ok in zip(union, keep) if ok]
    fit_y = fit_y[:, keep]
    weights = np.array([float(opts.marker_weights.get(n, 1.0)) for n in union])
    bodies = {m.body for m in generic.markers if m.name in set(union)}
    groups = make_groups(generic, bodies, symmetric=opts.symmetric_scales)
    generic_sk = Skeleton(generic)
    h_scale = 1.0 if height_m is None else float(height_m) / model_height(generic_sk)
    timings["setup"] = time.perf_counter() - t0

    # initial poses with the height-scaled model
    say("initial poses", 0.05)
    t1 = time.perf_counter()
    scales0 = np.full(groups.n_params, h_scale)
    init_sk = Skeleton(scale_model(generic, groups.body_scales(scales0)))
    init_solver = FrameSolver(init_sk, init_sk.marker_index(union), weights, opts.ik)
    q_init = _initial_fit_poses(init_solver, fit_y, trial_of)
    timings["initial_poses"] = time.perf_counter() - t1

    say("scale fit", 0.2)
    t2 = time.perf_counter()
    problem = ScaleFitProblem(generic, groups, union, fit_y, weights, h_scale, opts.fit)
    fit = _scale_fit(problem, q_init, scales0, trials)
    attached: dict[str, str] = {}
    if unmatched:
        say("attaching unmatched markers", 0.3)
        placed, _ = place_markers(fit.skeleton, fit.q, gather(unmatched), unmatched)
        if placed:
            body_scales = groups.body_scales(fit.scales)
            new = tuple(Marker(p.name, p.body, tuple(np.array(p.location) / body_scales[p.body]), False) for p in placed)
            generic = generic.with_markers(generic.markers + new)
            attached = {p.name: p.body for p in placed}
            union = union + [p.name for p in placed]
            fit_y = np.concatenate([fit_y, gather([p.name for p in placed])], axis=1)
            weights = np.append(weights, np.ones(len(placed)))
            problem = ScaleFitProblem(generic, groups, union, fit_y, weights, h_scale, opts.fit)
            fit = _scale_fit(problem, fit.q, fit.scales, trials)
    in_fit = set(union)
    landmarks = [m.name for m in generic.markers if m.fixed and m.name in in_fit]
    fit_trial = np.array(trial_of)
    response = landmark_scale_response(problem, fit, landmarks, {name: fit_trial == k for k, (name, _) in enumerate(trials)})
    timings["scale_fit"] = time.perf_counter() - t2

    # final IK of every trial with the fitted model
    t3 = time.perf_counter()
    sk = fit.skeleton
    results = []
    solved = [k for k, (name, _) in enumerate(trials) if ik_trials is None or name in ik_trials]
    for i, k in enumerate(solved):
        (name, markers), match = trials[k], matches[k]
        say(f"inverse kinematics: {name}", 0.4 + 0.6 * i / len(solved))
        names = [n for n in (*match.model_markers, *match.unmatched) if n in in_fit]
        w = np.array([weights[union.index(n)] for n in names])
        unmatched_k = tuple(n for n in match.unmatched if n not in attached)
        results.append(_trial_ik(sk, name, markers, names, columns[k], w, unmatched_k, opts.ik))
    timings["ik"] = time.perf_counter() - t3
    timings["total"] = time.perf_counter() - t0
    _warn_gross_errors(results)
    say("kinematics done", 1.0)
    body_scales = {b: tuple(float(v) for v in s) for b, s in groups.body_scales(fit.scales).items()}
    offsets = {n: tuple(float(v) for v in d) for n, d in zip(union, fit.offsets)}
    return KinematicsResult(
        model=fit.model,
        body_scales=body_scales,
        marker_offsets=offsets,
        trials=tuple(results),
        attached=attached,
        fit_marker_rms=fit.marker_rms,
        seconds=timings,
        landmark_scale_response={
            t: {n: tuple(tuple(float(v) for v in row) for row in m) for n, m in r.items()} for t, r in response.items()
        },
    )


def _trial_ik(
    sk: Skeleton,
    name: str,
    markers: MarkerTrajectories,
    names: Sequence[str],
    columns: Mapping[str, int],
    weights: FloatArray,
    unmatched: tuple[str, ...],
    settings: IkSettings,
) -> TrialKinematics:
    """Inverse kinematics of one trial with the model ``sk``: the first frame that sees a
    marker posed from scratch (:func:`initial_pose`), then every frame in time order
    (:func:`solve_trajectory`). When that frame sees fewer than half the markers of the
    best-observed frame (a subject walking into the capture volume, as in opensim-core's
    C3D walks, whose first frames see one marker), the best-observed frame is posed instead
    and the trial solved forwards and backwards from it (:func:`solve_trajectory_from`, as
    :func:`solve_trajectory_from_best_frame` does). ``names`` are the model markers used,
    ``columns`` their columns in ``markers``, ``weights`` ``(len(names),)`` their weights."""
    ts = time.perf_counter()
    y = np.array(markers.positions[:, [columns[n] for n in names]])
    index = sk.marker_index(list(names))
    solver = FrameSolver(sk, index, weights, settings)
    n_seen = np.isfinite(y).all(axis=2).sum(axis=1)
    first, best = int(np.argmax(n_seen > 0)), int(np.argmax(n_seen))
    if 2 * n_seen[first] < n_seen[best]:
        q = solve_trajectory_from(solver, y, best, initial_pose(solver, y[best]))
    else:
        q = solve_trajectory(solver, y, initial_pose(solver, y[first]))
    return TrialKinematics(
        name=name,
        time=markers.time,
        coordinate_names=sk.coordinate_names,
        q=q,
        marker_names=tuple(names),
        observed=y,
        modeled=sk.marker_positions(q, index),
        unmatched=unmatched,
        seconds=time.perf_counter() - ts,
    )


def _match_trials(
    model: OsimModel, trials: Sequence[tuple[str, MarkerTrajectories]], mapping: Mapping[str, str] | None
) -> tuple[list[MarkerMatch], list[dict[str, int]]]:
    """Each trial's marker match with ``model``'s markers (validated: frames, all-NaN
    markers) and the column of each of its (lab or model) marker names; raises
    :class:`KinematicsError` when there is no trial."""
    if not trials:
        raise KinematicsError("no trials to solve", path=model.source)
    names = [m.name for m in model.markers]
    matches: list[MarkerMatch] = []
    for name, markers in trials:
        match = match_markers(markers, names, mapping, trial_name=name)
        observations(markers, match, trial_name=name)  # validates: frames, all-NaN markers
        matches.append(match)
    columns = [
        {**{lab: i for i, lab in enumerate(m.names)}, **dict(zip(match.model_markers, match.trial_columns))}
        for (_, m), match in zip(trials, matches)
    ]
    return matches, columns


def run_ik(
    model: OsimModel,
    trials: Sequence[tuple[str, MarkerTrajectories]],
    *,
    mapping: Mapping[str, str] | None = None,
    options: KinematicsOptions | None = None,
    progress: Progress | None = None,
) -> KinematicsResult:
    """Inverse kinematics alone, with ``model`` taken as already scaled: the job of
    OpenSim's InverseKinematicsTool (no scale fit, no marker placement).

    Every model marker a trial records is used, weighted by ``options.marker_weights``;
    each trial is solved as by :func:`run_kinematics`'s last step, so the model that
    :func:`run_kinematics` fitted, written and read back, gives the same coordinates.

    Parameters
    ----------
    model
        The scaled model (e.g. ``<subject>_scaled.osim`` of an earlier ``addb kinematics``).
    trials
        ``(name, markers)`` of the trials to solve.
    mapping
        Lab marker name -> model marker name.
    options
        Stage options (``ik`` and ``marker_weights`` are used).
    progress
        Called with (message, fraction done) as the stage advances.

    Returns
    -------
    KinematicsResult
        With ``model`` as given, no body scales and no marker offsets.

    Raises
    ------
    KinematicsError, MarkerMismatchError
        As :func:`run_kinematics`: bad trials or markers, named.
    """
    t0 = time.perf_counter()
    opts = options or KinematicsOptions()
    say = progress or (lambda msg, frac: None)
    matches, columns = _match_trials(model, trials, mapping)
    sk = Skeleton(model)
    results = []
    for k, ((name, markers), match) in enumerate(zip(trials, matches)):
        say(f"inverse kinematics: {name}", 0.1 + 0.9 * k / len(trials))
        names = list(match.model_markers)
        w = np.array([float(opts.marker_weights.get(n, 1.0)) for n in names])
        results.append(_trial_ik(sk, name, markers, names, columns[k], w, tuple(match.unmatched), opts.ik))
    seconds = time.perf_counter() - t0
    _warn_gross_errors(results)
    say("kinematics done", 1.0)
    return KinematicsResult(model=model, body_scales={}, marker_offsets={}, trials=tuple(results), seconds={"ik": seconds, "total": seconds})
