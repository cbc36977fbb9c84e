# SPDX-License-Identifier: LGPL-2.1-or-later
"""Which cage edges are tagged as sharp creases (core.quadmesh.creases)."""
import numpy as np
import pytest
import trimesh

from core.quadmesh.creases import closed_network
from core.quadmesh.decimation.feature_decimation import FeatureDecimation
from core.quadmesh.decimation.paired_decimation import _paired_mesh, paired_decimation_base_mesh
from core.subdivision import sample_cages as sc
from core.subdivision.catmull_clark import mesh_topology
from core.target_surface import TargetSurface
from core.types import PolyMesh
from dev_meshes import load_dev_mesh


def _fine_box():
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = trimesh.remesh.subdivide_to_size(box.vertices + 0.5, box.faces, 0.1)
    return np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)


def test_closed_network_cuts_back_dangling_chains():
    loop = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    tail = np.array([[2, 4], [4, 5]])
    kept = closed_network(np.concatenate([loop, tail]), 6)
    assert np.array_equal(kept, loop)
    assert closed_network(tail, 6) is None


def _tagged_cage(target, budget):
    """The paired decimation's cage of ``budget`` faces with crease tags (its creased ladder's
    first round, before its inverted faces are unshrunk)."""
    surface = TargetSurface(target.vertices, target.faces)
    decimation = FeatureDecimation(target.vertices, target.faces, surface)
    return _paired_mesh(decimation, 2 * budget, surface).mesh


@pytest.mark.slow
def test_machined_part_cage_has_crease_network_and_simp_cage_none():
    featuretype = load_dev_mesh("featuretype.stl")
    cage = _tagged_cage(featuretype, 300)
    # many crease edges; no vertex with a single crease edge
    assert cage.n_creases > 250
    count = np.bincount(cage.creases.reshape(-1), minlength=len(cage.vertices))
    assert not (count == 1).any()
    topo = mesh_topology(cage.face_vertices, cage.face_offsets, len(cage.vertices))
    assert (topo.edge_index(cage.creases[:, 0], cage.creases[:, 1]) >= 0).all()
    simp = load_dev_mesh("to_simp_pylon.stl")
    assert _tagged_cage(simp, 300).creases is None
    # without tags (the default) none
    assert paired_decimation_base_mesh(featuretype.vertices, featuretype.faces,
                                       300).mesh.creases is None


def test_the_fit_and_the_strip_split_keep_the_creases():
    """A refined cube cage creased along the cube's edges, fitted to the box itself: the
    fitted cage keeps its tags and its limit surface stays on the box (it is the box); the
    quad-strip split of the tolerance refinement makes both halves of a cut crease edge
    creases."""
    from core.fitting import fit_base_mesh
    from core.fitting.refine import split_quad_strips
    from core.subdivision.catmull_clark import subdivide
    from core.types import TriMesh

    cube = sc.cube()
    topo = mesh_topology(cube.face_vertices, cube.face_offsets, 8)
    cage, _ = subdivide(PolyMesh(cube.vertices, cube.face_vertices, cube.face_offsets,
                                 topo.edges))
    V, F = _fine_box()
    fitted, info = fit_base_mesh(cage, TriMesh(V, F), levels=2, iterations=3)
    assert np.array_equal(fitted.creases, cage.creases)
    assert info.figures.initial.mean_distance < 1e-9
    split = split_quad_strips(cage, np.array([[0, 0]]))
    assert split.n_creases == cage.n_creases + 4  # a closed strip round the cube: 4 edges cut
    fine_topo = mesh_topology(split.face_vertices, split.face_offsets, len(split.vertices))
    assert (fine_topo.edge_index(split.creases[:, 0], split.creases[:, 1]) >= 0).all()
    assert (np.bincount(split.creases.reshape(-1)) != 1).all()
