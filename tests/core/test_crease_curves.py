# SPDX-License-Identifier: LGPL-2.1-or-later
"""The crease curves of a cage fitted to the target's feature lines
(core.fitting.crease_curves)."""
import numpy as np
import pytest

from core.fitting.crease_curves import CREASE, fit_crease_curves
from core.fitting.crossings import count_crossings
from core.geometry import shortest_edges_at, triangulate
from core.quality import containment
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices
from core.types import PolyMesh
from dev_meshes import load_dev_mesh
from test_crease_tags import _tagged_cage

RADIUS, HEIGHT, SECTIONS, RIM = 1.0, 0.6, 64, 8


def _cylinder():
    """A closed cylinder of ``SECTIONS`` sides (axis z), its cap centres last: the rims are
    its feature lines (90 degrees), the sides' edges are not (5.6 degrees)."""
    angle = 2 * np.pi * np.arange(SECTIONS) / SECTIONS
    ring = np.column_stack([RADIUS * np.cos(angle), RADIUS * np.sin(angle)])
    V = np.vstack([np.column_stack([ring, np.zeros(SECTIONS)]),
                   np.column_stack([ring, np.full(SECTIONS, HEIGHT)]),
                   [[0, 0, 0], [0, 0, HEIGHT]]])
    k = np.arange(SECTIONS)
    j = (k + 1) % SECTIONS
    top = k + SECTIONS
    faces = np.concatenate([np.column_stack([k, j, j + SECTIONS]),
                            np.column_stack([k, j + SECTIONS, top]),
                            np.column_stack([np.full(SECTIONS, 2 * SECTIONS), j, k]),
                            np.column_stack([np.full(SECTIONS, 2 * SECTIONS + 1), top,
                                             j + SECTIONS])])
    return V, faces.astype(np.int64)


def _octagonal_cage(target_vertices):
    """An octagonal prism on every eighth rim vertex of the cylinder, its two rims
    creased: the cage's crease vertices sit on the target's feature lines."""
    bottom = np.arange(0, SECTIONS, SECTIONS // RIM)
    V = np.vstack([target_vertices[bottom], target_vertices[bottom + SECTIONS]])
    k = np.arange(RIM)
    j = (k + 1) % RIM
    sides = np.column_stack([k, j, j + RIM, k + RIM]).reshape(-1)
    caps = np.concatenate([k[::-1], k + RIM])
    faces = np.concatenate([sides, caps]).astype(np.int64)
    offsets = np.concatenate([np.arange(0, 4 * RIM + 1, 4), [5 * RIM, 6 * RIM]])
    creases = np.concatenate([np.column_stack([k, j]), np.column_stack([k + RIM, j + RIM])])
    return PolyMesh(V, faces, offsets.astype(np.int64), creases.astype(np.int64))


def _limit(cage, levels=2):
    hierarchy = build_hierarchy(cage, levels)
    fine = hierarchy.meshes[levels]
    L, _, _ = limit_matrices(fine)
    return fine, (L @ hierarchy.composite(levels - 1)).tocsr(), triangulate(
        fine.face_vertices, fine.face_offsets)


def _rim_radii(fine, mapping, V):
    """Distances from the axis of the limit points on the cage's crease curves."""
    on_rim = np.unique(np.asarray(fine.creases).reshape(-1))
    X = mapping[on_rim] @ V
    return np.hypot(X[:, 0], X[:, 1])


def test_octagon_rims_follow_the_circle():
    """An octagon of crease vertices on a circle has a limit curve about 10 % inside it
    (0.902 of the radius at the vertices); fitted to the cylinder's rims, every limit point
    of both rims lies within 0.5 % of the radius of the circle."""
    target_vertices, target_faces = _cylinder()
    cage = _octagonal_cage(target_vertices)
    fine, mapping, triangles = _limit(cage)
    before = _rim_radii(fine, mapping, cage.vertices)
    assert before.max() < 0.91 * RADIUS  # 0.902 of the radius at the vertices
    fitted = fit_crease_curves(cage, fine, mapping, triangles, target_vertices, target_faces)
    assert fitted.matched == fitted.creases == 2 * RIM
    assert fitted.held == 0
    after = _rim_radii(fine, mapping, fitted.vertices)
    assert np.abs(after - RADIUS).max() < 0.005 * RADIUS
    # the rims stay in their planes: only the crease polygons' radii changed
    assert np.allclose(fitted.vertices[:, 2], cage.vertices[:, 2], atol=1e-12)


def test_no_feature_lines_no_move():
    """Crease vertices off the target's vertices have no feature chain: nothing moves."""
    target_vertices, target_faces = _cylinder()
    cage = _octagonal_cage(target_vertices)
    shifted = PolyMesh(cage.vertices * 0.9, cage.face_vertices, cage.face_offsets,
                       cage.creases)
    fine, mapping, triangles = _limit(shifted)
    fitted = fit_crease_curves(shifted, fine, mapping, triangles, target_vertices,
                               target_faces)
    assert fitted.matched == 0
    assert np.array_equal(fitted.vertices, shifted.vertices)


@pytest.mark.slow
def test_machined_part_holes_open_up():
    """A machined part's creased cage: its five- and six-vertex hole rims cut into the holes,
    and more than 4 % of the target's volume lies outside the cage's limit solid; with the
    crease curves fitted, under 2 %, nearly every crease edge matched, and no more crossings
    than the cage has."""
    target = load_dev_mesh("featuretype.stl")
    cage = _tagged_cage(target, 300)
    fine, mapping, triangles = _limit(cage)
    before = containment(mapping @ cage.vertices, triangles, target.vertices, target.faces)
    fitted = fit_crease_curves(cage, fine, mapping, triangles, target.vertices, target.faces)
    after = containment(mapping @ fitted.vertices, triangles, target.vertices, target.faces)
    assert fitted.matched > 0.9 * fitted.creases
    assert before["outside_volume_fraction"] > 0.04
    assert after["outside_volume_fraction"] < 0.02
    assert count_crossings(mapping, triangles, fitted.vertices) <= count_crossings(
        mapping, triangles, cage.vertices)


@pytest.mark.slow
def test_pocket_plate_moves_stay_within_reach():
    """A pocketed plate's creased cage: more than 6 % of the target's volume outside its
    limit solid, under 2 % with the crease curves fitted, and no crease vertex moved farther
    than ``CreaseCurveSettings.max_move`` times its shortest crease edge (next to kinks between long and short
    edges the line fit alone would carry vertices far off)."""
    target = load_dev_mesh("octagonal_pocket.stl")
    cage = _tagged_cage(target, 300)
    fine, mapping, triangles = _limit(cage)
    fitted = fit_crease_curves(cage, fine, mapping, triangles, target.vertices, target.faces)
    before = containment(mapping @ cage.vertices, triangles, target.vertices, target.faces)
    after = containment(mapping @ fitted.vertices, triangles, target.vertices, target.faces)
    assert before["outside_volume_fraction"] > 0.06
    assert after["outside_volume_fraction"] < 0.02
    creases = np.sort(np.asarray(cage.creases), axis=1)
    reach = CREASE.max_move * shortest_edges_at(cage.vertices, creases)
    moved = np.linalg.norm(fitted.vertices - cage.vertices, axis=1)
    assert (moved <= reach * (1 + 1e-9)).all()
    assert (moved > 0.99 * reach).sum() > 10  # the reach is what stops them


def test_feature_chains_need_feature_lines():
    """A smooth target (a sphere, no edge above 60 degrees) has no feature network: no pair
    of its vertices gets a chain, nor does a pair with an unmatched end (-1); on the
    cylinder the chain between two rim vertices an eighth of the circle apart runs along the
    rim (9 vertices)."""
    import trimesh

    from core.fitting.crease_curves import _FeatureGraph

    sphere = trimesh.creation.icosphere(subdivisions=2)
    graph = _FeatureGraph(np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64))
    assert graph.paths(np.array([[0, 1], [2, 3]]), set()) == [None, None]
    target_vertices, target_faces = _cylinder()
    graph = _FeatureGraph(target_vertices, target_faces)
    step = SECTIONS // RIM
    found = graph.paths(np.array([[0, step], [-1, step], [0, SECTIONS]]), {0, step})
    assert np.array_equal(found[0], np.arange(step + 1))
    assert found[1] is None
    assert found[2] is None  # the rims are not joined by feature edges


@pytest.mark.slow
def test_the_inside_fit_of_a_creased_cage_starts_from_its_fitted_crease_curves():
    """octagonal_pocket's creased cage: the inside fit starts from the cage with its crease
    curves fitted (``CREASED_START``), no least-squares rounds and no target samples, so two
    seeds give the same fit; it ends clean, with little of the volume outside and closer to
    the target than the cage."""
    from core.fitting import fit_base_mesh
    from core.fitting.fit import CREASED_START

    target = load_dev_mesh("octagonal_pocket.stl")
    cage = _tagged_cage(target, 300)
    fitted, info = fit_base_mesh(cage, target, mode="inside", seed=0)
    assert info.start.startswith(CREASED_START) and info.rounds == 0
    assert info.self_intersections == 0
    assert info.figures.outside_volume_fraction <= 0.01
    assert info.figures.distances.mean_distance <= 0.85 * info.figures.initial.mean_distance
    again, _ = fit_base_mesh(cage, target, mode="inside", seed=1)
    np.testing.assert_array_equal(again.vertices, fitted.vertices)
