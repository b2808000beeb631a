"""Results of the kinematics stage (frozen dataclasses, arrays read-only)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from solver.model.osim import OsimModel

FloatArray = NDArray[np.float64]


def _ro(a: object) -> FloatArray:
    arr = np.array(a, dtype=float, copy=True)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class TrialKinematics:
    """Inverse kinematics of one trial with the scaled model.

    Attributes
    ----------
    name
        Trial name.
    time
        ``(T,)`` s.
    coordinate_names
        ``(n,)`` OpenSim coordinate names (CoordinateSet order).
    q
        ``(T, n)`` coordinates, rad or m; couplers applied, locked ones at default.
    marker_names
        ``(M,)`` model marker names used by the trial.
    observed
        ``(T, M, 3)`` observed marker positions, m, ground frame, NaN where missing.
    modeled
        ``(T, M, 3)`` model marker positions at ``q``, m.
    unmatched
        Trial markers the model does not carry (ignored).
    seconds
        Wall time of this trial's IK, s.
    """

    name: str
    time: FloatArray
    coordinate_names: tuple[str, ...]
    q: FloatArray
    marker_names: tuple[str, ...]
    observed: FloatArray
    modeled: FloatArray
    unmatched: tuple[str, ...] = ()
    seconds: float = 0.0

    def __post_init__(self) -> None:
        for f in ("time", "q", "observed", "modeled"):
            object.__setattr__(self, f, _ro(getattr(self, f)))

    @property
    def errors(self) -> FloatArray:
        """``(T, M)`` marker error distances, m (NaN where the marker is missing)."""
        return np.linalg.norm(self.modeled - self.observed, axis=2)

    @property
    def marker_rms(self) -> float:
        """RMS of the error over all marker observations of the trial, m."""
        e = self.errors
        return float(np.sqrt(np.nanmean(e**2)))

    @property
    def marker_max(self) -> float:
        """Largest marker error of the trial, m."""
        return float(np.nanmax(self.errors))

    @property
    def frame_rms(self) -> FloatArray:
        """``(T,)`` RMS marker error per frame, m (NaN for a frame with no marker)."""
        e = self.errors
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(e**2, axis=1)) if e.size else np.full(e.shape[0], np.nan)

    def marker_rms_by_marker(self) -> dict[str, float]:
        """RMS error of each marker over the frames where it is seen, m."""
        e = self.errors
        return {n: float(np.sqrt(np.nanmean(e[:, i] ** 2))) for i, n in enumerate(self.marker_names) if np.isfinite(e[:, i]).any()}

    @property
    def worst_marker(self) -> str:
        """Name of the marker with the largest RMS error."""
        by = self.marker_rms_by_marker()
        return max(by, key=by.get) if by else ""


@dataclass(frozen=True)
class KinematicsResult:
    """Output of the kinematics stage for one subject.

    Attributes
    ----------
    model
        Scaled model with fitted marker locations (not yet mass-fitted).
    body_scales
        Body name -> (3,) scale factors applied to the generic model.
    marker_offsets
        Marker name -> (3,) body-fixed offset from the scaled generic location, m.
    attached
        Markers added to the model by automatic placement (name -> body).
    trials
        Per-trial inverse kinematics, in input order.
    fit_marker_rms
        RMS marker error of the joint scale fit over its frames, m.
    seconds
        Wall time of the stage, s, by step (``scale_fit``, ``ik``, ...).
    landmark_scale_response
        Trial -> landmark (``fixed``) marker name -> ``(3, 3)`` body-frame matrix L: the
        scaled landmark moves by ``L m`` when the marker is recorded ``m`` off it in that
        trial (:func:`solver.kinematics.fit.landmark_scale_response`).
    """

    model: OsimModel
    body_scales: dict[str, tuple[float, float, float]]
    marker_offsets: dict[str, tuple[float, float, float]]
    trials: tuple[TrialKinematics, ...]
    attached: dict[str, str] = field(default_factory=dict)
    fit_marker_rms: float = float("nan")
    seconds: dict[str, float] = field(default_factory=dict)
    landmark_scale_response: dict[str, dict[str, tuple[tuple[float, float, float], ...]]] = field(default_factory=dict)

    def trial(self, name: str) -> TrialKinematics:
        """The trial called ``name``; raises ``KeyError``."""
        for t in self.trials:
            if t.name == name:
                return t
        raise KeyError(f"no trial {name!r}")
