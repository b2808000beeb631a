"""Helpers shared by the text readers (TRC, MOT/STO): file text, lines, number tokens.

Line numbers are 1-based, as an editor shows them. Lines are split on ``\\n`` and a
trailing ``\\r`` is removed, so Windows and Unix files number lines the same way.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import FileFormatError
from solver.sampling import frame_interval, frame_rate

FloatArray = NDArray[np.float64]


def read_lines(path: str | Path, error: type[FileFormatError]) -> list[str]:
    """Lines of a text file, without line terminators.

    UTF-8 is tried first, then Latin-1 (lab software on Windows writes paths in the
    local code page); a UTF-8 byte-order mark is dropped.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    error
        The file is empty, UTF-16 text (named as such) or binary (contains NUL bytes).
    """
    raw = Path(path).read_bytes()
    if not raw.strip():
        raise error("the file is empty; expected a text header and data rows", path=path, line=1)
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise error("the file is UTF-16 text (its byte-order mark says so); save it as UTF-8 or ASCII text", path=path, line=1)
    if b"\x00" in raw:
        line = raw[: raw.index(b"\x00")].count(b"\n") + 1
        raise error("the file contains NUL bytes; expected a text file", path=path, line=line)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    text = text.removeprefix("\ufeff")
    return [line.removesuffix("\r") for line in text.split("\n")]


class TokenError(ValueError):
    """A token that is not a number; ``index`` is its position in the flat token list."""

    def __init__(self, index: int, token: str) -> None:
        super().__init__(f"not a number: {token!r}")
        self.index = index
        self.token = token


def _first_bad(tokens: Sequence[str], convert: object = float) -> TokenError:
    """The first token ``convert`` rejects (slow path used only to report an error)."""
    for i, tok in enumerate(tokens):
        try:
            convert(tok)  # type: ignore[operator]
        except (ValueError, ArithmeticError):
            return TokenError(i, tok)
    return TokenError(0, tokens[0] if tokens else "")  # pragma: no cover - numpy and float agree


def parse_floats(tokens: Sequence[str]) -> FloatArray:
    """``(N,)`` float64 values of decimal tokens (``nan``/``inf`` accepted).

    Raises
    ------
    TokenError
        A token is not a number (the first one, with its index).
    """
    try:
        return np.array(tokens, dtype=np.float64).reshape(len(tokens))
    except (ValueError, TypeError):
        raise _first_bad(tokens) from None


def flatten(rows: Sequence[Sequence[str]]) -> list[str]:
    """Concatenate token rows into one list."""
    return list(itertools.chain.from_iterable(rows))


def is_number(token: str) -> bool:
    """True if ``token`` parses as a float."""
    try:
        float(token)
    except ValueError:
        return False
    return True


def check_time(time: FloatArray, numbers: Sequence[int], path: str | Path, error: type[FileFormatError]) -> None:
    """Check a text file's time column: finite and increasing.

    Parameters
    ----------
    time
        ``(T,)`` the column's values, s.
    numbers
        ``(T,)`` the 1-based line of each row.
    path, error
        The file, and the error class to raise (:class:`~solver.errors.TrcFormatError`,
        :class:`~solver.errors.MotFormatError`).

    Raises
    ------
    error
        Naming the line of the first time that is not finite or does not increase.
    """
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise error("the time is not a finite number", path=path, line=numbers[bad[0]])
    with np.errstate(over="ignore"):  # 1e308 - -1e308 is inf, still an increase
        steps = np.flatnonzero(np.diff(time) <= 0)
    if steps.size:
        k = int(steps[0]) + 1
        raise error(
            f"time {float(time[k])!r} s does not increase (previous row: {float(time[k - 1])!r} s)",
            path=path,
            line=numbers[k],
        )


#: A step of the time column longer than this many times its median step leaves frames out.
GAP_STEP = 1.5


def frame_gaps(time: FloatArray) -> list[tuple[int, int]]:
    """Where frames are missing from a time column sampled at a fixed rate.

    Parameters
    ----------
    time
        ``(T,)`` frame times, s, increasing.

    Returns
    -------
    ``(k, n)`` for each step from row ``k - 1`` to row ``k`` longer than :data:`GAP_STEP`
    times the median step (the frame interval, :func:`solver.sampling.frame_interval`):
    ``n`` frames missing there (the step in frame intervals, rounded, less one; at least
    one). Empty for fewer than three rows.
    """
    if time.size < 3:
        return []
    steps = np.diff(time)
    interval = frame_interval(time)
    if not interval > 0.0:
        return []
    long = np.flatnonzero(steps > GAP_STEP * interval)
    return [(int(i) + 1, max(1, round(float(steps[i]) / interval) - 1)) for i in long]


def warn_frame_gaps(time: FloatArray, numbers: Sequence[int], path: str | Path) -> None:
    """Warn (:class:`UserWarning`) when rows are missing from a time column
    (:func:`frame_gaps`), naming the file, the line after the first gap, its times and
    the frames missing in all: the pipeline resamples every trial at a fixed rate, so it
    interpolates across a gap, motion or force the recording does not hold.

    Parameters
    ----------
    time
        ``(T,)`` frame times, s, increasing.
    numbers
        ``(T,)`` the 1-based line of each row.
    path
        The file.
    """
    gaps = frame_gaps(time)
    if not gaps:
        return
    k, n = gaps[0]
    total = sum(m for _, m in gaps)
    rate = frame_rate(time)
    more = f"; {total} frames missing in {len(gaps)} gaps in all" if len(gaps) > 1 else ""
    warnings.warn(
        f"{path}, line {numbers[k]}: the time steps from {float(time[k - 1]):.4f} s to {float(time[k]):.4f} s, "
        f"{n} frame{'s' * (n > 1)} missing at the file's {rate:g} Hz{more}; addb interpolates across a gap "
        "(the rows were cut or dropped: check the export, or flag those frames in review)",
        UserWarning,
        stacklevel=3,
    )
