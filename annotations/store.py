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

import fcntl
import os
import threading
import uuid
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, Self

import numpy as np
from numpy.typing import NDArray

from annotations.errors import AnnotationError, AnnotationFileError
from annotations.journal import (
    StorePaths,
    append_durably,
    atomic_write,
    create_journal,
    read_header,
    scan,
)
from annotations.masks import mask_to_ranges
from annotations.model import (
    ACTIVITY_LABELS,
    EXCLUDED,
    FEET,
    FLAG_KINDS,
    SOURCES,
    UNMEASURED_FORCE,
    ActivityRange,
    Conflict,
    Edit,
    FlagRun,
    FrameFlag,
    Note,
    Provenance,
    TrialReview,
    format_timestamp,
    utc_now,
)
from annotations.recovery import RecoveryReport
from annotations.schema import Key, Operation, encode_line, operation_to_json
from annotations.state import (
    SubjectState,
    detect_overrides,
    flag_mask,
    flag_runs,
    skipped_conflicts,
    undo_puts,
)
from annotations.subject_file import SubjectFile, decode_subject_file, encode_subject_file

MAX_FRAME = 50_000_000
"""Largest accepted frame index + 1 (about 5.8 days at 100 Hz): catches unit mistakes."""

Clock = Callable[[], datetime]
FramesLike = int | range | Iterable[int] | NDArray[np.integer]


@dataclass(slots=True)
class _History:
    """One undo (or redo) step: the values an operation wrote and the ones it replaced."""

    op: str
    trial: str | None
    kind: str | None
    applied: dict[Key, Any]
    replaced: dict[Key, Any]
    item_id: str | None
    edit_id: str


def _stat_key(path: Path) -> tuple[int, int, int] | None:
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns)


class AnnotationStore:
    """Review record of one subject: flags, activity ranges, notes, reviewed marks.

    Open with :meth:`open`; every edit method returns an :class:`~annotations.model.Edit`
    only once the edit is durable (in the journal and fsync-ed). All methods are
    thread-safe. Open one store per browser client to give each its own undo history
    and conflict detection; stores in one or several processes may share a subject.

    Frames are 0-based indices at the trial's frame rate; ranges are half-open
    ``[start, stop)``; a ``frames`` argument is an ``int``, a ``range`` or an iterable of
    ints (use :meth:`set_mask` for boolean masks).
    """

    def __init__(
        self,
        paths: StorePaths,
        *,
        reviewer: str,
        clock: Clock,
        compact_every: int,
        max_undo: int,
        _token: object = None,
    ) -> None:
        if _token is not _OPEN_TOKEN:
            raise AnnotationError("use AnnotationStore.open(path, reviewer=...) to open a store")
        self.paths = paths
        self._reviewer = reviewer
        self._clock = clock
        self._compact_every = compact_every
        self._max_undo = max_undo
        self._session = uuid.uuid4().hex
        self._tlock = threading.RLock()
        self._state = SubjectState()
        self._seq = 0
        self._offset = 0
        self._lines = 0
        self._journal_id = ""
        self._jfd = -1
        self._lock_fd = -1
        self._main_stat: tuple[int, int, int] | None = None
        self._since_compact = 0
        self._undo: list[_History] = []
        self._redo: list[_History] = []
        self._closed = False
        self._problems: list[str] = []

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
            _token=_OPEN_TOKEN,
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

    def _open_files(self) -> None:
        p = self.paths
        try:
            self._lock_fd = os.open(p.lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise AnnotationFileError(
                f"cannot create the lock file ({exc.strerror}); is the folder writable?",
                path=p.lock,
            ) from exc
        try:
            with self._locked(fcntl.LOCK_EX):
                self._load_locked()
        except BaseException:
            self._release_fds()
            raise

    def _load_locked(self) -> None:
        p = self.paths
        for name in (p.main.name, p.journal.name):  # left by a writer killed mid-rewrite
            for stale in p.main.parent.glob(f"{name}.tmp-*"):
                stale.unlink(missing_ok=True)
        main = None
        if p.main.exists():
            main = decode_subject_file(p.main.read_bytes(), p.main)
            self._main_stat = _stat_key(p.main)
        new_journal = not p.journal.exists()
        if new_journal:
            base = 0 if main is None else main.last_seq
            if main is not None:
                warnings.warn(
                    f"{p.journal} is missing; starting a new journal after operation {base}",
                    stacklevel=4,
                )
            create_journal(
                p.journal,
                journal_id=uuid.uuid4().hex,
                base_seq=base,
                created=self._now(),
                tmp_tag=self._session,
            )
        self._jfd = os.open(p.journal, os.O_RDWR | os.O_APPEND)
        journal_id, base_seq, header_size = read_header(self._jfd, p.journal)
        self._journal_id = journal_id
        if main is None:
            self._start_from_header(base_seq, header_size)
        elif new_journal:
            self._state = main.state
            self._seq, self._offset, self._lines = main.last_seq, header_size, 1
        else:
            self._start_from_main(main, base_seq)
        self._refresh_locked(repair=True)
        if main is None or new_journal or self._since_compact >= self._compact_every:
            self._compact_locked()

    def _start_from_header(self, base_seq: int, header_size: int) -> None:
        if base_seq != 0:
            raise AnnotationFileError(
                f"the subject file {self.paths.main.name} is missing but the journal only holds "
                f"operations after {base_seq}; restore the subject file from a backup",
                path=self.paths.journal,
            )
        self._seq, self._offset, self._lines = 0, header_size, 1

    def _start_from_main(self, main: SubjectFile, base_seq: int) -> None:
        p = self.paths
        if main.journal_id != self._journal_id:
            raise AnnotationFileError(
                f"belongs to journal {main.journal_id} but {p.journal.name} is journal "
                f"{self._journal_id} (a file was replaced or copied); run "
                "AnnotationStore.recover() to rebuild from the journal",
                path=p.main,
            )
        size = os.fstat(self._jfd).st_size
        if main.journal_offset > size or main.last_seq < base_seq:
            raise AnnotationFileError(
                f"the journal is shorter than {p.main.name} records (offset {main.journal_offset}, "
                f"size {size}); it was truncated or replaced; run AnnotationStore.recover()",
                path=p.journal,
            )
        self._state = main.state
        self._seq, self._offset, self._lines = (
            main.last_seq,
            main.journal_offset,
            main.journal_lines,
        )

    def close(self) -> None:
        """Compact (if anything changed) and release the files. Idempotent.

        Raises
        ------
        AnnotationFileError
            If the subject file on disk was damaged meanwhile (it is not overwritten; the
            edits are safe in the journal).
        """
        with self._tlock:
            if self._closed:
                return
            try:
                with self._locked(fcntl.LOCK_EX):
                    self._refresh_locked(repair=True)
                    if self._since_compact or _stat_key(self.paths.main) != self._main_stat:
                        self._compact_locked()
            finally:
                self._closed = True
                self._release_fds()

    def _release_fds(self) -> None:
        for fd in (self._jfd, self._lock_fd):
            if fd >= 0:
                os.close(fd)
        self._jfd = self._lock_fd = -1

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # =================================================================== properties
    @property
    def reviewer(self) -> str:
        """Reviewer name recorded with every edit of this store."""
        return self._reviewer

    @property
    def session(self) -> str:
        """Id of this store session (written with each operation)."""
        return self._session

    @property
    def seq(self) -> int:
        """Sequence number of the last operation this store has seen."""
        return self._seq

    @property
    def can_undo(self) -> bool:
        """Whether :meth:`undo` has a step to undo."""
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        """Whether :meth:`redo` has a step to redo."""
        return bool(self._redo)

    def problems(self) -> list[str]:
        """Problems met by automatic compaction (the edits themselves were saved)."""
        with self._tlock:
            return list(self._problems)

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
        kind = _check_kind(kind)
        with self._tlock:
            t = self._state.trials.get(trial)
            entry = None if t is None else t.flags[kind].get(int(frame))
        return None if entry is None else FrameFlag(int(frame), kind, entry[0], entry[1])

    def flag_runs(self, trial: str, kind: str = UNMEASURED_FORCE) -> list[FlagRun]:
        """Flagged frames as runs with equal foot and provenance, sorted."""
        kind = _check_kind(kind)
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
        kind = _check_kind(kind)
        foot = _check_foot(foot)
        with self._tlock:
            t = self._state.trials.get(trial)
            if t is None or not t.flags[kind]:
                return []
            flags = t.flags[kind]
            return mask_to_ranges(flag_mask(flags, max(flags) + 1, foot))

    def mask(
        self,
        trial: str,
        n_frames: int | None = None,
        *,
        kind: str = UNMEASURED_FORCE,
        foot: str | None = None,
    ) -> NDArray[np.bool_]:
        """Boolean mask of the flagged frames, as the solver takes it.

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
            ``(T,)`` bool, ``True`` where flagged, at the trial's frame rate.

        Raises
        ------
        AnnotationError
            If ``n_frames`` is unknown, or a frame at or past ``n_frames`` is flagged
            (the annotations do not belong to a trial of this length).
        """
        kind = _check_kind(kind)
        foot = _check_foot(foot)
        with self._tlock:
            t = self._state.trials.get(trial)
            if n_frames is None:
                n_frames = None if t is None else t.info[0]
                if n_frames is None:
                    raise AnnotationError(
                        "n_frames not given and not recorded for this trial", where=trial
                    )
            n = _count(n_frames, "n_frames")
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

    def refresh(self) -> bool:
        """Read the edits other writers saved since this store last looked.

        Returns
        -------
        bool
            True if anything new was read. Call it periodically (e.g. every second from the
            app) so that what the user sees includes other tabs' edits.
        """
        with self._tlock:
            self._check_open()
            if os.fstat(self._jfd).st_size == self._offset:
                return False
            with self._locked(fcntl.LOCK_SH):
                return bool(self._refresh_locked(repair=False))

    # =================================================================== editing: flags
    def set_unmeasured(
        self,
        trial: str,
        frames: FramesLike,
        value: bool = True,
        *,
        foot: str | None = None,
        source: str = "manual",
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

        Returns
        -------
        Edit
            Receipt; the edit is durable.
        """
        foot = _check_foot(foot)
        if foot is not None and not value:
            raise AnnotationError("foot is only given when flagging (value=True)")
        return self._flags_edit(
            trial, UNMEASURED_FORCE, frames, value=bool(value), foot=foot, source=source
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
        """
        kind = _check_kind(kind)
        foot = _check_foot(foot)
        if kind == EXCLUDED and foot is not None:
            raise AnnotationError("excluded frames have no foot")
        arr = np.asarray(mask)
        if arr.ndim != 1 or (arr.size and arr.dtype != np.bool_):
            raise AnnotationError(f"mask must be a (T,) bool array, got {arr.dtype} {arr.shape}")
        start = _count(start_frame, "start_frame")
        self._check_frame_bound(trial, start + arr.size)
        source = _check_source(source)

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
    ) -> Edit:
        source = _check_source(source)
        _check_trial(trial)
        frame_list = _frames(frames)
        self._check_frame_bound(trial, max(frame_list) + 1)

        def build(prov: Provenance) -> dict[Key, Any]:
            flags = self._state.trial(trial).flags[kind]
            if value:
                return dict.fromkeys([("flag", trial, kind, f) for f in frame_list], (foot, prov))
            return {("flag", trial, kind, f): None for f in frame_list if f in flags}

        return self._commit("flags", trial, source, build, kind=kind)

    # =================================================================== editing: other
    def set_reviewed(self, trial: str, reviewed: bool = True, *, source: str = "manual") -> Edit:
        """Mark the trial as reviewed (or not)."""
        source = _check_source(source)
        _check_trial(trial)
        return self._commit(
            "reviewed", trial, source, lambda prov: {("reviewed", trial): (bool(reviewed), prov)}
        )

    def set_trial_info(
        self, trial: str, *, n_frames: int | None = None, rate_hz: float | None = None
    ) -> Edit:
        """Record the trial's number of frames and frame rate (Hz), used by :meth:`mask`.

        Raises
        ------
        AnnotationError
            If frames at or past ``n_frames`` are already annotated.
        """
        _check_trial(trial)
        n = None if n_frames is None else _count(n_frames, "n_frames")
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
            "trial_info", trial, "manual", lambda prov: {("info", trial): (n, rate)}
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
        """Change an activity range's frames, label or note (``None``: keep)."""
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
        _check_trial(trial)
        source = _check_source(source)
        s, e = _span(start, stop)
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
        """Replace a note's text (its frames are kept)."""
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
        _check_trial(trial)
        source = _check_source(source)
        if not isinstance(text, str):
            raise AnnotationError(f"note text must be text, got {type(text).__name__}")
        if (start is None) != (stop is None):
            raise AnnotationError("give both start and stop, or neither (note on the whole trial)")
        s = e = None
        if start is not None:
            s, e = _span(start, stop)
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

    def _step(self, stack: list[_History], what: str) -> Edit | None:
        with self._tlock:
            self._check_open()
            if not stack:
                return None
            h = stack[-1]
            skipped: dict[Key, Any] = {}

            def build(prov: Provenance) -> dict[Key, Any]:
                restore, skip = undo_puts(self._state, h.applied, h.replaced)
                skipped.update(skip)
                return restore

            return self._commit(
                h.op,
                h.trial,
                "manual",
                build,
                kind=h.kind,
                item_id=h.item_id,
                history=what,
                skipped=skipped,
                reverts=h.edit_id,
            )

    # =================================================================== machinery
    def _commit(
        self,
        op_name: str,
        trial: str | None,
        source: str,
        build: Callable[[Provenance], dict[Key, Any]],
        *,
        kind: str | None = None,
        item_id: str | None = None,
        history: str = "edit",
        skipped: dict[Key, Any] | None = None,
        clear_ids: tuple[str, ...] = (),
        reverts: str | None = None,
    ) -> Edit:
        with self._tlock:
            self._check_open()
            with self._locked(fcntl.LOCK_EX):
                window = self._refresh_locked(repair=True)
                prov = Provenance(self._reviewer, self._now(), source)
                puts = build(prov)
                edit_id = uuid.uuid4().hex
                conflicts = detect_overrides(
                    puts, window, session=self._session, edit_id=edit_id, provenance=prov
                )
                if skipped:
                    conflicts += skipped_conflicts(
                        skipped, edit_id=edit_id, provenance=prov, reason=f"{history}_skipped"
                    )
                name = op_name if puts or op_name in ("flags", "clear_conflicts") else "none"
                prior = {k: self._state.get(k) for k in puts}
                op = Operation(
                    seq=self._seq + 1,
                    id=edit_id,
                    session=self._session,
                    op=name,
                    trial=trial,
                    provenance=prov,
                    puts=puts,
                    conflicts=tuple(conflicts),
                    clear_ids=clear_ids,
                    undo_of=reverts if history == "undo" else None,
                    redo_of=reverts if history == "redo" else None,
                    kind=kind if name == "flags" else None,
                )
                line = encode_line(operation_to_json(op))
                append_durably(self._jfd, line, valid_size=self._offset, path=self.paths.journal)
                self._seq += 1
                self._offset += len(line)
                self._lines += 1
                self._state.apply(op)
                self._since_compact += 1
                self._record_history(
                    history, _History(op_name, trial, kind, puts, prior, item_id, edit_id)
                )
                if self._since_compact >= self._compact_every:
                    self._compact_quietly()
            return Edit(edit_id, op.seq, name, trial, prov, item_id, len(puts), tuple(conflicts))

    def _record_history(self, history: str, step: _History) -> None:
        if step.trial is None:
            return
        if history == "edit":
            if step.applied:
                self._undo.append(step)
                self._redo.clear()
        elif history == "undo":
            self._undo.pop()
            self._redo.append(step)
        else:
            self._redo.pop()
            self._undo.append(step)
        if len(self._undo) > self._max_undo:
            del self._undo[: len(self._undo) - self._max_undo]

    def _refresh_locked(self, *, repair: bool) -> list[Operation]:
        """Apply operations appended by others since our offset (lock held)."""
        if os.stat(self.paths.journal).st_ino != os.fstat(self._jfd).st_ino:
            raise AnnotationFileError(
                "the journal was replaced by another program while this store was open; "
                "close and reopen the store",
                path=self.paths.journal,
            )
        size = os.fstat(self._jfd).st_size
        if size < self._offset:
            raise AnnotationFileError(
                f"the journal shrank below the part already read ({size} < {self._offset} bytes)",
                path=self.paths.journal,
            )
        if size == self._offset:
            return []
        data = os.pread(self._jfd, size - self._offset, self._offset)
        result = scan(
            data, path=self.paths.journal, first_line=self._lines + 1, next_seq=self._seq + 1
        )
        for op in result.ops:
            self._state.apply(op)
        if result.ops:
            self._seq = result.ops[-1].seq
            self._since_compact += len(result.ops)
        self._offset += result.consumed
        self._lines += result.lines
        if result.tail and repair:
            os.ftruncate(self._jfd, self._offset)  # an interrupted, never acknowledged write
            os.fsync(self._jfd)
        return result.ops

    def compact(self) -> None:
        """Rewrite the subject file now (atomically) to include every journal operation.

        Raises
        ------
        AnnotationFileError
            If the subject file on disk is damaged (it is left as it is).
        """
        with self._tlock:
            self._check_open()
            with self._locked(fcntl.LOCK_EX):
                self._refresh_locked(repair=True)
                self._compact_locked()

    def _compact_quietly(self) -> None:
        try:
            self._compact_locked()
        except AnnotationFileError as exc:
            msg = str(exc)
            if msg not in self._problems:
                self._problems.append(msg)
            warnings.warn(msg, stacklevel=4)

    def _compact_locked(self) -> None:
        p = self.paths
        current = _stat_key(p.main)
        if current is not None and current != self._main_stat:
            # Changed by someone else: overwrite only a valid file of our journal.
            try:
                other = decode_subject_file(p.main.read_bytes(), p.main)
            except AnnotationFileError as exc:
                raise AnnotationFileError(
                    f"{exc.message}; the file is damaged and was not overwritten; every edit is "
                    f"in {p.journal.name}: close the stores and run AnnotationStore.recover()",
                    path=p.main,
                    where=exc.where,
                ) from None
            if other.journal_id != self._journal_id or other.last_seq > self._seq:
                raise AnnotationFileError(
                    "the subject file now belongs to another journal or is ahead of it; "
                    "not overwritten",
                    path=p.main,
                )
        data = encode_subject_file(
            self._state,
            last_seq=self._seq,
            journal_id=self._journal_id,
            journal_offset=self._offset,
            journal_lines=self._lines,
            saved_at=self._now(),
        )
        atomic_write(p.main, data, tmp_tag=self._session)
        self._main_stat = _stat_key(p.main)
        self._since_compact = 0

    @contextmanager
    def _locked(self, how: int) -> Iterator[None]:
        fcntl.flock(self._lock_fd, how)
        try:
            yield
        finally:
            fcntl.flock(self._lock_fd, fcntl.LOCK_UN)

    def _check_open(self) -> None:
        if self._closed:
            raise AnnotationError("the store is closed", path=self.paths.main)

    def _now(self) -> str:
        try:
            return format_timestamp(self._clock())
        except ValueError as exc:
            raise AnnotationError(f"the clock gave an invalid time: {exc}") from None

    def _check_frame_bound(self, trial: str, stop: int) -> None:
        with self._tlock:
            t = self._state.trials.get(trial)
            n = None if t is None else t.info[0]
        limit = MAX_FRAME if n is None else n
        if stop > limit:
            raise AnnotationError(
                f"frame {stop - 1} is past the end of the trial ({limit} frames)", where=trial
            )


_OPEN_TOKEN = object()


# =================================================================== argument checks
def _check_kind(kind: str) -> str:
    if kind not in FLAG_KINDS:
        raise AnnotationError(f"unknown flag kind {kind!r}; expected one of {FLAG_KINDS}")
    return kind


def _check_foot(foot: str | None) -> str | None:
    if foot is not None and foot not in FEET:
        raise AnnotationError(f"unknown foot {foot!r}; expected one of {FEET} or None")
    return foot


def _check_source(source: str) -> str:
    if source not in SOURCES:
        raise AnnotationError(f"unknown source {source!r}; expected one of {SOURCES}")
    return source


def _check_trial(trial: str) -> None:
    if (
        not isinstance(trial, str)
        or not trial
        or len(trial) > 200
        or any(ord(c) < 32 for c in trial)
    ):
        raise AnnotationError(f"trial must be a non-empty name, got {trial!r}")


def _count(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise AnnotationError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)


def _span(start: Any, stop: Any) -> tuple[int, int]:
    s, e = _count(start, "start"), _count(stop, "stop")
    if e <= s:
        raise AnnotationError(f"empty or reversed frame range [{s}, {e})")
    return s, e


def _frames(frames: FramesLike) -> list[int]:
    """Frame indices from an int, a range or an iterable of ints (not booleans)."""
    if isinstance(frames, bool | np.bool_):
        raise AnnotationError("frames must be frame indices, got a boolean")
    if isinstance(frames, int | np.integer):
        out = [int(frames)]
    elif isinstance(frames, range):
        if frames.step != 1:
            raise AnnotationError("a frame range must have step 1")
        if frames.stop > MAX_FRAME:
            raise AnnotationError(f"frame range {frames} is beyond {MAX_FRAME} frames")
        out = list(frames)
    else:
        arr = np.asarray(list(frames) if not isinstance(frames, np.ndarray) else frames)
        if arr.dtype == np.bool_:
            raise AnnotationError("frames is a boolean mask; use set_mask() for masks")
        if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
            raise AnnotationError(
                f"frames must be integer frame indices, got {arr.dtype} {arr.shape}"
            )
        out = sorted(set(arr.tolist()))
    if not out:
        raise AnnotationError("no frames given")
    if min(out) < 0:
        raise AnnotationError(f"frame indices must be >= 0, got {min(out)}")
    return out
