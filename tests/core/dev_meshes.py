# SPDX-License-Identifier: LGPL-2.1-or-later
"""The shared dev meshes (``../shared/data/meshes``) for tests; a missing mesh skips the test.

Setting ``POLYCUBE_TEST_JITTER`` to an integer seed moves every vertex of every dev mesh by
about 1e-12 of the mesh's diagonal (a seeded random offset): the rounding of another machine.
A test that fails under some seed asserts a figure that rounding decides, not a property.
"""
import os

import numpy as np
import pytest
import trimesh

from core.types import TriMesh

JITTER_VARIABLE = "POLYCUBE_TEST_JITTER"
JITTER_SIZE = 1e-12  # relative to the diagonal
MESHES = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "meshes")


def load_dev_mesh(name):
    """TriMesh of dev mesh ``name`` (file name with extension), loaded with trimesh's merging;
    skips the calling test when the file is not there."""
    path = os.path.join(MESHES, name)
    if not os.path.exists(path):
        pytest.skip(f"dev mesh {name} not available")
    mesh = trimesh.load(path, process=True)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    return TriMesh(rounding_jitter(vertices), np.asarray(mesh.faces, dtype=np.int64))


def rounding_jitter(vertices):
    """(n, 3) float64 ``vertices`` moved by about 1e-12 of their diagonal when
    ``POLYCUBE_TEST_JITTER`` holds a seed, else unchanged."""
    seed = os.environ.get(JITTER_VARIABLE)
    if not seed:
        return vertices
    diagonal = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    offset = np.random.default_rng(int(seed)).uniform(-1.0, 1.0, vertices.shape)
    return vertices + JITTER_SIZE * diagonal * offset
