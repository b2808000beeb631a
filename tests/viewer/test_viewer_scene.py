"""Scene level, no browser: after seeking frame k, the marker, body and arrow handles of a
real viser server hold the positions the solver computed for frame k."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import viser

from addb_viewer.app.meshes import body_mesh
from addb_viewer.app.scene import (
    GRAVITY,
    MEASURED_NET_COLOR,
    REQUIRED_COLOR,
    SceneSettings,
    TrialScene,
    foot_of_body,
    frame_geometry,
)
from addb_viewer.app.summary import G
from addb_viewer.geometry import trial_search_path

F32 = {"atol": 1e-5, "rtol": 1e-5}  # viser stores positions as float32


def _expected_plate_arrows(trial, k: int, m_per_bw: float) -> np.ndarray:
    scale = m_per_bw / (trial.mass_kg * G)
    out = []
    for p in trial.plates:
        f, c = p.force[k], p.cop[k]
        if np.isfinite(f).all() and np.isfinite(c).all() and np.linalg.norm(f) > 1e-3:
            out.append((c, c + f * scale))
    return np.asarray(out).reshape(-1, 2, 3)


@pytest.mark.parametrize("k", [0, 57, 137, 237])
def test_seeking_frame_k_poses_every_handle(demo_paths, make_app, k: int) -> None:
    app = make_app(demo_paths)
    trial, scene = app.trial, app.scene
    assert trial.trial == "walk" and trial.n_frames == 238
    app.panel.frame.value = k  # as the page's slider does; fires on_update
    assert app.playback.frame == k and scene.frame == k

    seen = np.isfinite(trial.observed[k]).all(axis=1)
    np.testing.assert_allclose(scene.observed.points, trial.observed[k][seen], **F32)
    np.testing.assert_allclose(scene.modeled.points, trial.modeled[k], **F32)
    assert len(scene.bodies) == len(trial.body_names) == 22
    for b, name in enumerate(trial.body_names):
        np.testing.assert_allclose(scene.bodies[name].position, trial.body_position[k, b], **F32)
        np.testing.assert_allclose(scene.bodies[name].wxyz, trial.body_wxyz[k, b], **F32)
    expected = _expected_plate_arrows(trial, k, app.settings.m_per_bw)
    assert scene.plate_arrows.visible == (len(expected) > 0)
    if len(expected):
        np.testing.assert_allclose(scene.plate_arrows.points, expected, **F32)
    np.testing.assert_allclose(scene.com.position, trial.com[k], **F32)
    assert f"frame {k} / 237" in app.panel.status.content


def test_arrows_scale_with_the_body_weight_setting(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    k = 130  # single support on a plate in the demo
    app.seek(k)
    before = np.asarray(app.scene.plate_arrows.points, float)
    assert len(before) >= 1
    app.panel.m_per_bw.value = 0.5
    after = np.asarray(app.scene.plate_arrows.points, float)
    np.testing.assert_allclose(after[:, 0], before[:, 0], atol=1e-5)  # still at the CoP
    np.testing.assert_allclose(after[:, 1] - after[:, 0], 0.5 * (before[:, 1] - before[:, 0]), atol=1e-5)
    # 1 body weight is drawn 0.5 m long
    force = sum(np.nan_to_num(p.force[k]) for p in app.trial.plates)
    length = np.linalg.norm(after[:, 1] - after[:, 0], axis=1).sum()
    assert length == pytest.approx(0.5 * np.linalg.norm(force) / (app.trial.mass_kg * G), rel=1e-3)


def test_marker_error_lines_and_names(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    app.panel.marker_threshold_cm.value = 0.0  # every seen marker gets a line
    app.seek(10)
    trial, scene = app.trial, app.scene
    seen = np.isfinite(trial.observed[10]).all(axis=1)
    segs = np.asarray(scene.errors.points)
    assert scene.errors.visible and segs.shape == (seen.sum(), 2, 3)
    np.testing.assert_allclose(segs[:, 0], trial.observed[10][seen], **F32)
    np.testing.assert_allclose(segs[:, 1], trial.modeled[10][seen], **F32)
    app.panel.marker_threshold_cm.value = 100.0
    assert not scene.errors.visible
    app.panel.show_labels.value = True
    assert set(scene.labels) == set(trial.marker_names)
    first = trial.marker_names[0]
    np.testing.assert_allclose(scene.labels[first].position, trial.modeled[10, 0], **F32)
    app.panel.show_labels.value = False
    assert not scene.labels


def test_required_force_arrow_from_the_centre_of_mass_acceleration(demo_paths, make_app) -> None:
    """With dynamics (here synthesized), the second arrow at the COM is m (a_com - g)."""
    app = make_app(demo_paths)
    base = app.trial
    acc = np.tile([0.5, 1.0, -0.2], (base.n_frames, 1))
    trial = dataclasses.replace(base, com_acc=acc, residual_force=np.zeros((base.n_frames, 3)))
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        settings = SceneSettings(m_per_bw=1.0)
        meshes = {b: body_mesh(trial_search_path(trial), m)[0] for b, m in trial.body_meshes.items()}
        scene = TrialScene(server, trial, meshes, settings)
        k = 120
        scene.show(k)
        arrows = np.asarray(scene.com_arrows.points, float)
        scale = 1.0 / (trial.mass_kg * G)
        net = sum(np.nan_to_num(p.force[k]) for p in trial.plates)
        required = trial.mass_kg * (acc[k] - GRAVITY)
        np.testing.assert_allclose(arrows[0], [trial.com[k], trial.com[k] + net * scale], atol=1e-5)
        np.testing.assert_allclose(arrows[1], [trial.com[k], trial.com[k] + required * scale], atol=1e-5)
        np.testing.assert_array_equal(scene.com_arrows.colors, [MEASURED_NET_COLOR, REQUIRED_COLOR])
        scene.remove()
    finally:
        server.stop()


def test_missing_markers_and_unloaded_plates_are_left_out(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    t = app.trial
    obs = t.observed.copy()
    obs[5, :3] = np.nan
    plates = tuple(dataclasses.replace(p, force=np.zeros_like(p.force)) for p in t.plates)
    g = frame_geometry(dataclasses.replace(t, observed=obs, plates=plates), 5, SceneSettings())
    assert g.observed.shape == (len(t.marker_names) - 3, 3)
    assert g.plate_arrows.shape == (0, 2, 3)
    assert g.com_arrows.shape == (1, 2, 3)  # net plate force (zero length); no dynamics yet


def test_foot_of_body() -> None:
    assert [foot_of_body(b) for b in ("calcn_l", "toes_r", "pelvis", "LeftFoot", "r_foot")] == [
        "left", "right", "", "left", "right",
    ]


def test_arrow_colours_match_the_arrows_at_every_update(demo_paths, make_app) -> None:
    """Stepping through the walk, the plate arrows' count changes (one foot, two, none):
    each single update of the handle leaves colours the page accepts beside the points it
    has, one per arrow or one for all (a mismatch made the page log "Invalid
    batched_colors length")."""
    from addb_viewer.app import scene as scene_module

    app = make_app(demo_paths)
    states: list[tuple[int, int]] = []  # (arrows, colour rows) after each update

    class Recording:
        def __init__(self, handle: viser.ArrowsHandle) -> None:
            self.__dict__["handle"] = handle

        def __getattr__(self, name: str) -> object:
            return getattr(self.handle, name)

        def __setattr__(self, name: str, value: object) -> None:
            setattr(self.handle, name, value)
            if name in ("points", "colors"):
                colours = np.asarray(self.handle.colors)
                states.append((len(self.handle.points), 1 if colours.ndim == 1 else len(colours)))

    real = scene_module._set_arrows
    counts = []
    for k in range(app.trial.n_frames):
        geometry = frame_geometry(app.trial, k, app.settings)
        counts.append(len(geometry.plate_arrows))
        real(Recording(app.scene.plate_arrows), geometry.plate_arrows, geometry.plate_colors, True)
    assert {0, 1, 2} <= set(counts)  # the count does change along the walk
    assert states and all(colours in (1, arrows) for arrows, colours in states), [s for s in states if s[1] not in (1, s[0])][:5]
