"""OpenSim ExternalLoads XML: which plate's columns push on which body.

Read and written with :mod:`xml.etree.ElementTree`. The reader accepts the 3.x and
4.x documents (``<OpenSimDocument Version="30000"|"40000">``), ignores ``<defaults>``
and comments, and keeps only what the solver needs. The writer produces a 4.x document
that OpenSim 4.6 loads (``opensim.ExternalLoads(path, True)``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from solver.errors import XmlFormatError
from solver.io.force_columns import group_plates

_FIELDS = (
    "applied_to_body",
    "force_expressed_in_body",
    "point_expressed_in_body",
    "force_identifier",
    "point_identifier",
    "torque_identifier",
    "data_source_name",
)


@dataclass(frozen=True)
class ExternalForce:
    """One ``<ExternalForce>``: a force/point/torque column set applied to a body.

    Attributes
    ----------
    name
        The element's ``name`` attribute (``Right_GRF``).
    applied_to_body
        Body the force acts on (``calcn_r``).
    force_expressed_in_body, point_expressed_in_body
        Frames of the force vector and of the point (``ground`` for plate data).
    force_identifier, point_identifier, torque_identifier
        Column-name prefixes in the data file (``ground_force_r_v`` + x/y/z);
        ``torque_identifier`` is ``""`` when the file has no torque columns.
    data_source_name
        The data source (``Unassigned`` in most files; the ``datafile`` is used).
    """

    name: str
    applied_to_body: str
    force_expressed_in_body: str = "ground"
    point_expressed_in_body: str = "ground"
    force_identifier: str = ""
    point_identifier: str = ""
    torque_identifier: str = ""
    data_source_name: str = "Unassigned"


@dataclass(frozen=True)
class ExternalLoads:
    """An ExternalLoads document.

    Attributes
    ----------
    name
        The ``<ExternalLoads name=...>`` attribute.
    forces
        The external forces, in file order.
    datafile
        The ``<datafile>`` text as written (often relative to the XML file's folder).
    source
        Path of the XML file ("" if built in memory).
    """

    name: str
    forces: tuple[ExternalForce, ...]
    datafile: str = ""
    source: str = ""

    def datafile_path(self) -> Path | None:
        """``datafile`` resolved against the XML file's folder (None when empty)."""
        if not self.datafile:
            return None
        p = Path(self.datafile)
        return p if p.is_absolute() or not self.source else Path(self.source).parent / p


def read_external_loads(path: str | Path) -> ExternalLoads:
    """Read an OpenSim ExternalLoads XML file.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    XmlFormatError
        Not well-formed XML (with the parser's line), no ``<ExternalLoads>`` element
        (naming the root found), an ``<ExternalForce>`` without a name or without
        ``applied_to_body``/``force_identifier``/``point_identifier``, or two forces
        with the same name.
    """
    path = Path(path)
    root = _parse(path)
    loads = root if root.tag == "ExternalLoads" else root.find("ExternalLoads")
    if loads is None:
        inner = [child.tag for child in root]
        raise XmlFormatError(
            f"expected an <ExternalLoads> element, found <{root.tag}> containing "
            f"{', '.join('<' + t + '>' for t in inner[:3]) or 'nothing'}",
            path=path,
            where=root.tag,
        )
    forces = []
    names: set[str] = set()
    objects = loads.find("objects")
    for elem in [] if objects is None else objects.findall("ExternalForce"):
        force = _external_force(elem, path)
        if force.name in names:
            raise XmlFormatError(
                f"two ExternalForce elements are named {force.name!r}",
                path=path,
                where=f"ExternalForce {force.name}",
            )
        names.add(force.name)
        forces.append(force)
    datafile = (loads.findtext("datafile") or "").strip()
    return ExternalLoads(loads.get("name", ""), tuple(forces), datafile, str(path))


def _parse(path: Path) -> ET.Element:
    if not path.is_file():
        raise FileNotFoundError(2, "No such file", str(path))
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        line = exc.position[0] if exc.position else None
        raise XmlFormatError(f"not well-formed XML: {exc}", path=path, line=line) from None


def _external_force(elem: ET.Element, path: Path) -> ExternalForce:
    name = elem.get("name")
    if not name:
        raise XmlFormatError(
            "an <ExternalForce> has no name attribute", path=path, where="ExternalForce"
        )
    values = {f: (elem.findtext(f) or "").strip() for f in _FIELDS}
    for required in ("applied_to_body", "force_identifier", "point_identifier"):
        if not values[required]:
            raise XmlFormatError(
                f"<{required}> is missing or empty; expected e.g. calcn_r / ground_force_r_v",
                path=path,
                where=f"ExternalForce {name}",
            )
    for frame in ("force_expressed_in_body", "point_expressed_in_body"):
        values[frame] = values[frame] or "ground"
    values["data_source_name"] = values["data_source_name"] or "Unassigned"
    return ExternalForce(name=name, **values)


def write_external_loads(path: str | Path, loads: ExternalLoads) -> None:
    """Write an ExternalLoads XML file (OpenSim 4.x format) that OpenSim 4.6 loads.

    ``read_external_loads(path)`` returns ``loads`` again (except ``source``).

    Raises
    ------
    XmlFormatError
        An external force without a name or body, or a repeated name.
    """
    names = [f.name for f in loads.forces]
    for force in loads.forces:
        if not force.name or not force.applied_to_body or names.count(force.name) > 1:
            raise XmlFormatError(
                f"external force {force.name!r}: needs a unique name and applied_to_body",
                path=path,
                where=f"ExternalForce {force.name}",
            )
    doc = ET.Element("OpenSimDocument", Version="40000")
    root = ET.SubElement(doc, "ExternalLoads", name=loads.name or Path(path).stem)
    objects = ET.SubElement(root, "objects")
    for force in loads.forces:
        elem = ET.SubElement(objects, "ExternalForce", name=force.name)
        for field in _FIELDS:
            ET.SubElement(elem, field).text = getattr(force, field)
    ET.SubElement(root, "groups")
    ET.SubElement(root, "datafile").text = loads.datafile
    ET.indent(doc, space="\t")
    tree = ET.ElementTree(doc)
    tree.write(path, encoding="UTF-8", xml_declaration=True)


def plates_by_force(loads: ExternalLoads, columns: Sequence[str]) -> dict[str, str]:
    """Map each external force's name to the name of its plate in :func:`read_forces` output.

    Parameters
    ----------
    loads
        The ExternalLoads document.
    columns
        Column names of the force data file (``Table.column_names``).

    Raises
    ------
    XmlFormatError
        A ``force_identifier`` that matches no plate's force columns.
    """
    plates = group_plates(columns)
    by_identifier = {p.force_identifier: p.name for p in plates}
    out = {}
    for force in loads.forces:
        plate = by_identifier.get(force.force_identifier)
        if plate is None:
            raise XmlFormatError(
                f"force_identifier {force.force_identifier!r} matches no plate's columns; "
                f"the data has {sorted(by_identifier) or 'no force columns'}",
                path=loads.source or None,
                where=f"ExternalForce {force.name}",
            )
        out[force.name] = plate
    return out
