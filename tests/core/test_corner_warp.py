# SPDX-License-Identifier: LGPL-2.1-or-later
"""Warped fit targets near special vertices (core.export.corner_warp): the exponents of the
limit's growth come from the subdivision's eigenvalues, the warp keeps corners and disk rims
fixed and moves points along their ray, and a G1 export of a cage with a valence-8 vertex
stays closer to the limit surface than an equal-parameter fit can."""
import dataclasses

import numpy as np
import pytest

from core.export.corner_warp import WARP_RADIUS, corner_growth, spoke_growth, warped_params
from core.export.g1_patches import g1_surface_patches
from core.geometry import triangulate
from core.subdivision.catmull_clark import build_hierarchy, crease_edge_mask, mesh_topology
from core.subdivision.limit import limit_matrices
from core.target_surface import TargetSurface
from core.types import PolyMesh


def spindle(n):
    """A closed quad cage with two vertices of valence ``n`` (the tips), a ring of valence-3
    vertices and a ring of valence-4 ones."""
    a = 2.0 * np.pi * np.arange(n) / n
    b = a + np.pi / n
    r = np.stack([np.cos(a), np.sin(a), np.full(n, 0.5)], axis=1)
    s = np.stack([np.cos(b), np.sin(b), np.full(n, 0.5)], axis=1)
    v = np.concatenate([[[0.0, 0.0, 1.0]], r, s, r * [1, 1, -1], s * [1, 1, -1],
                        [[0.0, 0.0, -1.0]]])
    top, ring, mid, ring2, mid2, bottom = 0, 1, 1 + n, 1 + 2 * n, 1 + 3 * n, 1 + 4 * n
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[top, ring + i, mid + i, ring + j], [bottom, ring2 + j, mid2 + i, ring2 + i],
                  [ring + i, ring2 + i, mid2 + i, mid + i], [mid + i, mid2 + i, ring2 + j, ring + j]]
    return PolyMesh.from_faces(v, faces)


def _subdominant(n):
    """Catmull-Clark's subdominant eigenvalue at a smooth vertex of valence ``n``."""
    c1, c2 = np.cos(2.0 * np.pi / n), np.cos(np.pi / n)
    return (5.0 + c1 + c2 * np.sqrt(2.0 * (9.0 + c1))) / 16.0


@pytest.mark.parametrize("n", [3, 5, 8])
def test_growth_is_the_subdivision_exponent(n):
    """Along every spoke of a smooth vertex of valence ``n``: ``-log2`` of Catmull-Clark's
    subdominant eigenvalue (1 at valence 4); exactly 1 at vertices not flagged special."""
    cage = spindle(n)
    topo = mesh_topology(cage.face_vertices, cage.face_offsets, len(cage.vertices))
    crease = crease_edge_mask(topo, cage.creases)
    valence = np.bincount(cage.face_vertices)[cage.face_vertices]
    gamma = spoke_growth(cage, topo, crease, np.ones(len(cage.vertices), dtype=bool))
    assert np.abs(gamma[valence == 4] - 1.0).max() <= 1e-9
    assert np.abs(gamma[valence == n] + np.log2(_subdominant(n))).max() <= 1e-9
    assert np.abs(gamma[valence == 3] + np.log2(_subdominant(3))).max() <= 1e-9
    plain = spoke_growth(cage, topo, crease, np.bincount(cage.face_vertices) == n)
    assert np.all(plain[valence != n] == 1.0)
    sides = corner_growth(topo, gamma)
    assert np.array_equal(sides[..., 0].reshape(-1), gamma)
    assert np.abs(sides[..., 1].reshape(-1) - gamma).max() <= 1e-9  # one value per vertex


def test_crease_spokes_follow_their_crease_curve():
    """Two opposite crease edges out of a valence-8 tip: along them the limit is the crease's
    cubic B-spline (exponent 1), while the spokes between them keep a smaller exponent (the
    faces' ring contracts more slowly than 1/2)."""
    n = 8
    cage = spindle(n)
    cage = dataclasses.replace(cage, creases=np.array([[0, 1], [0, 1 + n // 2]], dtype=np.int64))
    topo = mesh_topology(cage.face_vertices, cage.face_offsets, len(cage.vertices))
    crease = crease_edge_mask(topo, cage.creases)
    gamma = spoke_growth(cage, topo, crease, np.ones(len(cage.vertices), dtype=bool))
    tip = cage.face_vertices == 0
    on_crease = crease[topo.corner_edge]
    assert (tip & on_crease).sum() == 2 and (tip & ~on_crease).sum() == n - 2
    assert np.abs(gamma[tip & on_crease] - 1.0).max() <= 1e-6  # a defective eigenvalue 1/2
    assert gamma[tip & ~on_crease].max() <= 0.95


def test_warp_moves_points_along_their_ray_inside_the_disks_only():
    rng = np.random.default_rng(3)
    u, v = rng.random((2, 1, 400))
    growth = np.array([[[0.7, 0.7], [1.0, 1.0], [1.29, 1.29], [0.9, 0.9]]])
    wu, wv = warped_params(u, v, growth)
    assert np.all((wu >= 0.0) & (wu <= 1.0) & (wv >= 0.0) & (wv <= 1.0))
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    d = np.hypot(u[..., None] - corners[:, 0], v[..., None] - corners[:, 1])[0]
    near = d.argmin(axis=1)
    far = d.min(axis=1) >= WARP_RADIUS
    assert np.array_equal(wu[0, far], u[0, far]) and np.array_equal(wv[0, far], v[0, far])
    c = corners[near]
    before = np.stack([u[0] - c[:, 0], v[0] - c[:, 1]], axis=1)
    after = np.stack([wu[0] - c[:, 0], wv[0] - c[:, 1]], axis=1)
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    assert np.abs(cross).max() <= 1e-12  # same ray from the nearest corner
    r, r_new = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
    g = growth[0, near, 0]
    inside = ~far
    expected = WARP_RADIUS * (r[inside] / WARP_RADIUS) ** (1.0 / g[inside])
    assert np.abs(r_new[inside] - expected).max() <= 1e-12
    cu, cv = warped_params(corners[None, :, 0], corners[None, :, 1], growth)
    assert np.array_equal(cu[0], corners[:, 0]) and np.array_equal(cv[0], corners[:, 1])


def test_valence_eight_tips_stay_close_to_the_limit_surface():
    """Near a valence-8 vertex the limit grows like r ** 0.71; matched at warped parameters
    the G1 patches stay within 1e-3 of the diagonal of the limit surface (an equal-parameter
    fit of the same patches misses it by about twice that), and still join G1."""
    cage = spindle(8)
    ps = g1_surface_patches(cage)
    fine = build_hierarchy(cage, 5).meshes[-1]
    surface = TargetSurface(limit_matrices(fine)[0] @ fine.vertices,
                            triangulate(fine.face_vertices, fine.face_offsets))
    s = np.linspace(0.0, 1.0, 17)
    from core.export.bspline_basis import evaluate_patch_points

    u, v = (a.reshape(-1) for a in np.meshgrid(s, s, indexing="ij"))
    k = len(ps.patches)
    points = evaluate_patch_points(ps.patches, np.repeat(np.arange(k), len(u)), np.tile(u, k),
                                   np.tile(v, k))
    diag = ps.info["bbox_diagonal"]
    assert surface.nearest(points).distance.max() <= 1e-3 * diag
    assert ps.info["max_error_rel"] <= 2e-3
    assert ps.info["normal_jump_max_deg"] <= 0.01
    assert max(p.poles.shape[0] * p.poles.shape[1] for p in ps.patches) <= 64


def test_reported_deviation_finds_the_limit_point_from_a_nearby_start():
    """The G1 report's deviation moves from the warped start to the nearest limit point in
    the quad: limit points found again from perturbed parameters (to rounding of the
    difference steps), and never farther than the start."""
    from core.export.bspline_measure import _closest_in_face
    from core.export.patch_context import PatchContext

    cage = spindle(5)
    ctx = PatchContext(cage, 1)
    rng = np.random.default_rng(7)
    k = 200
    face = rng.integers(0, cage.n_faces, k)
    u, v = rng.uniform(0.1, 0.9, (2, k))
    points = ctx.evaluate(face, u, v)
    du, dv = rng.uniform(-0.05, 0.05, (2, k))
    start = ctx.evaluate(face, u + du, v + dv)
    found = _closest_in_face(ctx, face, u + du, v + dv, points)
    d_start = np.linalg.norm(start - points, axis=1)
    d_found = np.linalg.norm(found - points, axis=1)
    assert np.all(d_found <= d_start)
    assert d_found.max() <= 1e-6 * ctx.bbox_diagonal < d_start.min()
