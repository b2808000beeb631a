"""Write -> read of .b3d files is exact on every field written.

1. results.b3d read, written and read again: the frame bytes are identical to the original
   and every header field and frame value is equal.
2. A subject with kinematics and dynamics passes, unequal plate counts per trial, NaN
   markers, IMU/EMG/custom channels, plate corners, tags and every missing-GRF reason:
   every value comes back exactly (per-frame header summaries as float32, as stored).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

from solver.io.b3d import (
    MISSING_GRF_REASONS,
    B3dFrames,
    B3dHeader,
    B3dPass,
    B3dPassFrames,
    B3dTrial,
    B3dTrialPass,
    open_b3d,
)
from solver.io.b3d_writer import write_b3d
from tests.conftest import SHARED_DATA

B3D = SHARED_DATA / "b3d" / "results.b3d"  # the published subject: its absence fails, as every shared file's


def assert_same(a: object, b: object, where: str = "") -> None:
    """Recursive exact equality of dataclasses, tuples, mappings and arrays (NaN == NaN)."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, (dict, MappingProxyType)):
        assert set(a) == set(b), where
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.shape == b.shape, f"{where}: {a.shape} vs {getattr(b, 'shape', None)}"
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, tuple) and a and not isinstance(a[0], str):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def test_results_b3d_rewrites_identically(tmp_path: Path) -> None:
    src = open_b3d(B3D)
    frames = [src.read_trial(k) for k in range(len(src.header.trials))]
    out = tmp_path / "rewritten.b3d"
    write_b3d(out, src.header, frames)
    back = open_b3d(out)
    assert_same(src.header, back.header, "header")
    for k, fr in enumerate(frames):
        assert_same(fr, back.read_trial(k), f"trial {k}")
    original = B3D.read_bytes()
    written = out.read_bytes()
    assert original[src.data_start:] == written[back.data_start:]


def _f32(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def _synthetic(rng: np.random.Generator) -> tuple[B3dHeader, list[B3dFrames]]:
    d, markers, bodies = 7, ("A", "B", "", "D"), ("calcn_r", "calcn_l")
    trials, blocks = [], []
    reasons = list(MISSING_GRF_REASONS)
    for k, (n, plates) in enumerate(((23, 2), (17, 3))):
        passes = tuple(
            B3dTrialPass(
                type=t,
                marker_rms=_f32(rng.random(n)),
                marker_max=_f32(rng.random(n)),
                linear_residual=_f32(rng.random(n) * 50),
                angular_residual=_f32(rng.random(n) * 20),
                joints_max_velocity=_f32(rng.random(n) * 9),
                dof_positions_observed=rng.random(d) > 0.3,
                dof_velocities_finite_differenced=rng.random(d) > 0.5,
                dof_accelerations_finite_differenced=np.ones(d, bool),
                lowpass_cutoff_hz=float(np.float32(6.0 * (j + 1))),
                lowpass_filter_order=2 * j,
                force_plate_cutoffs=_f32(rng.random(plates) * 20),
            )
            for j, t in enumerate(("kinematics", "dynamics"))
        )
        trials.append(
            B3dTrial(
                name=f"walk{k}_segment_0",
                original_name=f"walk{k}",
                split_index=k,
                timestep_s=1 / 120 if k else 0.005,
                n_frames=n,
                tags=("overground", f"tag{k}"),
                missing_grf=tuple(reasons[i % len(reasons)] for i in range(n)),
                n_force_plates=plates,
                force_plate_corners=rng.normal(size=(plates, 4, 3)),
                marker_names_guessed=bool(k),
                passes=passes,
            )
        )
        mk = rng.normal(size=(n, len(markers), 3))
        mk[rng.random((n, len(markers))) < 0.2] = np.nan
        pass_frames = tuple(
            B3dPassFrames(
                type=t,
                pos=rng.normal(size=(n, d)),
                vel=rng.normal(size=(n, d)),
                acc=rng.normal(size=(n, d)),
                tau=rng.normal(size=(n, d)) * 100,
                ground_contact_wrench=rng.normal(size=(n, 2, 6)),
                ground_contact_cop=rng.normal(size=(n, 2, 3)),
                ground_contact_torque=rng.normal(size=(n, 2, 3)),
                ground_contact_force=rng.normal(size=(n, 2, 3)),
                com_pos=rng.normal(size=(n, 3)),
                com_vel=rng.normal(size=(n, 3)),
                com_acc=rng.normal(size=(n, 3)),
                extra=MappingProxyType({
                    name: (rng.normal(size=(n, 6)) if name == "root_frame_residual" else np.zeros((n, 0)))
                    for name in ("root_frame_residual", "root_frame_com_acc")
                }),
            )
            for t in ("kinematics", "dynamics")
        )
        blocks.append(
            B3dFrames(
                trial=k,
                start=0,
                time_s=np.arange(n) * trials[-1].timestep_s,
                missing_grf=trials[-1].missing_grf,
                markers=mk,
                plate_force=rng.normal(size=(n, plates, 3)) * 300,
                plate_cop=rng.normal(size=(n, plates, 3)),
                plate_moment=rng.normal(size=(n, plates, 3)),
                passes=pass_frames,
                acc_obs=rng.normal(size=(n, 1, 3)),
                gyro_obs=rng.normal(size=(n, 1, 3)),
                emg=rng.normal(size=(n, 2 * 3)),
                exo=rng.normal(size=(n, 1)),
                custom=rng.normal(size=(n, 5)),
            )
        )
    header = B3dHeader(
        version=4,
        n_dofs=d,
        mass_kg=71.3,
        height_m=1.77,
        sex="female",
        age_years=31,
        tags=("healthy", "test"),
        notes="written by addb tests",
        href="https://example.org/subject",
        ground_contact_bodies=bodies,
        marker_names=markers,
        passes=(B3dPass("kinematics", "<OpenSimDocument/>"), B3dPass("dynamics", "<OpenSimDocument Version='4'/>")),
        trials=tuple(trials),
        n_joints=5,
        acc_names=("imu_pelvis",),
        gyro_names=("imu_pelvis",),
        emg_names=("soleus_r", "tibant_r"),
        emg_dim=3,
        exo_dof_indices=(4,),
        custom_value_names=("a", "b"),
        custom_value_lengths=(2, 3),
    )
    return header, blocks




def test_synthetic_two_pass_subject_round_trip(tmp_path: Path) -> None:
    header, blocks = _synthetic(np.random.default_rng(27))
    out = tmp_path / "synthetic.b3d"
    write_b3d(out, header, blocks)
    back = open_b3d(out)
    assert_same(header, back.header, "header")
    for k, written in enumerate(blocks):
        read = back.read_trial(k)
        for name in ("trial", "start", "missing_grf", "markers", "plate_force", "plate_cop", "plate_moment",
                     "acc_obs", "gyro_obs", "emg", "exo", "custom"):  # fmt: skip
            assert_same(getattr(written, name), getattr(read, name), f"trial {k}.{name}")
        np.testing.assert_allclose(read.time_s, written.time_s, rtol=1e-15)
        for j, (wp, rp) in enumerate(zip(written.passes, read.passes, strict=True)):
            for f in dataclasses.fields(wp):
                if f.name == "extra":
                    for name, arr in wp.extra.items():
                        assert_same(arr, rp.extra[name], f"trial {k} pass {j} {name}")
                else:
                    assert_same(getattr(wp, f.name), getattr(rp, f.name), f"trial {k} pass {j}.{f.name}")
        # a frame in the middle, read by seeking, equals the same row of the whole trial
        mid = back.read_frame(k, 9)
        np.testing.assert_array_equal(mid.passes[1].tau[0], written.passes[1].tau[9])


def test_writer_rejects_mismatched_frames(tmp_path: Path) -> None:
    header, blocks = _synthetic(np.random.default_rng(1))
    bad = dataclasses.replace(blocks[0], markers=blocks[0].markers[:, :2])
    with pytest.raises(ValueError, match="markers of shape"):
        write_b3d(tmp_path / "bad.b3d", header, [bad, blocks[1]])
    assert not (tmp_path / "bad.b3d").exists() and not (tmp_path / "bad.b3d.partial").exists()


def test_fields_the_schema_does_not_name_are_read_and_written_back(tmp_path: Path) -> None:
    """Audit 2026-12-02-b3d finding 7: header fields of the current nimblephysics format
    (``data_quality`` of the header; ``trial_type``, ``has_manual_GRF_annotation`` and the
    original trial's start of a trial; here at field numbers the schema does not name) were
    dropped when a file was rewritten. results.b3d with such fields added to its header, a
    trial, a trial pass and a pass: they are read as ``extra_fields`` and come back exactly
    (read -> write -> read equal, write -> read -> write byte-identical)."""
    import struct

    from solver.io import b3d_schema as schema

    data = B3D.read_bytes()
    (n,) = struct.unpack("<q", data[:8])
    msg = schema.Header.FromString(data[8:8 + n])
    header_extra = bytes([0xC8, 0x01, 2])  # field 25, varint 2
    trial_extra = bytes([0x80, 0x01, 1]) + bytes([0x61]) + struct.pack("<d", 1.25) + bytes([0x92, 0x01, 3, 1, 0, 1])  # 16 = 1, 12 = 1.25, 18 = packed bools
    pass_extra = bytes([0x68, 7])  # field 13, varint 7
    msg.MergeFromString(header_extra)
    msg.trial_header[1].MergeFromString(trial_extra)
    msg.trial_header[1].processing_pass_header[0].MergeFromString(pass_extra)
    msg.passes[0].MergeFromString(pass_extra)
    raw = msg.SerializeToString()
    source = tmp_path / "newer.b3d"
    source.write_bytes(struct.pack("<q", len(raw)) + raw + data[8 + n:])

    src = open_b3d(source)
    h = src.header
    frames = [src.read_trial(k) for k in range(len(h.trials))]
    first = tmp_path / "first.b3d"
    write_b3d(first, h, frames)
    written = first.read_bytes()
    (m,) = struct.unpack("<q", written[:8])
    rewritten = schema.Header.FromString(written[8:8 + m])  # each message keeps its own extra fields
    assert rewritten.SerializeToString()[-len(header_extra):] == header_extra
    assert rewritten.trial_header[1].SerializeToString()[-len(trial_extra):] == trial_extra
    assert rewritten.trial_header[1].processing_pass_header[0].SerializeToString()[-len(pass_extra):] == pass_extra
    assert rewritten.passes[0].SerializeToString()[-len(pass_extra):] == pass_extra
    from solver.io.b3d import extra_field_values

    assert h.extra_fields == header_extra and extra_field_values(h.extra_fields) == {25: (2,)}
    assert h.trials[0].extra_fields == b"" and h.trials[1].extra_fields == trial_extra
    assert extra_field_values(trial_extra) == {16: (1,), 12: (struct.pack("<d", 1.25),), 18: (bytes([1, 0, 1]),)}
    assert h.trials[1].passes[0].extra_fields == pass_extra == h.passes[0].extra_fields
    back = open_b3d(first)
    assert_same(h, back.header, "header")
    for k, fr in enumerate(frames):
        assert_same(fr, back.read_trial(k), f"trial {k}")
    second = tmp_path / "second.b3d"
    write_b3d(second, back.header, [back.read_trial(k) for k in range(len(h.trials))])
    assert second.read_bytes() == first.read_bytes()
    assert first.read_bytes()[back.data_start:] == data[8 + n:]
    # a field the schema names cannot pass as an extra one
    with pytest.raises(ValueError, match=r"header: extra_fields hold field\(s\) \[15\]"):
        write_b3d(tmp_path / "bad.b3d", dataclasses.replace(h, extra_fields=bytes([0x79]) + struct.pack("<d", 70.0)), frames)
