"""Running the benchmark's methods over subject splits (what ``addb benchmark`` does).

Protocols (every one keeps each subject in one split):

* ``train`` given: the trained methods (the MLP and the hybrid's network) train on those
  subjects' trials and every method is scored on
  the dataset's subjects (none may be in both);
* ``split="loso"`` (default): leave-one-subject-out folds; each subject is scored by
  networks trained on all the others, and the table pools the scored frames of all subjects.
  This is the protocol for a dataset of a handful of subjects, where a single seeded
  test split would hold one subject;
* ``split="seeded"``: one seeded train/dev/test split (:func:`~.dataset.split_subjects`);
  every method is scored on the test subjects, the networks train on the train subjects
  and report their loss on the dev subjects.

The analytical baseline needs no training; it is scored on the same frames.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from solver.benchmark.analytical import analytical_baseline
from solver.benchmark.dataset import (
    BenchmarkError,
    Dataset,
    Split,
    leave_one_subject_out,
    split_subjects,
)
from solver.benchmark.evaluate import MethodResult, evaluate
from solver.benchmark.hybrid import train_contact_split
from solver.benchmark.metrics import FrameErrors, summarize
from solver.benchmark.mlp import FeatureSpec, MlpOptions, train_mlp
from solver.errors import listed

Progress = Callable[[str, float], None]

#: Methods of the benchmark.
METHODS = ("analytical", "mlp", "hybrid")
#: Table labels of the trained methods.
LABELS = {"mlp": "MLP", "hybrid": "hybrid (analytical force, MLP contact split)"}
#: Protocols without a separate training set.
SPLITS = ("loso", "seeded")


@dataclass(frozen=True)
class BenchmarkResult:
    """The table rows and how they were obtained.

    Attributes
    ----------
    rows
        One per method (and contact rule of the analytical baseline).
    protocol
        Description of the splits.
    folds
        The splits used (train/dev/test subjects of each).
    test_subjects
        Subjects whose frames are scored.
    """

    rows: tuple[MethodResult, ...]
    protocol: str
    folds: tuple[Split, ...]
    test_subjects: tuple[str, ...]
    extra: dict[str, Any] = field(default_factory=dict)


def make_folds(dataset: Dataset, *, split: str, seed: int, train: Dataset | None) -> tuple[list[Split], str]:
    """The splits of a protocol (see the module docstring) and its description.

    Raises
    ------
    BenchmarkError
        ``train`` is None and ``split`` is neither ``"loso"`` nor ``"seeded"``.
    """
    subjects = dataset.subjects
    if train is not None:
        fold = Split(tuple(train.subjects), (), tuple(subjects), name="given training subjects")
        return [fold], f"networks trained on {', '.join(train.subjects)}; scored on {', '.join(subjects)}"
    if split == "loso":
        return leave_one_subject_out(subjects), f"leave-one-subject-out over {len(subjects)} subjects (every subject scored once)"
    if split == "seeded":
        s = split_subjects(subjects, seed=seed)
        return [s], f"seeded split (seed {seed}): train {', '.join(s.train) or '-'}; dev {', '.join(s.dev) or '-'}; test {', '.join(s.test)}"
    raise BenchmarkError(f"unknown split {split!r} (use one of {SPLITS})")


def _analytical_row(dataset: Dataset, test: Sequence[str], contact: str) -> MethodResult:
    t0 = time.perf_counter()
    errors, per_trial = evaluate(lambda t: analytical_baseline(t, contact=contact), dataset.of_subjects(test).trials)
    return MethodResult(
        method=f"analytical ({contact} contact)",
        metrics=summarize(errors),
        per_trial=per_trial,
        n_frames=int(errors.grf.size),
        seconds=time.perf_counter() - t0,
        notes={"contact": contact},
    )


def _fit(method: str, tr: Sequence[Any], dv: Sequence[Any], te: Sequence[Any], options: MlpOptions, progress: Progress) -> Any:
    """A trained model of ``method`` ("mlp" or "hybrid"), with ``predict``, ``seconds``,
    ``n_train`` and ``history``."""
    if method == "mlp":
        spec = FeatureSpec.common(list(tr) + list(dv) + list(te))
        return train_mlp(tr, dv, spec=spec, options=options, progress=progress)
    return train_contact_split(tr, dv, options=options, progress=progress)


def _trained_row(
    method: str, dataset: Dataset, folds: Sequence[Split], train: Dataset | None, options: MlpOptions, say: Progress
) -> MethodResult:
    source = train if train is not None else dataset
    parts: list[FrameErrors] = []
    per_trial: dict[str, dict[str, float]] = {}
    fold_notes = []
    t0 = time.perf_counter()
    for i, fold in enumerate(folds):
        tr, dv = source.of_subjects(fold.train).trials, source.of_subjects(fold.dev).trials
        te = dataset.of_subjects(fold.test).trials
        if not tr:
            raise BenchmarkError(f"{fold.name}: no training subject for the {LABELS[method]} (give more subjects or --train)")
        model = _fit(method, tr, dv, te, options, lambda m, f, i=i, name=fold.name: say(f"{name}: {m}", (i + f) / len(folds)))
        errors, pt = evaluate(model.predict, te)
        parts.append(errors)
        per_trial.update(pt)
        fold_notes.append(
            {
                "fold": fold.name,
                "train": list(fold.train),
                "dev": list(fold.dev),
                "test": list(fold.test),
                "train_frames": model.n_train,
                "train_seconds": model.seconds,
                "loss": model.history,
                **({"cutoff_hz": model.cutoff_hz, "cutoff_errors": model.cutoff_errors} if method == "hybrid" else {}),
            }
        )
    pooled = FrameErrors.concatenate(parts)
    return MethodResult(
        method=LABELS[method],
        metrics=summarize(pooled),
        per_trial=per_trial,
        n_frames=int(pooled.grf.size),
        seconds=time.perf_counter() - t0,
        notes={
            "train_seconds": sum(f["train_seconds"] for f in fold_notes),
            "options": {k: getattr(options, k) for k in options.__dataclass_fields__},
            "folds": fold_notes,
        },
    )


def run_benchmark(
    dataset: Dataset,
    *,
    methods: Sequence[str] = ("analytical",),
    contacts: Sequence[str] = ("measured",),
    split: str = "loso",
    seed: int = 0,
    train: Dataset | None = None,
    mlp_options: MlpOptions | None = None,
    progress: Progress | None = None,
) -> BenchmarkResult:
    """Score ``methods`` on ``dataset`` (see the module docstring for the protocols).

    Parameters
    ----------
    dataset
        The subjects to score (and to train on, without ``train``).
    methods
        Any of ``"analytical"``, ``"mlp"`` and ``"hybrid"`` (:mod:`~solver.benchmark.hybrid`).
    contacts
        Contact rules of the analytical baseline, one row each (``"measured"``, ``"kinematic"``).
    split, seed
        Protocol without ``train``: ``"loso"`` or ``"seeded"``.
    train
        Training subjects of the MLP (disjoint from ``dataset``'s).
    mlp_options
        Hyper-parameters of the MLP and the hybrid's network (default: the paper's; seeded
        with ``seed``).
    progress
        Called with (message, fraction).

    Raises
    ------
    BenchmarkError
        An unknown method, no trial, a subject in both ``train`` and ``dataset``, or a fold
        without training subjects for a trained method.
    """
    say = progress or (lambda m, f: None)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise BenchmarkError(f"unknown method(s) {', '.join(unknown)} (use {', '.join(METHODS)})")
    if not dataset.trials:
        why = [f"{k.subject}/{k.trial}: {k.reason}" for k in dataset.skipped]  # as the report lists them
        raise BenchmarkError("no trial with force data to score" + (f"; skipped trials: {listed(why, 5, '; ')}" if why else ""))
    if train is not None:
        both = sorted(set(train.subjects) & set(dataset.subjects))
        if both:
            raise BenchmarkError(f"subject(s) {', '.join(both)} both in the training and the scored subjects")
    folds, protocol = make_folds(dataset, split=split, seed=seed, train=train)
    test = tuple(dict.fromkeys(s for f in folds for s in f.test))
    rows = []
    for method in methods:
        if method == "analytical":
            for contact in contacts:
                say(f"analytical baseline ({contact} contact)", 0.0)
                rows.append(_analytical_row(dataset, test, contact))
        else:
            opts = mlp_options or MlpOptions(seed=seed)
            rows.append(_trained_row(method, dataset, folds, train, opts, say))
    return BenchmarkResult(tuple(rows), protocol, tuple(folds), test)
