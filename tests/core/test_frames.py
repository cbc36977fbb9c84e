# SPDX-License-Identifier: LGPL-2.1-or-later
"""PCA frames of parts and interfaces and the blended per-face frames."""
import manifold3d as m3
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from core.errors import ParameterError
from core.segmentation.frames import (
    CUBE_GROUP, compute_frames, match_frame, quaternion_to_rotation, rotation_to_quaternion,
)
from core.segmentation.part_frame import part_frames, pca_frame
from core.segmentation.parts import parts_from_user
from core.types import TriMesh


def _mesh(manifold):
    out = manifold.to_mesh()
    return TriMesh(np.asarray(out.vert_properties[:, :3], dtype=np.float64),
                   np.asarray(out.tri_verts, dtype=np.int64))


def _angle_deg(a, b):
    """Rotation angle between two (3, 3) frames in degrees."""
    c = (np.trace(a @ b.T) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def test_pca_box_cloud_axes_sorted_by_extent_and_right_handed():
    rng = np.random.default_rng(1)
    rot = Rotation.from_euler("xyz", [20, -35, 50], degrees=True).as_matrix()
    pts = rng.uniform(-1, 1, size=(4000, 3)) * [7.0, 1.0, 3.0]
    frame = pca_frame(pts @ rot.T)
    # smallest extent (world axis 1) -> x, then axis 2 -> y, largest (axis 0) -> z
    for row, world_axis in zip(frame, [1, 2, 0]):
        assert abs(row @ rot[:, world_axis]) > 0.995
    assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-12)
    for row in frame[:2]:  # sign convention: largest world component positive
        assert row[np.argmax(np.abs(row))] > 0


def test_pca_invariant_to_point_order():
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(500, 3)) * [1.0, 2.0, 5.0]
    perm = rng.permutation(len(pts))
    assert np.allclose(pca_frame(pts), pca_frame(pts[perm]), atol=1e-12)


def test_part_frames_invariant_to_vertex_and_face_order():
    mesh = _mesh(m3.Manifold.cube([6.0, 1.0, 2.5]).rotate([10, 20, 30]).refine(3))
    face_part = np.zeros(len(mesh.faces), dtype=np.int64)
    rng = np.random.default_rng(3)
    vperm = rng.permutation(len(mesh.vertices))
    inverse = np.argsort(vperm)
    fperm = rng.permutation(len(mesh.faces))
    shuffled = (mesh.vertices[vperm], inverse[mesh.faces][fperm])
    for mode in ("area", "vertices"):
        a = part_frames(mesh.vertices, mesh.faces, face_part, mode=mode)
        b = part_frames(*shuffled, face_part, mode=mode)
        assert np.allclose(a, b, atol=1e-10)


def test_area_frame_ignores_uneven_meshing_but_vertex_frame_does_not():
    """A 4 x 3 x 1 box whose +x half is meshed much finer: the area-weighted frame equals
    the box axes; Eq. 1 on vertices is pulled towards the dense half."""
    box = m3.Manifold.cube([4.0, 3.0, 1.0]).rotate([0, 0, 25])
    fine = (box ^ m3.Manifold.cube([10, 10, 10]).translate([1.5, -5, -5])).refine(6)
    coarse = box - m3.Manifold.cube([10, 10, 10]).translate([1.5, -5, -5])
    mesh = _mesh(fine + coarse)
    part = np.zeros(len(mesh.faces), dtype=np.int64)
    area = part_frames(mesh.vertices, mesh.faces, part, mode="area", align_degenerate=False)[0]
    ref = Rotation.from_euler("z", 25, degrees=True).as_matrix()
    assert abs(area[0] @ [0, 0, 1]) > 1 - 1e-9           # thinnest (z) -> x
    assert abs(area[1] @ ref[:, 1]) > 1 - 1e-9           # 3-long side -> y
    verts = part_frames(mesh.vertices, mesh.faces, part, mode="vertices",
                        align_degenerate=False)[0]
    assert abs(verts[2] @ ref[:, 0]) < 1 - 1e-4


def test_degenerate_pca_axes_are_aligned_to_the_normals():
    """Square bar turned 30 degrees about its long axis: PCA leaves y, z free; the
    alignment puts them on the side faces' normals."""
    bar = m3.Manifold.cube([2.0, 2.0, 12.0], center=True).rotate([0, 0, 30]).refine(2)
    mesh = _mesh(bar)
    part = np.zeros(len(mesh.faces), dtype=np.int64)
    frame = part_frames(mesh.vertices, mesh.faces, part)[0]
    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.abs(n @ frame.T).max(axis=1).min() > 1 - 1e-9
    assert np.linalg.det(frame) == pytest.approx(1.0)


def test_quaternion_round_trip_and_cube_group():
    mats = Rotation.random(50, random_state=4).as_matrix()
    back = quaternion_to_rotation(rotation_to_quaternion(mats))
    assert np.allclose(back, mats, atol=1e-10)
    assert len(CUBE_GROUP) == 24
    assert np.allclose(np.linalg.det(CUBE_GROUP), 1.0)
    frame = mats[0]
    matched = match_frame(CUBE_GROUP[7] @ frame, frame)
    assert np.allclose(matched, frame, atol=1e-12)


def _bent_bar(length_b=10.0):
    """Two 2 x 2 bars, 10 long along -x and ``length_b`` long at 30 degrees above +x, cut at
    x = 0."""
    leg_a = m3.Manifold.cube([10.0, 2.0, 2.0]).translate([-10.0, 0.0, 0.0])
    leg_b = m3.Manifold.cube([length_b, 2.0, 2.0]).rotate([0, -30, 0])
    mesh = _mesh((leg_a + leg_b).refine(5))
    face_part = parts_from_user(mesh, [((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))])
    return mesh, face_part


def test_blended_frames_orthonormal_part_far_interface_near():
    mesh, face_part = _bent_bar()
    assert face_part.max() == 1
    field = compute_frames(mesh, face_part)
    frames = field.face_frame
    assert np.allclose(np.einsum("fij,fkj->fik", frames, frames), np.eye(3), atol=1e-10)
    assert np.allclose(np.linalg.det(frames), 1.0, atol=1e-10)
    assert len(field.interfaces) == 1
    itf = field.interfaces[0]
    assert itf.closed == [True]
    dist = field.face_interface_distance
    far = dist >= field.blend_distance
    assert far.sum() > len(dist) // 2
    assert np.array_equal(frames[far], field.part_frames[face_part[far]])
    # the interface frame is one leg's own frame: that leg keeps it up to the interface
    offset = [_angle_deg(field.part_frames[p], match_frame(itf.frame, field.part_frames[p]))
              for p in (0, 1)]
    keep = int(np.argmin(offset))
    assert offset[keep] < 1e-4
    assert np.allclose(frames[face_part == keep], field.part_frames[keep], atol=1e-9)
    for p in (1 - keep,):
        target = match_frame(itf.frame, field.part_frames[p])
        total = _angle_deg(field.part_frames[p], target)
        assert total > 5.0  # the two legs really have different frames
        sel = np.flatnonzero(face_part == p)
        ang = np.array([_angle_deg(frames[f], target) for f in sel])
        near = dist[sel] < 0.05 * field.blend_distance
        assert near.any() and ang[near].max() < 0.05 * total
        mid = (dist[sel] > 0.3 * field.blend_distance) & (dist[sel] < 0.7 * field.blend_distance)
        assert mid.any()
        assert (ang[mid] > 0.05 * total).all() and (ang[mid] < 0.95 * total).all()
        # the blend turns monotonically with the distance (no spin)
        order = np.argsort(dist[sel])
        inside = dist[sel][order] < field.blend_distance
        assert np.all(np.diff(ang[order][inside]) > -0.5)


@pytest.mark.parametrize("length_b", [3.0, 16.0])
def test_the_part_mostly_inside_its_blend_band_keeps_its_frame(length_b):
    """Of two legs, the one whose blend band is the larger share of it (the shorter) keeps its
    own frame on every face; the other turns towards it near the interface (up to axis order)
    and keeps its own from the blend distance on."""
    mesh, face_part = _bent_bar(length_b)
    field = compute_frames(mesh, face_part)
    short = 1 if length_b < 10.0 else 0
    frames = field.face_frame
    assert np.allclose(frames[face_part == short], field.part_frames[short], atol=1e-9)
    turn = 1 - short
    own = field.part_frames[turn]
    target = match_frame(field.part_frames[short], own)
    assert _angle_deg(own, target) > 20.0
    total = _angle_deg(own, target)
    sel = np.flatnonzero(face_part == turn)
    dist = field.face_interface_distance[sel]
    at = sel[dist <= dist.min() + 1e-12]  # the faces nearest the interface: turned most
    assert max(_angle_deg(frames[f], target) for f in at) < 0.5 * total
    far = dist >= field.blend_distance
    assert np.allclose(frames[sel[far]], own, atol=1e-12)


def test_face_interface_axis_is_the_loop_normal():
    mesh = _mesh(m3.Manifold.cylinder(10.0, 1.0, 1.0, 48).refine(4))  # vertex rings at z = 5
    face_part = parts_from_user(mesh, [((0.0, 0.0, 5.0), (0.0, 0.0, 1.0))])
    field = compute_frames(mesh, face_part, blend_distance=1.0)
    nxt = field.face_interface >= 0
    assert nxt.sum() > 0
    assert np.isnan(field.face_interface_axis[~nxt]).all()
    assert np.allclose(np.abs(field.face_interface_axis[nxt] @ [0, 0, 1]), 1.0, atol=1e-9)
    # next to the interface = a vertex on the cut ring (Eq. 3 term 4 band)
    on_ring = (np.abs(mesh.vertices[mesh.faces][:, :, 2] - 5.0) < 1e-9).any(axis=1)
    assert np.array_equal(nxt, on_ring)


def test_compute_frames_rejects_bad_blend_distance():
    mesh, face_part = _bent_bar()
    with pytest.raises(ParameterError, match="blend_distance"):
        compute_frames(mesh, face_part, blend_distance=0.0)
    with pytest.raises(ParameterError, match="mode"):
        compute_frames(mesh, face_part, mode="median")


def test_face_interface_axis_is_the_axis_validity_judges_with():
    # a saddle-shaped (non-planar) interface: the x-axis is not obvious, so both stages must use
    # the same definition (Eq. 1 over the interface vertices)
    from core.segmentation.charts import build_topology
    from core.segmentation.parts import interface_x_axis
    from core.segmentation.validity import edge_interface_axes

    mesh = _mesh(m3.Manifold.cylinder(10.0, 2.0, 2.0, 48).refine(4))
    c = mesh.vertices[mesh.faces].mean(axis=1)
    face_part = (c[:, 2] > 5.0 + 0.8 * c[:, 0] * c[:, 1]).astype(np.int64)
    field = compute_frames(mesh, face_part, blend_distance=1.0)
    assert len(field.interfaces) == 1
    itf = field.interfaces[0]
    x = interface_x_axis(mesh.vertices[itf.vertices])
    nxt = field.face_interface >= 0
    assert np.allclose(np.abs(field.face_interface_axis[nxt] @ x), 1.0, atol=1e-12)
    topo = build_topology(mesh.faces, len(mesh.vertices))
    edge_ix = edge_interface_axes(mesh.vertices, topo, face_part)
    on = np.linalg.norm(edge_ix, axis=1) > 0
    assert on.sum() == len(itf.edges)
    assert np.allclose(np.abs(edge_ix[on] @ x), 1.0, atol=1e-12)
    # every face of an interface edge is in the term-4 band
    assert nxt[topo.edge_faces[on].reshape(-1)].all()
