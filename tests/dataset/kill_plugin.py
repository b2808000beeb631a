"""A Dask worker plugin for the fault tests: the worker that runs the first attempt of a
chosen subject kills itself with SIGKILL (as the kernel's OOM killer would), once."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

from distributed.diagnostics.plugin import WorkerPlugin


class KillOnFirstAttempt(WorkerPlugin):
    """SIGKILL the worker process while a task of subject ``rel`` runs, the first time only
    (``rel`` "": the first subject task of any subject); ``marker`` records the killed
    worker's pid (and that it happened).

    With ``out`` (the run's output tree) the kill waits until the task has started the
    subject (a work folder below ``out`` holds its process.log), as a subject that runs out
    of memory dies; without it the worker dies as the task enters its executing state, before
    the subject starts."""

    name = "addb-test-kill-on-first-attempt"

    def __init__(self, rel: str, marker: str, out: str | None = None) -> None:
        self.rel = rel
        self.marker = marker
        self.out = out

    def transition(self, key, start, finish, **kwargs) -> None:
        name = key if isinstance(key, str) else str(key)
        if finish == "executing" and name.startswith(f"addb-subject-{self.rel}"):
            marker = Path(self.marker)
            try:
                fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                return
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            if self.out is None:
                os.kill(os.getpid(), signal.SIGKILL)
            threading.Thread(target=self._kill_once_started, args=(name,), daemon=True).start()

    def _kill_once_started(self, key: str) -> None:
        """SIGKILL this worker once a work folder below ``out`` holds the log of a subject
        started by this process (its first line names the pid; the started mark is written
        before it)."""
        from solver.dataset.task import LOG_NAME, WORK_PREFIX

        mine = f"(pid {os.getpid()})"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            for log in Path(self.out).rglob(f"{WORK_PREFIX}*/{LOG_NAME}"):
                try:
                    if mine in log.read_text(encoding="utf-8"):
                        os.kill(os.getpid(), signal.SIGKILL)
                except OSError:
                    continue
            time.sleep(0.01)
