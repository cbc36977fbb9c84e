# SPDX-License-Identifier: LGPL-2.1-or-later
"""Coarse quad base mesh from a polycube (core.quadmesh)."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import LabelingError, ParameterError, StageNotAvailableError
from core.polycube.deform import polycube_deformation
from core.polymesh_checks import check_polymesh
from core.quadmesh import base_mesh_from_polycube, mesh_statistics
from core.quadmesh.quad_ops import chord_pieces, chord_refine, free_loop_merge, unmatched_half_edges
from core.types import TriMesh

MESHES = Path("/work/shared/data/meshes")


def nearest_labels(V, F):
    """Label 0..5 of the axis direction closest to each face normal."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return np.argmax(np.concatenate([n, -n], axis=1)[:, [0, 3, 1, 4, 2, 5]], axis=1)


def union_of_boxes(boxes, max_edge):
    """Closed triangle mesh of a union of axis-aligned boxes ((lo, hi) pairs), small triangles."""
    parts = [trimesh.creation.box(bounds=np.array(b, dtype=float)) for b in boxes]
    mesh = trimesh.boolean.union(parts, engine="manifold") if len(parts) > 1 else parts[0]
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=max_edge)
    mesh = trimesh.Trimesh(V, F, process=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def build(V, F, **kwargs):
    labels = nearest_labels(V, F)
    pc = polycube_deformation(V, F, labels, np.eye(3))
    return base_mesh_from_polycube(TriMesh(V, F), pc, labels, **kwargs), pc, labels


def distance_to_surface(points, V, F):
    """(q,) distance of each point to the nearest triangle it projects into (upper bound)."""
    a, e1, e2 = V[F[:, 0]], V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    n = np.cross(e1, e2)
    n2 = np.einsum("tk,tk->t", n, n)
    out = np.full(len(points), np.inf)
    for start in range(0, len(points), 64):
        d = points[start:start + 64, None] - a[None]
        height = np.einsum("qtk,tk->qt", d, n) / np.sqrt(n2)
        u = np.einsum("qtk,tk->qt", np.cross(d, e2[None]), n) / n2
        v = np.einsum("qtk,tk->qt", np.cross(e1[None], d), n) / n2
        inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
        out[start:start + 64] = np.where(inside, np.abs(height), np.inf).min(axis=1)
    return out


def t_junctions(mesh):
    """Number of vertices lying inside an edge they are not an end of (tolerance 1e-9)."""
    q = mesh.face_vertices.reshape(-1, 4)
    a, b = q.reshape(-1), np.roll(q, -1, axis=1).reshape(-1)
    P = mesh.vertices
    d = P[b] - P[a]
    t = np.einsum("evk,ek->ev", P[None] - P[a][:, None], d) / np.einsum("ek,ek->e", d, d)[:, None]
    foot = P[a][:, None] + t[..., None] * d[:, None]
    close = np.linalg.norm(P[None] - foot, axis=2) <= 1e-9 * np.ptp(P, axis=0).max()
    inside = (t > 1e-9) & (t < 1 - 1e-9) & close
    return int(inside.sum())


def test_box_gives_six_quads_on_the_box():
    mesh = trimesh.creation.box(extents=(2.0, 3.0, 4.0)).subdivide().subdivide().subdivide()
    V = np.asarray(mesh.vertices) + np.array([1.0, -2.0, 0.5])
    F = np.asarray(mesh.faces, dtype=np.int64)
    (base, info), _, _ = build(V, F)
    check_polymesh(base)
    assert info["faces"] == info["quads"] == 6 and info["vertices"] == 8 and info["genus"] == 0
    # the 8 vertices are the box corners
    corners = np.array([[x, y, z] for x in (0.0, 2.0) for y in (-3.5, -0.5) for z in (-1.5, 2.5)])
    dist = np.linalg.norm(base.vertices[:, None] - corners[None], axis=2).min(axis=1)
    assert dist.max() <= 1e-9
    assert info["volume"] == pytest.approx(24.0, rel=1e-9)
    assert info["located_in_flipped"] == 0 and info["located_outside"] == 0


def test_l_shape_is_closed_conforming_genus_zero():
    V, F = union_of_boxes([[(0, 0, 0), (2, 1, 1)], [(0, 0, 0), (1, 2, 1)]], 0.2)
    (base, info), _, _ = build(V, F)
    check_polymesh(base)
    assert info["genus"] == 0 and info["quads"] == info["faces"] == 14
    assert t_junctions(base) == 0
    assert distance_to_surface(base.vertices, V, F).max() <= 1e-9
    assert info["volume"] == pytest.approx(3.0, rel=1e-9)


def test_free_loops_are_removed():
    # a base with two posts of different heights: the top plane of the low post cuts the
    # high post in a loop that meets no corner; coarsening removes it
    boxes = [[(0, 0, 0), (3, 1, 1)], [(0, 0, 0), (1, 1, 2)], [(2, 0, 0), (3, 1, 3)]]
    V, F = union_of_boxes(boxes, 0.25)
    (fine, fine_info), _, _ = build(V, F, coarsen=False)
    (coarse, info), _, _ = build(V, F)
    for mesh in (fine, coarse):
        check_polymesh(mesh)
        assert t_junctions(mesh) == 0
    assert info["free_loops_removed"] >= 1 and info["faces"] < fine_info["faces"]
    assert info["genus"] == fine_info["genus"] == 0
    assert info["volume"] == pytest.approx(6.0, rel=1e-9)
    assert fine_info["volume"] == pytest.approx(6.0, rel=1e-9)


def test_sphere_gives_six_quads_on_the_sphere():
    mesh = trimesh.creation.icosphere(3)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)
    (base, info), _, _ = build(V, F)
    check_polymesh(base)
    assert info["faces"] == 6 and info["genus"] == 0 and info["volume"] > 0
    assert distance_to_surface(base.vertices, V, F).max() <= 1e-9
    # icosphere(3) is within 0.002 of the unit sphere
    assert np.abs(np.linalg.norm(base.vertices, axis=1) - 1.0).max() <= 0.01


def test_refinement_reaches_target_and_stays_valid():
    mesh = trimesh.creation.icosphere(3)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)
    (base, info), _, _ = build(V, F, target_faces=150)
    check_polymesh(base)
    assert 150 <= info["faces"] <= 300 and info["quads"] == info["faces"]
    assert info["genus"] == 0 and info["extraordinary_vertices"] == 8
    assert t_junctions(base) == 0
    assert distance_to_surface(base.vertices, V, F).max() <= 1e-9
    assert sum(info["chart_faces"]) == info["faces"]
    # the refined cage encloses nearly the sphere's volume (chordal loss only)
    assert info["volume"] == pytest.approx(4.0 / 3.0 * np.pi, rel=0.1)


def test_deterministic():
    V, F = union_of_boxes([[(0, 0, 0), (2, 1, 1)], [(0, 0, 0), (1, 2, 1)]], 0.3)
    (a, ia), _, _ = build(V, F, target_faces=60)
    (b, ib), _, _ = build(V, F, target_faces=60)
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.face_vertices, b.face_vertices)
    ia.pop("seconds"), ib.pop("seconds")
    assert ia == ib


def test_chord_refine_splits_strips_evenly():
    # unit cube cage: refine with spacing 0.5 -> every face 2 x 2
    P = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    pieces, edge = chord_pieces(quads, P, 0.5)
    out, pos, _, quad_face = chord_refine(quads, P, pieces, edge)
    assert len(out) == 24 and np.array_equal(quad_face, np.repeat(np.arange(6), 4))
    stats = mesh_statistics(_polymesh(pos, out))
    assert stats["vertices"] == 26 and stats["genus"] == 0 and stats["extraordinary_vertices"] == 8
    # the three mid loops run inside the faces and through regular vertices: all free
    merged, loops = free_loop_merge(out, quad_face)
    assert loops == 3 and np.array_equal(merged, quad_face)
    # with every small quad its own group no edge is inside a group: nothing is free
    merged, loops = free_loop_merge(out, np.arange(24))
    assert loops == 0 and np.array_equal(merged, np.arange(24))


def _polymesh(P, quads):
    from core.types import PolyMesh
    return PolyMesh(P, quads.reshape(-1), np.arange(0, 4 * len(quads) + 1, 4))


def test_errors():
    mesh = trimesh.creation.box(extents=(1.0, 1.0, 1.0)).subdivide().subdivide()
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)
    labels = nearest_labels(V, F)
    pc = polycube_deformation(V, F, labels, np.eye(3))
    target = TriMesh(V, F)
    with pytest.raises(StageNotAvailableError, match="2 parts"):
        base_mesh_from_polycube(target, pc, labels, face_part=(V[F].mean(axis=1)[:, 0] > 0)
                                .astype(np.int64))
    with pytest.raises(ParameterError, match="face_label"):
        base_mesh_from_polycube(target, pc, labels[:-1])
    with pytest.raises(ParameterError, match="do not match"):
        base_mesh_from_polycube(target, pc, (labels + 1) % 6)
    with pytest.raises(ParameterError, match="target_faces"):
        base_mesh_from_polycube(target, pc, labels, target_faces=2)
    # move one chart-boundary vertex off its grid line, inside the chart plane
    local = pc.local.copy()
    edge_vertex = np.flatnonzero((np.abs(np.abs(V) - 0.5) < 1e-12).sum(axis=1) == 2)[0]
    free_axis = int(np.flatnonzero(np.abs(np.abs(V[edge_vertex]) - 0.5) >= 1e-12)[0])
    along = [k for k in range(3) if k != free_axis][0]
    local[edge_vertex, along] -= 0.05 * np.sign(local[edge_vertex, along])
    broken = dataclasses.replace(pc, local=local)
    with pytest.raises(LabelingError, match="not rectilinear"):
        base_mesh_from_polycube(target, broken, labels)


def test_real_mesh_bone():
    from core.export.bspline import limit_surface_patches, triangle_mesh_volume
    from core.pipeline import reconstruct
    from core.subdivision.limit import limit_volume

    path = MESHES / "polycube_bone.obj"
    if not path.exists():
        pytest.skip("dev mesh not available")
    state = reconstruct(path, None, stop_after="basemesh").state
    target = state["target"]
    base, info = base_mesh_from_polycube(target, state["polycube"], state["face_label"],
                                         state["face_part"], state["frames"].part_frames,
                                         target_faces=300)
    check_polymesh(base)
    assert info["genus"] == 0 and info["faces"] >= 300
    assert distance_to_surface(base.vertices, target.vertices, target.faces).max() <= 1e-6
    patches = limit_surface_patches(base, measure=False)
    assert len(patches.patches) >= info["faces"]
    ratio = limit_volume(base, 4) / triangle_mesh_volume(target.vertices, target.faces)
    assert 0.8 <= ratio <= 1.2


def test_near_coincident_planes_merge_transitively():
    # four posts of equal height; their top planes drift apart by 0.9 merge tolerances each,
    # so the merged coordinate is more than one tolerance from the outer planes
    boxes = [[(0, 0, 0), (7, 1, 1)]] + [[(2 * k, 0, 0), (2 * k + 1, 1, 2)] for k in range(4)]
    V, F = union_of_boxes(boxes, 0.25)
    labels = nearest_labels(V, F)
    pc = polycube_deformation(V, F, labels, np.eye(3))
    top = np.flatnonzero((np.abs(pc.chart_plane - 2.0) < 1e-9) & (pc.chart_label == 4))
    assert len(top) == 4
    tol = 1e-6 * np.linalg.norm(np.ptp(pc.local, axis=0))
    local, plane = pc.local.copy(), pc.chart_plane.copy()
    for k, c in enumerate(top):
        local[np.unique(F[pc.face_chart == c]), 2] += 0.9 * k * tol
        plane[c] += 0.9 * k * tol
    drifted = dataclasses.replace(pc, local=local, chart_plane=plane)
    base, info = base_mesh_from_polycube(TriMesh(V, F), drifted, labels)
    check_polymesh(base)
    assert info["genus"] == 0 and info["grid"][2] == 3 and t_junctions(base) == 0
    assert info["volume"] == pytest.approx(11.0, rel=1e-5)


def test_collapsed_member_is_reported_with_its_charts():
    # a square ring whose hole is squeezed to zero width in the polycube: the two hole walls
    # facing +X and -X lie on one plane over the same cells
    boxes = [[(0, 0, 0), (3, 1, 1)], [(0, 2, 0), (3, 3, 1)], [(0, 0, 0), (1, 3, 1)],
             [(2, 0, 0), (3, 3, 1)]]
    V, F = union_of_boxes(boxes, 0.25)
    labels = nearest_labels(V, F)
    pc = polycube_deformation(V, F, labels, np.eye(3))
    (_, info), _, _ = build(V, F)
    assert info["genus"] == 1

    def squeeze(x):
        return np.where(x <= 1, x + 0.5, np.where(x >= 2, x - 0.5, 1.5))

    local = pc.local.copy()
    local[:, 0] = squeeze(local[:, 0])
    plane = np.where(pc.chart_label // 2 == 0, squeeze(pc.chart_plane), pc.chart_plane)
    walls = np.flatnonzero((pc.chart_label // 2 == 0) & (np.abs(plane - 1.5) < 1e-9))
    assert len(walls) == 2
    collapsed = dataclasses.replace(pc, local=local, chart_plane=plane)
    with pytest.raises(LabelingError, match="collapsed to zero thickness") as error:
        base_mesh_from_polycube(TriMesh(V, F), collapsed, labels)
    assert f"{walls[0]} and {walls[1]}" in str(error.value)


def test_unmatched_half_edges():
    cube = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6],
                     [3, 0, 4, 7]], dtype=np.int64)
    bad, twin = unmatched_half_edges(cube)
    assert not bad.any() and np.array_equal(twin[twin], np.arange(24))
    bad, _ = unmatched_half_edges(np.concatenate([cube, cube[:1]]))
    assert bad.reshape(-1, 4)[[0, 6]].all() and bad.sum() == 12


def test_real_mesh_octagonal_pocket():
    # many pocket-floor charts on planes within ~1e-6 of each other; polycube sheets touch
    from core.pipeline import reconstruct

    path = MESHES / "octagonal_pocket.stl"
    if not path.exists():
        pytest.skip("dev mesh not available")
    state = reconstruct(path, None, stop_after="basemesh").state
    target = state["target"]
    base, info = base_mesh_from_polycube(target, state["polycube"], state["face_label"],
                                         state["face_part"], state["frames"].part_frames,
                                         target_faces=300)
    check_polymesh(base)
    assert info["genus"] == state["input_genus"] == 1
    assert distance_to_surface(base.vertices, target.vertices, target.faces).max() <= 1e-6
