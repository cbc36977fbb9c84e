# SPDX-License-Identifier: LGPL-2.1-or-later
"""HBECVT labeling (Eqs. 2-3) and the repair loop."""
import os

import numpy as np
import pytest
import trimesh

from core.errors import InvalidMeshError, ParameterError
from core.segmentation.charts import OPPOSITE, build_topology
from core.segmentation.labeling import (face_colouring, face_normals, hbecvt_labeling,
                                        hbecvt_sweeps, label_cost, label_directions,
                                        mean_label_angle, nearest_direction_labels,
                                        part_neighbours)
from core.segmentation.repair import repair_labeling
from core.segmentation.validity import check_validity

MESHES = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "meshes")


def cube(levels=3):
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = np.asarray(box.vertices) + 0.5, np.asarray(box.faces)
    for _ in range(levels):
        V, F = trimesh.remesh.subdivide(V, F)
    return np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)


def identity_frames(m):
    return np.broadcast_to(np.eye(3), (m, 3, 3)).copy()


def rotation(ax, ay, az):
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def pca_frame(V):
    P = V - V.mean(axis=0)
    _, vec = np.linalg.eigh(P.T @ P)
    R = vec.T.copy()
    if np.linalg.det(R) < 0:
        R[2] *= -1
    return R


def no_opposite_neighbours(F, labels):
    nb = build_topology(F).neighbours
    return not (labels[nb] == OPPOSITE[labels][:, None]).any()


def test_rotated_cube_in_its_own_frame_gives_six_exact_charts():
    V, F = cube()
    R = rotation(0.3, -0.5, 1.1)
    Vr = V @ R.T
    frame = np.broadcast_to(R.T, (len(F), 3, 3)).copy()  # rows = rotated x, y, z axes
    labels, info = hbecvt_labeling(Vr, F, np.zeros(len(F)), frame)
    n = face_normals(Vr, F)
    assert info["converged"]
    assert np.allclose(label_directions(labels, frame), n, atol=1e-9)
    assert mean_label_angle(n, labels, frame) == pytest.approx(0.0, abs=1e-5)
    r = check_validity(Vr, F, np.zeros(len(F)), labels, frame).report
    assert r["valid"] and (r["charts"], r["corners"]) == (6, 8)


def test_smoothing_removes_noise_and_is_deterministic():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    rng = np.random.default_rng(0)
    V = V * (1.0 + 0.03 * rng.standard_normal(len(V)))[:, None]
    m = len(F)
    frame = identity_frames(m)
    n = face_normals(V, F)
    near = nearest_direction_labels(n, frame)
    a, info = hbecvt_labeling(V, F, np.zeros(m), frame)
    b, _ = hbecvt_labeling(V, F, np.zeros(m), frame)
    assert np.array_equal(a, b)
    assert a.dtype == np.int32 and a.min() >= 0 and a.max() <= 5
    assert info["converged"] and info["sweeps"] < 200
    topo = build_topology(F)
    before = check_validity(V, F, np.zeros(m), near, frame, topo).report
    after = check_validity(V, F, np.zeros(m), a, frame, topo).report
    assert after["charts"] < before["charts"]
    assert after["invalid_charts"]["count"] < before["invalid_charts"]["count"]
    # term 3 (p = 1e5): no face ends next to its opposite label
    assert no_opposite_neighbours(F, a)
    # term 1 keeps labels close to the normals
    assert mean_label_angle(n, a, frame) < mean_label_angle(n, near, frame) + 5.0


def test_sweeps_end_at_a_coordinate_wise_minimum_of_eq_3():
    """Where the sweeps stop, no face can lower the Eq. 3 energy by changing its own label (the
    sweeps revisit only faces whose neighbours moved; this checks every face), on a noisy sphere
    in a tilted frame and restricted to an active set."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    V = V * (1.0 + 0.05 * np.random.default_rng(3).standard_normal(len(V)))[:, None]
    m = len(F)
    frame = np.broadcast_to(rotation(0.4, 0.2, -0.3), (m, 3, 3)).copy()
    unary = label_cost(face_normals(V, F), frame)
    nb = part_neighbours(build_topology(F), np.zeros(m, dtype=np.int64))
    colour = face_colouring(nb)
    start = np.argmin(unary, axis=1)
    active = V[F].mean(axis=1)[:, 2] > -0.2
    for act in (None, active):
        labels, sweeps = hbecvt_sweeps(unary, nb, start, colour, lam=0.5, penalty=1e5,
                                       active=act)
        assert 1 < sweeps < 200
        cnt = (labels[nb][:, :, None] == np.arange(6)).sum(axis=1)
        d2 = unary + 0.5 * (3 - cnt) + 1e5 * cnt[:, OPPOSITE]
        own = d2[np.arange(m), labels]
        free = np.ones(m, dtype=bool) if act is None else act
        assert (own[free] <= d2[free].min(axis=1) + 1e-9).all()
        assert np.array_equal(labels[~free], start[~free])
        assert (labels != start).sum() > 50


def test_interface_term_forbids_labels_parallel_to_interface_axis():
    V, F = cube()
    m = len(F)
    frame = identity_frames(m)
    c = V[F].mean(axis=1)
    iface = np.full((m, 3), np.nan)
    near_plane = c[:, 2] < 0.3
    iface[near_plane] = [0.2, 0.1, 0.97]  # interface x-axis close to world Z
    labels, _ = hbecvt_labeling(V, F, np.zeros(m), frame, face_interface_axis=iface)
    assert not np.isin(labels[near_plane], [4, 5]).any()
    assert np.isin(labels[~near_plane], [4, 5]).any()


def test_neighbours_of_other_parts_do_not_count():
    V, F = cube(1)
    m = len(F)
    parts = (V[F].mean(axis=1)[:, 0] > 0.5).astype(np.int64)
    nb = part_neighbours(build_topology(F), parts)
    ok = nb >= 0
    assert (parts[np.where(ok, nb, 0)][ok] == np.repeat(parts, 3).reshape(m, 3)[ok]).all()
    assert (~ok).any()


def test_colouring_is_proper():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    nb = build_topology(np.asarray(sphere.faces)).neighbours
    colour = face_colouring(nb)
    assert (colour >= 0).all() and colour.max() <= 3
    assert not (colour[nb] == colour[:, None]).any()


def test_bad_input_raises_clear_errors():
    V, F = cube(0)
    m = len(F)
    with pytest.raises(ParameterError, match="shape"):
        hbecvt_labeling(V, F, np.zeros(m), np.zeros((m, 3)))
    bad = identity_frames(m)
    bad[3] *= 2.0
    with pytest.raises(ParameterError, match="1 frames.*face 3"):
        hbecvt_labeling(V, F, np.zeros(m), bad)
    F2 = F.copy()
    F2[5] = [F[5, 0], F[5, 0], F[5, 1]]
    with pytest.raises(InvalidMeshError) as err:
        hbecvt_labeling(V, F2, np.zeros(m), identity_frames(m))
    assert err.value.reason == "degenerate_faces" and err.value.examples == [5]
    with pytest.raises(ParameterError, match="outside 0..5"):
        repair_labeling(V, F, np.zeros(m), np.full(m, 7), identity_frames(m))


def test_repair_removes_island_and_opposite_boundary():
    V, F = cube()
    m = len(F)
    frame = identity_frames(m)
    labels = nearest_direction_labels(face_normals(V, F), frame).astype(np.int64)
    corner = V[F]
    top = (corner[:, :, 2] > 0.99).all(axis=1)
    island = top & ((np.abs(corner[:, :, :2] - 0.5) < 0.26).all(axis=2)).all(axis=1)
    labels[island] = 1  # -X island on the +Z face
    strip = ((np.abs(corner[:, :, 0] - 1.0) < 1e-9).all(axis=1)
             & (corner[:, :, 2] < 0.26).all(axis=1))
    labels[strip] = 1  # -X strip on the +X face: an opposite boundary
    before = check_validity(V, F, np.zeros(m), labels, frame).report
    assert not before["valid"]
    out, rep = repair_labeling(V, F, np.zeros(m), labels, frame)
    assert rep["valid"] and rep["after"]["valid"] and rep["stopped"] == "valid"
    assert rep["unfixed"] == {}
    assert rep["after"]["charts"] == 6
    assert np.array_equal(out, nearest_direction_labels(face_normals(V, F), frame))


@pytest.mark.parametrize("name", ["to_simp_cantilever.stl", "polycube_bone.obj"])
def test_dev_mesh_ends_valid_with_few_charts(name):
    path = os.path.join(MESHES, name)
    if not os.path.exists(path):
        pytest.skip(f"dev mesh {name} not available")
    mesh = trimesh.load(path, process=True)
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    frame = np.broadcast_to(pca_frame(V), (m, 3, 3)).copy()
    parts = np.zeros(m, dtype=np.int64)
    n = face_normals(V, F)
    labels, _ = hbecvt_labeling(V, F, parts, frame)
    out, rep = repair_labeling(V, F, parts, labels, frame)
    assert rep["valid"], rep["unfixed"]
    assert rep["after"]["charts"] <= 30
    near = nearest_direction_labels(n, frame)
    assert mean_label_angle(n, out, frame) <= mean_label_angle(n, near, frame) + 5.0


@pytest.mark.parametrize("name", ["to_simp_lbracket.stl", "to_simp_cantilever.stl",
                                  "gripper_domain.stl", "octagonal_pocket.stl",
                                  "to_simp_torsion_arm.stl"])
@pytest.mark.slow
def test_dev_mesh_with_automatic_parts_ends_valid(name):
    # the interface x-axis of Eq. 3 term 4 and of the validity rules is one and the same
    from core.segmentation.frames import compute_frames, mean_edge_length
    from core.segmentation.skeleton_parts import skeleton_segmentation
    from core.types import TriMesh

    path = os.path.join(MESHES, name)
    if not os.path.exists(path):
        pytest.skip(f"dev mesh {name} not available")
    mesh = trimesh.load(path, process=True)
    tm = TriMesh(np.asarray(mesh.vertices, dtype=np.float64),
                 np.asarray(mesh.faces, dtype=np.int64))
    V, F = tm.vertices, tm.faces
    parts = skeleton_segmentation(tm).face_part
    assert parts.max() >= 1
    field = compute_frames(tm, parts, blend_distance=4.0 * mean_edge_length(V, F))
    labels, _ = hbecvt_labeling(V, F, parts, field.face_frame, field.face_interface_axis)
    band = np.isfinite(field.face_interface_axis).all(axis=1)
    d = label_directions(labels, field.face_frame)
    assert (np.abs((d[band] * field.face_interface_axis[band]).sum(axis=1)) < 0.8).all()
    out, rep = repair_labeling(V, F, parts, labels, field.face_frame, field.face_interface_axis)
    assert rep["valid"], rep["unfixed"]
    assert check_validity(V, F, parts, out, field.face_frame).is_valid
    n = face_normals(V, F)
    near = nearest_direction_labels(n, field.face_frame)
    limit = mean_label_angle(n, near, field.face_frame) + 5.0
    assert mean_label_angle(n, out, field.face_frame) <= limit


def test_fandisk_with_the_chosen_frame_has_no_chart_below_four_boundaries():
    """With PCA frames fandisk keeps a +X chart with two boundaries between +Y and +Z (a lens
    whose tips are X, Y, Z corners, which no local split can make four-sided); the frame chosen by
    labeling energy labels it validly and fits the normals better."""
    from dev_meshes import load_dev_mesh

    from core.segmentation.frames import compute_frames

    tm = load_dev_mesh("fandisk.obj")
    V, F = tm.vertices, tm.faces
    parts = np.zeros(len(F), dtype=np.int64)
    chosen = compute_frames(tm, parts)
    pca = compute_frames(tm, parts, choose="pca")
    assert chosen.part_frame_source[0] != "pca"
    n = face_normals(V, F)
    area = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)

    def nearest_angle(field):
        near = nearest_direction_labels(n, field.face_frame)
        return mean_label_angle(n, near, field.face_frame, weights=area)

    assert nearest_angle(chosen) < nearest_angle(pca) - 5.0
    labels, _ = hbecvt_labeling(V, F, parts, chosen.face_frame)
    out, rep = repair_labeling(V, F, parts, labels, chosen.face_frame)
    assert rep["valid"], rep["unfixed"]
    v = check_validity(V, F, parts, out, chosen.face_frame)
    assert v.is_valid and v.layout.chart_boundary_count.min() >= 4


def test_saddle_of_alternating_labels_is_repaired():
    """+X, +Y, -X, -Y quadrants in the middle of the cube's top: four 3-boundary charts and a
    corner whose four boundaries all run along Z (opposite labels touching at a point)."""
    V, F = cube(4)
    m = len(F)
    frames = identity_frames(m)
    labels = nearest_direction_labels(face_normals(V, F), frames).astype(np.int64)
    c = V[F].mean(axis=1)
    saddle = (c[:, 2] > 0.99) & (np.abs(c[:, :2] - 0.5).max(axis=1) < 0.2)
    east, north = c[:, 0] > 0.5, c[:, 1] > 0.5
    quadrant = np.where(east, np.where(north, 0, 3), np.where(north, 2, 1))
    labels[saddle] = quadrant[saddle]
    parts = np.zeros(m, dtype=np.int64)
    before = check_validity(V, F, parts, labels, frames).report
    assert before["invalid_corners"]["count"] == 1 and before["invalid_charts"]["count"] == 4
    out, rep = repair_labeling(V, F, parts, labels, frames)
    assert rep["valid"], rep["unfixed"]
    assert check_validity(V, F, parts, out, frames).is_valid


def test_candidate_judge_judges_a_labeling_once():
    """The judge keeps its last whole-mesh judgements: the same labels give the same judgement,
    other labels a new one, and asking for turning points adds them to the kept judgement."""
    from core.geometry import face_areas
    from core.segmentation.repair import CandidateJudge

    V, F = cube()
    m = len(F)
    frame = identity_frames(m)
    topo = build_topology(F, len(V))
    parts = np.zeros(m, dtype=np.int64)
    judge = CandidateJudge.of_mesh(V, F, parts, frame, topo)
    assert np.allclose(judge.area * face_areas(V, F).sum(), face_areas(V, F))
    labels = nearest_direction_labels(face_normals(V, F), frame).astype(np.int64)
    first = judge.validity(labels)
    assert judge.validity(labels.copy()) is first and first.is_valid
    island = labels.copy()
    island[np.flatnonzero(labels == 4)[:2]] = 0
    other = judge.validity(island)
    assert other is not first and not other.is_valid
    assert judge.validity(labels) is first
    turning = judge.validity(island, tau=0.01)
    whole = check_validity(V, F, parts, island, frame, topo, turning_tolerance=0.01)
    assert turning.report == whole.report and turning.report["turning_points"]["count"] >= 1


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fandisk.obj", "octagonal_pocket.stl"])
def test_automatic_parts_are_labelled_near_their_nearest_directions(name):
    """With automatic parts every part's area-weighted mean normal-to-label angle is at most
    3 degrees above the better of its nearest-direction labelings in the world axes and in its
    PCA frame (the blend keeps the frame of the part whose band covers most of it; layers lying
    on their cut are not parts)."""
    from core.params import ReconstructionParams
    from core.pipeline import run_stages
    from core.segmentation.part_frame import face_geometry, part_frames
    from core.types import MeshSource, PipelineState

    path = os.path.join(MESHES, name)
    if not os.path.exists(path):
        pytest.skip(f"dev mesh {name} not available")
    state = PipelineState(source=MeshSource(path))
    state = run_stages(state, ["intake", "parts", "frames", "labeling"],
                       ReconstructionParams(parts="auto"))[0]
    V, F = state.intake.surface.vertices, state.intake.surface.faces
    part = state.parts.face_part
    assert part.max() >= 1 and state.labeling.validity.is_valid
    area, normal, _ = face_geometry(V, F)
    labels, frames = state.labeling.face_label, state.frames.frame_field.face_frame

    def angle(lab, frame):
        d = label_directions(lab, frame)
        return np.degrees(np.arccos(np.clip((d * normal).sum(axis=1), -1.0, 1.0)))

    world = identity_frames(len(F))
    pca = part_frames(V, F, part)[part]
    got = angle(labels, frames)
    in_world = angle(nearest_direction_labels(normal, world), world)
    in_pca = angle(nearest_direction_labels(normal, pca), pca)
    for p in range(int(part.max()) + 1):
        sel = part == p
        mean = [np.average(a[sel], weights=area[sel]) for a in (got, in_world, in_pca)]
        assert mean[0] <= min(mean[1:]) + 3.0, (p, mean)


def test_a_label_boundary_costs_its_length_not_its_edge_count():
    # face 0 between two neighbours of label +X across short edges and one of +Y across a long
    # edge, both labels equally near its normal: counted per neighbour (the paper's Eq. 3,
    # every weight 1) it joins the two, weighted by edge length it joins the long edge's side
    neighbours = np.array([[1, 2, 3], [0, -1, -1], [0, -1, -1], [0, -1, -1]])
    unary = np.full((4, 6), 4.0)
    unary[:, 0] = unary[:, 2] = 0.0  # +X and +Y cost nothing anywhere
    labels = np.array([4, 0, 0, 2])  # face 0 starts at +Z
    active = np.array([True, False, False, False])
    colour = np.array([0, 1, 1, 1])
    by_count, _ = hbecvt_sweeps(unary, neighbours, labels, colour, active=active)
    ones, _ = hbecvt_sweeps(unary, neighbours, labels, colour, active=active,
                            edge_weight=np.ones((4, 3)))
    weight = np.ones((4, 3))
    weight[0] = [0.5, 0.5, 3.0]
    by_length, _ = hbecvt_sweeps(unary, neighbours, labels, colour, active=active,
                                 edge_weight=weight)
    assert by_count[0] == ones[0] == 0
    assert by_length[0] == 2


def test_edge_weights_do_not_depend_on_the_size_or_the_resolution_of_the_mesh():
    from core.segmentation.labeling import edge_weights

    V, F = cube(2)
    weights = edge_weights(V, build_topology(F))
    assert weights.shape == (len(F), 3) and (weights > 0).all()
    assert np.allclose(edge_weights(10.0 * V, build_topology(F)), weights)
    # a uniform midpoint subdivision halves every edge: the weights are the same values
    V4, F4 = cube(3)
    assert np.allclose(np.sort(np.unique(np.round(edge_weights(V4, build_topology(F4)), 9))),
                       np.sort(np.unique(np.round(weights, 9))))


SHELF_BRACKET = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "simp_unseen",
                             "simp_shelf_bracket.stl")


@pytest.mark.slow
def test_a_stuck_repair_escapes_to_fewer_invalid_items_never_more():
    """A SIMP design in the world frame: the greedy repair stops where every candidate adds
    invalid items; with escapes it restarts from the best of them and keeps a restart only
    when it ends with fewer invalid items, so it ends valid here and never worse anywhere."""
    mesh = trimesh.load(SHELF_BRACKET, process=True)
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    m = len(F)
    frame, parts = identity_frames(m), np.zeros(m, dtype=np.int64)
    labels, _ = hbecvt_labeling(V, F, parts, frame)
    greedy, rep_greedy = repair_labeling(V, F, parts, labels, frame)
    out, rep = repair_labeling(V, F, parts, labels, frame, escapes=4)
    invalid = lambda r: sum(r["after"][k]["count"] for k in (  # noqa: E731
        "invalid_charts", "invalid_boundaries", "invalid_corners"))
    assert invalid(rep) <= invalid(rep_greedy)
    assert rep["escapes"] <= 4
    assert rep["valid"], rep["unfixed"]
    v = check_validity(V, F, parts, out, frame)
    assert v.is_valid and v.layout.chart_boundary_count.min() >= 4
    assert no_opposite_neighbours(F, out.astype(np.int64))
    with pytest.raises(ParameterError, match="escapes"):
        repair_labeling(V, F, parts, labels, frame, escapes=-1)


BOLT_PLATE = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "simp_unseen",
                          "simp_bolt_plate.stl")


@pytest.mark.slow
def test_the_labeling_stage_repairs_again_until_valid_and_keeps_a_valid_first_pass(monkeypatch):
    """The bolt plate's first pass of repair, absorption and straightening leaves an invalid
    chart; the next passes end with a labeling every rule accepts. A labeling the first pass
    leaves valid is what the stage returns, whatever the number of passes allowed."""
    import core.stages.labeling as stage
    from core.pipeline import reconstruct

    def labeling(path, passes):
        monkeypatch.setattr(stage, "REPAIR_PASSES", passes)
        result = reconstruct(path, stop_after="labeling")
        assert result.failed is None, result.report["stages"]
        return result.state

    state = labeling(BOLT_PLATE, stage.REPAIR_PASSES)
    surface, lab = state.intake.surface, state.labeling
    v = check_validity(surface.vertices, surface.faces, state.parts.face_part, lab.face_label,
                       state.frames.frame_field.face_frame)
    assert v.is_valid and lab.report["valid"] and lab.report["unfixed"] == {}
    assert v.layout.chart_boundary_count.min() >= 4
    assert no_opposite_neighbours(surface.faces, np.asarray(lab.face_label, dtype=np.int64))

    tiny = os.path.join(MESHES, "to_levelset_cantilever_tiny.stl")
    if not os.path.exists(tiny):
        pytest.skip("dev mesh to_levelset_cantilever_tiny.stl not available")
    one = labeling(tiny, 1).labeling
    assert one.report["valid"]
    assert np.array_equal(labeling(tiny, 3).labeling.face_label, one.face_label)
