"""Where the review app reads and writes, and the confinement of paths given from the page.

The page never names an arbitrary file: trial names pick folders inside the output folder,
a recording's file name is taken inside the recordings folder, and mesh file names from a
model are taken inside its geometry folder. :func:`confine` enforces this: a path that
resolves (symbolic links included) outside its root is refused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from addb_viewer.locations import annotations_path, default_output_dir, uses_subject_folder
from solver.errors import AddbError


class UnsafePathError(AddbError):
    """A path given from the page (or a model) points outside the folder it must stay in."""


def confine(root: str | os.PathLike[str], candidate: str | os.PathLike[str]) -> Path:
    """Resolve ``candidate`` inside ``root`` and refuse anything that leaves it.

    Parameters
    ----------
    root
        The folder the path must stay in (need not exist yet).
    candidate
        A path relative to ``root`` (or absolute, then it must still lie inside ``root``).

    Returns
    -------
    Path
        The resolved absolute path, inside the resolved ``root``.

    Raises
    ------
    UnsafePathError
        Empty, containing a NUL character, or resolving outside ``root`` (``..``,
        an absolute path elsewhere, a symbolic link pointing out).
    """
    text = os.fspath(candidate)
    if not str(text).strip() or "\x00" in str(text):
        raise UnsafePathError(f"not a usable path: {text!r}")
    base = Path(root).resolve()
    p = Path(text)
    full = (p if p.is_absolute() else base / p).resolve()
    if full != base and not full.is_relative_to(base):
        raise UnsafePathError(f"{text!r} is outside {base}", path=base)
    return full


def safe_name(name: str, *, what: str = "name") -> str:
    """``name`` if it is a single, plain path component (no separators, not ``.``/``..``).

    Raises
    ------
    UnsafePathError
        Otherwise.
    """
    if (
        not isinstance(name, str)
        or not name.strip()
        or name in (".", "..")
        or "/" in name
        or "\\" in name
        or any(ord(c) < 32 for c in name)
        or len(name) > 255
    ):
        raise UnsafePathError(f"{what} must be a plain file or folder name, got {name!r}")
    return name


@dataclass(frozen=True)
class ReviewPaths:
    """The folders of one reviewed subject.

    Attributes
    ----------
    subject_dir
        The AddBiomechanics subject folder (read only for the app).
    out_dir
        Processed output (``OUT/<trial>/trial.npz``), replaced by the solver.
    annotations
        The review record ``annotations.json`` (its journal and lock file beside it).
    recordings_dir
        Where "Record to Rerun" writes ``.rrd`` files.
    jobs_dir
        Scratch folders of reprocessing runs (a sibling of ``out_dir``, so that finished
        trial folders move into ``out_dir`` with a rename).
    """

    subject_dir: Path
    out_dir: Path
    annotations: Path
    recordings_dir: Path
    jobs_dir: Path

    @classmethod
    def for_subject(
        cls, subject_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str] | None = None
    ) -> ReviewPaths:
        """Default locations (see :mod:`addb_viewer.locations`), ``out_dir`` if given.

        The recordings go to ``<subject>/addb_recordings`` for a writable subject folder,
        else beside the output folder (``<out>.recordings``).
        """
        subject = Path(subject_dir).resolve()
        out = Path(out_dir).resolve() if out_dir is not None else default_output_dir(subject)
        if uses_subject_folder(subject):
            recordings = subject / "addb_recordings"
        else:
            recordings = out.parent / f"{out.name}.recordings"
        return cls(
            subject_dir=subject,
            out_dir=out,
            annotations=annotations_path(subject, out),
            recordings_dir=recordings,
            jobs_dir=out.parent / f".{out.name}.jobs",
        )

    def trial_dir(self, trial: str) -> Path:
        """``OUT/<trial>``, refusing a trial name that is not a plain folder name."""
        return confine(self.out_dir, safe_name(trial, what="trial name"))

    def recording_file(self, file_name: str, *, suffix: str = ".rrd") -> Path:
        """A recording file inside :attr:`recordings_dir` (``suffix`` added if missing)."""
        name = safe_name(file_name.strip(), what="recording file name")
        if not name.endswith(suffix):
            name += suffix
        return confine(self.recordings_dir, name)
