# SPDX-License-Identifier: LGPL-2.1-or-later
"""The compiled target surface: closest points, signs, pseudo-normals and ray exits."""
from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import InvalidMeshError
from core.fitting.responses import thickness, vertex_normals
from core.geometry import bisect_long_triangles, face_areas, unit_face_normals
from core.mesh_io import read_triangle_soup
from core.target_surface import TargetSurface
from core.box_tree import closest_on_triangles, nearest_triangles

MESHES = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "meshes"


def brute_force_distance(tri, points):
    """(p,) distance from every point to the nearest of all triangles (no tree)."""
    k = len(tri)
    every, _, _ = closest_on_triangles(np.tile(tri, (len(points), 1, 1)),
                                       np.repeat(points, k, axis=0))
    return np.linalg.norm(every - np.repeat(points, k, axis=0), axis=1).reshape(-1, k).min(1)


def brute_force_exit(X, T, origins, directions, max_length):
    """(r,) first exit along each ray, testing every triangle (numpy, tolerance 1e-9)."""
    tri = X[T]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    m = np.cross(e1, e2)
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    out = np.full(len(origins), np.inf)
    for i, (o, d) in enumerate(zip(origins, directions)):
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        s = o - tri[:, 0]
        q = np.cross(s, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.einsum("ij,ij->i", s, p) / det
            v = (q @ d) / det
            t = np.einsum("ij,ij->i", e2, q) / det
            ok = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (m @ d > 0)
            ok &= (t > 1e-9 * max_length) & (t <= max_length)
        if ok.any():
            out[i] = t[ok].min()
    return out


def test_closest_points_match_brute_force():
    mesh = trimesh.creation.icosphere(2)
    target = TargetSurface(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(3)
    points = rng.normal(size=(300, 3)) * 0.9
    near = target.closest(points)
    brute = brute_force_distance(np.asarray(mesh.triangles), points)
    assert np.allclose(np.linalg.norm(near.point - points, axis=1), brute, atol=1e-12)
    assert np.allclose(near.distance, brute, atol=1e-12)
    assert np.allclose(np.linalg.norm(near.normal, axis=1), 1.0)
    # the closest point lies on the face reported
    again, _, _ = closest_on_triangles(np.asarray(mesh.triangles)[near.face], points)
    assert np.allclose(again, near.point, atol=1e-14)
    # sign of (q - cpp) . pseudo-normal is the exact inside/outside test
    radius = np.linalg.norm(points, axis=1)
    clear = np.abs(radius - 0.97) > 0.04
    assert np.array_equal((near.signed < 0)[clear], (radius < 0.97)[clear])


def test_signs_at_edges_and_corners_of_a_cube():
    # points nearest to an edge or a corner of a box: the face normal of either face
    # could give the wrong sign, the pseudo-normal must not
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    target = TargetSurface(box.vertices, box.faces)
    outside = np.array([[1.5, 1.5, 0.0], [1.2, 1.3, 1.4], [1.01, 0.0, 1.01]])
    inside = np.array([[0.9, 0.95, 0.0], [0.99, 0.98, 0.97], [0.5, 0.0, 0.999]])
    near = target.closest(np.vstack([outside, inside]))
    assert np.all(near.signed[:3] > 0) and np.all(near.signed[3:] < 0)
    assert np.all(near.region[:2] >= 1)
    expected = np.linalg.norm(np.maximum(np.abs(outside) - 1.0, 0.0), axis=1)
    assert np.allclose(near.signed[:3], expected, atol=1e-12)


def test_mixed_triangle_sizes_on_a_real_mesh():
    V, F = read_triangle_soup(MESHES / "idler_riser.stl")
    target = TargetSurface(V, F)
    rng = np.random.default_rng(5)
    lo, hi = V.min(axis=0), V.max(axis=0)
    points = lo + (hi - lo) * rng.uniform(-0.1, 1.1, size=(200, 3))
    brute = brute_force_distance(V[F], points)
    assert np.max(np.abs(target.closest(points).distance - brute)) <= 1e-12 * target.diagonal


def test_bisected_pieces_cover_their_triangles_and_are_short_enough():
    V, F = read_triangle_soup(MESHES / "featuretype.stl")
    edge = np.linalg.norm(V[np.roll(F, -1, axis=1)] - V[F], axis=2)
    longest = 2.0 * np.median(edge)
    P, pieces, owner = bisect_long_triangles(V, F, longest, 10 * len(F))
    assert len(pieces) > 2 * len(F)  # the fans of long slivers were cut
    assert np.array_equal(P[:len(V)], V)
    # every piece short enough, the pieces of a triangle fill it, oriented like it
    piece_edge = np.linalg.norm(P[np.roll(pieces, -1, axis=1)] - P[pieces], axis=2)
    assert piece_edge.max() <= longest
    filled = np.bincount(owner, face_areas(P, pieces), len(F))
    assert np.allclose(filled, face_areas(V, F), rtol=1e-9, atol=0)
    along = np.einsum("ij,ij->i", unit_face_normals(P, pieces), unit_face_normals(V, F)[owner])
    assert np.all(along[face_areas(P, pieces) > 1e-12 * longest ** 2] > 1 - 1e-6)
    # each piece lies in its triangle: its centroid is its own closest point there (to the
    # rounding of the projection onto a needle of a triangle)
    centroid = P[pieces].mean(axis=1)
    again, _, _ = closest_on_triangles(V[F][owner], centroid)
    assert np.abs(again - centroid).max() <= 1e-8 * np.abs(V).max()
    # too many pieces: None, nothing half done
    assert bisect_long_triangles(V, F, longest, len(F) + 10) is None


def test_bisecting_degenerate_triangles_ends():
    # a zero-area needle along a long edge and a triangle with a repeated corner: cut into
    # pieces no longer than asked, each on its line; a limit of 0 asks for endless cuts and
    # gets None at the piece budget; a mesh of one point has nothing to cut
    V = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    F = np.array([[0, 1, 2], [0, 0, 2], [0, 2, 3]])
    P, pieces, owner = bisect_long_triangles(V, F, 1.0, 10_000)
    edge = np.linalg.norm(P[np.roll(pieces, -1, axis=1)] - P[pieces], axis=2)
    assert edge.max() <= 1.0
    assert np.allclose(P[pieces[owner < 2]][:, :, 1:], 0.0)  # the needles stay on their line
    assert np.isclose(face_areas(P, pieces)[owner == 2].sum(), face_areas(V, F)[2])
    assert bisect_long_triangles(V, F, 0.0, 1_000) is None
    point = TargetSurface(np.zeros((3, 3)), np.array([[0, 1, 2]]), split=True)
    assert point._piece_face is None and point.nearest(np.ones((1, 3))).distance[0] > 0


def test_a_split_search_tree_gives_the_same_distances_signs_and_exits():
    V, F = read_triangle_soup(MESHES / "octagonal_pocket.stl")
    whole, split = TargetSurface(V, F), TargetSurface(V, F, split=True)
    assert len(split._tree_mesh[1]) > len(F)  # this CAD mesh's long triangles were cut
    rng = np.random.default_rng(7)
    lo, hi = V.min(axis=0), V.max(axis=0)
    points = np.vstack([lo + (hi - lo) * rng.uniform(-0.1, 1.1, size=(300, 3)),
                        sample_points(V, F, 300, rng)])
    a, b = whole.closest(points), split.closest(points)
    brute = brute_force_distance(V[F], points)
    assert np.max(np.abs(b.distance - brute)) <= 1e-12 * whole.diagonal
    assert np.max(np.abs(b.distance - a.distance)) <= 1e-12 * whole.diagonal
    # the face returned is a triangle of the mesh holding the closest point
    again, _, _ = closest_on_triangles(V[F][b.face], points)
    assert np.allclose(again, b.point, atol=1e-12 * whole.diagonal)
    clear = np.abs(a.signed) > 1e-9 * whole.diagonal
    assert np.array_equal(np.sign(a.signed[clear]), np.sign(b.signed[clear]))
    direction = -vertex_normals(V, F)[::4]
    start = V[::4] + 1e-3 * whole.diagonal * direction  # inside, off the vertices
    exits_a = whole.first_exit(start, direction, whole.diagonal)
    exits_b = split.first_exit(start, direction, whole.diagonal)
    # the same exits but for a few rays (from all vertices 3 of 9,786) that the whole tree's
    # cast took past an exit and the entry behind it; the brute force sides with the split
    # tree on those
    differ = np.flatnonzero(~np.isclose(exits_a.t, exits_b.t, rtol=0,
                                        atol=1e-12 * whole.diagonal))
    assert len(differ) <= 1e-3 * len(start)
    brute = brute_force_exit(V, F, start[differ], direction[differ], whole.diagonal)
    assert np.allclose(exits_b.t[differ], brute, rtol=0, atol=1e-12 * whole.diagonal)
    # a mesh without long triangles keeps its own tree
    sphere = trimesh.creation.icosphere(2)
    assert TargetSurface(sphere.vertices, sphere.faces, split=True)._piece_face is None


def sample_points(V, F, count, rng):
    """``count`` random points on the triangles of ``V``, ``F``."""
    face = rng.integers(len(F), size=count)
    a, b = rng.uniform(size=(2, count))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    tri = V[F[face]]
    return tri[:, 0] + a[:, None] * (tri[:, 1] - tri[:, 0]) + b[:, None] * (tri[:, 2] - tri[:, 0])


def test_ray_exits_of_a_sphere_match_brute_force():
    sphere = trimesh.creation.icosphere(3)
    X, T = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    direction = -vertex_normals(X, T)
    hits = TargetSurface(X, T).first_exit(X, direction, 5.0)
    assert np.all(hits.face >= 0)
    assert np.allclose(hits.t, brute_force_exit(X, T, X, direction, 5.0), atol=1e-12)
    # the hit point is on the hit triangle's plane and its barycentric coordinates sum to 1
    point = X + hits.t[:, None] * direction
    on_face = np.einsum("ij,ijk->ik", hits.bary, X[T[hits.face]])
    assert np.allclose(point, on_face, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", direction, hits.normal) > 0)


def test_rays_through_vertices_and_edges_of_a_slab_are_not_lost():
    # vertices above vertices: every vertical ray leaves exactly through a vertex or edge
    slab = trimesh.creation.box(extents=(2.0, 2.0, 0.1)).subdivide().subdivide()
    X, T = np.asarray(slab.vertices), np.asarray(slab.faces, dtype=np.int64)
    top = np.flatnonzero((X[:, 2] > 0) & (np.abs(X[:, :2]) < 0.9).all(axis=1))
    down = np.tile([0.0, 0.0, -1.0], (len(top), 1))
    surface = TargetSurface(X, T)
    hits = surface.first_exit(X[top], down, 1.0)
    assert np.all(hits.face >= 0)
    assert np.allclose(hits.t, 0.1, atol=1e-12)
    # along the vertex normals (diagonal at the rim) the exits match the brute force
    direction = -vertex_normals(X, T)
    hits = surface.first_exit(X, direction, 1.0)
    brute = brute_force_exit(X, T, X, direction, 1.0)
    assert np.array_equal(np.isfinite(hits.t), np.isfinite(brute))
    assert np.allclose(hits.t[np.isfinite(brute)], brute[np.isfinite(brute)], atol=1e-12)
    # some of them leave exactly through an edge or a vertex (a barycentric coordinate 0)
    on_rim = hits.bary[np.isfinite(hits.t)].min(axis=1) <= 1e-12
    assert on_rim.sum() > 10


def test_ray_exits_on_a_real_mesh_match_brute_force():
    V, F = read_triangle_soup(MESHES / "to_levelset_cantilever_tiny.stl")
    surface = TargetSurface(V, F)
    direction = -vertex_normals(V, F)
    hits = surface.first_exit(V, direction, surface.diagonal)
    brute = brute_force_exit(V, F, V, direction, surface.diagonal)
    assert np.array_equal(np.isfinite(hits.t), np.isfinite(brute))
    finite = np.isfinite(brute)
    assert np.allclose(hits.t[finite], brute[finite], atol=1e-12 * surface.diagonal)
    # thickness uses the same rays: walls no thinner than the exits found
    assert np.allclose(thickness(V, F, surface.diagonal).thickness[finite], brute[finite],
                       atol=1e-12 * surface.diagonal)


def test_rays_longer_than_the_wall_limit_report_no_hit():
    sphere = trimesh.creation.icosphere(2)
    X, T = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    hits = TargetSurface(X, T).first_exit(X, -vertex_normals(X, T), 1.5)
    assert np.all(hits.face == -1) and np.all(np.isinf(hits.t))
    assert np.all(hits.bary == 0)


def test_malformed_arrays():
    sphere = trimesh.creation.icosphere(1)
    with pytest.raises(InvalidMeshError, match="target"):
        TargetSurface(sphere.vertices, np.asarray(sphere.faces) + 100)


def test_samples_lie_on_the_surface_and_are_drawn_once():
    mesh = trimesh.creation.icosphere(3, radius=2.0)
    surface = TargetSurface(mesh.vertices, mesh.faces)
    points, normals = surface.samples(3000, seed=4)
    assert points.shape == normals.shape == (3000, 3)
    assert surface.nearest(points).distance.max() < 1e-12 * surface.diagonal
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    outward = np.einsum("ij,ij->i", normals, points) / np.linalg.norm(points, axis=1)
    assert outward.min() > 0.99                       # outward, near radial on a sphere
    again = surface.samples(3000, seed=4)
    assert again[0] is points and again[1] is normals
    other, _ = surface.samples(3000, seed=5)
    assert not np.array_equal(other, points)


def test_vertex_pseudo_normals_are_angle_weighted():
    """At a corner of the tetrahedron (0, e_x, e_y, e_z) the pseudo-normal is the sum of the
    incident face normals weighted by the face angles there (Baerentzen and Aanaes): at
    e_x the faces z = 0 and y = 0 meet at 45 degrees each, the slanted face at 60."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    surface = TargetSurface(V, F)
    slanted = np.ones(3) / np.sqrt(3.0)
    expected = np.pi / 4 * np.array([0, -1.0, -1.0]) + np.pi / 3 * slanted
    expected /= np.linalg.norm(expected)
    found = surface.closest(np.array([[1.0, 0, 0] + 0.1 * expected]))
    assert found.region[0] >= 4  # the closest point is the corner e_x itself
    assert np.allclose(found.normal[0], expected, atol=1e-12)
    origin = surface.closest(np.array([[-0.1, -0.1, -0.1]]))
    assert np.allclose(origin.normal[0], -slanted, atol=1e-12)


def test_closest_answers_the_same_points_again_from_the_kept_answers():
    """The same points (bit for bit) get the kept answer, read only; a point moved by one
    unit in the last place gets a fresh one; an answer older than ``CLOSEST_KEPT`` other
    queries is recomputed, with the same values."""
    from core.target_surface import CLOSEST_KEPT

    mesh = trimesh.creation.icosphere(3)
    surface = TargetSurface(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(6)
    points = rng.normal(size=(200, 3))
    first = surface.closest(points)
    again = surface.closest(points.copy())
    assert again is first
    with pytest.raises(ValueError):
        first.signed[0] = 0.0
    moved = points.copy()
    moved[7, 0] = np.nextafter(moved[7, 0], np.inf)
    fresh = surface.closest(moved)
    assert fresh is not first
    np.testing.assert_array_equal(fresh.signed, TargetSurface(mesh.vertices, mesh.faces)
                                  .closest(moved).signed)
    for k in range(CLOSEST_KEPT):
        surface.closest(points + (k + 1.0))
    recomputed = surface.closest(points)
    assert recomputed is not first
    for name, value in vars(first).items():
        np.testing.assert_array_equal(getattr(recomputed, name), value)


def test_samples_nearest_keeps_its_answer_per_mesh():
    """The closest points on another mesh to the samples are those of a fresh
    ``TargetSurface`` of it; the same mesh (bit for bit) gets the kept answer again."""
    mesh = trimesh.creation.icosphere(3)
    surface = TargetSurface(mesh.vertices, mesh.faces)
    other = trimesh.creation.icosphere(2)
    vertices = 0.9 * other.vertices
    near, normals = surface.samples_nearest(vertices, other.faces, 300, seed=2)
    fresh = TargetSurface(vertices, other.faces).nearest(surface.samples(300, 2)[0])
    np.testing.assert_array_equal(near.point, fresh.point)
    np.testing.assert_array_equal(normals, TargetSurface(vertices, other.faces)
                                  .face_normals[fresh.face])
    again = surface.samples_nearest(vertices.copy(), other.faces.copy(), 300, seed=2)
    assert again[0] is near and again[1] is normals
    assert surface.samples_nearest(vertices * 1.01, other.faces, 300, seed=2)[0] is not near


def test_nearest_answers_each_point_as_the_tree_does_alone_whatever_the_order():
    """The points are queried in Z-order: each answer is the tree's for that point (the
    faces of a query point by point), and shuffling the points shuffles the answers."""
    mesh = trimesh.creation.icosphere(3)
    surface = TargetSurface(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(7)
    points = rng.normal(size=(400, 3)) * rng.uniform(0.2, 2.0, (400, 1))
    near = surface.nearest(points)
    alone = [int(nearest_triangles(surface._point_tree, point[None])[0]) for point in points]
    np.testing.assert_array_equal(near.face, alone)
    shuffle = rng.permutation(len(points))
    again = surface.nearest(points[shuffle])
    np.testing.assert_array_equal(again.face, near.face[shuffle])
    np.testing.assert_array_equal(again.point, near.point[shuffle])
    assert len(surface.nearest(np.zeros((0, 3))).face) == 0


def test_a_few_points_get_the_answers_they_get_within_a_large_query():
    """Queries of fewer than ORDERED_QUERIES points are searched as given, larger ones in
    Z-order: the answers (closest points, normals, ties) are the same bit for bit."""
    from core.target_surface import ORDERED_QUERIES

    mesh = trimesh.creation.icosphere(3)
    surface = TargetSurface(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(11)
    count = 4 * ORDERED_QUERIES
    points = rng.normal(size=(count, 3)) * rng.uniform(0.2, 2.0, (count, 1))
    points[:2] = 0.0  # the centre: tied with every direction
    whole = surface.closest(points)
    for start, size in ((0, 1), (0, 3), (5, ORDERED_QUERIES - 1), (7, ORDERED_QUERIES)):
        part = TargetSurface(mesh.vertices, mesh.faces).closest(points[start:start + size])
        for name, value in vars(part).items():
            np.testing.assert_array_equal(value, getattr(whole, name)[start:start + size])


def test_a_point_between_two_walls_is_tied_whatever_its_last_bits():
    # midway inside a thin slab both walls are as near: whichever one rounding names, the
    # answer names the other too, and the mean plane of the two is the same
    slab = trimesh.creation.box(extents=(4.0, 4.0, 0.2))
    target = TargetSurface(slab.vertices, slab.faces, split=True)
    rng = np.random.default_rng(1)
    middle = np.column_stack([rng.uniform(-1.5, 1.5, (50, 2)), np.zeros(50)])
    planes = []
    for noise in (0.0, 1e-13, -1e-13):
        near = target.closest(middle + [0.0, 0.0, noise])
        assert near.tied.all()
        walls = np.sort(np.column_stack([near.point[:, 2], near.other_point[:, 2]]), axis=1)
        assert np.allclose(walls, [-0.1, 0.1], atol=1e-12)
        planes.append(near.mean_plane())
    for normal, offset in planes[1:]:
        assert np.allclose(normal, planes[0][0], atol=1e-9)
        assert np.allclose(offset, planes[0][1], atol=1e-9)
    assert np.abs(planes[0][0]).max() < 1e-9  # opposite walls: the mean normal vanishes


def test_points_off_the_medial_axis_are_not_tied_and_keep_their_plane():
    slab = trimesh.creation.box(extents=(4.0, 4.0, 0.2))
    target = TargetSurface(slab.vertices, slab.faces)
    points = np.array([[0.3, 0.2, 0.02], [0.0, 0.0, 0.5], [1.0, -1.0, -0.09],
                       [0.5, 0.5, 0.1]])  # the last on the surface
    near = target.closest(points)
    assert not near.tied.any()
    normal, offset = near.mean_plane()
    assert np.array_equal(normal, near.normal)
    assert np.allclose(offset, np.einsum("ij,ij->i", near.normal, near.point), atol=0)


def test_a_point_outside_a_concave_corner_pulls_along_its_bisector():
    # an L-shaped solid: outside its inner corner, on the bisector, both faces are as near,
    # and the packaging gradient is the mean of the two distance gradients
    from core.fitting.responses import packaging

    a = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    a.apply_translation([0.0, -0.5, 0.0])
    b = trimesh.creation.box(extents=(1.0, 2.0, 1.0))
    b.apply_translation([-0.5, 0.0, 0.0])
    solid = a.union(b, engine="manifold")
    target = TargetSurface(solid.vertices, solid.faces)
    on_bisector = np.array([[0.2, 0.2, 0.1], [0.05, 0.05, -0.2]])
    near = target.closest(on_bisector)
    assert near.tied.all() and (near.signed > 0).all()
    _, gradient, _ = packaging(on_bisector, target)
    assert np.allclose(gradient, [[0.5, 0.5, 0.0]] * 2, atol=1e-12)


def test_no_query_points_give_empty_answers_with_their_ties():
    box = trimesh.creation.box()
    near = TargetSurface(box.vertices, box.faces, split=True).closest(np.zeros((0, 3)))
    normal, offset = near.mean_plane()
    assert near.tied.shape == (0,) and normal.shape == (0, 3) and offset.shape == (0,)


def test_a_query_differing_in_a_few_points_answers_as_a_fresh_surface_does():
    """The rows of the latest query of as many points are reused where the points are the
    same bit for bit; the others are computed: every array equals a fresh surface's."""
    mesh = trimesh.creation.icosphere(subdivisions=3)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)
    rng = np.random.default_rng(11)
    points = rng.normal(size=(300, 3)) * 0.8
    moved = points.copy()
    moved[::7] += rng.normal(size=moved[::7].shape) * 0.3
    moved[1] = -0.0 * moved[1]  # a sign bit alone is a change
    surface = TargetSurface(V, F, split=True)
    surface.closest(points)
    reused = surface.closest(moved)
    fresh = TargetSurface(V, F, split=True).closest(moved)
    for name, value in vars(fresh).items():
        assert np.array_equal(getattr(reused, name), value), name
    assert np.all(reused.signed[np.linalg.norm(moved, axis=1) < 0.5] < 0)
