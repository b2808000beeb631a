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
"""

from __future__ import annotations

import fcntl
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from solver.errors import DatasetError
from solver.outputs import output_tree_above

#: The lock file in the output tree (hidden: the dataset search and the exports skip it).
LOCK_NAME = ".addb_run.lock"


@contextmanager
def output_tree_lock(out_dir: str | Path) -> Iterator[None]:
    """Hold the output tree ``out_dir`` (an existing folder) for one dataset run.

    A file system without ``flock`` (some network mounts) is run on without the lock.

    Raises
    ------
    DatasetError
        Another run holds the tree; the message names it (process id, host, start time)
        and what to do.
    """
    path = Path(out_dir) / LOCK_NAME
    with open(path, "a+", encoding="utf-8") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            held = True
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            raise DatasetError(
                f"another addb run is writing this output tree ({holder}); wait for it to end (or stop it), "
                "or give another --out",
                path=Path(out_dir),
            ) from None
        except OSError:  # no flock on this file system: run unguarded, as before
            held = False
        if held:
            f.seek(0)
            f.truncate()
            f.write(f"process {os.getpid()} on {socket.gethostname()}, started {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            f.flush()
        try:
            yield
        finally:
            if held:
                fcntl.flock(f, fcntl.LOCK_UN)


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
