"""Random byte damage to TRC and MOT files: the readers either succeed or raise one of our
errors (an :class:`~solver.errors.AddbError`), never a bare numpy/Python exception."""

from __future__ import annotations

import re
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from solver.errors import AddbError
from solver.io.mot import read_coordinates, read_forces, read_table
from solver.io.trc import read_trc
from tests.conftest import SHARED_DATA as DATA

N_ROWS = 12


def _trimmed(rel: str, header_lines: int, count: re.Pattern[str], repl: str) -> bytes:
    """The header and the first rows of a shared file, with its row count fixed."""
    lines = (DATA / rel).read_bytes().split(b"\n")
    text = b"\n".join(lines[: header_lines + N_ROWS]) + b"\n"
    return count.sub(repl.encode(), text, count=1)


SEEDS: dict[str, bytes] = {
    # odd TRC: frames from 23, trailing tabs, mm
    "run.trc": _trimmed(
        "trials/rajagopal2016/motion_capture_run.trc", 6, re.compile(rb"100\t100\t510"),
        f"100\t100\t{N_ROWS}",
    ),
    # TRC in metres with nan cells (rows ~760 have them: keep the header, then those rows)
    "camargo.trc": b"\n".join(
        (DATA / "trials/camargo2021_levelground/markers.trc").read_bytes().split(b"\n")[:6]
        + (DATA / "trials/camargo2021_levelground/markers.trc").read_bytes().split(b"\n")[
            760 : 760 + N_ROWS
        ]
    ).replace(b"200\t200\t3067", f"200\t200\t{N_ROWS}".encode()),
    # MOT with datarows header, blank line, unnumbered + 1_ plates
    "stairdown.mot": _trimmed(
        "trials/stairdown/grf.mot", 7, re.compile(rb"datarows \d+"), f"datarows {N_ROWS}"
    ),
    # OpenSim 4 header, six plates with moments about plate origins
    "camargo.mot": _trimmed(
        "trials/camargo2021_levelground/grf.mot", 7, re.compile(rb"nRows=\d+"), f"nRows={N_ROWS}"
    ),
    # coordinates in degrees, CRLF
    "coords.mot": _trimmed(
        "expert_comparison/Expert1/walking1.mot", 11, re.compile(rb"nRows=\d+"), f"nRows={N_ROWS}"
    ),
}  # fmt: skip

READERS: dict[str, list[Callable[[Path], object]]] = {
    ".trc": [read_trc],
    ".mot": [read_table, read_forces, read_coordinates],
}


def test_seeds_are_valid() -> None:
    """Undamaged, every seed reads, so the fuzz below exercises damage, not bad seeds."""
    with tempfile.TemporaryDirectory() as tmp:
        for name, content in SEEDS.items():
            path = Path(tmp) / name
            path.write_bytes(content)
            if name.endswith(".trc"):
                assert read_trc(path).n_frames == N_ROWS
            elif name == "coords.mot":
                assert read_coordinates(path).time.shape == (N_ROWS,)
            else:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    assert read_forces(path).n_frames == N_ROWS


_edit = st.tuples(
    st.sampled_from(["flip", "delete", "insert", "truncate", "duplicate_line"]),
    st.floats(min_value=0.0, max_value=1.0, allow_nan=False),
    st.sampled_from([*b"\t\n\r -+.eE0159naN,;#=x", 0, 0xFF, 0xC3]),
)


def _damage(data: bytes, edits: list[tuple[str, float, int]]) -> bytes:
    buf = bytearray(data)
    for kind, where, byte in edits:
        if not buf:
            break
        i = min(int(where * len(buf)), len(buf) - 1)
        if kind == "flip":
            buf[i] = byte
        elif kind == "delete":
            del buf[i]
        elif kind == "insert":
            buf.insert(i, byte)
        elif kind == "truncate":
            del buf[i:]
        else:
            start = buf.rfind(b"\n", 0, i) + 1
            end = buf.find(b"\n", i)
            end = len(buf) if end < 0 else end + 1
            buf[start:start] = buf[start:end]
    return bytes(buf)


@pytest.mark.parametrize("name", sorted(SEEDS))
@settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(edits=st.lists(_edit, min_size=1, max_size=6))
def test_damaged_files_raise_only_our_errors(
    name: str, edits: list[tuple[str, float, int]]
) -> None:
    content = _damage(SEEDS[name], edits)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        path.write_bytes(content)
        for reader in READERS[path.suffix]:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # moment conversions
                try:
                    reader(path)
                except AddbError as exc:
                    assert str(path) in str(exc)  # every error names the file
