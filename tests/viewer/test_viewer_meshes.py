"""VTP reader (addb_viewer.app.meshes): vertex and triangle counts of the real OpenSim
Geometry files (shared data and the set bundled with addb), every inline binary encoding VTK
writes, strips, polygons, bad files, and merging/scaling per body."""

from __future__ import annotations

import base64
import re
import zlib
from pathlib import Path

import numpy as np
import pytest

from addb_viewer.app.meshes import (
    VtpFormatError,
    body_mesh,
    fan_triangulate,
    read_vtp,
    strip_triangulate,
)
from addb_viewer.demo import DEMO_SUBJECT
from addb_viewer.geometry import BUNDLED_GEOMETRY


def _declared(path: Path) -> tuple[int, int, int]:
    """NumberOfPoints, and the triangles a fan triangulation gives, from the file's text."""
    text = path.read_text()
    n_points = int(re.search(r'NumberOfPoints="(\d+)"', text).group(1))
    polys = text.split("<Polys>")[1]
    offsets = np.array(polys.split('Name="offsets"')[1].split(">", 1)[1].split("<")[0].split(), int)
    sizes = np.diff(np.concatenate(([0], offsets)))
    return n_points, int(np.sum(np.maximum(sizes - 2, 0))), int(sizes.size)


def _model_meshes(model: Path) -> list[str]:
    return sorted(set(re.findall(r"<(?:mesh_file|geometry_file)>\s*([^<\s]+)\s*<", model.read_text())))


def test_every_bundled_geometry_file_matches_its_declared_counts(shared_data: Path) -> None:
    files = sorted(BUNDLED_GEOMETRY.glob("*.vtp"))
    assert len(files) >= 100
    for f in files:
        mesh = read_vtp(f)
        assert len(mesh.faces) > 0, f.name
        # every file (hat_ribs_scap.vtp too, whose <Strips> is empty): counts from its text
        n_points, n_tris, _ = _declared(f)
        assert len(mesh.vertices) == n_points, f.name
        assert len(mesh.faces) == n_tris, f.name
        # a byte-for-byte copy of opensim-models' file in the shared data
        assert f.read_bytes() == (shared_data / "models" / "Geometry" / f.name).read_bytes(), f.name


def test_rajagopal_meshes_match_vtk_counts(shared_data: Path) -> None:
    names = _model_meshes(DEMO_SUBJECT / "unscaled_generic.osim")
    assert len(names) == 81
    total_v = total_f = 0
    for name in names:
        mesh = read_vtp(shared_data / "models" / "Geometry" / name)
        n_points, n_tris, _ = _declared(shared_data / "models" / "Geometry" / name)
        assert (len(mesh.vertices), len(mesh.faces)) == (n_points, n_tris), name
        total_v += len(mesh.vertices)
        total_f += len(mesh.faces)
    # figures measured with vtk's reader (notes/libraries.md section 4)
    assert (total_v, total_f) == (30751, 60856)


def test_known_file_in_the_bundled_set() -> None:
    femur = read_vtp(BUNDLED_GEOMETRY / "r_femur.vtp")
    assert femur.vertices.shape == (132, 3) and femur.faces.shape == (265, 3)
    assert 0.3 < np.ptp(femur.vertices[:, 1]) < 0.6  # a femur is ~0.4 m long
    skull = read_vtp(BUNDLED_GEOMETRY / "hat_skull.vtp")  # has polygons of > 3 vertices
    _, n_tris, n_polys = _declared(BUNDLED_GEOMETRY / "hat_skull.vtp")
    assert len(skull.faces) == n_tris > n_polys


def _vtp(points: np.ndarray, conn: np.ndarray, offsets: np.ndarray, *, encoder, header="UInt32",
         order="LittleEndian", compressor="", cells="Polys") -> str:
    comp = f' compressor="{compressor}"' if compressor else ""
    fmt = "ascii" if encoder is None else "binary"

    def arr(name, typ, data):
        body = " ".join(str(x) for x in data.ravel()) if encoder is None else encoder(data)
        return f'<DataArray type="{typ}" Name="{name}" NumberOfComponents="1" format="{fmt}">{body}</DataArray>'

    return (
        f'<?xml version="1.0"?><VTKFile type="PolyData" version="1.0" byte_order="{order}" header_type="{header}"{comp}>'
        f'<PolyData><Piece NumberOfPoints="{len(points)}" NumberOfPolys="{len(offsets)}">'
        f"<Points>{arr('Points', 'Float32', points.astype(np.float32))}</Points>"
        f"<{cells}>{arr('connectivity', 'Int64', conn)}{arr('offsets', 'Int64', offsets)}</{cells}>"
        "</Piece></PolyData></VTKFile>"
    )


def _binary(header: str, order: str, *, compressed: bool, joint: bool = False):
    e = "<" if order == "LittleEndian" else ">"
    h = np.dtype(e + ("u4" if header == "UInt32" else "u8"))

    def enc(data: np.ndarray) -> str:
        raw = data.astype(data.dtype.newbyteorder(e)).tobytes()
        if not compressed:
            head = np.array([len(raw)], h).tobytes()
            if joint:
                return base64.b64encode(head + raw).decode()
            return base64.b64encode(head).decode() + base64.b64encode(raw).decode()
        block = 16  # several blocks
        chunks = [zlib.compress(raw[i : i + block]) for i in range(0, len(raw), block)]
        last = len(raw) - block * (len(chunks) - 1)
        head = np.array([len(chunks), block, last, *[len(c) for c in chunks]], h).tobytes()
        return base64.b64encode(head).decode() + base64.b64encode(b"".join(chunks)).decode()

    return enc


CUBE_POINTS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float
)
# a quad, a triangle and a pentagon (fan: 2 + 1 + 3 triangles)
CONN = np.array([0, 1, 2, 3, 4, 5, 6, 0, 1, 5, 6, 7], np.int64)
OFFSETS = np.array([4, 7, 12], np.int64)


@pytest.mark.parametrize(
    ("header", "order", "compressed", "joint"),
    [
        ("UInt32", "LittleEndian", False, False),
        ("UInt32", "LittleEndian", False, True),
        ("UInt64", "LittleEndian", False, False),
        ("UInt64", "BigEndian", False, True),
        ("UInt32", "LittleEndian", True, False),
        ("UInt64", "LittleEndian", True, False),
        ("UInt32", "BigEndian", True, False),
    ],
)
def test_inline_binary_encodings(tmp_path: Path, header, order, compressed, joint) -> None:
    text = _vtp(
        CUBE_POINTS, CONN, OFFSETS, encoder=_binary(header, order, compressed=compressed, joint=joint),
        header=header, order=order, compressor="vtkZLibDataCompressor" if compressed else "",
    )
    (tmp_path / "m.vtp").write_text(text)
    mesh = read_vtp(tmp_path / "m.vtp")
    np.testing.assert_array_equal(mesh.vertices, CUBE_POINTS)
    np.testing.assert_array_equal(mesh.faces, fan_triangulate(CONN, OFFSETS))
    assert len(mesh.faces) == 6


def test_ascii_polygons_are_fan_triangulated(tmp_path: Path) -> None:
    (tmp_path / "m.vtp").write_text(_vtp(CUBE_POINTS, CONN, OFFSETS, encoder=None))
    faces = read_vtp(tmp_path / "m.vtp").faces
    assert faces.tolist() == [[4, 5, 6], [0, 1, 2], [0, 2, 3], [0, 1, 5], [0, 5, 6], [0, 6, 7]]


def test_triangle_strips(tmp_path: Path) -> None:
    conn = np.array([0, 1, 2, 3, 4], np.int64)
    (tmp_path / "s.vtp").write_text(_vtp(CUBE_POINTS, conn, np.array([5]), encoder=None, cells="Strips"))
    faces = read_vtp(tmp_path / "s.vtp").faces
    assert faces.tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4]]  # alternate winding
    assert strip_triangulate(np.zeros(0, np.int64), np.zeros(0, np.int64)).shape == (0, 3)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("not xml", "VTK XML"),
        ('<VTKFile type="UnstructuredGrid"/>', "PolyData"),
        ('<VTKFile type="PolyData"><PolyData/></VTKFile>', "Piece"),
        (
            ('<VTKFile type="PolyData"><PolyData><Piece NumberOfPoints="1"><Points>'
            '<DataArray type="Float32" format="ascii">0 0 0</DataArray></Points><Polys>'
            '<DataArray type="Int64" Name="connectivity" format="ascii">0 1 2</DataArray>'
            '<DataArray type="Int64" Name="offsets" format="ascii">3</DataArray></Polys></Piece></PolyData></VTKFile>'),
            "outside",
        ),
        (
            ('<VTKFile type="PolyData"><PolyData><Piece><Points>'
            '<DataArray type="Float32" format="appended" offset="0"/></Points></Piece></PolyData></VTKFile>'),
            "appended",
        ),
        (
            ('<VTKFile type="PolyData"><PolyData><Piece><Points>'
            '<DataArray type="Float32" format="binary">@@@@</DataArray></Points></Piece></PolyData></VTKFile>'),
            "bad binary",
        ),
    ],
)
def test_bad_files_raise_a_clear_error(tmp_path: Path, text: str, match: str) -> None:
    (tmp_path / "bad.vtp").write_text(text)
    with pytest.raises(VtpFormatError, match=match) as info:
        read_vtp(tmp_path / "bad.vtp")
    assert "bad.vtp" in str(info.value)


def test_body_mesh_merges_scales_and_stays_in_the_geometry_folder(tmp_path: Path) -> None:
    geo = BUNDLED_GEOMETRY
    one = read_vtp(geo / "r_pelvis.vtp")
    mesh, problems = body_mesh(geo, [("r_pelvis.vtp", (2.0, 1.0, 1.0)), ("sacrum.vtp", (1.0, 1.0, 1.0))])
    assert not problems
    assert len(mesh.vertices) == len(one.vertices) + len(read_vtp(geo / "sacrum.vtp").vertices)
    np.testing.assert_allclose(mesh.vertices[: len(one.vertices)], one.vertices * [2.0, 1.0, 1.0])
    mesh, problems = body_mesh(geo, [("../_subject.json", (1, 1, 1)), ("missing.vtp", (1, 1, 1))])
    assert mesh is None and len(problems) == 2
    assert "outside" in problems[0] and "not found" in problems[1]
