# SPDX-License-Identifier: LGPL-2.1-or-later
"""Sparse symmetric positive definite solve of the fit's normal equations
(core/fitting/spd_solve.py); a singular matrix and a missing python-mumps give clear errors."""
import importlib
import sys

import numpy as np
import pytest
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


def test_a_singular_matrix_raises_instead_of_returning_rubbish():
    singular = sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(RuntimeError, match="singular"):
        solve_spd(sp.triu(singular), np.ones(2))


def test_without_python_mumps_the_import_names_the_package(monkeypatch):
    import core.fitting.spd_solve as module

    monkeypatch.setitem(sys.modules, "mumps", None)  # import mumps now raises ImportError
    try:
        with pytest.raises(ImportError, match="python-mumps"):
            importlib.reload(module)
    finally:
        monkeypatch.undo()
        importlib.reload(module)
