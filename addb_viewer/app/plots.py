"""uPlot charts of a trial, synchronized with the current frame, flagged frames shaded.

viser's uPlot element has no cursor API and uPlot draws NaN badly, so the charts are
built from plain finite arrays on a "three samples per frame" x grid: each frame ``i``
is drawn at ``t_i - dt/2 + eps``, ``t_i`` and ``t_i + dt/2 - eps``. A flag shade is a
series on its own 0..1 scale that is 1 on the three samples of a flagged frame and 0
elsewhere, filled down to 0, which draws exact per-frame rectangles. The current-frame
cursor is a series on another 0..1 scale that sits at -1 (outside the plot, clipped)
except for two extra samples at ``t_k`` going up to 2: a vertical line. Moving the cursor
re-sends the arrays (a few kB; the app throttles it during playback).

NaN values (no force, no marker) are drawn as 0; a series that is NaN everywhere (the
dynamics before the dynamics stage ran) is hidden and the chart says so in its title.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser
from numpy.typing import NDArray

from addb_viewer.app.scene import FOOT_COLORS, plate_feet
from addb_viewer.app.summary import G, hicks_thresholds
from addb_viewer.app.timeline import TRACKS
from solver.results import ProcessedTrial
from solver.sampling import frame_interval

FloatArray = NDArray[np.float64]

FLAG_FILL = "rgba(90, 90, 90, 0.22)"
"""Flagged frames (either foot): grey over the full height (:func:`shading_legend`)."""
PROPOSAL_FILL = "rgba({}, {}, {}, 0.6)".format(*TRACKS["proposal"])
"""Pending proposals: the timeline's proposal colour (orange), in a band at the top."""
PROPOSAL_BAND = 0.88
"""Proposals are shaded in the top 12 % of a chart (flags over the full height)."""
CURSOR_COLOR = "rgba(20, 20, 20, 0.9)"


def shading_legend() -> str:
    """What the charts' shading means (a line above them)."""
    r, g, b = TRACKS["proposal"]
    return (f"<small>charts: <span style='color:rgb(90,90,90)'>■</span> flagged frames (full height), "
            f"<span style='color:rgb({r},{g},{b})'>■</span> pending proposals (band at the top), "
            "dashed: Hicks' per-frame limits</small>")  # fmt: skip


@dataclass(frozen=True)
class Line:
    """One plotted quantity.

    Attributes
    ----------
    label
        Legend label with unit.
    values
        ``(T,)`` values (NaN drawn as 0).
    color
        CSS colour.
    dash
        Dash pattern in pixels, () for a solid line.
    """

    label: str
    values: FloatArray
    color: str
    dash: tuple[float, ...] = ()


def _css(rgb: tuple[int, int, int]) -> str:
    return f"rgb({rgb[0]}, {rgb[1]}, {rgb[2]})"


def frame_grid(time: FloatArray) -> FloatArray:
    """``(3T,)`` x samples: each frame's left edge, centre and right edge (see module)."""
    t = np.asarray(time, float)
    dt = frame_interval(t, default=0.01)
    eps = dt * 1e-3
    return np.stack([t - dt / 2 + eps, t, t + dt / 2 - eps], axis=1).ravel()


def chart_arrays(
    time: FloatArray,
    lines: list[FloatArray],
    shades: list[NDArray[np.bool_]],
    frame: int,
    *,
    shade_floors: list[float] | None = None,
) -> tuple[FloatArray, ...]:
    """The data tuple of a chart: ``(x, *lines, *shades, cursor)``, all finite.

    Parameters
    ----------
    time
        ``(T,)`` frame times, s.
    lines
        ``(T,)`` values of each line (NaN -> 0).
    shades
        ``(T,)`` masks drawn as shaded frames.
    frame
        Current frame (the cursor).
    shade_floors
        Value of each shade series where its mask is False (default 0).

    Returns
    -------
    tuple of numpy.ndarray
        Each of length ``3T + 2``.
    """
    n = len(time)
    x = frame_grid(time)
    pos = 3 * int(frame) + 2  # after the centre sample of the current frame
    cols = [np.repeat(np.nan_to_num(np.asarray(v, float)), 3) for v in lines]
    floors = shade_floors or [0.0] * len(shades)
    cols += [np.where(np.repeat(np.asarray(m, bool), 3), 1.0, fl) for m, fl in zip(shades, floors, strict=True)]
    cursor = np.full(3 * n, -1.0)
    out = [np.insert(x, pos, [x[pos - 1]] * 2)]
    out += [np.insert(c, pos, [c[pos - 1]] * 2) for c in cols]
    out.append(np.insert(cursor, pos, [2.0, -1.0]))
    return tuple(out)


def _range(values: list[FloatArray], *, floor_zero: bool = False) -> tuple[float, float]:
    finite = [v[np.isfinite(v)] for v in values]
    allv = np.concatenate(finite) if finite else np.zeros(0)
    lo = float(allv.min()) if allv.size else 0.0
    hi = float(allv.max()) if allv.size else 1.0
    if floor_zero:
        lo = min(lo, 0.0)
    if hi - lo < 1e-9:
        hi = lo + 1.0
    pad = 0.05 * (hi - lo)
    return lo - (0 if floor_zero and lo == 0 else pad), hi + pad


class Chart:
    """One uPlot chart with lines, flag/proposal shading and a frame cursor.

    Parameters
    ----------
    gui
        Where to add the chart (``server.gui`` or a folder context).
    title
        Chart title.
    time
        ``(T,)`` s.
    lines
        The quantities to draw.
    unit
        Label of the y axis, on the left. Every chart has that one axis, of the same
        width, so that the plot areas and the frame cursors line up across the charts (a
        second axis on the right would narrow one chart's plot area).
    note
        Appended to the title (e.g. "no dynamics yet").
    """

    def __init__(
        self,
        gui: viser.GuiApi,
        title: str,
        time: FloatArray,
        lines: list[Line],
        unit: str,
        *,
        note: str = "",
        height: int = 150,
    ) -> None:
        self.time = np.asarray(time, float)
        self.lines = lines
        n = self.time.size
        self.flagged = np.zeros(n, bool)
        self.proposed = np.zeros(n, bool)
        self.frame = 0
        series: list[dict] = [{"label": "t (s)"}]
        scales: dict[str, dict] = {
            "x": {"time": False, "range": (float(self.time[0]), float(self.time[-1]) if n > 1 else 1.0)},
            "shade": {"auto": False, "range": (0.0, 1.0)},
            "cursor": {"auto": False, "range": (0.0, 1.0)},
        }
        vals = [ln.values for ln in lines if np.isfinite(ln.values).any()]
        scales["y"] = {"auto": False, "range": _range(vals, floor_zero=True)}
        # ticks at least 15 px apart (uPlot's default 30 px left a 90 px chart one tick, "0")
        # the time axis 30 px high (uPlot's 50 px left a 90 px chart a 40 px plot, too short
        # for the y axis' label "N, N·m")
        axes: list[dict] = [{"size": 30}, {"scale": "y", "label": unit, "side": 3, "size": 50, "space": 15}]
        for ln in lines:
            series.append(
                {
                    "label": ln.label, "stroke": ln.color, "width": 1.5, "scale": "y",
                    "dash": ln.dash, "points": {"show": False},
                    "show": bool(np.isfinite(ln.values).any()),
                }
            )
        series.append(
            {"label": "flagged", "scale": "shade", "stroke": "rgba(0,0,0,0)", "width": 0,
             "fill": FLAG_FILL, "fillTo": 0.0, "points": {"show": False}}
        )
        series.append(
            {"label": "proposed", "scale": "shade", "stroke": "rgba(0,0,0,0)", "width": 0,
             "fill": PROPOSAL_FILL, "fillTo": PROPOSAL_BAND, "points": {"show": False}}
        )
        series.append({"label": "frame", "scale": "cursor", "stroke": CURSOR_COLOR, "width": 1.5, "points": {"show": False}})
        self.handle = gui.add_uplot(
            data=self.arrays(),
            series=tuple(series),
            scales=scales,
            axes=tuple(axes),
            title=title + (f" — {note}" if note else ""),
            legend={"show": False},  # the series are named in the title (space beside the 3D view)
            height=height,
            aspect=2.0,
            padding=(8, 24, 0, 0),  # room above the plot for the top tick's label (viser's default 0 cut it)
        )

    def arrays(self) -> tuple[FloatArray, ...]:
        """The chart's current data tuple (see :func:`chart_arrays`): the times (s), each
        line's values (in the chart's ``unit``), the flagged and proposed shades and the
        cursor, each ``(n,)`` with n = 3T + 2."""
        return chart_arrays(
            self.time,
            [ln.values for ln in self.lines],
            [self.flagged, self.proposed],
            self.frame,
            shade_floors=[0.0, PROPOSAL_BAND],
        )

    def update(self, *, frame: int | None = None, flagged=None, proposed=None) -> None:
        """Move the cursor and/or change the shaded frames, then re-send the data."""
        if frame is not None:
            self.frame = int(frame)
        if flagged is not None:
            self.flagged = np.asarray(flagged, bool)
        if proposed is not None:
            self.proposed = np.asarray(proposed, bool)
        self.handle.data = self.arrays()

    def remove(self) -> None:
        """Remove the chart from the page."""
        self.handle.remove()


def grf_lines(trial: ProcessedTrial) -> list[Line]:
    """Vertical ground reaction force per foot (per plate while no plate is assigned to a
    foot), plus the vertical force the centre-of-mass acceleration requires when known."""
    feet = plate_feet(trial)
    lines: list[Line] = []
    if trial.plates and (feet != "").any():
        for foot in ("left", "right", ""):
            on = feet == foot
            if not on.any():
                continue
            fy = sum((np.where(on[i], np.nan_to_num(p.force[:, 1]), 0.0) for i, p in enumerate(trial.plates)), np.zeros(trial.n_frames))
            label = f"{foot} foot (N)" if foot else "unassigned (N)"
            lines.append(Line(label, fy, _css(FOOT_COLORS[foot])))
    else:
        palette = ["rgb(240, 60, 60)", "rgb(40, 110, 255)", "rgb(0, 150, 80)", "rgb(120, 120, 120)"]
        for i, p in enumerate(trial.plates):
            lines.append(Line(f"plate {p.name} (N)", np.nan_to_num(p.force[:, 1]), palette[i % len(palette)]))
    required = trial.mass_kg * (trial.com_acc[:, 1] + G)
    if np.isfinite(required).any():
        lines.append(Line("m(a+g) required (N)", required, "rgb(190, 0, 190)", dash=(4, 3)))
    return lines


def residual_lines(trial: ProcessedTrial) -> list[Line]:
    """Residual force (N) and moment (N·m) magnitudes and their Hicks thresholds, on one
    axis (the chart's frame cursor then lines up with the other charts')."""
    th = hicks_thresholds(trial)
    f = np.linalg.norm(trial.residual_force, axis=1)
    m = np.linalg.norm(trial.residual_moment, axis=1)
    dyn = trial.has_dynamics
    ones = np.ones(trial.n_frames) if dyn else np.full(trial.n_frames, np.nan)
    return [
        Line("|F| residual (N)", f, "rgb(220, 20, 60)"),
        Line("Hicks F (N)", th.force_n * ones, "rgb(220, 20, 60)", dash=(5, 4)),
        Line("|M| residual (N·m)", m, "rgb(30, 100, 220)"),
        Line("Hicks M (N·m)", th.moment_nm * ones, "rgb(30, 100, 220)", dash=(5, 4)),
    ]


#: Height of each chart, px (four charts and the timeline fit beside the 3D view at 1000 px).
CHART_HEIGHT = 90
#: The joint torque shown first (when the model has it).
DEFAULT_TORQUE = "knee_angle_r"


def torque_line(trial: ProcessedTrial, coordinate: str) -> Line:
    """The generalized force of ``coordinate`` (joint torque N·m, or force N for a
    translational coordinate) as a chart line."""
    j = list(trial.coordinate_names).index(coordinate)
    return Line(f"{coordinate}", np.asarray(trial.tau[:, j], float), "rgb(90, 60, 160)")


class TrialPlots:
    """The four charts of a trial: vertical GRF, residuals, marker RMS per frame, and one
    joint torque picked from a list.

    Parameters
    ----------
    gui
        Where to add the charts.
    trial
        The processed trial.
    container
        The GUI folder the charts live in (a chart added later, on picking another joint
        torque, goes there too); None: the current context.
    """

    def __init__(self, gui: viser.GuiApi, trial: ProcessedTrial, container: Any = None) -> None:
        t = trial.time
        self.gui, self.trial, self.container = gui, trial, container
        no_plates = "no force plates" if not trial.plates else ""
        # a trial without plates never has dynamics: its charts say why, not "yet"
        self.no_dyn = "" if trial.has_dynamics else ("kinematics only" if not trial.plates else "no dynamics yet")
        h = CHART_HEIGHT
        self.charts = [
            Chart(gui, "Vertical GRF: left · right · m(a+g) dashed", t, grf_lines(trial), "N", note=no_plates, height=h),
            Chart(gui, "Residual |F| (N, red) · |M| (N·m, blue); dashed: Hicks", t, residual_lines(trial), "N, N·m",
                  note=self.no_dyn, height=h),
            Chart(
                gui, "Marker RMS (cm)", t,
                [Line("marker RMS (cm)", 100 * trial.marker_rms_per_frame, "rgb(0, 120, 120)")],
                "cm", height=h,
            ),
        ]  # fmt: skip
        names = tuple(trial.coordinate_names)
        first = DEFAULT_TORQUE if DEFAULT_TORQUE in names else names[0]
        self.torque_choice = gui.add_dropdown("Joint torque", names, initial_value=first)
        self.charts.append(self._torque_chart(first))
        self.torque_choice.on_update(lambda e: self.show_torque(e.target.value))

    def _torque_chart(self, coordinate: str) -> Chart:
        return Chart(self.gui, f"Joint torque: {coordinate}", self.trial.time, [torque_line(self.trial, coordinate)],
                     "N·m", note=self.no_dyn, height=CHART_HEIGHT)  # fmt: skip

    def show_torque(self, coordinate: str) -> None:
        """Show ``coordinate``'s generalized force in the last chart (same cursor and shading)."""
        old = self.charts[-1]
        with self.container if self.container is not None else contextlib.nullcontext():
            new = self._torque_chart(coordinate)
        new.frame, new.flagged, new.proposed = old.frame, old.flagged, old.proposed
        old.remove()
        new.update()
        self.charts[-1] = new

    def update(self, *, frame: int | None = None, flagged=None, proposed=None) -> None:
        """Move every chart's cursor and/or change the shaded frames."""
        for c in self.charts:
            c.update(frame=frame, flagged=flagged, proposed=proposed)

    def remove(self) -> None:
        """Remove the charts (and the torque list) from the page."""
        for c in self.charts:
            c.remove()
        self.torque_choice.remove()
