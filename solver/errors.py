"""Exception classes of the solver, one per stage.

Every error carries where it happened (file, line or frame, element) and what was
expected, so that the command line and the review app can show an actionable message.
``to_dict()`` gives a JSON-serializable form for the UI; :func:`listed` names the first
few of many files or folders in a message.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any


class AddbError(Exception):
    """Base class of every error raised on purpose by :mod:`solver`.

    Parameters
    ----------
    message
        What was wrong and what was expected, in plain words.
    path
        The file (or folder) the problem is in, if any.
    line
        1-based line number in ``path`` (text formats), if known.
    where
        Any other location: an XML element, a column name, a frame index, a marker.
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


class FileFormatError(AddbError):
    """A data file could not be read: bad header, wrong column count, text in a number field."""


class TrcFormatError(FileFormatError):
    """A TRC marker file is malformed."""


class MotFormatError(FileFormatError):
    """A MOT/STO table is malformed."""


class C3dFormatError(FileFormatError):
    """A C3D file could not be read or holds inconsistent force-platform data."""


class XmlFormatError(FileFormatError):
    """An OpenSim XML file (ExternalLoads, setup, marker set) is malformed."""


class SubjectFolderError(FileFormatError):
    """An AddBiomechanics subject folder is incomplete or inconsistent."""


class OsimModelError(AddbError):
    """An .osim model is malformed or uses a feature the converter does not support."""


class ScaleFactorError(OsimModelError):
    """A body's scale factors are not 3 positive, finite numbers (:func:`solver.model.scaling.scale_model`)."""


class MarkerMismatchError(AddbError):
    """Markers of a trial and of the model do not match (none in common, all missing)."""


class KinematicsError(AddbError):
    """Scaling or inverse kinematics failed."""


class DynamicsError(AddbError):
    """The dynamics stage (filtering, contact, centre-of-mass or residual fit) failed.

    Attributes
    ----------
    kept_trials
        Set by :func:`solver.pipeline.process_subject` on the error it raises after writing
        its outputs: every trial written without dynamics (its kinematics kept), in order,
        with the error that left it out (this one among them). Empty for an error raised
        before anything was written.
    """

    kept_trials: tuple[tuple[str, DynamicsError], ...] = ()


class DiagnosisError(AddbError):
    """The diagnosis stage failed."""


class DatasetError(AddbError):
    """A dataset folder holds no subject, or a dataset run could not start or finish."""


class OutputFolderError(AddbError):
    """An output folder cannot be written without deleting what is not addb's output: it
    is a file, it is (or holds) the input folder, or it holds other files."""


class ProcessedTrialError(AddbError, ValueError):
    """An output folder's ``<trial>/trial.npz`` cannot be read as a processed trial: it is
    damaged (an interrupted copy or sync) or of another schema version
    (:func:`solver.results.load_processed`). A ``ValueError`` too, as it was before it had
    a class of its own."""


class B3dFormatError(FileFormatError):
    """An AddBiomechanics binary subject file (.b3d) is damaged, truncated or of an unknown version.

    ``offset`` is the byte offset in the file where the problem was found (also shown in
    the message as ``byte N``), or None when it concerns the whole file.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        offset: int | None = None,
        where: str | None = None,
    ) -> None:
        self.offset = offset
        parts = [p for p in (None if offset is None else f"byte {offset}", where) if p]
        super().__init__(message, path=path, where=", ".join(parts) or None)

    def to_dict(self) -> dict[str, Any]:
        """As :meth:`AddbError.to_dict`, plus ``offset``."""
        out = super().to_dict()
        out["offset"] = self.offset
        return out


def listed(names: Sequence[str], limit: int, sep: str = ", ") -> str:
    """The first ``limit`` of ``names`` for a message, joined with ``sep``, and how many more
    there are: ``"a, b, c and 4 more"``."""
    more = len(names) - limit
    return sep.join(names[:limit]) + (f" and {more} more" if more > 0 else "")


def counted(n: int, noun: str, *, figure: bool = False) -> str:
    """``n`` of ``noun`` for a message: "a .b3d file", "3 .b3d files", "1,200 trials"
    (``noun`` singular, its plural made with an s); with ``figure``, one is written as a
    figure too ("1 trial"), as in a table of counts."""
    return f"a {noun}" if n == 1 and not figure else f"{n:,} {noun}{'' if n == 1 else 's'}"
