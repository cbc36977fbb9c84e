# SPDX-License-Identifier: LGPL-2.1-or-later
"""Compile every cached compiled function of the spatial queries, the labeling's charts and
validity, the fold-free decimation, the fit's volume response and the limit evaluation now
(``make setup``).

numba compiles a function the first time it is called with new argument types, several
seconds for all of them here, and keeps the result in its cache (:mod:`core.compiled`); run once at
set-up, the first reconstruction on a machine does not spend its first seconds on it.
"""
import time

import numpy as np

from core.box_tree import box_pairs, face_boxes
from core.fitting.responses import volume
from core.quadmesh.decimation.fold_free_decimation import FoldFreeDecimation
from core.segmentation.validity import check_validity
from core.self_intersection import find_self_intersections
from core.subdivision.limit import LimitEvaluator
from core.target_surface import TargetSurface
from core.types import PolyMesh


def compile_now():
    """Compile (or load from numba's cache) every compiled function of the spatial queries
    with the argument types the reconstruction passes, on a small cube; returns the seconds
    taken."""
    started = time.perf_counter()
    corners = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    surface = TargetSurface(corners, faces, split=True)
    surface.closest(corners * 1.1 - 0.05)
    surface.first_exit(corners, np.full((8, 3), 0.5) - corners, 2.0)
    marked = np.ones(len(faces), dtype=bool)
    candidates = box_pairs(*face_boxes(corners[faces]), marked)
    find_self_intersections(corners, faces)
    find_self_intersections(corners, faces, among=marked, candidates=candidates)
    # each face labelled by its normal's axis and sign: the charts, boundaries and turning
    # points of a valid polycube labeling
    normals = np.cross(corners[faces[:, 1]] - corners[faces[:, 0]],
                       corners[faces[:, 2]] - corners[faces[:, 0]])
    axis = np.abs(normals).argmax(axis=1)
    labels = 2 * axis + (normals[np.arange(len(faces)), axis] < 0)
    check_validity(corners, faces, np.zeros(len(faces), dtype=np.int64), labels.astype(np.int64),
                   np.tile(np.eye(3), (len(faces), 1, 1)))
    FoldFreeDecimation(corners, faces).triangles(8)
    volume(corners, faces)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    # regular quads and the sub-quads around the cube's valence-3 corners
    LimitEvaluator(PolyMesh.from_faces(corners, quads)).evaluate(
        np.arange(6), np.full(6, 0.3), np.full(6, 0.6))
    return time.perf_counter() - started
