"""The Rerun recording: read back with rerun's own reader (``rerun.chunk.RrdReader``)
and compared with the solver's arrays; ``rerun rrd verify``; the default blueprint."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import uuid
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from addb_viewer.app.meshes import read_vtp
from addb_viewer.geometry import find_mesh, trial_search_path
from addb_viewer.recording.rerun_writer import FORCE_SCALE_M_PER_N, blueprint, write_rerun
from solver.results import ProcessedTrial
from tests.recording.recording_support import RERUN, REVIEW


class Recording:
    """The chunks of an .rrd file by entity: temporal rows merged in frame order."""

    def __init__(self, path: Path) -> None:
        self.reader = RrdReader(path)
        self.temporal: dict[str, list[pa.RecordBatch]] = defaultdict(list)
        self.static: dict[str, dict[str, object]] = defaultdict(dict)
        self.n_chunks: dict[str, int] = defaultdict(int)
        for c in self.reader.stream().to_chunks():
            rb = c.to_record_batch()
            self.n_chunks[c.entity_path] += 1
            if c.is_static:
                for name in rb.schema.names[1:]:
                    self.static[c.entity_path][name] = rb.column(name).to_pylist()[0]
            else:
                self.temporal[c.entity_path].append(rb)

    def column(self, entity: str, name: str) -> tuple[np.ndarray, list]:
        """(frame indices, per-row values) of a temporal component, sorted by frame."""
        frames, values = [], []
        for rb in self.temporal[entity]:
            frames += rb.column("frame").to_pylist()
            values += rb.column(name).to_pylist()
        order = np.argsort(frames, kind="stable")
        return np.asarray(frames)[order], [values[i] for i in order]


def per_frame_points(rec: Recording, entity: str, trial: ProcessedTrial) -> np.ndarray:
    """(T, M, 3) float32 rebuilt from the per-frame positions and labels (NaN: not logged)."""
    out = np.full((trial.n_frames, len(trial.marker_names), 3), np.nan, dtype=np.float32)
    index = {n: i for i, n in enumerate(trial.marker_names)}
    frames, positions = rec.column(entity, "Points3D:positions")
    _, labels = rec.column(entity, "Points3D:labels")
    assert frames.tolist() == list(range(trial.n_frames))  # one row per frame, empty rows kept
    for k, pts, names in zip(frames, positions, labels, strict=True):
        for p, name in zip(pts, names, strict=True):
            out[k, index[name]] = p
    return out


@pytest.fixture
def rrd(tmp_path: Path, any_trial: ProcessedTrial) -> tuple[ProcessedTrial, Recording, Path]:
    path = write_rerun(any_trial, tmp_path / "walk.rrd", annotations=REVIEW)
    return any_trial, Recording(path), path


def test_markers_round_trip_exactly(rrd: tuple[ProcessedTrial, Recording, Path]) -> None:
    trial, rec, _ = rrd
    # rerun stores positions as float32: the file holds exactly the float32 of our numbers
    for entity, data in (
        ("/world/markers/observed", trial.observed),
        ("/world/markers/model", trial.modeled),
    ):
        got = per_frame_points(rec, entity, trial)
        np.testing.assert_array_equal(got, data.astype(np.float32))


def test_plate_forces_round_trip_exactly(rrd: tuple[ProcessedTrial, Recording, Path]) -> None:
    trial, rec, _ = rrd
    for p in trial.plates:
        loaded = np.isfinite(p.cop).all(axis=1) & np.isfinite(p.force).all(axis=1)
        # GRF time series: float64, bit-exact
        frames, values = rec.column(f"/grf/{p.name}", "Scalars:scalars")
        np.testing.assert_array_equal(frames, np.flatnonzero(np.isfinite(p.force).all(axis=1)))
        np.testing.assert_array_equal(np.array(values), p.force[frames])
        # arrows: one per loaded frame, none while unloaded, from the CoP along F (1 mm/N)
        frames, origins = rec.column(f"/world/plates/{p.name}/grf", "Arrows3D:origins")
        _, vectors = rec.column(f"/world/plates/{p.name}/grf", "Arrows3D:vectors")
        assert frames.tolist() == list(range(trial.n_frames))
        assert [len(o) for o in origins] == loaded.astype(int).tolist()
        got_o = np.array([o[0] for o in origins if o], dtype=np.float32)
        got_v = np.array([v[0] for v in vectors if v], dtype=np.float32)
        np.testing.assert_array_equal(got_o, p.cop[loaded].astype(np.float32))
        np.testing.assert_array_equal(
            got_v, (p.force[loaded] * FORCE_SCALE_M_PER_N).astype(np.float32)
        )


def test_body_poses_and_timelines(rrd: tuple[ProcessedTrial, Recording, Path]) -> None:
    trial, rec, _ = rrd
    for j, body in enumerate(trial.body_names):
        entity = f"/world/skeleton/{body}"
        frames, translation = rec.column(entity, "Transform3D:translation")
        _, quat = rec.column(entity, "Transform3D:quaternion")
        assert frames.tolist() == list(range(trial.n_frames))
        np.testing.assert_array_equal(
            np.array([t[0] for t in translation]), trial.body_position[:, j].astype(np.float32)
        )
        # rerun quaternions are (x, y, z, w); ours are (w, x, y, z)
        np.testing.assert_array_equal(
            np.array([q[0] for q in quat]),
            trial.body_wxyz[:, j][:, [1, 2, 3, 0]].astype(np.float32),
        )
    rb = rec.temporal["/world/markers/observed"][0]
    time_ns = rb.column("time").cast(pa.int64()).to_numpy()
    np.testing.assert_array_equal(
        time_ns, np.round(trial.time[rb.column("frame").to_numpy()] * 1e9).astype(np.int64)
    )


def test_dynamics_series(rrd: tuple[ProcessedTrial, Recording, Path]) -> None:
    trial, rec, _ = rrd
    if not trial.has_dynamics:
        # NaN dynamics: nothing logged rather than NaN rows
        assert not any(e.startswith(("/residuals", "/joint_torques")) for e in rec.temporal)
        return
    for entity, data in (
        ("/residuals/force", trial.residual_force),
        ("/residuals/moment", trial.residual_moment),
    ):
        frames, values = rec.column(entity, "Scalars:scalars")
        assert frames.tolist() == list(range(trial.n_frames))
        np.testing.assert_array_equal(np.array(values), data)
    for i, name in enumerate(trial.coordinate_names):
        _, values = rec.column(f"/joint_torques/{name}", "Scalars:scalars")
        np.testing.assert_array_equal(np.array(values)[:, 0], trial.tau[:, i])
        assert rec.static[f"/joint_torques/{name}"]["SeriesLines:names"] == [name]
    rms_frames, rms = rec.column("/markers/rms", "Scalars:scalars")
    expected = trial.marker_rms_per_frame
    np.testing.assert_array_equal(rms_frames, np.flatnonzero(np.isfinite(expected)))
    np.testing.assert_array_equal(np.array(rms)[:, 0], expected[rms_frames])
    _, flags = rec.column("/flags/unobserved", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(flags)[:, 0], trial.unobserved.astype(float))
    frames, text = rec.column("/flags/reasons", "TextLog:text")
    assert frames.tolist() == [40, 50] and [t[0] for t in text] == [
        "zero vertical force",
        "CoP outside foot",
    ]
    _, review = rec.column("/flags/review_unmeasured", "Scalars:scalars")
    assert np.flatnonzero(np.array(review)[:, 0]).tolist() == list(range(40, 55))


def test_bulk_data_is_columnar(rrd: tuple[ProcessedTrial, Recording, Path]) -> None:
    """One send_columns call per entity gives a handful of chunks, not one per frame."""
    trial, rec, _ = rrd
    assert rec.n_chunks["/world/markers/observed"] <= 3 < trial.n_frames
    assert sum(rb.num_rows for rb in rec.temporal["/world/markers/observed"]) == trial.n_frames


def test_meshes_logged_once_per_body(rrd: tuple[ProcessedTrial, Recording, Path]) -> None:
    """Each body's mesh once, static: its files' vertices (read from the .vtp) times the
    body's scale factors, one file after the other, with each file's triangles shifted by
    the vertices before it."""
    trial, rec, _ = rrd
    search = trial_search_path(trial)
    scales = [s for meshes in trial.body_meshes.values() for _, s in meshes]
    assert not np.allclose(scales, 1.0)  # the demo's model is scaled: a lost scale shows
    for body, meshes in trial.body_meshes.items():
        entity = f"/world/skeleton/{body}/mesh"
        assert rec.n_chunks[entity] == 1 and entity not in rec.temporal
        parts = [(read_vtp(find_mesh(f, search)), s) for f, s in meshes]
        vertices = np.concatenate([m.vertices * np.asarray(s) for m, s in parts])
        starts = np.cumsum([0] + [len(m.vertices) for m, _ in parts[:-1]])
        faces = np.concatenate([m.faces + n for (m, _), n in zip(parts, starts, strict=True)])
        got = rec.static[entity]
        np.testing.assert_array_equal(
            np.array(got["Mesh3D:vertex_positions"]), vertices.astype(np.float32), err_msg=body
        )
        np.testing.assert_array_equal(np.array(got["Mesh3D:triangle_indices"]), faces, err_msg=body)
    # Y up, declared once at the root
    assert "/world" in rec.static and "ViewCoordinates:xyz" in rec.static["/world"]


def test_recording_carries_settings_and_annotations(
    rrd: tuple[ProcessedTrial, Recording, Path],
) -> None:
    trial, rec, _ = rrd
    props = rec.static["/__properties/addb"]
    assert json.loads(props["settings_json"][0]) == trial.settings
    assert json.loads(props["annotations_json"][0]) == REVIEW
    info = json.loads(props["info_json"][0])
    assert (info["subject"], info["trial"], info["n_frames"]) == (
        trial.subject,
        trial.trial,
        trial.n_frames,
    )
    assert rec.static["/meta"]["settings_json"] == props["settings_json"]
    assert "Solver settings" in rec.static["/meta/summary"]["TextDocument:text"][0]


def test_before_after_recordings_differ_in_state(
    tmp_path: Path, demo_trial: ProcessedTrial
) -> None:
    a = Recording(
        write_rerun(demo_trial, tmp_path / "before.rrd", annotations=None, settings={"w": 1})
    )
    b = Recording(
        write_rerun(demo_trial, tmp_path / "after.rrd", annotations=REVIEW, settings={"w": 2})
    )
    pa_, pb = a.static["/__properties/addb"], b.static["/__properties/addb"]
    assert json.loads(pa_["settings_json"][0]) == {"w": 1} and json.loads(
        pb["settings_json"][0]
    ) == {"w": 2}
    assert (
        json.loads(pa_["annotations_json"][0]) is None
        and json.loads(pb["annotations_json"][0]) == REVIEW
    )
    # two recordings open side by side in one viewer: distinct recording ids, same application
    ra, rb = a.reader.recordings()[0], b.reader.recordings()[0]
    assert ra.application_id == rb.application_id == "addb" and ra.recording_id != rb.recording_id


def test_rerun_cli_verifies_the_file(
    rrd: tuple[ProcessedTrial, Recording, Path], rerun_env: dict[str, str]
) -> None:
    _, _, path = rrd
    res = subprocess.run(
        [str(RERUN), "rrd", "verify", str(path)],
        check=False,
        env=rerun_env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    assert "verified without error" in res.stdout + res.stderr


def _blueprint_views(path: Path) -> tuple[dict[str, dict], dict[str, dict]]:
    reader = RrdReader(path)
    (store,) = reader.blueprints()
    parts: dict[str, dict] = defaultdict(dict)
    for c in reader.stream(store=store).to_chunks():
        rb = c.to_record_batch()
        for name in rb.schema.names:
            if ":" in name:
                parts[c.entity_path][name] = rb.column(name).to_pylist()[-1]
    views = {
        p: v
        for p, v in parts.items()
        if p.startswith("/view/") and "ViewBlueprint:class_identifier" in v
    }
    return views, parts


def test_blueprint_declares_views_that_exist(tmp_path: Path, dynamic_trial: ProcessedTrial) -> None:
    path = write_rerun(dynamic_trial, tmp_path / "walk.rrd")
    views, parts = _blueprint_views(path)
    by_name = {v["ViewBlueprint:display_name"][0]: v for v in views.values()}
    assert by_name["3D"]["ViewBlueprint:class_identifier"] == ["3D"]
    assert by_name["3D"]["ViewBlueprint:space_origin"] == ["/world"]
    for name in (
        "Residual force (N)",
        "Residual moment (N·m)",
        "GRF (N)",
        "Joint torques",
        "Marker RMS (m)",
        "Flags",
    ):
        assert by_name[name]["ViewBlueprint:class_identifier"] == ["TimeSeries"], name
    # every view's origin holds logged data in the recording
    entities = set(Recording(path).temporal)
    for name, v in by_name.items():
        origin = v["ViewBlueprint:space_origin"][0]
        assert any(e == origin or e.startswith(origin + "/") for e in entities), (name, origin)
    # layout: the root container is horizontal with the 3D view first; the time panel follows frames
    root = "/container/" + str(
        uuid.UUID(bytes=bytes(parts["/viewport"]["ViewportBlueprint:root_container"][0]))
    )
    assert parts[root]["ContainerBlueprint:container_kind"] == [2]  # Horizontal
    view_3d = next(p for p, v in views.items() if v is by_name["3D"])
    assert parts[root]["ContainerBlueprint:contents"][0] == view_3d.lstrip("/")
    assert parts["/time_panel"]["TimePanelBlueprint:timeline"] == ["frame"]


def test_blueprint_function_is_independent_of_a_trial(
    tmp_path: Path, demo_trial: ProcessedTrial
) -> None:
    """Without a trial the layout is the same as with one and plays at 100 frames/s; a
    trial sets only the playback rate (its own frames per second, here a 50 Hz copy)."""
    slow = dataclasses.replace(demo_trial, time=2 * demo_trial.time)

    def saved(bp: object, name: str) -> tuple[dict[str, tuple], list]:
        path = tmp_path / name
        bp.save("addb", path)  # type: ignore[attr-defined]
        views, parts = _blueprint_views(path)
        layout = {
            v["ViewBlueprint:display_name"][0]: (
                v["ViewBlueprint:class_identifier"][0],
                v["ViewBlueprint:space_origin"][0],
            )
            for v in views.values()
        }
        return layout, parts["/time_panel"]["TimePanelBlueprint:fps"]

    alone, fps_alone = saved(blueprint(), "alone.rbl")
    with_trial, fps_trial = saved(blueprint(slow), "slow.rbl")
    assert alone == with_trial and len(alone) == 7 and alone["3D"] == ("3D", "/world")
    assert fps_alone == [100.0] and fps_trial == [pytest.approx(50.0)]


def test_missing_mesh_files_are_reported_not_fatal(
    tmp_path: Path, demo_trial: ProcessedTrial
) -> None:
    import dataclasses

    (tmp_path / "empty").mkdir()
    rec = Recording(write_rerun(demo_trial, tmp_path / "walk.rrd", mesh_path=[tmp_path / "empty"]))
    assert not any(e.endswith("/mesh") for e in rec.static)
    text = rec.static["/meta/mesh_problems"]["TextDocument:text"][0]
    assert "r_femur.vtp" in text and text.count("r_femur.vtp") == 1
    assert "/world/skeleton/pelvis" in rec.temporal  # the poses are still there
    # a recorded geometry folder that is gone: the bundled meshes are used
    trial = dataclasses.replace(demo_trial, geometry_dir=str(tmp_path / "no-such-folder"))
    rec = Recording(write_rerun(trial, tmp_path / "walk2.rrd"))
    assert "/meta/mesh_problems" not in rec.static
    assert all(f"/world/skeleton/{b}/mesh" in rec.static for b, m in trial.body_meshes.items() if m)
