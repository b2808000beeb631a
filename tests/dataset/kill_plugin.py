"""A Dask worker plugin for the fault test: the worker that starts the first attempt of a
chosen subject kills itself with SIGKILL (as the kernel's OOM killer would), once."""

from __future__ import annotations

import os
import signal
from pathlib import Path

from distributed.diagnostics.plugin import WorkerPlugin


class KillOnFirstAttempt(WorkerPlugin):
    """SIGKILL the worker process when a task of subject ``rel`` starts executing, the
    first time only; ``marker`` records the killed worker's pid (and that it happened)."""

    name = "addb-test-kill-on-first-attempt"

    def __init__(self, rel: str, marker: str) -> None:
        self.rel = rel
        self.marker = marker

    def transition(self, key, start, finish, **kwargs) -> None:
        name = key if isinstance(key, str) else str(key)
        if finish == "executing" and name.startswith(f"addb-subject-{self.rel}-"):
            marker = Path(self.marker)
            try:
                fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                return
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            os.kill(os.getpid(), signal.SIGKILL)
