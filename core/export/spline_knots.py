# SPDX-License-Identifier: LGPL-2.1-or-later
"""Knot insertion, joining and knot removal of clamped cubic B-splines (along one axis).

The tools that merge patches into multi-span faces (:mod:`core.export.chart_faces`):

* :func:`refine` re-expresses a spline on a finer knot vector (knot insertion, exact: the
  coarse spline space lies in the fine one);
* :func:`join` puts splines on ``[0, 1]`` end to end on one knot vector over ``[0, 1]``, a
  knot of full multiplicity (degree) at each join, which represents any chain of pieces
  that meet with C0;
* :func:`remove_knots` lowers the multiplicity of interior knots where the spline is
  smooth enough there (Tiller's knot removal, as a least-squares projection): a knot
  stays only where removing it would move the spline by more than a tolerance.

Poles are arrays whose first axis runs along the spline; the other axes (a second pole
index of a surface, the coordinates) are carried along, so a tensor-product surface is
refined or reduced in one direction by calling these on its pole grid.
"""
from functools import lru_cache

import numpy as np

from core.export.bspline_basis import basis_matrix

DEGREE = 3


def _key(knots, mults):
    return (np.asarray(knots, dtype=np.float64).tobytes(), np.asarray(mults, dtype=np.int64).tobytes())


@lru_cache(maxsize=1024)
def _insertion(coarse_key, fine_key):
    """(n_fine, n_coarse) matrix of knot insertion (coarse poles -> fine poles)."""
    ck = np.frombuffer(coarse_key[0], dtype=np.float64)
    cm = np.frombuffer(coarse_key[1], dtype=np.int64)
    fk = np.frombuffer(fine_key[0], dtype=np.float64)
    fm = np.frombuffer(fine_key[1], dtype=np.int64)
    frac = (np.arange(DEGREE + 2) + 0.5) / (DEGREE + 2)
    t = (fk[:-1, None] + np.diff(fk)[:, None] * frac[None, :]).reshape(-1)
    fine = basis_matrix(fk, fm, t)
    coarse = basis_matrix(ck, cm, t)
    matrix = np.linalg.lstsq(fine, coarse, rcond=None)[0]
    matrix[np.abs(matrix) < 1e-15] = 0.0
    return matrix


def insertion_matrix(coarse_knots, coarse_mults, fine_knots, fine_mults):
    """(n_fine, n_coarse) float64 matrix taking poles on the coarse knot vector to the poles of
    the same spline on the fine one (every coarse knot is a fine knot with at least its
    multiplicity; both clamped cubic on the same interval)."""
    return _insertion(_key(coarse_knots, coarse_mults), _key(fine_knots, fine_mults))


def _apply(matrix, poles):
    """``matrix`` (a, b) applied along the first axis of ``poles`` (b, ...)."""
    return (matrix @ poles.reshape(poles.shape[0], -1)).reshape((matrix.shape[0],) + poles.shape[1:])


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


def remove_knots(poles, knots, mults, tolerance):
    """Lower interior knot multiplicities where the spline allows it within ``tolerance``.

    Each interior knot in turn is tried at multiplicity 1, then 2, ... up to its current one;
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
            keep = trial > 0
            T = insertion_matrix(knots[keep], trial[keep], knots, mults)
            flat = p0.reshape(len(p0), -1)
            q = np.linalg.lstsq(T, flat, rcond=None)[0]
            gap = (T @ q - flat).reshape(p0.shape)
            err = float(np.linalg.norm(gap, axis=-1).max())
            if err <= tolerance:
                current, error = trial, err
                best = q.reshape((len(q),) + p0.shape[1:])
                break
    keep = current > 0
    return best, knots[keep], current[keep], error
