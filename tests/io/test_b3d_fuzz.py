"""Random byte damage to results.b3d: opening it and reading every frame either succeeds or
raises :class:`~solver.errors.B3dFormatError` (naming the file and a byte offset), never a
protobuf/numpy/struct exception."""

from __future__ import annotations

import struct
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from solver.errors import B3dFormatError
from solver.io.b3d import open_b3d
from tests.conftest import SHARED_DATA

B3D = SHARED_DATA / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's


ORIGINAL = B3D.read_bytes()
_N = struct.unpack("<q", ORIGINAL[:8])[0]
DATA_START = 8 + _N
#: where the embedded model text ends: after it come the rest of the header (trial headers)
TEXT_END = ORIGINAL.find(b"</OpenSimDocument>") + len(b"</OpenSimDocument>")

#: byte ranges that matter: the length prefix, the start of the header (counts, sizes),
#: the header after the model text (trial headers, marker names), the frames, anywhere.
REGIONS = [(0, 8), (8, 64), (TEXT_END, DATA_START), (DATA_START, len(ORIGINAL)), (0, len(ORIGINAL))]


@st.composite
def damaged(draw: st.DrawFn) -> bytes:
    data = bytearray(ORIGINAL)
    kind = draw(st.sampled_from(["flip", "bytes", "truncate", "insert"]))
    lo, hi = draw(st.sampled_from(REGIONS))
    pos = draw(st.integers(lo, hi - 1))
    if kind == "flip":
        for _ in range(draw(st.integers(1, 4))):
            p = draw(st.integers(lo, hi - 1))
            data[p] ^= 1 << draw(st.integers(0, 7))
    elif kind == "bytes":
        new = draw(st.binary(min_size=1, max_size=16))
        data[pos:pos + len(new)] = new
    elif kind == "truncate":
        del data[pos:]
    else:
        data[pos:pos] = draw(st.binary(min_size=1, max_size=16))
    return bytes(data)


def _read_everything(path: Path) -> None:
    b3d = open_b3d(path)
    for k, trial in enumerate(b3d.header.trials):
        b3d.read_frames(k, 0, trial.n_frames)
    for j in range(len(b3d.header.passes)):
        b3d.model_text(j)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=damaged())
def test_damage_gives_only_our_error(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "damaged.b3d"
        path.write_bytes(data)
        try:
            _read_everything(path)
        except B3dFormatError as exc:
            assert str(path) in str(exc)
            assert exc.offset is None or 0 <= exc.offset <= len(data)


def test_known_damage_messages(tmp_path: Path) -> None:
    """Hand-made damage: each gives our error naming the offset and what was expected."""
    cases = {
        "empty": b"",
        "short prefix": ORIGINAL[:5],
        "huge header length": struct.pack("<q", 10**12) + ORIGINAL[8:],
        "truncated frames": ORIGINAL[:-100],
        "extra bytes": ORIGINAL + b"\0" * 7,
    }
    offsets = {}
    for name, data in cases.items():
        p = tmp_path / f"{name.replace(' ', '_')}.b3d"
        p.write_bytes(data)
        with pytest.raises(B3dFormatError) as info:
            _read_everything(p)
        assert str(p) in str(info.value) and "byte" in str(info.value)
        offsets[name] = info.value.offset
    assert offsets["empty"] == 0 and offsets["huge header length"] == 0
    assert offsets["truncated frames"] == len(ORIGINAL) - 100


def test_unknown_version(tmp_path: Path) -> None:
    from solver.io import b3d_schema

    header = b3d_schema.Header.FromString(ORIGINAL[8:DATA_START])
    header.version = 99
    raw = header.SerializeToString()
    p = tmp_path / "v99.b3d"
    p.write_bytes(struct.pack("<q", len(raw)) + raw + ORIGINAL[DATA_START:])
    with pytest.raises(B3dFormatError, match="version 99 is not supported"):
        open_b3d(p)


def test_damaged_frame_names_its_offset(tmp_path: Path) -> None:
    """A sensor frame whose first field length is broken: the error gives that frame's offset."""
    b3d = open_b3d(B3D)
    off = b3d.frame_offset(1, 7)
    data = bytearray(ORIGINAL)
    data[off + 1] = 0xFF  # the varint length of marker_obs now runs past the frame
    data[off + 2] = 0x7F
    p = tmp_path / "frame.b3d"
    p.write_bytes(bytes(data))
    damaged_file = open_b3d(p)
    damaged_file.read_frames(1, 0, 7)  # frames before it still read
    with pytest.raises(B3dFormatError) as info:
        damaged_file.read_frames(1, 0, 20)
    assert info.value.offset == off
    assert "frame 7" in str(info.value)


def test_a_file_that_is_not_a_b3d_is_named_as_such(tmp_path: Path) -> None:
    """A TRC (text) given where a .b3d is expected, as ``addb convert`` may be: the message
    says what the file looks like (a suffix, text, a binary file without the suffix); a
    damaged .b3d (binary, .b3d suffix) gets no such hint."""
    trc = B3D.parents[1] / "subjects" / "rajagopal2016_walk" / "trials" / "walk" / "markers.trc"
    with pytest.raises(B3dFormatError, match=r"this looks like a \.trc file, not an AddBiomechanics \.b3d"):
        open_b3d(trc)
    text = tmp_path / "notes.b3d"
    text.write_text("subject 01 notes\n")
    with pytest.raises(B3dFormatError, match=r"this looks like text, not an AddBiomechanics \.b3d"):
        open_b3d(text)
    binary = tmp_path / "capture"
    binary.write_bytes(struct.pack("<q", 10**12) + ORIGINAL[8:])
    with pytest.raises(B3dFormatError, match=r"this looks like a binary file without the \.b3d suffix"):
        open_b3d(binary)
    damaged = tmp_path / "damaged.b3d"
    damaged.write_bytes(struct.pack("<q", 10**12) + ORIGINAL[8:])
    with pytest.raises(B3dFormatError) as info:
        open_b3d(damaged)
    assert "looks like" not in str(info.value)
