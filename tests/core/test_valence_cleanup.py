# SPDX-License-Identifier: LGPL-2.1-or-later
"""Valence cleanup of paired cages (core.quadmesh.decimation.valence_cleanup): fewer
extraordinary vertices, the same closed 2-manifold genus, no inverted face, well within the face
window, the same result every time; and the paired decimation keeps a cleaned cage only where
its limit flaws do not grow."""
import dataclasses
from functools import lru_cache

import numpy as np
import pytest
import trimesh

from core.mesh_topology import polymesh_genus, polymesh_summary
from core.polymesh_checks import check_polymesh
from core.quadmesh.decimation.decimation import Decimation
from core.quadmesh.decimation.paired_decimation import (_cleaned_or_not, _paired_mesh,
                                                        _repaired, limit_flaws)
from core.quadmesh.decimation.valence_cleanup import clean_valences
from core.quadmesh.orientation import inverted_faces
from core.target_surface import TargetSurface
from dev_meshes import load_dev_mesh
from test_paired_decimation import torus


def sphere():
    mesh = trimesh.creation.icosphere(3, radius=2.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def small_torus():
    return torus(sections=48, rings=24)


@lru_cache(maxsize=None)
def paired_shape(shape, budget):
    """:func:`paired` of a shape built here (decimated once for all tests)."""
    return paired(*shape(), budget)


def paired(vertices, faces, budget):
    """The paired cage (before any cleanup) of ``budget`` faces and its target surface."""
    surface = TargetSurface(vertices, faces)
    decimation = Decimation(vertices, faces, coarse_triangles=2 * budget)
    return _paired_mesh(decimation, 2 * budget, surface), surface


def extraordinary(mesh):
    return polymesh_summary(mesh)["extraordinary_vertices"]


@pytest.mark.parametrize("shape, genus, budget", [(sphere, 0, 150), (small_torus, 1, 200),
                                                  (small_torus, 1, 60)])
def test_cleanup_lowers_extraordinary_vertices_and_keeps_the_surface(shape, genus, budget):
    result, surface = paired_shape(shape, budget)
    mesh = result.mesh
    low, high = int(0.9 * mesh.n_faces), int(1.1 * mesh.n_faces)
    cleanup = clean_valences(mesh, surface, low, high)
    cleaned = cleanup.mesh
    check_polymesh(cleaned)  # closed, 2-manifold, outward, no repeated corner, no zero area
    assert polymesh_genus(cleaned) == polymesh_genus(mesh) == genus
    valence = np.bincount(cleaned.face_vertices)
    assert valence.min() >= 3
    assert low <= cleaned.n_faces <= high
    assert (cleaned.face_sizes == 4).sum() >= 0.9 * cleaned.n_faces
    before, after = extraordinary(mesh), extraordinary(cleaned)
    assert (cleanup.extraordinary_before, cleanup.extraordinary_after) == (before, after)
    assert cleanup.rotations + cleanup.collapses + cleanup.splits > 0
    assert after <= 0.9 * before
    assert not inverted_faces(mesh, surface.vertices, surface.faces, surface).any()
    assert not inverted_faces(cleaned, surface.vertices, surface.faces, surface).any()
    # the vertices stay on the target
    assert surface.nearest(cleaned.vertices).distance.max() < 1e-9 * surface.diagonal


def test_cleanup_is_deterministic():
    result, surface = paired_shape(small_torus, 200)
    first = clean_valences(result.mesh, surface, 180, 220).mesh
    second = clean_valences(result.mesh, surface, 180, 220).mesh
    assert np.array_equal(first.face_vertices, second.face_vertices)
    assert np.array_equal(first.face_offsets, second.face_offsets)
    assert np.array_equal(first.vertices, second.vertices)


def test_fixed_vertices_keep_their_place_and_valence():
    result, surface = paired_shape(sphere, 150)
    mesh = result.mesh
    valence = np.bincount(mesh.face_vertices)
    # the extraordinary vertices of one half kept as they are
    fixed = np.flatnonzero((valence != 4) & (mesh.vertices[:, 2] > 0.0))
    cleanup = clean_valences(mesh, surface, 140, 160, fixed)
    after = np.bincount(cleanup.mesh.face_vertices)
    for v in fixed.tolist():
        kept = np.flatnonzero(cleanup.origin == v)
        assert len(kept) == 1  # neither merged nor split
        assert np.array_equal(cleanup.mesh.vertices[kept[0]], mesh.vertices[v])
        assert after[kept[0]] == valence[v]
    assert cleanup.extraordinary_after < cleanup.extraordinary_before


def test_creases_stay_edges_with_their_vertices_in_place():
    from dataclasses import replace

    result, surface = paired_shape(sphere, 150)
    mesh = result.mesh
    # the edges round one face tagged as creases: a closed chain
    first = mesh.face_vertices[mesh.face_offsets[0]:mesh.face_offsets[1]]
    creases = np.stack([first, np.roll(first, -1)], axis=1)
    tagged = replace(mesh, creases=creases)
    cleanup = clean_valences(tagged, surface, 140, 160)
    check_polymesh(cleanup.mesh)  # every crease pair is still an edge
    valence = np.bincount(mesh.face_vertices)
    after = np.bincount(cleanup.mesh.face_vertices)
    for v in first.tolist():
        kept = np.flatnonzero(cleanup.origin == v)
        assert len(kept) == 1
        assert np.array_equal(cleanup.mesh.vertices[kept[0]], mesh.vertices[v])
        assert after[kept[0]] == valence[v]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["idler_riser.stl", "to_simp_torsion_arm.stl"])
def test_the_cage_kept_has_no_more_limit_flaws_than_the_uncleaned_one(name):
    target = load_dev_mesh(name)
    result, surface = paired(target.vertices, target.faces, 300)
    repaired, plain_crossings, plain_inverted, _, _ = _repaired(result, surface)
    kept, crossings = _cleaned_or_not(repaired, surface, plain_crossings, plain_inverted)
    assert limit_flaws(kept.mesh, surface) == (crossings, kept_inverted(kept, surface))
    assert crossings <= plain_crossings
    assert kept_inverted(kept, surface) <= plain_inverted
    check_polymesh(kept.mesh)
    assert polymesh_genus(kept.mesh) == polymesh_genus(result.mesh)


def test_a_fold_free_cage_is_kept_as_it_is(monkeypatch):
    import core.quadmesh.decimation.paired_decimation as paired_decimation

    result, surface = paired_shape(sphere, 150)
    fold_free = dataclasses.replace(result, fold_free=True)

    def no_cleanup(*args, **kwargs):
        raise AssertionError("a fold-free cage was cleaned")

    monkeypatch.setattr(paired_decimation, "_cleaned", no_cleanup)
    kept, crossings = _cleaned_or_not(fold_free, surface, 3, 2)
    assert kept is fold_free and crossings == 3


def kept_inverted(result, surface):
    return int(inverted_faces(result.mesh, surface.vertices, surface.faces, surface).sum())
