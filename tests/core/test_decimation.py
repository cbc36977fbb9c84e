# SPDX-License-Identifier: LGPL-2.1-or-later
"""Decimations of one target (core.quadmesh.decimation.decimation): from the coarse decimation up to
its size (which folds small machined features), from the target above it (which does not); cached;
genus kept."""

import numpy as np
import pytest

from core.mesh_topology import genus_of
from core.quadmesh.decimation.decimation import REDUCE_ABOVE, SOURCE_TRIANGLES, Decimation
from core.self_intersection import find_self_intersections
from dev_meshes import load_dev_mesh


def test_decimating_from_the_target_keeps_small_machined_features_unfolded():
    target = load_dev_mesh("featuretype.stl")  # counterbores, notches, genus 9
    decimation = Decimation(target.vertices, target.faces)
    vertices, faces = decimation.triangles(450)
    assert len(faces) <= 450
    assert genus_of(len(vertices), faces, 1) == 9
    # no intersecting triangle pair (QSlim of a coarse QSlim result folds the stepped holes)
    assert len(find_self_intersections(vertices, faces)) == 0
    from_coarse = Decimation(target.vertices, target.faces, coarse_triangles=600)
    again_v, again_f = from_coarse.triangles(450)
    assert len(again_f) <= 450
    assert len(find_self_intersections(again_v, again_f)) >= 20
    # above the coarse decimation's size, from the target again
    assert len(find_self_intersections(*from_coarse.triangles(900))) == 0
    # the same count gives the same arrays
    assert decimation.triangles(450)[1] is faces


@pytest.mark.slow
def test_large_targets_start_from_one_fine_decimation():
    target = load_dev_mesh("ge_bracket_domain.stl")  # 76,652 triangles, genus 5
    assert len(target.faces) > SOURCE_TRIANGLES
    decimation = Decimation(target.vertices, target.faces, coarse_triangles=600)
    vertices, faces = decimation.triangles(600)
    assert 500 <= len(faces) <= 600
    assert genus_of(len(vertices), faces, 1) == 5
    fine_v, fine_f = decimation.fine_source
    assert 0.9 * SOURCE_TRIANGLES <= len(fine_f) <= SOURCE_TRIANGLES
    vertices, faces = decimation.triangles(1200)
    assert 1000 <= len(faces) <= 1200
    assert genus_of(len(vertices), faces, 1) == 5
    # more triangles than the target has: the target itself
    assert decimation.triangles(10 ** 6)[1] is not fine_f
    assert len(decimation.triangles(10 ** 6)[1]) == len(target.faces)


@pytest.mark.slow
def test_the_coarse_decimation_of_a_very_large_target_starts_from_a_reduction(monkeypatch):
    import igl

    from test_paired_decimation import torus

    reductions = []
    decimate = igl.decimate

    def spy(vertices, faces, count):
        reductions.append((len(faces), count))
        return decimate(vertices, faces, count)

    monkeypatch.setattr(igl, "decimate", spy)
    vertices, faces = torus(sections=320, rings=200)  # 128,000 triangles, genus 1
    assert len(faces) > REDUCE_ABOVE
    decimation = Decimation(vertices, faces, coarse_triangles=750)
    assert reductions == [(len(faces), SOURCE_TRIANGLES)]
    coarse_v, coarse_f = decimation.triangles(600)
    assert 500 <= len(coarse_f) <= 600
    assert genus_of(len(coarse_v), coarse_f, 1) == 1
    # near the torus (major radius 3, minor radius 1), though not on it (QSlim places the
    # coarse vertices off the surface)
    ring = np.hypot(coarse_v[:, 0], coarse_v[:, 1]) - 3.0
    assert np.abs(np.hypot(ring, coarse_v[:, 2]) - 1.0).max() < 0.06
    # larger budgets from QSlim's fine decimation of the target, not from the reduction
    fine_v, fine_f = decimation.fine_source
    assert 0.9 * SOURCE_TRIANGLES <= len(fine_f) <= SOURCE_TRIANGLES
    assert len(reductions) == 1
    assert 1000 <= len(decimation.triangles(1200)[1]) <= 1200
    # a smaller target is not reduced
    Decimation(*torus(sections=128, rings=64), coarse_triangles=750)
    assert len(reductions) == 1
