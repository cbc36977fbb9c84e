# SPDX-License-Identifier: LGPL-2.1-or-later
"""Sparse symmetric positive definite solve of the fit's normal equations
(core/fitting/spd_solve.py)."""
import numpy as np
import scipy.sparse as sp

from core.fitting.spd_solve import solve_spd


def test_solves_a_sparse_spd_system_from_its_upper_triangle():
    rng = np.random.default_rng(0)
    J = sp.random(600, 300, density=0.03, random_state=rng, format="csr")
    A = (J.T @ J + 0.1 * sp.identity(300)).tocsr()
    rhs = rng.normal(size=300)
    expected = np.linalg.solve(A.toarray(), rhs)
    # the upper triangle alone, the whole matrix, or with rubbish below the diagonal (not read)
    for given in (sp.triu(A), A, sp.triu(A) + sp.tril(rng.normal() * A, -1)):
        x = solve_spd(given, rhs)
        assert x.shape == (300,) and x.dtype == np.float64
        np.testing.assert_allclose(x, expected, atol=1e-9 * np.abs(expected).max())
