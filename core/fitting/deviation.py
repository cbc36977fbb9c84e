# SPDX-License-Identifier: LGPL-2.1-or-later
"""The largest deviation between a cage's limit surface and the target, per base face: what
``--tolerance`` promises (:mod:`core.fitting.refine`).

Both ways:

- **forward**, the limit surface to the target: the distance of the limit points of a fine
  subdivision level (:func:`deviation_level`, about ``DEVIATION.fine_quads`` quads, so the
  points are much closer together than any tolerance asked for) to the target;
- **backward**, the target to the limit surface, over the **whole** target, not samples of
  it (:func:`core.farthest.farthest_pieces`): every target triangle is bounded, and cut into
  smaller pieces where the bound straddles the tolerance or passes the largest distance
  found, down to ``DEVIATION.resolution * tolerance``. So no part of the target farther than
  the tolerance goes unseen, however small.

The limit surface is measured as its fine level triangulated. A coarse level with random
target samples can call a tolerance met that the exported solid misses: coarse triangles cut
off a thin flange's edge, and a few samples rarely land on the farthest spot. Every target
triangle is therefore looked at, on a fine level of the limit surface.
"""
from dataclasses import dataclass

import numpy as np

from core.farthest import farthest_pieces
from core.geometry import triangulate
from core.subdivision.catmull_clark import build_hierarchy, fine_face_owner
from core.subdivision.limit import limit_matrices
from core.target_surface import TargetSurface


@dataclass(frozen=True)
class DeviationSettings:
    """Tuned constants of :func:`face_deviation`."""

    fine_quads: int = 150_000
    """Most quads of the fine level the deviation is measured on (:func:`deviation_level`)."""
    resolution: float = 0.02
    """Smallest target triangle looked at, as its centroid's distance to its farthest corner,
    a fraction of the tolerance: the largest backward deviation is found to within that."""


DEVIATION = DeviationSettings()
"""The settings this module runs with."""


def deviation_level(n_faces):
    """The finest subdivision level whose mesh has at most ``DEVIATION.fine_quads`` quads
    (at least 1) for a cage of ``n_faces`` faces."""
    return int(max(1, np.floor(np.log(DEVIATION.fine_quads / max(n_faces, 1)) / np.log(4.0))))


def fine_limit_points(cage, levels):
    """The level-``levels`` limit points of ``cage`` (closed PolyMesh, ``levels >= 1``).

    Returns
    -------
    X : (n_fine, 3) float64 limit positions of the level-``levels`` vertices (model units).
    fine : PolyMesh, the level-``levels`` mesh (all quads).
    owner : (m_fine,) int64 the base face of each of its quads.
    """
    hierarchy = build_hierarchy(cage, levels)
    fine = hierarchy.meshes[levels]
    X = limit_matrices(fine)[0] @ hierarchy.composite(levels - 1) @ cage.vertices
    return X, fine, fine_face_owner(cage, levels)


@dataclass
class FaceDeviation:
    """Outcome of :func:`face_deviation`.

    per_face : (m,) float64 largest two-sided deviation of each base face's part of the limit
        surface, fractions of the target's bounding-box diagonal; a target piece counts for
        the base face its centroid's closest point lies in.
    unproven_area : float, fraction of the target's area in pieces that may lie beyond the
        tolerance but were left whole when :data:`core.farthest.PIECE_BUDGET` ran out (0:
        the search was exhaustive).
    """

    per_face: np.ndarray
    unproven_area: float


def face_deviation(cage, surface, tolerance):
    """The largest two-sided deviation of each base face's part of the limit surface.

    Parameters
    ----------
    cage : PolyMesh, closed; faces of any size.
    surface : TargetSurface of the target.
    tolerance : float > 0, fraction of ``surface.diagonal``: the backward search is exact to
        ``DEVIATION.resolution * tolerance`` around it and around the largest deviation.

    Returns
    -------
    FaceDeviation
    """
    X, fine, owner = fine_limit_points(cage, deviation_level(cage.n_faces))
    corner_distance = surface.nearest(X).distance[fine.face_vertices.reshape(-1, 4)]
    forward = _largest_per_owner(corner_distance.max(axis=1), owner, cage.n_faces)
    T = triangulate(fine.face_vertices, fine.face_offsets)  # two triangles per fine quad
    threshold = tolerance * surface.diagonal
    backward = farthest_pieces(surface.vertices, surface.faces,
                               TargetSurface(X, T, "fitted surface"), threshold,
                               DEVIATION.resolution * threshold)
    per_face = np.maximum(forward, _largest_per_owner(backward.distance, owner[backward.face // 2],
                                                      cage.n_faces))
    return FaceDeviation(per_face / surface.diagonal, backward.unproven_area)


def _largest_per_owner(values, owner, n):
    """(n,) float64 the largest of ``values`` per ``owner`` index (0 where none)."""
    largest = np.zeros(n)
    np.maximum.at(largest, owner, values)
    return largest
