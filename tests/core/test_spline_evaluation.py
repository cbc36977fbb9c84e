# SPDX-License-Identifier: LGPL-2.1-or-later
"""Point evaluation of B-spline patches and knot insertion (core.export.bspline_basis,
core.export.spline_knots) against the dense tensor-product formula, on random patches with
interior knots of every multiplicity and parameters on the knots themselves."""
import numpy as np
import pytest

from core.export.bspline_basis import basis_matrix, evaluate_patch_points
from core.export.spline_knots import insertion_matrix
from core.types import BSplinePatch

U_KNOTS, U_MULTS = np.array([0.0, 0.125, 0.5, 0.875, 1.0]), np.array([4, 2, 3, 1, 4])
V_KNOTS, V_MULTS = np.array([0.0, 0.3, 1.0]), np.array([4, 1, 4])


def _patches(rng):
    nu = int(U_MULTS.sum()) - 4
    nv = int(V_MULTS.sum()) - 4
    multi = [BSplinePatch(rng.standard_normal((nu, nv, 3)), U_KNOTS, U_MULTS, V_KNOTS, V_MULTS)
             for _ in range(3)]
    bezier = BSplinePatch(rng.standard_normal((4, 4, 3)), np.array([0.0, 1.0]),
                          np.array([4, 4]), np.array([0.0, 1.0]), np.array([4, 4]))
    return multi + [bezier]


@pytest.mark.parametrize("du, dv", [(0, 0), (1, 0), (0, 1), (1, 1), (2, 0)])
def test_points_match_the_dense_formula(du, dv):
    rng = np.random.default_rng(3)
    patches = _patches(rng)
    u = np.concatenate([rng.random(40), U_KNOTS, [0.3, 0.5, 1.0]])
    v = np.concatenate([rng.random(40), [0.0, 0.3, 1.0, 0.3, 0.0], rng.random(3)])
    face = rng.integers(0, len(patches), len(u))
    ours = evaluate_patch_points(patches, face, u, v, du, dv)
    for i in range(len(u)):
        p = patches[face[i]]
        bu = basis_matrix(p.u_knots, p.u_mults, u[i:i + 1], du)[0]
        bv = basis_matrix(p.v_knots, p.v_mults, v[i:i + 1], dv)[0]
        dense = np.einsum("a,b,abk->k", bu, bv, p.poles)
        assert np.abs(ours[i] - dense).max() <= 1e-9 * max(1.0, np.abs(dense).max())


def test_knot_insertion_reproduces_the_coarse_spline():
    """Poles on a finer knot vector (every coarse knot kept with at least its multiplicity)
    describe the same curve at every parameter."""
    coarse = (np.array([0.0, 0.5, 1.0]), np.array([4, 1, 4]))
    fine = (np.array([0.0, 0.25, 0.5, 0.75, 1.0]), np.array([4, 3, 2, 1, 4]))
    T = insertion_matrix(*coarse, *fine)
    t = np.linspace(0.0, 1.0, 257)
    gap = basis_matrix(*fine, t) @ T - basis_matrix(*coarse, t)
    assert np.abs(gap).max() <= 1e-12
