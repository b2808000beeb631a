"""The durable, multi-writer store of one subject's review record.

Files in the subject folder
---------------------------
``annotations.json``
    The record, human-readable (schema in :mod:`annotations.schema`). Rewritten
    atomically from time to time ("compaction"), never edited in place.
``annotations.journal``
    Every edit ever made, one JSON line each with a checksum, appended and fsync-ed
    before the edit call returns. The subject file says up to which line it is current;
    newer lines are replayed on open. The journal is the full history, so
    :meth:`AnnotationStore.recover` can rebuild a damaged subject file from it.
``annotations.lock``
    An empty file locked with ``flock`` around every read and write of the two others,
    so that several processes (two browser tabs served by two app processes, the app and
    a script) and threads can edit the same subject: each writer first reads what the
    others appended, then appends.

Two writers changing the same frame: the later write wins, and if its writer had not
seen the earlier one (it had not synchronised since), the loser is listed by
:meth:`AnnotationStore.conflicts`.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from annotations.arguments import (
    MAX_FRAME,
    FramesLike,
    check_foot,
    check_kind,
    check_source,
    check_trial,
    count,
    frames_list,
    span,
)
from annotations.engine import OPEN_TOKEN, Clock, JournaledStore
from annotations.errors import AnnotationError, AnnotationFileError
from annotations.journal import (
    StorePaths,
)
from annotations.masks import frames_to_ranges
from annotations.model import (
    ACTIVITY_LABELS,
    EXCLUDED,
    UNMEASURED_FORCE,
    ActivityRange,
    Conflict,
    Edit,
    FlagRun,
    FrameFlag,
    Note,
    Provenance,
    TrialReview,
    utc_now,
)
from annotations.recovery import RecoveryReport
from annotations.schema import Key
from annotations.state import (
    flag_mask,
    flag_runs,
)


class AnnotationStore(JournaledStore):
    """Review record of one subject: flags, activity ranges, notes, reviewed marks.

    Open with :meth:`open`; every edit method returns an :class:`~annotations.model.Edit`
    only once the edit is durable (in the journal and fsync-ed). All methods are
    thread-safe. Open one store per browser client to give each its own undo history
    and conflict detection; stores in one or several processes may share a subject.

    Frames are 0-based indices at the trial's frame rate; ranges are half-open
    ``[start, stop)``; a ``frames`` argument is an ``int``, a ``range`` or an iterable of
    ints (use :meth:`set_mask` for boolean masks).
    """

    # =================================================================== open / close
    @classmethod
    def open(
        cls,
        path: str | os.PathLike[str],
        *,
        reviewer: str,
        clock: Clock | None = None,
        compact_every: int = 1000,
        max_undo: int = 10_000,
    ) -> AnnotationStore:
        """Open (or create) the review record of a subject.

        Parameters
        ----------
        path
            The subject folder (the record is ``<folder>/annotations.json``) or the path
            of the ``.json`` record itself. The folder must exist.
        reviewer
            Name recorded as the author of every edit made through this store.
        clock
            Returns the current time as an aware ``datetime`` (default: UTC now).
            Injectable for tests.
        compact_every
            Rewrite the subject file after this many journal operations (also on
            :meth:`close`). Larger is faster per edit; the journal is replayed on open.
        max_undo
            Number of undo steps kept in this session.

        Returns
        -------
        AnnotationStore

        Raises
        ------
        AnnotationFileError
            If the subject file or the journal is damaged, of an unsupported version or
            inconsistent (the message names the file; nothing is overwritten; see
            :meth:`recover`), or the folder cannot be written.
        AnnotationError
            If ``reviewer`` is empty.
        """
        name = str(reviewer).strip() if reviewer is not None else ""
        if not name or len(name) > 200 or any(ord(c) < 32 for c in name):
            raise AnnotationError(f"reviewer must be a non-empty name, got {reviewer!r}")
        if compact_every < 1 or max_undo < 0:
            raise AnnotationError("compact_every must be >= 1 and max_undo >= 0")
        paths = StorePaths.for_path(path)
        if not paths.main.parent.is_dir():
            raise AnnotationFileError("the subject folder does not exist", path=paths.main.parent)
        store = cls(
            paths,
            reviewer=name,
            clock=clock or utc_now,
            compact_every=compact_every,
            max_undo=max_undo,
            _token=OPEN_TOKEN,
        )
        store._open_files()
        return store

    @staticmethod
    def recover(
        path: str | os.PathLike[str],
        *,
        skip_damaged_lines: bool = False,
        clock: Clock | None = None,
    ) -> RecoveryReport:
        """Rebuild a damaged subject file from the journal (or restart a damaged journal).

        See :func:`annotations.recovery.recover`. Close every store of the subject first.
        """
        from annotations.recovery import recover

        return recover(path, skip_damaged_lines=skip_damaged_lines, clock=clock)

    # =================================================================== reading
    def trials(self) -> list[str]:
        """Names of the trials with anything recorded, sorted."""
        with self._tlock:
            return self._state.trial_names()

    def review(self, trial: str) -> TrialReview:
        """Snapshot of everything recorded for a trial (empty if nothing)."""
        with self._tlock:
            return self._state.review(trial)

    def snapshot(self) -> dict[str, TrialReview]:
        """Snapshots of all trials with anything recorded, by name."""
        with self._tlock:
            return {name: self._state.review(name) for name in self._state.trial_names()}

    def flag(self, trial: str, frame: int, kind: str = UNMEASURED_FORCE) -> FrameFlag | None:
        """The flag of one frame, or ``None`` if the frame is not flagged."""
        kind = check_kind(kind)
        with self._tlock:
            t = self._state.trials.get(trial)
            entry = None if t is None else t.flags[kind].get(int(frame))
        return None if entry is None else FrameFlag(int(frame), kind, entry[0], entry[1])

    def flag_runs(self, trial: str, kind: str = UNMEASURED_FORCE) -> list[FlagRun]:
        """Flagged frames as runs with equal foot and provenance, sorted."""
        kind = check_kind(kind)
        with self._tlock:
            t = self._state.trials.get(trial)
            return [] if t is None else flag_runs(t.flags[kind], kind)

    def ranges(
        self, trial: str, kind: str = UNMEASURED_FORCE, *, foot: str | None = None
    ) -> list[tuple[int, int]]:
        """Flagged frames as sorted, disjoint half-open ``(start, stop)`` ranges.

        Parameters
        ----------
        trial
            Trial name.
        kind
            ``"unmeasured_force"`` or ``"excluded"``.
        foot
            Only frames flagged for this foot (``"both"`` counts for each); ``None``: all.
        """
        kind = check_kind(kind)
        foot = check_foot(foot)
        with self._tlock:
            t = self._state.trials.get(trial)
            if t is None or not t.flags[kind]:
                return []
            flags = t.flags[kind]
            return frames_to_ranges(np.flatnonzero(flag_mask(flags, max(flags) + 1, foot)))

    def mask(
        self,
        trial: str,
        n_frames: int | None = None,
        *,
        kind: str = UNMEASURED_FORCE,
        foot: str | None = None,
    ) -> NDArray[np.bool_]:
        """Boolean mask of the flagged frames, on the frames the record has for the trial
        (the solver's masks are made from it by ``addb_viewer.review_masks.unmeasured_force``).

        Parameters
        ----------
        trial
            Trial name.
        n_frames
            Number of frames ``T`` of the trial; default: as recorded by
            :meth:`set_trial_info`.
        kind
            ``"unmeasured_force"`` (frames left out of the dynamic fit) or ``"excluded"``.
        foot
            Only frames flagged for this foot (``"both"`` counts for each); ``None``: all.

        Returns
        -------
        numpy.ndarray
            ``(T,)`` bool, ``True`` where flagged, at the trial's frame rate as recorded.

        Raises
        ------
        AnnotationError
            If ``n_frames`` is unknown, or a frame at or past ``n_frames`` is flagged
            (the annotations do not belong to a trial of this length).
        """
        kind = check_kind(kind)
        foot = check_foot(foot)
        with self._tlock:
            t = self._state.trials.get(trial)
            if n_frames is None:
                n_frames = None if t is None else t.info[0]
                if n_frames is None:
                    raise AnnotationError(
                        "n_frames not given and not recorded for this trial", where=trial
                    )
            n = count(n_frames, "n_frames")
            flags = {} if t is None else t.flags[kind]
            if flags and max(flags) >= n:
                raise AnnotationError(
                    f"frame {max(flags)} is flagged {kind} but the trial has only {n} frames",
                    where=trial,
                )
            return flag_mask(flags, n, foot)

    def activities(self, trial: str) -> list[ActivityRange]:
        """Activity ranges of a trial, sorted by ``(start, stop, id)``."""
        with self._tlock:
            return list(self._state.review(trial, flags=False).activities)

    def notes(self, trial: str) -> list[Note]:
        """Notes of a trial (whole-trial notes first, then by start frame)."""
        with self._tlock:
            return list(self._state.review(trial, flags=False).notes)

    def is_reviewed(self, trial: str) -> bool:
        """Whether the trial is marked as reviewed."""
        with self._tlock:
            t = self._state.trials.get(trial)
            return False if t is None else t.reviewed[0]

    def conflicts(self) -> list[Conflict]:
        """Conflicts recorded so far (by every writer), oldest first."""
        with self._tlock:
            return list(self._state.conflicts.values())

    # =================================================================== editing: flags
    def set_unmeasured(
        self,
        trial: str,
        frames: FramesLike,
        value: bool = True,
        *,
        foot: str | None = None,
        source: str = "manual",
        keep_other_foot: bool = False,
    ) -> Edit:
        """Flag (or clear) frames whose ground reaction force is not fully measured.

        Parameters
        ----------
        trial
            Trial name.
        frames
            Frame index, ``range`` or iterable of frame indices (0-based, trial rate).
        value
            True to flag, False to clear.
        foot
            ``"left"``, ``"right"``, ``"both"`` or ``None`` (not said); only with
            ``value=True``. The new flag replaces any earlier one on those frames.
        source
            ``"manual"``, ``"proposal_accepted"`` or ``"imported"``.
        keep_other_foot
            With ``foot`` "left" or "right": a frame already flagged for the other foot or
            for both becomes "both" instead of losing that flag (one edit, one undo step).

        Returns
        -------
        Edit
            Receipt; the edit is durable.

        Raises
        ------
        AnnotationError
            If ``foot`` is given with ``value=False``, ``foot`` or ``source`` is unknown,
            the trial name or ``frames`` are invalid, or a frame is past the trial's end.
        """
        foot = check_foot(foot)
        if foot is not None and not value:
            raise AnnotationError("foot is only given when flagging (value=True)")
        return self._flags_edit(
            trial, UNMEASURED_FORCE, frames, value=bool(value), foot=foot, source=source,
            keep_other_foot=keep_other_foot and foot in ("left", "right"),
        )

    def set_excluded(
        self, trial: str, frames: FramesLike, value: bool = True, *, source: str = "manual"
    ) -> Edit:
        """Flag (or clear) frames as erroneous, excluded from the fits.

        Parameters are as for :meth:`set_unmeasured` (without ``foot``).
        """
        return self._flags_edit(
            trial, EXCLUDED, frames, value=bool(value), foot=None, source=source
        )

    def set_mask(
        self,
        trial: str,
        mask: NDArray[np.bool_] | Iterable[bool],
        *,
        kind: str = UNMEASURED_FORCE,
        start_frame: int = 0,
        foot: str | None = None,
        source: str = "proposal_accepted",
        overwrite: bool = False,
    ) -> Edit:
        """Set frames ``[start_frame, start_frame + T)`` to a boolean mask, in one edit.

        The reverse of :meth:`mask`: use it to accept an automatic proposal or to import.

        Parameters
        ----------
        trial
            Trial name.
        mask
            ``(T,)`` bool; ``True`` flags the frame, ``False`` clears it.
        kind
            ``"unmeasured_force"`` or ``"excluded"``.
        start_frame
            Trial frame of ``mask[0]``.
        foot
            Foot recorded with new ``unmeasured_force`` flags.
        source
            Provenance source of the new flags.
        overwrite
            If False, frames already flagged keep their flag (foot, author) where the mask
            is True; if True they are replaced.

        Raises
        ------
        AnnotationError
            If ``kind``, ``foot`` or ``source`` is unknown, a foot is given for
            ``"excluded"``, ``mask`` is not a ``(T,)`` bool array, ``start_frame`` is not a
            non-negative integer, or the mask reaches past the trial's end.
        """
        kind = check_kind(kind)
        foot = check_foot(foot)
        if kind == EXCLUDED and foot is not None:
            raise AnnotationError("excluded frames have no foot")
        arr = np.asarray(mask)
        if arr.ndim != 1 or (arr.size and arr.dtype != np.bool_):
            raise AnnotationError(f"mask must be a (T,) bool array, got {arr.dtype} {arr.shape}")
        start = count(start_frame, "start_frame")
        self._check_frame_bound(trial, start + arr.size)
        source = check_source(source)

        def build(prov: Provenance) -> dict[Key, Any]:
            flags = self._state.trial(trial).flags[kind]
            new = (foot, prov)
            puts: dict[Key, Any] = {}
            for i, on in enumerate(arr.tolist()):
                f = start + i
                cur = flags.get(f)
                if on and (cur is None or overwrite):
                    puts[("flag", trial, kind, f)] = new
                elif not on and cur is not None:
                    puts[("flag", trial, kind, f)] = None
            return puts

        return self._commit("flags", trial, source, build, kind=kind)

    def _flags_edit(
        self,
        trial: str,
        kind: str,
        frames: FramesLike,
        *,
        value: bool,
        foot: str | None,
        source: str,
        keep_other_foot: bool = False,
    ) -> Edit:
        source = check_source(source)
        check_trial(trial)
        frame_list = frames_list(frames)
        self._check_frame_bound(trial, max(frame_list) + 1)

        def build(prov: Provenance) -> dict[Key, Any]:
            flags = self._state.trial(trial).flags[kind]
            if value and keep_other_foot:
                def merged(f: int) -> str | None:
                    old = flags.get(f)
                    return "both" if old is not None and old[0] in ("left", "right", "both") and old[0] != foot else foot

                return {("flag", trial, kind, f): (merged(f), prov) for f in frame_list}
            if value:
                return dict.fromkeys([("flag", trial, kind, f) for f in frame_list], (foot, prov))
            return {("flag", trial, kind, f): None for f in frame_list if f in flags}

        return self._commit("flags", trial, source, build, kind=kind)

    # =================================================================== editing: other
    def set_reviewed(self, trial: str, reviewed: bool = True, *, source: str = "manual") -> Edit:
        """Mark the trial as reviewed (or not)."""
        source = check_source(source)
        check_trial(trial)
        return self._commit(
            "reviewed", trial, source, lambda prov: {("reviewed", trial): (bool(reviewed), prov)}
        )

    def set_trial_info(
        self, trial: str, *, n_frames: int | None = None, rate_hz: float | None = None
    ) -> Edit:
        """Record the trial's number of frames and frame rate (Hz), used by :meth:`mask`.

        Bookkeeping, not a review decision: it is durable like every edit but does not go on
        the undo stack (an Undo right after opening a trial undoes the reviewer's last edit).

        Raises
        ------
        AnnotationError
            If frames at or past ``n_frames`` are already annotated.
        """
        check_trial(trial)
        n = None if n_frames is None else count(n_frames, "n_frames")
        if n == 0:
            raise AnnotationError("n_frames must be >= 1")
        rate = None if rate_hz is None else float(rate_hz)
        if rate is not None and not (np.isfinite(rate) and rate > 0):
            raise AnnotationError(f"rate_hz must be finite and > 0, got {rate_hz!r}")
        with self._tlock:
            t = self._state.trials.get(trial)
            if n is not None and t is not None:
                last = max(
                    [max(f, default=-1) for f in t.flags.values()]
                    + [a.stop - 1 for a in t.activities.values()]
                )
                if last >= n:
                    raise AnnotationError(
                        f"frame {last} is annotated but n_frames is {n}", where=trial
                    )
        return self._commit(
            "trial_info", trial, "manual", lambda prov: {("info", trial): (n, rate)}, history="none"
        )

    def add_activity(
        self,
        trial: str,
        start: int,
        stop: int,
        label: str,
        *,
        note: str = "",
        source: str = "manual",
    ) -> Edit:
        """Label frames ``[start, stop)`` with an activity; ``Edit.item_id`` is the new id.

        Parameters
        ----------
        trial
            Trial name.
        start, stop
            Half-open frame range, ``start < stop``.
        label
            One of :data:`~annotations.model.ACTIVITY_LABELS`.
        note
            Free text.
        source
            Provenance source.
        """
        return self._put_activity(
            trial,
            uuid.uuid4().hex[:12],
            start=start,
            stop=stop,
            label=label,
            note=note,
            source=source,
        )

    def update_activity(
        self,
        trial: str,
        activity_id: str,
        *,
        start: int | None = None,
        stop: int | None = None,
        label: str | None = None,
        note: str | None = None,
        source: str = "manual",
    ) -> Edit:
        """Change an activity range's frames, label or note (``None``: keep).

        Raises
        ------
        AnnotationError
            If the trial has no activity range ``activity_id``, or a new value is invalid
            (an empty, reversed or out-of-trial range, a label not in
            :data:`~annotations.model.ACTIVITY_LABELS`, a note that is not text, an unknown
            ``source``).
        """
        with self._tlock:
            cur = self._state.get(("activity", trial, activity_id))
        if cur is None:
            raise AnnotationError(f"no activity range with id {activity_id!r}", where=trial)
        return self._put_activity(
            trial,
            activity_id,
            start=cur.start if start is None else start,
            stop=cur.stop if stop is None else stop,
            label=cur.label if label is None else label,
            note=cur.note if note is None else note,
            source=source,
        )

    def remove_activity(self, trial: str, activity_id: str) -> Edit:
        """Delete an activity range."""
        return self._remove_item("activity", trial, activity_id)

    def _put_activity(
        self,
        trial: str,
        item_id: str,
        *,
        start: int,
        stop: int,
        label: str,
        note: str,
        source: str,
    ) -> Edit:
        check_trial(trial)
        source = check_source(source)
        s, e = span(start, stop)
        self._check_frame_bound(trial, e)
        if label not in ACTIVITY_LABELS:
            raise AnnotationError(
                f"unknown activity label {label!r}; expected one of {ACTIVITY_LABELS}"
            )
        if not isinstance(note, str):
            raise AnnotationError(f"note must be text, got {type(note).__name__}")

        def build(prov: Provenance) -> dict[Key, Any]:
            return {("activity", trial, item_id): ActivityRange(item_id, s, e, label, note, prov)}

        return self._commit("activity", trial, source, build, item_id=item_id)

    def add_note(
        self,
        trial: str,
        text: str,
        *,
        start: int | None = None,
        stop: int | None = None,
        source: str = "manual",
    ) -> Edit:
        """Add a free-text note on the trial, or on frames ``[start, stop)``.

        ``Edit.item_id`` is the new note's id.
        """
        return self._put_note(
            trial, uuid.uuid4().hex[:12], text=text, start=start, stop=stop, source=source
        )

    def update_note(self, trial: str, note_id: str, text: str, *, source: str = "manual") -> Edit:
        """Replace a note's text (its frames are kept).

        Raises
        ------
        AnnotationError
            If the trial has no note ``note_id``, ``text`` is not text, or ``source`` is
            unknown.
        """
        with self._tlock:
            cur = self._state.get(("note", trial, note_id))
        if cur is None:
            raise AnnotationError(f"no note with id {note_id!r}", where=trial)
        return self._put_note(
            trial, note_id, text=text, start=cur.start, stop=cur.stop, source=source
        )

    def remove_note(self, trial: str, note_id: str) -> Edit:
        """Delete a note."""
        return self._remove_item("note", trial, note_id)

    def _put_note(
        self,
        trial: str,
        item_id: str,
        *,
        text: str,
        start: int | None,
        stop: int | None,
        source: str,
    ) -> Edit:
        check_trial(trial)
        source = check_source(source)
        if not isinstance(text, str):
            raise AnnotationError(f"note text must be text, got {type(text).__name__}")
        if (start is None) != (stop is None):
            raise AnnotationError("give both start and stop, or neither (note on the whole trial)")
        s = e = None
        if start is not None:
            s, e = span(start, stop)
            self._check_frame_bound(trial, e)

        def build(prov: Provenance) -> dict[Key, Any]:
            return {("note", trial, item_id): Note(item_id, text, s, e, prov)}

        return self._commit("note", trial, source, build, item_id=item_id)

    def _remove_item(self, kind: str, trial: str, item_id: str) -> Edit:
        with self._tlock:
            if self._state.get((kind, trial, item_id)) is None:
                raise AnnotationError(f"no {kind} with id {item_id!r}", where=trial)
            return self._commit(
                kind, trial, "manual", lambda prov: {(kind, trial, item_id): None}, item_id=item_id
            )

    def clear_conflicts(self, ids: Iterable[str] | None = None) -> Edit:
        """Remove conflicts from the list (all of them by default), for every writer."""
        with self._tlock:
            chosen = tuple(self._state.conflicts) if ids is None else tuple(ids)
            return self._commit(
                "clear_conflicts", None, "manual", lambda prov: {}, clear_ids=chosen
            )

    # =================================================================== undo / redo
    def undo(self) -> Edit | None:
        """Undo this session's last edit (itself a durable edit); ``None`` if nothing to undo.

        Values another writer changed after the undone edit are left as they are and
        listed as ``"undo_skipped"`` conflicts.
        """
        return self._step(self._undo, "undo")

    def redo(self) -> Edit | None:
        """Redo the last undone edit; ``None`` if nothing to redo."""
        return self._step(self._redo, "redo")

    def _check_frame_bound(self, trial: str, stop: int) -> None:
        with self._tlock:
            t = self._state.trials.get(trial)
            n = None if t is None else t.info[0]
        limit = MAX_FRAME if n is None else n
        if stop > limit:
            raise AnnotationError(
                f"frame {stop - 1} is past the end of the trial ({limit} frames)", where=trial
            )
