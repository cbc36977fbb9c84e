# SPDX-License-Identifier: LGPL-2.1-or-later
"""Knot insertion, joining and knot removal of clamped cubic B-splines (along one axis).

The tools that merge patches into multi-span faces (:mod:`core.export.chart_faces`):

* :func:`refine` re-expresses a spline on a finer knot vector (knot insertion, exact: the
  coarse spline space lies in the fine one);
* :func:`join` puts splines on ``[0, 1]`` end to end on one knot vector over ``[0, 1]``, a
  knot of full multiplicity (degree) at each join, which represents any chain of pieces
  that meet with C0;
* :func:`remove_knots` lowers the multiplicity of interior knots where the spline is
  smooth enough there (knot removal in the sense of Tiller, as a least-squares projection
  through knot insertion, checked against the input): a knot stays only where removing it
  would move the spline by more than a tolerance.

Poles are arrays whose first axis runs along the spline; the other axes (a second pole
index of a surface, the coordinates) are carried along, so a tensor-product surface is
refined or reduced in one direction by calling these on its pole grid.
"""
from functools import lru_cache

import numpy as np
from scipy.linalg import solve_triangular

from core.export.bspline_basis import basis_matrix, full_knots

DEGREE = 3


def _key(knots, mults):
    """Hashable form of a knot vector (for the cache of insertion matrices)."""
    return (np.asarray(knots, dtype=np.float64).tobytes(),
            np.asarray(mults, dtype=np.int64).tobytes())


@lru_cache(maxsize=1024)
def _insertion(coarse_key, fine_key):
    """(n_fine, n_coarse) matrix of knot insertion (coarse poles -> fine poles): the fine basis
    reproduces every coarse basis function, so interpolating them at the fine knot vector's
    Greville abscissae (where its collocation matrix is invertible, Schoenberg-Whitney) gives
    it exactly up to rounding, which is cleared."""
    ck = np.frombuffer(coarse_key[0], dtype=np.float64)
    cm = np.frombuffer(coarse_key[1], dtype=np.int64)
    fk = np.frombuffer(fine_key[0], dtype=np.float64)
    fm = np.frombuffer(fine_key[1], dtype=np.int64)
    flat = full_knots(fk, fm)
    n = len(flat) - DEGREE - 1
    greville = np.convolve(flat[1:-1], np.full(DEGREE, 1.0 / DEGREE), mode="valid")[:n]
    matrix = np.linalg.solve(basis_matrix(fk, fm, greville), basis_matrix(ck, cm, greville))
    matrix[np.abs(matrix) < 1e-15] = 0.0
    return matrix


def insertion_matrix(coarse_knots, coarse_mults, fine_knots, fine_mults):
    """(n_fine, n_coarse) float64 matrix taking poles on the coarse knot vector to the poles of
    the same spline on the fine one (every coarse knot is a fine knot with at least its
    multiplicity; both clamped cubic on the same interval)."""
    return _insertion(_key(coarse_knots, coarse_mults), _key(fine_knots, fine_mults))


def _apply(matrix, poles):
    """``matrix`` (a, b) applied along the first axis of ``poles`` (b, ...)."""
    flat = matrix @ poles.reshape(poles.shape[0], -1)
    return flat.reshape((matrix.shape[0],) + poles.shape[1:])


def refine(poles, knots, mults, fine_knots, fine_mults):
    """Poles (n_fine, ...) of the spline ``(poles, knots, mults)`` on the finer knot vector."""
    return _apply(insertion_matrix(knots, mults, fine_knots, fine_mults), np.asarray(poles))


def join(pieces):
    """Splines on ``[0, 1]`` end to end as one spline on ``[0, 1]``.

    Parameters
    ----------
    pieces : list of (poles (n_i, ...), knots (k_i,), mults (k_i,)), each clamped cubic on
        ``[0, 1]``; piece ``i + 1`` starts where piece ``i`` ends (its first pole is dropped
        for the last pole of piece ``i``).

    Returns
    -------
    poles (1 + sum(n_i - 1), ...), knots, mults: piece ``i`` occupies ``[i / m, (i + 1) / m]``
    (``m`` pieces) with its own interior knots; the joins have multiplicity 3 (C0).
    """
    m = len(pieces)
    poles = [np.asarray(pieces[0][0])]
    knots, mults = [0.0], [DEGREE + 1]
    for i, (p, k, mu) in enumerate(pieces):
        if i:
            poles.append(np.asarray(p)[1:])
            knots.append(i / m)
            mults.append(DEGREE)
        k = np.asarray(k, dtype=np.float64)
        knots += ((i + k[1:-1]) / m).tolist()
        mults += np.asarray(mu, dtype=np.int64)[1:-1].tolist()
    knots.append(1.0)
    mults.append(DEGREE + 1)
    return np.concatenate(poles), np.array(knots), np.array(mults, dtype=np.int64)


LAST_DIFFERENCES = np.array([[0.0, 0.0, -1.0, 1.0], [0.0, 1.0, -2.0, 1.0], [-1.0, 3.0, -3.0, 1.0]])
"""(3, 4) last first, second and third differences of four Bezier points."""
FIRST_DIFFERENCES = np.array([[-1.0, 1.0, 0.0, 0.0], [1.0, -2.0, 1.0, 0.0], [-1.0, 3.0, -3.0, 1.0]])
"""(3, 4) first first, second and third differences of four Bezier points."""


def _smoothness(poles, knots, mults, tolerance):
    """(k,) int64 multiplicity each knot needs: 3 - (order of continuity within ``tolerance``).

    The spline is refined to multiplicity 3 at every interior knot (its Bezier segments);
    across a knot, the jump of the ``r``-th derivative of the two segments times
    ``h^r / r!`` (``h`` the shorter span, so a length) measures how far the spline is from
    being C^r there. Ends keep 4; no knot gets more than it has.
    """
    knots = np.asarray(knots, dtype=np.float64)
    need = np.asarray(mults, dtype=np.int64).copy()
    if len(knots) < 3:
        return need
    full = np.where(np.arange(len(knots)) % (len(knots) - 1) == 0, DEGREE + 1, DEGREE)
    bez = refine(poles, knots, mults, knots, full)
    start = DEGREE * np.arange(1, len(knots) - 1)
    left = bez[start[:, None] + np.arange(-DEGREE, 1)]
    right = bez[start[:, None] + np.arange(DEGREE + 1)]
    shape = (-1,) + (1,) * (bez.ndim - 1)
    h = np.diff(knots)
    hl, hr = h[:-1].reshape(shape), h[1:].reshape(shape)
    scale = np.minimum(h[:-1], h[1:])
    dl = np.tensordot(LAST_DIFFERENCES, left, axes=(1, 1))
    dr = np.tensordot(FIRST_DIFFERENCES, right, axes=(1, 1))
    smooth = np.ones(len(start), dtype=bool)
    m = np.full(len(start), DEGREE)
    for r, coefficient, factorial in ((1, 3.0, 1.0), (2, 6.0, 2.0), (3, 6.0, 6.0)):
        jump = np.linalg.norm(dl[r - 1] * (coefficient / hl ** r)
                              - dr[r - 1] * (coefficient / hr ** r), axis=-1)
        jump = jump.reshape(len(start), -1).max(axis=1)
        smooth &= jump * scale ** r / factorial <= tolerance
        m = np.where(smooth, DEGREE - r, m)
    need[1:-1] = np.minimum(need[1:-1], m)
    return need


def remove_knots(poles, knots, mults, tolerance):
    """Lower interior knot multiplicities where the spline allows it within ``tolerance``.

    First every knot gets the multiplicity its continuity needs (:func:`_smoothness`, with a
    tenth of the tolerance) and the result is checked once; if that misses the tolerance, the
    knots are reduced one at a time (:func:`_remove_knots_one_by_one`).

    Parameters
    ----------
    poles : (n, ..., d) float64, the last axis the coordinates.
    knots, mults : the knot vector (distinct knots, multiplicities; clamped cubic).
    tolerance : float, model units.

    Returns
    -------
    poles (n', ..., d), knots, mults, error (float, the bound reached, model units).
    """
    p0 = np.asarray(poles, dtype=np.float64)
    knots = np.asarray(knots, dtype=np.float64)
    need = _smoothness(p0, knots, mults, 0.1 * tolerance)
    fit = _project(p0, knots, mults, need)
    if fit[1] <= tolerance:
        keep = need > 0
        return fit[0], knots[keep], need[keep], fit[1]
    return _remove_knots_one_by_one(p0, knots, mults, tolerance)


def _project(p0, knots, mults, reduced):
    """Poles on the knot vector with multiplicities ``reduced`` (a knot of 0 left out) closest
    to ``p0`` through knot insertion, and the largest pole distance (a bound of the distance
    between the two splines)."""
    keep = reduced > 0
    coarse = _key(knots[keep], reduced[keep])
    fine = _key(knots, mults)
    T = _insertion(coarse, fine)
    flat = p0.reshape(len(p0), -1)
    q = _least_squares(coarse, fine) @ flat
    gap = (T @ q - flat).reshape(p0.shape)
    return q.reshape((len(q),) + p0.shape[1:]), float(np.linalg.norm(gap, axis=-1).max())


@lru_cache(maxsize=1024)
def _least_squares(coarse_key, fine_key):
    """(n_coarse, n_fine) matrix of the least-squares inverse of knot insertion
    (:func:`_insertion`), ``R^-1 Q^T`` of its QR factorisation: the coarse poles whose
    insertion is closest to given fine poles."""
    Q, R = np.linalg.qr(_insertion(coarse_key, fine_key))
    return solve_triangular(R, Q.T)


def _remove_knots_one_by_one(poles, knots, mults, tolerance):
    """Lower interior knot multiplicities where the spline allows it within ``tolerance``.

    Knot removal one knot at a time: each interior knot in turn is tried at multiplicity 0
    (removed), then 1, ... up to its current one;
    the first that keeps the spline within ``tolerance`` of the input is kept. The poles on a
    candidate knot vector are the least-squares projection of the input's poles through knot
    insertion ``T`` (``min |T q - p|``), and the distance checked is the largest pole distance
    ``max |T q - p|``, which bounds the distance between the two splines at every parameter
    (the B-spline basis is a partition of unity). It is measured against the input, so the
    bound holds for the result as a whole, not per removal.

    Parameters
    ----------
    poles : (n, ..., d) float64, the last axis the coordinates.
    knots, mults : the knot vector (distinct knots, multiplicities; clamped cubic).
    tolerance : float, model units.

    Returns
    -------
    poles (n', ..., d), knots, mults, error (float, the bound reached, model units).
    """
    p0 = np.asarray(poles, dtype=np.float64)
    knots = np.asarray(knots, dtype=np.float64)
    current = np.asarray(mults, dtype=np.int64).copy()
    best, error = p0, 0.0
    for i in range(1, len(knots) - 1):
        for m in range(0, int(current[i])):
            trial = current.copy()
            trial[i] = m
            q, err = _project(p0, knots, mults, trial)
            if err <= tolerance:
                current, error, best = trial, err, q
                break
    keep = current > 0
    return best, knots[keep], current[keep], error
