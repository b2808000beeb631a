"""MOT/STO tables: OpenSim coordinates, ground reaction forces, any time series.

File layout::

    <header lines>          name, key=value pairs (version, nRows, nColumns, inDegrees,
                            DataType, OpenSimVersion, DataRate ...) or the older
                            "datacolumns 19", "datarows 4500", "range 0 4.5", free text
    endheader
    [blank lines]
    time <tab> col1 <tab> col2 ...
    0.000 <tab> 1.23 <tab> ...        (tab- or space-separated, padding allowed)

A ``.mot`` file is either ground reaction forces or coordinates: tell them apart with
:func:`is_force_table` (column names), not by the extension.

Units: forces N, centres of pressure m, moments N·m, translational coordinates m.
Rotational coordinates are radians inside the program; files say ``inDegrees=yes``
when they hold degrees and :func:`read_coordinates` converts the rotational columns.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection, Iterable, Sequence
from pathlib import Path

import numpy as np

from solver.errors import MotFormatError
from solver.io._numbers import format_degrees, format_float, parse_degrees
from solver.io._text import (
    TokenError,
    check_time,
    flatten,
    parse_floats,
    read_lines,
    warn_frame_gaps,
)
from solver.io.force_columns import (
    IncompletePlateError,
    PlateColumns,
    column_names,
    group_plates,
)
from solver.io.plate_moments import (
    MomentReference,
    Reference,
    detect_reference,
    free_moment,
    warn_conversion,
)
from solver.io.types import ForcePlate, ForceRecording, Table
from solver.sampling import frame_interval, nominal_rate

#: Header keys written as "key value" (older Motion Analysis / SIMM style) instead of key=value.
_SPACE_KEYS = {"name", "datacolumns", "datarows", "range"}
#: Header keys recomputed (or, for inDegrees_file, dropped) by the writers rather than
#: copied from ``Table.header``.
_COMPUTED_KEYS = {
    "name",
    "version",
    "nrows",
    "ncolumns",
    "datacolumns",
    "datarows",
    "range",
    "indegrees_file",
}
_TRANSLATIONAL = re.compile(r"(_t[xyz]|_beta)$|translation", re.IGNORECASE)


# --------------------------------------------------------------------------- reading


def read_table(path: str | Path) -> Table:
    """Read a MOT or STO file as it is: values as in the file, no unit conversion.

    ``Table.header["inDegrees"]`` (when present) tells whether rotational values are
    degrees; use :func:`read_coordinates` to get radians, :func:`read_forces` for plates.

    Parameters
    ----------
    path
        The ``.mot`` / ``.sto`` file.

    Returns
    -------
    Table
        ``data`` ``(T, K)`` (time column excluded), ``time`` ``(T,)`` s, ``header``
        with the key/values as read (free-text lines joined under ``"comment"``).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    MotFormatError
        Naming the file and 1-based line: no ``endheader``, no column line, a first
        column not named ``time``, empty or duplicate column names, a row with the
        wrong number of values, text in a number field, a row count different from
        ``nRows``/``datarows`` (truncated file), a column count different from
        ``nColumns``/``datacolumns``, a time that does not increase.

    Warns
    -----
    UserWarning
        Rows missing from the time column (:func:`solver.io._text.warn_frame_gaps`).
    """
    return _read(path, degree_columns=())


def read_coordinates(
    path: str | Path,
    rotational: Collection[str] | None = None,
    *,
    in_degrees: bool | None = None,
) -> Table:
    """Read a coordinates file (IK result) with rotational columns in radians.

    Parameters
    ----------
    path
        The ``.mot`` / ``.sto`` file.
    rotational
        Names of the columns that are rotational coordinates (motion type
        *rotational* in the model). OpenSim writes only those in degrees; coupled
        coordinates (e.g. the Rajagopal/Lai patella ``knee_angle_r_beta``) and
        translations stay in model units. When None, a name heuristic is used: every
        column is rotational except names ending in ``_tx``, ``_ty``, ``_tz`` or
        ``_beta`` or containing ``translation``. Pass the model's set when you have it.
    in_degrees
        Override the file's ``inDegrees``. None (default) reads it from the header
        and raises if the header does not say.

    Returns
    -------
    Table
        Rotational columns in rad, others as in the file; ``header["inDegrees"]`` is
        ``"no"`` since the values are now radians (the original value is kept under
        ``"inDegrees_file"``).

    Raises
    ------
    MotFormatError
        As :func:`read_table`; also when ``inDegrees`` is missing or not yes/no and
        ``in_degrees`` is None.
    """
    lines = read_lines(path, MotFormatError)
    header, _, _ = _parse_header(lines, path)
    if in_degrees is None:
        in_degrees = _header_in_degrees(header, path)
    degree_columns: Collection[str] | None = () if not in_degrees else rotational
    table = _read(path, degree_columns=degree_columns, lines=lines)
    new_header = dict(table.header)
    if "inDegrees" in new_header:
        new_header["inDegrees_file"] = new_header["inDegrees"]
    new_header["inDegrees"] = "no"
    return Table(table.column_names, table.data, table.time, new_header, table.source)


def default_rotational(columns: Iterable[str]) -> frozenset[str]:
    """The name heuristic of :func:`read_coordinates` (see there)."""
    return frozenset(c for c in columns if not _TRANSLATIONAL.search(c))


def _header_in_degrees(header: dict[str, str], path: str | Path) -> bool:
    value = header.get("inDegrees")
    if value is None:
        raise MotFormatError(
            "the header has no inDegrees line, so the unit of the rotational coordinates is "
            "unknown; pass in_degrees=True or False",
            path=path,
            where="header",
        )
    flag = value.strip().lower()
    if flag in ("yes", "true", "1"):
        return True
    if flag in ("no", "false", "0"):
        return False
    raise MotFormatError(f"inDegrees={value!r}; expected yes or no", path=path, where="header")


def _read(
    path: str | Path,
    *,
    degree_columns: Collection[str] | None,
    lines: list[str] | None = None,
) -> Table:
    """Parse ``path``; columns in ``degree_columns`` (None: the heuristic) go deg -> rad."""
    if lines is None:
        lines = read_lines(path, MotFormatError)
    header, names_line, names = _parse_header(lines, path)
    rows, numbers = _data_rows(lines, names_line + 1, len(names), path)
    _check_counts(header, len(rows), len(names), numbers, lines, path)
    width = len(names)
    flat = flatten(rows)
    try:
        values = parse_floats(flat).reshape(len(rows), width)
    except TokenError as exc:
        raise _token_error(exc, width, numbers, names, path) from None
    if degree_columns is None:
        degree_columns = default_rotational(names[1:])
    for j, name in enumerate(names):
        if j > 0 and name in degree_columns:
            try:
                values[:, j] = parse_degrees(flat[j::width])
            except TokenError as exc:  # pragma: no cover - parse_floats accepted it
                raise _token_error(
                    TokenError(exc.index * width + j, exc.token), width, numbers, names, path
                ) from None
    time = values[:, 0].copy()
    check_time(time, numbers, path, MotFormatError)
    warn_frame_gaps(time, numbers, path)
    return Table(tuple(names[1:]), values[:, 1:], time, header, str(path))


def _parse_header(lines: list[str], path: str | Path) -> tuple[dict[str, str], int, list[str]]:
    """Header dict, 0-based index of the column-name line, and the column names."""
    header: dict[str, str] = {}
    comments: list[str] = []
    end = None
    for i, raw in enumerate(lines):
        line = raw.strip()
        if line.lower() == "endheader":
            end = i
            break
        if not line:
            continue
        key, sep, value = line.partition("=")
        first, _, rest = line.partition(" ")
        if sep and key.strip() and " " not in key.strip():
            header[key.strip()] = value.strip()
        elif first.lower() in _SPACE_KEYS and rest.strip():
            header[first.lower()] = rest.strip()
        elif "name" not in header and not header and not comments:
            header["name"] = line
        else:
            comments.append(line)
    if end is None:
        raise MotFormatError(
            "no 'endheader' line; expected the header to end with a line 'endheader' "
            "followed by the column names",
            path=path,
            line=len(lines),
        )
    if comments:
        header["comment"] = "\n".join(comments)
    names_line = end + 1
    while names_line < len(lines) and not lines[names_line].strip():
        names_line += 1
    if names_line >= len(lines):
        raise MotFormatError(
            "the file ends after 'endheader'; expected a line of column names starting with 'time'",
            path=path,
            line=len(lines),
        )
    return header, names_line, _column_names(lines[names_line], names_line + 1, path)


def _column_names(line: str, number: int, path: str | Path) -> list[str]:
    cells = [c.strip() for c in line.split("\t")] if "\t" in line else line.split()
    while cells and not cells[-1]:
        cells.pop()
    if not cells or cells[0].lower() != "time":
        raise MotFormatError(
            f"expected the column names, starting with 'time', found {line.strip()[:40]!r}",
            path=path,
            line=number,
        )
    seen: set[str] = set()
    for k, name in enumerate(cells):
        if not name:
            raise MotFormatError(f"column {k + 1} has no name", path=path, line=number)
        if name in seen:
            raise MotFormatError(
                f"column {name!r} appears twice", path=path, line=number, where=name
            )
        seen.add(name)
    return cells


def _data_rows(
    lines: list[str], start: int, width: int, path: str | Path
) -> tuple[list[list[str]], list[int]]:
    rows: list[list[str]] = []
    numbers: list[int] = []
    for i in range(start, len(lines)):
        cells = lines[i].split()
        if not cells:
            continue
        if len(cells) != width:
            raise MotFormatError(
                f"expected {width} values (time and {width - 1} columns), found {len(cells)}",
                path=path,
                line=i + 1,
            )
        rows.append(cells)
        numbers.append(i + 1)
    return rows, numbers


def _header_int(header: dict[str, str], keys: Sequence[str], path: str | Path) -> int | None:
    for key in keys:
        for k, v in header.items():
            if k.lower() == key:
                try:
                    return int(v)
                except ValueError:
                    raise MotFormatError(
                        f"header {k}={v!r} is not an integer", path=path, where="header"
                    ) from None
    return None


def _check_counts(
    header: dict[str, str],
    n_rows: int,
    n_cols: int,
    numbers: list[int],
    lines: list[str],
    path: str | Path,
) -> None:
    expected_rows = _header_int(header, ("nrows", "datarows"), path)
    if expected_rows is not None and expected_rows != n_rows:
        hint = "truncated?" if n_rows < expected_rows else "extra rows"
        raise MotFormatError(
            f"the header says {expected_rows} rows but the file has {n_rows} ({hint})",
            path=path,
            line=numbers[-1] if numbers else len(lines),
        )
    expected_cols = _header_int(header, ("ncolumns", "datacolumns"), path)
    if expected_cols is not None and expected_cols != n_cols:
        raise MotFormatError(
            f"the header says {expected_cols} columns (time included) but the column line "
            f"names {n_cols}",
            path=path,
            where="header",
        )


def _token_error(
    exc: TokenError, width: int, numbers: list[int], names: list[str], path: str | Path
) -> MotFormatError:
    row, col = divmod(exc.index, width)
    return MotFormatError(
        f"expected a number in column {col + 1} ({names[col]}), found {exc.token!r}",
        path=path,
        line=numbers[row],
        where=names[col],
    )


# --------------------------------------------------------------------------- forces


def is_force_table(table: Table) -> bool:
    """True if ``table`` has at least one complete force-plate column set.

    Detection is by column names (see :mod:`solver.io.force_columns`), not by the
    file extension or header: a coordinates ``.mot`` has no ``ground_force`` columns.
    """
    try:
        return len(group_plates(table.column_names)) > 0
    except IncompletePlateError:
        return True


def read_forces(path: str | Path, *, moment_reference: Reference = "auto") -> ForceRecording:
    """Read a ground reaction force MOT/STO file.

    Parameters
    ----------
    path
        The ``.mot`` / ``.sto`` file, with any naming scheme of
        :mod:`solver.io.force_columns`.
    moment_reference
        What the moment columns are about. ``"cop"``: free moments (OpenSim's
        convention), used as is. ``"origin"``: moments about the lab origin.
        ``"auto"`` (default): decided per plate from the data, see
        :mod:`solver.io.plate_moments`; any conversion is reported with a
        :class:`UserWarning`.

    Returns
    -------
    ForceRecording
        One :class:`ForcePlate` per plate found, in column order: ``force`` ``(T, 3)`` N
        (ground reaction on the body), ``cop`` ``(T, 3)`` m, ``free_moment``
        ``(T, 3)`` N·m about the CoP, all in the file's lab frame (Y up for OpenSim
        files). Unloaded frames keep the file's CoP, which is often meaningless there.
        A plate without moment columns gets zeros. ``rate_hz`` is the header's
        ``DataRate`` when present (warned about when more than 1 % from the time column's
        rate), else estimated from the time column (see :func:`estimate_rate`). ``corners`` is None (MOT files carry no plate geometry).

    Raises
    ------
    MotFormatError
        As :func:`read_table`; fewer than two data rows; no force-plate columns; a plate with part of a force
        or CoP triple; with ``"auto"``, moment columns that are about no fixed point.
    """
    if moment_reference not in ("auto", "cop", "origin"):
        raise ValueError(f"moment_reference={moment_reference!r}; expected auto, cop or origin")
    table = read_table(path)
    if table.time.size < 2:
        raise MotFormatError(
            f"{table.time.size} data row{'s' * (table.time.size != 1)} after the header; force plates need at least two "
            "(one per sample)",
            path=path,
            where="data rows",
        )
    try:
        groups = group_plates(table.column_names)
    except IncompletePlateError as exc:
        raise MotFormatError(str(exc), path=path, where=f"plate {exc.plate}") from None
    if not groups:
        raise MotFormatError(
            "no ground reaction force columns; expected names such as ground_force_1_vx, "
            "R_ground_force_vx or ground_force_vx",
            path=path,
            where="column names",
        )
    plates = tuple(_plate(table, g, moment_reference, path) for g in groups)
    rate = _rate(table, path)
    return ForceRecording(table.time, rate, plates, source=str(path))


def _plate(
    table: Table, cols: PlateColumns, moment_reference: Reference, path: str | Path
) -> ForcePlate:
    def block(names: Sequence[str]) -> np.ndarray:
        return np.stack([table.column(n) for n in names], axis=1)

    force, cop = block(cols.force), block(cols.cop)
    if cols.moment is None:
        return ForcePlate(cols.name, force, cop, np.zeros_like(force))
    moment = block(cols.moment)
    if moment_reference == "cop":
        reference: MomentReference | None = MomentReference("cop", np.zeros(3), 0.0)
    elif moment_reference == "origin":
        reference = MomentReference("origin", np.zeros(3), 0.0)
    else:
        reference = detect_reference(force, cop, moment)
        if reference is None:
            raise MotFormatError(
                f"plate {cols.name}: the moment columns {list(cols.moment)} are neither free "
                "moments at the centre of pressure nor moments about a fixed point; pass "
                "moment_reference='cop' or 'origin' to choose",
                path=path,
                where=f"plate {cols.name}",
            )
        if reference.kind != "cop":
            warn_conversion(cols.name, reference, str(path))
    return ForcePlate(cols.name, force, cop, free_moment(force, cop, moment, reference))


def estimate_rate(time: np.ndarray) -> float:
    """Sampling rate, Hz, from a uniform time column ``time`` ``(T,)``, s:
    ``(T - 1) / (t[-1] - t[0])``.

    Given as :func:`solver.sampling.nominal_rate` (2000 Hz, not 1999.9999999).
    Returns NaN for fewer than two samples.
    """
    if time.shape[0] < 2:
        return math.nan
    return nominal_rate((time.shape[0] - 1) / (float(time[-1]) - float(time[0])))


#: Relative disagreement between a force recording's rate and its time column's above which
#: the reader warns and the dynamics filters at the time column's rate (input audit
#: 2026-12-02, finding 13: a DataRate of 1000 over samples 0.5 ms apart doubled the cutoff).
RATE_TOLERANCE = 0.01


def _rate(table: Table, path: str | Path) -> float:
    """Sampling rate (Hz) of a force table: its ``DataRate`` header (a UserWarning naming the
    file when it differs from :func:`time_column_rate` by more than :data:`RATE_TOLERANCE`),
    or the time column's (:func:`estimate_rate`) when there is none.

    Raises
    ------
    MotFormatError
        ``DataRate`` is not a positive number.
    """
    text = table.header.get("DataRate")
    if text is None:
        return estimate_rate(table.time)
    try:
        rate = float(text)
    except ValueError:
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0):
        raise MotFormatError(
            f"DataRate={text!r} is not a positive number (Hz)", path=path, where="header"
        )
    measured = time_column_rate(table.time)
    if abs(measured / rate - 1.0) > RATE_TOLERANCE:
        import warnings

        warnings.warn(
            f"{path}: DataRate says {rate:g} Hz but the time column steps {1.0 / measured:g} s ({measured:g} Hz); "
            "rate_hz keeps the header's value, and the dynamics filters the forces at the time column's rate",
            UserWarning,
            stacklevel=3,
        )
    return rate


def time_column_rate(time: np.ndarray) -> float:
    """The rate (Hz) of a time column ``(T,)``, s, at least two samples: its median step's
    (:func:`solver.sampling.frame_interval`: a dropped sample moves it not), nominal
    (:func:`solver.sampling.nominal_rate`)."""
    return nominal_rate(1.0 / frame_interval(time))


# --------------------------------------------------------------------------- writing


def write_table(path: str | Path, table: Table, *, kind: str = "mot") -> None:
    """Write a table as a MOT or STO file that OpenSim 4.6 and :func:`read_table` read.

    Values are written as-is (shortest exact decimal), so ``read_table(path)``
    returns the same column names, data and time bit for bit. ``inDegrees`` is
    copied from ``table.header`` (default ``no``); other header keys are kept except
    the counts, which are recomputed.

    Parameters
    ----------
    path
        Output file (overwritten).
    table
        The table; its column names must be non-empty, unique and free of whitespace.
    kind
        ``"mot"``: the classic header (name line, ``version=1``, ``nRows``,
        ``nColumns``, ``inDegrees``). ``"sto"``: the OpenSim 4 storage header
        (``version=3``, ``DataType=double``, no name line).

    Raises
    ------
    MotFormatError
        Invalid ``kind`` or column names, or a time that does not increase.
    """
    names = ("time", *table.column_names)
    _check_names(names, path)
    cells = [[format_float(v) for v in table.data[:, j].tolist()] for j in range(len(names) - 1)]
    _write(path, table.header, names, table.time, cells, kind=kind)


def write_coordinates(
    path: str | Path,
    names: Sequence[str],
    q: np.ndarray,
    time: np.ndarray,
    *,
    rotational: Collection[str],
) -> None:
    """Write coordinates as an OpenSim motion file, rotational columns in degrees.

    Parameters
    ----------
    path
        Output ``.mot`` file (overwritten); header ``Coordinates``, ``inDegrees=yes``.
    names
        ``(n,)`` coordinate names.
    q
        ``(T, n)`` coordinates: rad for rotational ones, model units (m, or rad for
        coupled coordinates) for the others, which are written unchanged.
    time
        ``(T,)`` s, increasing.
    rotational
        Names written in degrees (the model's rotational coordinates; OpenSim
        converts only those when it reads the file).

    Notes
    -----
    Degrees are written with enough digits that :func:`read_coordinates` with the
    same ``rotational`` returns ``q`` exactly.

    Raises
    ------
    MotFormatError
        Shapes that do not match, invalid names, a time that does not increase.
    """
    q = np.asarray(q, dtype=np.float64)
    time = np.asarray(time, dtype=np.float64)
    if q.ndim != 2 or q.shape != (time.shape[0], len(names)):
        raise MotFormatError(
            f"q must be (T, n) = ({time.shape[0]}, {len(names)}), got {q.shape}", path=path
        )
    all_names = ("time", *names)
    _check_names(all_names, path)
    rot = set(rotational)
    cells = [
        [(format_degrees if n in rot else format_float)(v) for v in q[:, j].tolist()]
        for j, n in enumerate(names)
    ]
    header = {"name": "Coordinates", "inDegrees": "yes"}
    _write(path, header, all_names, time, cells, kind="mot")


def write_forces(path: str | Path, recording: ForceRecording) -> None:
    """Write force plates as an OpenSim ground reaction MOT file.

    Columns per plate ``<k>`` (its name): ``ground_force_<k>_v{x,y,z}`` (N),
    ``ground_force_<k>_p{x,y,z}`` (m), ``ground_torque_<k>_{x,y,z}`` (N·m). The header
    carries ``DataRate``, so :func:`read_forces` returns the same plates, time and rate
    bit for bit (plate corners are not stored in MOT files).

    Raises
    ------
    MotFormatError
        A plate name that is empty, contains whitespace, or appears twice.
    """
    names: list[str] = ["time"]
    cells: list[list[str]] = []
    for plate in recording.plates:
        if not plate.name or any(c.isspace() for c in plate.name):
            raise MotFormatError(
                f"plate name {plate.name!r} cannot be a column-name part", path=path
            )
        names.extend(column_names(plate.name))
        for block in (plate.force, plate.cop, plate.free_moment):
            cells.extend([format_float(v) for v in block[:, a].tolist()] for a in range(3))
    _check_names(names, path)
    header = {
        "name": Path(path).stem,
        "inDegrees": "no",
        "DataRate": format_float(recording.rate_hz),
    }
    _write(path, header, names, recording.time, cells, kind="mot")


def _check_names(names: Sequence[str], path: str | Path) -> None:
    seen: set[str] = set()
    for name in names:
        if not name or any(c.isspace() for c in name) or name in seen:
            raise MotFormatError(
                f"column name {name!r} is empty, contains whitespace or is repeated",
                path=path,
                where=name,
            )
        seen.add(name)


def _safe_name(name: str) -> str:
    """A first header line that reads back as the name (no '=', not a header keyword)."""
    name = " ".join(name.replace("=", "-").split()) or "table"
    first = name.split()[0].lower()
    return f"table {name}" if first in _SPACE_KEYS | {"endheader"} else name


def _write(
    path: str | Path,
    header: dict[str, str],
    names: Sequence[str],
    time: np.ndarray,
    columns: list[list[str]],
    *,
    kind: str,
) -> None:
    if kind not in ("mot", "sto"):
        raise MotFormatError(f"kind={kind!r}; expected 'mot' or 'sto'", path=path)
    time = np.asarray(time, dtype=np.float64)
    if time.shape[0] > 1 and not np.all(np.diff(time) > 0):
        raise MotFormatError("time must increase", path=path, where="time")
    n_rows = time.shape[0]
    extra = {k: v for k, v in header.items() if k.lower() not in _COMPUTED_KEYS and k != "comment"}
    extra.setdefault("inDegrees", "no")
    if kind == "mot":
        name = _safe_name(header.get("name", "") or Path(path).stem)
        out = [name, "version=1", f"nRows={n_rows}", f"nColumns={len(names)}"]
    else:
        out = ["version=3", "DataType=double", f"nRows={n_rows}", f"nColumns={len(names)}"]
        extra.pop("version", None)
        extra.pop("DataType", None)
    out += [f"{k}={v}" for k, v in extra.items() if "\n" not in k + v and "=" not in k]
    out += ["endheader", "\t".join(names)]
    times = [format_float(t) for t in time.tolist()]
    for i in range(n_rows):
        out.append("\t".join([times[i], *(col[i] for col in columns)]))
    Path(path).write_text("\n".join(out) + "\n", encoding="utf-8")
