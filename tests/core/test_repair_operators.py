# SPDX-License-Identifier: LGPL-2.1-or-later
"""The repair's operators one by one, on a subdivided unit cube labelled by hand.

Each operator returns a typed ``Relabel`` (new labels, items worked on), never changes its
input labels, and fixes the kind of invalid item it is for (judged by ``check_validity``).
"""
import numpy as np
import trimesh

from core.segmentation.charts import OPPOSITE, build_topology
from core.segmentation.labeling import face_normals, label_cost, nearest_direction_labels
from core.segmentation.repair_operators import (Relabel, Trial, corner_growths,
                                                insert_one_axis_charts, merge_charts,
                                                one_axis_corners, split_opposite_boundaries)
from core.segmentation.validity import check_validity


def labelled_cube(levels=3):
    """(V, F, parts, frames, nearest-direction labels) of a subdivided unit cube in [0, 1]^3."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = np.asarray(box.vertices) + 0.5, np.asarray(box.faces)
    for _ in range(levels):
        V, F = trimesh.remesh.subdivide(V, F)
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    frames = np.broadcast_to(np.eye(3), (len(F), 3, 3)).copy()
    labels = nearest_direction_labels(face_normals(V, F), frames).astype(np.int64)
    return V, F, np.zeros(len(F), dtype=np.int64), frames, labels


def test_strip_insertion_separates_opposite_labels_by_a_third_axis():
    V, F, parts, frames, labels = labelled_cube()
    corner = V[F]
    strip = ((np.abs(corner[:, :, 0] - 1.0) < 1e-9).all(axis=1)
             & (corner[:, :, 2] < 0.26).all(axis=1))
    labels[strip] = 1  # -X strip on the +X side: an opposite-label boundary
    topology = build_topology(F, len(V))
    val = check_validity(V, F, parts, labels, frames, topology)
    assert (val.boundary_reason == 1).sum() == 1
    given = labels.copy()
    cost = label_cost(face_normals(V, F), frames)
    done = split_opposite_boundaries(F, topology, val, labels, cost)
    assert isinstance(done, Relabel) and done.items == 1
    assert np.array_equal(labels, given), "the input labels are not modified"
    changed = np.flatnonzero(done.labels != labels)
    assert len(changed) and (done.labels[changed] // 2 != 0).all(), "a label of another axis"
    neighbours = topology.neighbours
    assert not (done.labels[neighbours] == OPPOSITE[done.labels][:, None]).any()
    after = check_validity(V, F, parts, done.labels, frames, topology)
    assert not (after.boundary_reason == 1).any()


def test_merge_takes_a_chart_into_the_neighbouring_label_that_fits_it_best():
    V, F, parts, frames, labels = labelled_cube()
    corner = V[F]
    island = ((corner[:, :, 2] > 0.99).all(axis=1) & (corner[:, :, 0] > 0.74).all(axis=1)
              & (np.abs(corner[:, :, 1] - 0.5) < 0.26).all(axis=1))
    labels[island] = 3  # -Y on the top, at its +X edge: a chart with two boundaries, +Z and +X
    topology = build_topology(F, len(V))
    val = check_validity(V, F, parts, labels, frames, topology)
    assert val.invalid_chart.sum() == 1
    given = labels.copy()
    done = merge_charts(val, labels, label_cost(face_normals(V, F), frames), val.invalid_chart)
    assert done.items == 1 and np.array_equal(labels, given)
    assert (done.labels[island] == 4).all(), "+Z (the faces' normal), not +X"
    assert np.array_equal(done.labels[~island], labels[~island])
    assert check_validity(V, F, parts, done.labels, frames, topology).is_valid


def test_a_chart_of_the_common_axis_goes_in_at_a_one_axis_corner():
    """+X, +Y, -X, -Y quadrants in the middle of the top: their four boundaries meet at the
    top's centre and all run along Z."""
    V, F, parts, frames, labels = labelled_cube(4)
    c = V[F].mean(axis=1)
    saddle = (c[:, 2] > 0.99) & (np.abs(c[:, :2] - 0.5).max(axis=1) < 0.2)
    east, north = c[:, 0] > 0.5, c[:, 1] > 0.5
    labels[saddle] = np.where(east, np.where(north, 0, 3), np.where(north, 2, 1))[saddle]
    topology = build_topology(F, len(V))
    val = check_validity(V, F, parts, labels, frames, topology)
    found = one_axis_corners(topology, val)
    assert len(found.vertices) == 1 and found.axes.tolist() == [2]
    assert np.allclose(V[found.vertices[0]], (0.5, 0.5, 1.0), atol=1e-9)
    given = labels.copy()
    done = insert_one_axis_charts(F, topology, labels, parts,
                                  label_cost(face_normals(V, F), frames), found)
    assert done.items == 1 and np.array_equal(labels, given)
    around = np.flatnonzero((F == found.vertices[0]).any(axis=1))
    assert (done.labels[around] == 4).all(), "+Z, the sign of least normal cost"
    after = check_validity(V, F, parts, done.labels, frames, topology)
    assert found.vertices[0] not in after.invalid_corners


def test_corner_growths_grow_a_chart_around_one_of_its_corners_at_a_time():
    """A -Y island on the top at its +X edge: two corners where its boundary meets the edge;
    each trial gives the faces around one of them, and only those, the island's label."""
    V, F, parts, frames, labels = labelled_cube()
    corner = V[F]
    island = ((corner[:, :, 2] > 0.99).all(axis=1) & (corner[:, :, 0] > 0.74).all(axis=1)
              & (np.abs(corner[:, :, 1] - 0.5) < 0.26).all(axis=1))
    labels[island] = 3
    topology = build_topology(F, len(V))
    lay = check_validity(V, F, parts, labels, frames, topology).layout
    chart = int(lay.face_chart[np.flatnonzero(island)[0]])
    corners = np.intersect1d(lay.corners, F[island])
    assert len(corners) == 2
    given = labels.copy()
    trials = corner_growths(F, parts, lay, labels, chart)
    assert np.array_equal(labels, given), "the input labels are not modified"
    assert len(trials) == len(corners) and len({t.name for t in trials}) == len(trials)
    grown_at = []
    for trial in trials:
        assert isinstance(trial, Trial)
        changed = np.flatnonzero(trial.labels != labels)
        assert len(changed) and not island[changed].any()
        assert (trial.labels[changed] == 3).all()
        at = [v for v in corners.tolist() if (F[changed] == v).any(axis=1).all()]
        assert len(at) == 1, "every changed face lies around one and the same corner"
        around = (F == at[0]).any(axis=1)
        assert (trial.labels[around] == 3).all(), "every face around that corner grown"
        grown_at += at
    assert sorted(grown_at) == corners.tolist()
