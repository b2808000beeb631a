"""The diagnosis of one processed trial, end to end.

1. :mod:`.data` prepares the trial (reference: processed motion, stated mass, raw plates,
   reviewer flags); :mod:`.analysis` reports where the residuals concentrate.
2. :func:`unmeasured_frames` finds frames that look unmeasured; every candidate of
   :mod:`.candidates` is cross-validated (:mod:`.selection`) and the best alternative per
   cause is ranked; :func:`.selection.choose` names a cause or none.
3. The choice uses the processed motion (the dynamics fit made it consistent with the
   forces, so the residuals it leaves are small and clean). The dynamics fit also absorbs
   part of any force error into that motion (about a third of a centre-of-pressure shift,
   for example), so the parameters of the causes acting on the forces are estimated a
   second time on the motion the markers alone decide (:func:`.data.marker_kinematics`),
   with the generic model's mass distribution (:func:`.data.generic_mass_distribution`:
   the stage's mass factors were fitted to the forces too), which carries none of it:
   those are the reported estimates (the fitted-motion ones are kept as
   ``parameters_fitted_motion``).
4. For the chosen cause, the extension is applied and the trial refitted (:mod:`.refit`):
   "after" metrics in the pipeline's terms. Held-out metrics before and after come from
   the cross-validated, fixed-kinematics evaluation (each frame scored with parameters
   fitted without it).
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from solver.corrections import extend_subject, extension_masks
from solver.diagnose import candidates as C
from solver.diagnose.analysis import analyse
from solver.diagnose.causes.base import EntryInputs, RefitSetup
from solver.diagnose.causes.registry import CAUSES, NAMES, cause
from solver.diagnose.data import (
    DiagnosisData,
    generic_mass_distribution,
    load_offsets,
    load_scale_response,
    marker_kinematics,
    prepare,
)
from solver.diagnose.profile import Profile, Sigmas, own_noise_sigmas
from solver.diagnose.selection import (
    ChoiceRule,
    Evaluation,
    Folds,
    JointGains,
    KeptShare,
    also_standing_out,
    best_per_cause,
    channels,
    choose,
    confirmed,
    cross_validate,
    make_blocks,
)
from solver.dynamics.preprocess import nearest_frames
from solver.errors import DiagnosisError
from solver.io.subject import Subject, Trial, load_subject, load_trial
from solver.masks import join_masks, resample_mask, true_runs
from solver.model.osim import OsimModel, read_osim
from solver.results import ProcessedTrial, load_processed
from solver.sampling import frame_interval

if TYPE_CHECKING:
    from solver.diagnose.refit import Refit

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class DiagnoseOptions:
    """Options of :func:`diagnose_trial`.

    Attributes
    ----------
    folds
        Cross-validation folds K (dealt per cause: :class:`solver.diagnose.selection.Folds`).
    block_seconds
        Length of the contiguous blocks dealt to the folds, s.
    rule
        When a cause is named.
    refit
        Refit the trial with the chosen extension (off: fixed-kinematics figures only).
    causes
        Names of the causes to test (default: every registered one,
        :data:`solver.diagnose.causes.registry.NAMES`).
    """

    folds: int = 5
    block_seconds: float = 0.2
    rule: ChoiceRule = field(default_factory=ChoiceRule)
    refit: bool = True
    causes: tuple[str, ...] = NAMES


@dataclass
class Diagnosis:
    """Result of :func:`diagnose_trial` (see :func:`solver.diagnose.report.to_json`).

    Attributes
    ----------
    subject, trial
        Names.
    baseline
        The trial's results.json metrics.
    analysis
        Where the residuals concentrate (:func:`solver.diagnose.analysis.analyse`).
    evaluations
        Every cross-validated alternative.
    ranked
        The best alternative per cause, best score first.
    chosen
        The chosen evaluation, or None.
    reason
        One sentence on the choice.
    parameters
        The chosen cause's parameters after the refit's refinement (or its first estimate).
    after
        Metrics of the trial refitted with the extension (results.json keys), or None.
    before_refit
        Metrics of the same refit without the extension (what the refit alone gains, by
        starting from the processed motion, is not credited to the extension), or None.
    held_out
        ``{"before": {...}, "after": {...}}`` held-out figures of the chosen cause.
    extension
        The entry ``--apply`` saves (:mod:`solver.corrections`), or None.
    also_standing_out
        Marker offsets other than the chosen cause that stand out on their own markers'
        errors (:func:`solver.diagnose.selection.also_standing_out`), each with the entry
        ``--apply`` would save for it; ``--apply`` saves only the chosen cause's.
    settings
        Sigmas, folds and thresholds used.
    seconds
        Wall time by step.
    """

    subject: str
    trial: str
    baseline: dict[str, Any]
    analysis: dict[str, Any]
    evaluations: list[Evaluation]
    ranked: list[Evaluation]
    chosen: Evaluation | None
    reason: str
    parameters: dict[str, Any] | None = None
    after: dict[str, Any] | None = None
    before_refit: dict[str, Any] | None = None
    held_out: dict[str, Any] | None = None
    extension: dict[str, Any] | None = None
    also_standing_out: list[tuple[Evaluation, dict[str, Any]]] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    data: DiagnosisData | None = field(default=None, repr=False)


# --------------------------------------------------------------------------- evaluation


def build_context(
    data: DiagnosisData, sigmas: Sigmas | None = None, unmeasured: tuple[BoolArray, list[str]] | None = None
) -> tuple[C.Context, Profile]:
    """The shared context of the candidates and the profile with U evaluated.

    ``unmeasured`` gives the frames U, ``(T,)``, and their reasons (T strings, "" outside
    U; default: found on ``data``, :func:`solver.diagnose.candidates.unmeasured_frames`).
    """
    s = sigmas or Sigmas.of(data)
    u, reasons = C.unmeasured_frames(data) if unmeasured is None else unmeasured
    # frames the solver left out of its dynamic fit that U does not explain: their motion
    # had free centre-of-mass accelerations, so their residual says nothing about a cause
    considered = ~data.flagged & ~(data.left_out & ~u)
    evaluated = considered & ~u
    prof = Profile(data, evaluated, s)
    ref = prof.project(prof.raw_rows(data.residual(), data.external()[2]))
    full = prof if not u.any() else Profile(data, considered, s)
    return C.Context(data, s, evaluated, prof, ref, u, reasons), full


def alternatives(ctx: C.Context, full: Profile, causes: tuple[str, ...]) -> list[C.Alternative]:
    """Every alternative of the requested causes (names; in that order).

    Raises
    ------
    solver.diagnose.causes.registry.UnknownCause
        A name no registered cause has.
    """
    out: list[C.Alternative] = []
    for name in causes:
        out.extend(cause(name).alternatives(ctx, full))
    return out


def evaluate(
    data: DiagnosisData,
    options: DiagnoseOptions,
    unmeasured: tuple[BoolArray, list[str]] | None = None,
    sigmas: Sigmas | None = None,
) -> tuple[C.Context, list[C.Alternative], list[Evaluation], Folds]:
    """Cross-validate every alternative, each on its cause's folds (:class:`Folds`); returns
    the context, alternatives, evaluations and folds.

    ``unmeasured``: the frames U, ``(T,)``, and their reasons (T strings; default: found on
    ``data``); ``sigmas``: the channels' standard deviations (default: :meth:`Sigmas.of`
    ``data``, the fit's).
    """
    ctx, full = build_context(data, sigmas, unmeasured=unmeasured)
    alts = alternatives(ctx, full, options.causes)
    folds = Folds.of_trial(data.n_frames, data.dt, options.folds, options.block_seconds)
    return ctx, alts, [cross_validate(a, folds.of(a.cause)) for a in alts], folds


def _alt_of(alts: list[C.Alternative], ev: Evaluation) -> C.Alternative:
    return next(a for a in alts if a.cause == ev.cause and a.choice == ev.choice)


# --------------------------------------------------------------------------- held-out figures


def held_out_figures(ctx: C.Context, alt: C.Alternative, folds: np.ndarray, scored: BoolArray | None = None) -> dict[str, Any]:
    """Before/after figures on held-out frames: every frame scored after a fit without its fold.

    Before: the reference (processed motion, stated mass, translation re-optimized). After:
    the extension with the parameters of the fold the frame was held out of
    (:meth:`solver.diagnose.causes.base.Cause.held_out_figures` of the alternative's cause).
    ``scored`` ``(T,)``: the frames whose residuals count (default: every evaluated frame).
    """
    frames = np.ones(ctx.data.n_frames, dtype=bool) if scored is None else np.asarray(scored, dtype=bool)
    return cause(alt.cause).held_out_figures(ctx, alt, folds, frames)


# --------------------------------------------------------------------------- extensions


def entry_inputs(data: DiagnosisData, marker_time: FloatArray) -> EntryInputs:
    """What a cause needs to write its extension entry: the prepared trial, the raw marker
    times ``marker_time`` ``(T_markers,)``, s, and the rule that takes runs of the diagnosis'
    frames to the marker rate."""

    def marker_frames(runs: Any) -> list[list[int]]:
        found = np.zeros(data.time.size, dtype=bool)
        for a, b in runs:
            found[a:b] = True
        return [list(r) for r in true_runs(resample_mask(found, data.time, marker_time))]

    return EntryInputs(data, marker_time, marker_frames)


def extension_entry(ev: Evaluation, data: DiagnosisData, marker_time: FloatArray) -> dict[str, Any]:
    """The :mod:`solver.corrections` entry of an evaluation (what ``--apply`` saves): its
    cause's :meth:`~solver.diagnose.causes.base.Cause.extension`. ``marker_time``
    ``(T_markers,)``: the raw trial's marker sample times, s.

    Raises
    ------
    solver.diagnose.causes.registry.UnknownCause
        No registered cause has the evaluation's name.
    """
    return cause(ev.cause).extension(ev.parameters, entry_inputs(data, marker_time))


# --------------------------------------------------------------------------- main entry


@dataclass(frozen=True)
class TrialInputs:
    """What :func:`diagnose_processed` needs besides the processed trial.

    Attributes
    ----------
    subject
        The subject (mass, model, foot bodies), with saved extensions applied.
    raw
        The raw trial with saved extensions applied.
    unmeasured_force
        ``(T,)`` the reviewer's flags of unmeasured force at the trial's processed frames
        (:mod:`solver.masks`), or None.
    marker_offsets
        Fitted marker offsets (``OUT/subject.json``).
    reviewed
        A reviewer's flags were given: they replace the solver's own unmeasured-force
        proposals, as in ``addb process``; otherwise the proposals stand and saved
        extensions join them.
    known_unmeasured
        ``(T_markers,)`` frames of the saved ``unmeasured_force`` extensions, at the marker
        frames, or None.
    scale_response
        Landmark marker -> ``(3, 3)`` scale response of the trial (``OUT/subject.json``).
    """

    subject: Subject
    raw: Trial
    unmeasured_force: BoolArray | None
    marker_offsets: dict[str, list[float]]
    reviewed: bool = False
    known_unmeasured: BoolArray | None = None
    scale_response: dict[str, list[list[float]]] = field(default_factory=dict)


def load_inputs(
    subject_dir: str | Path, trial: str, out_dir: str | Path, unmeasured_force: BoolArray | None = None
) -> TrialInputs:
    """Load the subject, the raw trial (saved extensions applied), the reviewer's flags
    (``(T,)`` at the processed frames) and the saved unmeasured-force extensions."""
    from solver.corrections import apply_extensions

    subject = load_subject(subject_dir)
    raw = apply_extensions(subject, (load_trial(subject.trial(trial)),))[0]
    flags = None if unmeasured_force is None else np.asarray(unmeasured_force, dtype=bool)
    return TrialInputs(
        extend_subject(subject), raw, flags, load_offsets(out_dir), reviewed=flags is not None,
        known_unmeasured=extension_masks(subject).get(trial), scale_response=load_scale_response(out_dir, trial),
    )  # fmt: skip


def frame_flags(inputs: TrialInputs, flags_time: FloatArray, time: FloatArray) -> BoolArray:
    """``(T,)`` frames of ``time`` known to be unmeasured: the reviewer's flags (given on
    the processed frames ``flags_time``) joined with the saved unmeasured-force extensions
    (marker frames), both put on ``time`` by the overlap rule (:mod:`solver.masks`).

    Raises
    ------
    DiagnosisError
        The reviewer's flags or an extension were made on other frames (naming the trial
        and both lengths).
    """
    trial, marker_time = inputs.raw.name, np.asarray(inputs.raw.markers.time)
    out = {trial: np.zeros(time.size, dtype=bool)}
    for mask, on, what in ((inputs.unmeasured_force, flags_time, "processed"), (inputs.known_unmeasured, marker_time, "marker")):
        if mask is None:
            continue
        if np.size(mask) != on.size:
            raise DiagnosisError(
                f"an unmeasured-force mask has {np.size(mask)} frames but the trial has {on.size} {what} frames: "
                "it was made on other frames", where=f"trial {trial}",
            )  # fmt: skip
        out = join_masks(out, {trial: resample_mask(mask, on, time)}) or out
    return out[trial]


def diagnose_processed(
    processed: ProcessedTrial, inputs: TrialInputs, options: DiagnoseOptions | None = None, progress: Progress | None = None
) -> Diagnosis:
    """Diagnose a processed trial (see the module docstring).

    Parameters
    ----------
    processed
        The processed trial (``load_processed``).
    inputs
        Subject, raw trial, reviewer flags and fitted marker offsets (:func:`load_inputs`).
    options
        Folds, thresholds, refit.
    progress
        Called with (message, fraction).

    Returns
    -------
    Diagnosis
    """
    from solver import single_threaded_blas

    with single_threaded_blas():
        return _diagnose(processed, inputs, options or DiagnoseOptions(), progress or (lambda m, f: None))


def _diagnose(processed: ProcessedTrial, inputs: TrialInputs, options: DiagnoseOptions, say: Progress) -> Diagnosis:
    if not processed.has_dynamics or inputs.raw.forces is None:
        raise DiagnosisError(f"trial {processed.trial} has no dynamics to diagnose (no force plates)", path=processed.model_path)
    t0 = _time.perf_counter()
    subject = inputs.subject
    marker_time = np.asarray(inputs.raw.markers.time)
    generic = read_osim(subject.model_path)
    model = read_osim(processed.model_path)
    say("preparing", 0.05)

    def prep(trial: ProcessedTrial, fitted: OsimModel = model) -> DiagnosisData:
        return prepare(
            trial,
            inputs.raw.forces,
            stated_mass=subject.mass_kg,
            flagged=frame_flags(inputs, processed.time, trial.time),
            generic_model=generic,
            marker_offsets=inputs.marker_offsets,
            feet=subject.foot_body_names,
            model=fitted,
            scale_response=inputs.scale_response,
        )

    data = prep(processed)
    # the marker-only motion with masses the forces did not fit: the dynamics stage's mass
    # factors absorb part of a force error (on the walk, a hidden 2-4 cm plate shift moved
    # its estimate there by up to 0.9 cm), and estimates taken with them depend on it
    model_ik = generic_mass_distribution(model, generic)
    data_ik = prep(marker_kinematics(processed, model_ik), model_ik)
    t1 = _time.perf_counter()
    say("testing candidate causes", 0.15)
    ctx, alts, evaluations, folds = evaluate(data, options)
    # parameters from the marker-only motion (not pulled toward the forces by the fit)
    # (same frames U as the fitted motion: the marker-only motion is noisier, and its own
    # residual would call far more frames unmeasured)
    ik_options = replace(options, causes=tuple(c for c in options.causes if cause(c).on_marker_motion != "skipped"))
    ctx_ik, alts_ik, evaluations_ik, _ = evaluate(data_ik, ik_options, unmeasured=(ctx.unmeasured, ctx.unmeasured_reasons))
    twins: dict[tuple[str, object], Evaluation] = {}  # each alternative's evaluation on the marker-only motion
    for ev in evaluations_ik:
        ev.motion = "marker-only"
        twins.setdefault((ev.cause, ev.choice), ev)
    for ev in evaluations:
        twin = twins.get((ev.cause, ev.choice))
        if twin is not None and cause(ev.cause).on_marker_motion == "estimated":
            ev.parameters_fitted_motion, ev.uncertainty_fitted_motion = ev.parameters, ev.uncertainty
            twin.parameters_fitted_motion, twin.uncertainty_fitted_motion = ev.parameters, ev.uncertainty
            ev.parameters, ev.uncertainty = twin.parameters, twin.uncertainty
    blocks = make_blocks(data.n_frames, data.dt, options.block_seconds)
    ranked = best_per_cause(evaluations, options.rule)
    # a cause of the force recording that the marker-only motion does not confirm is no
    # candidate on the fitted motion (the plates' registration: selection.confirmed); the
    # report still ranks it, and the reason says why it was left out when its share of the
    # cost there would have counted
    candidates = confirmed(evaluations, twins, options.rule)
    # two overlapping causes (a plate's shift, the plates' registration) that each keep their
    # gain on top of the other on the fitted motion are told apart on the marker-only one
    kept_ik = JointGains(alts_ik, evaluations_ik, folds).kept_share

    def on_marker_motion(best: Evaluation, rival: Evaluation) -> float | None:
        a, b = twins.get((best.cause, best.choice)), twins.get((rival.cause, rival.choice))
        return None if a is None or b is None else kept_ik(a, b)

    kept = JointGains(alts, evaluations, folds).kept_share
    chosen, reason = choose(best_per_cause(candidates, options.rule), options.rule, blocks, candidates, kept, on_marker_motion)
    left_out = {id(e) for e in evaluations} - {id(e) for e in candidates}
    reason += "".join(
        f" ({e.cause} removes {100 * e.relative_gain:.0f}% of its channels' cost on the fitted motion but "
        f"{100 * twins[e.cause, e.choice].relative_gain:.1f}% on the motion the markers alone decide, which does not confirm it)"
        for e in ranked
        if id(e) in left_out and e.relative_gain >= options.rule.relative_gain_needed(e.cause)
    )
    held_ctx, held_alts = ctx, alts
    own_sigmas: list[Sigmas] = []

    def own_noise() -> tuple[list[Evaluation], KeptShare]:
        # the force-side causes on the marker-only motion whitened with its own noise
        own_sigmas.append(own_noise_sigmas(ctx_ik.ref_rows, ctx_ik.evaluated, ctx_ik.sigmas))
        own_options = replace(ik_options, causes=tuple(c for c in ik_options.causes if cause(c).acts_on_forces))
        _, alts_own, evs_own, _ = evaluate(data_ik, own_options, (ctx.unmeasured, ctx.unmeasured_reasons), own_sigmas[0])
        for ev in evs_own:
            ev.motion = "marker-only"
        return evs_own, JointGains(alts_own, evs_own, folds).kept_share

    on_markers = choice_on_marker_motion(chosen, evaluations_ik, options.rule, blocks, kept_ik, own_noise)
    if on_markers is not None:
        chosen, why = on_markers
        reason = (
            "On the motion the markers alone decide (the dynamics fit leaves out or absorbs the force "
            "transients a delay leaves at every foot strike, and turns the body to balance a shifted "
            f"centre of pressure): {why}"
        )
        ranked = [chosen] + [e for e in ranked if e.cause != chosen.cause]
        held_ctx, held_alts = ctx_ik, alts_ik
    t2 = _time.perf_counter()
    result = Diagnosis(
        subject=processed.subject,
        trial=processed.trial,
        baseline=dict(processed.metrics),
        analysis=analyse(data),
        evaluations=evaluations,
        ranked=ranked,
        chosen=chosen,
        reason=reason,
        settings={
            "sigmas": vars(ctx.sigmas),
            "sigmas_own_noise": vars(own_sigmas[0]) if own_sigmas else None,
            "folds": folds.count,
            "folds_mixing_phases": [c.name for c in CAUSES if c.folds_mix_phases and c.name in options.causes],
            "block_seconds": options.block_seconds,
            "rule": {k: getattr(options.rule, k) for k in options.rule.__dataclass_fields__},
            "stated_mass_kg": data.stated_mass,
            "fitted_mass_kg": data.fitted_mass,
            "frames": data.n_frames,
            "frames_flagged": int(data.flagged.sum()),
            "frames_unmeasured_candidates": int(ctx.unmeasured.sum()),
        },
        data=data,
    )
    result.seconds = {"prepare": t1 - t0, "candidates": t2 - t1}
    result.also_standing_out = [(e, extension_entry(e, data, marker_time)) for e in also_standing_out(evaluations, chosen, options.rule)]
    if chosen is not None:
        chosen_folds = folds.of(chosen.cause)
        result.held_out = held_out_figures(held_ctx, _alt_of(held_alts, chosen), chosen_folds)
        result.held_out["motion"] = chosen.motion
        result.parameters = dict(chosen.parameters)
        result.extension = extension_entry(chosen, data, marker_time)
        if options.refit:
            say(f"refitting with and without {chosen.cause}", 0.3)
            t_refit = _time.perf_counter()
            refit, plain = _refits(result, inputs, marker_time, data_ik.trial.q)
            result.after, result.before_refit = refit.metrics, plain.metrics
            result.seconds["refit"] = _time.perf_counter() - t_refit
            if cause(chosen.cause).corrects_forces and held_ctx is ctx:
                # the processed motion was bent to balance the uncorrected forces: score the
                # corrected forces on the motion refitted with them, against the same refit
                # without them (the parameters of each frame still fitted without its fold)
                def on(r: Refit) -> tuple[C.Context, C.Alternative]:
                    unmeasured = resample_mask(ctx.unmeasured, data.time, r.trial.time)
                    ctx_r, full_r = build_context(prep(r.trial, r.model), ctx.sigmas, (unmeasured, ctx.unmeasured_reasons))
                    return ctx_r, _alt_of(alternatives(ctx_r, full_r, (chosen.cause,)), chosen)

                (ctx_p, alt_p), (ctx_r, alt_r) = on(plain), on(refit)
                # the two refits may leave out different frames, and a corrected force delay
                # moves the span the plates and the cameras share (one frame fewer or more):
                # frames are matched by time, each keeping the fold of its processed frame
                in_r, in_p = _same_times(ctx_p.data.time, ctx_r.data.time), _same_times(ctx_r.data.time, ctx_p.data.time)
                shared = ctx_p.evaluated[in_r] & ctx_r.evaluated[in_p]  # the shared frames, in time order
                both_p, both_r = np.zeros_like(in_r), np.zeros_like(in_p)
                both_p[in_r], both_r[in_p] = shared, shared
                result.held_out.update(
                    before=held_out_figures(ctx_p, alt_p, _at_times(chosen_folds, data.time, ctx_p.data.time), both_p)["before"],
                    after=held_out_figures(ctx_r, alt_r, _at_times(chosen_folds, data.time, ctx_r.data.time), both_r)["after"],
                    motion="refitted",
                    note="translation re-optimized; on the motions refitted without (before) and with (after) the "
                    "extension, each frame corrected with parameters fitted without its fold",
                )
    result.seconds["total"] = _time.perf_counter() - t0
    say("done", 1.0)
    return result


def _same_times(time: FloatArray, other: FloatArray) -> BoolArray:
    """``(T,)`` frames of ``time`` that ``other`` has too (within a tenth of a frame)."""
    if time.size < 2 or other.size < 2:
        return np.isin(time, other)
    idx = nearest_frames(other, time)
    return np.abs(other[idx] - time) < 0.1 * frame_interval(time)


def _at_times(values: np.ndarray, time: FloatArray, at: FloatArray) -> np.ndarray:
    """Per-frame values on ``time`` (folds) taken at the nearest frame of each of ``at``:
    ``at``'s own frames (frame masks go through :func:`solver.masks.resample_mask`)."""
    return values if np.array_equal(time, at) else values[nearest_frames(time, at)]


#: Causes that act on the measured forces (the plates' readings or the body's weight):
#: compared again on the marker-only motion (:func:`choice_on_marker_motion`).
FORCE_CAUSES = tuple(c.name for c in CAUSES if c.acts_on_forces)


#: Causes that correct the plates' readings alone (model and markers as processed): their
#: held-out figures are taken on the refits without and with them (:func:`_diagnose`).
FORCE_CORRECTIONS = tuple(c.name for c in CAUSES if c.corrects_forces)


#: Force-side causes that may be chosen on the marker-only motion (:func:`choice_on_marker_motion`).
MARKER_MOTION_CHOICES = tuple(c.name for c in CAUSES if c.chosen_on_marker_motion)


def choice_on_marker_motion(
    chosen: Evaluation | None,
    evaluations_ik: list[Evaluation],
    rule: ChoiceRule,
    blocks: np.ndarray,
    kept: KeptShare | None = None,
    own_noise: Callable[[], tuple[list[Evaluation], KeptShare]] | None = None,
) -> tuple[Evaluation, str] | None:
    """A force delay, plate shift, plate registration, plate zero drift or plate gain
    chosen on the marker-only motion, or None.

    A delay between plates and cameras leaves its evidence in the force transients of
    every foot strike. The dynamics fit cannot follow a force that comes too late, so it
    leaves those frames out of its dynamic fit (free centre-of-mass accelerations there)
    or bends the motion toward the late force, and on the fitted motion what is left of
    the delay resembles a shifted centre of pressure or a wrong mass. A shifted centre of
    pressure under the large forces of running is absorbed too: the fit turns the body so
    that the shifted moment is balanced (on the treadmill run the fitted motion keeps
    0-10 % of a hidden 1-4 cm shift). The marker-only motion keeps every frame and owes
    nothing to the forces. When the fitted motion names no cause, one acting on the
    forces, a marker offset (which acts on other channels: the walk's own shoulder
    markers stand out on every draw hidden in it) or a cause on the whole-motion channels
    (named only when nothing else stands out, and a force error leaves a trace there too:
    since 2026-11-24, a run draw hiding a 2.7 cm sideways shift and a 1 degree turn of both
    belts named a 2.8 kg mass redistribution, the fitted motion keeping under 0.5 cm of the
    shift), the causes acting on the forces are compared on the marker-only motion (same
    :func:`.selection.choose` rule, same frames U); if a delay, a plate shift, the plates'
    registration or a plate's zero drift (:data:`MARKER_MOTION_CHOICES`; the drift since
    2026-11-26, judged on the converged fit) stands out there, it is the choice: a force
    error matters for every dynamic output, a marker offset for one marker's fit.

    When nothing that may be chosen there stands out, the force-side causes are compared once
    more on the marker-only motion whitened with its own noise (``own_noise``: their
    evaluations with :func:`.profile.own_noise_sigmas` and their joint gains; since
    2026-11-24), and a cause that may be chosen that way (``chosen_on_own_noise``: a plate's
    gain) and stands out there is the choice. Whitened with the fitted motion's sigmas, the
    marker-only motion's moment rows are mostly the inertial noise of a motion no force
    shaped, and a body-mass change, which scales that inertial moment, outscored a treadmill
    belt's gain that the marker-only motion recovers exactly (6 of 20 gain draws, all on the
    run, were missed). The causes decided on the moment rows (a delay, a plate's shift, the
    plates' registration) keep the first comparison: with the moment rows down-weighted (an
    experiment on modified code, docs/diagnose/RESULTS.md "The weakest rows"), run plate
    shifts, run registrations and a walk delay were lost. The returned evaluation is the cause's own on the marker-only
    motion with the fitted sigmas (the estimate and uncertainty reported for it anyway); the
    sentence says how it was chosen.

    Returns
    -------
    (evaluation on the marker-only motion, the rule's sentence), or None
    """
    if chosen is not None and not cause(chosen.cause).acts_on_forces and channels(chosen.cause) not in ("markers", "motion"):
        return None
    force_side = [e for e in evaluations_ik if cause(e.cause).acts_on_forces]
    pick, why = choose(best_per_cause(force_side), rule, blocks, force_side, kept)
    if pick is not None and cause(pick.cause).chosen_on_marker_motion:
        return pick, why
    if own_noise is None:
        return None
    evaluations_own, kept_own = own_noise()
    force_side = [e for e in evaluations_own if cause(e.cause).acts_on_forces]
    pick, why = choose(best_per_cause(force_side), rule, blocks, force_side, kept_own)
    if pick is None or not cause(pick.cause).chosen_on_own_noise:
        return None
    twin = next(e for e in evaluations_ik if e.cause == pick.cause and e.choice == pick.choice)
    return twin, f"whitened with its own noise: {why}"


#: Causes not evaluated on the marker-only motion at all: a mass distribution is judged with
#: the whole motion re-optimized (:mod:`.motion_profile`), so the motion it starts from only
#: sets the linearization point, and the fitted one is consistent with the forces.
FITTED_MOTION_ONLY = tuple(c.name for c in CAUSES if c.on_marker_motion == "skipped")


#: Causes whose parameters are estimated on the marker-only motion (see :func:`_diagnose`):
#: every cause acting on the forces, and the marker offsets. ``segment_mass_distribution`` and
#: ``unmeasured_force`` keep the fitted motion (the marker-only motion's moment noise
#: dominates the former).
MARKER_MOTION_ESTIMATES = tuple(c.name for c in CAUSES if c.on_marker_motion == "estimated")


def _refits(result: Diagnosis, inputs: TrialInputs, marker_time: FloatArray, ik_q: FloatArray) -> tuple[Refit, Refit]:
    """The refits with and without the chosen extension (``ik_q``: the marker-only motion,
    see :func:`refit_result`), side by side in two processes where the platform can fork
    (the two are independent; each takes seconds), else in turn."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    if "fork" in mp.get_all_start_methods():
        try:
            with ProcessPoolExecutor(1, mp_context=mp.get_context("fork")) as pool:
                plain_job = pool.submit(refit_result, result, inputs, marker_time, False)
                refit = refit_result(result, inputs, marker_time, ik_q=ik_q)
                return refit, plain_job.result()
        except (BrokenProcessPool, OSError):  # pragma: no cover - no process to spare
            pass
    return refit_result(result, inputs, marker_time, ik_q=ik_q), refit_result(result, inputs, marker_time, extension=False)


def refit_result(
    result: Diagnosis, inputs: TrialInputs, marker_time: FloatArray, extension: bool = True, ik_q: FloatArray | None = None
) -> Refit:
    """Refit the trial with the chosen extension (``extension=False``: with none, the
    reference the extension's refit is measured against) and return the refit
    (:class:`solver.diagnose.refit.Refit`).

    Without reviewer flags the extension's refit proposes its unmeasured frames as the next
    processing would: on ``ik_q`` ``(T, n)``, the marker-only motion, when given (proposals
    made on the processed motion differ at the edges of their runs, and the frames they let
    in bend the refitted motion). The refit without the extension keeps the frames the
    processing left out (same inputs, same frames).
    """
    from solver.diagnose.refit import refit_trial

    data = result.data
    assert data is not None and result.chosen is not None
    ev = result.chosen
    trial = data.trial
    setup = RefitSetup(read_osim(trial.model_path), inputs.raw.forces, data.stated_mass)
    # as `addb process` would: a reviewer's flags replace the solver's proposals; saved
    # extensions and an unmeasured_force extension join them
    flagged = np.asarray(data.flagged, dtype=bool)
    known: BoolArray | None = flagged.copy()
    unmeasured = flagged if inputs.reviewed else None
    if not extension:
        # the processing continued on the same inputs: the frames it left out stay out (the
        # refit's own proposals, made on the processed motion instead of the inverse
        # kinematics, differ at the edges of its runs)
        unmeasured, known = np.asarray(trial.unobserved, dtype=bool), None
    else:
        # the extension's own change (:meth:`solver.diagnose.causes.base.Cause.refit`)
        setup = cause(ev.cause).refit(setup, ev.parameters, entry_inputs(data, marker_time))
        for a, b in setup.unmeasured_runs:
            known[a:b] = True
    return refit_trial(
        trial,
        setup.model,
        setup.forces,
        mass_kg=setup.mass_kg,
        feet=data.feet,
        unmeasured=unmeasured,
        known_unmeasured=known,
        observed=setup.observed,
        proposal_q=ik_q if extension else None,
    )


def diagnose_trial(
    subject_dir: str | Path,
    trial: str,
    out_dir: str | Path,
    *,
    unmeasured_force: BoolArray | None = None,
    options: DiagnoseOptions | None = None,
    progress: Progress | None = None,
    subject_flags: Mapping[str, BoolArray] | None = None,
) -> Diagnosis:
    """Diagnose one processed trial of a subject.

    The trial is judged on the fit the diagnosis is calibrated on, the alternation of
    ``addb process --fit rounds`` (:mod:`solver.diagnose.judged_fit`): when the output was
    made with another (the default joint fit, ``--fit band``), the subject's dynamics are run
    again with it in a scratch folder first, and the report's figures are that fit's
    (``settings["judged_fit"]``: the two fits' names, :func:`solver.dynamics.fit.fit_name`).

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder (raw files, stated mass, saved extensions).
    trial
        Trial name.
    out_dir
        The subject's processed output folder (``OUT/<trial>/trial.npz``).
    unmeasured_force
        ``(T,)`` the reviewer's flags of unmeasured force at the trial's processed frames
        (:mod:`solver.masks`; None: none); they replace the solver's proposals.
    options
        Folds, thresholds, refit.
    progress
        Called with (message, fraction).
    subject_flags
        Trial name -> the reviewer's flags of every trial the output was processed with
        (the body mass factors are fitted over all of them), for the judged fit's run;
        default: ``unmeasured_force`` for ``trial`` alone.

    Raises
    ------
    FileNotFoundError
        The trial is not processed in ``out_dir``.
    DiagnosisError
        The trial has no dynamics (no force plates).
    """
    from solver.diagnose.judged_fit import is_judged_fit, judged_fit, judged_output
    from solver.dynamics.fit import fit_name
    from solver.pipeline import recorded_dynamics_options

    say = progress or (lambda m, f: None)
    recorded = recorded_dynamics_options(out_dir)
    processed_fit = recorded.fit
    rebuilt = not is_judged_fit(processed_fit)
    share = 0.3 if rebuilt else 0.0  # of the progress: the judged fit's run
    flags = dict(subject_flags) if subject_flags is not None else ({} if unmeasured_force is None else {trial: unmeasured_force})
    with judged_output(subject_dir, out_dir, trial, flags, lambda m, f: say(m, share * f), recorded=recorded) as base:
        inputs = load_inputs(subject_dir, trial, base, unmeasured_force)
        processed = load_processed(base, trial)
        diag = diagnose_processed(processed, inputs, options, lambda m, f: say(m, share + (1 - share) * f))
    diag.settings["judged_fit"] = {
        "fit": fit_name(judged_fit(processed_fit)),
        "processed_fit": fit_name(processed_fit),
        "rebuilt": rebuilt,
    }
    return diag
