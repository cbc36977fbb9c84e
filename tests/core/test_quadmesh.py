# SPDX-License-Identifier: LGPL-2.1-or-later
"""Quantized base mesh (core.quadmesh): chart complex, side directions, integer lengths,
rectangular refinement, lattice and embedding, on shapes built here and on a real TO mesh."""
import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from scipy.optimize import Bounds, LinearConstraint, milp

from core.errors import InternalError, LabelingError, ParameterError
from core.polymesh_checks import check_polymesh
from core.quality import point_surface_distance
from core.quadmesh import build_base_mesh
from core.quadmesh.polycube.chart_complex import build_chart_complex
from core.quadmesh.orientation import inverted_faces
from core.quadmesh.base_mesh import LayoutTooLargeError, chart_minimum_faces
from core.quadmesh.polycube.lattice import OverlappingChartsError, build_lattice
from core.quadmesh.polycube.milp_solve import MilpTimeLimitError, solve_milp
from core.quadmesh.polycube.quantize import (BUDGET_TOLERANCE, LoopTables, closeness_rows,
                                             collapsible_sides, loop_tables, minimum_faces,
                                             quantize, quantize_for_budget,
                                             rectangular_refinement)
from core.quadmesh.polycube.side_signs import (charts_close, loops_are_rectilinear,
                                               make_loops_rectilinear)
from core.types import TriMesh

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
L_SHAPE = [[[0, 0, 0], [4, 1, 1]], [[0, 0, 0], [1, 3, 1]]]
# a square frame: genus 1, its top and bottom charts are annuli (cut by slits)
FRAME = [[[0, 0, 0], [3, 1, 1]], [[0, 2, 0], [3, 3, 1]], [[0, 0, 0], [1, 3, 1]],
         [[2, 0, 0], [3, 3, 1]]]
# the frame as a thin plate: its walls are far thinner than half a unit at these budgets
THIN_FRAME = [[[0, 0, 0], [4, 1, 0.12]], [[0, 2, 0], [4, 3, 0.12]], [[0, 0, 0], [1, 3, 0.12]],
              [[3, 0, 0], [4, 3, 0.12]]]


def union_of_boxes(boxes, max_edge=0.25):
    """Closed triangle mesh of a union of axis-aligned boxes ((lo, hi) pairs), small triangles."""
    parts = [trimesh.creation.box(bounds=np.array(b, dtype=float)) for b in boxes]
    mesh = trimesh.boolean.union(parts, engine="manifold") if len(parts) > 1 else parts[0]
    V, F = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=max_edge)
    mesh = trimesh.Trimesh(V, F, process=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def nearest_labels(V, F):
    """Label 0..5 of the world axis direction closest to each face normal."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return np.argmax(np.concatenate([n, -n], axis=1)[:, [0, 3, 1, 4, 2, 5]], axis=1)


def identity_frames(m, parts=1):
    return np.tile(np.eye(3), (m, 1, 1)), np.tile(np.eye(3), (parts, 1, 1))


def assert_relabelled_quad_layout(V, F, labels, target_faces=150):
    """Build the one-part polycube base mesh of a labeling the layout has to relabel, and
    check that it is a closed quad mesh of the target's genus with some area relabelled.
    Returns the genus."""
    part = np.zeros(len(F), dtype=np.int64)
    frames, part_frames = identity_frames(len(F))
    base, info = build_base_mesh(TriMesh(V, F), part, labels, frames, part_frames, target_faces,
                                 method="polycube")
    check_polymesh(base)
    assert (base.face_sizes == 4).all()
    assert info["method"] == "polycube" and info["genus"] == euler_genus(V, F)
    assert info["relabelled_area"] > 0.0
    return info["genus"]


def base_of(boxes, face_part=None, target_faces=300, method="polycube", **kwargs):
    """The polycube base mesh (no fallback) of a union of boxes with nearest-axis labels."""
    V, F = union_of_boxes(boxes)
    face_part = np.zeros(len(F), dtype=np.int64) if face_part is None else face_part(V, F)
    face_frame, part_frames = identity_frames(len(F), int(face_part.max()) + 1)
    base, info = build_base_mesh(TriMesh(V, F), face_part, nearest_labels(V, F), face_frame,
                                 part_frames, target_faces, method=method, **kwargs)
    return V, F, base, info


def euler_genus(V, F):
    edges = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1),
                      axis=0)
    return (2 - (len(V) - len(edges) + len(F))) // 2


def on_surface_distance(points, V, F):
    return point_surface_distance(points, V, F)


def t_junctions(mesh):
    """Vertices lying strictly inside a base-mesh edge they are not an end of (tolerance 1e-9)."""
    q = mesh.face_vertices.reshape(-1, 4)
    a, b = q.reshape(-1), np.roll(q, -1, axis=1).reshape(-1)
    P = mesh.vertices
    count = 0
    for start, end in zip(P[a], P[b]):
        d = end - start
        t = (P - start) @ d / (d @ d)
        close = np.linalg.norm(P - (start + np.clip(t, 0, 1)[:, None] * d), axis=1) < 1e-9
        count += int((close & (t > 1e-9) & (t < 1 - 1e-9)).sum())
    return count


@pytest.mark.parametrize("boxes", [L_SHAPE, FRAME], ids=["l-shape", "frame"])
def test_base_mesh_is_a_closed_quad_mesh_on_the_target_with_its_genus(boxes):
    V, F, base, info = base_of(boxes)
    check_polymesh(base)  # closed, 2-manifold, outward, no degenerate faces
    assert (base.face_sizes == 4).all() and info["quads"] == info["faces"] == base.n_faces
    assert info["genus"] == euler_genus(V, F)
    # every vertex lies on the target surface (corners, side points and Tutte-mapped points)
    assert on_surface_distance(base.vertices, V, F).max() < 1e-9 * np.ptp(V, axis=0).max()
    assert t_junctions(base) == 0
    assert not inverted_faces(base, V, F).any()
    assert info["folded_points"] == 0


@pytest.mark.slow
def test_face_budget_is_met_within_a_quarter_and_grows_with_it():
    counts = []
    for budget in (150, 300, 1000):
        _, _, base, info = base_of(L_SHAPE, target_faces=budget)
        assert abs(base.n_faces - budget) <= 0.25 * budget, (budget, base.n_faces)
        assert info["within_budget"]
        counts.append(base.n_faces)
    assert counts == sorted(counts)


def test_two_parts_meet_with_the_same_splits_at_their_interface():
    def halves(V, F):
        return (V[F].mean(axis=1)[:, 0] > 2.0).astype(np.int64)

    V, F, base, info = base_of([[[0, 0, 0], [4, 1, 1]]], face_part=halves)
    check_polymesh(base)
    assert info["genus"] == 0 and t_junctions(base) == 0
    # the interface plane x = 2 is crossed by base-mesh vertices lying on it
    on_interface = np.abs(base.vertices[:, 0] - 2.0) < 1e-9
    assert on_interface.sum() >= 4


def test_chart_complex_of_a_box_and_slits_of_a_frame():
    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]])
    frames, _ = identity_frames(len(F))
    box = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    assert (box.n_charts, box.n_sides, box.n_corners) == (6, 12, 8)
    assert len(box.loop_chart) == 6 and (np.diff(box.loop_offsets) == 4).all()
    # measured extents: the box's edges are 2, 1 and 1 long along x, y and z
    length_by_axis = {0: 2.0, 1: 1.0, 2: 1.0}
    expected = np.array([length_by_axis[a] for a in box.side_axis[:, 0]])
    assert np.allclose(box.side_extent[:, 0], expected, atol=1e-9)
    V, F = union_of_boxes(FRAME)
    frames, _ = identity_frames(len(F))
    frame = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    slits = frame.side_chart[:, 0] == frame.side_chart[:, 1]
    # the top and bottom annuli each get one slit of two sides, walked twice by one loop
    assert slits.sum() == 4 and len(frame.loop_chart) == frame.n_charts
    assert len(frame.slit_walks()) == 4


def test_a_wrongly_measured_short_side_is_flipped_back():
    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]])
    frames, _ = identity_frames(len(F))
    box = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    assert loops_are_rectilinear(box) and charts_close(box)
    broken_sign = box.side_sign.copy()
    broken_sign[3] *= -1
    broken = dataclasses.replace(box, side_sign=broken_sign)
    assert not loops_are_rectilinear(broken)
    repaired, flipped = make_loops_rectilinear(broken)
    assert flipped.tolist() == [[3, 0], [3, 1]]  # its direction in both of its charts
    assert np.array_equal(repaired.side_sign, box.side_sign)


def test_a_chart_that_cannot_turn_by_four_is_found_in_its_neighbourhood():
    """A box chart whose loop runs x, x, x, y after one side is measured along the wrong axis
    admits no directions: the whole program is infeasible, and so is the neighbourhood program
    of the smallest ring holding that chart, which names it; the intact box has none."""
    from core.quadmesh.polycube.side_signs import _direction_program, _local_contradiction

    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]])
    frames, _ = identity_frames(len(F))
    box = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    none = np.zeros(box.n_sides, dtype=bool)
    assert _local_contradiction(box, none) is None
    loop = box.loop(0)
    sides = np.where(loop >= 0, loop, ~loop)
    column = np.where(box.side_chart[sides, 0] == box.loop_chart[0], 0, 1)
    axis = box.side_axis.copy()
    axis[sides[1], column[1]] = axis[sides[0], column[0]]
    broken = dataclasses.replace(box, side_axis=axis)
    charts, message = _local_contradiction(broken, none)
    assert box.loop_chart[0] in charts and "infeasible" in message
    assert len(charts) == 5  # a box chart and its four neighbours
    whole = _direction_program(broken, np.arange(broken.n_charts), none)
    assert milp(whole.cost, integrality=whole.integrality, bounds=whole.bounds,
                constraints=whole.constraints).status == 2
    with pytest.raises(LabelingError, match="rectilinear polygon"):
        make_loops_rectilinear(broken)


def test_an_undecided_root_goes_through_the_neighbourhoods_to_the_same_answer(monkeypatch):
    """With no root node allowed (HiGHS stops before deciding), a repairable box is checked
    neighbourhood by neighbourhood (each has a solution) and then gets the flips of the full
    search."""
    import core.quadmesh.polycube.side_signs as side_signs

    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]])
    frames, _ = identity_frames(len(F))
    box = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    sign = box.side_sign.copy()
    sign[3] *= -1
    checked = []
    local = side_signs._local_contradiction

    def counted(*args):
        checked.append(local(*args))
        return checked[-1]

    monkeypatch.setattr(side_signs, "ROOT_NODES", 0)
    monkeypatch.setattr(side_signs, "_local_contradiction", counted)
    repaired, flipped = make_loops_rectilinear(dataclasses.replace(box, side_sign=sign))
    assert checked == [None]
    assert flipped.tolist() == [[3, 0], [3, 1]]
    assert np.array_equal(repaired.side_sign, box.side_sign)


def test_a_stricter_copy_of_a_feasible_program_is_searched_where_it_is_stricter(monkeypatch):
    """A program known feasible with more collapsible sides can contradict only in the
    neighbourhoods holding a side that lost its freedom: those are solved (most such sides
    first), the others never; with no such side nothing is solved before the root, and the
    answer is that of the plain call (the side's own charts are also tried alone, a quick
    relaxation of their neighbourhoods). A collapsible side missing from the feasible set is an
    error."""
    import core.quadmesh.polycube.side_signs as side_signs

    V, F = union_of_boxes([[[0, 0, 0], [5, 1, 1]], [[0, 0, 0], [1, 2, 1]], [[4, 0, 0], [5, 2, 1]]],
                          max_edge=0.5)
    frames, _ = identity_frames(len(F))
    ell = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    none = np.zeros(ell.n_sides, dtype=bool)
    solved = []
    solve, feasibility = side_signs._solve, side_signs._feasibility

    def spy(program, node_limit):
        solved.append(np.unique(program.used // 2))
        return solve(program, node_limit)

    def feasibility_spy(program):
        solved.append(np.unique(program.used // 2))
        return feasibility(program)

    monkeypatch.setattr(side_signs, "_solve", spy)
    monkeypatch.setattr(side_signs, "_feasibility", feasibility_spy)
    assert side_signs._local_contradiction(ell, none, np.zeros(0, dtype=np.int64)) is None
    assert solved == []
    rings = [np.unique(ell.side_chart[(ell.side_chart == c).any(axis=1)])
             for c in range(ell.n_charts)]
    holding = np.array([[np.isin(ell.side_chart[s], ring).any() for ring in rings]
                        for s in range(ell.n_sides)])
    side = int(np.argmin(holding.sum(axis=1)))  # a tooth's side: far charts do not hold it
    assert holding[side].sum() < ell.n_charts
    assert side_signs._local_contradiction(ell, none, np.array([side])) is None
    # the neighbourhoods holding the side, and the side's charts on their own
    assert len(solved) == holding[side].sum() + len(np.unique(ell.side_chart[side]))
    assert all(side in sides for sides in solved)
    solved.clear()
    plain = make_loops_rectilinear(ell, none)
    assert solved == []  # its loops are rectilinear and close: no program at all
    assert np.array_equal(make_loops_rectilinear(ell, none, feasible_collapsible=none)[0].side_sign,
                          plain[0].side_sign)
    with pytest.raises(InternalError, match="every collapsible side"):
        make_loops_rectilinear(ell, ~none,
                               feasible_collapsible=none)


def _solve(refinement):
    n = refinement.n_vars
    lower = np.where(refinement.piece, 0.0, 1.0)
    result = milp(np.ones(n), integrality=np.ones(n), bounds=Bounds(lower, np.inf),
                  constraints=[LinearConstraint(refinement.equalities, 0, 0),
                               LinearConstraint(refinement.extents, 1, np.inf)])
    return np.rint(result.x).astype(int)


def test_rectangular_refinement_of_an_l_and_a_u():
    # L: +u 2, +v 1, -u 1, +v 1, -u 1, -v 2 (one reflex corner -> two rectangles)
    for axis, sign, rectangles in (([0, 1, 0, 1, 0, 1], [1, 1, -1, 1, -1, -1], 2),
                                   ([0, 1, 0, 1, 0, 1, 0, 1], [1, 1, -1, -1, -1, 1, -1, -1], 3)):
        n = len(axis)
        measured = np.cumsum(np.stack([np.where(np.array(axis) == 0, sign, 0),
                                       np.where(np.array(axis) == 1, sign, 0)], axis=1), axis=0)
        tables = LoopTables(np.zeros(n, dtype=np.int64), np.arange(n), np.array(axis),
                            np.array(sign), (np.arange(n) + 1) % n, np.array([1]),
                            np.roll(measured, 1, axis=0).astype(float))
        refinement = rectangular_refinement(SimpleNamespace(n_sides=n, n_charts=1, slit_walks=list),
                                            tables, refine={0})
        assert refinement.rectangles == rectangles
        lengths = _solve(refinement)[:n]
        # the solution draws a closed polygon with unit-or-longer sides
        steps = np.zeros((n, 2))
        steps[np.arange(n), axis] = np.array(sign) * lengths
        assert np.allclose(steps.sum(axis=0), 0) and (lengths >= 1).all()


def test_bad_budgets_and_too_many_faces_are_clear_errors():
    with pytest.raises(ParameterError, match="target_faces"):
        base_of(L_SHAPE, target_faces=3)
    with pytest.raises(LabelingError, match="max_base_faces=100"):
        base_of(L_SHAPE, target_faces=1000, max_base_faces=100)
    with pytest.raises(ParameterError, match="base-mesh method"):
        base_of(L_SHAPE, method="quadriflow")
    from core.params import ReconstructionParams

    with pytest.raises(ParameterError, match="base_mesh_method"):
        ReconstructionParams(base_mesh_method="")


def test_opposite_labels_on_one_boundary_are_refused():
    V, F = union_of_boxes([[[0, 0, 0], [2, 1, 1]]])
    labels = nearest_labels(V, F)
    centre = V[F].mean(axis=1)
    labels[(labels == 4) & (centre[:, 0] < 1.0)] = 5  # half the top face labelled -Z
    face_frame, part_frames = identity_frames(len(F))
    with pytest.raises(LabelingError, match="same or opposite labels"):
        build_base_mesh(TriMesh(V, F), np.zeros(len(F), dtype=np.int64), labels, face_frame,
                        part_frames, 300, method="polycube")
    # the default falls back to the paired decimation and says why
    base, info = build_base_mesh(TriMesh(V, F), np.zeros(len(F), dtype=np.int64), labels,
                                 face_frame, part_frames, 300)
    check_polymesh(base)
    assert info["method"] == "paired decimation"
    assert "same or opposite labels" in info["fallback_reason"]
    assert info["genus"] == 0 and info["within_budget"]


@pytest.mark.slow
def test_real_simp_cantilever_base_mesh():
    from core.pipeline import reconstruct

    result = reconstruct(EXAMPLES / "to_simp_cantilever.stl", stop_after="basemesh")
    assert result.report["stages"]["basemesh"]["status"] == "ok", result.report["stages"]
    base = result.state.basemesh.cage
    target = result.state.intake.target
    check_polymesh(base)
    info = result.report["base_mesh"]
    assert info["genus"] == result.report["input"]["genus"] == 0
    assert info["within_budget"] and abs(info["faces"] - 300) <= 75
    # at most 1% of the faces inverted (the limit surface facing away from the target, such
    # as a face of the clamped end's collapsed slivers)
    assert inverted_faces(base, target.vertices, target.faces).mean() <= 0.01
    diag = float(np.linalg.norm(np.ptp(target.vertices, axis=0)))
    assert on_surface_distance(base.vertices, target.vertices, target.faces).max() < 1e-9 * diag


def layout_problem(boxes):
    """Chart complex and loop tables of a union of boxes with nearest-axis labels."""
    V, F = union_of_boxes(boxes)
    frames, part_frames = identity_frames(len(F))
    complex_ = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    complex_, _ = make_loops_rectilinear(complex_)
    return complex_, loop_tables(complex_, V, part_frames)


@pytest.mark.slow
@pytest.mark.parametrize("boxes", [L_SHAPE, FRAME], ids=["l-shape", "frame"])
def test_a_larger_budget_never_gives_a_smaller_layout(boxes):
    """The budget search moves the scale only as far as the band needs, so the face count
    follows the budget: a first layout inside the band is kept, one just outside becomes the
    nearest layout inside it (not one near the budget, nor one that leaves the band)."""
    complex_, tables = layout_problem(boxes)
    refinement = rectangular_refinement(complex_, tables)
    counts = []
    for budget in range(20, 130):
        polycube, rounds = quantize_for_budget(complex_, tables, refinement, budget)
        first = rounds[0]["faces"]
        if abs(first - budget) <= BUDGET_TOLERANCE * budget:
            assert polycube.faces == first, (budget, rounds)
        if any(abs(r["faces"] - budget) <= BUDGET_TOLERANCE * budget for r in rounds):
            assert abs(polycube.faces - budget) <= BUDGET_TOLERANCE * budget, (budget, rounds)
        counts.append(polycube.faces)
    assert counts == sorted(counts)


@pytest.mark.parametrize("boxes", [L_SHAPE, FRAME], ids=["l-shape", "frame"])
def test_minimum_faces_is_a_lower_bound_of_every_layout(boxes):
    complex_, tables = layout_problem(boxes)
    plain = rectangular_refinement(complex_, tables)
    every_chart = rectangular_refinement(complex_, tables, range(complex_.n_charts))
    least, least_refined = (minimum_faces(complex_, tables, r) for r in (plain, every_chart))
    # rectangles only add constraints and a second bound, so the bound can only grow
    assert 6 <= least <= least_refined
    for refinement, bound in ((plain, least), (every_chart, least_refined)):
        for scale in (0.05, 1.0, 4.0, 10.0):
            polycube = quantize(complex_, tables, refinement, scale)
            try:
                build_lattice(complex_, tables, polycube)
            except OverlappingChartsError:
                continue  # not a layout the stage keeps
            assert polycube.faces >= bound, (scale, polycube.faces, bound)
    # the smallest layout of the refined L (every side one unit where it can be) meets it
    polycube = quantize(complex_, tables, every_chart, 1e-3)
    assert polycube.faces <= least_refined + 4 * complex_.n_charts


def test_closeness_rows_cost_every_integer_length_its_distance_and_cut_between_them():
    goal = np.array([0.3, 1.0, 2.5, 3.75, 7.01])
    rows = closeness_rows(goal, len(goal))
    A, lb = rows.A.toarray(), np.asarray(rows.lb)
    s = len(goal)

    def least_t(lengths):
        """Smallest t each side's three rows allow at these lengths (t has coefficient 1)."""
        return ((lb - A[:, :s] @ lengths)).reshape(3, s).max(axis=0)

    for shift in range(-3, 4):
        lengths = np.floor(goal) + shift
        assert np.allclose(least_t(lengths), np.abs(lengths - goal), atol=1e-12)
    # between the integers around a goal the rows cost the chord, above |l - g| inside
    between = np.floor(goal) + 0.5
    chord = 0.5 * (np.abs(np.floor(goal) - goal) + np.abs(np.floor(goal) + 1 - goal))
    assert np.allclose(least_t(between), chord, atol=1e-12)
    fractional = goal != np.floor(goal)
    assert (least_t(between)[fractional] > np.abs(between - goal)[fractional] + 1e-3).all()


@pytest.mark.parametrize("scale", [1.37, 3.1])
def test_the_quantization_program_is_solved_by_its_linear_relaxation(monkeypatch, scale):
    """The chord rows make the relaxation integral (module docstring of quantize): its optimum
    is the program's, so HiGHS closes at the root; without them the relaxation is weaker."""
    complex_, tables = layout_problem(FRAME)
    refinement = rectangular_refinement(complex_, tables, range(complex_.n_charts))
    programs = []

    def recorded(what, cost, integrality, bounds, constraints, gap=None, *limits):
        result = solve_milp(what, cost, integrality, bounds, constraints, gap, *limits)
        programs.append((cost, bounds, constraints, result))
        return result

    monkeypatch.setattr("core.quadmesh.polycube.quantize.solve_milp", recorded)
    quantize(complex_, tables, refinement, scale)
    (cost, bounds, constraints, result), = programs
    relaxed = milp(cost, bounds=bounds, constraints=constraints)
    n = refinement.n_vars
    assert np.abs(relaxed.x[:n] - np.rint(relaxed.x[:n])).max() < 1e-6
    assert relaxed.fun == pytest.approx(result.fun, abs=1e-6)
    # the first closeness block without its chord rows: the relaxation alone falls short
    s = complex_.n_sides
    plain = [LinearConstraint(constraints[0].A[:2 * s], constraints[0].lb[:2 * s], np.inf)]
    weaker = milp(cost, bounds=bounds, constraints=plain + list(constraints[1:]))
    assert weaker.fun < result.fun - 0.1


@pytest.mark.slow
def test_collapsed_walls_keep_a_closed_layout_of_the_target_genus_growing_with_the_budget():
    """A thin plate's walls collapse to length zero; the layout stays a closed 2-manifold of
    the plate's genus and a larger budget never gives fewer quads."""
    counts = []
    for budget in (60, 150, 300):
        V, F, base, info = base_of(THIN_FRAME, target_faces=budget)
        check_polymesh(base)
        assert info["collapsed_sides"] > 0
        assert info["genus"] == euler_genus(V, F) == 1
        counts.append(base.n_faces)
    assert counts == sorted(counts)


def test_a_box_needs_six_quads_by_the_bound_and_by_the_quantization():
    complex_, tables = layout_problem([[[0, 0, 0], [2, 1, 1]]])
    refinement = rectangular_refinement(complex_, tables)
    assert minimum_faces(complex_, tables, refinement) == 6
    assert quantize(complex_, tables, refinement, 1e-3).faces == 6


def test_an_attempt_over_the_bound_ends_before_any_program(monkeypatch):
    complex_, tables = layout_problem(L_SHAPE)
    least = minimum_faces(complex_, tables, rectangular_refinement(complex_, tables))

    def no_program(*args, **kwargs):
        raise AssertionError("a mixed-integer program was solved")

    monkeypatch.setattr("core.quadmesh.polycube.quantize.solve_milp", no_program)
    with pytest.raises(LayoutTooLargeError, match=f"at least {least} quads"):
        base_of(L_SHAPE, target_faces=300, max_base_faces=least - 1)


@pytest.mark.parametrize("boxes", [[[[0, 0, 0], [2, 1, 1]]], L_SHAPE, FRAME],
                         ids=["box", "l-shape", "frame"])
def test_the_chart_bound_needs_no_side_directions_and_is_below_every_layout(boxes):
    """Pick's theorem on the charts as measured bounds the linear bound of the directed charts
    and every layout the lattice accepts; charts with a collapsible side count zero."""
    V, F = union_of_boxes(boxes)
    frames, _ = identity_frames(len(F))
    measured = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    none = np.zeros(measured.n_sides, dtype=bool)
    bound = chart_minimum_faces(measured, none)
    assert bound >= measured.n_charts  # every chart is a disk of at least one square
    complex_, tables = layout_problem(boxes)
    refinement = rectangular_refinement(complex_, tables)
    assert bound <= minimum_faces(complex_, tables, refinement)
    for scale in (0.05, 1.0, 4.0):
        polycube = quantize(complex_, tables, refinement, scale)
        try:
            build_lattice(complex_, tables, polycube)
        except OverlappingChartsError:
            continue
        assert polycube.faces >= bound
    one_side = none.copy()
    one_side[0] = True
    assert chart_minimum_faces(measured, one_side) < bound
    assert chart_minimum_faces(measured, ~none) == 0


def test_an_attempt_over_the_chart_bound_ends_before_the_side_directions(monkeypatch):
    V, F = union_of_boxes(FRAME)
    frames, _ = identity_frames(len(F))
    measured = build_chart_complex(V, F, np.zeros(len(F)), nearest_labels(V, F), frames)
    bound = chart_minimum_faces(measured, collapsible_sides(measured, 300))
    assert bound >= measured.n_charts

    def no_directions(*args, **kwargs):
        raise AssertionError("the side directions were solved")

    monkeypatch.setattr("core.quadmesh.base_mesh.make_loops_rectilinear", no_directions)
    with pytest.raises(LayoutTooLargeError, match=f"at least {bound} quads .*Pick"):
        base_of(FRAME, target_faces=300, max_base_faces=bound - 1)


def test_the_hang_guard_is_an_error_not_another_answer(monkeypatch):
    monkeypatch.setattr("core.quadmesh.polycube.milp_solve.HANG_GUARD_SECONDS", 0.0)
    with pytest.raises(MilpTimeLimitError, match="depend on the machine's load"):
        solve_milp("a test program", np.ones(3), np.ones(3), Bounds(1, 10),
                   [LinearConstraint(np.ones((1, 3)), 4.5, np.inf)])


def _counted_solves(monkeypatch):
    """A list that gets an entry per HiGHS solve of ``milp_solve``, whose kept answers and
    verdicts start empty."""
    import core.quadmesh.polycube.milp_solve as milp_solve

    calls = []

    def counted(*args, **kwargs):
        calls.append(1)
        return milp(*args, **kwargs)

    monkeypatch.setattr(milp_solve, "milp", counted)
    monkeypatch.setattr(milp_solve, "_ANSWERS", type(milp_solve._ANSWERS)())
    monkeypatch.setattr(milp_solve, "_VERDICTS", type(milp_solve._VERDICTS)())
    return calls


def test_a_program_met_again_gets_the_first_answer_without_a_solve(monkeypatch):
    calls = _counted_solves(monkeypatch)
    cost = np.array([1.0, 2.0, 3.0])

    def program(rhs):
        # built afresh each time, the matrix once dense and once sparse with its entries
        # in another order: the same program
        matrix = np.ones((1, 3)) if rhs < 5 else sp.coo_matrix(
            (np.ones(3), (np.zeros(3), np.array([2, 0, 1]))), shape=(1, 3))
        return solve_milp("a test program", cost.copy(), np.ones(3), Bounds(0, 10),
                          [LinearConstraint(matrix, rhs, np.inf)])

    first = program(4.5)
    again = program(4.5)
    assert len(calls) == 1
    assert np.array_equal(first.x, again.x) and first.x is not again.x
    again.x[:] = -1  # a caller changing its copy changes no later answer
    assert np.array_equal(program(4.5).x, first.x) and len(calls) == 1
    other = program(7.5)
    assert len(calls) == 2 and other.x.sum() >= 7.5 > first.x.sum()
    sparse_again = program(7.5)
    assert len(calls) == 2 and np.array_equal(sparse_again.x, other.x)


def test_answers_kept_are_bounded(monkeypatch):
    import core.quadmesh.polycube.milp_solve as milp_solve

    monkeypatch.setattr(milp_solve, "_ANSWERS", type(milp_solve._ANSWERS)())
    monkeypatch.setattr(milp_solve, "ANSWERS_KEPT", 2)
    for rhs in (1.5, 2.5, 3.5):
        solve_milp("a test program", np.ones(3), np.ones(3), Bounds(0, 10),
                   [LinearConstraint(np.ones((1, 3)), rhs, np.inf)])
    assert len(milp_solve._ANSWERS) == 2


def test_feasibility_is_decided_once_per_feasible_set_whatever_the_costs(monkeypatch):
    import core.quadmesh.polycube.milp_solve as milp_solve

    calls = _counted_solves(monkeypatch)

    def status(cost, rhs, upper=10):
        # integers in [0, upper] summing to at least rhs and at most 2.5: none where rhs > 2.5
        return milp_solve.solve_feasibility(
            "a test program", np.asarray(cost, dtype=float), np.ones(3), Bounds(0, upper),
            [LinearConstraint(np.ones((1, 3)), rhs, 2.5)]).status

    assert status([1, 2, 3], 3.5) == 2 and len(calls) == 1
    assert status([3, 1, 2], 3.5) == 2 and len(calls) == 1  # other costs: decided already
    assert status([1, 2, 3], 1.5) == 0 and len(calls) == 2
    assert status([5, 5, 5], 1.5) == 0 and len(calls) == 2
    assert status([1, 2, 3], 1.5, upper=0) == 2 and len(calls) == 3  # other bounds: solved
    # a search stopped by its node limit decided nothing: solved again, never taken as given
    monkeypatch.setattr(milp_solve, "milp", lambda *args, **kwargs: SimpleNamespace(
        status=1, x=None, message="node limit"))
    assert milp_solve.solve_feasibility("a test program", np.ones(3), np.ones(3),
                                        Bounds(0, 10), [LinearConstraint(np.ones((1, 3)), 4.5,
                                                                         np.inf)]).status == 1
    assert len(milp_solve._VERDICTS) == 3


@pytest.mark.slow
def test_the_same_labelled_dev_mesh_gives_the_same_base_mesh_twice():
    from core.pipeline import reconstruct

    from tests.core.dev_meshes import MESHES

    path = Path(MESHES) / "polycube_bone.obj"
    if not path.exists():
        pytest.skip("dev mesh polycube_bone.obj not available")
    state = reconstruct(path, stop_after="labeling").state
    field = state.frames.frame_field
    builds = [build_base_mesh(state.intake.surface, state.parts.face_part,
                              state.labeling.face_label, field.face_frame, field.part_frames,
                              300, method="polycube") for _ in range(2)]
    (first, info), (second, again) = builds
    assert info["method"] == "polycube" and info["scale_rounds"] == again["scale_rounds"]
    assert np.array_equal(first.vertices, second.vertices)
    assert np.array_equal(first.face_vertices, second.face_vertices)


@pytest.mark.slow
def test_side_directions_that_cannot_be_found_end_the_attempt_after_one_program(monkeypatch):
    """With slivers allowed length zero no directions exist for ge_bracket_domain's labeling
    (one part); the retry that keeps every side one unit long is stricter, so it is not run."""
    import core.quadmesh.base_mesh as base_mesh
    from core.pipeline import reconstruct

    from tests.core.dev_meshes import MESHES

    path = Path(MESHES) / "ge_bracket_domain.stl"
    if not path.exists():
        pytest.skip("dev mesh ge_bracket_domain.stl not available")
    state = reconstruct(path, stop_after="labeling").state
    field = state.frames.frame_field
    programs = []

    def counted(complex_, collapsible=None, **kwargs):
        programs.append(collapsible.copy())
        return make_loops_rectilinear(complex_, collapsible, **kwargs)

    monkeypatch.setattr(base_mesh, "make_loops_rectilinear", counted)
    with pytest.raises(LabelingError, match="rectilinear polygon"):
        build_base_mesh(state.intake.surface, state.parts.face_part, state.labeling.face_label,
                        field.face_frame, field.part_frames, 300, method="polycube")
    assert len(programs) == 1 and programs[0].any()
