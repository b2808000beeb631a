"""The machinery behind :class:`~annotations.store.AnnotationStore`: files, lock, journal
position, in-memory state, compaction and the undo history.

Protocol (every step under ``flock`` of ``annotations.lock``):

* open: read the subject file, then replay the journal from the position it records;
* edit: read what other writers appended since our position (the "window"), build the
  new values against that fresh state, list conflicts with the window, append the
  operation and ``fdatasync`` it, then apply it in memory and return;
* compaction (every ``compact_every`` operations and on close): rewrite the subject file
  atomically with the journal position; a subject file that changed on disk is re-read
  first and never overwritten if it does not validate.
"""

from __future__ import annotations

import fcntl
import os
import threading
import uuid
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, Self

from annotations.errors import AnnotationError, AnnotationFileError
from annotations.journal import (
    StorePaths,
    append_durably,
    atomic_write,
    create_journal,
    read_header,
    scan,
)
from annotations.model import (
    Edit,
    Provenance,
    format_timestamp,
)
from annotations.schema import Key, Operation, encode_line, operation_to_json
from annotations.state import (
    SubjectState,
    detect_overrides,
    skipped_conflicts,
    undo_puts,
)
from annotations.subject_file import SubjectFile, decode_subject_file, encode_subject_file

Clock = Callable[[], datetime]
OPEN_TOKEN = object()


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


class JournaledStore:
    """Base class of :class:`~annotations.store.AnnotationStore` holding the durable state.

    Not meant to be used on its own; open stores with ``AnnotationStore.open``.
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
        if _token is not OPEN_TOKEN:
            raise AnnotationError("use AnnotationStore.open(path, reviewer=...) to open a store")
        self.paths = paths
        self._reviewer = reviewer
        self._acting = threading.local()
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
            self._start_from_main(main, base_seq, header_size)
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

    def _start_from_main(self, main: SubjectFile, base_seq: int, header_size: int) -> None:
        p = self.paths
        if main.journal_id != self._journal_id:
            raise AnnotationFileError(
                f"belongs to journal {main.journal_id} but {p.journal.name} is journal "
                f"{self._journal_id} (a file was replaced or copied); run "
                "AnnotationStore.recover() to rebuild from the journal",
                path=p.main,
            )
        size = os.fstat(self._jfd).st_size
        off = main.journal_offset
        at_line_start = header_size <= off <= size and os.pread(self._jfd, 1, off - 1) == b"\n"
        if not at_line_start or main.last_seq < base_seq:
            raise AnnotationFileError(
                f"{p.main.name} says the journal continues at byte {off}, which is not the start "
                f"of a line of this journal ({size} bytes): the journal was truncated or "
                "replaced; run AnnotationStore.recover()",
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

    @contextmanager
    def acting_as(self, reviewer: str) -> Iterator[None]:
        """Record ``reviewer`` (instead of :attr:`reviewer`) as the author of the edits this
        thread makes inside the block.

        For one store shared by several people, e.g. a review server used by a team: each
        edit keeps the name of whoever made it. Undo and redo stay per store (session).

        Raises
        ------
        AnnotationError
            If ``reviewer`` is empty, longer than 200 characters or has control characters.
        """
        name = str(reviewer).strip() if reviewer is not None else ""
        if not name or len(name) > 200 or any(ord(c) < 32 for c in name):
            raise AnnotationError(f"reviewer must be a non-empty name, got {reviewer!r}")
        prev = getattr(self._acting, "name", None)
        self._acting.name = name
        try:
            yield
        finally:
            self._acting.name = prev

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
                prov = Provenance(getattr(self._acting, "name", None) or self._reviewer, self._now(), source)
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
        if step.trial is None or history == "none":  # bookkeeping, not a reviewer's edit
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
