"""Concurrency test: several processes edit the same subject at once; no edit is lost."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import time
from pathlib import Path

from annotation_support import WORKER

from annotations import AnnotationStore
from annotations.journal import read_header, scan

N_WORKERS = 4
N_EDITS = 120
FEET = ("left", "right", "both")


def _journal_ops(subject: Path):
    path = subject / "annotations.journal"
    fd = os.open(path, os.O_RDONLY)
    try:
        _jid, base, header = read_header(fd, path)
        data = os.pread(fd, os.fstat(fd).st_size - header, header)
    finally:
        os.close(fd)
    return scan(data, path=path, first_line=2, next_seq=base + 1).ops


def test_several_processes_editing_at_once_lose_nothing(subject: Path) -> None:
    AnnotationStore.open(subject, reviewer="setup").close()
    go = subject.parent / "go"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    workers = [
        subprocess.Popen(
            [
                sys.executable,
                str(WORKER),
                "edit",
                str(subject),
                str(w),
                str(N_EDITS),
                str(go),
                "30",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
        )
        for w in range(N_WORKERS)
    ]
    time.sleep(0.5)  # let them all open the store, then start together
    go.touch()
    for p in workers:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err.decode()
        assert out.strip() == b"DONE"

    store = AnnotationStore.open(subject, reviewer="check")
    n_activities = len(range(0, N_EDITS, 25))
    n_shared = len(range(0, N_EDITS, 3))
    assert store.seq == N_WORKERS * (N_EDITS + n_shared + n_activities)
    for w in range(N_WORKERS):
        # every edit of every worker on its own frames is there, with its author
        for i in range(N_EDITS):
            flag = store.flag("shared", w * 1000 + i)
            assert flag is not None and flag.foot == FEET[w % 3]
            assert flag.provenance.reviewer == f"w{w}"
        notes = {a.note for a in store.activities("shared")}
        assert {f"w{w}-{i}" for i in range(0, N_EDITS, 25)} <= notes
    assert len(store.activities("shared")) == N_WORKERS * n_activities

    # the shared frames hold the value of the last write in the journal
    ops = _journal_ops(subject)
    assert [op.seq for op in ops] == list(range(1, store.seq + 1))
    switches = sum(a.session != b.session for a, b in itertools.pairwise(ops))
    assert switches > 4 * N_WORKERS  # the writers really did interleave
    last: dict[int, str] = {}
    for op in ops:
        for key in op.puts:
            if key[0] == "flag" and key[3] >= 5000:
                last[key[3]] = op.provenance.reviewer
    assert sorted(last) == list(range(5000, 5010))
    for frame, reviewer in last.items():
        assert store.flag("shared", frame).provenance.reviewer == reviewer
    # conflicts only ever concern the shared frames, never a worker's own frames
    for c in store.conflicts():
        assert all(5000 <= s < e <= 5010 for s, e in c.frames), c
    print(f"{switches} writer switches, {len(store.conflicts())} conflicts listed")
    store.close()
