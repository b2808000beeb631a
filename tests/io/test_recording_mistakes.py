"""Mistakes in a lab's recordings and folders (found by feeding damaged copies of the shared
walk to every command) get a clear error or a warning that names the file and the line or
frame, never a numpy traceback or a silently wrong result: rows cut from a TRC or a MOT,
a marker's single-frame spike or an infinite coordinate, a force file with no rows or
under another name, a UTF-16 file, a ``_subject.json`` saved with a byte-order mark or
naming a foot twice, a damaged ``trial.npz`` in an output folder.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.cli import main as addb
from solver.errors import MotFormatError, ProcessedTrialError, SubjectFolderError, TrcFormatError
from solver.io.mot import read_forces, read_table
from solver.io.spikes import SPIKE_M, marker_spikes, without_spikes
from solver.io.subject import load_subject, load_trial
from solver.io.trc import read_trc
from solver.pipeline import process_kinematics
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy
from tests.trial_edits import mot_first_row, trc_first_row

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"
TRC = WALK / "trials" / "walk" / "markers.trc"
GRF = WALK / "trials" / "walk" / "grf.mot"


@pytest.fixture
def walk(tmp_path: Path) -> Path:
    return writable_copy(WALK, tmp_path / "walk")


def _with_num_frames(lines: list[str], n: int) -> list[str]:
    """A TRC's lines with the NumFrames value of its header (line 3) set to ``n``."""
    k = lines[1].split().index("NumFrames")
    parts = re.split(r"(\s+)", lines[2].strip())  # values and the whitespace between them
    parts[2 * k] = str(n)
    return [*lines[:2], "\t".join(parts[::2]), *lines[3:]]


def _cut_rows(src: Path, dst: Path, first: int, count: int) -> None:
    """Write ``src`` to ``dst`` without ``count`` lines from 0-based line ``first``."""
    lines = src.read_text().split("\n")
    del lines[first : first + count]
    dst.write_text("\n".join(lines))


# ----------------------------------------------------------------------------- rows missing


def test_rows_cut_from_a_trc_are_named_with_their_line_and_count(tmp_path: Path) -> None:
    clean = read_trc(TRC)
    lines = TRC.read_text().split("\n")
    start = trc_first_row(lines)
    cut = tmp_path / "markers.trc"
    cut.write_text("\n".join(_with_num_frames(lines, clean.time.size - 30)))
    _cut_rows(cut, cut, start + 60, 30)
    with pytest.warns(UserWarning) as caught:
        markers = read_trc(cut)
    [note] = [str(w.message) for w in caught if "missing at the file's" in str(w.message)]
    line = start + 60 + 1  # 1-based: the first row after the gap
    t0, t1 = clean.time[59], clean.time[90]
    assert f"line {line}: the time steps from {t0:.4f} s to {t1:.4f} s, 30 frames missing at the file's 100 Hz" in note
    np.testing.assert_array_equal(markers.time, np.delete(clean.time, np.s_[60:90]))


def test_rows_cut_from_a_force_file_are_named_and_counted_in_all(tmp_path: Path) -> None:
    clean = read_table(GRF)
    lines = GRF.read_text().split("\n")
    head = mot_first_row(lines)
    n_rows = clean.time.size
    cut = tmp_path / "grf.mot"
    # two gaps: 400 rows, then (in the file left) 10 rows further on
    _cut_rows(GRF, cut, head + 1000, 400)
    text = cut.read_text().split("\n")
    del text[head + 2000 : head + 2010]
    text = [re.sub(r"^nRows=\d+", f"nRows={n_rows - 410}", s) for s in text]
    cut.write_text("\n".join(text))
    with pytest.warns(UserWarning) as caught:
        table = read_table(cut)
    [note] = [str(w.message) for w in caught if "missing at the file's" in str(w.message)]
    assert f"line {head + 1000 + 1}: the time steps from {clean.time[999]:.4f} s to {clean.time[1400]:.4f} s, 400 frames missing" in note
    assert "410 frames missing in 2 gaps in all" in note
    assert table.time.size == n_rows - 410


def test_no_shared_recording_has_a_row_missing_or_a_spike() -> None:
    """The checks above stay silent on every TRC, MOT and STO of ../shared/data."""
    files = [p for p in sorted(SHARED_DATA.rglob("*")) if p.suffix.lower() in (".trc", ".mot", ".sto")]
    assert len(files) > 50
    noisy = []
    for p in files:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if p.suffix.lower() == ".trc":
                without_spikes(read_trc(p))
            else:
                read_table(p)
        noisy += [f"{p}: {w.message}" for w in caught if "missing at the file's" in str(w.message) or "spike" in str(w.message)]
    assert noisy == []


# ----------------------------------------------------------------------------- marker values


def _set_cells(src: Path, dst: Path, row: int, marker: int, values: tuple[str, str, str]) -> int:
    """Write ``src`` to ``dst`` with marker ``marker``'s x y z on data row ``row`` (0-based)
    set to ``values``; returns the 1-based line edited."""
    lines = src.read_text().split("\n")
    k = trc_first_row(lines) + row
    cells = lines[k].split("\t")
    cells[2 + 3 * marker : 5 + 3 * marker] = values
    lines[k] = "\t".join(cells)
    dst.write_text("\n".join(lines))
    return k + 1


@pytest.mark.parametrize("value", ["9999999", "1e37", "-9999999"])
def test_a_marker_spike_is_read_as_missing_with_its_frame_named(walk: Path, value: str) -> None:
    clean = read_trc(TRC)
    path = walk / "trials" / "walk" / "markers.trc"
    _set_cells(TRC, path, 44, 5, (value, value, value))
    as_read = read_trc(path)
    assert as_read.positions[44, 5, 0] == float(value) / 1000.0  # the reader keeps what the file holds
    subject = load_subject(walk)
    [files] = [t for t in subject.trials if t.name == "walk"]
    with pytest.warns(UserWarning, match=rf"markers.trc, frame 44 \({clean.time[44]:.3f} s\): marker {re.escape(clean.names[5])} is .* m from where it is in the frames before and after; 1 such single-frame spike read as missing"):
        trial = load_trial(files)
    expected = clean.positions.copy()
    expected[44, 5] = np.nan
    np.testing.assert_array_equal(trial.markers.positions, expected)


def test_spikes_are_found_in_real_motion_only_where_put() -> None:
    """Three spikes put in the walk's markers are the three found, with their distance; the
    same markers read in millimetres as metres (a thousand times too far apart: smooth, however
    fast) have none."""
    clean = read_trc(TRC).positions
    spiked = clean.copy()
    put = [(10, 0, 5.0), (100, 7, 2.0), (200, 40, 50.0)]
    for f, m, d in put:
        spiked[f, m] = clean[f, m] + np.array([0.0, d, 0.0])
    frames, markers, distance = marker_spikes(spiked)
    assert list(zip(frames.tolist(), markers.tolist())) == [(f, m) for f, m, _ in put]
    for (f, m, d), got in zip(put, distance):
        step = np.linalg.norm(clean[f, m] - clean[[f - 1, f + 1], m], axis=1).max()
        assert abs(got - d) <= step + 1e-12
    assert marker_spikes(clean * 1000.0)[0].size == 0
    assert SPIKE_M == 1.0


def test_an_infinite_coordinate_is_refused_with_its_line_and_marker(tmp_path: Path) -> None:
    names = read_trc(TRC).names
    path = tmp_path / "markers.trc"
    line = _set_cells(TRC, path, 44, 5, ("inf", "0", "0"))
    with pytest.raises(TrcFormatError, match=rf"markers.trc:{line}\): marker {re.escape(names[5])}'s X is inf; expected a finite number"):
        read_trc(path)


# ----------------------------------------------------------------------------- empty, misnamed, encoded


def test_a_trc_with_no_data_rows_is_refused(tmp_path: Path) -> None:
    lines = TRC.read_text().split("\n")
    start = trc_first_row(lines)
    head = _with_num_frames(lines[:start], 0)
    path = tmp_path / "markers.trc"
    path.write_text("\n".join(head) + "\n")
    with pytest.raises(TrcFormatError, match="no data rows after the header"):
        read_trc(path)


def test_a_force_file_with_a_header_and_no_rows_is_refused(walk: Path, tmp_path: Path) -> None:
    lines = GRF.read_text().split("\n")
    head = mot_first_row(lines)
    empty = [re.sub(r"^nRows=\d+", "nRows=0", s) for s in lines[:head]]
    (walk / "trials" / "walk" / "grf.mot").write_text("\n".join(empty) + "\n")
    with pytest.raises(MotFormatError, match=r"grf.mot, data rows\): 0 data rows after the header; force plates need at least two"):
        read_forces(walk / "trials" / "walk" / "grf.mot")
    assert addb(["info", str(walk)]) == 1


def test_a_utf16_file_is_named_as_such(tmp_path: Path) -> None:
    path = tmp_path / "markers.trc"
    path.write_bytes(TRC.read_text().encode("utf-16"))
    with pytest.raises(TrcFormatError, match=r"markers.trc:1\): the file is UTF-16 text"):
        read_trc(path)


@pytest.mark.parametrize("name", ["GRF.mot", "grf.sto", "Grf.MOT"])
def test_a_force_file_under_another_name_is_named(walk: Path, name: str) -> None:
    trial = walk / "trials" / "walk"
    (trial / "grf.mot").rename(trial / name)
    with pytest.raises(SubjectFolderError, match=rf"found {re.escape(name)} but addb reads the force plates from grf.mot"):
        load_subject(walk)


def test_a_folder_named_grf_mot_is_refused(walk: Path) -> None:
    trial = walk / "trials" / "walk"
    (trial / "grf.mot").unlink()
    (trial / "grf.mot").mkdir()
    with pytest.raises(SubjectFolderError, match=r"grf.mot is not a file"):
        load_subject(walk)


def test_subject_json_with_a_byte_order_mark_reads_as_without(walk: Path) -> None:
    path = walk / "_subject.json"
    path.write_bytes(b"\xef\xbb\xbf" + (WALK / "_subject.json").read_bytes())
    with_bom = load_subject(walk)
    without = load_subject(WALK)
    assert (with_bom.mass_kg, with_bom.height_m, with_bom.raw) == (without.mass_kg, without.height_m, without.raw)


def test_a_foot_named_twice_is_refused_before_any_work(walk: Path) -> None:
    path = walk / "_subject.json"
    path.write_text(path.read_text().replace('"calcn_l"', '"calcn_r"'))
    with pytest.raises(SubjectFolderError, match=r"_subject.json, footBodyNames\): footBodyNames=\['calcn_r', 'calcn_r'\] names calcn_r more than once"):
        load_subject(walk)


# ----------------------------------------------------------------------------- output folders


def test_a_damaged_trial_npz_is_named_not_a_zipfile_traceback(walk: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    process_kinematics(walk, out)
    assert load_processed(out, "static").q.shape[0] > 0
    npz = out / "static" / "trial.npz"
    npz.write_bytes(npz.read_bytes()[:5000])
    with pytest.raises(ProcessedTrialError, match=rf"{re.escape(str(npz))}\): cannot be read as a processed trial \(BadZipFile") as err:
        load_processed(out, "static")
    assert isinstance(err.value, ValueError)
    code = addb(["export", str(walk), "--out", str(out), "--trial", "static", "-o", str(tmp_path / "x.mcap")])
    said = capsys.readouterr().err
    assert code == 1 and "cannot be read as a processed trial" in said and "Traceback" not in said
