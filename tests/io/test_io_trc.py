"""TRC reader and writer: every shared TRC file, the odd headers, broken copies, round trips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.errors import TrcFormatError
from solver.io.trc import read_trc, write_trc
from solver.io.types import MarkerTrajectories
from tests.conftest import OPENSIM_REASON, import_tool
from tests.conftest import SHARED_DATA as DATA
from tests.io.damage import damaged, expect_format_error

TRC_FILES = sorted(DATA.rglob("*.trc"))
PELVIS_WORDS = ("asi", "psi", "sacr")


def _raw_header(path: Path) -> dict[str, str]:
    """Header keys/values read the naive way, independent of the reader."""
    lines = path.read_text(encoding="latin-1").splitlines()
    return dict(zip(lines[1].split(), lines[2].split(), strict=True))


def _first_row_tokens(path: Path) -> list[str]:
    """The first data row split on tabs (first line after line 4 that starts with a digit)."""
    for line in path.read_text(encoding="latin-1").splitlines()[4:]:
        if line.strip()[:1].isdigit():
            return line.rstrip("\r").split("\t")
    raise AssertionError("no data row")


def test_shared_data_has_trc_files() -> None:
    assert len(TRC_FILES) >= 40, "the shared data folder moved or lost its TRC files"


@pytest.mark.parametrize("path", TRC_FILES, ids=lambda p: str(p.relative_to(DATA)))
def test_every_shared_trc_reads_in_metres_at_the_header_rate(path: Path) -> None:
    m = read_trc(path)
    header = _raw_header(path)
    assert m.positions.shape == (int(header["NumFrames"]), int(header["NumMarkers"]), 3)
    assert m.rate_hz == float(header["DataRate"])
    # the Time column agrees with DataRate (1 us tolerance: files print 5-8 decimals)
    np.testing.assert_allclose(np.diff(m.time), 1.0 / m.rate_hz, atol=1e-6)
    # units converted: pelvis markers of a person sit 0.5-1.45 m above the floor
    pelvis = [n for n in m.names if any(w in n.lower() for w in PELVIS_WORDS)]
    assert pelvis, "every shared trial has pelvis markers"
    height = np.nanmedian(np.stack([m.marker(n)[:, 1] for n in pelvis]))
    assert 0.5 < height < 1.45
    assert np.nanmax(m.positions[:, :, 1]) < 2.5  # nothing above 2.5 m
    # the first value equals the file's text divided by the unit (independent parse)
    scale = {"mm": 1e-3, "m": 1.0}[header["Units"].strip()]
    first = next(t for t in _first_row_tokens(path)[2:] if t.strip())
    assert m.positions[0, 0, 0] == pytest.approx(float(first) * scale, rel=1e-15)


def test_walking_pelvis_is_about_one_metre_high(shared_data: Path) -> None:
    m = read_trc(shared_data / "trials/rajagopal2016/motion_capture_walk.trc")
    assert 0.9 < np.median(m.marker("R.ASIS")[:, 1]) < 1.1


# ----------------------------------------------------------------------------- odd files


def test_padded_header_values_with_double_tabs(shared_data: Path) -> None:
    path = shared_data / "trials/rajagopal2016/motion_capture_walk.trc"
    assert "  100.0\t\t  100.0\t\t    238" in path.read_text()  # the oddity is there
    m = read_trc(path)
    assert (m.n_frames, len(m.names), m.rate_hz) == (238, 41, 100.0)
    assert m.names[:2] == ("R.Shoulder", "L.Shoulder")


def test_frame_numbers_not_starting_at_one_and_trailing_tabs(shared_data: Path) -> None:
    path = shared_data / "trials/rajagopal2016/motion_capture_run.trc"
    first = _first_row_tokens(path)
    assert first[0] == "23" and first[-1] == ""  # starts at frame 23, trailing tab
    m = read_trc(path)
    assert m.time[0] == pytest.approx(0.23)
    assert m.n_frames == 510
    assert not np.isnan(m.positions).any()  # the trailing empty cell is not a marker


def test_space_padded_units_and_header_trailing_tabs(shared_data: Path) -> None:
    path = shared_data / "trials/rajagopal2016/static_run.trc"
    assert "\t     mm\t" in path.read_text()
    m = read_trc(path)
    assert len(m.names) == 64
    assert 0.9 < np.median(m.marker("LASI")[:, 1]) < 1.2  # mm converted


def test_two_tab_name_separation_and_times_label(shared_data: Path) -> None:
    path = shared_data / "trials/stairdown/markers.trc"
    assert "Frame#\tTimes\t\tLFHD\t\tLBHD" in path.read_text()
    m = read_trc(path)
    assert len(m.names) == 61 and m.names[:2] == ("LFHD", "LBHD")
    assert 1.4 < np.median(m.marker("LFHD")[:, 1]) < 2.4  # head, metres, on stairs


def test_missing_axis_line_and_crlf(shared_data: Path) -> None:
    path = shared_data / "trials/initial_off_treadmill/markers.trc"
    raw = path.read_bytes()
    assert b"\r\n" in raw and b"X1\tY1" not in raw
    m = read_trc(path)
    assert (m.n_frames, len(m.names)) == (2000, 47)
    assert m.time[0] == 0.0


def test_nan_cells_become_nan(shared_data: Path) -> None:
    path = shared_data / "trials/camargo2021_levelground/markers.trc"
    tokens = "\t".join(path.read_text().splitlines()[6:]).split("\t")
    n_nan_tokens = sum(t.strip().lower() == "nan" for t in tokens)
    assert n_nan_tokens > 0
    m = read_trc(path)
    assert int(np.isnan(m.positions).sum()) == n_nan_tokens
    assert m.rate_hz == 200.0 and m.time[0] == 0.005


def test_gaps_exported_as_zeros_become_missing(shared_data: Path) -> None:
    """The stair-descent file fills a head marker's gaps with 0 0 0 (Vicon export): those
    frames are missing, every other frame keeps the file's values."""
    path = shared_data / "trials/stairdown/markers.trc"
    lines = path.read_text().splitlines()
    names = lines[3].split("\t")[2:]
    column = 2 + 3 * [n for n in names if n].index("RFHD")
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    zero_rows = [i for i, r in enumerate(rows) if all(float(v) == 0.0 for v in r[column : column + 3])]
    assert len(zero_rows) > 0
    m = read_trc(path)
    rfhd = m.marker("RFHD")
    assert sorted(np.flatnonzero(np.isnan(rfhd).all(axis=1)).tolist()) == zero_rows
    kept = [i for i in range(len(rows)) if i not in set(zero_rows)]
    expected = np.array([[float(v) for v in rows[i][column : column + 3]] for i in kept])
    np.testing.assert_allclose(rfhd[kept], expected, rtol=0, atol=1e-12)
    assert not np.isnan(np.delete(m.positions, m.names.index("RFHD"), axis=1)).any()


def test_blank_line_before_data_and_trailing_tab_in_expert_files(shared_data: Path) -> None:
    path = shared_data / "expert_comparison/Expert1/walking1.trc"
    assert path.read_text().splitlines()[5].strip() == ""
    m = read_trc(path)
    assert m.n_frames == 143 and not np.isnan(m.positions).any()


def test_empty_cells_are_missing_markers(tmp_path: Path) -> None:
    text = (
        "PathFileType\t4\t(X/Y/Z)\tx.trc\n"
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
        "10\t10\t2\t2\tmm\n"
        "Frame#\tTime\tA\t\t\tB\n"
        "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
        "1\t0.0\t1\t2\t3\t\t\t\n"
        "2\t0.1\t\t\t\t4\t5\t6\n"
    )
    path = tmp_path / "gaps.trc"
    path.write_text(text)
    m = read_trc(path)
    np.testing.assert_array_equal(m.positions[0, 0], [0.001, 0.002, 0.003])
    assert np.isnan(m.positions[0, 1]).all() and np.isnan(m.positions[1, 0]).all()
    np.testing.assert_array_equal(m.positions[1, 1], [0.004, 0.005, 0.006])


def test_space_separated_file_in_centimetres(tmp_path: Path) -> None:
    text = (
        "PathFileType 4 (X/Y/Z) x.trc\n"
        "DataRate CameraRate NumFrames NumMarkers Units\n"
        "50 50 2 1 cm\n"
        "Frame# Time A\n"
        "X1 Y1 Z1\n"
        "\n"
        "1 0.00 10 100 -5\n"
        "2 0.02 11 101 -6\n"
    )
    path = tmp_path / "cm.trc"
    path.write_text(text)
    m = read_trc(path)
    np.testing.assert_array_equal(m.positions[:, 0, 1], [1.0, 1.01])
    assert m.rate_hz == 50.0


# ----------------------------------------------------------------------------- broken input


@pytest.fixture
def small_trc(shared_data: Path, tmp_path: Path) -> list[str]:
    """Lines of a real TRC (rajagopal walk, 238 frames, data from line 7)."""
    return (shared_data / "trials/rajagopal2016/motion_capture_walk.trc").read_text().splitlines()


def _damaged(tmp_path: Path, lines: list[str]) -> Path:
    return damaged(tmp_path, lines, ".trc")


def _expect(path: Path, line: int | None, *words: str) -> TrcFormatError:
    return expect_format_error(TrcFormatError, read_trc, path, line, *words)


def test_truncated_rows_report_frame_count(tmp_path: Path, small_trc: list[str]) -> None:
    path = _damaged(tmp_path, small_trc[:100])  # rows of lines 7..100
    _expect(path, 100, "NumFrames=238", "94 data rows", "truncated")


def test_truncated_inside_a_row(tmp_path: Path, small_trc: list[str]) -> None:
    lines = [*small_trc[:50], small_trc[50][:40]]
    _expect(_damaged(tmp_path, lines), 51, "expected 125 values", "found")


def test_wrong_column_count(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    lines[19] = lines[19] + "\t1.0\t2.0"
    _expect(_damaged(tmp_path, lines), 20, "expected 125 values", "found 127")


def test_text_in_a_number_field(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    cells = lines[29].split("\t")
    cells[7] = "12.3abc"
    lines[29] = "\t".join(cells)
    err = _expect(_damaged(tmp_path, lines), 30, "'12.3abc'")
    assert err.where == "column 8"


def test_text_in_the_time_column(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    cells = lines[9].split("\t")
    cells[1] = "t=0.3"
    lines[9] = "\t".join(cells)
    _expect(_damaged(tmp_path, lines), 10, "Time", "'t=0.3'")


def test_unknown_units(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    lines[2] = lines[2].replace(" mm", " inches")
    err = _expect(_damaged(tmp_path, lines), 3, "'inches'", "mm, cm or m")
    assert err.where == "Units"


def test_missing_header_key(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    lines[1] = lines[1].replace("DataRate", "Rate")
    _expect(_damaged(tmp_path, lines), 2, "'DataRate'")


def test_marker_count_differs_from_header(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    lines[3] = lines[3].replace("\tL.Toe\t\t\t", "")
    _expect(_damaged(tmp_path, lines), 4, "NumMarkers=41", "40 markers")


def test_duplicate_marker_names(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    lines[3] = lines[3].replace("L.Toe", "L.Heel")
    err = _expect(_damaged(tmp_path, lines), 4, "'L.Heel'", "twice")
    assert err.where == "L.Heel"


def test_time_going_backwards(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    cells = lines[40].split("\t")
    cells[1] = "0.1"
    lines[40] = "\t".join(cells)
    _expect(_damaged(tmp_path, lines), 41, "does not increase")


def test_a_repeated_time_is_named_in_seconds_as_the_file_writes_it(tmp_path: Path, small_trc: list[str]) -> None:
    """A frame written twice (a lab export's repeated row, NumFrames mended): the error names
    the line and the two times as plain numbers of seconds."""
    lines = list(small_trc)
    lines.insert(40, lines[39])
    lines[2] = lines[2].replace("238", "239")
    t = lines[39].split("\t")[1]
    err = _expect(_damaged(tmp_path, lines), 41, "does not increase")
    assert f"time {float(t)!r} s does not increase (previous row: {float(t)!r} s)" in str(err), str(err)


def test_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.trc"
    path.write_text("")
    _expect(path, 1, "empty")


def test_not_a_trc_file(tmp_path: Path) -> None:
    path = tmp_path / "notes.trc"
    path.write_text("hello\nworld\nthis is\nnot a trc\n")
    _expect(path, 1, "PathFileType")


def test_missing_file_is_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_trc(tmp_path / "nope.trc")


# ----------------------------------------------------------------------------- round trip


def _assert_same(a: MarkerTrajectories, b: MarkerTrajectories) -> None:
    assert a.names == b.names
    assert a.rate_hz == b.rate_hz
    np.testing.assert_array_equal(a.time, b.time)
    # bit-exact, NaN where NaN, and the same sign of zero
    np.testing.assert_array_equal(a.positions, b.positions)
    assert np.array_equal(np.signbit(a.positions), np.signbit(b.positions))


def _random_markers(
    rng: np.random.Generator, n_frames: int = 40, n_markers: int = 7
) -> MarkerTrajectories:
    scales = rng.choice([1e-7, 1e-3, 1.0, 1e3], size=(n_frames, n_markers, 3))
    pos = rng.normal(size=(n_frames, n_markers, 3)) * scales
    pos[rng.random(pos.shape[:2]) < 0.1] = np.nan  # missing markers, whole xyz
    pos[0, 0] = [0.0, -0.0, 5e-324]
    rate = float(rng.uniform(30, 500))
    # arbitrary float64 times, close enough to the rate not to trigger the rate warning
    time = (np.arange(n_frames) + rng.uniform(-1e-3, 1e-3, n_frames)) / rate + rng.uniform(0, 9)
    names = tuple(f"M{k} name.{k}" for k in range(n_markers))  # spaces and dots
    return MarkerTrajectories(names, pos, time, rate)


@pytest.mark.parametrize("units", ["mm", "cm", "m"])
@pytest.mark.parametrize("seed", range(5))
def test_random_markers_round_trip_exactly(tmp_path: Path, units: str, seed: int) -> None:
    markers = _random_markers(np.random.default_rng(seed))
    path = tmp_path / f"rt_{units}.trc"
    write_trc(path, markers, units=units)
    _assert_same(read_trc(path), markers)


@pytest.mark.parametrize(
    "rel", ["trials/camargo2021_levelground/markers.trc", "trials/rajagopal2016/static_run.trc"]
)
def test_real_markers_round_trip_exactly(shared_data: Path, tmp_path: Path, rel: str) -> None:
    markers = read_trc(shared_data / rel)
    path = tmp_path / "real.trc"
    write_trc(path, markers)
    _assert_same(read_trc(path), markers)


def test_written_millimetres_are_the_decimal_shift_of_metres(tmp_path: Path) -> None:
    markers = MarkerTrajectories(("A",), np.array([[[1.2345, 0.1, -0.0001]]]), np.zeros(1), 100.0)
    path = tmp_path / "mm.trc"
    write_trc(path, markers)
    assert path.read_text().splitlines()[-1] == "1\t0.0\t1234.5\t100\t-0.1"


def test_writer_rejects_names_trc_cannot_hold(tmp_path: Path) -> None:
    markers = MarkerTrajectories(("bad\tname",), np.zeros((1, 1, 3)), np.zeros(1), 100.0)
    with pytest.raises(TrcFormatError, match="cannot be written"):
        write_trc(tmp_path / "x.trc", markers)
    with pytest.raises(TrcFormatError, match="unknown units"):
        write_trc(tmp_path / "x.trc", _random_markers(np.random.default_rng(0)), units="in")


@pytest.mark.opensim
def test_opensim_reads_written_trc(shared_data: Path, tmp_path: Path) -> None:
    opensim = import_tool("opensim", reason=OPENSIM_REASON)
    markers = read_trc(shared_data / "trials/camargo2021_levelground/markers.trc")
    path = tmp_path / "for_opensim.trc"
    write_trc(path, markers, units="mm")
    table = opensim.TimeSeriesTableVec3(str(path))
    assert table.getNumRows() == markers.n_frames
    assert table.getNumColumns() == len(markers.names)
    assert table.getTableMetaDataAsString("Units") == "mm"
    labels = list(table.getColumnLabels())
    assert labels == list(markers.names)
    missing_frame, missing_marker = map(int, np.argwhere(np.isnan(markers.positions[:, :, 0]))[0])
    for frame, marker in [(0, 0), (1500, 27), (missing_frame, missing_marker)]:
        vec = table.getRowAtIndex(frame)[marker]
        got = np.array([vec.get(i) for i in range(3)])
        np.testing.assert_allclose(got, markers.positions[frame, marker] * 1000, rtol=1e-12)
    assert np.isnan(markers.positions[missing_frame, missing_marker]).all()


def test_rate_disagreeing_with_time_column_warns(tmp_path: Path, small_trc: list[str]) -> None:
    lines = list(small_trc)
    lines[2] = lines[2].replace("  100.0", "  200.0", 1)  # DataRate 200, time steps 0.01 s
    with pytest.warns(UserWarning, match="DataRate says 200 Hz but the Time column steps 0.01 s"):
        markers = read_trc(_damaged(tmp_path, lines))
    assert markers.rate_hz == 200.0


def test_large_trc_reads_whole(shared_data: Path) -> None:
    # the largest TRC of the shared data (its read time: tests/benchmarks/bench_io.py)
    path = shared_data / "trials/camargo2021_levelground/markers.trc"
    markers = read_trc(path)
    assert markers.n_frames == 3067
    np.testing.assert_allclose(np.diff(markers.time), 1.0 / markers.rate_hz, rtol=1e-6)
