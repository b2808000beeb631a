"""Low-level file handling: the append-only journal, atomic rewrites, directory fsync.

The line format is defined in :mod:`annotations.schema`. A write is durable when
:func:`append_durably` returns: the bytes are written and ``fdatasync``-ed. A rewrite is
atomic: a temporary file in the same folder is written and synced, renamed over the
target, and the folder is synced so the rename itself survives a power cut.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from annotations.errors import AnnotationFileError
from annotations.schema import (
    Operation,
    TornLine,
    check_journal_header,
    decode_line,
    decode_operation,
    encode_line,
    journal_header,
)

_datasync = getattr(os, "fdatasync", os.fsync)

MAIN_NAME = "annotations.json"


@dataclass(frozen=True, slots=True)
class StorePaths:
    """The three files of a subject's store: record, journal, lock.

    Attributes
    ----------
    main
        ``annotations.json`` (or the ``.json`` path given).
    journal
        Same name with suffix ``.journal``.
    lock
        Same name with suffix ``.lock``.
    """

    main: Path
    journal: Path
    lock: Path

    @classmethod
    def for_path(cls, path: str | os.PathLike[str]) -> StorePaths:
        """Paths for a subject folder (``<folder>/annotations.json``) or a ``.json`` file."""
        p = Path(path)
        main = p if p.suffix == ".json" else p / MAIN_NAME
        return cls(main, main.with_suffix(".journal"), main.with_suffix(".lock"))


_HEADER_MAX = 4096


def fsync_dir(folder: Path) -> None:
    """Make a rename or file creation in ``folder`` durable (no-op where unsupported)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def atomic_write(path: Path, data: bytes, *, tmp_tag: str) -> None:
    """Replace ``path`` by ``data`` atomically (temporary file, fsync, rename, folder fsync).

    Parameters
    ----------
    path
        Target file.
    data
        New content.
    tmp_tag
        Suffix making the temporary name unique to the writer: ``<name>.tmp-<tmp_tag>``.

    Raises
    ------
    AnnotationFileError
        If the folder is not writable or the disk is full; ``path`` is then unchanged.
    """
    tmp = path.with_name(f"{path.name}.tmp-{tmp_tag}")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:  # pragma: no cover
            pass
        raise AnnotationFileError(
            f"could not write the file: {exc.strerror or exc}", path=path
        ) from exc
    fsync_dir(path.parent)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    done = 0
    while done < len(data):
        done += os.write(fd, view[done:])


def append_durably(fd: int, line: bytes, *, valid_size: int, path: Path) -> None:
    """Append one line and ``fdatasync`` it; on failure cut the file back to ``valid_size``.

    Raises
    ------
    AnnotationFileError
        If the write or the sync failed (the edit must then be reported as not saved).
    """
    try:
        _write_all(fd, line)
        _datasync(fd)
    except OSError as exc:
        try:
            os.ftruncate(fd, valid_size)
        except OSError:  # pragma: no cover
            pass
        raise AnnotationFileError(
            f"could not save the edit ({exc.strerror or exc}); it was not applied", path=path
        ) from exc


def create_journal(
    path: Path, *, journal_id: str, base_seq: int, created: str, tmp_tag: str
) -> None:
    """Create a journal holding only its header, atomically (never replaces an existing one).

    Raises
    ------
    AnnotationFileError
        If a journal already exists at ``path`` or the folder is not writable.
    """
    if path.exists():
        raise AnnotationFileError("a journal already exists here; not replaced", path=path)
    atomic_write(path, encode_line(journal_header(journal_id, base_seq, created)), tmp_tag=tmp_tag)


def read_header(fd: int, path: Path) -> tuple[str, int, int]:
    """Read and validate the journal header.

    Returns
    -------
    journal_id, base_seq, header_size
        The journal's id, the ``seq`` after which it starts, and the header's byte length.

    Raises
    ------
    AnnotationFileError
        Naming the journal and line 1, if the header is missing, incomplete or damaged, or
        is not a valid journal header of this schema version
        (:func:`annotations.schema.check_journal_header`).
    """
    head = os.pread(fd, _HEADER_MAX, 0)
    nl = head.find(b"\n")
    if nl < 0:
        raise AnnotationFileError(
            "the journal header (line 1) is missing or incomplete", path=path, line=1
        )
    try:
        obj = decode_line(head[:nl])
    except TornLine as why:
        raise AnnotationFileError(
            f"the journal header is damaged ({why})", path=path, line=1
        ) from None
    journal_id, base_seq = check_journal_header(obj, path)
    return journal_id, base_seq, nl + 1


@dataclass(frozen=True, slots=True)
class Scan:
    """Result of reading journal lines.

    Attributes
    ----------
    ops
        Valid operations, in order.
    consumed
        Bytes read up to the end of the last valid (or, with ``skip_damaged``, skipped)
        complete line.
    lines
        Number of lines consumed.
    tail
        Bytes after ``consumed``: an interrupted, never acknowledged write.
    damaged
        1-based line numbers skipped because damaged (only with ``skip_damaged``).
    """

    ops: list[Operation]
    consumed: int
    lines: int
    tail: int
    damaged: tuple[int, ...]


def scan(
    data: bytes,
    *,
    path: Path,
    first_line: int,
    next_seq: int,
    skip_damaged: bool = False,
) -> Scan:
    """Decode journal lines from ``data``.

    Parameters
    ----------
    data
        Bytes of the journal from a line boundary to its end.
    path
        The journal, for error messages.
    first_line
        1-based line number of the first line in ``data``.
    next_seq
        Expected ``seq`` of the first operation; each next one must follow without gaps.
    skip_damaged
        Skip damaged lines anywhere (recovery) instead of failing when a damaged line is
        followed by valid ones.

    Raises
    ------
    AnnotationFileError
        A damaged line followed by valid lines (acknowledged edits would be lost), an
        operation that does not validate, or a ``seq`` out of order.
    """
    ops: list[Operation] = []
    damaged: list[int] = []
    pos = 0
    line_no = first_line - 1
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            break
        line_no += 1
        try:
            obj = decode_line(data[pos:nl])
        except TornLine as why:
            if skip_damaged:
                damaged.append(line_no)
                pos = nl + 1
                continue
            if _has_valid_line(data, nl + 1):
                raise AnnotationFileError(
                    f"line {line_no} is damaged ({why}) and followed by valid lines; "
                    "run AnnotationStore.recover(..., skip_damaged_lines=True) to rebuild "
                    "without it",
                    path=path,
                    line=line_no,
                ) from None
            line_no -= 1
            break
        op = decode_operation(obj, path, line_no)
        if op.seq != next_seq and not (skip_damaged and op.seq > next_seq):
            raise AnnotationFileError(
                f"operation seq {op.seq} where {next_seq} was expected (journal out of order)",
                path=path,
                line=line_no,
            )
        next_seq = op.seq + 1
        ops.append(op)
        pos = nl + 1
    return Scan(ops, pos, line_no - first_line + 1, len(data) - pos, tuple(damaged))


def _has_valid_line(data: bytes, pos: int) -> bool:
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            return False
        try:
            decode_line(data[pos:nl])
        except TornLine:
            pos = nl + 1
            continue
        return True
