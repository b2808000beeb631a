"""Write a processed trial as an MCAP file (JSON channels, zstd chunks, full index).

The layout (topics, schemas, metadata records) is described in :mod:`solver.io.mcap_file`,
which reads it back. Our own channels carry exact float64 numbers (``repr`` round trip,
``null`` for NaN); ``/tf`` uses Foxglove's ``foxglove.FrameTransforms`` JSON schema so that
Foxglove's 3D panel places the bodies, and ``/scene`` is a ``foxglove.SceneUpdate`` with
the GRF arrows at the centre of pressure and the centre of mass, for display only;
``/skeleton/meshes`` carries the bone meshes once (found along the search path of
:mod:`addb_viewer.geometry`, as for the review app and Rerun), locked to the body frames,
and the metadata record ``addb.meshes`` names the folders searched and any file missing.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from addb_viewer.recording import foxglove_schemas as fox
from addb_viewer.recording.metadata import recording_info
from solver.files import as_created
from solver.io.mcap_file import (
    META_FRAMES,
    META_INFO,
    TOPIC_ANNOTATIONS,
    TOPIC_BONES,
    TOPIC_COM,
    TOPIC_COORDINATES,
    TOPIC_FLAGS,
    TOPIC_MODEL,
    TOPIC_OBSERVED,
    TOPIC_PLATE,
    TOPIC_RESIDUALS,
    TOPIC_SCENE,
    TOPIC_TF,
    TOPIC_TORQUES,
)
from solver.results import ProcessedTrial

#: Length of a GRF arrow in the ``/scene`` display per newton, m/N (1 mm per N).
FORCE_SCALE_M_PER_N = 1e-3

#: Metadata record of the bone meshes: ``search_path`` and ``missing`` (JSON arrays).
META_MESHES = "addb.meshes"

#: Uncompressed bytes per chunk: smaller chunks make reading one frame cheaper.
CHUNK_SIZE = 256 * 1024


def _num_array(n: int | None = None) -> dict[str, Any]:
    s: dict[str, Any] = {"type": "array", "items": {"type": ["number", "null"]}}
    if n is not None:
        s["minItems"] = s["maxItems"] = n
    return s


def _schema(title: str, description: str, props: dict[str, Any]) -> bytes:
    base = {
        "frame": {"type": "integer", "minimum": 0, "description": "frame index k"},
        "time": {"type": "number", "description": "time of the frame, s"},
    }
    return json.dumps(
        {
            "title": title,
            "description": description,
            "type": "object",
            "properties": {**base, **props},
        }
    ).encode()


def _own_schemas(n_markers: int, n_coords: int) -> dict[str, bytes]:
    vec3 = _num_array(3)
    return {
        "addb.Markers": _schema(
            "addb.Markers",
            "Marker positions of one frame, ground frame (Y up), m; null where missing. "
            "Marker names in the addb.recording metadata (marker_names).",
            {
                "positions": {
                    **_num_array(3 * n_markers),
                    "description": "x0 y0 z0 x1 ... (3M numbers)",
                }
            },
        ),
        "addb.PlateWrench": _schema(
            "addb.PlateWrench",
            "Ground reaction wrench of one plate, ground frame.",
            {
                "force": {**vec3, "description": "force on the body, N"},
                "cop": {**vec3, "description": "centre of pressure, m (null when unloaded)"},
                "free_moment": {**vec3, "description": "free moment, N·m"},
                "body": {"type": "integer", "description": "index into body_names, -1: none"},
            },
        ),
        "addb.CenterOfMass": _schema(
            "addb.CenterOfMass",
            "Whole-body centre of mass, ground frame.",
            {
                "position": {**vec3, "description": "m"},
                "acceleration": {**vec3, "description": "m/s^2"},
            },
        ),
        "addb.Coordinates": _schema(
            "addb.Coordinates",
            "Model coordinates (rad or m) in coordinate_names order.",
            {"q": _num_array(n_coords)},
        ),
        "addb.Residuals": _schema(
            "addb.Residuals",
            "Root residual force (N) and moment about the root body origin (N·m), ground "
            "frame, and the frame's marker RMS error (m).",
            {"force": vec3, "moment": vec3, "marker_rms": {"type": ["number", "null"]}},
        ),
        "addb.JointTorques": _schema(
            "addb.JointTorques",
            "Generalized forces (N·m or N) in coordinate_names order.",
            {"tau": _num_array(n_coords)},
        ),
        "addb.Flags": _schema(
            "addb.Flags",
            "Frame flags: unmeasured external force (excluded from the dynamic fit), "
            "solver proposal and its reason.",
            {
                "unobserved": {"type": "boolean"},
                "proposed": {"type": "boolean"},
                "reason": {"type": "string"},
            },
        ),
        "addb.Annotations": json.dumps(
            {
                "title": "addb.Annotations",
                "description": "Review state of the trial and the solver settings the recording was made with.",
                "type": "object",
                "properties": {
                    "subject": {"type": "string"},
                    "trial": {"type": "string"},
                    "state": {"type": ["object", "null"]},
                    "settings": {"type": "object"},
                },
            }
        ).encode(),
    }


def _rows(a: np.ndarray) -> list[str]:
    """JSON text of each row of ``a`` flattened, ``null`` for non-finite numbers."""
    flat = np.asarray(a, dtype=np.float64).reshape(len(a), -1)
    out = []
    for row in flat.tolist():
        s = json.dumps(row)
        if "N" in s or "I" in s:
            s = s.replace("-Infinity", "null").replace("Infinity", "null").replace("NaN", "null")
        out.append(s)
    return out


def _scalars(a: np.ndarray) -> list[str]:
    return [
        json.dumps(v) if np.isfinite(v) else "null"
        for v in np.asarray(a, dtype=np.float64).tolist()
    ]


def frame_log_times(time: np.ndarray) -> np.ndarray:
    """``(T,)`` MCAP log time of each frame, ns: the frame time (shifted to start at 0
    when it is negative).

    Raises
    ------
    ValueError
        Times that are not finite or not strictly increasing at ns resolution.
    """
    t = np.asarray(time, dtype=np.float64)
    if not np.isfinite(t).all():
        raise ValueError("frame times must be finite")
    ns = np.round((t - min(0.0, float(t[0]) if t.size else 0.0)) * 1e9).astype(np.int64)
    if ns.size > 1 and (np.diff(ns) <= 0).any():
        raise ValueError("frame times must be strictly increasing (at 1 ns resolution)")
    return ns


def write_mcap(
    trial: ProcessedTrial,
    path: str | os.PathLike[str],
    *,
    annotations: dict[str, Any] | None = None,
    settings: dict[str, Any] | None = None,
    mesh_path: Sequence[str | os.PathLike[str]] | None = None,
) -> Path:
    """Write ``trial`` as an MCAP file (layout in :mod:`solver.io.mcap_file`).

    Parameters
    ----------
    trial
        The processed trial; NaN dynamics (kinematics-only trials) are written as null.
    path
        Output file; written to a temporary file in the same folder, then renamed.
    annotations
        Review state of the trial (``addb_viewer.recording.metadata.review_state``).
    settings
        Solver settings to record; default ``trial.settings``.
    mesh_path
        Folders the bone meshes are looked up in, first match wins; default
        :func:`addb_viewer.geometry.trial_search_path` of the trial.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    GeometryPathError
        ``$ADDB_GEOMETRY`` names something that is not a folder (default ``mesh_path`` only).
    """
    from mcap.writer import CompressionType, IndexType, Writer

    from addb_viewer.geometry import trial_search_path

    search = tuple(mesh_path) if mesh_path is not None else trial_search_path(trial)

    path = Path(path)
    info = recording_info(trial, annotations=annotations, settings=settings)
    log_ns = frame_log_times(trial.time)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            w = Writer(
                f,
                chunk_size=CHUNK_SIZE,
                compression=CompressionType.ZSTD,
                index_types=IndexType.ALL,
            )
            w.start(profile="", library="addb")
            _write_all(w, trial, info, log_ns, search)
            w.finish()
        as_created(tmp_name)  # not mkstemp's 0600
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return path


def _write_all(
    w: Any, trial: ProcessedTrial, info: dict[str, Any], log_ns: np.ndarray, search: tuple[Any, ...]
) -> None:
    schema_ids = {
        name: w.register_schema(name=name, encoding="jsonschema", data=data)
        for name, data in _own_schemas(len(trial.marker_names), len(trial.coordinate_names)).items()
    }
    schema_ids["foxglove.FrameTransforms"] = w.register_schema(
        name="foxglove.FrameTransforms", encoding="jsonschema", data=fox.frame_transforms_schema()
    )
    schema_ids["foxglove.SceneUpdate"] = w.register_schema(
        name="foxglove.SceneUpdate", encoding="jsonschema", data=fox.scene_update_schema()
    )

    def channel(topic: str, schema: str, metadata: dict[str, str] | None = None) -> int:
        return w.register_channel(
            topic=topic,
            message_encoding="json",
            schema_id=schema_ids[schema],
            metadata=metadata or {},
        )

    w.add_metadata(META_INFO, {"info": json.dumps(info)})
    w.add_metadata(
        META_FRAMES,
        {
            "time_s": json.dumps(np.asarray(trial.time, dtype=np.float64).tolist()),
            "log_time_ns": json.dumps(log_ns.tolist()),
        },
    )
    ann = channel(TOPIC_ANNOTATIONS, "addb.Annotations")
    state = {
        "subject": trial.subject,
        "trial": trial.trial,
        "state": info["annotations"],
        "settings": info["settings"],
    }
    w.add_message(
        ann, log_time=int(log_ns[0]), publish_time=int(log_ns[0]), data=json.dumps(state).encode()
    )

    names = ", ".join(trial.marker_names)
    streams: list[tuple[int, list[str]]] = []

    def stream(ch: int, template: str, *columns: Sequence[str]) -> None:
        head = [f'{{"frame":{k},"time":{t}' for k, t in enumerate(_scalars(trial.time))]
        streams.append(
            (ch, [h + template.format(*c) for h, *c in zip(head, *columns, strict=True)])
        )

    stream(
        channel(TOPIC_OBSERVED, "addb.Markers", {"marker_names": names}),
        ',"positions":{}}}',
        _rows(trial.observed),
    )
    stream(
        channel(TOPIC_MODEL, "addb.Markers", {"marker_names": names}),
        ',"positions":{}}}',
        _rows(trial.modeled),
    )
    for i, p in enumerate(trial.plates):
        body = np.full(trial.n_frames, -1) if p.body is None else np.asarray(p.body)
        stream(
            channel(
                TOPIC_PLATE.format(name=p.name),
                "addb.PlateWrench",
                {"plate": p.name, "plate_index": str(i)},
            ),
            ',"force":{},"cop":{},"free_moment":{},"body":{}}}',
            _rows(p.force),
            _rows(p.cop),
            _rows(p.free_moment),
            [str(int(b)) for b in body],
        )
    stream(
        channel(TOPIC_COM, "addb.CenterOfMass"),
        ',"position":{},"acceleration":{}}}',
        _rows(trial.com),
        _rows(trial.com_acc),
    )
    stream(
        channel(
            TOPIC_COORDINATES,
            "addb.Coordinates",
            {"coordinate_names": ", ".join(trial.coordinate_names)},
        ),
        ',"q":{}}}',
        _rows(trial.q),
    )
    stream(
        channel(TOPIC_RESIDUALS, "addb.Residuals"),
        ',"force":{},"moment":{},"marker_rms":{}}}',
        _rows(trial.residual_force),
        _rows(trial.residual_moment),
        _scalars(trial.marker_rms_per_frame),
    )
    stream(
        channel(
            TOPIC_TORQUES,
            "addb.JointTorques",
            {"coordinate_names": ", ".join(trial.coordinate_names)},
        ),
        ',"tau":{}}}',
        _rows(trial.tau),
    )
    reasons = list(trial.proposal_reasons) + [""] * (trial.n_frames - len(trial.proposal_reasons))
    stream(
        channel(TOPIC_FLAGS, "addb.Flags"),
        ',"unobserved":{},"proposed":{},"reason":{}}}',
        [json.dumps(bool(v)) for v in trial.unobserved],
        [json.dumps(bool(v)) for v in trial.proposed],
        [json.dumps(r) for r in reasons],
    )
    streams.append(
        (channel(TOPIC_TF, "foxglove.FrameTransforms"), fox.frame_transforms(trial, log_ns))
    )
    streams.append(
        (
            channel(TOPIC_SCENE, "foxglove.SceneUpdate"),
            fox.scene_updates(trial, log_ns, FORCE_SCALE_M_PER_N),
        )
    )
    for k, t in enumerate(log_ns.tolist()):
        for ch, msgs in streams:
            w.add_message(ch, log_time=t, publish_time=t, sequence=k, data=msgs[k].encode())
    # last, in chunks of its own: reading a frame never decompresses the meshes (but frame 0)
    _write_bones(w, trial, log_ns, search, schema_ids["foxglove.SceneUpdate"])


def _write_bones(
    w: Any, trial: ProcessedTrial, log_ns: np.ndarray, search: tuple[Any, ...], schema: int
) -> None:
    """``/skeleton/meshes`` (one SceneUpdate at the first frame) and ``addb.meshes``."""
    from addb_viewer.app.meshes import body_mesh
    from addb_viewer.geometry import report_missing

    meshes: dict[str, Any] = {}
    problems: list[str] = []
    for body in trial.body_names:
        files = trial.body_meshes.get(body, [])
        if not files:
            continue
        mesh, why = body_mesh(search, files)
        problems += why
        if mesh is not None and len(mesh.faces):
            meshes[body] = mesh
    report_missing(problems)
    w.add_metadata(
        META_MESHES,
        {"search_path": json.dumps([str(p) for p in search]), "missing": json.dumps(problems)},
    )
    if not meshes or not len(log_ns):
        return
    ch = w.register_channel(topic=TOPIC_BONES, message_encoding="json", schema_id=schema, metadata={})
    w.flush()  # ends the frames' chunk: the meshes get a chunk of their own (time range: frame 0)
    t = int(log_ns[0])
    w.add_message(ch, log_time=t, publish_time=t, data=fox.bone_meshes_update(meshes, t).encode())
