"""The client process of ``addb process DATASET_DIR`` over a batch, with and without the
console script's start-up step (run on demand).

    .venv/bin/python tests/benchmarks/bench_dataset_client.py [--subjects N] [--workers W]

The ``addb`` console script runs a command that runs to completion with
:func:`addb_viewer.cli.run_to_completion`: glibc's mmap and trim thresholds set, full
garbage collections deferred (generation-2 threshold 1000), the last one skipped at exit.
For a dataset, that process is the Dask client and the local cluster's scheduler; its
workers are separate processes with the defaults. This script checks that deferring full
collections does not let that process grow over a batch: it builds a dataset of N copies of
the walk (../shared/data/subjects/rajagopal2016_walk; default 24) in a temporary folder and
runs ``addb process DATASET --out OUT --workers W`` (default 1) twice in a fresh child: as
the console script runs it, and with ``main`` called with its arguments (as from Python:
the interpreter's defaults). Prints per run the wall time, the subjects processed, the
client process's own peak resident memory (``getrusage(RUSAGE_SELF)`` at exit, which
leaves out the workers) and the garbage collections it ran per generation.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from user_env import compile_sources, user_environment  # this folder: the script's own

REPO = Path(__file__).resolve().parents[2]
WALK = REPO.parent / "shared" / "data" / "subjects" / "rajagopal2016_walk"

#: Run in the child: argv = mode ("console" or "defaults"), then addb's arguments. Prints
#: one JSON line at exit (after the command's own exit handlers registered later).
CHILD = """
import atexit, gc, json, resource, sys
def report():
    print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "collections": [s["collections"] for s in gc.get_stats()]}), flush=True)
if __name__ == "__main__":
    atexit.register(report)
    from addb_viewer.cli import main
    mode, args = sys.argv[1], sys.argv[2:]
    if mode == "console":
        sys.argv = ["addb", *args]
        main()
    else:
        main(args)
"""


def run(mode: str, dataset: Path, out: Path, workers: int) -> dict:
    """One ``addb process DATASET`` in a fresh child: its wall time, the subjects' outcomes
    (dataset_summary.json) and the client's peak RSS and collections."""
    cmd = [sys.executable, "-c", CHILD, mode, "process", str(dataset), "--out", str(out), "--workers", str(workers)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=True, env=user_environment())
    wall = time.perf_counter() - t0
    counts = json.loads((out / "dataset_summary.json").read_text())["totals"]["subjects"]
    return {"wall": wall, "subjects": counts, **json.loads(proc.stdout.strip().splitlines()[-1])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--subjects", type=int, default=24)
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    compile_sources()
    with tempfile.TemporaryDirectory() as tmp:
        dataset = Path(tmp) / "dataset"
        for i in range(args.subjects):
            shutil.copytree(WALK, dataset / f"s{i + 1:02d}")
        print(f"addb process DATASET --workers {args.workers}: {args.subjects} copies of the walk; client process only\n")
        print("| client process | wall (s) | subjects | peak RSS (MB) | collections per generation (0, 1, 2) |")
        print("| --- | ---: | --- | ---: | --- |")
        for mode, label in (("console", "as the `addb` console script (run_to_completion)"), ("defaults", "interpreter defaults")):
            r = run(mode, dataset, Path(tmp) / f"out_{mode}", args.workers)
            print(f"| {label} | {r['wall']:.0f} | {r['subjects']} | {r['peak_rss_mb']:.0f} | {', '.join(map(str, r['collections']))} |", flush=True)


if __name__ == "__main__":
    main()
