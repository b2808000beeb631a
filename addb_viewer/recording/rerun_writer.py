"""Write a processed trial as a Rerun recording (``.rrd``), without opening a viewer.

Entities (all data in the OpenSim ground frame, Y up, SI units)
---------------------------------------------------------------
``/world``                         static ``ViewCoordinates.RIGHT_HAND_Y_UP``
``/world/markers/observed``        Points3D per frame (visible markers only, with labels)
``/world/markers/model``           Points3D per frame
``/world/skeleton/<body>``         Transform3D per frame: translation m, quaternion (x, y, z, w)
``/world/skeleton/<body>/mesh``    static Mesh3D: the body's bone meshes merged and scaled
                                   (looked up along :mod:`addb_viewer.geometry`'s search path;
                                   ``/meta/mesh_problems`` names any file still missing, once)
``/world/plates/<plate>/grf``      Arrows3D per frame from the CoP, ``FORCE_SCALE_M_PER_N``
                                   m per N (no arrow while unloaded)
``/world/plates/<plate>/outline``  static LineStrips3D when the plate corners are known
``/world/com``                     Points3D per frame: whole-body centre of mass
``/grf/<plate>``                   Scalars (Fx, Fy, Fz), N
``/residuals/force``               Scalars (Fx, Fy, Fz), N
``/residuals/moment``              Scalars (Mx, My, Mz), N·m
``/joint_torques/<coordinate>``    Scalars, N·m (N for translational coordinates)
``/markers/rms``                   Scalars, marker RMS error per frame, m
``/flags/unobserved``              Scalars 0/1: frames with unmeasured force (not in the
                                   dynamic fit); ``/flags/proposed`` the solver's proposals;
                                   ``/flags/reasons`` TextLog at each proposal's first frame;
                                   ``/flags/review_unmeasured`` the review record's flags
``/meta``                          static TextDocument (markdown) and AnyValues: subject,
                                   trial, solver settings and annotation state as JSON

Every per-frame entity is on the ``frame`` sequence and the ``time`` timeline (s) and is
sent with ``send_columns`` (one call per entity, never one per frame). Frames where a
value is NaN (missing marker, unloaded plate, dynamics not run) log nothing for that
value. Recording properties ``addb`` hold the same JSON as ``/meta`` so that two
recordings (before / after a reprocess) can be compared without the viewer.
"""

from __future__ import annotations

import json
import os
import tempfile
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from addb_viewer.recording.metadata import recording_info
from solver.files import as_created
from solver.results import ProcessedTrial

#: Length of a GRF arrow per newton, m/N (1 mm per N, as AddBiomechanics draws it).
FORCE_SCALE_M_PER_N = 1e-3

APPLICATION_ID = "addb"

OBSERVED_COLOR = (255, 140, 0)
MODEL_COLOR = (60, 140, 255)
BONE_COLOR = (232, 226, 210)
GRF_COLOR = (220, 40, 40)
COM_COLOR = (50, 190, 80)
XYZ_COLORS = [(220, 60, 60), (60, 170, 60), (60, 100, 230)]


def blueprint(trial: ProcessedTrial | None = None) -> Any:
    """The default layout: the 3D view beside the residual and GRF plots.

    Left (3/5 of the width): ``Spatial3DView`` of ``/world``. Right, stacked: residual
    force, residual moment and GRF time series, then tabs with joint torques, marker RMS
    and flags. The time panel follows the ``frame`` sequence at the trial's rate.

    Parameters
    ----------
    trial
        Used for the playback rate (frames per second) only.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    import rerun.blueprint as rrb

    fps = trial.rate_hz if trial is not None and trial.rate_hz > 0 else 100.0
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="/world", name="3D"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/residuals/force", name="Residual force (N)"),
                rrb.TimeSeriesView(origin="/residuals/moment", name="Residual moment (N·m)"),
                rrb.TimeSeriesView(origin="/grf", name="GRF (N)"),
                rrb.Tabs(
                    rrb.TimeSeriesView(origin="/joint_torques", name="Joint torques"),
                    rrb.TimeSeriesView(origin="/markers/rms", name="Marker RMS (m)"),
                    rrb.TimeSeriesView(origin="/flags", name="Flags"),
                ),
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="frame", fps=fps),
        collapse_panels=False,
    )


def write_rerun(
    trial: ProcessedTrial,
    path: str | os.PathLike[str],
    *,
    annotations: dict[str, Any] | None = None,
    settings: dict[str, Any] | None = None,
    mesh_path: Sequence[str | os.PathLike[str]] | None = None,
) -> Path:
    """Write ``trial`` as a Rerun recording file with the default :func:`blueprint`.

    Parameters
    ----------
    trial
        The processed trial (see :class:`solver.results.ProcessedTrial` for shapes and
        units; dynamics may be NaN).
    path
        Output ``.rrd``; written to a temporary file in the same folder, then renamed.
    annotations
        Review state of the trial (``metadata.review_state``), stored with the recording.
    settings
        Solver settings to store; default ``trial.settings``.
    mesh_path
        Folders the bone meshes are looked up in, first match wins; default
        :func:`addb_viewer.geometry.trial_search_path` of the trial (its recorded geometry
        folder and model, ``$ADDB_GEOMETRY``, the bundled set).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    GeometryPathError
        ``$ADDB_GEOMETRY`` names something that is not a folder (default ``mesh_path`` only).
    """
    import rerun as rr

    from addb_viewer.geometry import trial_search_path

    search = tuple(mesh_path) if mesh_path is not None else trial_search_path(trial)

    path = Path(path)
    info = recording_info(trial, annotations=annotations, settings=settings)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=str(uuid.uuid4()))
    try:
        rec.save(tmp_name, default_blueprint=blueprint(trial))
        rec.send_recording_name(f"{trial.subject} / {trial.trial}")
        _log_all(rec, trial, info, search)
        rec.flush()
        rec.disconnect()
        as_created(tmp_name)  # not mkstemp's 0600
        os.replace(tmp_name, path)
    except BaseException:
        rec.disconnect()
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return path


def _log_all(rec: Any, trial: ProcessedTrial, info: dict[str, Any], search: tuple[Any, ...]) -> None:
    import rerun as rr

    _log_meta(rec, trial, info)
    rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
    frame = np.arange(trial.n_frames)
    # rounded to ns here: rerun truncates float seconds (2.01 s would become 2.009999999 s)
    time_ns = np.round(np.asarray(trial.time, dtype=np.float64) * 1e9).astype("timedelta64[ns]")

    def send(entity: str, rows: np.ndarray, columns: Any) -> None:
        rec.send_columns(
            entity,
            indexes=[
                rr.TimeColumn("frame", sequence=frame[rows]),
                rr.TimeColumn("time", duration=time_ns[rows]),
            ],
            columns=columns,
        )

    _log_markers(send, rec, trial)
    _log_skeleton(send, rec, trial, search)
    _log_plates(send, rec, trial)
    _log_series(send, rec, trial, info)


def _log_meta(rec: Any, trial: ProcessedTrial, info: dict[str, Any]) -> None:
    import rerun as rr

    values = {
        "subject": trial.subject,
        "trial": trial.trial,
        "settings_json": json.dumps(info["settings"], sort_keys=True),
        "annotations_json": json.dumps(info["annotations"], sort_keys=True),
        "info_json": json.dumps(info, sort_keys=True),
    }
    rec.send_property("addb", rr.AnyValues(**values))
    rec.log("/meta", rr.AnyValues(**values), static=True)
    text = (
        f"# {trial.subject} / {trial.trial}\n\n"
        f"{trial.n_frames} frames at {trial.rate_hz:.1f} Hz, mass {trial.mass_kg:.2f} kg, "
        f"dynamics {'yes' if trial.has_dynamics else 'not run'}; recorded {info['created_utc']} "
        f"by addb {info['addb_version']}.\n\n"
        f"## Solver settings\n\n```json\n{json.dumps(info['settings'], indent=2, sort_keys=True)}\n```\n\n"
        f"## Annotations\n\n```json\n{json.dumps(info['annotations'], indent=2, sort_keys=True)}\n```\n"
    )
    rec.log("/meta/summary", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)


def _points_per_frame(
    positions: np.ndarray, names: tuple[str, ...]
) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Finite points of each frame in frame order, their labels and per-frame counts."""
    ok = np.isfinite(positions).all(axis=2)
    labels = np.broadcast_to(np.asarray(names, dtype=object), ok.shape)[ok].tolist()
    return positions[ok], labels, ok.sum(axis=1)


def _log_markers(send: Any, rec: Any, trial: ProcessedTrial) -> None:
    import rerun as rr

    rows = np.ones(trial.n_frames, dtype=bool)
    for entity, data, color in (
        ("/world/markers/observed", trial.observed, OBSERVED_COLOR),
        ("/world/markers/model", trial.modeled, MODEL_COLOR),
    ):
        pts, labels, counts = _points_per_frame(
            np.asarray(data, dtype=np.float64), trial.marker_names
        )
        rec.log(
            entity,
            rr.Points3D.from_fields(colors=[color], radii=[0.008], show_labels=False),
            static=True,
        )
        send(entity, rows, rr.Points3D.columns(positions=pts, labels=labels).partition(counts))
    com = np.asarray(trial.com, dtype=np.float64)
    ok = np.isfinite(com).all(axis=1)
    rec.log(
        "/world/com",
        rr.Points3D.from_fields(colors=[COM_COLOR], radii=[0.02], labels=["CoM"]),
        static=True,
    )
    send("/world/com", rows, rr.Points3D.columns(positions=com[ok]).partition(ok.astype(np.int64)))


def _log_skeleton(send: Any, rec: Any, trial: ProcessedTrial, search: tuple[Any, ...]) -> None:
    import rerun as rr

    from addb_viewer.app.meshes import body_mesh
    from addb_viewer.geometry import report_missing

    problems: list[str] = []
    pos = np.asarray(trial.body_position, dtype=np.float64)
    wxyz = np.asarray(trial.body_wxyz, dtype=np.float64)
    for j, body in enumerate(trial.body_names):
        entity = f"/world/skeleton/{body}"
        ok = np.isfinite(pos[:, j]).all(axis=1) & np.isfinite(wxyz[:, j]).all(axis=1)
        if ok.any():
            xyzw = wxyz[ok, j][:, [1, 2, 3, 0]]
            send(entity, ok, rr.Transform3D.columns(translation=pos[ok, j], quaternion=xyzw))
        meshes = trial.body_meshes.get(body, [])
        if not meshes:
            continue
        mesh, why = body_mesh(search, meshes)
        problems += why
        if mesh is not None:
            rec.log(
                f"{entity}/mesh",
                rr.Mesh3D(
                    vertex_positions=np.asarray(mesh.vertices, dtype=np.float32),
                    triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
                    vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32),
                    albedo_factor=BONE_COLOR,
                ),
                static=True,
            )
    if problems:
        report_missing(problems)
        text = "Bone meshes not shown:\n\n" + "\n".join(f"* {p}" for p in problems)
        rec.log(
            "/meta/mesh_problems",
            rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN),
            static=True,
        )


def _log_plates(send: Any, rec: Any, trial: ProcessedTrial) -> None:
    import rerun as rr

    rows = np.ones(trial.n_frames, dtype=bool)
    for p in trial.plates:
        base = f"/world/plates/{p.name}"
        force = np.asarray(p.force, dtype=np.float64)
        cop = np.asarray(p.cop, dtype=np.float64)
        ok = np.isfinite(force).all(axis=1) & np.isfinite(cop).all(axis=1)
        rec.log(
            f"{base}/grf", rr.Arrows3D.from_fields(colors=[GRF_COLOR], radii=[0.006]), static=True
        )
        send(
            f"{base}/grf",
            rows,
            rr.Arrows3D.columns(origins=cop[ok], vectors=force[ok] * FORCE_SCALE_M_PER_N).partition(
                ok.astype(np.int64)
            ),
        )
        if p.corners is not None:
            c = np.asarray(p.corners, dtype=np.float64)
            rec.log(
                f"{base}/outline",
                rr.LineStrips3D([np.vstack([c, c[:1]])], colors=[(150, 150, 150)]),
                static=True,
            )


def _series(
    send: Any,
    rec: Any,
    entity: str,
    values: np.ndarray,
    names: list[str],
    colors: list[Any] | None = None,
) -> None:
    """Scalars columns of ``values (T, k)`` on ``entity``, rows with any NaN left out."""
    import rerun as rr

    values = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
    ok = np.isfinite(values).all(axis=1)
    if not ok.any():
        return
    rec.log(entity, rr.SeriesLines(names=names, colors=colors), static=True)
    send(entity, ok, rr.Scalars.columns(scalars=values[ok]))


def _log_series(send: Any, rec: Any, trial: ProcessedTrial, info: dict[str, Any]) -> None:
    import rerun as rr

    for p in trial.plates:
        _series(
            send,
            rec,
            f"/grf/{p.name}",
            p.force,
            [f"{p.name} Fx", f"{p.name} Fy", f"{p.name} Fz"],
            XYZ_COLORS,
        )
    _series(send, rec, "/residuals/force", trial.residual_force, ["Fx", "Fy", "Fz"], XYZ_COLORS)
    _series(send, rec, "/residuals/moment", trial.residual_moment, ["Mx", "My", "Mz"], XYZ_COLORS)
    tau = np.asarray(trial.tau, dtype=np.float64)
    for i, name in enumerate(trial.coordinate_names):
        _series(send, rec, f"/joint_torques/{name}", tau[:, i], [name])
    _series(send, rec, "/markers/rms", trial.marker_rms_per_frame, ["marker RMS"])
    _series(
        send,
        rec,
        "/flags/unobserved",
        np.asarray(trial.unobserved, dtype=np.float64),
        ["unmeasured force"],
    )
    _series(
        send, rec, "/flags/proposed", np.asarray(trial.proposed, dtype=np.float64), ["proposed"]
    )
    review = _review_mask(info.get("annotations"), trial.n_frames)
    if review is not None:
        _series(
            send,
            rec,
            "/flags/review_unmeasured",
            review.astype(np.float64),
            ["review: unmeasured force"],
        )
    reasons = np.array(
        list(trial.proposal_reasons) + [""] * (trial.n_frames - len(trial.proposal_reasons)),
        dtype=object,
    )
    starts = np.asarray(trial.proposed, dtype=bool) & (reasons != "")
    starts[1:] &= ~(np.asarray(trial.proposed[:-1], dtype=bool) & (reasons[1:] == reasons[:-1]))
    if starts.any():
        send(
            "/flags/reasons",
            starts,
            rr.TextLog.columns(text=reasons[starts].tolist(), level=["WARN"] * int(starts.sum())),
        )


def _review_mask(state: dict[str, Any] | None, n_frames: int) -> np.ndarray | None:
    """``(T,)`` unmeasured-force flags of a review state (runs with start/stop), or None."""
    if not state or "unmeasured_force" not in state:
        return None
    mask = np.zeros(n_frames, dtype=bool)
    for run in state["unmeasured_force"]:
        mask[max(0, int(run["start"])) : min(n_frames, int(run["stop"]))] = True
    return mask
