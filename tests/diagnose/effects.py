"""Hidden effects for the diagnosis tests and benchmark: each changes the raw files of a
subject copy the way its cause would (seeded magnitudes in realistic ranges), and the
neutral starting point they are hidden in.

Conventions (what each cause's parameter means, as :mod:`solver.diagnose` reports it):

* ``force_time_offset``: the force file's time column + delay (forces recorded late);
* ``body_mass``: ``massKg`` - change (the true mass is the stated one + change);
* ``plate_force_offset``: force + offset on every sample, acting at the plate's centre
  (median loaded CoP): the moment about that point as recorded, the centre of pressure and
  free moment derived again (:func:`solver.corrections.offset_plate`; where the
  plate is unloaded the centre of pressure is its centre);
* ``plate_force_gain``: force and free moment x gain;
* ``plate_position_offset``: centre of pressure + a horizontal shift;
* ``marker_offset``: a landmark (``fixed``) marker's recorded positions + R_body(t) shift,
  with the body orientations of the unmodified processed trial;
* ``segment_mass_distribution``: the generic model's trunk bodies lose (or gain) mass
  that the leg bodies gain, total kept;
* ``unmeasured_force``: one stance of one plate erased (all its columns zero); the share of
  it missed counts only its frames the base does not already leave out (its own steps off
  the plates, saved as extensions);
* ``plate_registration``: every plate's readings moved rigidly
  (:func:`solver.corrections.register_plates`): turned about the vertical through the
  plates' common centre (the mean of :func:`solver.diagnose.data.plate_centre`, as the
  diagnosis takes it), then shifted in the floor plane.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver.corrections import offset_plate, register_plates
from solver.diagnose.data import plate_centre, wxyz_to_matrix
from solver.io.mot import read_forces, write_forces
from solver.io.trc import read_trc, write_trc
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories
from solver.results import ProcessedTrial

CAUSES = (
    "force_time_offset",
    "body_mass",
    "plate_force_offset",
    "plate_force_gain",
    "plate_position_offset",
    "marker_offset",
    "segment_mass_distribution",
    "unmeasured_force",
    "plate_registration",
)

#: Tolerances of the hidden-effect tests (parameter error relative to the unmodified
#: trial's own estimate).
TOLERANCE = {
    "force_time_offset": 0.005,  # s
    "body_mass": 1.0,  # kg
    "plate_force_offset": 10.0,  # N
    "plate_force_gain": 0.01,  # relative
    "plate_position_offset": 0.005,  # m
    "marker_offset": 0.005,  # m
    "segment_mass_distribution": 2.0,  # kg moved to the legs
    "unmeasured_force": 0.2,  # 1 - overlap of the found frames with the erased ones
    "plate_registration": 0.005,  # m: |(sx, sz, ρφ)| error, ρ the reported radius (:func:`error`)
}


@dataclass
class Hidden:
    """One hidden effect: cause, what it concerns (plate or marker), true parameters."""

    cause: str
    choice: str | None
    truth: dict[str, Any] = field(default_factory=dict)


def copy_subject(src: Path, dst: Path, trials: tuple[str, ...] | None = None) -> Path:
    """Copy a subject folder (only ``trials`` when given, never ``addb_out``), writable."""
    dst.mkdir(parents=True)
    for item in src.iterdir():
        if item.name in ("addb_out",) or item.name.endswith(".lock"):
            continue
        if item.name == "trials":
            (dst / "trials").mkdir()
            for t in item.iterdir():
                if trials is None or t.name in trials:
                    shutil.copytree(t, dst / "trials" / t.name)
        elif item.is_dir():
            shutil.copytree(item, dst / item.name)
        else:
            shutil.copy2(item, dst / item.name)
    for p in dst.rglob("*"):
        p.chmod(0o644 if p.is_file() else 0o755)
    dst.chmod(0o755)
    return dst


def _forces_path(subject: Path, trial: str) -> Path:
    return subject / "trials" / trial / "grf.mot"


def _edit_forces(subject: Path, trial: str, fn: Any) -> None:
    path = _forces_path(subject, trial)
    write_forces(path, fn(read_forces(path)))


def _map_plate(rec: ForceRecording, name: str, fn: Any) -> ForceRecording:
    return ForceRecording(rec.time, rec.rate_hz, tuple(fn(p) if p.name == name else p for p in rec.plates), rec.source)


def stated_mass(subject: Path) -> float:
    """``massKg`` of a subject folder."""
    return float(json.loads((subject / "_subject.json").read_text())["massKg"])


def loaded_plates(subject: Path, trial: str, min_bw: float = 0.2) -> list[str]:
    """Plates of a trial that carry more than ``min_bw`` body weights at some sample."""
    rec = read_forces(_forces_path(subject, trial))
    bw = 9.80665 * stated_mass(subject)
    return [p.name for p in rec.plates if np.nanmax(p.force[:, 1]) > min_bw * bw]


def _random_direction(rng: np.random.Generator, horizontal: bool = False) -> np.ndarray:
    v = rng.normal(size=3)
    if horizontal:
        v[1] = 0.0
    return v / np.linalg.norm(v)


# --------------------------------------------------------------------------- effects


def hide_time_offset(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    delay = float(rng.uniform(0.010, 0.060) * rng.choice([-1.0, 1.0]))
    _edit_forces(subject, trial, lambda r: ForceRecording(np.asarray(r.time) + delay, r.rate_hz, r.plates, r.source))
    return Hidden("force_time_offset", None, {"delay_s": delay})


def hide_body_mass(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    change = float(rng.uniform(2.0, 10.0) * rng.choice([-1.0, 1.0]))
    path = subject / "_subject.json"
    data = json.loads(path.read_text())
    data["massKg"] = float(data["massKg"]) - change
    path.write_text(json.dumps(data, indent=2))
    return Hidden("body_mass", None, {"mass_change_kg": change})


def hide_plate_offset(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    plate = str(rng.choice(loaded_plates(subject, trial)))
    offset = _random_direction(rng) * rng.uniform(20.0, 80.0)
    bw = 9.80665 * stated_mass(subject)

    def fn(p: ForcePlate) -> ForcePlate:
        # a drift of the force channels: the plate's moment about its centre stays, the
        # exported centre of pressure follows the drifted force
        centre = plate_centre(p, bw)
        cop = np.array(p.cop)
        cop[np.linalg.norm(np.asarray(p.force), axis=1) < 1.0] = centre
        return offset_plate(ForcePlate(p.name, p.force, cop, p.free_moment, p.corners), offset, centre)

    _edit_forces(subject, trial, lambda r: _map_plate(r, plate, fn))
    return Hidden("plate_force_offset", plate, {"offset_N": offset.tolist()})


def hide_plate_gain(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    plate = str(rng.choice(loaded_plates(subject, trial)))
    gain = float(1.0 + rng.uniform(0.02, 0.08) * rng.choice([-1.0, 1.0]))
    _edit_forces(subject, trial, lambda r: _map_plate(r, plate, lambda p: ForcePlate(p.name, np.asarray(p.force) * gain, p.cop, np.asarray(p.free_moment) * gain, p.corners)))
    return Hidden("plate_force_gain", plate, {"gain": gain})


def hide_plate_shift(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    plate = str(rng.choice(loaded_plates(subject, trial)))
    shift = _random_direction(rng, horizontal=True) * rng.uniform(0.01, 0.04)
    _edit_forces(subject, trial, lambda r: _map_plate(r, plate, lambda p: ForcePlate(p.name, p.force, np.asarray(p.cop) + shift, p.free_moment, p.corners)))
    return Hidden("plate_position_offset", plate, {"shift_m": shift.tolist()})


def plates_centre(subject: Path, trial: str) -> np.ndarray:
    """``(3,)`` the plates' common centre of a trial, m: the mean of each plate's
    :func:`solver.diagnose.data.plate_centre` (the pivot of ``plate_registration``)."""
    rec = read_forces(_forces_path(subject, trial))
    bw = 9.80665 * stated_mass(subject)
    return np.mean([plate_centre(p, bw) for p in rec.plates], axis=0)


def hide_registration(
    subject: Path, trial: str, shift: np.ndarray, rotation: float = 0.0, plates: tuple[str, ...] | None = None
) -> np.ndarray:
    """Move the readings of ``plates`` (default: every plate) rigidly: turned by ``rotation``
    rad about the vertical through the plates' common centre, then shifted by ``shift`` (3,)
    m (:func:`solver.corrections.register_plates`); returns that centre."""
    centre = plates_centre(subject, trial)

    def fn(r: ForceRecording) -> ForceRecording:
        moved = {p.name: p for p in register_plates(r, shift, rotation, centre).plates}
        return ForceRecording(r.time, r.rate_hz, tuple(moved[p.name] if plates is None or p.name in plates else p for p in r.plates), r.source)

    _edit_forces(subject, trial, fn)
    return centre


def hide_plate_registration(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    """Every plate misregistered alike: a 1-3 cm shift in the floor plane and a 0.5-2 degree
    turn about the vertical (either sign) through the plates' common centre."""
    shift = _random_direction(rng, horizontal=True) * rng.uniform(0.01, 0.03)
    rotation = float(np.radians(rng.uniform(0.5, 2.0)) * rng.choice([-1.0, 1.0]))
    centre = hide_registration(subject, trial, shift, rotation)
    return Hidden("plate_registration", None, {"shift_m": shift.tolist(), "rotation_rad": rotation, "centre_m": centre.tolist()})


def fixed_markers(subject: Path) -> list[tuple[str, str]]:
    """(marker, body) of the subject's generic model's ``fixed`` (landmark) markers."""
    from solver.model.osim import read_osim

    return [(m.name, m.body) for m in read_osim(subject / "unscaled_generic.osim").markers if m.fixed]


def landmark_markers(subject: Path, processed: ProcessedTrial, min_seen: float = 0.9) -> list[tuple[str, str]]:
    """(marker, body) of the generic model's ``fixed`` markers seen on most frames of the trial."""
    seen = np.isfinite(processed.observed).all(axis=2).mean(axis=0)
    names = list(processed.marker_names)
    return [(m, b) for m, b in fixed_markers(subject) if m in names and seen[names.index(m)] >= min_seen]


def hide_marker_offset(subject: Path, trial: str, rng: np.random.Generator, processed: ProcessedTrial) -> Hidden:
    landmarks = landmark_markers(subject, processed)
    marker, body = landmarks[int(rng.integers(len(landmarks)))]
    shift = _random_direction(rng) * rng.uniform(0.01, 0.03)
    path = subject / "trials" / trial / "markers.trc"
    mk = read_trc(path)
    rot = wxyz_to_matrix(processed.body_wxyz[:, processed.body_names.index(body)])  # (T, 3, 3)
    idx = np.clip(np.searchsorted(processed.time, mk.time), 0, processed.n_frames - 1)
    pos = np.array(mk.positions)
    j = mk.names.index(marker)
    pos[:, j] += np.einsum("tij,j->ti", rot[idx], shift)
    write_trc(path, MarkerTrajectories(mk.names, pos, mk.time, mk.rate_hz, mk.source))
    return Hidden("marker_offset", marker, {"shift_m": shift.tolist(), "body": body})


def hide_segment_mass(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    """Move mass between the trunk group and the legs in the generic model (total kept)."""
    from solver.corrections import extend_subject
    from solver.diagnose.data import group_masses
    from solver.diagnose.refit import redistribute
    from solver.io.subject import load_subject
    from solver.model.osim import read_osim
    from solver.model.osim_writer import write_osim

    # the subject's current model: the generic one, or a redistribution the base applied
    path = extend_subject(load_subject(subject)).model_path
    model = read_osim(path)
    total = sum(b.mass for b in model.bodies)
    fraction = float(rng.uniform(0.04, 0.10) * rng.choice([-1.0, 1.0]))  # of the body mass, to the legs
    moved = fraction * total
    write_osim(redistribute(model, {"legs": moved, "trunk": -moved}), path)
    groups = group_masses(model)
    return Hidden("segment_mass_distribution", None, {"legs_fraction": fraction, "legs_kg_generic": moved, "legs_share": groups["legs"] / total})


def hide_unmeasured(subject: Path, trial: str, rng: np.random.Generator) -> Hidden:
    """Erase one whole stance of one plate (a step on uninstrumented ground)."""
    rec = read_forces(_forces_path(subject, trial))
    bw = 9.80665 * stated_mass(subject)
    steps = []
    for p in rec.plates:
        f = np.asarray(p.force)[:, 1]
        on = f > 1.0
        edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            margin = int(0.1 * rec.rate_hz)
            if a > margin and b < f.size - margin and f[a:b].max() > 0.5 * bw and (b - a) / rec.rate_hz > 0.1:
                steps.append((p.name, int(a), int(b)))
    plate, a, b = steps[int(rng.integers(len(steps)))]

    def fn(p: ForcePlate) -> ForcePlate:
        f, c, m = (np.array(x) for x in (p.force, p.cop, p.free_moment))
        f[a:b] = 0.0
        m[a:b] = 0.0
        return ForcePlate(p.name, f, c, m, p.corners)

    write_forces(_forces_path(subject, trial), _map_plate(rec, plate, fn))
    return Hidden("unmeasured_force", plate, {"times_s": [float(rec.time[a]), float(rec.time[b - 1])], "known_s": known_unmeasured(subject, trial)})


def known_unmeasured(subject: Path, trial: str) -> list[list[float]]:
    """Time spans (s) the subject's saved extensions already leave out of the dynamics (the
    base's own steps off the plates): an erased step found there cannot be found again."""
    from solver.corrections import read_extensions

    spans: list[list[float]] = []
    for e in read_extensions(subject):
        if e.get("cause") == "unmeasured_force" and e.get("trial") == trial:
            spans.extend([float(x), float(y)] for x, y in e.get("times_s", []))
    return spans


def _overlap(spans: list[list[float]], a: float, b: float) -> list[tuple[float, float]]:
    """The parts of the spans inside [a, b]."""
    return [(max(a, x), min(b, y)) for x, y in spans if min(b, y) > max(a, x)]


def hide(cause: str, subject: Path, trial: str, seed: int, processed: ProcessedTrial) -> Hidden:
    """Hide ``cause`` in the subject copy with magnitudes drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    if cause == "marker_offset":
        return hide_marker_offset(subject, trial, rng, processed)
    fn = {
        "force_time_offset": hide_time_offset,
        "body_mass": hide_body_mass,
        "plate_force_offset": hide_plate_offset,
        "plate_force_gain": hide_plate_gain,
        "plate_position_offset": hide_plate_shift,
        "segment_mass_distribution": hide_segment_mass,
        "unmeasured_force": hide_unmeasured,
        "plate_registration": hide_plate_registration,
    }[cause]
    return fn(subject, trial, rng)


# --------------------------------------------------------------------------- checking


def _candidate(report: dict[str, Any], cause: str, choice: str | None) -> dict[str, Any] | None:
    for c in report["candidates"]:
        if c["cause"] != cause:
            continue
        if choice is None or c["choice"] == choice:
            return c
        for alt in c.get("alternatives", []):
            if alt["choice"] == choice:
                return {**c, **alt}
    return None


def error(hidden: Hidden, modified: dict[str, Any], unmodified: dict[str, Any]) -> float:
    """Parameter error of the chosen cause, relative to the unmodified trial's own estimate
    of the same cause (and plate or marker), in the units of :data:`TOLERANCE`."""
    got = modified["chosen_parameters"]
    base = _candidate(unmodified, hidden.cause, hidden.choice)
    base_p = base["parameters"] if base else None
    t = hidden.truth
    if hidden.cause == "force_time_offset":
        return abs(got["delay_s"] - (base_p["delay_s"] if base_p else 0.0) - t["delay_s"])
    if hidden.cause == "body_mass":
        return abs(got["mass_change_kg"] - (base_p["mass_change_kg"] if base_p else 0.0) - t["mass_change_kg"])
    if hidden.cause == "plate_force_offset":
        return float(np.linalg.norm(np.subtract(got["offset_N"], base_p["offset_N"] if base_p else 0.0) - t["offset_N"]))
    if hidden.cause == "plate_force_gain":
        return abs(got["gain"] / (base_p["gain"] if base_p else 1.0) - t["gain"])
    if hidden.cause == "plate_position_offset":
        return float(np.linalg.norm(np.subtract(got["shift_m"], base_p["shift_m"] if base_p else 0.0) - t["shift_m"]))
    if hidden.cause == "marker_offset":
        return float(np.linalg.norm(np.subtract(got["shift_m"], base_p["shift_m"] if base_p else 0.0) - t["shift_m"]))
    if hidden.cause == "segment_mass_distribution":
        # the model's legs gained legs_fraction of the body mass: the diagnosis moves it back
        legs = got["mass_change_kg"].get("legs", 0.0) - (base_p["mass_change_kg"].get("legs", 0.0) if base_p else 0.0)
        expected = -t["legs_fraction"] * modified["settings"]["fitted_mass_kg"]
        return abs(legs - expected)
    if hidden.cause == "plate_registration":
        return registration_error(got, base_p, t)
    if hidden.cause == "unmeasured_force":
        # share of the erased step missed, counting only its frames not already left out
        # (time spans; the known spans do not overlap each other, nor do the found ones)
        a, b = t["times_s"]
        new = [(a, b)]
        for x, y in t.get("known_s", []):
            new = [piece for u, v in new for piece in ((u, min(v, x)), (max(u, y), v)) if piece[1] > piece[0]]
        length = sum(v - u for u, v in new)
        covered = sum(y - x for u, v in new for x, y in _overlap(got["times_s"], u, v))
        return 1.0 - covered / max(length, 1e-9)
    raise ValueError(hidden.cause)


def _turn(rotation: float, v: np.ndarray) -> np.ndarray:
    """``v`` (3,) turned by ``rotation`` rad about the vertical, minus ``v``: (R - I) v."""
    c, s = np.cos(rotation), np.sin(rotation)
    return np.array([c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]]) - v


def registration_error(got: dict[str, Any], base: dict[str, Any] | None, truth: dict[str, Any]) -> float:
    """Error of a ``plate_registration`` estimate, m: |(Δsx, Δsz, ρ Δφ)| with ρ its reported
    radius, the translations compared at the estimate's pivot.

    A registration about one pivot is one about another with the translation
    ``s + (R - I)(o_new - o)``: the hidden one and the base's own estimate (to first order,
    the estimate on the modified trial is their sum) are both taken to the pivot of the
    estimate ``got``."""
    o = np.asarray(got["centre_m"])
    expected_s = np.asarray(truth["shift_m"]) + _turn(truth["rotation_rad"], o - np.asarray(truth["centre_m"]))
    expected_phi = truth["rotation_rad"]
    if base is not None:
        expected_s = expected_s + np.asarray(base["shift_m"]) + _turn(base["rotation_rad"], o - np.asarray(base["centre_m"]))
        expected_phi += base["rotation_rad"]
    ds = np.asarray(got["shift_m"]) - expected_s
    return float(np.linalg.norm([ds[0], ds[2], got["radius_m"] * (got["rotation_rad"] - expected_phi)]))


def check(hidden: Hidden, modified: dict[str, Any], unmodified: dict[str, Any]) -> dict[str, Any]:
    """Detection, parameter error and held-out gain of one hidden-effect run."""
    chosen = modified["chosen"]
    cand = _candidate(modified, hidden.cause, None)
    right_choice = True
    if chosen == hidden.cause and hidden.choice is not None and hidden.cause != "unmeasured_force":
        right_choice = modified["chosen_parameters"].get("plate", modified["chosen_parameters"].get("marker")) == hidden.choice
    detected = chosen == hidden.cause and right_choice
    err = error(hidden, modified, unmodified) if detected else None
    held = modified.get("held_out") or {}
    gain = cand["gain"] if cand else None
    return {
        "cause": hidden.cause,
        "choice": hidden.choice,
        "truth": hidden.truth,
        "chosen": chosen,
        "chosen_choice": (modified.get("chosen_parameters") or {}).get("plate", (modified.get("chosen_parameters") or {}).get("marker")),
        "detected": detected,
        "error": err,
        "within_tolerance": detected and err is not None and err <= TOLERANCE[hidden.cause],
        "held_out_gain": gain,
        "held_out": held,
    }
