"""Ctrl-C in a dataset run is the command's to handle, not the local cluster's workers'.

A terminal sends SIGINT to every process of the command: the CLI and the worker processes
of its local Dask cluster. The workers start with SIGINT ignored (they inherit the
disposition from the command while it starts them, :func:`solver.dataset.runner.process_dataset`);
a worker its nanny starts again after a death (a retry) would inherit the command's own
handler instead, and print a page of tracebacks at the next Ctrl-C. :class:`IgnoreInterrupt`,
registered on the local cluster, makes every worker ignore SIGINT when it starts, restarted
ones included. Workers of a cluster started by hand (``--scheduler``) are left alone: their
own terminal's Ctrl-C stops them.
"""

from __future__ import annotations

import signal
import threading
from typing import Any

from distributed import WorkerPlugin


class IgnoreInterrupt(WorkerPlugin):
    """A Dask worker plugin: the worker process ignores SIGINT from its start (``setup``)."""

    name = "addb-ignore-interrupt"

    def setup(self, worker: Any) -> None:
        """Ignore SIGINT in this worker process (signal handlers are set from the main
        thread only, where a nanny's worker runs its event loop; elsewhere nothing is done)."""
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
