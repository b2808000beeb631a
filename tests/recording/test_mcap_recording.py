"""The MCAP recording: exact round trip through solver.io.mcap_file, indexed frame
access, Foxglove conventions, and clear errors on damaged files."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk

from addb_viewer.recording.foxglove_schemas import x_to_direction_quaternions
from addb_viewer.recording.mcap_writer import frame_log_times, write_mcap
from solver.errors import FileFormatError
from solver.io.mcap_file import (
    TOPIC_TF,
    McapFormatError,
    McapRecording,
    load_processed_mcap,
    open_recording,
)
from solver.results import ProcessedTrial
from tests.recording.recording_support import REVIEW

ARRAYS = (
    "observed",
    "modeled",
    "body_position",
    "body_wxyz",
    "com",
    "com_acc",
    "q",
    "tau",
    "residual_force",
    "residual_moment",
    "unobserved",
    "proposed",
)


@pytest.fixture
def mcap_file(tmp_path: Path, any_trial: ProcessedTrial) -> tuple[ProcessedTrial, Path]:
    return any_trial, write_mcap(any_trial, tmp_path / "walk.mcap", annotations=REVIEW)


def assert_same(got: np.ndarray, want: np.ndarray) -> None:
    """Bit-exact equality, NaN where NaN."""
    assert got.shape == want.shape and got.dtype.kind == np.asarray(want).dtype.kind
    np.testing.assert_array_equal(got, want, strict=False)


def test_round_trip_is_exact(mcap_file: tuple[ProcessedTrial, Path]) -> None:
    trial, path = mcap_file
    with open_recording(path) as rec:
        assert rec.n_frames == trial.n_frames
        a = rec.to_arrays()
        assert_same(rec.time, trial.time)
        for name in ARRAYS:
            assert_same(a[name], getattr(trial, name))
        for i, p in enumerate(trial.plates):
            assert_same(a["plate_force"][:, i], p.force)
            assert_same(a["plate_cop"][:, i], p.cop)
            assert_same(a["plate_free_moment"][:, i], p.free_moment)
            assert_same(a["plate_body"][:, i], p.body)
        assert_same(a["marker_rms"], trial.marker_rms_per_frame)
        assert a["reason"] == list(trial.proposal_reasons)
        assert rec.info["marker_names"] == list(trial.marker_names)
        assert rec.info["settings"] == trial.settings
        assert rec.annotations() == {
            "subject": trial.subject,
            "trial": trial.trial,
            "state": REVIEW,
            "settings": trial.settings,
        }


def test_processed_trial_rebuilt(mcap_file: tuple[ProcessedTrial, Path]) -> None:
    trial, path = mcap_file
    back = load_processed_mcap(path)
    for name in (*ARRAYS, "time"):
        assert_same(getattr(back, name), getattr(trial, name))
    assert (
        back.subject,
        back.trial,
        back.coordinate_names,
        back.marker_names,
        back.body_names,
    ) == (trial.subject, trial.trial, trial.coordinate_names, trial.marker_names, trial.body_names)
    assert back.body_meshes == trial.body_meshes and back.proposal_reasons == trial.proposal_reasons
    assert back.mass_kg == trial.mass_kg and back.settings == trial.settings
    for p, q in zip(back.plates, trial.plates, strict=True):
        assert p.name == q.name and (p.corners is None) == (q.corners is None)
        if q.corners is not None:
            assert_same(p.corners, q.corners)


@pytest.mark.parametrize("k", [0, 1, 117, -1])
def test_frame_k_is_frame_k(mcap_file: tuple[ProcessedTrial, Path], k: int) -> None:
    trial, path = mcap_file
    with open_recording(path) as rec:
        f = rec.frame(k)
    k = k % trial.n_frames
    assert f.frame == k and f.time == trial.time[k]
    for name in (
        "observed",
        "modeled",
        "body_position",
        "body_wxyz",
        "com",
        "com_acc",
        "q",
        "tau",
        "residual_force",
        "residual_moment",
    ):
        assert_same(getattr(f, name), getattr(trial, name)[k])
    assert_same(f.plate_force, np.stack([p.force[k] for p in trial.plates]))
    assert f.unobserved == trial.unobserved[k] and f.reason == trial.proposal_reasons[k]


def test_frame_out_of_range(mcap_file: tuple[ProcessedTrial, Path]) -> None:
    trial, path = mcap_file
    with open_recording(path) as rec, pytest.raises(IndexError, match="out of range"):
        rec.frame(trial.n_frames)


class CountingFile(io.BufferedReader):
    """A file that counts the bytes read through it."""

    def __init__(self, path: Path) -> None:
        super().__init__(io.FileIO(path, "rb"))
        self.bytes_read = 0

    def read(self, size: int | None = -1) -> bytes:
        data = super().read(size)
        self.bytes_read += len(data)
        return data


def test_reading_one_frame_uses_the_index(tmp_path: Path, dynamic_trial: ProcessedTrial) -> None:
    path = write_mcap(dynamic_trial, tmp_path / "walk.mcap")
    size = path.stat().st_size
    stream = CountingFile(path)
    rec = McapRecording(path, stream)
    opened = stream.bytes_read
    f = rec.frame(150)
    per_frame = stream.bytes_read - opened
    rec.close()
    assert f.frame == 150
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    largest_chunk = max(c.chunk_length for c in summary.chunk_indexes)
    # the summary + metadata, then one chunk (maybe two at a boundary): never the file
    assert len(summary.chunk_indexes) >= 8
    assert per_frame <= 2 * largest_chunk + 4096, (per_frame, largest_chunk, size)
    assert opened + per_frame < size / 3


def test_file_is_chunked_compressed_and_indexed(mcap_file: tuple[ProcessedTrial, Path]) -> None:
    trial, path = mcap_file
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        assert all(c.message_index_offsets for c in summary.chunk_indexes)  # message indexes
        # /annotations and /skeleton/meshes once; per frame: 2 marker sets, P plates, com, q,
        # residuals, tau, flags, tf, scene
        assert summary.statistics.message_count == 2 + trial.n_frames * (9 + len(trial.plates))
        channels = {c.topic: c for c in summary.channels.values()}
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        assert schemas[TOPIC_TF].name == "foxglove.FrameTransforms"
        assert schemas["/scene"].name == "foxglove.SceneUpdate"
        for topic, ch in channels.items():
            assert ch.message_encoding == "json" and schemas[topic].encoding == "jsonschema", topic
            schema = json.loads(schemas[topic].data)
            assert schema["type"] == "object"
        # every message's keys are declared by its channel's schema
        seen = set()
        for schema, channel, message in reader.iter_messages():
            if channel.topic in seen:
                continue
            seen.add(channel.topic)
            props = json.loads(schema.data)["properties"]
            assert set(json.loads(message.data)) <= set(props), channel.topic
        assert seen == set(channels)


def test_tf_follows_foxglove_conventions(mcap_file: tuple[ProcessedTrial, Path]) -> None:
    """Every frame's ``/tf`` message: ``z_up`` -> ``world`` turns the lab's Y up onto
    Foxglove's Z up, each body hangs from ``world`` with the trial's own position and
    quaternion at that frame (w, x, y, z named x, y, z, w), and every transform is stamped
    with the MCAP log time of its message (as Foxglove looks transforms up)."""
    trial, path = mcap_file
    with open(path, "rb") as fh:
        messages = list(make_reader(fh).iter_messages(topics=[TOPIC_TF]))
    assert len(messages) == trial.n_frames
    for k, (_, _, message) in enumerate(messages):
        assert message.log_time == round(trial.time[k] * 1e9), k  # the frame's time, ns
        msg = json.loads(message.data)
        tfs = {t["child_frame_id"]: t for t in msg["transforms"]}
        assert set(tfs) == {"world", *trial.body_names}
        sec, nsec = divmod(message.log_time, 1_000_000_000)
        assert all(t["timestamp"] == {"sec": sec, "nsec": nsec} for t in tfs.values()), k
        assert tfs["world"]["parent_frame_id"] == "z_up"
        r = tfs["world"]["rotation"]
        w, v = r["w"], np.array([r["x"], r["y"], r["z"]])
        y = np.array([0.0, 1.0, 0.0])
        up = y + 2 * w * np.cross(v, y) + 2 * np.cross(v, np.cross(v, y))
        np.testing.assert_allclose(up, [0.0, 0.0, 1.0], atol=1e-12)
        for j, body in enumerate(trial.body_names):
            t = tfs[body]
            assert t["parent_frame_id"] == "world", body
            got_p = [t["translation"][a] for a in "xyz"]
            got_q = [t["rotation"][a] for a in "wxyz"]
            got = np.array([np.nan if c is None else c for c in got_p + got_q], dtype=float)
            want = np.concatenate([trial.body_position[k, j], trial.body_wxyz[k, j]])
            np.testing.assert_array_equal(got, want, err_msg=f"frame {k} {body}")
    assert trial.time[0] == 0.0  # the demo starts at 0 s: no shift of the log times


def test_arrow_quaternion_turns_x_onto_the_force() -> None:
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), [[1, 0, 0], [-1, 0, 0]]])
    q = x_to_direction_quaternions(d)
    w, v = q[:, :1], q[:, 1:]
    x = np.array([1.0, 0, 0])
    rotated = x + 2 * w * np.cross(v, x) + 2 * np.cross(v, np.cross(v, x))
    np.testing.assert_allclose(rotated, d, atol=1e-12)


def test_frame_times_must_increase() -> None:
    assert frame_log_times(np.array([0.0, 0.01, 0.02])).tolist() == [0, 10_000_000, 20_000_000]
    assert frame_log_times(np.array([-0.5, 0.0])).tolist() == [0, 500_000_000]
    with pytest.raises(ValueError, match="strictly increasing"):
        frame_log_times(np.array([0.0, 0.0]))


# ---------------------------------------------------------------------- damaged files
def _chunk_data_offset(path: Path) -> tuple[int, int]:
    """(offset, length) of the compressed records of the second chunk."""
    with open(path, "rb") as fh:
        ci = make_reader(fh).get_summary().chunk_indexes[1]
        fh.seek(ci.chunk_start_offset + 1 + 8)
        from mcap.data_stream import ReadDataStream

        chunk = Chunk.read(ReadDataStream(fh))
    return ci.chunk_start_offset + ci.chunk_length - len(chunk.data), len(chunk.data)


def _damaged(src: Path, dst: Path, edit) -> Path:
    data = bytearray(src.read_bytes())
    dst.write_bytes(edit(data))
    return dst


def test_truncated_file_is_refused(tmp_path: Path, dynamic_trial: ProcessedTrial) -> None:
    good = write_mcap(dynamic_trial, tmp_path / "good.mcap")
    bad = _damaged(good, tmp_path / "cut.mcap", lambda d: d[: len(d) // 2])
    with pytest.raises(McapFormatError, match="cut.mcap") as exc:
        open_recording(bad)
    assert "truncated" in str(exc.value) and isinstance(exc.value, FileFormatError)
    assert exc.value.to_dict()["path"] == str(bad)


def test_flipped_bytes_in_a_chunk_are_reported(
    tmp_path: Path, dynamic_trial: ProcessedTrial
) -> None:
    good = write_mcap(dynamic_trial, tmp_path / "good.mcap")
    offset, length = _chunk_data_offset(good)

    def flip(d: bytearray) -> bytearray:
        for i in range(offset + length // 3, offset + length // 3 + 8):
            d[i] ^= 0xFF
        return d

    bad = _damaged(good, tmp_path / "flipped.mcap", flip)
    rec = open_recording(bad)  # the index is intact
    with pytest.raises(
        McapFormatError, match=r"flipped\.mcap.*damaged file while reading all frames"
    ):
        rec.to_arrays()
    with open(bad, "rb") as fh:
        start = make_reader(fh).get_summary().chunk_indexes[1].message_start_time
    first_frame_of_chunk = int(np.searchsorted(rec.log_time_ns, start))
    with pytest.raises(McapFormatError, match=f"reading frame {first_frame_of_chunk}"):
        rec.frame(first_frame_of_chunk)
    assert rec.frame(0).frame == 0  # other chunks still readable
    rec.close()


def test_flipped_bytes_in_the_summary_are_reported(
    tmp_path: Path, dynamic_trial: ProcessedTrial
) -> None:
    good = write_mcap(dynamic_trial, tmp_path / "good.mcap")
    with open(good, "rb") as fh:
        fh.seek(-(8 + 29), 2)
        start = int.from_bytes(fh.read(29)[9:17], "little")

    def flip(d: bytearray) -> bytearray:
        d[start + 40] ^= 0x01
        return d

    with pytest.raises(McapFormatError, match="summary section checksum mismatch"):
        open_recording(_damaged(good, tmp_path / "summary.mcap", flip))


def test_not_an_mcap_file(tmp_path: Path) -> None:
    p = tmp_path / "notes.mcap"
    p.write_text("hello, this is not a recording at all, just some text\n" * 3)
    with pytest.raises(McapFormatError, match="notes.mcap"):
        open_recording(p)


def test_foreign_mcap_is_not_an_addb_recording(tmp_path: Path) -> None:
    from mcap.writer import Writer

    p = tmp_path / "foreign.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        ch = w.register_channel("/x", "json", 0)
        w.add_message(ch, log_time=1, publish_time=1, data=b"{}")
        w.finish()
    with pytest.raises(McapFormatError, match="not an addb recording"):
        open_recording(p)


def test_missing_messages_are_reported(tmp_path: Path, demo_trial: ProcessedTrial) -> None:
    """A file whose /residuals channel lost a frame (rewritten without it) is refused by
    to_arrays, naming the channel."""
    from mcap.writer import Writer

    good = write_mcap(demo_trial, tmp_path / "good.mcap")
    bad = tmp_path / "gap.mcap"
    with open(good, "rb") as src, open(bad, "wb") as dst:
        reader = make_reader(src)
        summary = reader.get_summary()
        w = Writer(dst)
        w.start()
        for s in summary.schemas.values():
            w.register_schema(s.name, s.encoding, s.data)
        for c in sorted(summary.channels.values(), key=lambda c: c.id):
            w.register_channel(c.topic, c.message_encoding, c.schema_id, c.metadata)
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic == "/residuals" and message.sequence == 100:
                continue
            w.add_message(
                channel.id, message.log_time, message.data, message.publish_time, message.sequence
            )
        w.finish()
    with open_recording(bad) as rec:
        with pytest.raises(McapFormatError, match=r"/residuals.*1 frame\(s\) missing"):
            rec.to_arrays()
        with pytest.raises(McapFormatError, match="frame 100"):
            rec.frame(100)
        assert rec.frame(99).frame == 99
