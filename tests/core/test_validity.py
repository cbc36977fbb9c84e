# SPDX-License-Identifier: LGPL-2.1-or-later
"""Charts, boundaries, corners and validity rules on hand-checkable labelings of a cube."""
import numpy as np
import pytest
import trimesh

from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from core.segmentation.charts import (boundary_chains, build_topology, extract_layout,
                                      find_charts)
from core.segmentation.labeling import face_normals, nearest_direction_labels
from core.segmentation.validity import check_validity, corner_axes_valid

IDENTITY = np.eye(3)


def cube(levels=3):
    """Unit cube [0, 1]^3 with 12 * 4**levels triangles."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = np.asarray(box.vertices) + 0.5, np.asarray(box.faces)
    for _ in range(levels):
        V, F = trimesh.remesh.subdivide(V, F)
    return np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)


def frames(m):
    return np.broadcast_to(IDENTITY, (m, 3, 3)).copy()


def centroids(V, F):
    return V[F].mean(axis=1)


def judge(V, F, labels, parts=None, **kw):
    m = len(F)
    parts = np.zeros(m, dtype=np.int64) if parts is None else parts
    return check_validity(V, F, parts, labels, frames(m), **kw)


@pytest.mark.parametrize("n_labels, n_parts", [(1, 1), (2, 1), (6, 2), (6, 5)])
def test_charts_match_scipy_components_numbered_by_lowest_face(n_labels, n_parts):
    V, F = cube(3)
    rng = np.random.default_rng(10 * n_labels + n_parts)
    labels = rng.integers(0, n_labels, len(F))
    parts = rng.integers(0, n_parts, len(F))
    topology = build_topology(F, len(V))
    chart = find_charts(topology, parts, labels)
    assert chart.shape == (len(F),) and chart.dtype == np.int64
    f, g = topology.edge_faces.T
    same = (f >= 0) & (g >= 0) & (labels[f] == labels[g]) & (parts[f] == parts[g])
    graph = coo_matrix((np.ones(same.sum()), (f[same], g[same])), shape=(len(F), len(F)))
    _, ref = connected_components(graph, directed=False)
    # same partition: the two numberings map one to one
    pairs = np.unique(np.stack([chart, ref], axis=1), axis=0)
    assert len(pairs) == len(np.unique(chart)) == len(np.unique(ref))
    # ids in the order of each chart's lowest face
    first = np.unique(chart, return_index=True)[1]
    assert np.array_equal(chart[np.sort(first)], np.arange(len(first)))


def test_cube_by_normals_is_valid_polycube():
    V, F = cube()
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F)))
    v = judge(V, F, labels)
    r = v.report
    assert r["valid"] and r["monotone"]
    assert (r["charts"], r["boundaries"], r["corners"]) == (6, 12, 8)
    assert r["turning_points"]["count"] == 0
    lay = v.layout
    assert (lay.chart_boundary_count == 4).all()
    assert np.array_equal(np.sort(lay.chart_label), np.arange(6))
    # every cube edge's axis is the one perpendicular to both labels
    ca, cb = lay.boundary_charts.T
    la, lb = lay.chart_label[ca], lay.chart_label[cb]
    assert np.array_equal(v.boundary_axis, 3 - la // 2 - lb // 2)
    # each boundary is a straight cube edge along its axis: 8 mesh edges of length 1/8
    topo = build_topology(F, len(V))
    for b, (verts, _edges, closed) in enumerate(boundary_chains(topo, lay)):
        assert not closed and len(verts) == 9
        span = np.ptp(V[verts], axis=0)
        assert span[v.boundary_axis[b]] == pytest.approx(1.0)
        assert np.delete(span, v.boundary_axis[b]) == pytest.approx([0.0, 0.0])


def test_island_chart_is_invalid_and_turns():
    V, F = cube()
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F)))
    corner = V[F]
    island = ((corner[:, :, 2] > 0.99) & (np.abs(corner[:, :, 0] - 0.5) < 0.26)
              & (np.abs(corner[:, :, 1] - 0.5) < 0.26)).all(axis=1)
    labels[island] = 0  # +X inside the +Z face
    r = judge(V, F, labels).report
    assert r["charts"] == 7
    assert r["invalid_charts"]["count"] == 1
    ex = r["invalid_charts"]["examples"][0]
    assert ex["label"] == "+X" and ex["boundaries"] == 1 and ex["faces"] == int(island.sum())
    assert r["invalid_boundaries"]["count"] == 0 and r["invalid_corners"]["count"] == 0
    # the island's boundary is a closed loop around a +X/+Z boundary with axis Y: it must turn
    assert r["turning_points"]["count"] >= 2
    assert not r["valid"]


def test_three_boundary_chart_is_invalid():
    V, F = cube()
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F)))
    corner = V[F]
    top_half = ((corner[:, :, 2] > 0.99) & (corner[:, :, 0] >= corner[:, :, 1] - 1e-9)).all(axis=1)
    labels[top_half] = 0  # the +X chart takes the triangle x > y of the top face
    v = judge(V, F, labels)
    r = v.report
    bad = np.flatnonzero(v.invalid_chart)
    # the +Z triangle keeps -X, +Y and +X around it; the -Y face now meets the grown +X chart
    # along one bent boundary (the bend at (1, 0, 1) is no corner: only two charts meet there)
    assert sorted(v.layout.chart_label[bad].tolist()) == [3, 4]
    assert (v.layout.chart_boundary_count[bad] == 3).all()
    assert r["invalid_boundaries"]["count"] == 0


def test_opposite_boundary_and_its_corners_are_invalid():
    V, F = cube()
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F)))
    c = centroids(V, F)
    labels[(c[:, 2] > 0.99)] = 0  # the top face joins +X, so +X now touches -X along x = 0
    v = judge(V, F, labels)
    r = v.report
    assert r["invalid_boundaries"]["count"] == 1
    ex = r["invalid_boundaries"]["examples"][0]
    assert sorted(ex["labels"]) == ["+X", "-X"] and ex["reason"] == "opposite_labels"
    assert ex["point"][0] == pytest.approx(0.0) and ex["point"][2] == pytest.approx(1.0)
    # the two ends of that boundary are corners with an axis-less edge
    assert r["invalid_corners"]["count"] == 2
    assert r["invalid_corners"]["at_interfaces"] == r["invalid_boundaries"]["at_interfaces"] == 0
    assert all(e["point"][0] == pytest.approx(0.0) for e in r["invalid_corners"]["examples"])


def two_part_cube():
    V, F = cube()
    c = centroids(V, F)
    parts = (c[:, 0] > 0.5).astype(np.int64)
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F)))
    return V, F, parts, labels, c


def test_part_interface_edges_are_boundaries_and_corners_follow_interface_rules():
    V, F, parts, labels, _ = two_part_cube()
    v = judge(V, F, labels, parts)
    r = v.report
    # 6 charts per half-cube minus the missing cap on the interface side: 5 + 5
    assert r["charts"] == 10
    assert r["valid"], r
    # interface boundaries (between parts) are marked and counted for both charts
    assert (v.boundary_axis == -2).sum() == 4
    assert (v.layout.chart_boundary_count >= 4).all()
    # corners where cube edges cross the interface: 4 (plus the 8 cube corners)
    assert r["corners"] == 12


def test_label_parallel_to_interface_axis_is_invalid():
    V, F, parts, labels, c = two_part_cube()
    near_iface = (parts == 1) & (c[:, 0] < 0.5 + 1.0 / 8) & (c[:, 1] > 0.99)
    labels[near_iface] = 0  # +X faces touching the interface (its x-axis is world X)
    r = judge(V, F, labels, parts).report
    reasons = {e["reason"] for e in r["invalid_boundaries"]["examples"]}
    assert "label_parallel_to_interface" in reasons
    assert not r["valid"]
    # the interface-rule items are counted apart (an interface-blind check cannot see them)
    v = judge(V, F, labels, parts)
    assert r["invalid_boundaries"]["at_interfaces"] == int((v.boundary_reason == 2).sum()) >= 1
    assert 1 <= r["invalid_corners"]["at_interfaces"] <= r["invalid_corners"]["count"]


def test_single_chart_and_layout_bookkeeping():
    V, F = cube(1)
    m = len(F)
    topo = build_topology(F, len(V))
    lay = extract_layout(topo, np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64))
    assert lay.n_charts == 1 and lay.n_boundaries == 0 and len(lay.corners) == 0
    assert lay.chart_boundary_count.tolist() == [0]
    r = judge(V, F, np.zeros(m, dtype=np.int64)).report
    assert r["invalid_charts"]["count"] == 1 and not r["valid"]


def test_local_count_matches_whole_mesh_judgement():
    """Judging a change on the submesh around it gives the same invalid-count change as judging
    the whole mesh (random patches relabelled on a two-part cube, interface rules included)."""
    from core.segmentation.validity import counts_near, edge_interface_axes, local_invalid_count

    V, F = cube()
    m = len(F)
    parts = (centroids(V, F)[:, 0] > 0.5).astype(np.int64)
    labels = nearest_direction_labels(face_normals(V, F), frames(m)).astype(np.int64)
    topo = build_topology(F, len(V))
    edge_ix = edge_interface_axes(V, topo, parts)
    base = judge(V, F, labels, parts)
    rng = np.random.default_rng(7)
    for _ in range(25):
        cand = labels.copy()
        patch = np.flatnonzero(np.linalg.norm(centroids(V, F) - V[rng.integers(len(V))], axis=1)
                               < rng.uniform(0.05, 0.3))
        cand[patch] = rng.integers(6)
        vmask = np.zeros(len(V), dtype=bool)
        vmask[F[cand != labels]] = True
        touched = np.unique(base.layout.face_chart[vmask[F].any(axis=1)])
        vz = np.zeros(len(V), dtype=bool)
        vz[F[np.isin(base.layout.face_chart, touched)]] = True
        faces = np.flatnonzero(vz[F].any(axis=1))
        args = (F, topo, parts)
        old = local_invalid_count(*args, labels, frames(m), edge_ix, faces, vmask)
        assert counts_near(F, topo, base, vmask)[:4] == old  # read off the whole judgement
        new = local_invalid_count(*args, cand, frames(m), edge_ix, faces, vmask)
        full = judge(V, F, cand, parts)
        assert base.n_invalid + sum(new[:3]) - sum(old[:3]) == full.n_invalid
        assert new[3] == (full.boundary_reason == 1).sum()


@pytest.mark.parametrize("counts, valid", [
    ((1, 1, 1, 0), True),    # X, Y, Z group (a cube corner)
    ((2, 2, 0, 0), True),    # two pairs
    ((1, 1, 3, 0), True),    # a group plus a pair
    ((0, 2, 4, 0), True),    # pairs of two axes
    ((0, 0, 2, 0), True),    # plain pass-through of one axis
    ((0, 0, 3, 0), False),   # one axis alone, three times
    ((0, 0, 4, 0), False),   # one axis alone, four times
    ((0, 6, 0, 0), False),
    ((2, 1, 0, 0), False),   # parities differ
    ((1, 1, 0, 0), False),
    ((1, 1, 1, 1), False),   # an edge without axis (opposite labels)
    ((0, 0, 0, 3), False),
])
def test_corner_axis_rule(counts, valid):
    assert corner_axes_valid(np.array([counts]))[0] == valid


def quadrant_top_labels(quadrant_labels):
    """Cube labels by normals, the top face split into quadrants around (0.5, 0.5, 1) with
    ``quadrant_labels`` for (NE, NW, SW, SE); returns V, F, labels and the centre vertex."""
    V, F = cube()
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F))).astype(np.int64)
    c = centroids(V, F)
    top = c[:, 2] > 0.99
    east, north = c[:, 0] > 0.5, c[:, 1] > 0.5
    for (e, n), lab in zip([(True, True), (False, True), (False, False), (True, False)],
                           quadrant_labels):
        labels[top & (east == e) & (north == n)] = lab
    centre = int(np.argmin(np.linalg.norm(V - [0.5, 0.5, 1.0], axis=1)))
    return V, F, labels, centre


def test_one_axis_corner_of_four_boundaries_is_invalid():
    """Top quadrants +X, +Y, -X, -Y merge with the side faces; the four boundaries at the top
    centre all run along Z (what the parity rule alone accepted)."""
    V, F, labels, centre = quadrant_top_labels([0, 2, 1, 3])
    r = judge(V, F, labels).report
    assert r["invalid_boundaries"]["count"] == 0
    assert r["invalid_corners"]["count"] == 1
    ex = r["invalid_corners"]["examples"][0]
    assert ex["vertex"] == centre and sorted(ex["axes"]) == ["Z"] * 4
    assert not r["valid"]


def test_pair_and_group_corners_are_valid():
    """Top quadrants +Z, -X, +Z, -Y: the centre has edges X, X, Y, Y (two pairs); the other
    corners are X, Y, Z groups; none is invalid."""
    V, F, labels, centre = quadrant_top_labels([4, 1, 4, 3])
    v = judge(V, F, labels)
    r = v.report
    assert centre in v.layout.corners.tolist()
    lay = v.layout
    at_centre = (build_topology(F, len(V)).edges[lay.sep_edges] == centre).any(axis=1)
    assert sorted(v.boundary_axis[lay.sep_boundary[at_centre]].tolist()) == [0, 0, 1, 1]
    assert r["invalid_corners"]["count"] == 0 and r["invalid_boundaries"]["count"] == 0
    # the 8 cube corners minus (1, 0, 1) and (0, 1, 1), where only two charts meet now, plus
    # the centre and the two points where a quadrant boundary reaches a side chart
    assert r["corners"] == 9


def test_turning_points_added_to_a_judgement_match_a_full_check():
    """A judgement without turning points, completed by ``with_turning_points``, reports what
    ``check_validity`` with turning points does (a labeling with turning points: the island)."""
    from core.segmentation.validity import with_turning_points

    V, F = cube()
    c = centroids(V, F)
    labels = nearest_direction_labels(face_normals(V, F), frames(len(F)))
    labels[(np.abs(c[:, 0] - 0.5) < 0.2) & (np.abs(c[:, 1] - 0.5) < 0.2) & (c[:, 2] > 0.99)] = 2
    full = judge(V, F, labels, turning_tolerance=0.05)
    plain = judge(V, F, labels, turning=False)
    assert plain.report["turning_points"]["count"] is None and plain.report["monotone"] is None
    added = with_turning_points(V, build_topology(F, len(V)), frames(len(F)), plain, 0.05)
    assert len(full.turning_points) >= 2
    assert np.array_equal(added.turning_points, full.turning_points)
    assert added.report == full.report
