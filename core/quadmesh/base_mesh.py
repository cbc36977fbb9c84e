# SPDX-License-Identifier: LGPL-2.1-or-later
"""Coarse quad base mesh of a labelled target (paper Sect. 2.3).

1. :mod:`.polycube.chart_complex`: charts, sides and corners of the labeling, measured on the
   target.
2. :mod:`.polycube.side_signs`: side directions that make every chart a rectilinear polygon.
3. :mod:`.polycube.quantize`: integer side lengths (a mixed-integer program) closest to a scale
   times the measured lengths, every chart polygon closed; the scale is searched for the face
   budget.
4. :mod:`.polycube.lattice`: the unit squares of every integer chart polygon are the quads; side
   points are shared by both charts of a side, across part interfaces too (parts assembled).
5. :mod:`.polycube.embed`: quads placed on the target (corners, sides by arc length, interiors by a
   Tutte map of each chart region onto its polygon); :mod:`.polycube.relax` evens them out, each
   point kept on its own chart or side.
6. Where the limit surface of some quads faces away from the target (a chart one quad across
   a thin wall, whose limit is pulled past the wall's middle), the shortest sides of their
   charts get one unit more as their least length and the layout is quantized again
   (:func:`_polycube_base_mesh`).
7. Faces whose limit surface still faces away from the target are repaired as on the paired
   decimation's cages (:mod:`limit_interpolation` moves their vertices off the target until
   the limit reaches it; :mod:`local_repair` moves a corner, splits a quad or smooths the
   patch round a fold in the target's tangent planes), so a layout is
   not given up for a few folded quads that a local edit unfolds. The self-crossings of the
   repaired cage's limit surface are counted as on the decimation's cages: a layout whose
   limit surface crosses itself gives way to a decimation cage whose limit surface does not.
   The same quads untangled on the target (:func:`.polycube.relax.untangle_on_target`, near
   the folds and everywhere) are repaired too, and the one with the fewest flaws is kept.
"""
import time

import numpy as np

from core.errors import InvalidMeshError, LabelingError, OTHER_PARTS, ParameterError
from core.mesh_topology import connected_face_components, genus_of, polymesh_genus
from core.params import BASE_MESH_METHODS
from core.polymesh_checks import check_polymesh
from core.quadmesh.crossing_count import LimitCrossingCount
from core.quadmesh.limit_interpolation import unshrink_inverted
from core.quadmesh.local_repair import repair_inverted
from core.quadmesh.orientation import inverted_faces
from core.quadmesh.decimation.paired_decimation import TIGHTEN_ROUNDS, paired_decimation_base_mesh
from core.quadmesh.polycube.chart_complex import CornerlessLoopError, build_chart_complex
from core.quadmesh.polycube.embed import (interior_point_positions, side_point_positions,
                                          tutte_coordinates)
from core.quadmesh.polycube.lattice import OverlappingChartsError, build_lattice, chart_orientation
from core.quadmesh.polycube.milp_solve import MilpTimeLimitError
from core.quadmesh.polycube.overlap_cuts import corners_to_cut, crossing_separations
from core.quadmesh.polycube.quantize import (BUDGET_TOLERANCE, COLLAPSE_BELOW, REFINEMENTS,
                                             collapsible_sides, loop_tables, minimum_faces,
                                             quantize, quantize_for_budget,
                                             rectangular_refinement)
from core.quadmesh.polycube.relax import FLAW_RINGS, relax_on_target
from core.quadmesh.polycube.closable_labels import closable_labels
from core.quadmesh.polycube.side_signs import SideDirectionError, make_loops_rectilinear
from core.target_surface import TargetSurface
from core.types import PolyMesh

REFINE_BELOW = 8000
"""Targets with fewer triangles are split by midpoint subdivision (same surface) until they have
at least this many, so every chart has interior vertices for its Tutte map and its slits."""


class LayoutTooLargeError(LabelingError):
    """The quantized layout needs more quads than the caller accepts.

    ``faces`` is the number of quads of the smallest layout found, or the linear bound on every
    layout (an int), or None.
    """

    def __init__(self, message, faces=None):
        super().__init__(message)
        self.faces = faces


UNTANGLED_KEY = "untangled_layout"
"""Key of :func:`_polycube_base_mesh`'s report under which the untangled layout (a callable
giving a PolyMesh or None, or None) is handed to :func:`_repaired_or_untangled`, which takes
it out."""

FALLBACK_OVER_BUDGET = 1.5
"""Polycube layouts with up to this many times the budget are kept over the paired decimation
(which meets the budget, but whose cages have far more extraordinary vertices); larger ones
give way to it."""

CORNER_COST = 2.0
"""Objective weight (per unit and axis, against one per unit of side length) of the corners of
drifting charts in the quantization of a layout that lost the route review without them
(:func:`core.quadmesh.polycube.quantize.quantize`, ``core.stages.basemesh``)."""
COARSE_CHART_ROUNDS = 3
"""Quantizations tried with longer shortest sides on the charts of inverted faces
(:func:`_polycube_base_mesh`)."""
REFINEMENT_ROUNDS = 24
"""Rounds of quantization, each cutting the overlapping charts at more reflex corners."""
FALLBACK_REFINEMENT_ROUNDS = 8
"""The same where the paired decimation can take over: layouts within the budget seldom need
more than a few refinements."""
TOUCH_ROUNDS = 8
"""Most separations added, one round each, where the layout quantized with corner terms
touches itself (:func:`_with_corners`)."""
SEPARATION_ROUNDS = 24
"""Rounds of quantization, each keeping apart one more pair of crossing segments of every
overlapping chart, where the layout separates crossings instead of cutting charts."""


def refined_target(target):
    """The target split by midpoint subdivision until it has ``REFINE_BELOW`` triangles.

    Returns ``(V, F, parent)``: (n', 3) float64, (m', 3) int64 and (m',) int64 original face of
    every triangle. The surface is unchanged; original vertices keep their indices.
    """
    import trimesh

    V = np.asarray(target.vertices, dtype=np.float64)
    F = np.asarray(target.faces, dtype=np.int64)
    parent = np.arange(len(F))
    while len(F) < REFINE_BELOW:
        V, F = trimesh.remesh.subdivide(V, F)
        parent = np.repeat(parent, 4)
    return V, np.asarray(F, dtype=np.int64), parent


def _layout_on_target(V, F, complex_, tables, target_faces, max_base_faces, collapsible,
                      give_up_faces, refinement_rounds, least=None, separate=False,
                      corner_cost=0.0):
    """Quantize, lay out and embed; returns ``(mesh, polycube, rounds, refinement, folded,
    quad_chart, untangled)`` (``quad_chart``: (f,) int64 chart of every face of ``mesh``;
    ``untangled``: callable ``() -> PolyMesh`` ``mesh`` with its folds untangled on the target,
    :func:`core.quadmesh.polycube.relax.untangle_on_target`, or None where that degenerated
    a face; computed when called).

    With ``separate``, overlapping charts are cut only when no crossing is left to separate:
    in each of up to ``SEPARATION_ROUNDS`` rounds, every overlapping chart gets the separation
    of its crossing segments that the measured chart shows most clearly among those not tried
    yet (:func:`core.quadmesh.polycube.overlap_cuts.crossing_separations`); separations that
    make the program infeasible are dropped for good. With ``corner_cost`` > 0 the layout
    found is quantized once more with the corners of its drifting charts
    (:func:`_with_corners`), and that one is embedded unless it is not a closed 2-manifold.

    Charts whose integer polygon overlaps itself are cut at the reflex corners next to the
    overlap (:mod:`core.quadmesh.polycube.overlap_cuts`; only those charts, so the others keep their
    freedom), and the quantization is repeated at the same scale; a chart that still overlaps
    is cut at more corners, up to its full rectangular refinement (a chart whose refinement
    makes the program infeasible stays whole). Where the cuts made the layout larger than
    ``give_up_faces``, the scale is searched again with them.

    Before a program is solved, a linear lower bound on the quads of every layout it could
    lead to (:func:`core.quadmesh.polycube.quantize.minimum_faces`) ends an attempt that cannot stay
    within ``give_up_faces``: without refinements always (every later refinement only adds
    constraints, and the retry without collapsible sides has a larger bound), with them only
    when no side is collapsible (then no retry follows, so the outcome is the same failure).

    Raises
    ------
    LabelingError (no layout, or more than ``give_up_faces`` quads, at most
    ``max_base_faces``); InvalidMeshError when the
    embedded quads are not a closed 2-manifold (a collapse that pinched a vertex).
    """
    refine, cuts, unrefinable, last = {}, {}, set(), None
    separations, added, rejected, overlapping = [], [], set(), []
    scale, rounds = None, []
    refinements, bounded = {}, set()  # rounds that keep the refinement (separations) reuse it
    for _ in range(SEPARATION_ROUNDS if separate else refinement_rounds):
        key = (frozenset(refine.items()),
               frozenset((chart, frozenset(corners)) for chart, corners in cuts.items()))
        if key not in refinements:
            refinements[key] = rectangular_refinement(complex_, tables, refine, cuts)
        refinement = refinements[key]
        if (not refine or not np.any(collapsible)) and key not in bounded:
            _check_minimum(complex_, tables, refinement, collapsible, give_up_faces,
                           max_base_faces)
            bounded.add(key)
        try:
            if scale is None:
                # the face budget is searched once without refinements and once at the end;
                # refinement rounds in between keep that scale (one program each)
                polycube, rounds = quantize_for_budget(complex_, tables, refinement,
                                                       target_faces, collapsible, give_up_faces,
                                                       least, separations)
            else:
                polycube = quantize(complex_, tables, refinement, scale, collapsible, least,
                                    separations)
        except MilpTimeLimitError:
            raise  # not infeasible: another refinement would only make it load-dependent
        except LabelingError:
            if added:
                # the separations just added contradict the others: never ask for them again
                rejected.update(added)
                separations = [item for item in separations if item not in rejected]
                added = []
                continue
            if last is None:
                raise
            # this chart's rectangles contradict the others: try its next refinement, then
            # leave it whole
            following = REFINEMENTS.index(refine[last]) + 1
            if following < len(REFINEMENTS):
                refine[last] = REFINEMENTS[following]
            elif last in cuts:
                del cuts[last]  # its partial cuts failed every way: all its reflex corners
                refine[last] = REFINEMENTS[0]
            else:
                del refine[last]
                unrefinable.add(last)
                last = None
            continue
        added = []
        if polycube.faces > give_up_faces and scale is not None:
            scale = None  # the cuts made it larger at this scale: search the budget again
            continue
        if polycube.faces > give_up_faces:
            raise LayoutTooLargeError(
                f"the smallest quantized layout found has {polycube.faces} quads, more than "
                f"{_give_up_limit(give_up_faces, max_base_faces)} ({complex_.n_charts} charts, "
                f"{complex_.n_sides} sides, each at least one unit long"
                f"{' or collapsible' if collapsible is not None and np.any(collapsible) else ''})",
                polycube.faces)
        try:
            lattice = build_lattice(complex_, tables, polycube)
        except OverlappingChartsError as exc:
            overlapping = exc.charts
            if separate:
                added = _next_separations(tables, polycube, exc.charts, separations, rejected)
                if added:
                    separations = separations + added
                    scale = polycube.scale
                    continue
            last = _cut_overlapping_chart(complex_, tables, polycube, exc.charts, refine, cuts,
                                          unrefinable)
            if last is None:
                raise
            scale = polycube.scale
            continue
        if scale is None or abs(polycube.faces - target_faces) <= BUDGET_TOLERANCE * target_faces:
            break
        scale, last = None, None  # refined layout found: search the budget with it
    else:
        raise OverlappingChartsError(sorted(set(refine) | unrefinable | set(overlapping)))
    layouts = [(polycube, lattice)]
    if corner_cost > 0:
        layouts = _with_corners(complex_, tables, refinement, polycube, collapsible, least,
                                separations, corner_cost, give_up_faces) + layouts
    for polycube, lattice in layouts:
        orientation = chart_orientation(complex_, tables, polycube.corner_uv)
        face_uv = tutte_coordinates(V, F, complex_, tables, polycube)
        interior, folded = interior_point_positions(V, F, complex_, lattice, face_uv,
                                                    orientation)
        points = np.concatenate([V[complex_.corner_vertex],
                                 side_point_positions(V, complex_, lattice,
                                                      polycube.side_length), interior])
        # identified points become one vertex (the lowest name: a corner where there is one);
        # points no quad uses (on sides of charts the quantization collapsed to no area) are
        # dropped, and the checks below judge whether what remains is closed with the genus
        # kept
        vertex = _merge_points(lattice.n_points, lattice.identified)
        used, compact = np.unique(vertex[lattice.quads.reshape(-1)], return_inverse=True)
        mesh = PolyMesh(points[used], compact.astype(np.int64),
                        np.arange(0, 4 * len(lattice.quads) + 1, 4, dtype=np.int64))
        try:
            check_polymesh(mesh)
        except InvalidMeshError:
            if polycube is layouts[-1][0]:
                raise
            continue  # the layout with corners pinches where the plain one may not
        break
    n_side_points = len(lattice.side_point_side)
    side_of = np.full(lattice.n_points, -1, dtype=np.int64)
    side_of[lattice.n_corners:lattice.n_corners + n_side_points] = lattice.side_point_side
    step_of = np.zeros(lattice.n_points)
    step_of[lattice.n_corners:lattice.n_corners + n_side_points] = (
        lattice.side_point_step / polycube.side_length[lattice.side_point_side])
    chart_of = np.full(lattice.n_points, -1, dtype=np.int64)
    chart_of[lattice.n_corners + n_side_points:] = lattice.interior_chart
    relaxed = relax_on_target(mesh, V, F, complex_.face_chart, side_of[used], step_of[used],
                              polycube.side_length, chart_of[used],
                              lambda side: V[complex_.chain(side)], lattice.quad_chart)
    faces = (mesh.face_vertices, mesh.face_offsets)

    def untangled():
        meshes = []
        for rings in (FLAW_RINGS, None):
            positions = relaxed.untangle(rings)
            if np.array_equal(positions, relaxed.smoothed):
                continue  # nothing near a flaw moved
            untangled_mesh = PolyMesh(positions, *faces)
            try:
                check_polymesh(untangled_mesh)
            except InvalidMeshError:
                continue
            meshes.append(untangled_mesh)
        return meshes

    try:
        check_polymesh(PolyMesh(relaxed.smoothed, mesh.face_vertices, mesh.face_offsets))
        mesh = PolyMesh(relaxed.smoothed, mesh.face_vertices, mesh.face_offsets)
    except InvalidMeshError:
        pass  # smoothing degenerated a face somewhere: keep the Tutte placement
    return mesh, polycube, rounds, refinement, folded, lattice.quad_chart, untangled


def _with_corners(complex_, tables, refinement, polycube, collapsible, least, separations,
                  corner_cost, give_up_faces):
    """``[(polycube, lattice)]``: the layout ``polycube`` quantized again at its scale, with
    its refinement and separations, and the corners of its drifting charts kept near their
    measured places (:func:`core.quadmesh.polycube.quantize.quantize` with ``corner_cost``),
    where that program has a solution whose charts neither overlap nor touch themselves and
    which stays within ``give_up_faces``; else ``[]``.

    The corner terms make each program far slower than the plain one, so the scale, cuts and
    separations are searched without them and the terms only move the side lengths of the
    layout found. They can move corners that the plain layout kept apart onto one another,
    so that a chart polygon runs along itself (its boundary segments cross without any cell
    covered twice, which :func:`core.quadmesh.polycube.lattice.build_lattice` lets through:
    its points are identified and the cage pinches there); each such chart gets the
    separation of those segments that the measured chart shows most clearly
    (:func:`_next_separations`) and the program is solved again, up to :data:`TOUCH_ROUNDS`
    times.
    """
    charts = range(complex_.n_charts)
    added, rejected, touching = [], set(), None
    for _ in range(TOUCH_ROUNDS + 1):
        try:
            other = quantize(complex_, tables, refinement, polycube.scale, collapsible, least,
                             separations, corner_cost)
        except MilpTimeLimitError:
            raise
        except LabelingError:
            if not added:
                return []
            # the separations just added contradict the others: try the next ones of the
            # layout that touched itself
            rejected.update(added)
            separations = [item for item in separations if item not in rejected]
            added = _next_separations(tables, touching, charts, separations, rejected)
            if not added:
                return []
            separations = separations + added
            continue
        if other.faces > give_up_faces:
            return []
        try:
            lattice = build_lattice(complex_, tables, other)
        except OverlappingChartsError:
            return []
        # no cell is covered twice, so segments that cross run along one another: the
        # polygon touches itself there
        touching = other
        added = _next_separations(tables, touching, charts, separations, rejected)
        if not added:
            return [(other, lattice)]
        separations = list(separations) + added
    return []


def _cut_overlapping_chart(complex_, tables, polycube, charts, refine, cuts, unrefinable):
    """Cut one more overlapping chart, or cut one further; returns it (None: none left).

    The first of ``charts`` that is not split into rectangles yet gets the reflex corners next
    to its overlapping cells cut (:func:`core.quadmesh.polycube.overlap_cuts.corners_to_cut`), added
    to those it has in ``cuts``; where none is left to cut, all of them (``cuts`` loses the chart).
    ``refine`` and ``cuts`` are updated in place.
    """
    orientation = chart_orientation(complex_, tables, polycube.corner_uv)
    for chart in charts:
        if chart in unrefinable or (chart in refine and chart not in cuts):
            continue
        done = cuts.get(chart, set())
        more = corners_to_cut(tables, polycube.corner_uv, chart, int(orientation[chart]), done)
        if more:
            cuts[chart] = done | more
        else:
            cuts.pop(chart, None)
        refine.setdefault(chart, REFINEMENTS[0])
        return chart
    return None


def _next_separations(tables, polycube, charts, separations, rejected):
    """For each of ``charts``, the first of its crossing separations
    (:func:`core.quadmesh.polycube.overlap_cuts.crossing_separations`) that is neither in
    ``separations`` nor ``rejected``; returns them as a list (empty: none left)."""
    used = set(separations) | rejected
    added = []
    for chart in charts:
        fresh = [item for item in crossing_separations(tables, polycube.corner_uv, chart)
                 if item not in used]
        if fresh:
            added.append(fresh[0])
            used.add(fresh[0])
    return added


def _give_up_limit(give_up_faces, max_base_faces):
    """The limit a layout exceeded, for :class:`LayoutTooLargeError` messages (a str)."""
    if give_up_faces >= max_base_faces:
        return (f"max_base_faces={max_base_faces}; raise --max-base-faces or simplify the "
                f"labeling ({OTHER_PARTS})")
    return f"{give_up_faces}, {FALLBACK_OVER_BUDGET:g} times the budget"


def _check_minimum(complex_, tables, refinement, collapsible, give_up_faces, max_base_faces):
    """Raise LayoutTooLargeError when every layout of ``refinement`` has too many quads."""
    least = minimum_faces(complex_, tables, refinement, collapsible)
    if least > give_up_faces:
        raise LayoutTooLargeError(
            f"every quantized layout of this labeling has at least {least} quads (a linear "
            f"bound), more than {_give_up_limit(give_up_faces, max_base_faces)} "
            f"({complex_.n_charts} charts, {complex_.n_sides} sides, "
            f"{refinement.rectangles} rectangles)", least)


def chart_minimum_faces(complex_, collapsible):
    """A lower bound on the quads of every layout of ``complex_``, whatever its side directions.

    A chart with no collapsible side becomes a disk with integer corners whose sides are each
    at least one unit long (:func:`core.quadmesh.polycube.lattice.build_lattice` accepts no
    other), so the walk around it passes at least as many lattice points as its loop has side
    references, ``P`` (slit banks counted twice, as in
    :func:`core.quadmesh.polycube.quantize.minimum_faces`), and Pick's theorem (``A = I + B / 2 - 1``) gives it at least ``ceil(P / 2 - 1)`` unit squares.
    Charts with a collapsible side (which may vanish) and charts that are not disks (no layout
    exists then) count zero. Side directions, refinements and larger least lengths only add
    constraints, so no layout that :func:`_layout_on_target` can return is smaller.

    Parameters
    ----------
    complex_ : ChartComplex.
    collapsible : (s,) bool sides that may have length zero.

    Returns
    -------
    int, the bound (>= 0).
    """
    n_charts = complex_.n_charts
    sizes = np.diff(complex_.loop_offsets)
    ref_chart = np.repeat(complex_.loop_chart, sizes)
    refs = complex_.loop_sides
    sides = np.where(refs >= 0, refs, ~refs)
    perimeter = np.bincount(ref_chart, minlength=n_charts)
    vanishing = np.bincount(ref_chart, weights=np.asarray(collapsible, dtype=np.float64)[sides],
                            minlength=n_charts) > 0
    disk = np.bincount(complex_.loop_chart, minlength=n_charts) == 1
    squares = -(-(perimeter - 2) // 2)  # ceil(P / 2 - 1)
    return int(np.maximum(squares, 0)[disk & ~vanishing].sum())


def _check_chart_minimum(complex_, collapsible, give_up_faces, max_base_faces):
    """Raise LayoutTooLargeError when :func:`chart_minimum_faces` exceeds ``give_up_faces``:
    the side directions and the quantization, the costly part of a layout, are then not
    solved at all."""
    least = chart_minimum_faces(complex_, collapsible)
    if least > give_up_faces:
        raise LayoutTooLargeError(
            f"every quantized layout of this labeling has at least {least} quads (Pick's "
            f"theorem on the charts without a side shorter than half a unit), more than "
            f"{_give_up_limit(give_up_faces, max_base_faces)} ({complex_.n_charts} charts, "
            f"{complex_.n_sides} sides, each at least one unit long or collapsible)", least)


def _merge_points(n, pairs):
    """(n,) int64 representative (lowest index) of every point under the identified pairs."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    graph = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    lowest = np.full(component.max() + 1, n, dtype=np.int64)
    np.minimum.at(lowest, component, np.arange(n))
    return lowest[component]


def build_base_mesh(target, face_part, face_label, face_frame, part_frames, target_faces=300,
                    max_base_faces=2500, face_interface_axis=None, method="auto",
                    decimation=None, corner_cost=0.0):
    """Closed quad base mesh on the target: the polycube layout, else the paired decimation.

    With ``method="auto"`` the quantized polycube layout of the labeling (this module's
    docstring) is built first. Where it cannot be built, exceeds ``max_base_faces`` or needs
    more than ``FALLBACK_OVER_BUDGET`` times the budget, the stage falls back to
    :mod:`core.quadmesh.decimation.paired_decimation`, which needs no labeling, and the report says
    why (``method``, ``fallback_reason``); a layout within that limit is kept even where the
    decimation would meet the budget more closely. Inverted faces
    (:func:`core.quadmesh.orientation.inverted_faces`) of the layout and faces where its limit
    surface crosses itself are repaired (:func:`_repaired_or_untangled`) and the flaws counted
    again; where inverted faces or crossings remain, the paired decimation is built too and
    the one with fewer flaws is kept (:func:`_flaw_rank`: a limit surface that crosses itself
    never wins over one that does not). ``method="polycube"`` never falls back (its errors are
    raised; layouts up to ``max_base_faces`` are kept, repaired as in ``auto``);
    ``method="decimation"`` skips the polycube layout.

    Parameters
    ----------
    target : core.types.TriMesh (n vertices, m faces, outward).
    face_part : (m,) int part of each face; face_label : (m,) int labels 0..5 in the face frame.
    face_frame : (m, 3, 3) float64 blended frame of each face (rows x, y, z).
    part_frames : (P, 3, 3) float64 frame of each part.
    target_faces : int >= 6, the face budget (met within ``BUDGET_TOLERANCE`` when the
        labeling allows it; otherwise the smallest layout found is used and reported).
    max_base_faces : int, refuse layouts with more faces than this.
    face_interface_axis : (m, 3) float64 normal of the part interface next to each face, NaN
        rows where none (``FrameField.face_interface_axis``), or None.
    method : one of ``BASE_MESH_METHODS``.
    decimation : DecimationCache shared by the calls on one target (the paired decimation
        needs no labeling, so the layouts of several labelings share it), or None.
    corner_cost : float >= 0, weight of the corners of drifting charts in the layout's
        quantization (0: sides only). A layout with corner terms is the retry of one that lost
        (``core.stages.basemesh``): in ``auto`` it is returned with its flaws, no decimation
        built, for the caller to judge.

    Returns
    -------
    mesh : core.types.PolyMesh, quads (a few triangles possible where a quad was split by a
        repair, or in the fallback), closed, 2-manifold, outward, vertices on the target (those
        of repaired inverted faces may be moved off it: :mod:`core.quadmesh.limit_interpolation`).
    info : dict (JSON-serialisable) with ``method`` ("polycube" or "paired decimation"),
        ``fallback_reason`` (None for the polycube layout), ``faces``, ``quads``,
        ``triangles``, ``other``, ``vertices``, ``crease_edges`` (edges tagged as sharp
        creases, :mod:`core.quadmesh.creases`: the paired decimation's cage where every
        smooth one crossed itself, else 0),
        ``extraordinary_vertices``, ``min_valence``,
        ``max_valence``, ``genus``, ``target_faces``, ``within_budget``, ``minimum_reason``,
        ``inverted_faces``, ``seconds`` and ``candidates`` (for each route, ``"polycube"``
        and ``"paired decimation"``: None where it was not tried, else ``built`` and, when
        built, its ``faces``, ``extraordinary_vertices``, ``min_valence``, ``max_valence``,
        ``genus``, ``inverted_faces`` and ``limit_crossings``, or where it failed its ``reason`` and ``faces``: the
        size of the smallest layout found or bounded, where that was the reason, else None);
        the polycube layout adds ``scale``,
        ``solver_status``, ``scale_rounds``, ``charts``, ``sides``, ``corners``,
        ``side_directions_flipped``, ``folded_points``, ``rectangles``, ``collapsed_sides``,
        ``layout_inverted_faces`` (before the repair), ``limit_crossings`` (self-crossing
        triangle pairs of its level-2 limit surface), ``moved_vertices``, ``edits`` and
        ``untangled`` (the untangled layout was kept, :func:`_repaired_or_untangled`) and
        ``corner_cost`` (the weight of the corner terms its quantization had);
        the paired decimation adds ``decimated_triangles``, ``budget_rounds`` (the budgets
        tried while its limit surface crossed itself or had inverted faces; beyond the budget
        rule while it crossed itself, and ``minimum_reason`` says so), ``limit_crossings``
        (of the cage kept, level 2) and ``crossing_reason`` (None, or why no cage tried had
        a limit surface that does not cross itself).

    Raises
    ------
    ParameterError for a bad budget or method; with ``method="polycube"``, LabelingError or
    InvalidMeshError as :func:`_polycube_base_mesh`.
    """
    started = time.perf_counter()
    if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)) \
            or target_faces < 6:
        raise ParameterError(f"target_faces must be an integer >= 6, got {target_faces!r}")
    if method not in BASE_MESH_METHODS:
        raise ParameterError(f"base-mesh method must be one of {', '.join(BASE_MESH_METHODS)}, "
                             f"got {method!r}")
    target_v = np.asarray(target.vertices, dtype=np.float64)
    target_f = np.asarray(target.faces, dtype=np.int64)
    surface = TargetSurface(target_v, target_f)  # one search tree for every check below
    reason = "asked for (--base-mesh-method decimation)" if method == "decimation" else None
    decimate = _paired_decimation_base_mesh if decimation is None else decimation.build
    polycube_candidate, decimation_candidate = None, None
    if method == "polycube":
        mesh, info = _polycube_base_mesh(target, face_part, face_label, face_frame, part_frames,
                                         int(target_faces), max_base_faces, face_interface_axis,
                                         max_base_faces, surface=surface,
                                         corner_cost=corner_cost)
        mesh, info = _repaired_or_untangled(mesh, info, surface)
    elif method == "auto":
        give_up = int(min(max_base_faces, FALLBACK_OVER_BUDGET * target_faces))
        try:
            mesh, info = _polycube_base_mesh(target, face_part, face_label, face_frame,
                                             part_frames, int(target_faces), max_base_faces,
                                             face_interface_axis, give_up,
                                             FALLBACK_REFINEMENT_ROUNDS, surface=surface,
                                             corner_cost=corner_cost)
        except (LabelingError, InvalidMeshError) as exc:
            reason = f"the polycube layout failed: {exc}"
            polycube_candidate = {"built": False, "faces": getattr(exc, "faces", None),
                                  "reason": str(exc)}
        else:
            mesh, info = _repaired_or_untangled(mesh, info, surface)
            polycube_candidate = _candidate(info)
            if (info["inverted_faces"] or info["limit_crossings"]) and corner_cost == 0:
                other_mesh, other_info = decimate(
                    target_v, target_f, surface, int(target_faces), max_base_faces,
                    f"the polycube layout has {_flaws(info)} after its repair")
                decimation_candidate = _candidate(other_info)
                if _flaw_rank(other_info) < _flaw_rank(info):
                    other_info["fallback_reason"] += f", this one {_flaws(other_info)}"
                    mesh, info = other_mesh, other_info
    if reason is not None:
        mesh, info = decimate(target_v, target_f, surface, int(target_faces), max_base_faces,
                              reason)
        decimation_candidate = _candidate(info)
    info["candidates"] = {"polycube": polycube_candidate,
                          "paired decimation": decimation_candidate}
    info["seconds"] = round(time.perf_counter() - started, 4)
    return mesh, info


class DecimationCache:
    """The paired decimation of one target at one face budget, built at most once.

    It needs no labeling, so the base meshes of several labelings of one target (the parts'
    and the one-part labeling, :func:`core.stages.basemesh.run_basemesh`) share it.
    ``build`` has the signature of the decimation fallback inside :func:`build_base_mesh`.
    :meth:`start` builds it ahead on another core (:class:`core.forked.Ahead`) while the
    labeling is made and the polycube layout tried (``core.stages.basemesh``); :meth:`close`
    ends that work when it was not asked for.
    """

    def __init__(self):
        self._key = None
        self._built = None
        self._ahead = None  # (key, core.forked.Ahead) of the decimation built ahead

    @staticmethod
    def _key_of(target_v, target_f, target_faces, max_base_faces):
        return ((int(target_faces), int(max_base_faces)), np.array(target_v, dtype=np.float64),
                np.array(target_f, dtype=np.int64))

    @staticmethod
    def _same(key, other):
        return (key is not None and key[0] == other[0] and np.array_equal(key[1], other[1])
                and np.array_equal(key[2], other[2]))

    def start(self, target_v, target_f, target_faces, max_base_faces):
        """Build the decimation of this target ((n, 3) ``target_v``, (m, 3) ``target_f``)
        and budgets ahead, unless it is built or started already."""
        from core.forked import Ahead

        key = self._key_of(target_v, target_f, target_faces, max_base_faces)
        if self._ahead is None and not self._same(self._key, key):
            self._ahead = (key, Ahead(_decimation_ahead, *key))

    def close(self):
        """End the decimation built ahead when its result was not asked for."""
        if self._ahead is not None:
            self._ahead[1].cancel()
            self._ahead = None

    def build(self, target_v, target_f, surface, target_faces, max_base_faces, reason):
        """The paired decimation's ``(mesh, info)`` (:func:`build_base_mesh`'s), built on the
        first call (or taken from :meth:`start`'s child) and returned again, with this call's
        ``fallback_reason``, for the same target and budgets."""
        key = self._key_of(target_v, target_f, target_faces, max_base_faces)
        if self._built is None or not self._same(self._key, key):
            built = None
            if self._ahead is not None and self._same(self._ahead[0], key):
                built = self._ahead[1].result()
                self._ahead = None
            if built is None:
                built = _paired_decimation_base_mesh(target_v, target_f, surface, target_faces,
                                                     max_base_faces, reason)
            self._built, self._key = built, key
        mesh, info = self._built
        return mesh, {**info, "fallback_reason": reason}


def _decimation_ahead(budgets, target_v, target_f):
    """:func:`_paired_decimation_base_mesh` of the target with its own search tree (the
    ``fallback_reason`` is set by :meth:`DecimationCache.build`)."""
    return _paired_decimation_base_mesh(target_v, target_f, TargetSurface(target_v, target_f),
                                        budgets[0], budgets[1], None)


def _candidate(info):
    """A built route's figures for the report's ``candidates`` (a dict)."""
    return {"built": True, **{key: info[key] for key in (
        "faces", "extraordinary_vertices", "min_valence", "max_valence", "genus",
        "inverted_faces", "limit_crossings")}}


def _flaw_rank(info):
    """Order of two built cages' limit flaws, the smaller the better (a tuple).

    A limit surface that crosses itself gives no solid, so a cage without crossings comes
    first; then fewer inverted faces, then fewer crossing pairs.
    """
    return (info["limit_crossings"] > 0, info["inverted_faces"], info["limit_crossings"])


def _flaws(info):
    """The limit flaws of a built cage in words (a str)."""
    return (f"{info['inverted_faces']} inverted faces and {info['limit_crossings']} "
            f"self-crossing triangle pairs of its limit surface (level 2)")


def _repaired_or_untangled(mesh, info, surface):
    """The repaired layout (:func:`_repaired_layout`) where it had nothing to mend (no
    inverted face, no crossing, no edit); else of it and its untangled copies, each repaired,
    the one with the fewest flaws (:func:`_repair_rank`; on a tie the copy untangled near its
    flaws, then the one untangled everywhere, then the layout itself). ``info[UNTANGLED_KEY]`` is a callable giving the
    untangled layouts (the same quads with their folds untangled on the target near the flaws,
    then everywhere), or None.

    Returns ``(mesh, info)`` as :func:`_repaired_layout`, ``info["untangled"]`` saying which
    was kept.
    """
    info = dict(info)
    untangle = info.pop(UNTANGLED_KEY, None)
    mesh, repaired = _repaired_layout(mesh, info, surface)
    repaired["untangled"] = False
    if untangle is None or _repair_rank(repaired) == (False, 0, 0, 0, 0):
        return mesh, repaired  # nothing to mend: the layout as it is
    kept = None
    for untangled in untangle():
        inverted = int(inverted_faces(untangled, surface.vertices, surface.faces, surface).sum())
        # the best rank its repair can reach: no flaw left, no edit made; a copy kept needs a
        # rank below the copies before it and no worse than the layout's (which wins only
        # when strictly better), so one whose best cannot get there is not repaired at all
        best = (False, 0, 0, inverted, 0)
        if (kept is not None and best >= _repair_rank(kept[1])) or best > _repair_rank(repaired):
            continue
        other_mesh, other = _repaired_layout(untangled, info, surface, inverted)
        if kept is None or _repair_rank(other) < _repair_rank(kept[1]):
            kept = other_mesh, {**other, "untangled": True}
    if kept is None or _repair_rank(repaired) < _repair_rank(kept[1]):
        kept = mesh, repaired
    return kept


def _repair_rank(info):
    """Order of two repaired embeddings of one layout, the smaller the better (a tuple): the
    fewer limit flaws after the repair (:func:`_flaw_rank`), then the fewer inverted faces
    before it and the fewer edits it made (the less the embedding had to be mended)."""
    return (*_flaw_rank(info), info["layout_inverted_faces"], info["edits"])


def _repaired_layout(mesh, info, surface, inverted=None):
    """The polycube layout with its inverted faces, and the faces where its limit surface
    crosses itself, repaired where that helps, and its report.

    The repairs of the paired decimation's cages: vertices of inverted faces moved off the
    target towards a limit surface through their on-target positions
    (:func:`core.quadmesh.limit_interpolation.unshrink_inverted`, kept only where it lowers the
    inverted faces without adding self-crossings of the limit surface), then a corner moved or
    a quad split at the faces still inverted or crossing, and where neither helps, the patch
    round such a face smoothed in the target's tangent planes
    (:func:`core.quadmesh.local_repair.repair_inverted` with ``untangle``, kept where it
    lowers one flaw and raises neither). A quantized layout folds where its integer polygons
    differ much from the charts' shapes, over a few faces or many; the edits mend the few, and
    a layout left crossing itself gives way to the paired decimation (:func:`build_base_mesh`).

    ``inverted``: the inverted faces of ``mesh`` (an int) where already counted, or None.

    Returns ``(mesh, info)``: ``info`` updated with the figures of the repaired mesh,
    ``inverted_faces`` (after the repair), ``layout_inverted_faces`` (before it),
    ``limit_crossings`` (self-crossing triangle pairs of the repaired cage's level-2 limit
    surface, :class:`core.quadmesh.crossing_count.LimitCrossingCount`), ``moved_vertices`` and
    ``edits``.
    """
    if inverted is None:
        inverted = int(inverted_faces(mesh, surface.vertices, surface.faces, surface).sum())
    moved, edits, layout_inverted = 0, 0, inverted
    count_crossings = LimitCrossingCount(mesh)
    crossings = count_crossings.crossings
    if inverted:
        mesh, crossings, inverted, moved = unshrink_inverted(mesh, surface, crossings, inverted,
                                                             count_crossings)
    if inverted or crossings:
        mesh, crossings, inverted, edits = repair_inverted(mesh, surface, crossings,
                                                           inverted, count_crossings,
                                                           untangle=True)
    sizes = mesh.face_sizes
    info = {**info, **_mesh_figures(mesh), "quads": int((sizes == 4).sum()),
            "triangles": int((sizes == 3).sum()), "inverted_faces": inverted,
            "layout_inverted_faces": layout_inverted, "limit_crossings": crossings,
            "moved_vertices": moved, "edits": edits}
    return mesh, info


def _mesh_figures(mesh):
    """Report figures every base mesh has: faces, vertices, valences, genus and crease edges
    (a dict)."""
    valence = np.bincount(mesh.face_vertices, minlength=len(mesh.vertices))
    return {"faces": int(mesh.n_faces), "vertices": int(len(mesh.vertices)),
            "crease_edges": int(mesh.n_creases),
            "extraordinary_vertices": int((valence != 4).sum()),
            "min_valence": int(valence.min()), "max_valence": int(valence.max()),
            "genus": polymesh_genus(mesh)}


def _paired_decimation_base_mesh(target_v, target_f, surface, target_faces, max_base_faces,
                                 reason):
    """The fallback base mesh and its report section (see :func:`build_base_mesh`).

    Budgets up to the top of the budget tolerance (and at most ``max_base_faces``) are tried
    while the cage's limit surface crosses itself or has inverted faces, and beyond it (up to
    ``max_base_faces``) while it crosses itself; the report's ``budget_rounds`` lists them and
    ``minimum_reason`` says why a cage over the budget was kept.
    """
    largest = int(min(max_base_faces, (1.0 + BUDGET_TOLERANCE) * target_faces))
    result = paired_decimation_base_mesh(target_v, target_f, target_faces, surface, largest,
                                         max_base_faces)
    mesh = result.mesh
    within = bool(abs(mesh.n_faces - target_faces) <= BUDGET_TOLERANCE * target_faces)
    minimum_reason = None
    if not within and mesh.n_faces > target_faces and result.fold_free:
        minimum_reason = _fold_free_reason(result)
    elif not within and mesh.n_faces > target_faces:
        fewest = min((r["limit_crossings"] for r in result.rounds if r["faces"] < mesh.n_faces),
                     default=0)
        minimum_reason = (f"the limit surfaces of the smaller cages tried cross themselves (the "
                          f"fewest: {fewest} triangle pairs at subdivision level 2); this is the "
                          f"smallest one tried whose limit surface does not")
    crossing_reason = None
    if result.limit_crossings:
        largest_tried = max(r["faces"] for r in result.rounds)
        crossing_reason = (
            f"its limit surface crosses itself ({result.limit_crossings} triangle pairs at "
            f"subdivision level 2), as did those of all {len(result.rounds)} cages tried up to "
            f"{largest_tried} faces (more faces did not remove the crossings): no solid can be "
            f"built of it (" + (f"with {mesh.n_creases} of its edges tagged as sharp creases; "
                                f"its faces are too coarse or ill-shaped for the part's small "
                                f"steps and holes" if mesh.n_creases else
                                "sharp creases, which Catmull-Clark subdivision rounds off, are "
                                "the usual cause") + ")")
        if result.fold_free:
            crossing_reason += _fold_free_limit(mesh, max_base_faces)
    info = {
        "method": "paired decimation", "fallback_reason": reason,
        **_mesh_figures(mesh), "quads": result.quads, "triangles": result.triangles,
        "other": 0, "target_faces": int(target_faces), "within_budget": within,
        "minimum_reason": minimum_reason, "decimated_triangles": result.decimated_triangles,
        "budget_rounds": list(result.rounds), "limit_crossings": result.limit_crossings,
        "crossing_reason": crossing_reason,
        "inverted_faces": int(inverted_faces(mesh, target_v, target_f, surface).sum()),
    }
    return mesh, info


class _LayoutAttempts:
    """Quantized layouts of one labeling, with and without collapsible slivers.

    The first attempt lets sides measured shorter than half a unit collapse; where that fails
    (or changes the genus), the sides keep at least one unit and the side directions are
    chosen again. Where both fail, both are tried again with the crossings of overlapping
    charts kept apart instead of the charts cut (``separate`` of :func:`_layout_on_target`):
    cuts tie a chart into rectangles of at least one unit each, which can push the layout
    past the caller's limit where separating the few crossing segments would not. The side
    directions, loop tables and way of undoing overlaps of the first successful attempt are
    kept (``complex_``, ``tables``, ``collapsible``, ``separate``), so later attempts with
    larger least lengths quantize the same complex the same way. ``corner_cost`` is passed on
    to every quantization (:func:`core.quadmesh.polycube.quantize.quantize`).
    """

    def __init__(self, V, F, complex_, part_frames, target_faces, max_base_faces,
                 give_up_faces, refinement_rounds, target_genus, corner_cost=0.0):
        self.V, self.F, self.part_frames = V, F, part_frames
        self.corner_cost = corner_cost
        self.budget = (target_faces, max_base_faces)
        self.give_up_faces, self.refinement_rounds = give_up_faces, refinement_rounds
        self.target_genus = target_genus
        self.original = complex_
        self.complex_, self.tables, self.collapsible, self.flipped = None, None, None, None
        self.separate, self.reached = False, []

    def _run(self, least):
        result = _layout_on_target(self.V, self.F, self.complex_, self.tables, *self.budget,
                                   self.collapsible, self.give_up_faces,
                                   self.refinement_rounds, least, self.separate,
                                   self.corner_cost)
        mesh, polycube, rounds, refinement, folded, quad_chart, untangled = result
        return mesh, polycube, rounds, refinement, folded, self.complex_, quad_chart, untangled

    def attempt(self, least):
        """``(mesh, polycube, rounds, refinement, folded, complex_, quad_chart, untangled)``.

        Raises as :func:`_polycube_base_mesh`.
        """
        if self.complex_ is not None:
            result = self._run(least)
            if polymesh_genus(result[0]) != self.target_genus:
                raise LabelingError("the finer layout changed the genus")
            return result
        complex_ = self.original
        collapsible = collapsible_sides(complex_, self.budget[0])
        _check_chart_minimum(complex_, collapsible, self.give_up_faces, self.budget[1])
        # raised here, it ends the attempt: the retry below keeps every side at least one
        # unit long, a stricter program that no side directions can satisfy either
        try:
            return self._cut_attempt(least, collapsible)
        except MilpTimeLimitError:
            raise
        except LabelingError:
            for reached in list(self.reached):
                self.complex_, self.flipped, self.collapsible, self.tables = reached
                self.separate = True
                try:
                    result = self._run(least)
                except MilpTimeLimitError:
                    raise
                except (LabelingError, InvalidMeshError):
                    continue
                if polymesh_genus(result[0]) == self.target_genus:
                    return result
            raise

    def _cut_attempt(self, least, collapsible):
        """The attempts that cut overlapping charts (the class docstring); every side
        directions and loop tables they reach are listed in ``reached``."""
        complex_ = self.original
        self.complex_, self.flipped = make_loops_rectilinear(complex_, collapsible)
        self.collapsible = collapsible
        try:
            self.tables = loop_tables(self.complex_, self.V, self.part_frames)
            self.reached.append((self.complex_, self.flipped, collapsible, self.tables))
            result = self._run(least)
            if polymesh_genus(result[0]) != self.target_genus:
                raise LabelingError("collapsing sliver charts changed the genus")
            return result
        except (LayoutTooLargeError, MilpTimeLimitError):
            raise  # keeping the slivers would only make it larger (or slower)
        except (LabelingError, InvalidMeshError) as collapsing:
            # slivers that cannot vanish cleanly keep at least one unit
            self.complex_, self.flipped = make_loops_rectilinear(
                complex_, np.zeros(complex_.n_sides, dtype=bool),
                feasible_collapsible=collapsible)
            self.collapsible = np.zeros(complex_.n_sides, dtype=bool)
            self.tables = loop_tables(self.complex_, self.V, self.part_frames)
            self.reached.append((self.complex_, self.flipped, self.collapsible, self.tables))
            try:
                return self._run(least)
            except LayoutTooLargeError as exc:
                if not np.any(collapsible):
                    raise
                # the bound holds with every side at least one unit; smaller layouts were
                # reached with collapsing slivers, and why they failed is the real reason
                raise LayoutTooLargeError(
                    f"{exc}, where every side keeps at least one unit; with the sides shorter "
                    f"than {COLLAPSE_BELOW} unit allowed to collapse: {collapsing}",
                    exc.faces) from exc
            except InvalidMeshError as exc:
                raise LabelingError(f"the quantized layout does not embed as a closed "
                                    f"2-manifold: {exc}; try another labeling or --parts") from exc


def _narrowest_sides(tables, side_length, charts):
    """(k,) int64 the shortest sides (at least one unit) of each of ``charts``: across a
    chart's narrowest part, where one more unit gives its quads room to follow the target."""
    narrow = []
    for chart in charts.tolist():
        sides = np.unique(tables.ref_side[tables.ref_chart == chart])
        sides = sides[side_length[sides] > 0]
        if len(sides):
            narrow.append(sides[side_length[sides] == side_length[sides].min()])
    return np.unique(np.concatenate(narrow)) if narrow else np.zeros(0, dtype=np.int64)


def _fold_free_reason(result):
    """Why a fold-free cage (``result``, a PairedDecimation) has more faces than the budget
    (a str)."""
    reason = (f"the cage comes of a fold-free decimation ({result.decimated_triangles} "
              f"triangles paired): every further collapse would have made a triangle facing "
              f"across the target's normals, i.e. spanning one of its thin members, whose "
              f"cage faces fold the limit surface over itself")
    if result.tightened:
        reason += (f"; its limit surface crossed itself, so it was decimated less around the "
                   f"crossing faces in {result.tightened} round(s)")
    return reason


def _fold_free_limit(mesh, max_base_faces):
    """Where a fold-free cage still crosses itself and what to raise (a str)."""
    from core.subdivision.limit_crossings import limit_self_intersections

    _, base_faces, points = limit_self_intersections(mesh, 2)
    x, y, z = points[0]
    return (f"; the fold-free decimation's faces around the crossings, added in up to "
            f"{TIGHTEN_ROUNDS} rounds within max_base_faces={max_base_faces}, did not remove "
            f"them (base faces {base_faces[0, 0]} and {base_faces[0, 1]} cross near "
            f"({x:.6g}, {y:.6g}, {z:.6g})): raise --max-base-faces")


def _polycube_base_mesh(target, face_part, face_label, face_frame, part_frames, target_faces,
                        max_base_faces, face_interface_axis, give_up_faces,
                        refinement_rounds=REFINEMENT_ROUNDS, surface=None, corner_cost=0.0):
    """Closed all-quad base mesh on the target from a valid polycube labeling.

    Parameters as :func:`build_base_mesh`; ``give_up_faces``: the budget search stops and
    raises once the layout needs more quads than this; ``refinement_rounds``: most
    quantizations that split overlapping charts into rectangles; ``surface``: TargetSurface of
    the target (built here when None); ``corner_cost``: weight of the corners of drifting
    charts in the quantization (:func:`core.quadmesh.polycube.quantize.quantize`). Returns ``(mesh, info)`` as there, without
    ``inverted_faces`` and ``seconds``.

    A chart one quad across a thin wall has a limit surface pulled past the wall's middle, so
    its quads face away from the target. Where the layout has inverted faces, the shortest
    sides of their charts (:func:`_narrowest_sides`) get one unit more than they had as their
    least length and the layout is quantized again (up to :data:`COARSE_CHART_ROUNDS` times,
    while it stays within ``give_up_faces`` and each round lowers the inverted faces); the
    layout with the fewest inverted faces is kept.

    Raises
    ------
    LabelingError when the labeling cannot be quantized or laid out (the message names the
    charts), or the layout exceeds ``max_base_faces``; InvalidMeshError when the layout does not
    embed as a closed 2-manifold.
    """
    V, F, parent = refined_target(target)
    if surface is None:
        surface = TargetSurface(np.asarray(target.vertices, dtype=np.float64),
                                np.asarray(target.faces, dtype=np.int64))
    part_frames = np.asarray(part_frames, dtype=np.float64).reshape(-1, 3, 3)
    interface_axis = (None if face_interface_axis is None
                      else np.asarray(face_interface_axis, dtype=np.float64)[parent])
    fine_part, fine_frame = np.asarray(face_part)[parent], np.asarray(face_frame)[parent]
    fine_label = np.asarray(face_label)[parent]

    def build(labels):
        return build_chart_complex(V, F, fine_part, labels, fine_frame, interface_axis)

    target_genus = genus_of(len(V), F, int(connected_face_components(F).max()) + 1)
    relabelled = None
    try:
        layout = _LayoutAttempts(V, F, build(fine_label), part_frames, int(target_faces),
                                 max_base_faces, give_up_faces, refinement_rounds, target_genus,
                                 corner_cost)
        best = layout.attempt(None)
    except (SideDirectionError, CornerlessLoopError) as exc:
        # charts no side directions close, or a loop without corners: change their labels
        # (for the layout only)
        strict = isinstance(exc, SideDirectionError) and not exc.collapsible.any()
        try:
            relabelled = closable_labels(
                V, F, fine_part, fine_label, fine_frame, build,
                lambda c: (np.zeros(c.n_sides, dtype=bool) if strict
                           else collapsible_sides(c, int(target_faces))))
        except LabelingError as failed:
            if isinstance(exc, SideDirectionError):
                raise exc from failed  # its message names the charts and HiGHS's finding
            if isinstance(failed, CornerlessLoopError):
                raise  # the loop that no label change gives corners, and its shape
            raise LabelingError(f"label changes gave every chart boundary loop corners, but "
                                f"{failed}") from exc
        layout = _LayoutAttempts(V, F, relabelled.complex_, part_frames, int(target_faces),
                                 max_base_faces, give_up_faces, refinement_rounds, target_genus,
                                 corner_cost)
        best = layout.attempt(None)
    flipped_faces = inverted_faces(best[0], surface.vertices, surface.faces, surface)
    least = np.zeros(layout.complex_.n_sides, dtype=np.int64)
    for _ in range(COARSE_CHART_ROUNDS if flipped_faces.any() else 0):
        polycube, quad_chart = best[1], best[6]
        narrow = _narrowest_sides(layout.tables, polycube.side_length,
                                  np.unique(quad_chart[flipped_faces]))
        if not len(narrow):
            break
        least[narrow] = np.maximum(least[narrow], polycube.side_length[narrow] + 1)
        try:
            candidate = layout.attempt(least)
        except (LabelingError, InvalidMeshError):
            break  # no finer layout of those charts within the limit
        facing_away = inverted_faces(candidate[0], surface.vertices, surface.faces, surface)
        if facing_away.sum() >= flipped_faces.sum():
            break  # longer sides there did not help: the charts are not too narrow
        best, flipped_faces = candidate, facing_away
        if not facing_away.any():
            break
    mesh, polycube, rounds, refinement, folded, layout_complex, _, untangled = best
    flipped = layout.flipped
    complex_ = layout_complex
    within = abs(polycube.faces - target_faces) <= BUDGET_TOLERANCE * target_faces
    minimum_reason = None
    if not within and polycube.faces > target_faces and corner_cost > 0:
        # the corner terms, not the sides' least lengths, set this layout's size
        minimum_reason = (f"the layout quantized with the corners of its drifting charts near "
                          f"their measured places has {polycube.faces} quads "
                          f"({complex_.n_charts} charts)")
    elif not within and polycube.faces > target_faces:
        minimum_reason = (f"{complex_.n_sides} sides of at least one unit each around "
                          f"{complex_.n_charts} charts need at least about {polycube.faces} quads")
    info = {
        "method": "polycube", "fallback_reason": None,
        **_mesh_figures(mesh), "quads": int(mesh.n_faces), "triangles": 0, "other": 0,
        "target_faces": int(target_faces), "within_budget": bool(within),
        "minimum_reason": minimum_reason,
        "scale": polycube.scale, "solver_status": polycube.status, "scale_rounds": rounds,
        "charts": int(complex_.n_charts), "sides": int(complex_.n_sides),
        "corners": int(complex_.n_corners), "side_directions_flipped": int(len(flipped)),
        "folded_points": int(folded), "rectangles": refinement.rectangles,
        "collapsed_sides": int((polycube.side_length == 0).sum()),
        "relabelled_area": 0.0 if relabelled is None else relabelled.changed_area,
        "corner_cost": float(corner_cost), UNTANGLED_KEY: untangled,
    }
    return mesh, info
