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

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.diagnose.candidates import Alternative, FixedAlternative

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


def make_folds(n_frames: int, dt: float, folds: int = 5, block_seconds: float = 0.2) -> IntArray:
    """``(T,)`` fold index of each frame: contiguous blocks dealt to the folds in turn.

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
    """
    blocks = make_blocks(n_frames, dt, block_seconds)
    n_blocks = int(blocks[-1]) + 1 if n_frames else 0
    k = int(max(2, min(folds, n_blocks // 2)))
    return (blocks % k).astype(np.intp)


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
    """Fit ``alt`` on K-1 folds, score on the held-out one, for every fold."""
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
        Cause -> its own ``min_relative_gain``. ``segment_mass_distribution``'s channels
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
    min_effect
        Cause -> smallest effect worth naming (in the units of :func:`effect_size`).
    max_effect
        Cause -> largest plausible effect: a larger estimate (a segment gaining three times
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
        on the other plates. A centre of mass misplaced in the model moves the moment under
        both feet alike, which a shift of either plate mimics (two walk draws hiding a 4.5-5.4
        kg redistribution: the right plate's shift scored 409 and 350, the left one's 349 and
        295), and the fitted motion absorbs the redistribution itself; a misplaced plate
        stands out from the other one (in five captured draws of a hidden shift that were
        named, the hidden plate's shift scored 3.9 to 270 times the other's, or the other's
        score was negative).
    """

    min_relative_gain: float = 0.10
    relative_gain_of: dict[str, float] = field(default_factory=lambda: {"segment_mass_distribution": 0.0})
    min_folds_improved: float = 0.8
    runner_up_ratio: float = 0.6
    paired_t: float = 2.0
    paired_fraction: float = 0.6
    min_effect: dict[str, float] = field(
        default_factory=lambda: {
            "body_mass": 1.5,  # kg
            "force_time_offset": 0.005,  # s
            "plate_force_offset": 10.0,  # N
            "plate_force_gain": 0.015,  # relative
            "plate_position_offset": 0.005,  # m
            "segment_mass_distribution": 1.5,  # kg moved to the legs (consistent synthetic trials: up to 0.8)
            "marker_offset": 0.005,  # m (residual part the marker's error shows)
            "unmeasured_force": 3.0,  # frames
        }
    )
    max_effect: dict[str, float] = field(
        default_factory=lambda: {
            "body_mass": 30.0,  # kg
            "force_time_offset": 0.1,  # s (the search grid ends at 0.12 s)
            "plate_force_offset": 300.0,  # N
            "plate_force_gain": 0.3,  # relative
            "plate_position_offset": 0.1,  # m
            "segment_mass_distribution": 15.0,  # kg moved
            "marker_offset": 0.1,  # m
        }
    )
    distinct_choice: tuple[str, ...] = ("plate_position_offset",)
    min_t: float = 2.0

    def relative_gain_needed(self, cause: str) -> float:
        """The smallest relative gain that names ``cause``."""
        return self.relative_gain_of.get(cause, self.min_relative_gain)


#: Causes judged on the observed markers' own error channels; every other cause acts on the
#: root residual channels. Causes on different channels explain different residuals and may
#: both be true at once, so they do not stand in each other's way (:func:`choose`).
MARKER_CHANNEL_CAUSES = ("marker_offset",)

#: Causes judged on the whole-motion profile's channels (:mod:`.motion_profile`): the root
#: residual with every coordinate re-optimized. Such a cause is named only when no cause on
#: the other channels stands out (:func:`choose`): re-optimizing the whole motion leaves it
#: the weakest evidence (a fraction of a per cent of its channels' cost), and any force
#: error also leaves a trace there.
MOTION_CHANNEL_CAUSES = ("segment_mass_distribution",)


def channels(cause: str) -> str:
    """``"markers"``, ``"motion"``, ``"frames"`` or ``"residuals"``: what ``cause`` explains.

    ``unmeasured_force`` takes its frames U out of the residual terms, and every other
    cause is evaluated with U already out (:func:`solver.diagnose.core.build_context`): its
    gain is measured on top of U's, so the two are not alternatives and may both be true
    (opensim-core's C3D walk: after its steps off the plates were applied, six more frames
    of a foot on the floor stood in the way of a plate's zero drift that is real)."""
    if cause in MARKER_CHANNEL_CAUSES:
        return "markers"
    if cause in MOTION_CHANNEL_CAUSES:
        return "motion"
    return "frames" if cause == "unmeasured_force" else "residuals"


def effect_size(ev: Evaluation, parameters: dict[str, Any] | None = None) -> float:
    """The magnitude compared with :attr:`ChoiceRule.min_effect` (units per cause) of
    ``parameters`` (default: the evaluation's reported ones)."""
    p = ev.parameters if parameters is None else parameters
    if ev.cause == "body_mass":
        return abs(p["mass_change_kg"])
    if ev.cause == "force_time_offset":
        return abs(p["delay_s"])
    if ev.cause == "plate_force_offset":
        return float(np.linalg.norm(p["offset_N"]))
    if ev.cause == "plate_force_gain":
        return abs(p["gain"] - 1.0)
    if ev.cause == "plate_position_offset":
        return float(np.linalg.norm(p["shift_m"]))
    if ev.cause == "segment_mass_distribution":
        return float(np.sum(np.abs(list(p["mass_change_kg"].values()))) / 2)
    if ev.cause == "marker_offset":
        # the part of the shift the marker's own error shows (the pose takes up the rest)
        return float(np.linalg.norm(p["visible_shift_m"]))
    if ev.cause == "unmeasured_force":
        return float(p["n_frames"])
    return 0.0


def t_value(ev: Evaluation) -> float:
    """Distance of the reported estimate from "no effect" (a gain of 1, otherwise zero) in
    jackknife standard errors (vector estimates: norm over norm); ``inf`` when the
    estimate has no uncertainty (``unmeasured_force``'s frames)."""
    if ev.uncertainty is None or "value" not in ev.parameters:
        return float("inf")
    value = np.atleast_1d(np.asarray(ev.parameters["value"], dtype=float))
    if ev.cause == "marker_offset":
        # judged by the shift beyond the offset the kinematics stage already gave the model
        # marker (what the marker's own error shows and ``--apply`` corrects); the reported
        # value adds that offset, a constant, so its jackknife error is the same. Judged by
        # the whole shift, a marker the trial shows 1.3 cm from the model's marker (the
        # walk's L.Shoulder once corrected, 2026-11-23) was 0.8 errors from "no effect" and
        # blocked every other marker
        value = np.atleast_1d(np.asarray(ev.parameters["residual_shift_m"], dtype=float))
    if ev.cause == "plate_force_gain":
        value = value - 1.0
    se = float(np.linalg.norm(np.atleast_1d(np.asarray(ev.uncertainty, dtype=float))))
    size = float(np.linalg.norm(value))
    return size / se if se > 0 else float("inf")


def contends(ev: Evaluation, rule: ChoiceRule) -> bool:
    """Whether every estimate of ``ev`` is worth naming and plausible and lies at least
    ``rule.min_t`` standard errors from no effect (:meth:`ChoiceRule` fields)."""
    lo, hi = rule.min_effect.get(ev.cause, 0.0), rule.max_effect.get(ev.cause, np.inf)
    return all(lo <= effect_size(ev, p) <= hi for p in ev.estimates) and t_value(ev) >= rule.min_t


def best_per_cause(evaluations: list[Evaluation], rule: ChoiceRule | None = None) -> list[Evaluation]:
    """The best-scoring alternative of each cause, best first.

    With ``rule``, the best of a cause whose alternatives each act on a channel of their own
    (:data:`MARKER_CHANNEL_CAUSES`: a marker's offset explains that marker's error only) is
    the best that stands out on its own channel (:func:`stands_out_alone`), else the best
    that :func:`contends`: a marker whose estimate is no effect, or that improves too few
    folds, does not stand in the way of another marker's offset."""
    best: dict[str, Evaluation] = {}
    for ev in evaluations:
        if ev.cause not in best or ev.score > best[ev.cause].score:
            best[ev.cause] = ev
    if rule is not None:
        for cause in MARKER_CHANNEL_CAUSES:
            own = [e for e in evaluations if e.cause == cause]
            eligible = [e for e in own if stands_out_alone(e, rule)] or [e for e in own if contends(e, rule)]
            if eligible:
                best[cause] = max(eligible, key=lambda e: e.score)
    return sorted(best.values(), key=lambda e: e.score, reverse=True)


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
    out = [e for e in evaluations if e.cause in MARKER_CHANNEL_CAUSES and e is not chosen and stands_out_alone(e, rule)]
    return sorted(out, key=lambda e: e.score, reverse=True)


def make_blocks(n_frames: int, dt: float, block_seconds: float = 0.2) -> IntArray:
    """``(T,)`` index of the contiguous block of ``block_seconds`` each frame belongs to."""
    return (np.arange(n_frames) // max(round(block_seconds / dt), 1)).astype(np.intp)


def paired_blocks(best: Evaluation, other: Evaluation, blocks: IntArray) -> tuple[float, float]:
    """Paired comparison of two alternatives over blocks of frames.

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


def _stands_out(best: Evaluation, rival: Evaluation | None, rule: ChoiceRule, blocks: IntArray | None) -> tuple[bool, float, float]:
    """Whether ``best`` stands out from ``rival`` (score ratio or paired blocks), with the
    paired t and fraction of blocks (:func:`paired_blocks`)."""
    if rival is None:
        return True, 0.0, 0.0
    t_pair, frac_pair = paired_blocks(best, rival, blocks) if blocks is not None else (0.0, 0.0)
    clear = rival.score <= rule.runner_up_ratio * best.score or (t_pair >= rule.paired_t and frac_pair >= rule.paired_fraction)
    return clear, t_pair, frac_pair


def _verdict(
    group: list[Evaluation], rule: ChoiceRule, blocks: IntArray | None, alternatives: list[Evaluation] | None
) -> tuple[Evaluation, Evaluation | None, list[str]]:
    """The best of contenders acting on the same channels (best first), its runner-up, and
    the checks of :class:`ChoiceRule` it fails (empty: it stands out)."""
    best = group[0]
    second = group[1] if len(group) > 1 else None
    clear, t_pair, frac_pair = _stands_out(best, second, rule, blocks)
    siblings = [
        e for e in (alternatives or []) if best.cause in rule.distinct_choice and e.cause == best.cause and e.choice != best.choice
    ]
    sibling = max(siblings, key=lambda e: e.score) if siblings else None
    distinct, t_sib, frac_sib = _stands_out(best, sibling, rule, blocks)
    checks = [
        (best.score > 0, f"its score ({best.score:.0f}) is not positive"),
        (
            best.relative_gain >= rule.relative_gain_needed(best.cause),
            f"it removes only {100 * best.relative_gain:.0f}% of the held-out cost (needs {100 * rule.relative_gain_needed(best.cause):.0f}%)",
        ),
        (
            best.folds_improved >= rule.min_folds_improved,
            f"it improves only {100 * best.folds_improved:.0f}% of the held-out folds",
        ),
        (
            clear,
            (
                f"{second.cause if second else ''} explains the residuals nearly as well "
                f"(score {second.score if second else 0:.0f} vs {best.score:.0f}; better in {100 * frac_pair:.0f}% of the "
                f"blocks of frames, t = {t_pair:.1f})"
            ),
        ),
        (
            distinct,
            (
                f"the same cause on {sibling.choice if sibling else ''} explains them nearly as well (score "
                f"{sibling.score if sibling else 0:.0f}; better in {100 * frac_sib:.0f}% of the blocks, t = {t_sib:.1f}), "
                "as a centre of mass misplaced in the model would"
            ),
        ),
    ]
    return best, second, [msg for ok, msg in checks if not ok]


def choose(
    ranked: list[Evaluation],
    rule: ChoiceRule | None = None,
    blocks: IntArray | None = None,
    alternatives: list[Evaluation] | None = None,
) -> tuple[Evaluation | None, str]:
    """The chosen cause (or None) and a sentence saying why.

    The contenders are the causes whose estimates (:attr:`Evaluation.estimates`) are all
    worth naming and plausible (:attr:`ChoiceRule.min_effect`, :attr:`ChoiceRule.max_effect`);
    contenders are grouped by the channels they act on (:func:`channels`); the best of each
    group is checked against its group's runner-up, and the best-scoring one that passes
    the rule's checks is chosen, one on the whole-motion channels only when no other passes
    (:data:`MOTION_CHANNEL_CAUSES`; when none passes, the reason is that of the overall best).

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
            f"{rule.min_t:g} standard errors of no effect (the best, {best.cause}, {size}, {t_value(best):.1f} "
            f"standard errors; worth naming from {rule.min_effect.get(best.cause, 0.0):g} "
            f"to {rule.max_effect.get(best.cause, np.inf):g})."
        )
    # causes on different channels do not stand in each other's way: the best of each
    # channel group is checked against its own runner-up, and the best that passes is named
    groups: dict[str, list[Evaluation]] = {}
    for e in contenders:
        groups.setdefault(channels(e.cause), []).append(e)
    verdicts = [_verdict(group, rule, blocks, alternatives) for group in groups.values()]
    # a cause on the whole-motion channels only when nothing else stands out (stable sort)
    passed = sorted((v for v in verdicts if not v[2]), key=lambda v: channels(v[0].cause) == "motion")
    if not passed:
        best, _, failed = verdicts[0]
        return None, f"No cause stands out: the best candidate, {best.cause}, is not chosen because " + "; ".join(failed) + "."
    best, second, _ = passed[0]
    return best, (
        f"{best.cause} stands out: it removes {100 * best.relative_gain:.0f}% of the held-out cost of its channels "
        f"in {100 * best.folds_improved:.0f}% of the folds, with a score of {best.score:.0f} "
        + (f"against {second.score:.0f} for the runner-up ({second.cause})." if second else "and no rival acting on the same channels.")
    )
