"""Parse OpenSim .osim models (format 4.x, and the 3.x layout still found in labs).

The result, :class:`OsimModel`, is a plain description of the multibody system: bodies
with inertial properties, joints reduced to one uniform *spatial transform* (three
rotations composed intrinsically, then three translations expressed in the joint's
parent frame, as OpenSim's CustomJoint defines them), coordinates, coordinate coupler
constraints and markers. :mod:`solver.model.skeleton` builds the pinocchio model from it;
:mod:`solver.model.scaling` scales it; :mod:`solver.model.osim_writer` writes it back.

Joint semantics (checked against OpenSim 4.6, see tests/model):
X_ground_child = X_ground_parentBody * X_parentBody_parentFrame * X_joint(q) * inv(X_childBody_childFrame),
with X_joint(q) = [R1(f1(q)) R2(f2(q)) R3(f3(q)), sum_k f_{3+k}(q) a_{3+k}] and offset frame
orientations as body-fixed X-Y-Z Euler angles.

Joint types: CustomJoint, PinJoint (Z rotation), SliderJoint (X translation),
UniversalJoint (X then Y), GimbalJoint and BallJoint (body-fixed X-Y-Z rotations),
FreeJoint (X-Y-Z rotations and translations in the parent frame), PlanarJoint
(Z rotation, X and Y translations), WeldJoint. Anything else raises
:class:`~solver.errors.OsimModelError` naming the element.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.constants import GRAVITY_VECTOR
from solver.errors import OsimModelError
from solver.model.functions import (
    Constant,
    CubicSpline,
    Function,
    Linear,
    Multiplier,
    PiecewiseLinear,
    Polynomial,
)

FloatArray = NDArray[np.float64]

ROTATIONAL = "rotational"
TRANSLATIONAL = "translational"
COUPLED = "coupled"

_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Mesh:
    """A display mesh attached to a body: file name (e.g. ``r_femur.vtp``) and scale factors (3,)."""

    file: str
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Body:
    """A rigid body.

    Attributes
    ----------
    name
        Body name (``ground`` is not a Body).
    mass
        kg.
    com
        ``(3,)`` centre of mass in the body frame, m.
    inertia
        ``(3, 3)`` inertia about the centre of mass in body axes, kg·m².
    meshes
        Display meshes attached to the body frame.
    """

    name: str
    mass: float
    com: tuple[float, float, float]
    inertia: tuple[tuple[float, float, float], ...]
    meshes: tuple[Mesh, ...] = ()


@dataclass(frozen=True)
class Offset:
    """A fixed frame on a body: ``translation`` (3,) m in the body frame, ``orientation`` (3,)
    body-fixed X-Y-Z Euler angles, rad."""

    body: str
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation(self) -> FloatArray:
        """``(3, 3)`` rotation of the offset frame in its body: Rx(o0) Ry(o1) Rz(o2)."""
        return euler_xyz(self.orientation)


@dataclass(frozen=True)
class TransformAxis:
    """One axis of a joint's spatial transform.

    ``kind`` is ``"rotation"`` or ``"translation"``; ``coordinate`` is the OpenSim coordinate
    driving it (None for a constant axis); ``axis`` (3,) unit vector in the joint parent frame
    (rotations: in the frame rotated by the previous rotations); ``function`` maps the
    coordinate to an angle (rad) or a displacement (m).
    """

    kind: str
    coordinate: str | None
    axis: tuple[float, float, float]
    function: Function


@dataclass(frozen=True)
class Joint:
    """A joint between ``parent`` and ``child`` offset frames, in the uniform spatial-transform form."""

    name: str
    type: str
    parent: Offset
    child: Offset
    coordinates: tuple[str, ...]
    axes: tuple[TransformAxis, ...]


@dataclass(frozen=True)
class Coordinate:
    """An OpenSim coordinate: value range (rad or m), default, flags, and its motion type
    (``rotational``, ``translational`` or ``coupled``: degrees are used in files only for
    rotational ones)."""

    name: str
    joint: str
    motion_type: str
    default_value: float
    range: tuple[float, float]
    clamped: bool
    locked: bool


@dataclass(frozen=True)
class Coupler:
    """CoordinateCouplerConstraint: ``dependent`` = scale_factor * function(``independent``)."""

    name: str
    dependent: str
    independent: str
    function: Function
    scale_factor: float = 1.0


@dataclass(frozen=True)
class Marker:
    """A model marker: parent body, location in the body frame (3,) m, and the ``fixed`` flag."""

    name: str
    body: str
    location: tuple[float, float, float]
    fixed: bool = False


@dataclass(frozen=True)
class OsimModel:
    """Everything the solver needs from an .osim file. Build with :func:`read_osim`.

    ``coordinates`` are in OpenSim's CoordinateSet order (joints in declaration order);
    ``joints`` are sorted so that every parent comes before its child.
    """

    name: str
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    coordinates: tuple[Coordinate, ...]
    couplers: tuple[Coupler, ...]
    markers: tuple[Marker, ...]
    gravity: tuple[float, float, float] = GRAVITY_VECTOR
    source: str = ""

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        """OpenSim coordinate names in CoordinateSet order."""
        return tuple(c.name for c in self.coordinates)

    @property
    def body_names(self) -> tuple[str, ...]:
        """Body names in BodySet order."""
        return tuple(b.name for b in self.bodies)

    @property
    def total_mass(self) -> float:
        """Sum of body masses, kg."""
        return float(sum(b.mass for b in self.bodies))

    def body(self, name: str) -> Body:
        """The body called ``name``; raises ``KeyError``."""
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(f"no body {name!r} in model {self.name}")

    def with_markers(self, markers: tuple[Marker, ...]) -> OsimModel:
        """A copy with another marker set."""
        return replace(self, markers=tuple(markers))


def euler_xyz(angles: tuple[float, float, float] | FloatArray) -> FloatArray:
    """``(3, 3)`` rotation matrix of body-fixed X-Y-Z Euler angles ``(3,)`` (a, b, c), rad:
    Rx(a) @ Ry(b) @ Rz(c)."""
    a, b, c = (float(v) for v in angles)
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rx @ ry @ rz


# ----------------------------------------------------------------------------- XML helpers


class _Ctx:
    """Parsing context: the file path and its parsed document, for error messages."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.document: ET.Element | None = None
        self._lines: dict[int, int] | None = None

    def line_of(self, elem: ET.Element) -> int | None:
        """The 1-based line where ``elem`` starts in the file. ElementTree keeps no line
        numbers, so on the first error only the file is read again with expat, whose
        element starts come in the document order of ``document.iter()``."""
        if self.document is None:
            return None
        if self._lines is None:
            import xml.parsers.expat

            starts: list[int] = []
            parser = xml.parsers.expat.ParserCreate()
            parser.StartElementHandler = lambda _name, _attrs: starts.append(parser.CurrentLineNumber)
            with open(self.path, "rb") as f:
                parser.ParseFile(f)
            self._lines = {id(e): line for e, line in zip(self.document.iter(), starts, strict=False)}
        return self._lines.get(id(elem))

    def error(self, message: str, elem: ET.Element | None = None) -> OsimModelError:
        where = line = None
        if elem is not None:
            name = elem.get("name")
            where = f"<{elem.tag}{' name=' + repr(name) if name else ''}>"
            line = self.line_of(elem)
        return OsimModelError(message, path=self.path, line=line, where=where)

    def text(self, elem: ET.Element, tag: str, default: str | None = None) -> str:
        child = elem.find(tag)
        if child is None or child.text is None or not child.text.strip():
            if default is not None:
                return default
            raise self.error(f"missing <{tag}>", elem)
        return child.text.strip()

    def floats(self, elem: ET.Element, tag: str, n: int | None, default: str | None = None) -> tuple[float, ...]:
        raw = self.text(elem, tag, default)
        try:
            vals = tuple(float(v) for v in raw.split())
        except ValueError:
            raise self.error(f"<{tag}> must hold numbers, got {raw[:60]!r}", elem) from None
        if n is not None and len(vals) != n:
            raise self.error(f"<{tag}> must hold {n} numbers, got {len(vals)}", elem)
        if not all(np.isfinite(vals)):
            raise self.error(f"<{tag}> holds a non-finite number: {raw[:60]!r}", elem)
        return vals

    def flag(self, elem: ET.Element, tag: str, default: bool) -> bool:
        raw = self.text(elem, tag, "true" if default else "false").lower()
        if raw not in ("true", "false", "1", "0"):
            raise self.error(f"<{tag}> must be true or false, got {raw!r}", elem)
        return raw in ("true", "1")


_FUNCTION_TAGS = (
    "Constant",
    "LinearFunction",
    "PolynomialFunction",
    "SimmSpline",
    "NaturalCubicSpline",
    "PiecewiseLinearFunction",
    "MultiplierFunction",
    "GCVSpline",
    "StepFunction",
    "Sine",
    "PiecewiseConstantFunction",
)


def _find_function(ctx: _Ctx, parent: ET.Element) -> ET.Element:
    """The function element under ``parent``: a direct child (4.x) or inside <function> (3.x)."""
    for elem in list(parent):
        if elem.tag in _FUNCTION_TAGS:
            return elem
        if elem.tag in ("function", "coupled_coordinates_function"):
            for sub in list(elem):
                if sub.tag in _FUNCTION_TAGS:
                    return sub
    raise ctx.error("no function element found", parent)


def _parse_function(ctx: _Ctx, elem: ET.Element) -> Function:
    tag = elem.tag
    try:
        if tag == "Constant":
            return Constant(ctx.floats(elem, "value", 1)[0])
        if tag == "LinearFunction":
            c = ctx.floats(elem, "coefficients", 2)
            return Linear(c[0], c[1])
        if tag == "PolynomialFunction":
            return Polynomial(ctx.floats(elem, "coefficients", None))
        if tag in ("SimmSpline", "NaturalCubicSpline"):
            x, y = ctx.floats(elem, "x", None), ctx.floats(elem, "y", None)
            return CubicSpline(x, y, kind="fmm" if tag == "SimmSpline" else "natural")
        if tag == "PiecewiseLinearFunction":
            return PiecewiseLinear(ctx.floats(elem, "x", None), ctx.floats(elem, "y", None))
        if tag == "MultiplierFunction":
            inner = _parse_function(ctx, _find_function(ctx, elem))
            return Multiplier(inner, ctx.floats(elem, "scale", 1, "1")[0])
    except ValueError as exc:
        raise ctx.error(str(exc), elem) from None
    raise ctx.error(
        f"function type {tag} is not supported (supported: Constant, LinearFunction, "
        "PolynomialFunction, SimmSpline, NaturalCubicSpline, PiecewiseLinearFunction, "
        "MultiplierFunction)",
        elem,
    )


# ----------------------------------------------------------------------------- bodies


def _parse_inertia(ctx: _Ctx, body: ET.Element) -> tuple[tuple[float, float, float], ...]:
    if body.find("inertia") is not None:  # 4.x: xx yy zz xy xz yz
        xx, yy, zz, xy, xz, yz = ctx.floats(body, "inertia", 6)
    else:  # 3.x: separate elements
        xx, yy, zz, xy, xz, yz = (
            ctx.floats(body, f"inertia_{k}", 1, "0")[0] for k in ("xx", "yy", "zz", "xy", "xz", "yz")
        )
    return ((xx, xy, xz), (xy, yy, yz), (xz, yz, zz))


def _parse_meshes(ctx: _Ctx, body: ET.Element) -> tuple[Mesh, ...]:
    meshes = []
    for m in body.iter("Mesh"):  # 4.x attached_geometry
        f = m.findtext("mesh_file")
        if f and f.strip():
            meshes.append(Mesh(f.strip(), tuple(ctx.floats(m, "scale_factors", 3, "1 1 1"))))
    for g in body.iter("DisplayGeometry"):  # 3.x VisibleObject
        f = g.findtext("geometry_file")
        if f and f.strip():
            meshes.append(Mesh(f.strip(), tuple(ctx.floats(g, "scale_factors", 3, "1 1 1"))))
    return tuple(meshes)


def _parse_body(ctx: _Ctx, elem: ET.Element) -> Body:
    mass = ctx.floats(elem, "mass", 1)[0]
    if mass < 0:
        raise ctx.error(f"negative mass {mass}", elem)
    inertia = _parse_inertia(ctx, elem)
    # principal moments must not be negative (the triangle inequality a + b >= c is not asked:
    # the Rajagopal models' toes break it, and the rigid-body algorithms do not need it)
    moments = np.linalg.eigvalsh(np.array(inertia))
    if moments[0] < -1e-9 * max(float(np.abs(moments).max()), 1e-12):
        raise ctx.error(
            f"inertia {inertia} (kg·m², about the centre of mass) has a negative principal moment "
            f"({', '.join(f'{m:.6g}' for m in moments)}); expected a positive semi-definite matrix",
            elem,
        )
    return Body(
        name=elem.get("name") or "",
        mass=mass,
        com=tuple(ctx.floats(elem, "mass_center", 3, "0 0 0")),
        inertia=inertia,
        meshes=_parse_meshes(ctx, elem),
    )


# ----------------------------------------------------------------------------- joints

_SIMPLE_JOINTS: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    # type: the (kind, axis) of each coordinate in order
    "PinJoint": (("rotation", _Z),),
    "SliderJoint": (("translation", _X),),
    "UniversalJoint": (("rotation", _X), ("rotation", _Y)),
    "GimbalJoint": (("rotation", _X), ("rotation", _Y), ("rotation", _Z)),
    "BallJoint": (("rotation", _X), ("rotation", _Y), ("rotation", _Z)),
    "FreeJoint": (
        ("rotation", _X),
        ("rotation", _Y),
        ("rotation", _Z),
        ("translation", _X),
        ("translation", _Y),
        ("translation", _Z),
    ),
    "PlanarJoint": (("rotation", _Z), ("translation", _X), ("translation", _Y)),
    "WeldJoint": (),
}
SUPPORTED_JOINTS = ("CustomJoint", *_SIMPLE_JOINTS)


def _coordinate_elems(joint: ET.Element) -> list[ET.Element]:
    for container in ("coordinates", "CoordinateSet"):
        c = joint.find(container)
        if c is not None:
            return list(c.iter("Coordinate"))
    return []


def _parse_axes(ctx: _Ctx, joint: ET.Element, coords: list[str]) -> tuple[TransformAxis, ...]:
    jtype = joint.tag
    if jtype != "CustomJoint":
        spec = _SIMPLE_JOINTS[jtype]
        if len(coords) != len(spec):
            raise ctx.error(f"{jtype} needs {len(spec)} coordinates, found {len(coords)}", joint)
        return tuple(TransformAxis(k, c, a, Linear(1.0, 0.0)) for (k, a), c in zip(spec, coords))
    st = joint.find("SpatialTransform")
    if st is None:
        raise ctx.error("CustomJoint without <SpatialTransform>", joint)
    axes = []
    for ta in st.iter("TransformAxis"):
        name = ta.get("name") or ""
        kind = "rotation" if name.startswith("rotation") else "translation"
        if not name.startswith(("rotation", "translation")):
            raise ctx.error(f"TransformAxis name {name!r} must be rotation1..3 or translation1..3", ta)
        raw_coords = (ta.findtext("coordinates") or "").split()
        if len(raw_coords) > 1:
            raise ctx.error(
                f"TransformAxis {name} depends on {len(raw_coords)} coordinates; only functions "
                "of one coordinate are supported",
                ta,
            )
        coord = raw_coords[0] if raw_coords else None
        if coord is not None and coord not in coords:
            raise ctx.error(f"TransformAxis {name} uses coordinate {coord!r} not owned by the joint", ta)
        axis = np.array(ctx.floats(ta, "axis", 3))
        norm = np.linalg.norm(axis)
        if norm < 1e-12:
            raise ctx.error(f"TransformAxis {name} has a zero axis", ta)
        func = _parse_function(ctx, _find_function(ctx, ta))
        if coord is None and not func.is_constant():
            func = Constant(float(func.value(0.0)))
        axes.append(TransformAxis(kind, coord, tuple(axis / norm), func))
    if len(axes) != 6:
        raise ctx.error(f"SpatialTransform must have 6 TransformAxis elements, found {len(axes)}", st)
    return tuple(axes)


def _motion_type(coord: str, axes: tuple[TransformAxis, ...], declared: str | None) -> str:
    """OpenSim's rule: a coordinate that drives an axis through a LinearFunction takes that
    axis' kind; otherwise it is coupled. A 3.x ``<motion_type>`` wins when present."""
    if declared in (ROTATIONAL, TRANSLATIONAL, COUPLED):
        return declared
    for ax in axes:
        if ax.coordinate == coord and isinstance(ax.function, Linear):
            return ROTATIONAL if ax.kind == "rotation" else TRANSLATIONAL
    return COUPLED


def _parse_coordinate(ctx: _Ctx, elem: ET.Element, joint: str, axes: tuple[TransformAxis, ...]) -> Coordinate:
    name = elem.get("name") or ""
    declared = (elem.findtext("motion_type") or "").strip().lower() or None
    rng = ctx.floats(elem, "range", 2, "-99999.9 99999.9")
    if rng[0] > rng[1]:  # OpenSim 4.6 refuses such a model too ("Maximum coordinate range less than minimum")
        raise ctx.error(f"<range> {rng[0]:g} {rng[1]:g}: the minimum is above the maximum; expected 'min max'", elem)
    return Coordinate(
        name=name,
        joint=joint,
        motion_type=_motion_type(name, axes, declared),
        default_value=ctx.floats(elem, "default_value", 1, "0")[0],
        range=(rng[0], rng[1]),
        clamped=ctx.flag(elem, "clamped", False),
        locked=ctx.flag(elem, "locked", False),
    )


def _strip_path(ref: str) -> str:
    """``/bodyset/femur_r`` -> ``femur_r``; ``../femur_r_offset`` -> ``femur_r_offset``."""
    return ref.strip().rstrip("/").split("/")[-1]


class _FrameResolver:
    """Resolves a 4.x socket reference to an :class:`Offset` on a body."""

    def __init__(self, ctx: _Ctx, body_names: set[str], free_frames: dict[str, ET.Element]) -> None:
        self.ctx = ctx
        self.body_names = body_names | {"ground"}
        self.free_frames = free_frames

    def offset_from_elem(self, pof: ET.Element, seen: tuple[str, ...] = ()) -> Offset:
        parent = _strip_path(self.ctx.text(pof, "socket_parent"))
        base = self.resolve(parent, {}, seen + (pof.get("name") or "",))
        moved = base.orientation != (0.0, 0.0, 0.0) or base.translation != (0.0, 0.0, 0.0)
        if moved and parent not in self.body_names:
            raise self.ctx.error("offset frames on offset frames are not supported", pof)
        return Offset(
            body=base.body,
            translation=tuple(self.ctx.floats(pof, "translation", 3, "0 0 0")),
            orientation=tuple(self.ctx.floats(pof, "orientation", 3, "0 0 0")),
        )

    def resolve(self, ref: str, local: dict[str, ET.Element], seen: tuple[str, ...] = ()) -> Offset:
        name = _strip_path(ref)
        if name in seen:
            raise self.ctx.error(f"frame {name!r} refers to itself")
        if name in local:
            return self.offset_from_elem(local[name], seen)
        if name in self.body_names:
            return Offset(body=name)
        if name in self.free_frames:
            return self.offset_from_elem(self.free_frames[name], seen)
        raise self.ctx.error(f"frame {ref!r} is neither a body nor an offset frame")


def _parse_joint_v4(ctx: _Ctx, elem: ET.Element, frames: _FrameResolver) -> tuple[Joint, list[Coordinate]]:
    local = {}
    fr = elem.find("frames")
    if fr is not None:
        for pof in fr:
            if pof.tag == "PhysicalOffsetFrame":
                local[pof.get("name") or ""] = pof
    parent = frames.resolve(ctx.text(elem, "socket_parent_frame"), local)
    child = frames.resolve(ctx.text(elem, "socket_child_frame"), local)
    return _finish_joint(ctx, elem, parent, child)


def _parse_joint_v3(ctx: _Ctx, elem: ET.Element, child_body: str) -> tuple[Joint, list[Coordinate]]:
    parent = Offset(
        body=ctx.text(elem, "parent_body"),
        translation=tuple(ctx.floats(elem, "location_in_parent", 3, "0 0 0")),
        orientation=tuple(ctx.floats(elem, "orientation_in_parent", 3, "0 0 0")),
    )
    child = Offset(
        body=child_body,
        translation=tuple(ctx.floats(elem, "location", 3, "0 0 0")),
        orientation=tuple(ctx.floats(elem, "orientation", 3, "0 0 0")),
    )
    return _finish_joint(ctx, elem, parent, child)


def _finish_joint(ctx: _Ctx, elem: ET.Element, parent: Offset, child: Offset) -> tuple[Joint, list[Coordinate]]:
    if elem.tag not in SUPPORTED_JOINTS:
        raise ctx.error(
            f"joint type {elem.tag} is not supported (supported: {', '.join(SUPPORTED_JOINTS)})", elem
        )
    if ctx.flag(elem, "reverse", False):
        raise ctx.error("reversed joints (<reverse>true</reverse>) are not supported", elem)
    name = elem.get("name") or ""
    celems = _coordinate_elems(elem)
    cnames = [c.get("name") or "" for c in celems]
    axes = _parse_axes(ctx, elem, cnames)
    coords = [_parse_coordinate(ctx, c, name, axes) for c in celems]
    joint = Joint(name, elem.tag, parent, child, tuple(cnames), axes)
    return joint, coords


def _refuse_coupler_chains(ctx: _Ctx, couplers: list[Coupler]) -> None:
    """Each dependent coordinate has one coupler, and no coupler is driven by another's
    dependent coordinate (chained couplers are not supported).

    Raises
    ------
    OsimModelError
        Naming the couplers and the coordinate.
    """
    driver: dict[str, str] = {}
    for c in couplers:
        if c.dependent in driver:
            raise ctx.error(f"coordinate {c.dependent!r} is the dependent coordinate of two couplers, "
                            f"{driver[c.dependent]} and {c.name}; expected one")
        driver[c.dependent] = c.name
    for c in couplers:
        if c.independent in driver:
            raise ctx.error(f"coupler {c.name} is driven by {c.independent!r}, which coupler {driver[c.independent]} "
                            "drives; chained couplers (a dependent coordinate driving another) are not supported")


def _sort_joints(ctx: _Ctx, joints: list[Joint]) -> list[Joint]:
    """Order joints depth-first from ground (children in declaration order).

    Depth-first order keeps every subtree contiguous, which pinocchio's algorithms
    (CRBA, subtree sizes) require. Every body must be the child of exactly one joint.
    """
    by_child: dict[str, Joint] = {}
    children: dict[str, list[Joint]] = {}
    for j in joints:
        if j.child.body == "ground":  # nothing moves ground: the depth-first walk would revisit it forever
            raise ctx.error(f"the child frame of joint {j.name} is on ground; a joint's child must be a body")
        if j.child.body in by_child:
            raise ctx.error(f"body {j.child.body!r} is the child of two joints (closed loops are not supported)")
        by_child[j.child.body] = j
        children.setdefault(j.parent.body, []).append(j)
    ordered: list[Joint] = []
    stack = list(reversed(children.get("ground", [])))
    while stack:
        j = stack.pop()
        ordered.append(j)
        stack.extend(reversed(children.get(j.child.body, [])))
    if len(ordered) != len(joints):
        placed = {j.name for j in ordered}
        names = ", ".join(f"{j.name} (parent {j.parent.body})" for j in joints if j.name not in placed)
        raise ctx.error(f"joints not connected to ground: {names}")
    return ordered


# ----------------------------------------------------------------------------- markers, constraints


def _parse_markers(ctx: _Ctx, root: ET.Element, frames: _FrameResolver | None) -> list[Marker]:
    markers = []
    ms = root.find("MarkerSet")
    if ms is None:
        return markers
    for m in ms.iter("Marker"):
        name = m.get("name") or ""
        if m.find("socket_parent_frame") is not None and frames is not None:
            off = frames.resolve(ctx.text(m, "socket_parent_frame"), {})
        else:
            off = Offset(body=_strip_path(ctx.text(m, "body")))
        loc = np.array(ctx.floats(m, "location", 3, "0 0 0"))
        if off.translation != (0.0, 0.0, 0.0) or off.orientation != (0.0, 0.0, 0.0):
            loc = off.rotation() @ loc + np.array(off.translation)
        markers.append(Marker(name, off.body, tuple(float(v) for v in loc), ctx.flag(m, "fixed", False)))
    return markers


def _parse_couplers(ctx: _Ctx, root: ET.Element) -> list[Coupler]:
    out = []
    cs = root.find("ConstraintSet")
    if cs is None:
        return out
    for c in cs.iter():
        if c.tag == "CoordinateCouplerConstraint":
            enforced = ctx.flag(c, "isEnforced", True) and not ctx.flag(c, "isDisabled", False)
            if not enforced:
                continue
            indep = ctx.text(c, "independent_coordinate_names").split()
            if len(indep) != 1:
                raise ctx.error("coupler constraints with several independent coordinates are not supported", c)
            out.append(
                Coupler(
                    name=c.get("name") or "",
                    dependent=ctx.text(c, "dependent_coordinate_name"),
                    independent=indep[0],
                    function=_parse_function(ctx, _find_function(ctx, c)),
                    scale_factor=ctx.floats(c, "scale_factor", 1, "1")[0],
                )
            )
        elif c.tag.endswith("Constraint") and c.tag not in ("ConstraintSet",):
            enforced = ctx.flag(c, "isEnforced", True) and not ctx.flag(c, "isDisabled", False)
            if enforced:
                raise ctx.error(f"constraint type {c.tag} is not supported", c)
    return out


# ----------------------------------------------------------------------------- entry point


def is_v3_layout(model_elem: ET.Element) -> bool:
    """True for the OpenSim 3.x layout (joints inside bodies, no populated JointSet)."""
    jointset = model_elem.find("JointSet")
    return jointset is None or len(list(jointset.iter())) <= 1 or jointset.find(".//*[@name]") is None


def _refuse_duplicates(ctx: _Ctx, kind: str, names: list[str], elem: ET.Element | None) -> None:
    """Raise OsimModelError naming the first ``kind`` name that two components share."""
    seen: set[str] = set()
    for n in names:
        if n in seen:
            raise ctx.error(f"two {kind} components are named {n!r}; expected unique {kind} names", elem)
        seen.add(n)


def read_osim(path: str | Path) -> OsimModel:
    """Parse an OpenSim model file.

    Parameters
    ----------
    path
        An .osim file (OpenSim 4.x format, or the 3.x layout with joints inside bodies).

    Returns
    -------
    OsimModel

    Raises
    ------
    OsimModelError
        Unreadable XML, missing elements, unsupported joint/function/constraint types,
        a coupler naming an unknown coordinate, a marker on an unknown body; the message
        names the file and the element.
    FileNotFoundError
        If ``path`` does not exist.
    """
    path = str(path)
    ctx = _Ctx(path)
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        line = exc.position[0] if hasattr(exc, "position") else None
        raise OsimModelError(f"not well-formed XML: {exc}", path=path, line=line) from None
    doc = tree.getroot()
    ctx.document = doc
    root = doc.find("Model")
    if root is None:
        raise OsimModelError("no <Model> element under the document root", path=path)
    bodyset = root.find("BodySet")
    if bodyset is None:
        raise ctx.error("no <BodySet>", root)
    body_elems = [b for b in bodyset.iter("Body") if b.get("name") != "ground"]
    bodies = [_parse_body(ctx, b) for b in body_elems]
    _refuse_duplicates(ctx, "body", [b.name for b in bodies], bodyset)
    if not sum(b.mass for b in bodies) > 0:
        raise ctx.error("every body has zero mass; expected the segments' masses in kg", bodyset)
    names = {b.name for b in bodies}
    joints: list[Joint] = []
    coords: list[Coordinate] = []
    jointset = root.find("JointSet")
    frames = None
    if not is_v3_layout(root):  # 4.x
        free = {}
        for container in ("ComponentSet", "FrameSet", "components"):
            c = root.find(container)
            if c is not None:
                free.update({e.get("name") or "": e for e in c.iter("PhysicalOffsetFrame")})
        frames = _FrameResolver(ctx, names, free)
        objs = jointset.find("objects")
        for j in list(objs if objs is not None else jointset):
            if j.tag in ("objects", "groups"):
                continue
            joint, cs = _parse_joint_v4(ctx, j, frames)
            joints.append(joint)
            coords.extend(cs)
    else:  # 3.x: <Body><Joint><XJoint>
        for b in body_elems:
            jholder = b.find("Joint")
            if jholder is None:
                continue
            for j in list(jholder):
                joint, cs = _parse_joint_v3(ctx, j, b.get("name") or "")
                joints.append(joint)
                coords.extend(cs)
    if not joints:
        raise ctx.error("the model has no joints", root)
    for j in joints:
        for off in (j.parent, j.child):
            if off.body not in names and off.body != "ground":
                raise ctx.error(f"joint {j.name} refers to unknown body {off.body!r}")
    _refuse_duplicates(ctx, "joint", [j.name for j in joints], root)
    _refuse_duplicates(ctx, "coordinate", [c.name for c in coords], root)
    joints = _sort_joints(ctx, joints)
    cnames = {c.name for c in coords}
    couplers = _parse_couplers(ctx, root)
    for c in couplers:
        for n in (c.dependent, c.independent):
            if n not in cnames:
                raise ctx.error(f"coupler {c.name} names unknown coordinate {n!r}")
    _refuse_coupler_chains(ctx, couplers)
    markers = _parse_markers(ctx, root, frames)
    _refuse_duplicates(ctx, "marker", [m.name for m in markers], root.find("MarkerSet"))
    for m in markers:
        if m.body not in names and m.body != "ground":
            raise ctx.error(f"marker {m.name} is on unknown body {m.body!r}")
    gravity = ctx.floats(root, "gravity", 3, " ".join(map(str, GRAVITY_VECTOR)))
    return OsimModel(
        name=root.get("name") or Path(path).stem,
        bodies=tuple(bodies),
        joints=tuple(joints),
        coordinates=tuple(coords),
        couplers=tuple(couplers),
        markers=tuple(markers),
        gravity=tuple(gravity),
        source=path,
    )
