"""Dataset trees for the dataset-processing tests, built from ../shared/data.

``build_tree`` copies real subject folders under lab folders, and can add a broken subject
(its walk TRC cut in the middle of a row) and a kinematics-only subject (the walk with
``disableDynamics``).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from tests.conftest import SHARED_DATA, writable_copy

SUBJECTS = SHARED_DATA / "subjects"

#: Relative path in the tree -> shared subject folder.
FULL_TREE = {
    "labA/rajagopal2016_walk": "rajagopal2016_walk",
    "labA/rajagopal2016_run": "rajagopal2016_run",
    "labB/opencap_uhlrich2023": "opencap_uhlrich2023",
}
BROKEN = "labB/broken_walk"
KINEMATICS_ONLY = "labB/2023/walk_kinematics_only"
#: The 1-based line of the broken TRC that is cut short.
BROKEN_LINE = 121


def build_tree(root: Path, subjects: dict[str, str], *, broken: bool = False, kinematics_only: bool = False) -> Path:
    """Copy ``subjects`` (rel -> shared subject name) under ``root``, plus the extras."""
    for rel, name in subjects.items():
        writable_copy(SUBJECTS / name, root / rel)
    if broken:
        trc = writable_copy(SUBJECTS / "rajagopal2016_walk", root / BROKEN) / "trials" / "walk" / "markers.trc"
        lines = trc.read_text().split("\n")
        trc.write_text("\n".join(lines[: BROKEN_LINE - 1]) + "\n" + lines[BROKEN_LINE - 1][:30])
    if kinematics_only:
        folder = writable_copy(SUBJECTS / "rajagopal2016_walk", root / KINEMATICS_ONLY)
        meta = json.loads((folder / "_subject.json").read_text())
        meta["disableDynamics"] = True
        (folder / "_subject.json").write_text(json.dumps(meta, indent=2))
    return root


def results(out: Path) -> dict[str, dict]:
    """Trial name -> results.json of a subject output folder."""
    return {p.parent.name: json.loads(p.read_text()) for p in sorted(out.glob("*/results.json"))}


#: results.json entries compared between a dataset run and a serial one-subject run.
COMPARED = (
    "marker_rms_m", "marker_max_m", "linear_residual_rms_N", "angular_residual_rms_Nm",
    "linear_residual_rms_BW", "angular_residual_rms_BWh", "mass_kg", "n_observed_frames", "n_frames",
)  # fmt: skip


def assert_same_results(dataset_out: Path, serial_out: Path, tol: float = 1e-9) -> int:
    """Every compared metric of every trial equal within ``tol``; returns how many compared."""
    a, b = results(dataset_out), results(serial_out)
    assert sorted(a) == sorted(b) and a
    n = 0
    for trial in a:
        for key in COMPARED:
            if key in b[trial] or key in a[trial]:
                x, y = a[trial][key], b[trial][key]
                assert (x is None and y is None) or abs(x - y) <= tol, (trial, key, x, y)
                n += 1
    return n


def no_work_folders(out: Path) -> list[Path]:
    """Leftovers of unfinished writes below ``out`` (must be empty): work folders of the
    dataset tasks and the pipeline's staging folders (``.<name>.tmp-*``, ``.<name>.old-*``);
    the kinematics cache (``.addb_cache``) is part of a finished output."""
    return [p for p in out.rglob("*") if p.is_dir() and (p.name.startswith(".addb-work-") or ".tmp-" in p.name or ".old-" in p.name)]


def rm(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)
