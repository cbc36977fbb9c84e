# SPDX-License-Identifier: LGPL-2.1-or-later
"""Curve skeleton of a closed triangle mesh by voxel thinning, cut into pieces.

Route: scan-line voxelisation of the solid (parity of surface crossings along z),
3-D thinning (Lee et al. 1994, ``skimage.morphology.skeletonize``), a 26-connected
skeleton graph, pruning of spurs, then pieces: one per junction cluster and short
segments along every branch. Parts are built from these pieces by
:mod:`core.segmentation.skeleton_parts`.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import connected_components, dijkstra

from core.errors import ParameterError
from core.geometry import face_cross

PAD = 2
# fractional grid offsets (in voxels) that keep column centres off mesh vertices/edges
_JITTER = np.array([0.1309, 0.1737, 0.0])


@dataclass
class VoxelGrid:
    """occupied : (nx, ny, nz) bool, voxel centre inside the solid.
    origin : (3,) float64 corner of voxel (0, 0, 0); centre of voxel ijk is
    ``origin + (ijk + 0.5) * pitch``. pitch : float voxel edge length."""

    occupied: np.ndarray
    origin: np.ndarray
    pitch: float

    def centres(self, ijk):
        """(k, 3) world coordinates of voxel centres ``ijk`` (k, 3)."""
        return self.origin + (np.asarray(ijk, dtype=np.float64) + 0.5) * self.pitch


def choose_pitch(vertices, faces, resolution=160, voxels_across=4.0, max_voxels=3_000_000):
    """Voxel size for thinning.

    The finest of ``longest extent / resolution`` and ``thickness / voxels_across`` where
    thickness = 2 volume / area (exact for a plate, the radius for a round bar), then
    coarsened until the padded grid has at most ``max_voxels`` voxels.
    """
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces, dtype=np.int64)]
    cross = face_cross(v, faces)
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    volume = abs(np.einsum("fi,fi->", tri[:, 0], cross)) / 6.0
    extent = v.max(axis=0) - v.min(axis=0)
    pitch = extent.max() / resolution
    if area > 0 and volume > 0:
        pitch = min(pitch, 2.0 * volume / area / voxels_across)
    count = np.prod(np.ceil(extent / pitch) + 2 * PAD + 1)
    if count > max_voxels:
        pitch *= (count / max_voxels) ** (1.0 / 3.0)
    return float(pitch)


def voxelize(vertices, faces, pitch, chunk=200_000):
    """Solid voxelisation of a closed mesh by scan lines along z.

    Every (x, y) column of voxel centres is intersected with the triangles; a voxel is
    inside when an odd number of crossings lie below its centre.

    Returns
    -------
    VoxelGrid
    """
    v = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    origin = lo - (PAD + _JITTER) * pitch
    dims = (np.ceil((hi - origin) / pitch) + PAD).astype(np.int64)
    tri = v[faces]
    # column index ranges covered by each triangle's xy bounding box
    gmin = np.ceil((tri.min(axis=1)[:, :2] - origin[:2]) / pitch - 0.5).astype(np.int64)
    gmax = np.floor((tri.max(axis=1)[:, :2] - origin[:2]) / pitch - 0.5).astype(np.int64)
    span = np.maximum(gmax - gmin + 1, 0)
    count = span[:, 0] * span[:, 1]
    crossings = np.zeros(dims[0] * dims[1] * (dims[2] + 1), dtype=np.int32)
    todo = np.flatnonzero(count > 0)
    bounds = np.searchsorted(np.cumsum(count[todo]), np.arange(chunk, count.sum() + chunk, chunk))
    start = 0
    for stop in np.unique(np.append(bounds, len(todo))):
        ids = todo[start:stop]
        start = stop
        if len(ids) == 0:
            continue
        reps = count[ids]
        f = np.repeat(ids, reps)
        local = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
        i = gmin[f, 0] + local // span[f, 1]
        j = gmin[f, 1] + local % span[f, 1]
        px = origin[0] + (i + 0.5) * pitch
        py = origin[1] + (j + 0.5) * pitch
        t = tri[f]
        w0 = (t[:, 1, 0] - px) * (t[:, 2, 1] - py) - (t[:, 2, 0] - px) * (t[:, 1, 1] - py)
        w1 = (t[:, 2, 0] - px) * (t[:, 0, 1] - py) - (t[:, 0, 0] - px) * (t[:, 2, 1] - py)
        w2 = (t[:, 0, 0] - px) * (t[:, 1, 1] - py) - (t[:, 1, 0] - px) * (t[:, 0, 1] - py)
        total = w0 + w1 + w2
        inside = (((w0 >= 0) & (w1 >= 0) & (w2 >= 0)) | ((w0 <= 0) & (w1 <= 0) & (w2 <= 0)))
        inside &= total != 0
        w0, w1, w2, total, t = w0[inside], w1[inside], w2[inside], total[inside], t[inside]
        z = (w0 * t[:, 0, 2] + w1 * t[:, 1, 2] + w2 * t[:, 2, 2]) / total
        k = np.clip(np.ceil((z - origin[2]) / pitch - 0.5).astype(np.int64), 0, dims[2])
        flat = (i[inside] * dims[1] + j[inside]) * (dims[2] + 1) + k
        crossings += np.bincount(flat, minlength=len(crossings)).astype(np.int32)
    parity = np.cumsum(crossings.reshape(dims[0], dims[1], dims[2] + 1), axis=2)[:, :, :-1] % 2
    return VoxelGrid(parity.astype(bool), origin, float(pitch))


def thin(grid):
    """Curve skeleton voxels of ``grid`` by 3-D thinning.

    scikit-image's thinning can delete a whole simply connected component (scikit-image
    bug #3757); such a component keeps its deepest voxel (largest distance to the
    outside) as its skeleton.

    Returns
    -------
    ijk : (k, 3) int64 skeleton voxel indices (lexicographic order).
    vanished : int, number of components that needed that fallback.
    """
    from core.optional_imports import import_skeletonize

    skeletonize = import_skeletonize()
    skel = skeletonize(grid.occupied) > 0
    comp, n_comp = ndimage.label(grid.occupied, structure=np.ones((3, 3, 3)))
    has = np.zeros(n_comp + 1, dtype=bool)
    has[comp[skel]] = True
    missing = np.flatnonzero(~has[1:]) + 1
    if len(missing):
        depth = ndimage.distance_transform_edt(grid.occupied)
        for c in missing:
            where = np.flatnonzero((comp == c).ravel())
            skel.ravel()[where[np.argmax(depth.ravel()[where])]] = True
    return np.argwhere(skel).astype(np.int64), len(missing)


_OFFSETS = np.array([o for o in np.ndindex(3, 3, 3) if o != (1, 1, 1)], dtype=np.int64) - 1


def skeleton_edges(ijk, shape):
    """(e, 2) int64 pairs (a < b) of 26-adjacent skeleton voxels and (e,) lengths in voxels."""
    lookup = np.full(shape, -1, dtype=np.int64)
    lookup[tuple(ijk.T)] = np.arange(len(ijk))
    pairs, lengths = [], []
    for off in _OFFSETS[13:]:
        nb = ijk + off
        ok = ((nb >= 0) & (nb < np.array(shape))).all(axis=1)
        b = np.full(len(ijk), -1)
        b[ok] = lookup[tuple(nb[ok].T)]
        a = np.flatnonzero(b >= 0)
        pairs.append(np.stack([a, b[a]], axis=1))
        lengths.append(np.full(len(a), np.linalg.norm(off)))
    pairs = np.concatenate(pairs)
    return np.sort(pairs, axis=1), np.concatenate(lengths)


def _graph(n, pairs, weights, keep):
    sel = keep[pairs[:, 0]] & keep[pairs[:, 1]]
    p, w = pairs[sel], weights[sel]
    return sp.csr_matrix((np.concatenate([w, w]), (np.concatenate([p[:, 0], p[:, 1]]),
                                                   np.concatenate([p[:, 1], p[:, 0]]))),
                         shape=(n, n))


def _components(n, pairs, weights, keep):
    """Component label of each kept node (-1 elsewhere) in the graph restricted to ``keep``."""
    _, lab = connected_components(_graph(n, pairs, weights, keep), directed=False)
    lab = np.where(keep, lab, -1)
    uniq, lab[keep] = np.unique(lab[keep], return_inverse=True)
    return lab, len(uniq)


def _branches_and_junctions(n, pairs, weights, alive):
    """Split alive skeleton voxels into junction clusters and branches.

    A junction cluster is a connected set of voxels of degree >= 3 touching at least three
    branch ends; smaller clusters (staircase cliques) are folded into the branches.

    Returns
    -------
    branch : (n,) int64 branch id or -1; junction : (n,) int64 cluster id or -1;
    touching : list over clusters of the sorted branch ids around it.
    """
    live = pairs[alive[pairs[:, 0]] & alive[pairs[:, 1]]]
    deg = np.bincount(live.ravel(), minlength=n)
    is_j = alive & (deg >= 3)
    link = np.concatenate([live, live[:, ::-1]])
    while True:
        branch, _ = _components(n, pairs, weights, alive & ~is_j)
        cluster, n_cl = _components(n, pairs, weights, is_j)
        lk = link[(cluster[link[:, 0]] >= 0) & (branch[link[:, 1]] >= 0)]
        cb = np.unique(np.stack([cluster[lk[:, 0]], branch[lk[:, 1]]], axis=1), axis=0)
        touching = [cb[cb[:, 0] == c, 1] for c in range(n_cl)]
        weak = [c for c in range(n_cl) if len(touching[c]) < 3]
        if not weak:
            return branch, cluster, touching
        is_j &= ~np.isin(cluster, weak)


def prune_spurs(n, pairs, weights, radius, spur_factor, max_rounds=20):
    """(n,) bool alive mask after removing terminal branches shorter than
    ``spur_factor`` x the radius of the junction they hang from (lengths in voxels)."""
    alive = np.ones(n, dtype=bool)
    for _ in range(max_rounds):
        branch, cluster, touching = _branches_and_junctions(n, pairs, weights, alive)
        if not touching:
            break
        n_br = branch.max() + 1
        size = np.bincount(branch[branch >= 0], minlength=n_br)
        n_touch = np.bincount(np.concatenate(touching).astype(np.int64), minlength=n_br)
        cl_radius = np.zeros(len(touching))
        np.maximum.at(cl_radius, cluster[cluster >= 0], radius[cluster >= 0])
        doomed = np.zeros(n_br, dtype=bool)
        for c, brs in enumerate(touching):
            short = brs[(n_touch[brs] == 1) & (size[brs] < spur_factor * cl_radius[c])]
            if len(short) == len(brs):
                short = short[np.argsort(-size[short], kind="stable")[1:]]
            doomed[short] = True
        if not doomed.any():
            break
        alive &= ~((branch >= 0) & doomed[np.maximum(branch, 0)])
    return alive


@dataclass
class SkeletonPieces:
    """points : (k, 3) world coordinates of the skeleton voxels kept.
    piece : (k,) int64 piece of each point (junction clusters and branch segments).
    radius : (k,) float64 distance to the surface (mesh units).
    edges : (e, 2) int64 pairs (a < b) of 26-adjacent points; lengths : (e,) float64
    their distances (mesh units). junction : (k,) bool, point of a junction cluster.
    n_junctions : int; n_branches : int; pitch : float; vanished : int (see :func:`thin`)."""

    points: np.ndarray
    piece: np.ndarray
    radius: np.ndarray
    edges: np.ndarray
    lengths: np.ndarray
    junction: np.ndarray
    n_junctions: int
    n_branches: int
    pitch: float
    vanished: int


def skeleton_pieces(vertices, faces, pitch, spur_factor=2.0, segment_factor=4.0):
    """Curve skeleton of the mesh's solid, cut into pieces.

    Parameters
    ----------
    vertices : (n, 3) float64; faces : (m, 3) int64 closed, outward oriented.
    pitch : float voxel size (mesh units), see :func:`choose_pitch`.
    spur_factor : terminal branches shorter than this many junction radii are pruned.
    segment_factor : branches are cut into segments about this many radii long.

    Returns
    -------
    SkeletonPieces
    """
    if spur_factor < 0 or segment_factor <= 0:
        raise ParameterError(f"spur_factor must be >= 0 and segment_factor > 0, "
                             f"got {spur_factor}, {segment_factor}")
    grid = voxelize(vertices, faces, pitch)
    ijk, vanished = thin(grid)
    depth = ndimage.distance_transform_edt(grid.occupied)
    radius_vox = depth[tuple(ijk.T)]
    n = len(ijk)
    pairs, weights = skeleton_edges(ijk, grid.occupied.shape)
    alive = prune_spurs(n, pairs, weights, radius_vox, spur_factor)
    branch, cluster, touching = _branches_and_junctions(n, pairs, weights, alive)
    n_cl = len(touching)
    n_br = int(branch.max()) + 1 if (branch >= 0).any() else 0
    piece = np.full(n, -1, dtype=np.int64)
    piece[cluster >= 0] = cluster[cluster >= 0]
    if n_br:
        # arc length from one start voxel per branch: next to its first junction, else an end
        inb = branch >= 0
        graph = _graph(n, pairs, weights, inb)
        deg_in = np.diff(graph.indptr)
        start = np.full(n_br, -1)
        for c, brs in enumerate(touching):
            near = pairs[(cluster[pairs[:, 0]] == c) | (cluster[pairs[:, 1]] == c)].ravel()
            near = near[inb[near]]
            for b in brs:
                if start[b] < 0:
                    start[b] = near[branch[near] == b].min()
        cand = np.flatnonzero(inb)
        order = np.lexsort((cand, deg_in[cand] != 1, branch[cand]))
        first = cand[order][np.unique(branch[cand][order], return_index=True)[1]]
        start = np.where(start < 0, first, start)
        t = dijkstra(graph, directed=False, indices=start, min_only=True)
        t = np.where(np.isfinite(t), t, 0.0)
        length = np.zeros(n_br)
        np.maximum.at(length, branch[inb], t[inb])
        mean_r = np.bincount(branch[inb], weights=radius_vox[inb], minlength=n_br) / \
            np.maximum(np.bincount(branch[inb], minlength=n_br), 1)
        n_seg = np.maximum(1, np.round(length / (segment_factor * np.maximum(mean_r, 1.0))))
        seg_len = np.maximum(length / n_seg, 1e-9)
        b = branch[inb]
        seg = np.minimum((t[inb] / seg_len[b]).astype(np.int64), n_seg[b].astype(np.int64) - 1)
        offset = n_cl + np.concatenate([[0], np.cumsum(n_seg)[:-1]]).astype(np.int64)
        piece[inb] = offset[b] + seg
    keep = piece >= 0
    _, piece_kept = np.unique(piece[keep], return_inverse=True)
    new_id = np.cumsum(keep) - 1
    both = keep[pairs[:, 0]] & keep[pairs[:, 1]]
    return SkeletonPieces(grid.centres(ijk[keep]), piece_kept.astype(np.int64),
                          radius_vox[keep] * grid.pitch, new_id[pairs[both]],
                          weights[both] * grid.pitch, (cluster >= 0)[keep], n_cl, n_br,
                          grid.pitch, vanished)
