# SPDX-License-Identifier: LGPL-2.1-or-later
"""Monotonicity pass (boundary hooks) on a cube and on a dev mesh."""
import numpy as np
import trimesh
from dev_meshes import load_dev_mesh

from core.segmentation.frames import compute_frames
from core.segmentation.labeling import (face_normals, hbecvt_labeling, mean_label_angle,
                                        nearest_direction_labels)
from core.segmentation.monotone import straighten_boundaries
from core.segmentation.repair import repair_labeling
from core.segmentation.validity import check_validity


def test_monotone_labeling_is_left_alone():
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = trimesh.remesh.subdivide(box.vertices, box.faces)
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    frames = np.broadcast_to(np.eye(3), (len(F), 3, 3)).copy()
    labels = nearest_direction_labels(face_normals(V, F), frames)
    out, rep, val = straighten_boundaries(V, F, np.zeros(len(F), dtype=np.int64), labels,
                                          frames)
    assert np.array_equal(out, labels)
    assert rep["turning_points_before"] == rep["turning_points_after"] == 0
    assert rep["moves"] == 0 and rep["checks"] == 1 and val.is_valid


def test_lbracket_hooks_are_straightened_without_losing_validity():
    tm = load_dev_mesh("to_simp_lbracket.stl")
    V, F = tm.vertices, tm.faces
    parts = np.zeros(len(F), dtype=np.int64)
    field = compute_frames(tm, parts)
    labels, _ = hbecvt_labeling(V, F, parts, field.face_frame)
    labels, rep = repair_labeling(V, F, parts, labels, field.face_frame)
    assert rep["valid"]
    before = check_validity(V, F, parts, labels, field.face_frame)
    out, mono, val = straighten_boundaries(V, F, parts, labels, field.face_frame)
    after = check_validity(V, F, parts, out, field.face_frame)
    assert val.report == after.report
    assert mono["turning_points_before"] == len(before.turning_points) > 0
    assert mono["turning_points_after"] == len(after.turning_points)
    # hooks removed: at least a third fewer turning points, validity kept
    assert len(after.turning_points) <= (2 * len(before.turning_points)) // 3
    assert after.is_valid and mono["moves"] >= 1
    tri = V[F]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n = face_normals(V, F)
    assert (mean_label_angle(n, out, field.face_frame, weights=area)
            <= mean_label_angle(n, labels, field.face_frame, weights=area) + 0.5)
    # only faces next to the old turning points' boundaries moved, a small share of the mesh
    assert 0 < (out != labels).sum() < 0.02 * len(F)
