# SPDX-License-Identifier: LGPL-2.1-or-later
"""Automatic parts from the curve skeleton (paper Sect. 2.1): skeleton pieces merged while one
frame fits them, cut by planes across the members, boundaries smoothed, patches absorbed and
merged until every interface is one closed loop.

The result is a segmentation in the sense of :mod:`core.segmentation.parts` (whose checks and
interfaces it uses).
"""
import heapq
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix, diags
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

from core.errors import ParameterError
from core.geometry import face_areas, face_cross
from core.mesh_topology import edge_faces, face_adjacency, face_neighbours
from core.segmentation.frames import mean_edge_length
from core.segmentation.part_frame import cubic_energy, frame_from_moments, group_moments
from core.segmentation.parts import (canonical_order, face_interface_axes, interfaces,
                                     part_components)
from core.segmentation.skeleton import choose_pitch, skeleton_pieces
from core.types import TriMesh

MIN_PART_FACES = 12
"""Fewest faces an automatic part may have (five or six charts of two triangles)."""


@dataclass
class AutomaticParts:
    """Result of :func:`skeleton_segmentation`.

    face_part : (m,) int32 canonical parts.
    info : dict of figures (pitch, skeleton points, junctions, branches, pieces, parts).
    skeleton : :class:`core.segmentation.skeleton.SkeletonPieces`.
    """

    face_part: np.ndarray
    info: dict
    skeleton: object


def majority_smooth(neighbours, label, max_iter=20):
    """Give each face the label that at least two of its three neighbours share.

    neighbours : (m, 3) int64; label : (m,) int64. Returns the smoothed (m,) int64.
    """
    label = np.asarray(label, dtype=np.int64).copy()
    for _ in range(max_iter):
        nb = label[neighbours]
        a, b, c = nb[:, 0], nb[:, 1], nb[:, 2]
        vote = np.where(a == b, a, np.where(b == c, b, np.where(a == c, a, label)))
        change = vote != label
        if not change.any():
            break
        label = np.where(change, vote, label)
    return label


def absorb_fragments(pairs, neighbours, label, max_rounds=50):
    """Make every label edge-connected: pieces other than a label's largest move to the
    neighbouring label they share most edges with. Returns (m,) int64."""
    label = np.asarray(label, dtype=np.int64).copy()
    for _ in range(max_rounds):
        comp, n_comp = part_components(pairs, label)
        size = np.bincount(comp, minlength=n_comp)
        comp_label = np.zeros(n_comp, dtype=np.int64)
        comp_label[comp] = label
        order = np.lexsort((-size, comp_label))
        keep = np.zeros(n_comp, dtype=bool)
        keep[order[np.unique(comp_label[order], return_index=True)[1]]] = True
        if keep.all():
            break
        own = np.repeat(np.arange(len(label)), 3)
        other = neighbours.reshape(-1)
        sel = ~keep[comp[own]] & (comp[other] != comp[own])
        votes = np.unique(np.stack([comp[own[sel]], label[other[sel]]], axis=1),
                          axis=0, return_counts=True)
        (cc, lab), cnt = votes[0].T, votes[1]
        best = np.lexsort((lab, -cnt, cc))
        first = best[np.unique(cc[best], return_index=True)[1]]
        target = np.full(n_comp, -1)
        target[cc[first]] = lab[first]
        move = ~keep & (target >= 0)
        label = np.where(move[comp], target[comp], label)
    return label


def _merge_pieces(moments, counts, adjacency, min_area, max_parts, tol, align_degenerate):
    """Greedy agglomeration of pieces; returns (K,) int64 group of each piece.

    1. Adjacent groups merge, cheapest first, while the frame of their union raises
       neither group's area-mean cubic misalignment of normals by more than ``tol``.
    2. Groups with area below ``min_area`` or fewer than :data:`MIN_PART_FACES` faces
       (``counts``) merge, smallest first, with their cheapest neighbour.
    3. The cheapest merges continue until at most ``max_parts`` groups remain.
    """
    k = len(moments)
    parent = np.arange(k)
    mom = list(moments)
    count = np.asarray(counts, dtype=np.int64).copy()
    own = [cubic_energy(mo.normal4, frame_from_moments(mo, align_degenerate)) for mo in mom]
    nbrs = [set() for _ in range(k)]
    for a, b in adjacency:
        nbrs[a].add(b)
        nbrs[b].add(a)
    alive = set(range(k))
    version = np.zeros(k, dtype=np.int64)

    def cost(a, b):
        frame = frame_from_moments(mom[a] + mom[b], align_degenerate)
        ca = (cubic_energy(mom[a].normal4, frame) - own[a]) / mom[a].area
        cb = (cubic_energy(mom[b].normal4, frame) - own[b]) / mom[b].area
        return max(ca, cb)

    def merge(a, b):
        a, b = min(a, b), max(a, b)
        mom[a] = mom[a] + mom[b]
        count[a] += count[b]
        own[a] = cubic_energy(mom[a].normal4, frame_from_moments(mom[a], align_degenerate))
        alive.discard(b)
        parent[parent == b] = a
        nbrs[a] = (nbrs[a] | nbrs[b]) - {a, b}
        for x in nbrs[b]:
            nbrs[x].discard(b)
            if x != a:
                nbrs[x].add(a)
        version[a] += 1
        return a

    def run(limit):
        """Merge cheapest pairs while cost <= limit or too many groups remain."""
        heap = [(cost(a, b), a, b, version[a], version[b])
                for a in sorted(alive) for b in sorted(nbrs[a]) if a < b]
        heapq.heapify(heap)
        while heap:
            c, a, b, va, vb = heapq.heappop(heap)
            if a not in alive or b not in alive or (va, vb) != (version[a], version[b]):
                continue
            if c > limit and len(alive) <= max_parts:
                break
            a = merge(a, b)
            for x in sorted(nbrs[a]):
                lo, hi = min(a, x), max(a, x)
                heapq.heappush(heap, (cost(lo, hi), lo, hi, version[lo], version[hi]))

    run(tol)
    while True:
        small = [g for g in alive if (mom[g].area < min_area or count[g] < MIN_PART_FACES)
                 and nbrs[g]]
        if not small:
            break
        g = min(small, key=lambda x: (mom[x].area, x))
        merge(g, min(nbrs[g], key=lambda x: (cost(g, x), x)))
    run(-np.inf)
    return parent


# ----------------------------------------------------------------------------------------
# planar cuts across the skeleton

STRAIGHT_ANGLE = 30.0
"""Degrees: a cut whose two sides' skeleton tangents differ by less is a straight cut."""


def _skeleton_graph(skel, keep=None):
    """Symmetric csr graph (k, k) of skeleton edges with both ends in ``keep`` (all if None)."""
    e, w = skel.edges, skel.lengths
    if keep is not None:
        sel = keep[e[:, 0]] & keep[e[:, 1]]
        e, w = e[sel], w[sel]
    k = len(skel.points)
    return csr_matrix((np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]),
                                                np.concatenate([e[:, 1], e[:, 0]]))),
                      shape=(k, k))


def skeleton_point_parts(skel, nearest, face_part):
    """(k,) int64 part of every skeleton point: the part most of its nearest faces have
    (ties to the lower id); points no face chose take the part of the closest such point
    along the skeleton; -1 on skeleton components without any."""
    k = len(skel.points)
    pairs, cnt = np.unique(np.stack([nearest, face_part], axis=1), axis=0, return_counts=True)
    order = np.lexsort((pairs[:, 1], -cnt, pairs[:, 0]))
    first = order[np.unique(pairs[order, 0], return_index=True)[1]]
    point_part = np.full(k, -1, dtype=np.int64)
    point_part[pairs[first, 0]] = pairs[first, 1]
    seeds = np.flatnonzero(point_part >= 0)
    if len(seeds) < k:
        dist, _, source = dijkstra(_skeleton_graph(skel), directed=False, indices=seeds,
                                   min_only=True, return_predecessors=True)
        reach = np.isfinite(dist) & (point_part < 0)
        point_part[reach] = point_part[source[reach]]
    return point_part


def _cut_groups(skel, point_part):
    """Places where the skeleton passes from one part to another.

    Returns a list of ``(a, b, ends_a, ends_b)``: parts a < b and the (sorted) skeleton
    points of each side on the cut edges, one entry per connected group of cut edges.
    """
    e = skel.edges
    pa, pb = point_part[e[:, 0]], point_part[e[:, 1]]
    cut = e[(pa != pb) & (pa >= 0) & (pb >= 0)]
    if len(cut) == 0:
        return []
    k = len(skel.points)
    on_cut = np.zeros(k, dtype=bool)
    on_cut[cut.ravel()] = True
    link = e[on_cut[e[:, 0]] & on_cut[e[:, 1]]]
    graph = csr_matrix((np.ones(len(link)), (link[:, 0], link[:, 1])), shape=(k, k))
    _, comp = connected_components(graph, directed=False)
    pair = np.sort(point_part[cut], axis=1)
    key = np.stack([pair[:, 0], pair[:, 1], comp[cut[:, 0]]], axis=1)
    groups = []
    for a, b, c in np.unique(key, axis=0).tolist():
        ends = np.unique(cut[(key == (a, b, c)).all(axis=1)])
        groups.append((a, b, ends[point_part[ends] == a], ends[point_part[ends] == b]))
    groups.sort(key=lambda g: (g[0], g[1], min(g[2].min(), g[3].min())))
    return groups


def _tangent(points, dist, origin, r0, pitch):
    """Unit principal direction of the points at skeleton distance r0 .. 3 r0 from a cut
    (all within 3 r0 if too few), pointing away from ``origin``; None if under two."""
    sel = (dist >= r0) & (dist <= 3.0 * r0 + pitch)
    if sel.sum() < 3:
        sel = dist <= 3.0 * r0 + pitch
    if sel.sum() < 2:
        return None
    x = points[sel]
    centre = x.mean(axis=0)
    axis = np.linalg.svd(x - centre, full_matrices=False)[2][0]
    away = centre - origin
    if np.linalg.norm(away) > 1e-12 * max(r0, 1.0) and away @ axis < 0:
        axis = -axis
    return axis


def planar_cuts(vertices, faces, skel, nearest, face_part, straight_angle=STRAIGHT_ANGLE):
    """Replace every part boundary that crosses the skeleton by one plane across it.

    For each place where the skeleton passes from part a to part b (see
    :func:`_cut_groups`), with ``r0`` the larger skeleton radius at the cut:

    - tangents t_a, t_b of both sides come from the skeleton points 1-3 ``r0`` away;
    - straight cut (angle between t_a and -t_b below ``straight_angle`` and a junction
      cluster within 2 ``r0`` on neither or both sides): the plane through the cut with
      normal t_b - t_a;
    - otherwise (bend or junction) the side with the junction, else the larger part,
      keeps the corner; the plane is perpendicular to the other side's tangent and
      placed just beyond the keeper's skeleton balls (centre + radius), i.e. at the
      keeper's surface, offset from the junction by about the local radius.

    Only faces of parts a, b whose nearest skeleton point lies near the cut (within
    3 ``r0`` on the keeping side, 6 ``r0`` on the other) change side.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64.
    skel : :class:`core.segmentation.skeleton.SkeletonPieces`.
    nearest : (m,) int64 nearest skeleton point of each face centroid.
    face_part : (m,) int64 parts.

    Returns
    -------
    (m,) int64 new parts (same ids; parts may become disconnected or empty).
    """
    face_part = np.asarray(face_part, dtype=np.int64).copy()
    centroid = vertices[faces].mean(axis=1)
    point_part = skeleton_point_parts(skel, nearest, face_part)
    area = np.bincount(face_part, weights=face_areas(vertices, faces))
    cos_straight = np.cos(np.radians(straight_angle))
    pts, rad, pitch = skel.points, skel.radius, skel.pitch
    for a, b, ends_a, ends_b in _cut_groups(skel, point_part):
        ends = np.concatenate([ends_a, ends_b])
        origin = pts[ends].mean(axis=0)
        r0 = max(float(rad[ends].max()), pitch)
        reach = 6.0 * r0 + 2.0 * pitch
        dist = {}
        for p, src in ((a, ends_a), (b, ends_b)):
            dist[p] = dijkstra(_skeleton_graph(skel, point_part == p), directed=False,
                               indices=src, min_only=True, limit=reach)
        t_a = _tangent(pts, dist[a], origin, r0, pitch)
        t_b = _tangent(pts, dist[b], origin, r0, pitch)
        if t_a is None or t_b is None:
            continue
        near_j = {p: bool((skel.junction & (dist[p] <= 2.0 * r0)).any()) for p in (a, b)}
        if -t_a @ t_b >= cos_straight and near_j[a] == near_j[b]:
            keep, other, normal, offset = a, b, t_b - t_a, 0.0
            normal /= np.linalg.norm(normal)
            keep_reach = 3.0 * r0 + pitch
        else:
            if near_j[a] != near_j[b]:
                keep = a if near_j[a] else b
            else:
                keep = a if area[a] >= area[b] else b
            other = b if keep == a else a
            normal = t_b if other == b else t_a
            keep_reach = 3.0 * r0 + pitch
            balls = dist[keep] <= keep_reach
            offset = float(((pts[balls] - origin) @ normal + rad[balls]).max()) + 0.5 * pitch
            far = np.isfinite(dist[other])
            offset = min(offset, float(((pts[far] - origin) @ normal).max()))
        region = (dist[keep] <= keep_reach) | np.isfinite(dist[other])
        sel = np.flatnonzero(region[nearest] & ((face_part == a) | (face_part == b)))
        beyond = (centroid[sel] - origin) @ normal > offset
        face_part[sel] = np.where(beyond, other, keep)
    return face_part


def smooth_boundaries(vertices, faces, face_part, width, max_iter=8):
    """Straighten part boundaries by threshold dynamics (Merriman-Bence-Osher).

    Every part's indicator is diffused over the faces by one implicit heat step
    ``(M + t L) u = M chi`` (M face areas, L the face-adjacency Laplacian weighted by
    shared edge length / centroid distance, ``t = width**2``) and each face takes the
    part with the largest value; repeated until nothing changes or ``max_iter``. The
    factorisation is made once, and after the first step only the columns of the parts that
    gained or lost faces are solved again (on a fine mesh with many parts, a small fraction of
    the columns per step, with the same result).
    This moves boundaries by their geodesic curvature: staircase steps about
    ``width`` wide vanish and loops around a bar settle on short cross-sections.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64; face_part : (m,) int parts.
    width : float, smoothing length (mesh units).

    Returns
    -------
    (m,) int64 parts (same ids, some may become empty or disconnected).
    """
    label = np.asarray(face_part, dtype=np.int64).copy()
    n_parts = int(label.max()) + 1
    if n_parts < 2 or width <= 0:
        return label
    edges, fe = edge_faces(faces)
    inner = (fe >= 0).all(axis=1)
    f0, f1 = fe[inner, 0], fe[inner, 1]
    centroid = vertices[faces].mean(axis=1)
    length = np.linalg.norm(vertices[edges[inner, 0]] - vertices[edges[inner, 1]], axis=1)
    gap = np.maximum(np.linalg.norm(centroid[f0] - centroid[f1], axis=1), 1e-12)
    w = length / gap
    m = len(faces)
    area = face_areas(vertices, faces)
    lap = csr_matrix((np.concatenate([w, w]), (np.concatenate([f0, f1]),
                                               np.concatenate([f1, f0]))), shape=(m, m))
    lap = diags(np.asarray(lap.sum(axis=1)).ravel()) - lap
    solve = splu((diags(area) + width ** 2 * lap).tocsc()).solve
    heat = np.zeros((m, n_parts))
    changed = np.arange(n_parts)
    for _ in range(max_iter):
        # only the parts that gained or lost faces have a new indicator: the other columns of
        # the heat step are the same solve of the same right-hand side
        heat[:, changed] = solve(_indicators(label, area, changed))
        new = np.argmax(heat, axis=1)
        if np.array_equal(new, label):
            break
        moved = new != label
        changed = np.unique(np.concatenate([label[moved], new[moved]]))
        label = new
    return label


def _indicators(label, area, parts):
    """(m, k) float64 area-weighted indicators ``M chi`` of the ``parts`` (k,) int64 (sorted)."""
    chi = np.zeros((len(label), len(parts)))
    column = np.searchsorted(parts, label)
    mine = np.flatnonzero(parts[np.minimum(column, len(parts) - 1)] == label)
    chi[mine, column[mine]] = area[mine]
    return chi


PATCH_NORMAL = 0.5
"""A part whose area-weighted mean normal is at least this long (1 for a flat patch,
about 0 for a slab of the solid cut by closed loops) is a patch on a wall, not a part.
Over a part cut off by planar loops the sum of ``A n`` is minus that of its cut faces
(divergence theorem), so the length is the cut area over the part's own surface area: at
least one half means the cut is as large as half the part's surface, a layer of the solid
lying on the cut (an ``a x a`` plate of thickness ``a / 4`` or less) rather than a member
cut across. Its interface runs along its largest face, whose own label Eq. 3's term 4 then
forbids next to the interface."""


def _shared_lengths(vertices, faces, label):
    """Part pairs (q, 2) int64 (i < j) that share edges and (q,) float64 shared length."""
    edges, fe = edge_faces(faces)
    ok = (fe >= 0).all(axis=1)
    pa, pb = label[fe[:, 0]], label[np.maximum(fe[:, 1], 0)]
    cut = np.flatnonzero(ok & (pa != pb))
    pair = np.sort(np.stack([pa[cut], pb[cut]], axis=1), axis=1)
    length = np.linalg.norm(vertices[edges[cut, 0]] - vertices[edges[cut, 1]], axis=1)
    uniq, inv = np.unique(pair, axis=0, return_inverse=True)
    return uniq, np.bincount(inv.ravel(), weights=length, minlength=len(uniq))


def _merge_into(label, pairs, lengths, source):
    """Give part ``source`` to the neighbour it shares the longest boundary with."""
    touching = (pairs == source).any(axis=1)
    if not touching.any():
        return label
    idx = np.flatnonzero(touching)
    best = idx[np.lexsort((pairs[idx].sum(axis=1), -lengths[idx]))[0]]
    target = int(pairs[best].sum() - source)
    return np.where(label == source, target, label)


def _absorb_small(vertices, faces, label):
    """Merge parts with fewer than :data:`MIN_PART_FACES` faces, smallest first."""
    label = np.asarray(label, dtype=np.int64).copy()
    while True:
        parts, counts = np.unique(label, return_counts=True)
        if len(parts) < 2 or counts.min() >= MIN_PART_FACES:
            return label
        pairs, lengths = _shared_lengths(vertices, faces, label)
        label = _merge_into(label, pairs, lengths, int(parts[np.argmin(counts)]))


def absorb_patches(vertices, faces, face_part, max_normal=PATCH_NORMAL):
    """Merge every part that is a patch on a wall into its longest-bordering neighbour.

    A part is a patch when its area-weighted mean normal ``|sum A n| / sum A`` is at
    least ``max_normal``: its faces all look one way (a piece of a hole wall or of one
    face), whereas a part cut off the solid by loops has faces on opposite sides.
    Patches are taken one at a time, most one-sided first. Returns (m,) int64.
    """
    label = np.asarray(face_part, dtype=np.int64).copy()
    vec = 0.5 * face_cross(vertices, faces)
    area = np.linalg.norm(vec, axis=1)
    while True:
        parts = np.unique(label)
        if len(parts) < 2:
            return label
        total = np.stack([np.bincount(label, weights=vec[:, k], minlength=parts[-1] + 1)
                          for k in range(3)], axis=1)[parts]
        ratio = np.linalg.norm(total, axis=1) / np.maximum(
            np.bincount(label, weights=area)[parts], 1e-300)
        if ratio.max() < max_normal:
            return label
        pairs, lengths = _shared_lengths(vertices, faces, label)
        label = _merge_into(label, pairs, lengths, int(parts[np.argmax(ratio)]))


TANGENT_SHARE = 0.1
"""A small part (see :data:`TANGENT_AREA`) is cut along its wall, not across, when at least this
share of its area lies next to one of its interfaces (a vertex on it) with normals within 45
degrees of that interface's x-axis. Eq. 3's term 4 forbids those faces the label nearest to their
normal whatever the frame, so the part's labeling angle rises by about the share times the 50 to
80 degrees those faces then miss. A part cut across a member has almost none of its area
there, so the threshold sits well above that."""
TANGENT_AREA = 0.1
"""Largest share of the mesh's area a part cut along its wall may have to be merged: a larger
part is a member the skeleton found (a tube meeting another one flush with its side keeps its
own part, though the long faces of a coarse tube make its share high)."""


def tangent_cut_shares(vertices, faces, face_part):
    """Share of each part's area that lies along one of its interfaces (see
    :data:`TANGENT_SHARE`).

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64; face_part : (m,) int parts 0 .. P-1.

    Returns
    -------
    share : (P, K) float64, area of part p's faces next to interface k whose normal is within
        45 degrees of its x-axis (:func:`core.segmentation.parts.interface_x_axis`), over the
        part's area; K = number of interfaces (0 for one part).
    pairs : (K, 2) int64, the two parts of each interface.
    part_share : (P,) float64, each part's share of the mesh's area.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    label = np.asarray(face_part, dtype=np.int64)
    n_parts = int(label.max()) + 1
    itfs = interfaces(TriMesh(vertices, faces), label)
    pairs = np.array([itf.parts for itf in itfs], dtype=np.int64).reshape(-1, 2)
    vec = 0.5 * face_cross(vertices, faces)
    area = np.linalg.norm(vec, axis=1)
    part_area = np.bincount(label, weights=area, minlength=n_parts)
    part_share = part_area / max(float(area.sum()), 1e-300)
    if not itfs:
        return np.zeros((n_parts, 0)), pairs, part_share
    face_itf, axis = face_interface_axes(faces, label, itfs, vertices)
    along = np.zeros(len(faces), dtype=bool)
    has = face_itf >= 0
    along[has] = (np.abs((vec[has] * axis[has]).sum(axis=1))
                  >= np.cos(np.radians(45.0)) * area[has])
    key = label[along] * len(itfs) + face_itf[along]
    share = np.bincount(key, weights=area[along], minlength=n_parts * len(itfs))
    share = share.reshape(n_parts, len(itfs)) / np.maximum(part_area, 1e-300)[:, None]
    return share, pairs, part_share


def absorb_tangent_cuts(vertices, faces, face_part, max_share=TANGENT_SHARE,
                        max_area=TANGENT_AREA):
    """Merge every small part cut along its wall into the part across that interface.

    A part of at most ``max_area`` of the mesh's area whose :func:`tangent_cut_shares` reach
    ``max_share`` at an interface joins the other part of that interface; the largest share goes
    first and the test repeats. Returns (m,) int64 parts (ids of merged parts become unused;
    renumber afterwards).
    """
    label = np.asarray(face_part, dtype=np.int64).copy()
    while True:
        share, pairs, part_share = tangent_cut_shares(vertices, faces, label)
        share = np.where((part_share <= max_area)[:, None], share, 0.0)
        if share.size == 0 or share.max() < max_share:
            return label
        part, k = np.unravel_index(int(np.argmax(share)), share.shape)
        label[label == part] = int(pairs[k].sum() - part)


def close_interfaces(vertices, faces, face_part):
    """Merge parts until every interface is one closed loop.

    Where three parts meet, their interfaces are open chains. Among the pairs of parts
    with such an open interface, the pair sharing the longest boundary merges (so a bar
    ending where two larger parts meet keeps its own part), and the test repeats.
    Deterministic.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64; face_part : (m,) int parts.

    Returns
    -------
    (m,) int64 parts (ids of merged parts become unused; renumber afterwards).
    """
    label = np.asarray(face_part, dtype=np.int64).copy()
    while True:
        open_pairs = sorted({itf.parts for itf in interfaces(TriMesh(vertices, faces), label)
                             if len(itf.loops) != 1 or not itf.closed[0]})
        if not open_pairs:
            return label
        pairs, lengths = _shared_lengths(vertices, faces, label)
        key = {tuple(p): w for p, w in zip(pairs.tolist(), lengths)}
        a, b = max(open_pairs, key=lambda pr: (key[pr], -pr[0], -pr[1]))
        label[label == b] = a


def skeleton_segmentation(mesh, resolution=160, voxels_across=4.0, max_voxels=3_000_000,
                          spur_factor=2.0, segment_factor=4.0, merge_angle=10.0,
                          min_area_fraction=0.01, max_parts=None, align_degenerate=True,
                          smooth_factor=3.0):
    """Automatic parts from the curve skeleton (paper Sect. 2.1), with figures.

    1. Voxelise the solid and thin it to a curve skeleton
       (:func:`core.segmentation.skeleton.skeleton_pieces`): junction clusters and
       segments of every branch are pieces.
    2. Each face goes to the piece of its nearest skeleton point; pieces are split into
       edge-connected components.
    3. Adjacent pieces merge, cheapest first, while one PCA frame fits both: the union's
       frame may raise neither piece's area-mean cubic misalignment of normals
       (``sum A (1 - sum_k (n.a_k)^4) / 2``, 0 when normals lie on axes) by more than
       ``sin^2(2 merge_angle) / 4`` (the misalignment of a normal tilted by
       ``merge_angle`` in an axis plane). Pieces below ``min_area_fraction`` of the
       area (or below :data:`MIN_PART_FACES` faces) merge with their best neighbour.
    4. Where the skeleton passes from one part to another, the boundary is replaced by
       one plane across the skeleton (:func:`planar_cuts`; at a junction or bend it is
       offset to the surface of the part keeping the corner).
    5. Boundaries are straightened by threshold dynamics (:func:`smooth_boundaries`,
       width ``smooth_factor`` x the mean edge length, at most half the median skeleton
       radius) and a majority vote; every part is made edge-connected, parts that
       shrank below :data:`MIN_PART_FACES` faces merge with their longest-bordering
       neighbour, patches on walls are absorbed (:func:`absorb_patches`), parts cut along
       their walls join the part across (:func:`absorb_tangent_cuts`) and parts merge until
       every interface is one closed loop (:func:`close_interfaces`).

    Parameters
    ----------
    mesh : closed, outward-oriented triangle mesh (``vertices``, ``faces``).
    resolution : int >= 16, voxels along the longest extent (upper bound of the pitch).
    voxels_across : float >= 1, voxels across the mean thickness 2 V / A.
    max_voxels : int, grid size cap.
    spur_factor, segment_factor : see :func:`core.segmentation.skeleton.skeleton_pieces`.
    merge_angle : float in (0, 45) degrees.
    min_area_fraction : float in [0, 0.5).
    max_parts : int >= 1 or None (no cap).
    align_degenerate : frames resolve PCA-free rotations by normals (see frames module).
    smooth_factor : float in [0, 100], boundary smoothing width in mean edge lengths
        (0: no threshold-dynamics smoothing).

    Returns
    -------
    AutomaticParts
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    m = len(faces)
    _check_range("resolution", resolution, 16, 4096)
    _check_range("voxels_across", voxels_across, 1.0, 64.0)
    _check_range("max_voxels", max_voxels, 4096, 2e8)
    _check_range("spur_factor", spur_factor, 0.0, 100.0)
    _check_range("segment_factor", segment_factor, 0.5, 1000.0)
    _check_range("merge_angle", merge_angle, 0.0, 45.0, open_low=True, open_high=True)
    _check_range("min_area_fraction", min_area_fraction, 0.0, 0.5, open_high=True)
    _check_range("smooth_factor", smooth_factor, 0.0, 100.0)
    if max_parts is None:
        max_parts = max(1, m // MIN_PART_FACES)
    elif int(max_parts) != max_parts or max_parts < 1:
        raise ParameterError(f"max_parts must be an integer >= 1, got {max_parts}")
    if m < MIN_PART_FACES * max_parts and max_parts > 1:
        raise ParameterError(f"the mesh has {m} faces, too few for max_parts={max_parts} "
                             f"(each part needs at least {MIN_PART_FACES} faces)")
    if m < MIN_PART_FACES:
        raise ParameterError(f"the mesh has {m} faces; a part needs at least {MIN_PART_FACES}")

    pitch = choose_pitch(vertices, faces, resolution, voxels_across, max_voxels)
    skel = skeleton_pieces(vertices, faces, pitch, spur_factor, segment_factor)
    centroid = vertices[faces].mean(axis=1)
    _, nearest = cKDTree(skel.points).query(centroid)
    neighbours = face_neighbours(faces)
    piece = majority_smooth(neighbours, skel.piece[nearest])
    adj = face_adjacency(faces)
    piece = absorb_fragments(adj, neighbours, piece)
    piece = canonical_order(part_components(adj, piece)[0]).astype(np.int64)
    n_pieces = int(piece.max()) + 1
    moments = group_moments(vertices, faces, piece, n_pieces)
    pp = np.unique(np.sort(piece[adj], axis=1), axis=0)
    pp = pp[pp[:, 0] != pp[:, 1]]
    counts = np.bincount(piece, minlength=n_pieces)
    total_area = sum(mo.area for mo in moments)
    min_area = min_area_fraction * total_area
    tol = np.sin(np.radians(2.0 * merge_angle)) ** 2 / 4.0
    parent = _merge_pieces(moments, counts, pp.tolist(), min_area, max_parts, tol,
                           align_degenerate)
    label = parent[piece]
    label = planar_cuts(vertices, faces, skel, nearest, label)
    width = min(smooth_factor * mean_edge_length(vertices, faces),
                0.5 * float(np.median(skel.radius)))
    label = smooth_boundaries(vertices, faces, label, width)
    label = majority_smooth(neighbours, label)
    label = absorb_fragments(adj, neighbours, label)
    label = _absorb_small(vertices, faces, label)
    label = absorb_patches(vertices, faces, label)
    label = absorb_tangent_cuts(vertices, faces, label)
    label = close_interfaces(vertices, faces, label)
    face_part = canonical_order(label)
    info = {"pitch": skel.pitch, "skeleton_points": int(len(skel.points)),
            "junctions": skel.n_junctions, "branches": skel.n_branches,
            "vanished_components": skel.vanished, "pieces": n_pieces,
            "parts": int(face_part.max()) + 1}
    return AutomaticParts(face_part, info, skel)


def automatic_parts(mesh, **params):
    """(m,) int32 face_part from the curve skeleton; see :func:`skeleton_segmentation`."""
    return skeleton_segmentation(mesh, **params).face_part


def _check_range(name, value, low, high, open_low=False, open_high=False):
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name} must be a number, got {value!r}") from exc
    bad = not np.isfinite(v) or v < low or v > high or (open_low and v == low) \
        or (open_high and v == high)
    if bad:
        lo = "(" if open_low else "["
        hi = ")" if open_high else "]"
        raise ParameterError(f"{name} must be in {lo}{low}, {high}{hi}, got {value!r}")
