"""Typed, immutable containers returned by the readers of :mod:`solver.io`.

Conventions (see the project README, "Conventions"):

* SI units: m, s, kg, N, N·m, rad. Millimetres and degrees exist only in files.
* OpenSim lab frame: Y up; gravity (0, -9.80665, 0) m/s².
* Time is axis 0 of every array; missing values are NaN.

Arrays stored in these dataclasses are made read-only on construction, so a result
shared between the solver, the app and the recorders cannot be changed by accident.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def _freeze(obj: Any, *names: str) -> None:
    """Convert the named fields to read-only float64 arrays (in place on a frozen dataclass)."""
    for name in names:
        value = getattr(obj, name)
        if value is None:
            continue
        arr = np.array(value, dtype=np.float64, copy=True)
        arr.flags.writeable = False
        object.__setattr__(obj, name, arr)


@dataclass(frozen=True)
class MarkerTrajectories:
    """Optical marker positions of one trial.

    Attributes
    ----------
    names
        ``(M,)`` marker names, in file order.
    positions
        ``(T, M, 3)`` marker positions in the lab frame (Y up), metres; NaN where a
        marker is missing in a frame.
    time
        ``(T,)`` time of each frame, seconds.
    rate_hz
        Frame rate, Hz (from the file header).
    source
        Path of the file the data came from ("" if built in memory).
    """

    names: tuple[str, ...]
    positions: FloatArray
    time: FloatArray
    rate_hz: float
    source: str = ""

    def __post_init__(self) -> None:
        _freeze(self, "positions", "time")
        object.__setattr__(self, "names", tuple(self.names))
        t, m = self.positions.shape[:2] if self.positions.ndim == 3 else (-1, -1)
        if self.positions.ndim != 3 or self.positions.shape[2] != 3:
            raise ValueError(f"positions must be (T, M, 3), got {self.positions.shape}")
        if m != len(self.names) or self.time.shape != (t,):
            raise ValueError(
                f"{len(self.names)} names and time {self.time.shape} do not match "
                f"positions {self.positions.shape}"
            )

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions.shape[0])

    def index(self, name: str) -> int:
        """Column index of marker ``name``; raises ``KeyError`` naming the marker."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"marker {name!r} is not in {self.source or 'this trial'}") from None

    def marker(self, name: str) -> FloatArray:
        """``(T, 3)`` positions of one marker, metres, lab frame."""
        return self.positions[:, self.index(name), :]


@dataclass(frozen=True)
class ForcePlate:
    """One force platform's ground reaction wrench, expressed in the lab frame.

    The wrench applied to the body standing on the plate is: ``force`` acting at
    ``cop`` plus the pure couple ``free_moment`` (usually vertical only). Frames where
    the plate is unloaded have force ~0 and a meaningless CoP (kept as in the file).

    Attributes
    ----------
    name
        Plate identifier from the file ("1", "r", "L", ...).
    force
        ``(T, 3)`` ground reaction force on the body, N, lab frame.
    cop
        ``(T, 3)`` centre of pressure, m, lab frame.
    free_moment
        ``(T, 3)`` free moment about the CoP, N·m, lab frame.
    corners
        ``(4, 3)`` plate corners in the lab frame, m, or None when the file has none.
    """

    name: str
    force: FloatArray
    cop: FloatArray
    free_moment: FloatArray
    corners: FloatArray | None = None

    def __post_init__(self) -> None:
        _freeze(self, "force", "cop", "free_moment", "corners")
        for f in ("force", "cop", "free_moment"):
            a = getattr(self, f)
            if a.ndim != 2 or a.shape[1] != 3 or a.shape != self.force.shape:
                raise ValueError(f"plate {self.name}: {f} must be (T, 3), got {a.shape}")
        if self.corners is not None and self.corners.shape != (4, 3):
            raise ValueError(f"plate {self.name}: corners must be (4, 3), got {self.corners.shape}")


@dataclass(frozen=True)
class ForceRecording:
    """All force plates of one trial on a common time base.

    Attributes
    ----------
    time
        ``(T,)`` seconds.
    rate_hz
        Sampling rate, Hz.
    plates
        The plates, in the order found in the file.
    source
        Path of the file the data came from.
    """

    time: FloatArray
    rate_hz: float
    plates: tuple[ForcePlate, ...]
    source: str = ""

    def __post_init__(self) -> None:
        _freeze(self, "time")
        object.__setattr__(self, "plates", tuple(self.plates))
        for p in self.plates:
            if p.force.shape[0] != self.time.shape[0]:
                raise ValueError(
                    f"plate {p.name} has {p.force.shape[0]} frames, time has {self.time.shape[0]}"
                )

    @property
    def n_frames(self) -> int:
        """Number of samples T."""
        return int(self.time.shape[0])


@dataclass(frozen=True)
class Table:
    """A generic MOT/STO table (coordinates, generalized forces, any time series).

    Attributes
    ----------
    column_names
        ``(K,)`` data column names, without the time column.
    data
        ``(T, K)`` values in SI units: rotational coordinates in radians even when the
        file said ``inDegrees=yes`` (readers convert using the model or the column
        names, see :func:`solver.io.mot.read_coordinates`).
    time
        ``(T,)`` seconds.
    header
        Header key/values as read (``name``, ``version``, ``inDegrees``, ...).
    source
        Path of the file the data came from.
    """

    column_names: tuple[str, ...]
    data: FloatArray
    time: FloatArray
    header: dict[str, str] = field(default_factory=dict)
    source: str = ""

    def __post_init__(self) -> None:
        _freeze(self, "data", "time")
        object.__setattr__(self, "column_names", tuple(self.column_names))
        if self.data.ndim != 2 or self.data.shape != (self.time.shape[0], len(self.column_names)):
            raise ValueError(
                f"data {self.data.shape} does not match time {self.time.shape} and "
                f"{len(self.column_names)} columns"
            )

    def column(self, name: str) -> FloatArray:
        """``(T,)`` values of column ``name``; raises ``KeyError`` naming the column."""
        try:
            return self.data[:, self.column_names.index(name)]
        except ValueError:
            raise KeyError(f"column {name!r} is not in {self.source or 'this table'}") from None
