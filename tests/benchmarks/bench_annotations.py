"""Benchmark of the annotation store (run on demand, not a test).

    .venv/bin/python tests/benchmarks/bench_annotations.py

Targets (issue "The review record"): at least 200 single-frame edits per second with
durability on (each edit is fsync-ed before the call returns); loading a subject with
50 trials of 2,000 frames under 0.2 s.

The scratch folder defaults to a temporary folder on the same disk as the repository
(``--dir`` to choose another); fsync timings depend on that disk.
"""

from __future__ import annotations

import argparse
import random
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from annotations import ACTIVITY_LABELS, AnnotationStore

REPO = Path(__file__).resolve().parents[2]


def bench_edits(folder: Path, n_edits: int, n_trials: int, n_frames: int) -> dict[str, float]:
    """``n_edits`` single-frame edits, each durable; returns rate and latency percentiles."""
    store = AnnotationStore.open(folder, reviewer="bench")
    rng = random.Random(0)
    feet = ("left", "right", "both", None)
    latencies = []
    t_start = time.perf_counter()
    for i in range(n_edits):
        trial = f"trial{rng.randrange(n_trials):02d}"
        frame = rng.randrange(n_frames)
        t0 = time.perf_counter()
        if i % 10 == 9:
            store.set_excluded(trial, frame)
        else:
            store.set_unmeasured(trial, frame, foot=feet[i % 4])
        latencies.append(time.perf_counter() - t0)
    total = time.perf_counter() - t_start
    store.close()
    lat = sorted(latencies)
    return {
        "edits": n_edits,
        "seconds": total,
        "rate": n_edits / total,
        "p50_ms": lat[len(lat) // 2] * 1e3,
        "p99_ms": lat[int(len(lat) * 0.99)] * 1e3,
        "max_ms": lat[-1] * 1e3,
    }


def build_realistic_subject(folder: Path, n_trials: int, n_frames: int) -> None:
    """A subject as a reviewer leaves it: per trial an accepted automatic proposal of
    unmeasured-force runs, 20 manual single-frame corrections, excluded runs, activity
    ranges, notes, trial info and the reviewed mark."""
    rng = np.random.default_rng(1)
    store = AnnotationStore.open(folder, reviewer="builder", compact_every=10**6)
    for k in range(n_trials):
        trial = f"trial{k:02d}"
        store.set_trial_info(trial, n_frames=n_frames, rate_hz=100.0)
        proposal = np.zeros(n_frames, dtype=bool)
        for start in rng.choice(n_frames - 150, size=8, replace=False):
            proposal[start : start + rng.integers(20, 150)] = True
        store.set_mask(trial, proposal, foot=("left", "right")[k % 2])
        for frame in rng.choice(n_frames, size=20, replace=False):
            store.set_unmeasured(trial, int(frame), foot="both")
        for _ in range(2):
            start = int(rng.integers(0, n_frames - 40))
            store.set_excluded(trial, range(start, start + int(rng.integers(10, 40))))
        for j in range(3):
            start = j * n_frames // 3
            label = ACTIVITY_LABELS[int(rng.integers(len(ACTIVITY_LABELS)))]
            store.add_activity(trial, start, start + n_frames // 3, label, note=f"segment {j}")
        store.add_note(trial, "plate 2 saturates at heel strike", start=100, stop=120)
        store.add_note(trial, "checked against video")
        store.set_reviewed(trial)
    store.close()


def bench_load(folder: Path, repeats: int) -> dict[str, float]:
    """Open (load + replay) times of the subject, best and median of ``repeats``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        store = AnnotationStore.open(folder, reviewer="reader")
        times.append(time.perf_counter() - t0)
        store._release_fds()  # no compaction: measure opening only
    return {"best": min(times), "median": statistics.median(times)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--edits", type=int, default=10_000)
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--frames", type=int, default=2_000)
    parser.add_argument("--dir", type=Path, default=None, help="scratch folder (default: temp)")
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="addb-bench-", dir=args.dir))
    try:
        edits_dir = scratch / "edits"
        edits_dir.mkdir()
        e = bench_edits(edits_dir, args.edits, args.trials, args.frames)
        print(
            f"{e['edits']} single-frame edits, durable (fdatasync per edit, compaction every 1000):"
        )
        print(f"  {e['rate']:8.0f} edits/s  ({e['seconds']:.2f} s)   (target >= 200/s)")
        print(
            f"  latency p50 {e['p50_ms']:.2f} ms, p99 {e['p99_ms']:.2f} ms, "
            f"max {e['max_ms']:.1f} ms (max includes a compaction)"
        )
        size = (edits_dir / "annotations.journal").stat().st_size
        print(f"  journal {size / 1e6:.1f} MB, {size / args.edits:.0f} bytes per edit")

        subj = scratch / "subject"
        subj.mkdir()
        build_realistic_subject(subj, args.trials, args.frames)
        main_size = (subj / "annotations.json").stat().st_size
        store = AnnotationStore.open(subj, reviewer="reader")
        flagged = sum(int(store.mask(t).sum()) for t in store.trials())
        t0 = time.perf_counter()
        masks = [store.mask(t) for t in store.trials()]
        t_masks = time.perf_counter() - t0
        store.close()
        load = bench_load(subj, repeats=10)
        print(
            f"subject of {args.trials} trials x {args.frames} frames, realistic flags "
            f"({flagged} unmeasured-force frames), annotations.json {main_size / 1e3:.0f} kB:"
        )
        print(
            f"  open (load + validate): best {load['best'] * 1e3:.1f} ms, "
            f"median {load['median'] * 1e3:.1f} ms   (target < 200 ms)"
        )
        print(f"  masks of all {len(masks)} trials: {t_masks * 1e3:.1f} ms")

        writer = AnnotationStore.open(subj, reviewer="bench", compact_every=10**6)
        rng = random.Random(2)
        for _ in range(999):
            trial = f"trial{rng.randrange(args.trials):02d}"
            writer.set_unmeasured(trial, rng.randrange(args.frames), foot="left")
        writer._release_fds()  # as after a crash: 999 edits only in the journal
        tail = bench_load(subj, repeats=10)
        print(
            f"  open with 999 edits to replay from the journal: best {tail['best'] * 1e3:.1f} ms, "
            f"median {tail['median'] * 1e3:.1f} ms"
        )
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
