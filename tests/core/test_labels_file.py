# SPDX-License-Identifier: LGPL-2.1-or-later
"""The --labels PLY file: round trip, third-party reading, protection and validity from file."""

import numpy as np
import pytest
import trimesh

from core.errors import InvalidMeshError, ParameterError
from core.segmentation.labeling import face_normals, nearest_direction_labels
from core.segmentation.labels_file import (LABEL_COLOURS, frames_from_label_directions,
                                           read_labels_ply, validity_from_labels_file,
                                           write_labels_ply)
from core.segmentation.validity import check_validity


def rotated_cube(levels=2):
    box = trimesh.creation.box(extents=(2.0, 1.0, 1.5))
    V, F = np.asarray(box.vertices), np.asarray(box.faces)
    for _ in range(levels):
        V, F = trimesh.remesh.subdivide(V, F)
    a = 0.4
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    V = np.asarray(V) @ R.T
    frame = np.broadcast_to(R.T, (len(F), 3, 3)).copy()
    return V, np.asarray(F, dtype=np.int64), frame


def labelled(two_parts=False):
    V, F, frame = rotated_cube()
    labels = nearest_direction_labels(face_normals(V, F), frame)
    parts = np.zeros(len(F), dtype=np.int64)
    if two_parts:
        parts = (V[F].mean(axis=1) @ frame[0, 0] > 0).astype(np.int64)
    return V, F, parts, labels, frame


def test_round_trip_is_exact(tmp_path):
    V, F, parts, labels, frame = labelled(two_parts=True)
    path = str(tmp_path / "labels.ply")
    write_labels_ply(path, V, F, parts, labels, frame)
    d = read_labels_ply(path)
    assert np.array_equal(d["V"], V) and d["V"].dtype == np.float64
    assert np.array_equal(d["F"], F)
    assert np.array_equal(d["part"], parts) and d["part"].dtype == np.int32
    assert np.array_equal(d["label"], labels) and d["label"].dtype == np.int32
    sign = np.where(labels % 2 == 0, 1.0, -1.0)[:, None]
    expect = frame[np.arange(len(F)), labels // 2] * sign
    assert np.allclose(d["direction"], expect, atol=1e-6)
    assert np.allclose(np.linalg.norm(d["direction"], axis=1), 1.0, atol=1e-6)
    assert np.array_equal(d["colour"], LABEL_COLOURS[labels])
    assert len(np.unique(LABEL_COLOURS, axis=0)) == 6
    assert [p.name for p in tmp_path.iterdir()] == ["labels.ply"]  # no temporary file left


def test_trimesh_reads_the_file(tmp_path):
    V, F, parts, labels, frame = labelled()
    path = str(tmp_path / "labels.ply")
    write_labels_ply(path, V, F, parts, labels, frame)
    mesh = trimesh.load(path, process=False)
    assert len(mesh.faces) == len(F)
    assert np.allclose(mesh.vertices, V)
    assert np.array_equal(np.asarray(mesh.visual.face_colors)[:, :3], LABEL_COLOURS[labels])
    with open(path, "rb") as fh:
        head = fh.read(200)
    assert head.startswith(b"ply\nformat binary_little_endian 1.0\n")


def test_refuses_to_overwrite_protected_input_and_bad_arrays(tmp_path):
    V, F, parts, labels, frame = labelled()
    src = tmp_path / "input.ply"
    src.write_bytes(b"original")
    with pytest.raises(ParameterError, match="refusing"):
        write_labels_ply(str(src), V, F, parts, labels, frame, protect=str(src))
    assert src.read_bytes() == b"original"
    bad = labels.copy()
    bad[4] = 6
    with pytest.raises(ParameterError, match="1 values outside 0..5"):
        write_labels_ply(str(tmp_path / "x.ply"), V, F, parts, bad, frame)
    assert not (tmp_path / "x.ply").exists()
    (tmp_path / "junk.ply").write_bytes(b"not a ply")
    with pytest.raises(InvalidMeshError):
        read_labels_ply(str(tmp_path / "junk.ply"))


@pytest.mark.parametrize("two_parts", [False, True])
def test_validity_from_file_matches_validity_in_memory(tmp_path, two_parts):
    V, F, parts, labels, frame = labelled(two_parts)
    c = V[F].mean(axis=1) @ frame[0, 2]
    labels = labels.copy()
    labels[(labels == 2) & (c > 0.5)] = 4  # spoil: +Z faces on the +Y side
    path = str(tmp_path / "labels.ply")
    write_labels_ply(path, V, F, parts, labels, frame)
    from_file = validity_from_labels_file(path)
    direct = check_validity(V, F, parts, labels, frame).report
    for key in ("valid", "charts", "boundaries", "corners"):
        assert from_file[key] == direct[key]
    for key in ("invalid_charts", "invalid_boundaries", "invalid_corners", "turning_points"):
        assert from_file[key]["count"] == direct[key]["count"]


def test_rebuilt_frames_match_uniform_frames():
    V, F, parts, labels, frame = labelled()
    sign = np.where(labels % 2 == 0, 1.0, -1.0)[:, None]
    d = frame[np.arange(len(F)), labels // 2] * sign
    rebuilt = frames_from_label_directions(parts, labels, d)
    assert np.allclose(rebuilt, frame, atol=1e-9)
    assert np.allclose(np.linalg.det(rebuilt), 1.0)
