"""Read back the MCAP recordings of processed trials (written by ``addb export``).

File layout (written by :mod:`addb_viewer.recording.mcap_writer`)
----------------------------------------------------------------
Every frame ``k`` of the trial is one log time, ``log_time_ns[k]`` (the frame's time in
ns), and every data channel has exactly one JSON message per frame carrying ``frame``
(= k) and ``time`` (s, the exact float64 of the trial). Non-finite numbers are written as
``null`` and read back as NaN. Units SI, OpenSim ground frame (Y up); quaternions are
named ``{x, y, z, w}`` in Foxglove messages and returned here as ``(w, x, y, z)``.

================================  =====================  =================================
topic                             schema                 per-frame content
================================  =====================  =================================
``/markers/observed``             ``addb.Markers``       ``positions``: 3M numbers, m
``/markers/model``                ``addb.Markers``       same, model markers
``/tf``                           ``foxglove.FrameTransforms``  ``world`` -> each body, and
                                                         ``z_up`` -> ``world`` (display)
``/plates/<name>/wrench``         ``addb.PlateWrench``   ``force`` N, ``cop`` m,
                                                         ``free_moment`` N·m, ``body``
``/com``                          ``addb.CenterOfMass``  ``position`` m, ``acceleration``
``/coordinates``                  ``addb.Coordinates``   ``q`` (n,), rad or m
``/residuals``                    ``addb.Residuals``     ``force`` N, ``moment`` N·m,
                                                         ``marker_rms`` m
``/joint_torques``                ``addb.JointTorques``  ``tau`` (n,), N·m or N
``/flags``                        ``addb.Flags``         ``unobserved``, ``proposed``,
                                                         ``reason``
``/annotations``                  ``addb.Annotations``   one message at frame 0: review
                                                         state and solver settings
``/scene``                        ``foxglove.SceneUpdate``  display only: GRF arrows, CoM
``/skeleton/meshes``              ``foxglove.SceneUpdate``  one message at frame 0, display
                                                         only: each body's bone meshes as
                                                         a GLB model locked to the body's
                                                         frame
================================  =====================  =================================

Metadata records: ``addb.recording`` (key ``info``: JSON of the recording's
self-description: names, plates, settings, annotations) and ``addb.frames`` (keys
``time_s`` and ``log_time_ns``: JSON arrays). The writer always writes a summary with
chunk indexes, message indexes and statistics; this reader needs them, so reading one
frame touches only the chunk holding it.

Errors: anything wrong with the file raises :class:`McapFormatError` naming the file
and what is wrong (truncated, checksum mismatch, not an addb recording, missing frames).
"""

from __future__ import annotations

import io
import json
import os
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self

import numpy as np
from numpy.typing import NDArray

from solver.errors import FileFormatError

#: ``format`` field of the ``addb.recording`` metadata and of Rerun recordings.
RECORDING_FORMAT = "addb.recording"
#: Version of the layout described in the module docstring.
RECORDING_VERSION = 1

TOPIC_OBSERVED = "/markers/observed"
TOPIC_MODEL = "/markers/model"
TOPIC_TF = "/tf"
TOPIC_COM = "/com"
TOPIC_COORDINATES = "/coordinates"
TOPIC_RESIDUALS = "/residuals"
TOPIC_TORQUES = "/joint_torques"
TOPIC_FLAGS = "/flags"
TOPIC_ANNOTATIONS = "/annotations"
TOPIC_SCENE = "/scene"
#: Bone meshes for display (one ``foxglove.SceneUpdate`` at the first log time).
TOPIC_BONES = "/skeleton/meshes"
#: Topics that are not read back (display only, or read separately).
_NOT_FRAMES = (TOPIC_SCENE, TOPIC_ANNOTATIONS, TOPIC_BONES)
#: Plate ``i`` is on ``TOPIC_PLATE.format(name=...)``; its channel metadata has ``plate_index``.
TOPIC_PLATE = "/plates/{name}/wrench"

META_INFO = "addb.recording"
META_FRAMES = "addb.frames"

#: Frame of the Foxglove transforms that holds the OpenSim ground frame.
WORLD_FRAME = "world"
#: Z-up display frame, parent of :data:`WORLD_FRAME` (rotation +90° about x).
Z_UP_FRAME = "z_up"

_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_LEN = 1 + 8 + 8 + 8 + 4  # opcode, record length, summary_start, summary_offset_start, crc


class McapFormatError(FileFormatError):
    """An MCAP recording is damaged or is not an addb recording."""


@dataclass(frozen=True)
class McapFrame:
    """Everything recorded for one frame (see the module docstring for units and frames).

    Attributes
    ----------
    frame, time
        Frame index and its time, s.
    observed, modeled
        ``(M, 3)`` marker positions, m (NaN when missing).
    body_position, body_wxyz
        ``(B, 3)`` body origins, m, and ``(B, 4)`` orientations (w, x, y, z).
    plate_force, plate_cop, plate_free_moment
        ``(P, 3)`` per plate: GRF (N), CoP (m), free moment (N·m).
    plate_body
        ``(P,)`` body index each plate's wrench is applied to (-1: none).
    com, com_acc
        ``(3,)`` centre of mass (m) and its acceleration (m/s²).
    q, tau
        ``(n,)`` coordinates and generalized forces.
    residual_force, residual_moment
        ``(3,)`` root residual force (N) and moment (N·m).
    marker_rms
        Marker RMS error of the frame, m.
    unobserved, proposed, reason
        Flags of the frame and the proposal reason.
    """

    frame: int
    time: float
    observed: NDArray[np.float64]
    modeled: NDArray[np.float64]
    body_position: NDArray[np.float64]
    body_wxyz: NDArray[np.float64]
    plate_force: NDArray[np.float64]
    plate_cop: NDArray[np.float64]
    plate_free_moment: NDArray[np.float64]
    plate_body: NDArray[np.int64]
    com: NDArray[np.float64]
    com_acc: NDArray[np.float64]
    q: NDArray[np.float64]
    tau: NDArray[np.float64]
    residual_force: NDArray[np.float64]
    residual_moment: NDArray[np.float64]
    marker_rms: float
    unobserved: bool
    proposed: bool
    reason: str


def _num(values: list[Any]) -> NDArray[np.float64]:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


class _Frames:
    """Accumulates decoded messages into ``(T, ...)`` arrays."""

    def __init__(self, info: dict[str, Any], n: int) -> None:
        m, b = len(info["marker_names"]), len(info["body_names"])
        c, p = len(info["coordinate_names"]), len(info["plates"])
        nan = np.nan
        self.body_index = {name: i for i, name in enumerate(info["body_names"])}
        self.a: dict[str, np.ndarray] = {
            "time": np.full(n, nan),
            "observed": np.full((n, m, 3), nan),
            "modeled": np.full((n, m, 3), nan),
            "body_position": np.full((n, b, 3), nan),
            "body_wxyz": np.full((n, b, 4), nan),
            "plate_force": np.full((n, p, 3), nan),
            "plate_cop": np.full((n, p, 3), nan),
            "plate_free_moment": np.full((n, p, 3), nan),
            "plate_body": np.full((n, p), -1, dtype=np.int64),
            "com": np.full((n, 3), nan),
            "com_acc": np.full((n, 3), nan),
            "q": np.full((n, c), nan),
            "tau": np.full((n, c), nan),
            "residual_force": np.full((n, 3), nan),
            "residual_moment": np.full((n, 3), nan),
            "marker_rms": np.full(n, nan),
            "unobserved": np.zeros(n, dtype=bool),
            "proposed": np.zeros(n, dtype=bool),
        }
        self.reason = [""] * n
        self.seen: dict[str, np.ndarray] = {}
        self.shape_m, self.n_coords = m, c

    def add(self, topic: str, plate: int | None, k: int, msg: dict[str, Any]) -> None:
        """Store one decoded message of frame ``k`` (row ``k`` of the arrays)."""
        a = self.a
        if topic == TOPIC_TF:
            for tr in msg["transforms"]:
                j = self.body_index.get(tr["child_frame_id"])
                if j is None or tr["parent_frame_id"] != WORLD_FRAME:
                    continue
                t, r = tr["translation"], tr["rotation"]
                a["body_position"][k, j] = _num([t["x"], t["y"], t["z"]])
                a["body_wxyz"][k, j] = _num([r["w"], r["x"], r["y"], r["z"]])
            return
        a["time"][k] = msg["time"]
        if topic in (TOPIC_OBSERVED, TOPIC_MODEL):
            key = "observed" if topic == TOPIC_OBSERVED else "modeled"
            a[key][k] = _num(msg["positions"]).reshape(self.shape_m, 3)
        elif plate is not None:
            a["plate_force"][k, plate] = _num(msg["force"])
            a["plate_cop"][k, plate] = _num(msg["cop"])
            a["plate_free_moment"][k, plate] = _num(msg["free_moment"])
            a["plate_body"][k, plate] = int(msg["body"])
        elif topic == TOPIC_COM:
            a["com"][k] = _num(msg["position"])
            a["com_acc"][k] = _num(msg["acceleration"])
        elif topic == TOPIC_COORDINATES:
            a["q"][k] = _num(msg["q"])
        elif topic == TOPIC_TORQUES:
            a["tau"][k] = _num(msg["tau"])
        elif topic == TOPIC_RESIDUALS:
            a["residual_force"][k] = _num(msg["force"])
            a["residual_moment"][k] = _num(msg["moment"])
            a["marker_rms"][k] = np.nan if msg["marker_rms"] is None else msg["marker_rms"]
        elif topic == TOPIC_FLAGS:
            a["unobserved"][k] = bool(msg["unobserved"])
            a["proposed"][k] = bool(msg["proposed"])
            self.reason[k] = str(msg["reason"])


class McapRecording:
    """An addb MCAP recording opened for random access. Use :func:`open_recording`.

    Attributes
    ----------
    path
        The file.
    info
        The recording's self-description (names, plates, settings, annotations).
    time
        ``(T,)`` frame times, s.
    log_time_ns
        ``(T,)`` MCAP log time of each frame, ns.
    """

    def __init__(self, path: Path, stream: io.BufferedReader) -> None:
        from mcap.reader import SeekingReader

        self.path = path
        self._stream = stream
        with self._reading("reading the summary"):
            self._reader = SeekingReader(stream, validate_crcs=True)
            self._check_summary_crc()
            summary = self._reader.get_summary()
            if summary is None or not summary.chunk_indexes:
                raise McapFormatError(
                    "no summary section with chunk indexes (truncated, or not written by addb export)",
                    path=path,
                )
            self._summary = summary
            meta = {m.name: m.metadata for m in self._reader.iter_metadata()}
        if META_INFO not in meta or META_FRAMES not in meta:
            raise McapFormatError(
                f"not an addb recording: metadata records {META_INFO!r} and {META_FRAMES!r} are missing",
                path=path,
            )
        with self._reading("decoding the metadata records"):
            self.info: dict[str, Any] = json.loads(meta[META_INFO]["info"])
            self.time = np.array(json.loads(meta[META_FRAMES]["time_s"]), dtype=np.float64)
            self.log_time_ns = np.array(
                json.loads(meta[META_FRAMES]["log_time_ns"]), dtype=np.int64
            )
        if (
            self.info.get("format") != RECORDING_FORMAT
            or self.info.get("version") != RECORDING_VERSION
        ):
            raise McapFormatError(
                f"expected format {RECORDING_FORMAT!r} version {RECORDING_VERSION}, found "
                f"{self.info.get('format')!r} version {self.info.get('version')!r}",
                path=path,
            )
        if self.time.shape != self.log_time_ns.shape or self.time.size != int(
            self.info["n_frames"]
        ):
            raise McapFormatError(
                "frame table does not match n_frames", path=path, where=META_FRAMES
            )
        self._channels = {cid: (ch.topic, ch.metadata) for cid, ch in summary.channels.items()}

    # ------------------------------------------------------------------ basics
    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.time.size)

    @property
    def topics(self) -> list[str]:
        """Topics of the file, sorted."""
        return sorted({t for t, _ in self._channels.values()})

    def close(self) -> None:
        """Close the file."""
        self._stream.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _reading(self, what: str) -> Iterator[None]:
        """Turn any decoding failure into a :class:`McapFormatError` naming the file."""
        import zstandard
        from mcap.exceptions import McapError

        try:
            yield
        except McapFormatError:
            raise
        except (
            McapError,
            zstandard.ZstdError,
            struct.error,
            EOFError,
            ValueError,
            KeyError,
            IndexError,
            TypeError,
            zlib.error,
        ) as exc:
            detail = str(exc) or type(exc).__name__
            raise McapFormatError(
                f"damaged file while {what}: {type(exc).__name__}: {detail}", path=self.path
            ) from exc

    def _check_summary_crc(self) -> None:
        """Check the magic at both ends and the footer's summary CRC (the library does not)."""
        s = self._stream
        size = s.seek(0, os.SEEK_END)
        if size < 2 * len(_MAGIC) + _FOOTER_LEN:
            raise McapFormatError(f"file too short for an MCAP file ({size} bytes)", path=self.path)
        s.seek(size - len(_MAGIC) - _FOOTER_LEN)
        tail = s.read(_FOOTER_LEN + len(_MAGIC))
        if tail[-len(_MAGIC) :] != _MAGIC or tail[0] != 0x02:
            raise McapFormatError(
                "no MCAP footer at the end of the file (truncated?)", path=self.path
            )
        summary_start, _, crc = struct.unpack("<QQI", tail[9:_FOOTER_LEN])
        if crc and summary_start:
            end = size - len(_MAGIC) - 4
            if not 0 < summary_start < end:
                raise McapFormatError(
                    f"footer points outside the file (summary at {summary_start})", path=self.path
                )
            s.seek(summary_start)
            if zlib.crc32(s.read(end - summary_start)) != crc:
                raise McapFormatError(
                    "summary section checksum mismatch (damaged index)", path=self.path
                )

    def _decode(
        self, frames: _Frames, channel_id: int, log_time: int, data: bytes, k: int | None
    ) -> None:
        topic, meta = self._channels[channel_id]
        plate = int(meta["plate_index"]) if "plate_index" in meta else None
        if topic in _NOT_FRAMES:
            return
        msg = json.loads(data)
        if topic == TOPIC_TF:
            idx = int(np.searchsorted(self.log_time_ns, log_time))
            frame = idx if idx < self.n_frames and self.log_time_ns[idx] == log_time else -1
        else:
            frame = int(msg["frame"])
        if not 0 <= frame < self.n_frames or (k is not None and frame != k):
            raise McapFormatError(
                f"message of frame {frame} at an unexpected log time {log_time}",
                path=self.path,
                where=topic,
            )
        frames.add(topic, plate, frame if k is None else 0, msg)
        frames.seen.setdefault(
            topic + ("" if plate is None else f"#{plate}"), np.zeros(frames.a["time"].size, bool)
        )[frame if k is None else 0] = True

    def _expected_channels(self) -> set[str]:
        out = set()
        for topic, meta in self._channels.values():
            if topic in _NOT_FRAMES:
                continue
            out.add(topic + (f"#{meta['plate_index']}" if "plate_index" in meta else ""))
        return out

    def _check_complete(self, frames: _Frames, what: str) -> None:
        for key in sorted(self._expected_channels()):
            seen = frames.seen.get(key)
            missing = frames.a["time"].size if seen is None else int((~seen).sum())
            if missing:
                raise McapFormatError(
                    f"{what}: {missing} frame(s) missing on channel",
                    path=self.path,
                    where=key.split("#")[0],
                )

    # ------------------------------------------------------------------ reading
    def frame(self, k: int) -> McapFrame:
        """Everything recorded for frame ``k``, read through the chunk index (only the
        chunk(s) holding that log time are read and decompressed).

        Raises
        ------
        IndexError
            ``k`` outside ``[0, n_frames)``.
        McapFormatError
            The chunk is damaged or a channel has no message for the frame.
        """
        if not -self.n_frames <= k < self.n_frames:
            raise IndexError(f"frame {k} out of range (the recording has {self.n_frames} frames)")
        k = int(k) % self.n_frames
        t = int(self.log_time_ns[k])
        frames = _Frames(self.info, 1)
        with self._reading(f"reading frame {k}"):
            for _, channel, message in self._reader.iter_messages(
                starting_at=t, ending_before=t + 1
            ):
                self._decode(frames, channel.id, message.log_time, message.data, k)
        self._check_complete(frames, f"frame {k}")
        row = {name: v[0] for name, v in frames.a.items()}
        return McapFrame(
            frame=k,
            reason=frames.reason[0],
            marker_rms=float(row.pop("marker_rms")),
            unobserved=bool(row.pop("unobserved")),
            proposed=bool(row.pop("proposed")),
            time=float(row.pop("time")),
            **row,
        )

    def to_arrays(self) -> dict[str, Any]:
        """All frames as ``(T, ...)`` arrays (keys as the :class:`McapFrame` fields, plus
        ``reason`` as a list), reading every chunk once in file order.

        Raises
        ------
        McapFormatError
            A chunk is damaged or some frame is missing on some channel.
        """
        frames = _Frames(self.info, self.n_frames)
        with self._reading("reading all frames"):
            for _, channel, message in self._reader.iter_messages(log_time_order=False):
                self._decode(frames, channel.id, message.log_time, message.data, None)
        self._check_complete(frames, "whole file")
        out: dict[str, Any] = dict(frames.a)
        out["reason"] = frames.reason
        return out

    def annotations(self) -> dict[str, Any]:
        """The ``/annotations`` message: ``{"subject", "trial", "state", "settings"}``.

        Raises
        ------
        McapFormatError
            No message on ``/annotations``, or its chunk or JSON is damaged.
        """
        with self._reading("reading /annotations"):
            for _, _, message in self._reader.iter_messages(topics=[TOPIC_ANNOTATIONS]):
                return json.loads(message.data)
        raise McapFormatError("no message on /annotations", path=self.path)

    def to_processed(self) -> Any:
        """Rebuild a :class:`solver.results.ProcessedTrial` (``qd``, ``qdd`` are NaN: not
        recorded; ``settings`` and ``metrics`` come from the metadata)."""
        from solver.results import PlateData, ProcessedTrial

        a = self.to_arrays()
        info = self.info
        plates = tuple(
            PlateData(
                name=p["name"],
                force=a["plate_force"][:, i].copy(),
                cop=a["plate_cop"][:, i].copy(),
                free_moment=a["plate_free_moment"][:, i].copy(),
                corners=None
                if p.get("corners") is None
                else np.array(p["corners"], dtype=np.float64),
                body=a["plate_body"][:, i].copy(),
            )
            for i, p in enumerate(info["plates"])
        )
        return ProcessedTrial(
            subject=info["subject"],
            trial=info["trial"],
            time=self.time.copy(),
            coordinate_names=tuple(info["coordinate_names"]),
            q=a["q"],
            qd=np.full_like(a["q"], np.nan),
            qdd=np.full_like(a["q"], np.nan),
            marker_names=tuple(info["marker_names"]),
            observed=a["observed"],
            modeled=a["modeled"],
            body_names=tuple(info["body_names"]),
            body_position=a["body_position"],
            body_wxyz=a["body_wxyz"],
            body_meshes={b: [(f, tuple(s)) for f, s in m] for b, m in info["body_meshes"].items()},
            plates=plates,
            mass_kg=float(info["mass_kg"]) if info["mass_kg"] is not None else float("nan"),
            height_m=info["height_m"],
            com=a["com"],
            com_acc=a["com_acc"],
            residual_force=a["residual_force"],
            residual_moment=a["residual_moment"],
            tau=a["tau"],
            unobserved=a["unobserved"],
            proposed=a["proposed"],
            proposal_reasons=tuple(a["reason"]),
            metrics=info.get("metrics") or {},
            model_path=info.get("model_path", ""),
            geometry_dir=info.get("geometry_dir", ""),
            settings=info.get("settings") or {},
        )


def open_recording(path: str | os.PathLike[str]) -> McapRecording:
    """Open an addb MCAP recording for random access.

    Reads the footer, the summary (schemas, channels, chunk and metadata indexes) and the
    two metadata records; no message is read.

    Raises
    ------
    FileNotFoundError
        No such file.
    McapFormatError
        Not an MCAP file, truncated, damaged summary, or not an addb recording.
    """
    p = Path(path)
    # closed by McapRecording.close
    stream = open(p, "rb")  # noqa: SIM115
    try:
        return McapRecording(p, stream)
    except BaseException:
        stream.close()
        raise


def load_processed_mcap(path: str | os.PathLike[str]) -> Any:
    """The :class:`solver.results.ProcessedTrial` stored in an MCAP recording (for
    ``addb view FILE.mcap``).

    Raises
    ------
    McapFormatError
        As :func:`open_recording` and :meth:`McapRecording.to_arrays`.
    """
    with open_recording(path) as rec:
        return rec.to_processed()
