"""Synthetic processed trials for the benchmark tests: the Rajagopal 2016 model from
../shared/data moving in a known way, with force plates whose wrenches are what the
motion requires (no solver run, so the tests stay fast)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from solver.benchmark.dataset import GRAVITY, skeleton_for
from solver.model.rotations import rotations_to_wxyz
from solver.results import PlateData, ProcessedTrial
from tests.conftest import SHARED_DATA

MODEL = SHARED_DATA / "models" / "Rajagopal2016.osim"


def motion(n_frames: int, *, accel: tuple[float, float, float] = (0.5, 0.0, 0.0), swing: float = 0.3) -> np.ndarray:
    """``(T, n)`` coordinates at 100 Hz: the pelvis translating with constant acceleration
    ``accel`` (m/s²) from 1 m/s forward, the right hip flexing sinusoidally (1 Hz,
    ``swing`` rad) and the left knee bending slowly (``swing / 3`` rad at 0.5 Hz)."""
    sk = skeleton_for(str(MODEL))
    t = np.arange(n_frames) / 100.0
    q = np.tile(sk.neutral(), (n_frames, 1))
    for axis, name in enumerate(("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        q[:, sk.coordinate_index(name)] += (1.0 if axis == 0 else 0.0) * t + 0.5 * accel[axis] * t**2
    q[:, sk.coordinate_index("hip_flexion_r")] = swing * np.sin(2 * np.pi * t)
    q[:, sk.coordinate_index("knee_angle_l")] = 0.2 + swing / 3 * np.sin(np.pi * t)
    return np.array([sk.cmap.complete(row) for row in q])


def processed_trial(
    n_frames: int = 60,
    *,
    subject: str = "synthetic",
    trial: str = "walk",
    q: np.ndarray | None = None,
    right: np.ndarray | None = None,
    left: np.ndarray | None = None,
    unobserved: np.ndarray | None = None,
    plate_body: dict[str, np.ndarray] | None = None,
    cop_offset: tuple[float, float, float] = (0.1, -0.05, 0.02),
) -> ProcessedTrial:
    """A :class:`ProcessedTrial` of :func:`motion` (or ``q``) on the shared model.

    The total force the motion requires, ``m (a_com - g)`` (centre-of-mass acceleration by
    central differences), is split over plate "r" (right foot, where ``right`` is True;
    default all frames) and plate "l" (left foot, where ``left``; default none), half each
    in double support, with the centre of pressure ``cop_offset`` from the foot origin and a
    free moment of (0, 2, 0) N·m. ``plate_body`` overrides a plate's body assignment
    (indices into body_names, -1 for none).
    """
    from solver.dynamics.preprocess import derivatives

    sk = skeleton_for(str(MODEL))
    q = motion(n_frames) if q is None else q
    n_frames = q.shape[0]
    time = np.arange(n_frames) / 100.0
    qd, qdd = derivatives(q, 0.01)
    com = sk.center_of_mass(q)
    com_acc = derivatives(com, 0.01)[1]
    mass = sk.total_mass
    total = mass * (com_acc - GRAVITY)
    rot, pos = sk.body_poses(q)
    right = np.ones(n_frames, dtype=bool) if right is None else right
    left = np.zeros(n_frames, dtype=bool) if left is None else left
    n_on = right.astype(int) + left.astype(int)
    plates = []
    for name, on, foot in (("r", right, "calcn_r"), ("l", left, "calcn_l")):
        b = sk.body_index(foot)
        share = np.where(on, 1.0 / np.maximum(n_on, 1), 0.0)[:, None]
        force = share * total
        cop = pos[:, b] + np.array(cop_offset)
        cop[~on] = np.nan
        free = np.where(on[:, None], [0.0, 2.0, 0.0], 0.0)
        body = np.where(on, b, -1)
        if plate_body and name in plate_body:
            body = plate_body[name]
        plates.append(PlateData(name, force, cop, free, None, body))
    wrenches = []
    from solver.model.skeleton import ExternalWrench

    for p in plates:
        on = p.body >= 0
        for b in np.unique(p.body[on]):
            sel = p.body == b
            f = np.where(sel[:, None], p.force, 0.0)
            wrenches.append(ExternalWrench(sk.body_names[b], f, np.nan_to_num(p.cop), np.where(sel[:, None], p.free_moment, 0.0)))
    idr = sk.inverse_dynamics(q, qd, qdd, wrenches)
    markers = sk.marker_positions(q)
    return ProcessedTrial(
        subject=subject,
        trial=trial,
        time=time,
        coordinate_names=sk.coordinate_names,
        q=q,
        qd=qd,
        qdd=qdd,
        marker_names=sk.marker_names,
        observed=markers,
        modeled=markers,
        body_names=sk.body_names,
        body_position=pos,
        body_wxyz=rotations_to_wxyz(rot),
        body_meshes={},
        plates=tuple(plates),
        mass_kg=mass,
        height_m=1.8,
        com=com,
        com_acc=com_acc,
        residual_force=idr.root_force,
        residual_moment=idr.root_moment,
        tau=idr.tau,
        unobserved=np.zeros(n_frames, dtype=bool) if unobserved is None else unobserved,
        proposed=np.zeros(n_frames, dtype=bool),
        proposal_reasons=("",) * n_frames,
        metrics={"hicks_linear_ok": True, "hicks_angular_ok": True},
        model_path=str(MODEL),
        settings={"rate_hz": 100.0},
    )


@pytest.fixture
def make_trial() -> Callable[..., ProcessedTrial]:
    """:func:`processed_trial` as a fixture."""
    return processed_trial


@pytest.fixture(scope="session")
def model_path() -> Path:
    """The shared Rajagopal 2016 model used by the synthetic trials."""
    return MODEL
