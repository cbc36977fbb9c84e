# SPDX-License-Identifier: LGPL-2.1-or-later
"""Face-centre limit points and normals of cages (core/quadmesh/orientation.py)."""
from dataclasses import replace

import numpy as np

from core.quadmesh import orientation
from core.quadmesh.orientation import face_centre_limit
from core.subdivision import sample_cages


def fresh_face_centre_limit(cage):
    orientation._LAST_OPERATORS.clear()
    return face_centre_limit(cage)


def test_cages_with_the_faces_of_the_last_one_get_what_a_fresh_evaluation_gives():
    cage = sample_cages.genus3_block()
    rng = np.random.default_rng(2)
    face_centre_limit(cage)
    moved = replace(cage, vertices=cage.vertices + rng.normal(size=cage.vertices.shape) * 0.05)
    points, normals = face_centre_limit(moved)
    expected_points, expected_normals = fresh_face_centre_limit(moved)
    assert np.array_equal(points, expected_points) and np.array_equal(normals, expected_normals)
    # unit normals
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_creases_or_other_faces_are_not_taken_for_the_last_cage():
    cage = sample_cages.cube()
    smooth = face_centre_limit(cage)
    edges = np.array([[cage.face_vertices[0], cage.face_vertices[1]]])
    creased = face_centre_limit(replace(cage, creases=edges))
    assert not np.array_equal(smooth[0], creased[0])
    assert np.array_equal(creased[0], fresh_face_centre_limit(replace(cage, creases=edges))[0])
    other = sample_cages.torus()
    assert np.array_equal(face_centre_limit(other)[0], fresh_face_centre_limit(other)[0])
