"""Bad input that does not yet get the clear error the project promises (found by the input
audit of 2026-12-02, docs/audits/2026-12-02-inputs.md): each test states the error a user
should get, and is a strict expected failure until the reader gives it, so the fix turns it
into a pass (and a stale mark into a failure).

The fixes belong in modules every measured figure reads (solver/model/osim.py,
solver/io/c3d_layout.py, solver/io/trc.py), so they wait for the next batch of solver
changes, whose figures are all made again anyway.
"""

from __future__ import annotations

import struct
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from solver.errors import C3dFormatError, TrcFormatError
from solver.io.c3d import read_c3d
from solver.io.c3d_layout import check_c3d
from solver.io.trc import read_trc
from tests.conftest import SHARED_DATA

WALK_C3D = SHARED_DATA / "trials" / "opensim_c3d" / "walking2.c3d"
RUN_TRC = SHARED_DATA / "subjects" / "rajagopal2016_run" / "trials" / "run" / "markers.trc"
MODEL = SHARED_DATA / "models" / "Rajagopal2016.osim"
REPO = Path(__file__).resolve().parents[2]


def _c3d_with_float(path: Path, group: str, name: str, value: float, header_rate: float | None = None) -> Path:
    """walking2.c3d with the first value of parameter ``group:name`` set to ``value`` (and
    the header's frame rate, bytes 20-23, to ``header_rate``), written to ``path``."""
    param = check_c3d(WALK_C3D).get(group, name)
    data = bytearray(WALK_C3D.read_bytes())
    at = param.offset + 2 + len(name) + 2 + 2 + len(param.dims)  # the record's first value
    data[at : at + 4] = struct.pack("<f", value)
    if header_rate is not None:
        data[20:24] = struct.pack("<f", header_rate)
    path.write_bytes(bytes(data))
    return path


def _refused_c3d(bad: Path, match: str) -> None:
    """``read_c3d(bad)`` raises a C3dFormatError matching ``match`` that names ``bad``."""
    with warnings.catch_warnings(), pytest.raises(C3dFormatError, match=match) as err:
        warnings.simplefilter("ignore")
        read_c3d(bad)
    assert err.value.path == str(bad)


@pytest.mark.xfail(strict=True, raises=subprocess.TimeoutExpired,
                   reason="audit 2026-12-02 finding 1: solver/model/osim.py _sort_joints revisits a joint whose child "
                          "frame is ground and never ends (memory grows without bound)")
def test_a_joint_whose_child_is_ground_is_refused(tmp_path: Path) -> None:
    """A joint whose child frame is ground: an OsimModelError naming the joint, in a fresh
    interpreter (the reader hangs today; the test gives it 20 s)."""
    text = MODEL.read_text()
    old = "<socket_child_frame>pelvis_offset</socket_child_frame>"
    assert old in text
    model = tmp_path / "child_ground.osim"
    model.write_text(text.replace(old, "<socket_child_frame>ground_offset</socket_child_frame>", 1))
    code = ("import sys\nfrom solver.errors import OsimModelError\nfrom solver.model.osim import read_osim\n"
            "try:\n    read_osim(sys.argv[1])\nexcept OsimModelError as err:\n    print(err)\n")
    done = subprocess.run([sys.executable, "-c", code, str(model)], cwd=REPO, capture_output=True, text=True, timeout=20, check=False)
    assert done.returncode == 0 and "ground_pelvis" in done.stdout and str(model) in done.stdout, done.stderr[-2000:]


@pytest.mark.xfail(strict=True, raises=pytest.fail.Exception, reason="audit 2026-12-02 finding 4: solver/io/c3d_layout.py does not check the frame "
                                       "rate; a rate of 0 gives NaN and infinite frame times")
def test_a_c3d_frame_rate_of_zero_is_refused(tmp_path: Path) -> None:
    """POINT:RATE and the header's rate 0: a C3dFormatError naming the file and the rate."""
    _refused_c3d(_c3d_with_float(tmp_path / "rate0.c3d", "POINT", "RATE", 0.0, header_rate=0.0), "RATE")


@pytest.mark.xfail(strict=True, raises=pytest.fail.Exception, reason="audit 2026-12-02 finding 5: solver/io/c3d_layout.py reads ANALOG:RATE without "
                                       "comparing it with the header's analog samples per frame; ezc3d then reads every "
                                       "marker and force with the wrong layout")
def test_an_analog_rate_that_disagrees_with_the_header_is_refused(tmp_path: Path) -> None:
    """ANALOG:RATE 1000 Hz where the header says 8 samples per frame at 250 Hz (2000 Hz): a
    C3dFormatError naming the file and ANALOG:RATE, not 168,895 N peak forces."""
    _refused_c3d(_c3d_with_float(tmp_path / "analog_rate.c3d", "ANALOG", "RATE", 1000.0), "ANALOG:RATE")


@pytest.mark.xfail(strict=True, raises=pytest.fail.Exception, reason="audit 2026-12-02 finding 6: solver/io/trc.py accepts a row of exactly the data "
                                       "width in a file whose rows end with a tab, so a row missing one value is read "
                                       "shifted by one axis")
def test_a_row_missing_a_value_in_a_file_whose_rows_end_with_a_tab_is_refused(tmp_path: Path) -> None:
    """The run's TRC (rows end with a tab) with one value removed from line 11: a
    TrcFormatError naming the file and line 11, not 41 markers shifted by one axis."""
    lines = RUN_TRC.read_text().split("\n")
    assert lines[10].endswith("\t")
    cells = lines[10].split("\t")
    del cells[5]  # marker 2's X
    lines[10] = "\t".join(cells)
    bad = tmp_path / "markers.trc"
    bad.write_text("\n".join(lines))
    with pytest.raises(TrcFormatError, match="found 127 cells") as err:
        read_trc(bad)
    assert err.value.line == 11 and err.value.path == str(bad)
