"""addb's solver: file readers, model conversion, kinematics, dynamics, diagnosis.

No UI imports. The stages run single-threaded linear algebra (:func:`single_threaded_blas`):
their matrices are small or banded, and OpenBLAS threads on them were 5-50x slower on a
loaded 2-core machine than one thread.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext


def single_threaded_blas(*, load_scipy: bool = True) -> AbstractContextManager[object]:
    """Context manager limiting BLAS/OpenMP thread pools to one thread (threadpoolctl).

    threadpoolctl limits only the libraries loaded when the context is entered, and scipy
    ships its own OpenBLAS (the one behind ``scipy.linalg``, e.g. the dynamics fit's banded
    Cholesky), loaded on first use: it is loaded here first. With two threads that solve took
    70-180 ms instead of 7-19 ms on this loaded 2-core machine (up to 0.8 s seen in a run).
    ``load_scipy=False`` skips that (about 0.2 s of imports) for code that uses numpy's BLAS
    only, such as the kinematics stage.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return nullcontext()
    if load_scipy:
        import scipy.linalg  # noqa: F401  (loads scipy's BLAS so that the limit reaches it)

    return threadpool_limits(limits=1)
