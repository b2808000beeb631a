"""What every diagnosis cause provides: the :class:`Cause` base class.

A cause is one way the recordings or the model can be wrong (a force delay, a misplaced
plate, a wrong mass, ...). Everything the diagnosis needs to know about it lives in one
subclass of :class:`Cause`, in its own module of :mod:`solver.diagnose.causes`, and
:mod:`solver.diagnose.causes.registry` lists them. The rest of the diagnosis iterates the
registry and asks the cause; it never compares a cause's name.

The parts of a cause (class attributes, then methods):

* ``name`` (the key in reports and saved extensions), ``label`` (words for the command's
  help), ``channel`` (what it explains: :data:`CHANNELS`), ``main_parameter`` (the key its
  uncertainty is reported under);
* the choice rule's bounds: ``min_effect`` and ``max_effect`` (in the units of
  :meth:`Cause.effect_size`), ``min_relative_gain`` (None: the rule's default);
* where it is judged: ``acts_on_forces`` (a force-side cause, compared again on the
  marker-only motion), ``on_marker_motion`` (:data:`MARKER_MOTION`),
  ``chosen_on_marker_motion`` (may be named from that motion), ``chosen_on_own_noise``
  (may be named from that motion whitened with its own noise,
  :func:`solver.diagnose.core.choice_on_marker_motion`), ``confirmed_on_marker_motion``
  (named from the fitted motion only when the marker-only motion confirms it,
  :func:`solver.diagnose.selection.confirmed`), ``distinct_choice`` (its
  plate must stand out from the same cause on the other plates), ``overlaps`` (the causes
  it is told from by which keeps its gain on top of the other,
  :func:`solver.diagnose.selection._stands_out`), ``folds_mix_phases`` (its alternatives
  are cross-validated on folds that each mix the phases of a periodic movement instead of
  blocks dealt in turn, :class:`solver.diagnose.selection.Folds`);
* :meth:`Cause.alternatives`: the fitted alternatives (one per plate or marker, or one);
* :meth:`Cause.effect_size` and :meth:`Cause.deviation`: the size compared with the bounds
  and the vector whose distance from "no effect" is measured in standard errors;
  :meth:`Cause.plausible` for bounds other than the size's;
* :meth:`Cause.extension`: the entry ``addb diagnose --apply`` saves
  (:mod:`solver.corrections` applies it to the raw recordings through its table
  :data:`solver.corrections.CORRECTIONS`, which every cause must have an entry in);
* :meth:`Cause.refit`: how the diagnosis' refit with the extension differs from the
  refit without it;
* :meth:`Cause.describe` (one line of the text report), :meth:`Cause.uncertainty_json`,
  and :meth:`Cause.held_out_figures` (the before/after figures on held-out frames; the
  default scores the root residual rows).

A subclass that leaves out a method cannot be instantiated (``TypeError`` naming it); one
that leaves out an attribute, or whose name has no correction, is refused by
:func:`check` when the registry is imported.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from solver.diagnose.candidates import Alternative, Context
    from solver.diagnose.data import DiagnosisData
    from solver.io.types import ForceRecording
    from solver.model.osim import OsimModel

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: What a cause explains (:func:`solver.diagnose.selection.channels`): the root residual
#: (``residuals``), a marker's own error (``markers``), the whole-motion profile's rows
#: (``motion``, :mod:`solver.diagnose.motion_profile`) or the frames U it takes out of the
#: residual terms (``frames``). Causes on different channels do not stand in each other's way.
CHANNELS = ("residuals", "markers", "motion", "frames")

#: How a cause takes part on the marker-only motion (:func:`solver.diagnose.data.marker_kinematics`):
#: ``estimated`` (evaluated there, and its reported parameters come from there),
#: ``evaluated`` (evaluated there, parameters from the fitted motion), ``skipped`` (not
#: evaluated there: the whole-motion profile re-optimizes the motion anyway).
MARKER_MOTION = ("estimated", "evaluated", "skipped")

#: Note of the default held-out figures.
HELD_OUT_NOTE = "fixed kinematics, translation re-optimized; after: parameters fitted without the frame's fold"


@dataclass(frozen=True)
class EntryInputs:
    """What a cause needs to write its extension entry (:meth:`Cause.extension`).

    Attributes
    ----------
    data
        The prepared trial the cause was evaluated on.
    marker_time
        ``(T_markers,)`` marker sample times of the raw trial, s.
    marker_frames
        Runs ``[[a, b), ...]`` of the diagnosis' frames -> the same runs in marker frames
        (the diagnosis' frame-to-marker-rate rule, :func:`solver.diagnose.core.extension_entry`).
    """

    data: DiagnosisData
    marker_time: FloatArray
    marker_frames: Callable[[Sequence[Sequence[int]]], list[list[int]]]

    @property
    def trial(self) -> str:
        """The trial's name."""
        return self.data.trial.trial


@dataclass
class RefitSetup:
    """The inputs of the diagnosis' refit that a cause's extension may change
    (:meth:`Cause.refit`; :func:`solver.diagnose.core.refit_result` runs it).

    Attributes
    ----------
    model
        The processed (scaled, mass-fitted) model.
    forces
        The raw force recording (saved extensions applied).
    mass_kg
        The stated mass, kg.
    observed
        ``(T, M, 3)`` observed markers on the trial's frames, m, or None (the trial's own).
    unmeasured_runs
        Runs ``[a, b)`` of the trial's frames that join the known unmeasured frames.
    """

    model: OsimModel
    forces: ForceRecording
    mass_kg: float
    observed: FloatArray | None = None
    unmeasured_runs: list[tuple[int, int]] = field(default_factory=list)


def plus_minus(x: Any, scale: float, unit: str, digits: int) -> str:
    """`` ± [x * scale] unit`` rounded to ``digits`` ("" when ``x`` is None): the
    uncertainty part of a report line."""
    return "" if x is None else f" ± {np.round(np.asarray(x) * scale, digits).tolist()} {unit}"


class Cause(ABC):
    """One diagnosis cause (see the module docstring for its parts)."""

    name: ClassVar[str]
    label: ClassVar[str]
    channel: ClassVar[str]
    main_parameter: ClassVar[str]
    min_effect: ClassVar[float]
    max_effect: ClassVar[float] = math.inf
    min_relative_gain: ClassVar[float | None] = None
    acts_on_forces: ClassVar[bool] = False
    on_marker_motion: ClassVar[str] = "estimated"
    chosen_on_marker_motion: ClassVar[bool] = False
    chosen_on_own_noise: ClassVar[bool] = False
    confirmed_on_marker_motion: ClassVar[bool] = False
    distinct_choice: ClassVar[bool] = False
    overlaps: ClassVar[tuple[Cause, ...]] = ()
    folds_mix_phases: ClassVar[bool] = False

    def __repr__(self) -> str:
        return f"<cause {getattr(self, 'name', type(self).__name__)}>"

    @property
    def corrects_forces(self) -> bool:
        """Whether its extension corrects the plates' readings alone (model and markers as
        processed): its correction in :data:`solver.corrections.CORRECTIONS` acts on forces."""
        from solver.corrections import correction

        return correction(self.name).forces is not None

    # ------------------------------------------------------------------ fitting

    @abstractmethod
    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """The cause's alternatives on one trial (one per plate or marker, or one; [] when
        it cannot be evaluated there). ``full`` is the translation profile with the frames
        U evaluated (:func:`solver.diagnose.core.build_context`)."""

    @abstractmethod
    def effect_size(self, parameters: dict[str, Any]) -> float:
        """The magnitude compared with :attr:`min_effect` and :attr:`max_effect`."""

    def plausible(self, parameters: dict[str, Any]) -> bool:
        """Whether an estimate is physically plausible beyond its size
        (:attr:`max_effect`); an implausible one means the cause fits something else, and it
        is no contender (default: always)."""
        return True

    def deviation(self, parameters: dict[str, Any]) -> FloatArray:
        """``(n,)`` the estimate's departure from "no effect", in the units of ``value`` (n = 1
        for a scalar value): the vector whose norm over the norm of its jackknife standard
        error is the t value (default: ``value``)."""
        return np.atleast_1d(np.asarray(parameters["value"], dtype=float))

    # ------------------------------------------------------------------ extension

    @abstractmethod
    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """The entry ``addb diagnose --apply`` saves (:mod:`solver.corrections`)."""

    @abstractmethod
    def refit(self, setup: RefitSetup, parameters: dict[str, Any], inputs: EntryInputs) -> RefitSetup:
        """The refit's inputs with the extension applied."""

    # ------------------------------------------------------------------ report

    @abstractmethod
    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """One line of the text report: the estimate (JSON parameters, without ``value``)
        with its uncertainty (:meth:`uncertainty_json`'s dict, or None)."""

    def uncertainty_json(self, uncertainty: Any, parameters: dict[str, Any]) -> dict[str, Any]:
        """The jackknife standard error of ``value`` (of the estimate ``parameters``) as
        reported (default: under :attr:`main_parameter`)."""
        return {self.main_parameter: uncertainty}

    def held_out_figures(self, ctx: Context, alt: Alternative, folds: NDArray[np.intp], frames: BoolArray) -> dict[str, Any]:
        """Before/after figures on held-out frames (each frame corrected with the parameters
        fitted without its fold): marker RMS (m), linear (N) and angular (N·m) residual RMS
        over ``frames`` (residuals: on the evaluated ones), from the translation-profiled
        rows; before: the reference, after: the alternative's rows.

        Parameters
        ----------
        ctx
            The trial's shared context.
        alt
            The alternative (one of this cause's).
        folds
            ``(T,)`` fold of each frame, 0 to K-1 (:meth:`solver.diagnose.selection.Folds.of`).
        frames
            ``(T,)`` frames scored.
        """
        after = np.array(ctx.ref_rows)
        for f in range(int(folds.max()) + 1):
            test = folds == f
            after[test] = alt.rows(alt.solve(~test))[test]
        return {
            "before": residual_figures(ctx, ctx.ref_rows, frames, ctx.evaluated),
            "after": residual_figures(ctx, after, frames, ctx.evaluated),
            "note": HELD_OUT_NOTE,
        }


class ForceCorrection(Cause):
    """A cause whose extension corrects the raw force recording: the refit reads the
    forces corrected by its entry (:func:`solver.corrections.correct_forces`)."""

    acts_on_forces: ClassVar[bool] = True

    def refit(self, setup: RefitSetup, parameters: dict[str, Any], inputs: EntryInputs) -> RefitSetup:
        """The refit's forces corrected by the extension entry."""
        from dataclasses import replace

        from solver.corrections import correct_forces

        return replace(setup, forces=correct_forces(setup.forces, self.extension(parameters, inputs)))


def residual_figures(
    ctx: Context, rows: FloatArray, frames: BoolArray, evaluated: BoolArray, marker: tuple[int, FloatArray] | None = None
) -> dict[str, float]:
    """Marker RMS (m), linear (N) and angular (N·m) residual RMS from translation-profiled
    rows ``(T, R)`` over ``frames`` (residuals on ``evaluated`` among them); ``marker``
    ``(j, (T, 3) m)`` adds a lab-frame shift to marker j's error."""
    d, s = ctx.data, ctx.sigmas
    mk = d.markers
    mean_err, count = mk.mean_error()
    shifted = rows[:, :3] * (s.marker / np.sqrt(np.maximum(count, 1)))[:, None]
    err = mk.error - mean_err[:, None] + shifted[:, None]
    if marker is not None:
        j, lab = marker
        err[:, j] = err[:, j] + lab
    e = np.linalg.norm(err[frames], axis=2)
    res = frames & evaluated
    f = rows[res, 3:6] * s.force
    m = rows[res, 6:9] * s.moment
    return {
        "marker_rms_m": float(np.sqrt(np.nanmean(e**2))) if np.isfinite(e).any() else float("nan"),
        "linear_residual_rms_N": float(np.sqrt(np.mean(np.sum(f**2, axis=1)))) if res.any() else float("nan"),
        "angular_residual_rms_Nm": float(np.sqrt(np.mean(np.sum(m**2, axis=1)))) if res.any() else float("nan"),
        "frames": int(frames.sum()),
    }


#: The class attributes every cause must set (:func:`check`), with their types.
REQUIRED: dict[str, type | tuple[type, ...]] = {
    "name": str,
    "label": str,
    "channel": str,
    "main_parameter": str,
    "min_effect": (int, float),
    "max_effect": (int, float),
    "acts_on_forces": bool,
    "on_marker_motion": str,
    "chosen_on_marker_motion": bool,
    "chosen_on_own_noise": bool,
    "confirmed_on_marker_motion": bool,
    "distinct_choice": bool,
    "folds_mix_phases": bool,
}


def check(causes: Sequence[Cause]) -> None:
    """Refuse a registry whose causes lack a part.

    Raises
    ------
    TypeError
        An entry is not a :class:`Cause` instance.
    ValueError
        A cause lacks a required attribute (or has one of the wrong type or value), two
        causes share a name, or a cause has no correction in
        :data:`solver.corrections.CORRECTIONS`; the message names the cause and the part.
    """
    from solver.corrections import CORRECTIONS

    seen: set[str] = set()
    for c in causes:
        if not isinstance(c, Cause):
            raise TypeError(f"registry entry {c!r} is not a solver.diagnose.causes.base.Cause instance")
        who = getattr(c, "name", type(c).__name__)
        for attr, kind in REQUIRED.items():
            value = getattr(c, attr, None)
            if value is None or not isinstance(value, kind) or (isinstance(value, str) and not value):
                raise ValueError(f"diagnosis cause {who!r} ({type(c).__module__}) lacks its {attr!r} (expected {kind})")
        if c.channel not in CHANNELS:
            raise ValueError(f"diagnosis cause {who!r}: channel {c.channel!r} is none of {CHANNELS}")
        if c.on_marker_motion not in MARKER_MOTION:
            raise ValueError(f"diagnosis cause {who!r}: on_marker_motion {c.on_marker_motion!r} is none of {MARKER_MOTION}")
        if not 0 <= c.min_effect < c.max_effect:
            raise ValueError(f"diagnosis cause {who!r}: min_effect {c.min_effect} must lie in [0, max_effect {c.max_effect})")
        if c.min_relative_gain is not None and not isinstance(c.min_relative_gain, (int, float)):
            raise ValueError(f"diagnosis cause {who!r}: min_relative_gain must be a number or None")
        if c.name in seen:
            raise ValueError(f"diagnosis cause {who!r} is registered twice")
        if c.name not in CORRECTIONS:
            raise ValueError(
                f"diagnosis cause {who!r} has no correction in solver.corrections.CORRECTIONS "
                "(how its saved extension is applied to the raw recordings)"
            )
        seen.add(c.name)
