"""The review record's data model: immutable records returned by the store.

Conventions
-----------
* Frames are 0-based indices on the frames of the trial the record was made on, whose
  count and rate the record keeps (:attr:`TrialReview.n_frames`, :attr:`TrialReview.rate_hz`;
  the review app and ``addb convert`` record the solver's processed frames, 100 Hz; how
  other rates are read: :mod:`addb_viewer.review_masks`). A range is half-open,
  ``[start, stop)``.
* Times are UTC, ISO 8601 with milliseconds and a ``Z`` suffix:
  ``"2026-11-21T15:59:14.123Z"``.
* Every flag, activity range, note and "reviewed" mark carries a :class:`Provenance`:
  who made it, when, and from where.

The store keeps its own mutable state; these records are snapshots that the app can
keep, compare (``==``) and share between threads.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Final, Literal

FlagKind = Literal["unmeasured_force", "excluded"]
Foot = Literal["left", "right", "both"]
Source = Literal["manual", "proposal_accepted", "imported"]

UNMEASURED_FORCE: Final = "unmeasured_force"
"""Flag kind: the ground reaction force of this frame is not fully measured (a foot
off the plates, or any other unmeasured contact). The solver keeps the frame in the
kinematic fit and leaves it out of the dynamic fit."""

EXCLUDED: Final = "excluded"
"""Flag kind: the frame is erroneous (marker swap, gap filled badly) and is excluded."""

FLAG_KINDS: Final[tuple[str, ...]] = (UNMEASURED_FORCE, EXCLUDED)
FEET: Final[tuple[str, ...]] = ("left", "right", "both")
SOURCES: Final[tuple[str, ...]] = ("manual", "proposal_accepted", "imported")

ACTIVITY_LABELS: Final[tuple[str, ...]] = (
    "overground_walking",
    "treadmill_walking",
    "inclined_walking",
    "overground_running",
    "treadmill_running",
    "stairs_up",
    "stairs_down",
    "sit_to_stand",
    "jump",
    "drop_jump",
    "squat_jump",
    "box_jump",
    "squat",
    "lunge",
    "standing",
    "single_leg_standing",
    "transition_start",
    "transition_end",
    "other",
)
"""Activity classes of the seed paper, spelled in snake case as stored in the file."""


def format_timestamp(when: datetime) -> str:
    """UTC ISO 8601 text with milliseconds and ``Z``, e.g. ``2026-11-21T15:59:14.123Z``.

    Parameters
    ----------
    when
        A timezone-aware datetime (any zone; converted to UTC).

    Raises
    ------
    ValueError
        If ``when`` is naive (no timezone), since its instant would be a guess.
    """
    if when.tzinfo is None or when.utcoffset() is None:
        raise ValueError(f"timestamp {when!r} has no timezone; give an aware datetime (UTC)")
    return when.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.") + f"{when.microsecond // 1000:03d}Z"


def utc_now() -> datetime:
    """The current time, timezone-aware UTC (the store's default clock)."""
    return datetime.now(UTC)


@dataclass(frozen=True, slots=True)
class Provenance:
    """Who made an annotation, when, and from where.

    Attributes
    ----------
    reviewer
        Reviewer name given when the store was opened.
    timestamp
        UTC ISO 8601 time of the edit, e.g. ``"2026-11-21T15:59:14.123Z"``.
    source
        ``"manual"`` (set by hand), ``"proposal_accepted"`` (an automatic proposal the
        reviewer accepted) or ``"imported"`` (read from another file, e.g. AddBiomechanics).
    """

    reviewer: str
    timestamp: str
    source: str


@dataclass(frozen=True, slots=True)
class FrameFlag:
    """One flagged frame.

    Attributes
    ----------
    frame
        0-based frame index at the trial's frame rate.
    kind
        ``"unmeasured_force"`` or ``"excluded"``.
    foot
        For ``unmeasured_force``: ``"left"``, ``"right"``, ``"both"`` or ``None`` (not said).
        Always ``None`` for ``excluded``.
    provenance
        Who set the flag, when, from where.
    """

    frame: int
    kind: str
    foot: str | None
    provenance: Provenance


@dataclass(frozen=True, slots=True)
class FlagRun:
    """Consecutive frames ``[start, stop)`` with the same flag, foot and provenance.

    Attributes
    ----------
    start, stop
        Half-open frame range, 0-based frame indices at the trial's frame rate.
    kind
        ``"unmeasured_force"`` or ``"excluded"``.
    foot
        As in :class:`FrameFlag`.
    provenance
        Who set these flags, when, from where.
    """

    start: int
    stop: int
    kind: str
    foot: str | None
    provenance: Provenance


@dataclass(frozen=True, slots=True)
class ActivityRange:
    """A labelled range of frames.

    Attributes
    ----------
    id
        Identifier, unique in the subject (used to edit or remove the range).
    start, stop
        Half-open frame range ``[start, stop)``.
    label
        One of :data:`ACTIVITY_LABELS`.
    note
        Free text ("" if none).
    provenance
        Who created or last changed the range.
    """

    id: str
    start: int
    stop: int
    label: str
    note: str
    provenance: Provenance


@dataclass(frozen=True, slots=True)
class Note:
    """A free-text note on a trial, optionally attached to frames ``[start, stop)``.

    Attributes
    ----------
    id
        Identifier, unique in the subject.
    text
        The note.
    start, stop
        Half-open frame range, or both ``None`` for a note on the whole trial.
    provenance
        Who wrote the note.
    """

    id: str
    text: str
    start: int | None
    stop: int | None
    provenance: Provenance


@dataclass(frozen=True, slots=True)
class TrialReview:
    """Everything recorded about one trial (a snapshot).

    Attributes
    ----------
    trial
        Trial name (e.g. the trial's folder name).
    reviewed
        Whether the trial is marked as reviewed.
    reviewed_provenance
        Who set or cleared ``reviewed`` last; ``None`` if nobody ever did.
    unmeasured_force, excluded
        Flagged frames as runs, sorted by ``start``; consecutive frames with the same
        foot and provenance form one run.
    activities
        Activity ranges sorted by ``(start, stop, id)``.
    notes
        Notes sorted by ``(start, id)`` (trial notes, ``start is None``, first).
    n_frames
        Number of frames of the trial if recorded (see ``AnnotationStore.set_trial_info``).
    rate_hz
        Frame rate of the trial, Hz, if recorded.
    """

    trial: str
    reviewed: bool
    reviewed_provenance: Provenance | None
    unmeasured_force: tuple[FlagRun, ...]
    excluded: tuple[FlagRun, ...]
    activities: tuple[ActivityRange, ...]
    notes: tuple[Note, ...]
    n_frames: int | None
    rate_hz: float | None


@dataclass(frozen=True, slots=True)
class Conflict:
    """Two writers changed the same thing; the later write won and this records the loser.

    Attributes
    ----------
    id
        Identifier (``"<edit id>/<n>"``), used by ``AnnotationStore.clear_conflicts``.
    trial
        Trial name.
    target
        What was changed: ``"unmeasured_force"``, ``"excluded"``, ``"reviewed"``,
        ``"activity"``, ``"note"`` or ``"trial_info"``.
    item_id
        Activity or note id for those targets, else ``None``.
    frames
        Half-open frame ranges concerned (flags only; empty otherwise).
    kept_edit
        Id of the edit whose value is now in the record (``None`` if not known).
    kept
        Provenance of the value now in the record (``None`` if it has none).
    overridden_edit
        Id of the edit whose value was replaced or not restored.
    overridden
        Provenance of that edit.
    reason
        ``"last_write_wins"``: a writer changed what another writer had changed since
        the first last synchronised with the file. ``"undo_skipped"`` (``"redo_skipped"``):
        an undo (redo) left these values as they are, because another writer changed them
        after the edit being undone (redone).
    """

    id: str
    trial: str
    target: str
    item_id: str | None
    frames: tuple[tuple[int, int], ...]
    kept_edit: str | None
    kept: Provenance | None
    overridden_edit: str
    overridden: Provenance
    reason: str


@dataclass(frozen=True, slots=True)
class Edit:
    """Receipt of one durable edit: it is in the journal on disk when this is returned.

    Attributes
    ----------
    id
        Unique id of the operation in the journal.
    seq
        Its position in the subject's journal (1, 2, ...).
    op
        Operation type: ``"flags"``, ``"reviewed"``, ``"activity"``, ``"note"``,
        ``"trial_info"``, ``"clear_conflicts"`` or ``"none"`` (nothing changed, e.g. an
        undo whose values another writer had already replaced).
    trial
        Trial changed (``None`` for ``clear_conflicts``).
    provenance
        Who, when and from where.
    item_id
        Id of the activity range or note created or changed, else ``None``.
    changed
        Number of values changed (frames for flags; 0 or 1 otherwise).
    conflicts
        Conflicts this edit created (see :class:`Conflict`).
    """

    id: str
    seq: int
    op: str
    trial: str | None
    provenance: Provenance
    item_id: str | None = None
    changed: int = 0
    conflicts: tuple[Conflict, ...] = ()
