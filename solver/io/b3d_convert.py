"""Between .b3d files and addb's folders.

* :func:`b3d_to_subject`: a .b3d file -> an AddBiomechanics subject folder that
  ``addb process`` solves (``_subject.json``, the embedded model as
  ``unscaled_generic.osim``, ``trials/<trial>/markers.trc`` and ``grf.mot``), plus the
  file's missing-GRF labels per trial for the caller to store as a review record (this
  module does not write review records: :mod:`solver` does not import ``annotations``).
* :func:`processed_to_b3d`: a processed output folder -> a .b3d file (sensor data, a
  kinematics pass and a dynamics pass, the scaled model).

Format reference: keenon/nimblephysics ``dart/proto/SubjectOnDisk.proto`` and
``dart/biomechanics/SubjectOnDisk.cpp``; the raw plate torque of a sensor frame is the
free moment about the centre of pressure (checked on results.b3d: the stored contact
wrench about the origin equals CoP × force + that torque).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver.errors import SubjectFolderError
from solver.io.b3d import B3dFile, open_b3d
from solver.io.mot import write_forces
from solver.io.subject import MODEL_FILE, SUBJECT_JSON
from solver.io.trc import write_trc
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories

#: The name of the file in a converted subject folder that says where it came from.
SOURCE_JSON = "b3d_source.json"


@dataclass(frozen=True)
class ConvertedTrial:
    """One trial written by :func:`b3d_to_subject`.

    Attributes
    ----------
    name
        Trial folder name (the .b3d trial name, with path separators replaced).
    b3d_name
        The trial name in the .b3d file.
    n_frames, rate_hz
        Frames and frame rate of the written markers and forces.
    missing_grf
        ``(N,)`` the file's missing-GRF reason per frame (``"notMissingGRF"`` = measured).
    """

    name: str
    b3d_name: str
    n_frames: int
    rate_hz: float
    missing_grf: tuple[str, ...] = field(repr=False)

    @property
    def missing_mask(self) -> np.ndarray:
        """``(N,)`` bool: frames the file marks as missing ground reaction force."""
        return np.array([r != "notMissingGRF" for r in self.missing_grf], dtype=bool)


@dataclass(frozen=True)
class ConvertedSubject:
    """Result of :func:`b3d_to_subject`: the subject folder and its trials."""

    path: Path
    source: Path
    trials: tuple[ConvertedTrial, ...]


def _folder_name(name: str, used: set[str]) -> str:
    base = re.sub(r"[\\/:\s]+", "_", name).strip("._") or "trial"
    out, k = base, 1
    while out in used:
        k += 1
        out = f"{base}_{k}"
    used.add(out)
    return out


def b3d_to_subject(
    path: str | Path | B3dFile,
    out_dir: str | Path,
    *,
    pass_index: int = 0,
    overwrite: bool = False,
) -> ConvertedSubject:
    """Write a .b3d file as an AddBiomechanics subject folder.

    Markers go to ``markers.trc`` (mm, unobserved = NaN; a marker with an empty name is
    left out, as no TRC column can be named "", and so is a marker not observed on any
    frame of the trial, which ``addb process`` refuses; a position of exactly (0, 0, 0),
    which some .b3d files hold for unobserved markers, reads back from the TRC as missing,
    the TRC convention); the raw force plates of every frame to
    ``grf.mot`` (force N, centre of pressure m, free moment N·m, plates named 1..P). The
    model of processing pass ``pass_index`` (AddBiomechanics' scaled model) becomes
    ``unscaled_generic.osim``; ``_subject.json`` carries mass, height, sex, age, tags and
    the ground contact bodies as ``footBodyNames``.

    Parameters
    ----------
    path
        The .b3d file (or an open :class:`B3dFile`).
    out_dir
        The subject folder to write (created; must not already hold a ``_subject.json``
        unless ``overwrite``).
    pass_index
        Which pass's model to embed.
    overwrite
        Replace the files of an existing converted subject.

    Returns
    -------
    ConvertedSubject
        Including each trial's missing-GRF reasons, for the review record.

    Raises
    ------
    B3dFormatError
        The file is damaged.
    SubjectFolderError
        ``out_dir`` already holds a subject and ``overwrite`` is False, or the file has no
        trial with frames or no model.
    """
    b3d = path if isinstance(path, B3dFile) else open_b3d(path)
    h = b3d.header
    out = Path(out_dir)
    if (out / SUBJECT_JSON).exists() and not overwrite:
        raise SubjectFolderError("already holds a subject; pass overwrite (--force) to replace it", path=out)
    if not h.passes or not (0 <= pass_index < len(h.passes)):
        raise SubjectFolderError(f"the file has {len(h.passes)} processing passes, no pass {pass_index} to take the model from", path=b3d.path)
    if not any(t.n_frames for t in h.trials):
        raise SubjectFolderError("the file has no trial with frames", path=b3d.path)
    out.mkdir(parents=True, exist_ok=True)
    (out / MODEL_FILE).write_text(b3d.model_text(pass_index), encoding="utf-8")
    keep = [j for j, name in enumerate(h.marker_names) if name]
    used: set[str] = set()
    trials = []
    for k, t in enumerate(h.trials):
        if t.n_frames == 0:
            continue
        fr = b3d.read_trial(k)
        folder = out / "trials" / _folder_name(t.name, used)
        folder.mkdir(parents=True, exist_ok=True)
        time = np.arange(t.n_frames) * t.timestep_s
        absent = np.isnan(fr.markers).any(axis=2) | (fr.markers == 0.0).all(axis=2)  # (N, M)
        seen = [j for j in keep if not absent[:, j].all()]
        markers = MarkerTrajectories(
            tuple(h.marker_names[j] for j in seen), fr.markers[:, seen, :], time, t.rate_hz, source=str(b3d.path)
        )
        write_trc(folder / "markers.trc", markers)
        if t.n_force_plates:
            plates = tuple(
                ForcePlate(
                    name=str(p + 1),
                    force=np.nan_to_num(fr.plate_force[:, p]),
                    cop=np.nan_to_num(fr.plate_cop[:, p]),
                    free_moment=np.nan_to_num(fr.plate_moment[:, p]),
                    corners=t.force_plate_corners[p] if p < t.force_plate_corners.shape[0] else None,
                )
                for p in range(t.n_force_plates)
            )
            write_forces(folder / "grf.mot", ForceRecording(time, t.rate_hz, plates, source=str(b3d.path)))
        trials.append(ConvertedTrial(folder.name, t.name, t.n_frames, t.rate_hz, t.missing_grf))
    subject: dict[str, Any] = {
        "massKg": h.mass_kg,
        "heightM": h.height_m,
        "sex": h.sex or "unknown",
        "subjectTags": list(h.tags),
        "footBodyNames": list(h.ground_contact_bodies) or ["calcn_r", "calcn_l"],
        "disableDynamics": False,
        "segmentedTrials": [c.name for c in trials],
    }
    if h.age_years > 0:
        subject["ageYears"] = h.age_years
    (out / SUBJECT_JSON).write_text(json.dumps(subject, indent=2) + "\n")
    source = {
        "b3d": str(Path(b3d.path).resolve()),
        "version": h.version,
        "model_from_pass": pass_index,
        "model_pass_type": h.passes[pass_index].type,
        "notes": h.notes,
        "href": h.href,
        "trials": {c.name: {"b3d_trial": c.b3d_name, "frames": c.n_frames, "rate_hz": c.rate_hz} for c in trials},
    }
    (out / SOURCE_JSON).write_text(json.dumps(source, indent=2) + "\n")
    return ConvertedSubject(out, Path(b3d.path), tuple(trials))


ReviewWriter = Callable[[ConvertedSubject], Any]
