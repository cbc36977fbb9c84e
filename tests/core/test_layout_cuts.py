# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quantization details for designs with holes: a hole stays open where short sides may
collapse, a partial refinement cuts only the reflex corners it is given, and a separation of
two crossing segments undoes their crossing without cutting the chart."""
from types import SimpleNamespace

import numpy as np

from core.quadmesh.polycube.overlap_cuts import (Separation, chart_walk, corners_to_cut,
                                                 crossing_separations, overlapping_cells,
                                                 reflex_references)
from core.quadmesh.polycube.quantize import (LoopTables, corner_coordinates, first_scale,
                                             loop_tables, quantize, rectangular_refinement,
                                             separation_rows)
from core.quadmesh.polycube.side_signs import make_loops_rectilinear
from core.quadmesh.polycube.chart_complex import build_chart_complex
from tests.core.test_quadmesh import _solve, identity_frames, nearest_labels, union_of_boxes

# a 12 x 12 plate with a 0.5 x 0.5 through-hole in its middle (genus 1)
NARROW_HOLE = [[[0, 0, 0], [12, 5.75, 1]], [[0, 6.25, 0], [12, 12, 1]],
               [[0, 5.75, 0], [5.75, 6.25, 1]], [[6.25, 5.75, 0], [12, 6.25, 1]]]


def test_a_narrow_hole_stays_open_where_every_side_may_collapse():
    V, F = union_of_boxes(NARROW_HOLE)
    frames, part_frames = identity_frames(len(F))
    complex_ = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    collapsible = np.ones(complex_.n_sides, dtype=bool)
    complex_, _ = make_loops_rectilinear(complex_, collapsible)
    tables = loop_tables(complex_, V, part_frames)
    walks = complex_.slit_walks()
    assert len(walks) >= 2  # the plate's two faces are annuli cut open by slits
    # a coarse scale: the hole is far narrower than one unit
    polycube = quantize(complex_, tables, rectangular_refinement(complex_, tables),
                        0.2 * first_scale(complex_, 300), collapsible)
    for walk in walks:
        start = polycube.corner_uv[walk]
        end = polycube.corner_uv[tables.ref_next[walk]]
        both = np.concatenate([start, end])
        assert (both.max(axis=0) - both.min(axis=0) >= 1).all()  # open both ways


def u_shape():
    # U: +u 3, +v 2, -u 1, -v 1, -u 1, +v 1, -u 1, -v 2 (two reflex corners)
    axis = np.array([0, 1, 0, 1, 0, 1, 0, 1])
    sign = np.array([1, 1, -1, -1, -1, 1, -1, -1])
    length = np.array([3, 2, 1, 1, 1, 1, 1, 2])
    n = len(axis)
    step = np.zeros((n, 2))
    step[np.arange(n), axis] = sign * length
    start = np.cumsum(np.vstack([[0, 0], step[:-1]]), axis=0)
    tables = LoopTables(np.zeros(n, dtype=np.int64), np.arange(n), axis, sign,
                        (np.arange(n) + 1) % n, np.array([1]), start.astype(float))
    return SimpleNamespace(n_sides=n, n_charts=1, slit_walks=list), tables, axis, sign


def test_a_partial_refinement_cuts_only_the_corners_it_is_given():
    complex_, tables, axis, sign = u_shape()
    reflex = np.flatnonzero(reflex_references(tables, chart_walk(tables, 0)))
    assert len(reflex) == 2
    full = rectangular_refinement(complex_, tables, {0: "measured"})
    both = rectangular_refinement(complex_, tables, {0: "measured"}, {0: set(reflex.tolist())})
    one = rectangular_refinement(complex_, tables, {0: "measured"}, {0: {int(reflex[0])}})
    assert full.rectangles == both.rectangles == 3
    assert one.rectangles == 1  # one cut: a rectangle and an L that closes as a polygon
    for refinement in (full, both, one):
        lengths = _solve(refinement)[:complex_.n_sides]
        steps = np.zeros((complex_.n_sides, 2))
        steps[np.arange(complex_.n_sides), axis] = sign * lengths
        assert np.allclose(steps.sum(axis=0), 0) and (lengths >= 1).all()


def test_the_corners_cut_are_next_to_the_overlap():
    complex_, tables, axis, sign = u_shape()
    # lengths that close the U but draw its notch deeper than the U is high: the notch
    # pokes out below the bottom side, its cells covered backwards
    length = np.array([3, 2, 1, 3, 1, 3, 1, 2])
    step = np.zeros((len(axis), 2), dtype=np.int64)
    step[np.arange(len(axis)), axis] = sign * length
    assert (step.sum(axis=0) == 0).all()
    corner_uv = np.cumsum(np.vstack([[0, 0], step[:-1]]), axis=0)
    cut = corners_to_cut(tables, corner_uv, 0, 1, set())
    reflex = set(np.flatnonzero(reflex_references(tables, chart_walk(tables, 0))).tolist())
    assert cut and cut <= reflex
    assert not corners_to_cut(tables, corner_uv, 0, 1, reflex)  # nothing left to cut


def _poking_u():
    """The U of :func:`u_shape` with goal lengths that draw its notch deeper than the U is
    high (the notch's two sides cross the bottom side), measured as the U itself."""
    complex_, tables, axis, sign = u_shape()
    goal = np.array([3, 2, 1, 3, 1, 3, 1, 2], dtype=np.float64)
    complex_.side_extent = np.stack([goal, goal], axis=1)
    return complex_, tables, axis, sign


def test_separation_rows_measure_the_offset_between_two_corners():
    complex_, tables, axis, sign = _poking_u()
    rng = np.random.default_rng(3)
    length = np.array([3, 2, 1, 3, 1, 3, 1, 2])
    corner_uv = corner_coordinates(complex_, tables, length)
    pairs = [Separation(int(a), int(b), int(c))
             for a, b, c in zip(rng.integers(0, 8, 12), rng.integers(0, 8, 12),
                                rng.integers(0, 2, 12))]
    rows = separation_rows(tables, pairs, complex_.n_sides)
    expected = [corner_uv[p.high, p.axis] - corner_uv[p.low, p.axis] for p in pairs]
    assert np.allclose(rows.A @ length, expected)


def test_a_separation_undoes_a_crossing_without_cutting_the_chart():
    complex_, tables, axis, sign = _poking_u()
    refinement = rectangular_refinement(complex_, tables)
    crossing = quantize(complex_, tables, refinement, 1.0)
    walk = chart_walk(tables, 0)
    assert len(overlapping_cells(tables, crossing.corner_uv, walk, 1))  # the notch pokes out
    separations = crossing_separations(tables, crossing.corner_uv, 0)
    assert separations
    # every separation offered is one the crossing layout violates
    rows = separation_rows(tables, separations, complex_.n_sides)
    assert (rows.A @ crossing.side_length < 1).all()
    separated = quantize(complex_, tables, refinement, 1.0, separations=separations[:1])
    assert not len(overlapping_cells(tables, separated.corner_uv, walk, 1))
    assert (separated.side_length >= 1).all()
    # the notch sides cost 2 (3 - 1) each when it gets one unit shallower than the U is
    # high, so a U higher than 4 (its two sides 2 (h - 2) >= 6 off their goals) is never
    # the optimum: at most 3 x 4 squares less the notch
    assert 1 <= separated.faces <= 11
