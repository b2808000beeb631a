"""Exception classes of :mod:`annotations`.

Every error says what was wrong and, for file problems, which file (and line) it is in,
so that the review app and the command line can show an actionable message.
``to_dict()`` gives a JSON-serializable form for the UI. The interface mirrors
``solver.errors.AddbError`` without importing :mod:`solver` (the two packages are
independent; the app catches both).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


class AnnotationError(Exception):
    """Base class of every error raised on purpose by :mod:`annotations`.

    Raised directly for invalid arguments (an unknown flag kind, a negative frame, a
    reviewer name that is empty) and for operations that cannot be done (the store is
    closed, an activity id does not exist).

    Parameters
    ----------
    message
        What was wrong and what was expected, in plain words.
    path
        The file the problem is in, if any.
    line
        1-based line number in ``path`` (journal lines), if known.
    where
        Any other location: a trial name, a JSON path such as ``trials.walk.excluded[3]``.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        line: int | None = None,
        where: str | None = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else str(path)
        self.line = line
        self.where = where
        super().__init__(self._format())

    def _format(self) -> str:
        loc = []
        if self.path is not None:
            loc.append(self.path + (f":{self.line}" if self.line is not None else ""))
        elif self.line is not None:
            loc.append(f"line {self.line}")
        if self.where:
            loc.append(self.where)
        prefix = " (" + ", ".join(loc) + ")" if loc else ""
        return f"{type(self).__name__}{prefix}: {self.message}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-serializable description: ``type``, ``message``, ``path``, ``line``, ``where``."""
        return {
            "type": type(self).__name__,
            "message": self.message,
            "path": self.path,
            "line": self.line,
            "where": self.where,
        }


class AnnotationFileError(AnnotationError):
    """An annotation file, its journal or an AddBiomechanics review file is damaged,
    of an unknown schema version, inconsistent with its journal, or cannot be written.

    The file named in the error is never overwritten by the store.
    """
