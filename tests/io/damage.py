"""Helpers of the readers' damaged-file tests: a real file's lines with a fault put in,
written to a temporary file, and the format error the reader must raise for it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from solver.errors import AddbError


def damaged(tmp_path: Path, lines: list[str], suffix: str) -> Path:
    """``lines`` written to ``tmp_path/damaged<suffix>``, one per line."""
    path = tmp_path / f"damaged{suffix}"
    path.write_text("\n".join(lines) + "\n")
    return path


def expect_format_error(error: type[AddbError], read: Callable[[Path], object], path: Path, line: int | None, *words: str) -> AddbError:
    """``read(path)`` raises ``error`` naming ``path`` and ``line`` (None: no line), in its
    text too, with every one of ``words`` in its message; returns it."""
    with pytest.raises(error) as info:
        read(path)
    err = info.value
    assert err.path == str(path)
    assert err.line == line
    assert str(path) in str(err)
    for word in words:
        assert word in err.message
    return err
