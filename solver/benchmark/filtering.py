"""The filtering study (Werling et al. 2024, §5): the analytical baseline's errors against
the cut-off frequency of the low-pass filter applied to its input.

For each cut-off, every trial's unfiltered input coordinates (``q_unfiltered``, inverse
kinematics of the raw markers by default) are filtered with the 3rd-order zero-phase
Butterworth filter at that cut-off, and the analytical baseline is scored on the
benchmark frames. A cut-off at or above 50 Hz (the Nyquist frequency at 100 Hz) leaves the
input unfiltered. The ground truth does not change with the cut-off.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from solver.benchmark.analytical import analytical_baseline
from solver.benchmark.dataset import RATE_HZ, Dataset, benchmark_input
from solver.benchmark.evaluate import score_trial
from solver.benchmark.metrics import METRICS, TITLES, FrameErrors, summarize

#: Cut-offs of the study, Hz (60: no filter).
DEFAULT_CUTOFFS = (2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0, 60.0)


def filtering_study(
    dataset: Dataset, *, cutoffs: Sequence[float] = DEFAULT_CUTOFFS, contact: str = "measured"
) -> list[dict[str, float]]:
    """Analytical baseline errors per cut-off.

    Returns
    -------
    list of dict
        One per cut-off: ``cutoff_hz`` and the four mean errors (``com_acc``, ``grm``,
        ``grf``, ``torque``) over all benchmark frames.
    """
    rows = []
    for fc in cutoffs:
        parts = []
        for trial in dataset.trials:
            q = benchmark_input(trial.q_unfiltered, cutoff_hz=fc)
            parts.append(score_trial(trial, analytical_baseline(trial, q=q, contact=contact)))
        rows.append({"cutoff_hz": float(fc), **summarize(FrameErrors.concatenate(parts))})
    return rows


def _label(fc: float) -> str:
    return f"{fc:g} (none)" if fc >= RATE_HZ / 2 else f"{fc:g}"


def filtering_markdown(rows: Sequence[dict[str, float]]) -> str:
    """The study as a Markdown table (cut-off, four metrics)."""
    header = ["cut-off (Hz)"] + [TITLES[k] for k in METRICS]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    for r in rows:
        lines.append("| " + " | ".join([_label(r["cutoff_hz"])] + [f"{r[k]:.2f}" for k in METRICS]) + " |")
    return "\n".join(lines) + "\n"


def plot_filtering(rows: Sequence[dict[str, float]], path: str | Path, *, title: str = "") -> bool:
    """Plot the four errors against the cut-off into ``path`` (PNG); False when matplotlib
    is not installed (nothing written)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fc = [r["cutoff_hz"] for r in rows]
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4), constrained_layout=True)
    for ax, k in zip(axes, METRICS):
        ax.plot(fc, [r[k] for r in rows], "o-", color="C0")
        ax.axvline(30.0, color="0.6", linestyle="--", linewidth=1)
        ax.set_xlabel("low-pass cut-off (Hz)")
        ax.set_title(TITLES[k], fontsize=10)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    if fc and max(fc) >= RATE_HZ / 2:
        # below the point, clear of the panel's title
        axes[0].annotate("unfiltered", (max(fc), rows[-1]["com_acc"]), xytext=(0, -8), textcoords="offset points",
                         fontsize=8, ha="right", va="top")
    if title:
        fig.suptitle(title, fontsize=10)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True
