# SPDX-License-Identifier: LGPL-2.1-or-later
"""Limit-surface self-crossings counted again only where vertices moved
(core.quadmesh.crossing_count): the same counts as the full check, on a real cage."""
from dataclasses import replace

import numpy as np
import pytest

from core.quadmesh.crossing_count import LimitCrossingCount
from core.quadmesh.decimation.paired_decimation import paired_decimation_base_mesh
from core.subdivision.limit_crossings import count_limit_self_intersections
from core.target_surface import TargetSurface
from core.types import PolyMesh
from dev_meshes import load_dev_mesh


def _counts_of_moves(count, cage, moves, rng, scale):
    """``count`` (a LimitCrossingCount) of ``cage`` with each number in ``moves`` of random
    vertices moved by normal steps of ``scale`` (model units); each checked against the full
    count. Returns the list of counts."""
    totals = []
    for moved in moves:
        vertices = cage.vertices.copy()
        chosen = rng.choice(len(vertices), moved, replace=False)
        vertices[chosen] += rng.normal(scale=scale, size=(moved, 3))
        trial = replace(cage, vertices=vertices)
        totals.append(count(trial))
        assert totals[-1] == count_limit_self_intersections(trial, 2)
    return totals


@pytest.mark.slow
def test_the_crossing_count_of_moved_vertices_is_the_full_count():
    target = load_dev_mesh("gripper_domain.stl")
    surface = TargetSurface(target.vertices, target.faces)
    cage = paired_decimation_base_mesh(target.vertices, target.faces, 300, surface).mesh
    count = LimitCrossingCount(cage)
    assert count.crossings == count_limit_self_intersections(cage, 2)
    rng = np.random.default_rng(7)
    totals = _counts_of_moves(count, cage, (3, 10, 30), rng, 0.02 * surface.diagonal)
    assert max(totals) > count.crossings  # the moves made crossings: the test can tell
    # other faces: counted in full
    faces = cage.faces()
    quad = next(i for i, face in enumerate(faces) if len(face) == 4)
    split = PolyMesh.from_faces(cage.vertices, faces[:quad] + [faces[quad][[0, 1, 2]],
                                                               faces[quad][[0, 2, 3]]]
                                + faces[quad + 1:])
    assert count(split) == count_limit_self_intersections(split, 2)
    # moves on the split cage (a split kept, then corner moves tried): its count is kept and
    # the moves counted against it, the same as a full count; the first cage's still holds
    split_totals = _counts_of_moves(count, split, (3, 30), rng, 0.02 * surface.diagonal)
    assert max(split_totals) > count(split)
    assert count(replace(cage, vertices=cage.vertices.copy())) == count.crossings
