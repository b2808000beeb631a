"""Benchmark of the raw-file readers (run on demand, not a test).

    .venv/bin/python tests/benchmarks/bench_io.py [--repeats 5]

Targets: reading the largest TRC of ../shared/data (the Camargo level-ground circuit, 3,067
frames) and a 2,000 Hz force file (the Rajagopal walk, 4,778 samples) each under 0.2 s.
Prints the best and median of ``--repeats`` reads after one warm-up read.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from solver.io.mot import read_forces
from solver.io.trc import read_trc
from tests.conftest import SHARED_DATA

FILES = (
    ("TRC, 3067 frames", read_trc, SHARED_DATA / "trials/camargo2021_levelground/markers.trc"),
    ("MOT forces, 4778 samples", read_forces, SHARED_DATA / "trials/rajagopal2016/grf_walk.mot"),
)


def timings(read: Any, path: Path, repeats: int) -> list[float]:
    """Seconds of ``repeats`` reads of ``path`` after one warm-up read."""
    read(path)
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        read(path)
        out.append(time.perf_counter() - start)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    for label, read, path in FILES:
        t = timings(read, path, args.repeats)
        print(f"{label:<28s} best {1000 * min(t):7.1f} ms  median {1000 * statistics.median(t):7.1f} ms  (target < 200 ms)  {path.name}")


if __name__ == "__main__":
    main()
