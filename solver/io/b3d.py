"""Read AddBiomechanics binary subject files (.b3d) without nimblephysics.

Byte layout (format reference: keenon/nimblephysics ``dart/biomechanics/SubjectOnDisk.cpp``,
``SubjectOnDisk::SubjectOnDisk``, ``writeB3D`` and ``readFrames``; schema
``dart/proto/SubjectOnDisk.proto``, restated in :mod:`solver.io.b3d_schema`)::

    byte 0      int64, little-endian: H, the length of the header message
    byte 8      the header message (H bytes): subject, trials, passes, embedded model
    byte 8 + H  the frames, trial after trial; for every frame of a trial one sensor
                frame (``raw_sensor_frame_size`` bytes) followed by one pass frame
                (``processing_pass_frame_size`` bytes) per processing pass of that trial

Every frame has the same size, so frame ``t`` of trial ``k`` is found by arithmetic and
read with one seek: :meth:`B3dFile.read_frames` never parses the rest of the file.

Units are SI as stored: positions in m, angles in rad, forces in N, moments in N·m,
masses in kg, time step in s. The world frame is the model's ground (y up).
:func:`open_b3d` reads and checks the header; frames are read on request.
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from google.protobuf.message import DecodeError

from solver.errors import B3dFormatError
from solver.io import b3d_schema as schema
from solver.io.types import FloatArray

#: File format versions this reader understands (the ``version`` field of the header).
SUPPORTED_VERSIONS = frozenset({4})
#: Missing-GRF reason names, in the order of their number on disk.
MISSING_GRF_REASONS = schema.MISSING_GRF_REASONS
#: Processing pass types, in the order of their number on disk.
PASS_TYPES = schema.PASS_TYPES
#: Size of the header-length prefix, bytes.
PREFIX_BYTES = 8


def _frozen_array(values: Any, dtype: Any = np.float64, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.array(values, dtype=dtype)
    if shape is not None:
        arr = arr.reshape(shape)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class B3dTrialPass:
    """Per-frame summaries of one processing pass of one trial (stored in the header).

    Attributes
    ----------
    type
        ``"kinematics"``, ``"dynamics"`` or ``"lowPassFilter"``.
    marker_rms, marker_max
        (N,) marker error per frame, m (stored as float32).
    linear_residual, angular_residual
        (N,) norm of the residual force (N) and moment (N·m) per frame (float32).
    joints_max_velocity
        (N,) largest joint speed per frame, rad/s (float32).
    dof_positions_observed, dof_velocities_finite_differenced, dof_accelerations_finite_differenced
        (D,) bool per coordinate.
    lowpass_cutoff_hz, lowpass_filter_order
        The Butterworth filter of a low-pass pass (0 when none).
    force_plate_cutoffs
        (P,) noise cutoff per plate, N (float32), possibly empty.
    extra_fields
        Fields of the stored pass header this reader's schema does not name, as their
        protobuf wire bytes (:func:`extra_field_values`); written back unchanged.

    Arrays of a pass that does not store them are empty (shape (0,)).
    """

    type: str
    marker_rms: FloatArray
    marker_max: FloatArray
    linear_residual: FloatArray
    angular_residual: FloatArray
    joints_max_velocity: FloatArray
    dof_positions_observed: np.ndarray
    dof_velocities_finite_differenced: np.ndarray
    dof_accelerations_finite_differenced: np.ndarray
    lowpass_cutoff_hz: float = 0.0
    lowpass_filter_order: int = 0
    force_plate_cutoffs: FloatArray = field(default_factory=lambda: _frozen_array([]))
    extra_fields: bytes = b""


@dataclass(frozen=True)
class B3dTrial:
    """Header information of one trial.

    Attributes
    ----------
    name
        Trial name (``walking2_segment_0``).
    original_name, split_index
        The source trial before AddBiomechanics split it, and which piece this is (0-based).
    timestep_s
        Time between frames, s.
    n_frames
        Number of frames.
    tags
        Trial tags of the AddBiomechanics platform.
    missing_grf
        (N,) per-frame reason the ground reaction force is not trusted, by name
        (:data:`MISSING_GRF_REASONS`, or ``unknownReason<number>`` for a number this reader
        does not know; ``"notMissingGRF"`` = measured force is usable).
    n_force_plates
        Number of force plates in the sensor frames of this trial.
    force_plate_corners
        (P, 4, 3) plate corners in the world frame, m; shape (0, 4, 3) when not stored.
    marker_names_guessed
        Whether the marker names were guessed by the platform.
    passes
        One :class:`B3dTrialPass` per processing pass of this trial.
    extra_fields
        Fields of the stored trial header this reader's schema does not name (in the current
        nimblephysics format among them ``trial_type``, ``has_manual_GRF_annotation``, the
        original trial's start and end, detected features, per-trial force plates), as
        their protobuf wire bytes in stored order (:func:`extra_field_values`); written
        back unchanged.
    """

    name: str
    original_name: str
    split_index: int
    timestep_s: float
    n_frames: int
    tags: tuple[str, ...]
    missing_grf: tuple[str, ...]
    n_force_plates: int
    force_plate_corners: FloatArray
    marker_names_guessed: bool
    passes: tuple[B3dTrialPass, ...]
    extra_fields: bytes = b""

    @property
    def rate_hz(self) -> float:
        """Frames per second (1 / ``timestep_s``)."""
        return 1.0 / self.timestep_s if self.timestep_s > 0 else float("nan")


@dataclass(frozen=True)
class B3dPass:
    """A processing pass of the subject: its type and the OpenSim model it used (.osim text);
    ``extra_fields``: the stored fields this reader's schema does not name, as their
    protobuf wire bytes (:func:`extra_field_values`), written back unchanged."""

    type: str
    model_osim_text: str
    extra_fields: bytes = b""


@dataclass(frozen=True)
class B3dHeader:
    """Everything in a .b3d file except the frames.

    Attributes
    ----------
    version
        File format version.
    n_dofs
        Number of model coordinates D (the length of every pass's ``pos``).
    n_joints
        ``num_joints`` as stored (0 when not set).
    mass_kg, height_m, sex, age_years
        The subject (sex as stored: ``male``, ``female``, ``unknown``; age 0 or -1 when unknown).
    tags, notes, href
        Subject tags, free text, link to where the subject came from.
    ground_contact_bodies
        (B,) names of the bodies that take ground contact wrenches, in their order in the frames.
    marker_names
        (M,) marker names in the order of the sensor frames (may include ``""``).
    acc_names, gyro_names, emg_names, emg_dim, exo_dof_indices
        IMU, EMG and exoskeleton channels of the sensor frames.
    custom_value_names, custom_value_lengths
        Extra per-frame sensor values and their lengths.
    passes
        One :class:`B3dPass` per processing pass (type and model text).
    trials
        One :class:`B3dTrial` per trial.
    extra_fields
        Fields of the stored header this reader's schema does not name (in the current
        nimblephysics format ``data_quality`` among them), as their protobuf wire bytes in
        stored order (:func:`extra_field_values`); written back unchanged, so that reading
        and rewriting a file keeps them.
    """

    version: int
    n_dofs: int
    mass_kg: float
    height_m: float
    sex: str
    age_years: int
    tags: tuple[str, ...]
    notes: str
    href: str
    ground_contact_bodies: tuple[str, ...]
    marker_names: tuple[str, ...]
    passes: tuple[B3dPass, ...]
    trials: tuple[B3dTrial, ...]
    n_joints: int = 0
    acc_names: tuple[str, ...] = ()
    gyro_names: tuple[str, ...] = ()
    emg_names: tuple[str, ...] = ()
    emg_dim: int = 0
    exo_dof_indices: tuple[int, ...] = ()
    custom_value_names: tuple[str, ...] = ()
    custom_value_lengths: tuple[int, ...] = ()
    extra_fields: bytes = b""

    def trial_index(self, trial: int | str) -> int:
        """Index of a trial given by index or name.

        Raises
        ------
        KeyError
            An index out of range, or an unknown name (the message lists the trials).
        """
        if isinstance(trial, (int, np.integer)) and not isinstance(trial, bool):
            if 0 <= int(trial) < len(self.trials):
                return int(trial)
            raise KeyError(f"trial index {trial} out of range: the file has {len(self.trials)} trials")
        for i, t in enumerate(self.trials):
            if t.name == trial:
                return i
        raise KeyError(f"no trial {trial!r}; trials: {[t.name for t in self.trials]}")


@dataclass(frozen=True)
class B3dPassFrames:
    """One processing pass over a range of F frames.

    Attributes
    ----------
    type
        Pass type (:data:`PASS_TYPES`).
    pos, vel, acc
        (F, D) coordinates (rad or m), their velocities and accelerations.
    tau
        (F, D) joint torques (N·m or N).
    ground_contact_wrench
        (F, B, 6) wrench on each ground contact body, [moment (3), force (3)] at the world
        origin in the world frame, N·m and N.
    ground_contact_cop, ground_contact_torque, ground_contact_force
        (F, B, 3) the same contact as centre of pressure (m), free moment (N·m), force (N).
    com_pos, com_vel, com_acc
        (F, 3) centre of mass position (m), velocity (m/s), acceleration (m/s²), world frame.
    extra
        The other stored per-frame vectors (root-frame residual wrench, root-frame contact
        wrenches, joint centres, root histories), each (F, K) with K as stored (0 when absent).
    """

    type: str
    pos: FloatArray
    vel: FloatArray
    acc: FloatArray
    tau: FloatArray
    ground_contact_wrench: FloatArray
    ground_contact_cop: FloatArray
    ground_contact_torque: FloatArray
    ground_contact_force: FloatArray
    com_pos: FloatArray
    com_vel: FloatArray
    com_acc: FloatArray
    extra: Mapping[str, FloatArray] = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True)
class B3dFrames:
    """A range of frames ``start .. start + F`` of one trial: sensor data and every pass.

    Attributes
    ----------
    trial
        Trial index.
    start
        Index of the first frame.
    time_s
        (F,) frame times, s (frame index × time step; the file stores no time stamps).
    missing_grf
        (F,) missing-GRF reason names of these frames (from the header).
    markers
        (F, M, 3) marker positions, m, world frame; NaN where a marker is not observed.
    plate_force, plate_cop, plate_moment
        (F, P, 3) raw force plate force (N), centre of pressure (m) and moment (N·m), world frame.
    acc_obs, gyro_obs
        (F, A, 3) / (F, G, 3) IMU accelerometer (m/s²) and gyroscope (rad/s) readings.
    emg
        (F, E * emg_dim) EMG samples.
    exo
        (F, X) exoskeleton torques.
    custom
        (F, C) custom values, concatenated in header order.
    passes
        One :class:`B3dPassFrames` per processing pass of the trial.
    """

    trial: int
    start: int
    time_s: FloatArray
    missing_grf: tuple[str, ...]
    markers: FloatArray
    plate_force: FloatArray
    plate_cop: FloatArray
    plate_moment: FloatArray
    passes: tuple[B3dPassFrames, ...]
    acc_obs: FloatArray = field(default_factory=lambda: _frozen_array(np.zeros((0, 0, 3))))
    gyro_obs: FloatArray = field(default_factory=lambda: _frozen_array(np.zeros((0, 0, 3))))
    emg: FloatArray = field(default_factory=lambda: _frozen_array(np.zeros((0, 0))))
    exo: FloatArray = field(default_factory=lambda: _frozen_array(np.zeros((0, 0))))
    custom: FloatArray = field(default_factory=lambda: _frozen_array(np.zeros((0, 0))))

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.markers.shape[0])


# --------------------------------------------------------------------------- header


#: The name a missing-GRF reason number this reader does not know is read as (proto3 enums
#: are open: a newer writer may store reasons added since), ``unknownReason<number>``; such a
#: frame counts as not measured, and :func:`missing_grf_number` writes the number back.
UNKNOWN_REASON = "unknownReason"


def missing_grf_number(name: str) -> int:
    """The stored number of a missing-GRF reason name (:data:`MISSING_GRF_REASONS`, or
    ``unknownReason<number>`` for a number read from a newer file).

    Raises
    ------
    ValueError
        Neither a known name nor ``unknownReason`` followed by a non-negative number.
    """
    if name in MISSING_GRF_REASONS:
        return MISSING_GRF_REASONS.index(name)
    digits = name[len(UNKNOWN_REASON):] if name.startswith(UNKNOWN_REASON) else ""
    if digits.isdigit():
        return int(digits)
    raise ValueError(f"missing-GRF reason {name!r}; expected one of {', '.join(MISSING_GRF_REASONS)} or {UNKNOWN_REASON}<number>")


def _reason_name(number: int, path: Path) -> str:
    """A stored missing-GRF reason number as its name (an unknown non-negative one as
    ``unknownReason<number>``: the file stays readable)."""
    if number >= len(MISSING_GRF_REASONS):
        return f"{UNKNOWN_REASON}{number}"
    return _enum_name(MISSING_GRF_REASONS, number, "missing-GRF reason", path, PREFIX_BYTES)


def _enum_name(values: tuple[str, ...], number: int, what: str, path: Path, offset: int) -> str:
    if 0 <= number < len(values):
        return values[number]
    raise B3dFormatError(
        f"unknown {what} number {number} (expected 0..{len(values) - 1})", path=path, offset=offset
    )


def unknown_fields(extra: bytes) -> list[tuple[int, int, int | bytes]]:
    """``(field number, wire type, value)`` of each field of the protobuf wire bytes
    ``extra``, in stored order, read by protobuf itself (``UnknownFieldSet`` of an empty
    message): a varint as an int, a fixed 64- or 32-bit value (a double, a float) as its 8
    or 4 little-endian bytes, a length-delimited value (a string, message or packed array)
    as its bytes.

    Raises
    ------
    ValueError
        ``extra`` is not well-formed protobuf wire bytes.
    """
    from google.protobuf import empty_pb2
    from google.protobuf.message import DecodeError
    from google.protobuf.unknown_fields import UnknownFieldSet

    try:
        message = empty_pb2.Empty.FromString(bytes(extra))
    except DecodeError as exc:
        raise ValueError(f"not protobuf wire bytes ({exc})") from None
    width = {1: 8, 5: 4}  # the fixed wire types' sizes: protobuf gives their bits as an int
    return [
        (f.field_number, f.wire_type, f.data.to_bytes(width[f.wire_type], "little") if f.wire_type in width else f.data)
        for f in UnknownFieldSet(message)
    ]


def extra_field_values(extra: bytes) -> dict[int, tuple[int | bytes, ...]]:
    """The values of the ``extra_fields`` of a header, trial, trial pass or pass, by field
    number of the nimblephysics ``SubjectOnDisk.proto`` (such as ``data_quality`` or
    ``trial_type``, enums: ints), in stored order (:func:`unknown_fields`).

    Raises
    ------
    ValueError
        ``extra`` is not well-formed protobuf wire bytes.
    """
    values: dict[int, list[int | bytes]] = {}
    for number, _, value in unknown_fields(extra):
        values.setdefault(number, []).append(value)
    return {k: tuple(v) for k, v in values.items()}


def _extra_fields(msg: Any) -> bytes:
    """The wire bytes of the fields of ``msg`` that the schema does not name (protobuf keeps
    them as unknown fields when it parses), in stored order: ``msg`` serialized with every
    named field cleared (those of its nested messages with them)."""
    own = type(msg)()
    own.CopyFrom(msg)
    for described, _ in own.ListFields():
        own.ClearField(described.name)
    return own.SerializeToString()


def _per_frame(values: Any, n: int, what: str, path: Path, where: str) -> np.ndarray:
    arr = np.array(values, dtype=np.float64)
    if arr.size not in (0, n):
        raise B3dFormatError(f"{what} has {arr.size} values, expected {n} (one per frame) or none", path=path, offset=PREFIX_BYTES, where=where)
    arr.setflags(write=False)
    return arr


def _trial_pass(msg: Any, n: int, n_dofs: int, path: Path, where: str) -> B3dTrialPass:
    def flags(values: Any, what: str) -> np.ndarray:
        arr = np.array(values, dtype=bool)
        if arr.size not in (0, n_dofs):
            raise B3dFormatError(f"{what} has {arr.size} values, expected {n_dofs} (one per coordinate) or none", path=path, offset=PREFIX_BYTES, where=where)
        arr.setflags(write=False)
        return arr

    return B3dTrialPass(
        type=_enum_name(PASS_TYPES, msg.type, "processing pass type", path, PREFIX_BYTES),
        marker_rms=_per_frame(msg.marker_rms, n, "marker_rms", path, where),
        marker_max=_per_frame(msg.marker_max, n, "marker_max", path, where),
        linear_residual=_per_frame(msg.linear_residual, n, "linear_residual", path, where),
        angular_residual=_per_frame(msg.angular_residual, n, "angular_residual", path, where),
        joints_max_velocity=_per_frame(msg.joints_max_velocity, n, "joints_max_velocity", path, where),
        dof_positions_observed=flags(msg.dof_positions_observed, "dof_positions_observed"),
        dof_velocities_finite_differenced=flags(msg.dof_velocities_finite_differenced, "dof_velocities_finite_differenced"),
        dof_accelerations_finite_differenced=flags(msg.dof_acceleration_finite_differenced, "dof_acceleration_finite_differenced"),
        lowpass_cutoff_hz=float(msg.lowpass_cutoff_frequency),
        lowpass_filter_order=int(msg.lowpass_filter_order),
        force_plate_cutoffs=_frozen_array(list(msg.force_plate_cutoff)),
        extra_fields=_extra_fields(msg),
    )


def _trial(msg: Any, index: int, n_passes: int, n_dofs: int, path: Path) -> B3dTrial:
    where = f"trial {index} ({msg.name!r})"
    n = int(msg.trial_length)
    if n < 0:
        raise B3dFormatError(f"trial_length is {n}, expected >= 0", path=path, offset=PREFIX_BYTES, where=where)
    dt = float(msg.trial_timestep)
    if n > 0 and not (math.isfinite(dt) and dt > 0):
        raise B3dFormatError(f"trial_timestep is {dt}, expected a positive number of seconds", path=path, offset=PREFIX_BYTES, where=where)
    reasons = list(msg.missing_grf_reason)
    if len(reasons) not in (0, n):
        raise B3dFormatError(f"missing_GRF_reason has {len(reasons)} values, expected {n} (one per frame)", path=path, offset=PREFIX_BYTES, where=where)
    if not reasons:
        reasons = [0] * n
    names = tuple(_reason_name(r, path) for r in reasons)
    plates = int(msg.num_force_plates)
    if not 0 <= plates <= 10_000:
        raise B3dFormatError(f"num_force_plates is {plates}, expected 0..10000", path=path, offset=PREFIX_BYTES, where=where)
    corners = np.array(msg.force_plate_corners, dtype=np.float64)
    if corners.size % 12:
        raise B3dFormatError(f"force_plate_corners has {corners.size} values, expected 12 per plate", path=path, offset=PREFIX_BYTES, where=where)
    if len(msg.processing_pass_header) > n_passes:
        raise B3dFormatError(
            f"{len(msg.processing_pass_header)} processing passes, but the subject declares {n_passes}",
            path=path, offset=PREFIX_BYTES, where=where,
        )
    return B3dTrial(
        name=msg.name,
        original_name=msg.original_name,
        split_index=int(msg.split_index),
        timestep_s=dt,
        n_frames=n,
        tags=tuple(msg.trial_tag),
        missing_grf=names,
        n_force_plates=plates,
        force_plate_corners=_frozen_array(corners, shape=(-1, 4, 3)),
        marker_names_guessed=bool(msg.marker_names_guessed),
        passes=tuple(
            _trial_pass(p, n, n_dofs, path, f"{where}, pass {k}") for k, p in enumerate(msg.processing_pass_header)
        ),
        extra_fields=_extra_fields(msg),
    )


def _header(msg: Any, path: Path) -> B3dHeader:
    if msg.version not in SUPPORTED_VERSIONS:
        raise B3dFormatError(
            f"file format version {msg.version} is not supported (this reader knows version "
            f"{', '.join(str(v) for v in sorted(SUPPORTED_VERSIONS))})",
            path=path, offset=PREFIX_BYTES,
        )
    n_dofs = int(msg.num_dofs)
    if not 0 <= n_dofs <= 100_000:
        raise B3dFormatError(f"num_dofs is {n_dofs}, expected 0..100000", path=path, offset=PREFIX_BYTES)
    if msg.emg_dim < 0 or any(v < 0 for v in msg.custom_value_length):
        raise B3dFormatError("negative emg_dim or custom_value_length", path=path, offset=PREFIX_BYTES)
    if len(msg.custom_value_length) != len(msg.custom_value_name):
        raise B3dFormatError(
            f"{len(msg.custom_value_name)} custom value names but {len(msg.custom_value_length)} lengths",
            path=path, offset=PREFIX_BYTES,
        )
    passes = tuple(
        B3dPass(
            _enum_name(PASS_TYPES, p.pass_type, "processing pass type", path, PREFIX_BYTES),
            p.model_osim_text,
            _extra_fields(p),
        )
        for p in msg.passes
    )
    trials = tuple(_trial(t, i, len(passes), n_dofs, path) for i, t in enumerate(msg.trial_header))
    return B3dHeader(
        version=int(msg.version),
        n_dofs=n_dofs,
        n_joints=int(msg.num_joints),
        mass_kg=float(msg.mass_kg),
        height_m=float(msg.height_m),
        sex=msg.biological_sex,
        age_years=int(msg.age_years),
        tags=tuple(msg.subject_tag),
        notes=msg.notes,
        href=msg.href,
        ground_contact_bodies=tuple(msg.ground_contact_body),
        marker_names=tuple(msg.marker_name),
        passes=passes,
        trials=trials,
        acc_names=tuple(msg.acc_name),
        gyro_names=tuple(msg.gyro_name),
        emg_names=tuple(msg.emg_name),
        emg_dim=int(msg.emg_dim),
        exo_dof_indices=tuple(int(v) for v in msg.exo_dof_index),
        custom_value_names=tuple(msg.custom_value_name),
        custom_value_lengths=tuple(int(v) for v in msg.custom_value_length),
        extra_fields=_extra_fields(msg),
    )


# --------------------------------------------------------------------------- file


class B3dFile:
    """An open .b3d file: the checked header, and frames read on request by seeking.

    Create it with :func:`open_b3d`. The file is opened for each read (no handle is kept),
    so the object can be shared between threads and pickled.

    Attributes
    ----------
    path
        The file.
    header
        :class:`B3dHeader`.
    data_start
        Byte offset of the first frame.
    sensor_frame_bytes, pass_frame_bytes
        Size of one sensor frame and of one pass frame, bytes.
    file_bytes
        Size of the file, bytes.
    """

    def __init__(self, path: Path, header: B3dHeader, data_start: int, sensor_frame_bytes: int, pass_frame_bytes: int, file_bytes: int) -> None:
        self.path = path
        self.header = header
        self.data_start = data_start
        self.sensor_frame_bytes = sensor_frame_bytes
        self.pass_frame_bytes = pass_frame_bytes
        self.file_bytes = file_bytes
        starts = []
        offset = data_start
        for t in header.trials:
            starts.append(offset)
            offset += t.n_frames * self.frame_bytes(t)
        self._trial_starts = tuple(starts)
        self.data_end = offset

    def __repr__(self) -> str:
        return f"B3dFile({str(self.path)!r}, trials={len(self.header.trials)}, dofs={self.header.n_dofs})"

    def frame_bytes(self, trial: B3dTrial) -> int:
        """Bytes of one frame of ``trial`` (sensor frame + one pass frame per pass)."""
        return self.sensor_frame_bytes + len(trial.passes) * self.pass_frame_bytes

    def frame_offset(self, trial: int | str, frame: int) -> int:
        """Byte offset of frame ``frame`` (its sensor frame) of ``trial``."""
        k = self.header.trial_index(trial)
        return self._trial_starts[k] + frame * self.frame_bytes(self.header.trials[k])

    def model_text(self, pass_index: int = 0) -> str:
        """The OpenSim model (.osim XML text) of a processing pass (the scaled model of that pass)."""
        return self.header.passes[pass_index].model_osim_text

    def read_frame(self, trial: int | str, frame: int) -> B3dFrames:
        """One frame (F = 1); see :meth:`read_frames`."""
        return self.read_frames(trial, frame, frame + 1)

    def read_trial(self, trial: int | str) -> B3dFrames:
        """Every frame of a trial; see :meth:`read_frames`."""
        k = self.header.trial_index(trial)
        return self.read_frames(k, 0, self.header.trials[k].n_frames)

    def read_frames(self, trial: int | str, start: int, stop: int | None = None) -> B3dFrames:
        """Frames ``start`` (inclusive) to ``stop`` (exclusive) of a trial, read with one seek.

        Parameters
        ----------
        trial
            Trial index or name.
        start, stop
            Frame range; ``stop`` None means to the end of the trial. Must satisfy
            ``0 <= start <= stop <= n_frames``.

        Returns
        -------
        B3dFrames

        Raises
        ------
        KeyError
            Unknown trial.
        IndexError
            The range is outside the trial.
        B3dFormatError
            The file is truncated there, or a frame does not parse or has fields of the
            wrong length (the message gives the byte offset of the frame).
        """
        k = self.header.trial_index(trial)
        info = self.header.trials[k]
        if stop is None:
            stop = info.n_frames
        if not 0 <= start <= stop <= info.n_frames:
            raise IndexError(f"frames {start}..{stop} outside trial {info.name!r} of {info.n_frames} frames")
        size = self.frame_bytes(info)
        first = self._trial_starts[k] + start * size
        n = stop - start
        try:
            with open(self.path, "rb") as fh:
                fh.seek(first)
                blob = fh.read(n * size)
        except OSError as exc:
            raise B3dFormatError(f"cannot read: {exc.strerror or exc}", path=self.path, offset=first) from None
        if len(blob) != n * size:
            raise B3dFormatError(
                f"file ends at byte {first + len(blob)}, expected {n} frames of {size} bytes from here",
                path=self.path, offset=first, where=f"trial {info.name!r}, frame {start + len(blob) // size}",
            )
        with np.errstate(all="ignore"):  # damaged values (signalling NaNs) are data, not errors
            return _decode_frames(self, k, start, n, blob, first)


def _not_b3d_hint(path: Path, prefix: bytes) -> str:
    """A hint for a file whose first bytes cannot start a .b3d: what it looks like instead
    (its suffix, text, or a binary file without the suffix), or nothing when it may be a
    damaged .b3d."""
    suffix = path.suffix.lower()
    if suffix and suffix != ".b3d":
        kind = f"a {path.suffix} file"
    elif bool(prefix) and all(32 <= c < 127 or c in (9, 10, 13) for c in prefix):
        kind = "text"
    elif not suffix:
        kind = "a binary file without the .b3d suffix"
    else:
        return ""
    return f"; this looks like {kind}, not an AddBiomechanics .b3d (binary: an 8-byte header length, then protobuf messages)"


def open_b3d(path: str | Path) -> B3dFile:
    """Open a .b3d file: read and check its header (frames are read later, on request).

    Checks that the header-length prefix fits the file, the header parses, the version
    is supported, per-frame header arrays have one value per frame, frame sizes are
    positive, and the file holds exactly the frames the header declares.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    B3dFormatError
        The file is damaged, truncated, too long, or of an unknown version; the message
        names the file, the byte offset and what was expected.
    """
    p = Path(path)
    try:
        size = os.path.getsize(p)
        with open(p, "rb") as fh:
            prefix = fh.read(PREFIX_BYTES)
            if len(prefix) < PREFIX_BYTES:
                raise B3dFormatError(
                    f"file has {len(prefix)} bytes, expected at least {PREFIX_BYTES} (the header length)" + _not_b3d_hint(p, prefix),
                    path=p, offset=0,
                )
            (n,) = struct.unpack("<q", prefix)
            if not 0 < n <= size - PREFIX_BYTES:
                raise B3dFormatError(
                    f"header length is {n} bytes, expected 1..{size - PREFIX_BYTES} (the bytes left in the file)"
                    + _not_b3d_hint(p, prefix),
                    path=p, offset=0,
                )
            raw = fh.read(n)
    except FileNotFoundError:
        raise
    except IsADirectoryError:
        raise B3dFormatError("is a folder, expected a .b3d file", path=p) from None
    except OSError as exc:
        raise B3dFormatError(f"cannot read: {exc.strerror or exc}", path=p) from None
    try:
        msg = schema.Header.FromString(raw)
    except (DecodeError, RuntimeError, ValueError) as exc:
        raise B3dFormatError(f"the header ({n} bytes) does not parse as a .b3d header: {exc}", path=p, offset=PREFIX_BYTES) from None
    with np.errstate(all="ignore"):  # a damaged float32 array may hold signalling NaNs
        header = _header(msg, p)
    sensor, pass_bytes = int(msg.raw_sensor_frame_size), int(msg.processing_pass_frame_size)
    data_start = PREFIX_BYTES + n
    total_frames = sum(t.n_frames for t in header.trials)
    if sensor < 0:  # 0 is a frame with no marker, plate or IMU value (an empty message)
        raise B3dFormatError(f"raw_sensor_frame_size is {sensor}, expected 0 or more", path=p, offset=PREFIX_BYTES)
    if any(t.passes and t.n_frames for t in header.trials) and pass_bytes <= 0:
        raise B3dFormatError(f"processing_pass_frame_size is {pass_bytes}, expected > 0", path=p, offset=PREFIX_BYTES)
    b3d = B3dFile(p, header, data_start, max(sensor, 0), max(pass_bytes, 0), size)
    if b3d.data_end != size:
        raise B3dFormatError(
            f"the header declares {total_frames} frames, which end at byte {b3d.data_end}, but the file has "
            f"{size} bytes ({'truncated' if size < b3d.data_end else 'extra bytes after the last frame'})",
            path=p, offset=min(size, b3d.data_end),
        )
    return b3d


# --------------------------------------------------------------------------- frames

_PASS_FIXED = (
    ("pos", "D"), ("vel", "D"), ("acc", "D"), ("tau", "D"),
    ("ground_contact_wrench", "B6"), ("ground_contact_center_of_pressure", "B3"),
    ("ground_contact_torque", "B3"), ("ground_contact_force", "B3"),
    ("com_pos", "3"), ("com_vel", "3"), ("com_acc", "3"),
)


def _varint(data: bytes, pos: int) -> tuple[int, int] | None:
    """A base-128 varint at ``pos``: (value, next position), or None if truncated or too long."""
    value = shift = 0
    for i in range(pos, min(pos + 10, len(data))):
        b = data[i]
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, i + 1
        shift += 7
    return None


def _layout(message: bytes) -> list[tuple[int, int, int]] | None:
    """(field number, payload start, payload length) of every field of a serialized message
    made only of length-delimited fields (packed repeated doubles), or None otherwise."""
    out = []
    pos, end = 0, len(message)
    while pos < end:
        key = _varint(message, pos)
        if key is None or key[0] & 7 != 2 or key[0] >> 3 == 0:
            return None
        length = _varint(message, key[1])
        if length is None or length[1] + length[0] > end or length[0] % 8:
            return None
        out.append((key[0] >> 3, length[1], length[0]))
        pos = length[1] + length[0]
    return out


def _columns_fast(region: np.ndarray, fields: Mapping[int, str]) -> dict[str, np.ndarray] | None:
    """All frames of one message kind at once, when they share the first frame's layout.

    ``region`` is ``(F, L)`` bytes: message ``i`` in row ``i``. When every row has the same
    field keys and lengths at the same places as row 0 (checked byte for byte), each
    field's packed doubles sit in the same columns of every row and are read as one
    ``(F, K)`` little-endian float64 view; this gives what parsing every row would give.
    Returns None when the rows differ or are not all packed doubles (the caller then
    parses row by row and reports the damaged one).
    """
    layout = _layout(region[0].tobytes())
    if layout is None:
        return None
    framing = np.ones(region.shape[1], dtype=bool)
    for _, s0, ln in layout:
        framing[s0:s0 + ln] = False
    cols = np.flatnonzero(framing)
    if (region[:, cols] != region[0, cols]).any():
        return None
    parts: dict[str, list[np.ndarray]] = {}
    for number, s0, ln in layout:
        name = fields.get(number)
        if name is not None:
            parts.setdefault(name, []).append(np.ascontiguousarray(region[:, s0:s0 + ln]).view("<f8"))
    n = region.shape[0]
    out = {name: np.concatenate(v, axis=1) if len(v) > 1 else v[0] for name, v in parts.items()}
    for name in fields.values():
        out.setdefault(name, np.zeros((n, 0)))
    return {name: a.astype(np.float64, copy=False) for name, a in out.items()}


_SENSOR_FIELDS = {f.number: f.name for f in schema.SensorFrame.DESCRIPTOR.fields}
_PASS_FIELDS = {f.number: f.name for f in schema.PassFrame.DESCRIPTOR.fields}


def _decode_frames(b3d: B3dFile, k: int, start: int, n: int, blob: bytes, first: int) -> B3dFrames:
    h = b3d.header
    info = h.trials[k]
    path = b3d.path
    m, p = len(h.marker_names), info.n_force_plates
    na, ng = len(h.acc_names), len(h.gyro_names)
    ne = len(h.emg_names) * h.emg_dim
    nx, nc = len(h.exo_dof_indices), sum(h.custom_value_lengths)
    nb, d = len(h.ground_contact_bodies), h.n_dofs
    markers = np.full((n, m * 3), np.nan)
    force = np.full((n, p * 3), np.nan)
    cop = np.full((n, p * 3), np.nan)
    moment = np.full((n, p * 3), np.nan)
    acc_obs = np.full((n, na * 3), np.nan)
    gyro_obs = np.full((n, ng * 3), np.nan)
    emg = np.full((n, ne), np.nan)
    exo = np.full((n, nx), np.nan)
    custom = np.full((n, nc), np.nan)
    sizes = {"D": d, "B6": nb * 6, "B3": nb * 3, "3": 3}
    n_pass = len(info.passes)
    fixed = [{name: np.zeros((n, sizes[kind])) for name, kind in _PASS_FIXED} for _ in range(n_pass)]
    extra: list[dict[str, list[np.ndarray]]] = [{name: [] for name in schema.PASS_EXTRA_FIELDS} for _ in range(n_pass)]
    size = b3d.frame_bytes(info)
    sb, pb = b3d.sensor_frame_bytes, b3d.pass_frame_bytes

    def fail(message: str, offset: int, frame: int, what: str) -> B3dFormatError:
        return B3dFormatError(message, path=path, offset=offset, where=f"trial {info.name!r}, frame {frame}, {what}")

    def take(target: np.ndarray, i: int, values: Any, need: int, name: str, offset: int, frame: int, what: str, *, minimum: bool = False) -> None:
        got = len(values)
        if got == need or (minimum and got >= need):
            if need:
                target[i] = np.asarray(values, dtype=np.float64)[:need]
            return
        if got == 0 and not minimum:
            return
        raise fail(f"{name} has {got} values, expected {need}", offset, frame, what)

    def take_all(target: np.ndarray, values: np.ndarray, need: int, name: str, offset: int, what: str, *, minimum: bool = False) -> None:
        got = values.shape[1]
        if got == need or (minimum and got >= need):
            target[:] = values[:, :need]
        elif got or minimum:
            raise fail(f"{name} has {got} values, expected {need}", offset, start, what)

    fast = None
    if n:
        rows = np.frombuffer(blob, dtype=np.uint8).reshape(n, size)
        fast_sensor = _columns_fast(rows[:, :sb], _SENSOR_FIELDS)
        fast_passes = [_columns_fast(rows[:, sb + j * pb: sb + (j + 1) * pb], _PASS_FIELDS) for j in range(n_pass)]
        if fast_sensor is not None and all(f is not None for f in fast_passes):
            fast = (fast_sensor, fast_passes)
    if fast is not None:
        fs, fps = fast
        what = "sensor frame"
        take_all(markers, fs["marker_obs"], m * 3, "marker_obs", first, what)
        take_all(force, fs["raw_force_plate_force"], p * 3, "raw_force_plate_force", first, what, minimum=True)
        take_all(cop, fs["raw_force_plate_cop"], p * 3, "raw_force_plate_cop", first, what, minimum=True)
        take_all(moment, fs["raw_force_plate_torque"], p * 3, "raw_force_plate_torque", first, what, minimum=True)
        take_all(acc_obs, fs["acc_obs"], na * 3, "acc_obs", first, what)
        take_all(gyro_obs, fs["gyro_obs"], ng * 3, "gyro_obs", first, what)
        take_all(emg, fs["emg_obs"], ne, "emg_obs", first, what)
        take_all(exo, fs["exo_obs"], nx, "exo_obs", first, what)
        take_all(custom, fs["custom_values"], nc, "custom_values", first, what)
        for j, fp in enumerate(fps):
            what = f"pass {j} frame"
            for name, kind in _PASS_FIXED:
                take_all(fixed[j][name], fp[name], sizes[kind], name, first + sb + j * pb, what)
            for name in schema.PASS_EXTRA_FIELDS:
                extra[j][name] = fp[name]  # type: ignore[assignment]  # (F, K) already
    for i in range(n if fast is None else 0):
        frame = start + i
        base = i * size
        off = first + base
        try:
            s = schema.SensorFrame.FromString(blob[base:base + sb])
        except (DecodeError, RuntimeError, ValueError) as exc:
            raise fail(f"sensor frame ({sb} bytes) does not parse: {exc}", off, frame, "sensor frame") from None
        what = "sensor frame"
        take(markers, i, s.marker_obs, m * 3, "marker_obs", off, frame, what)
        take(force, i, s.raw_force_plate_force, p * 3, "raw_force_plate_force", off, frame, what, minimum=True)
        take(cop, i, s.raw_force_plate_cop, p * 3, "raw_force_plate_cop", off, frame, what, minimum=True)
        take(moment, i, s.raw_force_plate_torque, p * 3, "raw_force_plate_torque", off, frame, what, minimum=True)
        take(acc_obs, i, s.acc_obs, na * 3, "acc_obs", off, frame, what)
        take(gyro_obs, i, s.gyro_obs, ng * 3, "gyro_obs", off, frame, what)
        take(emg, i, s.emg_obs, ne, "emg_obs", off, frame, what)
        take(exo, i, s.exo_obs, nx, "exo_obs", off, frame, what)
        take(custom, i, s.custom_values, nc, "custom_values", off, frame, what)
        for j in range(n_pass):
            poff = off + sb + j * pb
            what = f"pass {j} frame"
            try:
                f = schema.PassFrame.FromString(blob[base + sb + j * pb: base + sb + (j + 1) * pb])
            except (DecodeError, RuntimeError, ValueError) as exc:
                raise fail(f"processing pass frame ({pb} bytes) does not parse: {exc}", poff, frame, what) from None
            for name, kind in _PASS_FIXED:
                take(fixed[j][name], i, getattr(f, name), sizes[kind], name, poff, frame, what)
            for name in schema.PASS_EXTRA_FIELDS:
                values = getattr(f, name)
                rows = extra[j][name]
                if rows and len(values) != len(rows[0]):
                    raise fail(f"{name} has {len(values)} values, but {len(rows[0])} on frame {start}", poff, frame, what)
                rows.append(np.asarray(values, dtype=np.float64))

    def freeze(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        a = a.reshape(shape)
        a.setflags(write=False)
        return a

    passes = []
    for j in range(n_pass):
        fx = fixed[j]
        ex = {}
        for name, rows in extra[j].items():
            if isinstance(rows, np.ndarray):
                arr = rows.copy()
            else:
                arr = np.stack(rows) if rows else np.zeros((0, 0))
            ex[name] = freeze(arr, arr.shape)
        passes.append(
            B3dPassFrames(
                type=h.passes[j].type if j < len(h.passes) else info.passes[j].type,
                pos=freeze(fx["pos"], (n, d)),
                vel=freeze(fx["vel"], (n, d)),
                acc=freeze(fx["acc"], (n, d)),
                tau=freeze(fx["tau"], (n, d)),
                ground_contact_wrench=freeze(fx["ground_contact_wrench"], (n, nb, 6)),
                ground_contact_cop=freeze(fx["ground_contact_center_of_pressure"], (n, nb, 3)),
                ground_contact_torque=freeze(fx["ground_contact_torque"], (n, nb, 3)),
                ground_contact_force=freeze(fx["ground_contact_force"], (n, nb, 3)),
                com_pos=freeze(fx["com_pos"], (n, 3)),
                com_vel=freeze(fx["com_vel"], (n, 3)),
                com_acc=freeze(fx["com_acc"], (n, 3)),
                extra=MappingProxyType(ex),
            )
        )
    time = np.arange(start, start + n, dtype=np.float64) * info.timestep_s
    time.setflags(write=False)
    return B3dFrames(
        trial=k,
        start=start,
        time_s=time,
        missing_grf=info.missing_grf[start:start + n],
        markers=freeze(markers, (n, m, 3)),
        plate_force=freeze(force, (n, p, 3)),
        plate_cop=freeze(cop, (n, p, 3)),
        plate_moment=freeze(moment, (n, p, 3)),
        passes=tuple(passes),
        acc_obs=freeze(acc_obs, (n, na, 3)),
        gyro_obs=freeze(gyro_obs, (n, ng, 3)),
        emg=freeze(emg, (n, ne)),
        exo=freeze(exo, (n, nx)),
        custom=freeze(custom, (n, nc)),
    )


def dof_names(model: Any) -> tuple[str, ...]:
    """The names of the D coordinates of a .b3d pass, for the pass's OpenSim model.

    A .b3d file stores no coordinate names: its D values per frame are the model's
    coordinates in CoordinateSet order, without the dependent coordinates of
    CoordinateCouplerConstraints (nimblephysics folds those into their joint; e.g. the
    Rajagopal model's ``knee_angle_r_beta``). Checked against nimblephysics' skeleton DOF
    names for results.b3d (tests/io/test_b3d_oracle.py).

    Parameters
    ----------
    model
        A :class:`solver.model.osim.OsimModel`.
    """
    dependent = {c.dependent for c in model.couplers}
    return tuple(c.name for c in model.coordinates if c.name not in dependent)
