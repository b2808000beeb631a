"""A real effect found from the motion alone: the zero drift of opensim-core's C3D plates.

The force platforms of ``walking2.c3d`` (``scripts/make_example_subject.py
opensim_c3d_walking``) read about -14 N (plate 1) and -20 N (plate 2) vertically when
nothing stands on them. ``addb diagnose`` first names the steps off the plates
(``unmeasured_force``); once they are applied (``--apply``), the next diagnosis must name
plate 2's offset, and its vertical estimate must match what the plate reads unloaded,
which the diagnosis never looks at (it sees the loaded frames through the motion).

Until 2026-11-22 the second round named nothing: the applied frames were padded a second
time (3 frames each side), and that small ``unmeasured_force`` candidate stood in the way.

Since 2026-11-25 the trial's kinematics start at its best-observed frame (the subject
walks into the volume: the first frames see one to a few markers;
tests/kinematics/test_ik_entry.py). The first round then leaves 21 of those entry frames
(0.88-1.08 s, seeing 1-5 markers) out of its steps off the plates, and the second names
them; the third names plate 2's offset, with the same estimate to 1e-9 N as the second
round did before. So the steps off the plates are applied until another cause is named
(at most three rounds).

Which motion the offset is named on depends on round-off: on 2026-11-27, on an AMD EPYC
host whose OpenBLAS ran its AVX-512 kernels, the code that had passed here the day before
(a9d2af6) named it through the marker-only comparison (it removes 27 % of its channels'
held-out cost there, 66.5 % on the fitted motion); with ``OPENBLAS_CORETYPE=Haswell`` the
same code names it on the fitted motion (66.5 %), as before. The test asserts the 30 % on
the fitted motion's evaluation of the named plate, which both paths report, and the
diagnosis' own 10 % rule on the reported one; the choice and the estimate are asserted as
before.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from solver.diagnose.selection import ChoiceRule
from solver.io.c3d import read_c3d
from tests.conftest import SHARED_DATA
from tests.diagnose.harness import diagnose_json

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
C3D = SHARED_DATA / "trials" / "opensim_c3d" / "walking2.c3d"


def _unloaded_vertical(plate: str) -> float:
    """Median vertical reading of a plate while it carries less than 20 N, N."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _, forces = read_c3d(C3D)
    fy = next(p for p in forces.plates if p.name == plate).force[:, 1]
    return float(np.median(fy[np.abs(fy) < 20.0]))


def test_second_round_names_the_plates_zero_drift(tmp_path: Path) -> None:
    subject = tmp_path / "c3d"
    subprocess.run([sys.executable, "scripts/make_example_subject.py", "opensim_c3d_walking", str(subject)], check=True, cwd=REPO, capture_output=True)
    shutil.rmtree(subject / "trials" / "walking5")  # one trial keeps the test short

    first = diagnose_json(subject, "walking2", "--apply")
    assert first["chosen"] == "unmeasured_force"
    shutil.rmtree(subject / "addb_out")

    for _ in range(2):  # the steps off the plates, until another cause is named
        second = diagnose_json(subject, "walking2", "--apply")
        shutil.rmtree(subject / "addb_out")
        if second["chosen"] != "unmeasured_force":
            break
    assert second["chosen"] == "plate_force_offset", second["reason"]
    plate = second["chosen_parameters"]["plate"]
    fy = second["chosen_parameters"]["offset_N"][1]
    assert fy == pytest.approx(_unloaded_vertical(plate), abs=1.5)
    chosen = next(c for c in second["candidates"] if c["cause"] == "plate_force_offset")
    # the named plate's evaluation on the fitted motion (the candidates' alternatives are
    # the fitted motion's), whichever motion the choice was made on: share of its channels'
    # held-out cost that it removes
    fitted = next(a for a in chosen["alternatives"] if a["choice"] == chosen["choice"])
    assert fitted["gain"] > 0.3
    # the reported evaluation clears the choice rule's own minimum for the cause (10 %)
    assert chosen["gain"] >= ChoiceRule().relative_gain_needed("plate_force_offset"), chosen
