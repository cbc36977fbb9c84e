# SPDX-License-Identifier: LGPL-2.1-or-later
"""Solve a sparse symmetric positive definite system by a multifrontal factorisation.

The fit's normal equations (:class:`core.fitting.best_fit.NormalEquations`) have a few
thousand unknowns and are a few percent full: a base vertex is coupled to every vertex whose
limit stencil shares a fine point with its own, a neighbourhood of some tens of vertices. A
dense Cholesky factorisation spends its time on zeros, and SuperLU's LU works on both
triangles and column by column. MUMPS (through the ``python-mumps`` bindings) orders the
unknowns by approximate minimum degree and factors the symmetric matrix as ``L D L^T``
in dense frontal blocks by BLAS: several times faster than either at these sizes. A
positive definite matrix needs no pivoting, so the pivot threshold is 0 and the
factorisation keeps the fill-reducing order. Without python-mumps this module's import
raises ImportError saying how to install it.
"""
import numpy as np
import scipy.sparse as sp

from core.optional_imports import optional_module

# imported with this module, not at the first solve: the BLAS that the bindings load with
# MUMPS is then loaded when the fit starts and limits every BLAS pool to one thread
# (core.threads.single_threaded around core.fitting.fit.fit_base_mesh), so it is limited too
# and the factorisation rounds the same in every call
mumps = optional_module("mumps", package="python-mumps")


def solve_spd(upper, rhs):
    """Solve ``A x = rhs`` for a symmetric positive definite ``A`` given by its upper triangle
    (definiteness is not checked: the factorisation does not pivot).

    Parameters
    ----------
    upper : (m, m) sparse float64, ``A``'s upper triangle, diagonal included (entries below
        the diagonal are not read, so the whole of ``A`` may be given).
    rhs : (m,) float64

    Returns
    -------
    (m,) float64 ``x``.

    Raises
    ------
    RuntimeError
        MUMPS failed (``mumps.MUMPSError``, e.g. a zero pivot of a singular matrix).
    """
    # not a ``with`` block: the bindings' context exit repeats the last job instead of
    # releasing (it solves again in place of the returned solution); the instance releases
    # MUMPS's memory when it is collected
    context = mumps.Context()
    context.set_matrix(sp.coo_matrix(upper, dtype=np.float64), symmetric=True)
    context.factor(ordering="amd", pivot_tol=0.0)
    return np.asarray(context.solve(np.array(rhs, dtype=np.float64)), dtype=np.float64)
