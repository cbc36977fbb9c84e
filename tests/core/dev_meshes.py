# SPDX-License-Identifier: LGPL-2.1-or-later
"""The shared dev meshes (``../shared/data/meshes``) for tests; a missing mesh skips the test."""
import os

import numpy as np
import pytest
import trimesh

from core.types import TriMesh

MESHES = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "meshes")


def load_dev_mesh(name):
    """TriMesh of dev mesh ``name`` (file name with extension), loaded with trimesh's merging;
    skips the calling test when the file is not there."""
    path = os.path.join(MESHES, name)
    if not os.path.exists(path):
        pytest.skip(f"dev mesh {name} not available")
    mesh = trimesh.load(path, process=True)
    return TriMesh(np.asarray(mesh.vertices, dtype=np.float64),
                   np.asarray(mesh.faces, dtype=np.int64))
