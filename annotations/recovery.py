"""Recovery of a subject whose record or journal is damaged.

Nothing is deleted: a damaged file is renamed to ``<name>.damaged-<UTC time>`` next to
the original, and a new one is written beside it.
"""

from __future__ import annotations

import fcntl
import os
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from annotations.errors import AnnotationFileError
from annotations.journal import Scan, StorePaths, atomic_write, create_journal, read_header, scan
from annotations.model import utc_now
from annotations.state import SubjectState
from annotations.subject_file import SubjectFile, decode_subject_file, encode_subject_file


@dataclass(frozen=True, slots=True)
class RecoveryReport:
    """What :func:`recover` did.

    Attributes
    ----------
    action
        ``"nothing_to_do"`` (both files fine), ``"rebuilt_from_journal"`` (a new subject
        file made by replaying the whole journal) or ``"new_journal"`` (the subject file
        was fine, the journal was not: a new journal continues after the file).
    main, journal
        Paths of the subject file and the journal.
    moved_aside
        Damaged files renamed (kept for inspection).
    operations
        Journal operations replayed into the rebuilt subject file.
    damaged_lines
        Journal lines skipped because damaged (with ``skip_damaged_lines``).
    message
        One-line summary for the user.
    """

    action: str
    main: Path
    journal: Path
    moved_aside: tuple[Path, ...]
    operations: int
    damaged_lines: tuple[int, ...]
    message: str


def recover(
    path: str | os.PathLike[str],
    *,
    skip_damaged_lines: bool = False,
    clock: Callable[[], datetime] | None = None,
) -> RecoveryReport:
    """Make a subject openable again without losing recorded edits.

    * Subject file damaged, missing or not matching the journal, journal readable from
      its start: the record is rebuilt by replaying the journal (it holds every edit).
    * Subject file fine, journal header damaged or journal truncated: the journal is
      set aside and a new one continues after the subject file.

    Close every store of the subject before calling it.

    Parameters
    ----------
    path
        Subject folder or ``.json`` record path, as for ``AnnotationStore.open``.
    skip_damaged_lines
        Replay around damaged journal lines in the middle of the journal (their edits are
        lost and listed in the report) instead of stopping with an error.
    clock
        Time source for file names (default UTC now).

    Returns
    -------
    RecoveryReport

    Raises
    ------
    AnnotationFileError
        If a file is of a newer schema version (use a newer addb), if the journal has
        damaged lines and ``skip_damaged_lines`` is False, or if neither file is usable.
    """
    paths = StorePaths.for_path(path)
    stamp = (clock or utc_now)().strftime("%Y%m%dT%H%M%SZ")
    lock_fd = os.open(paths.lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(lock_fd, fcntl.LOCK_EX)
        return _recover_locked(paths, stamp, skip_damaged_lines)
    finally:
        os.close(lock_fd)


def journal_holds_every_edit(path: str | os.PathLike[str]) -> bool:
    """Whether :func:`recover` can rebuild the subject file from the journal alone: the
    journal beside the record exists, its header is readable and it starts at the first
    edit (it was never restarted after the subject file). Reads only; nothing is changed.

    Parameters
    ----------
    path
        Subject folder or ``.json`` record path, as for ``AnnotationStore.open``.
    """
    try:
        journal = _read_journal(StorePaths.for_path(path))
    except (AnnotationFileError, OSError):
        return False
    return journal is not None and journal.base_seq == 0


def _recover_locked(paths: StorePaths, stamp: str, skip: bool) -> RecoveryReport:
    main, main_err = _read_main(paths)
    journal = _read_journal(paths)
    if main is not None and journal is not None and _consistent(paths, main, journal):
        return RecoveryReport(
            "nothing_to_do",
            paths.main,
            paths.journal,
            (),
            0,
            (),
            "the subject file and the journal are consistent; nothing changed",
        )
    if journal is not None and journal.base_seq == 0:
        result = scan(journal.data, path=paths.journal, first_line=2, next_seq=1, skip_damaged=skip)
        return _rebuild(paths, stamp, journal, result)
    if main is not None:
        return _new_journal(paths, stamp, main)
    raise AnnotationFileError(
        f"cannot recover: the subject file is unusable ({main_err}) and the journal does not "
        "hold the whole history",
        path=paths.main,
    )


def _read_main(paths: StorePaths) -> tuple[SubjectFile | None, AnnotationFileError | None]:
    if not paths.main.exists():
        return None, None
    try:
        return decode_subject_file(paths.main.read_bytes(), paths.main), None
    except AnnotationFileError as exc:
        if exc.where == "version" and "newer" in exc.message:
            raise
        return None, exc


@dataclass(frozen=True, slots=True)
class _Journal:
    journal_id: str
    base_seq: int
    header_size: int
    data: bytes  # everything after the header

    @property
    def size(self) -> int:
        return self.header_size + len(self.data)


def _read_journal(paths: StorePaths) -> _Journal | None:
    if not paths.journal.exists():
        return None
    fd = os.open(paths.journal, os.O_RDONLY)
    try:
        try:
            journal_id, base_seq, header_size = read_header(fd, paths.journal)
        except AnnotationFileError as exc:
            if exc.where == "version" and "newer" in exc.message:
                raise
            return None
        size = os.fstat(fd).st_size
        data = os.pread(fd, size - header_size, header_size)
    finally:
        os.close(fd)
    return _Journal(journal_id, base_seq, header_size, data)


def _consistent(paths: StorePaths, main: SubjectFile, journal: _Journal) -> bool:
    """Whether a store would open these files (same checks as ``AnnotationStore.open``)."""
    if main.journal_id != journal.journal_id or main.last_seq < journal.base_seq:
        return False
    off = main.journal_offset
    if not journal.header_size <= off <= journal.size:
        return False
    if off > journal.header_size and journal.data[off - journal.header_size - 1] != ord("\n"):
        return False
    try:
        scan(
            journal.data[main.journal_offset - journal.header_size :],
            path=paths.journal,
            first_line=main.journal_lines + 1,
            next_seq=main.last_seq + 1,
        )
    except AnnotationFileError:
        return False
    return True


def _set_aside(path: Path, stamp: str) -> Path:
    target = path.with_name(f"{path.name}.damaged-{stamp}")
    n = 1
    while target.exists():
        target = path.with_name(f"{path.name}.damaged-{stamp}-{n}")
        n += 1
    os.rename(path, target)
    return target


def _rebuild(paths: StorePaths, stamp: str, journal: _Journal, result: Scan) -> RecoveryReport:
    state = SubjectState()
    for op in result.ops:
        state.apply(op)
    aside = (_set_aside(paths.main, stamp),) if paths.main.exists() else ()
    end = journal.header_size + result.consumed
    if end < journal.size:  # an interrupted, never acknowledged write at the end
        fd = os.open(paths.journal, os.O_RDWR)
        try:
            os.ftruncate(fd, end)
            os.fsync(fd)
        finally:
            os.close(fd)
    last_seq = result.ops[-1].seq if result.ops else 0
    data = encode_subject_file(
        state,
        last_seq=last_seq,
        journal_id=journal.journal_id,
        journal_offset=end,
        journal_lines=1 + result.lines,
        saved_at=_iso(stamp),
    )
    atomic_write(paths.main, data, tmp_tag="recovery")
    msg = f"rebuilt {paths.main.name} from {len(result.ops)} journal operations"
    if aside:
        msg += f"; the previous file was kept as {aside[0].name}"
    if result.damaged:
        msg += f"; skipped damaged journal lines {list(result.damaged)} (their edits are lost)"
    return RecoveryReport(
        "rebuilt_from_journal",
        paths.main,
        paths.journal,
        aside,
        len(result.ops),
        result.damaged,
        msg,
    )


def _new_journal(paths: StorePaths, stamp: str, main: SubjectFile) -> RecoveryReport:
    aside = (_set_aside(paths.journal, stamp),) if paths.journal.exists() else ()
    journal_id = uuid.uuid4().hex
    create_journal(
        paths.journal,
        journal_id=journal_id,
        base_seq=main.last_seq,
        created=_iso(stamp),
        tmp_tag="recovery",
    )
    header_size = paths.journal.stat().st_size
    data = encode_subject_file(
        main.state,
        last_seq=main.last_seq,
        journal_id=journal_id,
        journal_offset=header_size,
        journal_lines=1,
        saved_at=_iso(stamp),
    )
    atomic_write(paths.main, data, tmp_tag="recovery")
    return RecoveryReport(
        "new_journal",
        paths.main,
        paths.journal,
        aside,
        0,
        (),
        f"the journal was unusable; set aside and restarted after operation {main.last_seq} "
        "(edits after the last save of the subject file may be lost)",
    )


def _iso(stamp: str) -> str:
    return (
        f"{stamp[0:4]}-{stamp[4:6]}-{stamp[6:8]}T{stamp[9:11]}:{stamp[11:13]}:{stamp[13:15]}.000Z"
    )
