"""Running ``addb diagnose`` the public way, on neutral subject copies and hidden effects.

A *neutral base* is a copy of a real subject whose own findings have been applied with
``addb diagnose --apply`` until no cause stands out (at most ``max_rounds`` rounds, each a
processing run): natural unmeasured frames, a marker the lab placed off its landmark, ...
The other marker offsets the report lists as standing out on their own markers' errors
(``also_standing_out``) are applied in the same round: markers do not compete, and the
walk's landmark markers carry a dozen real offsets of about 1 cm (2026-11-23), which one
marker per round would take a dozen processing runs to apply.
Hidden effects are then added to copies of that base, so that the hidden effect is the one
thing left to find, and parameters are compared with the base's own estimates.
"""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import tempfile
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from addb_viewer.cli import main as cli
from solver.corrections import append_extension
from solver.results import ProcessedTrial, load_processed
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import Hidden, copy_subject, hide

SUBJECTS = SHARED_DATA / "subjects"

#: (subject folder, trial) of the real trials used.
TRIALS = {
    "walk": ("rajagopal2016_walk", "walk"),
    "run": ("rajagopal2016_run", "run"),
    "DJ1": ("opencap_uhlrich2023", "DJ1"),
    "walking1": ("opencap_uhlrich2023", "walking1"),
}


def diagnose_json(subject: Path, trial: str, *extra: str) -> dict[str, Any]:
    """``addb diagnose SUBJECT --trial TRIAL --json [extra]`` -> the parsed JSON object."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli(["diagnose", str(subject), "--trial", trial, "--json", *extra])
    if code != 0:
        raise RuntimeError(f"addb diagnose exited with {code}")
    return json.loads(buf.getvalue())


@dataclass
class Base:
    """A neutral base subject: its folder, trial, final report and processed trial."""

    subject: Path
    trial: str
    report: dict[str, Any]
    applied: list[dict[str, Any]]

    @property
    def processed(self) -> ProcessedTrial:
        """The processed trial of the base (its default output folder, default fit)."""
        return load_processed(self.subject / "addb_out", self.trial)


def neutral_base(key: str, dst: Path, max_rounds: int = 8) -> Base:
    """Copy a real trial's subject (that trial and any static trial) and apply its own
    findings until none stands out."""
    folder, trial = TRIALS[key]
    src = SUBJECTS / folder
    keep = tuple(t.name for t in (src / "trials").iterdir() if t.name == trial or not (t / "grf.mot").exists())
    subject = copy_subject(src, dst, keep)
    applied = []
    report: dict[str, Any] = {}
    for _ in range(max_rounds):
        _process(subject)
        report = diagnose_json(subject, trial, "--apply")
        others = [a["extension"] for a in report.get("also_standing_out", [])]
        for entry in others:
            append_extension(subject, entry, source="tests.diagnose.harness")
        if report["chosen"] is None and not others:
            break
        applied += ([report["extension"]] if report["chosen"] is not None else []) + others
    else:
        _process(subject)
        report = diagnose_json(subject, trial)
    return Base(subject, trial, report, applied)


def probe_walk_base(work: Path | None, prefix: str) -> tuple[Path, Base]:
    """For the benchmark probes: the working folder (``work``, or a new temporary one named
    ``prefix``...) and the walk's neutral base built in it, its progress kept off stderr."""
    folder = work or Path(tempfile.mkdtemp(prefix=prefix))
    with contextlib.redirect_stderr(io.StringIO()):
        return folder, neutral_base("walk", folder / "base")


def _process(subject: Path) -> None:
    """Process ``subject`` into its default output folder with the fit the diagnosis judges
    on (``--fit rounds``, :mod:`solver.diagnose.judged_fit`): a base's processed motion, on
    which hidden marker offsets and consistent trials are built, is then the one the
    diagnosis was calibrated with, and its diagnosis runs no second fit."""
    shutil.rmtree(subject / "addb_out", ignore_errors=True)
    with contextlib.redirect_stdout(io.StringIO()):  # its summary table: not a benchmark's output
        code = cli(["process", str(subject), "--out", str(subject / "addb_out"), "--fit", "rounds"])
    if code != 0:
        raise RuntimeError(f"addb process failed on {subject}")


def draw(cause: str, index: int, keys: tuple[str, ...] = ("walk", "run")) -> tuple[str, int]:
    """(trial key, seed) of draw ``index`` of ``cause``: the draws of the benchmark
    (``tests/benchmarks/bench_diagnose.py``) alternate between the trials; the tests run
    its first draws, so their outcome is in ``docs/diagnose/RESULTS.md`` too.

    ``marker_offset`` draws only use trials whose model has landmark (``fixed``) markers:
    every other marker's offset is fitted by the kinematics stage, which absorbs a constant
    body-fixed shift entirely (the run's model has none)."""
    from tests.diagnose.effects import CAUSES

    if cause == "marker_offset":
        keys = tuple(k for k in keys if has_landmarks(k)) or keys
    return keys[index % len(keys)], 1000 * (CAUSES.index(cause) + 1) + index


@cache
def has_landmarks(key: str) -> bool:
    """Whether the generic model of trial ``key``'s subject has a ``fixed`` marker."""
    from tests.diagnose.effects import fixed_markers

    return bool(fixed_markers(SUBJECTS / TRIALS[key][0]))


def hidden_run(base: Base, cause: str, seed: int, dst: Path) -> tuple[Hidden, dict[str, Any]]:
    """Hide ``cause`` (magnitudes from ``seed``) in a copy of ``base`` and diagnose it."""
    processed = base.processed
    subject = copy_subject(base.subject, dst)
    hidden = hide(cause, subject, base.trial, seed, processed)
    return hidden, diagnose_json(subject, base.trial)
