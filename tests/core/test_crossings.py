# SPDX-License-Identifier: LGPL-2.1-or-later
"""A fitted limit surface never crosses itself: refits, hold-back, and the solid's refusal."""
import os
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from core.errors import ExportError
from core.fitting import crossings, fit_base_mesh
from core.fitting.crossings import (UNTANGLE, hold_back_crossings, influencing,
                                    stiffen_until_clean)
from core.geometry import triangulate
from core.params import ReconstructionParams
from core.pipeline import reconstruct, run_stages
from core.progress import NO_PROGRESS
from core.quadmesh.decimation.paired_decimation import paired_decimation_base_mesh
from core.self_intersection import box_pairs, face_boxes, find_self_intersections
from core.subdivision.limit_crossings import export_limit_crossings
from core.stages.patches import run_patches
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices
from core.subdivision.sample_cages import cube, torus
from core.types import FitResult, PipelineState

from tests.core.dev_meshes import MESHES, load_dev_mesh


def icosphere(subdivisions=2):
    mesh = trimesh.creation.icosphere(subdivisions)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def pushed_through(V, vertex):
    """``V`` with one vertex pushed through the far side of the unit sphere."""
    W = V.copy()
    W[vertex] = -1.5 * V[vertex]
    return W


def test_hold_back_keeps_the_reference_crossings_and_adds_none():
    V, T = icosphere()                         # 162 vertices; the mapping is the identity
    M = sp.identity(len(V), format="csr")
    reference = pushed_through(V, 0)           # the reference already crosses itself
    allowed = find_self_intersections(reference, T)
    assert len(allowed)
    moved = pushed_through(reference, 80)      # one more crossing, and a harmless move
    away = (np.abs(V @ V[0]) < 0.5) & (np.abs(V @ V[80]) < 0.5)   # far from both spikes
    moved[away] *= 1.02
    assert len(find_self_intersections(moved, T)) > len(allowed)
    held, count, crossings = hold_back_crossings(reference, moved, M, T, clean=False)
    result = find_self_intersections(held, T)
    assert crossings == len(result) <= len(allowed)
    assert {tuple(p) for p in result} <= {tuple(p) for p in allowed}
    assert 1 <= count <= 0.1 * len(V)
    kept = np.linalg.norm(held - moved, axis=1) < 1e-12
    assert kept.sum() == len(V) - count        # every other vertex keeps its whole move
    # the moved mesh's crossing pairs handed in: the same hold-back
    again = hold_back_crossings(reference, moved, M, T, clean=False,
                                moved_pairs=find_self_intersections(moved, T))
    np.testing.assert_array_equal(again[0], held)
    assert again[1:] == (count, crossings)


def test_crossings_among_marked_faces_are_the_full_search_restricted_to_them():
    V, T = icosphere()
    W = pushed_through(pushed_through(V, 0), 80)    # two spikes, far apart
    every = find_self_intersections(W, T)
    marked = np.zeros(len(T), dtype=bool)
    marked[np.flatnonzero((T == 80).any(axis=1))] = True
    expected = every[marked[every].any(axis=1)]
    assert 0 < len(expected) < len(every)
    np.testing.assert_array_equal(find_self_intersections(W, T, among=marked), expected)
    assert len(find_self_intersections(W, T, among=np.zeros(len(T), dtype=bool))) == 0


def test_hold_back_rechecking_only_what_moved_agrees_with_full_searches(monkeypatch):
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    moved = pushed_through(pushed_through(V, 5), 120)
    moved[(np.abs(V @ V[5]) < 0.5) & (np.abs(V @ V[120]) < 0.5)] *= 1.02
    quick = hold_back_crossings(V, moved, M, T)
    monkeypatch.setattr(crossings, "_crossings_after",
                        lambda X, triangles, pairs, mapping, changed, candidates:
                        find_self_intersections(X, triangles))
    full = hold_back_crossings(V, moved, M, T)
    np.testing.assert_array_equal(quick[0], full[0])
    assert quick[1:] == full[1:] and quick[2] == 0 and quick[1] >= 2


def test_hold_back_tests_only_the_moving_triangles_from_the_first_round(monkeypatch):
    """A reference that crosses itself and a move of a few vertices: the first round
    searches only the triangles around the moving vertices, and the result is the one of
    full searches in every round."""
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    reference = pushed_through(V, 5)              # crosses itself (allowed: clean=False)
    moved = pushed_through(reference, 120)
    assert (moved != reference).any(axis=1).sum() == 1
    searched = []
    real = crossings.find_self_intersections

    def recording(X, triangles, among=None, candidates=None):
        searched.append(len(triangles) if among is None else int(among.sum()))
        return real(X, triangles, among, candidates)

    monkeypatch.setattr(crossings, "find_self_intersections", recording)
    quick = hold_back_crossings(reference, moved, M, T, clean=False)
    assert searched[0] == len(T)                  # the reference's own pairs, once
    assert 0 < searched[1] <= 6                   # the one-ring of vertex 120
    monkeypatch.setattr(crossings, "_crossings_after",
                        lambda X, triangles, pairs, mapping, changed, candidates:
                        real(X, triangles))
    full = hold_back_crossings(reference, moved, M, T, clean=False)
    np.testing.assert_array_equal(quick[0], full[0])
    assert quick[1:] == full[1:] and quick[1] == 1


def test_swept_pairs_hold_every_pair_overlapping_on_the_way_and_find_the_same_crossings():
    """On a torus cage's level-2 limit surface, a random move of half the base vertices
    (the other half keeps its place): the triangle pairs whose swept boxes overlap include
    those overlapping at any per-vertex fractions, but for the pairs sharing an edge and
    those that no moving vertex influences, and the crossing search among them finds what
    the full search finds."""
    cage = torus()
    hierarchy = build_hierarchy(cage, 2)
    fine = hierarchy.meshes[2]
    M = (limit_matrices(fine)[0] @ hierarchy.composite(1)).tocsr()
    T = triangulate(fine.face_vertices, fine.face_offsets)
    rng = np.random.default_rng(3)
    reference = cage.vertices
    moved = reference + rng.normal(scale=0.6, size=reference.shape)
    moved[:len(moved) // 2] = reference[:len(moved) // 2]
    swept = crossings._swept_pairs(reference, moved, M, T)
    known = {tuple(p) for p in swept}
    still = np.asarray(abs(M) @ (moved != reference).any(axis=1)).ravel() == 0
    apart = still[T].all(axis=1)
    assert apart.any()
    edge_pairs = 0
    found = 0
    for fraction in (np.zeros(len(reference)), np.ones(len(reference)),
                     *rng.random((4, len(reference)))):
        X = M @ (reference + fraction[:, None] * (moved - reference))
        now = box_pairs(*face_boxes(X[T]))
        shared = (T[now[:, 0]][:, :, None] == T[now[:, 1]][:, None, :]).sum(axis=(1, 2))
        left_out = (shared == 2) | apart[now].all(axis=1)
        edge_pairs += int((shared == 2).sum())
        assert {tuple(p) for p in now[~left_out]} <= known
        every = find_self_intersections(X, T)
        found += len(every)
        np.testing.assert_array_equal(find_self_intersections(X, T, candidates=swept), every)
        marked = rng.random(len(T)) < 0.2
        np.testing.assert_array_equal(
            find_self_intersections(X, T, among=marked, candidates=swept),
            find_self_intersections(X, T, among=marked))
    assert found > 0 and edge_pairs > 0 and len(swept) < len(T) * (len(T) - 1) // 4


def test_hold_back_halves_a_mover_that_owns_none_of_the_crossing_corners():
    """Two tetrahedra of fine points: A's are base vertices 0-3, B's are 0.6 of base
    vertices 4-7 plus 0.4 of a driver, base vertex 8, which owns no fine point. Moving only
    the driver carries B into A; halving the crossing corners' owners changes nothing (they
    do not move), so the driver's move is halved instead, once, and half of it is kept."""
    tet = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    T = np.vstack([faces, faces + 4])
    rows = np.r_[np.arange(8), np.arange(4, 8)]
    cols = np.r_[np.arange(8), np.full(4, 8)]
    weights = np.r_[np.ones(4), np.full(4, 0.6), np.full(4, 0.4)]
    M = sp.csr_matrix((weights, (rows, cols)), shape=(8, 9))
    V = np.vstack([tet, (tet + [3.0, 0.2, 0.2]) / 0.6, np.zeros((1, 3))])
    moved = V.copy()
    moved[8] = [-7.0, 0.0, 0.0]                    # B shifted by -2.8 in x, through A
    assert len(find_self_intersections(M @ V, T)) == 0
    assert len(find_self_intersections(M @ moved, T)) > 0
    held, count, crossings = hold_back_crossings(V, moved, M, T)
    assert crossings == 0 and count == 1
    np.testing.assert_array_equal(held[:8], V[:8])
    np.testing.assert_allclose(held[8], [-3.5, 0.0, 0.0], atol=1e-12)


def test_stiffen_until_clean_stiffens_only_under_the_crossings():
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    crossing = pushed_through(V, 5)
    under = influencing(find_self_intersections(crossing, T), M, T)
    calls = []

    def refit(stiffness, previous):            # "the fit": clean once vertex 5 is stiff
        calls.append((stiffness.copy(), previous.copy()))
        return V.copy() if stiffness[5] > 1 else crossing

    untangled = stiffen_until_clean(crossing, refit, M, T)
    assert untangled.crossings == 0 and untangled.refits == 1 == len(calls)
    assert untangled.counts[0] > 0 and untangled.counts[-1] == 0
    assert np.array_equal(np.flatnonzero(calls[0][0] > 1), under)
    assert np.all(calls[0][0][under] == UNTANGLE.stiffen)
    np.testing.assert_array_equal(calls[0][1], crossing)   # started from the crossing fit
    np.testing.assert_array_equal(untangled.vertices, V)


def test_stiffen_until_clean_keeps_the_fit_with_fewest_crossings():
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    one, two = pushed_through(V, 5), pushed_through(pushed_through(V, 5), 120)
    three = pushed_through(pushed_through(V, 7), 120)
    fits = iter([two, three, two])              # each refit crosses somewhere else
    untangled = stiffen_until_clean(one, lambda stiffness, previous: next(fits), M, T, tries=3)
    assert untangled.refits == 3 and len(untangled.counts) == 4
    assert untangled.crossings == untangled.counts[0] == min(untangled.counts)
    np.testing.assert_array_equal(untangled.vertices, one)
    assert np.all(untangled.stiffness == 1.0)  # the weights of the fit that was kept


def test_stiffen_until_clean_stops_when_a_stiffer_refit_crosses_at_the_same_triangles():
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    one, two = pushed_through(V, 5), pushed_through(pushed_through(V, 5), 120)
    calls = []

    def refit(stiffness, previous):             # stiffening never untangles vertex 120
        calls.append(stiffness.copy())
        return two

    untangled = stiffen_until_clean(one, refit, M, T, tries=4)
    assert len(calls) == 2 and untangled.refits == 2
    assert untangled.counts[1] == untangled.counts[2] > untangled.counts[0]
    np.testing.assert_array_equal(untangled.vertices, one)


def test_stiffen_until_clean_stops_when_a_refit_of_a_tangled_fit_takes_too_little_off():
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    spikes = [pushed_through(pushed_through(V, a), b)        # 38 pairs each
              for a, b in ((5, 120), (7, 80), (0, 80), (7, 120))]
    counts = [len(find_self_intersections(W, T)) for W in spikes]
    assert len(set(counts)) == 1 and counts[0] > UNTANGLE.few_crossings

    def refits(fits):
        fits = iter(fits)                       # each refit crosses elsewhere, as much
        return lambda stiffness, previous: next(fits)

    stalled = stiffen_until_clean(spikes[0], refits(spikes[1:]), M, T, tries=3,
                                  progress=UNTANGLE.progress)
    assert stalled.refits == 1 and stalled.counts == counts[:2]
    np.testing.assert_array_equal(stalled.vertices, spikes[0])
    assert stiffen_until_clean(spikes[0], refits(spikes[1:]), M, T, tries=3).refits == 3
    # a few crossings (one spike, 10 pairs) are worth every refit, progress or not
    few = [pushed_through(V, vertex) for vertex in (5, 7, 9, 80)]
    assert stiffen_until_clean(few[0], refits(few[1:]), M, T, tries=3,
                               progress=UNTANGLE.progress).refits == 3


def test_stiffen_until_clean_goes_on_without_progress_once_the_fit_is_near_clean():
    V, T = icosphere()
    M = sp.identity(len(V), format="csr")
    two = pushed_through(pushed_through(V, 5), 120)
    fits = iter([pushed_through(V, 5), pushed_through(V, 7), V])
    untangled = stiffen_until_clean(two, lambda stiffness, previous: next(fits), M, T,
                                    tries=3, progress=UNTANGLE.progress)
    counts = untangled.counts
    # the second refit took nothing off
    assert counts[1] == counts[2] <= UNTANGLE.tangled * counts[0]
    assert untangled.refits == 3 and untangled.crossings == 0
    np.testing.assert_array_equal(untangled.vertices, V)


@pytest.fixture(scope="module")
def idler():
    """idler_riser and its paired-decimation cage (280 faces, about the pipeline's 300), whose
    plain least-squares fit crosses itself."""
    target = load_dev_mesh("idler_riser.stl")
    cage = paired_decimation_base_mesh(target.vertices, target.faces, 280).mesh
    return target, cage


@pytest.fixture(scope="module")
def idler_290(idler):
    """idler_riser and its 290-face paired-decimation cage, whose inside fit keeps its start
    at the RGP's first run."""
    target, _ = idler
    return target, paired_decimation_base_mesh(target.vertices, target.faces, 290).mesh


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["best-fit", "inside"])
def test_fit_of_a_decimation_cage_on_a_thin_part_does_not_cross_itself(idler, mode):
    target, cage = idler
    fitted, info = fit_base_mesh(cage, target, mode=mode)
    # the plain least-squares fit pulls thin walls through each other here
    assert info.least_squares.untangled.refit_crossings[0] > 0
    assert info.self_intersections == 0
    assert export_limit_crossings(fitted).count == 0      # the export's own check agrees
    # closeness is kept: best-fit at most half the unfitted mean distance (inside mode, one
    # sided, 0.7), the largest distance no worse than the cage's
    assert info.figures.distances.mean_distance <= (0.5 if mode == "best-fit" else 0.7) * \
        info.figures.initial.mean_distance
    assert info.figures.distances.max_distance <= info.figures.initial.max_distance
    if mode == "inside":
        assert info.figures.outside_volume_fraction <= 0.01


@pytest.mark.slow
def test_the_inside_fit_ends_clean_and_inside_whether_crossings_count_as_local_or_spread(
        idler, monkeypatch):
    """idler_riser's least-squares fit crosses itself. Local crossings are held back towards the
    cage, spread ones refitted stiffer first (``FitSettings.spread_crossings`` decides
    which); with the fraction at its default and at 0 (every crossing spread) the inside fit
    ends with a limit surface that does not cross itself and little of the volume
    outside."""
    import core.fitting.fit as fit_module

    target, cage = idler
    _, info = fit_base_mesh(cage, target, mode="inside", seed=1)
    # the least-squares start crosses itself
    assert info.least_squares.untangled.refit_crossings[0] > 0
    assert info.self_intersections == 0 and info.figures.outside_volume_fraction <= 0.01
    monkeypatch.setattr(fit_module, "FIT", replace(fit_module.FIT, spread_crossings=0.0))
    fitted, spread = fit_base_mesh(cage, target, mode="inside", seed=1)
    assert spread.self_intersections == 0 and export_limit_crossings(fitted).count == 0
    assert spread.figures.outside_volume_fraction <= 0.01


@pytest.mark.slow
@pytest.mark.parametrize("left, long_way", [(10, True), (40, False)])
def test_the_long_refits_run_only_after_the_short_ones_took_most_crossings_off(
        idler, monkeypatch, left, long_way):
    """The short untangling refits are made to report ``left`` of 100 crossing pairs: the long
    way (whole two-level refits from the cage) runs at 10 (within
    ``FitSettings.long_way_left`` of the first fit's pairs, where it cleared the rest on the
    dev meshes) and not at 40 (where it never had fewer); either way the result does not
    cross itself."""
    import core.fitting.fit as fit_module

    assert 10 <= fit_module.FIT.long_way_left * 100 < 40
    real = fit_module.stiffen_until_clean
    refits = []

    def reported(vertices, refit, mapping, triangles, **options):
        refits.append(refit.__name__)
        untangled = real(vertices, refit, mapping, triangles, **options)
        if refit.__name__ == "refit":
            untangled.crossings, untangled.counts = left, [100, left]
        return untangled

    monkeypatch.setattr(fit_module, "stiffen_until_clean", reported)
    target, cage = idler
    _, info = fit_base_mesh(cage, target, mode="best-fit")
    assert refits[0] == "refit"
    assert ("cold_refit" in refits) == long_way
    assert (info.least_squares.untangled.cold_refit_crossings is not None) == long_way
    assert info.self_intersections == 0


@pytest.mark.slow
def test_the_rgp_retry_with_a_shorter_step_ends_clean_and_inside(idler_290, monkeypatch):
    """Where the RGP's first run keeps its start and that start leaves more than
    ``FitSettings.retry_outside`` of the volume outside, the RGP runs again with a shorter
    step. With the threshold at its default and at 0 (every kept start retried) the fit of
    idler_riser's decimation cage ends clean and with little of the volume outside, and the
    retry never leaves more outside than the start it replaces."""
    import core.fitting.fit as fit_module

    target, cage = idler_290
    fitted, kept = fit_base_mesh(cage, target)
    assert kept.self_intersections == 0 and kept.figures.outside_volume_fraction <= 0.01
    monkeypatch.setattr(fit_module, "FIT", replace(fit_module.FIT, retry_outside=0.0))
    _, again = fit_base_mesh(cage, target)
    assert again.self_intersections == 0 and again.figures.outside_volume_fraction <= 0.01
    assert again.figures.distances.mean_distance <= again.figures.initial.mean_distance


def spindle_torus():
    """A torus whose tube is wider than its hole: its limit surface crosses itself."""
    return torus(major_radius=0.5, minor_radius=1.0)


def test_patches_refuse_a_crossing_fitted_cage_and_say_where():
    fit = FitResult(spindle_torus(), levels=2, cage_self_intersections=7)
    with pytest.raises(ExportError, match="intersects itself") as raised:
        run_patches(fit, ReconstructionParams(), NO_PROGRESS)
    message = str(raised.value)
    assert "between base faces" in message and " near (" in message
    assert "already crosses itself (7 pairs at the fit's level 2)" in message


def test_the_runner_records_the_refusal_as_a_failed_stage():
    state = PipelineState(fit=FitResult(spindle_torus(), levels=2))
    state, report, failed = run_stages(state, ["patches"], ReconstructionParams())
    assert isinstance(failed, ExportError)
    assert report["stages"]["patches"]["status"] == "failed"
    assert "intersects itself" in report["stages"]["patches"]["message"]
    assert state.patches is None


def test_patches_of_a_clean_cage_are_built():
    result = run_patches(FitResult(cube(), levels=2), ReconstructionParams(), NO_PROGRESS)
    assert result.patches.info  # the export ran
    assert export_limit_crossings(cube()).count == 0


def test_the_export_checks_at_the_fits_level_up_to_large_cages():
    from core.subdivision.limit_crossings import EXPORT_CHECK_LEVELS, FIT_FACE_BUDGET, fit_levels
    from core.subdivision.sample_cages import grid_sphere

    # 864 faces: the fit works at level 2, and so does the check (a level-1 check would
    # refuse cages the fit found clean)
    medium = grid_sphere(12)
    assert medium.n_faces == 864
    assert fit_levels(medium.n_faces, EXPORT_CHECK_LEVELS) == EXPORT_CHECK_LEVELS == 2
    crossings = export_limit_crossings(medium)
    assert crossings.levels == 2 and crossings.count == 0
    # beyond the fit's budget at level 2, both take one level
    large = grid_sphere(21)
    assert large.n_faces * 16 > FIT_FACE_BUDGET
    assert export_limit_crossings(large).levels == fit_levels(large.n_faces, 2) == 1


@pytest.mark.slow
def test_the_fit_stage_types_the_levels_and_the_cages_crossings():
    """The patches stage reads ``levels`` and ``cage_self_intersections`` from the typed
    result; the report keeps both. A spindle torus whose hole is nearly closed (major radius
    0.3, tube radius 1), fitted to its own self-crossing limit surface: no clean surface is
    near that target, so the fit still crosses itself and the cage's crossings are counted
    (the wider spindle torus of the other tests is untangled by the fit, the vertex
    pseudo-normals being angle-weighted)."""
    from core.stages.fit import run_fit
    from core.subdivision.limit_crossings import limit_self_intersections
    from core.types import BaseMeshResult, IntakeResult, TriMesh

    cage = torus(major_radius=0.3, minor_radius=1.0)
    fine = build_hierarchy(cage, 3).meshes[3]
    target = TriMesh(limit_matrices(fine)[0] @ fine.vertices,
                     triangulate(fine.face_vertices, fine.face_offsets))
    params = ReconstructionParams(fit_mode="best-fit", subdivision_levels=2)
    fit = run_fit(IntakeResult(target, genus=1), BaseMeshResult(cage), params, NO_PROGRESS)
    assert fit.levels == fit.report["levels"] == 2
    assert fit.report["self_intersections"] > 0
    assert fit.cage_self_intersections == fit.report["cage_self_intersections"]
    assert fit.cage_self_intersections == len(limit_self_intersections(cage, 2)[0]) > 0
    clean = run_fit(IntakeResult(target, genus=1), BaseMeshResult(cube()), params, NO_PROGRESS)
    assert clean.levels == 2 and clean.cage_self_intersections is None


def test_rgp_keeps_fixed_vertices_in_place():
    from core.fitting.rgp import Evaluation, run_rgp

    class Push:
        """Objective -sum(x): every vertex is pushed along +x."""

        def evaluate(self, V):
            gradient = np.zeros_like(V)
            gradient[:, 0] = -1.0
            return Evaluation(-float(V[:, 0].sum()), gradient, [], {"volume": 0.0}, 1.0)

    V0 = np.zeros((5, 3))
    fixed = np.array([True, False, True, False, False])
    result = run_rgp(Push(), V0, 0.1, iterations=4, fixed=fixed)
    assert np.all(result.vertices[fixed] == 0.0)
    assert np.allclose(result.vertices[~fixed, 0], 0.4)


@pytest.fixture(scope="module")
def gripper():
    """gripper_domain (a 3.4 mm plate, 289 mm across) and the pipeline's cage of it."""
    path = os.path.join(MESHES, "gripper_domain.stl")
    if not os.path.exists(path):
        pytest.skip("dev mesh gripper_domain.stl not available")
    state = reconstruct(path, stop_after="basemesh").state
    return state.intake.target, state.basemesh.cage


@pytest.mark.slow
def test_inside_fit_of_a_thin_plate_stays_inside_and_clean(gripper):
    """The RGP pulls the plate's two walls through each other; the fit holds those moves
    back, so its limit surface does not cross itself, most of the cage still moves, and little
    of the volume is left outside (the fit stage's outside refinement takes the rest to its
    0.5 % rule; the fit alone is held to twice that)."""
    target, cage = gripper
    fitted, info = fit_base_mesh(cage, target, mode="inside")
    assert info.self_intersections == 0 and export_limit_crossings(fitted).count == 0
    assert info.figures.outside_volume_fraction <= 0.01
    assert info.held_back < 0.5 * len(cage.vertices)
