"""Force-plate column names of MOT/STO ground reaction files, grouped by plate.

Naming schemes found in lab files (``<k>`` is the plate id: ``1``, ``r``, ``L`` ...;
``<a>`` is ``x``, ``y`` or ``z``):

==========================  ===========================  ==============================
force                        centre of pressure           moment
==========================  ===========================  ==============================
``ground_force_<k>_v<a>``    ``ground_force_<k>_p<a>``    ``ground_torque_<k>_<a>`` or
                                                          ``ground_force_<k>_m<a>``
``<k>_ground_force_v<a>``    ``<k>_ground_force_p<a>``    ``<k>_ground_torque_<a>``
``ground_force_v<a>``        ``ground_force_p<a>``        ``ground_torque_<a>``
==========================  ===========================  ==============================

The unnumbered scheme is OpenSim's name for the first plate when the others are
``1_ground_force_v<a>``, ``2_...`` (stair descent file); it gets the plate id ``"0"``.
``ground_moment`` is accepted as a synonym of ``ground_torque``. Other columns are
ignored. Plates are listed in the order their first column appears.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

UNNAMED_PLATE = "0"

_PATTERN = re.compile(
    r"^(?:(?P<pre>[^\s_][^\s]*?)_)?ground_(?P<qty>force|torque|moment)"
    r"(?:_(?P<mid>[^\s]+?))?_(?P<comp>[vpm]?)(?P<axis>[xyz])$"
)
_AXES = "xyz"


@dataclass(frozen=True)
class PlateColumns:
    """The column names of one plate; each triple is in x, y, z order.

    Attributes
    ----------
    name
        Plate id from the names (``"0"`` for the unnumbered scheme).
    force
        Force columns (``..._vx``, ``_vy``, ``_vz``).
    cop
        Centre-of-pressure columns (``..._px``, ...).
    moment
        Moment columns (``ground_torque_..._x`` or ``..._mx``), or None when absent.
    """

    name: str
    force: tuple[str, str, str]
    cop: tuple[str, str, str]
    moment: tuple[str, str, str] | None

    @property
    def force_identifier(self) -> str:
        """OpenSim ExternalForce ``force_identifier``: the force names without the axis."""
        return self.force[0][:-1]

    @property
    def point_identifier(self) -> str:
        """OpenSim ExternalForce ``point_identifier``."""
        return self.cop[0][:-1]

    @property
    def torque_identifier(self) -> str | None:
        """OpenSim ExternalForce ``torque_identifier`` (None without moment columns)."""
        return None if self.moment is None else self.moment[0][:-1]


def classify(column: str) -> tuple[str, str, int] | None:
    """``(plate, kind, axis)`` of a force-plate column, or None for any other column.

    ``kind`` is ``"force"``, ``"cop"`` or ``"moment"``; ``axis`` is 0, 1 or 2.
    """
    m = _PATTERN.match(column)
    if m is None:
        return None
    pre, mid, qty, comp = m["pre"], m["mid"], m["qty"], m["comp"]
    if pre is not None and mid is not None:
        return None
    plate = pre if pre is not None else (mid if mid is not None else UNNAMED_PLATE)
    if qty == "force":
        kind = {"v": "force", "p": "cop", "m": "moment"}.get(comp)
    else:
        kind = "moment" if comp in ("", "m") else None
    if kind is None:
        return None
    return plate, kind, _AXES.index(m["axis"])


class IncompletePlateError(ValueError):
    """A plate has some but not all columns of a force or CoP triple, or two columns for
    one of them (:class:`ClashingPlateColumnsError`)."""

    def __init__(self, plate: str, kind: str, present: list[str]) -> None:
        super().__init__(f"plate {plate!r} has {kind} columns {present} but not all of x, y, z")
        self.plate = plate
        self.kind = kind
        self.present = present


class ClashingPlateColumnsError(IncompletePlateError):
    """Two columns give the same axis of the same plate's force, CoP or moment (e.g.
    ``ground_force_r_vx`` and ``r_ground_force_vx``, or ``ground_torque_r_x`` and
    ``ground_force_r_mx``): which one holds the plate's values cannot be told."""

    def __init__(self, plate: str, kind: str, axis: int, first: str, second: str) -> None:
        ValueError.__init__(
            self, f"columns {first} and {second} both give plate {plate!r}'s {kind} {_AXES[axis]}; expected one column"
        )
        self.plate = plate
        self.kind = kind
        self.present = [first, second]


def group_plates(columns: Sequence[str]) -> tuple[PlateColumns, ...]:
    """Group force-plate columns by plate.

    Raises
    ------
    IncompletePlateError
        A plate lacks one of x, y, z of its force or CoP (or has a partial moment
        triple), or has force without CoP / CoP without force.
    ClashingPlateColumnsError
        Two columns give the same axis of a plate's force, CoP or moment.
    """
    found: dict[str, dict[str, list[str | None]]] = {}
    for col in columns:
        c = classify(col)
        if c is None:
            continue
        plate, kind, axis = c
        slots = found.setdefault(plate, {}).setdefault(kind, [None, None, None])
        if slots[axis] is not None:
            raise ClashingPlateColumnsError(plate, kind, axis, slots[axis], col)
        slots[axis] = col
    plates = []
    for plate, kinds in found.items():
        for kind, slots in kinds.items():
            if any(s is None for s in slots):
                raise IncompletePlateError(plate, kind, [s for s in slots if s is not None])
        for kind in ("force", "cop"):
            if kind not in kinds:
                other = next(iter(kinds.values()))
                raise IncompletePlateError(plate, kind, [s for s in other if s is not None])
        moment = kinds.get("moment")
        plates.append(
            PlateColumns(
                name=plate,
                force=tuple(kinds["force"]),  # type: ignore[arg-type]
                cop=tuple(kinds["cop"]),  # type: ignore[arg-type]
                moment=None if moment is None else tuple(moment),  # type: ignore[arg-type]
            )
        )
    return tuple(plates)


def column_names(plate: str) -> tuple[str, ...]:
    """The 9 names :func:`solver.io.mot.write_forces` uses for ``plate``.

    ``ground_force_<k>_v{x,y,z}``, ``ground_force_<k>_p{x,y,z}``, ``ground_torque_<k>_{x,y,z}``.
    """
    return (
        *(f"ground_force_{plate}_v{a}" for a in _AXES),
        *(f"ground_force_{plate}_p{a}" for a in _AXES),
        *(f"ground_torque_{plate}_{a}" for a in _AXES),
    )
