"""The Foxglove message types the MCAP writer uses, as JSON schemas and messages.

Written by hand from Foxglove's message reference (``foxglove.FrameTransforms`` and the
parts of ``foxglove.SceneUpdate`` used here: arrows, spheres, line loops). Foxglove picks
its built-in panels by the schema name, which must be exactly ``foxglove.<Type>``; JSON
channels use schema encoding ``jsonschema`` and message encoding ``json``; times are
``{"sec", "nsec"}``; quaternions are named ``{x, y, z, w}``; an arrow is posed at its tail
and points along +x of its pose.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from solver.io.mcap_file import WORLD_FRAME, Z_UP_FRAME
from solver.results import ProcessedTrial

_HALF_SQRT2 = float(np.sqrt(0.5))


def _obj(title: str, props: dict[str, Any], description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"title": title, "type": "object", "properties": props}
    if description:
        out["description"] = description
    return out


def _numbers(*names: str) -> dict[str, Any]:
    return {n: {"type": "number"} for n in names}


_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}
_DURATION = {
    "type": "object",
    "title": "duration",
    "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}
_VEC3 = _obj("foxglove.Vector3", _numbers("x", "y", "z"))
_QUAT = _obj("foxglove.Quaternion", _numbers("x", "y", "z", "w"))
_POSE = _obj("foxglove.Pose", {"position": _VEC3, "orientation": _QUAT})
_COLOR = _obj("foxglove.Color", _numbers("r", "g", "b", "a"), "RGBA, each between 0 and 1")
_POINT3 = _obj("foxglove.Point3", _numbers("x", "y", "z"))


def _frame_transform() -> dict[str, Any]:
    return _obj(
        "foxglove.FrameTransform",
        {
            "timestamp": _TIME,
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _VEC3,
            "rotation": _QUAT,
        },
        "Pose of the child frame in the parent frame",
    )


def frame_transforms_schema() -> bytes:
    """JSON schema named ``foxglove.FrameTransforms`` (an array of FrameTransform)."""
    schema = _obj(
        "foxglove.FrameTransforms", {"transforms": {"type": "array", "items": _frame_transform()}}
    )
    return json.dumps(schema).encode()


def scene_update_schema() -> bytes:
    """JSON schema named ``foxglove.SceneUpdate`` restricted to the primitives we send
    (arrows, spheres, lines); the other primitive lists are sent empty."""
    arrow = _obj(
        "foxglove.ArrowPrimitive",
        {
            "pose": _POSE,
            **_numbers("shaft_length", "shaft_diameter", "head_length", "head_diameter"),
            "color": _COLOR,
        },
    )
    sphere = _obj("foxglove.SpherePrimitive", {"pose": _POSE, "size": _VEC3, "color": _COLOR})
    line = _obj(
        "foxglove.LinePrimitive",
        {
            "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
            "pose": _POSE,
            "thickness": {"type": "number"},
            "scale_invariant": {"type": "boolean"},
            "points": {"type": "array", "items": _POINT3},
            "color": _COLOR,
            "colors": {"type": "array", "items": _COLOR},
            "indices": {"type": "array", "items": {"type": "integer"}},
        },
    )
    anything = {"type": "array", "items": {"type": "object"}}
    entity = _obj(
        "foxglove.SceneEntity",
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": _DURATION,
            "frame_locked": {"type": "boolean"},
            "metadata": {
                "type": "array",
                "items": _obj(
                    "foxglove.KeyValuePair",
                    {"key": {"type": "string"}, "value": {"type": "string"}},
                ),
            },
            "arrows": {"type": "array", "items": arrow},
            "spheres": {"type": "array", "items": sphere},
            "lines": {"type": "array", "items": line},
            "cubes": anything,
            "cylinders": anything,
            "triangles": anything,
            "texts": anything,
            "models": anything,
        },
    )
    deletion = _obj(
        "foxglove.SceneEntityDeletion",
        {"timestamp": _TIME, "type": {"type": "integer"}, "id": {"type": "string"}},
    )
    schema = _obj(
        "foxglove.SceneUpdate",
        {
            "deletions": {"type": "array", "items": deletion},
            "entities": {"type": "array", "items": entity},
        },
    )
    return json.dumps(schema).encode()


def _stamp(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _f(v: float) -> float | None:
    return v if np.isfinite(v) else None


def frame_transforms(trial: ProcessedTrial, log_ns: np.ndarray) -> list[str]:
    """One ``foxglove.FrameTransforms`` JSON message per frame, stamped ``log_ns`` ``(T,)``
    (each frame's log time, ns): ``world`` -> each body (translation m, rotation
    {x, y, z, w}) and ``z_up`` -> ``world`` (+90° about x, so that Foxglove, which is Z-up,
    shows the Y-up lab upright with display frame ``z_up``)."""
    pos = np.asarray(trial.body_position, dtype=np.float64).tolist()
    quat = np.asarray(trial.body_wxyz, dtype=np.float64).tolist()
    out = []
    for k, ns in enumerate(log_ns.tolist()):
        stamp = _stamp(ns)
        tfs = [
            {
                "timestamp": stamp,
                "parent_frame_id": Z_UP_FRAME,
                "child_frame_id": WORLD_FRAME,
                "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
                "rotation": {"x": _HALF_SQRT2, "y": 0.0, "z": 0.0, "w": _HALF_SQRT2},
            }
        ]
        for name, (x, y, z), (qw, qx, qy, qz) in zip(
            trial.body_names, pos[k], quat[k], strict=True
        ):
            tfs.append(
                {
                    "timestamp": stamp,
                    "parent_frame_id": WORLD_FRAME,
                    "child_frame_id": name,
                    "translation": {"x": _f(x), "y": _f(y), "z": _f(z)},
                    "rotation": {"x": _f(qx), "y": _f(qy), "z": _f(qz), "w": _f(qw)},
                }
            )
        out.append(json.dumps({"transforms": tfs}))
    return out


def x_to_direction_quaternions(d: np.ndarray) -> np.ndarray:
    """``(N, 4)`` unit quaternions (w, x, y, z) rotating +x onto the unit vectors ``d (N, 3)``."""
    d = np.asarray(d, dtype=np.float64)
    q = np.stack([1.0 + d[:, 0], np.zeros(len(d)), -d[:, 2], d[:, 1]], axis=1)
    anti = q[:, 0] < 1e-12
    q[anti] = [0.0, 0.0, 0.0, 1.0]  # d = -x: half turn about z
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _empty_entity(stamp: dict[str, int], ident: str) -> dict[str, Any]:
    return {
        "timestamp": stamp,
        "frame_id": WORLD_FRAME,
        "id": ident,
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [],
        "arrows": [],
        "cubes": [],
        "spheres": [],
        "cylinders": [],
        "lines": [],
        "triangles": [],
        "texts": [],
        "models": [],
    }


def scene_updates(trial: ProcessedTrial, log_ns: np.ndarray, force_scale: float) -> list[str]:
    """One ``foxglove.SceneUpdate`` JSON message per frame, stamped ``log_ns`` ``(T,)``
    (each frame's log time, ns): an arrow per loaded plate from the CoP along the GRF
    (``force_scale`` m per N), the plate outlines, and a sphere at the centre of mass
    (display only; not read back)."""
    red = {"r": 0.86, "g": 0.16, "b": 0.16, "a": 1.0}
    plates = []
    for p in trial.plates:
        f = np.asarray(p.force, dtype=np.float64)
        norm = np.linalg.norm(f, axis=1)
        ok = np.isfinite(norm) & (norm > 1e-9) & np.isfinite(p.cop).all(axis=1)
        q = np.zeros((len(f), 4))
        q[ok] = x_to_direction_quaternions(f[ok] / norm[ok, None])
        outline = None
        if p.corners is not None:
            outline = {
                "type": 1,
                "pose": _pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
                "thickness": 0.005,
                "scale_invariant": False,
                "points": [{"x": x, "y": y, "z": z} for x, y, z in np.asarray(p.corners).tolist()],
                "color": {"r": 0.6, "g": 0.6, "b": 0.6, "a": 1.0},
                "colors": [],
                "indices": [],
            }
        plates.append(
            (
                p.name,
                ok,
                np.asarray(p.cop).tolist(),
                q.tolist(),
                (norm * force_scale).tolist(),
                outline,
            )
        )
    com = np.asarray(trial.com, dtype=np.float64)
    com_ok = np.isfinite(com).all(axis=1)
    out = []
    for k, ns in enumerate(log_ns.tolist()):
        stamp = _stamp(ns)
        entities = []
        for name, ok, cop, q, length, outline in plates:
            e = _empty_entity(stamp, f"plate/{name}")
            if ok[k]:
                shaft = max(length[k] - 0.05, 0.0)
                e["arrows"] = [
                    {
                        "pose": _pose(cop[k], q[k]),
                        "shaft_length": shaft,
                        "shaft_diameter": 0.01,
                        "head_length": min(0.05, length[k]),
                        "head_diameter": 0.03,
                        "color": red,
                    }
                ]
            if outline is not None:
                e["lines"] = [outline]
            entities.append(e)
        e = _empty_entity(stamp, "com")
        if com_ok[k]:
            e["spheres"] = [
                {
                    "pose": _pose(com[k].tolist(), [1.0, 0.0, 0.0, 0.0]),
                    "size": {"x": 0.05, "y": 0.05, "z": 0.05},
                    "color": {"r": 0.2, "g": 0.75, "b": 0.3, "a": 1.0},
                }
            ]
        entities.append(e)
        out.append(json.dumps({"deletions": [], "entities": entities}))
    return out


def bone_meshes_update(
    meshes: dict[str, Any], log_ns: int, color: tuple[float, float, float] = (0.91, 0.89, 0.82)
) -> str:
    """One ``foxglove.SceneUpdate`` JSON message with an entity ``bone/<body>`` per body of
    ``meshes`` (body name -> trimesh mesh in the body frame, m): a GLB model
    (``model/gltf-binary``, base64) at the body frame's origin, ``frame_locked`` to the
    body's frame of ``/tf`` so that it follows the body, lifetime unlimited."""
    import base64

    stamp = _stamp(int(log_ns))
    entities = []
    for body, mesh in meshes.items():
        e = _empty_entity(stamp, f"bone/{body}")
        e["frame_id"] = body
        e["frame_locked"] = True
        glb = mesh.export(file_type="glb")
        e["models"] = [
            {
                "pose": _pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
                "scale": {"x": 1.0, "y": 1.0, "z": 1.0},
                "color": {"r": color[0], "g": color[1], "b": color[2], "a": 1.0},
                "override_color": True,
                "url": "",
                "media_type": "model/gltf-binary",
                "data": base64.b64encode(glb).decode("ascii"),
            }
        ]
        entities.append(e)
    return json.dumps({"deletions": [], "entities": entities})


def _pose(p: list[float], wxyz: list[float]) -> dict[str, Any]:
    return {
        "position": {"x": p[0], "y": p[1], "z": p[2]},
        "orientation": {"x": wxyz[1], "y": wxyz[2], "z": wxyz[3], "w": wxyz[0]},
    }
