"""C3D files (markers and force platforms) through ezc3d, into the OpenSim lab frame.

**Axes.** C3D labs are usually Z up; OpenSim is Y up. The rotation ``R`` (a proper
rotation, ``det R = +1``) maps lab coordinates to OpenSim ones, ``p_osim = R @ p_lab``:
OpenSim Y is the lab's up axis, OpenSim X is the lab's screen-right axis
(``POINT:X_SCREEN``) and OpenSim Z = X x Y. The up axis is ``up_axis`` when given,
else ``POINT:Y_SCREEN``, else +Z. For the common ``X_SCREEN=+X, Y_SCREEN=+Z`` this is
``(x, y, z)_lab -> (x, z, -y)``.

**Force platforms.** ezc3d's platform module (``extract_forceplat_data=True``) applies
the analog scales, the calibration matrix, the plate type (2, 3, 4) and the plate
corners, and gives per analog sample the force and the moment about the centre of the
plate surface (mean of ``FORCE_PLATFORM:CORNERS``) in the lab frame. Its own CoP
divides by the vertical force on every sample, which is noise on unloaded plates, so
it is not used. This module:

1. averages force and moment over the analog samples of each marker frame (a boxcar
   of ``ANALOG:RATE / POINT:RATE`` samples: the wrench is linear, so averaging it is
   exact, unlike averaging a CoP; the average is centred half a frame after the frame
   time minus half an analog sample, 1.75 ms at 250/2000 Hz);
2. rotates into the OpenSim frame and converts to N, m, N·m;
3. computes the CoP on the plate plane (normal ``n``, centre ``c``) from
   ``cop = c + (n x M) / (n . F)`` and the free moment ``M - (cop - c) x F``, which is
   along ``n``. Where ``n . F`` is below ``cop_threshold_n`` the CoP is set to the
   plate centre and the free moment is the whole moment about it (the wrench is
   unchanged, only its split differs).

The plate force is taken as the ground reaction on the body when its largest vertical
value is positive; a plate that reports the force *on the plate* (largest magnitude
negative) is negated and a :class:`UserWarning` says so. No zero-offset correction is
applied (``FORCE_PLATFORM:ZERO`` is ignored): unloaded plates keep their offset.

**Damaged files.** ezc3d trusts the counts and offsets in a file and can die of a
segmentation fault on a damaged one, so :func:`read_c3d` first checks the header,
parameter section and data extent in pure Python
(:func:`solver.io.c3d_layout.check_c3d`, about 0.3 ms) and raises
:class:`~solver.errors.C3dFormatError` naming the section and byte offset.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.errors import C3dFormatError
from solver.io.c3d_layout import check_c3d
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories

FloatArray = NDArray[np.float64]

_LENGTH = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "meters": 1.0}
_FORCE = {"n": 1.0}
_MOMENT = {"nmm": 1e-3, "n.mm": 1e-3, "nm": 1.0, "n.m": 1.0}
_AXES = {"x": 0, "y": 1, "z": 2}
_NOT_MARKERS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")


def read_c3d(
    path: str | Path, *, up_axis: str | None = None, cop_threshold_n: float = 20.0
) -> tuple[MarkerTrajectories, ForceRecording | None]:
    """Read markers and force platforms of a C3D file, in the OpenSim (Y up) frame.

    Parameters
    ----------
    path
        The ``.c3d`` file.
    up_axis
        The lab's up axis, ``"+z"``, ``"z"``, ``"-y"``, ...; None: from
        ``POINT:Y_SCREEN``, else +Z (see module docstring).
    cop_threshold_n
        Vertical force, N, below which a plate counts as unloaded (CoP at the plate
        centre).

    Returns
    -------
    markers : MarkerTrajectories
        ``(T, M, 3)`` m, Y up, NaN where ezc3d marks a marker invalid (negative
        residual). Model outputs listed in ``POINT:ANGLES``/``FORCES``/... are dropped.
    forces : ForceRecording or None
        At the marker rate and times: per plate (named "1", "2", ...) ``force``
        ``(T, 3)`` N on the body, ``cop`` ``(T, 3)`` m, ``free_moment`` ``(T, 3)`` N·m,
        ``corners`` ``(4, 3)`` m, all Y up. None when the file has no platforms.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    C3dFormatError
        the header, parameter section or data section is damaged or inconsistent
        (:func:`solver.io.c3d_layout.check_c3d`: the section, byte offset and what was
        expected; a truncated file names the first incomplete frame), ezc3d cannot
        read the file, unknown or missing ``POINT:UNITS`` or platform
        units, an invalid up axis, analog samples that are not a whole number per
        frame, or an unsupported platform type.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "No such file", str(path))
    check_c3d(path)  # a damaged layout gives our error before ezc3d can crash on it
    c3d = _open(path)
    params = c3d["parameters"]
    rot = rotation_to_opensim(params, up_axis=up_axis, path=path)
    markers = _markers(c3d, rot, path)
    forces = _forces(c3d, rot, markers, cop_threshold_n, path)
    return markers, forces


def _open(path: Path) -> Any:
    import ezc3d  # heavy import kept local

    try:
        return ezc3d.c3d(str(path), extract_forceplat_data=True)
    except Exception as exc:  # noqa: BLE001 (ezc3d raises plain RuntimeError/ValueError on bad files)
        try:
            ezc3d.c3d(str(path))
        except Exception:  # noqa: BLE001 (any failure of the plain read: the file is not a C3D)
            raise C3dFormatError(f"ezc3d cannot read the file: {exc}", path=path) from None
        raise C3dFormatError(
            f"the force platforms cannot be processed: {exc}", path=path, where="FORCE_PLATFORM"
        ) from None


def _param(params: dict[str, Any], group: str, name: str) -> Any:
    try:
        return params[group][name]["value"]
    except (KeyError, TypeError):
        return None


def _axis(text: str, path: Path, where: str) -> NDArray[np.float64]:
    """Unit vector of an axis text such as ``+Z``, ``-y``, ``x``."""
    t = text.strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    if t not in _AXES:
        raise C3dFormatError(
            f"axis {text!r}; expected one of +x, -x, +y, -y, +z, -z", path=path, where=where
        )
    v = np.zeros(3)
    v[_AXES[t]] = sign
    return v


def rotation_to_opensim(
    params: dict[str, Any], *, up_axis: str | None = None, path: str | Path = ""
) -> FloatArray:
    """``(3, 3)`` rotation ``R`` with ``p_osim = R @ p_lab`` (see module docstring)."""
    path = Path(path)
    x_screen = _param(params, "POINT", "X_SCREEN")
    y_screen = _param(params, "POINT", "Y_SCREEN")
    if up_axis is not None:
        up = _axis(up_axis, path, "up_axis")
    elif y_screen:
        up = _axis(str(y_screen[0]), path, "POINT:Y_SCREEN")
    else:
        up = np.array([0.0, 0.0, 1.0])
    forward = _axis(str(x_screen[0]), path, "POINT:X_SCREEN") if x_screen else None
    if forward is None or abs(forward @ up) > 0.5:
        forward = next(e for e in np.eye(3) if abs(e @ up) < 0.5)
    side = np.cross(forward, up)
    rot = np.stack([forward, up, side])
    return rot  # rows orthonormal, side = forward x up: det +1


def _scale(units: str | None, table: dict[str, float], what: str, path: Path) -> float:
    key = (units or "").strip().lower()
    if key not in table:
        raise C3dFormatError(
            f"unknown {what} unit {units!r}; expected one of {', '.join(table)}",
            path=path,
            where=what,
        )
    return table[key]


def _markers(c3d: Any, rot: FloatArray, path: Path) -> MarkerTrajectories:
    params = c3d["parameters"]
    units = _param(params, "POINT", "UNITS")
    scale = _scale(units[0] if units else None, _LENGTH, "POINT:UNITS", path)
    points = np.asarray(c3d["data"]["points"], dtype=np.float64)[:3]  # (3, M, T)
    labels = [str(s).strip() for s in (_param(params, "POINT", "LABELS") or [])]
    for extra in ("LABELS2", "LABELS3"):
        labels += [str(s).strip() for s in (_param(params, "POINT", extra) or [])]
    n_points = points.shape[1]
    if len(labels) < n_points:
        raise C3dFormatError(
            f"{n_points} points but only {len(labels)} POINT:LABELS",
            path=path,
            where="POINT:LABELS",
        )
    labels = labels[:n_points]
    skip = {str(s).strip() for g in _NOT_MARKERS for s in (_param(params, "POINT", g) or [])}
    keep = [i for i, name in enumerate(labels) if name not in skip]
    names = [labels[i] for i in keep]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise C3dFormatError(f"marker {dup!r} appears twice", path=path, where="POINT:LABELS")
    xyz = np.einsum("ij,jmt->tmi", rot, points[:, keep, :]) * scale
    rate = float(c3d["header"]["points"]["frame_rate"])
    first = int(c3d["header"]["points"]["first_frame"])
    time = (first + np.arange(xyz.shape[0])) / rate
    return MarkerTrajectories(tuple(names), xyz, time, rate, source=str(path))


def _forces(
    c3d: Any, rot: FloatArray, markers: MarkerTrajectories, threshold: float, path: Path
) -> ForceRecording | None:
    platforms = c3d["data"].get("platform") or []
    if not platforms:
        return None
    n_frames = markers.n_frames
    plates = []
    for k, pf in enumerate(platforms, start=1):
        f_scale = _scale(str(pf["unit_force"]), _FORCE, "force platform force", path)
        m_scale = _scale(str(pf["unit_moment"]), _MOMENT, "force platform moment", path)
        l_scale = _scale(str(pf["unit_position"]), _LENGTH, "force platform position", path)
        force = _per_frame(np.asarray(pf["force"], dtype=np.float64), n_frames, path)
        moment = _per_frame(np.asarray(pf["moment"], dtype=np.float64), n_frames, path)
        corners = (rot @ np.asarray(pf["corners"], dtype=np.float64)).T * l_scale  # (4, 3)
        force = force @ rot.T * f_scale
        moment = moment @ rot.T * m_scale
        plates.append(_plate(str(k), force, moment, corners, threshold, path))
    return ForceRecording(markers.time, markers.rate_hz, tuple(plates), source=str(path))


def _per_frame(samples: FloatArray, n_frames: int, path: Path) -> FloatArray:
    """``(3, N*n)`` analog-rate samples -> ``(n_frames, 3)`` mean of each frame's samples."""
    total = samples.shape[1]
    if n_frames == 0 or total % n_frames:
        raise C3dFormatError(
            f"{total} analog samples do not divide into {n_frames} frames",
            path=path,
            where="ANALOG:RATE",
        )
    per = total // n_frames
    return samples.reshape(3, n_frames, per).mean(axis=2).T


def _plate(
    name: str,
    force: FloatArray,
    moment: FloatArray,
    corners: FloatArray,
    threshold: float,
    path: Path,
) -> ForcePlate:
    """CoP and free moment from the wrench about the plate centre (module docstring)."""
    centre = corners.mean(axis=0)
    normal = np.cross(corners[2] - corners[0], corners[3] - corners[1])
    if np.linalg.norm(normal) == 0:
        raise C3dFormatError(
            f"plate {name} corners do not span a plane", path=path, where="FORCE_PLATFORM:CORNERS"
        )
    normal /= np.linalg.norm(normal)
    if normal[1] < 0:
        normal = -normal
    normal_force = force @ normal
    if normal_force.size and -normal_force.min() > max(normal_force.max(), threshold):
        warnings.warn(
            f"{path}: plate {name} reports the force applied to the plate (vertical force "
            "negative when loaded); negated to the ground reaction force on the body",
            UserWarning,
            stacklevel=4,
        )
        force, moment, normal_force = -force, -moment, -normal_force
    loaded = normal_force > threshold
    lever = np.zeros_like(force)
    lever[loaded] = np.cross(normal, moment[loaded]) / normal_force[loaded, None]
    cop = centre + lever
    free = moment - np.cross(lever, force)
    return ForcePlate(name, force, cop, free, corners)
