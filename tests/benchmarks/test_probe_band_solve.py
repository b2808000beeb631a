"""tests/benchmarks/probe_band_solve.py on the shared walk's joint fit: the forward
substitution in row chunks gives LAPACK's ``dtbtrs`` solution of the fit's own system, for
chunks larger and smaller than the bandwidth and for one that does not divide the rows."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg.lapack import dtbtrs

from tests.conftest import SHARED_DATA
from tests.scripts import load_script

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def probe():
    return load_script("tests/benchmarks/probe_band_solve.py")


@pytest.fixture(scope="module")
def system(probe):
    """The first multi-column forward solve of the walk's joint fit: factor, right-hand sides."""
    factor, rhs, count = probe.capture(SHARED_DATA / "subjects" / "rajagopal2016_walk")
    assert count >= 2  # one per step of the fit, and the walk's fit takes several
    return factor, rhs


@pytest.mark.parametrize("m", [97, 1000, 4096, 10**6])
def test_chunked_forward_solve_matches_dtbtrs_on_the_fits_system(probe, system, m: int) -> None:
    factor, rhs = system
    u, n = factor.shape[0] - 1, factor.shape[1]
    assert rhs.shape == (n, rhs.shape[1]) and rhs.shape[1] > 1 and m != u and n % 97 != 0
    ref, info = dtbtrs(factor, rhs, uplo="L")
    assert info == 0
    got = probe.chunked_forward_solve(factor, rhs, m)
    assert np.abs(got - ref).max() <= 1e-11 * np.abs(ref).max()
    # and it is the solution: L x = rhs, L x summed from the band storage (L[c + d, c] = factor[d, c])
    lx = np.zeros_like(rhs)
    for d in range(u + 1):
        lx[d:] += factor[d, : n - d, None] * got[: n - d]
    assert np.abs(lx - rhs).max() <= 1e-9 * np.abs(rhs).max()
