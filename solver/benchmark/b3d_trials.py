"""Benchmark trials from AddBiomechanics .b3d files (the published dataset's format).

Werling et al. 2024, §5: the inputs are the kinematics pass's coordinates and the labels
come from the dynamics pass, on frames with measured force. :func:`b3d_processed_trials`
turns each trial of a .b3d file into a :class:`~solver.results.ProcessedTrial` made of the
file's last ``dynamics`` pass, so :func:`solver.benchmark.dataset.benchmark_trial` scores
it like one of ours:

* coordinates, velocities, accelerations and joint torques: the pass's (the D stored
  coordinates put into the embedded model's coordinate vector, the dependent coupled
  coordinates completed by their couplers; their torque 0);
* centre of mass and its acceleration: the pass's;
* contact: one pseudo plate per ground contact body, applied to that body: force and
  moment about the origin from ``ground_contact_wrench`` ([moment, force]), the centre of
  pressure from ``ground_contact_center_of_pressure`` (the origin's when not stored),
  free moment = moment − CoP × force;
* frames with unmeasured force: those whose missing-GRF reason is not ``notMissingGRF``;
* observed markers: the sensor frames' markers that the model has (exactly (0, 0, 0)
  counts as missing); body poses by our forward kinematics of the model;
* the benchmark input with ``inputs="kinematic"``: the kinematics pass's coordinates when
  the file has one (``settings["kinematic_q"]``), else inverse kinematics of the markers.

Format reference: keenon/nimblephysics ``dart/proto/SubjectOnDisk.proto``.
"""

from __future__ import annotations

import hashlib
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from solver.results import PlateData, ProcessedTrial


def _model_file(text: str) -> Path:
    """The model text as a file (the benchmark's skeleton cache is keyed by path)."""
    folder = Path(tempfile.gettempdir()) / "addb_b3d_models"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{hashlib.sha1(text.encode('utf-8')).hexdigest()[:20]}.osim"
    if not path.exists():
        tmp = path.with_suffix(".partial")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)
    return path


def b3d_processed_trials(path: str | Path) -> Iterator[ProcessedTrial]:
    """The trials of a .b3d file's dynamics pass as processed trials (see the module docstring).

    Raises
    ------
    B3dFormatError
        The file is damaged.
    BenchmarkError
        The file has no dynamics pass (no ground truth).
    """
    from solver.benchmark.models import BenchmarkError, skeleton_for
    from solver.io.b3d import dof_names, open_b3d
    from solver.model.rotations import rotations_to_wxyz

    f = open_b3d(path)
    h = f.header
    dyn = [j for j, p in enumerate(h.passes) if p.type == "dynamics"]
    if not dyn:
        raise BenchmarkError(
            f"no dynamics pass (passes: {', '.join(p.type for p in h.passes) or 'none'}): the benchmark's ground truth is a dynamics pass",
            path=path,
        )
    d = dyn[-1]
    kin = next((j for j, p in enumerate(h.passes) if p.type == "kinematics"), None)
    model_path = _model_file(f.model_text(d))
    skel = skeleton_for(str(model_path))
    model = skel.osim
    names = dof_names(model)
    if len(names) != h.n_dofs:
        raise BenchmarkError(f"the embedded model has {len(names)} independent coordinates, the file {h.n_dofs}", path=path)
    cols = np.array([skel.coordinate_index(n) for n in names], dtype=np.intp)
    model_markers = {m.name for m in model.markers}
    markers = [(j, m) for j, m in enumerate(h.marker_names) if m in model_markers]
    midx = skel.marker_index([m for _, m in markers])
    subject = Path(path).stem

    def full(values: np.ndarray, complete: bool) -> np.ndarray:
        out = np.zeros((values.shape[0], skel.n))
        out[:, cols] = values
        return skel.cmap.complete(out) if complete else out

    for k, info in enumerate(h.trials):
        if info.n_frames == 0 or d >= len(info.passes):
            continue
        fr = f.read_trial(k)
        p = fr.passes[d]
        t = info.n_frames
        q = full(p.pos, True)
        rot, pos = skel.body_poses(q)
        observed = fr.markers[:, [j for j, _ in markers], :].copy()
        observed[(observed == 0.0).all(axis=2)] = np.nan
        plates = []
        for b, body in enumerate(h.ground_contact_bodies):
            force = p.ground_contact_wrench[:, b, 3:]
            moment_o = p.ground_contact_wrench[:, b, :3]
            cop = p.ground_contact_cop[:, b] if p.ground_contact_force[:, b].any() else np.zeros((t, 3))
            body_index = skel.body_names.index(body) if body in skel.body_names else -1
            plates.append(
                PlateData(
                    name=body, force=force.copy(), cop=cop.copy(), free_moment=moment_o - np.cross(cop, force),
                    corners=None, body=np.full(t, body_index, dtype=np.int64),
                )
            )
        residual = p.extra.get("root_frame_residual")
        res_f = np.zeros((t, 3))
        res_m = np.zeros((t, 3))
        if residual is not None and residual.shape == (t, 6):
            root_body = model.joints[0].child.body if model.joints else skel.body_names[0]
            root = rot[:, skel.body_names.index(root_body)]
            res_m = np.einsum("tij,tj->ti", root, residual[:, :3])
            res_f = np.einsum("tij,tj->ti", root, residual[:, 3:])
        unobserved = np.array([r != "notMissingGRF" for r in info.missing_grf], dtype=bool)
        settings: dict = {"source": str(Path(path).resolve()), "pass": d}
        if kin is not None and kin != d and kin < len(info.passes):
            settings["kinematic_q"] = full(fr.passes[kin].pos, True)
        yield ProcessedTrial(
            subject=subject,
            trial=info.name,
            time=np.arange(t) * info.timestep_s,
            coordinate_names=skel.coordinate_names,
            q=q,
            qd=full(p.vel, False),
            qdd=full(p.acc, False),
            marker_names=tuple(m for _, m in markers),
            observed=observed,
            modeled=skel.marker_positions(q, midx),
            body_names=skel.body_names,
            body_position=pos,
            body_wxyz=rotations_to_wxyz(rot),
            body_meshes={},
            plates=tuple(plates),
            mass_kg=h.mass_kg,
            height_m=h.height_m or None,
            com=p.com_pos.copy(),
            com_acc=p.com_acc.copy(),
            residual_force=res_f,
            residual_moment=res_m,
            tau=full(p.tau, False),
            unobserved=unobserved,
            proposed=unobserved.copy(),
            proposal_reasons=tuple("" if r == "notMissingGRF" else r for r in info.missing_grf),
            metrics={},
            model_path=str(model_path),
            settings=settings,
        )
