# SPDX-License-Identifier: LGPL-2.1-or-later
"""Limit surface -> bicubic B-spline patches: exactness, error, continuity, sharing."""
import copy

import numpy as np
import pytest

from core.errors import ExportError
from core.export import bspline as bs
from core.export import bspline_basis, bspline_measure, bspline_tessellation
from core.export.brep_topology import check_topology
from core.export.patch_mesh import build_patch_mesh
from core.geometry import triangle_mesh_volume
from core.subdivision import sample_cages as sc
from core.subdivision.catmull_clark import mesh_topology
from core.subdivision.limit import LimitEvaluator, limit_volume

EV_CAGES = ["cube", "mixed_prism", "pentagonal_prism", "genus3_block"]


@pytest.fixture(scope="module")
def patchsets():
    return {name: bs.limit_surface_patches(getattr(sc, name)())
            for name in EV_CAGES + ["torus", "grid_sphere"]}


@pytest.mark.slow
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
        got = bspline_basis.evaluate_patch_grid([ps.patches[f]], t, t)[0]
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
        got = bspline_basis.evaluate_patch_grid([ps.patches[f]], t, t)[0].reshape(-1, 3)
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


@pytest.mark.parametrize("name, quads, others, per_other", [("mixed_prism", 7, 10, 3),
                                                           ("pentagonal_prism", 5, 2, 5)])
def test_one_patch_per_base_quad_on_mixed_cages(patchsets, name, quads, others, per_other):
    """One patch per quad, n per n-gon; quad sides next to an n-gon are split in two."""
    ps = patchsets[name]
    base = getattr(sc, name)()
    sizes = base.face_sizes
    assert len(ps.patches) == quads + per_other * others
    per_face = np.bincount(ps.face_of_patch, minlength=base.n_faces)
    assert (per_face[sizes == 4] == 1).all() and (per_face[sizes != 4] == sizes[sizes != 4]).all()
    assert ps.info["patches_per_base_face"] == {"4": 1.0, str(sizes[sizes != 4][0]): per_other}
    loops = np.bincount(ps.topology.use_face)
    quad_patch = np.flatnonzero(sizes[ps.face_of_patch] == 4)
    assert (loops[quad_patch] > 4).any() and (loops[sizes[ps.face_of_patch] != 4] == 4).all()


@pytest.mark.parametrize("name", EV_CAGES + ["torus"])
def test_shared_edges_lie_on_both_patches(patchsets, name):
    """Every B-rep edge is used once in each direction and lies on both its patches
    (bit-identical boundary rows on whole shared sides, within 1e-12 of the diagonal
    on split sides)."""
    ps = patchsets[name]
    gap = check_topology(ps.topology, ps.patches, 1e-12 * ps.info["bbox_diagonal"], samples=9)
    assert gap <= 1e-12 * ps.info["bbox_diagonal"]
    checked = 0
    for p, patch in enumerate(ps.patches):
        uses = np.flatnonzero(ps.topology.use_face == p)
        if len(uses) != 4:
            continue  # a quad with split sides: its halves are checked by check_topology above
        for k, use in enumerate(uses):
            row, _ = _boundary(patch, k)
            curve = ps.topology.edge_curves[ps.topology.use_edge[use]].poles
            assert np.array_equal(row, curve[::-1] if ps.topology.use_reversed[use] else curve)
            checked += 1
    assert checked >= 0.5 * len(ps.topology.use_edge)


def test_topology_check_detects_a_moved_edge(patchsets):
    ps = patchsets["mixed_prism"]
    topo = ps.topology
    moved = copy.deepcopy(topo)
    moved.edge_curves[5].poles[2] += 1e-3
    with pytest.raises(ExportError, match="edge 5 lies"):
        check_topology(moved, ps.patches, 1e-7)
    flipped = copy.deepcopy(topo)
    flipped.use_reversed[0] = not flipped.use_reversed[0]
    with pytest.raises(ExportError, match="not used once in each direction"):
        check_topology(flipped, ps.patches, 1e-7)


def _boundary(patch, k):
    """Poles and knots of the boundary leaving corner k, in the corner's direction."""
    P = patch.poles
    rows = [P[:, 0], P[-1, :], P[::-1, -1], P[0, ::-1]]
    knots = [(patch.u_knots, patch.u_mults), (patch.v_knots, patch.v_mults),
             (1.0 - patch.u_knots[::-1], patch.u_mults[::-1]),
             (1.0 - patch.v_knots[::-1], patch.v_mults[::-1])]
    return rows[k], knots[k]


def test_c2_across_regular_edges(patchsets):
    """Across edges away from EVs the two patches agree in 1st and 2nd cross derivatives."""
    for name in ("torus", "grid_sphere"):
        ps = patchsets[name]
        quads = build_patch_mesh(getattr(sc, name)()).mesh
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
    return sign ** order * bspline_basis.evaluate_patches([patch], u, v, du, dv)[0]


@pytest.mark.parametrize("name", ["cube", "genus3_block"])
def test_tessellation_watertight_and_volume(patchsets, name):
    import trimesh

    V, F = bspline_tessellation.tessellate_patches(patchsets[name], resolution=64)
    mesh = trimesh.Trimesh(V, F, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    exact = limit_volume(getattr(sc, name)(), 5)
    assert abs(triangle_mesh_volume(V, F) - exact) < 5e-4 * exact


def test_deviation_detects_wrong_patches(patchsets):
    """The measuring function is not blind: a shifted pole is reported."""
    base = sc.cube()
    ps = bs.limit_surface_patches(base, depth=4, measure=False)
    ps.patches[0].poles[3, 3] += 0.01
    dev = bspline_measure.patch_deviation(ps, base)
    assert dev["max_error"] > 1e-3
    jumps = bspline_measure.normal_jumps(ps, base)
    assert jumps["normal_jump_max_deg"] > patchsets["cube"].info["normal_jump_max_deg"]


def test_deeper_grading_reduces_error():
    base = sc.mixed_prism()
    e = [bs.limit_surface_patches(base, depth=d).info["max_ev_error"] for d in (4, 6)]
    assert e[1] < 0.6 * e[0]
