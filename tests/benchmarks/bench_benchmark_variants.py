"""Variants around the seed-paper benchmark: where the analytical baseline's error comes
from, the kinematic contact rule, the hybrid's and the MLP's variants (run on demand).

    .venv/bin/python tests/benchmarks/bench_benchmark_variants.py [--work DIR] [--fresh] [--parts NAME ...]

Uses the subjects processed by tests/benchmarks/bench_benchmark.py into ``DIR/out`` (the
same default folder; processed first when missing, or again with ``--fresh``: without it,
outputs of older code are reused) and the benchmark's kinematic inputs
(``--inputs kinematic``: q̃, inverse kinematics of the raw markers low-passed at 30 Hz),
leave-one-subject-out folds, the scored frames of ``addb benchmark``. Prints Markdown
(standard output; progress on standard error), one section per part:

* ``analytical``: the analytical baseline (measured contact) by contact phase, and with
  the measured split between the feet or the measured total force in place of its own;
  the baseline at the hybrid's extra filter (q̃ low-passed again at 6 Hz);
* ``contact``: agreement of the kinematic contact rule with the plates' contact, for the
  rule in use (a foot's own lowest point within 0.5 s) and the earlier one (0.1 m above
  the trial's lowest foot origin);
* ``hybrid``: the hybrid (solver/benchmark/hybrid.py) as adopted and varied one setting
  at a time (seeds, epochs, the airborne gate, the contact indicator feature, the extra
  filter fixed or chosen pooled by frames, the CoM acceleration from its own forces);
  trained on one subject and scored on another;
* ``mlp``: the paper's MLP as specified and varied (seed, learning rate, a single-frame
  input, 50 epochs); the four-subject folds of the first benchmark (walk, run, OpenCap,
  Camargo) against the six-subject folds, scored on the same frames.

Takes about 4 minutes on the 2-core development machine when it is quiet (mostly the
networks' training), several times longer when it is shared.
Needs PyTorch.
"""

from __future__ import annotations

import argparse
import contextlib
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from solver.benchmark import hybrid
from solver.benchmark.analytical import (
    Prediction,
    analytical_baseline,
    kinematic_contact,
    torques_from_feet,
)
from solver.benchmark.dataset import BenchmarkTrial, Dataset, leave_one_subject_out, load_dataset
from solver.benchmark.evaluate import score_trial
from solver.benchmark.metrics import FrameErrors, grf_errors, summarize
from solver.benchmark.mlp import FeatureSpec, MlpOptions, train_mlp
from solver.benchmark.models import skeleton_for

SUBJECTS = ("rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023", "camargo2021_levelground", "stairdown", "opensim_c3d_walking")
FOUR = SUBJECTS[:4]
PARTS = ("analytical", "contact", "hybrid", "mlp")
RUN = "rajagopal2016_run/run"


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _f(x: float) -> str:
    return f"{x:.2f}"


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def ensure_processed(work: Path, fresh: bool) -> list[Path]:
    outs = [work / "out" / s for s in SUBJECTS]
    if fresh or not all(any(o.glob("*/trial.npz")) for o in outs):
        say(f"processing the subjects into {work}/out (tests/benchmarks/bench_benchmark.py's first step)")
        sys.path.insert(0, str(REPO / "tests" / "benchmarks"))
        from bench_benchmark import _process  # type: ignore[import-not-found]

        _process(Path(sys.executable).parent / "addb", work, fresh)
    return outs


# ------------------------------------------------------------------------------ scoring


def pooled(per_trial: dict[str, FrameErrors], keys: Sequence[str] | None = None) -> dict[str, float]:
    parts = [per_trial[k] for k in (keys if keys is not None else per_trial)]
    return summarize(FrameErrors.concatenate(parts))


def score_all(predict: Callable[[BenchmarkTrial], Prediction], trials: Sequence[BenchmarkTrial]) -> dict[str, FrameErrors]:
    return {f"{t.subject}/{t.trial}": score_trial(t, predict(t)) for t in trials}


def loso(dataset: Dataset, train: Callable[[list[BenchmarkTrial], list[BenchmarkTrial]], Any],
         predict: Callable[[Any, BenchmarkTrial], Prediction] | None = None) -> tuple[dict[str, FrameErrors], list[Any]]:
    """Per-trial frame errors of a trained method over leave-one-subject-out folds, and the
    trained models (``train(train_trials, test_trials)``; ``predict(model, trial)``,
    default ``model.predict``)."""
    per_trial: dict[str, FrameErrors] = {}
    models = []
    for fold in leave_one_subject_out(dataset.subjects):
        tr, te = list(dataset.of_subjects(fold.train).trials), list(dataset.of_subjects(fold.test).trials)
        model = train(tr, te)
        models.append(model)
        per_trial.update(score_all(lambda t, m=model: predict(m, t) if predict else m.predict(t), te))
    return per_trial, models


# ------------------------------------------------------------------------------ analytical


def part_analytical(ds: Dataset) -> None:
    print("### The analytical baseline's GRF error, part by part (measured contact)\n")
    phases: dict[str, list[np.ndarray]] = {"single support": [], "double support": [], "flight": []}
    own, split, total = [], [], []
    for t in ds.trials:
        k, m = t.frames, t.mass_kg
        pred = analytical_baseline(t, contact="measured")
        err = grf_errors(pred.grf[k], t.grf[k], m)
        n_on = t.contact[k].sum(axis=1)
        for name, n in (("single support", 1), ("double support", 2), ("flight", 0)):
            phases[name].append(err[n_on == n])
        own.append(err)
        analytic_total = pred.grf.sum(axis=1)  # (T, 3) = m (a_com - g): the baseline's own total force
        fy = np.clip(t.grf[..., 1], 0.0, None)
        share = np.where(fy.sum(axis=1, keepdims=True) > 0, fy / np.maximum(fy.sum(axis=1, keepdims=True), 1e-12), 0.0)
        split.append(grf_errors((share[:, :, None] * analytic_total[:, None, :])[k], t.grf[k], m))
        on = t.contact.astype(float)
        even = np.where(on.sum(axis=1, keepdims=True) > 0, on / np.maximum(on.sum(axis=1, keepdims=True), 1), 0.0)
        measured_total = t.grf.sum(axis=1)
        total.append(grf_errors((even[:, :, None] * measured_total[:, None, :])[k], t.grf[k], m))
    rows = [[name, str(sum(e.size for e in v)), _f(float(np.concatenate(v).mean()))] for name, v in phases.items()]
    rows.append(["all frames (the benchmark's row)", str(sum(e.size for e in own)), _f(float(np.concatenate(own).mean()))])
    rows.append(["all frames, the measured split between the feet instead of the even one", "", _f(float(np.concatenate(split).mean()))])
    rows.append(["all frames, the measured total force instead of its own m (a_com - g)", "", _f(float(np.concatenate(total).mean()))])
    print(table(["frames", "count", "GRF error (N/kg)"], rows))
    print("\n### The analytical baseline with the hybrid's extra filter (q̃ low-passed again at 6 Hz)\n")
    rows = []
    for contact in ("measured", "kinematic"):
        for fc, label in ((None, "q̃ as it is (30 Hz)"), (6.0, "q̃ re-filtered at 6 Hz")):
            errs = score_all(lambda t, c=contact, f=fc: analytical_baseline(t, q=hybrid.smoothed_input(t, f), contact=c), ds.trials)
            s = pooled(errs)
            rows.append([f"{contact} contact", label, _f(s["com_acc"]), _f(s["grf"]), _f(s["torque"])])
    print(table(["contact", "input", "CoM acc. error (m/s²)", "GRF error (N/kg)", "joint torque error (N·m/kg)"], rows))
    print()


# ------------------------------------------------------------------------------ contact


def earlier_rule(t: BenchmarkTrial, q: np.ndarray, height_m: float = 0.1) -> np.ndarray:
    """The rule before 2026-11-22: a foot origin within 0.1 m of the trial's lowest foot origin."""
    from solver.benchmark.analytical import foot_origins

    y = foot_origins(t, q)[..., 1]
    return (y - y.min()) < height_m


def part_contact(ds: Dataset) -> None:
    print("### Kinematic contact against the plates' contact (benchmark frames)\n")
    rules = {
        "own lowest point within 0.5 s (in use)": lambda t: kinematic_contact(t, t.q),
        "0.1 m above the trial's lowest foot origin (earlier)": lambda t: earlier_rule(t, t.q),
    }
    rows = []
    for label, rule in rules.items():
        frames = feet = n = 0
        stairs = stairs_feet = stairs_n = 0
        for t in ds.trials:
            k = t.frames
            on = rule(t)[k]
            same = on == t.contact[k]
            frames += int(same.all(axis=1).sum())
            feet += int(same.sum())
            n += len(k)
            if t.subject == "stairdown":
                stairs += int(same.all(axis=1).sum())
                stairs_feet += int(same.sum())
                stairs_n += len(k)
        rows.append([label, f"{100 * frames / n:.0f} %", f"{100 * feet / (2 * n):.0f} %",
                     f"{100 * stairs / stairs_n:.0f} %, {100 * stairs_feet / (2 * stairs_n):.0f} %" if stairs_n else "-"])
    print(table(["rule", "frames with both feet right", "feet right (frame x foot)", "stair descent: frames, feet"], rows))
    print()


# ------------------------------------------------------------------------------ hybrid


def hybrid_predict(model: hybrid.TrainedContactSplit, t: BenchmarkTrial, *, gate: bool = True, com_from_forces: bool = False) -> Prediction:
    """:meth:`hybrid.TrainedContactSplit.predict` with its gate or CoM source switched."""
    total, q, qd, qdd = hybrid.total_force(t, model.cutoff_hz)
    sk = skeleton_for(t.model_path)
    g = np.asarray(sk.model.gravity.linear, dtype=float)
    share = model.shares(t)[:, :2]
    if gate:
        share = share * kinematic_contact(t, t.q)
    grf = share[:, :, None] * total[:, None, :]
    com_acc = grf.sum(axis=1) / sk.total_mass + g if com_from_forces else total / sk.total_mass + g
    grm = np.zeros_like(grf)
    return Prediction(com_acc=com_acc, grf=grf, grm=grm, tau=torques_from_feet(t, q, qd, qdd, grf, grm))


@contextlib.contextmanager
def without_indicator() -> Iterator[None]:
    """The hybrid's features without the kinematic contact indicator (its last feature)."""
    original, n = hybrid.contact_features, hybrid.FEATURES_PER_FOOT
    hybrid.contact_features = lambda t, q=None: original(t, q)[:, :-1]
    hybrid.FEATURES_PER_FOOT = n - 1
    try:
        yield
    finally:
        hybrid.contact_features, hybrid.FEATURES_PER_FOOT = original, n


@contextlib.contextmanager
def memoized() -> Iterator[None]:
    """The hybrid's per-trial features and total force computed once per trial (and
    cut-off) over all folds and variants: pure functions of the trial, so the numbers are
    unchanged and only the time is saved."""
    features, force = hybrid.contact_features, hybrid.total_force
    cf: dict[int, np.ndarray] = {}
    tf: dict[tuple[int, float | None], Any] = {}

    def contact_features(t: BenchmarkTrial, q: np.ndarray | None = None) -> np.ndarray:
        if q is not None:
            return features(t, q)
        if id(t) not in cf:
            cf[id(t)] = features(t)
        return cf[id(t)]

    def total_force(t: BenchmarkTrial, cutoff_hz: float | None = None) -> Any:
        key = (id(t), cutoff_hz)
        if key not in tf:
            tf[key] = force(t, cutoff_hz)
        return tf[key]

    hybrid.contact_features, hybrid.total_force = contact_features, total_force
    try:
        yield
    finally:
        hybrid.contact_features, hybrid.total_force = features, force


def select_cutoff_pooled(trials: Sequence[BenchmarkTrial], candidates: Sequence[float] = hybrid.CUTOFFS_HZ) -> tuple[float, dict[float, float]]:
    """:func:`hybrid.select_cutoff` with the training frames pooled (every frame counts the same)."""
    errors = {}
    for fc in candidates:
        e = [np.linalg.norm(t.grf[t.frames].sum(axis=1) - hybrid.total_force(t, fc)[0][t.frames], axis=1) / t.mass_kg for t in trials]
        errors[float(fc)] = float(np.concatenate(e).mean())
    return min(errors, key=errors.__getitem__), errors


@contextlib.contextmanager
def pooled_cutoff() -> Iterator[None]:
    original = hybrid.select_cutoff
    hybrid.select_cutoff = select_cutoff_pooled
    try:
        yield
    finally:
        hybrid.select_cutoff = original


def part_hybrid(ds: Dataset) -> None:
    with memoized():
        _part_hybrid(ds)


def _part_hybrid(ds: Dataset) -> None:
    print("### The hybrid, varied one setting at a time (leave-one-subject-out, kinematic inputs)\n")
    null = contextlib.nullcontext
    variants: list[tuple[str, dict[str, Any], Callable[[], Any], dict[str, Any]]] = [
        ("as adopted (cut-off chosen per fold, subjects weighted equally; gate; indicator feature; seed 0; 10 epochs)", {}, null, {}),
        ("seed 1", {"options": MlpOptions(seed=1)}, null, {}),
        ("seed 2", {"options": MlpOptions(seed=2)}, null, {}),
        ("5 epochs", {"options": MlpOptions(epochs=5)}, null, {}),
        ("20 epochs", {"options": MlpOptions(epochs=20)}, null, {}),
        ("without the gate (a foot the kinematic rule calls airborne may bear force)", {}, null, {"gate": False}),
        ("without the contact indicator feature (gate kept)", {}, without_indicator, {}),
        ("no extra filter (q̃ as it is, 30 Hz)", {"cutoffs_hz": (30.0,)}, null, {}),
        ("no extra filter, without the gate", {"cutoffs_hz": (30.0,)}, null, {"gate": False}),
        *((f"extra filter fixed at {fc:g} Hz", {"cutoffs_hz": (fc,)}, null, {}) for fc in (6.0, 8.0, 10.0, 15.0)),
        ("cut-off chosen with the training frames pooled", {}, pooled_cutoff, {}),
        ("CoM acceleration from the gated forces instead of the motion", {}, null, {"com_from_forces": True}),
    ]
    rows = []
    for label, train_kw, ctx, pred_kw in variants:
        t0 = time.perf_counter()
        with ctx():
            per_trial, models = loso(
                ds, lambda tr, te, kw=train_kw: hybrid.train_contact_split(tr, **kw),
                lambda m, t, kw=pred_kw: hybrid_predict(m, t, **kw),
            )
        s = pooled(per_trial)
        cut = sorted({m.cutoff_hz for m in models})
        rows.append([label, _f(s["grf"]), _f(s["com_acc"]), _f(pooled(per_trial, [RUN])["grf"]), ", ".join(f"{c:g}" for c in cut)])
        say(f"hybrid variant {label}: GRF {s['grf']:.3f} N/kg ({time.perf_counter() - t0:.0f} s)")
    print(table(["variant", "GRF error (N/kg)", "CoM acc. error (m/s²)", "run's GRF error (N/kg)", "cut-offs chosen (Hz)"], rows))
    print("\n### The hybrid trained on one subject, scored on another\n")
    rows = []
    for train_s, test_s in (("rajagopal2016_walk", "opencap_uhlrich2023"), ("opencap_uhlrich2023", "rajagopal2016_walk")):
        model = hybrid.train_contact_split(list(ds.of_subjects([train_s]).trials))
        for t in ds.of_subjects([test_s]).trials:
            h = summarize(score_trial(t, model.predict(t)))["grf"]
            k = summarize(score_trial(t, analytical_baseline(t, contact="kinematic")))["grf"]
            rows.append([train_s, f"{t.subject}/{t.trial}", _f(h), _f(k)])
    print(table(["trained on", "scored on", "hybrid GRF error (N/kg)", "analytical, kinematic contact (N/kg)"], rows))
    print()


# ------------------------------------------------------------------------------ mlp


def train_mlp_fold(options: MlpOptions) -> Callable[[list[BenchmarkTrial], list[BenchmarkTrial]], Any]:
    def train(tr: list[BenchmarkTrial], te: list[BenchmarkTrial]) -> Any:
        return train_mlp(tr, spec=FeatureSpec.common(tr + te), options=options)

    return train


def part_mlp(ds: Dataset) -> None:
    print("### The paper's MLP, varied one setting at a time (leave-one-subject-out, kinematic inputs)\n")
    variants = [
        ("as specified (512 sigmoid units, RMSprop 1e-4, batch 32, 10 epochs, 50-frame history every 5 frames, seed 0)", MlpOptions()),
        ("seed 1", MlpOptions(seed=1)),
        ("learning rate 1e-3", MlpOptions(learning_rate=1e-3)),
        ("a single frame as input (no history)", MlpOptions(history_frames=1, stride=1)),
        ("50 epochs", MlpOptions(epochs=50)),
    ]
    rows = []
    base: dict[str, FrameErrors] = {}
    for label, opts in variants:
        t0 = time.perf_counter()
        per_trial, _ = loso(ds, train_mlp_fold(opts))
        base = base or per_trial
        s = pooled(per_trial)
        rows.append([label, _f(s["grf"]), _f(s["com_acc"]), _f(s["torque"])])
        say(f"MLP variant {label}: GRF {s['grf']:.3f} N/kg ({time.perf_counter() - t0:.0f} s)")
    print(table(["variant", "GRF error (N/kg)", "CoM acc. error (m/s²)", "joint torque error (N·m/kg)"], rows))
    print("\n### More subjects: the four subjects of the first benchmark, folds of four against folds of six\n")
    four = ds.of_subjects(FOUR)
    per_four, _ = loso(four, train_mlp_fold(MlpOptions()))
    keys = list(per_four)
    rows = [["all four subjects' frames", str(sum(per_four[k].grf.size for k in keys)),
             _f(pooled(per_four)["grf"]), _f(pooled(base, keys)["grf"])]]
    rows += [[k, str(per_four[k].grf.size), _f(pooled(per_four, [k])["grf"]), _f(pooled(base, [k])["grf"])] for k in keys]
    ana = {c: pooled(score_all(lambda t, c=c: analytical_baseline(t, contact=c), four.trials)) for c in ("measured", "kinematic")}
    print(table(["scored frames", "frames", "MLP GRF error, trained on the other 3 (N/kg)", "MLP GRF error, trained on the other 5 (N/kg)"], rows))
    print(f"\nOn the same frames the analytical baseline: {_f(ana['measured']['grf'])} N/kg (measured contact), "
          f"{_f(ana['kinematic']['grf'])} (kinematic contact).\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/addb_bench_benchmark"))
    ap.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    ap.add_argument("--fresh", action="store_true", help="process the subjects again (else DIR/out is reused when complete)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    outs = ensure_processed(args.work, args.fresh)
    ds = load_dataset(outs, inputs="kinematic")
    say(f"dataset: {len(ds.subjects)} subjects, {len(ds.trials)} trials, {ds.n_frames} frames ({time.perf_counter() - t0:.0f} s)")
    print(f"Dataset: {len(ds.subjects)} subjects, {len(ds.trials)} trials, {ds.n_frames} scored frames (kinematic inputs).\n")
    for part in PARTS:
        if part in args.parts:
            globals()[f"part_{part}"](ds)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True, check=False).stdout.strip()
    say(f"done in {time.perf_counter() - t0:.0f} s (commit {commit})")


if __name__ == "__main__":
    main()
