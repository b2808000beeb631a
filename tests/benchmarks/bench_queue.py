"""How fast the review queue of a large dataset opens (run on demand).

    .venv/bin/python tests/benchmarks/bench_queue.py [--subjects 300]

Processes the walk once, then builds a synthetic dataset of N subject folders (each a
``_subject.json`` under ``labK/sNNN``) with an output tree that holds each subject's
``manifest.json`` (the walk's real summary rows) and a review record for every third
subject (flags on one proposed range; every ninth marked reviewed). Prints the time of
``dataset_subjects`` + ``build_queue`` (median of 5) against the target of 1 s.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
WALK = REPO.parent / "shared" / "data" / "subjects" / "rajagopal2016_walk"


def main() -> None:
    from addb_viewer.app.queue import build_queue, dataset_subjects
    from addb_viewer.locations import annotations_path
    from annotations import AnnotationStore
    from solver.dataset.summary import subject_rows
    from solver.pipeline import process_subject

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subjects", type=int, default=300)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        process_subject(WALK, base / "walk_out")
        rows = subject_rows(base / "walk_out")
        first = next(r for r in rows if r["trial"] == "walk")["proposed_ranges"][0]
        meta = (WALK / "_subject.json").read_text()
        root = base / "dataset"
        for k in range(args.subjects):
            rel = f"lab{k % 15}/s{k:03d}"
            (root / rel).mkdir(parents=True)
            (root / rel / "_subject.json").write_text(meta)
            out = root / "addb_out" / rel
            out.mkdir(parents=True)
            (out / "manifest.json").write_text(json.dumps({"key": {}, "status": "ok", "trials": rows}))
            if k % 3 == 0:
                with AnnotationStore.open(annotations_path(root / rel, out), reviewer="bench") as s:
                    s.set_unmeasured("walk", range(*first))
                    if k % 9 == 0:
                        s.set_reviewed("walk")
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            _, _, subjects = dataset_subjects(root)
            queue = build_queue(subjects)
            times.append(time.perf_counter() - t0)
    print(f"{time.strftime('%Y-%m-%d')}: queue of {args.subjects} processed subjects ({len(queue)} rows, "
          f"{args.subjects // 3} review records): {statistics.median(times) * 1000:.0f} ms median of 5 "
          f"(min {min(times) * 1000:.0f} ms); target under 1000 ms")  # fmt: skip


if __name__ == "__main__":
    main()
