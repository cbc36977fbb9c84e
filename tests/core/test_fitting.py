# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit stage (paper Sect. 2.5): closest points, responses, gradient mapping, RGP fit."""
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from core.errors import InvalidMeshError, ParameterError
from core.fitting import TargetSurface, fit_base_mesh
from core.fitting.records import WarmStart
from core.fitting.best_fit import NormalEquations, _FineEntries, _umbrella, best_fit
from core.fitting.responses import (InsideBounds, packaging, thickness, thickness_constraint,
                                    volume)
from core.geometry import triangulate
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices
from core.subdivision.sample_cages import cube, grid_sphere
from core.types import PolyMesh, TriMesh


def sphere_target(radius, subdivisions=4):
    mesh = trimesh.creation.icosphere(subdivisions, radius=radius)
    return TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64))


def centred_cube(size):
    c = cube(size)
    return PolyMesh(c.vertices - 0.5 * size, c.face_vertices, c.face_offsets)


def fine_mesh(base, levels):
    h = build_hierarchy(base, levels)
    fine = h.meshes[levels]
    return h, fine, triangulate(fine.face_vertices, fine.face_offsets)


def limit_points(base, levels):
    h, fine, T = fine_mesh(base, levels)
    L, _, _ = limit_matrices(fine)
    return L @ h.composite(levels - 1) @ base.vertices, T


def test_volume_gradient_matches_finite_differences():
    _, fine, T = fine_mesh(grid_sphere(2), 1)
    rng = np.random.default_rng(0)
    X = fine.vertices + 0.05 * rng.normal(size=fine.vertices.shape)
    value, grad = volume(X, T)
    assert value == pytest.approx(trimesh.Trimesh(X, T, process=False).volume, rel=1e-12)
    h = 1e-3  # volume is linear in one coordinate of one vertex: no truncation error
    for j in rng.choice(len(X), 8, replace=False):
        for k in range(3):
            Xp, Xm = X.copy(), X.copy()
            Xp[j, k] += h
            Xm[j, k] -= h
            fd = (volume(Xp, T)[0] - volume(Xm, T)[0]) / (2 * h)
            assert fd == pytest.approx(grad[j, k], rel=1e-6, abs=1e-9)


def test_packaging_gradient_matches_finite_differences_where_active():
    sphere = sphere_target(1.0, 3)
    target = TargetSurface(sphere.vertices, sphere.faces)
    rng = np.random.default_rng(1)
    X = rng.normal(size=(400, 3))
    X *= (rng.uniform(0.7, 1.3, 400) / np.linalg.norm(X, axis=1))[:, None]
    value, grad, signed = packaging(X, target)
    assert value == pytest.approx(signed[signed > 0].sum())
    active = np.flatnonzero(signed > 1e-3)
    assert len(active) > 50
    inactive = np.flatnonzero(signed < -1e-3)
    assert np.all(grad[inactive] == 0)
    h = 1e-7
    for k in range(3):
        # the sum is separable per vertex: perturb all active vertices at once
        Xp, Xm = X.copy(), X.copy()
        Xp[active, k] += h
        Xm[active, k] -= h
        fd = (target.closest(Xp).signed - target.closest(Xm).signed) / (2 * h)
        assert np.allclose(fd[active], grad[active, k], rtol=1e-6, atol=1e-6)


def test_inside_bounds_skip_only_points_proven_inside_and_change_nothing():
    """Moves of half a point cloud in and out of a unit sphere: with the bounds and the
    kept answers the response, gradient and outside signs are those of querying every
    point, and only moved points are queried again."""
    sphere = sphere_target(1.0, 3)
    target = TargetSurface(sphere.vertices, sphere.faces)
    queried = []
    closest = target.closest
    target.closest = lambda points: queried.append(np.array(points)) or closest(points)
    rng = np.random.default_rng(4)
    X = rng.normal(size=(600, 3))
    X *= (rng.uniform(0.2, 1.3, 600) / np.linalg.norm(X, axis=1))[:, None]
    known = InsideBounds(1e-9)
    moved = []
    for _ in range(6):
        value, grad, signed = packaging(X, target, known=known)
        full_value, full_grad, full_signed = packaging(X, target)
        assert value == full_value
        np.testing.assert_array_equal(grad, full_grad)
        exact = signed == full_signed
        assert np.all(full_signed[~exact] < signed[~exact]) and np.all(signed[~exact] < 0)
        moving = rng.random(600) < 0.5
        X = np.where(moving[:, None], X * rng.uniform(0.97, 1.05, (600, 1)), X)
        moved.append({tuple(p) for p in X[moving]})
    with_bounds = queried[0::2]
    assert len(with_bounds[0]) == 600
    for points, now_moved in zip(with_bounds[1:], moved):
        assert 0 < len(points) and {tuple(p) for p in points} <= now_moved
    assert packaging(X[:10], target, known=known)[0] == packaging(X[:10], target)[0]


@pytest.mark.parametrize("with_limit", [False, True])
def test_transpose_mapping_is_the_base_gradient(with_limit):
    base = grid_sphere(2)
    h, fine, T = fine_mesh(base, 2)
    M = h.composite(1)
    if with_limit:
        M = limit_matrices(fine)[0] @ M
    rng = np.random.default_rng(2)
    V0 = base.vertices + 0.03 * rng.normal(size=base.vertices.shape)
    _, grad_fine = volume(M @ V0, T)
    grad_base = M.T @ grad_fine
    step = 1e-3  # volume is quadratic along one base coordinate: central FD is exact
    for j in rng.choice(len(V0), 6, replace=False):
        for k in range(3):
            Vp, Vm = V0.copy(), V0.copy()
            Vp[j, k] += step
            Vm[j, k] -= step
            fd = (volume(M @ Vp, T)[0] - volume(M @ Vm, T)[0]) / (2 * step)
            assert fd == pytest.approx(grad_base[j, k], rel=1e-6, abs=1e-9)


def test_thickness_of_a_sphere_and_a_slab():
    sphere = trimesh.creation.icosphere(3)
    result = thickness(np.asarray(sphere.vertices), np.asarray(sphere.faces), 5.0)
    assert np.all(result.hit_face >= 0)
    assert np.allclose(result.thickness, 2.0, atol=5e-3)
    slab = trimesh.creation.box(extents=(2.0, 2.0, 0.1))
    slab = slab.subdivide().subdivide()
    V, F = np.asarray(slab.vertices), np.asarray(slab.faces)
    result = thickness(V, F, 1.0)
    inner = (np.abs(V[:, 0]) < 0.9) & (np.abs(V[:, 1]) < 0.9)
    assert np.allclose(result.thickness[inner], 0.1, atol=1e-9)
    g, _, t_found = thickness_constraint(V, F, t_min=0.05)
    assert g < 0 and t_found <= 0.1 + 1e-9
    g, grad, _ = thickness_constraint(V, F, t_min=0.2)
    assert g >= (0.2 - 0.1) / 0.2 - 1e-9
    # raising a top vertex (moving it outward) thickens the wall there
    top = np.flatnonzero(inner & (V[:, 2] > 0))
    assert np.all(grad[top, 2] <= 0)


def test_cube_cage_fills_a_sphere_from_inside():
    target = sphere_target(1.0)
    base = centred_cube(1.0)
    # the paper's start (the cage as given): the volume grows, nothing leaves the target
    fitted, info = fit_base_mesh(base, target, levels=2, iterations=60, start="cage")
    assert info.rounds == 0
    assert info.inside.volume[info.inside.best_iteration] > 2.0 * info.inside.volume[0]
    assert info.figures.outside_volume_fraction <= 1e-3
    assert info.figures.distances.mean_distance < 0.1 * info.figures.initial.mean_distance
    assert np.array_equal(fitted.face_vertices, base.face_vertices)
    again, info2 = fit_base_mesh(base, target, levels=2, iterations=60, start="cage")
    assert np.array_equal(again.vertices, fitted.vertices)
    assert info2.inside.objective == info.inside.objective
    # from the least-squares start (the default) it holds as well
    _, lsq = fit_base_mesh(base, target, levels=2, iterations=60)
    assert lsq.rounds >= 1 and lsq.figures.outside_volume_fraction <= 1e-3
    assert lsq.figures.distances.mean_distance < 0.1 * lsq.figures.initial.mean_distance


def test_the_rgp_continued_with_shorter_steps_ends_no_worse_by_its_objective(monkeypatch):
    """The runs with halved steps start from the best design before them and keep their best,
    so the fit's objective at its best design is never above that of the first run alone,
    and the result still fills the target from inside."""
    import core.fitting.fit as fit_module

    target, base = sphere_target(1.0), centred_cube(1.0)
    _, continued = fit_base_mesh(base, target, levels=2, iterations=60, start="cage")
    monkeypatch.setattr(fit_module, "FIT", replace(fit_module.FIT, polish_halvings=0))
    _, single = fit_base_mesh(base, target, levels=2, iterations=60, start="cage")
    assert single.inside.polish == [] and len(continued.inside.polish) >= 1
    assert sum(continued.inside.polish) < continued.inside.iterations <= 60
    best = continued.inside.objective[continued.inside.best_iteration]
    assert best <= single.inside.objective[single.inside.best_iteration]
    assert best == min(continued.inside.objective)  # every iterate of the sphere is feasible
    assert continued.figures.outside_volume_fraction <= 1e-3


def test_a_warm_start_runs_few_rounds_and_still_fills_from_inside():
    from core.fitting.fit import FIT, WARM_START

    target = sphere_target(1.0)
    base = centred_cube(1.0)
    _, cold = fit_base_mesh(base, target, levels=2, iterations=60)
    _, warm = fit_base_mesh(base, target, levels=2, iterations=60,
                            warm=WarmStart(cold.least_squares.vertices,
                                           cold.inside_start.stiffness))
    assert cold.least_squares.rounds > FIT.warm_rounds >= warm.least_squares.rounds
    assert warm.start.startswith(WARM_START)
    assert warm.figures.outside_volume_fraction <= 1e-3
    assert warm.figures.distances.mean_distance < 1.5 * cold.figures.distances.mean_distance


@pytest.mark.slow
def test_best_fit_recovers_a_scaled_limit_surface():
    # the target is the (finely sampled) limit surface of the cage scaled by 1.2; since
    # the limit map is linear, the cage scaled by 1.2 fits it exactly (the fit may slide
    # vertices along the surface, so the surfaces are compared, not the cages)
    base = grid_sphere(3)
    h, fine, T = fine_mesh(base, 4)
    X = limit_matrices(fine)[0] @ h.composite(3) @ (1.2 * base.vertices)
    target = TriMesh(X, T)
    fitted, info = fit_base_mesh(base, target, levels=2, mode="best-fit", rounds=15)
    assert info.figures.initial.mean_distance > 0.03
    fitted_distances = info.figures.distances
    assert fitted_distances.mean_distance < 1e-3 and fitted_distances.max_distance < 2e-3
    assert info.least_squares.rms[-1] < 0.02 * info.least_squares.coarse_rms[0]
    assert info.figures.outside_volume_fraction < 5e-3
    assert info.figures.uncovered_volume_fraction < 5e-3
    again, _ = fit_base_mesh(base, target, levels=2, mode="best-fit", rounds=15)
    assert np.array_equal(again.vertices, fitted.vertices)


def test_mode_none_keeps_the_cage_and_reports_its_figures():
    target = sphere_target(1.0, 3)
    base = centred_cube(1.0)
    fitted, info = fit_base_mesh(base, target, mode="none")
    assert np.array_equal(fitted.vertices, base.vertices)
    assert info.rounds == 0 and info.iterations == 0
    assert info.figures.distances.mean_distance == info.figures.initial.mean_distance > 0.05
    assert info.figures.distances.max_distance == info.figures.initial.max_distance


def test_the_target_to_surface_figure_sees_the_corners_the_limit_surface_misses():
    # the cube cage's limit surface lies inside the cube it is the cage of; its corner vertex
    # has the limit (9 v + 4 sum(edge neighbours) + sum(diagonals)) / 24 = v / 2, so the
    # target's corners are |v| / 2 = sqrt(3) / 2 from it: a quarter of the diagonal 2 sqrt(3),
    # while no limit point is farther than 1 - 1/2 from the cube (a seventh of the diagonal)
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    target = TriMesh(np.asarray(box.vertices), np.asarray(box.faces, dtype=np.int64))
    _, info = fit_base_mesh(centred_cube(2.0), target, mode="none")
    distances = info.figures.distances
    assert distances.target_max_distance == pytest.approx(0.25, abs=1e-3)
    assert distances.max_distance == pytest.approx(0.5 / (2 * np.sqrt(3)), abs=1e-3)
    assert info.figures.initial.target_max_distance == distances.target_max_distance
    assert 0 < distances.target_mean_distance < distances.target_max_distance


def test_grid_sphere_converges_into_a_slightly_larger_sphere():
    base = grid_sphere(3)
    X, _ = limit_points(base, 2)
    target = sphere_target(1.1 * np.linalg.norm(X, axis=1).max())
    _, info = fit_base_mesh(base, target, levels=2, iterations=100)
    assert info.figures.initial.mean_distance > 0.04
    assert info.figures.distances.mean_distance < 2e-3
    assert info.figures.distances.max_distance < 5e-3
    assert info.figures.outside_volume_fraction <= 1e-3


def test_thickness_constraint_holds_when_the_target_is_thin():
    # a flat ellipsoid: the packaging squeezes the cage, the constraint keeps t >= t_min
    mesh = trimesh.creation.icosphere(4)
    mesh.apply_scale((1.0, 1.0, 0.12))
    target = TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64))
    base = PolyMesh(grid_sphere(2).vertices * [0.7, 0.7, 0.3], grid_sphere(2).face_vertices,
                    grid_sphere(2).face_offsets)
    t_min = 0.18
    walls = []
    for limit in (t_min, 0.0):
        fitted, _ = fit_base_mesh(base, target, levels=2, iterations=40, t_min=limit,
                                  start="cage")
        X, T = limit_points(fitted, 2)
        walls.append(thickness(X, T, 1.0).thickness.min())
    assert walls[0] >= 0.95 * t_min
    assert walls[1] < 0.9 * t_min  # without the constraint the walls do get thinner


@pytest.mark.parametrize("kwargs", [
    {"levels": 0}, {"levels": 5}, {"levels": 1.5}, {"iterations": -1},
    {"t_min": -0.1}, {"t_min": float("nan")}, {"mode": "outside"}, {"penalty": 0.0},
    {"step_fraction": 0.0}, {"step_fraction": 2.0}, {"surface": "cage"},
    {"mode": "nearest"}, {"start": "middle"}, {"rounds": -1}, {"rounds": 2.5},
    {"warm": WarmStart(np.zeros((3, 3)))}, {"warm": WarmStart(np.zeros((8, 3)), np.ones(3))},
])
def test_bad_parameters_raise(kwargs):
    with pytest.raises(ParameterError):
        fit_base_mesh(centred_cube(1.0), sphere_target(1.0, 1), **kwargs)


def test_inverted_target_is_rejected():
    target = sphere_target(1.0, 1)
    flipped = TriMesh(target.vertices, target.faces[:, ::-1].copy())
    with pytest.raises(InvalidMeshError):
        fit_base_mesh(centred_cube(1.0), flipped, iterations=1)


def test_pull_inside_moves_the_outside_points_to_the_margin():
    from core.fitting.best_fit import pull_inside

    base = grid_sphere(3)
    V = base.vertices / np.linalg.norm(base.vertices, axis=1).max()
    base = PolyMesh(1.4 * V, base.face_vertices, base.face_offsets)  # limit surface pokes out
    h, fine, _ = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    sphere = sphere_target(1.0)
    target = TargetSurface(sphere.vertices, sphere.faces)
    before = target.closest(M @ base.vertices).signed
    assert before.max() > 0.03
    pulled = pull_inside(base, M, target, base.vertices, margin=0.01, rounds=3)
    after = target.closest(M @ pulled).signed
    # every point ends within 2 mm-equivalents (0.2 % of the radius) of 1 % inside
    assert after.max() < -0.01 + 2e-3
    assert np.abs(after + 0.01).max() < 0.01


def test_pull_inside_queries_only_points_not_proven_deep_and_pulls_the_same():
    """A cage poking out of one side of a sphere: handed the start's closest points, the
    pull queries in its later rounds only the points not proven deeper than the margin,
    and its result is the same as querying every point every round."""
    from core.fitting.best_fit import pull_inside

    base = grid_sphere(3)
    V = 0.7 * base.vertices / np.linalg.norm(base.vertices, axis=1).max() + [0.6, 0.0, 0.0]
    base = PolyMesh(V, base.face_vertices, base.face_offsets)
    h, fine, _ = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    sphere = sphere_target(1.0)
    target = TargetSurface(sphere.vertices, sphere.faces)
    pulled = pull_inside(base, M, target, base.vertices, margin=0.01, rounds=3)
    queried = []
    closest = target.closest
    target.closest = lambda points: queried.append(len(points)) or closest(points)
    again = pull_inside(base, M, target, base.vertices, margin=0.01, rounds=3,
                        start_closest=closest(M @ base.vertices))
    np.testing.assert_array_equal(again, pulled)
    assert len(queried) == 2 and max(queried) < 0.5 * M.shape[0]
    assert target.closest(M @ pulled).signed.max() < 0


def test_hold_back_crossings_undoes_only_the_crossing_move():
    import scipy.sparse as sp

    from core.fitting.crossings import hold_back_crossings
    from core.self_intersection import find_self_intersections

    sphere = sphere_target(1.0, 2)              # 162 vertices; the mapping is the identity
    V, T = sphere.vertices, sphere.faces
    M = sp.identity(len(V), format="csr")
    moved = 1.02 * V                            # a harmless move everywhere
    moved[0] = -1.5 * V[0]                      # one vertex pushed through the far side
    assert len(find_self_intersections(M @ moved, T))
    held, count, crossings = hold_back_crossings(V, moved, M, T)
    assert crossings == 0
    assert len(find_self_intersections(M @ held, T)) == 0
    assert 1 <= count <= 0.1 * len(V)
    kept = np.linalg.norm(held - moved, axis=1) < 1e-12
    assert kept.sum() == len(V) - count         # every other vertex keeps its whole move


def test_normal_equations_solve_the_dense_least_squares_problem():
    # two data terms (one row per fine point; one through three corners with barycentric
    # weights) solved by the fine-level assembly against the same problem written out as
    # a dense least-squares system with an explicit Jacobian
    base = grid_sphere(2)
    h, fine, T = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    n_f, n = M.shape
    rng = np.random.default_rng(3)
    normal_f = rng.normal(size=(n_f, 3))
    normal_f /= np.linalg.norm(normal_f, axis=1, keepdims=True)
    b_f = rng.normal(size=n_f)
    k = 500
    corners = T[rng.integers(0, len(T), k)]
    weights = rng.dirichlet(np.ones(3), k)
    normal_b = rng.normal(size=(k, 3))
    b_b = rng.normal(size=k)
    stiffness = np.where(np.arange(n) % 3 == 0, 10.0, 1.0)
    V_prev = base.vertices + 0.01 * rng.normal(size=base.vertices.shape)
    system = NormalEquations(base, M, 1e-2, 1e-3, stiffness)
    solved = system.solve(V_prev, [(normal_f, np.arange(n_f)[:, None], np.ones((n_f, 1)),
                                    b_f, n_f), (normal_b, corners, weights, b_b, k)])
    Md = M.toarray()
    rows_b = np.zeros((k, n_f))
    np.add.at(rows_b, (np.repeat(np.arange(k), 3), corners.reshape(-1)), weights.reshape(-1))
    J_f = np.hstack([normal_f[:, [a]] * Md for a in range(3)]) / np.sqrt(n_f)
    J_b = np.hstack([normal_b[:, [a]] * (rows_b @ Md) for a in range(3)]) / np.sqrt(k)
    data = J_f.T @ J_f + J_b.T @ J_b
    scale = np.diag(data).mean()
    D = _umbrella(base, n).toarray() * np.sqrt(stiffness)[:, None]
    smooth = np.kron(np.eye(3), D.T @ D)
    lhs = data + 1e-2 * scale * smooth + 1e-3 * scale * np.eye(3 * n)
    rhs = (J_f.T @ (b_f / np.sqrt(n_f)) + J_b.T @ (b_b / np.sqrt(k))
           + 1e-2 * scale * smooth @ base.vertices.T.reshape(-1)
           + 1e-3 * scale * V_prev.T.reshape(-1))
    expected = np.linalg.solve(lhs, rhs).reshape(3, -1).T
    np.testing.assert_allclose(solved, expected, atol=1e-9 * np.abs(expected).max())


def test_normal_equations_pair_the_blocks_bit_for_bit_and_leave_the_mapping_alone():
    # the paired (complex) products give each block of M^T Z_ab M exactly as the real
    # products do; the caller's mapping, whose rows are not sorted, keeps its entries' order
    # (the fit's limit points M @ V are summed in that order)
    import scipy.sparse as sp

    base = grid_sphere(2)
    h, fine, T = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    rows = np.repeat(np.arange(M.shape[0]), np.diff(M.indptr))
    reverse = M.indptr[rows] + M.indptr[rows + 1] - 1 - np.arange(M.nnz)  # each row reversed
    shuffled = sp.csr_matrix((M.data[reverse], M.indices[reverse], M.indptr), shape=M.shape)
    assert not shuffled.has_sorted_indices
    data, indices = shuffled.data.copy(), shuffled.indices.copy()
    rng = np.random.default_rng(4)
    n_f = M.shape[0]
    normal = rng.normal(size=(n_f, 3))
    corners = T[rng.integers(0, len(T), 300)]
    terms = [(normal, np.arange(n_f)[:, None], np.ones((n_f, 1)), rng.normal(size=n_f), n_f),
             (rng.normal(size=(300, 3)), corners, rng.dirichlet(np.ones(3), 300),
              rng.normal(size=300), 300)]
    system = NormalEquations(base, shuffled, 1e-2, 1e-3)
    np.testing.assert_array_equal(shuffled.data, data)
    np.testing.assert_array_equal(shuffled.indices, indices)
    blocks = system._data_blocks(terms)
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    real_z = [_real_fine_block(terms, pair, n_f) for pair in pairs]
    for k, pair in enumerate(pairs):
        real = system.mapping.T @ (real_z[k] @ system.mapping)
        np.testing.assert_array_equal(blocks[pair].toarray(), real.toarray())
    # the complex fine matrix is the sum of the two real ones, entry for entry
    fine = _FineEntries(terms)
    for first, second in ((0, 1), (2, 3), (4, 5)):
        built, summed = fine.pair_matrix(first, second, n_f), real_z[first] + 1j * real_z[second]
        np.testing.assert_array_equal(built.indptr, summed.indptr)
        np.testing.assert_array_equal(built.indices, summed.indices)
        np.testing.assert_array_equal(built.data, summed.data)


def _real_fine_block(terms, pair, n_fine):
    """(n_fine, n_fine) CSR the fine block ``Z_ab`` of the normal equations' data part,
    entries as real numbers (summed in the sparse constructor's order)."""
    import scipy.sparse as sp

    a, c = pair
    rows, cols, vals = [], [], []
    for normal, corners, weights, _, count in terms:
        product = weights[:, :, None] * weights[:, None, :] / count
        rows.append(np.broadcast_to(corners[:, :, None], product.shape).reshape(-1))
        cols.append(np.broadcast_to(corners[:, None, :], product.shape).reshape(-1))
        vals.append(((normal[:, a] * normal[:, c])[:, None, None] * product).reshape(-1))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_fine, n_fine))


def test_a_refit_does_not_return_its_start():
    # started from the unstiffened fit, a stiffer refit has a higher RMS distance than its
    # start; it still returns the stiffer fit, not the start
    base = grid_sphere(3)
    target = sphere_target(1.3)
    h, fine, T = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    surface = TargetSurface(target.vertices, target.faces)
    first = best_fit(base, M, T, surface, rounds=6)
    stiff = np.full(len(base.vertices), 1e4)
    refit = best_fit(base, M, T, surface, rounds=2, start=first.vertices, stiffness=stiff,
                     refit=True)
    assert refit.rms[1] > refit.rms[0]                # stiffer: the start was closer
    assert refit.rounds >= 2 and not np.array_equal(refit.vertices, first.vertices)
    kept = best_fit(base, M, T, surface, rounds=2, start=first.vertices, stiffness=stiff)
    np.testing.assert_array_equal(kept.vertices, first.vertices)   # without the flag


def test_nudge_inside_moves_only_the_vertices_under_outside_points_and_stays_clean():
    """A cage poking out of one side of a sphere: the nudge brings the outside points in,
    moves no vertex it was not allowed to, and its limit surface does not cross itself."""
    from core.fitting.contain import nudge_inside
    from core.self_intersection import find_self_intersections

    base = grid_sphere(3)
    V = 0.7 * base.vertices / np.linalg.norm(base.vertices, axis=1).max() + [0.6, 0.0, 0.0]
    base = PolyMesh(V, base.face_vertices, base.face_offsets)
    h, fine, T = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    sphere = sphere_target(1.0)
    target = TargetSurface(sphere.vertices, sphere.faces)
    before = target.closest(M @ V).signed
    assert before.max() > 0.1
    movable = V[:, 2] > 0                       # one half may move
    nudged, moved = nudge_inside(V, M, T, target, movable=movable)
    np.testing.assert_array_equal(nudged[~movable], V[~movable])
    assert moved and moved[0] > 0
    after = target.closest(M @ nudged).signed
    half = (M @ V)[:, 2] > 0.1                  # fine points carried by the movable half
    assert after[half].max() < 0.5 * before[half].max()
    assert len(find_self_intersections(M @ nudged, T)) == 0
    # the fine points with no weight on a movable vertex stay where they were
    untouched = abs(M) @ movable.astype(np.float64) == 0
    assert untouched.sum() > 0.1 * len(untouched)
    np.testing.assert_allclose((M @ nudged)[untouched], (M @ V)[untouched], atol=1e-12)


def test_nudge_inside_queries_fewer_points_and_moves_as_if_it_queried_all(monkeypatch):
    """The nudge skips the closest-point queries of the fine points its bounds prove inside
    (and of the far walls' corners whose bounds already prove the room): the same moves,
    bit for bit, as querying every point every round, with fewer queries (both kinds of
    rounds run: the near walls alone, then with the far walls carried)."""
    from core.fitting import contain
    from core.fitting.responses import InsideBounds

    base = grid_sphere(3)
    V = 0.7 * base.vertices / np.linalg.norm(base.vertices, axis=1).max() + [0.6, 0.0, 0.0]
    h, fine, T = fine_mesh(PolyMesh(V, base.face_vertices, base.face_offsets), 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    sphere = sphere_target(1.0)
    target = TargetSurface(sphere.vertices, sphere.faces)
    queried = []
    closest = TargetSurface.closest

    def counting(self, points):
        queried.append(len(points))
        return closest(self, points)

    monkeypatch.setattr(TargetSurface, "closest", counting)
    # each run on its own copy of the map (scipy's abs() sorts a map's rows in place)
    bounded, moved = contain.nudge_inside(V, M.copy(), T, target, movable=V[:, 2] > 0)
    fewer = sum(queried)
    queried.clear()
    monkeypatch.setattr(InsideBounds, "undecided", lambda self, X: np.arange(len(X)))
    every, moved_every = contain.nudge_inside(V, M.copy(), T, target, movable=V[:, 2] > 0)
    assert len(moved) > 2 and moved == moved_every
    np.testing.assert_array_equal(bounded, every)
    assert fewer < 0.8 * sum(queried)


def test_a_nudge_round_with_loose_bounds_carries_the_far_walls_as_with_exact_ones():
    """Bounds from queries made elsewhere (every point's last query about 0.3 away) prove
    little: the round queries the points and far-wall corners they leave undecided, and its
    move and depth are those of a round that queried everything."""
    from core.fitting.contain import _shift
    from core.fitting.responses import InsideBounds

    base = grid_sphere(3)                       # a small cage, its far wall within reach
    V = 0.3 * base.vertices / np.linalg.norm(base.vertices, axis=1).max() + [0.9, 0.0, 0.0]
    h, fine, T = fine_mesh(PolyMesh(V, base.face_vertices, base.face_offsets), 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    M.sort_indices()
    sphere = sphere_target(1.0)
    target = TargetSurface(sphere.vertices, sphere.faces)
    X = M @ V
    elsewhere = X + 0.3 * np.random.default_rng(2).normal(size=X.shape) / np.sqrt(3)
    loose = InsideBounds(0.0)
    loose.record(elsewhere, np.arange(len(X)), target.closest(elsewhere))
    assert (loose.bound(X) > target.closest(X).signed + 0.1).mean() > 0.5
    movable = np.ones(len(V), dtype=bool)
    shift, depth = _shift(V, M, T, target, movable, True, loose)
    exact_shift, exact_depth = _shift(V, M, T, target, movable, True, InsideBounds(0.0))
    carried = _shift(V, M, T, target, movable, False, InsideBounds(0.0))[0]
    assert np.abs(exact_shift - carried).max() > 0   # far walls were carried
    np.testing.assert_array_equal(shift, exact_shift)
    assert depth == exact_depth


def test_a_nudge_round_moves_continuously_as_points_cross_the_target_surface():
    """A box whose top face passes exactly through a ring of fine limit points of a grid
    sphere poking out of it: moving the base vertex that carries them by 1e-12 up or down
    takes them just outside or just inside, which changes how many outside points that
    vertex carries, and its move changes by no more than rounding's size (a plain mean
    over the points would divide by another count)."""
    from core.fitting.contain import _owner, _shift
    from core.fitting.responses import InsideBounds

    base = grid_sphere(3)
    V = base.vertices / np.linalg.norm(base.vertices, axis=1).max()
    h, fine, T = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    M.sort_indices()
    X = M @ V
    owner = _owner(M, np.arange(len(X)))
    top = owner[np.argmax(X[:, 2])]
    carried = np.flatnonzero(owner == top)
    heights = np.unique(X[carried, 2])
    assert len(heights) >= 3
    level = heights[-2]                         # the points below the highest one
    box = trimesh.creation.box(extents=(4.0, 4.0, 4.0))
    corners = np.asarray(box.vertices)
    corners[:, 2] = np.where(corners[:, 2] > 0, level, -2.0)
    target = TargetSurface(corners, np.asarray(box.faces, dtype=np.int64))
    shifts, outside = [], []
    for sign in (1.0, -1.0):
        W = V.copy()
        W[top, 2] += sign * 1e-12
        outside.append(int((target.closest(M @ W).signed > 0).sum()))
        shifts.append(_shift(W, M, T, target, None, False, InsideBounds(0.0))[0][top])
    assert outside[0] > outside[1]              # the ring is outside, then inside
    assert np.linalg.norm(shifts[0]) > 1e-4
    assert np.linalg.norm(shifts[0] - shifts[1]) < 1e-9 * np.linalg.norm(shifts[0])


def test_nudge_inside_stops_a_kind_of_rounds_that_no_longer_takes_depth_off(monkeypatch):
    """When a round leaves the summed outside depth where it was (less than
    ``NudgeSettings.progress`` off), no further round of that kind runs: with a depth that never
    falls, one round of each kind, not ``rounds`` of each (the moves themselves are real and
    clean: a small outward shift of every base vertex of a grid sphere)."""
    from core.fitting import contain

    base = grid_sphere(3)
    h, fine, T = fine_mesh(base, 2)
    M = (limit_matrices(fine)[0] @ h.composite(1)).tocsr()
    sphere = sphere_target(1.0)
    target = TargetSurface(sphere.vertices, sphere.faces)
    calls = []

    def stalled_shift(V, mapping, triangles, target, movable, carry, known):
        calls.append(carry)
        return 1e-3 * V, 1.0                   # the same summed depth every round

    monkeypatch.setattr(contain, "_shift", stalled_shift)
    nudged, moved = contain.nudge_inside(base.vertices, M, T, target, rounds=8)
    assert len(moved) == 2 and min(moved) == len(base.vertices)   # one round of each kind
    assert calls == [False, False, True, True]  # the second of each kind saw no progress
    np.testing.assert_allclose(nudged, base.vertices * 1.001 ** 2, rtol=1e-12)


@pytest.mark.parametrize("mode", ["inside", "best-fit"])
def test_the_fit_does_not_depend_on_the_blas_thread_count(mode):
    """Called under a two-thread BLAS limit, the fit gives bit-identical vertices to one
    under a one-thread limit (without :func:`core.threads.single_threaded` on the fit, the
    grid sphere's vertices differed by about 2e-12 between the two)."""
    from threadpoolctl import threadpool_limits

    base = grid_sphere(3)
    X, _ = limit_points(base, 2)
    target = sphere_target(1.1 * np.linalg.norm(X, axis=1).max())
    fitted = {}
    for threads in (1, 2):
        with threadpool_limits(limits=threads):
            fitted[threads], _ = fit_base_mesh(base, target, levels=2, iterations=60, mode=mode)
    np.testing.assert_array_equal(fitted[1].vertices, fitted[2].vertices)


def test_single_threaded_limits_blas_and_restores_the_limit():
    from threadpoolctl import threadpool_info, threadpool_limits

    from core.threads import single_threaded

    with threadpool_limits(limits=2):
        before = [pool["num_threads"] for pool in threadpool_info()]
        with single_threaded():
            inside = [pool["num_threads"] for pool in threadpool_info()]
        after = [pool["num_threads"] for pool in threadpool_info()]
    assert inside and all(n == 1 for n in inside)
    assert after == before
