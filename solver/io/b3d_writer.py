"""Write AddBiomechanics binary subject files (.b3d) without nimblephysics.

The layout is the one :mod:`solver.io.b3d` reads (format reference: keenon/nimblephysics
``dart/biomechanics/SubjectOnDisk.cpp``, ``SubjectOnDisk::writeB3D``): an int64
little-endian header length, the header message, then for every trial and frame one
sensor frame followed by one pass frame per processing pass. Every sensor frame must
serialize to the same number of bytes, and so must every pass frame; this holds when
every frame carries the same array lengths (unobserved markers are NaN, not left out),
which :func:`write_b3d` checks.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from solver.io import b3d_schema as schema
from solver.io.b3d import (
    PASS_TYPES,
    B3dFrames,
    B3dHeader,
    B3dTrial,
    missing_grf_number,
    unknown_fields,
)

#: The file format version written.
WRITE_VERSION = 4


def _merge_extra(msg: Any, extra: bytes, where: str) -> None:
    """Add ``extra`` (the wire bytes of fields the schema does not name, as read) to ``msg``.

    Raises
    ------
    ValueError
        ``extra`` is not well-formed, or holds a field the schema names (it would change that
        field instead of being kept beside it).
    """
    if not extra:
        return
    try:
        numbers = {number for number, *_ in unknown_fields(extra)}
    except ValueError as exc:
        raise ValueError(f"{where}: extra_fields are {exc}") from None
    named = sorted(numbers & {f.number for f in msg.DESCRIPTOR.fields})
    if named:
        raise ValueError(f"{where}: extra_fields hold field(s) {named}, which the schema names; give them as attributes")
    msg.MergeFromString(bytes(extra))


def _header_message(header: B3dHeader, sensor_bytes: int, pass_bytes: int) -> Any:
    msg = schema.Header(
        num_dofs=header.n_dofs,
        num_joints=header.n_joints,
        num_trials=len(header.trials),
        raw_sensor_frame_size=sensor_bytes,
        processing_pass_frame_size=pass_bytes,
        version=WRITE_VERSION,
        href=header.href,
        notes=header.notes,
        biological_sex=header.sex,
        height_m=header.height_m,
        mass_kg=header.mass_kg,
        age_years=header.age_years,
        emg_dim=header.emg_dim,
    )
    msg.ground_contact_body.extend(header.ground_contact_bodies)
    msg.custom_value_name.extend(header.custom_value_names)
    msg.custom_value_length.extend(header.custom_value_lengths)
    msg.marker_name.extend(header.marker_names)
    msg.acc_name.extend(header.acc_names)
    msg.gyro_name.extend(header.gyro_names)
    msg.emg_name.extend(header.emg_names)
    msg.exo_dof_index.extend(header.exo_dof_indices)
    msg.subject_tag.extend(header.tags)
    for k, p in enumerate(header.passes):
        _merge_extra(msg.passes.add(pass_type=PASS_TYPES.index(p.type), model_osim_text=p.model_osim_text), p.extra_fields, f"pass {k}")
    for t in header.trials:
        _trial_message(msg.trial_header.add(), t)
    _merge_extra(msg, header.extra_fields, "header")  # fields the schema does not name, as read: kept unchanged
    return msg


def _trial_message(out: Any, t: B3dTrial) -> None:
    out.name = t.name
    out.original_name = t.original_name
    out.split_index = t.split_index
    out.trial_length = t.n_frames
    out.trial_timestep = t.timestep_s
    out.num_force_plates = t.n_force_plates
    out.marker_names_guessed = t.marker_names_guessed
    out.trial_tag.extend(t.tags)
    out.missing_grf_reason.extend(missing_grf_number(r) for r in t.missing_grf)
    out.force_plate_corners.extend(np.asarray(t.force_plate_corners, dtype=np.float64).ravel().tolist())
    for k, p in enumerate(t.passes):
        ph = out.processing_pass_header.add(
            type=PASS_TYPES.index(p.type),
            lowpass_cutoff_frequency=p.lowpass_cutoff_hz,
            lowpass_filter_order=p.lowpass_filter_order,
        )
        ph.dof_positions_observed.extend(bool(v) for v in p.dof_positions_observed)
        ph.dof_velocities_finite_differenced.extend(bool(v) for v in p.dof_velocities_finite_differenced)
        ph.dof_acceleration_finite_differenced.extend(bool(v) for v in p.dof_accelerations_finite_differenced)
        ph.marker_rms.extend(np.asarray(p.marker_rms, dtype=np.float64).tolist())
        ph.marker_max.extend(np.asarray(p.marker_max, dtype=np.float64).tolist())
        ph.linear_residual.extend(np.asarray(p.linear_residual, dtype=np.float64).tolist())
        ph.angular_residual.extend(np.asarray(p.angular_residual, dtype=np.float64).tolist())
        ph.joints_max_velocity.extend(np.asarray(p.joints_max_velocity, dtype=np.float64).tolist())
        ph.force_plate_cutoff.extend(np.asarray(p.force_plate_cutoffs, dtype=np.float64).tolist())
        _merge_extra(ph, p.extra_fields, f"trial {t.name!r}, pass {k}")
    _merge_extra(out, t.extra_fields, f"trial {t.name!r}")


def _flat(a: np.ndarray, i: int) -> list[float]:
    return a[i].ravel().tolist()


def _padded_plates(a: np.ndarray, i: int, plates: int) -> list[float]:
    row = a[i].ravel().tolist()
    return row + [0.0] * (3 * plates - len(row))


def _frames(fr: B3dFrames, max_plates: int) -> Any:
    """Yield (sensor bytes, [pass bytes]) per frame."""
    n = fr.n_frames
    for i in range(n):
        s = schema.SensorFrame()
        s.marker_obs.extend(_flat(fr.markers, i))
        s.raw_force_plate_cop.extend(_padded_plates(fr.plate_cop, i, max_plates))
        s.raw_force_plate_torque.extend(_padded_plates(fr.plate_moment, i, max_plates))
        s.raw_force_plate_force.extend(_padded_plates(fr.plate_force, i, max_plates))
        s.acc_obs.extend(_flat(fr.acc_obs, i) if fr.acc_obs.size else [])
        s.gyro_obs.extend(_flat(fr.gyro_obs, i) if fr.gyro_obs.size else [])
        s.emg_obs.extend(_flat(fr.emg, i) if fr.emg.size else [])
        s.exo_obs.extend(_flat(fr.exo, i) if fr.exo.size else [])
        s.custom_values.extend(_flat(fr.custom, i) if fr.custom.size else [])
        passes = []
        for p in fr.passes:
            f = schema.PassFrame()
            f.pos.extend(_flat(p.pos, i))
            f.vel.extend(_flat(p.vel, i))
            f.acc.extend(_flat(p.acc, i))
            f.tau.extend(_flat(p.tau, i))
            f.ground_contact_wrench.extend(_flat(p.ground_contact_wrench, i))
            f.ground_contact_center_of_pressure.extend(_flat(p.ground_contact_cop, i))
            f.ground_contact_torque.extend(_flat(p.ground_contact_torque, i))
            f.ground_contact_force.extend(_flat(p.ground_contact_force, i))
            f.com_pos.extend(_flat(p.com_pos, i))
            f.com_vel.extend(_flat(p.com_vel, i))
            f.com_acc.extend(_flat(p.com_acc, i))
            for name, arr in p.extra.items():
                if arr.shape[0] == n and arr.shape[1]:
                    getattr(f, name).extend(_flat(arr, i))
            passes.append(f.SerializeToString())
        yield s.SerializeToString(), passes


def write_b3d(path: str | Path, header: B3dHeader, frames: Sequence[B3dFrames]) -> None:
    """Write a .b3d file: ``header`` and, per trial, all of its frames.

    Parameters
    ----------
    path
        Output file; written to a temporary name beside it and renamed, so a failed
        write leaves no partial file.
    header
        The subject, passes (with model text) and trials (with per-frame pass summaries
        and missing-GRF reasons). ``version``, ``raw_sensor_frame_size`` and
        ``processing_pass_frame_size`` are set by the writer. The ``extra_fields`` of the
        header, its passes, trials and trial passes (fields the schema does not name, as
        :func:`solver.io.b3d.open_b3d` read them) are written unchanged, after the named ones.
    frames
        One :class:`B3dFrames` per trial of ``header.trials`` (same order), holding every
        frame of that trial (``start`` 0, F = ``n_frames``) and one pass per trial pass.

    Raises
    ------
    ValueError
        ``frames`` does not match the header (trial count, frame count, pass count, array
        shapes), the frames would not all serialize to one size, or ``extra_fields`` are
        not protobuf wire bytes or hold a field the schema names.
    """
    p = Path(path)
    if len(frames) != len(header.trials):
        raise ValueError(f"{len(frames)} frame blocks for {len(header.trials)} trials")
    d, nm, nb = header.n_dofs, len(header.marker_names), len(header.ground_contact_bodies)
    for t, fr in zip(header.trials, frames, strict=True):
        if fr.n_frames != t.n_frames or fr.start != 0:
            raise ValueError(f"trial {t.name!r}: {fr.n_frames} frames from {fr.start}, expected {t.n_frames} from 0")
        if len(fr.passes) != len(t.passes) or len(t.passes) > len(header.passes):
            raise ValueError(f"trial {t.name!r}: {len(fr.passes)} pass frames, {len(t.passes)} trial passes, {len(header.passes)} subject passes")
        if len(t.missing_grf) != t.n_frames:
            raise ValueError(f"trial {t.name!r}: {len(t.missing_grf)} missing-GRF reasons for {t.n_frames} frames")
        if fr.markers.shape[1:] != (nm, 3):
            raise ValueError(f"trial {t.name!r}: markers of shape {fr.markers.shape}, expected (F, {nm}, 3)")
        if fr.plate_force.shape[1:] != (t.n_force_plates, 3):
            raise ValueError(f"trial {t.name!r}: plate forces of shape {fr.plate_force.shape}, expected (F, {t.n_force_plates}, 3)")
        for name in ("acc_obs", "gyro_obs", "emg", "exo", "custom"):
            arr = getattr(fr, name)
            if arr.size and arr.shape[0] != t.n_frames:
                raise ValueError(f"trial {t.name!r}: {name} has {arr.shape[0]} frames, expected {t.n_frames}")
        for pf in fr.passes:
            if pf.pos.shape[1:] != (d,) or pf.tau.shape[1:] != (d,):
                raise ValueError(f"trial {t.name!r}: pass coordinates of shape {pf.pos.shape}, expected (F, {d})")
            if pf.ground_contact_wrench.shape[1:] != (nb, 6):
                raise ValueError(f"trial {t.name!r}: contact wrenches of shape {pf.ground_contact_wrench.shape}, expected (F, {nb}, 6)")
    max_plates = max((t.n_force_plates for t in header.trials), default=0)
    sizes: dict[str, int] = {}

    def check(kind: str, blob: bytes, where: str) -> None:
        if sizes.setdefault(kind, len(blob)) != len(blob):
            raise ValueError(f"{where}: {kind} serializes to {len(blob)} bytes, other frames to {sizes[kind]}: every frame must hold the same array lengths")

    # sizes first (from the first frame that has them), then stream
    for fr in frames:
        for sensor, passes in _frames(fr, max_plates):
            sizes["sensor frame"] = len(sensor)
            if passes:
                sizes["pass frame"] = len(passes[0])
            break
        if "pass frame" in sizes:
            break
    msg = _header_message(header, sizes.get("sensor frame", 0), sizes.get("pass frame", 0))
    raw = msg.SerializeToString()
    tmp = p.with_name(p.name + ".partial")
    try:
        with open(tmp, "wb") as fh:
            fh.write(struct.pack("<q", len(raw)))
            fh.write(raw)
            for t, fr in zip(header.trials, frames, strict=True):
                for i, (sensor, passes) in enumerate(_frames(fr, max_plates)):
                    check("sensor frame", sensor, f"trial {t.name!r} frame {i}")
                    fh.write(sensor)
                    for blob in passes:
                        check("pass frame", blob, f"trial {t.name!r} frame {i}")
                        fh.write(blob)
        os.replace(tmp, p)
    finally:
        if tmp.exists():
            tmp.unlink()
