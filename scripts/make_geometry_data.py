"""Regenerate ``addb_viewer/geometry_data/``: the bone meshes addb ships with the package.

    python scripts/make_geometry_data.py [--shared ../shared/data] [--check]

The set is every mesh file named (``<mesh_file>`` in OpenSim 4.x, ``<geometry_file>`` in
3.x) by an ``.osim`` model anywhere under ``--shared`` (the Rajagopal 2015/2016 variants,
LaiUhlrich2022, the subjects' and the expert comparison's models), plus :data:`CLASSIC`,
the files of the classic gait models (Gait2354, Gait2392, Hamner 2010) chosen by their
names in OpenSim's Geometry folder. The files are copied byte for byte from
``<shared>/models/Geometry`` (opensim-models' Geometry folder, Apache-2.0); a named file
that folder lacks is listed and skipped. ``FILES.txt`` records the list with the model(s)
that asked for each file. ``--check`` only compares the folder with what would be written
(exit code 1 when they differ).
"""

from __future__ import annotations

import argparse
import hashlib
import re
import shutil
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
TARGET = REPO / "addb_viewer" / "geometry_data"

#: Files of the classic OpenSim gait models (Gait2354/Gait2392: pelvis, legs, HAT torso;
#: Hamner 2010 adds the arms and hands), as named in opensim-models' Geometry folder, in
#: both of its naming schemes (``r_femur`` / ``femur_r``, ``humerus_rv`` / ``r_humerus``).
CLASSIC = ["sacrum", "pelvis", "r_pelvis", "l_pelvis", "femur_r", "femur_l", "r_femur", "l_femur", "tibia_r", "tibia_l", "r_tibia", "l_tibia", "fibula", "fibula_r", "fibula_l", "r_fibula", "l_fibula", "talus", "r_talus", "l_talus", "talus_rv", "talus_lv", "foot", "r_foot", "l_foot", "bofoot", "r_bofoot", "l_bofoot", "r_patella", "l_patella", "pat", "l_pat", "patella_r", "patella_l", "hat_spine", "hat_jaw", "hat_skull", "hat_ribs", "hat_ribs_scap", "humerus", "r_humerus", "l_humerus", "humerus_rv", "humerus_lv", "ulna", "r_ulna", "l_ulna", "ulna_rv", "ulna_lv", "radius", "r_radius", "l_radius", "radius_rv", "radius_lv", "r_hand", "l_hand", "r_scapula", "l_scapula", "r_clavicle", "l_clavicle"]

_MESH = re.compile(r"<(?:mesh_file|geometry_file)>\s*([^<]+?)\s*</(?:mesh_file|geometry_file)>")


def referenced(shared: Path) -> dict[str, list[str]]:
    """Mesh file name -> the models (paths relative to ``shared``) that reference it."""
    refs: dict[str, list[str]] = {}
    for model in sorted(shared.rglob("*.osim")):
        for name in sorted(set(_MESH.findall(model.read_text(errors="replace")))):
            refs.setdefault(Path(name).name, []).append(str(model.relative_to(shared)))
    for name in CLASSIC:
        refs.setdefault(f"{name}.vtp", []).append("classic gait models (by name)")
    return dict(sorted(refs.items()))


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def main(argv: list[str] | None = None) -> int:
    """The command line (the module docstring); returns the exit code (1: ``--check`` found a difference; 2: no Geometry folder)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=SHARED, help="the shared data folder (default ../shared/data)")
    ap.add_argument("--check", action="store_true", help="compare only, write nothing")
    args = ap.parse_args(argv)
    source = args.shared / "models" / "Geometry"
    if not source.is_dir():
        print(f"no Geometry folder at {source}", file=sys.stderr)
        return 2
    refs = referenced(args.shared)
    present = {n: r for n, r in refs.items() if (source / n).is_file()}
    missing = sorted(set(refs) - set(present))
    lines = [f"{n}\t{'; '.join(r)}" for n, r in present.items()]
    listing = "# file\tmodels that reference it (made by scripts/make_geometry_data.py)\n" + "\n".join(lines) + "\n"
    if args.check:
        have = {p.name for p in TARGET.glob("*.vtp")}
        differ = sorted(have ^ set(present)) + [
            n for n in sorted(have & set(present)) if _digest(TARGET / n) != _digest(source / n)
        ]
        stale = (TARGET / "FILES.txt").read_text() != listing if (TARGET / "FILES.txt").is_file() else True
        if differ or stale:
            print(f"{TARGET} differs from {source}: {', '.join(differ) or 'FILES.txt'}", file=sys.stderr)
            return 1
        print(f"{TARGET}: {len(present)} files, up to date")
        return 0
    TARGET.mkdir(parents=True, exist_ok=True)
    for old in TARGET.glob("*.vtp"):
        if old.name not in present:
            old.unlink()
    for name in present:
        shutil.copyfile(source / name, TARGET / name)
    (TARGET / "FILES.txt").write_text(listing)
    size = sum((TARGET / n).stat().st_size for n in present)
    print(f"wrote {len(present)} meshes ({size / 1e6:.1f} MB) to {TARGET}")
    if missing:
        print(f"named but not in {source} (skipped): {', '.join(missing)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
