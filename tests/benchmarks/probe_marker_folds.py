"""Why the marker offsets' folds mix the phases: the walk's foot markers carry an error that
repeats with every stride, and folds dealt in turn sample one phase of the stride each.

The diagnosis cuts a trial into 0.2 s blocks and deals them to 5 folds
(:func:`solver.diagnose.selection.make_folds`). Dealt in turn (block b to fold b mod 5, every
cause's dealing before 2026-11-25), a fold's blocks sit 1.0 s apart, about one stride of the
walk: each fold holds nearly the same phase of the gait cycle, and a marker offset is named
only if the shift fitted on the other folds improves at least 80 % of them. Dealt mixing the
phases (block b to fold (b + b // 5) mod 5), each fold holds several phases; the marker
offsets and the segment mass distribution, whose rows carry the markers' errors, use that
dealing (``Cause.folds_mix_phases``), the causes judged on the residual wrench the first.

Part 1 (the walk's neutral base, :func:`tests.diagnose.harness.neutral_base`, nothing
hidden): the stride period (autocorrelation of the right heel marker's height), and for each
foot landmark marker and each dealing, per fold, the mean of its error (marker sigmas,
``ctx.sigmas.marker``) along the shift fitted on the whole trial, and its held-out gain
(cost units).

Part 2 (``--draws N``): the first N ``marker_offset`` draws of the benchmark
(:func:`tests.diagnose.harness.draw`, as ``probe_marker_draws.py``), each diagnosed with the
refit off twice: with every cause's blocks dealt in turn (a variant in this script only)
and with the folds the causes ask for (the default). The counts at the end: hidden marker named,
another marker named, nothing named.

    .venv/bin/python tests/benchmarks/probe_marker_folds.py [--draws 20] [--work DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from solver.diagnose import core
from solver.diagnose.causes.registry import CAUSES
from solver.diagnose.core import DiagnoseOptions, diagnose_trial
from solver.io.trc import read_trc
from tests.diagnose.effects import check, copy_subject, hide
from tests.diagnose.harness import diagnose_json, draw, probe_walk_base

FOOT = ("Toe", "MT5", "Heel", "Ankle")


@contextlib.contextmanager
def captured(mixed: bool) -> Iterator[dict[str, Any]]:
    """Diagnose with the folds as the causes ask (``mixed``, the default) or with every cause's
    blocks dealt in turn, recording the first evaluation of each marker alternative:
    ``{marker: (alternative, folds)}``."""
    seen: dict[str, Any] = {}
    original_cv = core.cross_validate
    mixing = [type(c) for c in CAUSES if c.folds_mix_phases]

    def cv(alt: Any, folds: np.ndarray) -> Any:
        if alt.cause == "marker_offset" and alt.choice not in seen:
            seen[alt.choice] = (alt, folds)
        return original_cv(alt, folds)

    core.cross_validate = cv
    for kind in mixing:
        kind.folds_mix_phases = mixed
    try:
        yield seen
    finally:
        core.cross_validate = original_cv
        for kind in mixing:
            kind.folds_mix_phases = True


def stride_period(trc: Path, marker: str = "R.Heel") -> float:
    """Period (s) of the marker's height: the lag of the largest autocorrelation in 0.6-1.8 s."""
    rec = read_trc(trc)
    y = rec.positions[:, rec.names.index(marker), 1]
    ok = np.isfinite(y)
    y = np.where(ok, y - np.nanmean(y), 0.0)
    dt = float(np.median(np.diff(rec.time)))
    lags = np.arange(int(0.6 / dt), min(int(1.8 / dt), y.size - 10))
    ac = [np.dot(y[:-lag], y[lag:]) / max(np.dot(ok[:-lag], ok[lag:]), 1) for lag in lags]
    return float(lags[int(np.argmax(ac))] * dt)


def part_one(base_subject: Path, trial: str) -> None:
    period = stride_period(base_subject / "trials" / trial / "markers.trc")
    print(f"stride period of the walk (R.Heel height): {period:.2f} s; blocks dealt in turn repeat in a fold every 5 x 0.2 s = 1.00 s")
    for mixed in (False, True):
        with captured(mixed) as seen, contextlib.redirect_stderr(io.StringIO()):
            diagnose_trial(base_subject, trial, base_subject / "addb_out", options=DiagnoseOptions(refit=False))
        print(f"\nfolds {'mixing the phases (the default)' if mixed else 'dealt in turn'}:\n")
        print("| marker | mean error along the fitted shift, per fold (sigmas) | held-out gain per fold | folds improved |")
        print("|---|---|---|---:|")
        for name, (alt, folds) in seen.items():
            if not any(name.endswith(f) for f in FOOT):
                continue
            theta = alt.solve(np.ones(folds.size, dtype=bool))
            shown = -np.einsum("trk,k->tr", alt.g, theta)  # the error the fitted shift accounts for
            unit = shown / np.maximum(np.linalg.norm(shown, axis=1, keepdims=True), 1e-12)
            along = np.einsum("tr,tr->t", alt.rho0, unit)
            k = int(folds.max()) + 1
            means = [float(along[folds == f].mean()) for f in range(k)]
            gains = []
            for f in range(k):
                test = folds == f
                costs = alt.frame_costs(alt.solve(~test))
                gains.append(float(np.sum(alt.ref_costs[test] - costs[test])))
            improved = np.mean([g > 0 for g in gains if g != 0]) if any(gains) else 0.0
            print(
                f"| {name} | {', '.join(f'{m:+.2f}' for m in means)} | {', '.join(f'{g:+.0f}' for g in gains)} | {improved:.0%} |"
            )


def named(report: dict[str, Any]) -> str:
    if report["chosen"] == "marker_offset":
        return f"marker_offset {report['chosen_parameters']['marker']}"
    return report["chosen"] or "none"


def part_two(base: Any, work: Path, n_draws: int) -> None:
    print("\n| draw | hidden marker | hidden |s| (cm) | named, folds dealt in turn | named, folds mixing the phases (the default) |")
    print("|---:|---|---:|---|---|")
    counts = {False: [0, 0, 0], True: [0, 0, 0]}
    for index in range(n_draws):
        _, seed = draw("marker_offset", index)
        dst = work / f"draw-{seed}"
        subject = copy_subject(base.subject, dst)
        hidden = hide("marker_offset", subject, base.trial, seed, base.processed)
        cells = []
        for mixed in (False, True):
            with captured(mixed), contextlib.redirect_stderr(io.StringIO()):
                report = diagnose_json(subject, base.trial, "--no-refit")  # processes the copy once
            res = check(hidden, report, base.report)
            slot = 0 if res["detected"] else 1 if report["chosen"] == "marker_offset" else 2
            counts[mixed][slot] += 1
            cells.append(named(report))
        size = 100 * float(np.linalg.norm(hidden.truth["shift_m"]))
        print(f"| {seed} | {hidden.choice} | {size:.2f} | {cells[0]} | {cells[1]} |", flush=True)
    for mixed in (False, True):
        c = counts[mixed]
        label = "folds mixing the phases (the default)" if mixed else "folds dealt in turn"
        print(f"\n{label}: hidden marker named {c[0]}, another marker named {c[1]}, nothing named {c[2]}", end="")
    print()


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--work", type=Path, default=None, help="working folder (default: a temporary one)")
    args = p.parse_args()
    work, base = probe_walk_base(args.work, "addb_probe_folds_")
    part_one(base.subject, base.trial)
    if args.draws:
        part_two(base, work, args.draws)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
