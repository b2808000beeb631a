"""TRC marker files (the OpenSim / Motion Analysis text format).

Layout read and written::

    line 1  PathFileType <tab> 4 <tab> (X/Y/Z) <tab> <file name>
    line 2  DataRate CameraRate NumFrames NumMarkers Units OrigDataRate ...   (keys)
    line 3  100.0    100.0      240       51         mm    100.0        ...   (values)
    line 4  Frame# <tab> Time <tab> name1 <tab><tab><tab> name2 ...
    line 5  <tab><tab> X1 <tab> Y1 <tab> Z1 <tab> X2 ...      (optional)
    line 6+ frame number, time (s), then x y z of each marker, in ``Units``

Variants found in lab files and accepted: tab- or space-separated header values padded
with spaces or extra tabs; trailing tabs on any line; marker names separated by one,
two or three tabs; a missing ``X1 Y1 Z1`` line; blank lines before, between or after
the data rows; frame numbers not starting at 1; an empty cell (or ``nan``) for a
missing marker, and a marker at exactly (0, 0, 0), which is how several exporters (Vicon
Nexus among them) fill a gap; rows missing from the Time column are read with a warning
that names them. Everything else is an error naming the file and the line (a marker's
single-frame spike, such as 9999999 written for a lost marker, is read as it is:
:func:`solver.io.spikes.without_spikes` judges it where a trial is loaded).
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np

from solver.errors import TrcFormatError
from solver.io._numbers import format_float, format_shifted, parse_shifted
from solver.io._text import (
    TokenError,
    check_time,
    flatten,
    is_number,
    parse_floats,
    read_lines,
    warn_frame_gaps,
)
from solver.io.types import MarkerTrajectories
from solver.sampling import frame_interval

#: Power of ten from the TRC ``Units`` value to metres: value_m = value * 10**-shift.
UNIT_SHIFT = {"mm": 3, "millimeters": 3, "cm": 2, "m": 0, "meters": 0}
_REQUIRED_KEYS = ("DataRate", "NumFrames", "NumMarkers", "Units")
_AXIS_LABEL = re.compile(r"^[XYZxyz]\d+$")


def read_trc(path: str | Path) -> MarkerTrajectories:
    """Read a TRC marker file.

    Parameters
    ----------
    path
        The ``.trc`` file.

    Returns
    -------
    MarkerTrajectories
        ``positions`` ``(T, M, 3)`` in metres in the file's lab frame (OpenSim files
        are Y up; no rotation is applied), NaN where a marker is missing (empty cell,
        ``nan``, or all three coordinates exactly 0, a gap filled with zeros); ``time`` ``(T,)`` s from the Time column; ``rate_hz`` from
        ``DataRate`` (a :class:`UserWarning` says so when the Time column steps at a
        rate more than 1 % away); marker names from line 4.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    TrcFormatError
        Naming the file and the 1-based line: missing header keys, an unknown
        ``Units`` (known: mm, cm, m), a marker count different from ``NumMarkers``,
        duplicate marker names, a row with the wrong number of values, text in a
        number field, an infinite coordinate, a frame count different from
        ``NumFrames`` (truncated file), no data rows, or a time column that does not
        increase.

    Warns
    -----
    UserWarning
        Rows missing from the time column (:func:`solver.io._text.warn_frame_gaps`).
    """
    lines = read_lines(path, TrcFormatError)
    header = _read_header(lines, path)
    names = _read_names(lines, path, int(header["NumMarkers"]))
    rate = float(header["DataRate"])
    shift = _unit_shift(header["Units"], path)
    first = _first_data_line(lines)
    rows, line_numbers = _data_rows(lines, first, len(names), path)
    n_frames = int(header["NumFrames"])
    if len(rows) != n_frames:
        where = "truncated?" if len(rows) < n_frames else "extra rows"
        raise TrcFormatError(
            f"line 3 says NumFrames={n_frames} but the file has {len(rows)} data rows ({where})",
            path=path,
            line=line_numbers[-1] if rows else len(lines),
        )
    if not rows:
        raise TrcFormatError("no data rows after the header; expected one row per frame", path=path, line=len(lines))
    _parse_column(rows, line_numbers, 0, path)  # frame numbers: checked, not used
    time = _parse_column(rows, line_numbers, 1, path)
    check_time(time, line_numbers, path, TrcFormatError)
    _check_rate(time, rate, path)
    warn_frame_gaps(time, line_numbers, path)
    coords = _parse_coordinates(rows, line_numbers, shift, path)
    positions = coords.reshape(len(rows), len(names), 3)
    _check_finite(positions, names, line_numbers, path)
    positions[np.all(positions == 0.0, axis=2)] = np.nan  # gaps exported as (0, 0, 0)
    return MarkerTrajectories(names, positions, time, rate, source=str(path))


def _read_header(lines: list[str], path: str | Path) -> dict[str, str]:
    """Keys of line 2 mapped to the values of line 3 (whitespace-separated)."""
    if len(lines) < 4 or not lines[0].strip():
        raise TrcFormatError(
            "expected 4 header lines (PathFileType, keys, values, marker names)",
            path=path,
            line=min(len(lines), 4),
        )
    if not lines[0].lstrip().startswith("PathFileType"):
        raise TrcFormatError(
            f"expected the first line to start with 'PathFileType', found {lines[0][:40]!r}",
            path=path,
            line=1,
        )
    keys, values = lines[1].split(), lines[2].split()
    if len(keys) != len(values):
        raise TrcFormatError(
            f"line 2 has {len(keys)} header keys but line 3 has {len(values)} values",
            path=path,
            line=3,
        )
    header = dict(zip(keys, values, strict=True))
    for key in _REQUIRED_KEYS:
        if key not in header:
            raise TrcFormatError(
                f"header key {key!r} is missing; expected {', '.join(_REQUIRED_KEYS)}",
                path=path,
                line=2,
            )
    rate = header["DataRate"]
    if not is_number(rate) or not (math.isfinite(float(rate)) and float(rate) > 0):
        raise TrcFormatError(f"DataRate {rate!r} is not a positive number (Hz)", path=path, line=3)
    for key in ("NumFrames", "NumMarkers"):
        if not re.fullmatch(r"\d+(\.0*)?", header[key]):
            raise TrcFormatError(
                f"{key} {header[key]!r} is not a non-negative integer", path=path, line=3
            )
        header[key] = str(int(float(header[key])))
    return header


def _unit_shift(units: str, path: str | Path) -> int:
    shift = UNIT_SHIFT.get(units.strip().lower())
    if shift is None:
        raise TrcFormatError(
            f"unknown Units {units!r}; expected mm, cm or m", path=path, line=3, where="Units"
        )
    return shift


def _read_names(lines: list[str], path: str | Path, n_markers: int) -> tuple[str, ...]:
    """Marker names of line 4 (after ``Frame#`` and ``Time``)."""
    line = lines[3]
    cells = line.split("\t") if "\t" in line else line.split()
    cells = [c.strip() for c in cells]
    if len(cells) < 2 or not cells[0].lower().startswith("frame"):
        raise TrcFormatError(
            f"expected line 4 to start with 'Frame#' and 'Time', found {line[:40]!r}",
            path=path,
            line=4,
        )
    names = tuple(c for c in cells[2:] if c)
    if len(names) != n_markers:
        raise TrcFormatError(
            f"line 3 says NumMarkers={n_markers} but line 4 names {len(names)} markers",
            path=path,
            line=4,
        )
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise TrcFormatError(f"marker {name!r} appears twice", path=path, line=4, where=name)
        seen.add(name)
    return names


def _first_data_line(lines: list[str]) -> int:
    """0-based index of the first line after the names that is not blank or ``X1 Y1 Z1``."""
    i = 4
    while i < len(lines):
        tokens = lines[i].split()
        if tokens and not all(_AXIS_LABEL.match(t) for t in tokens):
            break
        i += 1
    return i


def _data_rows(
    lines: list[str], first: int, n_markers: int, path: str | Path
) -> tuple[list[list[str]], list[int]]:
    """Token rows (frame, time, 3M coordinates; '' for empty cells) and their line numbers.

    A file whose rows end with a tab after their last value (most of them: width + 1 cells,
    the last empty) reads a row of exactly ``width`` cells as one value short: its trailing
    empty cell would otherwise stand for the last value and every value after the gap would
    move one axis (a row with an empty cell reported "found 125" of 125, and a full-width row
    missing one value was read shifted).

    Raises
    ------
    TrcFormatError
        A row with another number of values, naming its line.
    """
    width = 2 + 3 * n_markers
    split: list[tuple[int, list[str]]] = []
    for i in range(first, len(lines)):
        line = lines[i]
        if line.strip():
            split.append((i, line.split("\t") if "\t" in line else line.split()))
    trailing_tab = 2 * sum(len(c) == width + 1 and not c[-1].strip() for _, c in split) > len(split)
    rows: list[list[str]] = []
    numbers: list[int] = []
    for i, cells in split:
        if len(cells) != width or trailing_tab:
            if len(cells) > width and not "".join(cells[width:]).strip():
                cells = cells[:width]
            else:
                values = cells[:-1] if trailing_tab and cells and not cells[-1].strip() else cells
                empty = sum(not c.strip() for c in values)
                raise TrcFormatError(
                    f"expected {width} values (frame, time and x y z of {n_markers} markers), "
                    f"found {len(values)} cells"
                    + (f" ({empty} of them empty)" if empty else "")
                    + ("; the other rows end with a tab after their last value" if trailing_tab else ""),
                    path=path,
                    line=i + 1,
                )
        rows.append(cells)
        numbers.append(i + 1)
    return rows, numbers


def _parse_column(
    rows: list[list[str]], numbers: list[int], col: int, path: str | Path
) -> np.ndarray:
    tokens = [r[col] for r in rows]
    try:
        values = parse_floats(tokens)
    except TokenError as exc:
        label = ("Frame#", "Time")[col]
        raise TrcFormatError(
            f"expected a number in column {col + 1} ({label}), found {exc.token!r}",
            path=path,
            line=numbers[exc.index],
        ) from None
    return values


def _check_rate(time: np.ndarray, rate: float, path: str | Path) -> None:
    """Warn when the Time column's median step disagrees with DataRate by more than 1 %."""
    if time.shape[0] < 2:
        return
    step = frame_interval(time)
    if abs(step * rate - 1.0) > 0.01:
        warnings.warn(
            f"{path}: DataRate says {rate:g} Hz but the Time column steps {step:g} s "
            f"({1.0 / step:g} Hz); rate_hz keeps the header's value",
            UserWarning,
            stacklevel=3,
        )


def _parse_coordinates(
    rows: list[list[str]], numbers: list[int], shift: int, path: str | Path
) -> np.ndarray:
    """``(T, 3M)`` coordinates in metres of ``rows`` (at least one); empty cells are NaN."""
    width = len(rows[0]) - 2
    tokens = flatten(r[2:] for r in rows)
    try:
        values = parse_shifted(tokens, shift, empty_is_nan=True)
    except TokenError as exc:
        row, col = divmod(exc.index, width)
        raise TrcFormatError(
            f"expected a number, found {exc.token!r}",
            path=path,
            line=numbers[row],
            where=f"column {col + 3}",
        ) from None
    return values.reshape(len(rows), width)


def _check_finite(positions: np.ndarray, names: tuple[str, ...], numbers: list[int], path: str | Path) -> None:
    """Refuse an infinite coordinate (``inf``), naming its line and marker: a missing
    marker is an empty cell or ``nan``."""
    bad = np.argwhere(np.isinf(positions))
    if bad.size:
        row, marker, axis = (int(v) for v in bad[0])
        raise TrcFormatError(
            f"marker {names[marker]}'s {'XYZ'[axis]} is {float(positions[row, marker, axis])!r}; expected a finite number "
            "(an empty cell or nan for a missing marker)",
            path=path,
            line=numbers[row],
        )


def write_trc(path: str | Path, markers: MarkerTrajectories, *, units: str = "mm") -> None:
    """Write markers to a TRC file that OpenSim and :func:`read_trc` read.

    Parameters
    ----------
    path
        Output ``.trc`` file (overwritten).
    markers
        Positions ``(T, M, 3)`` in metres; NaN is written as ``NaN`` (OpenSim's TRC
        reader drops empty cells at the end of a row, so empty cells are not used).
    units
        ``"mm"`` (default), ``"cm"`` or ``"m"``. Values are written as the shortest
        decimal that reads back to the same float64, shifted to ``units``, so
        ``read_trc(path)`` returns exactly ``markers`` (names, positions, time, rate).

    Raises
    ------
    TrcFormatError
        Unknown ``units``, or a marker name that TRC cannot hold (empty, tab or newline).
    """
    shift = UNIT_SHIFT.get(units)
    if shift is None:
        raise TrcFormatError(f"unknown units {units!r}; expected mm, cm or m", path=path)
    for name in markers.names:
        if not name.strip() or any(c in name for c in "\t\r\n") or name != name.strip():
            raise TrcFormatError(
                f"marker name {name!r} cannot be written to a TRC file (empty, tab, newline "
                "or surrounding spaces)",
                path=path,
                where=name,
            )
    rate = format_float(markers.rate_hz)
    n_frames, n_markers = markers.n_frames, len(markers.names)
    out = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n_frames}\t{n_markers}\t{units}\t{rate}\t1\t{n_frames}",
        "Frame#\tTime\t" + "".join(f"{n}\t\t\t" for n in markers.names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, n_markers + 1)),
        "",
    ]
    flat = markers.positions.reshape(n_frames, 3 * n_markers)
    for i in range(n_frames):
        cells = ["NaN" if math.isnan(v) else format_shifted(v, shift) for v in flat[i].tolist()]
        out.append(f"{i + 1}\t{format_float(markers.time[i])}\t" + "\t".join(cells))
    Path(path).write_text("\n".join(out) + "\n", encoding="utf-8")
