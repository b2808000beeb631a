"""Damaged C3D files: the reader raises our own error, never dies of a signal inside ezc3d.

ezc3d trusts the counts and offsets in a file; a damaged byte can make it crash the whole
process (a segmentation fault), which pytest cannot catch. So every read of a damaged file
here happens in a child process: one child reads a batch of damaged files (start-up is
paid once per batch) and reports per file; a file after which the child died of a signal
is named with the damage that produced it.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from solver.io.c3d_layout import _dec_floats, check_c3d
from tests.conftest import SHARED_DATA as DATA

ROOT = Path(__file__).resolve().parents[2]
TRIALS = DATA / "trials" / "opensim_c3d"
SOURCES = {name: (TRIALS / name).read_bytes() for name in ("walking2.c3d", "walking5.c3d")}
PARAMETER_END = 13 * 512  # header block + 12 parameter blocks in both files; data after

# The child: reads every path given on the command line with read_c3d and summarize and
# prints one JSON line per file, flushed before the next file, so a crash points at the
# file being read; a file that takes over 15 s (a normal read takes well under 1 s) ends
# the child with SIGALRM, reported like any other signal.
CHILD = r"""
import json, signal, sys, warnings
warnings.simplefilter("ignore")
signal.signal(signal.SIGALRM, signal.SIG_DFL)  # an alarm ends the process, even inside C++
from solver.errors import AddbError
from solver.io.c3d import read_c3d
from solver.io.summary import summarize
for index, path in enumerate(sys.argv[1:]):
    print(json.dumps({"index": index, "state": "start"}), flush=True)
    signal.alarm(PER_FILE_S)  # a file that hangs the reader: SIGALRM, reported for it
    result = {"index": index, "state": "ok"}
    for reader in (read_c3d, summarize):
        try:
            reader(path)
        except AddbError as exc:
            result = {"index": index, "state": "addb", "error": str(exc)}
        except BaseException as exc:  # noqa: BLE001 - reported to the parent
            result = {"index": index, "state": "other", "error": repr(exc)}
            break
    print(json.dumps(result), flush=True)
signal.alarm(0)
""".replace("PER_FILE_S", "15")


CHILD_MEMORY = 4 << 30  # bytes of address space: a normal read needs far less


def _limit_memory() -> None:
    """In the child before it starts: without the check, ezc3d allocates for the counts
    a damaged file announces (11 GB seen); limited, that is a MemoryError or an abort
    the test reports, not a machine out of memory."""
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY, CHILD_MEMORY))


def read_in_child(
    paths: list[Path], per_file_s: float = 3.0, child: str = CHILD
) -> list[dict[str, object]]:
    """Read ``paths`` in child processes (running ``child``); one result per path, in order.

    A child that dies of a signal gives ``{"state": "signal", "signal": n}`` for the file
    it was reading; one that takes longer than ``30 + per_file_s`` seconds per remaining
    file is killed and gives ``{"state": "timeout"}`` for the file it was reading (ezc3d
    can also loop for minutes on a damaged file). A new child continues with the next file.
    """
    results: list[dict[str, object]] = []
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    while len(results) < len(paths):
        rest = paths[len(results) :]
        with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
            try:
                proc = subprocess.run(
                    [sys.executable, "-c", child, *map(str, rest)],
                    check=False,
                    stdout=out,
                    stderr=err,
                    text=True,
                    cwd=ROOT,
                    env=env,
                    timeout=30 + per_file_s * len(rest),
                    preexec_fn=_limit_memory,
                )
                returncode: int | None = proc.returncode
            except subprocess.TimeoutExpired:  # run() has killed the child
                returncode = None
            out.seek(0)
            err.seek(0)
            lines, stderr = out.read().splitlines(), err.read()[-2000:]
        done = [json.loads(line) for line in lines if line.startswith("{")]
        finished = [r for r in done if r["state"] != "start"]
        results.extend(finished)
        if returncode is not None and len(finished) == len(rest):
            assert returncode == 0, stderr
            break
        if returncode is None:
            stopped: dict[str, object] = {"state": "timeout", "stderr": stderr}
        else:
            stopped = {
                "state": "signal" if returncode < 0 else "exit",
                "signal": -returncode,
                "returncode": returncode,
                "stderr": stderr,
            }
        results.append(stopped)  # the file after the last finished one
    return results


def damage(data: bytes, edits: list[tuple[str, int, int]]) -> bytes:
    """Apply ``(kind, position, byte)`` edits: set a byte, delete, insert or truncate."""
    buf = bytearray(data)
    for kind, where, byte in edits:
        if not buf:
            break
        i = where % len(buf)
        if kind == "set":
            buf[i] = byte
        elif kind == "delete":
            del buf[i]
        elif kind == "insert":
            buf.insert(i, byte)
        else:
            del buf[i:]
    return bytes(buf)


# ----------------------------------------------------------------------------- the issue


def test_the_issue_two_bytes_give_our_error_naming_the_parameter_section(
    tmp_path: Path,
) -> None:
    """Bytes 689-690 (from 1) of walking2.c3d, 0x00 0x01 -> 0xB6 0xFB: SUBJECTS:USED then
    announces -74 dimensions (a signed byte), ezc3d keeps no dimension and reads the first
    of an empty list: a segmentation fault before the check existed."""
    data = bytearray(SOURCES["walking2.c3d"])
    assert data[688:690] == b"\x00\x01"
    data[688:690] = b"\xb6\xfb"
    path = tmp_path / "walking2_damaged.c3d"
    path.write_bytes(bytes(data))
    (result,) = read_in_child([path])
    assert result["state"] == "addb", result
    message = str(result["error"])
    assert message.startswith("C3dFormatError")
    assert str(path) in message
    assert "parameter section: SUBJECTS:USED" in message
    assert "byte offset 688" in message and "number of dimensions -74" in message


def test_undamaged_files_read_in_the_child() -> None:
    """The child itself works: both real files read without error."""
    results = read_in_child([TRIALS / name for name in SOURCES])
    assert [r["state"] for r in results] == ["ok", "ok"]


def test_the_harness_reports_a_signal_death_and_goes_on(tmp_path: Path) -> None:
    """Without the check, ezc3d itself dies on the issue's file (so the fuzz below can
    see a regression): the child reports a signal for that file and a new child reads
    the next one."""
    data = bytearray(SOURCES["walking2.c3d"])
    data[688:690] = b"\xb6\xfb"
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(bytes(data))
    raw = CHILD.replace(
        "for reader in (read_c3d, summarize):",
        "import ezc3d\n    for reader in (ezc3d.c3d,):",
    )
    results = read_in_child([bad, TRIALS / "walking5.c3d"], child=raw)
    assert [r["state"] for r in results] == ["signal", "ok"], results


def test_check_reads_the_layout_of_the_real_files() -> None:
    """The pure-Python walk agrees with the files' own counts (and with ezc3d's reading,
    which tests/io/test_io_c3d.py checks): 250 Hz markers, 2000 Hz analogs, two plates."""
    w2, w5 = (check_c3d(TRIALS / name) for name in ("walking2.c3d", "walking5.c3d"))
    for layout, points, frames in ((w2, 44, 1249), (w5, 40, 1103)):
        assert layout.processor == "Intel" and layout.float_storage
        assert (layout.n_points, layout.n_frames) == (points, frames)
        assert (layout.n_analog_values, layout.analog_per_frame) == (96, 8)  # 12 channels
        assert layout.data_offset == 13 * 512
        assert layout.frame_bytes == (points * 4 + 96) * 4
        assert layout.get("POINT", "FRAMES").values == (frames,)
        assert layout.get("POINT", "RATE").values == (250.0,)
        assert layout.get("ANALOG", "RATE").values == (2000.0,)
        assert layout.get("FORCE_PLATFORM", "CHANNEL").dims == (6, 2)
        assert layout.get("FORCE_PLATFORM", "CORNERS").dims == (3, 4, 2)
        assert len(layout.get("POINT", "LABELS").values) == points
    assert w2.get("SUBJECTS", "USED").offset == 679  # the record the issue's bytes are in


def test_dec_floats_are_decoded() -> None:
    """DEC (VAX F) floats: 16-bit words swapped and exponent bias 128 (value / 4 after the
    swap): 1.0 is stored 0x80 0x40 0x00 0x00, -0.01 (a typical scale) 0x23 0xBD 0x0A 0xD7."""
    assert _dec_floats(bytes([0x80, 0x40, 0, 0])) == [1.0]
    (scale,) = _dec_floats(bytes([0x23, 0xBD, 0x0A, 0xD7]))
    assert abs(scale - -0.01) < 1e-9


# Damage found by fuzzing: each crashed ezc3d 1.7.2 with a segmentation fault (or, for the
# screen axes, raised a bare ValueError in our reader) before the check; (file, edits,
# expected ``where``, expected text in the message).
FOUND = [
    ("walking5.c3d", [("set", 4300, 0)], "parameter section", "ANALOG:SCALE is missing"),
    ("walking5.c3d", [("set", 4408, 182)], "parameter section: ANALOG:OFFSET",
     "number of dimensions -74"),
    ("walking5.c3d", [("set", 6133, 255), ("set", 5953, 166), ("set", 3701, 128)],
     "parameter section: group LABELS", "description length -1"),
    ("walking5.c3d", [("delete", 7143, 127), ("set", 4753, 255), ("set", 4166, 215)],
     "parameter section: group DESCRIPTIONS", "description length -1"),
    ("walking2.c3d", [("truncate", 2982, 172), ("set", 3918, 255), ("set", 1278083, 128),
                      ("insert", 1706, 128)], "parameter section",
     "12 parameter blocks from byte 512 (to byte 6656); the file has 2983 bytes"),
    ("walking2.c3d", [("set", 728, 128)], "parameter section: SUBJECTS:USES_PREFIXES",
     "number of dimensions -128"),
    ("walking2.c3d", [("set", 966, 1)], "parameter section: POINT:X_SCREEN",
     "data type byte; expected char"),
    ("walking2.c3d", [("set", 984, 1)], "parameter section: POINT:Y_SCREEN",
     "data type byte; expected char"),
]  # fmt: skip


def test_damage_found_by_fuzzing_gives_our_error(tmp_path: Path) -> None:
    paths = []
    for k, (name, edits, _, _) in enumerate(FOUND):
        path = tmp_path / f"{k}_{name}"
        path.write_bytes(damage(SOURCES[name], edits))
        paths.append(path)
    results = read_in_child(paths)
    for path, (_, edits, where, text), result in zip(paths, FOUND, results, strict=True):
        assert result["state"] == "addb", (edits, result)
        assert f"({path}, {where})" in str(result["error"]), (edits, result)
        assert text in str(result["error"]), (edits, result)


# ----------------------------------------------------------------------------- fuzz

_edit = st.tuples(
    st.sampled_from(["set", "set", "set", "delete", "insert", "truncate"]),
    st.one_of(  # mostly in the header and parameter section, where ezc3d trusts counts
        st.integers(min_value=0, max_value=PARAMETER_END - 1),
        st.integers(min_value=0, max_value=len(SOURCES["walking5.c3d"]) - 1),
    ),
    st.one_of(st.sampled_from([0x00, 0x01, 0x7F, 0x80, 0xFF, 0xB6]), st.integers(0, 255)),
)
_file_damage = st.tuples(st.sampled_from(sorted(SOURCES)), st.lists(_edit, min_size=1, max_size=4))
BATCH = 40


@settings(
    max_examples=6,
    deadline=None,
    derandomize=True,
    # no shrinking: the assertion already names the one damaged file and its edits, and
    # shrinking a batch would rerun children for many minutes
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(batch=st.lists(_file_damage, min_size=BATCH, max_size=BATCH))
def test_damaged_c3d_files_give_only_our_errors(
    batch: list[tuple[str, list[tuple[str, int, int]]]],
) -> None:
    """Random byte changes, deletions, insertions and truncations of walking2/walking5:
    each read either succeeds or raises an AddbError subclass naming the file; no child
    dies of a signal and no other exception escapes."""
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for k, (name, edits) in enumerate(batch):
            path = Path(tmp) / f"{k:03d}_{name}"
            path.write_bytes(damage(SOURCES[name], edits))
            paths.append(path)
        results = read_in_child(paths)
    for (name, edits), result in zip(batch, results, strict=True):
        where = f"{name} damaged by {edits}"
        assert result["state"] in ("ok", "addb"), f"{where}: {result}"
        if result["state"] == "addb":
            assert "Error (" in str(result["error"]) and name in str(result["error"]), where
