# SPDX-License-Identifier: LGPL-2.1-or-later
"""Fit a subdivision base mesh to a target mesh (paper Sect. 2.5).

The base vertices are moved by relaxed gradient projection so that the Catmull-Clark
surface of level ``levels`` grows (volume) while it stays inside the target
(packaging penalty) and keeps a minimal wall thickness. The responses are evaluated
on the limit positions of the level-``levels`` vertices (``X = L S_i V0``, ``L`` the
exact limit masks of :func:`core.subdivision.limit.limit_matrices`), so the surface
that is fitted is the one exported later; ``surface='control'`` uses the level-i
control points ``S_i V0`` as in the paper's Eq. 10.
"""
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from core.errors import InvalidMeshError, ParameterError
from core.fitting.best_fit import BestFitResult, best_fit, pull_inside
from core.fitting.contain import nudge_inside
from core.fitting.crease_curves import fit_crease_curves
from core.fitting.crossings import (UNTANGLE, count_crossings, crossing_pairs,
                                     hold_back_crossings, influencing, stiffen_until_clean)
from core.fitting.records import (Distances, FitFigures, FitRecord, FitSetup, InsideFit,
                                    InsideStart, LeastSquaresFit, Untangling)
from core.fitting.responses import thickness, volume
from core.fitting.rgp import FitProblem, run_rgp
from core.forked import Ahead
from core.geometry import face_areas, sample_surface, triangulate
from core.mesh_topology import next_corners
from core.progress import NO_PROGRESS
from core.quality import containment
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices
from core.target_surface import TargetSurface
from core.threads import single_threaded
from core.tolerances import CONTACT
from core.types import PolyMesh

MODES = ("inside", "best-fit", "none")
STARTS = ("best-fit", "cage")
SURFACES = ("limit", "control")


@dataclass(frozen=True)
class FitSettings:
    """Tuned constants of :func:`fit_base_mesh`, one per choice the fit makes."""

    fine_rounds: int = 2
    """Least-squares rounds kept for the fit's level after the level-1 rounds (at least; it
    also gets those the level-1 rounds leave, :func:`_two_level_best_fit`), and the rounds of
    each untangling refit (:func:`_untangled`)."""
    retry_step: float = 0.4
    """Step of the RGP's second run, times the first's, when the first kept its start
    (:func:`_rgp`)."""
    retry_outside: float = 1e-3
    """Fraction of the target's volume the start's outside points must stand for before the
    RGP runs again with ``retry_step`` (a fifth of the 0.5 % containment goal): a start with
    only a little outside is kept, since a second run raises its mean distance; one with
    much outside runs again."""
    rgp_passes: int = 3
    """Most further RGP passes of :func:`_passes_around_crossings`."""
    polish_halvings: int = 2
    """RGP runs after the first, each from the best design of the one before with half its
    step (:func:`_polished`), within the fit's iteration budget: every vertex of an RGP
    iterate moves by about the step, so the best design of a run sits that far inside
    the target; the shorter steps bring it back out to the target's surface."""
    inside_margin: float = 0.25
    """Depth the inside start pulls the outside limit points to, times the RMS signed distance
    of the least-squares fit's limit points (a quarter gives a lower mean distance after the
    RGP than none or a half)."""
    inside_rounds: int = 2
    """Rounds of the pull inside (:func:`core.fitting.best_fit.pull_inside`)."""
    spread_crossings: float = 2.0 / 3.0
    """Fraction of the base vertices influencing the least-squares fit's crossing triangles
    above which the inside fit's start is refitted stiffer (:func:`_untangled`): a thin plate
    pulled through itself over most of its area. Where the crossings are local (at most
    about half of the base vertices), the fit is held back towards the cage there instead.
    The refits stiffen the smoothness term at every vertex influencing a crossing, and the
    inside fit that starts from them is worse than the one that starts from the unstiffened
    fit held back (a larger mean distance, at twice the CPU time); a thin plate held back
    without refits leaves more of its volume outside."""
    long_way_left: float = 0.15
    """Fraction of the first fit's crossing pairs the short untangling refits may leave for
    the refits to be made again the long way (:func:`_untangled`). Where they left less, the
    long way usually clears what was left; where they left more, the crossings are where
    the cage cannot follow the part, and the long way does not have fewer but costs
    seconds."""
    warm_rounds: int = 2
    """Least-squares rounds of a fit from ``WARM_START`` (on the fit's level only)."""
    warm_pull_tries: int = 1
    """Stiffer pulls inside of a fit from ``WARM_START`` (:func:`_pulled_inside`)."""
    distance_samples: int = 20000
    """Target samples of the target-to-surface figures (:func:`_distances`)."""
    near_touch: float = 0.01
    """Thinnest wall of the inside start, times the mean base edge, below which the default
    ``t_min`` is 0 (the thickness constraint left off, :func:`_default_t_min`)."""


FIT = FitSettings()
"""The settings this module runs with."""


@single_threaded()
def fit_base_mesh(base, target, levels=2, iterations=100, t_min=None, mode="inside",
                  progress=None, penalty=1e5, step_fraction=0.05, surface="limit",
                  start="best-fit", rounds=10, tol=2e-3, patience=5, seed=0, warm=None):
    """Move the base-mesh vertices so the subdivision surface fills or fits the target.

    The fit runs in phases, each returning a record of :mod:`core.fitting.records`:

    1. :func:`_prepare`: the subdivision hierarchy, the limit map and the target;
    2. a cage with creases (``base.creases``) has its crease curves placed on the target's
       feature lines (:func:`core.fitting.crease_curves.fit_crease_curves`); in both fitting
       modes that cage is the fit's start, the reference of the smoothness term and of the
       hold-backs (the ``initial`` figures stay the cage's as given);
    3. :func:`_least_squares`: the two-sided least-squares fit (best-fit mode, and inside
       mode from ``start='best-fit'`` without creases), untangled where it crosses itself;
    4. :func:`_inside_start` (inside mode from ``start='best-fit'``): that fit, or the
       creased cage (``CREASED_START``), pulled just inside the target and held back where
       it crosses itself;
    5. :func:`_inside_fit` (inside mode): the relaxed gradient projection from there, held
       back where it crosses itself, further passes around those vertices and a nudge of
       the held-back vertices inwards;
    6. :func:`_measure`: distances and containment of the result and of the cage.

    The returned level-``levels`` limit surface does not cross itself when the cage's does
    not, and never where the start did not. The fit runs with one BLAS thread
    (:func:`core.threads.single_threaded`): the result does not depend on the machine's
    core count.

    Parameters
    ----------
    base : PolyMesh, closed 2-manifold, outward oriented (model units).
    target : TriMesh, closed, outward oriented.
    levels : int in 1..4, subdivision level ``i`` on which the responses live.
    iterations : int >= 0, maximum RGP iterations (paper: 100).
    t_min : float or None, minimal wall thickness (model units) at every fine vertex;
        ``None`` picks ``min(0.1 * mean base edge, 0.5 * thinnest wall of the start)``;
        0 disables the constraint. The least-squares start does not see it: a given
        ``t_min`` above the start's walls is a constraint the RGP has to restore, so use
        ``start='cage'`` with a cage that satisfies it.
    mode : ``'inside'`` (paper: fill the target from inside, relaxed gradient
        projection), ``'best-fit'`` (two-sided least squares,
        :func:`core.fitting.best_fit.best_fit`) or ``'none'`` (the cage unchanged, its
        figures only).
    progress : core.progress.Progress or None
    penalty : float > 0, ``p`` of Eq. 6 (dimensionless, see :mod:`core.fitting.rgp`).
    step_fraction : float in (0, 1], largest base-vertex move per iteration as a
        fraction of the mean base edge length.
    surface : ``'limit'`` or ``'control'``, which fine positions the responses use.
    start : ``'best-fit'`` (inside mode starts from the least-squares fit, pulled just
        inside the target by :func:`core.fitting.best_fit.pull_inside` and held back where
        it crosses itself, :func:`core.fitting.crossings.hold_back_crossings`; a cage with
        creases starts from itself, its crease curves fitted, ``CREASED_START``) or
        ``'cage'`` (from the cage as given, the paper's start).
    rounds : int >= 0, most Gauss-Newton rounds of the least-squares fit.
    seed : int, seed of its target samples (:meth:`core.target_surface.TargetSurface.samples`).
    warm : None, or core.fitting.records.WarmStart carried from the fit of a cage that
        ``base`` refines: the least-squares fit starts from its ``vertices`` with
        ``FIT.warm_rounds`` rounds on the fit's level only, the pull inside from its
        ``pull_stiffness`` with ``FIT.warm_pull_tries`` stiffer pulls (``WARM_START``);
        ignored without a least-squares fit.
    tol, patience : the RGP stops when its best objective improved by less than
        ``tol * max(|best|, step)`` over the last ``patience`` iterations (see
        :func:`core.fitting.rgp.run_rgp`); ``iterations`` is the cap.

    Returns
    -------
    fitted : PolyMesh, the base mesh with moved vertices (same faces).
    record : core.fitting.records.FitRecord, the records of the phases that ran and the
        figures of the result.

    Raises
    ------
    ParameterError
        A parameter is out of range; the message names it and the value.
    InvalidMeshError
        The target is not a valid closed, outward-oriented triangle mesh, or the base
        mesh is not closed.
    """
    started = time.perf_counter()
    progress = NO_PROGRESS if progress is None else progress
    _check_parameters(levels, iterations, t_min, mode, penalty, step_fraction)
    _check_choices(surface, start, rounds, tol, patience)
    V0 = _check_base(base)
    if warm is not None and (np.shape(warm.vertices) != V0.shape or (
            warm.pull_stiffness is not None and np.shape(warm.pull_stiffness) != V0.shape[:1])):
        raise ParameterError(f"warm: vertices of shape {V0.shape} and pull_stiffness of shape "
                             f"{V0.shape[:1]} (or None) expected, got "
                             f"{np.shape(warm.vertices)} and "
                             f"{np.shape(warm.pull_stiffness)}")
    setup = _prepare(base, target, levels, surface)
    creased = None
    if mode != "none" and base.n_creases:
        creased = fit_crease_curves(base, setup.hierarchy.meshes[levels], setup.limit_map,
                                    setup.triangles, setup.target.vertices,
                                    setup.target.faces)
        base = replace(base, vertices=creased.vertices)
    least_squares = inside_start = inside = None
    if mode == "best-fit" or (mode == "inside" and start == "best-fit" and not base.n_creases):
        progress.report("fit", 0.0, "least-squares fit")
        least_squares = _least_squares(base, setup, rounds, seed, refit_local=mode != "inside",
                                       warm=warm)
    if mode == "inside" and start == "best-fit":
        inside_start = _inside_start(base, setup, least_squares, start,
                                     None if least_squares is None else warm)
    vertices, crossings = _latest(base.vertices, least_squares, inside_start)
    if mode == "inside":
        inside = _inside_fit(base, setup, vertices, crossings, iterations, t_min, penalty,
                             step_fraction, dict(stall_tol=tol, patience=patience,
                                                 progress=progress))
        vertices, crossings = inside.vertices, inside.crossings
    self_intersections, cage_self_intersections = _crossing_counts(setup, V0, crossings,
                                                                   least_squares)
    figures = _measure(setup, vertices, V0, seed)
    label = inside_start.label if inside_start else (start if least_squares else None)
    return replace(base, vertices=vertices), FitRecord(
        mode, levels, surface, label, figures, time.perf_counter() - started,
        crease_curves=creased, least_squares=least_squares, inside_start=inside_start,
        inside=inside, self_intersections=self_intersections,
        cage_self_intersections=cage_self_intersections)


@single_threaded()
def least_squares_preview(base, target, levels=2, rounds=10, seed=0, mode="inside"):
    """How close ``base`` can come to the target before containment: the least-squares fit
    of phase 3 of :func:`fit_base_mesh` in ``mode`` (untangled as that mode does: held back
    where it crosses itself, after refits with a stiffer smoothness term in best-fit mode and
    where the inside fit makes them) and its distances, without the pull inside and the RGP.

    A cage whose least-squares fit crosses itself is held back towards the cage there, and
    those vertices stay far from the target through the rest of the inside fit; the preview
    says how far, so that two cages of the same target can be compared before either is
    fitted (:mod:`core.quadmesh.route_review`).

    Parameters
    ----------
    base : PolyMesh, closed 2-manifold, outward oriented (model units); its creases, if any,
        are not fitted (the least-squares start of a creased cage differs, see
        :func:`fit_base_mesh`).
    target : TriMesh, closed, outward oriented.
    levels : int in 1..4; rounds : int >= 0; seed : int, as in :func:`fit_base_mesh`.
    mode : ``'inside'`` or ``'best-fit'``, the fit mode whose least-squares fit is previewed.

    Returns
    -------
    core.fitting.records.LeastSquaresFit, the fit (``untangled.held_back`` base vertices held
    back, ``untangled.crossings`` pairs left); core.fitting.records.Distances of its limit
    surface (fractions of the target's bounding-box diagonal).
    """
    if mode not in ("inside", "best-fit"):
        raise ParameterError(f"a least-squares preview is of the inside or best-fit mode, "
                             f"got {mode!r}")
    _check_parameters(levels, 0, None, mode, 1.0, 0.05)
    _check_choices("limit", "best-fit", rounds, 2e-3, 1)
    _check_base(base)
    setup = _prepare(base, target, levels, "limit")
    least_squares = _least_squares(base, setup, rounds, seed, refit_local=mode != "inside")
    points = sample_surface(setup.target.vertices, setup.target.faces, FIT.distance_samples,
                            np.random.default_rng(seed))
    X = setup.limit_map @ least_squares.untangled.vertices
    return least_squares, _distances(X, setup.triangles, setup.target, points)


def _prepare(base, target, levels, surface):
    """The :class:`core.fitting.records.FitSetup` of a fit of ``base`` to ``target``.

    Raises InvalidMeshError when the target encloses a non-positive volume (its faces are
    not counter-clockwise seen from outside).
    """
    # the fit's many closest-point queries search pieces of the target's long triangles
    target_surface = TargetSurface(target.vertices, target.faces, split=True)
    target_volume, _ = volume(target_surface.vertices, target_surface.faces)
    if not target_volume > 0:
        raise InvalidMeshError(f"target encloses a non-positive volume ({target_volume:g}); "
                               "its faces must be counter-clockwise seen from outside",
                               "orientation")
    hierarchy = build_hierarchy(base, levels)
    fine = hierarchy.meshes[levels]
    S = hierarchy.composite(levels - 1)
    L, _, _ = limit_matrices(fine)
    limit_map = (L @ S).tocsr()
    return FitSetup(target_surface, target_volume, hierarchy, limit_map,
                    limit_map if surface == "limit" else S,
                    triangulate(fine.face_vertices, fine.face_offsets), surface)


def _latest(vertices, *phases):
    """Base vertices and crossing pairs of the last phase that ran (``None``: not run);
    ``vertices`` and ``None`` (crossings not known) when none did."""
    crossings = None
    for phase in phases:
        if phase is not None:
            vertices, crossings = phase.vertices, phase.crossings
    return vertices, crossings


def _least_squares(base, setup, rounds, seed, refit_local, warm=None):
    """The least-squares fit (:func:`_two_level_best_fit`; from ``warm.vertices``, ``warm`` a
    WarmStart or None, ``FIT.warm_rounds`` rounds on the fit's level, ``WARM_START``),
    untangled (:func:`_untangled`).

    Returns
    -------
    core.fitting.records.LeastSquaresFit
    """
    if warm is None:
        fitted, coarse = _two_level_best_fit(base, setup.hierarchy, setup.limit_map,
                                             setup.triangles, setup.target, rounds, seed=seed)
    else:
        fitted = best_fit(base, setup.limit_map, setup.triangles, setup.target,
                          rounds=min(rounds, FIT.warm_rounds), seed=seed, start=warm.vertices)
        coarse = BestFitResult(fitted.vertices, 0, [], "rounds")
    untangled = _untangled(base, setup, fitted.vertices, rounds, seed, refit_local)
    return LeastSquaresFit(fitted.rounds + coarse.rounds, fitted.rms, coarse.rms,
                           fitted.stopped, untangled)


def _inside_start(base, setup, least_squares, start, warm=None):
    """The inside fit's start: the least-squares fit, or without one the creased cage
    (``CREASED_START``, its crease curves on the target's feature lines already), pulled
    just inside the target (:func:`_pulled_inside`; from a WarmStart ``warm``, with its
    ``pull_stiffness``) and held back where the pull crosses itself, so that the RGP starts
    nowhere crossing itself.

    Returns
    -------
    core.fitting.records.InsideStart
    """
    carried = None
    if least_squares is None:
        vertices, label, held = base.vertices, CREASED_START, 0
        crossings = count_crossings(setup.limit_map, setup.triangles, vertices)
        stiffness = None
    else:
        vertices, crossings, label = least_squares.vertices, least_squares.crossings, start
        held, stiffness = least_squares.untangled.held_back, least_squares.untangled.stiffness
        if warm is not None:
            label, carried = WARM_START, warm.pull_stiffness
    pulled, margin, pull_crossings, weights = _pulled_inside(
        base, setup.limit_map, setup.triangles, setup.target, vertices, stiffness, carried)
    vertices, crossings, pull_held = _held_back(vertices, crossings, pulled.vertices,
                                                setup.limit_map, setup.triangles, pulled.pairs)
    held += pull_held
    if held:
        label = f"{label}, held back at {held} base vertices (it crossed itself)"
    return InsideStart(vertices, crossings, label, margin, pull_crossings, held, weights)


def _inside_fit(base, setup, vertices, crossings, iterations, t_min, penalty, step_fraction,
                options):
    """The relaxed gradient projection from ``vertices`` (paper Sect. 2.5, :func:`_rgp`),
    continued with shorter steps (:func:`_polished`), held back where its limit surface
    crosses itself (:func:`_rgp_held_back`); where it was
    held back on a clean surface, further passes with the held-back vertices fixed
    (:func:`_passes_around_crossings`), then those vertices nudged inwards under the points
    left outside (:func:`core.fitting.contain.nudge_inside`).

    Parameters
    ----------
    vertices : (n, 3) float64 the start; crossings : int or None, its crossing pairs.
    iterations, t_min, penalty, step_fraction : see :func:`fit_base_mesh`.
    options : dict of further :func:`core.fitting.rgp.run_rgp` arguments.

    Returns
    -------
    core.fitting.records.InsideFit
    """
    T = setup.triangles
    edge = _mean_edge_length(base)
    step = step_fraction * edge
    X_start = setup.mapping @ vertices
    defaulted = t_min is None
    if defaulted:
        t_min = _default_t_min(X_start, T, edge)
    problem = FitProblem(setup.mapping, T, setup.target, penalty, "inside", t_min,
                         _area(X_start, T))
    result, problem, retried = _rgp(problem, vertices, step, iterations, options,
                                    setup.target_volume, defaulted)
    rgp_step = FIT.retry_step * step if retried and problem.t_min > 0 else step
    result, rgp_step, polish = _polished(problem, result, rgp_step, iterations, options)
    vertices, crossings, held = _rgp_held_back(setup, vertices, crossings, result.vertices)
    used, passes, nudged = result.iterations, None, None
    if held and setup.surface == "limit" and crossings == 0:
        vertices, passes, used, fixed = _passes_around_crossings(
            problem, vertices, result.vertices, T, rgp_step, iterations - used, options)
        used += result.iterations
        # the held-back vertices sit where the start was, partly outside
        vertices, nudged = nudge_inside(vertices, setup.limit_map, T, setup.target,
                                        movable=fixed)
    return InsideFit(vertices, crossings, used, result.stopped, result.best_iteration,
                     result.history["objective"], result.history["volume"],
                     float(problem.t_min), float(step), held, retried, passes, nudged, polish)


def _rgp_held_back(setup, start, crossings, moved):
    """The RGP's result ``moved`` held back towards its ``start`` where it crosses itself
    (:func:`_held_back`; on the control points with ``surface='control'``).

    Returns
    -------
    vertices : (n, 3) float64; crossings : int, crossing pairs of their fine mesh;
    held : int, base vertices held back.
    """
    limit = setup.surface == "limit"
    if limit and crossings is not None and np.array_equal(moved, start):
        return start, crossings, 0  # the RGP's best is its start, checked before
    return _held_back(start, crossings if limit else None, moved, setup.mapping,
                      setup.triangles)


def _crossing_counts(setup, V0, crossings, least_squares):
    """``self_intersections`` and ``cage_self_intersections`` of the record: the result's
    crossing pairs when counted on its limit surface, and, when it still crosses, the
    cage's (counted by the least-squares fit, else here from ``V0``)."""
    if setup.surface != "limit" or crossings is None:
        crossings = None
    cage = None if least_squares is None else least_squares.untangled.cage_self_intersections
    if crossings and cage is None:
        cage = count_crossings(setup.limit_map, setup.triangles, V0)
    return crossings, cage


def _measure(setup, vertices, V0, seed):
    """Distances and containment of the result (:func:`_distances`,
    :func:`core.quality.containment`) and the distances of the cage ``V0``.

    Returns
    -------
    core.fitting.records.FitFigures
    """
    measuring = time.perf_counter()
    target, T = setup.target, setup.triangles
    # the points of target.samples without the pseudo-normals it also finds (not needed here)
    points = sample_surface(target.vertices, target.faces, FIT.distance_samples,
                            np.random.default_rng(seed))
    X, X0 = setup.limit_map @ vertices, setup.limit_map @ V0
    # the distances on another core while the containment is measured here
    both = Ahead(_both_distances, X, X0, T, target, points)
    try:
        report = containment(X, T, target.vertices, target.faces)
        distances, initial = both.result() or _both_distances(X, X0, T, target, points)
    finally:
        both.cancel()  # ends the child where the containment raised
    return FitFigures(distances, initial, report["outside_volume_fraction"],
                      report["uncovered_volume_fraction"], time.perf_counter() - measuring)


def _both_distances(X, X0, T, target, points):
    """:func:`_distances` of the result's fine limit points ``X`` and of the cage's ``X0``."""
    return _distances(X, T, target, points), _distances(X0, T, target, points)


def _rgp(problem, vertices, step, iterations, options, target_volume, defaulted=False):
    """The RGP from ``vertices``; run again when no iterate after the start was feasible and
    the start leaves more than ``FIT.retry_outside`` of ``target_volume`` (model units
    cubed) outside, estimated as the summed depth of its outside fine points times the mean
    area per fine point: without the thickness constraint when its ``t_min`` is the default
    (``defaulted``), else with ``FIT.retry_step`` times the step.

    The thickness constraint is linearised and its rays reach ``2 t_min``, while a step
    moves a vertex up to ``step`` (0.05 of the mean base edge, about ten times a default
    ``t_min`` taken from a thin start): the first step can close a wall the constraint did
    not yet see, and no later iterate is feasible again, so the RGP's best is its start
    and the start's outside points stay. A default ``t_min`` is only what the start's
    walls could keep (:func:`_default_t_min`), and a start that cannot keep it through one
    step is one whose walls nearly touch: as there, the constraint is left off and the
    crossing hold-back after the RGP keeps the walls apart. Whether a shorter step would
    find a feasible iterate turns on the last bits of the start (the same cage with other
    target samples ends either way), and where it finds one it is at the first step or
    two, with most of the start's outside points left. A ``t_min`` that was asked for is
    kept, and a shorter step leaves much less outside than the start.

    Returns
    -------
    result : core.fitting.rgp.RGPResult, ``iterations`` counting both runs.
    problem : FitProblem, the problem of the run returned (``t_min`` 0 when it was dropped).
    retried : bool, the RGP ran again.
    """
    result = run_rgp(problem, vertices, step, iterations=iterations, **options)
    outside = result.history["packaging"][0] * problem.area / problem.mapping.shape[0]
    if result.iterations and result.best_iteration == 0 and problem.t_min > 0 \
            and result.iterations < iterations and outside > FIT.retry_outside * target_volume:
        first = result.iterations
        if defaulted:
            problem = problem.with_t_min(0.0)
        else:
            step = FIT.retry_step * step
        result = run_rgp(problem, vertices, step, iterations=iterations - first, **options)
        result.iterations += first
        return result, problem, True
    return result, problem, False


def _polished(problem, result, step, iterations, options):
    """The RGP's result continued by ``FIT.polish_halvings`` runs, each from the best design
    of the run before with half its step, while the budget of ``iterations`` (counting
    ``result.iterations``) lasts.

    The step rule moves every base vertex by about the step in each iteration, so a run's
    best design lies about a step inside the target where it touches it, and which
    iterate is best turns on small changes of the start; a run with half the step from
    there moves the surface back out by about half of that, and its best design is never
    worse by the objective than its start. Continuing the step towards zero this way
    (instead of a single step that decides both how far the fit travels and how close it
    ends) brings the mean distance down, and fits of the same cage from slightly different
    starts end closer together. A run whose best design is its start is not continued:
    that start leaves little of the volume outside (:func:`_rgp`), and shorter steps from
    it would trade mean distance for that little.

    Returns
    -------
    result : core.fitting.rgp.RGPResult, the last run's best design, ``iterations``
        counting all runs, ``history`` the evaluations of all runs in order (each run's
        first is the best design of the one before) and ``best_iteration`` the index there.
    step : float, the last run's step (model units).
    polish : list of int, iterations of each further run.
    """
    polish, used = [], result.iterations
    for _ in range(FIT.polish_halvings):
        if used >= iterations or result.best_iteration == 0:
            break
        step *= 0.5
        again = run_rgp(problem, result.vertices, step, iterations=iterations - used,
                        **options)
        used += again.iterations
        polish.append(again.iterations)
        offset = len(result.history["objective"])
        history = {key: result.history.get(key, []) + again.history[key]
                   for key in again.history}
        result = replace(again, iterations=used, history=history,
                         best_iteration=offset + again.best_iteration)
    return result, step, polish


def _passes_around_crossings(problem, held, moved, T, step, budget, options):
    """Further RGP passes from a result held back where it crossed itself, the held-back
    base vertices fixed.

    The RGP does not see crossings: on a thin plate of a coarse cage it pulls the two walls
    through each other within a few iterations, and the hold-back
    (:func:`core.fitting.crossings.hold_back_crossings`) puts the vertices there back
    towards the start, which lies partly outside. From the held-back result the RGP runs
    again with those vertices fixed, so the others can still move in; its result is held
    back the same way, and the vertices cut then are fixed too, until a pass holds nothing
    back, ``FIT.rgp_passes`` passes ran or the iteration budget is spent (on a thin plate the
    later passes bring in part of what the first left outside).

    Parameters
    ----------
    problem : FitProblem; held : (n, 3) float64 the held-back result, its fine mesh clean;
    moved : (n, 3) float64 the RGP's result it was held back from; T : fine triangles;
    step : float, RGP step (model units); budget : int, RGP iterations left;
    options : dict of further :func:`core.fitting.rgp.run_rgp` arguments.

    Returns
    -------
    vertices : (n, 3) float64, its fine mesh clean.
    passes : list of [iterations, held back base vertices], one per pass.
    iterations : int, RGP iterations of the passes.
    fixed : (n,) bool, the base vertices held back in the first hold-back or a pass.
    """
    fixed = (held != moved).any(axis=1)
    passes, used = [], 0
    while len(passes) < FIT.rgp_passes and used < budget:
        again = run_rgp(problem, held, step, iterations=budget - used, fixed=fixed, **options)
        used += again.iterations
        vertices, _, count = _held_back(held, 0, again.vertices, problem.mapping, T)
        passes.append([again.iterations, count])
        fixed |= (vertices != again.vertices).any(axis=1)
        held = vertices
        if not count:
            break
    return held, passes, used, fixed


WARM_START = "best-fit from the fit of the cage this one refines"
"""The inside fit of a refined cage (:mod:`core.fitting.outside_refinement`) starts its
least-squares fit from the least-squares fit of the cage it refines, placed on the refined
cage, and runs ``FIT.warm_rounds`` rounds on the fit's level only: the coarse level's large
moves were made in the first fit, and the refined strips start on its limit surface. Its
pull inside starts with the smoothness weights that fit's pull ended with (stiffer where the
walls of a thin plate were pulled through each other) and makes ``FIT.warm_pull_tries``
stiffer pulls (:func:`_pulled_inside`). The RGP and the hold-backs run as from a cold
start."""


CREASED_START = "crease-fitted cage"
"""The inside fit of a cage with creases starts from the cage with its crease curves fitted
to the target's feature lines (:func:`core.fitting.crease_curves.fit_crease_curves`), pulled
inside once, instead of from a least-squares fit. On creased cages the least-squares fit
crosses itself at the creases, and holding it back there returns most of the base vertices
to that cage anyway, while its rounds and crossing searches cost a third of the fit; stiffer
pulls do not untangle it either. The crease-curve start reaches a comparable fit in less
time, and without samples of the target it does not depend on the seed."""


def _untangled(base, setup, vertices, rounds, seed, refit_local=True):
    """The least-squares fit made not to cross itself where a refit or the cage allows.

    Refits with a stiffer smoothness term under the crossings
    (:func:`core.fitting.crossings.stiffen_until_clean`), each from the fit before it and on
    the fit's level only (``FIT.fine_rounds`` rounds: the stiffer term changes the fit only
    near the crossings, so the coarse rounds' large moves need not be made again). If they
    do not reach a clean fit, the refits are made again the long way, each a whole
    two-level fit from the cage (``cold_refit_crossings``), and the fit with fewer
    crossings is kept: stiffening from a crossing fit can bring its crossings back.
    The long way is taken only when the short way took most crossings off
    (``FIT.long_way_left``). Either way the refits stop once one takes less than
    ``UNTANGLE.progress`` off the fewest crossings of a fit still far from clean (the
    creased cages' fits cross in a hundred pairs or more, and stiffening does not untangle
    them). With ``refit_local=False`` (the inside fit) there are no refits when at most
    ``FIT.spread_crossings`` of the base vertices influence the first fit's crossings. If the fit
    still crosses and the cage's limit surface does not, the fit is held back towards the
    cage there (:func:`core.fitting.crossings.hold_back_crossings`); a cage that crosses
    itself is no reference to hold back to (nearly every base vertex would go back).

    Parameters
    ----------
    base : PolyMesh, the cage (its crease curves fitted); setup : FitSetup;
    vertices : (n, 3) float64 the least-squares fit; rounds, seed : of the least-squares fit.

    Returns
    -------
    core.fitting.records.Untangling
    """
    limit_map, T, target = setup.limit_map, setup.triangles, setup.target

    def refit(stiffness, previous):
        return best_fit(base, limit_map, T, target, rounds=min(rounds, FIT.fine_rounds),
                        seed=seed, start=previous, stiffness=stiffness, refit=True).vertices

    def cold_refit(stiffness, previous):
        return _two_level_best_fit(base, setup.hierarchy, limit_map, T, target, rounds,
                                   stiffness, seed)[0].vertices

    first = crossing_pairs(limit_map, T, vertices)
    refitted = refit_local or (len(influencing(first, limit_map, T))
                               > FIT.spread_crossings * len(vertices))
    tries = UNTANGLE.stiffen_tries if refitted else 0
    untangled = stiffen_until_clean(vertices, refit, limit_map, T, tries=tries, pairs=first,
                                    progress=UNTANGLE.progress)
    cold_counts = None
    if tries and 0 < untangled.crossings <= FIT.long_way_left * untangled.counts[0]:
        cold = stiffen_until_clean(vertices, cold_refit, limit_map, T, pairs=first,
                                   progress=UNTANGLE.progress)
        cold_counts = cold.counts
        if cold.crossings < untangled.crossings:
            untangled = cold
    vertices, crossings, held, cage = untangled.vertices, untangled.crossings, 0, None
    if crossings:
        cage = count_crossings(limit_map, T, base.vertices)
        if cage == 0:
            vertices, crossings, held = _held_back(base.vertices, 0, vertices, limit_map, T,
                                                   untangled.pairs)
    return Untangling(vertices, crossings, untangled.stiffness, untangled.refits,
                      untangled.counts, cold_counts, int((untangled.stiffness > 1).sum()),
                      held, cage)


def _held_back(reference, crossings, moved, mapping, T, moved_pairs=None):
    """``moved`` held back towards ``reference`` where it crosses itself and the reference
    does not (:func:`core.fitting.crossings.hold_back_crossings`).

    crossings : int or None, crossing pairs of the reference's fine mesh (None: unknown).
    moved_pairs : (k, 2) int64 or None, the crossing pairs of ``moved``'s fine mesh if known.

    Returns
    -------
    vertices : (n, 3) float64; crossings : int, crossing pairs of their fine mesh;
    held : int, base vertices held back.
    """
    vertices, held, crossings = hold_back_crossings(reference, moved, mapping, T,
                                                    clean=crossings == 0, moved_pairs=moved_pairs)
    return vertices, crossings, held


def _pulled_inside(base, limit_map, T, target, vertices, stiffness, carried=None):
    """The least-squares fit pulled just inside the target (:func:`pull_inside`, with the
    fit's smoothness weights ``stiffness``), made stiffer where the pull crosses itself;
    with ``stiffness=None`` (a creased cage's own start, ``CREASED_START``) pulled once, with
    the plain smoothness term. ``carried`` ((n,) float64 or None, the weights the pull of
    the fit of a cage that this one refines ended with, ``WARM_START``) multiplies the
    weights, and at most ``FIT.warm_pull_tries`` stiffer pulls follow: the pull starts stiff
    where that fit's pull crossed, so it crosses in far fewer pairs than a pull with the
    plain term, and one stiffer pull leaves fewer than four from the plain term do.

    Where the pull's limit surface crosses itself (the two walls of a thin plate pulled
    through each other by a coarse cage's wide stencils), it is made again with the
    smoothness term stiffer there (:func:`core.fitting.crossings.stiffen_until_clean`,
    each pull from ``vertices``), so that less of it has to be held back and less of the
    target's volume is left outside after the hold-back.

    Returns
    -------
    pulled : core.fitting.crossings.Untangled, the pull with the fewest crossings.
    margin : float, the depth pulled to (model units).
    crossings : list of int, crossing pairs of the pull and of each stiffer pull.
    weights : (n,) float64 or None, the smoothness weights of the pull kept (None: the plain
        term of a creased cage's start).
    """
    start = target.closest(limit_map @ vertices)
    margin = FIT.inside_margin * float(np.sqrt(np.mean(start.signed ** 2)))
    weights = np.ones(len(vertices)) if stiffness is None else stiffness
    tries = 0 if stiffness is None else UNTANGLE.stiffen_tries
    if carried is not None and stiffness is not None:
        weights, tries = weights * carried, min(tries, FIT.warm_pull_tries)

    def pull(extra, previous=None):
        return pull_inside(base, limit_map, target, vertices, margin, FIT.inside_rounds,
                           stiffness=weights * extra, start_closest=start)

    pulled = stiffen_until_clean(pull(np.ones(len(vertices))), pull, limit_map, T,
                                 tries=tries)
    kept = None if stiffness is None else weights * pulled.stiffness
    return pulled, margin, pulled.counts, kept


def _two_level_best_fit(base, hierarchy, limit_map, T, target, rounds, stiffness=None, seed=0):
    """Least-squares fit: up to ``rounds - FIT.fine_rounds`` rounds on the level-1 limit
    points (a quarter of the points; the large moves), then the rest of the ``rounds`` (at
    least ``FIT.fine_rounds``) on the fit's level: 8 + 2 rounds reach a lower mean distance
    than 10 level-2 rounds in about half the time. Where the level-1 rounds converge early
    the fit's level gets the rounds they left: holding it to ``FIT.fine_rounds`` leaves the
    inside fit that follows more of the volume outside on thin-walled parts.

    Returns
    -------
    fine, coarse : BestFitResult of the two stages (``coarse`` has 0 rounds when the fit
        itself is on level 1 or ``rounds <= FIT.fine_rounds``).
    """
    levels = len(hierarchy.meshes) - 1
    coarse_rounds = rounds - FIT.fine_rounds if levels > 1 else 0
    if coarse_rounds > 0:
        coarse_mesh = hierarchy.meshes[1]
        coarse_map = (limit_matrices(coarse_mesh)[0] @ hierarchy.composite(0)).tocsr()
        coarse = best_fit(base, coarse_map,
                          triangulate(coarse_mesh.face_vertices, coarse_mesh.face_offsets),
                          target, rounds=coarse_rounds, stiffness=stiffness, seed=seed)
    else:
        coarse = BestFitResult(np.asarray(base.vertices, dtype=np.float64), 0, [], "rounds")
    fine = best_fit(base, limit_map, T, target, rounds=rounds - coarse.rounds,
                    start=coarse.vertices, stiffness=stiffness, seed=seed)
    return fine, coarse


def _distances(X, T, target, points):
    """Both one-sided distances between the fine limit surface and the target.

    Parameters
    ----------
    X : (n, 3) float64 fine limit points; T : (t, 3) int64 their triangles.
    target : TargetSurface; points : (FIT.distance_samples, 3) float64 area-weighted samples of
        it (drawn once per fit, for the result's figures and the cage's).

    Returns
    -------
    core.fitting.records.Distances, fractions of the target's bounding-box diagonal:
    ``mean_distance`` / ``max_distance``, the fine limit points to the target;
    ``target_mean_distance`` / ``target_max_distance``, ``FIT.distance_samples``
    area-weighted target samples (the maximum also over the target's vertices) to the
    triangulated limit surface: what the surface misses, such as a thin horn's tip the
    limit surface stops short of.
    """
    forward = target.nearest(X).distance / target.diagonal
    fitted = TargetSurface(X, T, "fitted surface")
    back = fitted.nearest(points)
    backward = back.distance / target.diagonal
    largest = float(backward.max())
    vertices = target.vertices[_may_be_farther(target.vertices, np.vstack([X, back.point]),
                                               largest * target.diagonal, target.diagonal)]
    if len(vertices):
        largest = max(largest, float((fitted.nearest(vertices).distance
                                      / target.diagonal).max()))
    return Distances(float(forward.mean()), float(forward.max()), float(backward.mean()),
                     largest)


def _may_be_farther(points, on_surface, distance, diagonal):
    """(k,) bool: the ``points`` ((k, 3)) whose distance to a surface may exceed
    ``distance`` (model units).

    A point of the surface (``on_surface``, (s, 3), such as the fine limit points and the
    closest points of the samples) bounds the distance from above, so a target vertex nearer
    than ``distance`` to one of them cannot raise the maximum and is not queried
    (``core.tolerances.CONTACT * diagonal`` of slack for the rounding of those points): on a
    fine target the query of the rest costs a fraction of the query of all.
    """
    bound, _ = cKDTree(on_surface).query(points)
    return bound > distance - CONTACT * diagonal


def _check_parameters(levels, iterations, t_min, mode, penalty, step_fraction):
    """Raise ParameterError naming the first of these parameters out of range."""
    if not isinstance(levels, (int, np.integer)) or not 1 <= levels <= 4:
        raise ParameterError(f"levels must be an integer in 1..4, got {levels!r}")
    if not isinstance(iterations, (int, np.integer)) or iterations < 0:
        raise ParameterError(f"iterations must be an integer >= 0, got {iterations!r}")
    if t_min is not None and not (np.isfinite(t_min) and t_min >= 0):
        raise ParameterError(f"t_min must be None or a finite number >= 0, got {t_min!r}")
    if mode not in MODES:
        raise ParameterError(f"mode must be one of {MODES}, got {mode!r}")
    if not (np.isfinite(penalty) and penalty > 0):
        raise ParameterError(f"penalty must be a finite number > 0, got {penalty!r}")
    if not (np.isfinite(step_fraction) and 0 < step_fraction <= 1):
        raise ParameterError(f"step_fraction must be in (0, 1], got {step_fraction!r}")


def _check_choices(surface, start, rounds, tol, patience):
    """Raise ParameterError naming the first of these parameters out of range."""
    if surface not in SURFACES:
        raise ParameterError(f"surface must be one of {SURFACES}, got {surface!r}")
    if start not in STARTS:
        raise ParameterError(f"start must be one of {STARTS}, got {start!r}")
    if not isinstance(rounds, (int, np.integer)) or rounds < 0:
        raise ParameterError(f"rounds must be an integer >= 0, got {rounds!r}")
    if not (np.isfinite(tol) and tol >= 0) or not (isinstance(patience, (int, np.integer))
                                                   and patience >= 1):
        raise ParameterError(f"tol must be >= 0 and patience an integer >= 1, got {tol!r}, "
                             f"{patience!r}")


def _check_base(base):
    if not isinstance(base, PolyMesh):
        raise ParameterError(f"base must be a PolyMesh, got {type(base).__name__}")
    V = np.asarray(base.vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise InvalidMeshError(f"base: vertices must be a non-empty (n, 3) array, got shape "
                               f"{V.shape}", "format")
    bad = np.flatnonzero(~np.isfinite(V).all(axis=1))
    if len(bad):
        raise InvalidMeshError(f"base: {len(bad)} vertices have non-finite coordinates, "
                               f"e.g. {bad[:5].tolist()}", "non_finite", len(bad), bad[:5])
    return V


def _mean_edge_length(mesh):
    fv, fo = mesh.face_vertices, mesh.face_offsets
    nxt = next_corners(fo)
    pairs = np.unique(np.sort(np.stack([fv, fv[nxt]], axis=1), axis=1), axis=0)
    V = mesh.vertices
    return float(np.linalg.norm(V[pairs[:, 0]] - V[pairs[:, 1]], axis=1).mean())


def _area(X, T):
    return float(face_areas(X, T).sum())


def _default_t_min(X, T, edge):
    """``min(0.1 * edge, 0.5 * thinnest wall)``, walls measured up to ``0.2 * edge``; 0 where
    the thinnest wall is below ``FIT.near_touch * edge``.

    A start whose walls nearly touch (where a crossing was held back just far enough,
    :func:`core.fitting.crossings.hold_back_crossings`) cannot keep a constraint that thin:
    the first RGP step closes it, no later iterate is feasible and the RGP's result is its
    start, leaving more of the volume outside than without the constraint. The crossing
    hold-back after the RGP keeps the walls apart instead.
    """
    cap = 0.1 * edge
    found = thickness(X, T, 2.0 * cap).thickness.min()
    if found < FIT.near_touch * edge:
        return 0.0
    return float(min(cap, 0.5 * found))
