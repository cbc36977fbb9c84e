# SPDX-License-Identifier: LGPL-2.1-or-later
"""Infinitely sharp creases: subdivision rules, limit masks and limit evaluation."""
from dataclasses import replace

import numpy as np
import pytest

from core.errors import InvalidMeshError
from core.subdivision import sample_cages as sc
from core.subdivision.catmull_clark import (build_hierarchy, face_grids, mesh_topology,
                                            subdivide, subdivision_operator)
from core.export.bspline import limit_surface_patches
from core.export.bspline_tessellation import enclosed_volume
from core.subdivision.limit import LimitEvaluator, bspline_weights, limit_matrices, quad_mesh_of


def _all_creased(mesh):
    topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    return replace(mesh, creases=topo.edges)


def _torus_with_crease_loop(n_major=8, n_minor=6):
    """The quad torus with the ring ``j = 0`` (a loop of ``n_major`` edges) creased."""
    mesh = sc.torus(n_major, n_minor)
    ring = np.arange(n_major) * n_minor
    return replace(mesh, creases=np.stack([ring, np.roll(ring, -1)], axis=1))


def test_creased_cube_subdivides_to_itself():
    """All 12 edges creased: every level's vertices lie on the cube's faces, corners stay."""
    cube = _all_creased(sc.cube())
    h = build_hierarchy(cube, 4)
    for level in range(1, 5):
        X = h.meshes[level].vertices
        assert np.array_equal(X[:8], cube.vertices)
        assert X.min() >= 0.0 and X.max() <= 1.0
        # every vertex on a face plane of the cube, every quad planar on one face
        corners = X[h.meshes[level].face_vertices.reshape(-1, 4)]
        on_plane = ((np.abs(corners) < 1e-15) | (np.abs(corners - 1) < 1e-15)).all(axis=1)
        assert on_plane.any(axis=1).all()
    fine = h.meshes[4]
    L, Tu, Tv = limit_matrices(fine)
    lim = L @ fine.vertices
    assert np.abs(np.minimum(np.abs(lim), np.abs(lim - 1)).min(axis=1)).max() < 1e-15
    nrm = np.cross(Tu @ fine.vertices, Tv @ fine.vertices)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    # one-sided normals of the corners and crease vertices are face normals pointing out
    centre = lim - 0.5
    assert (np.abs(nrm).max(axis=1) > 1 - 1e-12).all()
    assert (np.einsum("ij,ij->i", nrm, centre) > 0).all()


def test_crease_limit_is_the_bspline_curve_of_its_polygon():
    """A creased ring of the torus: its limit is the closed cubic B-spline of the ring."""
    n_major, n_minor = 8, 6
    mesh = _torus_with_crease_loop(n_major, n_minor)
    h = build_hierarchy(mesh, 3)
    L, _, _ = limit_matrices(h.meshes[3])
    lim = L @ h.meshes[3].vertices
    grid = face_grids(h, 3)
    P = mesh.vertices[np.arange(n_major) * n_minor]
    worst = 0.0
    for i in range(n_major):
        f = i * n_minor  # the quad (i, 0): its side v = 0 is the crease edge (i, i + 1)
        w = bspline_weights(np.arange(9) / 8.0)
        curve = w @ P[(i + np.arange(-1, 3)) % n_major]
        worst = max(worst, np.abs(lim[grid[f, :, 0]] - curve).max())
    assert worst < 1e-12
    # and the smooth torus limit differs there by far more
    smooth_h = build_hierarchy(sc.torus(n_major, n_minor), 3)
    smooth = limit_matrices(smooth_h.meshes[3])[0] @ smooth_h.meshes[3].vertices
    assert np.linalg.norm(smooth[grid[0, :, 0]] - lim[grid[0, :, 0]], axis=1).min() > 0.1


def test_limit_masks_with_crease_corner_and_dart():
    """Level-k vertices converge to the crease, corner and dart limit masks (O(4^-k))."""
    mesh = quad_mesh_of(sc.mixed_prism())
    topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    # every edge at vertex 0 (a corner), a path 1-2-3 through vertex 2, one edge at vertex 5
    at0 = topo.edges[(topo.edges == 0).any(axis=1)]
    others = topo.edges[~(topo.edges == 0).any(axis=1)][[0, 7, 20]]
    creased = replace(mesh, creases=np.concatenate([at0, others]))
    counts = np.bincount(creased.creases.reshape(-1), minlength=len(mesh.vertices))
    assert counts.max() >= 3 and (counts == 2).any() and (counts == 1).any()
    h = build_hierarchy(creased, 6)
    lim = limit_matrices(creased)[0] @ creased.vertices
    n = len(mesh.vertices)
    errs = [np.abs(h.meshes[k].vertices[:n] - lim).max() for k in (3, 4, 5, 6)]
    assert errs[-1] < 1e-3 * np.ptp(mesh.vertices)
    assert all(e1 < 0.5 * e0 for e0, e1 in zip(errs, errs[1:]))
    assert np.array_equal(h.meshes[6].vertices[0], mesh.vertices[0])


def test_no_creases_leave_the_operator_unchanged():
    mesh = sc.mixed_prism()
    args = (mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    S0 = subdivision_operator(*args)[2]
    S1 = subdivision_operator(*args, creases=np.zeros((0, 2), dtype=np.int64))[2]
    assert (S0 != S1).nnz == 0 and np.array_equal(S0.indptr, S1.indptr)
    fine, _ = subdivide(mesh)
    assert fine.creases is None


def test_crease_that_is_not_an_edge_is_refused():
    cube = replace(sc.cube(), creases=np.array([[0, 6]]))
    with pytest.raises(InvalidMeshError) as err:
        subdivide(cube)
    assert err.value.reason == "crease_not_edge"


def _dyadic_error(mesh, level):
    """Largest distance between the exact evaluator and the level-``level`` limit points
    (crease masks of :func:`limit_matrices`) at the dyadic parameters of every face."""
    evaluator = LimitEvaluator(mesh)
    h = build_hierarchy(mesh, level)
    lim = limit_matrices(h.meshes[level])[0] @ h.meshes[level].vertices
    grid = face_grids(h, level)
    k = 2 ** level
    a, b = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    face = np.repeat(np.arange(mesh.n_faces), (k + 1) ** 2)
    u = np.tile(a.reshape(-1) / k, mesh.n_faces)
    v = np.tile(b.reshape(-1) / k, mesh.n_faces)
    points = evaluator.evaluate(face, u, v)
    return np.linalg.norm(points - lim[grid.reshape(-1)], axis=1).max()


def _random_creases(mesh, count, seed):
    topo = mesh_topology(mesh.face_vertices, mesh.face_offsets, len(mesh.vertices))
    pick = np.random.default_rng(seed).choice(len(topo.edges), count, replace=False)
    return replace(mesh, creases=topo.edges[pick])


@pytest.mark.parametrize("name", ["cube_all", "torus_ring", "prism_random", "genus3_random"])
def test_exact_evaluation_with_creases_matches_the_masks(name):
    """Regular crease quads (phantom nets) and crease templates (darts, corners, crease
    vertices of any valence) against subdivision plus limit masks, at level-4 parameters."""
    mesh = {"cube_all": lambda: _all_creased(sc.cube()),
            "torus_ring": _torus_with_crease_loop,
            "prism_random": lambda: _random_creases(quad_mesh_of(sc.mixed_prism()), 25, 1),
            "genus3_random": lambda: _random_creases(quad_mesh_of(sc.genus3_block()), 40, 0),
            }[name]()
    assert _dyadic_error(mesh, 4) < 1e-12 * np.ptp(mesh.vertices)


def test_creased_box_exports_exactly_with_jumps_only_on_creases():
    """A refined cube cage creased along the cube's edges: its limit is the cube, the patches
    reproduce it, and the normal jumps only across the 24 crease B-rep edges."""
    fine, _ = subdivide(_all_creased(sc.cube()))
    patches = limit_surface_patches(fine)
    info = patches.info
    assert info["max_error_rel"] < 1e-12
    assert info["normal_jump_crease_edges"] == 24
    assert info["normal_jump_max_deg"] < 1e-6
    assert abs(enclosed_volume(patches.patches) - 1.0) < 1e-9
