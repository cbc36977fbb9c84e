# SPDX-License-Identifier: LGPL-2.1-or-later
"""Tolerance-driven refinement: conforming quad-strip splits and the refit loop."""
import numpy as np
import pytest
import trimesh

from core.errors import ParameterError
from core.fitting import fit_base_mesh
from core.fitting.refine import fit_to_tolerance, refined_without_crossings, split_quad_strips
from core.geometry import triangulate
from core.polymesh_checks import check_polymesh
from core.quality import surface_distances
from core.subdivision.catmull_clark import build_hierarchy
from core.subdivision.limit import limit_matrices
from core.subdivision.sample_cages import cube, grid_sphere, mixed_prism, pentagonal_prism
from core.types import PolyMesh, TriMesh
from polycube_wb.cli import _tolerance


def capsule_and_box_cage():
    mesh = trimesh.creation.capsule(height=2.0, radius=0.5, count=[24, 24])
    target = TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64))
    c = cube(1.0)
    return target, PolyMesh((c.vertices - 0.5) * [1.0, 1.0, 3.0], c.face_vertices, c.face_offsets)


@pytest.mark.parametrize("seeds, extra", [([[0, 0]], 12), ([[0, 1]], 12),
                                          ([[0, 0], [0, 1]], 26)])
def test_strip_splits_are_conforming_quads(seeds, extra):
    cage = grid_sphere(3)  # 54 quads, every strip is a ring of 12
    refined = split_quad_strips(cage, np.array(seeds))
    check_polymesh(refined)  # closed, 2-manifold, consistently oriented
    assert (refined.face_sizes == 4).all()
    # one strip: 12 quads become 24; two strips around the sphere cross twice: 20 quads
    # are cut in two and the 2 shared ones in four
    assert refined.n_faces == cage.n_faces + extra
    n = len(cage.vertices)
    assert np.array_equal(refined.vertices[:n], cage.vertices)
    # every new vertex is the midpoint of an edge of the old cage or a face centre
    V = cage.vertices
    quads = cage.face_vertices.reshape(-1, 4)
    mids = 0.5 * (V[quads] + V[np.roll(quads, -1, axis=1)]).reshape(-1, 3)
    candidates = np.vstack([mids, V[quads].mean(axis=1)])
    gap = np.linalg.norm(refined.vertices[n:, None] - candidates[None], axis=2).min(axis=1)
    assert gap.max() <= 1e-12


def _edge_neighbours(cage, face):
    from core.subdivision.catmull_clark import mesh_topology

    topo = mesh_topology(cage.face_vertices, cage.face_offsets, len(cage.vertices))
    corners = range(cage.face_offsets[face], cage.face_offsets[face + 1])
    return [int(topo.face_of_corner[topo.twin[k]]) for k in corners]


def test_a_strip_within_one_quad_ends_in_two_pentagons():
    """A strip kept to its seed quad cuts it in two and ends in the two quads across: each
    keeps its corners plus the midpoint (a pentagon), so one face is added, not a ring."""
    cage = grid_sphere(3)
    within = np.zeros(cage.n_faces, dtype=bool)
    within[0] = True
    refined = split_quad_strips(cage, np.array([[0, 0]]), within=within)
    check_polymesh(refined)
    assert refined.n_faces == cage.n_faces + 1
    assert sorted(refined.face_sizes.tolist()) == [4] * (cage.n_faces - 1) + [5, 5]


def test_local_strips_change_only_the_region_and_its_neighbours():
    """Strips in both directions through a cross of five quads: the result is conforming
    (closed, 2-manifold, oriented), has only quads and pentagons, and every face that is
    neither in the cross nor next to it is unchanged."""
    cage = grid_sphere(3)
    region = [0] + _edge_neighbours(cage, 0)
    within = np.zeros(cage.n_faces, dtype=bool)
    within[region] = True
    seeds = np.array([[f, d] for f in region for d in (0, 1)])
    refined = split_quad_strips(cage, seeds, within=within)
    check_polymesh(refined)
    assert set(refined.face_sizes.tolist()) == {4, 5}
    touched = set(region)
    for f in region:
        touched.update(_edge_neighbours(cage, f))
    kept = {tuple(np.roll(r, -int(np.argmin(r))).tolist()) for r in refined.faces()}
    untouched = [f for f in range(cage.n_faces) if f not in touched]
    assert len(untouched) >= 30
    for f in untouched:
        ring = cage.faces()[f]
        assert tuple(np.roll(ring, -int(np.argmin(ring))).tolist()) in kept
    assert cage.n_faces < refined.n_faces <= cage.n_faces + 3 * len(touched)


def test_a_quad_entered_on_two_neighbouring_edges_becomes_three_quads():
    """Two strips ending in the same quad from neighbouring sides cut it into three quads
    around its centre (no T-junction, no pentagon there)."""
    cage = grid_sphere(4)  # 96 quads; face f's neighbours across edges 0 and 1
    f = 40
    across = _edge_neighbours(cage, f)
    within = np.zeros(cage.n_faces, dtype=bool)
    within[[across[0], across[1]]] = True
    # each neighbour's strip runs towards f: through the neighbour's edge shared with f
    seeds = []
    for g in (across[0], across[1]):
        shared = _edge_neighbours(cage, g).index(f)
        seeds.append([g, shared % 2])
    refined = split_quad_strips(cage, np.array(seeds), within=within)
    check_polymesh(refined)
    ring = set(cage.faces()[f].tolist())
    centre = refined.vertices[len(refined.vertices) - 1]
    assert np.allclose(centre, cage.vertices[list(ring)].mean(axis=0))
    around = [r for r in refined.faces() if len(refined.vertices) - 1 in r.tolist()]
    assert len(around) == 3 and all(len(r) == 4 for r in around)


def _limit_mesh(cage, level=3):
    fine = build_hierarchy(cage, level).meshes[level]
    return limit_matrices(fine)[0] @ fine.vertices, triangulate(fine.face_vertices,
                                                                fine.face_offsets)


def test_kept_limit_interpolates_the_cages_surface():
    """With ``keep_limit`` the refined cage's limit passes through the cage's limit at the
    same parameters (its vertex points, edge points, face points) and stays much closer to
    it than the cage with plain edge midpoints does."""
    from core.subdivision.catmull_clark import subdivide
    from core.subdivision.limit import vertex_limit_matrix

    cage = grid_sphere(3)
    cage = PolyMesh(cage.vertices * [1.0, 1.4, 0.8], cage.face_vertices, cage.face_offsets)
    within = np.zeros(cage.n_faces, dtype=bool)
    within[[0] + _edge_neighbours(cage, 0)] = True
    seeds = np.array([[f, 0] for f in np.flatnonzero(within)])
    plain = split_quad_strips(cage, seeds, within=within)
    kept = split_quad_strips(cage, seeds, within=within, keep_limit=True)
    assert np.array_equal(kept.face_vertices, plain.face_vertices)
    fine, _ = subdivide(cage)
    on_cage = vertex_limit_matrix(fine) @ fine.vertices
    at_vertices = vertex_limit_matrix(kept) @ kept.vertices
    gap = np.linalg.norm(at_vertices[:, None] - on_cage[None], axis=2).min(axis=1)
    assert gap.max() <= 1e-9
    X, T = _limit_mesh(cage)
    for refined, largest in ((kept, 0.01), (plain, None)):
        Y, U = _limit_mesh(refined)
        d = surface_distances(Y, U, X, T, samples=5000, seed=1)["hausdorff"]
        if largest is not None:
            assert d <= largest
            kept_distance = d
    assert kept_distance <= 0.3 * d  # 0.005 against 0.022 (sizes 1.8-3.1)


@pytest.mark.slow
def test_refinement_leaves_faces_whole_where_a_split_would_cross():
    """A refined cage whose limit crosses itself more than the fitted one's is not fitted:
    the deviating faces under the crossings stay whole, and when none is left the
    refinement stops and says why (here every refined cage is reported as crossing)."""
    target, base = capsule_and_box_cage()
    result = fit_to_tolerance(
        base, target, 0.01, 2000,
        lambda cage: fit_base_mesh(cage, target, 2, 50, mode="best-fit"),
        crossing_faces=lambda cage: np.zeros((0, 2), dtype=np.int64) if cage.n_faces == 6
        else np.stack([np.arange(cage.n_faces)] * 2, axis=1))
    assert not result.met and len(result.rounds) == 1
    assert "cross itself" in result.reason and result.mesh.n_faces == base.n_faces


def face_centres(cage):
    """(m, 3) the mean of each face's corners."""
    return np.array([cage.vertices[cage.face_vertices[cage.face_offsets[f]:
                                                      cage.face_offsets[f + 1]]].mean(0)
                     for f in range(cage.n_faces)])


@pytest.mark.parametrize("long_way_crosses, short_way_crosses, where", [
    (True, False, "everywhere"), (True, True, "everywhere"), (True, False, "opposite")])
def test_a_split_that_crosses_is_tried_the_other_way_before_the_face_is_left_whole(
        long_way_crosses, short_way_crosses, where):
    """A side face of the box cage (1 x 3) is cut across its long edges first; where that is
    reported to cross, across its short edges; where that crosses too, it is left whole. A
    crossing reported only in the opposite side face, two rings of faces away, counts for
    the deviating face too."""
    _, base = capsule_and_box_cage()
    deviating = np.zeros(base.n_faces, dtype=bool)
    deviating[np.argmax(face_centres(base)[:, 0])] = True  # +x: long edges along z
    tried = []

    def crossing(cage):
        if cage.n_faces == base.n_faces:
            return np.zeros((0, 2), dtype=np.int64)
        new = cage.vertices[len(base.vertices):]
        long_way = bool(np.any(np.abs(new[:, 2]) < 0.5))  # the long edges cut near z = 0
        tried.append("long" if long_way else "short")
        crosses = long_way_crosses if long_way else short_way_crosses
        faces = (np.arange(cage.n_faces) if where == "everywhere"
                 else np.flatnonzero(face_centres(cage)[:, 0] < -0.4))
        return (np.stack([faces] * 2, axis=1) if crosses else np.zeros((0, 2), dtype=np.int64))

    refined, why_not = refined_without_crossings(base, deviating, crossing)
    assert tried == ["long", "short"]
    if short_way_crosses:
        assert refined is None and "cross itself" in why_not
    else:
        assert why_not is None and refined.n_faces == base.n_faces + 1
        new = refined.vertices[len(base.vertices):]
        assert np.all(np.abs(new[:, 2]) > 1.0)  # on the short edges, at the box's ends


@pytest.mark.slow
def test_when_every_split_of_the_fitted_cage_crosses_the_cage_before_the_fit_is_split():
    """Refinements of the fitted cage are reported as crossing (told apart by their limit
    surface, which reaches the capsule's tips at |z| = 1.5, while the box cage's stops near
    1.2): the strips of the cage the fit started from are split instead, on its surface."""
    from core.fitting.deviation import fine_limit_points

    target, base = capsule_and_box_cage()

    def height(cage):
        return float(np.abs(fine_limit_points(cage, 1)[0][:, 2]).max())

    def crossing(cage):
        tall = cage.n_faces > base.n_faces and height(cage) > 1.35
        return (np.stack([np.arange(cage.n_faces)] * 2, axis=1) if tall
                else np.zeros((0, 2), dtype=np.int64))

    fitted_cages = []

    def fit(cage):
        fitted, info = fit_base_mesh(cage, target, 2, 50, mode="best-fit")
        fitted_cages.append((cage, fitted))
        return fitted, info

    result = fit_to_tolerance(base, target, 0.01, 2000, fit, crossing_faces=crossing,
                              max_rounds=2)
    (first, first_fit), (second, _) = fitted_cages
    assert height(base) < 1.35 < height(first_fit)
    assert result.rounds[0]["split"] == "unfitted cage"
    assert second.n_faces > base.n_faces and height(second) < 1.35
    assert result.met and len(result.rounds) == 2  # the refit from it met the tolerance


@pytest.mark.slow
def test_refinement_meets_the_tolerance_on_a_capsule():
    target, base = capsule_and_box_cage()
    tolerance = 0.01
    result = fit_to_tolerance(base, target, tolerance, 2000,
                              lambda cage: fit_base_mesh(cage, target, 2, 50, mode="best-fit"))
    assert result.met and result.reason == "tolerance met"
    faces = [r["faces"] for r in result.rounds]
    assert len(faces) >= 2 and faces == sorted(faces) and faces[0] == base.n_faces
    assert result.rounds[0]["max_deviation"] > tolerance >= result.rounds[-1]["max_deviation"]
    check_polymesh(result.mesh)
    # checked independently on the level-3 limit mesh with other samples
    h = build_hierarchy(result.mesh, 3)
    fine = h.meshes[3]
    X = limit_matrices(fine)[0] @ fine.vertices
    d = surface_distances(X, triangulate(fine.face_vertices, fine.face_offsets),
                          target.vertices, target.faces, samples=20000, seed=5)
    assert d["hausdorff"] <= 1.2 * tolerance


@pytest.mark.slow
def test_refinement_says_why_it_stops_at_the_face_budget():
    target, base = capsule_and_box_cage()
    result = fit_to_tolerance(base, target, 0.002, 60,
                              lambda cage: fit_base_mesh(cage, target, 2, 50, mode="best-fit"))
    assert not result.met
    assert "max_base_faces=60" in result.reason
    assert result.mesh.n_faces <= 60
    assert result.rounds[-1]["max_deviation"] > 0.002


@pytest.mark.slow
def test_refinement_keeps_the_closest_fit_when_it_stops_unmet():
    """When the tolerance is not met, the cage returned is the fit with the smallest largest
    deviation, not the last one (here every refined fit is made worse on purpose)."""
    from dataclasses import replace

    target, base = capsule_and_box_cage()

    def fit(cage):
        fitted, info = fit_base_mesh(cage, target, 2, 50, mode="best-fit")
        if cage.n_faces == base.n_faces:
            return fitted, info
        return replace(fitted, vertices=fitted.vertices * 1.2), info

    result = fit_to_tolerance(base, target, 0.001, 40, fit)
    assert not result.met and len(result.rounds) >= 2
    assert result.rounds[1]["max_deviation"] > result.rounds[0]["max_deviation"]
    assert result.mesh.n_faces == base.n_faces
    assert "the closest fit is kept (6 faces" in result.reason


@pytest.mark.parametrize("make", [mixed_prism, pentagonal_prism])
def test_strips_end_conformingly_in_faces_that_are_not_quads(make):
    """On prisms with triangles or pentagons, strips seeded in quads and in the other faces
    end in the other faces: the result is closed, 2-manifold and consistently oriented, every
    new vertex an edge midpoint or a face centre, and the split quads stay quads."""
    cage = make()
    sizes = cage.face_sizes
    quad, other = int(np.flatnonzero(sizes == 4)[0]), int(np.flatnonzero(sizes != 4)[0])
    refined = split_quad_strips(cage, np.array([[quad, 0], [quad, 1], [other, 0]]))
    check_polymesh(refined)
    assert refined.n_faces > cage.n_faces and (refined.face_sizes >= 3).all()
    assert (refined.face_sizes == 4).sum() > (sizes == 4).sum()
    n = len(cage.vertices)
    assert np.array_equal(refined.vertices[:n], cage.vertices)
    V = cage.vertices
    rings = np.split(cage.face_vertices, cage.face_offsets[1:-1])
    mids = np.vstack([0.5 * (V[r] + V[np.roll(r, -1)]) for r in rings])
    candidates = np.vstack([mids, [V[r].mean(axis=0) for r in rings]])
    gap = np.linalg.norm(refined.vertices[n:, None] - candidates[None], axis=2).min(axis=1)
    assert gap.max() <= 1e-12


def test_a_pentagon_entered_once_becomes_two_quads():
    """The side quads of a pentagonal prism form one ring of five through their side edges,
    which does not enter the caps; the strip across a side quad's other direction runs
    cap to cap: each pentagon cap is entered once and cut into two quads."""
    cage = pentagonal_prism()
    around = split_quad_strips(cage, np.array([[0, 1]]))
    assert around.n_faces == cage.n_faces + 5 and sorted(around.face_sizes) == [4] * 10 + [5, 5]
    across = split_quad_strips(cage, np.array([[0, 0]]))
    check_polymesh(across)
    assert (across.face_sizes == 4).all() and across.n_faces == cage.n_faces + 3


@pytest.mark.slow
def test_refinement_meets_the_tolerance_on_a_quad_dominant_cage():
    """A hexagonal prism cage of quads and triangle fans is refined to fit a cylinder within
    the tolerance (no all-quad requirement), the result still a closed 2-manifold."""
    mesh = trimesh.creation.cylinder(radius=1.0, height=1.5, sections=32)
    target = TriMesh(np.asarray(mesh.vertices) + [0, 0, 0.75],
                     np.asarray(mesh.faces, dtype=np.int64))
    base = mixed_prism(radius=1.0, height=1.5)
    result = fit_to_tolerance(base, target, 0.015, 2000,
                              lambda cage: fit_base_mesh(cage, target, 2, 20, mode="best-fit"))
    assert result.met and len(result.rounds) >= 2
    assert result.rounds[0]["max_deviation"] > 0.015 >= result.rounds[-1]["max_deviation"]
    check_polymesh(result.mesh)
    assert (result.mesh.face_sizes != 4).any()


def test_refinement_needs_a_positive_tolerance():
    target, base = capsule_and_box_cage()
    with pytest.raises(ParameterError, match="positive"):
        fit_to_tolerance(base, target, 0.0, 100, None)


def test_tolerance_option_text():
    assert _tolerance("0.002") == {"tolerance": 0.002}
    assert _tolerance("0.5mm") == {"tolerance_mm": 0.5}
    assert _tolerance("0.05cm") == {"tolerance_mm": pytest.approx(0.5)}
    assert _tolerance(" 0.02in") == {"tolerance_mm": pytest.approx(0.508)}
    with pytest.raises(Exception, match="--tolerance"):
        _tolerance("fine")
