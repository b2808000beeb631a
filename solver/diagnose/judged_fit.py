"""The dynamics fit the diagnosis judges on, rebuilt when a trial was processed with another.

The diagnosis' choice rule (its 10 % relative gain, the folds, the plausible sizes, the
neutral bases of its benchmark: docs/diagnose/RESULTS.md) is calibrated on the alternation
of exact coordinate steps and body mass solves (:func:`solver.dynamics.fit.alternating_fit`,
``addb process --fit rounds``), the pipeline's default until 2026-11-26. Before
that it was calibrated on the older band fit (``direction="band"``, a fixed number of rounds,
``addb process --fit band``). The converged motion takes up more of a hidden force error (a
plate's zero drift shows on its idle rows and far less on its loaded ones), so causes acting
on the forces are also chosen on the motion the markers alone decide (a plate's zero drift,
:attr:`solver.diagnose.causes.base.Cause.chosen_on_marker_motion`).

The pipeline's default is now the joint mass fit (:func:`~solver.dynamics.fit.converged_fit`,
:mod:`solver.dynamics.joint_fit`). Its freer body masses take up part of a hidden mass or
plate error before the diagnosis looks: with it in the alternation's place and the rules
unchanged, the segment-mass row of docs/diagnose/RESULTS.md falls from 17 to 2 draws of 20
within tolerance, the plate-position row from 17 to 14 and the marker-offset row from 14 to
13 (tests/benchmarks/RESULTS.md, block ``diagnose-joint-compare``, 2026-11-27). A tighter mass
prior is not enough: at ``mass_sigma`` 0.1 the marker-offset row comes back, while plate
position and segment masses stay two draws short each (block ``diagnose-joint-sigma-compare``).
Until the rules are re-derived on it, the diagnosis judges every trial on the alternation: an
output made with it (``--fit rounds``, or an older default output) is judged as it is; when the trial's
output was made with another fit (the default, ``--fit band``), the dynamics stage is run
again with :func:`~solver.dynamics.fit.alternating_fit` (the recorded ``derivative`` kept)
into a scratch folder, from the output's cached kinematics
(:func:`solver.pipeline.reprocess_dynamics`, run cold, which equals a full run with the same
flags bit for bit), and the diagnosis reads that folder. The user's output is not touched,
but for one cache: that folder is kept in ``OUT/.addb_cache/judged_fit/<trial>/`` with the
key it was made from (the subject's input files, model, options, addb's version and source
digest as for the kinematics cache, the judged dynamics options, the trial and the
reviewer's flags; :func:`judged_cache_key`), so a second diagnosis of unchanged inputs
(``addb diagnose``, then ``addb diagnose --apply``) reads it instead of running the fit
again. Any change of the key runs the fit again and replaces the entry; a folder that cannot
be written keeps no cache.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from solver.dynamics.fit import FitSettings, alternating_fit

if TYPE_CHECKING:
    from solver.dynamics.stage import DynamicsOptions

Progress = Callable[[str, float], None]

#: Folder of ``OUT/.addb_cache`` holding the judged fit's output of each diagnosed trial.
JUDGED_CACHE = "judged_fit"
_KEY_FILE = "key.json"


def judged_fit(recorded: FitSettings) -> FitSettings:
    """The fit the diagnosis judges a trial processed with ``recorded`` on: the one its
    thresholds are calibrated on, :func:`~solver.dynamics.fit.alternating_fit`, with the
    recorded ``derivative`` (which also sets the inverse dynamics' derivatives)."""
    return alternating_fit(derivative=recorded.derivative)


def is_judged_fit(recorded: FitSettings) -> bool:
    """True when an output made with ``recorded`` can be judged as it is."""
    return recorded == judged_fit(recorded)


@contextmanager
def judged_output(
    subject_dir: str | Path,
    out_dir: str | Path,
    trial: str,
    unmeasured_force: Mapping[str, np.ndarray] | None = None,
    progress: Progress | None = None,
    *,
    recorded: DynamicsOptions | None = None,
) -> Iterator[Path]:
    """The output folder to diagnose ``trial`` in: ``out_dir`` itself when it was made with
    the judged fit; else the trial processed again with it, read from
    ``OUT/.addb_cache/judged_fit/<trial>/out`` when that entry's key equals
    :func:`judged_cache_key` now, or run in a scratch folder (removed on exit) and stored
    there for the next diagnosis. A cache entry is read from a copy in the scratch folder,
    so another diagnosis that replaces the entry meanwhile cannot take files from under
    this one.

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        The subject's processed output (its ``subject.json`` records the fit).
    trial
        The trial to write in the scratch folder.
    unmeasured_force
        Trial name -> ``(T,)`` reviewer's flags at the processed frames, as the output was
        processed with (every trial's: the body mass factors are fitted over all of them).
    progress
        Called with (message, fraction).
    recorded
        The dynamics options ``out_dir`` was made with, when the caller has read them
        already (default: :func:`solver.pipeline.recorded_dynamics_options`).

    Raises
    ------
    SubjectFolderError, FileFormatError, KinematicsError, DynamicsError
        As :func:`solver.pipeline.reprocess_dynamics`.
    """
    from solver.pipeline import (
        CACHE_DIR,
        KINEMATICS_CACHE,
        ProcessOptions,
        recorded_dynamics_options,
        reprocess_dynamics,
    )

    if recorded is None:
        recorded = recorded_dynamics_options(out_dir)
    if is_judged_fit(recorded.fit):
        yield Path(out_dir)
        return
    options = ProcessOptions(dynamics=replace(recorded, fit=judged_fit(recorded.fit)))
    say = progress or (lambda m, f: None)
    key = judged_cache_key(subject_dir, trial, options, unmeasured_force)
    entry = Path(out_dir) / CACHE_DIR / JUDGED_CACHE / trial
    with tempfile.TemporaryDirectory(prefix="addb_judged_fit_") as tmp:
        base = Path(tmp) / "out"
        if _copy_entry(entry, base, key):
            say("the diagnosis' fit (--fit rounds): reused from the cache (same inputs, options and flags)", 1.0)
            yield base
            return
        cache = Path(out_dir) / CACHE_DIR
        if (cache / KINEMATICS_CACHE).is_file():
            (base / CACHE_DIR).mkdir(parents=True)
            shutil.copy2(cache / KINEMATICS_CACHE, base / CACHE_DIR / KINEMATICS_CACHE)
        reprocess_dynamics(
            subject_dir, base, [trial], dict(unmeasured_force or {}) or None,
            lambda m, f: say(f"the diagnosis' fit (--fit rounds): {m}", f), options=options, warm_start=False,
        )  # fmt: skip
        shutil.rmtree(base / CACHE_DIR, ignore_errors=True)  # the kinematics cache stays in OUT only
        _store(base, entry, key)
        yield base


def judged_cache_key(
    subject_dir: str | Path, trial: str, options: object, unmeasured_force: Mapping[str, np.ndarray] | None
) -> dict[str, object]:
    """What the judged fit's output of ``trial`` depends on, as a JSON-like dict.

    :func:`solver.pipeline.kinematics_cache_key` of the subject (every input file by size,
    modification time and digest, the model, the kinematics options, addb's version and
    source digest: ``addb_extensions.json`` and the stated mass are input files), the
    judged dynamics options (``options``, a :class:`solver.pipeline.ProcessOptions`), the
    trial and each trial's flags (length and SHA-256 of the ``(T,)`` booleans).

    Raises
    ------
    SubjectFolderError
        As :func:`solver.io.subject.load_subject`.
    """
    from solver.io.subject import load_subject
    from solver.pipeline import kinematics_cache_key

    flags = {}
    for name, mask in sorted((unmeasured_force or {}).items()):
        bits = np.asarray(mask, dtype=bool)
        flags[name] = [int(bits.size), hashlib.sha256(np.packbits(bits).tobytes()).hexdigest()]
    return {
        "schema": "addb.judged_fit_cache/1",
        "kinematics": kinematics_cache_key(load_subject(subject_dir), options.kinematics),  # type: ignore[attr-defined]
        "dynamics": repr(options.dynamics),  # type: ignore[attr-defined]
        "trial": trial,
        "flags": flags,
    }


def _cached_key(entry: Path) -> object:
    """The key stored with a cache entry (None when there is none or it is unreadable)."""
    try:
        return json.loads((entry / _KEY_FILE).read_text())
    except (OSError, ValueError):
        return None


def _copy_entry(entry: Path, base: Path, key: dict[str, object]) -> bool:
    """Copy the cached output of ``entry`` to ``base`` when its key equals ``key`` before
    and after the copy (another diagnosis may replace the entry meanwhile); False, with
    ``base`` absent, when there is no such entry or it could not be copied."""
    if _cached_key(entry) != key:
        return False
    try:
        shutil.copytree(entry / "out", base)
    except OSError:  # gone or replaced while copying (shutil.Error is an OSError)
        shutil.rmtree(base, ignore_errors=True)
        return False
    if _cached_key(entry) != key:
        shutil.rmtree(base, ignore_errors=True)
        return False
    return True


def _store(base: Path, entry: Path, key: dict[str, object]) -> None:
    """Copy the judged output ``base`` into ``entry`` with its key, replacing an older entry
    in two renames (:func:`solver.outputs.replace_folder`); skipped when ``entry``'s
    folder cannot be written."""
    from solver.outputs import replace_folder

    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{entry.name}-", dir=entry.parent))
    except OSError:
        return
    try:
        shutil.copytree(base, staging / "out")
        (staging / _KEY_FILE).write_text(json.dumps(key, sort_keys=True))
        replace_folder(staging, entry, aside_prefix=f".{entry.name}-old-")
    except OSError:
        shutil.rmtree(staging, ignore_errors=True)
