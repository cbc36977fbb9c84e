# SPDX-License-Identifier: LGPL-2.1-or-later
"""Even triangulation before the pairing (core.quadmesh.decimation.even_triangulation): planar fans
get interior vertices with the count and topology kept, QSlim's folded triangles on a real CAD-like
mesh mostly go, and a SIMP iso-surface is left almost as QSlim made it."""
import igl
import numpy as np
import trimesh

from core.geometry import unit_face_normals
from core.mesh_topology import genus_of, unique_edges
from core.quadmesh.decimation.even_triangulation import even_triangulation
from core.target_surface import TargetSurface
from dev_meshes import load_dev_mesh


def facing_away(vertices, faces, surface):
    """Triangles whose normal is more than 90 degrees from the target's at their centroid."""
    reference = surface.closest(vertices[faces].mean(axis=1)).normal
    return int((np.einsum("ij,ij->i", unit_face_normals(vertices, faces), reference) < 0).sum())


def closed_manifold(faces):
    """Every undirected edge in exactly two triangles, every directed edge once."""
    _, halfedge_edge = unique_edges(faces)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    return (np.bincount(halfedge_edge) == 2).all() and \
        len(np.unique(directed, axis=0)) == len(directed)


def test_planar_caps_get_interior_vertices_keeping_count_and_topology():
    # a flat disc: QSlim keeps only the rim of each cap, a fan of long chords
    disc = trimesh.creation.cylinder(radius=2.0, height=0.2, sections=96)
    V, F = np.asarray(disc.vertices, float), np.asarray(disc.faces, np.int64)
    surface = TargetSurface(V, F)
    qslim_v, qslim_f, _, _ = igl.qslim(V, F, 100)
    qslim_f = np.asarray(qslim_f, dtype=np.int64)

    def interior(points):
        return int((np.linalg.norm(points[:, :2], axis=1) < 1.9).sum())

    assert interior(qslim_v) == 0
    vertices, faces = even_triangulation(qslim_v, qslim_f, surface)
    # interior vertices appear, for as many triangles as before
    assert interior(vertices) >= 6
    assert len(qslim_f) - 2 <= len(faces) <= len(qslim_f)
    assert closed_manifold(faces)
    assert genus_of(len(vertices), faces, 1) == 0
    # the new interior vertices lie on the caps, to the 2-degree planarity that lets a vertex
    # be smoothed (the pairing then projects every vertex onto the target), and every
    # triangle faces outwards
    inner = np.linalg.norm(vertices[:, :2], axis=1) < 1.9
    assert np.abs(np.abs(vertices[inner, 2]) - 0.1).max() < 1e-3
    assert facing_away(vertices, faces, surface) == 0


def test_qslim_folds_on_a_real_cad_like_mesh_mostly_repaired():
    target = load_dev_mesh("tray_bottom.stl")
    surface = TargetSurface(target.vertices, target.faces)
    qslim_v, qslim_f, _, _ = igl.qslim(target.vertices, target.faces, 600)
    qslim_f = np.asarray(qslim_f, dtype=np.int64)
    vertices, faces = even_triangulation(qslim_v, qslim_f, surface)
    genus = genus_of(len(target.vertices), target.faces, 1)
    assert genus_of(len(vertices), faces, 1) == genus
    assert closed_manifold(faces)
    assert len(faces) >= 0.95 * len(qslim_f)
    # most of the triangles facing away from the target are turned round
    assert facing_away(qslim_v, qslim_f, surface) >= 40
    assert facing_away(vertices, faces, surface) <= 10


def test_a_simp_iso_surface_is_left_almost_as_qslim_made_it():
    target = load_dev_mesh("to_simp_pylon.stl")
    surface = TargetSurface(target.vertices, target.faces)
    qslim_v, qslim_f, _, _ = igl.qslim(target.vertices, target.faces, 600)
    vertices, faces = even_triangulation(qslim_v, np.asarray(qslim_f, dtype=np.int64), surface)
    # no planar region: at most a few splits, so almost every QSlim vertex is still there
    kept = TargetSurface(vertices, faces).nearest(qslim_v).distance < 1e-9
    assert kept.mean() >= 0.9


def test_flips_on_a_machined_part_end_in_a_triangulation_no_flip_changes():
    from core.quadmesh.decimation.even_triangulation import _flip_pass

    target = load_dev_mesh("featuretype.stl")  # counterbores and notches, genus 9
    surface = TargetSurface(target.vertices, target.faces)
    qslim_v, qslim_f, _, _ = igl.qslim(target.vertices, target.faces, 600)
    vertices, faces = even_triangulation(qslim_v, np.asarray(qslim_f, dtype=np.int64), surface)
    assert closed_manifold(faces)
    assert genus_of(len(vertices), faces, 1) == 9
    # every flip makes both its triangles face the target, so none is undone: the result is a
    # fixed point (flips would go back and forth if an untangling flip could leave a triangle
    # facing away)
    assert np.array_equal(_flip_pass(vertices, faces, surface, max_passes=1), faces)
