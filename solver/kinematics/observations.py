"""Match a trial's markers to the model's markers and build the observation arrays.

Lab marker names map to model markers by exact name, or through a user mapping
(``{"lab name": "model name"}``, e.g. a ``markers.yaml`` / ``markers.json`` next to the
subject). Markers the model does not carry are listed (and can later be attached to a
body automatically, see :mod:`solver.kinematics.autoplace`).
"""

from __future__ import annotations

import json
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import KinematicsError, MarkerMismatchError
from solver.io.types import MarkerTrajectories

FloatArray = NDArray[np.float64]

MAPPING_FILES = ("markers.yaml", "markers.yml", "markers.json", "marker_map.yaml", "marker_map.json")


@dataclass(frozen=True)
class MarkerSettings:
    """What a subject's marker file says.

    Attributes
    ----------
    mapping
        Lab marker name -> model marker name.
    attach_unmatched
        Attach lab markers the model lacks to the body they move with.
    source
        The file read ("" when there is none).
    """

    mapping: dict[str, str]
    attach_unmatched: bool = False
    source: str = ""


class _DuplicateKey(ValueError):
    """A key given twice in one mapping of a marker mapping file (the message names it)."""


def _unique_pairs(pairs: list[tuple[str, object]]) -> dict[str, object]:
    """``json.loads``' object hook: the pairs as a dict, refusing a key given twice."""
    out: dict[str, object] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(f"{key!r} is mapped twice ({out[key]!r} and {value!r}); give each lab marker once")
        out[key] = value
    return out


def _load_yaml_unique(text: str) -> object:
    """``yaml.safe_load`` of ``text``, refusing a key given twice in one mapping (PyYAML
    keeps the last silently: input audit 2026-12-02, finding 15).

    Raises
    ------
    _DuplicateKey
        Naming the key, both values and the line of the second.
    yaml.YAMLError
        Text that is not YAML.
    """
    import yaml

    class UniqueKeyLoader(yaml.SafeLoader):
        def construct_mapping(self, node, deep=False):  # PyYAML's signature
            seen: dict[object, object] = {}
            for key_node, value_node in node.value:
                key = self.construct_object(key_node, deep=deep)
                if not isinstance(key, Hashable):  # PyYAML's own mapping refuses it, naming the line
                    break
                if key in seen:
                    raise _DuplicateKey(
                        f"line {key_node.start_mark.line + 1}: {key!r} is mapped twice ({seen[key]!r} on an earlier line, "
                        f"then {self.construct_object(value_node, deep=deep)!r}); give each lab marker once"
                    )
                seen[key] = self.construct_object(value_node, deep=deep)
            return super().construct_mapping(node, deep=deep)

    return yaml.load(text, Loader=UniqueKeyLoader)  # a SafeLoader subclass: safe_load's constructors


def read_marker_settings(path: str | Path) -> MarkerSettings:
    """Read a marker mapping file (YAML or JSON).

    Either a plain mapping ``{lab_name: model_name}``, or an object with ``markers`` (that
    mapping) and optionally ``attach_unmatched: true``.

    Raises
    ------
    KinematicsError
        Unparsable file or other content, or a lab marker mapped twice, naming the file
        (and the line, for YAML).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise KinematicsError(f"not UTF-8 text (byte {exc.start}: {exc.object[exc.start:exc.start + 1]!r}); save it as UTF-8",
                              path=path) from None
    try:
        if path.suffix in (".yaml", ".yml"):
            data = _load_yaml_unique(text)
        else:
            data = json.loads(text, object_pairs_hook=_unique_pairs)
    except _DuplicateKey as exc:
        raise KinematicsError(str(exc), path=path) from None
    except Exception as exc:  # noqa: BLE001 (yaml/json errors carry their own position)
        raise KinematicsError(f"cannot parse marker mapping: {exc}", path=path) from None
    attach = False
    if isinstance(data, dict) and "markers" in data:
        attach = data.get("attach_unmatched", False)
        if not isinstance(attach, bool):
            raise KinematicsError("attach_unmatched must be true or false", path=path)
        data = data["markers"] or {}
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise KinematicsError("marker mapping must be a mapping of lab names to model marker names", path=path)
    return MarkerSettings(dict(data), attach, str(path))


def find_marker_settings(subject_dir: str | Path) -> MarkerSettings:
    """The marker file next to a subject (first of :data:`MAPPING_FILES`), or empty settings."""
    for name in MAPPING_FILES:
        p = Path(subject_dir) / name
        if p.is_file():
            return read_marker_settings(p)
    return MarkerSettings({})


def mapping_mistakes(
    settings: MarkerSettings, model_marker_names: Sequence[str], trials: Sequence[tuple[str, Sequence[str]]]
) -> list[str]:
    """What in a subject's marker mapping leaves markers of its trials out of the fit, as
    messages for the user (empty when nothing does).

    Parameters
    ----------
    settings
        The subject's marker settings (:func:`find_marker_settings`).
    model_marker_names
        The model's marker names.
    trials
        ``(trial name, its marker column names)`` for each trial.

    Returns
    -------
    One message per mapping entry whose lab marker a trial has and whose model marker the
    model lacks (the lab marker is left out, or attached as its own with
    ``attach_unmatched``), then one per trial and model marker that two or more of the
    trial's columns stand for (:func:`match_markers` takes the first).
    """
    where = Path(settings.source).name if settings.source else "the marker mapping"
    model = set(model_marker_names)
    present = {name for _, names in trials for name in names}
    out = []
    for lab, target in settings.mapping.items():
        if lab in present and target not in model:
            fate = ("is attached as a marker of its own (attach_unmatched)" if settings.attach_unmatched
                    else "is left out of the fit")  # fmt: skip
            out.append(f"{where} maps {lab} to {target}, which is not a marker of the model: {lab} {fate}")
    for trial, names in trials:
        columns: dict[str, list[str]] = {}
        for name in names:
            target = settings.mapping.get(name, name)
            if target in model:
                columns.setdefault(target, []).append(name)
        for target, labs in columns.items():
            if len(labs) > 1:
                via = f" ({where})" if any(lab in settings.mapping for lab in labs) else ""
                out.append(f"trial {trial}: the columns {' and '.join(labs)} both stand for the model marker {target}{via}; "
                           f"the fit uses {labs[0]}, the first, and leaves {', '.join(labs[1:])} out")  # fmt: skip
    return out


@dataclass(frozen=True)
class MarkerMatch:
    """How one trial's markers relate to the model's.

    Attributes
    ----------
    model_markers
        Model marker names used by this trial, in the order of ``trial_columns``.
    trial_columns
        Column index in the trial's marker array for each used model marker.
    unmatched
        Trial marker names the model does not carry (ignored unless attached).
    """

    model_markers: tuple[str, ...]
    trial_columns: tuple[int, ...]
    unmatched: tuple[str, ...]


def match_markers(
    trial: MarkerTrajectories,
    model_marker_names: Sequence[str],
    mapping: Mapping[str, str] | None = None,
    *,
    trial_name: str = "",
) -> MarkerMatch:
    """Pair trial marker columns with model markers.

    Raises
    ------
    MarkerMismatchError
        When no trial marker matches a model marker, naming the trial and listing a few
        names of each side.
    """
    mapping = dict(mapping or {})
    model_set = set(model_marker_names)
    used, cols, unmatched = [], [], []
    for i, name in enumerate(trial.names):
        target = mapping.get(name, name)
        if target in model_set and target not in used:
            used.append(target)
            cols.append(i)
        else:
            unmatched.append(name)
    if not used:
        raise MarkerMismatchError(
            f"no marker of the trial matches a model marker (trial: {', '.join(trial.names[:6])}...; "
            f"model: {', '.join(list(model_marker_names)[:6])}...); give a marker mapping file",
            path=trial.source or None,
            where=trial_name or None,
        )
    return MarkerMatch(tuple(used), tuple(cols), tuple(unmatched))


def observations(trial: MarkerTrajectories, match: MarkerMatch, *, trial_name: str = "") -> FloatArray:
    """``(T, M, 3)`` observed positions (m) of the matched markers, NaN where missing.

    Raises
    ------
    KinematicsError
        The trial has zero frames.
    MarkerMismatchError
        Every matched marker is missing in every frame, or one matched marker is missing
        in every frame (named in the message).
    """
    if trial.n_frames == 0:
        raise KinematicsError("the trial has zero frames", path=trial.source or None, where=trial_name or None)
    obs = trial.positions[:, list(match.trial_columns), :]
    seen = np.isfinite(obs).all(axis=2)
    if not seen.any():
        raise MarkerMismatchError(
            "all matched markers are missing (NaN) in every frame", path=trial.source or None, where=trial_name or None
        )
    empty = [trial.names[c] for c, s in zip(match.trial_columns, seen.any(axis=0)) if not s]
    if empty:
        raise MarkerMismatchError(
            f"marker {empty[0]!r}{' (and ' + str(len(empty) - 1) + ' more)' if len(empty) > 1 else ''} is missing "
            "(NaN) in every frame; remove the column from the file or the name from the marker mapping",
            path=trial.source or None,
            where=f"trial {trial_name}" if trial_name else None,
        )
    return np.array(obs, dtype=float)


