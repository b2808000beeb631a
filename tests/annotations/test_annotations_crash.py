"""Crash test: a child process edits and is killed with SIGKILL at random moments.

Every edit the child acknowledged (printed after the edit call returned) must be present
after reload, and the subject file must always parse.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from annotation_support import WORKER
from annotation_worker import crash_ops

from annotations import EXCLUDED, UNMEASURED_FORCE, AnnotationStore

ROUNDS = 10
TRIAL = "walk"


def _run_and_kill(
    subject: Path, seed: int, first: int, delay_s: float, *, after_ready: bool = False
) -> list[int]:
    """Start the child, SIGKILL it ``delay_s`` after the start (or, with ``after_ready``,
    after it has opened the store and printed READY, so that the kill lands among edits
    however slowly the interpreter starts on a loaded machine); return the acknowledged op
    numbers."""
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    lines: list[bytes] = []
    ready = threading.Event()

    def read(stream) -> None:
        for line in stream:
            lines.append(line)
            if line.startswith(b"READY"):
                ready.set()

    with subprocess.Popen(
        [sys.executable, str(WORKER), "crash", str(subject), TRIAL, str(seed), str(first), "17"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    ) as child:
        reader = threading.Thread(target=read, args=(child.stdout,), daemon=True)
        reader.start()
        if after_ready:
            assert ready.wait(timeout=60), "the child never opened the store"
        time.sleep(delay_s)
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
        reader.join(timeout=30)
        err = child.stderr.read().decode()
    assert "Traceback" not in err, err
    return [int(x.split()[1]) for x in lines if x.startswith(b"ACK ")]


def _expected(seed: int, first: int, count: int, base: dict) -> dict:
    """State of every (kind, frame) after ops first..first+count-1 on top of ``base``."""
    state = dict(base)
    ops = crash_ops(seed, first)
    for _ in range(count):
        _i, kind, frame, value, foot = next(ops)
        state[(kind, frame)] = foot if value else "clear"
    return state


def _actual(store: AnnotationStore) -> dict:
    out = {}
    for kind in (UNMEASURED_FORCE, EXCLUDED):
        for s, e in store.ranges(TRIAL, kind):
            for f in range(s, e):
                out[(kind, f)] = store.flag(TRIAL, f, kind).foot
    return out


def _flagged(state: dict) -> dict:
    return {k: v for k, v in state.items() if v != "clear"}


def test_acknowledged_edits_survive_sigkill(subject: Path) -> None:
    rng = random.Random(20261121)
    seed = 7
    done = 0  # ops known to be in the record
    base: dict = {}
    total_acked = 0
    for _round in range(ROUNDS):
        # even rounds: a random moment from the start (sometimes before the first edit);
        # odd rounds: 0.2-0.7 s after the store is open, in the middle of editing
        after_ready = _round % 2 == 1
        delay = (0.2 if after_ready else 0.05) + rng.random() * 0.5
        acked = _run_and_kill(subject, seed, done, delay, after_ready=after_ready)
        assert acked == list(range(done, done + len(acked)))  # acks in order, no gaps
        if after_ready:
            assert acked, f"round {_round}: the kill did not land among edits"
        total_acked += len(acked)
        main = subject / "annotations.json"
        if main.exists() or done:  # (a kill before the child created the files is fine)
            json.loads(main.read_bytes())  # the subject file always parses
        store = AnnotationStore.open(subject, reviewer="checker")
        actual = _actual(store)
        store.close()
        with_acked = _expected(seed, done, len(acked), base)
        # the edit in flight at the kill may or may not have become durable
        with_in_flight = _expected(seed, done, len(acked) + 1, base)
        if actual == _flagged(with_acked):
            done += len(acked)
            base = with_acked
        else:
            assert actual == _flagged(with_in_flight), f"round {_round}: acknowledged edit lost"
            done += len(acked) + 1
            base = with_in_flight
    print(f"{total_acked} acknowledged edits over {ROUNDS} kills")
    # temporary files of rewrites cut short are removed by the next open
    assert [p.name for p in subject.iterdir() if ".tmp-" in p.name] == []
