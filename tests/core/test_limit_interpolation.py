# SPDX-License-Identifier: LGPL-2.1-or-later
"""Inverted faces of paired-decimation cages unshrunk (core.quadmesh.limit_interpolation): on
the thin plate of ``tray_bottom``, whose rim's limit surface is pulled past the plate's middle."""
import numpy as np
import pytest

from core.mesh_topology import polymesh_genus
from core.polymesh_checks import check_polymesh
from core.quadmesh.limit_interpolation import (MOVE_SHARE, shortest_edges, unshrink_inverted,
                                               vertex_limit_positions)
from core.quadmesh.orientation import inverted_faces
from core.quadmesh.decimation.paired_decimation import limit_flaws, paired_decimation_base_mesh
from core.subdivision.limit_crossings import count_limit_self_intersections
from dev_meshes import load_dev_mesh


@pytest.fixture(scope="module")
def tray():
    """The tray's target surface and its paired cage of one budget (300) as the pairing
    leaves it (no valence cleanup), not unshrunk."""
    from core.quadmesh.decimation.decimation import Decimation
    from core.quadmesh.decimation.paired_decimation import _paired_mesh
    from core.target_surface import TargetSurface

    target = load_dev_mesh("tray_bottom.stl")  # a 3.2 mm plate, 356 mm square, genus 23
    surface = TargetSurface(target.vertices, target.faces)
    decimation = Decimation(target.vertices, target.faces, coarse_triangles=600)
    return surface, _paired_mesh(decimation, 600, surface).mesh


def test_the_rim_of_a_thin_plate_is_unshrunk_without_new_crossings(tray):
    surface, cage = tray
    crossings, inverted = limit_flaws(cage, surface)
    assert inverted > 0  # the rim's limit surface is pulled past the plate's middle
    moved, moved_crossings, moved_inverted, count = unshrink_inverted(
        cage, surface, crossings, inverted, lambda mesh: count_limit_self_intersections(mesh, 2))
    assert moved_inverted < inverted and moved_crossings <= crossings
    assert int(inverted_faces(moved, surface.vertices, surface.faces, surface).sum()) \
        == moved_inverted
    assert count_limit_self_intersections(moved, 2) == moved_crossings
    # the same faces; only the vertices of inverted faces moved, each by at most its bound
    assert np.array_equal(moved.face_vertices, cage.face_vertices)
    assert np.array_equal(moved.face_offsets, cage.face_offsets)
    shift = np.linalg.norm(moved.vertices - cage.vertices, axis=1)
    assert (shift > 0).sum() == count and 0 < count < len(cage.vertices) / 4  # local moves
    assert np.all(shift <= MOVE_SHARE * shortest_edges(cage) * (1 + 1e-9))
    check_polymesh(moved)
    assert polymesh_genus(moved) == 23


def test_the_moves_bring_the_limit_points_to_the_original_vertices(tray):
    surface, cage = tray
    crossings, inverted = limit_flaws(cage, surface)
    moved, *_ = unshrink_inverted(cage, surface, crossings, inverted,
                                  lambda mesh: count_limit_self_intersections(mesh, 2))
    shifted = np.linalg.norm(moved.vertices - cage.vertices, axis=1) > 0
    anchors = cage.vertices[shifted]  # on the target, on the right side of the plate
    before = np.linalg.norm(vertex_limit_positions(cage)[shifted] - anchors, axis=1)
    after = np.linalg.norm(vertex_limit_positions(moved)[shifted] - anchors, axis=1)
    # the moves are bounded by the rim's 3.2 mm edges, so the limit points come closer only
    # by part of the way, and one may move away where its neighbours' moves pull it
    assert after.mean() < 0.9 * before.mean()
    assert np.median(after - before) < 0


def test_the_budget_ladder_keeps_the_unshrunk_cage_of_the_thin_plate(tray):
    surface, _ = tray
    result = paired_decimation_base_mesh(surface.vertices, surface.faces, 300, surface, 375)
    # the ladder moves the rim's vertices and keeps its least flawed cage
    flaws = [r["limit_crossings"] + r["inverted_faces"] for r in result.rounds]
    assert any(r["moved_vertices"] > 0 for r in result.rounds)
    assert sum(limit_flaws(result.mesh, surface)) == min(flaws)
    assert abs(result.mesh.n_faces - 300) <= 0.25 * 300
    assert result.quads >= 0.9 * result.mesh.n_faces
