"""Probe: the diagnosis on the joint fit with the force-side causes scored on the whole-motion profile.

    .venv/bin/python tests/benchmarks/probe_motion_currency.py [--sigma 0.1] [--segment-on-residuals] -- BENCH_DIAGNOSE_ARGS ...
    .venv/bin/python tests/benchmarks/probe_motion_currency.py [--sigma 0.1] [--segment-on-residuals] --compare DEFAULT.json ... --with PROBE.json ...

A probe for issue 29's second gap (the diagnosis' rules re-derived on the joint mass fit,
solver/diagnose/judged_fit.py), not a change of ``addb diagnose``. The first form runs
``bench_diagnose_joint.py`` (the diagnosis' benchmark with the joint fit, ``mass_sigma``
``--sigma``, in the alternation's place) with these changes made in this process:

* Every cause on the residual channels (``force_time_offset``, ``body_mass``,
  ``plate_force_offset``, ``plate_force_gain``, ``plate_position_offset``,
  ``plate_registration``) is scored on the rows of the whole-motion profile
  (:class:`solver.diagnose.motion_profile.MotionProfile`: every free coordinate at every frame
  re-optimized, linearized about the processed motion) with the idle plates' rows appended,
  instead of the translation profile (:class:`solver.diagnose.profile.Profile`). The
  reference rows are the root residual at the stated mass, as the translation profile's.
  What a cause's Gauss-Newton step then measures is the joint refit of the cause and the
  whole motion that the converged fit would make; the translation profile lets only a
  translation of the whole body take part, while the converged fit also turns the body to
  balance a shifted centre of pressure (block ``diagnose-joint-choice-probe``: on the joint
  fit the plates' registration outscores a hidden shift of the walk's right plate, which
  improves too few folds).
* The relative gain of those causes is measured against the reference cost of their own
  channels (the residual rows and the idle plates' rows), not of every row of the profile
  (which carries every marker's error and the fit's acceleration prior).
* With ``--segment-on-residuals``, ``segment_mass_distribution`` is scored on the same rows
  and competes on the residual channels (its channel ``motion``, named only when nothing
  else stands out, was a consequence of its own currency).

Every threshold of :class:`solver.diagnose.selection.ChoiceRule` is left as it is. The second
form is ``bench_diagnose_joint.py --compare`` under a heading naming the probe's changes (give it
the ``--sigma`` and ``--segment-on-residuals`` the results were made with).
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
from numpy.typing import NDArray

from solver.diagnose import core, selection
from solver.diagnose.candidates import Context, GridAlternative, LinearAlternative, residual_rows
from solver.diagnose.causes import (
    body_mass,
    force_time_offset,
    plate_force_gain,
    plate_force_offset,
    plate_position_offset,
    plate_registration,
    segment_mass_distribution,
)
from solver.diagnose.profile import ROWS

FloatArray = NDArray[np.float64]

#: Key of the motion-currency reference rows in a :class:`Context`'s ``__dict__``.
_REF = "_probe_motion_ref_rows"


def _motion_rows(
    ctx: Context, residuals: list[FloatArray], idle_forces: list[FloatArray]
) -> FloatArray:
    """``(T, Rm + 3P, k)`` whole-motion-profiled rows of k root residuals ``(T, 6)`` (N, N·m
    about the pelvis origin), each with its idle plates' readings ``(P, T, 3)`` appended
    (unprofiled: they do not depend on the motion)."""
    mp = ctx.motion_profile
    n = mp._n_residual_rows
    z = np.repeat(mp.z0[:, None], len(residuals), axis=1)
    for j, r in enumerate(residuals):
        z[:n, j] = (r[mp.evaluated] / mp._sig).ravel()
    t = ctx.data.n_frames
    idle = np.stack(
        [np.transpose(f, (1, 0, 2)).reshape(t, -1) / ctx.sigmas.force for f in idle_forces], axis=2
    )
    return np.concatenate([mp.per_frame(mp.project(z)), idle], axis=1)


def reference_rows(ctx: Context) -> FloatArray:
    """``(T, Rm + 3P)`` the trial's reference rows in the motion currency (kept on ``ctx``)."""
    ref = ctx.__dict__.get(_REF)
    if ref is None:
        d = ctx.data
        ref = _motion_rows(ctx, [d.residual()], [d.external()[2]])[:, :, 0]
        ctx.__dict__[_REF] = ref
    return ref


def channel_costs(ctx: Context, rows: FloatArray) -> FloatArray:
    """``(T,)`` cost of the residual rows and the idle plates' rows of ``rows``."""
    nm = ctx.motion_profile.n_rows
    return np.sum(rows[:, :6] ** 2, axis=1) + np.sum(rows[:, nm:] ** 2, axis=1)


def motion_columns(ctx: Context, wrench: FloatArray, idle: FloatArray | None = None) -> FloatArray:
    """``(T, Rm + 3P, k)`` columns of a change ``wrench`` ``(T, 6, k)`` of the root residual
    and ``idle`` ``(P, T, 3, k)`` of the idle plates' readings, in the motion currency."""
    mp = ctx.motion_profile
    moved = mp.per_frame(mp.project(mp.wrench_rows(wrench)))
    return np.concatenate([moved, residual_rows(ctx, wrench, idle)[:, ROWS:]], axis=1)


def held_out_figures(
    self: Any, ctx: Context, alt: Any, folds: NDArray[np.intp], frames: NDArray[np.bool_]
) -> dict[str, Any]:
    """Linear and angular residual RMS before and after on held-out frames, from the motion-currency rows."""
    mp = ctx.motion_profile
    ref = reference_rows(ctx)
    after = np.array(ref)
    for f in range(int(folds.max()) + 1):
        test = folds == f
        after[test] = alt.rows(alt.solve(~test))[test]

    def figures(rows: FloatArray) -> dict[str, Any]:
        res = frames & mp.evaluated
        force, moment = rows[res, :3] * mp.sigmas.force, rows[res, 3:6] * mp.sigmas.moment
        rms = lambda x: float(np.sqrt(np.mean(np.sum(x**2, axis=1)))) if res.any() else float("nan")
        return {
            "linear_residual_rms_N": rms(force),
            "angular_residual_rms_Nm": rms(moment),
            "frames": int(frames.sum()),
        }

    return {
        "before": figures(ref),
        "after": figures(after),
        "note": "whole-motion profile (probe_motion_currency.py)",
    }


def _on_motion_rows(module: Any) -> None:
    """Build ``module``'s cause's linear alternatives on the motion currency: its own code,
    given the motion reference rows as ``ctx.ref_rows`` and the motion columns for its
    ``profiled``."""
    cls = type(module.CAUSE)
    own = cls.alternatives

    def alternatives(self: Any, ctx: Context, full: Any) -> list[Any]:
        ref = reference_rows(ctx)
        proxy = copy.copy(ctx)  # shares the built profiles and the reference rows
        proxy.ref_rows = ref
        translation = module.profiled
        module.profiled = lambda c, wrench, idle=None: motion_columns(ctx, wrench, idle)
        try:
            out = own(self, proxy, full)
        finally:
            module.profiled = translation
        for alt in out:
            alt.channel_costs = channel_costs(ctx, ref)
        return out

    cls.alternatives = alternatives
    cls.held_out_figures = held_out_figures


def _delay_alternatives(self: Any, ctx: Context, full: Any) -> list[Any]:
    """``force_time_offset`` on the motion currency (its grid of delays, as its own module)."""
    d = ctx.data
    grid = force_time_offset.DELAY_GRID
    ref = reference_rows(ctx)

    def parts(tau: float) -> tuple[FloatArray, FloatArray]:
        _, total, idle_force = d.external(tau)
        return d.inertial * (d.stated_mass / d.fitted_mass) - total, idle_force

    costs = np.empty((d.n_frames, grid.size))
    for s in range(0, grid.size, 40):
        chunk = [parts(float(tau)) for tau in grid[s : s + 40]]
        costs[:, s : s + len(chunk)] = np.sum(
            _motion_rows(ctx, [c[0] for c in chunk], [c[1] for c in chunk]) ** 2, axis=1
        )

    def rows_at(tau: float) -> FloatArray:
        residual, idle = parts(tau)
        return _motion_rows(ctx, [residual], [idle])[:, :, 0]

    alt = GridAlternative(
        self.name,
        grid,
        costs,
        np.sum(ref**2, axis=1),
        lambda tau: {"value": tau, "delay_s": tau},
        rows_at,
    )
    alt.channel_costs = channel_costs(ctx, ref)  # type: ignore[attr-defined]
    return [alt]


def _on_residual_channels(cls: Any) -> None:
    """Move ``segment_mass_distribution``'s alternatives onto the motion currency and the
    residual channels: its own alternatives' columns (already on the whole-motion profile's
    rows, the idle plates' rows zero) over the reference rows at the stated mass."""
    own = cls.alternatives

    def alternatives(self: Any, ctx: Context, full: Any) -> list[Any]:
        ref = reference_rows(ctx)
        out = []
        for alt in own(self, ctx, full):
            idle = np.zeros((alt.g.shape[0], ref.shape[1] - alt.g.shape[1], alt.n_params))
            g = np.concatenate([alt.g, idle], axis=1)
            moved = LinearAlternative(alt.cause, alt.choice, ref, g, alt.physical, alt.names)
            moved.channel_costs = channel_costs(ctx, ref)  # type: ignore[attr-defined]
            out.append(moved)
        return out

    cls.alternatives = alternatives
    cls.channel = "residuals"
    cls.held_out_figures = held_out_figures


def _cross_validate(alt: Any, folds: NDArray[np.intp]) -> selection.Evaluation:
    """:func:`solver.diagnose.selection.cross_validate`, its relative gain measured against
    the alternative's ``channel_costs`` when it has them."""
    ev = _own_cross_validate(alt, folds)
    own = getattr(alt, "channel_costs", None)
    if own is not None:
        ev.reference = float(np.sum(own if alt.acts_on is None else own[alt.acts_on]))
    return ev


_own_cross_validate = selection.cross_validate


def apply(segment_on_residuals: bool = False) -> None:
    """Make the changes of the module docstring in this process."""
    for module in (
        body_mass,
        plate_force_gain,
        plate_force_offset,
        plate_position_offset,
        plate_registration,
    ):
        _on_motion_rows(module)
    type(force_time_offset.CAUSE).alternatives = _delay_alternatives
    type(force_time_offset.CAUSE).held_out_figures = held_out_figures
    selection.cross_validate = _cross_validate
    core.cross_validate = _cross_validate  # type: ignore[attr-defined]
    if segment_on_residuals:
        _on_residual_channels(type(segment_mass_distribution.CAUSE))


def main() -> None:
    argv = sys.argv[1:]
    passed = argv[argv.index("--") :] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--sigma",
        type=float,
        default=0.1,
        help="mass_sigma of the joint fit in the alternation's place",
    )
    ap.add_argument(
        "--segment-on-residuals",
        action="store_true",
        help="score the segment mass redistribution on the same rows, on the residual channels",
    )
    ap.add_argument("--compare", type=Path, nargs="+", help="--json results of the judged fit")
    ap.add_argument(
        "--with", dest="probe", type=Path, nargs="+", help="--json results of this probe"
    )
    args = ap.parse_args(own)
    import bench_diagnose_joint  # this folder

    if args.compare:
        if not args.probe:
            ap.error("--compare needs --with")
        segment = (
            ", the segment mass redistribution on the residual channels"
            if args.segment_on_residuals
            else ""
        )
        print(
            f"**Force-side causes on the whole-motion profile{segment}; joint fit, mass_sigma {args.sigma:g}**\n"
        )
        print(bench_diagnose_joint.compare(args.compare, args.probe, args.sigma))
        return
    apply(args.segment_on_residuals)
    sys.argv = [str(Path(bench_diagnose_joint.__file__)), "--sigma", str(args.sigma), *passed]
    bench_diagnose_joint.main()


if __name__ == "__main__":
    main()
