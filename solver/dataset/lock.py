"""One dataset run at a time per output tree.

Two runs writing one output tree (``addb process DATASET --out OUT`` started twice, or
while ``addb view DATASET`` processes into the same tree in the background) would each
delete the other's work folders at start (:func:`solver.dataset.task.remove_stale_work`),
so the other's running subjects would fail, and a failure with unchanged inputs is not run
again. :func:`output_tree_lock` takes an exclusive ``flock`` on ``OUT/.addb_run.lock`` for
the run: the system releases it when the process ends, however it ends, so a crashed run
leaves no stale lock. The file stays, naming the last run that held it.

A one-subject run whose ``--out`` lies inside a dataset run's output tree (``addb process
labA/s01 --out OUT/labA/s01``) replaces that subject's folder: it holds the same lock
(:func:`subject_output_lock`), so that it does not write the folder while a dataset run
works on the tree, nor a dataset run start while it does.

In one process, a writer that runs beside the process's own dataset run (the review app's
Reprocess under ``addb view DATASET``'s background run, which does not process that subject)
joins that run's hold (:func:`join_tree_hold`): the ``flock`` is released once the last of
them ends, so the tree stays held while the Reprocess writes even if the dataset run ends
first.
"""

from __future__ import annotations

import fcntl
import os
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from solver.errors import DatasetError
from solver.outputs import RUN_LOCK_NAME, output_tree_above

#: The lock file in the output tree (hidden: the dataset search and the exports skip it).
LOCK_NAME = RUN_LOCK_NAME


#: The trees this process holds: resolved tree -> [the lock file, number of holders].
_held: dict[Path, list] = {}
_held_guard = threading.Lock()


@contextmanager
def output_tree_lock(out_dir: str | Path) -> Iterator[None]:
    """Hold the output tree ``out_dir`` (an existing folder) for one dataset run.

    A file system without ``flock`` (some network mounts) is run on without the lock. A
    writer of this process may join the hold (:func:`join_tree_hold`); the lock is then
    released when the last holder ends.

    Raises
    ------
    DatasetError
        Another run holds the tree (another process, or another holder in this one); the
        message names it (process id, host, start time) and what to do.
    """
    path = Path(out_dir) / LOCK_NAME
    f = open(path, "a+", encoding="utf-8")  # noqa: SIM115 - closed by _release, maybe by a later holder
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        held = True
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "another process"
        f.close()
        raise DatasetError(
            f"another addb run is writing this output tree ({holder}); wait for it to end (or stop it), "
            "or give another --out",
            path=Path(out_dir),
        ) from None
    except OSError:  # no flock on this file system: run unguarded, as before
        held = False
    key = Path(out_dir).resolve()
    if held:
        try:
            f.seek(0)
            f.truncate()
            f.write(f"process {os.getpid()} on {socket.gethostname()}, started {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            f.flush()
        except BaseException:  # a full disk: closing the file releases the lock now
            f.close()
            raise
        with _held_guard:
            _held[key] = [f, 1]
    try:
        yield
    finally:
        _release(key, f)


def _release(key: Path, f: Any) -> None:
    """One holder of ``key``'s lock file ``f`` ends; the last one unlocks and closes it."""
    with _held_guard:
        entry = _held.get(key)
        if entry is not None and entry[0] is f:
            entry[1] -= 1
            if entry[1] > 0:
                return  # another holder in this process keeps the tree
            del _held[key]
    try:
        fcntl.flock(f, fcntl.LOCK_UN)
    except OSError:  # never locked (no flock here)
        pass
    f.close()


@contextmanager
def join_tree_hold(tree: str | Path | None) -> Iterator[bool]:
    """Join this process's hold of the output tree ``tree`` (an :func:`output_tree_lock`
    held by another thread of this process, e.g. the review app's background dataset run)
    for as long as this context lasts: the lock is released only when both have ended.
    Yields False, holding nothing, when this process does not hold ``tree`` (or ``tree`` is
    None); the caller then takes the lock itself (:func:`subject_output_lock`)."""
    key = Path(tree).resolve() if tree is not None else None
    with _held_guard:
        entry = _held.get(key) if key is not None else None
        if entry is not None:
            entry[1] += 1
    if entry is None:
        yield False
        return
    try:
        yield True
    finally:
        _release(key, entry[0])


@contextmanager
def subject_output_lock(out_dir: str | Path) -> Iterator[Path | None]:
    """Hold the dataset output tree that a one-subject run's output folder ``out_dir`` lies
    in (:func:`solver.outputs.output_tree_above`) while the run writes it, yielding the tree;
    yield None, holding nothing, when ``out_dir`` lies in no output tree.

    Raises
    ------
    DatasetError
        A dataset run (or another one-subject run) holds the tree (:func:`output_tree_lock`).
    """
    tree = output_tree_above(out_dir)
    if tree is None:
        yield None
        return
    with output_tree_lock(tree):
        yield tree
