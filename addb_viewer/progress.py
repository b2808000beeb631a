"""A one-line text progress bar for the command line (stderr), no dependencies."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Callable ``(message, fraction)`` that redraws one line on a terminal.

    On a non-terminal stream (CI logs, pipes) it prints one line per new message instead.
    """

    def __init__(self, stream: TextIO | None = None, width: int = 30) -> None:
        self.stream = stream or sys.stderr
        self.width = width
        self.t0 = time.perf_counter()
        self._last = ""
        self._tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def __call__(self, message: str, fraction: float) -> None:
        """Redraw the bar at ``fraction`` (clipped to [0, 1]) with ``message``."""
        frac = min(max(fraction, 0.0), 1.0)
        elapsed = time.perf_counter() - self.t0
        if self._tty:
            filled = round(frac * self.width)
            bar = "#" * filled + "-" * (self.width - filled)
            self.stream.write(f"\r[{bar}] {frac * 100:5.1f}% {elapsed:6.1f}s {message[:50]:<50}")
            if frac >= 1.0:
                self.stream.write("\n")
        elif message != self._last:
            self.stream.write(f"[{frac * 100:5.1f}%] {elapsed:6.1f}s {message}\n")
        self._last = message
        self.stream.flush()


def table(rows: list[list[str]], header: list[str]) -> str:
    """A plain-text table with aligned columns."""
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows)]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths))
    sep = "  ".join("-" * w for w in widths)
    body = ["  ".join(str(x).rjust(w) if i else str(x).ljust(w) for i, (x, w) in enumerate(zip(r, widths))) for r in rows]
    return "\n".join([line, sep, *body])
