"""The skeleton always: bone meshes are found for a subject folder without a ``Geometry``
folder (shared/data/subjects/rajagopal2016_walk) in the review app's scene, in
``addb record`` (Rerun) and ``addb export`` (MCAP); the search path's order, ``--geometry``
and ``$ADDB_GEOMETRY``; the bundled set is the regenerable copy of the shared meshes."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import viser
from mcap.reader import make_reader
from rerun.chunk import RrdReader

from addb_viewer.app.meshes import body_mesh, read_vtp
from addb_viewer.app.paths import ReviewPaths, UnsafePathError
from addb_viewer.cli import main
from addb_viewer.geometry import (
    BUNDLED_GEOMETRY,
    GEOMETRY_ENV,
    GeometryPathError,
    find_mesh,
    mesh_search_path,
    report_missing,
    trial_search_path,
)
from solver.io.mcap_file import TOPIC_BONES
from solver.results import ProcessedTrial, load_processed
from tests.conftest import writable_copy

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def plain_subject(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An ordinary AddBiomechanics subject folder: no Geometry folder beside the model. A
    private copy of the shared walk: the app and the recorders open the subject's review
    record, which on a writable ../shared would otherwise be written into the shared data."""
    shared = shared_data / "subjects" / "rajagopal2016_walk"
    assert not (shared / "Geometry").exists() and not (shared.parent / "Geometry").exists()
    subject = writable_copy(shared, tmp_path_factory.mktemp("plain_subject") / "rajagopal2016_walk")
    assert not (subject.parent / "Geometry").exists()
    return subject


@pytest.fixture(scope="module")
def plain_out(plain_subject: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The subject through the kinematics stage (what the app and the recorders read)."""
    from solver.pipeline import process_kinematics

    out = tmp_path_factory.mktemp("plain") / "out"
    process_kinematics(plain_subject, out)
    return out


@pytest.fixture(scope="module")
def plain_trial(plain_out: Path) -> ProcessedTrial:
    return load_processed(plain_out, "walk")


def _mesh_files(trial: ProcessedTrial) -> dict[str, list[str]]:
    return {b: [f for f, _ in m] for b, m in trial.body_meshes.items() if m}


def _expected_vertices(files: list[str]) -> int:
    return sum(len(read_vtp(BUNDLED_GEOMETRY / f).vertices) for f in files)


# ----------------------------------------------------------------------------- search path
def test_search_path_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(GEOMETRY_ENV, raising=False)
    subject = tmp_path / "s01"
    (subject / "Geometry").mkdir(parents=True)
    models = tmp_path / "models"
    (models / "Geometry").mkdir(parents=True)
    (models / "generic.osim").write_text("<OpenSimDocument/>")
    (subject / "unscaled_generic.osim").symlink_to(models / "generic.osim")
    mine = tmp_path / "mine"
    mine.mkdir()
    path = mesh_search_path(subject, subject / "unscaled_generic.osim", mine)
    assert path == (
        subject / "Geometry",
        subject,  # the model's folder (as linked) ...
        models / "Geometry",  # ... and the folders of the file the link points to
        models,
        mine,
        BUNDLED_GEOMETRY,
    )
    # a file in an earlier folder wins over the bundled copy
    shutil.copyfile(BUNDLED_GEOMETRY / "sacrum.vtp", mine / "r_femur.vtp")
    assert find_mesh("r_femur.vtp", path) == (mine / "r_femur.vtp").resolve()
    assert find_mesh("Geometry/r_pelvis.vtp", path) == BUNDLED_GEOMETRY / "r_pelvis.vtp"
    assert find_mesh("no_such_bone.vtp", path) is None
    with pytest.raises(UnsafePathError, match="outside"):
        find_mesh("../s01/unscaled_generic.osim", (mine, BUNDLED_GEOMETRY))


def test_environment_and_bad_folders(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    monkeypatch.setenv(GEOMETRY_ENV, f"{a}:{b}")
    assert mesh_search_path(None, None) == (a, b, BUNDLED_GEOMETRY)
    assert mesh_search_path(None, None, b) == (b, BUNDLED_GEOMETRY)  # --geometry replaces it
    monkeypatch.setenv(GEOMETRY_ENV, str(tmp_path / "nope"))
    with pytest.raises(GeometryPathError, match=r"nope.*\$ADDB_GEOMETRY must name a folder"):
        mesh_search_path(None, None)
    with pytest.raises(GeometryPathError, match=r"missing.*--geometry"):
        mesh_search_path(None, None, tmp_path / "missing")


def test_a_missing_mesh_is_named_once(capsys: pytest.CaptureFixture[str]) -> None:
    problem = "mesh file nowhere_test_only.vtp not found in /x"
    assert report_missing([problem, problem]) == [problem]
    assert report_missing([problem]) == []
    assert capsys.readouterr().err.count("nowhere_test_only.vtp") == 1


def test_bundled_set_is_what_the_script_makes() -> None:
    """``scripts/make_geometry_data.py --check`` agrees with the folder (files and list), and
    every mesh of the shared models that OpenSim's set holds is bundled."""
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "make_geometry_data.py"), "--check"],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 0, done.stderr
    listed = [line.split("\t")[0] for line in (BUNDLED_GEOMETRY / "FILES.txt").read_text().splitlines()[1:]]
    assert sorted(listed) == sorted(p.name for p in BUNDLED_GEOMETRY.glob("*.vtp"))
    size = sum(p.stat().st_size for p in BUNDLED_GEOMETRY.iterdir())
    assert size < 6e6  # a few MB, not OpenSim's 16 MB
    assert "opensim-models" in (BUNDLED_GEOMETRY / "README.md").read_text()


def test_every_shared_model_is_drawn_from_the_bundled_set(shared_data: Path) -> None:
    for model in sorted(shared_data.rglob("*.osim")):
        names = set(re.findall(r"<(?:mesh_file|geometry_file)>\s*([^<\s]+)\s*<", model.read_text()))
        missing = {n for n in names if find_mesh(n, (BUNDLED_GEOMETRY,)) is None}
        # the expert comparison's pelvis meshes are not part of OpenSim's set
        assert missing <= {"r_pelvis_raja.vtp", "l_pelvis_raja.vtp"}, (model, missing)


# ----------------------------------------------------------------------------- the app's scene
def test_scene_has_a_mesh_for_every_body_without_a_geometry_folder(
    plain_subject: Path, plain_out: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, make_app
) -> None:
    monkeypatch.delenv(GEOMETRY_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    out = tmp_path / "out"
    shutil.copytree(plain_out, out)
    app = make_app(ReviewPaths.for_subject(plain_subject, out))
    assert app.trial is not None and app.scene is not None
    files = _mesh_files(app.trial)
    assert len(files) == len(app.trial.body_names) == 22
    assert not app.panel.error.visible, app.panel.error.content  # no "drawn as axes" error
    for body, names in files.items():
        node = app.scene.bodies[body]
        assert isinstance(node, viser.MeshHandle), body  # not an axes frame
        assert len(node.vertices) == _expected_vertices(names), body
    assert not any(isinstance(h, viser.FrameHandle) for h in app.scene.bodies.values())


def test_review_app_uses_the_geometry_option(
    plain_subject: Path, plain_out: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, make_app
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    mine = tmp_path / "mine"
    mine.mkdir()
    shutil.copyfile(BUNDLED_GEOMETRY / "hat_skull.vtp", mine / "r_femur.vtp")  # a recognizable stand-in
    out = tmp_path / "out"
    shutil.copytree(plain_out, out)
    app = make_app(ReviewPaths.for_subject(plain_subject, out), geometry=mine)
    femur = app.scene.bodies["femur_r"]
    assert len(femur.vertices) == len(read_vtp(mine / "r_femur.vtp").vertices)


def test_missing_files_fall_back_to_axes_and_are_reported(plain_trial: ProcessedTrial, tmp_path: Path) -> None:
    mesh, problems = body_mesh((tmp_path,), plain_trial.body_meshes["femur_r"])
    assert mesh is None and len(problems) == 1 and "r_femur.vtp not found in" in problems[0]


# ----------------------------------------------------------------------------- recordings
def test_record_writes_mesh3d_for_every_body(
    plain_subject: Path, plain_out: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``addb record`` of a subject without a Geometry folder writes the bones."""
    monkeypatch.delenv(GEOMETRY_ENV, raising=False)
    rrd = tmp_path / "walk.rrd"
    argv = ["record", str(plain_subject), "--trial", "walk", "-o", str(rrd), "--out", str(plain_out)]
    assert main(argv) == 0
    meshes: dict[str, int] = {}
    entities = set()
    for c in RrdReader(rrd).stream().to_chunks():
        entities.add(c.entity_path)
        rb = c.to_record_batch()
        if c.is_static and "Mesh3D:vertex_positions" in rb.schema.names:
            meshes[c.entity_path] = len(rb.column("Mesh3D:vertex_positions").to_pylist()[0])
    trial = load_processed(plain_out, "walk")
    files = _mesh_files(trial)
    assert set(meshes) == {f"/world/skeleton/{b}/mesh" for b in files}
    for body, names in files.items():
        assert meshes[f"/world/skeleton/{body}/mesh"] == _expected_vertices(names), body
    assert "/meta/mesh_problems" not in entities


def test_record_with_geometry_option_and_a_bad_one(
    plain_subject: Path, plain_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    shutil.copyfile(BUNDLED_GEOMETRY / "hat_skull.vtp", mine / "r_femur.vtp")
    rrd = tmp_path / "walk.rrd"
    base = ["record", str(plain_subject), "--trial", "walk", "-o", str(rrd), "--out", str(plain_out)]
    assert main([*base, "--geometry", str(mine)]) == 0
    femur = next(
        c.to_record_batch() for c in RrdReader(rrd).stream().to_chunks()
        if c.entity_path == "/world/skeleton/femur_r/mesh"
    )
    n = len(femur.column("Mesh3D:vertex_positions").to_pylist()[0])
    assert n == len(read_vtp(mine / "r_femur.vtp").vertices)
    capsys.readouterr()
    assert main([*base, "--geometry", str(tmp_path / "nowhere")]) == 1
    assert "nowhere" in capsys.readouterr().err


def test_export_mcap_carries_the_bones(
    plain_subject: Path, plain_out: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(GEOMETRY_ENV, raising=False)
    path = tmp_path / "walk.mcap"
    argv = ["export", str(plain_subject), "--trial", "walk", "--format", "mcap", "-o", str(path)]
    assert main([*argv, "--out", str(plain_out)]) == 0
    trial = load_processed(plain_out, "walk")
    files = _mesh_files(trial)
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        msgs = list(reader.iter_messages(topics=[TOPIC_BONES]))
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert len(msgs) == 1  # once, not per frame
    schema, _, message = msgs[0]
    assert schema.name == "foxglove.SceneUpdate"
    update = json.loads(message.data)
    by_id = {e["id"]: e for e in update["entities"]}
    assert set(by_id) == {f"bone/{b}" for b in files}
    for body, names in files.items():
        e = by_id[f"bone/{body}"]
        assert e["frame_id"] == body and e["frame_locked"] is True
        (model,) = e["models"]
        assert model["media_type"] == "model/gltf-binary"
        glb = trimesh.load(io.BytesIO(base64.b64decode(model["data"])), file_type="glb")
        n = sum(len(g.vertices) for g in glb.geometry.values())
        assert n == _expected_vertices(names), body
    assert json.loads(meta["addb.meshes"]["missing"]) == []
    assert str(BUNDLED_GEOMETRY) in json.loads(meta["addb.meshes"]["search_path"])


def test_trial_search_path_follows_the_trial(plain_trial: ProcessedTrial, plain_subject: Path) -> None:
    path = trial_search_path(plain_trial, plain_subject)
    # compared resolved: ../shared may be a link to the data (the search path resolves it)
    assert path[0].resolve() == plain_subject.resolve() and path[-1] == BUNDLED_GEOMETRY
    assert np.all([p.is_dir() for p in path])
