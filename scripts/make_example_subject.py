"""Assemble an AddBiomechanics subject folder for an example that is not one in shared/data.

    python scripts/make_example_subject.py camargo2021_levelground OUT_DIR

The trial files and the model stay in ../shared (they are linked, not copied); the
folder gets the example's marker mapping (examples/<name>/markers.yaml) and a
``_subject.json``. Used by the tests and by the benchmark of the dynamics stage.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"

EXAMPLES = {
    # Camargo et al. 2021 publish no body mass with this trial; 74 kg is the mean vertical
    # ground reaction force over the frames where every step is on a plate, divided by g
    # (tests/io check it); the dynamics stage fits the mass anyway.
    "camargo2021_levelground": {
        "model": SHARED / "models" / "Rajagopal2015_passiveCal_hipAbdMoved.osim",
        "trials": {"levelground": SHARED / "trials" / "camargo2021_levelground"},
        "subject": {"massKg": 74.0, "heightM": 1.75, "sex": "unknown", "footBodyNames": ["calcn_r", "calcn_l"]},
    },
}


def make_subject(name: str, out: Path) -> Path:
    """Create (or replace) the subject folder ``out`` for example ``name``."""
    spec = EXAMPLES[name]
    if out.exists():
        shutil.rmtree(out)
    (out / "trials").mkdir(parents=True)
    (out / "unscaled_generic.osim").symlink_to(spec["model"])
    shutil.copy(REPO / "examples" / name / "markers.yaml", out / "markers.yaml")
    (out / "_subject.json").write_text(json.dumps(spec["subject"], indent=2) + "\n")
    for trial, folder in spec["trials"].items():
        (out / "trials" / trial).mkdir()
        for f in ("markers.trc", "grf.mot"):
            if (folder / f).exists():
                (out / "trials" / trial / f).symlink_to(folder / f)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("example", choices=sorted(EXAMPLES))
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    print(make_subject(args.example, args.out))


if __name__ == "__main__":
    main()
