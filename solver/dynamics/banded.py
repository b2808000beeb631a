"""Symmetric block-banded matrices: assembly into LAPACK band storage and the Cholesky solve.

The dynamics fit's normal matrix H is symmetric and block-banded in time: with T frames of
``nf`` unknowns each, block (i, i + o) of size ``nf x nf`` is nonzero only for
``0 <= o <= nb``. It is assembled as its upper block bands, ``blocks[i, o] = H(i, i + o)``,
and solved by a banded Cholesky factorization (LAPACK ``dpbtrf`` / ``dpbtrs``) in the
lower band storage ``ab[d, c] = H[c + d, c]`` (d = 0 is the diagonal), whose column c is
row c of the upper block band read from its diagonal on: a strided view of the blocks,
so the conversion is a single copy. :func:`banded_forward_solve` applies the factor's
inverse to many right-hand sides at once (the joint fit's mass border), and
:func:`banded_back_solve` its transpose's.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import LinAlgError
from scipy.linalg.lapack import dpbtrf, dpbtrs, dtbtrs

FloatArray = NDArray[np.float64]

#: Rows of the band per chunk of :func:`banded_forward_solve`: a chunk of the Camargo
#: circuit's factor (145 band rows) is 9 MB; a system of at most this many rows is solved
#: whole (tests/benchmarks/RESULTS.md, block ``band-solve``, times 512 to 8192).
FORWARD_CHUNK = 8192


class BlockBands:
    """Zeroed upper block bands of a symmetric block-banded matrix, to accumulate into.

    ``blocks[i, o]`` (``(T, nb + 1, nf, nf)``, a writable view) is H(i, i + o). The
    storage is row panels ``(T, nf, (nb + 1) nf)``: row r of block row i holds
    H(i nf + r, i nf ... (i + nb + 1) nf), so the band storage LAPACK takes is nf strided
    copies of it (:meth:`lower_band_storage`), and the bands of one block row,
    ``blocks[i, o:o + m]``, are the contiguous columns ``panel[i, :, o nf:(o + m) nf]``.

    Parameters
    ----------
    t, nbp1, nf
        Block rows T, block bands nb + 1 (the diagonal one included), block size nf.
    """

    def __init__(self, t: int, nbp1: int, nf: int) -> None:
        self.t, self.nbp1, self.nf = t, nbp1, nf
        self.panel = np.zeros((t, nf, nbp1 * nf))
        self.blocks = self.panel.reshape(t, nf, nbp1, nf).transpose(0, 2, 1, 3)

    def lower_band_storage(self) -> FloatArray:
        """LAPACK lower band storage of the whole symmetric matrix.

        Returns
        -------
        ``(u + 1, T nf)`` Fortran-ordered array, ``ab[d, c] = H[c + d, c]`` with bandwidth
        ``u = (nb + 1) nf - 1``; entries past the matrix end are zero. Blocks past the last
        frame are ignored (zeroed here), as is the lower triangle of the diagonal blocks.
        """
        t, nbp1, nf = self.t, self.nbp1, self.nf
        width = nbp1 * nf  # u + 1
        panel = self.panel
        for o in range(1, nbp1):  # blocks past the last frame
            panel[max(t - o, 0) :, :, o * nf : (o + 1) * nf] = 0.0
        # H[c, c + d] is panel[i, r, r + d] for c = i nf + r (zero for r + d past the panel:
        # past the block band); written row by row of the block, with no temporary the size
        # of the matrix (the 2,000-frame trial's is 110 MB)
        ab = np.zeros((width, t * nf), order="F")
        for r in range(nf):
            ab[: width - r, r::nf] = panel[:, r, r:].T
        return ab


def lower_band_storage(blocks: FloatArray) -> FloatArray:
    """Upper block bands -> LAPACK lower band storage of the whole symmetric matrix.

    Parameters
    ----------
    blocks
        ``(T, nb + 1, nf, nf)`` with ``blocks[i, o] = H(i, i + o)`` (blocks past the last
        frame are ignored; only the upper triangle of each diagonal block ``blocks[i, 0]``
        is read).

    Returns
    -------
    ``(u + 1, T nf)`` Fortran-ordered array, ``ab[d, c] = H[c + d, c]`` with bandwidth
    ``u = (nb + 1) nf - 1``; entries past the matrix end are zero.
    """
    t, nbp1, nf, _ = blocks.shape
    bands = BlockBands(t, nbp1, nf)
    bands.blocks[...] = blocks
    return bands.lower_band_storage()


def banded_cholesky(ab: FloatArray, overwrite: bool = False) -> FloatArray:
    """Cholesky factor of a symmetric positive definite banded H (LAPACK dpbtrf).

    Parameters
    ----------
    ab
        ``(u + 1, N)`` lower band storage, ``ab[d, c] = H[c + d, c]``.
    overwrite
        Factor in place (``ab`` must then be Fortran-ordered; it holds the factor after).

    Returns
    -------
    ``(u + 1, N)`` the lower factor in the same storage, for :func:`banded_cholesky_back`.

    Raises
    ------
    LinAlgError
        H is not positive definite (or a LAPACK argument error).
    """
    c, info = dpbtrf(ab, lower=1, overwrite_ab=int(overwrite))
    if info > 0:
        raise LinAlgError(f"{info}-th leading minor not positive definite")
    if info < 0:
        raise LinAlgError(f"illegal value in {-info}-th argument of dpbtrf")
    return c


def banded_cholesky_back(factor: FloatArray, rhs: FloatArray) -> FloatArray:
    """Solve H x = rhs with the factor of :func:`banded_cholesky` (LAPACK dpbtrs).

    Parameters
    ----------
    factor
        ``(u + 1, N)`` from :func:`banded_cholesky`.
    rhs
        ``(N,)`` right-hand side.

    Returns
    -------
    ``(N,)`` solution.

    Raises
    ------
    LinAlgError
        A LAPACK argument error.
    """
    x, info = dpbtrs(factor, rhs, lower=1)
    if info != 0:
        raise LinAlgError(f"illegal value in {-info}-th argument of dpbtrs")
    return x


def banded_cholesky_solve(ab: FloatArray, rhs: FloatArray) -> FloatArray:
    """Solve H x = rhs for a symmetric positive definite banded H (LAPACK dpbtrf + dpbtrs).

    The same factorization as ``scipy.linalg.solveh_banded(ab, rhs, lower=True)``
    without its argument checks and copies.

    Parameters
    ----------
    ab
        ``(u + 1, N)`` lower band storage, ``ab[d, c] = H[c + d, c]`` (not modified).
    rhs
        ``(N,)`` right-hand side.

    Returns
    -------
    ``(N,)`` solution.

    Raises
    ------
    LinAlgError
        H is not positive definite (or a LAPACK argument error).
    """
    return banded_cholesky_back(banded_cholesky(ab), rhs)


def banded_forward_solve(factor: FloatArray, rhs: FloatArray, chunk: int = FORWARD_CHUNK) -> FloatArray:
    """``L^-1 rhs`` for the lower banded Cholesky factor L of :func:`banded_cholesky`, by
    forward substitution in row chunks (Golub & Van Loan, *Matrix Computations*, 4th ed.,
    §3.1.4 and §4.3).

    LAPACK's ``dtbtrs`` solves one right-hand side at a time and reads the whole factor for
    each; a large factor (the Camargo circuit's is 51 MB) then comes from memory once per
    column. Here each chunk of rows [s, e) first subtracts its dependence on the solution
    above it, one dense product with the band's corner ``L[s:s + u, s - u:s]``, and then
    ``dtbtrs`` solves the chunk's own band, a few MB read once for all columns. A system of
    at most ``chunk`` rows is one ``dtbtrs`` call, bit for bit; larger ones agree with it to
    round-off (1e-13 relative on the Camargo circuit, block ``band-solve``).

    Parameters
    ----------
    factor
        ``(u + 1, N)`` lower band storage of L, ``factor[d, c] = L[c + d, c]``, Fortran-ordered.
    rhs
        ``(N,)`` or ``(N, k)`` right-hand sides.
    chunk
        Rows per chunk (any positive number).

    Returns
    -------
    The solution, shaped as ``rhs``.

    Raises
    ------
    LinAlgError
        A zero on the factor's diagonal (or a LAPACK argument error), naming its chunk.
    """
    u, n = factor.shape[0] - 1, factor.shape[1]
    x = np.array(rhs, dtype=np.float64, order="F", copy=True).reshape(n, -1, order="F")
    for s in range(0, n, chunk):
        e = min(s + chunk, n)
        if s > 0:  # the chunk's rows that reach above it: L[r, c] = factor[r - c, c]
            lo, hi = max(s - u, 0), min(s + u, e)
            d = np.arange(s, hi)[:, None] - np.arange(lo, s)[None, :]
            corner = np.where(d <= u, factor[np.minimum(d, u), np.arange(lo, s)[None, :]], 0.0)
            x[s:hi] -= corner @ x[lo:s]
        part, info = dtbtrs(factor[:, s:e], x[s:e], uplo="L")
        if info != 0:
            raise LinAlgError(f"dtbtrs failed on rows {s}..{e} (info {info})")
        x[s:e] = part
    return x.reshape(rhs.shape)


def banded_back_solve(factor: FloatArray, rhs: FloatArray) -> FloatArray:
    """``L^-T rhs`` for the lower banded Cholesky factor L of :func:`banded_cholesky`: back
    substitution with the transposed factor (LAPACK ``dtbtrs``, ``trans="T"``; Golub & Van
    Loan, *Matrix Computations*, 4th ed., §3.1.4). Its one right-hand side reads the factor
    once, so it is not chunked as :func:`banded_forward_solve` is.

    ``factor`` is ``(u + 1, N)``, as :func:`banded_forward_solve` takes it; ``rhs`` is
    ``(N,)`` or ``(N, k)``, and the solution is returned in its shape. Raises LinAlgError
    for a zero on the factor's diagonal (or a LAPACK argument error).
    """
    x, info = dtbtrs(factor, rhs.reshape(rhs.shape[0], -1), uplo="L", trans="T")
    if info != 0:
        raise LinAlgError(f"dtbtrs failed (info {info})")
    return x.reshape(rhs.shape)
