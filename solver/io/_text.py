"""Helpers shared by the text readers (TRC, MOT/STO): file text, lines, number tokens.

Line numbers are 1-based, as an editor shows them. Lines are split on ``\\n`` and a
trailing ``\\r`` is removed, so Windows and Unix files number lines the same way.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import FileFormatError

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
        The file is empty or binary (contains NUL bytes).
    """
    raw = Path(path).read_bytes()
    if not raw.strip():
        raise error("the file is empty; expected a text header and data rows", path=path, line=1)
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
