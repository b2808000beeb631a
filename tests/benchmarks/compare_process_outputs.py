"""Compare two ``addb process`` output trees value by value (the exactness check of speedups).

    .venv/bin/python tests/benchmarks/compare_process_outputs.py OLD_ROOT NEW_ROOT

OLD_ROOT and NEW_ROOT hold one output folder per subject (``addb process SUBJECT --out
ROOT/SUBJECT``). Every numeric value of every JSON file (subject.json, results.json; wall
times and the output model path left out) and every array of every trial.npz (its JSON
header value by value) that both trees have is compared; non-numeric values must be equal;
keys only one tree has (settings an older version did not record) are listed. Prints per subject
the number of values, the largest relative difference and the four worst, where the
relative difference of an array is max |a - b| / max |a| (NaN must match NaN).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

SKIP = ("seconds", "model_path")  # wall-time fields, the output folder

def flat(x, prefix=""):
    if isinstance(x, dict):
        for k, v in x.items():
            if any(s in k for s in SKIP):
                continue
            yield from flat(v, f"{prefix}.{k}" if prefix else k)
    elif isinstance(x, list):
        try:
            a = np.asarray(x, dtype=float)
            yield prefix, a
        except (ValueError, TypeError):
            for i, v in enumerate(x):
                yield from flat(v, f"{prefix}[{i}]")
    elif isinstance(x, bool) or x is None or isinstance(x, str):
        yield prefix, x
    elif isinstance(x, (int, float)):
        yield prefix, np.asarray(float(x))

def rel(a, b):
    a = np.asarray(a, dtype=float); b = np.asarray(b, dtype=float)
    if a.shape != b.shape:
        return np.inf
    fa, fb = np.isfinite(a), np.isfinite(b)
    if (fa != fb).any():
        return np.inf
    if not fa.any():
        return 0.0
    scale = max(np.abs(a[fa]).max(), 1e-300)
    return float(np.abs(a[fa] - b[fb]).max() / scale)

def _compare_values(da: dict, db: dict, where: str, worst: list, only: dict) -> None:
    """Append (relative difference, name) for every value the two flattened documents
    share; keys one of them lacks go to ``only`` (``{"old": [...], "new": [...]}``: e.g.
    settings an older version did not record)."""
    only["old"] += [f"{where}:{k}" for k in da.keys() - db.keys()]
    only["new"] += [f"{where}:{k}" for k in db.keys() - da.keys()]
    for k in da.keys() & db.keys():
        va, vb = da[k], db[k]
        if isinstance(va, np.ndarray) and va.dtype.kind == "f":
            worst.append((rel(va, vb), f"{where}:{k}"))
        elif not (isinstance(va, np.ndarray) and np.array_equal(va, vb)) and va != vb:
            worst.append((np.inf, f"{where}:{k} {va!r} != {vb!r}"))


def main(old: str, new: str) -> None:
    root_old, root_new = Path(old), Path(new)
    for subj in sorted(p.name for p in root_old.iterdir() if p.is_dir()):
        worst: list = []
        only: dict = {"old": [], "new": []}
        for f in sorted((root_old / subj).rglob("*.json")):
            g = root_new / subj / f.relative_to(root_old / subj)
            _compare_values(dict(flat(json.loads(f.read_text()))), dict(flat(json.loads(g.read_text()))), str(f.relative_to(root_old)), worst, only)
        for f in sorted((root_old / subj).rglob("*.npz")):
            a, b = np.load(f), np.load(root_new / subj / f.relative_to(root_old / subj))
            assert set(a.files) == set(b.files)
            where = str(f.relative_to(root_old))
            for k in a.files:
                if k == "header":  # JSON text: compared value by value like results.json
                    ha, hb = dict(flat(json.loads(str(a[k])))), dict(flat(json.loads(str(b[k]))))
                    _compare_values(ha, hb, f"{where}:header", worst, only)
                elif a[k].dtype.kind in "fiub":
                    worst.append((rel(a[k], b[k]), f"{where}:{k}"))
                elif not np.array_equal(a[k], b[k]):
                    worst.append((np.inf, f"{where}:{k} differs"))
        worst.sort(reverse=True)
        print(
            f"{subj}: {len(worst)} values compared, max relative difference {worst[0][0]:.2e}; worst: "
            + "; ".join(f"{n} {r:.1e}" for r, n in worst[:4])
        )
        for side in ("old", "new"):
            if only[side]:
                names = sorted({k.split(":", 1)[1] for k in only[side]})
                print(f"  only in the {side} outputs ({len(only[side])} values, not compared): {', '.join(names)}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
