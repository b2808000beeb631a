"""The output folder of a processed subject, written so that OpenSim users can open it.

Layout (``<subject>`` is the subject folder's name)::

    OUT/<subject>_scaled.osim            scaled (and, after dynamics, mass-fitted) model
    OUT/<trial>/<trial>_ik.mot           coordinates, degrees for rotational coordinates
    OUT/<trial>/<trial>_id.sto           generalized forces (dynamics stage)
    OUT/<trial>/<trial>_grf.mot          plate wrenches as applied (dynamics stage)
    OUT/<trial>/<trial>_external_loads.xml
    OUT/<trial>/results.json             metrics of the trial
    OUT/subject.json                     subject-level results (scales, offsets, mass)

Everything is first written into a temporary sibling folder, which then replaces OUT in
two renames, so a crash or an error never leaves a half-written OUT behind.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np


def _clean(value: Any) -> Any:
    """JSON-safe copy: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON (NaN written as null)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(data), indent=2) + "\n")


@contextmanager
def staged_output(out_dir: str | Path, *, merge: bool = False) -> Iterator[Path]:
    """Yield a temporary folder; on success it replaces ``out_dir`` atomically.

    With ``merge`` and an existing ``out_dir``, each entry written (a trial folder, the
    model, subject.json) replaces its namesake inside ``out_dir`` by a rename, and the other
    entries stay (used to reprocess some trials of a subject). On an exception the
    temporary folder is removed and ``out_dir`` is left untouched.
    """
    out = Path(out_dir).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if merge and out.is_dir():
        trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
        for entry in tmp.iterdir():
            target = out / entry.name
            if target.exists():
                os.replace(target, trash / entry.name)
            os.replace(entry, target)
        shutil.rmtree(trash, ignore_errors=True)
        shutil.rmtree(tmp, ignore_errors=True)
        return
    replace_folder(tmp, out, aside_prefix=f".{out.name}.old-")


def replace_folder(src: Path, dst: Path, *, aside_prefix: str) -> None:
    """Move folder ``src`` to ``dst`` in two renames: an existing ``dst`` is first moved
    into a new temporary folder ``<aside_prefix>*/previous`` beside it (deleted at the end),
    so ``dst`` is at every moment either the old or the new folder, or (between the two
    renames of a killed process) absent with the old one in ``previous``."""
    old = None
    if dst.exists():
        old = Path(tempfile.mkdtemp(prefix=aside_prefix, dir=dst.parent))
        os.replace(dst, old / "previous")
    os.replace(src, dst)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
