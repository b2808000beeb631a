"""Probe: the diagnosis on the joint fit with some force-side causes on the whole-motion profile.

    .venv/bin/python tests/benchmarks/probe_hybrid_currency.py [--sigma 0.1] [--motion-causes NAME ...] [--segment-on-residuals] [--channel-gain] [--fitted-motion-only] -- BENCH_DIAGNOSE_ARGS ...
    .venv/bin/python tests/benchmarks/probe_hybrid_currency.py [--sigma 0.1] [--motion-causes NAME ...] [--segment-on-residuals] [--channel-gain] [--fitted-motion-only] --compare DEFAULT.json ... --with PROBE.json ...

A probe for issue 29's second gap (the diagnosis' rules re-derived on the joint mass fit,
solver/diagnose/judged_fit.py), not a change of ``addb diagnose``. It is
``probe_motion_currency.py`` (this folder) with the currency chosen cause by cause: only the
causes named by ``--motion-causes`` (default: the plates' shift and registration,
``plate_position_offset`` and ``plate_registration``) are scored on the rows of the
whole-motion profile with the idle plates' rows appended, their relative gain against their
own channels' rows; the others (by default the force delay, the body mass and the plates'
zero drift and gain) stay on the translation profile, as ``addb diagnose`` scores them.
Two causes in different currencies are not fitted together (their rows differ: no kept
share, :func:`solver.diagnose.selection.joint_held_out` returns None); they are compared by
their scores and paired blocks of frames alone. With ``--segment-on-residuals``,
``segment_mass_distribution`` is scored on the whole-motion rows too and competes on the
residual channels, so a plate's shift and a mass redistribution are fitted together. With
``--channel-gain`` a moved cause's relative gain is the held-out decrease of its channels'
own rows (the residual and idle plates' rows, after the joint refit of the cause and the
motion) over their reference cost (:class:`ChannelEvaluation`), a share of at most 1 as on
the translation profile; its score stays the whole profiled cost's decrease. With
``--fitted-motion-only`` the moved causes are scored on the whole-motion rows on the fitted
motion only; on the marker-only motion (:func:`solver.diagnose.core.choice_on_marker_motion`,
the motion the markers alone decide) they keep the translation profile, since re-optimizing
the whole motion there would let the forces reshape it.

Why that split (tests/benchmarks/RESULTS.md, block ``diagnose-currency-compare``): with every
force-side cause on the whole-motion profile, the plates' rows gain on the treadmill run
(a belt's shift and registration named in all 10 of its draws) while the body mass and the
delay lose there, where the motion takes up what the run's large forces leave on the
residual rows. Every threshold of :class:`solver.diagnose.selection.ChoiceRule` is left as it is.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
import probe_motion_currency as currency  # this folder
from numpy.typing import NDArray

from solver.diagnose import core, selection
from solver.diagnose.candidates import Context

#: Cause name -> its module (solver/diagnose/causes/<name>.py), for the causes that may move
#: to the whole-motion rows.
MOVABLE = {
    name: importlib.import_module(f"solver.diagnose.causes.{name}")
    for name in (
        "force_time_offset",
        "body_mass",
        "plate_force_offset",
        "plate_force_gain",
        "plate_position_offset",
        "plate_registration",
    )
}
SEGMENTS = importlib.import_module("solver.diagnose.causes.segment_mass_distribution")
DEFAULT_MOTION_CAUSES = ("plate_position_offset", "plate_registration")


class ChannelEvaluation(selection.Evaluation):
    """An evaluation whose relative gain is the held-out decrease of its channels' own rows.

    On the whole-motion rows a cause's held-out gain ``gain`` (its score's) is the decrease
    of the whole profiled cost: the residual rows, every marker's rows and the motion's
    prior, re-balanced by the motion's refit. Over the reference cost of the residual and
    idle rows alone it can exceed 1 (block ``diagnose-currency-compare``). Here the
    relative gain is ``channel_gain`` (those rows' own held-out decrease, after the joint
    refit of the cause and the motion) over their reference cost, as on the translation
    profile, whose rows are the channels' rows and nothing else.
    """

    channel_gain: float = 0.0

    @property
    def relative_gain(self) -> float:
        return float(self.channel_gain / self.reference) if self.reference > 0 else 0.0


def _channel_rows(cls: type) -> None:
    """Give the whole-motion alternatives of ``cls`` a way to read their channels' cost from rows."""
    own = cls.alternatives

    def alternatives(self, ctx: Context, full):  # type: ignore[no-untyped-def]
        out = own(self, ctx, full)
        for alt in out:
            if getattr(alt, "channel_costs", None) is not None:
                alt.channel_of = lambda rows, ctx=ctx: currency.channel_costs(ctx, rows)
        return out

    cls.alternatives = alternatives


def _cross_validate(alt, folds: NDArray[np.intp]) -> selection.Evaluation:  # type: ignore[no-untyped-def]
    """``probe_motion_currency``'s cross-validation; with ``--channel-gain`` (``alt.channel_of``
    set) a :class:`ChannelEvaluation` whose relative gain is the channels' own decrease."""
    ev = currency._cross_validate(alt, folds)
    channel_of = getattr(alt, "channel_of", None)
    if channel_of is None:
        return ev
    ref = np.asarray(alt.channel_costs)
    after = np.array(ref)
    for f in range(int(folds.max()) + 1):
        test = folds == f
        after[test] = channel_of(alt.rows(alt.solve(~test)))[test]
    drop = ref - after
    ev.__class__ = ChannelEvaluation
    ev.channel_gain = float(np.sum(drop if alt.acts_on is None else drop[alt.acts_on]))
    return ev


#: Whether :func:`solver.diagnose.core.evaluate` is evaluating the marker-only motion.
_MARKER_MOTION = {"now": False}


def _evaluate(data, options, unmeasured=None, sigmas=None):  # type: ignore[no-untyped-def]
    """:func:`solver.diagnose.core.evaluate`, noting when it evaluates the marker-only
    motion (called with the fitted motion's frames U)."""
    _MARKER_MOTION["now"] = unmeasured is not None
    try:
        return _own_evaluate(data, options, unmeasured, sigmas)
    finally:
        _MARKER_MOTION["now"] = False


_own_evaluate = core.evaluate


def _fitted_motion_only(cls: type, translation_alternatives, translation_figures) -> None:  # type: ignore[no-untyped-def]
    """Keep ``cls``'s whole-motion alternatives for the fitted motion: on the marker-only
    motion (the motion the markers alone decide, which no force may reshape) its
    translation-profile alternatives, and their held-out figures."""
    motion_alternatives, motion_figures = cls.alternatives, cls.held_out_figures

    def alternatives(self, ctx: Context, full):  # type: ignore[no-untyped-def]
        own = translation_alternatives if _MARKER_MOTION["now"] else motion_alternatives
        return own(self, ctx, full)

    def held_out_figures(self, ctx, alt, folds, frames):  # type: ignore[no-untyped-def]
        own = motion_figures if hasattr(alt, "channel_costs") else translation_figures
        return own(self, ctx, alt, folds, frames)

    cls.alternatives = alternatives
    cls.held_out_figures = held_out_figures


def apply(
    motion_causes: tuple[str, ...] = DEFAULT_MOTION_CAUSES,
    segment_on_residuals: bool = False,
    channel_gain: bool = False,
    fitted_motion_only: bool = False,
) -> None:
    """Move ``motion_causes`` (and with ``segment_on_residuals`` the mass redistribution) onto
    the whole-motion rows in this process (the module docstring).

    Raises
    ------
    SystemExit
        A name that is not one of :data:`MOVABLE`.
    """
    unknown = sorted(set(motion_causes) - set(MOVABLE))
    if unknown:
        raise SystemExit(f"--motion-causes: {', '.join(unknown)} not one of {', '.join(MOVABLE)}")
    translation = {
        name: (type(MOVABLE[name].CAUSE).alternatives, type(MOVABLE[name].CAUSE).held_out_figures)
        for name in motion_causes
    }
    for name in motion_causes:
        if name == "force_time_offset":
            cls = type(MOVABLE["force_time_offset"].CAUSE)
            cls.alternatives = currency._delay_alternatives
            cls.held_out_figures = currency.held_out_figures
        else:
            currency._on_motion_rows(MOVABLE[name])
    selection.cross_validate = _cross_validate
    core.cross_validate = _cross_validate  # type: ignore[attr-defined]
    if segment_on_residuals:
        currency._on_residual_channels(type(SEGMENTS.CAUSE))
    if channel_gain:
        for name in motion_causes:
            _channel_rows(type(MOVABLE[name].CAUSE))
        if segment_on_residuals:
            _channel_rows(type(SEGMENTS.CAUSE))
    if fitted_motion_only:
        for name in motion_causes:
            _fitted_motion_only(type(MOVABLE[name].CAUSE), *translation[name])
        core.evaluate = _evaluate


#: The switches of :func:`apply`: flag -> (its help, what the comparison's heading adds).
SWITCHES = {
    "--segment-on-residuals": (
        "score the segment mass redistribution on the same rows, on the residual channels",
        ", the segment mass redistribution on them, on the residual channels",
    ),
    "--channel-gain": (
        "relative gain: the held-out decrease of the channels' own rows",
        ", relative gain of their channels' own rows",
    ),
    "--fitted-motion-only": (
        "the moved causes on the whole-motion rows on the fitted motion only",
        ", on the fitted motion only",
    ),
}


def main() -> None:
    """The two forms of the module docstring."""
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigma", type=float, default=0.1, help="mass_sigma of the joint fit")
    ap.add_argument("--motion-causes", nargs="+", default=list(DEFAULT_MOTION_CAUSES))
    for flag, (text, _) in SWITCHES.items():
        ap.add_argument(flag, action="store_true", help=text)
    ap.add_argument("--compare", type=Path, nargs="+", help="--json results of the judged fit")
    ap.add_argument("--with", dest="probe", type=Path, nargs="+", help="--json of this probe")
    args = ap.parse_args(argv[:cut])
    on = [vars(args)[flag[2:].replace("-", "_")] for flag in SWITCHES]
    import bench_diagnose_joint  # this folder

    if not args.compare:
        apply(tuple(args.motion_causes), *on)
        bench = str(Path(bench_diagnose_joint.__file__))
        sys.argv = [bench, "--sigma", str(args.sigma), *argv[cut:]]
        bench_diagnose_joint.main()
    elif not args.probe:
        ap.error("--compare needs --with")
    else:
        added = "".join(heading for (_, heading), yes in zip(SWITCHES.values(), on) if yes)
        causes = ", ".join(args.motion_causes)
        print(
            f"**{causes} on the whole-motion profile{added}; joint fit, mass_sigma {args.sigma:g}**\n"
        )
        print(bench_diagnose_joint.compare(args.compare, args.probe, args.sigma))


if __name__ == "__main__":
    main()
