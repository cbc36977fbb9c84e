# SPDX-License-Identifier: LGPL-2.1-or-later
"""The walls of a hole's rim relabelled at once (core.quadmesh.polycube.rim_walls, through
core.quadmesh.polycube.closable_labels), on a plate with a round hole whose wall carries too
few labels: two (its rim has a single side along an axis) or one (its rim has no corners)."""
import numpy as np
import pytest
import trimesh

from core.errors import LabelingError
from core.quadmesh.polycube.chart_complex import build_chart_complex, cornerless_rims
from core.quadmesh.polycube.closable_labels import closable_labels
from core.quadmesh.polycube.rim_walls import _remnants_joined
from core.quadmesh.polycube.side_signs import (contradicting_charts, lone_sides,
                                               make_loops_rectilinear)
from core.segmentation.charts import build_topology, extract_layout
from core.segmentation.validity import check_validity
from tests.core.test_quadmesh import (assert_relabelled_quad_layout,
                                      identity_frames, nearest_labels, union_of_boxes)

CENTRE, RADIUS = np.array([2.0, 2.0]), 0.8


def _plate_with_a_hole(max_edge=0.5):
    """A 4 x 4 x 1 plate with a round hole (16 facets, none facing a diagonal) through z."""
    plate = trimesh.creation.box(bounds=np.array([[0, 0, 0], [4, 4, 1]], dtype=float))
    drill = trimesh.creation.cylinder(radius=RADIUS, height=3.0, sections=16)
    drill.apply_translation([CENTRE[0], CENTRE[1], 0.5])
    mesh = trimesh.boolean.difference([plate, drill], engine="manifold")
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=max_edge)
    mesh = trimesh.Trimesh(V, F, process=True)
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    labels = nearest_labels(V, F)
    centre = V[F].mean(axis=1)
    wall = (labels < 4) & (np.linalg.norm(centre[:, :2] - CENTRE, axis=1) < RADIUS + 0.1)
    return V, F, labels, wall


def _none(complex_):
    return np.zeros(complex_.n_sides, dtype=bool)


def _repaired(V, F, labels):
    part = np.zeros(len(F), dtype=np.int64)
    frames, _ = identity_frames(len(F))
    fixed = closable_labels(V, F, part, labels, frames,
                            lambda face_label: build_chart_complex(V, F, part, face_label,
                                                                   frames), _none)
    return part, frames, fixed


def _assert_closable_with_the_wall_facing_into_the_hole(V, F, labels, wall, part, frames,
                                                        fixed):
    assert fixed is not None and fixed.rounds >= 1
    assert check_validity(V, F, part, fixed.face_label, frames).report["valid"]
    assert cornerless_rims(F, part, fixed.face_label)[1] == []
    assert len(contradicting_charts(fixed.complex_, _none(fixed.complex_))) == 0
    make_loops_rectilinear(fixed.complex_, _none(fixed.complex_))  # does not raise
    changed = fixed.face_label != labels
    assert changed.any() and not (changed & ~wall).any()  # only the hole's wall changed
    # each wall face faces the side of the hole it stands on (its nearest axis: the hole's
    # facets lie 11.25 degrees or more from a diagonal)
    assert np.array_equal(fixed.face_label[wall], nearest_labels(V, F)[wall])
    # the hole's wall is four charts, each sharing a side with the top face (the slit that
    # joins the rim to the top face's outer loop may end on one, splitting its side)
    complex_ = fixed.complex_
    walls = np.unique(complex_.face_chart[wall])
    assert sorted(complex_.chart_label[walls].tolist()) == [0, 1, 2, 3]
    top = int(complex_.face_chart[np.flatnonzero(labels == 4)[0]])
    for chart in walls.tolist():
        assert np.sum(np.all(np.sort(complex_.side_chart, axis=1) == sorted((top, chart)),
                             axis=1)) >= 1


def test_a_rim_with_a_single_side_along_an_axis_gets_its_four_walls():
    """The wall is labelled -Y above the hole's centre line and +X below it, so +X stands
    on both sides of the hole in x and the rim has one side along y and one along x."""
    V, F, labels, wall = _plate_with_a_hole()
    centre = V[F].mean(axis=1)
    labels[wall] = np.where(centre[wall, 1] > CENTRE[1], 3, 0)
    part = np.zeros(len(F), dtype=np.int64)
    frames, _ = identity_frames(len(F))
    assert check_validity(V, F, part, labels, frames).report["valid"]
    broken = build_chart_complex(V, F, part, labels, frames)
    assert lone_sides(broken, _none(broken))
    with pytest.raises(LabelingError, match="rectilinear polygon"):
        make_loops_rectilinear(broken, _none(broken))
    part, frames, fixed = _repaired(V, F, labels)
    _assert_closable_with_the_wall_facing_into_the_hole(V, F, labels, wall, part, frames,
                                                        fixed)


def test_a_rim_without_corners_gets_its_four_walls():
    """The wall is labelled -X all round: both rims pass no corner."""
    V, F, labels, wall = _plate_with_a_hole()
    labels[wall] = 1
    part = np.zeros(len(F), dtype=np.int64)
    frames, _ = identity_frames(len(F))
    _, rims = cornerless_rims(F, part, labels)
    hole_wall = np.unique(_chart_ids(F, part, labels)[wall])
    assert len(hole_wall) == 1 and len(rims) == 4  # two rims, each seen from both sides
    assert all(chart in hole_wall or walls.tolist() == hole_wall.tolist()
               for chart, _, walls in rims)
    with pytest.raises(LabelingError, match="without corners"):
        build_chart_complex(V, F, part, labels, frames)
    part, frames, fixed = _repaired(V, F, labels)
    _assert_closable_with_the_wall_facing_into_the_hole(V, F, labels, wall, part, frames,
                                                        fixed)


def test_an_island_without_corners_is_dissolved_into_the_chart_around_it():
    """A patch of a box's top labelled +Y: its loop passes no corner, and its faces fit the
    label of the top far better than any wall's."""
    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]], max_edge=0.1)
    labels = nearest_labels(V, F)
    centre = V[F].mean(axis=1)
    island = (labels == 4) & (np.abs(centre[:, 0] - 1.0) < 0.2) & (np.abs(centre[:, 1] - 0.5)
                                                                   < 0.2)
    labels[island] = 2
    part = np.zeros(len(F), dtype=np.int64)
    assert len(cornerless_rims(F, part, labels)[1]) == 2  # one loop, seen from both sides
    part, frames, fixed = _repaired(V, F, labels)
    assert fixed is not None
    assert check_validity(V, F, part, fixed.face_label, frames).report["valid"]
    assert cornerless_rims(F, part, fixed.face_label)[1] == []
    assert np.array_equal(fixed.face_label, nearest_labels(V, F))  # the island is top again


def _chart_ids(F, part, labels):
    """(m,) int64 chart of each face, as cornerless_rims numbers them."""
    return cornerless_rims(F, part, labels)[0]


def test_a_labeling_with_corners_everywhere_has_no_cornerless_rims():
    V, F, labels, _ = _plate_with_a_hole()
    part = np.zeros(len(F), dtype=np.int64)
    assert cornerless_rims(F, part, labels)[1] == []


@pytest.mark.slow
def test_the_polycube_base_mesh_of_a_plate_with_a_badly_walled_hole_is_a_closed_quad_mesh():
    V, F, labels, wall = _plate_with_a_hole()
    labels[wall] = 1
    assert assert_relabelled_quad_layout(V, F, labels) == 1


def test_a_piece_of_a_chart_cut_off_by_relabelled_faces_is_joined_back_to_it():
    """A ring of a box's top relabelled +X cuts a patch of the top off (a chart of one
    boundary, invalid); the shortest path of ring faces back to the top takes its label back,
    so the patch is the top again and the rest of the ring stays relabelled."""
    V, F = union_of_boxes([[[0, 0, 0], [2, 2, 1]]], max_edge=0.1)
    labels = nearest_labels(V, F)
    part = np.zeros(len(F), dtype=np.int64)
    topology = build_topology(F, len(V))
    centre = V[F].mean(axis=1)
    distance = np.linalg.norm(centre[:, :2] - 1.0, axis=1)
    ring = (labels == 4) & (distance > 0.3) & (distance < 0.5)
    candidate = labels.copy()
    candidate[ring] = 0
    cut = extract_layout(topology, part, candidate)
    assert (cut.chart_boundary_count <= 3).any()  # the patch inside the ring
    joined = _remnants_joined(topology, part, labels, candidate)
    layout = extract_layout(topology, part, joined)
    small = layout.chart_boundary_count[layout.face_chart] <= 3
    assert not (small & (joined == labels)).any()  # no piece of an unchanged chart is left
    back = joined != candidate
    assert back.any() and not (back & ~ring).any()  # only ring faces took their label back
    assert back.sum() < 0.25 * ring.sum()  # a path across the ring, not the ring
    top = np.unique(layout.face_chart[joined == 4])
    assert len(top) == 1  # the patch and the rest of the top are one chart again
