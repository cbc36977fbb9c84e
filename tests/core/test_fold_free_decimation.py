# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fold-free decimation (core.quadmesh.decimation.fold_free_decimation) and the paired cages of
thin-strut lattices built here: closed, the target's genus, no triangle across a strut, and a limit
surface that does not cross itself."""
import numpy as np
import pytest

from core.mesh_topology import connected_face_components, genus_of, polymesh_genus
from core.polymesh_checks import check_polymesh
from core.quadmesh.decimation.fold_free_decimation import (MIN_NORMAL_COSINE, NORMAL_SMOOTHING,
                                                           FoldFreeDecimation, folded_share,
                                                           smoothed_vertex_normals)

pytestmark = pytest.mark.unit


def strut_lattice(cells=(1, 1, 1), radius=0.12, step=0.05, voxel=False):
    """Closed outward triangle surface of round struts along the edges of a grid of unit
    cells (genus: struts - nodes + 1), by marching cubes of its distance field; with
    ``voxel`` of the field thresholded to the voxels first (a raw voxel staircase).

    Returns ``(V, F, genus)``.
    """
    from skimage.measure import marching_cubes
    import trimesh

    nodes = np.stack(np.meshgrid(*[np.arange(c + 1.0) for c in cells], indexing="ij"),
                     -1).reshape(-1, 3)
    starts, ends = [], []
    for a in nodes:
        for axis in range(3):
            b = a.copy()
            b[axis] += 1
            if b[axis] <= cells[axis]:
                starts.append(a)
                ends.append(b)
    lo = -2 * radius - step
    axes = [np.arange(lo, c + 2 * radius + step, step) for c in cells]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    distance = np.full(P.shape[:3], np.inf)
    for s, e in zip(starts, ends):
        u = e - s
        t = np.clip(((P - s) @ u) / (u @ u), 0.0, 1.0)
        distance = np.minimum(distance, np.linalg.norm(P - s - t[..., None] * u, axis=-1))
    field = radius - distance
    if voxel:
        field = (field > 0).astype(float) - 0.5
    V, F, _, _ = marching_cubes(field, 0.0, spacing=(step,) * 3)
    mesh = trimesh.Trimesh(V, F[:, ::-1], process=True)
    return (np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64),
            len(starts) - len(nodes) + 1)


def _genus(V, F):
    return genus_of(len(V), F, int(connected_face_components(F).max()) + 1)


@pytest.mark.parametrize("voxel", [False, True])
def test_decimated_lattice_keeps_its_genus_and_no_triangle_spans_a_strut(voxel):
    V, F, genus = strut_lattice(voxel=voxel)
    assert _genus(V, F) == genus == 5
    decimation = FoldFreeDecimation(V, F)
    v, f = decimation.triangles(120)
    assert len(f) < len(F) / 10
    assert _genus(v, f) == genus
    # closed 2-manifold: every edge in exactly two triangles, once each way
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)
    reverse = {tuple(e) for e in directed[:, ::-1].tolist()}
    assert all(tuple(e) in reverse for e in directed.tolist())
    # every vertex left is a vertex of the target
    target = {tuple(p) for p in V.tolist()}
    assert all(tuple(p) in target for p in v.tolist())
    # no triangle faces across the target's normals at its corners (a triangle spanning a
    # strut has corners on opposite sides of it)
    normals = smoothed_vertex_normals(V, F, NORMAL_SMOOTHING)
    index = {tuple(p): k for k, p in enumerate(V.tolist())}
    corner_normal = normals[np.array([index[tuple(p)] for p in v.tolist()])][f]
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    unit = cross / np.linalg.norm(cross, axis=1)[:, None]
    assert np.einsum("fkj,fj->fk", corner_normal, unit).min() >= MIN_NORMAL_COSINE - 1e-9
    assert folded_share(V, F, v, f) == 0.0
    # turned inside out, every triangle faces across the target
    assert folded_share(V, F, v, f[:, ::-1]) == 1.0
    # the same count gives the same arrays, and a smaller one no more triangles
    assert decimation.triangles(120)[1] is f
    assert len(decimation.triangles(60)[1]) <= len(f)


@pytest.mark.slow
@pytest.mark.parametrize("voxel", [False, True])
def test_paired_cage_of_a_thin_strut_lattice_has_a_limit_surface_that_does_not_cross(voxel):
    from core.quadmesh.orientation import inverted_faces
    from core.quadmesh.decimation.paired_decimation import paired_decimation_base_mesh
    from core.subdivision.limit_crossings import count_limit_self_intersections
    from core.target_surface import TargetSurface

    V, F, genus = strut_lattice(voxel=voxel)
    surface = TargetSurface(V, F)
    result = paired_decimation_base_mesh(V, F, 100, surface, 115, 2500)
    check_polymesh(result.mesh)  # closed, 2-manifold, oriented, no degenerate face
    assert polymesh_genus(result.mesh) == genus
    assert count_limit_self_intersections(result.mesh, 2) == 0
    assert result.limit_crossings == 0
    assert not inverted_faces(result.mesh, V, F, surface).any()
    assert result.mesh.n_faces <= 6 * 100


@pytest.mark.slow
def test_without_the_normal_rule_it_reaches_the_count_and_tightening_brings_the_rule_in_there():
    V, F, genus = strut_lattice()
    relaxed = FoldFreeDecimation(V, F, min_normal_cosine=-1.0)
    fold_free = FoldFreeDecimation(V, F)
    assert not relaxed.fold_free and fold_free.fold_free
    v, f = relaxed.triangles(80)
    # fewer refusals: no more triangles than the fold-free decimation keeps
    assert len(f) <= len(fold_free.triangles(80)[1]) and _genus(v, f) == genus
    # tightened around one corner of the lattice: the normal rule holds for the target
    # vertices collapsed there, nowhere else
    tight = relaxed.tightened(80, V[[np.argmin(V.sum(axis=1))]])
    raised = tight.min_normal_cosine > relaxed.min_normal_cosine
    assert 0 < raised.sum() < len(V) / 2
    assert (tight.min_normal_cosine[raised] >= MIN_NORMAL_COSINE).all()
    assert (tight.min_normal_cosine[~raised] == -1.0).all()
    assert tight.tightenings == 1 and not tight.fold_free
