"""The results.json of the trials with force plates in an ``addb process`` output folder."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any


def force_trial_results(out: Path) -> Iterator[tuple[str, dict[str, Any]]]:
    """``(trial name, results.json)`` of every trial of ``out`` that has dynamics (residuals),
    in name order; trials without force plates (a static trial) are skipped."""
    for res in sorted(Path(out).glob("*/results.json")):
        r = json.loads(res.read_text())
        if "linear_residual_rms_N" in r:
            yield res.parent.name, r
