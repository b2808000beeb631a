"""Cross-validation, scores and the choice of a cause.

Frames are cut into contiguous blocks of ``block_seconds`` assigned to ``folds`` folds in
turn (block b -> fold b mod K). Each alternative is fitted K times on the other folds and
scored on the held-out one, so every frame is scored once by parameters that did not see
it. For an alternative with k parameters:

    held-out gain   G = sum over held-out frames of (reference cost - extension cost)
    score           S = G - k log(T)          (a BIC-like charge per parameter, T frames)
    relative gain   g = G / (reference cost of the channels the cause acts on)

``unmeasured_force`` has no global parameters (each frame of U gets its own free wrench,
6 per frame): its gain is the same in and out of sample and the charge is 6 |U| log(T).
The estimate reported is the fit on all frames; its uncertainty is the jackknife
standard error over the K fold fits, which (unlike a least-squares covariance with white
noise) respects the strong correlation of residuals between neighbouring frames.

A cause is chosen when its best alternative (plate or marker) passes :class:`ChoiceRule`;
otherwise no cause stands out.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from solver.diagnose.candidates import (
    Alternative,
    FixedAlternative,
    GridAlternative,
    LinearAlternative,
)
from solver.diagnose.causes.registry import CAUSES, cause

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


def make_folds(n_frames: int, dt: float, folds: int = 5, block_seconds: float = 0.2, mix_phases: bool = False) -> IntArray:
    """``(T,)`` fold index of each frame: contiguous blocks dealt to the folds in turn, or so
    that each fold mixes the phases of a periodic movement.

    In turn, block b goes to fold ``b mod K``: a fold's blocks sit K x ``block_seconds``
    apart (1.0 s by default), about one stride of a walk, so each fold holds nearly one phase
    of the gait cycle. With ``mix_phases``, block b goes to fold ``(b + b // K) mod K``: the
    first K blocks as in turn, the next K rotated by one, and so on, so each fold holds
    blocks from different phases. Both keep every block contiguous and the folds' sizes
    within one block of each other. Which causes use which: :class:`Folds`.

    Parameters
    ----------
    n_frames
        T.
    dt
        Frame interval, s.
    folds
        K; fewer when the trial has fewer than 2 K blocks.
    block_seconds
        Block length, s.
    mix_phases
        Deal so that each fold mixes the phases (above).
    """
    blocks = make_blocks(n_frames, dt, block_seconds)
    n_blocks = int(blocks[-1]) + 1 if n_frames else 0
    k = int(max(2, min(folds, n_blocks // 2)))
    return ((blocks + blocks // k) % k if mix_phases else blocks % k).astype(np.intp)


@dataclass(frozen=True)
class Folds:
    """The cross-validation folds of one trial, in both dealings of :func:`make_folds`;
    each cause's alternatives use the dealing its
    :attr:`~solver.diagnose.causes.base.Cause.folds_mix_phases` asks for.

    Attributes
    ----------
    in_turn, mixing
        ``(T,)`` fold of each frame, blocks dealt in turn and mixing the phases.
    """

    in_turn: IntArray
    mixing: IntArray

    @classmethod
    def of_trial(cls, n_frames: int, dt: float, folds: int = 5, block_seconds: float = 0.2) -> Folds:
        """Both dealings for a trial of ``n_frames`` frames ``dt`` s apart."""
        return cls(make_folds(n_frames, dt, folds, block_seconds), make_folds(n_frames, dt, folds, block_seconds, mix_phases=True))

    def of(self, cause_name: str) -> IntArray:
        """``(T,)`` the folds the cause's alternatives are cross-validated on.

        Raises
        ------
        solver.diagnose.causes.registry.UnknownCause
            No registered cause has that name.
        """
        return self.mixing if cause(cause_name).folds_mix_phases else self.in_turn

    @property
    def count(self) -> int:
        """K, the number of folds."""
        return int(self.in_turn.max()) + 1


@dataclass
class Evaluation:
    """The cross-validated evaluation of one alternative.

    Attributes
    ----------
    cause, choice
        Cause name and plate/marker (None when the cause has no choice).
    parameters
        Fit on all frames, in their units (``value`` is the reported vector).
    uncertainty
        Jackknife standard error of ``value`` over the folds (same shape), or None.
    n_params
        Parameters charged.
    gain
        Held-out gain G (cost units).
    reference
        Held-out reference cost of the cause's channels, on the frames it acts on
        (``acts_on`` of the alternative: a plate shift only where its plate is loaded).
    fold_gains
        ``(K,)`` G per fold.
    score
        S = G - n_params log T.
    motion
        The motion the costs were computed on: ``"fitted"`` (the processed motion) or
        ``"marker-only"`` (:func:`solver.diagnose.data.marker_kinematics`).
    """

    cause: str
    choice: str | None
    parameters: dict[str, Any]
    uncertainty: Any
    n_params: int
    gain: float
    reference: float
    fold_gains: FloatArray
    score: float
    held_out_costs: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    reference_costs: FloatArray = field(repr=False, default_factory=lambda: np.zeros(0))
    parameters_fitted_motion: dict[str, Any] | None = None
    uncertainty_fitted_motion: Any = None
    motion: str = "fitted"

    @property
    def estimates(self) -> list[dict[str, Any]]:
        """The estimates that must all be worth naming for this alternative to contend: the
        reported one and, when scored on the fitted motion, that motion's own estimate too
        (a cause that matters on one motion and is negligible on the other is not robust,
        and the extension saved, the reported estimate, would change nothing)."""
        if self.motion == "fitted" and self.parameters_fitted_motion is not None:
            return [self.parameters, self.parameters_fitted_motion]
        return [self.parameters]

    def block_gains(self, blocks: IntArray) -> FloatArray:
        """``(B,)`` held-out gain of each block of frames (``blocks`` ``(T,)`` block index)."""
        return np.bincount(blocks, weights=self.reference_costs - self.held_out_costs, minlength=int(blocks.max()) + 1)

    @property
    def relative_gain(self) -> float:
        """G over the reference cost of the cause's channels (0 when that is 0)."""
        return float(self.gain / self.reference) if self.reference > 0 else 0.0

    @property
    def folds_improved(self) -> float:
        """Fraction of the folds the extension changes whose held-out cost went down."""
        changed = self.fold_gains != 0
        return float(np.mean(self.fold_gains[changed] > 0)) if changed.any() else 0.0


def cross_validate(alt: Alternative, folds: IntArray) -> Evaluation:
    """Fit ``alt`` on K-1 folds, score on the held-out one, for every fold (``folds``
    ``(T,)``: fold of each frame, 0 to K-1)."""
    t = folds.size
    k = int(folds.max()) + 1
    ref = alt.ref_costs
    held = np.empty(t)
    thetas = []
    fold_gains = np.empty(k)
    for f in range(k):
        test = folds == f
        theta = alt.solve(~test)
        thetas.append(theta)
        costs = alt.frame_costs(theta)
        held[test] = costs[test]
        fold_gains[f] = float(np.sum(ref[test] - costs[test]))
    theta_all = alt.solve(np.ones(t, dtype=bool))
    params = alt.physical(theta_all)
    unc = None
    if alt.n_params and not isinstance(alt, FixedAlternative):
        vecs = np.array([alt.vector(th) for th in thetas])
        jack = np.sqrt((k - 1) / k * np.sum((vecs - vecs.mean(axis=0)) ** 2, axis=0))
        unc = jack.tolist() if jack.size > 1 else float(jack[0])
    gain = float(np.sum(ref - held))
    score = gain - alt.n_params * np.log(t)
    reference = float(np.sum(ref if alt.acts_on is None else ref[alt.acts_on]))
    return Evaluation(alt.cause, alt.choice, params, unc, alt.n_params, gain, reference, fold_gains, float(score), held, ref)


@dataclass(frozen=True)
class ChoiceRule:
    """When a cause is named (all must hold for the best-scoring alternative).

    Attributes
    ----------
    min_relative_gain
        Its held-out gain removes at least this fraction of the reference cost of its channels.
    relative_gain_of
        Cause -> its own ``min_relative_gain`` (default: each cause's
        :attr:`~solver.diagnose.causes.base.Cause.min_relative_gain` that is set).
        ``segment_mass_distribution``'s channels
        carry every marker's error and the whole motion's prior (:mod:`.motion_profile`),
        which no mass changes: a hidden 4-9 % redistribution removes 0.3-6 % of them, a
        consistent synthetic trial's estimate of under 1 kg 0.1-0.5 % (2026-11-23). It is
        judged by its effect size, its t and its folds instead.
    min_folds_improved
        At least this fraction of the folds improve on held-out frames.
    runner_up_ratio, paired_t, paired_fraction
        It stands out from the best alternative of any *other* cause when that one's score
        is at most ``runner_up_ratio`` of its score, or when, block by block of held-out
        frames, it does better with a paired t statistic of at least ``paired_t`` in at
        least ``paired_fraction`` of the blocks.
    kept_share
        ... or when, fitted together with that rival (:class:`JointGains`), it keeps at
        least this share of its own held-out gain: the two explain different parts of the
        residual, so both may be true and the rival does not stand in its way (on the
        treadmill run's marker-only motion a hidden 2-4 cm plate shift keeps 93-109 % of its
        gain on top of the trial's own 6 ms force delay, and the delay 85-115 % on top of the
        shift, while a plate's zero drift keeps 3-8 % of its gain on top of that plate's
        shift; 2026-11-23).
        Causes that overlap (:attr:`solver.diagnose.causes.base.Cause.overlaps`) need
        ``1 - kept_share`` of it (:func:`_stands_out`).
    contained_share
        ... or when it keeps at least this share of its gain on top of a rival that keeps
        nothing (a share of at most 0) on top of it: what the rival explains, it explains
        too (:func:`_stands_out`; since 2026-11-24).
        Neither is used for :attr:`distinct_choice`: a centre of mass misplaced in the model moves
        the moment under each plate on that plate's own stances, so the two plates' shifts
        explain different frames and would both be kept.
    min_effect
        Cause -> smallest effect worth naming (in the units of :func:`effect_size`; default:
        each cause's :attr:`~solver.diagnose.causes.base.Cause.min_effect`).
    max_effect
        Cause -> largest plausible effect (default: each cause's finite
        :attr:`~solver.diagnose.causes.base.Cause.max_effect`): a larger estimate (a segment gaining three times
        its mass, a 50 % gain error) means the cause is fitting something else, and it is
        no contender.
    min_t
        The reported estimate must lie at least this many jackknife standard errors from
        "no effect" (:func:`t_value`): on opensim-core's C3D walk, once both plates' zero
        drift was applied, a body-mass change of -7.2 ± 4.2 kg that removed 11 % of the
        held-out cost in one motion and 3 % in the other was named otherwise (the plates,
        zeroed, give the stated 66 kg).
    distinct_choice
        Causes whose named plate must also stand out, by the same test, from the same cause
        on the other plates (default: those with
        :attr:`~solver.diagnose.causes.base.Cause.distinct_choice`). A centre of mass misplaced in the model moves the moment under
        both feet alike, which a shift of either plate mimics (two walk draws hiding a 4.5-5.4
        kg redistribution: the right plate's shift scored 409 and 350, the left one's 349 and
        295), and the fitted motion absorbs the redistribution itself; a misplaced plate
        stands out from the other one (in five captured draws of a hidden shift that were
        named, the hidden plate's shift scored 3.9 to 270 times the other's, or the other's
        score was negative).
    min_confirming_gain
        A cause confirmed on the marker-only motion
        (:attr:`~solver.diagnose.causes.base.Cause.confirmed_on_marker_motion`, the plates'
        registration) is a candidate on the fitted motion only when its twin there removes
        at least this share of its channels' cost (:func:`confirmed`; 0: it does not make
        that motion's cost worse). Any share from 0 to 3 % named the same draws in the
        replay of 380 captured draws (tests/benchmarks/RESULTS.md, block
        ``diagnose-rule-confirmed-alternation``; 2026-11-27).
    """

    min_relative_gain: float = 0.10
    relative_gain_of: dict[str, float] = field(
        default_factory=lambda: {c.name: c.min_relative_gain for c in CAUSES if c.min_relative_gain is not None}
    )
    min_folds_improved: float = 0.8
    runner_up_ratio: float = 0.6
    paired_t: float = 2.0
    paired_fraction: float = 0.6
    min_effect: dict[str, float] = field(default_factory=lambda: {c.name: c.min_effect for c in CAUSES})
    max_effect: dict[str, float] = field(default_factory=lambda: {c.name: c.max_effect for c in CAUSES if np.isfinite(c.max_effect)})
    distinct_choice: tuple[str, ...] = field(default_factory=lambda: tuple(c.name for c in CAUSES if c.distinct_choice))
    min_t: float = 2.0
    kept_share: float = 0.8
    contained_share: float = 0.1
    min_confirming_gain: float = 0.0

    def relative_gain_needed(self, cause: str) -> float:
        """The smallest relative gain that names ``cause``."""
        return self.relative_gain_of.get(cause, self.min_relative_gain)


def channels(cause_name: str) -> str:
    """``"markers"``, ``"motion"``, ``"frames"`` or ``"residuals"``: what the cause explains
    (:attr:`solver.diagnose.causes.base.Cause.channel`).

    Causes on different channels explain different residuals and may both be true at once,
    so they do not stand in each other's way (:func:`choose`): a marker offset acts on its
    marker's own error; a cause on the whole-motion profile's channels (:mod:`.motion_profile`,
    the root residual with every coordinate re-optimized) is named only when no cause on the
    other channels stands out, since re-optimizing the whole motion leaves it the weakest
    evidence (a fraction of a per cent of its channels' cost) and any force error also leaves
    a trace there; ``unmeasured_force`` takes its frames U out of the residual terms, and
    every other cause is evaluated with U already out
    (:func:`solver.diagnose.core.build_context`): its gain is measured on top of U's, so the
    two are not alternatives and may both be true (opensim-core's C3D walk: after its steps
    off the plates were applied, six more frames of a foot on the floor stood in the way of
    a plate's zero drift that is real).

    Raises
    ------
    solver.diagnose.causes.registry.UnknownCause
        No registered cause has that name.
    """
    return cause(cause_name).channel


def effect_size(ev: Evaluation, parameters: dict[str, Any] | None = None) -> float:
    """The magnitude compared with :attr:`ChoiceRule.min_effect` (units per cause,
    :meth:`solver.diagnose.causes.base.Cause.effect_size`) of ``parameters`` (default: the
    evaluation's reported ones).

    Raises
    ------
    solver.diagnose.causes.registry.UnknownCause
        No registered cause has the evaluation's name (a cause left out of the registry is
        an error, not an effect of size zero).
    """
    return cause(ev.cause).effect_size(ev.parameters if parameters is None else parameters)


def t_value(ev: Evaluation, parameters: dict[str, Any] | None = None, uncertainty: Any = None) -> float:
    """Distance of the reported estimate (or ``parameters`` with ``uncertainty``) from "no
    effect" (:meth:`solver.diagnose.causes.base.Cause.deviation`: zero, or a gain of 1) in
    jackknife standard errors (vector estimates: norm over norm); ``inf`` when the estimate
    has no uncertainty (``unmeasured_force``'s frames)."""
    p, unc = (ev.parameters, ev.uncertainty) if parameters is None else (parameters, uncertainty)
    if unc is None or "value" not in p:
        return float("inf")
    value = cause(ev.cause).deviation(p)
    se = float(np.linalg.norm(np.atleast_1d(np.asarray(unc, dtype=float))))
    size = float(np.linalg.norm(value))
    return size / se if se > 0 else float("inf")


def significance(ev: Evaluation) -> float:
    """The largest :func:`t_value` of the estimates of ``ev`` (:attr:`Evaluation.estimates`):
    the reported one and, when scored on the fitted motion, that motion's own.

    An effect must be told from noise on one of the two motions, and be worth naming on
    both (:func:`contends`). The fitted motion's estimate is pulled toward the forces (a
    walk's hidden plate shift comes back at about half its size) but carries little noise;
    the marker-only motion's is unbiased, but one foot strike's transient can swing it
    between folds (the walk's left plate bears one stance of 74 frames: a hidden 2.7 cm
    shift is 4.3 jackknife errors from zero on the fitted motion, 1.6 on the marker-only
    one, where leaving out 20 of those frames moves it by 1.1 cm).
    """
    t = t_value(ev)
    if ev.motion == "fitted" and ev.parameters_fitted_motion is not None:
        t = max(t, t_value(ev, ev.parameters_fitted_motion, ev.uncertainty_fitted_motion))
    return t


def contends(ev: Evaluation, rule: ChoiceRule) -> bool:
    """Whether every estimate of ``ev`` is worth naming and plausible (its size within
    :meth:`ChoiceRule` bounds, and :meth:`solver.diagnose.causes.base.Cause.plausible`) and
    one of them lies at least ``rule.min_t`` standard errors from no effect (:func:`significance`)."""
    lo, hi = rule.min_effect.get(ev.cause, 0.0), rule.max_effect.get(ev.cause, np.inf)
    c = cause(ev.cause)
    return all(lo <= c.effect_size(p) <= hi and c.plausible(p) for p in ev.estimates) and significance(ev) >= rule.min_t


def best_per_cause(evaluations: list[Evaluation], rule: ChoiceRule | None = None) -> list[Evaluation]:
    """The best-scoring alternative of each cause, best first.

    With ``rule``, the best of a cause whose alternatives each act on a channel of their own
    (channel ``markers``: a marker's offset explains that marker's error only) is
    the best that stands out on its own channel (:func:`stands_out_alone`), else the best
    that :func:`contends`: a marker whose estimate is no effect, or that improves too few
    folds, does not stand in the way of another marker's offset."""
    best: dict[str, Evaluation] = {}
    for ev in evaluations:
        if ev.cause not in best or ev.score > best[ev.cause].score:
            best[ev.cause] = ev
    if rule is not None:
        for c in CAUSES:
            if c.channel != "markers":
                continue
            own = [e for e in evaluations if e.cause == c.name]
            eligible = [e for e in own if stands_out_alone(e, rule)] or [e for e in own if contends(e, rule)]
            if eligible:
                best[c.name] = max(eligible, key=lambda e: e.score)
    return sorted(best.values(), key=lambda e: e.score, reverse=True)


def confirmed(evaluations: list[Evaluation], twins: Mapping[tuple[str, str | None], Evaluation], rule: ChoiceRule) -> list[Evaluation]:
    """``evaluations`` (on the fitted motion) without those of a cause confirmed on the
    marker-only motion (:attr:`~solver.diagnose.causes.base.Cause.confirmed_on_marker_motion`)
    whose twin there (``twins``: ``(cause, choice)`` -> that motion's evaluation) removes
    less than :attr:`ChoiceRule.min_confirming_gain` of its channels' cost; an evaluation
    without a twin stays. The ones left out neither get named from the fitted motion nor
    stand in another's way there (the marker-only motion may still name them,
    :func:`solver.diagnose.core.choice_on_marker_motion`).

    Why: the plates' registration is an error of the force recording, which the motion the
    markers alone decide shows as well; on the fitted motion, a mass misplaced in the model
    leaves a residue the registration explains (tests/benchmarks/RESULTS.md, "A change of
    the rule's structure", 2026-11-27: on draws 0-39 of the walk and the run, segment masses
    35 to 38 of 40 within tolerance, every other row the same, no false alarm).
    """
    out = []
    for ev in evaluations:
        twin = twins.get((ev.cause, ev.choice))
        if cause(ev.cause).confirmed_on_marker_motion and twin is not None and twin.relative_gain < rule.min_confirming_gain:
            continue
        out.append(ev)
    return out


def stands_out_alone(ev: Evaluation, rule: ChoiceRule) -> bool:
    """Whether ``ev`` passes every check of ``rule`` that does not compare it with another
    cause: it contends (:func:`contends`), its score is positive, and it removes
    ``rule.min_relative_gain`` of its channels' held-out cost in ``rule.min_folds_improved``
    of the folds."""
    return (
        contends(ev, rule)
        and ev.score > 0
        and ev.relative_gain >= rule.relative_gain_needed(ev.cause)
        and ev.folds_improved >= rule.min_folds_improved
    )


def also_standing_out(evaluations: list[Evaluation], chosen: Evaluation | None, rule: ChoiceRule) -> list[Evaluation]:
    """Marker offsets other than ``chosen`` that stand out on their own channel
    (:func:`stands_out_alone`). Markers do not compete with each other (each explains its
    own error), so every one of them is a finding; best score first."""
    out = [e for e in evaluations if channels(e.cause) == "markers" and e is not chosen and stands_out_alone(e, rule)]
    return sorted(out, key=lambda e: e.score, reverse=True)


def make_blocks(n_frames: int, dt: float, block_seconds: float = 0.2) -> IntArray:
    """``(T,)`` index of the contiguous block of ``block_seconds`` each frame belongs to."""
    return (np.arange(n_frames) // max(round(block_seconds / dt), 1)).astype(np.intp)


def paired_blocks(best: Evaluation, other: Evaluation, blocks: IntArray) -> tuple[float, float]:
    """Paired comparison of two alternatives over blocks of frames (``blocks`` ``(T,)``: block
    index of each frame, :func:`make_blocks`).

    Returns
    -------
    t, fraction
        t statistic of the per-block difference of held-out gains (best minus other; blocks
        are treated as independent, which frames are not) and the fraction of the blocks
        where ``best`` does better, among those where they differ.
    """
    d = best.block_gains(blocks) - other.block_gains(blocks)
    differ = d != 0
    if differ.sum() < 3:
        return 0.0, 0.0
    sd = float(np.std(d, ddof=1))
    t = float(np.mean(d) / (sd / np.sqrt(d.size))) if sd > 0 else float("inf")
    return t, float(np.mean(d[differ] > 0))


#: The share of ``best``'s held-out gain it keeps when fitted together with ``rival``, or None
#: when the two cannot be fitted together (:class:`JointGains`).
KeptShare = Callable[[Evaluation, Evaluation], "float | None"]


def joint_held_out(a: Alternative, b: Alternative, folds: IntArray, window: float = 0.012) -> FloatArray | None:
    """``(T,)`` held-out cost of each frame with both extensions fitted together, each fold's
    parameters fitted without it (as :func:`cross_validate`), or None when the two do not
    combine (other channels, or no global parameters).

    Two linear alternatives on the same rows stack their columns (``rows = rho0 + G_a
    theta_a + G_b theta_b``). With the force delay (a 1-D grid), the linear parameters are
    fitted at each delay within ``window`` s of the delay's own estimate and the delay
    with the lowest cost on the fitted folds is kept (the linear columns taken at no
    delay: a few ms move them by a fraction of a per cent).
    """
    t = folds.size
    k = int(folds.max()) + 1
    held = np.empty(t)
    if isinstance(a, GridAlternative) != isinstance(b, GridAlternative):
        grid, lin = (a, b) if isinstance(a, GridAlternative) else (b, a)
        if not isinstance(lin, LinearAlternative):
            return None
        centre = float(grid.solve(np.ones(t, dtype=bool))[0])
        rows = [grid.rows_at(float(tau)) for tau in grid.grid[np.abs(grid.grid - centre) <= window + 1e-9]]
        if lin.rho0.shape != rows[0].shape:
            return None
        # (lin.g and lin.prior already carry its basis)
        probe = LinearAlternative(lin.cause, lin.choice, rows[0], lin.g, lin.physical, lin.names, prior=lin.prior)
        for f in range(k):
            fit = folds != f
            best_cost, best_rows = np.inf, None
            for rho in rows:
                probe.rho0 = rho
                costs = probe.frame_costs(probe.solve(fit))
                if costs[fit].sum() < best_cost:
                    best_cost, best_rows = float(costs[fit].sum()), costs
            held[folds == f] = best_rows[folds == f]
        return held
    if not (isinstance(a, LinearAlternative) and isinstance(b, LinearAlternative)):
        return None
    if a.rho0.shape != b.rho0.shape or not np.array_equal(a.rho0, b.rho0):
        return None
    prior = None
    if a.prior is not None or b.prior is not None:
        pa = a.prior if a.prior is not None else np.zeros((0, a.n_params))
        pb = b.prior if b.prior is not None else np.zeros((0, b.n_params))
        prior = np.block([[pa, np.zeros((pa.shape[0], b.n_params))], [np.zeros((pb.shape[0], a.n_params)), pb]])
    both = LinearAlternative(a.cause, a.choice, a.rho0, np.concatenate([a.g, b.g], axis=2), a.physical, a.names + b.names, prior=prior)
    for f in range(k):
        test = folds == f
        held[test] = both.frame_costs(both.solve(~test))[test]
    return held


class JointGains:
    """Held-out gains of pairs of alternatives fitted together (:func:`joint_held_out`),
    computed on demand and kept.

    Parameters
    ----------
    alternatives
        Every alternative of one motion.
    evaluations
        Their cross-validated evaluations (same order).
    folds
        The trial's folds; a pair is fitted on the folds of its first alternative's cause
        (only alternatives on the same channel combine, :func:`joint_held_out`, and the
        dealing is one per channel).
    """

    def __init__(self, alternatives: list[Alternative], evaluations: list[Evaluation], folds: Folds) -> None:
        self._alt = {id(e): a for a, e in zip(alternatives, evaluations)}
        self._folds = folds
        self._gain: dict[tuple[int, int], float | None] = {}

    def gain(self, a: Evaluation, b: Evaluation) -> float | None:
        """Held-out gain of ``a`` and ``b`` fitted together (cost units), or None."""
        key = (min(id(a), id(b)), max(id(a), id(b)))
        if key not in self._gain:
            alt_a, alt_b = self._alt.get(id(a)), self._alt.get(id(b))
            held = None if alt_a is None or alt_b is None else joint_held_out(alt_a, alt_b, self._folds.of(alt_a.cause))
            self._gain[key] = None if held is None else float(np.sum(alt_a.ref_costs - held))
        return self._gain[key]

    def kept_share(self, best: Evaluation, rival: Evaluation) -> float | None:
        """Share of ``best``'s held-out gain that remains on top of ``rival``'s:
        (G_joint - G_rival) / G_best, or None."""
        g = self.gain(best, rival)
        if g is None or best.gain <= 0:
            return None
        return (g - rival.gain) / best.gain


def _stands_out(
    best: Evaluation,
    rival: Evaluation | None,
    rule: ChoiceRule,
    blocks: IntArray | None,
    kept: KeptShare | None = None,
    tie_break: KeptShare | None = None,
) -> tuple[bool, float, float, float | None]:
    """Whether ``best`` stands out from ``rival`` (score ratio, paired blocks or, with
    ``kept``, the share of its gain it keeps on top of the rival's), with the paired t and
    fraction of blocks (:func:`paired_blocks`) and that share (None if not computed).

    Causes that overlap (:attr:`solver.diagnose.causes.base.Cause.overlaps`: a shift of
    one plate and a shift shared by every plate) explain the same residual on one plate's
    stances and differ on the others, so neither keeps all of its gain on top of the other
    even when both are there. ``best`` stands out from an overlapping ``rival`` when it keeps
    at least ``1 - rule.kept_share`` of its gain on top of it (a part the rival cannot
    explain, and it scores higher); from any other rival when it keeps ``rule.kept_share``.
    When each of two overlapping causes keeps that much on top of the other, ``tie_break``
    (the same shares on another motion: the marker-only one, which no force shaped) decides:
    ``best`` stands out only if it keeps at least as much of its gain on top of the rival
    there as the rival keeps on top of it (since 2026-11-26, on the converged fit: walk draw
    9006, a 1.5 cm shift and a 1 degree turn of both plates, where the left plate's shift,
    its single stance, scored higher and each kept about half of its gain on top of the
    other; on the marker-only motion the registration kept 68 % on top of the shift and the
    shift nothing on top of the registration).
    And from any rival when the rival keeps nothing on top of ``best`` (no held-out gain:
    what the rival explains, ``best`` explains too) while ``best`` keeps at least
    ``rule.contained_share`` of its gain (since 2026-11-24: a walk draw hiding a -40 ms
    force delay, on the marker-only motion, kept 39 % of its gain on top of the plates'
    registration, which kept -2 % on top of the delay; before this clause the fitted
    motion's marker offset was named). Measured on 2026-11-24: a walk draw hiding a
    shared 2.4 cm shift and a 1.1 degree turn of every plate, every plate's registration
    kept 38 % of its gain on top of the left plate's shift and the shift 16 % on top of it
    (marker-only motion: 36 % and -5 %); the same 2.5 cm shift of both walk plates without a
    turn, on the marker-only motion: the registration kept 17 % on top of the right plate's
    shift (the left plate's single stance is all that tells them apart), the shift -3 %; a
    run draw hiding a 3.7 cm shift of belt L: the shift kept 62 % on top of the
    registration, which kept 44 % on top of the shift (the run's own forward reading of both
    belts, docs/diagnose/RESULTS.md).
    """
    if rival is None:
        return True, 0.0, 0.0, None
    t_pair, frac_pair = paired_blocks(best, rival, blocks) if blocks is not None else (0.0, 0.0)
    clear = rival.score <= rule.runner_up_ratio * best.score or (t_pair >= rule.paired_t and frac_pair >= rule.paired_fraction)
    share = None
    if not clear and kept is not None:
        share = kept(best, rival)
        if share is not None:
            enough = rule.kept_share if not overlapping(best.cause, rival.cause) else 1.0 - rule.kept_share
            clear = share >= enough
            if clear and tie_break is not None and overlapping(best.cause, rival.cause):
                back = kept(rival, best)
                if back is not None and back >= enough:  # each keeps enough on top of the other
                    mine, theirs = tie_break(best, rival), tie_break(rival, best)
                    clear = mine is None or theirs is None or mine >= theirs
            if not clear and share >= rule.contained_share:
                back = kept(rival, best)
                clear = back is not None and back <= 0.0
    return clear, t_pair, frac_pair, share


def overlapping(a: str, b: str) -> bool:
    """Whether the causes called ``a`` and ``b`` overlap
    (:attr:`solver.diagnose.causes.base.Cause.overlaps`, either way)."""
    ca, cb = cause(a), cause(b)
    return cb in ca.overlaps or ca in cb.overlaps


class Failed(NamedTuple):
    """A failed check of :class:`ChoiceRule`: ``key`` names the check (``score``,
    ``relative_gain``, ``folds``, ``rival``: another cause explains the residuals nearly as
    well, ``sibling``: the same cause on another plate does), ``text`` says it."""

    key: str
    text: str


def _sentences(failed: list[Failed]) -> str:
    """The failed checks' sentences, joined."""
    return "; ".join(f.text for f in failed)


def _checks(
    best: Evaluation,
    group: list[Evaluation],
    rule: ChoiceRule,
    blocks: IntArray | None,
    alternatives: list[Evaluation] | None,
    kept: KeptShare | None,
    tie_break: KeptShare | None = None,
) -> tuple[Evaluation | None, list[Failed]]:
    """The checks of :class:`ChoiceRule` that ``best`` fails (empty: it stands out) and the
    rival it was compared with. Its rivals are the other contenders of its channel group
    that are not clearly weaker (score above ``runner_up_ratio`` of its own)."""
    rivals = [e for e in group if e is not best and e.score > rule.runner_up_ratio * best.score]
    second = max((e for e in group if e is not best), key=lambda e: e.score, default=None)
    clear, t_pair, frac_pair, share, blocker = True, 0.0, 0.0, None, None
    for rival in sorted(rivals, key=lambda e: e.score, reverse=True):
        clear, t_pair, frac_pair, share = _stands_out(best, rival, rule, blocks, kept, tie_break)
        if not clear:
            blocker = rival
            break
    siblings = [
        e for e in (alternatives or []) if best.cause in rule.distinct_choice and e.cause == best.cause and e.choice != best.choice
    ]
    sibling = max(siblings, key=lambda e: e.score) if siblings else None
    distinct, t_sib, frac_sib, _ = _stands_out(best, sibling, rule, blocks)
    kept_text = "" if share is None else f", and fitted together it keeps {100 * share:.0f}% of its own gain"
    checks = [
        ("score", best.score > 0, f"its score ({best.score:.0f}) is not positive"),
        (
            "relative_gain",
            best.relative_gain >= rule.relative_gain_needed(best.cause),
            f"it removes only {100 * best.relative_gain:.0f}% of the held-out cost (needs {100 * rule.relative_gain_needed(best.cause):.0f}%)",
        ),
        (
            "folds",
            best.folds_improved >= rule.min_folds_improved,
            f"it improves only {100 * best.folds_improved:.0f}% of the held-out folds",
        ),
        (
            "rival",
            clear,
            (
                f"{blocker.cause if blocker else ''} explains the residuals nearly as well "
                f"(score {blocker.score if blocker else 0:.0f} vs {best.score:.0f}; better in {100 * frac_pair:.0f}% of the "
                f"blocks of frames, t = {t_pair:.1f}{kept_text})"
            ),
        ),
        (
            "sibling",
            distinct,
            (
                f"the same cause on {sibling.choice if sibling else ''} explains them nearly as well (score "
                f"{sibling.score if sibling else 0:.0f}; better in {100 * frac_sib:.0f}% of the blocks, t = {t_sib:.1f}), "
                "as a centre of mass misplaced in the model would"
            ),
        ),
    ]
    return second, [Failed(key, msg) for key, ok, msg in checks if not ok]


def _verdict(
    group: list[Evaluation],
    rule: ChoiceRule,
    blocks: IntArray | None,
    alternatives: list[Evaluation] | None,
    kept: KeptShare | None = None,
    tie_break: KeptShare | None = None,
) -> tuple[Evaluation, Evaluation | None, list[Failed]]:
    """The contender of a channel group that stands out (best first), its runner-up and
    the checks it fails (empty: it stands out); when none does, the group's best with its
    failed checks.

    Contenders are tried in score order: one that fails a check of its own (too small a
    share of the cost, too few folds) does not hide a weaker one that passes them all and
    stands out from it (with ``kept``: keeps its gain on top of it, a separate effect)."""
    first: tuple[Evaluation, Evaluation | None, list[Failed]] | None = None
    for best in group:
        second, failed = _checks(best, group, rule, blocks, alternatives, kept, tie_break)
        if not failed:
            return best, second, failed
        if first is None:
            first = (best, second, failed)
        if kept is None:
            break  # without joint fits, only the group's best is tried (the earlier rule)
    assert first is not None
    return first


def choose(
    ranked: list[Evaluation],
    rule: ChoiceRule | None = None,
    blocks: IntArray | None = None,
    alternatives: list[Evaluation] | None = None,
    kept: KeptShare | None = None,
    tie_break: KeptShare | None = None,
) -> tuple[Evaluation | None, str]:
    """The chosen cause (or None) and a sentence saying why.

    The contenders are the causes whose estimates (:attr:`Evaluation.estimates`) are all
    worth naming and plausible (:attr:`ChoiceRule.min_effect`, :attr:`ChoiceRule.max_effect`)
    and told from noise (:func:`significance`); contenders are grouped by the channels they
    act on (:func:`channels`); in each group they are tried in score order against the
    group's other contenders (:func:`_verdict`), and the best-scoring one that passes the
    rule's checks is chosen, one on the whole-motion channels only when no other passes and
    no force error on the residual channels is held back only by a rival
    (channel ``motion``; when none passes, the reason is that of the overall best).

    Parameters
    ----------
    ranked
        Best alternative per cause, best score first (:func:`best_per_cause`).
    rule
        Thresholds.
    blocks
        ``(T,)`` block index of each frame (:func:`make_blocks`) for the paired comparison
        with the runner-up; None: the score ratio alone decides.
    alternatives
        Every evaluated alternative (all plates of each cause), for
        :attr:`ChoiceRule.distinct_choice`; None: that check is skipped.
    kept
        The share of a contender's held-out gain it keeps on top of a rival's
        (:meth:`JointGains.kept_share`); None: rivals are compared by scores and blocks
        alone, and only each group's best is tried.
    tie_break
        The same shares on another motion, for two overlapping causes that each keep enough
        on top of the other (:func:`_stands_out`); None: the higher score stands out.
    """
    rule = rule or ChoiceRule()
    if not ranked:
        return None, "no candidate cause could be evaluated on this trial"
    # a cause whose estimate is negligible (a 1 ms delay, a 0.3 kg mass change) is no
    # contender: it neither gets named nor stands in the way of one that matters
    contenders = [e for e in ranked if contends(e, rule)]
    if not contenders:
        best = ranked[0]
        size = f"{effect_size(best):.3g}"
        if len(best.estimates) > 1:  # the fitted motion's estimate may be the one out of range
            size += f" ({effect_size(best, best.parameters_fitted_motion):.3g} on the fitted motion)"
        return None, (
            f"No cause stands out: every candidate's estimate is negligible, implausible or within "
            f"{rule.min_t:g} standard errors of no effect (the best, {best.cause}, {size}, {significance(best):.1f} "
            f"standard errors; worth naming from {rule.min_effect.get(best.cause, 0.0):g} "
            f"to {rule.max_effect.get(best.cause, np.inf):g})."
        )
    # causes on different channels do not stand in each other's way: the best of each
    # channel group is checked against its own runner-up, and the best that passes is named
    groups: dict[str, list[Evaluation]] = {}
    for e in contenders:
        groups.setdefault(channels(e.cause), []).append(e)
    verdicts = [_verdict(group, rule, blocks, alternatives, kept, tie_break) for group in groups.values()]
    # a cause on the whole-motion channels only when nothing else stands out (stable sort),
    # nor is held back only by a rival: a force error that two causes explain alike is still
    # a force error, and it leaves a trace on those channels too (a -10 ms force delay on
    # the walk, which a plate shift explained nearly as well on the fitted motion, named a
    # 12 kg mass redistribution)
    passed = sorted((v for v in verdicts if not v[2]), key=lambda v: channels(v[0].cause) == "motion")
    # (a plate shift that the other plate's explains as well is no such force error: that is
    # how a misplaced centre of mass looks)
    held_back = [v for v in verdicts if channels(v[0].cause) == "residuals" and [f.key for f in v[2]] == ["rival"]]
    if passed and channels(passed[0][0].cause) == "motion" and held_back:
        best, _, failed = held_back[0]
        return None, (
            f"No cause stands out: {best.cause} is not chosen because " + _sentences(failed) + f", and "
            f"{passed[0][0].cause} is not named while a force error is held back by a rival (it leaves a trace on "
            "the whole-motion channels too)."
        )
    if not passed:
        best, _, failed = verdicts[0]
        return None, f"No cause stands out: the best candidate, {best.cause}, is not chosen because " + _sentences(failed) + "."
    best, second, _ = passed[0]
    if second is None:
        against = "and no rival acting on the same channels."
    elif second.score > best.score:
        against = (
            f"besides {second.cause} (score {second.score:.0f}), which explains another part of the residual "
            "(fitted together, each keeps its gain) but is not named itself."
        )
    else:
        against = f"against {second.score:.0f} for the runner-up ({second.cause})."
    return best, (
        f"{best.cause} stands out: it removes {100 * best.relative_gain:.0f}% of the held-out cost of its channels "
        f"in {100 * best.folds_improved:.0f}% of the folds, with a score of {best.score:.0f} " + against
    )
