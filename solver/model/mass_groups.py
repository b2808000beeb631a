"""Body groups of a model (trunk, pelvis, legs) and moving mass between them.

Used by the diagnosis's ``segment_mass_distribution`` cause (its fit and its refit) and by
the correction ``addb diagnose --apply`` saves for it (:mod:`solver.corrections`), which
writes the redistributed model that every later ``addb process`` uses.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from solver.model.osim import Body, OsimModel

#: Body groups of ``segment_mass_distribution`` (name prefixes of OpenSim bodies; a body
#: that matches none joins the trunk).
BODY_GROUPS: dict[str, tuple[str, ...]] = {
    "trunk": ("torso", "head", "neck", "humerus", "ulna", "radius", "hand", "lunate", "arm", "thorax"),
    "pelvis": ("pelvis", "sacrum"),
    "legs": ("femur", "patella", "thigh", "tibia", "fibula", "shank", "talus", "calcn", "toes", "foot"),
}


def body_group(name: str) -> str:
    """The :data:`BODY_GROUPS` group of an OpenSim body name (default ``trunk``)."""
    low = name.lower()
    for group, prefixes in BODY_GROUPS.items():
        if any(low.startswith(p) for p in prefixes):
            return group
    return "trunk"


def group_masses(model: OsimModel) -> dict[str, float]:
    """Mass of each :data:`BODY_GROUPS` group of ``model`` (groups without a body left out), kg."""
    out: dict[str, float] = {}
    for b in model.bodies:
        out[body_group(b.name)] = out.get(body_group(b.name), 0.0) + b.mass
    return out


def redistribute(model: OsimModel, change_kg: Mapping[str, float]) -> OsimModel:
    """``model`` with each body group's mass (and inertia) changed by ``change_kg[group]`` kg,
    shared among its bodies in proportion to their masses (a body keeps at least 5 % of its
    mass); centres of mass and meshes unchanged."""
    group_mass = group_masses(model)
    bodies = []
    for b in model.bodies:
        g = body_group(b.name)
        f = 1.0 + float(change_kg.get(g, 0.0)) / group_mass[g] if group_mass[g] > 0 else 1.0
        f = max(f, 0.05)
        bodies.append(Body(b.name, b.mass * f, b.com, tuple(map(tuple, np.array(b.inertia) * f)), b.meshes))
    return replace(model, bodies=tuple(bodies))
