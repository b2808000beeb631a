"""Scale an OpenSim model by per-body scale factors, as OpenSim's ScaleTool does.

For each body with scale factors s = (sx, sy, sz) (its own frame's axes):

* offset frames on the body (joint parent/child frames) have their translation scaled
  element-wise by s; markers likewise; the centre of mass likewise;
* a CustomJoint's translation functions are multiplied by the *parent* body's factor
  along the translation axis (|axis| · s, which is the factor itself for the usual unit
  axes); constant translations too;
* display meshes are scaled by s;
* inertial properties (OpenSim 4.6 ``Body::scaleInertialProperties``, behaviour checked
  against OpenSim in tests/model): with equal factors the inertia scales by s²; otherwise
  the body is treated as a uniform cylinder whose axis is the principal axis of the
  smallest moment: radius from the axial moment (I_a = m r²/2) scaled by the geometric
  mean of the two radial factors, length from the first transverse moment
  (I_t = m (3 r² + L²)/12) scaled by the axial factor; products of inertia vanish;
* masses: with ``preserve_mass_distribution`` (default) masses keep their ratios; without
  it each mass scales by sx·sy·sz. In both cases, when ``mass`` is given, all masses and
  inertias are then multiplied by one factor so that the total equals ``mass``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from solver.errors import OsimModelError, ScaleFactorError
from solver.model.functions import Multiplier
from solver.model.osim import Body, Joint, Marker, Mesh, Offset, OsimModel, TransformAxis

Vec3 = tuple[float, float, float]


def _vec(a: ArrayLike) -> Vec3:
    x = np.asarray(a, dtype=float).reshape(3)
    return (float(x[0]), float(x[1]), float(x[2]))


def _scaled_inertia(inertia: np.ndarray, mass: float, s: np.ndarray, scale_mass: bool) -> np.ndarray:
    """Inertia about the centre of mass after scaling the body by ``s`` (see module doc)."""
    if mass <= np.finfo(float).eps:
        return np.zeros((3, 3))
    mass_factor = abs(float(np.prod(s))) if scale_mass else 1.0
    if np.allclose(s, s[0], rtol=1e-10, atol=0.0):
        return inertia * s[0] ** 2 * mass_factor
    moments = np.diag(inertia).copy()
    axis = int(np.argmin(moments))
    trans = [i for i in range(3) if i != axis]
    r2 = 2.0 * moments[axis] / mass
    l2 = 12.0 * moments[trans[0]] / mass - 3.0 * r2
    new_mass = mass * mass_factor
    r2n = r2 * abs(s[trans[0]] * s[trans[1]])
    l2n = l2 * s[axis] ** 2
    out = np.zeros((3, 3))
    out[axis, axis] = new_mass * r2n / 2.0
    out[trans[0], trans[0]] = out[trans[1], trans[1]] = new_mass * (3.0 * r2n + l2n) / 12.0
    return out


def scale_model(
    model: OsimModel,
    scales: Mapping[str, ArrayLike],
    *,
    mass: float | None = None,
    preserve_mass_distribution: bool = True,
) -> OsimModel:
    """Return a scaled copy of ``model``.

    Parameters
    ----------
    model
        The generic model.
    scales
        Body name -> (3,) scale factors along the body's axes (unitless, > 0). Bodies not
        listed keep factor 1.
    mass
        Target total mass, kg; None keeps the masses from the scaling rule.
    preserve_mass_distribution
        Keep mass ratios between bodies (True) or scale each mass by its volume change.

    Returns
    -------
    OsimModel
        The scaled model (markers, offsets, functions, meshes, inertial properties).

    Raises
    ------
    OsimModelError
        Unknown body name; :class:`~solver.errors.ScaleFactorError` (a subclass) for scale
        factors that are not 3 positive, finite numbers.
    """
    names = set(model.body_names)
    fac: dict[str, np.ndarray] = {}
    for body, s in scales.items():
        arr = np.asarray(s, dtype=float).reshape(-1)
        if arr.size == 1:
            arr = np.repeat(arr, 3)
        if body not in names:
            raise OsimModelError(f"scale factors given for unknown body {body!r}", path=model.source)
        if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            raise ScaleFactorError(f"scale factors of {body} must be 3 positive numbers, got {arr}", path=model.source)
        fac[body] = arr
    one = np.ones(3)

    def factor(body: str) -> np.ndarray:
        return fac.get(body, one)

    bodies = []
    for b in model.bodies:
        s = factor(b.name)
        inertia = _scaled_inertia(np.array(b.inertia), b.mass, s, not preserve_mass_distribution)
        new_mass = b.mass * (abs(float(np.prod(s))) if not preserve_mass_distribution else 1.0)
        meshes = tuple(Mesh(m.file, _vec(np.array(m.scale) * s)) for m in b.meshes)
        bodies.append(
            Body(b.name, new_mass, _vec(np.array(b.com) * s), tuple(map(tuple, inertia)), meshes)
        )
    if mass is not None:
        if not np.isfinite(mass) or mass <= 0:
            raise OsimModelError(f"target mass must be positive, got {mass}", path=model.source)
        k = mass / sum(b.mass for b in bodies)
        bodies = [
            replace(b, mass=b.mass * k, inertia=tuple(map(tuple, np.array(b.inertia) * k))) for b in bodies
        ]

    def scale_offset(off: Offset) -> Offset:
        return replace(off, translation=_vec(np.array(off.translation) * factor(off.body)))

    joints = []
    for j in model.joints:
        sp = factor(j.parent.body) if j.parent.body != "ground" else None
        axes = []
        for a in j.axes:
            if a.kind == "translation" and sp is not None:
                k = float(np.abs(np.array(a.axis)) @ sp)
                a = TransformAxis(a.kind, a.coordinate, a.axis, _multiply(a.function, k))
            axes.append(a)
        joints.append(Joint(j.name, j.type, scale_offset(j.parent), scale_offset(j.child), j.coordinates, tuple(axes)))
    markers = tuple(
        Marker(m.name, m.body, _vec(np.array(m.location) * factor(m.body)), m.fixed) for m in model.markers
    )
    return replace(model, bodies=tuple(bodies), joints=tuple(joints), markers=markers)


def _multiply(function: object, k: float) -> Multiplier:
    """function * k, folding nested multipliers like OpenSim does."""
    if isinstance(function, Multiplier):
        return Multiplier(function.inner, function.scale * k)
    return Multiplier(function, k)  # type: ignore[arg-type]
