"""Bone meshes of OpenSim models: VTK XML PolyData (``.vtp``) -> :class:`trimesh.Trimesh`.

trimesh and meshio do not read ``.vtp`` and the ``vtk`` wheel is large, so this is a small
reader with :mod:`xml.etree` and numpy. It reads the ``Points`` and the ``Polys`` and
``Strips`` cells, each DataArray in ``ascii`` or inline ``binary`` (base64, raw or
``vtkZLibDataCompressor``, ``UInt32`` or ``UInt64`` headers, either byte order).
Polygons with more than three vertices are fan-triangulated, strips are split into
triangles. ``appended`` data is not supported (OpenSim's Geometry files do not use it).

Vertices are in the body frame, metres; :func:`body_mesh` looks the files up along a
search path (:mod:`addb_viewer.geometry`), merges the meshes attached to one body, each
multiplied by its scale factors, and caches what it read.
"""

from __future__ import annotations

import base64
import binascii
import functools
import os
import xml.etree.ElementTree as ET
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import trimesh
from numpy.typing import NDArray

from addb_viewer.app.paths import UnsafePathError
from addb_viewer.geometry import find_mesh
from solver.errors import FileFormatError

_TYPES = {
    "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4",
    "UInt32": "u4", "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8",
}


class VtpFormatError(FileFormatError):
    """A ``.vtp`` file is not PolyData we can read (message names the file and array)."""


def read_vtp(path: str | os.PathLike[str]) -> trimesh.Trimesh:
    """Read a VTK XML PolyData file as a triangle mesh.

    Parameters
    ----------
    path
        The ``.vtp`` file.

    Returns
    -------
    trimesh.Trimesh
        ``vertices (V, 3)`` as in the file (float64, no scaling) and ``faces (F, 3)``;
        built with ``process=False`` so vertices are neither merged nor reordered.

    Raises
    ------
    VtpFormatError
        Not XML, not PolyData, an unsupported encoding, or cells that index missing points.
    """
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except (ET.ParseError, OSError) as exc:
        raise VtpFormatError(f"cannot read as VTK XML: {exc}", path=p) from None
    if root.tag != "VTKFile" or root.get("type") != "PolyData":
        raise VtpFormatError("not a VTKFile of type PolyData", path=p)
    enc = _Encoding.of(root, p)
    pieces = root.findall("PolyData/Piece")
    if not pieces:
        raise VtpFormatError("no PolyData/Piece element", path=p)
    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    n = 0
    for piece in pieces:
        v, f = _read_piece(piece, enc)
        verts.append(v)
        faces.append(f + n)
        n += len(v)
    vertices = np.concatenate(verts) if verts else np.zeros((0, 3))
    tris = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    return trimesh.Trimesh(vertices=vertices, faces=tris, process=False)


class _Encoding:
    """How binary DataArrays of one file are encoded (header type, byte order, compression)."""

    def __init__(self, header: np.dtype, order: str, compressed: bool, path: Path) -> None:
        self.header = header
        self.order = order
        self.compressed = compressed
        self.path = path

    @classmethod
    def of(cls, root: ET.Element, path: Path) -> _Encoding:
        order = ">" if root.get("byte_order") == "BigEndian" else "<"
        htype = root.get("header_type", "UInt32")
        if htype not in ("UInt32", "UInt64"):
            raise VtpFormatError(f"unsupported header_type {htype!r}", path=path)
        compressor = root.get("compressor")
        if compressor not in (None, "", "vtkZLibDataCompressor"):
            raise VtpFormatError(f"unsupported compressor {compressor!r} (only zlib)", path=path)
        return cls(np.dtype(order + _TYPES[htype]), order, bool(compressor), path)

    def array(self, elem: ET.Element) -> np.ndarray:
        """The values of one DataArray element, flattened."""
        name = elem.get("Name") or elem.tag
        typ = elem.get("type")
        if typ not in _TYPES:
            raise VtpFormatError(f"unsupported DataArray type {typ!r}", path=self.path, where=name)
        dtype = np.dtype(self.order + _TYPES[typ])
        fmt = elem.get("format", "ascii")
        text = elem.text or ""
        try:
            if fmt == "ascii":
                return np.array(text.split(), dtype=dtype.newbyteorder("="))
            if fmt == "binary":
                return np.frombuffer(self._binary("".join(text.split())), dtype=dtype)
        except (ValueError, binascii.Error, zlib.error) as exc:
            raise VtpFormatError(f"bad {fmt} data: {exc}", path=self.path, where=name) from None
        raise VtpFormatError(
            f"DataArray format {fmt!r} not supported (ascii or inline binary)",
            path=self.path,
            where=name,
        )

    def _binary(self, b64: str) -> bytes:
        size = self.header.itemsize
        if not self.compressed:
            head, body = _split_header(b64, size)
            (nbytes,) = np.frombuffer(head, self.header, count=1)
            if len(body) < nbytes:
                raise ValueError(f"{len(body)} bytes of data, header says {int(nbytes)}")
            return body[: int(nbytes)]
        first = base64.b64decode(b64[: _b64_len(3 * size)])
        n_blocks = int(np.frombuffer(first, self.header, count=1)[0])
        head, body = _split_header(b64, (3 + n_blocks) * size)
        sizes = np.frombuffer(head, self.header, count=3 + n_blocks).astype(np.int64)
        out, pos = [], 0
        for s in sizes[3:]:
            out.append(zlib.decompress(body[pos : pos + int(s)]))
            pos += int(s)
        return b"".join(out)


def _b64_len(nbytes: int) -> int:
    return 4 * -(-nbytes // 3)


def _split_header(b64: str, nbytes: int) -> tuple[bytes, bytes]:
    """Split base64 text into its ``nbytes`` header and the rest.

    VTK encodes the header and the data as two base64 runs; some writers encode them as
    one. The two agree when ``nbytes`` is a multiple of 3; otherwise a padded header
    ('=' at the end of its run) tells that it was encoded alone.
    """
    n = _b64_len(nbytes)
    if nbytes % 3 == 0 or b64[n - 1 : n] == "=":
        return base64.b64decode(b64[:n], validate=True)[:nbytes], base64.b64decode(b64[n:], validate=True)
    raw = base64.b64decode(b64, validate=True)
    return raw[:nbytes], raw[nbytes:]


def _read_piece(piece: ET.Element, enc: _Encoding) -> tuple[np.ndarray, np.ndarray]:
    pts = piece.find("Points/DataArray")
    if pts is None:
        raise VtpFormatError("Piece has no Points/DataArray", path=enc.path)
    vertices = enc.array(pts).astype(np.float64)
    if vertices.size % 3:
        raise VtpFormatError(f"{vertices.size} point coordinates is not a multiple of 3", path=enc.path)
    vertices = vertices.reshape(-1, 3)
    declared = piece.get("NumberOfPoints")
    if declared is not None and int(declared) != len(vertices):
        raise VtpFormatError(f"NumberOfPoints={declared} but {len(vertices)} points", path=enc.path)
    faces = [
        fan_triangulate(*_cells(piece, "Polys", enc)),
        strip_triangulate(*_cells(piece, "Strips", enc)),
    ]
    tris = np.concatenate(faces)
    if tris.size and (tris.min() < 0 or tris.max() >= len(vertices)):
        raise VtpFormatError(f"a cell indexes a point outside 0..{len(vertices) - 1}", path=enc.path)
    return vertices, tris


def _cells(piece: ET.Element, kind: str, enc: _Encoding) -> tuple[np.ndarray, np.ndarray]:
    """``connectivity`` and ``offsets`` (end of each cell) of a cell block, or empty arrays."""
    block = piece.find(kind)
    empty = np.zeros(0, np.int64)
    if block is None:
        return empty, empty
    arrays = {a.get("Name"): a for a in block.findall("DataArray")}
    if "connectivity" not in arrays or "offsets" not in arrays:
        if not arrays:
            return empty, empty
        raise VtpFormatError(f"{kind} needs connectivity and offsets arrays", path=enc.path)
    conn = enc.array(arrays["connectivity"]).astype(np.int64)
    offsets = enc.array(arrays["offsets"]).astype(np.int64)
    if offsets.size and (np.any(np.diff(offsets) < 0) or offsets[0] < 0 or offsets[-1] != conn.size):
        raise VtpFormatError(f"{kind} offsets do not describe the connectivity array", path=enc.path)
    return conn, offsets


def fan_triangulate(connectivity: NDArray[np.int64], offsets: NDArray[np.int64]) -> NDArray[np.int64]:
    """Triangles ``(F, 3)`` of polygons given as VTK ``connectivity`` and end ``offsets``.

    A polygon ``(v0, v1, ..., vk-1)`` gives the fan ``(v0, vi, vi+1)``, ``i = 1..k-2``;
    polygons of fewer than three vertices give nothing.
    """
    if offsets.size == 0:
        return np.zeros((0, 3), np.int64)
    starts = np.concatenate(([0], offsets[:-1])).astype(np.int64)
    sizes = offsets - starts
    out = [np.zeros((0, 3), np.int64)]
    for k in np.unique(sizes[sizes >= 3]):
        s = starts[sizes == k][:, None]
        i = np.arange(1, k - 1)[None, :]
        tri = np.stack(
            [np.broadcast_to(connectivity[s], (s.shape[0], k - 2)), connectivity[s + i], connectivity[s + i + 1]],
            axis=2,
        )
        out.append(tri.reshape(-1, 3))
    return np.concatenate(out)


def strip_triangulate(connectivity: NDArray[np.int64], offsets: NDArray[np.int64]) -> NDArray[np.int64]:
    """Triangles ``(F, 3)`` of VTK triangle strips, alternating the winding as VTK does."""
    if offsets.size == 0:
        return np.zeros((0, 3), np.int64)
    starts = np.concatenate(([0], offsets[:-1])).astype(np.int64)
    out = [np.zeros((0, 3), np.int64)]
    for s, e in zip(starts, offsets, strict=True):
        strip = connectivity[s:e]
        if strip.size < 3:
            continue
        j = np.arange(strip.size - 2)
        a, b, c = strip[j], strip[j + 1], strip[j + 2]
        odd = (j % 2) == 1
        out.append(np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1))
    return np.concatenate(out)


@functools.lru_cache(maxsize=512)
def _read_cached(path: str, mtime_ns: int, size: int) -> trimesh.Trimesh:
    return read_vtp(path)


def cached_vtp(path: str | os.PathLike[str]) -> trimesh.Trimesh:
    """:func:`read_vtp` with a cache keyed by path, modification time and size.

    The returned mesh is shared: copy it before changing it.
    """
    st = os.stat(path)
    return _read_cached(str(Path(path).resolve()), st.st_mtime_ns, st.st_size)


def body_mesh(
    search_path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    meshes: list[tuple[str, tuple[float, float, float]]],
) -> tuple[trimesh.Trimesh | None, list[str]]:
    """The meshes attached to one body, each scaled, merged into one mesh.

    Parameters
    ----------
    search_path
        The folders mesh files are looked up in, first match wins
        (:func:`addb_viewer.geometry.mesh_search_path`), or one folder; a file is taken
        only inside the folder it is found in.
    meshes
        ``(file name, (3,) scale factors)`` pairs, as in ``ProcessedTrial.body_meshes``.

    Returns
    -------
    mesh
        Merged mesh in the body frame (m), or None when no file could be read.
    problems
        One message per file that is missing from every folder, outside them or
        unreadable (the other meshes are still used).
    """
    folders = (
        (search_path,) if isinstance(search_path, (str, os.PathLike)) else tuple(search_path)
    )
    parts: list[trimesh.Trimesh] = []
    problems: list[str] = []
    for name, scale in meshes:
        try:
            path = find_mesh(name, folders)
            if path is None:
                raise FileNotFoundError(name)
            m = cached_vtp(path)
        except FileNotFoundError:
            where = ", ".join(str(f) for f in folders) or "no folder"
            problems.append(f"mesh file {name} not found in {where}")
            continue
        except (UnsafePathError, VtpFormatError, OSError) as exc:
            problems.append(str(exc))
            continue
        parts.append(
            trimesh.Trimesh(vertices=m.vertices * np.asarray(scale, float), faces=m.faces, process=False)
        )
    if not parts:
        return None, problems
    if len(parts) == 1:
        return parts[0], problems
    return trimesh.util.concatenate(parts), problems
