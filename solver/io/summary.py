"""One-screen summaries of lab files and subject folders (``addb info PATH``).

:func:`summarize` returns a JSON-serializable dict; :func:`format_summary` turns it
into readable text. Units in the keys: ``_s``, ``_hz``, ``_n`` (newtons), ``_bw`` (body
weights, only when the subject's mass is known, i.e. for subject folders).
Warnings raised by the readers (e.g. a moment-reference conversion) are collected
under ``"notes"`` instead of being printed.
"""

from __future__ import annotations

import json
import math
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from solver.constants import GRAVITY
from solver.errors import FileFormatError, XmlFormatError
from solver.io.c3d import read_c3d
from solver.io.external_loads import read_external_loads
from solver.io.mot import estimate_rate, is_force_table, read_forces, read_table
from solver.io.review import KEY as REVIEW_KEY
from solver.io.review import read_review
from solver.io.spikes import without_spikes
from solver.io.subject import SUBJECT_JSON, load_subject, load_trial, unapplied_range_note
from solver.io.trc import read_trc
from solver.io.types import ForceRecording, MarkerTrajectories
from solver.masks import true_runs
from solver.outputs import MANIFEST_NAME, SUBJECT_RECORD, TRIAL_RESULTS, output_marker


def summarize(path: str | Path) -> dict[str, Any]:
    """Summary of a TRC, MOT/STO, C3D, .osim, OpenSim XML, review JSON or .b3d file, a subject
    folder, or a folder of .b3d files (one without ``_subject.json``: each file's trials,
    frames, mass, height and processing passes, kind ``b3d_folder``; a file that cannot be
    read is an entry with its ``error``, so that one damaged file does not hide the others),
    an output folder of addb (kind ``output``, from its JSON files: given and fitted mass,
    per trial frames, measured frames, marker RMS error, residual forces, Hicks verdicts or the
    dynamics error; a dataset run's subject folder adds its status), a trial's output folder
    (its ``results.json``: kind ``trial_results``). A dataset run's output tree is summarized
    by :func:`solver.dataset.report.run_text`, a folder inside it by
    :func:`~solver.dataset.report.part_text`.
    A folder of subject folders (a dataset folder) is summarized by
    :func:`solver.dataset.inventory.dataset_inventory`, which calls this for each subject.

    Returns
    -------
    dict
        Always ``kind`` and ``path``; then per kind: ``frames``, ``rate_hz``,
        ``duration_s``, ``markers``, ``gaps`` (markers with missing frames, longest
        gap in frames and its marker), ``plates`` with peak vertical force (N, and
        body weights when the mass is known), model counts, external forces, trials.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    FileFormatError
        (or a subclass) The file is malformed or of an unknown type; the message
        names the file and the line or element.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(2, "No such file or folder", str(p))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        try:
            with np.errstate(all="ignore"):  # absurd values give inf/nan in the summary
                summary = _dispatch(p)
        except FileNotFoundError:
            raise
        except OSError as exc:
            raise FileFormatError(f"cannot read: {exc.strerror or exc}", path=p) from None
    notes = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    if notes:
        summary["notes"] = notes
    return summary


def _dispatch(p: Path) -> dict[str, Any]:
    if p.is_dir():
        b3d_files = sorted(f for f in p.iterdir() if f.suffix.lower() == ".b3d" and f.is_file())
        if b3d_files and not (p / SUBJECT_JSON).exists():
            return _b3d_folder(p, b3d_files)
        if not (p / SUBJECT_JSON).exists() and output_marker(p) is not None:
            return _output(p)
        if not (p / SUBJECT_JSON).exists() and (p / TRIAL_RESULTS).is_file():
            return _json(p / TRIAL_RESULTS)  # a trial's output folder: its results
        return _subject(p)  # a folder without _subject.json: the reader's error names it
    readers: dict[str, Callable[[Path], dict[str, Any]]] = {
        ".trc": _trc,
        ".mot": _table,
        ".sto": _table,
        ".c3d": _c3d,
        ".osim": _osim,
        ".xml": _xml,
        ".json": _json,
        ".b3d": _b3d,
    }
    reader = readers.get(p.suffix.lower())
    if reader is None:
        raise FileFormatError(
            f"unknown file type {p.suffix!r}; expected .trc, .mot, .sto, .c3d, .osim, .xml, "
            ".json, .b3d or a subject folder",
            path=p,
        )
    return reader(p)


# --------------------------------------------------------------------------- per kind


def _markers_summary(m: MarkerTrajectories) -> dict[str, Any]:
    out: dict[str, Any] = {
        "frames": m.n_frames,
        "rate_hz": m.rate_hz,
        "start_s": float(m.time[0]) if m.n_frames else None,
        "duration_s": float(m.time[-1] - m.time[0]) if m.n_frames else 0.0,
        "markers": len(m.names),
    }
    out["gaps"] = marker_gaps(m)
    return out


def marker_gaps(m: MarkerTrajectories) -> dict[str, Any]:
    """Markers with missing (NaN) frames: count, longest gap in frames and its marker."""
    missing = np.isnan(m.positions).any(axis=2)  # (T, M)
    longest, worst = 0, None
    n_with = 0
    for j, name in enumerate(m.names):
        run = _longest_run(missing[:, j])
        if run:
            n_with += 1
            if run > longest:
                longest, worst = run, name
    return {
        "markers_with_gaps": n_with,
        "longest_gap_frames": longest,
        "longest_gap_marker": worst,
        "missing_fraction": float(missing.mean()) if missing.size else 0.0,
    }


def _longest_run(flags: np.ndarray) -> int:
    return max((b - a for a, b in true_runs(flags)), default=0)


def _forces_summary(f: ForceRecording, mass_kg: float | None) -> dict[str, Any]:
    total = np.zeros(f.n_frames)
    plates = []
    for plate in f.plates:
        vertical = plate.force[:, 1]
        total += vertical
        entry: dict[str, Any] = {
            "name": plate.name,
            "peak_vertical_force_n": float(vertical.max()) if vertical.size else 0.0,
        }
        plates.append(entry)
    out: dict[str, Any] = {
        "force_frames": f.n_frames,
        "force_rate_hz": f.rate_hz,
        "plates": plates,
        "peak_vertical_force_n": float(total.max()) if total.size else 0.0,
    }
    if mass_kg:
        weight = mass_kg * GRAVITY
        out["peak_vertical_force_bw"] = out["peak_vertical_force_n"] / weight
        for entry in plates:
            entry["peak_vertical_force_bw"] = entry["peak_vertical_force_n"] / weight
    return out


def _trc(p: Path) -> dict[str, Any]:
    return {"kind": "trc", "path": str(p), **_markers_summary(without_spikes(read_trc(p)))}


def _table(p: Path) -> dict[str, Any]:
    table = read_table(p)
    if is_force_table(table):
        forces = read_forces(p)
        return {
            "kind": "forces",
            "path": str(p),
            "frames": forces.n_frames,
            "rate_hz": forces.rate_hz,
            "duration_s": float(np.ptp(forces.time)) if forces.n_frames else 0.0,
            **_forces_summary(forces, None),
        }
    t = table.time
    return {
        "kind": "table",
        "path": str(p),
        "frames": int(t.shape[0]),
        "rate_hz": _rate(t),
        "duration_s": float(np.ptp(t)) if t.size else 0.0,
        "columns": len(table.column_names),
        "in_degrees": table.header.get("inDegrees"),
    }


def _rate(t: np.ndarray) -> float | None:
    r = estimate_rate(t)
    return None if math.isnan(r) else r


def _c3d(p: Path) -> dict[str, Any]:
    markers, forces = read_c3d(p)
    out = {"kind": "c3d", "path": str(p), **_markers_summary(without_spikes(markers))}
    if forces is not None:
        out.update(_forces_summary(forces, None))
    return out


def _xml_root(p: Path) -> ET.Element:
    try:
        return ET.parse(p).getroot()
    except ET.ParseError as exc:
        line = exc.position[0] if exc.position else None
        raise XmlFormatError(f"not well-formed XML: {exc}", path=p, line=line) from None


def model_counts(p: Path) -> dict[str, Any]:
    """Bodies (ground excluded), coordinates and markers of an .osim file, by XML.

    Raises
    ------
    XmlFormatError
        The file is not well-formed XML, or holds no OpenSim ``<Model>``.
    """
    root = _xml_root(p)
    model = root if root.tag == "Model" else root.find("Model")
    if model is None:
        raise XmlFormatError(
            f"expected an OpenSim <Model>, found <{root.tag}>", path=p, where=root.tag
        )
    bodies = [b for b in model.iter("Body") if b.get("name") and b.get("name") != "ground"]
    return {
        "model": model.get("name", ""),
        "version": root.get("Version"),
        "bodies": len(bodies),
        "coordinates": sum(1 for c in model.iter("Coordinate") if c.get("name")),
        "markers": sum(1 for m in model.iter("Marker") if m.get("name")),
    }


def model_details(p: Path) -> dict[str, Any]:
    """What a user checks in a model before processing with it, as addb reads it
    (:func:`solver.model.osim.read_osim`): total mass and each body's, coordinates with
    their motion type, range and default (degrees for rotational ones, m for translational
    ones, the model's units for coupled ones), the
    locked, clamped and coupled ones, and the markers of each body.

    Returns
    -------
    ``{"mass_kg", "body_masses_kg": {body: kg}, "coordinate_list": [{"name", "joint",
    "motion_type", "range", "default", "unit", "locked", "clamped", "coupled_to"}],
    "markers_by_body": {body: [names]}}``.

    Raises
    ------
    OsimModelError, XmlFormatError
        The model cannot be read, naming the file and element.
    """
    from solver.model.osim import ROTATIONAL, TRANSLATIONAL, read_osim

    model = read_osim(p)
    coupled = {c.dependent: c.independent for c in model.couplers}
    coordinates = []
    for c in model.coordinates:
        k = math.degrees(1.0) if c.motion_type == ROTATIONAL else 1.0
        coordinates.append({
            "name": c.name, "joint": c.joint, "motion_type": c.motion_type,
            "range": [_fmt(c.range[0] * k), _fmt(c.range[1] * k)], "default": _fmt(c.default_value * k),
            "unit": {ROTATIONAL: "deg", TRANSLATIONAL: "m"}.get(c.motion_type, "(model units)"), "locked": c.locked,
            "clamped": c.clamped,
            "coupled_to": coupled.get(c.name),
        })  # fmt: skip
    markers: dict[str, list[str]] = {}
    for m in model.markers:
        markers.setdefault(m.body, []).append(m.name)
    return {
        "mass_kg": float(sum(b.mass for b in model.bodies)),
        "body_masses_kg": {b.name: float(b.mass) for b in model.bodies},
        "coordinate_list": coordinates,
        "markers_by_body": markers,
    }


def _osim(p: Path) -> dict[str, Any]:
    return {"kind": "osim", "path": str(p), **model_counts(p), **model_details(p)}


def _osim_lines(d: dict[str, Any]) -> list[str]:
    """The body masses, coordinates and markers of :func:`model_details`, one line each
    (markers: one line per body)."""
    masses = ", ".join(f"{b} {_fmt(m)}" for b, m in d["body_masses_kg"].items())
    lines = [f"  mass {_fmt(d['mass_kg'])} kg: {masses}"]
    coords = d["coordinate_list"]
    flags = {k: sum(1 for c in coords if c[k]) for k in ("locked", "clamped", "coupled_to")}
    lines.append(f"  coordinates ({flags['locked']} locked, {flags['clamped']} clamped, {flags['coupled_to']} coupled):")
    for c in coords:
        state = [w for w in ("locked", "clamped") if c[w]] + ([f"coupled to {c['coupled_to']}"] if c["coupled_to"] else [])
        lines.append(f"    {c['name']} ({c['joint']}, {c['motion_type']}): {c['range'][0]} to {c['range'][1]} {c['unit']}, "
                     f"default {c['default']}" + (f"; {', '.join(state)}" if state else ""))  # fmt: skip
    lines.append("  markers:")
    lines += [f"    {body}: {', '.join(names)}" for body, names in d["markers_by_body"].items()]
    return lines


def _xml(p: Path) -> dict[str, Any]:
    root = _xml_root(p)
    document = root if root.tag != "OpenSimDocument" else next(iter(root), root)
    if document.tag == "ExternalLoads":
        loads = read_external_loads(p)
        return {
            "kind": "external_loads",
            "path": str(p),
            "datafile": loads.datafile,
            "forces": [
                {"name": f.name, "body": f.applied_to_body, "force": f.force_identifier}
                for f in loads.forces
            ],
        }
    if document.tag == "Model":
        return _osim(p)
    return {
        "kind": "opensim_xml",
        "path": str(p),
        "element": document.tag,
        "name": document.get("name", ""),
    }


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_bytes().decode("utf-8", errors="replace"))
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"not valid JSON: {exc.msg}", path=path, line=exc.lineno) from None


def _json(p: Path) -> dict[str, Any]:
    raw = _read_json(p)
    if isinstance(raw, dict) and "n_frames" in raw and "marker_rms_m" in raw:  # a trial's results.json
        return {"kind": "trial_results", "path": str(p), "trials": [_trial_results(p.parent.name, raw)]}
    if isinstance(raw, dict) and REVIEW_KEY in raw:
        mask = read_review(p)
        return {
            "kind": "review",
            "path": str(p),
            "review_frames": int(mask.shape[0]),
            "missing_grf_frames": int(mask.sum()),
        }
    if isinstance(raw, dict) and "massKg" in raw:
        return {
            "kind": "subject_json",
            "path": str(p),
            "mass_kg": raw.get("massKg"),
            "height_m": raw.get("heightM"),
            "foot_bodies": raw.get("footBodyNames"),
        }
    raise FileFormatError(
        f"unknown JSON file; expected a review file with {REVIEW_KEY!r}, a subject JSON or a trial's results.json",
        path=p,
    )


def _subject(p: Path) -> dict[str, Any]:
    subject = load_subject(p)
    trials = []
    for files in subject.trials:
        trial = load_trial(files)
        entry: dict[str, Any] = {"name": trial.name, **_markers_summary(trial.markers)}
        if trial.forces is None:
            entry["kinematics_only"] = True
        else:
            entry.update(_forces_summary(trial.forces, subject.mass_kg))
        trials.append(entry)
        note = unapplied_range_note(subject, trial.name, trial.markers.time)
        if note is not None:  # a note of the summary (summarize), not a warning of processing
            warnings.warn(note, UserWarning, stacklevel=2)
    return {
        "kind": "subject",
        "path": str(p),
        "name": subject.name,
        "mass_kg": subject.mass_kg,
        "height_m": subject.height_m,
        "foot_bodies": list(subject.foot_body_names),
        "disable_dynamics": subject.disable_dynamics,
        "model": model_counts(subject.model_path),
        "trials": trials,
    }


#: Keys of a trial's results.json that the summary of an output folder shows.
_OUTPUT_TRIAL_KEYS = (
    "n_frames", "n_observed_frames", "marker_rms_m", "linear_residual_rms_N", "linear_residual_rms_BW",
    "angular_residual_rms_Nm", "angular_residual_rms_BWh", "hicks_linear_ok", "hicks_angular_ok",
)


def _read_json_object(path: Path) -> dict[str, Any]:
    raw = _read_json(path)
    if not isinstance(raw, dict):
        raise FileFormatError("expected a JSON object", path=path)
    return raw


def _output(p: Path) -> dict[str, Any]:
    """An output folder of addb (``addb process --out``, or a dataset run's subject folder):
    the subject's given and fitted mass from ``subject.json``, the dataset run's status from
    ``manifest.json`` and, per processed trial (``*/results.json``), its frames, measured
    frames, marker RMS error, residual forces and Hicks verdicts, or its dynamics error."""
    d: dict[str, Any] = {"kind": "output", "path": str(p), "trials": []}
    if (p / SUBJECT_RECORD).is_file():
        subject = _read_json_object(p / SUBJECT_RECORD)
        d.update(
            name=subject.get("subject"), mass_kg=subject.get("mass_kg"), height_m=subject.get("height_m"),
            fitted_mass_kg=subject.get("fitted_mass_kg"),
        )
    if (p / MANIFEST_NAME).is_file():
        manifest = _read_json_object(p / MANIFEST_NAME)
        d["status"] = manifest.get("status")
        error = manifest.get("error")
        if isinstance(error, dict):
            d["error"] = f"{error.get('type')}: {error.get('message')}"
    d["trials"] = [_trial_results(f.parent.name, _read_json_object(f)) for f in sorted(p.glob("*/results.json"))]
    return d


def _trial_results(name: str, metrics: dict[str, Any]) -> dict[str, Any]:
    """The metrics of a trial's results.json that a summary shows, and its dynamics error."""
    trial: dict[str, Any] = {"name": name, **{k: metrics[k] for k in _OUTPUT_TRIAL_KEYS if k in metrics}}
    error = metrics.get("dynamics_error")
    if isinstance(error, dict):
        trial["dynamics_error"] = f"{error.get('type')}: {error.get('message')}"
    return trial


def _output_lines(d: dict[str, Any]) -> list[str]:
    lines = []
    if d.get("name") is not None:
        mass = f"{_fmt(d['mass_kg'])} kg" if d.get("mass_kg") is not None else "mass unknown"
        fitted = f", fitted {_fmt(d['fitted_mass_kg'])} kg" if d.get("fitted_mass_kg") is not None else ""
        height = f", {_fmt(d['height_m'])} m" if d.get("height_m") else ""
        lines.append(f"  subject {d['name']}: {mass}{fitted}{height}")
    if "status" in d:
        lines.append(f"  dataset run: {d['status']}" + (f" ({d['error']})" if "error" in d else ""))
    if not d["trials"]:
        lines.append("  no processed trial")
    return lines + _trial_lines(d["trials"])


def _trial_lines(trials: list[dict[str, Any]]) -> list[str]:
    """Two lines per trial of :func:`_trial_results` (one without dynamics)."""
    lines = []
    for t in trials:
        head = f"  trial {t['name']}:"
        if "n_frames" in t:
            measured = f" ({t['n_observed_frames']} with measured force)" if "n_observed_frames" in t else ""
            head += f" {t['n_frames']} frames{measured}"
        if t.get("marker_rms_m") is not None:
            head += f", marker RMS {t['marker_rms_m'] * 100:.2f} cm"
        if "dynamics_error" in t:
            lines += [head, f"    dynamics failed: {t['dynamics_error']}"]
            continue
        if "n_observed_frames" not in t:
            lines.append(head + " (kinematics only)")
            continue
        parts = []
        if t.get("linear_residual_rms_N") is not None:
            bw = f" ({t['linear_residual_rms_BW']:.3f} BW)" if t.get("linear_residual_rms_BW") is not None else ""
            parts.append(f"residual force {t['linear_residual_rms_N']:.1f} N RMS{bw}")
        if t.get("angular_residual_rms_Nm") is not None:
            bwh = f" ({t['angular_residual_rms_BWh']:.3f} BW·h)" if t.get("angular_residual_rms_BWh") is not None else ""
            parts.append(f"moment {t['angular_residual_rms_Nm']:.1f} N·m RMS{bwh}")
        verdict = {True: "within", False: "over"}
        if t.get("hicks_linear_ok") is not None:
            angular = f", angular {verdict[t['hicks_angular_ok']]}" if t.get("hicks_angular_ok") is not None else ""
            parts.append(f"Hicks: linear {verdict[t['hicks_linear_ok']]}{angular}")
        if not parts and t.get("n_observed_frames") == 0:
            parts.append("no frame with measured force entered the fit: no residuals or Hicks verdicts")
        lines += [head, "    " + "; ".join(parts)]
    return lines


# --------------------------------------------------------------------------- text


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _data_lines(d: dict[str, Any], indent: str = "  ") -> list[str]:
    lines = []
    if "frames" in d:
        rate = d.get("rate_hz")
        rate_text = f" at {_fmt(rate)} Hz" if rate else ""
        duration = _fmt(d.get("duration_s", 0.0))
        lines.append(f"{indent}frames: {d['frames']}{rate_text}, {duration} s")
    if "markers" in d and isinstance(d["markers"], int) and d.get("kind") != "osim":
        gaps = d.get("gaps", {})
        gap_text = "no gaps"
        if gaps.get("markers_with_gaps"):
            gap_text = (
                f"{gaps['markers_with_gaps']} with gaps, longest {gaps['longest_gap_frames']} "
                f"frames ({gaps['longest_gap_marker']})"
            )
        lines.append(f"{indent}markers: {d['markers']} ({gap_text})")
    if "plates" in d:
        names = ", ".join(p["name"] for p in d["plates"])
        peak = f"{_fmt(d['peak_vertical_force_n'])} N"
        if "peak_vertical_force_bw" in d:
            peak += f" = {d['peak_vertical_force_bw']:.2f} BW"
        lines.append(f"{indent}plates: {len(d['plates'])} ({names}); peak vertical force {peak}")
    if d.get("kinematics_only"):
        lines.append(f"{indent}forces: none (kinematics only)")
    return lines


def _b3d(p: Path) -> dict[str, Any]:
    from solver.io.b3d import open_b3d

    b3d = open_b3d(p)
    h = b3d.header
    trials = []
    for t in h.trials:
        reasons: dict[str, int] = {}
        for r in t.missing_grf:
            if r != "notMissingGRF":
                reasons[r] = reasons.get(r, 0) + 1
        trials.append({
            "name": t.name,
            "original_name": t.original_name,
            "split_index": t.split_index,
            "frames": t.n_frames,
            "rate_hz": t.rate_hz,
            "duration_s": t.n_frames * t.timestep_s,
            "force_plates": t.n_force_plates,
            "passes": [tp.type for tp in t.passes],
            "tags": list(t.tags),
            "missing_grf_frames": sum(reasons.values()),
            "missing_grf_by_reason": reasons,
        })
    return {
        "kind": "b3d",
        "path": str(p),
        "version": h.version,
        "bytes": b3d.file_bytes,
        "mass_kg": h.mass_kg,
        "height_m": h.height_m,
        "sex": h.sex,
        "age_years": h.age_years,
        "subject_tags": list(h.tags),
        "notes_text": h.notes,
        "dofs": h.n_dofs,
        "markers": len(h.marker_names),
        "ground_contact_bodies": list(h.ground_contact_bodies),
        "passes": [ps.type for ps in h.passes],
        "frames": sum(t.n_frames for t in h.trials),
        "trials": trials,
    }


def _b3d_folder(p: Path, files: list[Path]) -> dict[str, Any]:
    """A folder of .b3d files (no ``_subject.json``): each file's header, one entry each."""
    from solver.io.b3d import open_b3d

    entries: list[dict[str, Any]] = []
    for f in files:
        try:
            h = open_b3d(f).header
        except FileFormatError as exc:  # one damaged file does not hide the others
            entries.append({"name": f.name, "error": str(exc), "frames": 0})
            continue
        entries.append({
            "name": f.name,
            "trials": len(h.trials),
            "frames": sum(t.n_frames for t in h.trials),
            "mass_kg": h.mass_kg,
            "height_m": h.height_m,
            "passes": [ps.type for ps in h.passes],
        })
    return {"kind": "b3d_folder", "path": str(p), "files": entries, "frames": sum(e["frames"] for e in entries)}


def _b3d_folder_lines(d: dict[str, Any]) -> list[str]:
    lines = [f"  {len(d['files'])} .b3d files, {d['frames']} frames (addb info FILE.b3d for one; addb view FOLDER reviews them):"]
    for e in d["files"]:
        if "error" in e:
            lines.append(f"    {e['name']}: cannot be read: {e['error']}")
            continue
        lines.append(
            f"    {e['name']}: {e['trials']} trials, {e['frames']} frames; {_fmt(e['mass_kg'])} kg, {_fmt(e['height_m'])} m; "
            f"passes {', '.join(e['passes']) or 'none'}"
        )
    return lines


def _b3d_lines(d: dict[str, Any]) -> list[str]:
    # the format stores an unknown age as -1 (and 0 in files that leave it unset)
    age = f"age {d['age_years']}" if d["age_years"] > 0 else "age unknown"
    tags = ", ".join(d["subject_tags"]) or "none"
    lines = [
        (
            f"  version {d['version']}, {d['bytes']:,} bytes; subject: {d['sex'] or 'unknown'}, {age}, "
            f"{_fmt(d['mass_kg'])} kg, {_fmt(d['height_m'])} m, tags: {tags}"
        ),
        f"  {d['dofs']} DOFs, {d['markers']} markers, contact bodies {', '.join(d['ground_contact_bodies'])}",
        f"  processing passes: {', '.join(d['passes']) or 'none'}",
        f"  {len(d['trials'])} trials, {d['frames']} frames:",
    ]
    for t in d["trials"]:
        missing = ", ".join(f"{k} {v}" for k, v in sorted(t["missing_grf_by_reason"].items())) or "none"
        # the trial it was split from only when the name does not already say it (AddBiomechanics
        # names part k of trial T "T_segment_k"; addb export names a trial as its original)
        original, part = t["original_name"], t["split_index"]
        source = "" if t["name"] in (original, f"{original}_segment_{part}") else f" (from {original} part {part})"
        lines.append(
            f"    {t['name']}{source}: {t['frames']} frames at "
            f"{_fmt(t['rate_hz'])} Hz ({_fmt(t['duration_s'])} s), {t['force_plates']} plates, "
            f"passes {', '.join(t['passes'])}; missing GRF frames: {t['missing_grf_frames']} ({missing})"
        )
    return lines


def format_summary(d: dict[str, Any]) -> str:
    """Readable multi-line text of a :func:`summarize` result."""
    kind = d.get("kind", "?")
    lines = [f"{d.get('path', '')}: {kind.replace('_', ' ')}"]
    lines += _data_lines(d)
    if kind == "table":
        lines.append(f"  columns: {d['columns']} (inDegrees={d.get('in_degrees')})")
    if kind == "osim":
        lines.append(
            f"  model {d['model']!r} (version {d['version']}): {d['bodies']} bodies, "
            f"{d['coordinates']} coordinates, {d['markers']} markers"
        )
        if "coordinate_list" in d:
            lines += _osim_lines(d)
    if kind == "external_loads":
        lines.append(f"  datafile: {d['datafile']}")
        lines += [f"  {f['name']}: {f['force']} -> {f['body']}" for f in d["forces"]]
    if kind == "opensim_xml":
        lines.append(f"  <{d['element']}> {d['name']}")
    if kind == "b3d":
        lines = lines[:1] + _b3d_lines(d)
    if kind == "b3d_folder":
        lines = lines[:1] + _b3d_folder_lines(d)
    if kind == "output":
        lines += _output_lines(d)
    if kind == "trial_results":
        lines += _trial_lines(d["trials"])
    if kind == "review":
        lines.append(f"  frames: {d['review_frames']}, missing GRF: {d['missing_grf_frames']}")
    if kind == "subject_json":  # the values as written (addb info SUBJECT_DIR checks them)
        height = f"height {d['height_m']} m" if d["height_m"] is not None else "no height"
        lines.append(f"  mass {d['mass_kg']} kg, {height}")
        if isinstance(d.get("foot_bodies"), list):
            lines.append(f"  feet: {', '.join(map(str, d['foot_bodies']))}")
    if kind == "subject":
        height = f"{_fmt(d['height_m'])} m" if d["height_m"] else "unknown height"
        m = d["model"]
        lines.append(f"  subject {d['name']}: {_fmt(d['mass_kg'])} kg, {height}")
        lines.append(
            f"  model: {m['bodies']} bodies, {m['coordinates']} coordinates, {m['markers']} markers"
        )
        for t in d["trials"]:
            lines.append(f"  trial {t['name']}:")
            lines += _data_lines(t, indent="    ")
    lines += [f"  note: {n}" for n in d.get("notes", [])]
    return "\n".join(lines)
