"""The subject folders of a dataset folder, and where each one's output goes.

A *subject folder* is a folder holding ``_subject.json`` (the AddBiomechanics layout,
:mod:`solver.io.subject`). A *dataset folder* holds subject folders at any depth, for
example one folder per lab::

    DATASET/labA/s01/_subject.json  ->  OUT/labA/s01/   (the one-subject output layout)
    DATASET/labA/s02/_subject.json  ->  OUT/labA/s02/
    DATASET/labB/p7/_subject.json   ->  OUT/labB/p7/

The search does not descend into a subject folder (its ``trials/`` are not subjects),
into hidden folders, into addb's own output folders (``addb_out``) or into the output
folder of the run itself when it lies inside the dataset folder.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from solver.errors import DatasetError
from solver.io.subject import SUBJECT_JSON

#: Folder names never searched for subjects (addb's default output folder).
SKIPPED_FOLDERS = frozenset({"addb_out", "__pycache__", "node_modules"})


@dataclass(frozen=True)
class DatasetSubject:
    """One subject folder of a dataset.

    Attributes
    ----------
    rel
        Its path relative to the dataset folder, with ``/`` separators (``labA/s01``);
        also the subject's key in the summary and its output folder below OUT.
    path
        The subject folder (absolute).
    """

    rel: str
    path: Path

    def out_dir(self, out_root: str | Path) -> Path:
        """Its output folder below ``out_root`` (the mirrored relative path)."""
        return Path(out_root).resolve().joinpath(*PurePosixPath(self.rel).parts)


def is_subject_folder(path: str | Path) -> bool:
    """True when ``path`` is a folder holding ``_subject.json``."""
    return (Path(path) / SUBJECT_JSON).is_file()


def find_subjects(root: str | Path, *, exclude: tuple[str | Path, ...] = ()) -> tuple[DatasetSubject, ...]:
    """Every subject folder below ``root``, sorted by relative path.

    Parameters
    ----------
    root
        The dataset folder (not itself a subject folder).
    exclude
        Folders not to search (the run's output folder when it lies inside ``root``).

    Returns
    -------
    tuple of DatasetSubject
        At least one.

    Raises
    ------
    DatasetError
        ``root`` is not a folder, or holds no subject folder.
    """
    base = Path(root).resolve()
    if not base.is_dir():
        raise DatasetError("not a folder; expected a dataset folder of subject folders", path=root)
    skip = {Path(p).resolve() for p in exclude}
    found: list[DatasetSubject] = []
    for folder, dirs, files in os.walk(base, followlinks=True):
        here = Path(folder)
        if SUBJECT_JSON in files and here != base:
            found.append(DatasetSubject(here.relative_to(base).as_posix(), here))
            dirs[:] = []  # a subject's trials are not subjects
            continue
        dirs[:] = sorted(
            d for d in dirs if not d.startswith(".") and d not in SKIPPED_FOLDERS and (here / d).resolve() not in skip
        )
    if not found:
        raise DatasetError(
            f"no subject folder (a folder holding {SUBJECT_JSON}) below this folder", path=base
        )
    return tuple(sorted(found, key=lambda s: s.rel))
