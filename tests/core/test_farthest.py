# SPDX-License-Identifier: LGPL-2.1-or-later
"""The farthest-point search between two triangle surfaces: every triangle looked at, not
samples of it."""
import numpy as np
import pytest

import core.farthest as farthest
from core.farthest import farthest_pieces
from core.geometry import sample_surface
from core.subdivision.sample_cages import cube
from core.target_surface import TargetSurface

RESOLUTION = 0.02
"""The searches' resolution here, a fraction of their threshold (the tolerance's)."""


def search(target, surface, threshold):
    """:func:`farthest_pieces` of ``target``'s triangles (TargetSurface) against ``surface``."""
    return farthest_pieces(target.vertices, target.faces, surface, threshold,
                           RESOLUTION * threshold)


def square(half):
    """Two triangles covering ``[-half, half]^2`` at ``z = 0``."""
    V = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], float)
    return TargetSurface(V, np.array([[0, 1, 2], [0, 2, 3]]), "square")


def pitted_plane(half, width, depth):
    """The square ``[-half, half]^2`` at ``z = 0`` with a square pit: its rim the square
    ``[-width, width]^2``, its bottom the point ``(0, 0, -depth)``."""
    outer = [[-half, -half], [half, -half], [half, half], [-half, half]]
    rim = [[-width, -width], [width, -width], [width, width], [-width, width]]
    V = np.array([[x, y, 0.0] for x, y in outer + rim] + [[0.0, 0.0, -depth]])
    F = [[i, (i + 1) % 4, 4 + i] for i in range(4)]
    F += [[(i + 1) % 4, 4 + (i + 1) % 4, 4 + i] for i in range(4)]
    F += [[4 + i, 4 + (i + 1) % 4, 8] for i in range(4)]
    return TargetSurface(V, np.array(F), "pitted plane")


def test_the_whole_target_is_looked_at_to_its_resolution():
    """Over a pit 1 wide in a 100 x 100 plane, the plane's points lie up to about 0.5 from the
    pitted surface (0 at its corners); the search finds the largest deviation to within its
    resolution, every piece proven."""
    target, surface = square(50), pitted_plane(50, 0.5, 5.0)
    near = np.stack(np.meshgrid(np.linspace(-1, 1, 401), np.linspace(-1, 1, 401)), -1)
    dense = np.column_stack([near.reshape(-1, 2), np.zeros(401 * 401)])
    largest = surface.nearest(dense).distance.max()  # spacing 0.005 where it is not 0
    assert 0.45 < largest < 0.5
    assert surface.nearest(target.vertices).distance.max() < 1e-9

    threshold = 0.25
    found = search(target, surface, threshold)
    assert found.unproven_area == 0.0
    resolution = RESOLUTION * threshold
    assert largest - resolution <= found.distance.max() <= largest + 1e-9
    far = found.face[found.distance > threshold]
    assert len(far) and (far >= 8).all()  # the pit's own triangles


def test_a_deviation_samples_miss_is_found_and_the_rest_proven():
    """A pit half as wide: 20,000 samples of the plane see at most a fifth of the largest
    deviation; the search finds it to within its resolution and proves the rest of the
    plane."""
    target, surface = square(50), pitted_plane(50, 0.25, 5.0)
    samples = sample_surface(target.vertices, target.faces, 20000, np.random.default_rng(0))
    assert surface.nearest(samples).distance.max() < 0.05
    threshold = 0.12
    found = search(target, surface, threshold)
    assert found.unproven_area == 0.0
    assert 0.24 - RESOLUTION * threshold < found.distance.max() < 0.25


def test_pieces_left_whole_when_the_budget_runs_out_are_reported(monkeypatch):
    monkeypatch.setattr(farthest, "PIECE_BUDGET", 10)
    found = search(square(50), pitted_plane(50, 0.5, 5.0), 0.25)
    # two triangles, their eight quarters looked at, then none: every quarter straddles
    assert len(found.distance) == 2 + 8
    assert found.unproven_area == pytest.approx(1.0)


def test_a_parallel_target_is_proven_without_cutting_it():
    """A 100 x 100 square 0.24 above a 120 x 120 one: ``d + r`` (r about 47)
    passes a threshold of 0.25 everywhere, the distance to the surface triangle closest to
    each centroid is 0.24 at every corner, so the two triangles are proven as they are."""
    square_above = square(50)
    target = TargetSurface(square_above.vertices + [0.0, 0.0, 0.24], square_above.faces)
    found = search(target, square(60), 0.25)
    assert len(found.distance) == 2
    assert found.unproven_area == 0.0
    assert found.distance == pytest.approx(0.24)


def test_the_bounds_are_never_below_a_point_of_the_piece():
    """Random target pieces near a curved surface (the cube's level-4 limit surface): no point
    of a piece lies farther from the surface than the piece's bound."""
    from core.fitting.deviation import fine_limit_points
    from core.geometry import triangulate

    X, fine, _ = fine_limit_points(cube(1.0), 4)
    surface = TargetSurface(X, triangulate(fine.face_vertices, fine.face_offsets))
    rng = np.random.default_rng(3)
    corners = rng.uniform(-0.8, 0.8, (500, 1, 3)) + rng.normal(0, 0.1, (500, 3, 3))
    centroid = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centroid[:, None], axis=2).max(axis=1)
    bound = farthest._bounds(corners, surface.nearest(centroid), radius, surface)
    weights = rng.dirichlet(np.ones(3), 200)  # (200, 3) points of every piece
    inside = np.einsum("sj,kjd->ksd", weights, corners).reshape(-1, 3)
    distance = surface.nearest(inside).distance.reshape(500, 200).max(axis=1)
    assert np.all(distance <= bound + 1e-12)
    assert np.mean(bound < np.linalg.norm(corners - centroid[:, None], axis=2).max(axis=1)
                   + surface.nearest(centroid).distance) > 0.5  # tighter than d + r mostly



def test_only_the_largest_distance_is_searched_for_without_a_threshold():
    """With no threshold the search still finds the pit's largest distance to within its
    resolution, and its upper bound holds every point of the plane."""
    target, surface = square(50), pitted_plane(50, 0.5, 5.0)
    near = np.stack(np.meshgrid(np.linspace(-1, 1, 401), np.linspace(-1, 1, 401)), -1)
    dense = np.column_stack([near.reshape(-1, 2), np.zeros(401 * 401)])
    largest = surface.nearest(dense).distance.max()
    found = farthest_pieces(target.vertices, target.faces, surface, np.inf, 0.005)
    assert found.unproven_area == 0.0
    assert largest - 0.005 <= found.distance.max() <= largest + 1e-9
    assert largest <= found.largest_bound <= found.distance.max() + 0.005 + 1e-9


@pytest.mark.parametrize("threshold, resolution", [(0.25, 0.0), (0.25, -1.0),
                                                   (0.25, np.nan), (0.25, np.inf),
                                                   (np.nan, 0.01)])
def test_a_bad_resolution_or_threshold_is_refused(threshold, resolution):
    from core.errors import ParameterError

    target, surface = square(50), pitted_plane(50, 0.5, 5.0)
    with pytest.raises(ParameterError, match="resolution|threshold"):
        farthest_pieces(target.vertices, target.faces, surface, threshold, resolution)
