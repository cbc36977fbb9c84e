# SPDX-License-Identifier: LGPL-2.1-or-later
"""Tolerance-driven refinement: conforming quad-strip splits and the refit loop."""
import numpy as np
import pytest
import trimesh

from core.errors import ParameterError
from core.fitting import fit_base_mesh
from core.fitting.refine import fit_to_tolerance, split_quad_strips
from core.geometry import triangulate
from core.polymesh_checks import check_polymesh
from core.quality import surface_distances
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices
from core.subdivision.sample_cages import cube, grid_sphere, mixed_prism
from core.types import PolyMesh, TriMesh
from polycube_wb.cli import _tolerance


def capsule_and_box_cage():
    mesh = trimesh.creation.capsule(height=2.0, radius=0.5, count=[24, 24])
    target = TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64))
    c = cube(1.0)
    return target, PolyMesh((c.vertices - 0.5) * [1.0, 1.0, 3.0], c.face_vertices, c.face_offsets)


@pytest.mark.parametrize("seeds, extra", [([[0, 0]], 12), ([[0, 1]], 12),
                                          ([[0, 0], [0, 1]], 26)])
def test_strip_splits_are_conforming_quads(seeds, extra):
    cage = grid_sphere(3)  # 54 quads, every strip is a ring of 12
    refined = split_quad_strips(cage, np.array(seeds))
    check_polymesh(refined)  # closed, 2-manifold, consistently oriented
    assert (refined.face_sizes == 4).all()
    # one strip: 12 quads become 24; two strips around the sphere cross twice: 20 quads
    # are cut in two and the 2 shared ones in four
    assert refined.n_faces == cage.n_faces + extra
    n = len(cage.vertices)
    assert np.array_equal(refined.vertices[:n], cage.vertices)
    # every new vertex is the midpoint of an edge of the old cage or a face centre
    V = cage.vertices
    quads = cage.face_vertices.reshape(-1, 4)
    mids = 0.5 * (V[quads] + V[np.roll(quads, -1, axis=1)]).reshape(-1, 3)
    candidates = np.vstack([mids, V[quads].mean(axis=1)])
    gap = np.linalg.norm(refined.vertices[n:, None] - candidates[None], axis=2).min(axis=1)
    assert gap.max() <= 1e-12


def test_refinement_meets_the_tolerance_on_a_capsule():
    target, base = capsule_and_box_cage()
    tolerance = 0.01
    result = fit_to_tolerance(base, target, tolerance, 2000,
                              lambda cage: fit_base_mesh(cage, target, 2, 50, mode="best-fit"))
    assert result.met and result.reason == "tolerance met"
    faces = [r["faces"] for r in result.rounds]
    assert len(faces) >= 2 and faces == sorted(faces) and faces[0] == base.n_faces
    assert result.rounds[0]["max_deviation"] > tolerance >= result.rounds[-1]["max_deviation"]
    check_polymesh(result.mesh)
    # checked independently on the level-3 limit mesh with other samples
    h = build_hierarchy(result.mesh, 3)
    fine = h.meshes[3]
    X = limit_matrices(fine)[0] @ fine.vertices
    d = surface_distances(X, triangulate(fine.face_vertices, fine.face_offsets),
                          target.vertices, target.faces, samples=20000, seed=5)
    assert d["hausdorff"] <= 1.2 * tolerance


def test_refinement_says_why_it_stops_at_the_face_budget():
    target, base = capsule_and_box_cage()
    result = fit_to_tolerance(base, target, 0.002, 60,
                              lambda cage: fit_base_mesh(cage, target, 2, 50, mode="best-fit"))
    assert not result.met
    assert "max_base_faces=60" in result.reason
    assert result.mesh.n_faces <= 60
    assert result.rounds[-1]["max_deviation"] > 0.002


def test_refinement_needs_quads_and_a_positive_tolerance():
    target, base = capsule_and_box_cage()
    with pytest.raises(ParameterError, match="all-quad"):
        fit_to_tolerance(mixed_prism(), target, 0.01, 100, None)
    with pytest.raises(ParameterError, match="positive"):
        fit_to_tolerance(base, target, 0.0, 100, None)


def test_tolerance_option_text():
    assert _tolerance("0.002") == {"tolerance": 0.002}
    assert _tolerance("0.5mm") == {"tolerance_mm": 0.5}
    assert _tolerance("0.05cm") == {"tolerance_mm": pytest.approx(0.5)}
    assert _tolerance(" 0.02in") == {"tolerance_mm": pytest.approx(0.508)}
    with pytest.raises(Exception, match="--tolerance"):
        _tolerance("fine")
