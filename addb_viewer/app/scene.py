"""One processed trial frame -> viser scene nodes.

Everything is drawn in OpenSim's ground frame (Y up; the server's up direction is set to
+y, the data is not rotated). Per frame, :meth:`TrialScene.show` updates inside
``server.atomic()``:

* observed markers (one point cloud) and model markers (another colour), a line between
  each pair whose distance exceeds the marker threshold, names on demand;
* one mesh node per body (its ``.vtp`` files merged and scaled), posed by position + wxyz;
* one arrow node for all plates: each loaded plate's ground reaction force from its
  centre of pressure, ``m_per_bw`` metres per body weight, coloured by the foot it is
  assigned to; plate outlines where the corners are known;
* the centre of mass, with two arrows from it at the same scale: the summed plate force
  (measured) and ``m (a_com - g)``, the net external force the centre-of-mass
  acceleration requires; their mismatch is the residual force.

:func:`frame_geometry` computes what is drawn (pure numpy), so tests can compare the
handles with the trial's arrays.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import trimesh
import viser
from numpy.typing import NDArray

from addb_viewer.app.summary import G
from solver.results import ProcessedTrial

FloatArray = NDArray[np.float64]

OBSERVED_COLOR = (30, 150, 255)
MODEL_COLOR = (255, 140, 0)
ERROR_COLOR = (220, 20, 60)
BONE_COLOR = (225, 220, 205)
FOOT_COLORS = {"left": (40, 110, 255), "right": (240, 60, 60), "": (250, 190, 0)}
MEASURED_NET_COLOR = (0, 160, 80)
REQUIRED_COLOR = (190, 0, 190)
COM_COLOR = (30, 30, 30)
GRAVITY = np.array([0.0, -G, 0.0])


@dataclass
class SceneSettings:
    """Display options.

    Attributes
    ----------
    marker_threshold_m
        Draw a line between an observed and a model marker farther apart than this, m.
    m_per_bw
        Arrow length of one body weight of force, m.
    show_labels
        Show marker names (at the model markers).
    show_markers, show_bones, show_forces
        Layer visibility.
    """

    marker_threshold_m: float = 0.02
    m_per_bw: float = 1.0
    show_labels: bool = False
    show_markers: bool = True
    show_bones: bool = True
    show_forces: bool = True


@dataclass(frozen=True)
class FrameGeometry:
    """What the scene shows for one frame (ground frame, m).

    Attributes
    ----------
    observed
        ``(Mo, 3)`` observed markers present in this frame.
    modeled
        ``(M, 3)`` model markers.
    error_segments
        ``(K, 2, 3)`` observed -> model marker pairs farther apart than the threshold.
    body_position, body_wxyz
        ``(B, 3)`` body origins and ``(B, 4)`` orientations.
    plate_arrows, plate_colors
        ``(P, 2, 3)`` CoP -> CoP + force·scale of each loaded plate and ``(P, 3)`` colours.
    com
        ``(3,)`` centre of mass.
    com_arrows, com_colors
        ``(A, 2, 3)`` arrows from the centre of mass: summed plate force, and the force the
        centre-of-mass acceleration requires (absent without dynamics); ``(A, 3)`` colours.
    """

    observed: FloatArray
    modeled: FloatArray
    error_segments: FloatArray
    body_position: FloatArray
    body_wxyz: FloatArray
    plate_arrows: FloatArray
    plate_colors: NDArray[np.uint8]
    com: FloatArray
    com_arrows: FloatArray
    com_colors: NDArray[np.uint8]


def foot_of_body(name: str) -> str:
    """"left", "right" or "" from an OpenSim body name (``calcn_l``, ``toes_r``, ``LeftFoot``)."""
    n = name.lower()
    if re.search(r"(_l|_left)$", n) or n.startswith(("left", "l_")):
        return "left"
    if re.search(r"(_r|_right)$", n) or n.startswith(("right", "r_")):
        return "right"
    return ""


def plate_feet(trial: ProcessedTrial) -> NDArray[np.object_]:
    """``(P, T)`` foot each plate's wrench is assigned to per frame ("" when unassigned)."""
    feet_of_body = [foot_of_body(b) for b in trial.body_names]
    out = np.full((len(trial.plates), trial.n_frames), "", dtype=object)
    for i, p in enumerate(trial.plates):
        if p.body is None:
            continue
        idx = np.asarray(p.body)
        ok = (idx >= 0) & (idx < len(feet_of_body))
        out[i, ok] = [feet_of_body[j] for j in idx[ok]]
    return out


def frame_geometry(
    trial: ProcessedTrial,
    k: int,
    settings: SceneSettings,
    feet: NDArray[np.object_] | None = None,
) -> FrameGeometry:
    """The geometry of frame ``k`` (see :class:`FrameGeometry`).

    Parameters
    ----------
    trial
        The processed trial.
    k
        Frame index.
    settings
        Thresholds and arrow scale.
    feet
        ``(P, T)`` :func:`plate_feet` of the trial: the foot each plate's wrench is assigned
        to per frame (computed when not given).
    """
    feet = plate_feet(trial) if feet is None else feet
    obs = trial.observed[k]
    mod = trial.modeled[k]
    seen = np.isfinite(obs).all(axis=1)
    with np.errstate(invalid="ignore"):
        far = seen & (np.linalg.norm(mod - obs, axis=1) > settings.marker_threshold_m)
    scale = settings.m_per_bw / max(trial.mass_kg * G, 1e-9)
    arrows, colors = [], []
    for i, p in enumerate(trial.plates):
        f, c = p.force[k], p.cop[k]
        if np.isfinite(f).all() and np.isfinite(c).all() and np.linalg.norm(f) > 1e-3:
            arrows.append((c, c + f * scale))
            colors.append(FOOT_COLORS[feet[i, k]])
    com = trial.com[k]
    com_arrows, com_colors = [], []
    if trial.plates and np.isfinite(com).all():
        net = sum((np.nan_to_num(p.force[k]) for p in trial.plates), np.zeros(3))
        com_arrows.append((com, com + net * scale))
        com_colors.append(MEASURED_NET_COLOR)
    acc = trial.com_acc[k]
    if np.isfinite(acc).all() and np.isfinite(com).all():
        required = trial.mass_kg * (acc - GRAVITY)
        com_arrows.append((com, com + required * scale))
        com_colors.append(REQUIRED_COLOR)
    return FrameGeometry(
        observed=obs[seen],
        modeled=mod,
        error_segments=np.stack([obs[far], mod[far]], axis=1),
        body_position=trial.body_position[k],
        body_wxyz=trial.body_wxyz[k],
        plate_arrows=np.asarray(arrows, float).reshape(-1, 2, 3),
        plate_colors=np.asarray(colors, np.uint8).reshape(-1, 3),
        com=com,
        com_arrows=np.asarray(com_arrows, float).reshape(-1, 2, 3),
        com_colors=np.asarray(com_colors, np.uint8).reshape(-1, 3),
    )


def _node(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name) or "_"


class TrialScene:
    """The scene nodes of one trial; :meth:`show` poses them for a frame.

    Parameters
    ----------
    server
        The viser server (the nodes are shared by all clients).
    trial
        The processed trial.
    meshes
        Body name -> merged body-frame mesh (None: drawn as a small axes frame).
    settings
        Display options (kept by reference: change them, then call :meth:`show`).
    """

    ROOT = "/trial"

    def __init__(
        self,
        server: viser.ViserServer,
        trial: ProcessedTrial,
        meshes: dict[str, trimesh.Trimesh | None],
        settings: SceneSettings,
    ) -> None:
        self.server = server
        self.trial = trial
        self.settings = settings
        self.frame = -1
        self.feet = plate_feet(trial)
        self.labels: dict[str, viser.LabelHandle] = {}
        sc = server.scene
        r = self.ROOT
        with server.atomic():
            self._add_floor()
            self.observed = sc.add_point_cloud(
                f"{r}/markers/observed", np.zeros((0, 3)), OBSERVED_COLOR,
                point_size=0.02, point_shape="circle", precision="float32", point_shading="flat",
            )
            self.modeled = sc.add_point_cloud(
                f"{r}/markers/model", np.zeros((0, 3)), MODEL_COLOR,
                point_size=0.014, point_shape="circle", precision="float32", point_shading="flat",
            )
            self.errors = sc.add_line_segments(
                f"{r}/markers/errors", np.zeros((0, 2, 3)), ERROR_COLOR, thickness=0.004
            )
            self.bodies: dict[str, viser.SceneNodeHandle] = {}
            for i, body in enumerate(trial.body_names):
                self.bodies[body] = self._add_body(f"{r}/bodies/{i:02d}_{_node(body)}", meshes.get(body))
            self.plate_arrows = sc.add_arrows(
                f"{r}/forces/plates", np.zeros((1, 2, 3)), FOOT_COLORS[""],
                shaft_radius=0.008, head_radius=0.02, head_length=0.05, visible=False,
            )
            self._add_plate_outlines()
            self.com = sc.add_icosphere(f"{r}/com/point", radius=0.03, color=COM_COLOR, cast_shadow=False)
            self.com_arrows = sc.add_arrows(
                f"{r}/com/forces", np.zeros((1, 2, 3)), REQUIRED_COLOR,
                shaft_radius=0.006, head_radius=0.016, head_length=0.04, visible=False,
            )
            self.banner = sc.add_label(
                f"{r}/banner", "", font_screen_scale=1.3, anchor="bottom-center", visible=False
            )

    # ------------------------------------------------------------------ building
    def _add_floor(self) -> None:
        pel = self.trial.body_position[:, 0, :]
        ok = np.isfinite(pel).all(axis=1)
        c = np.median(pel[ok], axis=0) if ok.any() else np.zeros(3)
        span = np.ptp(pel[ok], axis=0) if ok.any() else np.zeros(3)
        size = float(max(4.0, np.ceil(max(span[0], span[2]) + 2.0)))
        self.server.scene.add_grid(
            f"{self.ROOT}/floor", width=size, height=size, plane="xz",
            cell_size=0.25, section_size=1.0, position=(float(c[0]), 0.0, float(c[2])),
            shadow_opacity=0.0,
        )

    def _add_body(self, name: str, mesh: trimesh.Trimesh | None) -> viser.SceneNodeHandle:
        sc = self.server.scene
        if mesh is None or len(mesh.faces) == 0:
            return sc.add_frame(name, axes_length=0.06, axes_radius=0.004)
        return sc.add_mesh_simple(
            name,
            vertices=np.asarray(mesh.vertices, np.float32),
            faces=np.asarray(mesh.faces, np.uint32),
            color=BONE_COLOR,
            cast_shadow=False,
            receive_shadow=False,
        )

    def _add_plate_outlines(self) -> None:
        segs = []
        for p in self.trial.plates:
            if p.corners is not None and np.isfinite(p.corners).all():
                c = np.asarray(p.corners, float)
                segs.extend((c[i], c[(i + 1) % 4]) for i in range(4))
        if segs:
            self.server.scene.add_line_segments(
                f"{self.ROOT}/forces/outlines", np.asarray(segs), (90, 90, 90), thickness=0.006
            )

    # ------------------------------------------------------------------ per frame
    def show(self, k: int, banner: str | None = None) -> FrameGeometry:
        """Pose every node for frame ``k`` (one atomic update); ``banner`` is a text shown
        above the subject (e.g. the frame's flag), None to hide it."""
        s = self.settings
        g = frame_geometry(self.trial, k, s, self.feet)
        with self.server.atomic():
            self._show_markers(g)
            for i, h in enumerate(self.bodies.values()):
                h.position = g.body_position[i]
                h.wxyz = g.body_wxyz[i]
                h.visible = s.show_bones
            _set_arrows(self.plate_arrows, g.plate_arrows, g.plate_colors, s.show_forces)
            _set_arrows(self.com_arrows, g.com_arrows, g.com_colors, s.show_forces)
            if np.isfinite(g.com).all():
                self.com.position = g.com
            self.banner.visible = banner is not None
            if banner is not None:
                self.banner.text = banner
                head = g.body_position[:, 1].max() if g.body_position.size else 1.8
                self.banner.position = (float(g.com[0]), float(head) + 0.35, float(g.com[2]))
        self.frame = k
        return g

    def _show_markers(self, g: FrameGeometry) -> None:
        s = self.settings
        self.observed.points = g.observed.astype(np.float32)
        self.modeled.points = g.modeled.astype(np.float32)
        self.observed.visible = self.modeled.visible = s.show_markers
        if len(g.error_segments):
            self.errors.points = g.error_segments
        self.errors.visible = s.show_markers and len(g.error_segments) > 0
        if s.show_labels and s.show_markers:
            self._show_labels(g.modeled)
        elif self.labels:
            self._remove_labels()

    def _show_labels(self, modeled: FloatArray) -> None:
        names = self.trial.marker_names
        if not self.labels:
            for i, n in enumerate(names):
                self.labels[n] = self.server.scene.add_label(
                    f"{self.ROOT}/labels/{i:03d}_{_node(n)}", n, font_screen_scale=0.6, anchor="bottom-left"
                )
        for i, n in enumerate(names):
            if np.isfinite(modeled[i]).all():
                self.labels[n].position = modeled[i]

    def _remove_labels(self) -> None:
        for h in self.labels.values():
            h.remove()
        self.labels.clear()

    def remove(self) -> None:
        """Remove every node of this trial from the scene."""
        self.server.scene.remove_by_name(self.ROOT)
        self.labels.clear()


def _set_arrows(handle: viser.ArrowsHandle, arrows: FloatArray, colors: NDArray[np.uint8], show: bool) -> None:
    """Show ``arrows`` ``(N, 2, 3)`` (start and end, m) in ``colors`` ``(N, 3)`` on ``handle``.

    The page applies the points and the colours as two updates (within one atomic group
    still two renders), so when the number of arrows changes the colours go to one colour
    for all first, ``(3,)``, valid for any number of arrows: per-arrow colours of the old
    count beside the new points made the page log "Invalid batched_colors length"."""
    if len(arrows):
        if len(arrows) != len(handle.points):
            handle.colors = colors[0]
        handle.points = arrows
        handle.colors = colors
    handle.visible = show and len(arrows) > 0
