"""Check the layout of a C3D file in pure Python before ezc3d reads it.

ezc3d trusts the counts and offsets it finds in a file: a damaged byte can make it index
past the end of a vector and die with a segmentation fault (for example a parameter whose
number of dimensions reads as negative leaves its dimension list empty, and ezc3d then
reads ``dimension[0]``). A crash takes the whole process with it (a batch worker, the
review app's server), so :func:`check_c3d` walks the file the way the format defines it
and raises :class:`~solver.errors.C3dFormatError` at the first thing that is off, naming
the file, the section (``header``, ``parameter section`` with the group and parameter,
``data section``), the byte offset and what was expected.

Layout (the C3D format specification by Motion Lab Systems, c3d.org; bytes counted from
0, blocks of 512 bytes counted from 1):

* **header**, block 1: byte 0 the first block of the parameter section, byte 1 the key
  0x50; 16-bit words 2-10 (from byte 2): number of points, analog values per frame (all
  channels x samples), first and last frame (1-based), maximum gap, the scale factor
  (a 32-bit float; negative: data stored as floats), the first block of the data
  section, analog samples per frame and the frame rate (a float).
* **parameter section**: a 4-byte header (byte 2 the number of 512-byte blocks, byte 3
  the processor type: 84 Intel, 85 DEC, 86 MIPS) then groups and parameters. Each
  starts with a signed name length (negative: locked; 0 ends the section), a signed
  id (negative: a group, positive: a parameter of that group), the name, and an
  unsigned 16-bit offset from that offset field to the next item (0: last item).
  A group then has a description (length byte, text); a parameter has a data type
  (-1 char, 1 byte, 2 int16, 4 float32), a number of dimensions (0-7; 0: a scalar),
  the dimensions (one byte each), the data, and a description.
* **data section**, from the data start block: per frame, per point 4 values (x, y, z,
  residual/camera word) and then the analog values, each a float32 (scale < 0) or an
  int16.

Integers follow the processor type (little-endian for Intel and DEC, big-endian for
MIPS); DEC floats are the VAX F format (:func:`_dec_floats`).
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.errors import C3dFormatError

BLOCK = 512
_PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}
_TYPES = {-1: "char", 1: "byte", 2: "int16", 4: "float32"}
_NAME_CHARS = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")
_MAX_DIMS = 7
_POINT_TEXT = (
    "X_SCREEN", "Y_SCREEN", "UNITS", "LABELS", "LABELS2", "LABELS3",
    "ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS",
)  # fmt: skip
_MAX_HEAD = 255 * BLOCK + 255 * BLOCK  # parameter section: from block <= 255, <= 255 blocks


@dataclass(frozen=True)
class C3dParameter:
    """One parameter as stored: ``type`` (-1 char, 1 byte, 2 int16, 4 float32), ``dims``
    (as written, first fastest; ``()`` for a scalar), ``offset`` (byte of its record in
    the file) and its values flattened (strings of a char array split along the first
    dimension, numbers as Python ints/floats)."""

    group: str
    name: str
    type: int
    dims: tuple[int, ...]
    offset: int
    values: tuple[object, ...]


@dataclass(frozen=True)
class C3dLayout:
    """What :func:`check_c3d` found: processor, header counts, parameters, data extent.

    ``n_frames`` is from the header (or ``TRIAL:ACTUAL_START_FIELD``/``ACTUAL_END_FIELD``
    when present); ``data_offset`` and ``frame_bytes`` are in bytes.
    """

    processor: str
    n_points: int
    n_analog_values: int
    analog_per_frame: int
    n_frames: int
    float_storage: bool
    data_offset: int
    frame_bytes: int
    parameters: dict[tuple[str, str], C3dParameter]

    def get(self, group: str, name: str) -> C3dParameter | None:
        """The parameter ``GROUP:NAME`` (upper case), or None."""
        return self.parameters.get((group, name))


def check_c3d(path: str | Path) -> C3dLayout:
    """Check that the header, parameter section and data section of a C3D file agree.

    Everything ezc3d relies on is checked: the section pointers stay inside the file,
    every group/parameter record stays inside the parameter section and links to the
    next one, names are plain ASCII, data types and dimension counts are those of the
    format, the parameters the reader needs exist with the right types and enough
    values (``POINT:USED``/``SCALE``/``DATA_START``/``LABELS``, ``ANALOG:USED``/
    ``SCALE``/``OFFSET``/``GEN_SCALE``/``LABELS``, the text parameters ``POINT:X_SCREEN``/
    ``Y_SCREEN``/``UNITS``/``ANGLES``/..., ``FORCE_PLATFORM:USED``/``TYPE``/
    ``CHANNEL``/``CORNERS``/``ORIGIN``/``CAL_MATRIX``) and agree with the header, plate
    channels name existing analog channels, and the file holds every frame it announces
    (``frames x (points x 4 + analog values) x word size`` bytes from the data start).

    Parameters
    ----------
    path
        The ``.c3d`` file.

    Returns
    -------
    C3dLayout
        The decoded header counts and parameters.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    C3dFormatError
        The first inconsistency found; ``where`` names the section (``header``,
        ``parameter section``, ``parameter section: GROUP:NAME``, ``parameter section:
        group NAME``, or ``frame N``, the first incomplete frame of a truncated data
        section) and the message the byte offset (from 0) and what was expected.

    Source: the C3D format specification (Motion Lab Systems, c3d.org).
    """
    path = Path(path)
    with path.open("rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        head = fh.read(_MAX_HEAD)  # header + the largest parameter section a file can point to
    return _Checker(path, head, size).run()


class _Checker:
    def __init__(self, path: Path, head: bytes, size: int) -> None:
        self.path = path
        self.data = head
        self.size = size
        self.endian = "<"
        self.dec = False

    # ------------------------------------------------------------------ helpers
    def fail(self, where: str, message: str) -> C3dFormatError:
        return C3dFormatError(message, path=self.path, where=where)

    def _floats(self, raw: bytes) -> list[float]:
        n = len(raw) // 4
        if self.dec:
            return _dec_floats(raw)
        return list(struct.unpack(f"{self.endian}{n}f", raw))

    # ------------------------------------------------------------------ header
    def run(self) -> C3dLayout:
        d = self.data
        if self.size < BLOCK:
            raise self.fail(
                "header",
                f"the file has {self.size} bytes; a C3D file starts with a 512-byte header "
                "block (ezc3d cannot read the file)",
            )
        if d[1] != 0x50:
            raise self.fail(
                "header",
                f"byte offset 1 is 0x{d[1]:02X}; a C3D header has the key 0x50 there "
                "(not a C3D file; ezc3d cannot read the file)",
            )
        p_block = d[0]
        p_start = (p_block - 1) * BLOCK
        if p_block < 2 or p_start + 4 > self.size:
            raise self.fail(
                "header",
                f"byte offset 0 points the parameter section to block {p_block}; expected a block "
                f"from 2 to {self.size // BLOCK} (the file has {self.size} bytes)",
            )
        processor = d[p_start + 3]
        if processor not in _PROCESSORS:
            raise self.fail(
                "parameter section",
                f"byte offset {p_start + 3} (processor type) is {processor}; expected 84 (Intel), "
                "85 (DEC) or 86 (MIPS)",
            )
        self.endian = ">" if processor == 86 else "<"
        self.dec = processor == 85
        e = self.endian
        n_points, n_analog, first, last, _gap = struct.unpack(e + "5H", d[2:12])
        (scale,) = self._floats(d[12:16])
        data_block, analog_per_frame = struct.unpack(e + "2H", d[16:20])
        if not math.isfinite(scale):
            raise self.fail("header", f"bytes 12-15 (scale factor) are {scale}; expected a number")
        if n_analog and (analog_per_frame == 0 or n_analog % analog_per_frame):
            raise self.fail(
                "header",
                f"bytes 4-5 give {n_analog} analog values per frame and bytes 18-19 "
                f"{analog_per_frame} samples per channel; expected a whole number of channels",
            )
        n_blocks = d[p_start + 2]
        p_end = p_start + n_blocks * BLOCK
        if n_blocks < 1 or p_end > self.size:
            raise self.fail(
                "parameter section",
                f"byte offset {p_start + 2} gives {n_blocks} parameter blocks from byte {p_start} "
                f"(to byte {p_end}); the file has {self.size} bytes",
            )
        params = self._parameters(p_start + 4, p_end)
        analogs = n_analog // analog_per_frame if n_analog else 0
        float_storage = scale < 0
        self._check_required(params, n_points, analogs, scale, data_block, p_start, p_end)
        if n_points or analogs:
            self._check_rates(params, self._floats(d[20:24])[0], analog_per_frame if analogs else 0)
        first, last = self._frame_range(params, first, last)
        n_frames = last - first + 1
        width = 4 if float_storage else 2
        frame_bytes = (n_points * 4 + n_analog) * width
        offset = (data_block - 1) * BLOCK
        if (n_points or analogs) and n_frames < 0:
            raise self.fail(
                "header",
                f"frames {first} to {last} (header bytes 6-9, or TRIAL:ACTUAL_START_FIELD/"
                "ACTUAL_END_FIELD when present); expected the last frame not before the first",
            )
        if (n_points or analogs) and n_frames > 0 and self.size < offset + n_frames * frame_bytes:
            complete = max(0, (self.size - offset) // frame_bytes)
            raise self.fail(
                f"frame {complete + 1}",
                f"the file is truncated: its header announces {n_frames} frames "
                f"({offset + n_frames * frame_bytes} bytes), the file has {self.size} bytes "
                f"({complete} complete frames); data section from byte {offset}, "
                f"{frame_bytes} bytes per frame",
            )
        return C3dLayout(
            processor=_PROCESSORS[processor],
            n_points=n_points,
            n_analog_values=n_analog,
            analog_per_frame=analog_per_frame,
            n_frames=max(n_frames, 0) if (n_points or analogs) else 0,
            float_storage=float_storage,
            data_offset=offset,
            frame_bytes=frame_bytes,
            parameters=params,
        )

    # ------------------------------------------------------------------ parameters
    def _parameters(self, pos: int, end: int) -> dict[tuple[str, str], C3dParameter]:
        d, e = self.data, self.endian
        groups: dict[int, str] = {}
        records: list[tuple[int, str, int, tuple[int, ...], int, bytes]] = []
        while True:
            if pos + 2 > end:
                raise self.fail(
                    "parameter section",
                    f"byte offset {pos}: the next group or parameter starts past the end of the "
                    f"section (byte {end}); expected a record or a zero name length",
                )
            (n_name, gid) = struct.unpack("bb", d[pos : pos + 2])
            if n_name == 0:
                break
            if gid == 0:
                raise self.fail(
                    "parameter section",
                    f"byte offset {pos + 1}: group id 0; expected a negative id (group) or a "
                    "positive one (parameter of that group)",
                )
            start = pos
            name_end = pos + 2 + abs(n_name)
            if name_end + 2 > end:
                raise self.fail(
                    "parameter section",
                    f"byte offset {pos}: a name of {abs(n_name)} characters runs past the end of "
                    f"the section (byte {end})",
                )
            raw_name = d[pos + 2 : name_end]
            if not all(c in _NAME_CHARS for c in raw_name):
                raise self.fail(
                    "parameter section",
                    f"byte offset {pos + 2}: name {raw_name!r} is not plain ASCII letters, digits "
                    "and underscores",
                )
            name = raw_name.decode("ascii")  # as stored: ezc3d looks names up as written
            (to_next,) = struct.unpack(e + "H", d[name_end : name_end + 2])
            nxt = name_end + to_next if to_next else 0
            body = name_end + 2
            label = (
                f"parameter section: group {name}"
                if gid < 0
                else (f"parameter section: {groups.get(gid, f'#{gid}')}:{name}")
            )
            if gid < 0:
                item_end = self._description(body, end, label)
                if -gid in groups:
                    raise self.fail(label, f"byte offset {start}: group id {-gid} defined twice")
                groups[-gid] = name
            else:
                if body + 2 > end:
                    raise self.fail(label, f"byte offset {body}: record runs past the section end")
                kind, n_dims = struct.unpack("bb", d[body : body + 2])
                if kind not in _TYPES:
                    raise self.fail(
                        label, f"byte offset {body}: data type {kind}; expected -1, 1, 2 or 4"
                    )
                if not 0 <= n_dims <= _MAX_DIMS:
                    raise self.fail(
                        label,
                        f"byte offset {body + 1}: number of dimensions {n_dims}; expected 0 to "
                        f"{_MAX_DIMS}",
                    )
                if kind == -1 and n_dims == 0:
                    raise self.fail(
                        label,
                        f"byte offset {body + 1}: a character parameter with no dimension; expected "
                        "at least its string length",
                    )
                dims_end = body + 2 + n_dims
                if dims_end > end:
                    raise self.fail(
                        label, f"byte offset {body + 2}: dimensions run past the section"
                    )
                dims = tuple(d[body + 2 : dims_end])
                count = math.prod(dims) if dims else 1
                values_end = dims_end + count * abs(kind)
                if values_end + 1 > end:
                    raise self.fail(
                        label,
                        f"byte offset {dims_end}: {count} values of {abs(kind)} bytes (dimensions "
                        f"{list(dims)}) run past the end of the section (byte {end})",
                    )
                item_end = self._description(values_end, end, label)
                records.append((gid, name, kind, dims, start, d[dims_end:values_end]))
            if nxt and not item_end <= nxt <= end:
                raise self.fail(
                    label,
                    f"byte offset {name_end}: offset to the next record {to_next} points to byte "
                    f"{nxt}; expected from byte {item_end} (end of this record) to the end "
                    f"of the section (byte {end})",
                )
            if not nxt:
                break
            pos = nxt
        params: dict[tuple[str, str], C3dParameter] = {}
        for gid, name, kind, dims, start, raw in records:
            if gid not in groups:
                raise self.fail(
                    f"parameter section: #{gid}:{name}",
                    f"byte offset {start + 1}: the parameter belongs to group id {gid}, which the "
                    "section does not define",
                )
            group = groups[gid]
            params[(group, name)] = C3dParameter(
                group, name, kind, dims, start, self._values(kind, dims, raw)
            )
        return params

    def _description(self, pos: int, end: int, label: str) -> int:
        if pos + 1 > end:
            raise self.fail(label, f"byte offset {pos}: description length past the section end")
        (n,) = struct.unpack("b", self.data[pos : pos + 1])
        if n < 0 or pos + 1 + n > end:
            raise self.fail(
                label,
                f"byte offset {pos}: description length {n}; expected 0 to 127 characters inside "
                f"the section (ends at byte {end})",
            )
        return pos + 1 + n

    def _values(self, kind: int, dims: tuple[int, ...], raw: bytes) -> tuple[object, ...]:
        if kind == -1:
            width = dims[0]
            if width == 0:
                return ()
            text = raw.decode("latin-1")
            return tuple(text[i : i + width].rstrip() for i in range(0, len(text), width))
        if kind == 1:
            return tuple(struct.unpack(f"{len(raw)}b", raw))
        if kind == 2:
            return tuple(struct.unpack(f"{self.endian}{len(raw) // 2}h", raw))
        return tuple(self._floats(raw))

    # ------------------------------------------------------------------ required content
    def _param(
        self,
        params: dict[tuple[str, str], C3dParameter],
        group: str,
        name: str,
        types: tuple[int, ...],
        min_count: int,
        *,
        required: bool = True,
    ) -> C3dParameter | None:
        p = params.get((group, name))
        label = f"parameter section: {group}:{name}"
        if p is None:
            if required:
                raise self.fail(
                    "parameter section",
                    f"{group}:{name} is missing; expected it for the header's counts",
                )
            return None
        if p.type not in types:
            raise self.fail(
                label,
                f"byte offset {p.offset}: data type {_TYPES[p.type]}; expected "
                + " or ".join(_TYPES[t] for t in types),
            )
        if len(p.values) < min_count:
            raise self.fail(
                label,
                f"byte offset {p.offset}: {len(p.values)} values (dimensions {list(p.dims)}); "
                f"expected at least {min_count}",
            )
        return p

    def _check_required(
        self,
        params: dict[tuple[str, str], C3dParameter],
        n_points: int,
        analogs: int,
        scale: float,
        data_block: int,
        p_start: int,
        p_end: int,
    ) -> None:
        integer = (1, 2)
        used = self._param(params, "POINT", "USED", integer, 1)
        assert used is not None
        if int(used.values[0]) % 65536 != n_points:
            raise self.fail(
                "parameter section: POINT:USED",
                f"byte offset {used.offset}: {used.values[0]} points; the header (bytes 2-3) "
                f"says {n_points}",
            )
        start = self._param(params, "POINT", "DATA_START", integer, 1)
        assert start is not None
        if int(start.values[0]) % 65536 != data_block:
            raise self.fail(
                "parameter section: POINT:DATA_START",
                f"byte offset {start.offset}: block {start.values[0]}; the header (bytes 16-17) "
                f"says block {data_block}",
            )
        if (data_block - 1) * BLOCK < p_end:
            raise self.fail(
                "header",
                f"bytes 16-17: the data section starts at block {data_block} (byte "
                f"{(data_block - 1) * BLOCK}), inside the parameter section (bytes "
                f"{p_start}-{p_end}); expected a block after it",
            )
        self._param(params, "POINT", "FRAMES", (1, 2, 4), 1, required=False)
        for name in _POINT_TEXT:  # read as text (axes, units, labels, model outputs)
            self._param(params, "POINT", name, (-1,), 0, required=False)
        self._param(params, "POINT", "RATE", (4,), 1, required=False)
        if n_points:
            point_scale = self._param(params, "POINT", "SCALE", (4,), 1)
            assert point_scale is not None
            value = float(point_scale.values[0])  # type: ignore[arg-type]
            if not math.isfinite(value) or (value < 0) != (scale < 0):
                raise self.fail(
                    "parameter section: POINT:SCALE",
                    f"byte offset {point_scale.offset}: {value}; the header scale factor (bytes "
                    f"12-15) is {scale}, expected a finite number of the same sign",
                )
            self._labels(params, "POINT", n_points)
        a_used = self._param(params, "ANALOG", "USED", integer, 1, required=analogs > 0)
        if a_used is not None and int(a_used.values[0]) % 65536 != analogs:
            raise self.fail(
                "parameter section: ANALOG:USED",
                f"byte offset {a_used.offset}: {a_used.values[0]} channels; the header (bytes 4-5 "
                f"over bytes 18-19) gives {analogs}",
            )
        if ("ANALOG", "GEN_SCALE") in params or analogs:
            self._param(params, "ANALOG", "GEN_SCALE", (4,), 1)
        if analogs:
            self._param(params, "ANALOG", "SCALE", (4,), analogs)
            self._param(params, "ANALOG", "OFFSET", integer, analogs)
            self._labels(params, "ANALOG", analogs)
            self._param(params, "ANALOG", "RATE", (4,), 1, required=False)
        self._check_plates(params, analogs)

    def _check_rates(self, params: dict[tuple[str, str], C3dParameter], header_rate: float, analog_per_frame: int) -> None:
        """The frame rate (POINT:RATE, else the header's bytes 20-23) is a positive number of
        Hz, and ANALOG:RATE, when present, is the header's analog samples per frame (bytes
        18-19) times it: C3D readers take the samples per frame from the two rates, so a
        disagreement reads every analog and point value with the wrong stride."""
        point_rate = params.get(("POINT", "RATE"))
        rate = float(point_rate.values[0]) if point_rate is not None else header_rate  # type: ignore[arg-type]
        where = "parameter section: POINT:RATE" if point_rate is not None else "header"
        at = f"byte offset {point_rate.offset}" if point_rate is not None else "bytes 20-23 (frame rate)"
        if not (math.isfinite(rate) and rate > 0):
            raise self.fail(where, f"{at}: a frame rate of {rate:g} Hz; expected a positive number")
        analog_rate = params.get(("ANALOG", "RATE"))
        if analog_per_frame and analog_rate is not None:
            hz = float(analog_rate.values[0])  # type: ignore[arg-type]
            if not (math.isfinite(hz) and math.isclose(hz, analog_per_frame * rate, rel_tol=1e-4)):
                raise self.fail(
                    "parameter section: ANALOG:RATE",
                    f"byte offset {analog_rate.offset}: {hz:g} Hz, {hz / rate:g} samples per frame at {rate:g} Hz; "
                    f"the header (bytes 18-19) gives {analog_per_frame} samples per frame ({analog_per_frame * rate:g} Hz)",
                )

    def _labels(self, params: dict[tuple[str, str], C3dParameter], group: str, n: int) -> None:
        count = 0
        for key in ("LABELS", "LABELS2", "LABELS3", "LABELS4"):
            p = self._param(params, group, key, (-1,), 0, required=key == "LABELS")
            count += len(p.values) if p is not None else 0
        if count < n:
            raise self.fail(
                f"parameter section: {group}:LABELS",
                f"{count} labels for {n} {'points' if group == 'POINT' else 'channels'}; "
                "expected one each",
            )

    def _check_plates(self, params: dict[tuple[str, str], C3dParameter], analogs: int) -> None:
        used = self._param(params, "FORCE_PLATFORM", "USED", (1, 2), 1, required=False)
        if used is None:
            return
        n = int(used.values[0])
        if n < 0 or n > 64:
            raise self.fail(
                "parameter section: FORCE_PLATFORM:USED",
                f"byte offset {used.offset}: {n} platforms; expected 0 to 64",
            )
        if n == 0:
            return
        types = self._param(params, "FORCE_PLATFORM", "TYPE", (1, 2), n)
        assert types is not None
        channel = self._param(params, "FORCE_PLATFORM", "CHANNEL", (1, 2), 0)
        assert channel is not None
        need = max(8 if t == 3 else 6 for t in types.values[:n])  # type: ignore[operator]
        if len(channel.dims) != 2 or channel.dims[0] < need or channel.dims[1] < n:
            raise self.fail(
                "parameter section: FORCE_PLATFORM:CHANNEL",
                f"byte offset {channel.offset}: dimensions {list(channel.dims)}; expected "
                f"[{need} or more, {n} or more] (channels x platforms)",
            )
        rows = channel.dims[0]
        for k in range(n):
            for i, c in enumerate(channel.values[k * rows : (k + 1) * rows]):
                if not 1 <= int(c) <= analogs:  # type: ignore[call-overload]
                    raise self.fail(
                        "parameter section: FORCE_PLATFORM:CHANNEL",
                        f"byte offset {channel.offset}: platform {k + 1} channel {i + 1} is analog "
                        f"{c}; expected 1 to {analogs} (ANALOG:USED)",
                    )
        shapes = {"CORNERS": (3, 4), "ORIGIN": (3,)}
        for name, lead in shapes.items():
            p = self._param(params, "FORCE_PLATFORM", name, (4,), 0)
            assert p is not None
            want = (*lead, n)
            if len(p.dims) != len(want) or p.dims[:-1] != lead or p.dims[-1] < n:
                raise self.fail(
                    f"parameter section: FORCE_PLATFORM:{name}",
                    f"byte offset {p.offset}: dimensions {list(p.dims)}; expected "
                    f"{[*lead, f'{n} or more']}",
                )
            if not np.isfinite(np.asarray(p.values, dtype=np.float64)).all():
                raise self.fail(
                    f"parameter section: FORCE_PLATFORM:{name}",
                    f"byte offset {p.offset}: a value is not a finite number",
                )
        cal = self._param(
            params,
            "FORCE_PLATFORM",
            "CAL_MATRIX",
            (4,),
            0,
            required=any(t in (4, 7) for t in types.values[:n]),  # type: ignore[operator]
        )
        if (
            cal is not None
            and cal.values
            and (len(cal.dims) != 3 or cal.dims[0] != cal.dims[1] or cal.dims[2] < n)
        ):
            raise self.fail(
                "parameter section: FORCE_PLATFORM:CAL_MATRIX",
                f"byte offset {cal.offset}: dimensions {list(cal.dims)}; expected [c, c, "
                f"{n} or more] (a square matrix per platform)",
            )

    def _frame_range(
        self, params: dict[tuple[str, str], C3dParameter], first: int, last: int
    ) -> tuple[int, int]:
        start = params.get(("TRIAL", "ACTUAL_START_FIELD"))
        end = params.get(("TRIAL", "ACTUAL_END_FIELD"))
        if (
            start is not None
            and end is not None
            and start.type in (1, 2)
            and end.type in (1, 2)
            and len(start.values) == 2
            and len(end.values) == 2
        ):
            first = int(start.values[0]) % 65536 + 65536 * (int(start.values[1]) % 65536)  # type: ignore[call-overload]
            last = int(end.values[0]) % 65536 + 65536 * (int(end.values[1]) % 65536)  # type: ignore[call-overload]
        return first, last


def _dec_floats(raw: bytes) -> list[float]:
    """VAX/DEC F floats (pairs of little-endian 16-bit words, high word first, exponent
    bias 128 rather than IEEE's 127 with the hidden bit below the point) as Python
    floats: swap the words and divide by 4."""
    out = []
    for i in range(0, len(raw) - 3, 4):
        b = raw[i : i + 4]
        (v,) = struct.unpack("<f", bytes((b[2], b[3], b[0], b[1])))
        out.append(v / 4.0)
    return out
