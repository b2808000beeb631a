"""Why the joint fit loses draws the alternation names: the contenders of each draw on the
fitted motion and on the marker-only motion, with each fit in the diagnosis' place.

For each ``--seeds`` draw of the diagnosis benchmark (:func:`tests.diagnose.harness.draw`:
the hidden cause and the trial follow from the seed, ``1000 x (cause's index + 1) + draw``,
even draws on the walk and odd ones on the run, a marker offset's all on the walk), hidden
in a copy of its trial's neutral base and diagnosed (``addb diagnose --no-refit``: naming
does not depend on the refit), once with the
alternation the diagnosis judges on (:func:`solver.dynamics.fit.alternating_fit`) and once
per ``--sigma`` with the joint mass fit in its place
(:func:`bench_diagnose_joint.joint_in_place`, as ``bench_diagnose_joint.py``; the neutral
bases are built again with each fit). For each it prints the cause named and the strongest
contenders on the fitted motion (score, relative held-out gain, fraction of the held-out folds
improved: the report's candidates) and, where the diagnosis compares the force-side causes on
the marker-only motion (:func:`solver.diagnose.core.choice_on_marker_motion`, read as it runs),
the strongest contenders evaluated there (every cause judged on that motion; the comparison
takes the force-side ones among them) and what that comparison returns. The choice rule is
:class:`solver.diagnose.selection.ChoiceRule` (a contender must improve 80 % of the folds).

    .venv/bin/python tests/benchmarks/probe_joint_choice.py [--sigma 0.1 ...] [--seeds 5006 5014 7006] [--top 5]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench_diagnose_joint import joint_in_place  # this folder

import solver.dynamics.stage as stage_module
from solver.diagnose import core
from tests.diagnose.effects import CAUSES, copy_subject, hide
from tests.diagnose.harness import Base, diagnose_json, draw, neutral_base

Row = tuple[str, float, float, float]


def _draw_of(seed: int) -> tuple[str, str]:
    """(hidden cause, trial key) of a benchmark seed (:func:`tests.diagnose.harness.draw`).

    Raises
    ------
    SystemExit
        ``seed`` is no seed of the benchmark's draws.
    """
    index = seed // 1000 - 1
    if not 0 <= index < len(CAUSES):
        raise SystemExit(f"seed {seed} is no draw of the benchmark (1000 x (cause's index + 1) + draw)")
    key, again = draw(CAUSES[index], seed % 1000)
    assert again == seed
    return CAUSES[index], key


def _table(title: str, rows: list[Row]) -> list[str]:
    lines = [f"{title}:", "", "| contender | score | relative held-out gain | folds improved |", "| --- | ---: | ---: | ---: |"]
    lines += [f"| {name} | {score:.0f} | {rel:.3f} | {folds:.2f} |" for name, score, rel, folds in rows]
    return [*lines, ""]


def probe(fit_name: str, seeds: list[int], top: int, work: Path) -> list[str]:
    """Markdown lines for ``seeds`` with the fit in place (each trial's neutral base built with it)."""
    seen: list[tuple[str | None, list[Row], str | None]] = []
    original = core.choice_on_marker_motion

    def spy(chosen, evaluations_ik, rule, blocks, kept=None, own_noise=None):  # type: ignore[no-untyped-def]
        out = original(chosen, evaluations_ik, rule, blocks, kept, own_noise)
        best = sorted(evaluations_ik, key=lambda e: -e.score)[:top]
        rows = [(f"{e.cause} {e.choice or ''}".strip(), e.score, e.relative_gain, e.folds_improved) for e in best]
        seen.append((chosen.cause if chosen else None, rows, out[0].cause if out else None))
        return out

    core.choice_on_marker_motion = spy  # type: ignore[assignment]
    try:
        bases: dict[str, Base] = {}
        lines = [f"**{fit_name}**", ""]
        for seed in seeds:
            cause, key = _draw_of(seed)
            if key not in bases:
                with contextlib.redirect_stderr(io.StringIO()):
                    bases[key] = neutral_base(key, work / f"base-{key}")
            base = bases[key]
            seen.clear()
            subject = copy_subject(base.subject, work / f"draw-{seed}")
            hide(cause, subject, base.trial, seed, base.processed)
            with contextlib.redirect_stderr(io.StringIO()):
                report: dict[str, Any] = diagnose_json(subject, base.trial, "--no-refit")
            lines += [f"Draw {seed} ({key}, hidden: {cause}): named {report['chosen'] or 'none'}.", ""]
            best = sorted(report["candidates"], key=lambda c: -c["score"])[:top]
            rows = [(f"{c['cause']} {c['choice'] or ''}".strip(), c["score"], c["gain"], c["folds_improved"]) for c in best]
            lines += _table("on the fitted motion", rows)
            for chosen, ik_rows, picked in seen:
                lines += _table(f"on the marker-only motion (fitted motion's choice {chosen or 'none'}; returns {picked or 'none'})", ik_rows)
        return lines
    finally:
        core.choice_on_marker_motion = original  # type: ignore[assignment]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigma", type=float, nargs="+", default=[0.1], help="mass_sigma of each joint fit probed")
    ap.add_argument("--seeds", type=int, nargs="+", default=[5006, 5014, 7006])
    ap.add_argument("--top", type=int, default=5)
    args = ap.parse_args()
    fits: list[tuple[str, Any]] = [("alternation (the judged fit)", None)] + [(f"joint fit, mass_sigma {s:g}", s) for s in args.sigma]
    original = stage_module.fit_dynamics
    out: list[str] = []
    for name, sigma in fits:
        stage_module.fit_dynamics = original if sigma is None else joint_in_place(sigma)  # type: ignore[assignment]
        with tempfile.TemporaryDirectory(prefix="addb_probe_joint_choice_") as tmp:
            out += probe(name, args.seeds, args.top, Path(tmp))
    stage_module.fit_dynamics = original  # type: ignore[assignment]
    print("\n".join(out).rstrip())


if __name__ == "__main__":
    main()
