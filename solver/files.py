"""File-system helpers: the permissions of files and folders made through :mod:`tempfile`,
symbolic links that lead back to a folder above them (:func:`links_back`), and which
folders a search for subject folders enters (:func:`folders_to_search`).

Outputs are written under a temporary name (``tempfile.mkstemp`` / ``mkdtemp``) and
renamed into place, so that a crash never leaves a half-written file. ``tempfile`` makes
them private to their owner (0600 / 0700) whatever the umask; :func:`as_created` gives
them the permissions ``open()`` or ``mkdir()`` would have (0666 / 0777 less the process's
umask), so that the reviewers of a lab server read what ``addb process`` wrote.
"""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

_lock = threading.Lock()

#: Folder names a search for subject folders never enters (addb's default output folder,
#: Python's byte-code caches, npm's packages); hidden folders are not entered either.
SKIPPED_FOLDERS = frozenset({"addb_out", "__pycache__", "node_modules"})


def _umask() -> int:
    """The process's umask (read by setting and restoring it, under a lock)."""
    with _lock:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def as_created(path: str | Path) -> None:
    """Give ``path`` (a file or a folder) the mode a plain ``open(path, "w")`` or
    ``os.mkdir(path)`` would have given it: 0o666 or 0o777 less the umask.

    Raises
    ------
    OSError
        ``path`` does not exist or its mode cannot be changed.
    """
    p = Path(path)
    base = 0o777 if stat.S_ISDIR(p.stat().st_mode) else 0o666
    os.chmod(p, base & ~_umask())


def links_back(folder: str | Path, name: str) -> bool:
    """True when the entry ``name`` of ``folder`` is a symbolic link to ``folder`` itself or
    to a folder above it: a walk that follows links (``os.walk(followlinks=True)``) would
    go round it until the path grew too long."""
    entry = Path(folder) / name
    if not entry.is_symlink():
        return False
    real, here = entry.resolve(), Path(folder).resolve()
    return real == here or real in here.parents


def folders_to_search(folder: str | Path, names: list[str]) -> tuple[list[str], list[str]]:
    """Which of the sub-folders ``names`` of ``folder`` a search for subject folders enters:
    not hidden ones, not :data:`SKIPPED_FOLDERS`, and not a symbolic link leading back to a
    folder above (:func:`links_back`). The one rule of the dataset search
    (:func:`solver.dataset.discover.scan_dataset`) and of the note on a dataset folder given
    where one subject was expected (:func:`solver.io.subject.dataset_folder_note`).

    Returns
    -------
    (entered, loops)
        The names entered, sorted, and the names left out as links back (sorted).
    """
    entered: list[str] = []
    loops: list[str] = []
    for name in sorted(names):
        if name.startswith(".") or name in SKIPPED_FOLDERS:
            continue
        (loops if links_back(folder, name) else entered).append(name)
    return entered, loops
