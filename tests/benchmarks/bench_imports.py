"""Start-up cost of a whole ``addb process``: the imports (run on demand).

    .venv/bin/python tests/benchmarks/bench_imports.py [--repeat N]

Prints (1) each heavy library's import time alone in a fresh interpreter (``python -X
importtime -c "import NAME"``: the cumulative time of its top-level entry, median of
``--repeat``), with the installed versions, and (2) the import time of a whole ``addb
process`` of the walk (the sum of the top-level entries of ``-X importtime``, median of
``--repeat``) beside that process' wall time. A Dask worker pays the imports once for all
its subjects (block ``dataset``); a single ``addb process`` pays them every time (block
``process``). addb's bytecode is compiled first, as an install has it (``user_env.py``).
"""

from __future__ import annotations

import argparse
import importlib.metadata as md
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from user_env import REPO, compile_sources, user_environment  # this folder: the script's own

MODULES = ("numpy", "pinocchio", "scipy.linalg", "scipy.sparse.linalg", "scipy.interpolate", "scipy.signal", "solver.pipeline")
WALK = REPO.parent / "shared" / "data" / "subjects" / "rajagopal2016_walk"


def _top_level_us(stderr: str) -> list[tuple[str, int]]:
    """(module, cumulative µs) of the top-level entries of ``-X importtime`` output."""
    rows = []
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        _, cumulative, name = line.split("|")
        if not name.startswith("  "):  # nested imports are indented by two spaces per level
            rows.append((name.strip(), int(cumulative)))
    return rows


def _import_alone(module: str) -> float:
    """Seconds to import ``module`` (and what it imports) in a fresh interpreter."""
    r = subprocess.run([sys.executable, "-X", "importtime", "-c", f"import {module}"], capture_output=True, text=True, check=True, env=user_environment())
    return sum(us for _, us in _top_level_us(r.stderr)) / 1e6


def _whole_process() -> tuple[float, float]:
    """(import s, wall s) of one ``addb process`` of the walk."""
    addb = str(Path(sys.executable).parent / "addb")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-X", "importtime", addb, "process", str(WALK), "--out", tmp], capture_output=True, text=True, check=True, env=user_environment())
        wall = time.perf_counter() - t0
    return sum(us for _, us in _top_level_us(r.stderr)) / 1e6, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    compile_sources()
    versions = ", ".join(f"{p} {md.version(p)}" for p in ("numpy", "scipy", "pin"))
    print(f"imports, median of {args.repeat} fresh interpreters; {versions}; Python {sys.version.split()[0]}")
    print("| module (alone, with what it imports) | import (s) |")
    print("| --- | ---: |")
    for m in MODULES:
        print(f"| `{m}` | {statistics.median(_import_alone(m) for _ in range(args.repeat)):.2f} |")
    runs = [_whole_process() for _ in range(args.repeat)]
    imports, walls = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
    print(f"\nwhole `addb process` of the walk (with -X importtime): imports {imports:.2f} s of {walls:.2f} s wall (medians)")


if __name__ == "__main__":
    main()
