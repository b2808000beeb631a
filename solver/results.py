"""Everything known about one processed trial, in one object: the input of the review
app, the recorders (Rerun, MCAP), the diagnosis and the benchmark.

A :class:`ProcessedTrial` is written by the pipeline as ``OUT/<trial>/trial.npz``
(arrays) plus ``OUT/<trial>/results.json`` (metrics) and read back with
:func:`load_processed`. All arrays are on the trial's frames (the solver's common rate),
SI units, OpenSim ground frame (Y up). Dynamics fields are NaN when the trial was not
processed by the dynamics stage (no force plates, or kinematics only).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.errors import ProcessedTrialError
from solver.sampling import frame_rate

FloatArray = NDArray[np.float64]

SCHEMA_VERSION = 1


@dataclass(frozen=True)
class PlateData:
    """One force plate on the trial's frames.

    Attributes
    ----------
    name
        Plate name from the force file.
    force, cop, free_moment
        ``(T, 3)`` ground reaction force on the body (N), centre of pressure (m) and free
        moment (N·m), ground frame. CoP is NaN where the plate is unloaded.
    corners
        ``(4, 3)`` plate outline in the ground frame, m, or None when unknown.
    body
        ``(T,)`` index into :attr:`ProcessedTrial.body_names` of the body the plate's
        wrench is applied to, -1 where it is applied to none (unloaded or unmeasured).
    """

    name: str
    force: FloatArray
    cop: FloatArray
    free_moment: FloatArray
    corners: FloatArray | None = None
    body: NDArray[np.int64] | None = None


@dataclass(frozen=True)
class ProcessedTrial:
    """One trial after the solver (see the module docstring for frames and units).

    Attributes
    ----------
    subject, trial
        Names.
    time
        ``(T,)`` s.
    coordinate_names
        ``(n,)`` OpenSim coordinate names.
    q, qd, qdd
        ``(T, n)`` coordinates (rad or m) and their first and second time derivatives.
    marker_names
        ``(M,)`` model marker names.
    observed, modeled
        ``(T, M, 3)`` observed (NaN when missing) and model marker positions, m.
    body_names
        ``(B,)`` body names.
    body_position
        ``(T, B, 3)`` body frame origins, m.
    body_wxyz
        ``(T, B, 4)`` body orientations as unit quaternions (w, x, y, z).
    body_meshes
        Body name -> list of (mesh file name, (3,) scale factors) of the scaled model.
    plates
        The force plates.
    mass_kg, height_m
        Subject mass (fitted when the dynamics stage ran) and height.
    com
        ``(T, 3)`` whole-body centre of mass, m.
    com_acc
        ``(T, 3)`` centre-of-mass acceleration, m/s².
    residual_force, residual_moment
        ``(T, 3)`` root residual force (N) and moment about the root body origin (N·m),
        ground frame.
    tau
        ``(T, n)`` generalized forces (joint torques N·m, forces N).
    unobserved
        ``(T,)`` frames with unmeasured external force, excluded from the dynamic fit.
    proposed
        ``(T,)`` frames the solver proposes as unmeasured.
    proposal_reasons
        ``(T,)`` reason of each proposal ("" when none).
    metrics
        The trial's results.json content.
    model_path
        The scaled model file (.osim) the poses refer to.
    geometry_dir
        Folder holding the mesh files ("" when unknown).
    settings
        Solver settings the trial was processed with.
    """

    subject: str
    trial: str
    time: FloatArray
    coordinate_names: tuple[str, ...]
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    marker_names: tuple[str, ...]
    observed: FloatArray
    modeled: FloatArray
    body_names: tuple[str, ...]
    body_position: FloatArray
    body_wxyz: FloatArray
    body_meshes: dict[str, list[tuple[str, tuple[float, float, float]]]]
    plates: tuple[PlateData, ...]
    mass_kg: float
    height_m: float | None
    com: FloatArray
    com_acc: FloatArray
    residual_force: FloatArray
    residual_moment: FloatArray
    tau: FloatArray
    unobserved: NDArray[np.bool_]
    proposed: NDArray[np.bool_]
    proposal_reasons: tuple[str, ...]
    metrics: dict[str, Any] = field(default_factory=dict)
    model_path: str = ""
    geometry_dir: str = ""
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.time.size)

    @property
    def rate_hz(self) -> float:
        """Frame rate, Hz."""
        return frame_rate(self.time, default=0.0)

    @property
    def has_dynamics(self) -> bool:
        """True when the dynamics stage filled the residuals."""
        return bool(np.isfinite(self.residual_force).any())

    @property
    def marker_errors(self) -> FloatArray:
        """``(T, M)`` marker error distances, m."""
        return np.linalg.norm(self.modeled - self.observed, axis=2)

    @property
    def marker_rms_per_frame(self) -> FloatArray:
        """``(T,)`` RMS marker error of each frame, m (NaN when no marker is seen)."""
        e = self.marker_errors
        seen = np.isfinite(e)
        count = seen.sum(axis=1)
        total = np.where(seen, e**2, 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, np.sqrt(total / np.maximum(count, 1)), np.nan)


_ARRAYS = (
    "time", "q", "qd", "qdd", "observed", "modeled", "body_position", "body_wxyz",
    "com", "com_acc", "residual_force", "residual_moment", "tau", "unobserved", "proposed",
)


def save_processed(path: str | Path, trial: ProcessedTrial) -> None:
    """Write ``trial`` as one ``.npz`` file (arrays + a JSON header entry)."""
    arrays: dict[str, np.ndarray] = {k: np.asarray(getattr(trial, k)) for k in _ARRAYS}
    header = {
        "schema": "addb.processed_trial",
        "version": SCHEMA_VERSION,
        "subject": trial.subject,
        "trial": trial.trial,
        "coordinate_names": list(trial.coordinate_names),
        "marker_names": list(trial.marker_names),
        "body_names": list(trial.body_names),
        "body_meshes": {b: [[f, list(s)] for f, s in m] for b, m in trial.body_meshes.items()},
        "plates": [p.name for p in trial.plates],
        "mass_kg": trial.mass_kg,
        "height_m": trial.height_m,
        "proposal_reasons": list(trial.proposal_reasons),
        "model_path": trial.model_path,
        "geometry_dir": trial.geometry_dir,
        "settings": trial.settings,
    }
    for i, p in enumerate(trial.plates):
        arrays[f"plate{i}_force"] = p.force
        arrays[f"plate{i}_cop"] = p.cop
        arrays[f"plate{i}_free_moment"] = p.free_moment
        arrays[f"plate{i}_body"] = np.full(trial.n_frames, -1) if p.body is None else p.body
        if p.corners is not None:
            arrays[f"plate{i}_corners"] = p.corners
    arrays["header"] = np.array(json.dumps(header))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)  # uncompressed: writing and loading stay fast (~1 MB per 1000 frames)


def load_processed(folder: str | Path, trial: str) -> ProcessedTrial:
    """Read ``folder/<trial>/trial.npz`` and ``results.json`` written by the pipeline.

    The recorded ``model_path`` is where the scaled model was written, which is inside
    the output folder. When that file is gone and a file of the same name sits in
    ``folder``, that one is the model: the folder was moved or copied (a dataset subject
    written in a work folder and renamed into place, the diagnosis' cached judged fit).

    Raises
    ------
    FileNotFoundError
        The trial was not processed into ``folder``.
    ProcessedTrialError
        (a ``ValueError``) naming the file: it is not a processed trial of a known schema
        version, or it is damaged (truncated, not a zip archive, an array missing).
    """
    base = Path(folder) / trial
    try:
        return _load_processed(Path(folder), base)
    except ProcessedTrialError:  # already names the file (a ValueError too: kept apart)
        raise
    except (zipfile.BadZipFile, EOFError, KeyError, json.JSONDecodeError) as exc:
        raise ProcessedTrialError(
            f"cannot be read as a processed trial ({type(exc).__name__}: {exc}); the file is damaged (an interrupted "
            "copy or sync?): process the subject again",
            path=base / "trial.npz",
        ) from None
    except ValueError as exc:
        raise ProcessedTrialError(f"cannot be read as a processed trial: {exc}", path=base / "trial.npz") from None


def _load_processed(folder: Path, base: Path) -> ProcessedTrial:
    """:func:`load_processed` of ``base`` (``folder/<trial>``), its errors not yet named."""
    with np.load(base / "trial.npz", allow_pickle=False) as data:
        header = json.loads(str(data["header"]))
        if header.get("schema") != "addb.processed_trial" or header.get("version") != SCHEMA_VERSION:
            raise ProcessedTrialError(f"not a processed trial of schema version {SCHEMA_VERSION}", path=base / "trial.npz")
        arrays = {k: data[k] for k in _ARRAYS}
        plates = tuple(
            PlateData(
                name=name,
                force=data[f"plate{i}_force"],
                cop=data[f"plate{i}_cop"],
                free_moment=data[f"plate{i}_free_moment"],
                corners=data[f"plate{i}_corners"] if f"plate{i}_corners" in data.files else None,
                body=data[f"plate{i}_body"],
            )
            for i, name in enumerate(header["plates"])
        )
    metrics_path = base / "results.json"
    try:
        metrics = json.loads(metrics_path.read_text()) if metrics_path.exists() else {}
    except json.JSONDecodeError as exc:
        raise ProcessedTrialError(f"not valid JSON: {exc.msg}; the file is damaged: process the subject again",
                                  path=metrics_path, line=exc.lineno) from None  # fmt: skip
    return ProcessedTrial(
        subject=header["subject"],
        trial=header["trial"],
        coordinate_names=tuple(header["coordinate_names"]),
        marker_names=tuple(header["marker_names"]),
        body_names=tuple(header["body_names"]),
        body_meshes={b: [(f, tuple(s)) for f, s in m] for b, m in header["body_meshes"].items()},
        plates=plates,
        mass_kg=float(header["mass_kg"]),
        height_m=header["height_m"],
        proposal_reasons=tuple(header["proposal_reasons"]),
        metrics=metrics,
        model_path=_model_in(Path(folder), header["model_path"]),
        geometry_dir=header["geometry_dir"],
        settings=header["settings"],
        **{k: arrays[k] for k in _ARRAYS},
    )


def processed_trials(folder: str | Path) -> list[str]:
    """Names of the trials processed into ``folder`` (those with a trial.npz)."""
    return sorted(p.parent.name for p in Path(folder).glob("*/trial.npz"))


def field_names() -> list[str]:
    """Names of the fields of :class:`ProcessedTrial` (for documentation and tests)."""
    return [f.name for f in fields(ProcessedTrial)]


def _model_in(folder: Path, recorded: str) -> str:
    """``recorded``, or the file of that name in ``folder`` when ``recorded`` is gone."""
    if not recorded or Path(recorded).is_file():
        return recorded
    moved = folder / Path(recorded).name
    return str(moved) if moved.is_file() else recorded
