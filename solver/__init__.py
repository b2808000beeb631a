"""addb's solver: file readers, model conversion, kinematics, dynamics, diagnosis.

No UI imports. The stages run single-threaded linear algebra (:func:`single_threaded_blas`):
their matrices are small or banded, and OpenBLAS threads on them were 5-50x slower on a
loaded 2-core machine than one thread.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext


def single_threaded_blas() -> AbstractContextManager[object]:
    """Context manager limiting BLAS/OpenMP thread pools to one thread (threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return nullcontext()
    return threadpool_limits(limits=1)
