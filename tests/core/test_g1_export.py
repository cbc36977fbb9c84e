# SPDX-License-Identifier: LGPL-2.1-or-later
"""The light G1 export (core.export.g1_patches) on cages built here: a closed shell, tangent
continuity across every edge, closeness to the Catmull-Clark limit, exact regular faces and
poles that are affine combinations of the cage."""
import dataclasses

import numpy as np
import pytest

from core.export.brep_topology import check_topology
from core.export.bspline_basis import evaluate_patch_points
from core.export.g1_patches import connection_alpha, g1_surface_patches
from core.export.quad_blocks import quad_blocks
from core.geometry import triangulate
from core.subdivision import sample_cages
from core.subdivision.catmull_clark import build_hierarchy, crease_edge_mask, mesh_topology
from core.subdivision.limit import limit_matrices, quad_mesh_of
from core.target_surface import TargetSurface

CAGES = ("cube", "torus", "genus3_block", "mixed_prism", "pentagonal_prism")


@pytest.fixture(scope="module", params=CAGES)
def exported(request):
    cage = getattr(sample_cages, request.param)()
    return request.param, cage, g1_surface_patches(cage)


def _patch_samples(patchset, n=17):
    s = np.linspace(0.0, 1.0, n)
    u, v = (a.reshape(-1) for a in np.meshgrid(s, s, indexing="ij"))
    k = len(patchset.patches)
    return evaluate_patch_points(patchset.patches, np.repeat(np.arange(k), len(u)),
                                 np.tile(u, k), np.tile(v, k))


def test_patches_form_one_closed_shell(exported):
    _, _, ps = exported
    diag = ps.info["bbox_diagonal"]
    assert check_topology(ps.topology, ps.patches, 1e-7 * diag) <= 1e-7 * diag
    per_quad = 64 if (exported[1].face_sizes == 4).all() else 100
    assert max(p.poles.shape[0] * p.poles.shape[1] for p in ps.patches) <= per_quad


def test_mixed_cage_gets_one_face_per_base_quad(exported):
    """A cage with non-quad faces: one face per base quad (its four refined patches joined
    C2, at most two double knots and a single knot line at 1/2 per direction) and one per
    quad of each other face, within the merge tolerance of the refined patches."""
    name, cage, ps = exported
    sizes = cage.face_sizes
    if (sizes == 4).all():
        pytest.skip("all quads")
    assert len(ps.patches) == int((sizes == 4).sum() + sizes[sizes != 4].sum())
    assert max(p.poles.shape[0] * p.poles.shape[1] for p in ps.patches) <= 81
    for patch, face in zip(ps.patches, ps.face_of_patch):
        if sizes[face] == 4:
            for knots, mults in ((patch.u_knots, patch.u_mults), (patch.v_knots, patch.v_mults)):
                assert np.all(np.asarray(mults)[np.isclose(knots, 0.5)] <= 1)
    assert ps.info["faces"] == "quad" and ps.info["merge_error"] <= 1e-7


def test_normals_do_not_jump_across_edges(exported):
    """G1 holds up to the penalty's residual: far below the 1 degree a CAD model may show."""
    _, _, ps = exported
    assert ps.info["normal_jump_max_deg"] <= 0.01
    assert ps.info["normal_jump_ev_max_deg"] <= 0.01


def test_surface_is_close_to_the_limit_surface(exported):
    """Every patch point lies near the limit surface (a level-5 mesh of exact limit points,
    whose own chordal error is far smaller). These cages have 6 to 58 quads, so a
    patch spans a large part of the shape; the bound is on the bounding-box diagonal."""
    _, cage, ps = exported
    fine = build_hierarchy(cage, 5).meshes[-1]
    limit = limit_matrices(fine)[0] @ fine.vertices
    surface = TargetSurface(limit, triangulate(fine.face_vertices, fine.face_offsets))
    distance = surface.nearest(_patch_samples(ps)).distance
    assert distance.max() <= 2.5e-3 * ps.info["bbox_diagonal"]


def test_regular_faces_are_the_exact_limit(exported):
    """Quads whose corners all have valence 4 are single Bezier patches equal to the limit
    (of a mixed cage, its refinement's quads: the same limit surface)."""
    name, cage, ps = exported
    quads = quad_mesh_of(cage)
    if quads is not cage:
        ps = g1_surface_patches(quads, measure=False)
    regular = np.flatnonzero([p.poles.shape[:2] == (4, 4) for p in ps.patches])
    if name == "torus":
        assert len(regular) == len(ps.patches)
    if name in ("genus3_block", "mixed_prism"):
        assert len(regular) > 0
    if not len(regular):
        return
    from core.subdivision.limit import LimitEvaluator

    s = np.linspace(0.0, 1.0, 7)
    u, v = (a.reshape(-1) for a in np.meshgrid(s, s, indexing="ij"))
    face = np.repeat(regular, len(u))
    U, V = np.tile(u, len(regular)), np.tile(v, len(regular))
    exact = LimitEvaluator(quads).evaluate(face, U, V)
    ours = evaluate_patch_points(ps.patches, face, U, V)
    assert np.abs(ours - exact).max() <= 1e-12 * ps.info["bbox_diagonal"]


def test_poles_are_affine_combinations_of_the_cage():
    """Moving the cage by an affine map moves every pole by it: the pole weights are fixed
    and sum to 1 (a translation moves the poles by the same vector)."""
    cage = sample_cages.mixed_prism()
    rng = np.random.default_rng(5)
    M = np.eye(3) + 0.3 * rng.standard_normal((3, 3))
    shift = np.array([3.0, -7.0, 11.0])
    moved = dataclasses.replace(cage, vertices=cage.vertices @ M.T + shift)
    a = g1_surface_patches(cage, measure=False)
    b = g1_surface_patches(moved, measure=False)
    for pa, pb in zip(a.patches, b.patches):
        assert np.abs(pa.poles @ M.T + shift - pb.poles).max() <= 1e-9


def test_connection_function_ends():
    """alpha is 2 cos(2 pi / n) at an extraordinary end and 0 with slope 0 at a valence-4 end."""
    t = np.array([0.0, 1.0, 1.0 - 1e-6])
    n3, n4 = np.full(3, 3), np.full(3, 4)
    a = connection_alpha(t, n3, n4)
    assert abs(a[0] - 2.0 * np.cos(2.0 * np.pi / 3.0)) <= 1e-15 and a[1] == 0.0
    assert abs(a[2]) <= 1e-11
    mirrored = connection_alpha(1.0 - t, n4, n3)
    assert np.allclose(mirrored, -a, atol=1e-15)
    assert np.all(connection_alpha(t, n4, n4) == 0.0)


def _creased_cages():
    """A torus with one crease loop around its tube (crease vertices of valence 4), and a
    cube with the rim of its top face creased (crease vertices with sectors of one and two
    faces) and one vertical edge (a corner of three creases above, a dart below)."""
    torus = sample_cages.torus()
    ring = np.arange(6)
    torus = dataclasses.replace(torus, creases=np.stack([ring, (ring + 1) % 6], axis=1))
    cube = sample_cages.cube()
    fv = cube.face_vertices.reshape(-1, 4)
    top = fv[np.argmax(cube.vertices[fv, 2].min(axis=1))]
    rim = np.stack([top, np.roll(top, -1)], axis=1)
    below = [v for v in _neighbours(cube, int(top[0])) if v not in top.tolist()]
    creases = np.concatenate([rim, [[top[0], below[0]]]]).astype(np.int64)
    cube = dataclasses.replace(cube, creases=creases)
    return {"creased_torus": torus, "creased_cube": cube}


def _edges(mesh):
    fv = mesh.face_vertices.reshape(-1, 4)
    pairs = np.stack([fv, np.roll(fv, -1, axis=1)], axis=-1).reshape(-1, 2)
    return {tuple(sorted(p)) for p in pairs.tolist()}


def _neighbours(mesh, vertex):
    return [b if a == vertex else a for a, b in _edges(mesh) if vertex in (a, b)]


@pytest.mark.parametrize("name", ["creased_torus", "creased_cube"])
def test_creased_cage_joins_g1_off_its_creases(name):
    """Sharp creases: the patches across a crease edge share it (one closed shell); every
    other edge joins G1, and the patches stay close to the creased limit surface. With
    faces per block, every crease edge lies on a block side (a B-rep edge)."""
    cage = _creased_cages()[name]
    assert cage.n_creases >= 3
    ps = g1_surface_patches(cage)
    diag = ps.info["bbox_diagonal"]
    assert check_topology(ps.topology, ps.patches, 1e-9 * diag) <= 1e-9 * diag
    assert ps.info["normal_jump_crease_edges"] >= cage.n_creases
    assert ps.info["normal_jump_max_deg"] <= 0.01
    assert ps.info["max_error_rel"] <= 2.5e-3
    chart = g1_surface_patches(cage, measure=False, faces="chart")
    assert check_topology(chart.topology, chart.patches, 1e-7 * diag) <= 1e-7 * diag
    assert len(chart.patches) <= len(ps.patches)
    quads = quad_mesh_of(cage)
    topo = mesh_topology(quads.face_vertices, quads.face_offsets, len(quads.vertices))
    assert quad_blocks(quads).cut_edge[crease_edge_mask(topo, quads.creases)].all()


def test_regular_crease_needs_no_knots():
    """A crease loop through valence-4 vertices with two faces on each side: the limit surface
    is the bicubic B-spline of the grid reflected across the crease, so every patch is one
    bicubic (16 poles) equal to the exact limit, joined C1 off the crease."""
    cage = _creased_cages()["creased_torus"]
    ps = g1_surface_patches(cage)
    assert max(p.poles.shape[0] * p.poles.shape[1] for p in ps.patches) == 16
    assert ps.info["max_error_rel"] <= 1e-9
    assert ps.info["normal_jump_max_deg"] <= 0.01


def test_two_face_crease_sector_needs_no_knot_towards_a_regular_end():
    """The once-refined cube with its top rim creased: each rim vertex (valence 3) has a sector
    of one face on top and one of two faces on the sides, whose limit surface is the reflected
    bicubic grid. The eight side quads there, whose other corners are regular, are single
    bicubics (16 poles), the surface stays G1 off the creases and close to the limit; the
    six-face cube, whose side quads reach extraordinary vertices at their other end, keeps
    its knots and stays as close to the limit as without creases."""
    cube = sample_cages.cube()
    fv = cube.face_vertices.reshape(-1, 4)
    top = fv[np.argmax(cube.vertices[fv, 2].min(axis=1))]
    rim = np.stack([top, np.roll(top, -1)], axis=1).astype(np.int64)
    creased = dataclasses.replace(cube, creases=rim)
    refined = build_hierarchy(creased, 1).meshes[1]
    ps = g1_surface_patches(refined)
    quads = refined.face_vertices.reshape(-1, 4)
    at_rim = np.isin(quads, top).any(axis=1)
    sizes = np.array([p.poles.shape[0] * p.poles.shape[1] for p in ps.patches])
    assert (sizes[at_rim] == 16).sum() == 8
    assert ps.info["normal_jump_max_deg"] <= 0.01
    assert ps.info["max_error_rel"] <= 1e-3
    coarse = g1_surface_patches(creased)
    assert coarse.info["max_error_rel"] <= 1.2 * g1_surface_patches(cube).info["max_error_rel"]


def test_pipeline_patches_stage_builds_the_g1_form_on_request():
    """``reconstruct --export g1``: the patches stage exports the fitted cage in the G1 form;
    an unknown form is refused by the parameters."""
    from core.errors import ParameterError
    from core.params import ReconstructionParams
    from core.progress import NO_PROGRESS
    from core.stages.patches import run_patches
    from core.types import FitResult

    cage = sample_cages.genus3_block()
    result = run_patches(FitResult(cage, levels=2), ReconstructionParams(export="g1"), NO_PROGRESS)
    ps = result.patches
    assert result.report["export"] == "g1" and len(ps.patches) == cage.n_faces
    assert max(p.poles.shape[0] * p.poles.shape[1] for p in ps.patches) <= 64
    assert ps.info["normal_jump_max_deg"] <= 0.01
    with pytest.raises(ParameterError, match="export"):
        ReconstructionParams(export="light")


def test_corner_sector_follows_the_limit_tangents():
    """Three crease edges out of one valence-4 vertex of the genus-3 block make a corner with
    a sector of two faces; its inner spoke is no regular fan's, and the connection there takes
    the limit surface's own tangent relation, so the patches stay within 1.15e-3 of the
    diagonal of the creased limit surface."""
    cage = sample_cages.genus3_block()
    valence = np.bincount(cage.face_vertices)
    top = int(np.argmax(cage.vertices[:, 2] + 1e-3 * cage.vertices[:, 0] * (valence == 4)))
    neighbours = sorted(_neighbours(cage, top))
    creases = np.array([[top, v] for v in neighbours[:3]], dtype=np.int64)
    ps = g1_surface_patches(dataclasses.replace(cage, creases=creases))
    assert valence[top] == 4
    assert ps.info["normal_jump_max_deg"] <= 0.01
    assert ps.info["max_error_rel"] <= 1.15e-3


def test_kkt_solve_meets_redundant_conditions_and_matches_the_constrained_fit():
    # a least-squares fit subject to conditions given twice over (redundant rows, as the G1
    # conditions are at every vertex): the solve must meet them to rounding and give the
    # constrained minimiser, which the null-space method computes densely
    from scipy.linalg import null_space
    import scipy.sparse as sp

    from core.export.g1_patches import _solve

    rng = np.random.default_rng(3)
    n, k = 40, 12
    J = rng.normal(size=(80, n))
    H = J.T @ J
    rhs = rng.normal(size=(n, 3))
    A = rng.normal(size=(k, n)) * 300.0  # condition rows far from the fit's scale
    A = np.vstack([A, 2.0 * A[:4] - A[4:8], np.zeros((1, n))])  # dependent rows, an empty one
    x_star = rng.normal(size=(n, 3))
    y = A @ x_star
    centre = rng.normal(size=3)
    x = _solve(sp.csc_matrix(H), rhs, centre, sp.csr_matrix(A), y)
    N = null_space(A)
    expected = x_star + N @ np.linalg.solve(N.T @ H @ N, N.T @ (rhs - H @ x_star))
    scale = np.abs(expected).max()
    assert np.abs(A @ x - y).max() < 1e-9 * np.abs(A).max() * scale
    np.testing.assert_allclose(x, expected, atol=1e-8 * scale)


def test_joins_that_contradict_the_g1_conditions_are_left_out(monkeypatch):
    """The C2 joins inside base quads only save poles: where they cannot hold with the G1
    conditions, the export still gives a closed G1 shell (the quads join C1)."""
    import scipy.sparse as sp

    import core.export.g1_patches as g1

    joins = g1._base_join_system

    def contradicting(*args):
        A, y = joins(*args)
        row = A[:1]
        return sp.vstack([A, row, row]).tocsr(), np.concatenate([y, y[:1] + 1.0, y[:1] - 1.0])

    monkeypatch.setattr(g1, "_base_join_system", contradicting)
    ps = g1_surface_patches(sample_cages.mixed_prism())
    diag = ps.info["bbox_diagonal"]
    assert ps.info["g1_residual"] <= g1.G1_RESIDUAL_MAX * diag
    assert check_topology(ps.topology, ps.patches, 1e-7 * diag) <= 1e-7 * diag
    assert ps.info["normal_jump_max_deg"] < 0.01
