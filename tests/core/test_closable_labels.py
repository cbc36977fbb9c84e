# SPDX-License-Identifier: LGPL-2.1-or-later
"""Label changes that let every chart close (core.quadmesh.polycube.closable_labels), on a box
whose top carries a chart of two sides, which no side directions make rectilinear."""
import numpy as np
import pytest

from core.errors import LabelingError
from core.quadmesh.polycube.chart_complex import build_chart_complex
from core.quadmesh.polycube.closable_labels import closable_labels
from core.quadmesh.polycube.side_signs import (contradicting_charts, lone_sides,
                                               make_loops_rectilinear)
from core.segmentation.validity import check_validity
from tests.core.test_quadmesh import (assert_relabelled_quad_layout,
                                      identity_frames, nearest_labels, union_of_boxes)


def _box_with_a_tongue():
    """A 2 x 1 x 1 box labelled by nearest axis, but for a triangle of its top at x = 2
    labelled +Y: a chart with two corners and two sides (one along z with +X, one along x with
    +Z), which turns by two at most."""
    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]], max_edge=0.1)
    labels = nearest_labels(V, F)
    centre = V[F].mean(axis=1)
    tongue = (labels == 4) & (np.abs(centre[:, 1] - 0.5) < 0.3 - (2.0 - centre[:, 0]))
    labels[tongue] = 2
    return V, F, labels, tongue


def _none(complex_):
    return np.zeros(complex_.n_sides, dtype=bool)


def test_a_chart_that_cannot_close_is_relabelled_into_a_valid_closable_labeling():
    V, F, labels, tongue = _box_with_a_tongue()
    part = np.zeros(len(F), dtype=np.int64)
    frames, _ = identity_frames(len(F))

    def build(face_label):
        return build_chart_complex(V, F, part, face_label, frames)

    broken = build(labels)
    assert len(contradicting_charts(broken, _none(broken)))
    with pytest.raises(LabelingError, match="rectilinear polygon"):
        make_loops_rectilinear(broken, _none(broken))
    fixed = closable_labels(V, F, part, labels, frames, build, _none)
    assert fixed is not None and fixed.rounds >= 1
    assert check_validity(V, F, part, fixed.face_label, frames).report["valid"]
    assert len(contradicting_charts(fixed.complex_, _none(fixed.complex_))) == 0
    make_loops_rectilinear(fixed.complex_, _none(fixed.complex_))  # no longer raises
    # only the faces around the tongue changed, far less than a face of the box
    face_area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                     axis=1)
    assert 0.0 < fixed.changed_area < 0.5 * face_area[labels == 4].sum()
    changed = fixed.face_label != labels
    assert fixed.changed_area == pytest.approx(face_area[changed].sum())
    # the changed faces take a label their normals fit (nearest-axis labels everywhere)
    assert np.array_equal(fixed.face_label[changed], nearest_labels(V, F)[changed])


def test_a_walk_with_a_single_side_along_an_axis_is_named():
    """The tongue's loop has one side along z and one along x: both are lone sides of an outer
    boundary, and the error names the tongue; the plain box has none."""
    V, F, labels, tongue = _box_with_a_tongue()
    part = np.zeros(len(F), dtype=np.int64)
    frames, _ = identity_frames(len(F))
    broken = build_chart_complex(V, F, part, labels, frames)
    chart = int(broken.face_chart[np.flatnonzero(tongue)[0]])
    found = lone_sides(broken, _none(broken))
    assert sorted((c, hole, axis) for c, hole, axis, _ in found if c == chart) == [
        (chart, False, 0), (chart, False, 2)]
    assert all(chart in broken.side_chart[side] for c, _, _, side in found if c == chart)
    with pytest.raises(LabelingError, match=f"chart {chart} has a single side along"):
        make_loops_rectilinear(broken, _none(broken))
    box = build_chart_complex(V, F, part, nearest_labels(V, F), frames)
    assert lone_sides(box, _none(box)) == []


def test_a_closable_labeling_is_left_as_it_is():
    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]], max_edge=0.25)
    labels = nearest_labels(V, F)
    part = np.zeros(len(F), dtype=np.int64)
    frames, _ = identity_frames(len(F))
    fixed = closable_labels(V, F, part, labels, frames,
                            lambda lab: build_chart_complex(V, F, part, lab, frames), _none)
    assert fixed.rounds == 0 and fixed.changed_area == 0.0
    assert np.array_equal(fixed.face_label, labels)


@pytest.mark.slow
def test_the_polycube_base_mesh_of_such_a_labeling_is_a_closed_quad_mesh():
    V, F, labels, _ = _box_with_a_tongue()
    assert_relabelled_quad_layout(V, F, labels)


def test_contradicting_charts_are_those_of_a_search_of_every_neighbourhood():
    """Charts whose own program has no solution mark their neighbourhoods without a search of
    their own; the list is the one a search of every neighbourhood finds."""
    import core.quadmesh.polycube.side_signs as side_signs

    V, F, labels, _ = _box_with_a_tongue()
    broken = build_chart_complex(V, F, np.zeros(len(F), dtype=np.int64), labels,
                                 identity_frames(len(F))[0])
    slits = broken.slit_walks()
    searched = [chart for chart, ring in enumerate(side_signs._rings(broken))
                if side_signs._solve(side_signs._direction_program(
                    broken, np.sort(ring), _none(broken), slits),
                    side_signs.NODE_LIMIT).status == side_signs.INFEASIBLE]
    assert searched
    assert contradicting_charts(broken, _none(broken)).tolist() == searched
