"""Child process of the crash and concurrency tests (run as a script, not collected).

Usage::

    python annotation_worker.py crash <subject> <trial> <seed> <first_op> <compact_every>
    python annotation_worker.py edit <subject> <worker_id> <n_edits> <go_file> <compact_every>

``crash`` makes an endless, seed-determined sequence of edits (see :func:`crash_ops`) and
prints ``ACK <i>`` after each edit call has returned (the edit is then durable); the parent
kills it with SIGKILL at a random moment. ``edit`` waits for ``go_file`` to exist, then
makes ``n_edits`` edits: frames of its own (``worker_id * 1000 + i``) and frames shared
with the other workers (``5000 + i % 10``), and prints ``DONE``.
"""

from __future__ import annotations

import random
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from annotations import AnnotationStore

FEET = ("left", "right", "both", None)


def crash_ops(seed: int, first: int) -> Iterator[tuple[int, str, int, bool, str | None]]:
    """Op ``i`` (from ``first`` on): ``(i, kind, frame, value, foot)``; same for a given seed."""
    i = first
    while True:
        rng = random.Random(seed * 1_000_003 + i)
        frame = rng.randrange(300)
        r = rng.random()
        if r < 0.75:
            yield i, "unmeasured_force", frame, True, FEET[rng.randrange(4)]
        elif r < 0.85:
            yield i, "unmeasured_force", frame, False, None
        else:
            yield i, "excluded", frame, rng.random() < 0.7, None
        i += 1


def run_crash(subject: str, trial: str, seed: int, first: int, compact_every: int) -> None:
    store = AnnotationStore.open(subject, reviewer="crash", compact_every=compact_every)
    print("READY", flush=True)
    for i, kind, frame, value, foot in crash_ops(seed, first):
        if kind == "unmeasured_force":
            store.set_unmeasured(trial, frame, value, foot=foot)
        else:
            store.set_excluded(trial, frame, value)
        print(f"ACK {i}", flush=True)


def run_edit(subject: str, worker: int, n_edits: int, go_file: str, compact_every: int) -> None:
    store = AnnotationStore.open(subject, reviewer=f"w{worker}", compact_every=compact_every)
    deadline = time.monotonic() + 30
    while not Path(go_file).exists() and time.monotonic() < deadline:
        time.sleep(0.001)
    foot = FEET[worker % 3]
    for i in range(n_edits):
        store.set_unmeasured("shared", worker * 1000 + i, foot=foot)
        if i % 3 == 0:
            store.set_unmeasured("shared", 5000 + i % 10, foot=foot)
        if i % 25 == 0:
            store.add_activity(
                "shared", worker * 1000 + i, worker * 1000 + i + 5, "squat", note=f"w{worker}-{i}"
            )
    store.close()
    print("DONE", flush=True)


if __name__ == "__main__":
    mode, *args = sys.argv[1:]
    if mode == "crash":
        run_crash(args[0], args[1], int(args[2]), int(args[3]), int(args[4]))
    else:
        run_edit(args[0], int(args[1]), int(args[2]), args[3], int(args[4]))
