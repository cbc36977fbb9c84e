# SPDX-License-Identifier: LGPL-2.1-or-later
"""Where a cage's Catmull-Clark limit surface crosses itself, and at which subdivision level
the fit, the base mesh and the export look for it.

A solid needs a limit surface that does not cross itself: the base-mesh stage compares its
candidate cages by these crossings, the fit holds back the moves that make them, and the
export refuses a cage that still has them. All three count on the same limit mesh, the
subdivided cage with its vertices at their limit positions, its quads split into triangles.
"""
from dataclasses import dataclass

import numpy as np

FIT_FACE_BUDGET = 40_000
"""Most faces of the subdivided mesh the fit works on: above it, fewer levels are used
(the closest-point queries and thickness rays of every iteration scale with it)."""

EXPORT_CHECK_LEVELS = 2
"""Subdivision level at which the export checks that a limit surface does not cross itself
(:func:`export_limit_crossings`): the fit's default (paper: 2), at which the fit holds
crossings back, fewer only where the fit also takes fewer (:data:`FIT_FACE_BUDGET`). A coarser
check would refuse fitted cages the fit found clean: coarse level-1 triangles can cross where
the level-2 surface does not."""


def fit_levels(n_base_faces, wanted):
    """Subdivision levels for the fit: ``wanted``, fewer if the fine mesh would exceed the budget."""
    affordable = int(np.floor(np.log(FIT_FACE_BUDGET / max(n_base_faces, 1)) / np.log(4.0)))
    return int(max(1, min(wanted, affordable)))


def count_limit_self_intersections(base, levels):
    """Intersecting triangle pairs of the level-``levels`` limit mesh of ``base`` (0 = clean)."""
    return int(len(limit_self_intersections(base, levels)[0]))


def limit_self_intersections(base, levels):
    """Where the level-``levels`` limit mesh of ``base`` intersects itself.

    The base mesh is subdivided ``levels >= 1`` times, its vertices moved to their
    limit positions and its quads split into two triangles each.

    Returns
    -------
    pairs : (k, 2) int64 intersecting triangle pairs (``core.self_intersection``).
    base_faces : (k, 2) int64 the base faces the two triangles of each pair lie on.
    points : (k, 3) float64 the centroid of the first triangle of each pair.
    """
    from core.geometry import triangulate
    from core.self_intersection import find_self_intersections
    from core.subdivision.catmull_clark import build_hierarchy, fine_face_owner
    from core.subdivision.limit import limit_matrices

    fine = build_hierarchy(base, levels).meshes[levels]
    limit, _, _ = limit_matrices(fine)
    points = limit @ fine.vertices
    triangles = triangulate(fine.face_vertices, fine.face_offsets)
    pairs = find_self_intersections(points, triangles)
    base_faces = fine_face_owner(base, levels)[pairs // 2]
    return pairs, base_faces, points[triangles[pairs[:, 0]]].mean(axis=1)


@dataclass(frozen=True)
class LimitCrossings:
    """Where a cage's limit surface crosses itself (:func:`export_limit_crossings`).

    levels : int, the subdivision level checked.
    pairs, base_faces, points : as returned by :func:`limit_self_intersections`.
    """

    levels: int
    pairs: np.ndarray
    base_faces: np.ndarray
    points: np.ndarray

    @property
    def count(self):
        """Crossing triangle pairs (0 = the surface does not cross itself)."""
        return int(len(self.pairs))

    def message(self):
        """What crosses and where, for an error message (the surface must cross)."""
        x, y, z = self.points[0]
        return (f"the limit surface intersects itself ({self.count} crossing triangle pairs "
                f"of its level-{self.levels} limit mesh), e.g. between base faces "
                f"{self.base_faces[0, 0]} and {self.base_faces[0, 1]} near "
                f"({x:.6g}, {y:.6g}, {z:.6g}); a STEP solid of it would not be a solid")


def export_limit_crossings(base):
    """The export's check that the limit surface of ``base`` does not cross itself.

    Tested on the limit mesh at :data:`EXPORT_CHECK_LEVELS` (fewer for cages so large that
    the fit takes fewer, :func:`fit_levels`); ``subd-to-step`` refuses a cage that fails it, and
    the pipeline refuses to build a solid of a fitted cage that fails it
    (``core.stages.patches``).

    Returns
    -------
    LimitCrossings
    """
    levels = fit_levels(base.n_faces, EXPORT_CHECK_LEVELS)
    return LimitCrossings(levels, *limit_self_intersections(base, levels))
