"""The reviewer's edits of one trial, through :class:`annotations.AnnotationStore`.

Every edit method returns only once the store has made the edit durable (journal
fsync-ed), so the page may say "saved" when it returns. :class:`FlagView` is what the
page shows: flagged frames per foot, and the solver's automatic proposals split into
pending, accepted (flags whose provenance source is ``proposal_accepted``) and rejected.

Rejections are recorded as frame-range notes whose text starts with
:data:`REJECTED_NOTE` (the store has no record type for a declined proposal yet), so
they are durable, attributed and undoable like every other edit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from addb_viewer.app.state import run_at
from annotations import (
    FEET,
    AnnotationError,
    AnnotationStore,
    Edit,
    TrialReview,
)
from solver.masks import true_runs

REJECTED_NOTE = "[addb] proposal rejected"
"""Text prefix of the notes that record a rejected automatic proposal."""

BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class FlagView:
    """The review state of one trial as masks over its frames.

    Attributes
    ----------
    flagged
        ``(T,)`` frames flagged with unmeasured force (any foot or none said).
    left, right
        ``(T,)`` frames flagged for that foot (``"both"`` counts for each).
    accepted
        ``(T,)`` flagged frames whose flag came from an accepted proposal.
    proposed
        ``(T,)`` the solver's automatic proposals.
    rejected
        ``(T,)`` proposals the reviewer rejected and has not flagged since (a flag made by
        hand over a rejected proposal is what the solver takes: it is agreed then).
    pending
        ``(T,)`` proposals neither flagged nor rejected.
    feet
        ``(T,)`` object array: the flag's foot ("left", "right", "both", "" when not
        said) or None where not flagged.
    reviewed
        Whether the trial is marked as reviewed.
    beyond
        Number of flagged frames at or past the end of the trial (a record that does not
        belong to this trial's length); they are not shown.
    """

    flagged: BoolArray
    left: BoolArray
    right: BoolArray
    accepted: BoolArray
    proposed: BoolArray
    rejected: BoolArray
    pending: BoolArray
    feet: NDArray[np.object_]
    reviewed: bool
    beyond: int = 0

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.flagged.size)

    @property
    def agreed(self) -> BoolArray:
        """``(T,)`` proposals the reviewer's flags cover and that are not rejected: accepted,
        or flagged by hand. Every proposal is pending, agreed or rejected, and the timeline,
        the status line and the Flags summary count it so."""
        return self.proposed & self.flagged & ~self.rejected


def build_view(review: TrialReview, proposed: BoolArray) -> FlagView:
    """:class:`FlagView` of a store snapshot and the solver's ``(T,)`` proposals."""
    n = int(proposed.size)
    flagged = np.zeros(n, bool)
    left = np.zeros(n, bool)
    right = np.zeros(n, bool)
    accepted = np.zeros(n, bool)
    feet = np.full(n, None, dtype=object)
    beyond = 0
    for run in review.unmeasured_force:
        s, e = min(run.start, n), min(run.stop, n)
        beyond += run.stop - max(run.start, e)
        if s >= e:
            continue
        flagged[s:e] = True
        feet[s:e] = run.foot or ""
        if run.foot in ("left", "both"):
            left[s:e] = True
        if run.foot in ("right", "both"):
            right[s:e] = True
        if run.provenance.source == "proposal_accepted":
            accepted[s:e] = True
    rejected = np.zeros(n, bool)
    for note in review.notes:
        if note.start is not None and note.stop is not None and note.text.startswith(REJECTED_NOTE):
            rejected[min(note.start, n) : min(note.stop, n)] = True
    rejected &= proposed & ~flagged  # rejected, then flagged by hand: the flag is what the fit takes
    return FlagView(
        flagged=flagged,
        left=left,
        right=right,
        accepted=accepted,
        proposed=proposed.copy(),
        rejected=rejected,
        pending=proposed & ~flagged & ~rejected,
        feet=feet,
        reviewed=review.reviewed,
        beyond=beyond,
    )


def flags_replace_proposals(view: FlagView) -> bool:
    """Whether the reviewer's flags replace the solver's own proposals in the next solver
    run: once the trial has any flag (past its end too) or is marked reviewed
    (:mod:`addb_viewer.review_masks`)."""
    return bool(view.flagged.any()) or view.reviewed or view.beyond > 0


def pending_replaced(view: FlagView) -> int:
    """Pending proposals that the next solver run fits as measured frames: once a trial has
    any flag or is marked reviewed, the reviewer's flags replace the solver's own proposals
    (:mod:`addb_viewer.review_masks`), so a proposal neither accepted nor rejected is then a
    measured frame; 0 while the trial has neither (the solver keeps its proposals)."""
    return int(view.pending.sum()) if flags_replace_proposals(view) else 0


def rejections_ignored(view: FlagView) -> int:
    """Rejected proposals that the next solver run does not take: while a trial has no flag
    and is not marked reviewed, the solver keeps its own proposals
    (:mod:`addb_viewer.review_masks`), rejected ones included; 0 once it has either (then
    :func:`pending_replaced` applies)."""
    return 0 if flags_replace_proposals(view) else int(view.rejected.sum())


#: The reasons the dynamics stage gives the frames it leaves out (results.json's
#: ``unobserved_reasons``, :mod:`solver.dynamics.stage`) for the reviewer's flags and for a
#: saved correction of ``addb diagnose``.
FLAGGED_REASON = "flagged by the reviewer"
CORRECTION_REASON = "unmeasured force found by addb diagnose"


def flags_differ_from_fit(mask: BoolArray | None, unobserved: BoolArray, proposed: BoolArray, reasons: list[str]) -> int:
    """Frames the next solver run would leave out, or fit, otherwise than the fit shown:
    how stale the shown results are after flag edits (a flag, an Undo after a Reprocess).

    Parameters
    ----------
    mask
        ``(T,)`` the reviewer's flags as the solver takes them
        (:func:`addb_viewer.review_masks.unmeasured_force`), None when the solver keeps its
        own choice for the trial (no flag, not marked reviewed).
    unobserved, proposed
        ``(T,)`` the fit's left-out frames and the solver's proposals (the processed trial).
    reasons
        The fit's reasons for its left-out frames (results.json ``unobserved_reasons``).

    Returns
    -------
    int
        0 when the next run takes the same frames; without flags, at least 1 when the fit
        used flags since removed. Frames a saved correction added are not counted.
    """
    used_flags = FLAGGED_REASON in reasons
    if mask is None:
        return max(int((unobserved != proposed).sum()), 1) if used_flags else 0
    mask = np.asarray(mask, bool)
    if mask.shape != unobserved.shape:
        return 0  # other frames: the run says so itself
    if any(r.startswith(CORRECTION_REASON) for r in reasons):
        return int((mask & ~unobserved).sum())  # the correction's frames are left out as well
    return int((mask != unobserved).sum())


def unproposed_replaced(view: FlagView, unobserved: BoolArray, proposed: BoolArray, reasons: list[str]) -> int:
    """Frames the solver left out of the fit shown without proposing them (two feet on one
    plate, plate force with no foot on the plate: :mod:`solver.dynamics.stage`) that the
    next run fits as measured because the reviewer's flags replace the solver's choice
    (:func:`flags_replace_proposals`) and do not cover them; 0 when the fit shown already
    took the reviewer's flags (``reasons``: results.json's ``unobserved_reasons``).
    ``unobserved``, ``proposed``: ``(T,)`` the fit's left-out frames and the solver's
    proposals (the processed trial)."""
    if not flags_replace_proposals(view) or FLAGGED_REASON in reasons or unobserved.shape != view.flagged.shape:
        return 0
    return int((unobserved & ~proposed & ~view.flagged).sum())


def describe_flags(v: FlagView, *, differ: int = 0, unproposed: int = 0, record: str = "") -> str:
    """The Flags folder's summary of a trial's flags (markdown): frames flagged per foot, the
    proposals pending, agreed and rejected, and in red what the next solver run does
    otherwise than the reviewer may think (rejections it ignores, pending proposals it fits
    as measured: :func:`rejections_ignored`, :func:`pending_replaced`); ``differ`` frames
    whose flags differ from the fit shown (:func:`flags_differ_from_fit`), ``unproposed``
    frames left out without a proposal that the next run fits as measured
    (:func:`unproposed_replaced`), ``record`` a sentence naming the review record when it
    is not in the subject folder."""
    n_prop = int(v.proposed.sum())
    no_foot = int((v.flagged & ~v.left & ~v.right).sum())  # accepted proposals, flags without a foot
    both = int((v.left & v.right).sum())  # counted once, not under left and right (the parts add up)
    sentences = [
        f"{int(v.flagged.sum())} frames flagged ({int((v.left & ~v.right).sum())} left, {int((v.right & ~v.left).sum())} right"
        + (f", {both} both feet" if both else "") + (f", {no_foot} without a foot" if no_foot else "") + ")",
        f"Automatic proposals: {n_prop} frames" + (
            f" — {int(v.pending.sum())} pending, {int(v.agreed.sum())} accepted or flagged, {int(v.rejected.sum())} rejected"
            if n_prop else ""),
    ]  # fmt: skip
    if v.beyond:
        sentences.append(f"{v.beyond} flagged frames lie past the end of this trial")
    ignored = rejections_ignored(v)
    if ignored:
        sentences.append(
            f"<span style='color:#c00'>**{ignored} rejected proposed frames are still left out of the fit**</span>: "
            "the solver keeps its own choice until the trial has a flag or is marked reviewed; tick "
            "Trial reviewed to fit them as measured"
        )
    pending = pending_replaced(v)
    if pending:
        sentences.append(
            f"<span style='color:#c00'>**{pending} pending proposed frames will be fitted as measured**</span>: "
            "once a trial has flags or is marked reviewed, its flags replace the solver's own choice "
            "(in Reprocess and in the dataset run); accept or reject them first"
        )
    if unproposed:
        sentences.append(
            f"<span style='color:#c00'>**{unproposed} more frames the solver left out without proposing them will be "
            "fitted as measured**</span> (two feet on one plate, or plate force with no foot on it: the left out "
            "track); flag them to keep them out"
        )
    if differ:
        sentences.append(
            f"<span style='color:#c00'>**The results shown were fitted with other flags**</span> ({differ} "
            f"frame{'s differ' if differ != 1 else ' differs'}): Reprocess to fit these"
        )
    if record:
        sentences.append(record)
    return ". ".join(sentences) + "."


def toggled_foot(current: str | None, foot: str) -> str | None:
    """The foot a frame is flagged for after toggling ``foot`` (None: not flagged).

    ``current`` is the frame's flag (None not flagged, "" flagged without a foot).
    Toggling a foot on an unflagged frame flags it; on a frame flagged for the other
    foot it gives "both"; on "both" it leaves the other foot; toggling the frame's own
    foot, "both", or any foot on a flag without a foot clears it.

    Raises
    ------
    AnnotationError
        ``foot`` is not "left", "right" or "both".
    """
    if foot not in FEET:
        raise AnnotationError(f"foot must be one of {FEET}, got {foot!r}")
    if current is None:
        return foot
    if current == "" or current == foot or foot == "both":
        return None
    if current == "both":
        return "left" if foot == "right" else "right"
    return "both"


class TrialEditor:
    """Reads and edits one trial's flags in an open store.

    Parameters
    ----------
    store
        The subject's open store (its reviewer is recorded with every edit).
    trial
        Trial name.
    proposed
        ``(T,)`` the solver's automatic proposals.
    reasons
        ``(T,)`` the reason of each proposal ("" where none).
    """

    def __init__(
        self, store: AnnotationStore, trial: str, proposed: BoolArray, reasons: tuple[str, ...]
    ) -> None:
        self.store = store
        self.trial = trial
        self.proposed = np.asarray(proposed, dtype=bool)
        self.reasons = reasons
        self.n_frames = int(self.proposed.size)

    def view(self) -> FlagView:
        """The current :class:`FlagView` (includes other writers' saved edits once the
        store has been refreshed)."""
        return build_view(self.store.review(self.trial), self.proposed)

    # ------------------------------------------------------------------ flags
    def toggle(self, frame: int, foot: str) -> Edit:
        """Toggle ``foot``'s unmeasured-force flag on one frame (see :func:`toggled_foot`)."""
        frame = self._frame(frame)
        new = toggled_foot(self.view().feet[frame], foot)
        if new is None:
            return self.store.set_unmeasured(self.trial, frame, False)
        return self.store.set_unmeasured(self.trial, frame, True, foot=new)

    def flag_range(self, start: int, stop: int, foot: str | None) -> Edit:
        """Flag frames ``[start, stop)`` for ``foot``: a frame flagged for the other foot
        becomes "both" (the reviewer's earlier flag is kept), other earlier flags there are
        replaced; one edit (one undo step)."""
        return self.store.set_unmeasured(self.trial, self._range(start, stop), True, foot=foot, keep_other_foot=True)

    def clear_range(self, start: int, stop: int, foot: str = "both") -> list[Edit]:
        """Clear the unmeasured-force flags of frames ``[start, stop)``: every flag with
        ``foot`` "both", else ``foot``'s ("left" or "right"): a frame flagged for both feet
        keeps the other foot's flag, a flag of this foot goes, the other foot's flags and
        flags without a foot (accepted proposals) stay (Foot "both" clears those). Returns
        the edits made (one action: one undo step in the app; empty when nothing changed).

        Raises
        ------
        AnnotationError
            A range outside the trial, or an unknown foot.
        """
        rng = self._range(start, stop)
        if foot not in FEET:
            raise AnnotationError(f"foot must be one of {FEET}, got {foot!r}")
        if foot == "both":
            return [self.store.set_unmeasured(self.trial, rng, False)]
        feet = self.view().feet
        other = "left" if foot == "right" else "right"
        cleared = [f for f in rng if feet[f] == foot]
        kept_other = [f for f in rng if feet[f] == "both"]
        edits = []
        if cleared:
            edits.append(self.store.set_unmeasured(self.trial, cleared, False))
        if kept_other:
            edits.append(self.store.set_unmeasured(self.trial, kept_other, True, foot=other))
        return edits

    # ------------------------------------------------------------------ proposals
    def proposal_at(self, frame: int) -> tuple[int, int, str] | None:
        """The pending proposal run ``(start, stop, reason)`` containing ``frame``."""
        run = run_at(self.view().pending, frame)
        if run is None:
            return None
        return run[0], run[1], self.reasons[run[0]] if run[0] < len(self.reasons) else ""

    def accept(self, frame: int | None = None) -> Edit | None:
        """Accept the pending proposal at ``frame`` (all pending ones when None) as
        unmeasured-force flags; None when there is nothing to accept."""
        pending = self.view().pending
        if frame is not None:
            run = run_at(pending, self._frame(frame))
            if run is None:
                return None
            frames: range | list[int] = range(*run)
        else:
            frames = np.flatnonzero(pending).tolist()
            if not frames:
                return None
        return self.store.set_unmeasured(self.trial, frames, True, source="proposal_accepted")

    def reject(self, frame: int | None = None) -> list[Edit]:
        """Reject the pending proposal at ``frame`` (all pending ones when None).

        Returns one edit per rejected run (empty when there was nothing to reject).
        """
        pending = self.view().pending
        if frame is not None:
            run = run_at(pending, self._frame(frame))
            runs = [] if run is None else [run]
        else:
            runs = true_runs(pending)
        return self._reject_runs(runs)

    def accept_range(self, start: int, stop: int) -> Edit | None:
        """Accept the pending proposals inside frames ``[start, stop)`` as flags; None when
        none is pending there."""
        rng = self._range(start, stop)
        pending = self.view().pending
        frames = [f for f in rng if pending[f]]
        if not frames:
            return None
        return self.store.set_unmeasured(self.trial, frames, True, source="proposal_accepted")

    def reject_range(self, start: int, stop: int) -> list[Edit]:
        """Reject the pending proposals inside frames ``[start, stop)`` (each run clipped to
        the range); one edit per run, empty when none is pending there."""
        rng = self._range(start, stop)
        inside = np.zeros(self.n_frames, bool)
        inside[rng.start : rng.stop] = True
        return self._reject_runs(true_runs(self.view().pending & inside))

    def _reject_runs(self, runs: list[tuple[int, int]]) -> list[Edit]:
        """Record each half-open run of proposals as rejected (a note with its reason)."""
        edits = []
        for s, e in runs:
            reason = self.reasons[s] if s < len(self.reasons) else ""
            text = f"{REJECTED_NOTE}: {reason}" if reason else REJECTED_NOTE
            edits.append(self.store.add_note(self.trial, text, start=s, stop=e))
        return edits

    # ------------------------------------------------------------------ other
    def set_reviewed(self, reviewed: bool = True) -> Edit:
        """Mark the trial as reviewed (or not)."""
        return self.store.set_reviewed(self.trial, reviewed)

    def _frame(self, frame: int) -> int:
        f = int(frame)
        if not 0 <= f < self.n_frames:
            raise AnnotationError(f"frame {f} is outside the trial (0..{self.n_frames - 1})")
        return f

    def _range(self, start: int, stop: int) -> range:
        s, e = int(start), int(stop)
        if not 0 <= s < e <= self.n_frames:
            raise AnnotationError(f"frame range [{s}, {e}) is not inside the trial (0..{self.n_frames})")
        return range(s, e)


def describe_frame(view: FlagView, frame: int, reasons: tuple[str, ...]) -> str:
    """One line about a frame's flag and proposal, for the page."""
    parts = []
    foot = view.feet[frame] if 0 <= frame < view.n_frames else None
    if foot is not None:
        what = "unmeasured force" + (f" ({foot} foot)" if foot in ("left", "right") else "")
        what += " (both feet)" if foot == "both" else ""
        what += ", accepted proposal" if view.accepted[frame] else ""
        parts.append("**flagged**: " + what)
    if 0 <= frame < view.n_frames and view.proposed[frame]:
        reason = reasons[frame] if frame < len(reasons) and reasons[frame] else "no reason given"
        state = "pending" if view.pending[frame] else "rejected" if view.rejected[frame] else "accepted"
        parts.append(f"proposal ({state}): {reason}")
    return "; ".join(parts) if parts else "not flagged"
