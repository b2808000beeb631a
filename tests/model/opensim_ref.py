"""Reference numbers computed with OpenSim 4.6 at test time (the ``opensim`` test extra).

Same method as shared/oracles (see its .json): forces removed, every coordinate
unlocked, values set without assembly, dependent coordinates set from their coupler.

Import it only after ``require_tool("opensim", OPENSIM, OPENSIM_REASON)`` (tests/conftest.py),
which skips the test without OpenSim, or fails it under ``CI=true``.
"""

from __future__ import annotations

import numpy as np
import opensim as osim

osim.Logger.setLevelString("error")


class OpenSimModel:
    """An OpenSim model prepared for kinematics and inverse dynamics queries."""

    def __init__(self, path: str) -> None:
        self.model = osim.Model(path)
        self.model.updForceSet().clearAndDestroy()
        self.state = self.model.initSystem()
        cs = self.model.getCoordinateSet()
        self.coords = [cs.get(i) for i in range(cs.getSize())]
        self.names = [c.getName() for c in self.coords]
        for c in self.coords:
            c.setLocked(self.state, False)
        self._mobility = self._mobility_order()

    def _mobility_order(self) -> list[int]:
        s = self.state
        order = []
        for c in self.coords:
            c.setSpeedValue(s, 12345.0)
            u = s.getU()
            order.append(next(j for j in range(u.size()) if u.get(j) == 12345.0))
            c.setSpeedValue(s, 0.0)
        return order

    def set_state(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        s = self.state
        for c, v in zip(self.coords, q):
            c.setValue(s, float(v), False)
        if qd is not None:
            for c, v in zip(self.coords, qd):
                c.setSpeedValue(s, float(v))
        self.model.realizeDynamics(s) if qd is not None else self.model.realizePosition(s)

    def markers(self) -> tuple[list[str], np.ndarray]:
        ms = self.model.getMarkerSet()
        names = [ms.get(i).getName() for i in range(ms.getSize())]
        pos = [[ms.get(i).getLocationInGround(self.state).get(k) for k in range(3)] for i in range(ms.getSize())]
        return names, np.array(pos).reshape(-1, 3)

    def bodies(self) -> tuple[list[str], np.ndarray]:
        bs = self.model.getBodySet()
        names = [bs.get(i).getName() for i in range(bs.getSize())]
        pos = [[bs.get(i).getPositionInGround(self.state).get(k) for k in range(3)] for i in range(bs.getSize())]
        return names, np.array(pos)

    def com(self) -> np.ndarray:
        c = self.model.calcMassCenterPosition(self.state)
        return np.array([c.get(k) for k in range(3)])

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Generalized forces ignoring constraints, in coordinate order."""
        self.set_state(q, qd)
        udot = osim.Vector(self.state.getNU(), 0.0)
        for i, j in enumerate(self._mobility):
            udot.set(j, float(qdd[i]))
        tau = osim.InverseDynamicsSolver(self.model).solve(self.state, udot)
        return np.array([tau.get(j) for j in self._mobility])


def random_states(names_ranges: np.ndarray, n: int, seed: int) -> np.ndarray:
    """(n, k) coordinate values uniform in each range, unbounded ranges clipped to ±1."""
    rng = np.random.default_rng(seed)
    lo = np.clip(names_ranges[:, 0], -1.0, 1.0)
    hi = np.clip(names_ranges[:, 1], -1.0, 1.0)
    return rng.uniform(lo, hi, size=(n, lo.size))
