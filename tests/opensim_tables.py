"""OpenSim tables (.mot, .sto) and TRC files read by hand, not by addb's readers, for the tests
that check the files those readers and addb's writers handle."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_table_by_hand(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """An OpenSim table (.mot, .sto) read by hand, not by addb's reader, for tests that check
    that reader's files: the header's ``key=value`` lines, the column names after
    ``endheader``, and the ``(T, K)`` values."""
    lines = path.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    header = dict(line.split("=", 1) for line in lines[:end] if "=" in line)
    names = lines[end + 1].split("\t")
    values = np.array([[float(v) for v in line.split()] for line in lines[end + 2 :] if line.strip()])
    return header, names, values


def trc_times_by_hand(path: Path) -> np.ndarray:
    """The Time column of a TRC file, s, ``(T,)``, read by hand (not by addb's reader): the
    second field of every row after the header whose first field is a frame number."""
    rows = [line.split("\t") for line in path.read_text().splitlines()[5:] if line.strip()]
    return np.array([float(r[1]) for r in rows if r[0].strip().isdigit()])
