# SPDX-License-Identifier: LGPL-2.1-or-later
"""Catmull-Clark matrices, limit masks and exact limit evaluation."""
import numpy as np
import pytest

from core.errors import InvalidMeshError
from core.subdivision import sample_cages as sc
from core.subdivision.catmull_clark import build_hierarchy, face_grids, subdivide
from core.subdivision.limit import (LimitEvaluator, bspline_weights, limit_matrices,
                                    limit_normals, limit_volume, quad_mesh_of, template_matrix)
from core.types import PolyMesh

CAGES = ["cube", "torus", "mixed_prism", "pentagonal_prism", "genus3_block"]


@pytest.fixture(params=CAGES)
def cage(request):
    return getattr(sc, request.param)()


def test_rows_sum_to_one_and_counts(cage):
    fine, S = subdivide(cage)
    n, m = len(cage.vertices), cage.n_faces
    e = len(cage.face_vertices) // 2
    assert S.shape == (n + m + e, n)
    assert np.abs(np.asarray(S.sum(axis=1)).ravel() - 1.0).max() < 1e-14
    assert (fine.face_sizes == 4).all() and fine.n_faces == len(cage.face_vertices)
    assert S.min() >= 0.0


def test_affine_invariance(cage):
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    t = rng.normal(size=3)
    _, S = subdivide(cage)
    X = cage.vertices
    assert np.allclose(S @ (X @ A + t), (S @ X) @ A + t, atol=1e-12)


def test_rules_match_opensubdiv_formulas():
    """Face, edge and vertex points of the mixed mesh against the textbook rules."""
    mesh = sc.mixed_prism()
    X = np.random.default_rng(1).normal(size=mesh.vertices.shape)
    mesh = PolyMesh(X, mesh.face_vertices, mesh.face_offsets)
    fine, _ = subdivide(mesh)
    n, faces = len(X), mesh.faces()
    centres = np.array([X[f].mean(axis=0) for f in faces])
    assert np.allclose(fine.vertices[n:n + len(faces)], centres, atol=1e-14)
    for v in range(n):
        adj = [i for i, f in enumerate(faces) if v in f]
        nbrs = sorted({int(f[(list(f).index(v) + s) % len(f)]) for f in faces if v in f
                       for s in (1, -1)})
        k = len(adj)
        Q = centres[adj].mean(axis=0)
        R = np.mean([(X[v] + X[w]) / 2 for w in nbrs], axis=0)
        expected = (Q + 2 * R + (k - 3) * X[v]) / k
        assert np.allclose(fine.vertices[v], expected, atol=1e-13)
    # edge point of edge (0, 1): average of its ends and the two face points
    corners = fine.face_vertices.reshape(-1, 4)
    adj = [i for i, f in enumerate(faces) if 0 in f and 1 in f]
    expected = (X[0] + X[1] + centres[adj[0]] + centres[adj[1]]) / 4
    assert np.min(np.linalg.norm(fine.vertices[np.unique(corners[:, 1])] - expected,
                                 axis=1)) < 1e-13


def test_open_mesh_rejected():
    cube = sc.cube()
    faces = cube.faces()[1:]
    with pytest.raises(InvalidMeshError) as err:
        subdivide(PolyMesh.from_faces(cube.vertices, faces))
    assert err.value.reason == "open"


def test_hierarchy_composite_and_adjoint():
    h = build_hierarchy(sc.mixed_prism(), 3)
    S2 = h.composite(2)
    X0 = h.meshes[0].vertices
    assert np.allclose(S2 @ X0, h.meshes[3].vertices, atol=1e-13)
    assert np.allclose(h.positions(X0, 3), h.meshes[3].vertices, atol=1e-13)
    assert np.abs(np.asarray(S2.sum(axis=1)).ravel() - 1).max() < 1e-13
    # gradient of f(V3) = sum(sin(V3) * W) mapped back with S_2^T vs central differences
    rng = np.random.default_rng(2)
    W = rng.normal(size=h.meshes[3].vertices.shape)
    f = lambda X: float(np.sum(np.sin(S2 @ X) * W))  # noqa: E731
    grad = S2.T @ (np.cos(S2 @ X0) * W)
    eps = 1e-6
    for i, k in [(0, 0), (5, 2), (12, 1), (13, 0)]:
        Xp, Xm = X0.copy(), X0.copy()
        Xp[i, k] += eps
        Xm[i, k] -= eps
        assert abs((f(Xp) - f(Xm)) / (2 * eps) - grad[i, k]) < 1e-7


def _uniform_bspline(P, u, v):
    """Direct evaluation of the uniform bicubic B-spline of a 4 x 4 net at (u, v)."""
    def basis(t):
        return np.array([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4,
                         -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3]) / 6
    return np.einsum("i,j,ijk->k", basis(u), basis(v), P)


def test_regular_grid_is_uniform_bspline():
    """Torus (all valence 4): limit points of level 3 equal the analytic B-spline."""
    n_major, n_minor = 8, 6
    mesh = sc.torus(n_major, n_minor)
    h = build_hierarchy(mesh, 3)
    L, _, _ = limit_matrices(h.meshes[3])
    lim = L @ h.meshes[3].vertices
    grid = face_grids(h, 3)
    X = mesh.vertices.reshape(n_major, n_minor, 3)
    worst = 0.0
    for f in (0, 13, 47):
        i, j = divmod(f, n_minor)
        net = X[np.ix_((i + np.arange(-1, 3)) % n_major, (j + np.arange(-1, 3)) % n_minor)]
        for a in range(9):
            for b in range(9):
                p = _uniform_bspline(net, a / 8, b / 8)
                worst = max(worst, np.linalg.norm(p - lim[grid[f, a, b]]))
    assert worst < 1e-12


def test_limit_points_converge_to_masks():
    mesh = quad_mesh_of(sc.mixed_prism())
    h = build_hierarchy(mesh, 6)
    L, _, _ = limit_matrices(mesh)
    lim = L @ mesh.vertices
    n = len(mesh.vertices)
    errs = [np.abs(h.meshes[k].vertices[:n] - lim).max() for k in (3, 4, 5, 6)]
    assert errs[-1] < 1e-3 * np.ptp(mesh.vertices)
    assert all(e1 < 0.5 * e0 for e0, e1 in zip(errs, errs[1:]))


def test_limit_normals_match_surface():
    """Mask normals at EVs against normals of the exact surface at a tiny offset."""
    mesh = quad_mesh_of(sc.mixed_prism())
    ev = LimitEvaluator(mesh)
    nrm = limit_normals(mesh)
    L, Tu, Tv = limit_matrices(mesh)
    assert np.abs(np.asarray(Tu.sum(axis=1))).max() < 1e-12
    fv = mesh.face_vertices.reshape(-1, 4)
    eps = 2.0 ** -14
    worst = 0.0
    for f in range(mesh.n_faces):
        v = fv[f, 0]
        p = ev.evaluate([f, f, f], [0.0, eps, 0.0], [0.0, 0.0, eps])
        assert np.allclose(p[0], (L @ mesh.vertices)[v], atol=1e-14)
        n_fd = np.cross(p[1] - p[0], p[2] - p[0])
        n_fd /= np.linalg.norm(n_fd)
        worst = max(worst, np.degrees(np.arccos(np.clip(n_fd @ nrm[v], -1, 1))))
    assert worst < 0.5


@pytest.mark.parametrize("name", ["cube", "mixed_prism", "genus3_block"])
def test_exact_evaluation_matches_masks(name):
    """Template-based evaluation near EVs equals level-5 limit masks at dyadic points."""
    mesh = quad_mesh_of(getattr(sc, name)())
    h = build_hierarchy(mesh, 5)
    L, _, _ = limit_matrices(h.meshes[5])
    lim = L @ h.meshes[5].vertices
    grid = face_grids(h, 5)
    t = np.arange(33) / 32
    U, V = np.meshgrid(t, t, indexing="ij")
    faces = np.repeat(np.arange(mesh.n_faces), U.size)
    P = LimitEvaluator(mesh).evaluate(faces, np.tile(U.ravel(), mesh.n_faces),
                                      np.tile(V.ravel(), mesh.n_faces))
    assert np.abs(P - lim[grid.reshape(-1)]).max() < 1e-12


def test_template_matrices_are_affine():
    for n in (3, 5, 6, 7):
        A = template_matrix(n)
        assert A.shape == (1 + 12 * n, 1 + 12 * n)
        assert np.abs(A.sum(axis=1) - 1).max() < 1e-14


def test_bspline_weights_partition_of_unity():
    t = np.linspace(0, 1, 11)
    assert np.allclose(bspline_weights(t).sum(axis=1), 1.0)


def test_limit_volume_converges():
    cube = sc.cube()
    v4, v5, v6 = (limit_volume(cube, k) for k in (4, 5, 6))
    assert abs(v6 - v5) < 1e-5 * v6 and abs(v5 - v4) < 1e-4 * v6
    assert 0.3 < v6 < 0.4
    big = PolyMesh(cube.vertices * 2.0, cube.face_vertices, cube.face_offsets)
    assert abs(limit_volume(big, 5) - 8 * v5) < 1e-12
