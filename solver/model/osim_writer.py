"""Write an :class:`OsimModel` back to an .osim file that OpenSim 4.6 loads.

The writer starts from the model's source file and updates, in place, what the solver
changes: body masses, centres of mass, inertias and mesh scale factors; joint offset
frames; joint functions (scaled translations become MultiplierFunctions); the marker
set (locations, added markers); muscle path points are scaled with their body when
``path_point_scales`` is given. Everything else (muscles, wrap objects, controllers)
is kept as it was. Both the 4.x layout and the 3.x layout (joints inside bodies) are
updated in their own layout; OpenSim 4.6 upgrades a 3.x file when it loads it.

The file is written to a temporary name in the target folder and renamed into place.
"""

from __future__ import annotations

import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from solver.errors import OsimModelError
from solver.files import as_created
from solver.model import functions as fn
from solver.model.osim import _FUNCTION_TAGS, Joint, OsimModel, is_v3_layout


def _fmt(values: ArrayLike) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(values, dtype=float).reshape(-1))


def _set(parent: ET.Element, tag: str, text: str) -> None:
    child = parent.find(tag)
    if child is None:
        child = ET.SubElement(parent, tag)
    child.text = text


def function_element(function: fn.Function, name: str | None = "function") -> ET.Element:
    """XML element of an OpenSim function (``name`` attribute as the 4.x layout uses).

    Raises
    ------
    OsimModelError
        ``function``, or the function a ``Multiplier`` scales, is of an unsupported type.
    """
    attrs = {"name": name} if name else {}
    if isinstance(function, fn.Multiplier):
        el = ET.Element("MultiplierFunction", attrs)
        ET.SubElement(el, "function").append(function_element(function.inner, "function"))
        ET.SubElement(el, "scale").text = repr(float(function.scale))
        return el
    if isinstance(function, fn.Constant):
        el = ET.Element("Constant", attrs)
        ET.SubElement(el, "value").text = repr(float(function.c))
        return el
    if isinstance(function, fn.Linear):
        el = ET.Element("LinearFunction", attrs)
        ET.SubElement(el, "coefficients").text = _fmt([function.slope, function.intercept])
        return el
    if isinstance(function, fn.Polynomial):
        el = ET.Element("PolynomialFunction", attrs)
        ET.SubElement(el, "coefficients").text = _fmt(function.coefficients)
        return el
    if isinstance(function, fn.CubicSpline):
        el = ET.Element("SimmSpline" if function.kind == "fmm" else "NaturalCubicSpline", attrs)
        ET.SubElement(el, "x").text = _fmt(function.x)
        ET.SubElement(el, "y").text = _fmt(function.y)
        return el
    if isinstance(function, fn.PiecewiseLinear):
        el = ET.Element("PiecewiseLinearFunction", attrs)
        ET.SubElement(el, "x").text = _fmt(function.x)
        ET.SubElement(el, "y").text = _fmt(function.y)
        return el
    raise OsimModelError(f"cannot write function of type {type(function).__name__}")


def _replace_function(ta: ET.Element, function: fn.Function, v3: bool) -> None:
    """Replace the function of a TransformAxis element, keeping the file's layout."""
    holder = ta.find("function") if v3 else ta
    if holder is None:
        holder = ta
    for child in list(holder):
        if child.tag in _FUNCTION_TAGS:
            holder.remove(child)
    holder.append(function_element(function, None if v3 else "function"))


def _update_bodies(root: ET.Element, model: OsimModel, v3: bool) -> None:
    by_name = {b.name: b for b in model.bodies}
    for el in root.find("BodySet").iter("Body"):  # type: ignore[union-attr]
        b = by_name.get(el.get("name") or "")
        if b is None:
            continue
        _set(el, "mass", repr(b.mass))
        _set(el, "mass_center", _fmt(b.com))
        inertia = np.array(b.inertia)
        six = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
        if v3:
            for k, v in zip(("xx", "yy", "zz", "xy", "xz", "yz"), six):
                _set(el, f"inertia_{k}", repr(float(v)))
        else:
            _set(el, "inertia", _fmt(six))
        meshes = [m for m in el.iter("Mesh") if (m.findtext("mesh_file") or "").strip()]
        meshes += [g for g in el.iter("DisplayGeometry") if (g.findtext("geometry_file") or "").strip()]
        for m_el, mesh in zip(meshes, b.meshes):
            _set(m_el, "scale_factors", _fmt(mesh.scale))


def _joint_elements(root: ET.Element, v3: bool) -> dict[str, ET.Element]:
    if v3:
        out = {}
        for b in root.find("BodySet").iter("Body"):  # type: ignore[union-attr]
            holder = b.find("Joint")
            for j in list(holder) if holder is not None else []:
                out[j.get("name") or ""] = j
        return out
    jointset = root.find("JointSet")
    objs = jointset.find("objects") if jointset is not None else None
    container = objs if objs is not None else jointset
    return {j.get("name") or "": j for j in list(container if container is not None else []) if j.get("name")}


def _update_joint(el: ET.Element, joint: Joint, v3: bool) -> None:
    if v3:
        _set(el, "location_in_parent", _fmt(joint.parent.translation))
        _set(el, "location", _fmt(joint.child.translation))
    else:
        frames = {f.get("name"): f for f in el.iter("PhysicalOffsetFrame")}
        for sock, off in (("socket_parent_frame", joint.parent), ("socket_child_frame", joint.child)):
            ref = (el.findtext(sock) or "").strip().rstrip("/").split("/")[-1]
            if ref in frames:
                _set(frames[ref], "translation", _fmt(off.translation))
            elif any(off.translation):
                raise OsimModelError(f"joint {joint.name}: cannot store a translated {sock} on {ref!r}")
    if joint.type == "CustomJoint":
        tas = list(el.iter("TransformAxis"))
        for ta, axis in zip(tas, joint.axes):
            _replace_function(ta, axis.function, v3)


def _update_markers(root: ET.Element, model: OsimModel, v3: bool) -> None:
    ms = root.find("MarkerSet")
    if ms is None:
        ms = ET.SubElement(root, "MarkerSet")
    objs = ms.find("objects")
    if objs is None:
        objs = ET.SubElement(ms, "objects")
    for old in list(objs):
        objs.remove(old)
    for m in model.markers:
        el = ET.SubElement(objs, "Marker", {"name": m.name})
        if v3:
            ET.SubElement(el, "body").text = m.body
        else:
            parent = "/ground" if m.body == "ground" else f"/bodyset/{m.body}"
            ET.SubElement(el, "socket_parent_frame").text = parent
        ET.SubElement(el, "location").text = _fmt(m.location)
        ET.SubElement(el, "fixed").text = "true" if m.fixed else "false"


def _scale_path_points(root: ET.Element, scales: Mapping[str, ArrayLike], v3: bool) -> None:
    for tag in ("PathPoint", "ConditionalPathPoint"):
        for pp in root.iter(tag):
            ref = pp.findtext("body") if v3 else pp.findtext("socket_parent_frame")
            body = (ref or "").strip().rstrip("/").split("/")[-1]
            loc = pp.find("location")
            if body in scales and loc is not None and loc.text:
                vals = np.array([float(v) for v in loc.text.split()]) * np.asarray(scales[body], dtype=float)
                loc.text = _fmt(vals)


def write_osim(
    model: OsimModel,
    path: str | Path,
    *,
    name: str | None = None,
    path_point_scales: Mapping[str, ArrayLike] | None = None,
) -> Path:
    """Write ``model`` as an .osim file, starting from its source file.

    Parameters
    ----------
    model
        The model to write (typically scaled and mass-fitted).
    path
        Output file.
    name
        Model name to write (default: unchanged).
    path_point_scales
        Body name -> ``(3,)`` scale factors along the body's axes (unitless) to apply to
        muscle path points (the same as given to :func:`solver.model.scaling.scale_model`);
        None leaves them unchanged.

    Returns
    -------
    Path of the written file.

    Raises
    ------
    OsimModelError
        If the source file is missing or unreadable, or the model does not fit it.
    """
    try:
        tree = ET.parse(model.source)
    except (OSError, ET.ParseError) as exc:
        raise OsimModelError(f"cannot re-read the source model: {exc}", path=model.source) from None
    root = tree.getroot().find("Model")
    if root is None:
        raise OsimModelError("no <Model> element", path=model.source)
    v3 = is_v3_layout(root)
    if name:
        root.set("name", name)
    _update_bodies(root, model, v3)
    elems = _joint_elements(root, v3)
    for joint in model.joints:
        if joint.name not in elems:
            raise OsimModelError(f"joint {joint.name} not found in the source file", path=model.source)
        _update_joint(elems[joint.name], joint, v3)
    _update_markers(root, model, v3)
    if path_point_scales:
        _scale_path_points(root, path_point_scales, v3)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            ET.indent(tree, space="\t")
            tree.write(fh, encoding="UTF-8", xml_declaration=True)
        as_created(tmp)  # mkstemp's 0600 would keep the model from the other users of a lab server
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
