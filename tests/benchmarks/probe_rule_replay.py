"""Can the choice rule's thresholds, re-derived on the joint fit, give back what the
alternation names? Capture every draw's candidates once, then replay the choice under
other thresholds (a probe, run on demand; not a change of ``addb diagnose``).

    .venv/bin/python tests/benchmarks/probe_rule_replay.py capture [--sigma 0.1 | --alternation] --out CAPTURE.pkl -- BENCH_DIAGNOSE_ARGS ...
    .venv/bin/python tests/benchmarks/probe_rule_replay.py replay --derive CAPTURE.pkl ... --table TABLE.json ... [--check CAPTURE.pkl ... --table-check TABLE.json ...] [--confirm-registration GAIN]
    .venv/bin/python tests/benchmarks/probe_rule_replay.py live [--sigma 0.1 | --alternation] --values NAME=VALUE ... [--confirm-registration GAIN] -- BENCH_DIAGNOSE_ARGS ...
    .venv/bin/python tests/benchmarks/probe_rule_replay.py compare --table TABLE.json ... --with LIVE.json ... --label LABEL

``capture`` runs ``tests/benchmarks/bench_diagnose.py`` with the arguments after ``--`` in
this process, the joint fit with ``mass_sigma`` ``--sigma`` in the alternation's place (as
``bench_diagnose_joint.py`` does; with ``--alternation`` the fit the diagnosis judges on,
as it is), and records for each draw and each consistent synthetic
trial what :func:`solver.diagnose.core._diagnose` hands to the choice: every alternative's
cross-validated :class:`~solver.diagnose.selection.Evaluation` on the fitted motion, on the
marker-only motion and on the marker-only motion whitened with its own noise (the last
computed for every trial here, where the diagnosis computes it only when it needs it), the
blocks of frames, and the share of its held-out gain each alternative keeps on top of
another (:meth:`~solver.diagnose.selection.JointGains.kept_share`) for every ordered pair of
the best alternatives of the causes on one channel group, on each motion, and on the
marker-only motion for the pairs of the fitted motion (the tie-break). Each record is
pickled with the hidden effect's truth and the base's report as soon as its draw ends.

``replay`` runs the choice again on the records (:func:`solver.diagnose.selection.choose`,
:func:`~solver.diagnose.selection.best_per_cause`, :func:`solver.diagnose.core.choice_on_marker_motion`,
the product's own functions) with a :class:`~solver.diagnose.selection.ChoiceRule`, and
scores each draw with the benchmark's own check (:func:`tests.diagnose.effects.check`); the
thresholds are searched on the ``--derive`` draws (:func:`search`, coordinate ascent over
one and two thresholds at a time, and with ``--random N`` as many rules drawn at random from
the same grid) and checked on the ``--check`` draws.
With the rule as it is, every draw must come out as the capture's live run named it (the
replay says how many do not). A kept share the capture did not compute counts as not
computed (the rule then decides by scores and blocks); the replay counts such lookups.
The neutral bases stay those of the capture (built with the rule as it is): a rule that
the product took would build its own.

``live`` runs the benchmark with the joint fit (or ``--alternation``) and thresholds given
(``--values``) for every diagnosis, the neutral bases' included: the derived thresholds
measured as the product would.

``--confirm-registration GAIN`` (``replay`` and ``live``) tries one change of the rule's
structure rather than its thresholds (:func:`unconfirmed_dropped`): the plates' registration
is named from the fitted motion only when the marker-only motion confirms it, its relative
gain there at least GAIN (0: it does not make that motion's forces worse). A registration is
an error of the force recording, which the marker-only motion shows as well; on the joint fit
a mass misplaced in the model leaves a registration-like residue on the motion the forces
bent and none on the marker-only one. The replay prints the rule as it is, the rule with the
confirmation, and the confirmation with thresholds re-derived on top of it.

``compare`` puts ``live`` results (``--json`` of the runs) beside the table's, draw by draw
(:func:`compare`).
"""

from __future__ import annotations

import argparse
import itertools
import pickle
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from solver.diagnose import core
from solver.diagnose.report import _params
from solver.diagnose.selection import ChoiceRule, Evaluation, best_per_cause, channels, choose
from solver.diagnose.selection import confirmed as confirmed_by_rule

Key = tuple[str, str | None]


def _key(ev: Evaluation) -> Key:
    return (ev.cause, ev.choice)


@dataclass
class Record:
    """What one diagnosis handed to its choice, and what its live run chose."""

    fitted: list[Evaluation]
    marker_only: list[Evaluation]
    own_noise: list[Evaluation] | None
    blocks: Any
    kept: dict[tuple[str, Key, Key], float | None] = field(default_factory=dict)
    chosen: Key | None = None
    kind: str = ""  # "draw" or "synthetic"
    trial: str = ""
    seed: int = 0
    hidden: Any = None  # (cause, choice, truth)
    report: dict[str, Any] | None = None  # the live run's report (its settings, candidates)
    base_report: dict[str, Any] | None = None


def _pairs(evaluations: list[Evaluation]) -> Iterator[tuple[Evaluation, Evaluation]]:
    """Ordered pairs of the best alternatives of the causes (by score) on one channel group."""
    best = best_per_cause(evaluations)
    for a, b in itertools.permutations(best, 2):
        if channels(a.cause) == channels(b.cause):
            yield a, b


def unconfirmed_dropped(fitted: list[Evaluation], marker_only: list[Evaluation], min_gain: float | None) -> list[Evaluation]:
    """``fitted`` without the alternatives of a cause confirmed on the marker-only motion (the
    plates' registration) whose twin in ``marker_only`` has a relative gain below ``min_gain``:
    :func:`solver.diagnose.selection.confirmed`, the product's own rule, with
    :attr:`~solver.diagnose.selection.ChoiceRule.min_confirming_gain` ``min_gain``; None:
    ``fitted`` as it is. An alternative without a twin stays."""
    if min_gain is None:
        return fitted
    return confirmed_by_rule(fitted, {_key(e): e for e in marker_only}, ChoiceRule(min_confirming_gain=min_gain))


def confirmed(records: list[Record], min_gain: float | None) -> list[Record]:
    """``records`` with :func:`unconfirmed_dropped` applied to each one's fitted motion
    (copies; None: ``records`` as they are)."""
    if min_gain is None:
        return records
    return [replace(r, fitted=unconfirmed_dropped(r.fitted, r.marker_only, min_gain)) for r in records]


class _Capture:
    """The wrappers put in :mod:`solver.diagnose.core`'s place while the benchmark runs."""

    def __init__(self) -> None:
        self.current: Record | None = None
        self._inside = False
        self._choose = core.choose
        self._on_markers = core.choice_on_marker_motion

    def choose(self, ranked, rule=None, blocks=None, alternatives=None, kept=None, tie_break=None):  # type: ignore[no-untyped-def]
        if self._inside:  # the calls of choice_on_marker_motion: recorded there
            return self._choose(ranked, rule, blocks, alternatives, kept, tie_break)
        rec = Record(fitted=list(alternatives or []), marker_only=[], own_noise=None, blocks=blocks)
        self.current = rec
        for a, b in _pairs(rec.fitted):
            rec.kept["fitted", _key(a), _key(b)] = kept(a, b) if kept else None
            rec.kept["tie", _key(a), _key(b)] = tie_break(a, b) if tie_break else None
        return self._choose(ranked, rule, blocks, alternatives, kept, tie_break)

    def choice_on_marker_motion(self, chosen, evaluations_ik, rule, blocks, kept=None, own_noise=None):  # type: ignore[no-untyped-def]
        rec = self.current
        assert rec is not None, "choice_on_marker_motion before choose"
        rec.marker_only = list(evaluations_ik)
        force = [e for e in evaluations_ik if core.cause(e.cause).acts_on_forces]
        for a, b in _pairs(force):
            rec.kept["marker-only", _key(a), _key(b)] = kept(a, b) if kept else None
        own = own_noise() if own_noise is not None else None
        if own is not None:
            rec.own_noise = list(own[0])
            force_own = [e for e in own[0] if core.cause(e.cause).acts_on_forces]
            for a, b in _pairs(force_own):
                rec.kept["own", _key(a), _key(b)] = own[1](a, b)
        self._inside = True
        try:
            out = self._on_markers(chosen, evaluations_ik, rule, blocks, kept, (lambda: own) if own is not None else None)
        finally:
            self._inside = False
        rec.chosen = _key(out[0]) if out is not None else (_key(chosen) if chosen is not None else None)
        return out


def _benchmark_on(sigma: float | None) -> Any:
    """``tests/benchmarks/bench_diagnose.py`` (the module), with the dynamics stage running the
    joint fit at ``mass_sigma`` ``sigma`` where it runs the alternation
    (:func:`bench_diagnose_joint.joint_in_place`); None: the alternation, as it is."""
    import bench_diagnose  # this folder
    import bench_diagnose_joint  # this folder

    import solver.dynamics.stage as stage_module

    if sigma is not None:
        stage_module.fit_dynamics = bench_diagnose_joint.joint_in_place(sigma)  # type: ignore[assignment]
    return bench_diagnose


def _run(bench_diagnose: Any, passed: list[str]) -> None:
    """The benchmark's command line with the arguments ``passed``, in this process."""
    sys.argv = [str(Path(bench_diagnose.__file__)), *passed]
    bench_diagnose.main()


def capture(sigma: float | None, out: Path, passed: list[str]) -> None:
    """Run the benchmark with the joint fit (``mass_sigma`` ``sigma``; None: the
    alternation the diagnosis judges on, as it is) and pickle a :class:`Record` per draw and
    synthetic trial to ``out`` (one pickle after another, as each ends)."""
    from tests.diagnose.effects import check as live_check

    bench_diagnose = _benchmark_on(sigma)
    cap = _Capture()
    core.choose = cap.choose  # type: ignore[assignment]
    core.choice_on_marker_motion = cap.choice_on_marker_motion  # type: ignore[assignment]
    out.parent.mkdir(parents=True, exist_ok=True)
    sink = out.open("wb")
    seeds: dict[str, int] = {}

    def check(hidden, report, base_report):  # type: ignore[no-untyped-def]
        res = live_check(hidden, report, base_report)
        rec = cap.current
        if rec is not None:
            rec.kind, rec.hidden, rec.report, rec.base_report = "draw", (hidden.cause, hidden.choice, hidden.truth), report, base_report
            pickle.dump(rec, sink)
            sink.flush()
        cap.current = None
        return res

    live_diagnose_json = bench_diagnose.diagnose_json

    def diagnose_json(subject, trial, *extra):  # type: ignore[no-untyped-def]
        report = live_diagnose_json(subject, trial, *extra)
        rec = cap.current
        if rec is not None:
            rec.kind, rec.trial, rec.report = "synthetic", trial, report
            rec.seed = seeds[trial] = seeds.get(trial, -1) + 1
            pickle.dump(rec, sink)
            sink.flush()
        cap.current = None
        return report

    bench_diagnose.check = check  # type: ignore[assignment]
    bench_diagnose.diagnose_json = diagnose_json  # type: ignore[assignment]
    if "--json" not in passed:  # the replay labels each draw from it
        passed = [*passed, "--json", str(out.with_suffix(".json"))]
    elif Path(passed[passed.index("--json") + 1]) != out.with_suffix(".json"):
        raise SystemExit(f"--json must be {out.with_suffix('.json')} (beside the capture), or left out")
    try:
        _run(bench_diagnose, passed)
    finally:
        sink.close()


class _Unpickler(pickle.Unpickler):
    """Reads records pickled by ``capture`` run as a script (class ``__main__.Record``)."""

    def find_class(self, module: str, name: str) -> Any:
        if name == "Record" and module in ("__main__", __name__):
            return Record
        return super().find_class(module, name)


def live(sigma: float | None, values: dict[str, float], passed: list[str], min_gain: float | None = None) -> None:
    """Run the benchmark with the joint fit (``mass_sigma`` ``sigma``; None: the alternation
    the diagnosis judges on, as it is) and the thresholds ``values`` (names of
    :data:`SEARCH`) in the rule's place for every diagnosis of the run, the neutral bases'
    included: what a product that took them would measure. ``min_gain``: the confirmation of
    the registration on the marker-only motion (:func:`unconfirmed_dropped`; None: none)."""
    bench_diagnose = _benchmark_on(sigma)
    rule = rule_of(values)
    diagnose = core._diagnose

    def with_rule(processed, inputs, options, say):  # type: ignore[no-untyped-def]
        return diagnose(processed, inputs, replace(options, rule=rule), say)

    core._diagnose = with_rule  # type: ignore[assignment]
    if min_gain is not None:
        _confirm_in_place(min_gain)
    _run(bench_diagnose, passed)


def _confirm_in_place(min_gain: float) -> None:
    """Put :func:`unconfirmed_dropped` in :mod:`solver.diagnose.core`'s choice on the fitted
    motion: ``_diagnose`` evaluates the fitted motion, then the marker-only one (each
    evaluation then marked ``"marker-only"``), then chooses among the fitted motion's
    alternatives, which the wrapper filters with the latest marker-only evaluations (the
    ranking rebuilt from what is left). The choices on the marker-only motion, inside
    :func:`~solver.diagnose.core.choice_on_marker_motion`, pass as they are."""
    evaluate, choose = core.evaluate, core.choose
    latest: list[list[Evaluation]] = [[]]

    def evaluating(*args, **kwargs):  # type: ignore[no-untyped-def]
        out = evaluate(*args, **kwargs)
        latest[0] = out[2]
        return out

    def choosing(ranked, rule=None, blocks=None, alternatives=None, kept=None, tie_break=None):  # type: ignore[no-untyped-def]
        alternatives = list(alternatives or [])
        if alternatives and all(e.motion == "fitted" for e in alternatives):
            marker_only = [e for e in latest[0] if e.motion == "marker-only"]
            alternatives = unconfirmed_dropped(alternatives, marker_only, min_gain)
            ranked = best_per_cause(alternatives, rule)
        return choose(ranked, rule, blocks, alternatives, kept, tie_break)

    core.evaluate = evaluating  # type: ignore[assignment]
    core.choose = choosing  # type: ignore[assignment]


def compare(table: list[Path], results: list[Path], label: str) -> str:
    """Markdown: per cause, the draws within tolerance in the table's ``--json`` files and in
    ``results`` (a ``live`` run's), side by side, and every draw whose named cause or verdict
    differs (:func:`bench_diagnose_joint.compare`, its second column named ``label``).

    Raises
    ------
    SystemExit
        ``results`` holds a draw the table has not, or leaves out a draw of a cause it holds.
    """
    import bench_diagnose_joint  # this folder

    return bench_diagnose_joint.compare(table, results, sigma=0.1, label=label)


def _values(items: list[str]) -> dict[str, float]:
    """``NAME=VALUE`` items (names of :data:`SEARCH`) -> values.

    Raises
    ------
    SystemExit
        An item that is not ``NAME=NUMBER`` with a name of :data:`SEARCH`.
    """
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = None
        if name not in SEARCH or number is None:
            raise SystemExit(f"--values: {item!r} is not NAME=NUMBER with NAME one of {', '.join(SEARCH)}")
        out[name] = number
    return out


def load(paths: list[Path]) -> list[Record]:
    """Every record of the capture files, in order (a file cut short by a capture still
    running, or stopped, gives the records before the cut), each draw labelled with its
    trial and seed from the benchmark's ``--json`` beside it (``CAPTURE.json``: the row of
    the same cause and truth).

    Raises
    ------
    SystemExit
        A draw whose row the ``--json`` beside its capture does not hold.
    """
    import json

    out: list[Record] = []
    for p in paths:
        bench = json.loads(p.with_suffix(".json").read_text()) if p.with_suffix(".json").exists() else {"rows": [], "complete": True}
        with p.open("rb") as f:
            while True:
                try:
                    rec = _Unpickler(f).load()
                except (EOFError, pickle.UnpicklingError):
                    break
                if rec.kind == "draw":
                    truth = json.loads(json.dumps(rec.hidden[2], default=str))
                    row = next((r for r in bench["rows"] if r["cause"] == rec.hidden[0] and r.get("truth") == truth), None)
                    if row is None and not bench.get("complete", True):
                        break  # a capture still running: its row is not written yet
                    if row is None:
                        raise SystemExit(f"{p.with_suffix('.json')}: no row of {rec.hidden[0]} with truth {rec.hidden[2]}")
                    rec.trial, rec.seed = row["trial"], row["seed"]
                out.append(rec)
    return out


class Lookup:
    """Kept shares from a record; a pair it has not counts as not computed."""

    def __init__(self, rec: Record, motion: str, misses: list[int]) -> None:
        self.rec, self.motion, self.misses = rec, motion, misses

    def __call__(self, a: Evaluation, b: Evaluation) -> float | None:
        k = (self.motion, _key(a), _key(b))
        if k not in self.rec.kept:
            self.misses[0] += 1
            return None
        return self.rec.kept[k]


def replay(rec: Record, rule: ChoiceRule, misses: list[int]) -> Evaluation | None:
    """The evaluation :func:`solver.diagnose.core._diagnose`'s choice names under ``rule``."""
    twins = {_key(e): e for e in rec.marker_only}
    tie = Lookup(rec, "tie", misses)

    def on_marker_motion(best: Evaluation, rival: Evaluation) -> float | None:
        if _key(best) not in twins or _key(rival) not in twins:
            return None
        return tie(best, rival)

    chosen, _ = choose(best_per_cause(rec.fitted, rule), rule, rec.blocks, rec.fitted, Lookup(rec, "fitted", misses), on_marker_motion)
    own = rec.own_noise
    on_markers = core.choice_on_marker_motion(
        chosen, rec.marker_only, rule, rec.blocks, Lookup(rec, "marker-only", misses),
        (lambda: (own, Lookup(rec, "own", misses))) if own is not None else None,
    )
    return on_markers[0] if on_markers is not None else chosen


def score(records: list[Record], rule: ChoiceRule) -> dict[str, Any]:
    """Per cause, draws within tolerance; false alarms; replayed choices unlike the live run's."""
    from tests.diagnose.effects import Hidden, check

    within: dict[str, int] = {}
    draws: dict[str, int] = {}
    alarms = 0
    unlike = 0
    misses = [0]
    verdicts: dict[tuple[str, str, int], tuple[Key | None, bool]] = {}
    for rec in records:
        got = replay(rec, rule, misses)
        key = _key(got) if got is not None else None
        if rec.kind == "synthetic":
            alarms += got is not None
            unlike += key != rec.chosen
            continue
        cause_name, choice, truth = rec.hidden
        modified = dict(rec.report or {})
        modified["chosen"] = got.cause if got is not None else None
        modified["chosen_parameters"] = _params(got.parameters) if got is not None else None
        res = check(Hidden(cause_name, choice, truth), modified, rec.base_report or {})
        draws[cause_name] = draws.get(cause_name, 0) + 1
        within[cause_name] = within.get(cause_name, 0) + bool(res["within_tolerance"])
        unlike += key != rec.chosen
        verdicts[cause_name, rec.trial, rec.seed] = (key, bool(res["within_tolerance"]))
    return {"within": within, "draws": draws, "alarms": alarms, "unlike": unlike, "misses": misses[0], "verdicts": verdicts}


#: The statistical thresholds searched (:class:`~solver.diagnose.selection.ChoiceRule`), each
#: over these values; the sizes worth naming (``min_effect``, ``max_effect``) are physical
#: and stay. ``registration_gain`` and ``shift_gain`` are the plates' registration's and a
#: plate shift's own ``min_relative_gain`` (the rule's default for them).
SEARCH: dict[str, tuple[float, ...]] = {
    "min_relative_gain": (0.05, 0.075, 0.1, 0.125, 0.15, 0.2),
    "registration_gain": (0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3),
    "shift_gain": (0.03, 0.05, 0.075, 0.1, 0.15, 0.2),
    "min_folds_improved": (0.6, 0.8, 1.0),
    "runner_up_ratio": (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
    "paired_t": (1.0, 1.5, 2.0, 2.5, 3.0, 4.0),
    "paired_fraction": (0.5, 0.6, 0.7, 0.8),
    "min_t": (1.5, 2.0, 2.5, 3.0, 4.0),
    "kept_share": (0.5, 0.6, 0.7, 0.8, 0.9),
    "contained_share": (0.0, 0.05, 0.1, 0.2, 0.3),
}


def rule_of(values: dict[str, float]) -> ChoiceRule:
    """A :class:`ChoiceRule` with ``values`` (names of :data:`SEARCH`) set, the rest as it is."""
    base = ChoiceRule()
    own = dict(base.relative_gain_of)
    kw = {k: v for k, v in values.items() if k not in ("registration_gain", "shift_gain")}
    if "registration_gain" in values:
        own["plate_registration"] = values["registration_gain"]
    if "shift_gain" in values:
        own["plate_position_offset"] = values["shift_gain"]
    return replace(base, relative_gain_of=own, **kw)


def current_values() -> dict[str, float]:
    """The values of :data:`SEARCH`'s names in the rule as it is."""
    r = ChoiceRule()
    out = {k: float(getattr(r, k)) for k in SEARCH if hasattr(r, k)}
    out["registration_gain"] = r.relative_gain_needed("plate_registration")
    out["shift_gain"] = r.relative_gain_needed("plate_position_offset")
    return out


def table_rows(paths: list[Path], records: list[Record]) -> dict[str, int]:
    """Per cause, the draws of ``records`` within tolerance in the benchmark's ``--json``
    files (the alternation's results of the same draws).

    Raises
    ------
    SystemExit
        A draw of ``records`` the files do not hold.
    """
    import json

    rows = {}
    for p in paths:
        rows.update({(r["cause"], r["trial"], r["seed"]): bool(r["within_tolerance"]) for r in json.loads(p.read_text())["rows"]})
    out: dict[str, int] = {}
    for rec in records:
        if rec.kind != "draw":
            continue
        k = (rec.hidden[0], rec.trial, rec.seed)
        if k not in rows:
            raise SystemExit(f"{', '.join(map(str, paths))}: no row of {k}")
        out[k[0]] = out.get(k[0], 0) + rows[k]
    return out


def table_alarms(paths: list[Path]) -> str | None:
    """False alarms of the consistent synthetic trials in the ``--json`` files, "N of M"
    (None: none ran)."""
    import json

    trials = [t for p in paths for t in json.loads(p.read_text()).get("synthetic") or []]
    return f"{sum(t['chosen'] is not None for t in trials)} of {len(trials)}" if trials else None


def objective(s: dict[str, Any], target: dict[str, int]) -> tuple[int, int, int]:
    """What the search maximizes, in order: no false alarm, the rows' shortfall against
    ``target`` (0 when every row reaches it), the draws within tolerance."""
    short = sum(min(0, s["within"].get(c, 0) - n) for c, n in target.items())
    return (-s["alarms"], short, sum(s["within"].values()))


def search(records: list[Record], target: dict[str, int], sweeps: int = 4, say: Callable[[str], None] = print) -> dict[str, float]:
    """Coordinate ascent of :func:`objective` over :data:`SEARCH` from the rule as it is:
    each sweep tries every value of each threshold with the others held, then every pair of
    values of every two thresholds, keeping each change that raises the objective (the
    earlier one on a tie), until a sweep changes nothing (at most ``sweeps``)."""
    values = current_values()
    best = objective(score(records, rule_of(values)), target)
    say(f"rule as it is: {best}")

    def tries() -> Iterator[dict[str, float]]:
        for name, grid in SEARCH.items():
            for v in grid:
                yield {name: v}
        for (a, ga), (b, gb) in itertools.combinations(SEARCH.items(), 2):
            for va, vb in itertools.product(ga, gb):
                yield {a: va, b: vb}

    for sweep in range(sweeps):
        changed = False
        for change in tries():
            trial = {**values, **change}
            if trial == values:
                continue
            got = objective(score(records, rule_of(trial)), target)
            if got > best:
                best, values, changed = got, trial, True
                say(f"sweep {sweep + 1}: " + ", ".join(f"{k} = {v:g}" for k, v in change.items()) + f": {got}")
        if not changed:
            break
    return values


def random_search(records: list[Record], target: dict[str, int], n: int, seed: int) -> tuple[tuple[int, int, int], dict[str, float], dict[int, int]]:
    """``n`` rules drawn at random from the grid of :data:`SEARCH` (every threshold's value
    uniformly, ``random.Random(seed)``): the best :func:`objective` and its thresholds (the
    first drawn on a tie), and how many rules without a false alarm leave each shortfall."""
    import random

    rng = random.Random(seed)
    best: tuple[tuple[int, int, int], dict[str, float]] | None = None
    shortfalls: dict[int, int] = {}
    for _ in range(n):
        values = {k: rng.choice(grid) for k, grid in SEARCH.items()}
        got = objective(score(records, rule_of(values)), target)
        if got[0] == 0:
            shortfalls[got[1]] = shortfalls.get(got[1], 0) + 1
        if best is None or got > best[0]:
            best = (got, values)
    assert best is not None
    return best[0], best[1], dict(sorted(shortfalls.items(), reverse=True))


def _report(parts: list[tuple[str, dict[str, int], dict[str, int], str | None]]) -> str:
    causes = list(parts[0][2])
    head = "| cause | draws | " + " | ".join(p[0] for p in parts) + " |"
    lines = [head, "| --- | ---: |" + " ---: |" * len(parts)]
    for c in causes:
        lines.append(f"| {c} | {parts[0][2][c]} | " + " | ".join(str(p[1].get(c, 0)) for p in parts) + " |")
    lines.append("| false alarms (consistent trials) | | " + " | ".join("—" if p[3] is None else str(p[3]) for p in parts) + " |")
    return "\n".join(lines)


def _section(title: str, table_label: str, table: dict[str, int], table_alarms: str | None, records: list[Record],
             columns: list[tuple[str, dict[str, Any]]]) -> str:
    """One set of draws: the table's rows beside the replay's ``columns`` (label, :func:`score`;
    the first the rule as it is, the last the re-derived rule), and the draws the last changes
    against the first (false alarms "N of M", or a dash where no consistent trial was
    captured)."""
    n_syn = sum(r.kind == "synthetic" for r in records)
    draws = columns[0][1]["draws"]
    parts = [(table_label, table, draws, table_alarms)]
    parts += [(label, s["within"], draws, f"{s['alarms']} of {n_syn}" if n_syn else None) for label, s in columns]
    what = "thresholds change" if len(columns) == 2 else "rule changes against the rule as it is"
    return f"{title}\n\n{_report(parts)}\n\nDraws the re-derived {what} (named cause, within tolerance):\n\n" + _flips(columns[0][1], columns[-1][1])


def _named(key: Key | None) -> str:
    return "None" if key is None else key[0] + (f" {key[1]}" if key[1] else "")


def _flips(now: dict[str, Any], new: dict[str, Any]) -> str:
    """The draws whose named cause or verdict the re-derived thresholds change."""
    out = []
    for k, (a, ok_a) in sorted(now["verdicts"].items(), key=lambda kv: (kv[0][0], kv[0][2])):
        b, ok_b = new["verdicts"][k]
        if (a, ok_a) != (b, ok_b):
            out.append(f"- {k[0]}, {k[1]} draw {k[2]}: {_named(a)} ({'yes' if ok_a else 'no'}) -> {_named(b)} ({'yes' if ok_b else 'no'})")
    return "\n".join(out) if out else "(none)"


def main() -> None:
    argv = sys.argv[1:]
    passed = argv[argv.index("--") + 1 :] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    c = sub.add_parser("capture")
    c.add_argument("--sigma", type=float, default=0.1, help="mass_sigma of the joint fit judged on")
    c.add_argument("--alternation", action="store_true", help="judge on the alternation, as addb diagnose does (no --sigma)")
    c.add_argument("--out", type=Path, required=True, help="capture file (pickles)")
    v = sub.add_parser("live")
    v.add_argument("--sigma", type=float, default=0.1, help="mass_sigma of the joint fit judged on")
    v.add_argument("--alternation", action="store_true", help="judge on the alternation, as addb diagnose does (no --sigma)")
    v.add_argument("--values", nargs="+", default=[], help="thresholds NAME=VALUE (names of SEARCH), the others as they are")
    r = sub.add_parser("replay")
    r.add_argument("--derive", type=Path, nargs="+", required=True, help="captures the thresholds are derived on")
    r.add_argument("--table", type=Path, nargs="+", required=True, help="the alternation's --json results of the same draws (the rows to reach)")
    r.add_argument("--check", type=Path, nargs="*", default=[], help="captures of other draws, to check the derived thresholds on")
    r.add_argument("--table-check", type=Path, nargs="*", default=[], help="the alternation's --json results of the --check draws")
    r.add_argument("--random", type=int, default=0, help="also this many rules drawn at random from the grid")
    r.add_argument("--fit-label", default="joint fit", help="the captures' fit, for the columns' headings")
    r.add_argument("--seed", type=int, default=1, help="seed of --random")
    m = sub.add_parser("compare")
    m.add_argument("--table", type=Path, nargs="+", required=True, help="the table's --json results")
    m.add_argument("--with", dest="results", type=Path, nargs="+", required=True, help="--json results of live runs")
    m.add_argument("--label", required=True, help="the live runs' column heading")
    for sp in (r, v):
        sp.add_argument("--confirm-registration", type=float, default=None, metavar="GAIN",
                        help="name the plates' registration from the fitted motion only when its relative gain on the marker-only motion is at least GAIN")
    args = ap.parse_args(own)
    if args.command == "capture":
        capture(None if args.alternation else args.sigma, args.out, passed)
        return
    if args.command == "compare":
        print(compare(args.table, args.results, args.label))
        return
    if args.command == "live":
        live(None if args.alternation else args.sigma, _values(args.values), passed, args.confirm_registration)
        return
    as_captured = {"derive": load(args.derive), "check": load(args.check)}
    target = table_rows(args.table, as_captured["derive"])
    now = {k: score(recs, ChoiceRule()) for k, recs in as_captured.items()}
    for name, recs in as_captured.items():
        if recs:
            print(f"{name}: {len(recs)} records; the rule as it is: {now[name]['unlike']} replayed choices unlike the live run's, "
                  f"{now[name]['misses']} kept shares not captured")
    gain = args.confirm_registration
    derive, check = confirmed(as_captured["derive"], gain), confirmed(as_captured["check"], gain)
    if gain is not None:
        print(f"the registration confirmed on the marker-only motion (relative gain at least {gain:g} there); thresholds re-derived on top of it")
    values = search(derive, target, say=lambda m: print("  " + m))
    if args.random:
        got, drawn, shortfalls = random_search(derive, target, args.random, args.seed)
        print(f"  {args.random} rules drawn at random from the same grid (seed {args.seed}): the best {got}; rules without a false "
              "alarm by shortfall against the table: " + ", ".join(f"{k}: {v}" for k, v in shortfalls.items()))
        if got > objective(score(derive, rule_of(values)), target):
            values = drawn
            print("  (the random draw's best is taken)")
    start = current_values()
    print("\nthresholds: " + ", ".join(f"{k} {start[k]:g} -> {v:g}" if v != start[k] else f"{k} {v:g}" for k, v in values.items()) + "\n")
    rule = rule_of(values)

    def columns(name: str, recs: list[Record]) -> list[tuple[str, dict[str, Any]]]:
        out = [(f"{args.fit_label}, rule as it is", now[name])]
        if gain is not None:
            out.append((f"{args.fit_label}, confirmed", score(recs, ChoiceRule())))
        return [*out, (f"{args.fit_label}, {'confirmed, ' if gain is not None else ''}re-derived", score(recs, rule))]

    print(_section("**draws the thresholds are derived on**", "alternation (the table)", target, table_alarms(args.table),
                   derive, columns("derive", derive)))
    if check:
        print("\n" + _section("**other draws (checked, not derived on)**", "alternation", table_rows(args.table_check, check),
                                table_alarms(args.table_check), check, columns("check", check)))


if __name__ == "__main__":
    main()
