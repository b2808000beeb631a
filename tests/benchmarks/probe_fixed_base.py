"""Probe: the same hidden draws in one neutral base, diagnosed under each variant of the hybrid probe.

    .venv/bin/python tests/benchmarks/probe_fixed_base.py --trial run --draws CAUSE:INDEX ... [--variants NAME ...] [--sigma 0.1]

A probe for issue 29's second gap, not a change of ``addb diagnose``. The diagnosis' table
(``bench_diagnose.py``, and the probes that run it) builds each trial's neutral base with the
diagnosis it measures, so two variants of the rules hide their draws in different bases (the
run's base of block ``diagnose-hybrid-compare`` had two belt shifts and two mass
redistributions applied, the table's a mass redistribution, the registration and another).
Here the base of ``--trial`` is built once, with the joint fit at ``mass_sigma`` ``--sigma``
in the alternation's place and the rules as they are (``bench_diagnose_joint.py``), and each
draw (``tests.diagnose.harness.draw``: cause and index, as numbered in the table) is hidden
in it and diagnosed under every variant, each variant in a process of its own (the changes
of ``probe_hybrid_currency.py`` are made in the process):

* ``translation``: the rules as they are, every cause on the translation profile;
* ``whole-motion``: the plates' shift and registration on the whole-motion rows;
* ``channel-gain``: the same, their relative gain on their channels' own rows;
* ``fitted-motion-only``: whole-motion rows on the fitted motion only;
* ``both``: ``--channel-gain --fitted-motion-only``, as block ``diagnose-hybrid-compare``.

Prints one row per draw and variant: the cause named and the four best-scoring candidates
(score, relative gain, share of folds improved).
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: Variant -> the switches of ``probe_hybrid_currency.apply`` (channel gain, fitted motion
#: only), or None for the rules as they are.
VARIANTS: dict[str, tuple[bool, bool] | None] = {
    "translation": None,
    "whole-motion": (False, False),
    "channel-gain": (True, False),
    "fitted-motion-only": (False, True),
    "both": (True, True),
}


def _joint_fit(sigma: float) -> None:
    """The joint fit at ``mass_sigma`` ``sigma`` in the alternation's place, in this process."""
    import bench_diagnose_joint  # this folder

    import solver.dynamics.stage as stage_module

    stage_module.fit_dynamics = bench_diagnose_joint.joint_in_place(sigma)  # type: ignore[assignment]


def _worker(base_file: Path, variant: str, draws: list[str], work: Path, sigma: float) -> None:
    """Diagnose ``draws`` hidden in the pickled base under ``variant``: one JSON line each."""
    from tests.diagnose.harness import draw, hidden_run

    _joint_fit(sigma)
    switches = VARIANTS[variant]
    if switches is not None:
        import probe_hybrid_currency  # this folder

        probe_hybrid_currency.apply(probe_hybrid_currency.DEFAULT_MOTION_CAUSES, False, *switches)
    base = pickle.loads(base_file.read_bytes())
    for text in draws:
        name, index = text.split(":")
        _, seed = draw(name, int(index))
        _, report = hidden_run(base, name, seed, work / f"{variant}-{name}-{index}")
        top = [
            f"{c['cause']}{'/' + c['choice'] if c.get('choice') else ''} "
            f"{c['score']:.0f}, {100 * c['gain']:.0f} %, {c['folds_improved']:.1f}"
            for c in report["candidates"][:4]
        ]
        print(
            json.dumps({"draw": text, "variant": variant, "chosen": report["chosen"], "top": top}),
            flush=True,
        )


def main() -> None:
    """Build the base, run every variant in its own process, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trial", required=True, help="walk or run (tests.diagnose.harness.TRIALS)")
    ap.add_argument(
        "--draws", nargs="+", required=True, help="CAUSE:INDEX, as numbered in the table"
    )
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--sigma", type=float, default=0.1, help="mass_sigma of the joint fit")
    ap.add_argument(
        "--worker", nargs=3, metavar=("BASE", "VARIANT", "WORK"), help=argparse.SUPPRESS
    )
    args = ap.parse_args()
    if args.worker:
        _worker(Path(args.worker[0]), args.worker[1], args.draws, Path(args.worker[2]), args.sigma)
        return
    from tests.diagnose.harness import draw, neutral_base

    for text in args.draws:
        name, index = text.split(":")
        if draw(name, int(index))[0] != args.trial:
            ap.error(
                f"draw {text} is hidden in the {draw(name, int(index))[0]} trial, not {args.trial}"
            )
    with tempfile.TemporaryDirectory(prefix="addb-fixed-base-") as tmp:
        work = Path(tmp)
        _joint_fit(args.sigma)
        base = neutral_base(args.trial, work / "base")
        base_file = work / "base.pickle"
        base_file.write_bytes(pickle.dumps(base))
        print(
            f"base {args.trial}, built with the joint fit at mass_sigma {args.sigma:g} and the rules as they are: "
            f"applied {', '.join(e['cause'] for e in base.applied) or 'nothing'}\n"
        )
        print(
            "| draw | variant | named | best four candidates: score, relative gain, folds improved |"
        )
        print("| --- | --- | --- | --- |")
        for variant in args.variants:
            cmd = [
                sys.executable,
                __file__,
                "--worker",
                str(base_file),
                variant,
                str(work),
                "--sigma",
                str(args.sigma),
                "--trial",
                args.trial,
                "--draws",
                *args.draws,
            ]
            out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
            for line in out.splitlines():
                if line.startswith("{"):
                    row = json.loads(line)
                    print(
                        f"| {row['draw']} | {row['variant']} | {row['chosen']} | {'; '.join(row['top'])} |"
                    )


if __name__ == "__main__":
    main()
