"""Symmetric block-banded matrices: assembly into LAPACK band storage and the Cholesky solve.

The dynamics fit's normal matrix H is symmetric and block-banded in time: with T frames of
``nf`` unknowns each, block (i, i + o) of size ``nf x nf`` is nonzero only for
``0 <= o <= nb``. It is assembled as its upper block bands, ``blocks[i, o] = H(i, i + o)``,
and solved by a banded Cholesky factorization (LAPACK ``dpbtrf`` / ``dpbtrs``) in the
lower band storage ``ab[d, c] = H[c + d, c]`` (d = 0 is the diagonal), whose column c is
row c of the upper block band read from its diagonal on: a strided view of the blocks,
so the conversion is a single copy.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import LinAlgError
from scipy.linalg.lapack import dpbtrf, dpbtrs

FloatArray = NDArray[np.float64]


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
