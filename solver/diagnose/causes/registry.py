"""The registered diagnosis causes, in the order they are evaluated and listed.

Adding a cause is one new module beside this one (a :class:`~solver.diagnose.causes.base.Cause`
subclass and its instance ``CAUSE``) plus one line in :data:`CAUSES` and its entry in :data:`solver.corrections.CORRECTIONS`
(every cause has one: how its saved entry is applied and the entry's fields that
:func:`solver.corrections.read_extensions` checks);
see solver/diagnose/README.md, "Adding a cause". :func:`~solver.diagnose.causes.base.check` refuses, when this
module is imported, a cause that lacks a part.
"""

from __future__ import annotations

from solver.diagnose.causes import (
    body_mass,
    force_time_offset,
    marker_offset,
    plate_force_gain,
    plate_force_offset,
    plate_position_offset,
    plate_registration,
    segment_mass_distribution,
    unmeasured_force,
)
from solver.diagnose.causes.base import Cause, check

#: Every cause, in evaluation order.
CAUSES: tuple[Cause, ...] = (
    unmeasured_force.CAUSE,
    body_mass.CAUSE,
    force_time_offset.CAUSE,
    plate_force_offset.CAUSE,
    plate_force_gain.CAUSE,
    plate_position_offset.CAUSE,
    segment_mass_distribution.CAUSE,
    marker_offset.CAUSE,
    plate_registration.CAUSE,
)

check(CAUSES)

#: Their names, in the same order.
NAMES: tuple[str, ...] = tuple(c.name for c in CAUSES)

_BY_NAME = {c.name: c for c in CAUSES}


class UnknownCause(KeyError):
    """A cause name that no registered cause has."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def cause(name: str) -> Cause:
    """The registered cause called ``name``.

    Raises
    ------
    UnknownCause
        (a ``KeyError``) no cause has that name; the message lists the registered ones.
    """
    try:
        return _BY_NAME[name]
    except (KeyError, TypeError):
        raise UnknownCause(f"unknown diagnosis cause {name!r}; the registered causes are {', '.join(NAMES)}") from None


def registered(name: str) -> bool:
    """Whether a registered cause is called ``name``."""
    return name in _BY_NAME
