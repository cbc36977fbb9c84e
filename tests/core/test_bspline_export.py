# SPDX-License-Identifier: LGPL-2.1-or-later
"""Limit surface -> bicubic B-spline patches: exactness, error, continuity, sharing."""
import numpy as np
import pytest

from core.export import bspline as bs
from core.subdivision import sample_cages as sc
from core.subdivision.catmull_clark import mesh_topology
from core.subdivision.limit import LimitEvaluator, limit_volume

EV_CAGES = ["cube", "mixed_prism", "pentagonal_prism", "genus3_block"]


@pytest.fixture(scope="module")
def patchsets():
    return {name: bs.limit_surface_patches(getattr(sc, name)())
            for name in EV_CAGES + ["torus", "grid_sphere"]}


def test_knot_layout_and_mults(patchsets):
    for ps in patchsets.values():
        for p in ps.patches:
            nu, nv, _ = p.poles.shape
            assert p.u_mults.sum() == nu + 4 and p.v_mults.sum() == nv + 4
            assert (np.diff(p.u_knots) > 0).all() and (np.diff(p.v_knots) > 0).all()
            assert p.u_knots[0] == 0.0 and p.u_knots[-1] == 1.0


def test_regular_mesh_gives_exact_bezier_patches(patchsets):
    """Torus: 16 poles per patch, equal to the analytic uniform B-spline to 1e-12."""
    mesh = sc.torus()
    ps = patchsets["torus"]
    assert all(p.poles.shape == (4, 4, 3) for p in ps.patches)
    assert ps.info["n_extraordinary_vertices"] == 0
    X = mesh.vertices.reshape(8, 6, 3)
    t = np.linspace(0, 1, 7)
    Bt = np.stack([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4,
                   -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3], axis=1) / 6
    for f in range(mesh.n_faces):
        i, j = divmod(f, 6)
        net = X[np.ix_((i + np.arange(-1, 3)) % 8, (j + np.arange(-1, 3)) % 6)]
        expected = np.einsum("ai,bj,ijk->abk", Bt, Bt, net)
        got = bs.evaluate_patch_grid([ps.patches[f]], t, t)[0]
        assert np.abs(got - expected).max() < 1e-12


def test_regular_faces_exact_next_to_evs(patchsets):
    """Faces without EV corners (graded or not) match the exact limit to 1e-12."""
    mesh = sc.grid_sphere()
    ps = patchsets["grid_sphere"]
    ev = LimitEvaluator(mesh)
    val = np.bincount(mesh.face_vertices)
    regular = np.flatnonzero((val[mesh.face_vertices.reshape(-1, 4)] == 4).all(axis=1))
    graded = [f for f in regular if ps.patches[f].poles.shape[0] > 4]
    assert len(graded) > 0 and len(regular) > len(graded)
    t = np.linspace(0, 1, 9)
    U, V = np.meshgrid(t, t, indexing="ij")
    for f in regular:
        got = bs.evaluate_patch_grid([ps.patches[f]], t, t)[0].reshape(-1, 3)
        exact = ev.evaluate(np.full(U.size, f), U.ravel(), V.ravel())
        assert np.abs(got - exact).max() < 1e-12


@pytest.mark.parametrize("name", EV_CAGES)
def test_ev_error_and_continuity_targets(patchsets, name):
    info = patchsets[name].info
    assert info["n_extraordinary_vertices"] > 0
    assert info["max_ev_error_rel"] <= 1e-4
    assert info["max_error_rel"] <= 1e-4
    assert info["normal_jump_max_deg"] <= 1.0
    assert info["normal_jump_p95_deg"] <= info["normal_jump_max_deg"]


def test_non_quad_faces_use_level_one_patches(patchsets):
    ps = patchsets["mixed_prism"]
    base = sc.mixed_prism()
    assert ps.info["patch_level"] == 1
    assert len(ps.patches) == len(base.face_vertices)
    assert np.array_equal(ps.face_of_patch, np.repeat(np.arange(base.n_faces), base.face_sizes))


def _boundary(patch, k):
    """Poles and knots of the boundary leaving corner k, in the corner's direction."""
    P = patch.poles
    rows = [P[:, 0], P[-1, :], P[::-1, -1], P[0, ::-1]]
    knots = [(patch.u_knots, patch.u_mults), (patch.v_knots, patch.v_mults),
             (1.0 - patch.u_knots[::-1], patch.u_mults[::-1]),
             (1.0 - patch.v_knots[::-1], patch.v_mults[::-1])]
    return rows[k], knots[k]


@pytest.mark.parametrize("name", EV_CAGES + ["torus"])
def test_shared_boundaries_bit_identical(patchsets, name):
    ps = patchsets[name]
    quads = bs.patch_mesh(getattr(sc, name)())[0]
    topo = mesh_topology(quads.face_vertices, quads.face_offsets, len(quads.vertices))
    for c in range(len(quads.face_vertices)):
        t = topo.twin[c]
        fa, fb = c // 4, t // 4
        ra, (ka, ma) = _boundary(ps.patches[fa], c % 4)
        rb, (kb, mb) = _boundary(ps.patches[fb], t % 4)
        assert np.array_equal(ra, rb[::-1])
        assert np.array_equal(ka, 1.0 - kb[::-1]) and np.array_equal(ma, mb[::-1])


def test_c2_across_regular_edges(patchsets):
    """Across edges away from EVs the two patches agree in 1st and 2nd cross derivatives."""
    for name in ("torus", "grid_sphere"):
        ps = patchsets[name]
        quads = bs.patch_mesh(getattr(sc, name)())[0]
        topo = mesh_topology(quads.face_vertices, quads.face_offsets, len(quads.vertices))
        val = np.bincount(quads.face_vertices)
        has_ev = (val[quads.face_vertices.reshape(-1, 4)] != 4).any(axis=1)
        t = np.linspace(0.0, 1.0, 7)
        checked = 0
        for c in range(len(quads.face_vertices)):
            tw = topo.twin[c]
            if has_ev[c // 4] or has_ev[tw // 4]:
                continue
            d_a = [_cross_derivative(ps.patches[c // 4], c % 4, t, order) for order in (1, 2)]
            d_b = [_cross_derivative(ps.patches[tw // 4], tw % 4, 1.0 - t, order)
                   for order in (1, 2)]
            scale = np.abs(d_a[0]).max()
            assert np.abs(d_a[0] + d_b[0]).max() < 1e-9 * scale
            assert np.abs(d_a[1] - d_b[1]).max() < 1e-8 * scale
            checked += 1
        assert checked > 10


def _cross_derivative(patch, k, t, order):
    """Derivative of ``order`` into the patch, across the edge leaving corner k."""
    u, v = bs._edge_param(np.full(len(t), k), t)
    du, dv = (0, order) if k in (0, 2) else (order, 0)
    sign = 1.0 if k in (0, 3) else -1.0
    return sign ** order * bs.evaluate_patches([patch], u, v, du, dv)[0]


@pytest.mark.parametrize("name", ["cube", "genus3_block"])
def test_tessellation_watertight_and_volume(patchsets, name):
    import trimesh

    V, F = bs.tessellate_patches(patchsets[name], resolution=64)
    mesh = trimesh.Trimesh(V, F, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    exact = limit_volume(getattr(sc, name)(), 5)
    assert abs(bs.triangle_mesh_volume(V, F) - exact) < 5e-4 * exact


def test_deviation_detects_wrong_patches(patchsets):
    """The measuring function is not blind: a shifted pole is reported."""
    base = sc.cube()
    ps = bs.limit_surface_patches(base, depth=4, measure=False)
    ps.patches[0].poles[3, 3] += 0.01
    dev = bs.patch_deviation(ps, base)
    assert dev["max_error"] > 1e-3
    jumps = bs.normal_jumps(ps, base)
    assert jumps["normal_jump_max_deg"] > patchsets["cube"].info["normal_jump_max_deg"]


def test_deeper_grading_reduces_error():
    base = sc.mixed_prism()
    e = [bs.limit_surface_patches(base, depth=d).info["max_ev_error"] for d in (4, 6)]
    assert e[1] < 0.6 * e[0]
