# SPDX-License-Identifier: LGPL-2.1-or-later
"""Chart boundary loops without corners (core.quadmesh.polycube.chart_complex): the error says
what a loop runs round, on shapes built here: a ring whose bar two labels share round its
girth (a member with no walls of its own), a plate whose hole's wall two labels share round
its middle (a hole with no walls of its own), and a hole's wall with one label all round
(its rims)."""
import numpy as np
import pytest
import trimesh

from core.quadmesh.polycube.chart_complex import (CornerlessLoopError, build_chart_complex,
                                                  cornerless_rims)
from core.quadmesh.polycube.closable_labels import closable_labels
from tests.core.test_quadmesh import identity_frames, nearest_labels, union_of_boxes


def _ring_with_a_shared_bar():
    """A square ring (genus 1) whose front bar (along x) is labelled -Y on its left half and
    -Z on its right half all round, so the two charts meet in one loop round the bar."""
    V, F = union_of_boxes([[[0, 0, 0], [4, 1, 1]], [[0, 3, 0], [4, 4, 1]],
                           [[0, 0, 0], [1, 4, 1]], [[3, 0, 0], [4, 4, 1]]])
    labels = nearest_labels(V, F)
    centre = V[F].mean(axis=1)
    bar = (centre[:, 1] < 1.0 + 1e-6) & (centre[:, 0] > 1.25) & (centre[:, 0] < 2.75)
    labels[bar & (centre[:, 0] < 2.0)] = 3
    labels[bar & (centre[:, 0] >= 2.0)] = 5
    return V, F, labels


def _plate_with_a_shared_hole():
    """A 4 x 4 x 1 plate with a square hole through z whose wall carries the top's label (+Z)
    on its upper half and the bottom's (-Z) on its lower half, so the two charts meet in one
    loop inside the hole (where opposite labels meet: no polycube has that either, but the
    loop is what has no corners)."""
    plate = trimesh.creation.box(bounds=np.array([[0, 0, 0], [4, 4, 1]], dtype=float))
    drill = trimesh.creation.box(bounds=np.array([[1.5, 1.5, -1], [2.5, 2.5, 2]], dtype=float))
    mesh = trimesh.boolean.difference([plate, drill], engine="manifold")
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=0.25)
    mesh = trimesh.Trimesh(V, F, process=True)
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    labels = nearest_labels(V, F)
    centre = V[F].mean(axis=1)
    wall = (labels < 4) & (np.abs(centre[:, :2] - 2.0).max(axis=1) < 0.5 + 1e-6)
    labels[wall & (centre[:, 2] > 0.5)] = 4
    labels[wall & (centre[:, 2] <= 0.5)] = 5
    return V, F, labels, wall


def _cornerless_loops(F, labels):
    """The loops without corners, each seen from one of its two charts."""
    return [rim for rim in cornerless_rims(F, np.zeros(len(F), dtype=np.int64), labels)[1]]


def test_a_loop_round_a_bar_shared_by_two_labels_is_named_a_member():
    V, F, labels = _ring_with_a_shared_bar()
    assert len(_cornerless_loops(F, labels)) == 2  # one loop round the bar, from both sides
    frames, _ = identity_frames(len(F))
    # the bar is 1 x 1 across: its girth's widest span is the diagonal, 1.41
    with pytest.raises(CornerlessLoopError, match=r"round a member [0-9]+ edges round and "
                                                   r"1\.4[0-9]* units across"):
        build_chart_complex(V, F, np.zeros(len(F), dtype=np.int64), labels, frames)


def test_a_loop_inside_a_hole_shared_by_two_labels_is_named_a_hole():
    V, F, labels, _ = _plate_with_a_shared_hole()
    assert len(_cornerless_loops(F, labels)) == 2
    frames, _ = identity_frames(len(F))
    with pytest.raises(CornerlessLoopError, match="round a hole through the design"):
        build_chart_complex(V, F, np.zeros(len(F), dtype=np.int64), labels, frames)


def test_the_rim_of_a_wall_with_one_label_is_named_a_rim():
    """The square hole's wall labelled +X all round: its two rims pass no corner."""
    V, F, labels, wall = _plate_with_a_shared_hole()
    labels[wall] = 0
    frames, _ = identity_frames(len(F))
    with pytest.raises(CornerlessLoopError, match="rim of a wall, boss or island"):
        build_chart_complex(V, F, np.zeros(len(F), dtype=np.int64), labels, frames)


def test_label_changes_give_the_shared_loops_corners_or_name_the_loop_left():
    """Either every loop gets corners and the labels stay a polycube's, or the error names a
    loop that is left (never a silent failure)."""
    for V, F, labels in (_ring_with_a_shared_bar(), _plate_with_a_shared_hole()[:3]):
        part = np.zeros(len(F), dtype=np.int64)
        frames, _ = identity_frames(len(F))
        try:
            fixed = closable_labels(V, F, part, labels, frames,
                                    lambda lab: build_chart_complex(V, F, part, lab, frames),
                                    lambda c: np.zeros(c.n_sides, dtype=bool))
        except CornerlessLoopError as exc:
            assert "edges round" in str(exc) or "rim of a wall" in str(exc)
        else:
            assert cornerless_rims(F, part, fixed.face_label)[1] == []
