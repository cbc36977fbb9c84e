# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polycube deformation (core.polycube.deform) and wireframe (core.polycube.wireframe)."""
import numpy as np
import pytest
import trimesh

from core.errors import ParameterError
from core.polycube.deform import polycube_deformation, rotations_to
from core.segmentation.charts import build_topology, extract_layout


def nearest_labels(V, F, frame):
    """Label 0..5 of the frame direction closest to each face normal."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]) @ np.asarray(frame).T
    return np.argmax(np.concatenate([n, -n], axis=1)[:, [0, 3, 1, 4, 2, 5]], axis=1)


def box_mesh():
    mesh = trimesh.creation.box(extents=(2.0, 3.0, 4.0)).subdivide().subdivide()
    V = np.asarray(mesh.vertices, dtype=np.float64) + np.array([1.0, -2.0, 0.5])
    return V, np.asarray(mesh.faces, dtype=np.int64)


def sphere_mesh():
    mesh = trimesh.creation.icosphere(3)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def random_rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("method, weighting", [("fast", "relative"), ("fast", "uniform"),
                                               ("iterative", "relative")])
def test_box_deforms_to_itself(method, weighting):
    V, F = box_mesh()
    labels = nearest_labels(V, F, np.eye(3))
    r = polycube_deformation(V, F, labels, np.eye(3), method=method, weighting=weighting)
    assert r.info["charts"] == 6
    assert r.info["flipped"] == 0 and r.info["degenerate"] == 0
    assert r.info["max_chart_planarity"] <= 1e-9
    assert r.info["max_normal_deviation_deg"] <= 1e-6
    # a box is already a polycube: the deformation reproduces it
    assert np.abs(r.vertices - V).max() <= 1e-9
    expected = {0: 2.0, 1: 0.0, 2: -0.5, 3: -3.5, 4: 2.5, 5: -1.5}
    for chart, label in enumerate(r.chart_label):
        assert abs(r.chart_plane[chart] - expected[int(label)]) <= 1e-9


def test_sphere_gives_cube_like_polycube():
    V, F = sphere_mesh()
    labels = nearest_labels(V, F, np.eye(3))
    r = polycube_deformation(V, F, labels, np.eye(3))
    assert r.info["charts"] == 6 and sorted(r.chart_label.tolist()) == [0, 1, 2, 3, 4, 5]
    assert r.info["flipped"] == 0
    assert r.info["max_chart_planarity"] <= 1e-12
    # every chart plane lies on its side of the centre, the result is a box-like solid
    sign = np.where(r.chart_label % 2 == 0, 1.0, -1.0)
    assert np.all(sign * r.chart_plane > 0.4)
    extent = np.ptp(r.vertices, axis=0)
    assert np.all(extent > 1.0) and extent.max() / extent.min() < 1.1
    # the only zero-area faces are staircase teeth: all three corners on chart boundaries
    layout = extract_layout(build_topology(F, len(V)), np.zeros(len(F), int), labels)
    teeth = (layout.vertex_sep_degree[F] > 0).all(axis=1)
    assert np.all(teeth[r.degenerate])
    assert r.info["max_normal_deviation_deg"] <= 1e-6


def test_rotated_frame_gives_rotated_result():
    V, F = sphere_mesh()
    R = random_rotation(3)
    labels = nearest_labels(V, F, np.eye(3))
    base = polycube_deformation(V, F, labels, np.eye(3))
    # rotating the mesh by R turns frame rows e_i into (R e_i)^T, i.e. the frame matrix R.T
    rot = polycube_deformation(V @ R.T, F, labels, R.T)
    assert np.abs(rot.vertices - base.vertices @ R.T).max() <= 1e-9
    assert np.abs(rot.local - base.local).max() <= 1e-9
    assert rot.info["flipped"] == base.info["flipped"]


def test_deterministic():
    V, F = sphere_mesh()
    labels = nearest_labels(V, F, np.eye(3))
    a = polycube_deformation(V, F, labels, np.eye(3), method="iterative", iterations=5)
    b = polycube_deformation(V, F, labels, np.eye(3), method="iterative", iterations=5)
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.flipped, b.flipped)
    assert len(a.history) == 6


def test_two_parts_are_solved_in_their_own_frames():
    V, F = box_mesh()
    labels = nearest_labels(V, F, np.eye(3))
    centroid_x = V[F].mean(axis=1)[:, 0]
    part = (centroid_x > 1.0).astype(np.int64)
    R = random_rotation(5)
    frames = np.stack([np.eye(3), R])
    face_frame = frames[part]
    labels = np.where(part == 0, labels, nearest_labels(V, F, R))
    r = polycube_deformation(V, F, labels, face_frame, part, part_frames=frames)
    assert len(r.parts) == 2
    shared = np.intersect1d(r.parts[0].vertex_ids, r.parts[1].vertex_ids)
    assert r.info["interface_vertices"] == len(shared) > 0
    for p in r.parts:
        assert np.allclose(p.local @ p.frame, p.world)
    assert r.info["max_chart_planarity"] <= 1e-9


def test_rotations_to():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = rng.normal(size=(50, 3))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    b[0], b[1] = -a[0], a[1]
    R = rotations_to(a, b)
    assert np.abs(np.einsum("fij,fj->fi", R, a) - b).max() <= 1e-12
    assert np.abs(np.einsum("fij,fkj->fik", R, R) - np.eye(3)).max() <= 1e-12
    assert np.all(np.linalg.det(R) > 0.999)


@pytest.mark.parametrize("change, match", [
    (lambda a: a.update(face_label=np.where(np.arange(len(a["F"])) == 3, 6, a["face_label"])),
     "outside 0..5"),
    (lambda a: a.update(face_label=a["face_label"][:-1]), "face_label"),
    (lambda a: a.update(face_label=a["face_label"].astype(float)), "face_label"),
    (lambda a: a.update(V=a["V"][:, :2]), "vertices"),
    (lambda a: a.update(F=a["F"] + len(a["V"])), "outside"),
    (lambda a: a.update(face_frame=np.eye(3) * 2.0), "orthonormal"),
    (lambda a: a.update(face_frame=np.eye(4)), "face_frame"),
    (lambda a: a.update(face_part=-np.ones(len(a["F"]), int)), "negative part"),
    (lambda a: a.update(method="magic"), "method"),
    (lambda a: a.update(iterations=-1), "iterations"),
    (lambda a: a.update(weighting="cot"), "weighting"),
])
def test_bad_inputs_raise(change, match):
    V, F = box_mesh()
    args = dict(V=V, F=F, face_label=nearest_labels(V, F, np.eye(3)), face_frame=np.eye(3))
    change(args)
    with pytest.raises(ParameterError, match=match):
        polycube_deformation(**args)


@pytest.mark.parametrize("mesh", [box_mesh, sphere_mesh])
def test_wireframe_of_box_and_sphere(mesh):
    from core.polycube.wireframe import extract_wireframe, straighten_wireframe

    V, F = mesh()
    labels = nearest_labels(V, F, np.eye(3))
    r = polycube_deformation(V, F, labels, np.eye(3))
    wf, layout = extract_wireframe(F, np.zeros(len(F), int), labels, len(V))
    assert len(wf.corners) == 8 and len(wf.chains) == 12 and not wf.closed.any()
    assert np.isin(wf.edges, wf.corners).all()
    # each boundary runs along the axis perpendicular to both chart labels, four per axis
    assert np.bincount(wf.axis, minlength=3).tolist() == [4, 4, 4]
    axes = layout.chart_label[wf.charts] // 2
    assert np.all((axes[:, 0] != wf.axis) & (axes[:, 1] != wf.axis))
    straight, deviation, extent = straighten_wireframe(r.local, wf, layout, r.chart_plane)
    # planar charts already give straight wireframe edges
    assert deviation.max() <= 1e-12
    assert np.array_equal(straight, r.local)
    # every wireframe edge spans the polycube's full extent along its axis
    size = np.ptp(r.local, axis=0)
    assert np.allclose(np.abs(extent), size[wf.axis], atol=1e-9)


def test_straighten_moves_perturbed_chains_onto_plane_lines():
    from core.polycube.wireframe import extract_wireframe, straighten_wireframe

    V, F = box_mesh()
    labels = nearest_labels(V, F, np.eye(3))
    r = polycube_deformation(V, F, labels, np.eye(3))
    wf, layout = extract_wireframe(F, np.zeros(len(F), int), labels, len(V))
    noisy = r.local + 1e-3 * np.random.default_rng(1).normal(size=r.local.shape)
    straight, deviation, _ = straighten_wireframe(noisy, wf, layout, r.chart_plane)
    assert 1e-4 < deviation.max() < 1e-2
    for chain, charts in zip(wf.chains, wf.charts):
        for chart in charts:
            k = layout.chart_label[chart] // 2
            assert np.all(straight[chain, k] == r.chart_plane[chart])
