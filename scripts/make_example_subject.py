"""Assemble an AddBiomechanics subject folder for an example that is not one in shared/data.

    python scripts/make_example_subject.py camargo2021_levelground|stairdown|opensim_c3d_walking OUT_DIR

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
    # Stair descent over two plates set in the stairs (AddBiomechanics test data). No body
    # mass is published with it: 65 kg is the mean vertical ground reaction force over the
    # stride from the first plate's mid-stance to its second mid-stance (1.66-3.16 s, every
    # foot on a plate), divided by g; the height (used only to normalise moments) is the head
    # markers' height above the heel marker while the subject stands on the top step (1.58
    # m) plus 12 cm.
    "stairdown": {
        "model": SHARED / "models" / "Rajagopal2015_ViconPlugInGait.osim",
        "trials": {"stairdown": SHARED / "trials" / "stairdown"},
        "subject": {"massKg": 65.0, "heightM": 1.70, "sex": "unknown", "footBodyNames": ["calcn_r", "calcn_l"]},
    },
    # Two overground walks of one subject from opensim-core's test data (C3D, forces from
    # the file's two platforms). 66 kg: the mean vertical force from one plate's mid-stance
    # to the other's (every foot on a plate; each plate's unloaded reading, -14 and -19 N,
    # subtracted), divided by g, 65.6 and 66.3 kg in the two trials; height: the head
    # markers' highest point (1.73 m) plus 5 cm.
    "opensim_c3d_walking": {
        "model": SHARED / "models" / "Rajagopal2016.osim",
        "trials": {
            "walking2": SHARED / "trials" / "opensim_c3d" / "walking2.c3d",
            "walking5": SHARED / "trials" / "opensim_c3d" / "walking5.c3d",
        },
        "subject": {"massKg": 66.0, "heightM": 1.78, "sex": "unknown", "footBodyNames": ["calcn_r", "calcn_l"]},
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
    for trial, source in spec["trials"].items():
        (out / "trials" / trial).mkdir()
        if source.suffix.lower() == ".c3d":  # markers and forces in one file
            (out / "trials" / trial / "markers.c3d").symlink_to(source)
            continue
        for f in ("markers.trc", "grf.mot"):
            if (source / f).exists():
                (out / "trials" / trial / f).symlink_to(source / f)
    return out


def main() -> None:
    """The command line (the module docstring): assemble one example subject folder."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("example", choices=sorted(EXAMPLES))
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    print(make_subject(args.example, args.out))


if __name__ == "__main__":
    main()
