# SPDX-License-Identifier: LGPL-2.1-or-later
"""The tolerance's deviation measure per base face, both ways (the backward search itself:
``test_farthest.py``)."""
import numpy as np
import pytest

import core.fitting.deviation as deviation
from core.fitting.deviation import deviation_level, face_deviation
from core.subdivision.sample_cages import cube
from core.target_surface import TargetSurface


@pytest.mark.slow
def test_face_deviation_of_a_scaled_limit_surface():
    """The target is the cube cage's own limit surface (level 5) scaled by 1.02 about its
    centre: every face deviates by about 0.02 of the distance from the centre, which lies
    between half the cube's side (face centres) and its limit surface's corners."""
    from core.fitting.deviation import fine_limit_points
    from core.geometry import triangulate

    cage = cube(1.0)
    X, fine, _ = fine_limit_points(cage, 5)
    centre = X.mean(axis=0)
    radius = np.linalg.norm(X - centre, axis=1)
    target = TargetSurface(centre + 1.02 * (X - centre),
                           triangulate(fine.face_vertices, fine.face_offsets))
    tolerance = 0.5 * 0.02 * radius.max() / target.diagonal
    result = face_deviation(cage, target, tolerance)
    assert result.per_face.shape == (6,)
    assert result.unproven_area == 0.0
    per_face = result.per_face * target.diagonal  # model units
    # the scaled surface's distance is at most 0.02 r (r from the centre) and, the limit
    # surface convex, at least 0.02 times its inscribed radius; the level-5 chords and the
    # search's resolution add a little
    assert np.all(per_face >= 0.02 * radius.min() * 0.99)
    assert np.all(per_face <= 0.02 * radius.max() * 1.01)
    assert np.ptp(per_face) < 1e-3 * per_face.max()  # the six faces alike


@pytest.mark.parametrize("faces, level", [(6, 7), (300, 4), (600, 3), (1500, 3), (40000, 1)])
def test_deviation_level_keeps_the_fine_mesh_within_its_budget(faces, level):
    assert deviation_level(faces) == level
    assert level == 1 or faces * 4 ** level <= deviation.DEVIATION.fine_quads