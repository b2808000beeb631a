"""OpenSim tables (.mot, .sto) read by hand, not by addb's reader, for the tests that check
the files that reader and addb's writers handle."""

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
