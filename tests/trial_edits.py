"""Edits of a subject's trial files that the tests make to reproduce a user's data."""

from __future__ import annotations

import shutil
from pathlib import Path


def trc_first_row(lines: list[str]) -> int:
    """0-based index of a TRC's first data row among its ``lines`` (the first line whose
    first cell is a frame number)."""
    return next(k for k, line in enumerate(lines) if line.split("\t")[0].strip().isdigit())


def mot_first_row(lines: list[str]) -> int:
    """0-based index of a MOT/STO's first data row among its ``lines`` (the line after the
    column names, which follow ``endheader``)."""
    return next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 2


def keep_first_marker_frames(trc: Path, n: int) -> None:
    """Cut the TRC file ``trc`` to its first ``n`` data rows, its header's frame counts
    (line 3) with them."""
    lines = trc.read_text().splitlines()
    first = trc_first_row(lines)
    frames = len(lines) - first
    if str(frames) not in lines[2]:
        raise ValueError(f"{trc}: line 3 does not give the {frames} data rows the file has")
    lines = [*lines[:first], *lines[first : first + n]]
    lines[2] = lines[2].replace(str(frames), str(n))
    trc.write_text("\n".join(lines) + "\n")


def add_short_walk(subject: Path, n: int = 6) -> Path:
    """Add the trial ``walk_short`` to the walk subject folder ``subject``: its walk trial
    with the first ``n`` marker frames only and its forces whole (too short for the
    dynamics). Returns the trial folder."""
    short = subject / "trials" / "walk_short"
    shutil.copytree(subject / "trials" / "walk", short)
    keep_first_marker_frames(short / "markers.trc", n)
    return short


def zero_forces(grf: Path) -> None:
    """Set every column of the grf.mot ``grf`` but time to 0 (plates switched off, an empty
    export: no frame carries force)."""
    lines = grf.read_text().splitlines()
    first = mot_first_row(lines)
    rows = [line.split("\t") for line in lines[first:]]
    grf.write_text("\n".join([*lines[:first], *("\t".join([r[0]] + ["0"] * (len(r) - 1)) for r in rows)]) + "\n")
