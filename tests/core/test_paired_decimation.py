# SPDX-License-Identifier: LGPL-2.1-or-later
"""Paired-decimation base mesh (core.quadmesh.decimation.paired_decimation): closed, the target's
genus, quads, on budget, near the target; on a torus built here and on a real SIMP result."""
import os

import numpy as np
import pytest

from core.geometry import triangle_mesh_volume
from core.polymesh_checks import check_polymesh
from core.mesh_topology import polymesh_genus
from core.quadmesh.decimation.paired_decimation import (MIN_WEIGHT, VALENCE_FACE_SLACK,
                                                        _candidate_quads,
                                                        paired_decimation_base_mesh)
from core.quality import point_surface_distance
from dev_meshes import MESHES, load_dev_mesh


def torus(major=3.0, minor=1.0, sections=64, rings=32):
    """Closed outward triangle torus around z (genus 1)."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, sections, endpoint=False),
                       np.linspace(0, 2 * np.pi, rings, endpoint=False), indexing="ij")
    V = np.stack([(major + minor * np.cos(v)) * np.cos(u), (major + minor * np.cos(v)) * np.sin(u),
                  minor * np.sin(v)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(sections), np.arange(rings), indexing="ij")
    a = i * rings + j
    b = ((i + 1) % sections) * rings + j
    c = ((i + 1) % sections) * rings + (j + 1) % rings
    d = i * rings + (j + 1) % rings
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                        np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F


def polymesh_volume(mesh):
    """Enclosed volume of a polygon mesh, its faces fanned from their first corner."""
    tris = []
    for f in range(mesh.n_faces):
        corners = mesh.face_vertices[mesh.face_offsets[f]:mesh.face_offsets[f + 1]]
        tris += [[corners[0], corners[k], corners[k + 1]] for k in range(1, len(corners) - 1)]
    return triangle_mesh_volume(mesh.vertices, np.asarray(tris))


def test_two_right_triangles_make_a_perfect_quad_and_a_fold_the_worst():
    # a unit square split along its diagonal, closed by a second square below it (a flat,
    # degenerate "pillow" is enough for the weights)
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]])
    pairs, quads, weight = _candidate_quads(V, F)
    flat = [k for k, (a, b) in enumerate(pairs.tolist()) if {a, b} in ({0, 1}, {2, 3})]
    assert np.allclose(weight[flat], 1.0 + MIN_WEIGHT)
    # the pairs across the square's border fold by 180 degrees
    folded = [k for k in range(len(pairs)) if k not in flat]
    assert np.allclose(weight[folded], MIN_WEIGHT)
    for quad in quads[flat]:
        assert sorted(quad.tolist()) == [0, 1, 2, 3]


@pytest.mark.parametrize("budget", [100, 300])
def test_torus_gives_a_closed_quad_mesh_of_genus_one_on_budget(budget):
    V, F = torus()
    result = paired_decimation_base_mesh(V, F, budget)
    mesh = result.mesh
    check_polymesh(mesh)  # closed, 2-manifold, consistently oriented, no degenerate face
    assert polymesh_genus(mesh) == 1
    assert result.quads + result.triangles == mesh.n_faces
    assert result.quads >= 0.9 * mesh.n_faces
    assert abs(mesh.n_faces - budget) <= 0.25 * budget
    # outward like the target: positive volume; its vertices lie on the target, so it is an
    # inscribed polyhedron: less volume, but at least 75% of the target's at 100 faces
    ratio = polymesh_volume(mesh) / triangle_mesh_volume(V, F)
    assert 0.75 <= ratio <= 1.0
    # the vertices are moved onto the target
    assert point_surface_distance(mesh.vertices, V, F).max() < 1e-9 * 8.0


def test_real_simp_result_with_handles():
    target = load_dev_mesh("to_simp_pylon.stl")
    result = paired_decimation_base_mesh(target.vertices, target.faces, 300)
    check_polymesh(result.mesh)
    assert polymesh_genus(result.mesh) == 2
    assert result.quads >= 0.9 * result.mesh.n_faces
    assert abs(result.mesh.n_faces - 300) <= 75


def test_augmenting_path_completes_a_greedy_matching():
    from core.quadmesh.decimation.paired_decimation import _match_pairs

    # a chain 0-1-2-3 whose heaviest pair (1, 2) would strand 0 and 3
    pairs = np.array([[0, 1], [1, 2], [2, 3]])
    chosen = _match_pairs(4, pairs, np.array([1.0, 2.0, 1.0]))
    assert chosen.tolist() == [True, False, True]
    # a triangle of faces plus a pendant: an odd cycle; three of the four still pair up
    pairs = np.array([[0, 1], [1, 2], [2, 0], [2, 3]])
    chosen = _match_pairs(4, pairs, np.array([3.0, 1.0, 1.0, 0.5]))
    assert chosen.sum() == 2
    assert np.bincount(pairs[chosen].ravel(), minlength=4).max() == 1


@pytest.mark.slow
def test_larger_budgets_are_tried_while_the_limit_surface_of_thin_struts_is_flawed():
    from core.quadmesh.decimation.paired_decimation import limit_flaws
    from core.target_surface import TargetSurface

    target = load_dev_mesh("to_simp_torsion_arm.stl")
    surface = TargetSurface(target.vertices, target.faces)
    result = paired_decimation_base_mesh(target.vertices, target.faces, 300, surface, 375)
    flaws = [r["limit_crossings"] + r["inverted_faces"] for r in result.rounds]
    assert len(result.rounds) >= 2 and flaws[0] > 0
    assert min(flaws) < flaws[0] / 2
    chosen = result.rounds[int(np.argmin(flaws))]
    assert chosen["faces"] <= 1.02 * 375
    # the cage kept, its valences cleaned up: a few more faces (vertex splits), no more flaws
    assert chosen["faces"] <= result.mesh.n_faces <= (1 + VALENCE_FACE_SLACK) * chosen["faces"]
    crossings, inverted = limit_flaws(result.mesh, surface)
    assert crossings == result.limit_crossings <= chosen["limit_crossings"]
    assert inverted <= chosen["inverted_faces"]
    check_polymesh(result.mesh)
    assert polymesh_genus(result.mesh) == 18


@pytest.mark.slow
def test_budgets_beyond_the_rule_are_tried_while_every_cage_crosses_itself():
    from core.quadmesh import build_base_mesh
    from core.subdivision.limit_crossings import count_limit_self_intersections
    from core.target_surface import TargetSurface

    target = load_dev_mesh("to_simp_torsion_arm.stl")  # genus 18, thin struts
    surface = TargetSurface(target.vertices, target.faces)
    result = paired_decimation_base_mesh(target.vertices, target.faces, 300, surface, 375, 2500)
    within = [r for r in result.rounds if r["faces"] <= 1.02 * 375]
    # every cage within the rule crosses itself (those of the budget decimated again and
    # tightened around the crossings too); a larger one beyond it does not
    assert len(within) >= 2 and all(r["limit_crossings"] > 0 for r in within)
    assert any(r["tightened"] for r in result.rounds if "tightened" in r)
    assert result.mesh.n_faces > 375
    assert any(r["faces"] <= result.mesh.n_faces <= (1 + VALENCE_FACE_SLACK) * r["faces"]
               and r["limit_crossings"] == 0 for r in result.rounds)
    assert count_limit_self_intersections(result.mesh, 2) == 0
    assert result.mesh.n_faces <= 1.02 * 3 * 300
    assert polymesh_genus(result.mesh) == 18
    # the stage reports the budget missed and why
    m = len(target.faces)
    mesh, info = build_base_mesh(target, np.zeros(m, int), np.zeros(m, int),
                                 np.tile(np.eye(3), (m, 1, 1)), np.eye(3)[None],
                                 method="decimation")
    assert mesh.n_faces == result.mesh.n_faces
    assert info["within_budget"] is False
    assert "cross themselves" in info["minimum_reason"]
    assert info["budget_rounds"] == list(result.rounds)


@pytest.mark.slow
def test_budgets_beyond_the_rule_stop_where_more_faces_do_not_unfold_the_limit_surface():
    from core.pipeline import reconstruct
    from core.quadmesh.decimation.paired_decimation import OVER_BUDGET_MISSES
    from core.subdivision.limit_crossings import count_limit_self_intersections
    from core.target_surface import TargetSurface

    target = load_dev_mesh("featuretype.stl")  # machined: counterbores, steps, genus 9
    surface = TargetSurface(target.vertices, target.faces)
    result = paired_decimation_base_mesh(target.vertices, target.faces, 300, surface, 375, 2500)
    # the QSlim ladder's rounds (not those of the budget decimated again and tightened)
    smooth = [r for r in result.rounds if "crease_edges" not in r and "tightened" not in r]
    creased = [r for r in result.rounds if "crease_edges" in r]
    flaws = [r["limit_crossings"] + r["inverted_faces"] for r in smooth]
    within = sum(r["faces"] <= 1.02 * 375 for r in smooth)
    # the flaws grow beyond the rule, so the ladder ends after OVER_BUDGET_MISSES budgets
    assert within == 4 and len(smooth) == within + OVER_BUDGET_MISSES
    assert all(r["limit_crossings"] > 0 for r in smooth)
    assert min(flaws[within:]) >= min(flaws[:within])
    # every smooth cage crosses itself: the ladder ran again on feature-preserving
    # decimations with crease tags, whose first cage is clean
    assert creased and all("crease_edges" not in r for r in result.rounds[:-len(creased)])
    assert len(creased) == 1 and creased[0]["crease_edges"] > 250
    assert result.mesh.n_creases == creased[0]["crease_edges"]
    assert result.limit_crossings == count_limit_self_intersections(result.mesh, 2) == 0
    assert result.mesh.n_faces == creased[0]["faces"] <= 375
    # the stage reports the creased cage it kept
    path = os.path.join(MESHES, "featuretype.stl")
    report = reconstruct(path, {"base_mesh_method": "decimation"}, stop_after="basemesh").report
    assert report["base_mesh"]["limit_crossings"] == 0
    assert report["base_mesh"]["crossing_reason"] is None
    assert report["base_mesh"]["crease_edges"] == result.mesh.n_creases
    assert report["base_mesh"]["within_budget"]
