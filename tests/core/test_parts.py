# SPDX-License-Identifier: LGPL-2.1-or-later
"""Part segmentation: single part, user parts (validation), interfaces, automatic parts."""
from pathlib import Path

import manifold3d as m3
import numpy as np
import pytest
import trimesh

from core.errors import ParameterError
from core.segmentation.parts import interfaces, parts_from_user, single_part, validate_face_part
from core.segmentation.skeleton_parts import (MIN_PART_FACES, TANGENT_AREA, TANGENT_SHARE,
                                              absorb_patches, absorb_tangent_cuts,
                                              automatic_parts, close_interfaces,
                                              skeleton_segmentation, smooth_boundaries,
                                              tangent_cut_shares)
from core.types import TriMesh

MESHES = Path("/work/shared/data/meshes")


def _mesh(manifold):
    out = manifold.to_mesh()
    return TriMesh(np.asarray(out.vert_properties[:, :3], dtype=np.float64),
                   np.asarray(out.tri_verts, dtype=np.int64))


def _load(name):
    tm = trimesh.load(MESHES / name, process=True)
    tm.merge_vertices()
    return TriMesh(np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64))


@pytest.fixture(scope="module")
def bar():
    """10 x 2 x 2 box, vertex planes at x = 0, 2.5, 5, 7.5, 10."""
    return _mesh(m3.Manifold.cube([10.0, 2.0, 2.0]).refine(4))


def _centroids(mesh):
    return mesh.vertices[mesh.faces].mean(axis=1)


def test_single_part(bar):
    part = single_part(bar)
    assert part.dtype == np.int32 and part.shape == (len(bar.faces),) and not part.any()
    assert interfaces(bar, part) == []


def test_user_array_accepted_and_validated(bar):
    half = (_centroids(bar)[:, 0] > 5.0).astype(np.int64)
    assert np.array_equal(parts_from_user(bar, half), half)
    assert np.array_equal(parts_from_user(bar, half.tolist()), half)
    with pytest.raises(ParameterError, match="one entry per face"):
        parts_from_user(bar, half[:-1])
    with pytest.raises(ParameterError, match="integers"):
        parts_from_user(bar, half + 0.5)
    with pytest.raises(ParameterError, match="part 1"):
        parts_from_user(bar, half * 2)  # ids 0 and 2: part 1 empty
    ends = ((_centroids(bar)[:, 0] < 2.5) | (_centroids(bar)[:, 0] > 7.5)).astype(np.int64)
    with pytest.raises(ParameterError, match="part 1 has 2 separate pieces"):
        parts_from_user(bar, ends)


def test_face_groups(bar):
    x = _centroids(bar)[:, 0]
    groups = [np.flatnonzero(x < 5.0).tolist(), np.flatnonzero(x >= 5.0).tolist()]
    part = parts_from_user(bar, groups)
    assert np.array_equal(part, (x >= 5.0).astype(np.int32))
    missing = [groups[0], groups[1][:-3]]
    with pytest.raises(ParameterError, match="3 faces are in no group"):
        parts_from_user(bar, missing)
    with pytest.raises(ParameterError, match="more than once"):
        parts_from_user(bar, [groups[0], groups[1] + groups[0][:2]])
    with pytest.raises(ParameterError, match="outside"):
        parts_from_user(bar, [groups[0], groups[1] + [len(x) + 5]])


def test_cutting_planes_give_connected_parts(bar):
    part = parts_from_user(bar, [((2.5, 0, 0), (1, 0, 0)), ((7.5, 0, 0), (1, 0, 0))])
    assert part.max() == 2
    validate_face_part(bar, part)
    x = _centroids(bar)[:, 0]
    for p in range(3):
        lo, hi = x[part == p].min(), x[part == p].max()
        assert hi - lo <= 5.0 + 1e-9
    # a plane that splits one sign-cell into two separate pieces still gives connected parts
    ring = _mesh(m3.Manifold.cube([6.0, 6.0, 1.0], center=True)
                 - m3.Manifold.cube([4.0, 4.0, 2.0], center=True))
    part = parts_from_user(ring, [((0, 0, 0), (1, 0, 0))])
    assert part.max() == 1
    validate_face_part(ring, part)
    with pytest.raises(ParameterError, match="zero normal"):
        parts_from_user(bar, [((0, 0, 0), (0, 0, 0))])


def test_interfaces_are_closed_loops_on_the_cut(bar):
    part = parts_from_user(bar, [((2.5, 0, 0), (1, 0, 0)), ((7.5, 0, 0), (1, 0, 0))])
    itfs = interfaces(bar, part)
    assert [i.parts for i in itfs] == [(0, 1), (1, 2)]
    for itf, x_cut in zip(itfs, (2.5, 7.5)):
        assert itf.closed == [True] and len(itf.loops) == 1
        loop = itf.loops[0]
        assert len(loop) == len(itf.vertices) == len(itf.edges)
        assert np.allclose(bar.vertices[loop, 0], x_cut)
        consecutive = np.sort(np.stack([loop, np.roll(loop, -1)], axis=1), axis=1)
        assert {tuple(e) for e in consecutive} == {tuple(e) for e in np.sort(itf.edges, axis=1)}


def _assert_legs_split(mesh, part, reach):
    """Two parts, each holding all faces of one leg beyond ``reach`` from the corner
    (leg a along +x, leg b along +z) and none of the other leg's."""
    assert part.max() + 1 == 2
    validate_face_part(mesh, part)
    c = _centroids(mesh)
    far = [c[:, 0] > reach, c[:, 2] > reach]
    owner = [np.unique(part[f]) for f in far]
    assert [len(o) for o in owner] == [1, 1] and owner[0][0] != owner[1][0]
    itfs = interfaces(mesh, part)
    assert len(itfs) == 1 and itfs[0].closed == [True]


@pytest.mark.slow
def test_automatic_parts_split_an_l_of_boxes_at_the_corner():
    mesh = _mesh((m3.Manifold.cube([10, 2, 2]) + m3.Manifold.cube([2, 2, 10])).refine(4))
    part = automatic_parts(mesh)
    _assert_legs_split(mesh, part, reach=4.0)
    assert np.array_equal(automatic_parts(mesh), part)  # deterministic


def test_automatic_cut_of_an_l_is_planar_at_the_other_legs_surface():
    """The corner stays with one leg; the cut is the plane of the other leg's side face
    (x = 2 or z = 2), not an oblique or staircase cut through the corner."""
    mesh = _mesh((m3.Manifold.cube([10, 2, 2]) + m3.Manifold.cube([2, 2, 10])).refine(4))
    itf = interfaces(mesh, automatic_parts(mesh))[0]
    x = mesh.vertices[itf.vertices]
    assert np.allclose(x[:, 0], 2.0, atol=1e-9) or np.allclose(x[:, 2], 2.0, atol=1e-9)


def test_smooth_boundaries_straightens_a_jagged_cut():
    bar = _mesh(m3.Manifold.cube([10.0, 2.0, 2.0]).refine(8))
    c = _centroids(bar)
    jagged = (c[:, 0] + 0.6 * np.sign(np.sin(7 * c[:, 1] + 5 * c[:, 2])) > 5).astype(np.int64)
    before = interfaces(bar, jagged)
    assert np.ptp(bar.vertices[before[0].vertices, 0]) > 2.0
    part = smooth_boundaries(bar.vertices, bar.faces, jagged, width=0.5)
    itfs = interfaces(bar, part)
    assert len(itfs) == 1 and itfs[0].closed == [True]
    assert np.ptp(bar.vertices[itfs[0].vertices, 0]) < 1e-9  # one cross-section


@pytest.mark.slow
def test_smooth_boundaries_equals_a_full_heat_step_every_round():
    """Solving only the parts that changed gives the labels of solving every part each round
    (the threshold dynamics written out here), on a real SIMP mesh cut into six slabs whose
    jagged boundaries take several rounds to settle."""
    from scipy.sparse import csr_matrix, diags
    from scipy.sparse.linalg import splu

    from core.geometry import face_areas
    from core.mesh_topology import edge_faces

    mesh = _load("to_simp_cantilever.stl")
    v, f = mesh.vertices, mesh.faces
    c = v[f].mean(axis=1)
    span = np.ptp(c[:, 0])
    wobble = 0.02 * span * np.sign(np.sin(40 * c[:, 1] / span + 30 * c[:, 2] / span))
    label = np.clip(((c[:, 0] - c[:, 0].min() + wobble) / span * 6).astype(np.int64), 0, 5)
    width = 0.01 * span
    edges, fe = edge_faces(f)
    inner = (fe >= 0).all(axis=1)
    f0, f1 = fe[inner, 0], fe[inner, 1]
    w = (np.linalg.norm(v[edges[inner, 0]] - v[edges[inner, 1]], axis=1)
         / np.linalg.norm(c[f0] - c[f1], axis=1))
    m = len(f)
    lap = csr_matrix((np.r_[w, w], (np.r_[f0, f1], np.r_[f1, f0])), shape=(m, m))
    lap = diags(np.asarray(lap.sum(axis=1)).ravel()) - lap
    area = face_areas(v, f)
    solve = splu((diags(area) + width ** 2 * lap).tocsc()).solve
    expected, rounds = label.copy(), 0
    for rounds in range(1, 9):
        chi = np.zeros((m, 6))
        chi[np.arange(m), expected] = area
        new = np.argmax(solve(chi), axis=1)
        if np.array_equal(new, expected):
            break
        expected = new
    assert rounds >= 3  # the incremental columns are exercised
    assert not np.array_equal(expected, label)
    assert np.array_equal(smooth_boundaries(v, f, label, width), expected)


def test_close_interfaces_removes_three_part_junctions(bar):
    c = _centroids(bar)
    part = np.where(c[:, 0] < 5.0, 0, np.where(c[:, 1] < 1.0, 1, 2))
    assert any(itf.closed != [True] for itf in interfaces(bar, part))
    closed = close_interfaces(bar.vertices, bar.faces, part)
    assert len(np.unique(closed)) == 2
    assert all(itf.closed == [True] and len(itf.loops) == 1 for itf in interfaces(bar, closed))


def test_absorb_patches_merges_a_patch_on_a_wall(bar):
    c = _centroids(bar)
    part = (c[:, 0] > 5.0).astype(np.int64)
    patch = (c[:, 2] > 2.0 - 1e-9) & (c[:, 0] > 1.0) & (c[:, 0] < 3.0)  # on the top face
    part[patch] = 2
    out = absorb_patches(bar.vertices, bar.faces, part)
    assert np.array_equal(out, (c[:, 0] > 5.0).astype(np.int64))


def test_absorb_patches_merges_a_layer_lying_on_its_cut(bar):
    """The top 1.625 of an 8 x 8 x 6.5 block: mean normal 64 / 116 = 0.55 (its cut is more than
    half its own surface), merged into the block below (64 / 220 = 0.29, kept); the halves of a
    bar cut across (mean normal 4 / 44) are kept."""
    block = _mesh(m3.Manifold.cube([8.0, 8.0, 6.5]).refine(4))  # vertex planes every 1.625
    layer = (_centroids(block)[:, 2] > 4.875).astype(np.int64)
    assert 0 < layer.sum() < len(layer)
    assert len(np.unique(absorb_patches(block.vertices, block.faces, layer))) == 1
    kept = absorb_patches(block.vertices, block.faces, layer, max_normal=0.6)
    assert np.array_equal(kept, layer)
    halves = (_centroids(bar)[:, 0] > 5.0).astype(np.int64)
    assert np.array_equal(absorb_patches(bar.vertices, bar.faces, halves), halves)


def test_automatic_parts_split_two_cylinders_at_right_angles():
    tube = m3.Manifold.cylinder(10.0, 1.0, 1.0, 32)
    mesh = _mesh((tube + tube.rotate([0, 90, 0])).refine(2))
    _assert_legs_split(mesh, automatic_parts(mesh), reach=4.0)


def test_automatic_parts_on_genus_two_frame():
    """A plate with two windows (genus 2): the skeleton has loops."""
    plate = m3.Manifold.cube([12.0, 6.0, 1.0])
    holes = (m3.Manifold.cube([4.0, 4.0, 3.0]).translate([1.0, 1.0, -1.0])
             + m3.Manifold.cube([4.0, 4.0, 3.0]).translate([7.0, 1.0, -1.0]))
    mesh = _mesh((plate - holes).refine(3))
    result = skeleton_segmentation(mesh)
    validate_face_part(mesh, result.face_part)
    assert result.info["parts"] == 1  # one frame fits the whole plate
    assert result.info["junctions"] >= 2


def test_absorb_tangent_cuts_merges_a_cap_cut_along_its_wall():
    """A unit sphere cut by the plane z = cos 30 deg: the cap's faces next to the cut have normals
    within about 30 degrees of the cut's axis (z), so they make up more than TANGENT_SHARE of the
    cap and the cap joins the rest; cut at the equator, the faces next to the cut are
    perpendicular to it (share 0) and the halves are kept."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces, dtype=np.int64)
    z = V[F].mean(axis=1)[:, 2]
    cap = (z > np.cos(np.radians(30.0))).astype(np.int64)
    share, pairs, part_share = tangent_cut_shares(V, F, cap)
    assert pairs.tolist() == [[0, 1]] and share[1, 0] >= TANGENT_SHARE > share[0, 0]
    assert part_share[1] <= TANGENT_AREA and abs(part_share.sum() - 1.0) < 1e-12
    assert len(np.unique(absorb_tangent_cuts(V, F, cap))) == 1
    # the same cap counts as a member when it may be a larger share of the surface than it is
    assert np.array_equal(absorb_tangent_cuts(V, F, cap, max_area=0.5 * part_share[1]), cap)
    halves = (z > 0).astype(np.int64)
    share, _, _ = tangent_cut_shares(V, F, halves)
    assert share.max() < 0.01
    assert np.array_equal(absorb_tangent_cuts(V, F, halves), halves)


@pytest.mark.slow
def test_automatic_parts_of_idler_riser_are_cut_across():
    """The curve skeleton of idler_riser ends in a small sliver of a curved wall whose cut runs
    along it (Eq. 3's term 4 would label it well above its nearest directions); no automatic
    part may keep such a cut."""
    mesh = _load("idler_riser.stl")
    part = skeleton_segmentation(mesh).face_part
    validate_face_part(mesh, part)
    share, _, part_share = tangent_cut_shares(mesh.vertices, mesh.faces, part)
    small = share[part_share <= TANGENT_AREA]
    assert small.size == 0 or small.max() < TANGENT_SHARE


def test_automatic_parameter_errors(bar):
    with pytest.raises(ParameterError, match="merge_angle"):
        automatic_parts(bar, merge_angle=0.0)
    with pytest.raises(ParameterError, match="resolution"):
        automatic_parts(bar, resolution=2)
    with pytest.raises(ParameterError, match="too few"):
        automatic_parts(bar, max_parts=len(bar.faces) // MIN_PART_FACES + 1)


@pytest.mark.slow
@pytest.mark.parametrize("name, low, high", [("to_simp_lbracket.stl", 2, 8),
                                             ("polycube_bone.obj", 1, 4)])
def test_automatic_parts_on_dev_meshes(name, low, high):
    mesh = _load(name)
    result = skeleton_segmentation(mesh)
    part = validate_face_part(mesh, result.face_part)
    n_parts = part.max() + 1
    assert low <= n_parts <= high
    assert np.bincount(part).min() >= MIN_PART_FACES
    assert all(itf.closed == [True] for itf in interfaces(mesh, part))


def test_frames_validity_and_repair_share_one_interface_grouping_and_axis(bar):
    """Three parts meeting at two junction points: the interfaces (frames), the per-edge axes
    (validity) and the per-face axes (labeling term 4, and the repair when it is not given
    them) all come from ``interface_pieces`` and ``interface_x_axis``."""
    from core.mesh_topology import edge_faces
    from core.segmentation.charts import build_topology
    from core.segmentation.frames import compute_frames
    from core.segmentation.labeling import hbecvt_labeling
    from core.segmentation.parts import face_interface_axes, interface_pieces, interface_x_axis
    from core.segmentation.repair import repair_labeling
    from core.segmentation.validity import edge_interface_axes

    c = _centroids(bar)
    part = validate_face_part(bar, np.where(c[:, 0] < 5.0, 0, np.where(c[:, 1] < 1.0, 1, 2)))
    itfs = interfaces(bar, part)
    edges, fe = edge_faces(bar.faces)
    pieces = interface_pieces(edges, fe, part, len(bar.vertices))
    assert [pair for pair, _ in pieces] == [itf.parts for itf in itfs] == [(0, 1), (0, 2), (1, 2)]
    assert all(np.array_equal(edges[index], itf.edges) for (_, index), itf in zip(pieces, itfs))
    assert [itf.closed for itf in itfs] == [[False]] * 3  # open chains between the junctions

    topo = build_topology(bar.faces, len(bar.vertices))
    row = {edge: k for k, edge in enumerate(map(tuple, topo.edges.tolist()))}
    expected = np.zeros((len(topo.edges), 3))
    for itf in itfs:
        expected[[row[edge] for edge in map(tuple, itf.edges.tolist())]] = \
            interface_x_axis(bar.vertices[itf.vertices])
    assert np.array_equal(edge_interface_axes(bar.vertices, topo, part), expected)

    field = compute_frames(bar, part, blend_distance=0.5)
    face_itf, axis = face_interface_axes(bar.faces, part, itfs, bar.vertices)
    assert np.array_equal(face_itf, field.face_interface)
    assert np.array_equal(axis, field.face_interface_axis, equal_nan=True)
    near = np.flatnonzero(face_itf >= 0)
    pairs = np.array([itf.parts for itf in itfs])[face_itf[near]]
    assert ((pairs == part[near, None]).any(axis=1)).all()  # never another pair's axis

    # a band of +Y across the junctions gives the repair work where the axes matter (a
    # junction face given another interface's axis would be repaired differently)
    labels = hbecvt_labeling(bar.vertices, bar.faces, part, field.face_frame, max_sweeps=3)[0]
    labels[np.abs(c[:, 0] - 5.0) < 1.3] = 2
    given = repair_labeling(bar.vertices, bar.faces, part, labels, field.face_frame,
                            field.face_interface_axis)
    derived = repair_labeling(bar.vertices, bar.faces, part, labels, field.face_frame)
    assert (given[0] != labels).sum() > 10
    assert np.array_equal(given[0], derived[0]) and given[1] == derived[1]
