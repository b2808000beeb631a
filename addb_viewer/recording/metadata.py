"""What a recording says about itself, shared by the Rerun and MCAP writers.

Two recordings of the same trial (before and after a reprocess) can be compared on
this dictionary: it holds the solver settings and the review (annotation) state the
trial was recorded with, besides names needed to rebuild arrays from the file.
"""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, datetime
from importlib import metadata as importlib_metadata
from typing import Any

import numpy as np

from solver.io.mcap_file import RECORDING_FORMAT, RECORDING_VERSION
from solver.results import ProcessedTrial


def jsonable(value: Any) -> Any:
    """A JSON-safe copy: numpy scalars/arrays and tuples to lists, NaN/inf to None,
    dataclasses to dicts."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return jsonable(dataclasses.asdict(value))
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        f = float(value)
        return f if math.isfinite(f) else None
    return value


def review_state(review: Any) -> dict[str, Any]:
    """The annotation state of one trial as a JSON-safe dict.

    Parameters
    ----------
    review
        An :class:`annotations.TrialReview` (flags as runs with provenance, activity
        ranges, notes, reviewed mark) or an already plain dict.

    Returns
    -------
    dict
        ``dataclasses.asdict`` of the review with tuples as lists.
    """
    return jsonable(review)


def _version() -> str:
    try:
        return importlib_metadata.version("addb")
    except importlib_metadata.PackageNotFoundError:  # pragma: no cover - source checkout
        return "unknown"


def recording_info(
    trial: ProcessedTrial,
    *,
    annotations: dict[str, Any] | None = None,
    settings: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Self-description of a recording of ``trial``.

    Parameters
    ----------
    trial
        The processed trial.
    annotations
        Review state of the trial (see :func:`review_state`), or None when unknown.
    settings
        Solver settings; default: ``trial.settings``.

    Returns
    -------
    dict
        JSON-safe: ``format``, ``version``, ``subject``, ``trial``, ``n_frames``,
        ``rate_hz``, ``mass_kg``, ``height_m``, ``coordinate_names``, ``marker_names``,
        ``body_names``, ``body_meshes``, ``plates`` (name and ``(4, 3)`` corners, m, or
        None), ``geometry_dir``, ``model_path``, ``has_dynamics``, ``metrics``,
        ``settings``, ``annotations``, ``created_utc``, ``addb_version``.
    """
    return jsonable(
        {
            "format": RECORDING_FORMAT,
            "version": RECORDING_VERSION,
            "subject": trial.subject,
            "trial": trial.trial,
            "n_frames": trial.n_frames,
            "rate_hz": trial.rate_hz,
            "mass_kg": trial.mass_kg,
            "height_m": trial.height_m,
            "coordinate_names": list(trial.coordinate_names),
            "marker_names": list(trial.marker_names),
            "body_names": list(trial.body_names),
            "body_meshes": {b: [[f, list(s)] for f, s in m] for b, m in trial.body_meshes.items()},
            "plates": [{"name": p.name, "corners": p.corners} for p in trial.plates],
            "geometry_dir": trial.geometry_dir,
            "model_path": trial.model_path,
            "has_dynamics": trial.has_dynamics,
            "metrics": trial.metrics,
            "settings": trial.settings if settings is None else settings,
            "annotations": annotations,
            "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "addb_version": _version(),
        }
    )
