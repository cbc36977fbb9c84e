# SPDX-License-Identifier: LGPL-2.1-or-later
"""Feature-preserving decimation (core.quadmesh.decimation.feature_decimation) and the creased cages
of the paired decimation built on it."""
import numpy as np
import pytest
import trimesh

from core.mesh_topology import genus_of, unique_edges
from core.quadmesh.creases import feature_edges
from core.quadmesh.decimation.even_triangulation import even_creased_triangulation
from core.quadmesh.decimation.feature_decimation import FeatureDecimation, corner_vertices
from dev_meshes import load_dev_mesh

BORE_RADIUS = 1.1
HOLE_RADIUS = 0.6


def _counterbored_block():
    """A 4 x 4 x 2 block with a through hole and a counterbore (genus 1; 32-gon circles),
    its faces split to edges of at most 0.5 so that the planes have free vertices."""
    manifold3d = pytest.importorskip("manifold3d")
    block = manifold3d.Manifold.cube([4.0, 4.0, 2.0])
    hole = manifold3d.Manifold.cylinder(4.0, HOLE_RADIUS, HOLE_RADIUS, 32).translate(
        [2.0, 2.0, -1.0])
    bore = manifold3d.Manifold.cylinder(1.0, BORE_RADIUS, BORE_RADIUS, 32).translate(
        [2.0, 2.0, 1.4])
    mesh = (block - hole - bore).to_mesh()
    V, F = trimesh.remesh.subdivide_to_size(mesh.vert_properties[:, :3], mesh.tri_verts, 0.5)
    merged = trimesh.Trimesh(V, F, process=True)
    return np.asarray(merged.vertices, dtype=np.float64), np.asarray(merged.faces, dtype=np.int64)


def _distance_to_segments(points, starts, ends):
    """(p,) distance of every point to the nearest of the segments ``starts``-``ends``."""
    along = ends - starts
    t = np.einsum("pkj,kj->pk", points[:, None] - starts[None], along) / np.einsum(
        "kj,kj->k", along, along)[None]
    foot = starts[None] + np.clip(t, 0.0, 1.0)[..., None] * along[None]
    return np.linalg.norm(points[:, None] - foot, axis=2).min(axis=1)


@pytest.mark.slow
@pytest.mark.parametrize("count", [300, 120])
def test_every_feature_line_of_a_counterbored_block_stays_a_chain_of_edges(count):
    V, F = _counterbored_block()
    target_features = feature_edges(V, F)
    assert len(target_features) > 100  # 12 block edges, 4 circles of 32 edges, split
    decimation = FeatureDecimation(V, F)
    v, f, features = decimation.triangles(count)
    assert len(f) == count
    assert genus_of(len(v), f, 1) == genus_of(len(V), F, 1) == 1
    # the decimated feature edges are edges of the result
    edges, _ = unique_edges(f)
    n = len(v)
    assert np.isin(features[:, 0] * n + features[:, 1], edges[:, 0] * n + edges[:, 1]).all()
    # every target feature edge's midpoint lies on a decimated feature edge: on the straight
    # lines exactly, on a circle within the sagitta of a chord of the bore's circle cut into
    # 6 (a round hole keeps 6 edges)
    midpoint = V[target_features].mean(axis=1)
    distance = _distance_to_segments(midpoint, v[features[:, 0]], v[features[:, 1]])
    sagitta = BORE_RADIUS * (1.0 - np.cos(np.pi / 6))
    assert distance.max() < sagitta
    on_circle = np.abs(np.linalg.norm(midpoint[:, :2] - 2.0, axis=1) - 2.0) > 0.9
    assert distance[~on_circle].max() < 1e-9
    # the corners (the block's 8 corners) are kept in place
    corner = corner_vertices(V, target_features)
    assert corner.sum() == 8
    assert (np.linalg.norm(V[corner][:, None] - v[None], axis=2).min(axis=1) == 0.0).all()


def _smallest_angles(v, f):
    """(m,) smallest corner angle (degrees) of every triangle."""
    P = v[f]
    to_next, to_prev = np.roll(P, -1, axis=1) - P, np.roll(P, 1, axis=1) - P
    cosine = np.einsum("tkj,tkj->tk", to_next, to_prev) / (
        np.linalg.norm(to_next, axis=2) * np.linalg.norm(to_prev, axis=2))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).min(axis=1)


@pytest.mark.slow
def test_evening_a_feature_decimation_keeps_its_feature_lines_and_fattens_its_fans():
    from core.target_surface import TargetSurface

    V, F = _counterbored_block()
    surface = TargetSurface(V, F)
    decimation = FeatureDecimation(V, F, surface)
    plain_v, plain_f, _ = decimation.triangles(200)
    v, f, features = even_creased_triangulation(decimation, 200, surface)
    assert len(f) == 200
    assert genus_of(len(v), f, 1) == 1
    # every feature edge is an edge of the result, and every target feature edge's midpoint
    # still lies on one (as in the decimation itself)
    edges, _ = unique_edges(f)
    n = len(v)
    assert np.isin(features[:, 0] * n + features[:, 1], edges[:, 0] * n + edges[:, 1]).all()
    midpoint = V[feature_edges(V, F)].mean(axis=1)
    distance = _distance_to_segments(midpoint, v[features[:, 0]], v[features[:, 1]])
    assert distance.max() < BORE_RADIUS * (1.0 - np.cos(np.pi / 6))
    # the vertices stay on the block (planar moves only)
    assert surface.nearest(v).distance.max() < 1e-9
    # the planar fans got fatter: the smallest angles went up. The very smallest may stay:
    # where the decimation left a thin triangle with its three corners on feature lines
    # (which never move), flips inside planar regions cannot always reach it (the decimation
    # differs in the last bits between machines, so whether it does is not asserted)
    before, after = _smallest_angles(plain_v, plain_f), _smallest_angles(v, f)
    assert after.min() >= before.min()
    assert np.percentile(after, 10) > np.percentile(before, 10)
    assert np.median(after) > np.median(before) + 3.0


@pytest.mark.slow
def test_pairing_never_merges_triangles_across_a_feature_edge():
    from core.quadmesh.decimation.paired_decimation import _paired_mesh, _rim_folds
    from core.subdivision.catmull_clark import mesh_topology
    from core.target_surface import TargetSurface

    V, F = _counterbored_block()
    surface = TargetSurface(V, F)
    decimation = FeatureDecimation(V, F, surface)
    cage = _paired_mesh(decimation, 200, surface).mesh
    _, _, features = even_creased_triangulation(decimation, 200, surface)
    assert cage.n_creases == len(features)  # every decimated feature edge stays a cage edge
    topo = mesh_topology(cage.face_vertices, cage.face_offsets, len(cage.vertices))
    assert (topo.edge_index(cage.creases[:, 0], cage.creases[:, 1]) >= 0).all()
    # the bore's rims on the block's flat faces are fans: a quad of two fan triangles would
    # have a reflex corner between two of its crease edges, and those are not paired, so
    # fewer faces are quads than on a smooth part
    assert (cage.face_sizes == 4).mean() > 0.6
    quads = np.array([cage.face_vertices[o:o + 4] for o, size in
                      zip(cage.face_offsets[:-1], cage.face_sizes) if size == 4])
    assert not _rim_folds(cage.vertices, quads, cage.creases).any()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["octagonal_pocket.stl", "featuretype.stl"])
def test_creased_cage_of_a_machined_part_is_clean_at_the_default_budget(name):
    """The creased ladder's first cage (300 faces wanted) of two machined parts: no
    inverted face, no crossing of its level-2 limit surface, within the face budget rule
    (with QSlim's edges tagged instead, both cross themselves)."""
    from core.quadmesh.decimation.paired_decimation import _flawed_mesh
    from core.target_surface import TargetSurface

    target = load_dev_mesh(name)
    surface = TargetSurface(target.vertices, target.faces)
    rounds = []
    result, crossings, inverted = _flawed_mesh(
        FeatureDecimation(target.vertices, target.faces, surface), 300, surface, rounds)
    assert crossings == 0 and inverted == 0
    assert 0.75 * 300 <= result.mesh.n_faces <= 1.25 * 300
    assert result.quads >= 0.85 * result.mesh.n_faces
    assert rounds[0]["crease_edges"] > 250


@pytest.mark.slow
def test_a_decimation_that_stops_short_answers_every_smaller_count_alike():
    """Where every collapse left is refused, the decimation to any count below the triangles
    reached is the same; the cached answer equals a fresh decimation to that count."""
    box = trimesh.creation.box([2.0, 2.0, 1.0])
    V, F = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, 0.3)
    merged = trimesh.Trimesh(V, F, process=True)
    V, F = np.asarray(merged.vertices, dtype=np.float64), np.asarray(merged.faces, dtype=np.int64)
    decimation = FeatureDecimation(V, F)
    floor = decimation.triangles(2)
    assert len(floor[1]) > 2  # the box's corners and edges stop it
    count = len(floor[1]) - 1
    cached = decimation.triangles(count)
    assert cached[1] is floor[1]
    for mine, fresh in zip(cached, FeatureDecimation(V, F).triangles(count)):
        np.testing.assert_array_equal(mine, fresh)
    assert len(decimation.triangles(len(floor[1]) + 4)[1]) == len(floor[1]) + 4


@pytest.mark.slow
def test_counts_asked_in_any_order_give_the_fresh_decimations():
    """A lower count continues the decimation made before and a higher one replays its first
    collapses; either way the answer equals a decimation of a new object to that count."""
    V, F = _counterbored_block()
    decimation = FeatureDecimation(V, F)
    for count in (300, 200, 400, 240):
        mine = decimation.triangles(count)
        assert len(mine[1]) == count
        for got, fresh in zip(mine, FeatureDecimation(V, F).triangles(count)):
            np.testing.assert_array_equal(got, fresh)
